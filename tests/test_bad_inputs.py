"""The corpus of bad inputs (tests/data/bad/, written by tests/hostile_files.py) through the
command line: for each file the exit status, at most one error line and no traceback, no
output file left behind, and the expected error or warning.

Exit statuses (docs/LIMITS.md): 0 rendered (perhaps with warnings), 2 a user error.  No
file of the corpus may end in an internal error (70) or a Python traceback.
"""

import logging
import os

import hostile_files
import numpy as np
import pytest

from rtmesh.cli import main

BAD = hostile_files.BAD

# file -> (exit status, a fragment of the error line (status 2) or of a warning (status 0))
EXPECTED = {
    "nan_vertices.obj": (0, "dropped 8 of 12 faces that use vertices with NaN or infinite coordinates"),
    "huge_cube.obj": (0, None),
    "tiny_cube.obj": (0, None),
    "offset_cube.obj": (0, None),
    "far_outlier.obj": (0, "dropped 12 of 24 faces that lie far from the rest"),
    "wall_with_door.obj": (0, None),
    "index_out_of_range.obj": (2, "a face refers to a vertex the file does not have"),
    "short_faces.obj": (0, "1 faces with fewer than 3 vertices skipped"),
    "garbage.obj": (2, "not a valid OBJ file (binary data, not text)"),
    "garbage.stl": (2, "not a valid STL file (not ASCII, and its binary header announces"),
    "garbage.glb": (2, "not a valid GLB file (no glTF header)"),
    "garbage.ply": (2, "not a valid PLY file (no 'ply' header)"),
    "latin1_garbage.off": (2, "cannot read mesh"),
    "only_comments.obj": (2, "nothing to render (no triangles)"),
    "lying_count.stl": (2, "its binary header announces 1000 triangles (50084 bytes) in a file of 584 bytes"),
    "truncated_ascii.stl": (2, "nothing to render (no triangles)"),
    "lying_header.ply": (2, "nothing to render (no triangles)"),
    "truncated_faces.ply": (0, "the file holds fewer elements than its header announces (1 of 3 face elements)"),
    "index_out_of_range.ply": (0, "dropped 1 of 2 faces that refer to vertices the file does not have"),
    "garbage_mtl.obj": (0, "garbage.mtl: malformed values ignored, defaults used: line 2: kd 'abc 1 zz'"),
    "node_cycle.gltf": (2, "node_cycle.gltf: 2 nodes form a cycle: 'a' -> 'b' -> 'a' (glTF forbids cycles"),
    "zero_scale.gltf": (0, "node 'hidden' has a zero scale"),
    "missing_buffer.gltf": (2, "buffer file gone.bin not found"),
    "bad_pbr_extensions.gltf": (0, "bad_pbr_extensions.gltf: material 'glass': KHR_materials_transmission "
                                   "transmissionFactor = 'lots' is not usable; 0.0 used"),
    "bad_layer_extension.gltf": (2, "bad_layer_extension.gltf: material 'paint': KHR_materials_clearcoat "
                                    "clearcoatFactor 2 is out of range (expected [0.0, 1.0])"),
    "truncated.glb": (2, "truncated.glb: cannot read glTF JSON: Unterminated string"),
    "corrupt_texture.glb": (2, "square baseColorTexture: corrupt or unreadable texture"),
    "bad_types.toml": (2, "bad_types.toml: render.width: expected an integer"),
    "fov_270.toml": (2, "fov_270.toml: camera.fov: expected degrees more than 0 and less than 180"),
    "huge_spp.toml": (2, "render at 100000000000 spp on "),
    "not_utf8.toml": (2, "not_utf8.toml: not a UTF-8 text file"),
    "singular_instances.toml": (2, "singular_instances.toml: objects[0].instances: "),
}
# what the scene files above read besides (a singular transform, named in the error line)
READ_THROUGH = {"singular_instances.npy": "singular_instances.npy: instance 1 has a singular transform"}


def test_the_corpus_is_what_hostile_files_writes_and_small():
    # regenerate with: python tests/hostile_files.py
    corpus = hostile_files.corpus()
    on_disk = sorted(os.listdir(BAD))
    assert on_disk == sorted(corpus)
    for name, content in corpus.items():
        with open(os.path.join(BAD, name), "rb") as f:
            assert f.read() == (content if isinstance(content, bytes) else content.encode()), name
    assert sum(os.path.getsize(os.path.join(BAD, n)) for n in on_disk) < 1_000_000
    # every input file of the corpus has an expectation (the MTL is read through its OBJ, the
    # .npy through its scene file)
    assert sorted(EXPECTED) == sorted(n for n in on_disk if not n.endswith(".mtl") and n not in READ_THROUGH)


def run(path, tmp_path, capsys, caplog, *extra):
    """Run the command line in-process: (status, error lines, warnings, output path)."""
    out = tmp_path / "out.png"
    with caplog.at_level(logging.WARNING):
        status = main(["render", str(path), "-o", str(out), "--width", "24", "--height", "18", "-q", *extra])
    err = capsys.readouterr().err
    warnings = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    return status, err, warnings, out


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_bad_input(name, tmp_path, capsys, caplog):
    status, message = EXPECTED[name]
    code, err, warnings, out = run(os.path.join(BAD, name), tmp_path, capsys, caplog)
    assert code == status, (err, warnings)
    assert "Traceback" not in err and "internal error" not in err
    errors = [line for line in err.splitlines() if line.startswith("rtmesh: error:")]
    if status == 2:
        assert len(errors) == 1 and len(err.strip().splitlines()) == 1, err
        assert message in errors[0], errors[0]
        assert all(why in errors[0] for file, why in READ_THROUGH.items() if name == file.replace(".npy", ".toml"))
        assert not out.exists()
    else:
        assert not errors and out.exists()
        if message is not None:
            assert any(message in w for w in warnings), warnings
        else:
            assert not warnings, warnings
    # no temporary of the atomic write is left either
    assert [p.name for p in tmp_path.iterdir()] == (["out.png"] if status == 0 else [])


def test_a_huge_texture_made_at_test_time_is_one_line(tmp_path, capsys, caplog):
    hostile_files.write_big_png(tmp_path / "big.png")  # 20000 x 20000, a few hundred KB
    (tmp_path / "big.mtl").write_text("newmtl m\nmap_Kd big.png\n")
    obj = tmp_path / "big.obj"
    obj.write_text("mtllib big.mtl\nusemtl m\n" + hostile_files.cube_obj())
    code, err, _, out = run(obj, tmp_path, capsys, caplog)
    assert code == 2 and not out.exists()
    assert err == (f"rtmesh: error: {tmp_path / 'big.png'}: texture of 400000000 pixels is larger than "
                   "rtmesh reads (67108864 pixels, e.g. 8192x8192): downsample it\n")


@pytest.mark.parametrize("value", ['"yes"', "1", "[true]"])
def test_a_bad_dither_in_a_scene_file_is_one_line(tmp_path, capsys, caplog, value):
    path = tmp_path / "dither.toml"
    path.write_text(f"[render]\ndither = {value}\n[[objects]]\nprimitive = \"box\"\n")
    code, err, _, out = run(path, tmp_path, capsys, caplog)
    assert code == 2 and not out.exists()
    assert err == f"rtmesh: error: {path}: render.dither: expected true or false\n"


@pytest.mark.parametrize("args, message", [
    (["--width", "100000", "--height", "100000"], "a 100000x100000 render at 4 spp on "),
    (["--exposure", "nan"], "exposure must be a number of stops from -64 to 64 (got nan)"),
    (["--exposure", "inf"], "exposure must be a number of stops from -64 to 64 (got inf)"),
    (["--ao-distance", "nan"], "ao_distance must be > 0 and finite (got nan)"),
    (["--max-depth", "100000"], "max_depth must be >= 0 and <= 1024"),
])
def test_bad_settings_on_the_command_line(args, message, tmp_path, capsys, caplog):
    code, err, _, out = run(os.path.join(BAD, "offset_cube.obj"), tmp_path, capsys, caplog, *args)
    assert code == 2 and not out.exists()
    assert len(err.splitlines()) == 1 and message in err


@pytest.mark.parametrize("name", ["corrupt_texture.glb", "nan_vertices.obj"])
def test_as_a_separate_process(name, tmp_path):
    # as a user runs it: stderr holds only rtmesh's own lines, no NumPy or Python warning
    import subprocess
    import sys

    out = tmp_path / "out.png"
    proc = subprocess.run([sys.executable, "-m", "rtmesh.cli", "render", os.path.join(BAD, name), "-o",
                           str(out), "--width", "24", "--height", "18", "-q"],
                          capture_output=True, text=True, timeout=300)
    status, message = EXPECTED[name]
    assert proc.returncode == status
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0]
    assert lines[0].startswith("rtmesh: error: " if status else "rtmesh: warning: ")
    assert out.exists() == (status == 0)


# ---------------------------------------------------------------- mutated valid files

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), os.pardir)
# numbers a mutation puts into a scene file: extremes of every kind
EXTREMES = ["0", "-1", "1e308", "-1e308", "5e-324", "1e-30", "1e30", "-1e30", "1e18", "-1e18",
            "1e-18", "1e39", "180", "1e9", "-0.0", "100000000000"]


def _render_or_user_error(path, **settings):
    """Load and render; a user error (RtmeshError) is fine, anything else fails the test,
    and so does a non-finite image (and, by the pytest configuration, any RuntimeWarning)."""
    import numpy as np

    from rtmesh.api import load_scene
    from rtmesh.core.errors import RtmeshError
    from rtmesh.rendering.integrator import Integrator
    from rtmesh.rendering.memory import check

    try:
        scene, loaded = load_scene(path, check_settings=check, **settings)
        image = Integrator(scene, loaded).render().image
    except RtmeshError:
        return
    assert np.isfinite(image).all()


def _scene_file_mutations(count, seed):
    import glob
    import random
    import re

    rng = random.Random(seed)
    scenes = sorted(glob.glob(os.path.join(ROOT, "assets", "**", "*.toml"), recursive=True))
    number = re.compile(r"(?<![\w.])-?\d+(\.\d+)?(e-?\d+)?(?![\w.])")
    for i in range(count):
        path = scenes[i % len(scenes)]
        with open(path) as f:
            text = f.read()
        spots = list(number.finditer(text))
        for m in sorted(rng.sample(spots, rng.randint(1, 3)), key=lambda m: -m.start()):
            text = text[:m.start()] + rng.choice(EXTREMES) + text[m.end():]
        yield pytest.param(os.path.basename(path), text, id=f"{os.path.basename(path)}-{i}")


def _check_scene_file_mutation(name, text, tmp_path):
    for folder in ("meshes", "environments"):
        os.symlink(os.path.join(ROOT, "assets", folder), tmp_path / folder)
    path = tmp_path / name
    path.write_text(text)
    _render_or_user_error(path, width=8, height=6, spp=2, threads=1)


@pytest.mark.parametrize("name, text", list(_scene_file_mutations(24, seed=1)))
def test_scene_files_with_extreme_numbers_render_or_fail_as_user_errors(name, text, tmp_path):
    _check_scene_file_mutation(name, text, tmp_path)


@pytest.mark.slow
@pytest.mark.parametrize("name, text", list(_scene_file_mutations(400, seed=2)))
def test_many_scene_files_with_extreme_numbers(name, text, tmp_path):
    _check_scene_file_mutation(name, text, tmp_path)


MESHES = ["Duck.glb", "BoxTextured.glb", "fuze.obj", "quadknot.obj", "textured_tetrahedron.obj", "rabbit.obj"]
COMPANIONS = ["fuze uv.jpg", "fuze.obj.mtl", "rabbit.mtl"]


def _mesh_mutations(count, seed):
    import random

    rng = random.Random(seed)
    data_dir = os.path.join(ROOT, "tests", "data")
    for i in range(count):
        name = MESHES[i % len(MESHES)]
        with open(os.path.join(data_dir, name), "rb") as f:
            data = bytearray(f.read())
        kind = ("truncate", "bytes", "digits")[i // len(MESHES) % 3]
        if kind == "truncate":
            data = data[:rng.randrange(len(data))]
        elif kind == "bytes":
            for _ in range(rng.randint(1, 20)):
                data[rng.randrange(len(data))] = rng.randrange(256)
        else:  # digits changed into other digits, signs, exponents, 'n' (nan, inf)
            codes = np.frombuffer(bytes(data), dtype=np.uint8)
            digits = np.flatnonzero((codes >= 48) & (codes <= 57)).tolist()  # collection time: not a Python loop
            for k in rng.sample(digits, min(len(digits), rng.randint(1, 20))):
                data[k] = ord(rng.choice("0123456789-e.n"))
        yield pytest.param(name, bytes(data), id=f"{name}-{kind}-{i}")


def _check_mesh_mutation(name, data, tmp_path):
    import shutil

    for companion in COMPANIONS:
        shutil.copy(os.path.join(ROOT, "tests", "data", companion), tmp_path / companion)
    path = tmp_path / name
    path.write_bytes(data)
    _render_or_user_error(path, width=8, height=6, spp=1, threads=1)


@pytest.mark.parametrize("name, data", list(_mesh_mutations(24, seed=1)))
def test_mutated_mesh_files_render_or_fail_as_user_errors(name, data, tmp_path):
    _check_mesh_mutation(name, data, tmp_path)


@pytest.mark.slow
@pytest.mark.parametrize("name, data", list(_mesh_mutations(400, seed=2)))
def test_many_mutated_mesh_files(name, data, tmp_path):
    _check_mesh_mutation(name, data, tmp_path)
