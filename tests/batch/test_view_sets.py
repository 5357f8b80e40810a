"""View sets of multi-view renders: Fibonacci, random (seeded, uniform) and rings."""

import json

import numpy as np
import pytest
import trimesh
from scipy import stats

import rtmesh
from rtmesh.batch import jobs, view_scenes
from rtmesh.batch.view_sets import fibonacci_directions, view_set
from rtmesh.cli import main
from rtmesh.rendering.settings import RenderSettings


def _directions(views):
    return np.array([v.direction for v in views])


@pytest.mark.parametrize("count", [20, 100, 500])
def test_fibonacci_views_are_evenly_spread(count):
    """Every view's nearest-neighbour angle is within 10 % of the mean one."""
    d = _directions(view_set(f"fibonacci:{count}"))
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-12)
    cosine = d @ d.T
    np.fill_diagonal(cosine, -2.0)
    nearest = np.degrees(np.arccos(np.clip(cosine.max(axis=1), -1.0, 1.0)))
    assert np.abs(nearest / nearest.mean() - 1.0).max() < 0.10
    # random directions are not (the test tells them apart)
    r = _directions(view_set(f"random:{count}", seed=3))
    cosine = r @ r.T
    np.fill_diagonal(cosine, -2.0)
    spread = np.degrees(np.arccos(np.clip(cosine.max(axis=1), -1.0, 1.0)))
    assert np.abs(spread / spread.mean() - 1.0).max() > 0.3


def test_random_views_are_uniform_on_the_sphere_and_in_a_band():
    """Uniform on the sphere: height y and azimuth each uniform (Archimedes), independent;
    Kolmogorov-Smirnov at the 0.1 % level; the seed fixes the set."""
    views = view_set("random:3000", seed=11)
    d = _directions(views)
    azimuth = np.arctan2(d[:, 0], d[:, 2])
    assert stats.kstest(d[:, 1], "uniform", args=(-1.0, 2.0)).pvalue > 1e-3
    assert stats.kstest(azimuth, "uniform", args=(-np.pi, 2.0 * np.pi)).pvalue > 1e-3
    # no preferred direction: the mean vector is ~ N(0, 1/(3n)) per axis
    assert np.abs(d.mean(axis=0)).max() < 4.0 / np.sqrt(3 * len(d))
    # a clumped set fails the same test
    assert stats.kstest(np.abs(d[:, 1]), "uniform", args=(-1.0, 2.0)).pvalue < 1e-3
    assert _directions(view_set("random:3000", seed=11)).tolist() == d.tolist()
    assert _directions(view_set("random:3000", seed=12)).tolist() != d.tolist()
    band = _directions(view_set("random:2000", seed=5, elevation=(10.0, 40.0)))
    elevation = np.degrees(np.arcsin(band[:, 1]))
    assert elevation.min() >= 10.0 and elevation.max() <= 40.0
    low, high = np.sin(np.radians(10.0)), np.sin(np.radians(40.0))
    assert stats.kstest(band[:, 1], "uniform", args=(low, high - low)).pvalue > 1e-3


def test_rings_hit_their_elevations_exactly():
    views = view_set("rings:-30,0,15.5,90x6")
    assert len(views) == 24 and views[7].name == "ring1_001"
    bounds = np.array([[-1.0, 0.0, 2.0], [3.0, 1.0, 2.5]])
    settings = RenderSettings(width=30, height=20).validate()
    for ring, elevation in enumerate((-30.0, 0.0, 15.5, 90.0)):
        ring_views = views[6 * ring:6 * ring + 6]
        d = _directions(ring_views)
        np.testing.assert_allclose(np.degrees(np.arcsin(d[:, 1])), elevation, atol=1e-12)
        if elevation < 90.0:
            azimuth = np.degrees(np.arctan2(d[:, 0], d[:, 2])) % 360.0
            np.testing.assert_allclose(azimuth, np.arange(6) * 60.0, atol=1e-9)
        for view in ring_views:  # the auto-framed camera too
            camera, _ = view_scenes._camera_and_lights(bounds, view, settings)
            offset = camera.position - camera.look_at
            assert np.degrees(np.arcsin(offset[1] / np.linalg.norm(offset))) == pytest.approx(elevation, abs=1e-9)


def test_radius_jitter_moves_cameras_out_only_and_is_seeded():
    bounds = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    settings = RenderSettings(width=16, height=16).validate()
    plain = view_set("fibonacci:50")
    jittered = view_set("fibonacci:50", seed=2, radius_jitter=0.5)
    assert _directions(plain).tolist() == _directions(jittered).tolist()
    scales = np.array([v.distance_scale for v in jittered])
    assert scales.min() >= 1.0 and scales.max() <= 1.5 and scales.std() > 0.1
    for a, b in zip(plain[:5], jittered[:5]):
        ca, _ = view_scenes._camera_and_lights(bounds, a, settings)
        cb, _ = view_scenes._camera_and_lights(bounds, b, settings)
        np.testing.assert_allclose(np.linalg.norm(cb.position - cb.look_at),
                                   b.distance_scale * np.linalg.norm(ca.position - ca.look_at))


def test_fibonacci_directions_cover_both_poles():
    d = fibonacci_directions(7)
    assert d[0, 1] > 0.8 and d[-1, 1] < -0.8


@pytest.mark.usefixtures("in_process_jobs")
def test_a_batch_renders_a_view_set_with_its_cameras(tmp_path):
    trimesh.creation.box().export(tmp_path / "a.obj")
    report = rtmesh.batch_convert([tmp_path / "a.obj"], tmp_path / "out", workers=1, width=8, height=8,
                                  spp=1, views=("rings:0,45x3",), camera_json=True, progress="none")
    assert report.counts["images"] == 6
    names = sorted(p.name for p in (tmp_path / "out").glob("a.obj.ring*.png"))
    assert names == [f"a.obj.ring{r}_{k:03d}.png" for r in range(2) for k in range(3)]
    record = json.loads((tmp_path / "out" / "a.obj.ring1_002.camera.json").read_text())
    c2w = np.array(record["camera_to_world_opencv"])
    forward = c2w[:3, 2]
    assert np.degrees(np.arcsin(-forward[1])) == pytest.approx(45.0, abs=1e-9)


@pytest.mark.parametrize("args, message", [
    (["--views", "fibonacci:0"], "--views"),
    (["--views", "rings:10,100x4"], "--views"),
    (["--views", "rings:10,20"], "--views"),
    (["--views", "random:5", "--elevation", "40,10"], "--elevation"),
    (["--radius-jitter", "-1"], "--radius-jitter"),
    (["--normalize", "unit-box"], "--normalize"),
])
def test_bad_view_set_options_give_one_line_and_exit_2_with_no_files(tmp_path, capsys, args, message):
    trimesh.creation.box().export(tmp_path / "a.obj")
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as exit_:
        main(["batch", str(tmp_path / "a.obj"), "-o", str(out), *args])
    assert exit_.value.code == 2
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert message in last and "error" in last
    assert not out.exists()


def test_views_of_earlier_batches_keep_their_fingerprint_fields():
    """Fields added to View are left out of the fingerprint at their defaults."""
    for view in [jobs.fixed_view("iso"), jobs.turntable_views(3)[1]]:
        assert set(view.identity()) == {"name", "direction", "up", "light_direction"}
    assert view_set("fibonacci:2", radius_jitter=0.5)[0].identity()["distance_scale"] > 1.0
