"""Batch conversion: inputs, names, resume after a kill, bad assets, limits, Dask.

Every batch here renders tiny images (16-64 pixels, 1 spp) so the whole file stays quick.
Starting worker processes costs more than such images: the tests of names, manifests,
resumes, the ledger and failures run their jobs in the test process (the
``in_process_jobs`` fixture, tests/batch/conftest.py); those of the pool and the processes
(two local workers, time and memory limits, kills, a closed pipe, the scripts, Dask)
start real ones.
"""

import json
import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import threading
import time

import distributed
import numpy as np
import psutil
import pytest
import trimesh
import scenes

import rtmesh
from rtmesh.batch.books import REPORT_NAME, SUMMARY_NAME
from rtmesh.batch.inputs import Asset, InputError, discover
from rtmesh.batch.ledger import LEDGER_NAME, STATUS, Ledger, decode
from rtmesh.cli import main
from rtmesh.io.atomic_files import target_of
from rtmesh.io.images import read_image

HERE = scenes.TESTS
DATA = os.path.join(HERE, "data")
REPO = os.path.dirname(HERE)

TINY = dict(width=24, height=16, spp=1, quiet=True)


def make_mesh(path, subdivisions=1, kind="sphere"):
    """Write a small mesh (the format follows the extension) and return its path."""
    os.makedirs(os.path.dirname(path), exist_ok=True)
    if kind == "sphere":
        mesh = trimesh.creation.icosphere(subdivisions=subdivisions)
    else:
        mesh = trimesh.creation.box(extents=(1.0, 2.0, 0.5))
    mesh.export(path)
    return str(path)


def truncated_glb(path):
    """A GLB cut off in the middle of its binary chunk."""
    make_mesh(path, subdivisions=2)
    data = open(path, "rb").read()
    with open(path, "wb") as f:
        f.write(data[: len(data) // 2])
    return str(path)


def ledger_records(outdir):
    """Every row of the ledger (read-only, while a batch may be writing it)."""
    path = os.path.join(outdir, LEDGER_NAME)
    if not os.path.exists(path):
        return []
    db = sqlite3.connect(f"file:{path}?mode=ro", uri=True, timeout=10)
    try:
        db.row_factory = sqlite3.Row
        rows = [dict(r) for r in db.execute("SELECT * FROM images")]
    except sqlite3.OperationalError:  # not created yet
        rows = []
    finally:
        db.close()
    for r in rows:
        r["files"] = [o[0] for o in decode(r["outputs"])]
    return rows


def counts(**given):
    """A report's counts: the given ones, zero for the rest."""
    keys = ("assets", "done", "skipped", "failed", "known_failed", "retried", "not_attempted", "images")
    return {k: given.get(k, 0) for k in keys}


def summary(outdir):
    return json.loads((outdir / SUMMARY_NAME).read_text())


def report_lines(outdir):
    return [json.loads(line) for line in (outdir / REPORT_NAME).read_text().splitlines()]


def temporary_files(folder):
    """Files a half-finished write could have left behind."""
    return [os.path.join(here, f) for here, _, files in os.walk(folder)
            for f in files if ".tmp" in f]


# ------------------------------------------------------------------------- inputs and names

@pytest.mark.usefixtures("in_process_jobs")
def test_duplicate_file_names_in_different_folders_get_distinct_outputs(tmp_path):
    src = tmp_path / "assets"
    make_mesh(src / "chairs" / "model.obj")
    make_mesh(src / "tables" / "model.obj", kind="box")
    make_mesh(src / "tables" / "model.ply")  # same stem, same folder, other format
    out = tmp_path / "out"
    report = rtmesh.batch_convert([src], out, workers=2, **TINY)
    assert report.counts == counts(assets=3, done=3, images=3)
    for name in ("chairs/model.obj.png", "tables/model.obj.png", "tables/model.ply.png"):
        image, _ = read_image(out / name)
        assert image.shape == (16, 24, 3)
    # the box and the sphere really are different images
    a, _ = read_image(out / "chairs/model.obj.png")
    b, _ = read_image(out / "tables/model.obj.png")
    assert not np.array_equal(a, b)


def test_names_are_relative_to_the_input_they_were_found_under(tmp_path):
    first = make_mesh(tmp_path / "x" / "a" / "m.obj")
    second = make_mesh(tmp_path / "x" / "b" / "deep" / "m.obj")
    names = [a.name for a in discover([first, second, first])]  # a file named twice: once
    assert names[0] == "m.obj" and names[1].startswith("m.obj-") and len(names) == 2
    # a folder input is the base of its own files, whatever else is given
    assert [a.name for a in discover([tmp_path / "x" / "b"])] == ["deep/m.obj"]
    assert [a.name for a in discover([tmp_path / "x" / "b", first])] == ["deep/m.obj", "m.obj"]


def test_empty_input_is_a_one_line_error(tmp_path, cli):
    (tmp_path / "empty").mkdir()
    (tmp_path / "list.txt").write_text("# nothing yet\n\n")
    for inputs in ([tmp_path / "empty"], [tmp_path / "list.txt"]):
        code = main(["batch", *map(str, inputs), "-o", str(tmp_path / "out"), "-q"])
        assert code == 2
    with pytest.raises(InputError, match="no mesh files"):
        rtmesh.batch_convert([tmp_path / "empty"], tmp_path / "out", **TINY)
    assert not (tmp_path / "out").exists()  # nothing created for nothing to do
    code, out, err = cli("batch", tmp_path / "missing", "-o", tmp_path / "out")
    assert code == 2 and err.strip().count("\n") == 0
    assert err.startswith("rtmesh: error:") and "missing" in err


@pytest.mark.usefixtures("in_process_jobs")
def test_manifests_line_and_csv_with_per_asset_overrides(tmp_path):
    a = make_mesh(tmp_path / "m" / "a.obj")
    b = make_mesh(tmp_path / "m" / "b.stl", kind="box")
    (tmp_path / "list.txt").write_text(f"# assets\n{a}\n\nm/b.stl  # relative to the manifest\n")
    (tmp_path / "list.csv").write_text(
        "path,width,height,views,formats\n"
        "m/a.obj,32,20,,\n"
        f'{b},16,16,"front,top",png;exr\n')
    report = rtmesh.batch_convert([tmp_path / "list.txt"], tmp_path / "out1", workers=1, **TINY)
    assert report.counts["done"] == 2
    assert sorted(os.listdir(tmp_path / "out1" / "m"))[:2] == ["a.obj.png", "b.stl.png"]
    report = rtmesh.batch_convert([tmp_path / "list.csv"], tmp_path / "out2", workers=1, **TINY)
    assert report.counts["done"] == 2 and report.counts["images"] == 3
    out = tmp_path / "out2" / "m"
    assert read_image(out / "a.obj.png")[0].shape == (20, 32, 3)
    assert read_image(out / "b.stl.front.png")[0].shape == (16, 16, 3)
    assert "AO" not in read_image(out / "b.stl.top.exr")[1]
    assert not (out / "b.stl.top.jpg").exists()
    # a bad cell stops the batch before anything runs, naming the file and the line
    (tmp_path / "bad.csv").write_text("path,spp\nm/a.obj,many\n")
    with pytest.raises(InputError, match=r"bad\.csv: line 2: spp"):
        rtmesh.batch_convert([tmp_path / "bad.csv"], tmp_path / "out3", **TINY)


@pytest.mark.parametrize("cell, message", [
    ("views", "views: unknown 'bogus' (expected iso, front, back, left, right, top, bottom)"),
    ("formats", "formats: unknown 'bogus' (expected png, exr, jpg)"),
])
def test_a_bad_manifest_cell_is_named_by_the_manifests_line(cell, message, tmp_path, cli):
    make_mesh(tmp_path / "a.obj")
    manifest = tmp_path / "m.csv"
    manifest.write_text(f"path,{cell}\n\na.obj,bogus\n")
    code, _, err = cli("batch", manifest, "-o", tmp_path / "out", "-q")
    assert code == 2 and err == f"rtmesh: error: {manifest}: line 3: {message}\n"
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("name, content, message", [
    ("nul.txt", b"a\0b.obj\n", "{m}: line 1: the path holds a NUL character"),
    ("nul.csv", b'path\n"a\0b.obj"\n', "{m}: line 2: the path holds a NUL character"),
    ("latin.txt", b"caf\xe9.obj\n", "{m}: cannot read manifest: not UTF-8 text (byte 3)"),
    ("zero.txt", "/dev/zero", "{m}: not a regular file"),
])
def test_a_manifest_that_cannot_be_read_is_one_line_before_anything_runs(name, content, message, tmp_path, cli):
    manifest = tmp_path / name
    if isinstance(content, str):
        manifest.symlink_to(content)  # a device: read, it would never end
    else:
        manifest.write_bytes(content)
    code, _, err = cli("batch", manifest, "-o", tmp_path / "out", "-q")
    assert code == 2 and err == f"rtmesh: error: {message.format(m=manifest)}\n"
    assert not (tmp_path / "out").exists()


# ------------------------------------------------------------------------- bad assets, bad outputs

def test_corrupt_files_in_the_middle_of_a_batch_fail_alone(tmp_path):
    src = tmp_path / "src"
    make_mesh(src / "a_good.obj")
    shutil.copy(os.path.join(DATA, "empty.obj"), src / "b_empty.obj")
    shutil.copy(os.path.join(DATA, "notenoughindices.obj"), src / "c_notenoughindices.obj")
    truncated_glb(src / "d_truncated.glb")
    make_mesh(src / "e_good.ply", kind="box")
    out = tmp_path / "out"
    code = main(["batch", str(src), "-o", str(out), "--width", "16", "--height", "16",
                 "--spp", "1", "--workers", "2", "-q"])
    assert code == 1  # something failed
    status = {a["asset"]: a for a in report_lines(out)}
    assert status["a_good.obj"]["status"] == status["e_good.ply"]["status"] == "done"
    for bad in ("b_empty.obj", "d_truncated.glb"):
        assert status[bad]["status"] == "failed"
        (error,) = status[bad]["errors"]
        assert error["stage"] == "load" and bad in error["message"] and "\n" not in error["message"]
        assert not (out / f"{bad}.png").exists()
    # whatever happens to a half-broken file, the batch finished and accounted for it
    assert status["c_notenoughindices.obj"]["status"] in ("done", "failed")
    assert summary(out)["counts"]["assets"] == 5 == len(status)
    assert temporary_files(out) == []


def test_unwritable_output_folder_is_a_one_line_error(tmp_path, cli):
    src = make_mesh(tmp_path / "a.obj")
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    code, out, err = cli("batch", src, "-o", blocker / "out")
    assert code == 2 and err.count("\n") == 1 and err.startswith("rtmesh: error:")
    assert blocker.read_text() == "not a folder"
    if os.geteuid() != 0:  # root writes anywhere: the permission case needs a normal user
        locked = tmp_path / "locked"
        locked.mkdir(mode=0o500)
        code, out, err = cli("batch", src, "-o", locked)
        assert code == 2 and "not writable" in err


@pytest.mark.usefixtures("in_process_jobs")
def test_an_output_path_that_cannot_be_written_fails_only_that_asset(tmp_path):
    make_mesh(tmp_path / "src" / "sub" / "a.obj")
    make_mesh(tmp_path / "src" / "b.obj")
    out = tmp_path / "out"
    out.mkdir()
    (out / "sub").write_text("a file where a folder of images should go")
    report = rtmesh.batch_convert([tmp_path / "src"], out, workers=1, **TINY)
    (failed,) = report.failed
    assert failed["asset"] == "sub/a.obj" and failed["errors"][0]["stage"] == "write"
    assert read_image(out / "b.obj.png")[0].shape == (16, 24, 3)


def test_time_limit_stops_a_runaway_asset_and_the_batch_goes_on(tmp_path):
    make_mesh(tmp_path / "src" / "a_slow.obj", subdivisions=4)
    make_mesh(tmp_path / "src" / "b_quick.obj")
    (tmp_path / "list.csv").write_text("path,width,height,spp\nsrc/a_slow.obj,512,512,256\nsrc/b_quick.obj,,,\n")
    start = time.perf_counter()
    report = rtmesh.batch_convert([tmp_path / "list.csv"], tmp_path / "out", workers=1,
                                  threads=1, time_limit=1.0, **TINY)
    assert time.perf_counter() - start < 30
    (failed,) = report.failed
    assert failed["asset"] == "src/a_slow.obj" and failed["errors"][0]["stage"] == "time"
    assert report.counts["done"] == 1


def test_memory_guard_fails_an_asset_that_needs_too_much(tmp_path):
    src = make_mesh(tmp_path / "a.obj")
    # a 6000 x 6000 film needs gigabytes; the guard lets the worker start but not render it
    report = rtmesh.batch_convert([src], tmp_path / "out", workers=1, width=6000, height=6000,
                                  spp=1, memory_limit=1536 * 2**20, quiet=True)
    (failed,) = report.failed
    assert failed["errors"][0]["stage"] in ("memory", "crash")
    assert "memory" in failed["errors"][0]["message"]


@pytest.mark.usefixtures("in_process_jobs")
def test_a_render_beyond_the_memory_fails_at_once_as_rtmesh_render_refuses_it(tmp_path):
    src = make_mesh(tmp_path / "a.obj")
    report = rtmesh.batch_convert([src], tmp_path / "out", workers=1, width=32, height=24, spp=10**11,
                                  quiet=True)
    (failed,) = report.failed
    (error,) = failed["errors"]
    assert error["stage"] == "memory"
    assert error["message"].startswith("a 32x24 render at 100000000000 spp on ") and "needs about" in error["message"]


# ------------------------------------------------------------------------- resume

@pytest.mark.usefixtures("in_process_jobs")
def test_rerun_skips_finished_images_and_redoes_changed_or_deleted_ones(tmp_path):
    make_mesh(tmp_path / "src" / "a.obj")
    make_mesh(tmp_path / "src" / "b.obj", kind="box")
    out = tmp_path / "out"
    first = rtmesh.batch_convert([tmp_path / "src"], out, workers=1, **TINY)
    assert first.counts["done"] == 2
    inode = os.stat(out / "a.obj.png").st_ino
    again = rtmesh.batch_convert([tmp_path / "src"], out, workers=1, **TINY)
    assert again.counts["skipped"] == 2 and again.counts["images"] == 0
    assert os.stat(out / "a.obj.png").st_ino == inode  # not rewritten
    os.unlink(out / "b.obj.png")
    again = rtmesh.batch_convert([tmp_path / "src"], out, workers=1, **TINY)
    assert again.counts == counts(assets=2, done=1, skipped=1, images=1)
    # other settings, other images: nothing is skipped
    again = rtmesh.batch_convert([tmp_path / "src"], out, workers=1, **{**TINY, "spp": 2})
    assert again.counts["done"] == 2


def test_ledger_rows_commit_per_asset_and_refuse_old_or_foreign_formats(tmp_path, cli):
    with Ledger(str(tmp_path)) as ledger:
        ledger.record("a", "a.obj", "f1", "done", outputs=[["a.obj.png", 3, 1, "x"]])
        ledger.record("b", "b.obj", "f2", "failed", stage="load", message="bad")
        ledger.commit()
        ledger.record("b", "b.obj", "f2", "failed", stage="load", message="bad again")
    with Ledger(str(tmp_path)) as ledger:
        found = ledger.lookup(["a", "b", "c"])
        assert sorted(found) == ["a", "b"] and found["a"][STATUS] == "done"
        assert ledger.failure("b") == (2, "load", "bad again")  # same fingerprint: counted
        assert ledger.failure("a") is None
        # a look-up of keys spread over more rows than it asks for takes the index
        for i in range(300):
            ledger.record(f"a{i:03d}", "x", "f", "done")
        assert sorted(ledger.lookup(["b", "a", "a150", "zzz"])) == ["a", "a150", "b"]
        assert ledger.count() == 302
        with pytest.raises(rtmesh.OutputError, match="another rtmesh batch"):
            Ledger(str(tmp_path))
    # rtmesh 0.1's JSON-lines ledger is refused in one line, never silently trusted
    old = tmp_path / "old"
    old.mkdir()
    (old / "rtmesh-batch-ledger.jsonl").write_text('{"key": "a", "status": "done"}\n')
    code, out, err = cli("batch", make_mesh(tmp_path / "m.obj"), "-o", old)
    assert code == 2 and err.count("\n") == 1 and "rtmesh 0.1" in err and "delete it" in err
    assert sorted(os.listdir(old)) == ["rtmesh-batch-ledger.jsonl"]


@pytest.mark.usefixtures("in_process_jobs")
def test_an_output_folder_without_locks_runs_the_batch_with_one_warning(tmp_path, monkeypatch, caplog):
    """flock fails on file systems without locks (NFS without its lock service): the batch
    runs and says once that nothing keeps a second batch out."""
    import errno

    from rtmesh.batch import ledger as batch_ledger

    def no_locks(file, operation):
        raise OSError(errno.ENOLCK, os.strerror(errno.ENOLCK))

    monkeypatch.setattr(batch_ledger.fcntl, "flock", no_locks)
    caplog.set_level("WARNING", logger="rtmesh.batch.ledger")
    report = rtmesh.batch_convert([make_mesh(tmp_path / "a.obj")], tmp_path / "out", workers=1, **TINY)
    assert report.counts == counts(assets=1, done=1, images=1)
    (line,) = [r.getMessage() for r in caplog.records]
    assert line == (f"{tmp_path / 'out'}: cannot lock the output folder (No locks available): make sure "
                    "no other batch writes to it at the same time")


@pytest.mark.usefixtures("in_process_jobs")
def test_no_temporary_file_outlives_a_killed_run(tmp_path):
    """The SQLite ledger is never copied (no compaction); what a killed run of any version
    left behind (image, summary, probe and old compaction temporaries) is removed."""
    out = tmp_path / "out"
    out.mkdir()
    stale = [".rtmesh-batch-ledger.k2j3h4.tmp", ".rtmesh-batch-summary.json.x1.tmp",
             ".rtmesh-batch-probe-0123.tmp", ".m.obj.ab12.tmp.png", ".m.obj.turntable.mp4.cd34.tmp"]
    for name in stale:
        (out / name).write_bytes(b"x" * 1000)
    rtmesh.batch_convert([make_mesh(tmp_path / "src" / "m.obj")], out, workers=1, **TINY)
    assert temporary_files(out) == []
    # readable by the group and others, as the umask says (not 0600)
    umask = os.umask(0)
    os.umask(umask)
    for name in (SUMMARY_NAME, REPORT_NAME, LEDGER_NAME):
        assert os.stat(out / name).st_mode & 0o777 == 0o666 & ~umask, name


# ------------------------------------------------------------------------- identity, changes

@pytest.mark.usefixtures("in_process_jobs")
def test_adding_an_input_or_reaching_the_library_through_a_link_renames_nothing(tmp_path):
    make_mesh(tmp_path / "A" / "chairs" / "oak.obj")
    make_mesh(tmp_path / "A" / "m.obj")
    make_mesh(tmp_path / "B" / "m.obj", kind="box")  # same relative path as A's
    out = tmp_path / "out"
    first = rtmesh.batch_convert([tmp_path / "A"], out, workers=1, **TINY)
    assert first.counts["done"] == 2
    inode = os.stat(out / "chairs" / "oak.obj.png").st_ino
    both = rtmesh.batch_convert([tmp_path / "A", tmp_path / "B"], out, workers=1, **TINY)
    assert both.counts == counts(assets=3, done=1, skipped=2, images=1)
    (new,) = [a["asset"] for a in both.assets]
    assert new.startswith("m.obj-")  # B's clashing name gets a suffix, A's names stay
    os.symlink(tmp_path / "A", tmp_path / "link")
    linked = rtmesh.batch_convert([tmp_path / "link"], out, workers=1, **TINY)
    assert linked.counts == counts(assets=2, skipped=2)
    assert os.stat(out / "chairs" / "oak.obj.png").st_ino == inode
    # manifests: one path per line; "#" starts a comment only at a line start or after a space
    make_mesh(tmp_path / "A" / "part#2.obj")
    (tmp_path / "A" / "list.txt").write_text("# parts\npart#2.obj   # the second\nm.obj\n")
    assert [a.name for a in discover([tmp_path / "A" / "list.txt"])] == ["part#2.obj", "m.obj"]


def test_symlinked_subfolders_are_searched_once(tmp_path):
    make_mesh(tmp_path / "elsewhere" / "x.obj")
    make_mesh(tmp_path / "lib" / "a.obj")
    os.symlink(tmp_path / "elsewhere", tmp_path / "lib" / "linked")
    os.symlink(tmp_path / "lib", tmp_path / "lib" / "loop")  # a cycle is not followed
    assert [a.name for a in discover([tmp_path / "lib"])] == ["a.obj", "linked/x.obj"]


def obj_with_material(folder, colour="1 0 0", texture=None):
    folder.mkdir(parents=True, exist_ok=True)
    make_mesh(folder / "m.obj")
    text = (folder / "m.obj").read_text()
    (folder / "m.obj").write_text("mtllib m.mtl\nusemtl paint\n" + text)
    mtl = f"newmtl paint\nKd {colour}\n" + (f"map_Kd {texture}\n" if texture else "")
    (folder / "m.mtl").write_text(mtl)
    return folder / "m.obj"


@pytest.mark.usefixtures("in_process_jobs")
def test_editing_a_dependency_or_damaging_an_image_redoes_it(tmp_path):
    from PIL import Image

    src = tmp_path / "src"
    obj_with_material(src / "paint")
    Image.new("RGB", (4, 4), (0, 255, 0)).save(src / "tex.bmp")  # fixed size
    obj_with_material(src / "textured", texture="../tex.bmp")
    gltf = trimesh.creation.box().export(file_type="gltf")
    (src / "buffers").mkdir()
    for name, data in gltf.items():
        (src / "buffers" / name).write_bytes(data)
    out = tmp_path / "out"
    run = lambda **kw: rtmesh.batch_convert([src], out, workers=1, **{**TINY, **kw})  # noqa: E731
    assert run().counts["done"] == 3
    rows = {r["key"]: decode(r["inputs"]) for r in ledger_records(out)}
    assert [e[0] for e in rows["paint/m.obj"]] == ["", "m.mtl"]
    assert [e[0] for e in rows["textured/m.obj"]] == ["", "m.mtl", "../tex.bmp"]
    assert sorted(e[0] for e in rows["buffers/model.gltf"])[1:] == ["gltf_buffer_0.bin",
                                                                    "gltf_buffer_1.bin"]
    assert run().counts["skipped"] == 3

    # each dependency edited, same size and time kept: content decides
    def edit(path, data):
        st = os.stat(path)
        path.write_bytes(data)
        os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns))

    edit(src / "paint" / "m.mtl", (src / "paint" / "m.mtl").read_bytes().replace(b"1 0 0", b"0 0 1"))
    Image.new("RGB", (4, 4), (255, 0, 255)).save(tmp_path / "t.bmp")
    edit(src / "tex.bmp", (tmp_path / "t.bmp").read_bytes())
    buffer = src / "buffers" / "gltf_buffer_1.bin"  # the box's 8 float32 positions
    edit(buffer, (np.frombuffer(buffer.read_bytes(), np.float32) * 2).tobytes())
    # with --trust-mtime, equal size and time are taken as unchanged...
    assert run(trust_mtime=True).counts["skipped"] == 3
    # ...by default the content is compared
    again = run()
    assert again.counts == counts(assets=3, done=3, images=3)
    assert {a["asset"] for a in again.assets} == {"paint/m.obj", "textured/m.obj", "buffers/model.gltf"}

    # damaged images: truncated, emptied, overwritten by another asset's image (same size)
    png = out / "paint" / "m.obj.png"
    png.write_bytes(png.read_bytes()[:50])
    (out / "textured" / "m.obj.png").write_bytes(b"")
    assert run(trust_mtime=True).counts == counts(assets=3, done=2, skipped=1, images=2)
    shutil.copy(out / "paint" / "m.obj.png", out / "textured" / "m.obj.png")
    data = bytearray(png.read_bytes())
    data[-20] ^= 0xFF  # same size, other content
    png.write_bytes(bytes(data))
    assert run().counts == counts(assets=3, done=2, skipped=1, images=2)
    # the rtmesh version is part of every image's fingerprint
    from rtmesh.batch import identity as batch_identity

    fp = batch_identity.image_fingerprint({"spp": 1}, {"name": "iso"}, ["*.png"], False)
    batch_identity.__version__ = "99"
    try:
        assert batch_identity.image_fingerprint({"spp": 1}, {"name": "iso"}, ["*.png"], False) != fp
    finally:
        batch_identity.__version__ = rtmesh.__version__


class RenameWatch:
    """Every file renamed into some folders, in order (Linux inotify, IN_MOVED_TO), as paths
    relative to the first folder: the batch puts each image and the run file in place by
    renaming a temporary file, so this counts their writes exactly, without touching the
    writers."""

    IN_MOVED_TO = 0x80

    def __init__(self, folder, *more):
        import ctypes
        import ctypes.util

        self.libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        self.fd = self.libc.inotify_init1(os.O_NONBLOCK)
        if self.fd < 0:
            pytest.skip("inotify is not available")
        self.folders = {}
        for path in (folder, *more):
            wd = self.libc.inotify_add_watch(self.fd, os.fsencode(path), self.IN_MOVED_TO)
            if wd < 0:
                pytest.skip("inotify is not available")
            self.folders[wd] = os.path.relpath(path, folder)
        self.names = []

    def poll(self):
        import struct

        while True:
            try:
                data = os.read(self.fd, 65536)
            except BlockingIOError:
                return self.names
            offset = 0
            while offset < len(data):
                wd, mask, _, length = struct.unpack_from("iIII", data, offset)
                name = data[offset + 16: offset + 16 + length].rstrip(b"\0").decode()
                self.names.append(os.path.normpath(os.path.join(self.folders[wd], name)))
                offset += 16 + length

    def close(self):
        os.close(self.fd)


PNG_END = b"\x00\x00\x00\x00IEND\xaeB`\x82"  # the last chunk of every PNG


def finished_unrecorded_image(out):
    """A PNG image some worker has finished writing but the batch has not recorded: whole
    under a temporary name (or in place without a ledger row, were workers to put images in
    place themselves); None if there is none."""
    recorded = {f for r in ledger_records(out) for f in r["files"]}
    for here, _, names in os.walk(out):
        for name in names:
            target = target_of(name) if name.startswith(".") else name
            image = os.path.relpath(os.path.join(here, target), out) if target else ""
            if not image.endswith(".png") or image in recorded:
                continue
            try:
                with open(os.path.join(here, name), "rb") as f:
                    f.seek(-len(PNG_END), os.SEEK_END)
                    if f.read() == PNG_END:
                        return image
            except OSError:
                pass  # too short yet, or put in place meanwhile
    return None


def stop_at_an_unrecorded_image(batch, out, ready, timeout=120):
    """Stop (SIGSTOP) the ``batch`` process at the worst moment for a kill: once
    ``ready(rows)`` holds for the ledger rows it has committed and one of its workers has
    finished an image it has not recorded (the workers go on while it is stopped).
    Returns that image's name."""
    deadline = time.monotonic() + timeout
    while True:
        assert time.monotonic() < deadline and batch.poll() is None, "the batch ended before it could be stopped"
        if not ready(len(ledger_records(out))):
            time.sleep(0.01)
            continue
        batch.send_signal(signal.SIGSTOP)
        if ready(len(ledger_records(out))):  # what it committed before it stopped
            break
        batch.send_signal(signal.SIGCONT)
    while time.monotonic() < deadline:
        image = finished_unrecorded_image(out)
        if image:
            return image
        time.sleep(0.02)
    batch.send_signal(signal.SIGCONT)
    raise AssertionError("no worker finished an image while the batch was stopped")


def check_one_writer_per_image(names, at_kill, out, images, lost):
    """The images put in place (renamed, from a :class:`RenameWatch`) by a batch killed when
    ``at_kill`` names had been seen, and by its resume: each image once; none between the
    kill and the resume's take-over (its run file); before the kill, exactly the images the
    ledger says the killed run put in place, after the take-over those of the resumed run,
    among them ``lost``, which a worker of the killed run had finished.
    """
    from collections import Counter

    takeovers = [i for i, n in enumerate(names) if n == ".rtmesh-batch-run"]
    assert len(takeovers) == 2 and takeovers[0] < at_kill <= takeovers[1]
    placed = [(i, n) for i, n in enumerate(names) if n.endswith(".png")]
    assert Counter(n for _, n in placed) == Counter(images), names  # every image, once
    assert not [n for i, n in placed if at_kill <= i < takeovers[1]], names
    resumed = summary(out)["run"]
    run_of = {f: r["run"] for r in ledger_records(out) for f in r["files"]}
    assert {n for i, n in placed if i < at_kill} == {f for f, run in run_of.items() if run != resumed}
    assert {n for i, n in placed if i > takeovers[1]} == {f for f, run in run_of.items() if run == resumed}
    assert lost in {n for i, n in placed if i > takeovers[1]}


def test_resume_after_sigkill_writes_every_image_exactly_once(tmp_path):
    """kill -9 of a local batch at the worst moment (its worker has finished an image the
    batch has not recorded), then a resume: each image is put in place once, by one run;
    images finished before the kill are kept, not written again."""
    src = tmp_path / "src"
    for i in range(8):
        make_mesh(src / f"group{i % 3}" / f"m{i:02d}.obj", subdivisions=3)
    out = tmp_path / "out"
    folders = [out / f"group{g}" for g in range(3)]
    for folder in folders:
        folder.mkdir(parents=True)
    watch = RenameWatch(out, *folders)
    views = ("iso", "front", "back", "left")
    command = [sys.executable, "-m", "rtmesh.cli", "batch", str(src), "-o", str(out), "--views",
               ",".join(views), "--width", "64", "--height", "64", "--spp", "4", "--workers", "1",
               "--threads", "1", "-q"]
    batch = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    # in the middle of an asset (4 views), so the worker goes on with its next view
    lost = stop_at_an_unrecorded_image(batch, out, lambda rows: rows >= 3 and rows % 4)
    at_kill = len(watch.poll())
    workers = psutil.Process(batch.pid).children()
    batch.send_signal(signal.SIGKILL)
    batch.wait()
    # the workers die with the batch: none goes on writing images nobody records
    gone, alive = psutil.wait_procs(workers, timeout=5)
    assert not alive

    finished = {r["key"]: r for r in ledger_records(out) if r["status"] == "done"}
    assert 3 <= len(finished) < 32 and lost not in {f for r in finished.values() for f in r["files"]}
    # (a file recorded but not yet renamed when the batch stopped is rolled forward later)
    before = {f: os.stat(out / f).st_ino for r in finished.values() for f in r["files"]
              if os.path.exists(out / f)}
    # a killed batch leaves its temporary files behind; none of them is taken for an image
    for name in os.listdir(out / "group0"):
        assert name.startswith(".") or name.endswith(tuple(f".obj.{v}.png" for v in views)), name

    proc = subprocess.run(command, capture_output=True, text=True, timeout=120)
    names = watch.poll()
    watch.close()
    assert proc.returncode == 0, proc.stderr
    report = summary(out)
    assert report["counts"]["images"] == 32 - len(finished)
    records = ledger_records(out)
    assert len(records) == 32 and all(r["status"] == "done" for r in records)
    check_one_writer_per_image(names, at_kill, out, [f for r in records for f in r["files"]], lost)
    for name, inode in before.items():  # finished before the kill: never written again
        assert os.stat(out / name).st_ino == inode
    for r in records:
        image, _ = read_image(out / r["files"][0])
        assert image.shape == (64, 64, 3) and image.max() > 0
    assert temporary_files(out) == []  # leftovers of the killed run are cleaned up


@pytest.mark.usefixtures("in_process_jobs")
def test_a_run_killed_between_recording_and_renaming_is_rolled_forward(tmp_path):
    """A kill after an image's ledger row is committed but before all its files are renamed
    into place leaves their temporaries: the next run puts them in place after checking
    their content against the row, instead of rendering the image again; a temporary with
    other content is removed and its image redone."""
    src = tmp_path / "src"
    make_mesh(src / "a.obj")
    make_mesh(src / "b.obj", kind="box")
    out = tmp_path / "out"
    settings = dict(TINY, workers=1, formats=("png", "exr"))
    rtmesh.batch_convert([src], out, **settings)
    # as such a kill leaves them: a's EXR, and b's PNG (damaged here), at temporary names
    os.rename(out / "a.obj.exr", out / ".a.obj.k2j4_x9q.tmp.exr")
    inode = os.stat(out / ".a.obj.k2j4_x9q.tmp.exr").st_ino
    data = bytearray((out / "b.obj.png").read_bytes())
    data[-20] ^= 0xFF
    (out / ".b.obj.p0q1r2s3.tmp.png").write_bytes(bytes(data))
    os.unlink(out / "b.obj.png")
    again = rtmesh.batch_convert([src], out, **settings)
    assert again.counts == counts(assets=2, done=1, skipped=1, images=1)
    assert [a["asset"] for a in again.assets] == ["b.obj"]
    assert os.stat(out / "a.obj.exr").st_ino == inode  # renamed, not written again
    # the run that put the files in place
    assert {r["key"]: r["run"] for r in ledger_records(out)} == {"a.obj": again.extra["run"],
                                                                  "b.obj": again.extra["run"]}
    assert temporary_files(out) == []


def test_a_superseded_task_removes_what_it_wrote_and_says_so(tmp_path):
    from rtmesh.batch.jobs import AssetJob, ImageTask, fixed_view
    from rtmesh.batch.worker import run_job

    mesh = make_mesh(tmp_path / "a.obj")
    out = tmp_path / "out"
    out.mkdir()
    tasks = tuple(ImageTask(f"a.obj.{v}", fixed_view(v), (f"a.obj.{v}.png",), "") for v in ("iso", "front"))
    job = AssetJob("a.obj", mesh, str(out), {"width": 16, "height": 16, "spp": 1, "threads": 1}, tasks,
                   meta=True, staged=True)
    # a newer run takes the folder (or the cluster drops the task) while it writes its first image
    result = run_job(job, abandoned=lambda: any(n.endswith(".tmp.png") for n in os.listdir(out)))
    assert result["superseded"] and result["images"] == []  # not failed, not done
    assert os.listdir(out) == []  # neither the image nor the asset's metadata file is left
    # not superseded: every file stays at its temporary name, for the submitting process
    iso, front = run_job(job)["images"]
    (meta,) = iso["side_files"]
    assert meta[1] == "a.obj.meta.json" and "side_files" not in front
    assert [target_of(n) for n in iso["staged"] + front["staged"]] == ["a.obj.iso.png", "a.obj.front.png"]
    assert sorted(os.listdir(out)) == sorted(iso["staged"] + front["staged"] + [meta[0]])
    assert iso["outputs"][0][0] == "a.obj.iso.png" and iso["outputs"][0][1] > 0


# ------------------------------------------------------------------------- entry points, Dask

@pytest.mark.usefixtures("in_process_jobs")
def test_tool_script_runs_the_batch_command(tmp_path, monkeypatch, capsys):
    # ``python -m benchmarks.batch_convert ARGS`` from the repository root, in this process
    # (the rtmesh command's own process is tested above: the closed pipe, the kill)
    import runpy

    src = make_mesh(tmp_path / "a.obj")
    monkeypatch.chdir(REPO)
    monkeypatch.setattr(sys, "argv", ["batch_convert.py", src, "-o", str(tmp_path / "out"), "--width", "16",
                                      "--height", "16", "--spp", "1", "--formats", "png,exr", "-q"])
    with pytest.raises(SystemExit) as exit_status:
        runpy.run_module("benchmarks.batch_convert", run_name="__main__")
    stdout, err = capsys.readouterr()
    assert exit_status.value.code == 0, err
    assert "1 done" in stdout
    images = sorted(n for n in os.listdir(tmp_path / "out") if n.startswith("a."))
    assert images == ["a.obj.exr", "a.obj.png"]


def test_missing_dask_gives_an_install_hint(tmp_path, monkeypatch):
    src = make_mesh(tmp_path / "a.obj")
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed -> ImportError
    with pytest.raises(rtmesh.RtmeshError, match=r"pip install rtmesh\[distributed\]"):
        rtmesh.batch_convert([src], tmp_path / "out", scheduler="tcp://127.0.0.1:1", **TINY)


@pytest.fixture(scope="module")
def two_worker_cluster():
    """One local Dask cluster of two worker processes (with nannies, which restart a killed
    worker), shared by the tests that need nothing else of a cluster: each starts once it
    has its two workers again."""
    # its HTTP server on a free port: clusters started meanwhile (here, or by the other
    # pytest-xdist worker) would find the default one taken and warn
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0", silence_logs=50) as cluster:
        yield cluster


# a Dask cluster's failure drill (a cluster and processes, about 3-6 s of CPU): under -m slow,
# where the local resume after a killed batch (test_resume_after_sigkill_...) stays in the default run
@pytest.mark.slow
def test_dask_cluster_with_a_worker_killed_mid_batch(tmp_path, two_worker_cluster):
    src = tmp_path / "src"
    for i in range(14):
        make_mesh(src / f"m{i:02d}.obj", subdivisions=3)
    out = tmp_path / "out"
    cluster = two_worker_cluster
    with distributed.Client(cluster) as client:
        wait_for_workers(client, 2)
        pids = list(client.run(os.getpid).values())
        result = {}

        def batch():
            result["report"] = rtmesh.batch_convert(
                [src], out, scheduler=cluster.scheduler_address, width=64, height=64, spp=4,
                quiet=True)

        runner = threading.Thread(target=batch)
        runner.start()
        ledger = out / LEDGER_NAME
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and runner.is_alive():
            if ledger.exists() and len(ledger_records(out)) >= 2:
                break
            time.sleep(0.01)
        assert runner.is_alive(), "the batch finished before a worker could be killed"
        os.kill(pids[0], signal.SIGKILL)  # the nanny restarts it; its task runs again
        runner.join(timeout=120)
        assert not runner.is_alive()
    report = result["report"]
    assert report.counts == counts(assets=14, done=14, images=14)
    assert report.runner == "dask"
    records = ledger_records(out)
    assert len(records) == 14 == len({r["key"] for r in records})
    for r in records:
        assert read_image(out / r["files"][0])[0].shape == (64, 64, 3)
    # the killed worker may have died mid-write: its temporary file is hidden, and the next
    # run over this folder removes it
    visible = [n for n in os.listdir(out) if not n.startswith(".")]
    assert len([n for n in visible if n.endswith(".png")]) == 14


# ------------------------------------------------------------------------- Dask: storage, runs, loss

def start_process(*command, env=None, cwd=None):
    return subprocess.Popen(list(map(str, command)), stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True, env=env, cwd=cwd)


def dask_worker_command(address, *extra):
    return [sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads", "1",
            "--no-nanny", "--no-dashboard", *extra]


def wait_for_workers(client, n, timeout=60):
    client.wait_for_workers(n, timeout=timeout)
    return list(client.scheduler_info(n_workers=-1)["workers"])


def stop(*procs):
    for proc in procs:
        if proc.poll() is None:
            proc.kill()
        proc.wait()


# a Dask cluster of its own (about 5 s of CPU): under -m slow with the cluster drills
@pytest.mark.slow
def test_dask_worker_with_a_private_output_folder_is_refused(tmp_path, capsys, caplog):
    """A real second worker process in its own mount namespace, where OUTDIR is another
    folder (as on a node that mounts its own disk there): it is refused before any job."""
    if shutil.which("unshare") is None or subprocess.run(
            ["unshare", "-m", "true"], capture_output=True).returncode != 0:
        pytest.skip("needs mount namespaces (unshare -m)")
    src = tmp_path / "src"
    for i in range(4):
        make_mesh(src / f"m{i}.obj")
    out, private = tmp_path / "out", tmp_path / "private"
    out.mkdir()
    private.mkdir()
    with distributed.LocalCluster(n_workers=0, threads_per_worker=1, processes=True,
                                  dashboard_address=":0", silence_logs=50) as cluster, \
            distributed.Client(cluster) as client:
        script = (f"mount --bind {private} {out} && exec "
                  + " ".join(dask_worker_command(cluster.scheduler_address)))
        worker = start_process("unshare", "-m", "--propagation", "private", "sh", "-c", script)
        try:
            (bad,) = wait_for_workers(client, 1)
            # only the private worker: nothing is dispatched, one line, exit 2
            code = main(["batch", str(src), "-o", str(out), "--scheduler",
                         cluster.scheduler_address, "-q"])
            err = capsys.readouterr().err
            assert code == 2 and err.startswith("rtmesh: error: no Dask worker") and err.count("\n") == 1
            assert os.listdir(private) == []
            assert not [n for n in os.listdir(out) if n.endswith(".png")]
            # with a worker that shares the folder, it does every job and the other none
            cluster.scale(1)
            wait_for_workers(client, 2)
            caplog.set_level("WARNING", logger="rtmesh.batch.runner")
            caplog.clear()  # the refusal of the run above
            report = rtmesh.batch_convert([src], out, scheduler=cluster.scheduler_address, **TINY)
            (refused,) = [r.getMessage() for r in caplog.records if "refused" in r.getMessage()]
            assert bad in refused and "shared storage" in refused and "\n" not in refused
            assert report.counts["done"] == 4
            assert os.listdir(private) == []  # the refused worker wrote nothing, not even a probe
            assert sorted(n for n in os.listdir(out) if n.endswith(".png")) == [
                f"m{i}.obj.png" for i in range(4)]
        finally:
            stop(worker)


def test_images_a_job_reports_must_be_visible_here(tmp_path):
    """After each job the submitter checks every reported file: missing, short or other
    content fails the image as not visible (on Dask the content is compared too)."""
    from rtmesh.batch.books import Books
    from rtmesh.batch.identity import describe
    from rtmesh.batch.options import BatchOptions

    (tmp_path / "a.png").write_bytes(b"12345")
    (tmp_path / "b.png").write_bytes(b"12345")
    entry = describe(tmp_path / "a.png", "a.png")
    with Ledger(str(tmp_path)) as ledger:
        books = Books(ledger, str(tmp_path), BatchOptions(scheduler="tcp://x:1", quiet=True), 4)
        cases = {"ok": ["a.png", entry], "gone": ["c.png", ["c.png", 5, 0, entry[3]]],
                 "short": ["a.png", ["a.png", 9, 0, entry[3]]],
                 "other": ["b.png", ["b.png", 5, 0, "0" * 32]]}
        for key, (name, output) in cases.items():
            books.planned(Asset(f"/src/{key}", key), [], [], False, True)
            books.on_image({"asset": key, "key": key, "fingerprint": "f", "status": "done",
                            "files": [name], "seconds": 0.1, "inputs": [], "outputs": [output]})
            books.on_job({"asset": key, "seconds": 0.1})
        books.close()
        rows = ledger.lookup(list(cases))
        failures = {key: ledger.failure(key) for key in cases}
    assert rows["ok"][STATUS] == "done" and failures["ok"] is None
    for key in ("gone", "short", "other"):
        _, stage, message = failures[key]
        assert rows[key][STATUS] == "failed" and stage == "storage"
        assert message.startswith("output not visible to the submitting machine")


def test_an_image_is_recorded_before_its_files_are_put_in_place(tmp_path, monkeypatch):
    """The submitting process commits a done image's row, then renames its staged files into
    place; files it cannot accept are removed, not put in place."""
    from rtmesh.batch import books as batch_books
    from rtmesh.batch.books import Books
    from rtmesh.batch.identity import describe
    from rtmesh.batch.options import BatchOptions

    committed = []

    def publish(outdir, pairs):
        pairs = list(pairs)
        if pairs:
            committed.append({r["key"]: r["status"] for r in ledger_records(outdir)})
        real_publish(outdir, pairs)

    real_publish = batch_books.publish
    monkeypatch.setattr(batch_books, "publish", publish)
    images = {}
    for key in ("a", "b"):
        temporary = f".{key}.obj.k2j4_x9q.tmp.png"
        (tmp_path / temporary).write_bytes(b"12345")
        entry = describe(tmp_path / temporary, f"{key}.obj.png")
        images[key] = {"asset": key, "key": key, "fingerprint": "f", "status": "done", "seconds": 0.1,
                       "files": [f"{key}.obj.png"], "staged": [temporary], "inputs": [], "outputs": [entry]}
    images["b"]["outputs"][0][1] = 9  # the worker says it wrote 9 bytes
    with Ledger(str(tmp_path)) as ledger:
        books = Books(ledger, str(tmp_path), BatchOptions(quiet=True), 2)
        for key, image in images.items():
            books.planned(Asset(f"/src/{key}", key), [], [], False, True)
            books.on_image(image)
            books.on_job({"asset": key, "seconds": 0.1})
        books.close()
        assert ledger.failure("b")[1] == "storage"
    assert committed == [{"a": "done"}]
    assert sorted(os.listdir(tmp_path)) == [".rtmesh-batch.lock", "a.obj.png", LEDGER_NAME, REPORT_NAME]
    assert (tmp_path / "a.obj.png").read_bytes() == b"12345"


def start_scheduler(tmp_path):
    """A Dask scheduler in its own process (so that it can be killed); returns it and its
    address."""
    info = tmp_path / "scheduler.json"
    scheduler = start_process(sys.executable, "-m", "distributed.cli.dask_scheduler", "--port", "0",
                              "--no-dashboard", "--scheduler-file", info)
    deadline = time.monotonic() + 60
    while not info.exists() or not info.read_text().strip():
        assert time.monotonic() < deadline and scheduler.poll() is None, scheduler.stderr.read()
        time.sleep(0.1)
    time.sleep(0.2)
    return scheduler, json.loads(info.read_text())["address"]


def wait_for_rows(out, n, proc, timeout=90):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and proc.poll() is None:
        if (out / LEDGER_NAME).exists() and len(ledger_records(out)) >= n:
            return
        time.sleep(0.05)
    raise AssertionError(f"no {n} ledger rows (batch exit status {proc.poll()})")


# a Dask cluster's failure drill (a cluster and processes, about 3-6 s of CPU): under -m slow,
# where the local resume after a killed batch (test_resume_after_sigkill_...) stays in the default run
@pytest.mark.slow
def test_a_lost_scheduler_ends_the_batch_with_its_own_exit_code_and_no_failures(tmp_path):
    src = tmp_path / "src"
    for i in range(12):
        make_mesh(src / f"m{i:02d}.obj", subdivisions=3)
    out = tmp_path / "out"
    scheduler, address = start_scheduler(tmp_path)
    worker = start_process(*dask_worker_command(address))
    try:
        # the batch refuses a cluster without workers (exit 2): on a busy machine (a first run
        # compiling) the worker process takes a while to join
        with distributed.Client(address, timeout="60s") as client:
            wait_for_workers(client, 1)
        batch = subprocess.Popen(
            [sys.executable, "-m", "rtmesh.cli", "batch", str(src), "-o", str(out), "--scheduler",
             address, "--width", "96", "--height", "96", "--spp", "16", "-q"],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        wait_for_rows(out, 2, batch)
        scheduler.kill()
        stdout, err = batch.communicate(timeout=120)
    finally:
        stop(scheduler, worker)
    rows = ledger_records(out)
    assert rows and all(r["status"] == "done" for r in rows)  # nothing marked failed
    lost = 12 - len(rows)
    assert batch.returncode == 3, err
    assert err.strip().splitlines() == [
        f"rtmesh: cluster lost: {lost} assets not attempted, resume to continue"]
    assert summary(out)["counts"]["not_attempted"] == lost


SIDE = 96  # pixels of the images of the resume after a killed client


# a Dask cluster's failure drill (a cluster and processes, about 3-6 s of CPU): under -m slow,
# where the local resume after a killed batch (test_resume_after_sigkill_...) stays in the default run
@pytest.mark.slow
def test_resume_right_after_killing_the_client_gives_each_image_one_writer(tmp_path, two_worker_cluster):
    """kill -9 of the submitting process at the worst moment (a Dask worker has finished an
    image it has not recorded, others are rendering), and a resume at once: the killed
    run's tasks put nothing in place (only a submitting process does, after recording), so
    each image is put in place once, by one run, and nothing is left behind."""
    src = tmp_path / "src"
    for i in range(6):
        make_mesh(src / f"m{i}.obj", subdivisions=4)
    out = tmp_path / "out"
    out.mkdir()
    watch = RenameWatch(out)
    cluster = two_worker_cluster
    with distributed.Client(cluster) as client:
        wait_for_workers(client, 2)  # after another test's kill, once the nanny has restarted it
        # each image takes a few tenths of a second: long enough to stop the batch between
        # its first and its fifth row, with the other worker still rendering
        command = [sys.executable, "-m", "rtmesh.cli", "batch", str(src), "-o", str(out),
                   "--scheduler", cluster.scheduler_address, "--width", str(SIDE), "--height",
                   str(SIDE), "--spp", "160", "-q"]
        first = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        lost = stop_at_an_unrecorded_image(first, out, lambda rows: 1 <= rows < 5)
        at_kill = len(watch.poll())
        first.kill()  # its tasks go on, on the cluster, until they notice
        first.wait()
        proc = subprocess.run(command, capture_output=True, text=True, timeout=180)
    names = watch.poll()
    watch.close()
    assert proc.returncode == 0, proc.stderr
    rows = ledger_records(out)
    assert len(rows) == 6 and all(r["status"] == "done" for r in rows)
    check_one_writer_per_image(names, at_kill, out, [f"m{i}.obj.png" for i in range(6)], lost)
    for r in rows:
        assert read_image(out / r["files"][0])[0].shape == (SIDE, SIDE, 3)
    assert temporary_files(out) == []


# ------------------------------------------------------------------------- failure policy, exit codes

@pytest.mark.usefixtures("in_process_jobs")
def test_failures_are_retried_once_per_run_or_skipped_as_known(tmp_path, capsys):
    src = tmp_path / "src"
    make_mesh(src / "good.obj")
    shutil.copy(os.path.join(DATA, "empty.obj"), src / "bad.obj")
    out = tmp_path / "out"
    args = ["batch", str(src), "-o", str(out), "--width", "16", "--height", "16", "--spp", "1",
            "--workers", "1", "-q"]
    assert main(args) == 1
    # default: the known failure is tried again (once), and fails again: exit 1
    assert main(args) == 1
    assert summary(out)["counts"] == counts(assets=2, skipped=1, failed=1, retried=1)
    with Ledger(str(out)) as ledger:
        assert ledger.failure("bad.obj")[:2] == (2, "load")
    # --skip-failed: left as a known failure, reported as such, and not an error any more
    capsys.readouterr()
    code = main(args + ["--skip-failed"])
    stdout, err = capsys.readouterr()
    assert code == 0, err
    assert summary(out)["counts"] == counts(assets=2, skipped=1, known_failed=1)
    assert "1 known failures not retried" in stdout
    (line,) = report_lines(out)
    assert line["status"] == "known-failed" and line["errors"][0]["stage"] == "load"
    # a changed input is a new attempt, whatever the policy
    make_mesh(src / "bad.obj")
    assert main(args + ["--skip-failed"]) == 0
    assert summary(out)["counts"] == counts(assets=2, done=1, skipped=1, images=1)


def test_bad_invocations_are_one_line_exit_2_and_create_nothing(tmp_path, capsys):
    src = make_mesh(tmp_path / "a.obj")
    out = tmp_path / "out"
    (tmp_path / "list.csv").write_text("path,passes\na.obj,ao\n")
    for args, words in (([src, "--passes", "ao"], "only to EXR"),
                        ([tmp_path / "list.csv"], "only to EXR"),
                        ([src, "--memory-limit", "200M"], "memory limit"),
                        ([src, "--progress", "jsonl", "--progress-file", tmp_path / "no" / "p"],
                         "cannot write progress")):
        code = main(["batch", *map(str, args), "-o", str(out)])
        err = capsys.readouterr().err
        assert code == 2 and err.count("\n") == 1 and words in err, err
        assert err.startswith("rtmesh: error:") and not out.exists()


# ------------------------------------------------------------------------- smaller defects

def test_a_killed_worker_keeps_the_images_it_finished_and_is_not_called_out_of_memory(tmp_path):
    make_mesh(tmp_path / "src" / "a.obj", subdivisions=3)
    out = tmp_path / "out"
    others = {p.pid for p in psutil.Process().children()}  # say, a shared Dask cluster's
    result = {}
    runner = threading.Thread(target=lambda: result.update(report=rtmesh.batch_convert(
        [tmp_path / "src"], out, workers=1, threads=1, turntable=12, width=96, height=96, spp=16,
        quiet=True)))
    runner.start()
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and len(list(out.glob("a.obj.turn*.png"))) < 2:
        time.sleep(0.01)
    (worker,) = [p for p in psutil.Process().children()
                 if p.pid not in others and "spawn_main" in " ".join(p.cmdline())]
    worker.kill()
    runner.join(timeout=60)
    report = result["report"]
    written = len(list(out.glob("a.obj.turn*.png")))
    assert 2 <= written < 12
    assert report.counts["images"] == written  # the images finished before the kill count
    (failed,) = report.failed
    errors = failed["errors"]
    assert len(errors) == 12 - written and errors[0]["stage"] == "crash"
    assert "SIGKILL" in errors[0]["message"] and "out of memory?" not in errors[0]["message"]


@pytest.mark.usefixtures("in_process_jobs")
def test_nothing_to_do_starts_no_worker(tmp_path, monkeypatch):
    make_mesh(tmp_path / "src" / "a.obj")
    rtmesh.batch_convert([tmp_path / "src"], tmp_path / "out", workers=1, **TINY)
    from rtmesh.batch import pool as batch_pool

    def no_pool(*args, **kwargs):
        raise AssertionError("a worker pool was started")

    monkeypatch.setattr(batch_pool, "run_local", no_pool)
    report = rtmesh.batch_convert([tmp_path / "src"], tmp_path / "out", workers=1, **TINY)
    assert report.counts["skipped"] == 1 and report.runner == "nothing to do"


@pytest.mark.usefixtures("in_process_jobs")
def test_ground_under_a_view_from_below_does_not_hide_the_asset(tmp_path):
    src = make_mesh(tmp_path / "a.obj", kind="box")
    images = {}
    for ground in (False, True):
        out = tmp_path / f"out{ground}"
        rtmesh.batch_convert([src], out, views=("bottom", "front"), ground=ground, width=32,
                             height=32, spp=4, quiet=True)
        images[ground] = {v: read_image(out / f"a.obj.{v}.png")[0] for v in ("bottom", "front")}
    bottom = images[True]["bottom"].astype(float)
    assert bottom.std() > 0.05 * bottom.mean()  # the box, not a blank plane
    np.testing.assert_array_equal(images[True]["bottom"], images[False]["bottom"])
    assert not np.array_equal(images[True]["front"], images[False]["front"])  # ground elsewhere


@pytest.mark.usefixtures("in_process_jobs")
def test_summary_to_a_closed_pipe_and_jsonl_progress(tmp_path):
    make_mesh(tmp_path / "src" / "a.obj")
    make_mesh(tmp_path / "src" / "b.obj", kind="box")
    command = [sys.executable, "-m", "rtmesh.cli", "batch", str(tmp_path / "src"), "-o",
               str(tmp_path / "out"), "--width", "16", "--height", "16", "--spp", "1",
               "--workers", "1", "--progress", "jsonl"]
    proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    proc.stdout.close()  # like "| head" once it has read its lines
    err = proc.stderr.read()
    assert proc.wait(timeout=120) == 0  # no BrokenPipeError
    # stderr holds the progress, one JSON line per finished asset, and nothing else
    lines = [json.loads(line) for line in err.splitlines()]
    assert [(line["asset"], line["status"], line["images"]) for line in lines] == [
        ("a.obj", "done", 1), ("b.obj", "done", 1)]
    assert [line["finished"] for line in lines] == [1, 2] and lines[0]["total"] == 2
    # or appended to a file
    progress = tmp_path / "progress.jsonl"
    os.unlink(tmp_path / "out" / "b.obj.png")
    rtmesh.batch_convert([tmp_path / "src"], tmp_path / "out", workers=1, width=16, height=16,
                         spp=1, progress="jsonl", progress_file=str(progress))
    (line,) = [json.loads(line) for line in progress.read_text().splitlines()]
    assert line["asset"] == "b.obj" and line["finished"] == line["total"] == 2


# ------------------------------------------------------------------------- cost at scale

def bench_batch():
    from benchmarks import bench_batch as module

    return module


class _SqliteWork:
    """Counts what SQLite does on every connection opened while installed: statements run
    and virtual-machine steps (in units of ``every``), a measure of the ledger's work that does
    not depend on the machine or its load."""

    def __init__(self, monkeypatch, every=100):
        self.statements, self.steps = [], 0
        connect = sqlite3.connect

        def counted(*args, **kwargs):
            db = connect(*args, **kwargs)
            db.set_trace_callback(self.statements.append)
            db.set_progress_handler(self._step, every)
            return db

        monkeypatch.setattr(sqlite3, "connect", counted)

    def _step(self):
        self.steps += 1
        return 0

    def reset(self):
        self.statements, self.steps = [], 0


def test_noop_resume_reads_the_ledger_in_work_proportional_to_its_rows(tmp_path, monkeypatch):
    """A no-op resume (open the ledger, fetch and decode the row of every image, close it,
    as ``rtmesh.batch.plan`` does) asks SQLite a few range queries per 5,000 images, and its
    work grows with the ledger's rows, not faster (the times at 1M images are a benchmark:
    ``python -m benchmarks.bench_batch --ledger 1000000``)."""
    bench = bench_batch()
    work = _SqliteWork(monkeypatch)
    steps = {}
    for n in (5_000, 20_000):
        folder = tmp_path / str(n)
        folder.mkdir()
        keys, _ = bench.synthetic_ledger(str(folder), n)
        work.reset()
        bench.noop_resume_ledger_cost(str(folder), keys)
        lookups = [s for s in work.statements if "FROM images" in s]
        # one query a chunk of keys: the keys of a folder walk are the ledger's order
        assert len(lookups) == -(-n // 5000), lookups[:3]
        steps[n] = work.steps
    # a sequential read (a scan or a search per key would grow with n^2 or n log n more)
    assert steps[20_000] <= 4 * steps[5_000] * 1.15, steps


def test_bookkeeping_of_a_finished_asset_does_the_same_work_at_any_batch_size(tmp_path, monkeypatch):
    """The submitting process's bookkeeping of a finished asset (check its staged image,
    its ledger row and commit, the rename into place, its report line) runs the same
    statements for every asset, however many came before (the milliseconds it takes are a
    benchmark: ``benchmarks/bench_batch.py``)."""
    bench = bench_batch()
    work = _SqliteWork(monkeypatch, every=10)
    counts = {}
    for n in (25, 50, 200):
        folder = tmp_path / str(n)
        folder.mkdir()
        work.reset()
        bench.bookkeeping_cost(str(folder), n)
        counts[n] = np.array([len(work.statements), work.steps])
    # the marginal work of an asset: the same after 25 assets as after 50
    early, late = (counts[50] - counts[25]) / 25, (counts[200] - counts[50]) / 150
    assert early[0] == late[0] > 0, counts  # statements (a row and a commit)
    assert late[1] <= 1.15 * early[1], counts  # SQLite's steps


_RELEASE = threading.Event()


_HELD = threading.Event()


def _hold(seconds):
    """A task that runs ``seconds``, or until the test releases it (an in-process worker
    runs it in this process); says when it ends."""
    _RELEASE.wait(seconds)
    _HELD.set()


def test_a_resume_cancels_the_earlier_runs_tasks_of_its_folder_without_waiting():
    from rtmesh.batch.dask_pool import cancel_earlier_runs, task_prefix

    _RELEASE.clear(), _HELD.clear()
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=":0", silence_logs=50) as cluster, \
            distributed.Client(cluster) as client:
        old = task_prefix("/out", "old")
        # a running task that would take 3 s; released once the test is done with it, so
        # that closing the cluster does not wait for it
        running = client.submit(_hold, 3, key=f"{old}0")
        queued = client.submit(time.sleep, 0, key=f"{old}1", resources={"none": 1})
        ours = client.submit(time.sleep, 0, key=f"{task_prefix('/out', 'new')}0", resources={"none": 1})
        other = client.submit(time.sleep, 0, key=f"{task_prefix('/elsewhere', 'old')}0",
                              resources={"none": 1})
        keys = {f.key for f in (running, queued, ours, other)}
        # the submissions reach the scheduler on another connection than run_on_scheduler
        while not (keys <= set(client.run_on_scheduler(lambda dask_scheduler: list(dask_scheduler.tasks)))
                   and any(running.key in k for k in client.processing().values())):
            time.sleep(0.01)
        assert cancel_earlier_runs(client, "/out", "new") == 2
        assert not _HELD.is_set()  # did not wait for the running one to end
        deadline = time.monotonic() + 10
        while running.status != "cancelled" and time.monotonic() < deadline:
            time.sleep(0.01)
        assert running.status == "cancelled" and queued.status == "cancelled"
        # this run's own tasks and another folder's batch are left alone
        assert ours.status == "pending" and other.status == "pending"
        _RELEASE.set()


def test_warm_up_converts_a_tiny_asset_one_worker_per_host_first(monkeypatch):
    from rtmesh.batch import worker
    from rtmesh.batch.dask_pool import warm_up_workers

    # a render under each integrator, so that the kernels of both are compiled or loaded
    # before the first asset (a glTF asset's path kernel was compiled within its first job)
    used = []
    original = worker.integrator_for_view
    monkeypatch.setattr(worker, "integrator_for_view",
                        lambda built, loaded, view, settings, ground: used.append(settings.integrator) or original(
                            built, loaded, view, settings, ground))
    results = worker.warm_up()
    assert used == ["whitted", "path"]
    for result in results:
        (image,) = result["images"]
        assert image["status"] == "done" and image["outputs"][0][1] > 0

    class Client:
        calls = []

        def run(self, function, workers, on_error):
            self.calls.append(workers)

    warm_up_workers(Client(), ["tcp://a:1", "tcp://a:2", "tcp://b:1", "tcp://a:3"])
    assert Client.calls == [["tcp://a:1", "tcp://b:1"], ["tcp://a:2", "tcp://a:3"]]


def test_images_read_by_openimageio_are_recorded_as_inputs(tmp_path):
    """OpenImageIO opens EXR/HDR files natively; read_image announces them, so a changed EXR
    texture or environment changes the asset's fingerprint like a changed PNG does."""
    from rtmesh.batch.identity import OpenedFiles
    from rtmesh.io.images import write_image

    exr = tmp_path / "env.exr"
    write_image(str(exr), np.full((4, 8, 3), 0.5, dtype=np.float32))
    with OpenedFiles() as opened:
        read_image(str(exr))
    assert os.fspath(exr) in opened.paths


def test_package_metadata_and_rtmesh_files_read_during_a_load_are_not_inputs(tmp_path):
    """A lazy entry-point lookup during a load reads packages' metadata (an editable install's
    egg-info lies outside the Python prefix), and rtmesh reads its own data lazily: neither
    is a file of the asset, whose fingerprint would otherwise depend on how rtmesh is
    installed and on which load came first in the process."""
    import rtmesh
    from rtmesh.batch.identity import OpenedFiles

    mesh = tmp_path / "m.obj"
    mesh.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    texture = tmp_path / "tex.png"
    texture.write_bytes(b"png")
    metadata = tmp_path / "site" / "somepackage.egg-info" / "entry_points.txt"
    metadata.parent.mkdir(parents=True)
    metadata.write_text("[x]\n")
    own = os.path.join(os.path.dirname(rtmesh.__file__), "io", "dither_tile.npy")
    with OpenedFiles() as opened:
        for path in (texture, metadata, own):
            with open(path, "rb"):
                pass
    assert [entry[0] for entry in opened.entries(str(mesh))] == ["", "tex.png"]
