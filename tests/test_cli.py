"""End-to-end command line: renders that read back, and one-line errors for bad input."""

import io
import logging
import os
import subprocess
import sys

import numpy as np
import pytest

from rtmesh.cli import main
from rtmesh.io.images import read_image

HERE = os.path.dirname(__file__)
DATA = os.path.join(HERE, "data")
ASSETS = os.path.join(HERE, "..", "assets")

SMALL_SCENE = """
[render]
width = 48
height = 32
spp = 2

[camera]
position = [0.0, -4.0, 2.0]
look_at = [0.0, 0.0, 0.5]
up = [0.0, 0.0, 1.0]

[materials.red]
diffuse = [0.8, 0.1, 0.1]

[[objects]]
primitive = "icosphere"
subdivisions = 2
translate = [0.0, 0.0, 1.0]
material = "red"

[[objects]]
primitive = "plane"
size = [10.0, 10.0]

[[lights]]
type = "point"
position = [2.0, -2.0, 5.0]
intensity = 30.0
"""


@pytest.fixture
def scene_file(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text(SMALL_SCENE)
    return path


def run_cli(*args):
    """Run ``python -m rtmesh.cli`` as a user would, in a process of its own; returns (exit
    code, stdout, stderr).  Most tests use the ``cli`` fixture (tests/conftest.py), the same
    command in this process; this one is for the real entry point."""
    proc = subprocess.run([sys.executable, "-m", "rtmesh.cli", *map(str, args)],
                          capture_output=True, text=True, timeout=120)
    return proc.returncode, proc.stdout, proc.stderr


def test_render_writes_exr_and_png_that_read_back(scene_file, tmp_path):
    exr, png = tmp_path / "out.exr", tmp_path / "out.png"
    assert main(["render", str(scene_file), "-o", str(exr), "--passes", "ao", "-q"]) == 0
    assert main(["render", str(scene_file), "-o", str(png), "-q"]) == 0
    linear, names = read_image(exr)
    assert names == ["R", "G", "B", "ao.Y"]
    assert linear.shape == (32, 48, 4)
    assert np.isfinite(linear).all()
    # the red sphere is in the middle of the frame: red dominates there
    centre = linear[14:18, 22:26, :3].mean(axis=(0, 1))
    assert centre[0] > 2 * centre[1] and centre[0] > 2 * centre[2]
    assert ((linear[..., 3] >= 0) & (linear[..., 3] <= 1)).all()
    display, _ = read_image(png)
    assert display.shape == (32, 48, 3)
    # the PNG is the EXR tone mapped (reinhard) and sRGB encoded, to 8-bit precision
    x = np.clip(linear[..., :3] / (1 + linear[..., :3]), 0, 1)
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
    assert np.abs(display - srgb).max() <= 0.5 / 255 + 1e-6


def test_summary_line_reports_resolution_rays_and_time(scene_file, tmp_path, capsys):
    assert main(["render", str(scene_file), "-o", str(tmp_path / "a.png"), "-q"]) == 0
    line = capsys.readouterr().out.strip()
    assert "48x32" in line and "2 spp" in line and "rays/s" in line and " s, " in line


def test_bare_mesh_file_renders(tmp_path):
    out = tmp_path / "bunny.png"
    mesh = os.path.join(ASSETS, "meshes", "bunny.ply")
    assert main(["render", mesh, "-o", str(out), "--width", "40", "--height", "30", "--spp", "1", "-q"]) == 0
    image, _ = read_image(out)
    # the automatic camera frames the mesh: something lit in the centre, background at a corner
    assert image[12:18, 17:23].mean() > 0.05
    assert image[0, 0].max() == 0.0


@pytest.mark.parametrize(
    "args, message",
    [
        (["render", "{data}/empty.obj", "-o", "{tmp}/x.png"], "nothing to render"),
        (["render", "{tmp}/missing.ply", "-o", "{tmp}/x.png"], "no such mesh file"),
        (["render", "{scene}", "-o", "{tmp}/no/such/folder/x.png"], "does not exist"),
        (["render", "{scene}", "-o", "{tmp}/x.bmp"], "unsupported output format"),
        (["render", "{tmp}/notes.txt", "-o", "{tmp}/x.png"], "unsupported mesh format"),
    ],
)
def test_bad_input_is_one_line_exit_2_no_traceback_no_file(args, message, scene_file, tmp_path, cli):
    (tmp_path / "notes.txt").write_text("hello")
    fill = {"data": DATA, "tmp": tmp_path, "scene": scene_file}
    args = [a.format(**fill) for a in args]
    code, out, err = cli(*args)
    assert code == 2
    assert message in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not (tmp_path / "x.png").exists() and not (tmp_path / "x.bmp").exists()
    assert not [p for p in os.listdir(tmp_path) if ".tmp" in p]


def test_scene_file_error_names_file_and_key(tmp_path, cli):
    path = tmp_path / "bad.toml"
    path.write_text(SMALL_SCENE.replace('material = "red"', 'material = "red"\nsmoth = true'))
    code, _, err = cli("render", path, "-o", tmp_path / "x.png")
    assert code == 2
    assert f"{path}: objects[0].smoth: unknown key" in err
    assert "Traceback" not in err


def test_dither_moves_png_values_by_at_most_one_step(scene_file, tmp_path):
    rounded, dithered = tmp_path / "rounded.png", tmp_path / "dithered.png"
    assert main(["render", str(scene_file), "-o", str(rounded), "-q"]) == 0
    assert main(["render", str(scene_file), "-o", str(dithered), "--dither", "-q"]) == 0
    a, b = (np.round(read_image(path)[0] * 255.0) for path in (rounded, dithered))
    assert np.abs(a - b).max() == 1.0


def test_a_scene_files_dither_reaches_the_png_and_no_dither_overrides_it(scene_file, tmp_path):
    dithering = tmp_path / "dithering.toml"
    dithering.write_text(SMALL_SCENE.replace("spp = 2\n", "spp = 2\ndither = true\n"))
    paths = {name: tmp_path / f"{name}.png" for name in ("rounded", "flag", "key", "overridden")}
    for name, scene, extra in (("rounded", scene_file, []), ("flag", scene_file, ["--dither"]),
                               ("key", dithering, []), ("overridden", dithering, ["--no-dither"])):
        assert main(["render", str(scene), "-o", str(paths[name]), "-q", *extra]) == 0
    steps = {name: np.round(read_image(path)[0] * 255.0) for name, path in paths.items()}
    assert np.array_equal(steps["key"], steps["flag"])
    assert np.array_equal(steps["overridden"], steps["rounded"])
    # dithered: other values, at most a step away, the same mean (measured: 16 % of the values
    # changed, means 0.009 step apart)
    difference = steps["key"] - steps["rounded"]
    assert (difference != 0).mean() > 0.1 and np.abs(difference).max() == 1.0
    assert abs(difference.mean()) < 0.1


def test_failed_write_keeps_existing_image_and_leaves_no_temporary(scene_file, tmp_path, monkeypatch):
    out = tmp_path / "keep.png"
    out.write_bytes(b"previous image")
    import rtmesh.io.images as image_io

    class Failing:
        @staticmethod
        def create(path):
            raise KeyboardInterrupt  # the user stops the program in the middle of the write

    monkeypatch.setattr(image_io.oiio, "ImageOutput", Failing)
    assert main(["render", str(scene_file), "-o", str(out), "-q"]) == 130
    assert out.read_bytes() == b"previous image"
    assert sorted(os.listdir(tmp_path)) == ["keep.png", "scene.toml"]


def test_bundled_showcase_scene_renders(tmp_path):
    # the README's first command renders assets/showcase.toml: keep that file valid
    showcase = os.path.join(os.path.dirname(__file__), os.pardir, "assets", "showcase.toml")
    out = tmp_path / "showcase.png"
    assert main(["render", showcase, "-o", str(out), "--width", "64", "--height", "48", "--spp", "1",
                 "-q"]) == 0
    image, _ = read_image(out)
    assert image.shape == (48, 64, 3)
    # lit objects in front of a sky-blue background: not a blank frame
    assert image.std() > 0.05


def test_the_program_flushes_its_line_and_a_closed_pipe_is_no_error(scene_file, tmp_path):
    # the program ends without the interpreter's teardown (cli.command): what it printed
    # still reaches the reader
    out = tmp_path / "a.png"
    code, stdout, err = run_cli("render", scene_file, "-o", out)
    assert code == 0 and err == ""
    assert stdout.startswith(f"{out}: 48x32, 2 spp") and stdout.endswith("\n")
    # and a reader that has gone away (| head) does not make the finished render an error
    out.unlink()
    proc = subprocess.Popen([sys.executable, "-m", "rtmesh.cli", "render", str(scene_file), "-o", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    proc.stdout.close()
    err = proc.stderr.read()
    assert proc.wait(timeout=120) == 0 and err == ""
    assert read_image(out)[0].shape == (32, 48, 3)


def test_argparse_error_is_one_line_exit_2(tmp_path):
    code, out, err = run_cli("render", tmp_path / "scene.toml", "--width", "0")
    assert code == 2
    assert err.startswith("rtmesh: error: ") and "--help" in err
    assert len(err.strip().splitlines()) == 1 and "usage:" not in err


def _failing_render(monkeypatch, exc):
    import rtmesh.cli as cli

    def render(self, progress=None):
        raise exc

    monkeypatch.setattr(cli.Integrator, "render", render)


def test_internal_error_is_one_line_exit_70_without_traceback(scene_file, tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("RTMESH_DEBUG", raising=False)
    _failing_render(monkeypatch, ValueError("a bug\nwith a second line"))
    out = tmp_path / "x.png"
    assert main(["render", str(scene_file), "-o", str(out), "-q"]) == 70
    err = capsys.readouterr().err
    assert err == ("rtmesh: internal error: ValueError: a bug (run with --debug or RTMESH_DEBUG=1 "
                   "for the traceback)\n")
    assert not out.exists()


@pytest.mark.parametrize("how", ["flag before", "flag after", "environment"])
def test_debug_shows_the_traceback_of_an_internal_error(how, scene_file, tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("RTMESH_DEBUG", raising=False)
    _failing_render(monkeypatch, ValueError("a bug"))
    args = ["render", str(scene_file), "-o", str(tmp_path / "x.png"), "-q"]
    if how == "flag before":
        args = ["--debug"] + args
    elif how == "flag after":
        args = args + ["--debug"]
    else:
        monkeypatch.setenv("RTMESH_DEBUG", "1")
    assert main(args) == 70
    err = capsys.readouterr().err
    assert "Traceback (most recent call last)" in err and "ValueError: a bug" in err


def test_running_out_of_memory_is_a_user_error(scene_file, tmp_path, monkeypatch, capsys):
    _failing_render(monkeypatch, MemoryError())
    assert main(["render", str(scene_file), "-o", str(tmp_path / "x.png"), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("rtmesh: error: out of memory") and len(err.splitlines()) == 1


@pytest.mark.parametrize("args", [["--width", "100000", "--height", "100000"],
                                  ["--width", "64", "--height", "48", "--memory-limit", "1M"]])
def test_a_render_too_large_for_memory_is_refused_in_one_line(args, tmp_path, cli):
    mesh = os.path.join(ASSETS, "meshes", "bunny.ply")
    out = tmp_path / "x.png"
    code, _, err = cli("render", mesh, "-o", out, *args)
    assert code == 2 and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1
    size = "x".join(args[1::2][:2])
    assert err.startswith(f"rtmesh: error: a {size} render at 4 spp on ")
    assert "needs about" in err and ("is available" in err or "--memory-limit is 1 MiB" in err)
    assert "set --memory-limit (0 = no check)" in err
    assert not out.exists()


def test_scene_file_spp_too_large_for_memory_or_the_samplers_is_refused(scene_file, tmp_path, capsys):
    out = tmp_path / "x.png"
    for spp in (2147483648, 100000000000):
        scene_file.write_text(SMALL_SCENE.replace("spp = 2", f"spp = {spp}"))
        assert main(["render", str(scene_file), "-o", str(out), "-q"]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"rtmesh: error: a 48x32 render at {spp} spp on ")
        assert "chunks" in err and len(err.splitlines()) == 1
    # beyond the Sobol sampler's sample index: refused by the settings, naming the value
    scene_file.write_text(SMALL_SCENE.replace("spp = 2", 'spp = 100000000000\nsampler = "sobol"'))
    assert main(["render", str(scene_file), "-o", str(out), "-q"]) == 2
    err = capsys.readouterr().err
    assert err == (f"rtmesh: error: {scene_file}: render: spp and max_spp must be <= 4294967296 with the "
                   "sobol sampler (its sample index is 32-bit; got 100000000000)\n")
    assert not out.exists()


def test_memory_limit_zero_turns_the_check_off(scene_file, tmp_path):
    out = tmp_path / "x.png"
    assert main(["render", str(scene_file), "-o", str(out), "--memory-limit", "0", "-q"]) == 0
    assert out.exists()


@pytest.mark.parametrize("command", ["render", "batch"])
@pytest.mark.parametrize("size", ["inf", "1e400", "infK", "nan", "-1", "0.5", "0.9", "1e30G"])
def test_a_memory_limit_that_is_no_size_is_refused_in_one_line(command, size, scene_file, tmp_path, cli):
    """Not finite, negative, or below one byte (which would round to 0, no check)."""
    out = tmp_path / ("x.png" if command == "render" else "out")
    code, _, err = cli(command, scene_file, "-o", out, "--memory-limit", size, "-q")
    assert code == 2 and "Traceback" not in err
    assert err == (f"rtmesh: error: argument --memory-limit: expected 0 or a size from 1 byte to 8 EiB, got "
                   f"{size!r} (see rtmesh {command} --help)\n")
    assert not out.exists()


@pytest.mark.parametrize("extra, message", [
    (["--camera-json", "{tmp}"], "{tmp}: is a folder, not a name for the camera file"),
    (["--annotations", "{tmp}"], "{tmp}: is a folder, not a name for the annotations file"),
    (["--camera-json", "{scene}"], "{scene}: the camera file would replace the input"),
    (["--annotations", "{scene}"], "{scene}: the annotations file would replace the input"),
    (["--camera-json", "{tmp}/x.png"], "{tmp}/x.png: the camera file would replace the image"),
    (["--camera-json", "{tmp}/a.json", "--annotations", "{tmp}/a.json"],
     "{tmp}/a.json: the annotations file would replace the camera file"),
    (["--passes", "depth", "--pass-png", "--camera-json", "{tmp}/x_depth.png"],
     "{tmp}/x_depth.png: the depth pass PNG would replace the camera file"),
])
def test_side_outputs_that_would_replace_a_file_or_are_folders_are_refused_before_rendering(
        extra, message, scene_file, tmp_path, cli):
    before = scene_file.read_bytes()
    fill = {"tmp": tmp_path, "scene": scene_file}
    code, _, err = cli("render", scene_file, "-o", tmp_path / "x.png", *[a.format(**fill) for a in extra], "-q")
    assert code == 2 and err == f"rtmesh: error: {message.format(**fill)}\n"
    assert not (tmp_path / "x.png").exists() and not (tmp_path / "a.json").exists()
    assert scene_file.read_bytes() == before


def test_the_memory_check_comes_before_any_mesh_is_read(tmp_path, monkeypatch, capsys):
    import rtmesh.api
    import rtmesh.loaders.scene_objects

    def no_mesh(*args, **kwargs):
        raise AssertionError("a mesh was read before the memory check")

    monkeypatch.setattr(rtmesh.api, "load_mesh_scene", no_mesh)
    monkeypatch.setattr(rtmesh.loaders.scene_objects, "mesh_file_parts", no_mesh)
    mesh = os.path.join(ASSETS, "meshes", "bunny.ply")
    scene = tmp_path / "s.toml"
    scene.write_text(f'[render]\nwidth = 100000\nheight = 100000\n[[objects]]\nmesh = "{mesh}"\n')
    for source, args in ((mesh, ["--width", "100000", "--height", "100000"]), (scene, [])):
        assert main(["render", str(source), "-o", str(tmp_path / "x.png"), "-q", *args]) == 2
        assert "a 100000x100000 render at 4 spp" in capsys.readouterr().err


@pytest.mark.parametrize("integrator", ["whitted", "path"])
def test_without_embree_packets_a_render_is_refused_in_one_line(scene_file, tmp_path, integrator):
    # rtmesh renders through its compiled kernels over Embree's packet queries; embreex's
    # one-ray-at-a-time run() (RTMESH_EMBREE=run) is no render path of its own
    out = tmp_path / "out.png"
    env = dict(os.environ, RTMESH_EMBREE="run")
    proc = subprocess.run([sys.executable, "-m", "rtmesh.cli", "render", str(scene_file), "-o", str(out),
                           "--integrator", integrator, "--spp", "1"], capture_output=True, text=True, timeout=120,
                          env=env)
    assert proc.returncode == 2 and not out.exists()
    assert proc.stderr.strip().splitlines() == ["rtmesh: error: rtmesh cannot render without Embree's packet queries "
                                                "(RTMESH_EMBREE=run)"]


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def test_a_terminal_is_told_once_that_a_first_render_compiles_and_warnings_still_pass(caplog):
    from rtmesh.cli import first_run_note
    from rtmesh.core import compile_ahead
    from rtmesh.core.compile_ahead import FIRST_RUN_NOTE

    logger = compile_ahead.log
    before = (logger.level, logger.propagate, list(logger.handlers))
    terminal = _Terminal()
    with first_run_note(terminal):
        # what KernelGroup.prepare logs for each group the disk cache lacks
        logger.info("compiling the %s kernels for this machine", "build")
        logger.info("compiling the %s kernels for this machine", "path")
        logger.warning("a warning of the module")
    assert terminal.getvalue() == FIRST_RUN_NOTE + "\n"
    assert [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING] == ["a warning of the module"]
    assert (logger.level, logger.propagate, list(logger.handlers)) == before
    # -q, or stderr not a terminal (cmd_render's condition): nothing
    quiet = _Terminal()
    with first_run_note(quiet, enabled=False):
        logger.info("compiling the %s kernels for this machine", "build")
    assert quiet.getvalue() == ""



def test_compile_prepares_every_kernel_group_the_cache_lacks_and_says_so(monkeypatch, cli):
    from rtmesh.core import compile_ahead

    prepared = []
    monkeypatch.setattr(compile_ahead.KernelGroup, "cached", lambda self: self.name == "build")
    monkeypatch.setattr(compile_ahead.KernelGroup, "compile_ahead", lambda self: None)
    monkeypatch.setattr(compile_ahead.KernelGroup, "prepare", lambda self: prepared.append(self.name))
    code, out, err = cli("compile")
    names = [group.name for group in compile_ahead.groups()]
    # the package's five groups (and the tests' wavefront's, declared in this process)
    assert {"build", "fused direct", "path", "photons", "packet queries"} <= set(names)
    assert code == 0 and err == ""
    assert prepared == [name for name in names if name != "build"]
    assert out == f"rtmesh: {len(names) - 1} of {len(names)} kernel groups compiled for this machine in 0 s\n"
    monkeypatch.setattr(compile_ahead.KernelGroup, "cached", lambda self: True)
    prepared.clear()
    assert cli("compile")[1] == f"rtmesh: all {len(names)} kernel groups are compiled for this machine already\n"
    assert prepared == []


@pytest.mark.parametrize("args, message", [
    (["--time-limit", "inf"], "argument --time-limit: expected a finite number > 0, got inf (see rtmesh batch --help)"),
    (["--time-limit", "1e300"], "time limit: must be > 0 and at most 1e+07 seconds, got 1e+300"),
    (["--turntable", "100000000"], "turntable: must be from 0 to 100000 frames, got 100000000"),
])
def test_batch_options_without_bounds_are_refused_before_anything_runs(args, message, scene_file, tmp_path, cli):
    """An infinite time limit overflowed the clocks (an internal error, a temporary image
    left); a turntable of 1e8 frames ran out of memory building its views."""
    code, _, err = cli("batch", scene_file, "-o", tmp_path / "out", *args, "-q")
    assert code == 2 and err == f"rtmesh: error: {message}\n"
    assert not (tmp_path / "out").exists()
