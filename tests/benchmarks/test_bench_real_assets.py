"""benchmarks/bench_real_assets.py reads the numbers of the render's own summary line and
passes --integrator on only where the command has it."""

from types import SimpleNamespace

import pytest

from benchmarks import bench_real_assets as bench
from rtmesh.cli import summary_line


@pytest.mark.parametrize("integrator", ["whitted", "path"])
def test_parses_the_summary_line_the_command_prints(integrator):
    settings = SimpleNamespace(width=320, height=240, spp=16, adaptive=False, integrator=integrator)
    stats = SimpleNamespace(relative_error=0.0062, total_rays=1.47e6, rays_per_second=2.49e6,
                            wall_seconds=0.59, threads=2, samples=320 * 240 * 16,
                            rays={"camera": 1.2e6, "bounce": 0.15e6, "shadow": 0.12e6}, photon_passes=0)
    line = summary_line("/tmp/duck.png", settings, stats)
    values = bench.parse_summary(line + "\n")
    assert values == {"spp": 16, "rays": 1.47, "rate": 2.49, "seconds": 0.59, "threads": 2}
    # the path integrator's line adds its rays by kind and its samples per second
    assert ("path: M rays 1.20 camera / 0.15 bounce / 0.12 shadow, 2.08 M samples/s" in line) == (integrator == "path")
    with pytest.raises(ValueError, match="no render summary"):
        bench.parse_summary("rtmesh: error: cannot read Duck.glb\n")


def test_medians_give_samples_per_second_from_the_render_time():
    runs = [{"spp": 16, "rays": 2.0, "rate": 4.0, "seconds": s, "threads": 2, "wall": s + 1}
            for s in (0.5, 0.4, 2.0)]
    m = bench.medians(runs, pixels=1000)
    assert m["samples_per_second"] == pytest.approx(16000 / 0.5)
    assert m["rays_per_second"] == pytest.approx(4e6)
    assert m["rays_per_sample"] == pytest.approx(2e6 / 16000)
    assert m["wall"] == pytest.approx(1.5)


def test_integrator_is_passed_on_only_when_asked_and_supported():
    args = SimpleNamespace(width=32, height=24, spp=4, threads=2)
    plain = bench.render_command(bench.DEFAULT_FOLDER / "Duck.glb", "out.png", args, None)
    assert "--integrator" not in plain and "--background" in plain
    assert plain[plain.index("--background") + 1] == str(bench.STUDIO) and bench.STUDIO.exists()
    assert bench.render_command("Duck.glb", "out.png", args, "path")[-2:] == ["--integrator", "path"]
    assert bench.has_option(bench.ROOT, "--spp")
    assert not bench.has_option(bench.ROOT, "--no-such-option")
