"""The zsobol sampler: its index against a scalar reference, nets at every level of the
Morton quadtree, blue-noise error, the path kernel's pairs, settings, and renders that do not
depend on threads or chunks under both integrators."""

import logging

import numba
import numpy as np
import pytest
from scenes import box, floor_quad, icosphere, part, render

from benchmarks._lib import blue_noise_ratio, gaussian_blur, radial_power_spectrum
from rtmesh.lights.area_lights import QuadLight
from rtmesh.lights.point_lights import PointLight
from rtmesh.materials.table import Material
from rtmesh.rendering.settings import RenderSettings
from rtmesh.sampling.patterns import Dim, decorrelated_points, dimension_key, pixel_offsets
from rtmesh.sampling.zsobol import (PERMUTATIONS, block_bits, sequence_keys, sequence_number, sequence_pair,
                                    sequence_ray_pair, zsobol_index)
from rtmesh.scene.camera import Camera
from rtmesh.scene.model import Scene

MASK64 = (1 << 64) - 1


def _mix64(x):
    x ^= x >> 30
    x = (x * 0xBF58476D1CE4E5B9) & MASK64
    x ^= x >> 27
    x = (x * 0x94D049BB133111EB) & MASK64
    return x ^ (x >> 31)


def _reference_index(key, column, line, sample, ray, spp, rays, width, height):
    """The global index in Python integers, as the module notes describe it: the round on
    top, the Morton digits permuted from the digits above them, the pixel's own bits
    flipped from the bits above them."""
    levels = (max(width, height) - 1).bit_length()
    block = (spp * rays - 1).bit_length()
    morton = 0
    for b in range(levels):
        morton |= ((column >> b) & 1) << (2 * b) | ((line >> b) & 1) << (2 * b + 1)
    top = 2 * levels + block
    z = (sample // spp) << top | morton << block | ((sample % spp) * rays + ray)
    index = (sample // spp) << top
    for level in reversed(range(levels)):
        shift = block + 2 * level
        chosen = (_mix64((z >> (shift + 2)) ^ key) >> 24) % 24
        index |= int(PERMUTATIONS[chosen, (z >> shift) & 3]) << shift
    for bit in reversed(range(block)):
        index |= (((z >> bit) & 1) ^ (_mix64((z >> (bit + 1)) ^ key) & 1)) << bit
    return index


@numba.njit
def _indices(key, morton, sample, ray, log2_spp, rays, levels, block):
    out = np.empty(len(sample), np.uint64)
    for i in range(len(sample)):
        out[i] = zsobol_index(key, np.uint64(morton[i]), np.uint64(sample[i]), np.uint64(ray[i]), log2_spp, rays,
                              levels, block)
    return out


@pytest.mark.parametrize("spp, rays, width, height", [(1, 1, 7, 5), (2, 1, 16, 16), (4, 3, 33, 9), (8, 1, 1, 1)])
def test_index_matches_a_scalar_reference(spp, rays, width, height):
    rng = np.random.default_rng(spp)
    n = 300
    column, line = rng.integers(0, width, n), rng.integers(0, height, n)
    sample, ray = rng.integers(0, 3 * spp, n), rng.integers(0, rays, n)
    key = 0x0123456789ABCDEF
    levels = (max(width, height) - 1).bit_length()
    morton = [sum((((c >> b) & 1) << (2 * b)) | (((r >> b) & 1) << (2 * b + 1)) for b in range(levels))
              for c, r in zip(column, line)]
    got = _indices(np.uint64(key), np.array(morton, np.uint64), sample, ray, np.uint64(spp.bit_length() - 1),
                   np.uint64(rays), np.uint64(levels), np.uint64((spp * rays - 1).bit_length()))
    expected = [_reference_index(key, int(c), int(r), int(s), int(j), spp, rays, width, height)
                for c, r, s, j in zip(column, line, sample, ray)]
    assert got.tolist() == expected


def is_net(points, m):
    """Whether ``points`` (2^m, 2) put one point in every elementary interval of area 2^-m."""
    for a in range(m + 1):
        cells = np.floor(points[:, 0] * 2 ** a) * 2 ** (m - a) + np.floor(points[:, 1] * 2 ** (m - a))
        if sorted(cells.astype(int).tolist()) != list(range(2 ** m)):
            return False
    return True


@pytest.mark.parametrize("spp", [1, 2, 4, 8])
@pytest.mark.parametrize("dimension", [Dim.PIXEL, Dim.LIGHT + 6])
def test_every_aligned_block_of_pixels_holds_a_net(spp, dimension):
    # the blue noise: the points of a pixel, of each aligned 2x2 quad of pixels, of each
    # 4x4 block ... are each a (0, m, 2)-net (an aligned block of one scrambled sequence)
    size = 16
    pixel = np.repeat(np.arange(size * size), spp)
    sample = np.tile(np.arange(spp), size * size)
    u = decorrelated_points("zsobol", 5, pixel, sample, spp, dimension, resolution=(size, size))
    u = u.reshape(size, size, spp, 2)
    m = spp.bit_length() - 1
    for side in (1, 2, 4, 16):
        k = 2 * (side.bit_length() - 1)
        for y in range(0, size, side):
            for x in range(0, size, side):
                assert is_net(u[y:y + side, x:x + side].reshape(-1, 2), m + k), (side, y, x)


def half_plane(u):
    """The indicator of a half-plane over (n, 2) points: a straight shadow edge across a light."""
    return (u[:, 0] + 0.7 * u[:, 1] < 0.8).astype(float)


def constant_integrand_errors(sampler, spp, size=128, seeds=4, integrand=half_plane, mean=0.8 ** 2 / 1.4):
    """Error images of every pixel integrating the same ``integrand`` (exact integral
    ``mean``) over its light-dimension points, one per seed, (seeds, size, size)."""
    pixel = np.repeat(np.arange(size * size), spp)
    sample = np.tile(np.arange(spp), size * size)
    errors = []
    for seed in range(seeds):
        u = decorrelated_points(sampler, seed, pixel, sample, spp, Dim.LIGHT, resolution=(size, size))
        errors.append(integrand(u).reshape(-1, spp).mean(axis=1).reshape(size, size) - mean)
    return np.array(errors)


def pooled_rmse(errors, blur=False):
    """RMSE of error images pooled over their seeds, after a Gaussian blur of 1 pixel if ``blur``."""
    return np.sqrt(np.mean([np.mean((gaussian_blur(e) if blur else e) ** 2) for e in errors]))


def spectrum_ratio(errors):
    """:func:`blue_noise_ratio` of the error images' mean radial power spectrum."""
    return blue_noise_ratio(np.mean([radial_power_spectrum(e)[1] for e in errors], axis=0))


@pytest.mark.parametrize("spp", [1, 2, 4, 8])
def test_error_of_a_smooth_image_is_blue_noise(spp):
    # the criteria where neighbouring pixels integrate the same function: zsobol's
    # error after a 1-pixel Gaussian blur at most 0.75x sobol's, unblurred at most 1.05x,
    # and its power spectrum's top third of frequencies at least 2x its bottom third
    # (sobol's is white: 1x).  Errors pooled and spectra averaged over four seeds.
    z, s = constant_integrand_errors("zsobol", spp), constant_integrand_errors("sobol", spp)
    assert pooled_rmse(z, blur=True) <= 0.75 * pooled_rmse(s, blur=True)
    assert pooled_rmse(z) <= 1.05 * pooled_rmse(s)
    assert spectrum_ratio(z) >= 2.0
    assert 0.8 < spectrum_ratio(s) < 1.25


def test_blue_noise_needs_an_integrand_coherent_in_the_sample_square():
    # why the soft-shadow scene's glowing ball falls short (docs/SAMPLERS.md): an integrand
    # that jumps at random between 320 cells of the first coordinate (an emissive mesh's
    # face chosen through the power CDF, the faces in no spatial order) keeps its error
    # after the blur and stays nearly white, the same function in every pixel: the
    # complementary points of neighbouring pixels land in cells whose values are unrelated,
    # so their errors do not cancel (measured 0.95x and 1.27 at 4 spp)
    steps = np.random.default_rng(7).random(320)

    def cells(u):
        return steps[(u[:, 0] * len(steps)).astype(np.int64)]

    z, s = (constant_integrand_errors(sampler, 4, integrand=cells, mean=steps.mean())
            for sampler in ("zsobol", "sobol"))
    assert pooled_rmse(z, blur=True) > 0.85 * pooled_rmse(s, blur=True)
    assert spectrum_ratio(z) < 2.0


@numba.njit
def _path_pairs(keys, which, pixel, sample):
    out = np.empty((len(pixel), 2))
    for i in range(len(pixel)):
        out[i, 0], out[i, 1] = sequence_pair(keys, which, np.uint64(pixel[i]), sample[i])
    return out


@pytest.mark.parametrize("sampler", ["sobol", "zsobol"])
def test_path_kernel_pairs_are_the_samplers_points(sampler):
    # the path integrator's first-vertex light and BSDF points are the sampler's points of
    # those dimensions (the row the kernel calls, against the NumPy path)
    rng = np.random.default_rng(1)
    width, height, spp = 50, 30, 8
    pixel, sample = rng.integers(0, width * height, 400), rng.integers(0, 3 * spp, 400)
    keys = sequence_keys(sampler, 9, (Dim.PATH_LIGHT, Dim.PATH_BSDF), spp, (width, height))
    for which, dimension in enumerate((Dim.PATH_LIGHT, Dim.PATH_BSDF)):
        expected = decorrelated_points(sampler, 9, pixel, sample, spp, dimension, resolution=(width, height))
        np.testing.assert_array_equal(_path_pairs(keys, which, pixel, sample), expected)
    assert keys[4] == dimension_key(9, Dim.PATH_LIGHT)


@numba.njit
def _path_ray_pairs(keys, which, pixel, sample, ray, rays, log2_block):
    out = np.empty((len(pixel), 2))
    for i in range(len(pixel)):
        out[i, 0], out[i, 1] = sequence_ray_pair(keys, which, np.uint64(pixel[i]), sample[i], ray, rays, log2_block)
    return out


@pytest.mark.parametrize("sampler", ["sobol", "zsobol"])
@pytest.mark.parametrize("rays", [1, 3, 4])
def test_path_kernel_light_samples_are_the_samplers_rays_of_a_hit(sampler, rays):
    # the path integrator's first-vertex light samples (light_samples = rays) and the Whitted
    # configuration's AO directions (ao_samples = rays) are the sampler's points of several
    # rays a hit, as the Whitted stages' shadow and AO rays; one ray is sequence_pair's point
    rng = np.random.default_rng(2)
    width, height, spp = 50, 30, 8
    pixel, sample = rng.integers(0, width * height, 300), rng.integers(0, 3 * spp, 300)
    keys = sequence_keys(sampler, 9, (Dim.PATH_LIGHT, Dim.PATH_BSDF, Dim.AO), spp, (width, height))
    for which, dimension in ((0, Dim.PATH_LIGHT), (2, Dim.AO)):
        for ray in range(rays):
            expected = decorrelated_points(sampler, 9, pixel, sample, spp, dimension, ray=ray, rays=rays,
                                           resolution=(width, height))
            got = _path_ray_pairs(keys, which, pixel, sample, ray, rays, block_bits(spp, rays))
            np.testing.assert_array_equal(got, expected)
    if rays == 1:
        np.testing.assert_array_equal(_path_ray_pairs(keys, 0, pixel, sample, 0, 1, block_bits(spp)),
                                      _path_pairs(keys, 0, pixel, sample))


@numba.njit
def _numbers(keys, which, pixel, sample, ray, rays, log2_block):
    out = np.empty(len(pixel))
    for i in range(len(pixel)):
        out[i] = sequence_number(keys, which, np.uint64(pixel[i]), sample[i], ray, rays, log2_block)
    return out


@pytest.mark.parametrize("sampler", ["sobol", "zsobol"])
@pytest.mark.parametrize("rays", [1, 2])
def test_light_choice_numbers_are_stratified_in_a_dimension_of_their_own(sampler, rays):
    # the path kernel's first-vertex light choice (zsobol.sequence_number): a pixel's
    # spp x rays numbers (two adaptive rounds' worth) take distinct strata, and the samples
    # of one stratum are not those of one stratum of the light points (the earlier design
    # rescaled the light pair's first number, so they were)
    width, height, spp = 16, 16, 32
    keys = sequence_keys(sampler, 9, (Dim.PATH_LIGHT, Dim.PATH_BSDF, Dim.AO, Dim.PATH_CHOICE), spp,
                         (width, height))
    block = block_bits(spp, rays)
    pixels = np.repeat(np.arange(width * height), spp)
    samples = np.tile(np.arange(spp), width * height)
    spread = []
    for round_ in range(2):
        numbers = np.stack([_numbers(keys, 3, pixels, samples + round_ * spp, ray, rays, block)
                            for ray in range(rays)], axis=-1).reshape(width * height, spp * rays)
        assert numbers.min() >= 0.0 and numbers.max() < 1.0
        strata = np.floor(numbers * (1 << block)).astype(np.int64)
        assert all(len(np.unique(row)) == spp * rays for row in strata)
        points = np.stack([_path_ray_pairs(keys, 0, pixels, samples + round_ * spp, ray, rays, block)[:, 0]
                           for ray in range(rays)], axis=-1).reshape(width * height, spp * rays)
        # the light points' x (in eighths) of the samples whose number lies in the first eighth
        chosen = [np.unique(np.floor(p[n < 0.125] * 8)) for n, p in zip(numbers, points)]
        spread.append(np.mean([len(c) for c in chosen]))
    # a random choice of 4 or 8 of the pixel's points: ~3 or ~5 distinct eighths; one if dependent
    assert min(spread) > (2.5 if spp * rays == 32 else 4.0)
    if sampler == "zsobol":
        # zsobol's number is the first coordinate of the dimension's point (blue noise)
        np.testing.assert_array_equal(_numbers(keys, 3, pixels, samples, 0, rays, block),
                                      _path_ray_pairs(keys, 3, pixels, samples, 0, rays, block)[:, 0])


def test_spp_not_a_power_of_two_rounds_up_with_a_warning(caplog):
    with caplog.at_level(logging.WARNING):
        settings = RenderSettings(sampler="zsobol", spp=6).validate()
    assert settings.spp == 8
    assert [r.getMessage() for r in caplog.records] == ["sampler 'zsobol' takes a power-of-two spp: 6 rounded up to 8"]
    caplog.clear()
    # an adaptive render's cap between the two rises with spp
    settings = RenderSettings(sampler="zsobol", spp=3, max_spp=3, target_error=0.1).validate()
    assert (settings.spp, settings.max_spp) == (4, 4)
    assert caplog.records[0].getMessage().endswith("3 rounded up to 4 (max_spp too)")
    assert RenderSettings(sampler="zsobol", spp=3, max_spp=9, target_error=0.1).validate().max_spp == 9
    caplog.clear()
    assert RenderSettings(sampler="zsobol", spp=16).validate().spp == 16
    assert RenderSettings(sampler="sobol", spp=6).validate().spp == 6
    assert not caplog.records


def test_zsobol_needs_the_resolution_and_a_power_of_two():
    one = np.zeros(1, np.int64)
    with pytest.raises(ValueError, match="resolution"):
        pixel_offsets("zsobol", 0, one, one, 4)
    with pytest.raises(ValueError, match="power-of-two"):
        pixel_offsets("zsobol", 0, one, one, 6, (4, 4))


def soft_shadow_scene():
    """A quad light over a box on a floor (area-light samples), a point light."""
    parts = [part("floor", floor_quad(6.0), 0), part("box", box((1.0, 1.0, 1.0), (0.0, 0.0, 0.5)), 1),
             part("ball", icosphere(2, 0.5, (1.5, 0.5, 0.5)), 1, smooth=True)]
    materials = [Material("floor", diffuse=0.6), Material("box", diffuse=[0.7, 0.4, 0.2], specular=0.3)]
    lights = [QuadLight([-0.5, 0.0, 3.0], [0.0, 2.0, 0.0], [2.0, 0.0, 0.0], 4.0), PointLight([3.0, -2.0, 4.0], 10.0)]
    camera = Camera([0.5, -5.0, 3.5], [0.0, 0.0, 0.3], [0.0, 0.0, 1.0], 45.0, aperture=0.05, focus_distance=5.5)
    return Scene.from_parts(parts, materials, lights, camera, ambient=0.05)


@pytest.mark.parametrize("threads, chunk_samples", [(2, 1000), (2, 77)])
def test_whitted_renders_do_not_depend_on_threads_or_chunks(threads, chunk_samples):
    settings = dict(width=24, height=18, spp=4, sampler="zsobol", light_samples=2, ao_samples=2, ao_distance=1.0,
                    seed=3)
    reference = render(soft_shadow_scene(), threads=1, chunk_samples=50000, **settings)
    result = render(soft_shadow_scene(), threads=threads, chunk_samples=chunk_samples, **settings)
    np.testing.assert_array_equal(result.image, reference.image)
    # and the sampler matters
    other = render(soft_shadow_scene(), threads=1, chunk_samples=50000, **dict(settings, sampler="sobol"))
    assert not np.array_equal(other.image, reference.image)


def test_adaptive_rounds_continue_each_pixel_and_estimate_the_error():
    settings = dict(width=20, height=14, spp=2, sampler="zsobol", light_samples=1, seed=1, target_error=0.02,
                    max_spp=16)
    a = render(soft_shadow_scene(), threads=1, **settings)
    b = render(soft_shadow_scene(), threads=2, chunk_samples=40, **settings)
    np.testing.assert_array_equal(a.image, b.image)
    assert len(a.stats.rounds) > 1
    assert np.isfinite(a.film.pixel_display_error()).all()


def test_path_renders_do_not_depend_on_threads_or_chunks():
    # the path kernel's first-vertex pairs and the camera's dimensions under zsobol
    settings = dict(width=20, height=14, spp=4, sampler="zsobol", integrator="path", max_depth=3, seed=2)
    reference = render(soft_shadow_scene(), threads=1, chunk_samples=50000, **settings)
    for threads, chunk_samples in ((2, 1000), (2, 61)):
        result = render(soft_shadow_scene(), threads=threads, chunk_samples=chunk_samples, **settings)
        np.testing.assert_array_equal(result.image, reference.image)
    other = render(soft_shadow_scene(), threads=1, chunk_samples=50000, **dict(settings, sampler="sobol"))
    assert not np.array_equal(other.image, reference.image)


@pytest.fixture(scope="module")
def soft_shadow_errors():
    """benchmarks/bench_zsobol.py's measurement of assets/effects/soft_shadow.toml at its own
    size (480x360), one light sample, 2, 4 and 8 spp, eight seeds, against a reference of
    256 spp x 4 light samples (cached in out/bench_zsobol)."""
    from benchmarks import _lib, bench_zsobol

    ref = bench_zsobol.reference(480, 360, 256, 2, _lib.ROOT / "out" / "bench_zsobol")
    rows = bench_zsobol.measure(ref, (2, 4, 8), 8, threads=2, samplers=("sobol", "zsobol"), log=lambda line: None)[0]
    return {(r["spp"], r["sampler"]): r for r in rows}


@pytest.mark.slow
@pytest.mark.parametrize("spp", [2, 4, 8])
def test_soft_shadow_scene_error_is_no_larger_and_blurs_away_better(soft_shadow_errors, spp):
    # without the emitters and the floor touching the glowing ball (whose 1/r^2 fireflies
    # decide any RMSE of the whole image: there random comes out below sobol)
    z, s = soft_shadow_errors[spp, "zsobol"], soft_shadow_errors[spp, "sobol"]
    assert z["raw_masked"] <= 1.05 * s["raw_masked"]
    assert z["blurred_masked"] <= 0.9 * s["blurred_masked"]
    assert z["blue_masked"] > s["blue_masked"]
