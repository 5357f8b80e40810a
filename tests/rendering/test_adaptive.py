"""Adaptive sampling in rounds, the error estimate it steers by, and the variance/spp passes.

Also the convergence rate of each pixel sampler on an edge-heavy image, measured against the
exact pixel coverage: the rates adaptive sampling relies on when it adds samples in rounds.
"""

import types

import numpy as np
import pytest
from scenes import floor_quad, part, render, settings, sphere_on_floor_scene

from rtmesh.cli import main
from rtmesh.core.errors import SceneError
from rtmesh.lights.point_lights import DirectionalLight
from rtmesh.loaders.scene_file import scene_from_dict
from rtmesh.materials.table import Material
from rtmesh.rendering.adaptive import dilate
from rtmesh.rendering.film import Film
from rtmesh.rendering.integrator import Integrator
from rtmesh.rendering.settings import RenderSettings
from rtmesh.sampling.patterns import pixel_offsets
from rtmesh.scene.camera import Camera
from rtmesh.scene.model import Scene

SPHERE = sphere_on_floor_scene()


def flat_scene():
    """A diffuse plane filling the view under a directional light: one radiance everywhere."""
    camera = Camera(np.array([0.0, 0.0, 5.0]), np.array([0.0, 0.0, 0.0]), [0.0, 1.0, 0.0], 30.0)
    light = DirectionalLight(np.array([0.0, 0.0, -1.0]), np.array([2.0, 2.0, 2.0]))
    return Scene.from_parts([part("floor", floor_quad(50.0))], [Material("floor", diffuse=0.5)],
                            [light], camera)


def adaptive(scene=SPHERE, **overrides):
    values = dict(spp=4, sampler="jittered", target_error=0.02, max_spp=64)
    values.update(overrides)
    return render(scene, **values)


# ---------------------------------------------------------------- film and chunks
def test_film_adds_samples_of_scattered_pixels_like_consecutive_ones():
    rng = np.random.default_rng(1)
    radiance = rng.uniform(size=(6, 3, 3))
    by_slice, by_index = Film(6, 1), Film(6, 1)
    by_slice.add_tile(0, radiance)
    order = np.array([4, 0, 5, 2, 1, 3])
    by_index.add_tile(order, radiance[order])
    np.testing.assert_array_equal(by_index.sum, by_slice.sum)
    np.testing.assert_array_equal(by_index.count, by_slice.count)
    # a second set of samples for two pixels only
    by_index.add_tile(np.array([1, 4]), radiance[[1, 4]])
    np.testing.assert_array_equal(by_index.count, [3, 6, 3, 3, 6, 3])


def test_film_variance_is_the_sample_variance_of_the_mean():
    integrator = Integrator(SPHERE, settings(spp=8, sampler="random"))
    pixels = np.arange(300, 340)
    radiance = integrator.render_chunk(pixels, 0, 8)[0]
    film = Film(32, 32)
    film.add_tile(pixels, radiance[:, :5])
    film.add_tile(pixels, radiance[:, 5:])  # a second round: sums accumulate
    expected = radiance.var(axis=1, ddof=1) / 8
    np.testing.assert_allclose(film.variance_of_mean().reshape(-1, 3)[pixels], expected,
                               rtol=1e-5, atol=1e-12)
    mean = radiance.mean(axis=1)
    error = np.mean(np.sqrt(expected) / (mean + 0.01), axis=1)
    np.testing.assert_allclose(film.pixel_relative_error()[pixels], error, rtol=1e-5)
    assert np.isnan(film.pixel_relative_error()[0])  # no samples, no estimate


def test_later_samples_continue_the_sequences_instead_of_repeating_them():
    integrator = Integrator(SPHERE, settings(spp=4, sampler="jittered"))
    pixels = np.array([5, 500, 501, 777])
    whole = integrator.render_chunk(pixels, 0, 8)[0]
    first, second = integrator.render_chunk(pixels, 0, 4)[0], integrator.render_chunk(pixels, 4, 4)[0]
    np.testing.assert_array_equal(whole, np.concatenate([first, second], axis=1))
    # the silhouette pixel 500 sees new positions in round two, not the first four again
    edge = np.flatnonzero(np.ptp(whole[:, :, 0], axis=1) > 0)
    assert len(edge) and not np.array_equal(first[edge], second[edge])


def test_per_pixel_sample_indices_give_the_samples_of_scalar_calls():
    # one batch with a different first sample and count per pixel takes exactly the samples
    # that one call per pixel would (sampler purity: a point depends on the pixel and the
    # global sample index only), for the pixel offsets and every other dimension
    for sampler in ("sobol", "jittered"):
        integrator = Integrator(SPHERE, settings(spp=4, sampler=sampler, ao_samples=2))
        pixels = np.array([5, 500, 501, 777])
        first, counts = np.array([4, 0, 8, 16]), np.array([4, 2, 8, 1])
        radiance, passes, _ = integrator.render_chunk(pixels, first, counts)
        assert radiance.shape == (counts.sum(), 3) and passes is None
        rows = np.split(radiance, np.cumsum(counts)[:-1])
        for p, f, c, got in zip(pixels, first, counts, rows):
            np.testing.assert_array_equal(got, integrator.render_chunk(np.array([p]), int(f), int(c))[0][0])


def test_film_adds_ragged_samples_like_tiles_pixel_by_pixel():
    rng = np.random.default_rng(3)
    pixels, counts = np.array([7, 2, 4, 0]), np.array([3, 1, 5, 2])
    radiance = rng.uniform(size=(counts.sum(), 3))
    passes = {"depth": rng.uniform(size=(counts.sum(), 1)), "ao": rng.uniform(size=(counts.sum(), 1)),
              "object_id": rng.integers(0, 9, size=(counts.sum(), 1)).astype(float)}
    specs = {"depth": (1, "min"), "ao": 1, "object_id": (1, "first")}
    ragged, tiles = Film(4, 2, specs), Film(4, 2, specs)
    ragged.add_samples(pixels, counts, radiance, passes)
    for p, rows in zip(pixels, np.split(np.arange(counts.sum()), np.cumsum(counts)[:-1])):
        tiles.add_tile(np.array([p]), radiance[rows][None], {k: v[rows][None] for k, v in passes.items()})
    np.testing.assert_array_equal(ragged.sum, tiles.sum)
    np.testing.assert_array_equal(ragged.sum_sq, tiles.sum_sq)
    np.testing.assert_array_equal(ragged.count, tiles.count)
    for name in specs:
        np.testing.assert_array_equal(ragged.pass_sums[name], tiles.pass_sums[name])
    # a second, ragged round keeps the first samples of the "first" pass
    ragged.add_samples(pixels[:2], counts[:2], radiance[:4], {k: v[:4] + 1 for k, v in passes.items()})
    np.testing.assert_array_equal(ragged.pass_sums["object_id"], tiles.pass_sums["object_id"])


@pytest.mark.parametrize("counts, chunk", [([4, 8, 16, 4, 4, 64, 1], 10), ([3] * 10, 6), ([5], 100),
                                           ([2, 2, 2], 1)])
def test_pixel_chunks_cover_the_pixels_without_splitting_one(counts, chunk):
    from rtmesh.rendering.scheduler import pixel_chunks
    counts = np.array(counts)
    spans = pixel_chunks(counts, len(counts), chunk)
    assert spans[0][0] == 0 and spans[-1][1] == len(counts)
    assert all(a < b and b == c for (a, b), (c, _) in zip(spans, spans[1:]))
    # each chunk starts at the first pixel whose samples begin past a multiple of chunk
    sizes = [counts[a:b].sum() for a, b in spans]
    assert all(size < chunk + counts.max() for size in sizes)
    assert len(spans) == len(np.unique((np.cumsum(counts) - counts) // chunk))


@pytest.mark.parametrize("spp", [1, 3])
def test_chunks_shrink_towards_the_end(spp):
    # guided chunks: 1 / (GUIDE x SCHEDULE_THREADS) of what is left, between the minimum and the cap
    from rtmesh.rendering.scheduler import MIN_CHUNK_SAMPLES, pixel_chunks
    n, cap = 512 * 512, 32768
    spans = pixel_chunks(spp, n, cap)
    sizes = np.array([(b - a) * spp for a, b in spans])
    assert spans[0][0] == 0 and spans[-1][1] == n
    assert all(b == c for (_, b), (c, _) in zip(spans, spans[1:]))
    assert sizes.max() <= cap + spp and sizes[0] >= cap
    assert np.all(np.diff(sizes[:-1]) <= spp)  # never growing (up to a pixel's rounding)
    assert sizes[-2] <= MIN_CHUNK_SAMPLES + spp and sizes[-1] <= MIN_CHUNK_SAMPLES + spp
    assert sizes[-2] < sizes[0] / 2
    # the same cuts for per-pixel counts as for one count for all
    assert pixel_chunks(np.full(n, spp), n, cap) == spans
    assert len(spans) <= n * spp // cap + 16  # the shrinking tail is short (geometric)


def test_display_error_weights_noise_by_the_square_root_of_brightness():
    # two pixels with the same relative noise, one 4x brighter: the relative error sees
    # them (nearly) alike, the display error ranks the bright one about sqrt(4) = 2x noisier
    samples = np.array([0.9, 1.1, 0.95, 1.05])
    film = Film(2, 1)
    film.add_tile(0, np.stack([samples, samples / 4])[:, :, None].repeat(3, axis=2))
    std_err = np.std(samples, ddof=1) / 2 * np.array([1.0, 1 / 4])
    display, relative = film.pixel_display_error(), film.pixel_relative_error()
    np.testing.assert_allclose(display, std_err / np.sqrt([1.01, 0.26]))
    np.testing.assert_allclose(relative, std_err / np.array([1.01, 0.26]))
    assert display[0] > 1.9 * display[1]
    assert abs(relative[0] / relative[1] - 1) < 0.05


def test_an_adaptive_round_is_one_batch_across_sample_counts(monkeypatch):
    # later rounds hold pixels at several counts: each round is still one render_samples
    # call, with per-pixel first samples equal to the pixels' counts
    calls = []
    render_samples = Integrator.render_samples

    def spy(self, film, pixels, first_sample, spp, stats, progress=None, pool=None):
        calls.append((np.ndim(spp), bool(np.all(first_sample == film.count[pixels]))))
        render_samples(self, film, pixels, first_sample, spp, stats, progress, pool)

    monkeypatch.setattr(Integrator, "render_samples", spy)
    result = adaptive(sampler="sobol", target_error=0.005, max_spp=64)
    assert len(calls) == len(result.stats.rounds) >= 3
    assert calls[0] == (0, True) and all(c == (1, True) for c in calls[1:])
    assert len(np.unique(result.film.count)) >= 4


def test_dilation_adds_the_eight_neighbours():
    mask = np.zeros((5, 6), dtype=bool)
    mask[2, 3] = True
    mask[0, 0] = True
    expected = np.zeros((5, 6), dtype=bool)
    expected[1:4, 2:5] = True
    expected[0:2, 0:2] = True
    np.testing.assert_array_equal(dilate(mask), expected)


# ---------------------------------------------------------------- rounds
def test_noisy_pixels_get_more_samples_than_converged_ones():
    first = render(SPHERE, spp=4, sampler="jittered")
    error0 = first.film.pixel_display_error()
    result = adaptive()
    count = result.film.count
    noisy = error0 > 0.02
    assert 20 < noisy.sum() < 500  # the silhouette and shadow edges
    assert (count[noisy] >= 8).all()
    near = dilate(noisy.reshape(32, 32)).ravel()
    assert (count[~near] == 4).sum() > 0.5 * count.size  # most of the image: round 0 only
    assert count[noisy].mean() > 3 * count[~near].mean()
    # round 1 refines exactly the noisy pixels of round 0 and their neighbours
    assert result.stats.rounds[0].pixels == 32 * 32 and result.stats.rounds[0].samples == 4096
    assert result.stats.rounds[1].pixels == near.sum()


def test_uniform_image_stops_after_the_first_round():
    result = adaptive(flat_scene(), target_error=1e-3)
    assert result.stats.stop_reason == "target"
    assert len(result.stats.rounds) == 1
    assert (result.film.count == 4).all()
    assert result.stats.relative_error < 1e-6


TARGET = 0.02


def test_target_is_reached_and_the_estimate_tracks_the_true_error():
    # random sampling: the per-pixel sample variance is an unbiased estimate of the error
    result = adaptive(sampler="random", target_error=TARGET, max_spp=1024)
    st = result.stats
    assert st.stop_reason == "target"
    assert (result.film.pixel_display_error() <= TARGET).all()
    assert [r.above_target for r in st.rounds][-1] == 0
    errors = [r.error for r in st.rounds]
    assert errors == sorted(errors, reverse=True) and len(errors) >= 3
    reference = render(SPHERE, spp=1024, sampler="sobol", seed=7).image
    # the estimate is the standard error over sqrt(mean + 0.01): measure the same
    true_error = np.mean(np.abs(result.image - reference) / np.sqrt(reference + 0.01))
    # the mean absolute deviation of a normal error is 0.8 of its standard deviation
    assert 0.4 * errors[-1] < true_error < 1.2 * errors[-1]


def test_max_spp_caps_every_pixel():
    result = adaptive(target_error=1e-6, max_spp=12)
    assert result.stats.stop_reason == "max_spp"
    assert result.film.count.max() == 12
    assert set(np.unique(result.film.count)) <= {4, 8, 12}
    # 4 -> 8 -> 12, and more rounds for neighbours that joined the noisy set later
    assert len(result.stats.rounds) >= 3


@pytest.fixture
def sample_clock(monkeypatch):
    """A simulated clock for rtmesh.rendering.adaptive on which every camera sample takes 1 us."""
    clock = types.SimpleNamespace(now=0.0)
    monkeypatch.setattr("rtmesh.rendering.adaptive.time", types.SimpleNamespace(perf_counter=lambda: clock.now))
    render_samples = Integrator.render_samples

    def timed(self, film, pixels, first_sample, spp, stats, progress=None, pool=None):
        render_samples(self, film, pixels, first_sample, spp, stats, progress, pool)
        clock.now += 1e-6 * np.sum(np.broadcast_to(spp, np.shape(pixels)))

    monkeypatch.setattr(Integrator, "render_samples", timed)
    return clock


def test_time_limit_stops_the_rounds(sample_clock):
    result = adaptive(target_error=1e-6, time_limit=0.012, max_spp=1024)
    st = result.stats
    assert st.stop_reason == "time_limit"
    assert st.samples <= 12000 and st.samples == result.film.count.sum()
    assert st.samples > 8000  # the last round was cut down to what fits, not dropped
    assert len(st.rounds) >= 3
    # a limit shorter than the first round: that round only
    sample_clock.now = 0.0
    assert len(adaptive(target_error=1e-6, time_limit=1e-4).stats.rounds) == 1


def test_time_limit_alone_refines_the_noisy_pixels_until_the_limit(sample_clock):
    result = adaptive(target_error=None, max_spp=None, time_limit=0.02)
    st = result.stats
    assert st.stop_reason == "time_limit" and 15000 < st.samples <= 20000
    # the samples go to the pixels that were noisier than average, not everywhere
    error0 = render(SPHERE, spp=4, sampler="jittered").film.pixel_display_error()
    count = result.film.count
    assert (count == 4).sum() > 0.5 * count.size
    assert (count[error0 > error0.mean()] >= 8).all() and count.max() >= 32


def test_adaptive_render_is_the_same_for_any_thread_count():
    one = adaptive(threads=1, chunk_samples=300)
    two = adaptive(threads=2, chunk_samples=300)
    assert len(one.stats.rounds) > 2
    np.testing.assert_array_equal(one.image, two.image)
    np.testing.assert_array_equal(one.film.count, two.film.count)
    # and for any chunk size: rounds with pixels at different counts are cut into chunks
    # at pixel boundaries, one chunk for the whole round here
    whole = adaptive(threads=1, sampler="sobol", chunk_samples=1 << 20)
    cut = adaptive(threads=1, sampler="sobol", chunk_samples=97)
    assert len(np.unique(whole.film.count)) >= 3
    np.testing.assert_array_equal(whole.image, cut.image)
    np.testing.assert_array_equal(whole.film.count, cut.film.count)


# ---------------------------------------------------------------- passes
def test_variance_and_spp_passes_come_from_the_film():
    result = adaptive(passes=("variance", "spp", "depth"))
    assert list(result.passes) == ["variance", "spp", "depth"]
    np.testing.assert_array_equal(result.passes["variance"], result.film.variance_of_mean())
    np.testing.assert_array_equal(result.passes["spp"][:, :, 0], result.film.count.reshape(32, 32))
    assert result.passes["variance"].dtype == np.float32 and result.passes["variance"].shape == (32, 32, 3)


def test_cli_writes_variance_and_spp_channels_and_reports_rounds(tmp_path, capsys):
    from rtmesh.io.images import read_image
    scene = tmp_path / "s.toml"
    scene.write_text('[render]\nwidth = 24\nheight = 16\nspp = 4\n'
                     '[camera]\nposition = [0.0, -4.0, 2.0]\nlook_at = [0.0, 0.0, 0.5]\nup = [0.0, 0.0, 1.0]\n'
                     '[[objects]]\nprimitive = "icosphere"\nsubdivisions = 2\ntranslate = [0.0, 0.0, 1.0]\n'
                     '[[lights]]\ntype = "point"\nposition = [2.0, -2.0, 5.0]\nintensity = 30.0\n')
    out = tmp_path / "out.exr"
    assert main(["render", str(scene), "-o", str(out), "--target-error", "0.05", "--max-spp", "32",
                 "--passes", "variance,spp", "-q"]) == 0
    line = capsys.readouterr().out
    assert "est. rel. error" in line and "rounds" in line and "stopped:" in line and "spp mean" in line
    pixels, names = read_image(out)
    assert sorted(names) == sorted(["R", "G", "B", "variance.R", "variance.G", "variance.B", "spp.Y"])
    spp = pixels[..., names.index("spp.Y")]
    assert spp.min() == 4 and spp.max() > 4 and spp.max() <= 32


# ---------------------------------------------------------------- bad settings
@pytest.mark.parametrize("values, message", [
    (dict(target_error=0.0), "target_error must be a number > 0"),
    (dict(target_error=-0.1), "target_error must be a number > 0"),
    (dict(target_error=float("inf")), "target_error must be a number > 0"),
    (dict(time_limit=0.0), "time_limit must be a number of seconds > 0"),
    (dict(target_error=0.1, max_spp=2), "max_spp must be >= spp"),
    (dict(max_spp=64), "max_spp needs target_error or time_limit"),
    (dict(target_error=0.1, spp=1), "spp must be >= 2 with target_error or time_limit"),
])
def test_invalid_adaptive_settings_are_rejected(values, message):
    with pytest.raises(ValueError, match=message):
        RenderSettings(**{"spp": 4, **values}).validate()


def test_scene_file_adaptive_keys_are_read_and_checked():
    doc = {"render": {"spp": 4, "target_error": 0.03, "time_limit": 20.0, "max_spp": 256},
           "objects": [{"primitive": "box"}]}
    _, s = scene_from_dict(doc)
    assert (s.target_error, s.time_limit, s.max_spp, s.adaptive) == (0.03, 20.0, 256, True)
    for key, value, message in [("target_error", "low", "render.target_error"),
                                ("time_limit", -1.0, "render.time_limit"),
                                ("max_spp", 2, "render: max_spp must be >= spp")]:
        bad = {**doc, "render": {**doc["render"], key: value}}
        with pytest.raises(SceneError, match=message):
            scene_from_dict(bad)


@pytest.mark.parametrize("flag, value", [("--target-error", "0"), ("--time-limit", "-2"),
                                         ("--max-spp", "0"), ("--target-error", "abc")])
def test_cli_rejects_bad_adaptive_flags(flag, value, tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["render", "scene.toml", "-o", str(tmp_path / "x.png"), flag, value])
    assert exit_info.value.code == 2
    assert flag in capsys.readouterr().err


# ---------------------------------------------------------------- convergence of the samplers
def half_square_area(normal, offset):
    """Area of ``{p in [0, 1]^2 : normal . p < offset}``: the unit square clipped by a line
    (one Sutherland-Hodgman step) and measured with the shoelace formula."""
    corners = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]
    kept = []
    for i, p in enumerate(corners):
        q = corners[(i + 1) % 4]
        dp = normal[0] * p[0] + normal[1] * p[1] - offset
        dq = normal[0] * q[0] + normal[1] * q[1] - offset
        if dp < 0:
            kept.append(p)
        if (dp < 0) != (dq < 0):
            t = dp / (dp - dq)
            kept.append((p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])))
    return 0.5 * abs(sum(kept[i][0] * kept[i - 1][1] - kept[i - 1][0] * kept[i][1] for i in range(len(kept))))


def test_half_square_area_matches_simple_cases():
    assert half_square_area((1.0, 0.0), 0.3) == pytest.approx(0.3)
    assert half_square_area((1.0, 1.0), 1.0) == pytest.approx(0.5)
    assert half_square_area((1.0, 1.0), 0.5) == pytest.approx(0.125)
    assert half_square_area((-1.0, 0.0), 1.0) == pytest.approx(1.0)


def edge_pixels(seed, n_pixels=400):
    """An edge-heavy test image: every pixel cut by an edge at a random angle and offset.

    Returns
    -------
    normal : (n, 2) float
    offset : (n,) float
        Pixel ``i`` is covered where ``normal[i] . p < offset[i]``, ``p`` in [0, 1)^2.
    truth : (n,) float
        The covered area of each pixel.
    """
    rng = np.random.default_rng(seed)
    angle = rng.uniform(0, 2 * np.pi, n_pixels)
    normal = np.column_stack([np.cos(angle), np.sin(angle)])
    offset = normal @ np.array([0.5, 0.5]) + rng.uniform(-0.4, 0.4, n_pixels)
    truth = np.array([half_square_area(nv, c) for nv, c in zip(normal, offset)])
    return normal, offset, truth


def covered_fraction(sampler, normal, offset, spp, set_size):
    """(n, spp) bool: which of each pixel's first ``spp`` samples (stratified in sets of
    ``set_size``) fall on the covered side of its edge."""
    n_pixels = len(offset)
    pixel = np.repeat(np.arange(n_pixels), spp)
    sample = np.tile(np.arange(spp), n_pixels)
    xy = pixel_offsets(sampler, 11, pixel, sample, set_size, (n_pixels, 1))
    return (np.einsum("ij,ij->i", xy, normal[pixel]) < offset[pixel]).reshape(n_pixels, spp)


def log_slope(counts, rmse):
    return np.polyfit(np.log(counts), np.log(rmse), 1)[0]


COUNTS = [4, 16, 64, 256]


@pytest.mark.parametrize("sampler, edge_rate, smooth_rate", [
    ("random", (-0.58, -0.42), (-0.62, -0.42)),  # Monte Carlo: N^-1/2 whatever the image
    ("jittered", (-0.85, -0.7), (-1.1, -0.85)),  # stratified: N^-3/4 on an edge, N^-1 smooth
    ("sobol", (-0.85, -0.7), (-1.6, -1.2)),  # Owen-scrambled (0,2): N^-3/4 on an edge, N^-3/2 smooth
    ("zsobol", (-0.85, -0.7), (-1.6, -1.2)),  # each pixel's block of one scrambled (0,2)-sequence: as sobol
])
def test_pixel_error_falls_at_the_rate_of_the_sampler(sampler, edge_rate, smooth_rate):
    # Edges: the pixel estimate is the fraction of its samples on the covered side, the
    # truth its area.  N^-3/4 is the rate of both stratified samplers on a discontinuity,
    # so measured slopes scatter around -0.75 (-0.75 to -0.76 with 2000 pixels, N up to
    # 1024); the bound leaves room for that scatter.
    normal, offset, truth = edge_pixels(2, n_pixels=1000)
    rmse = [np.sqrt(np.mean((covered_fraction(sampler, normal, offset, n, n).mean(axis=1) - truth) ** 2))
            for n in COUNTS]
    slope = log_slope(COUNTS, rmse)
    assert edge_rate[0] < slope < edge_rate[1], f"{sampler} on edges: slope {slope:.2f}"
    # smooth pixels, exp(a x + b y), where the low-discrepancy points pull ahead
    rng = np.random.default_rng(4)
    a, b = rng.uniform(-3.0, 3.0, (2, 1000))
    truth = np.expm1(a) / a * (np.expm1(b) / b)
    rmse = []
    # zsobol's pixels share one image-wide scramble, so the pixels of one seed are not
    # independent draws: its mean squared error is taken over eight seeds
    seeds = range(11, 19) if sampler == "zsobol" else [11]
    for n in COUNTS:
        pixel = np.repeat(np.arange(1000), n)
        squares = []
        for seed in seeds:
            xy = pixel_offsets(sampler, seed, pixel, np.tile(np.arange(n), 1000), n, (1000, 1))
            estimate = np.exp(a[pixel] * xy[:, 0] + b[pixel] * xy[:, 1]).reshape(1000, n).mean(axis=1)
            squares.append(np.mean((estimate - truth) ** 2))
        rmse.append(np.sqrt(np.mean(squares)))
    slope = log_slope(COUNTS, rmse)
    assert smooth_rate[0] < slope < smooth_rate[1], f"{sampler} on a smooth image: slope {slope:.2f}"


def test_sobol_prefixes_converge_like_whole_sets():
    # adaptive rounds take a pixel's samples as prefixes 0 .. 4 * 2^k - 1 of its sequence,
    # stratified in sets of the first round's 4: Sobol prefixes keep the N^-3/4 edge rate,
    # jittered sets of 4 are independent of each other past the first
    normal, offset, truth = edge_pixels(3)
    for sampler, high in [("sobol", -0.75), ("jittered", -0.45)]:
        covered = covered_fraction(sampler, normal, offset, COUNTS[-1], 4)
        rmse = [np.sqrt(np.mean((covered[:, :n].mean(axis=1) - truth) ** 2)) for n in COUNTS]
        slope = log_slope(COUNTS, rmse)
        assert slope < high, f"{sampler}: slope {slope:.2f}"


def test_a_uniform_render_estimates_no_per_pixel_error(monkeypatch):
    # one round, nothing to steer: the whole-film per-pixel error pass must not run, while
    # the render still reports its own error
    def refuse(self, *args, **kwargs):
        raise AssertionError("per-pixel error computed for a uniform render")

    monkeypatch.setattr(Film, "pixel_display_error", refuse)
    result = render(SPHERE, width=16, height=12, spp=4, sampler="jittered")
    assert len(result.stats.rounds) == 1 and np.isnan(result.stats.rounds[0].error)
    assert result.stats.relative_error > 0
