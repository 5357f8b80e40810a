"""rtmesh.sampling.patterns: pixel patterns, the counter-based generator and the warps."""

import numpy as np
import pytest
from scipy import stats

from rtmesh.sampling.patterns import (SAMPLERS, Dim, decorrelated_points, pixel_offsets, strata_shape,
                                      stratified_values, uniform, uniform2)
from rtmesh.sampling.warps import (cosine_hemisphere_to_square, square_to_cosine_hemisphere,
                                   square_to_cosine_hemisphere_pdf, square_to_uniform_disk_concentric,
                                   square_to_uniform_disk_concentric_pdf, uniform_disk_concentric_to_square)

SPPS = [1, 2, 4, 6, 9, 12, 16]


def chi_square_p_value(counts):
    """p-value of a chi-square test that ``counts`` come from equally likely bins."""
    counts = np.asarray(counts, dtype=np.float64).ravel()
    return stats.chisquare(counts).pvalue


def uniform_keys(count):
    """Pixel and sample keys like a render's: many pixels, a few samples each."""
    pixel = np.repeat(np.arange(count // 4, dtype=np.int64), 4)
    sample = np.tile(np.arange(4, dtype=np.int64), count // 4)
    return pixel, sample


# ---------------------------------------------------------------- pixel patterns
@pytest.mark.parametrize("spp", SPPS)
def test_strata_shape_covers_spp_and_is_as_square_as_possible(spp):
    nx, ny = strata_shape(spp)
    assert nx * ny == spp
    assert nx >= ny
    # no squarer factorisation exists
    for rows in range(ny + 1, int(np.sqrt(spp)) + 1):
        assert spp % rows
    assert strata_shape(16) == (4, 4) and strata_shape(6) == (3, 2)


@pytest.mark.parametrize("spp", [1, 4, 6, 16])
def test_every_jittered_stratum_holds_exactly_one_sample(spp):
    pixels = 500
    nx, ny = strata_shape(spp)
    pixel = np.repeat(np.arange(pixels, dtype=np.int64), spp)
    sample = np.tile(np.arange(spp, dtype=np.int64), pixels)
    offsets = pixel_offsets("jittered", 42, pixel, sample, spp)
    assert ((offsets >= 0.0) & (offsets < 1.0)).all()
    column = np.floor(offsets[:, 0] * nx).astype(int)
    row = np.floor(offsets[:, 1] * ny).astype(int)
    stratum = (row * nx + column).reshape(pixels, spp)
    expected = np.arange(spp)
    for p in range(pixels):
        np.testing.assert_array_equal(np.sort(stratum[p]), expected)
    # and the jitter is not degenerate: positions inside a stratum vary between pixels
    inside = np.column_stack([offsets[:, 0] * nx - column, offsets[:, 1] * ny - row])
    assert inside.std(axis=0).min() > 0.25


@pytest.mark.parametrize("spp", [1, 4, 6, 16])
def test_regular_samples_sit_at_stratum_centres(spp):
    nx, ny = strata_shape(spp)
    pixel = np.repeat(np.arange(3, dtype=np.int64), spp)
    sample = np.tile(np.arange(spp, dtype=np.int64), 3)
    offsets = pixel_offsets("regular", 7, pixel, sample, spp)
    column, row = sample % nx, sample // nx
    expected = np.column_stack([(column + 0.5) / nx, (row + 0.5) / ny])
    np.testing.assert_allclose(offsets, expected, rtol=0, atol=1e-15)
    # the seed does not move a regular pattern
    np.testing.assert_array_equal(offsets, pixel_offsets("regular", 8, pixel, sample, spp))


def test_random_pixel_offsets_are_in_the_unit_square_and_uniform():
    pixel, sample = uniform_keys(40000)
    offsets = pixel_offsets("random", 3, pixel, sample, 4)
    assert ((offsets >= 0.0) & (offsets < 1.0)).all()
    counts, _, _ = np.histogram2d(offsets[:, 0], offsets[:, 1], bins=4, range=[[0, 1], [0, 1]])
    assert chi_square_p_value(counts) > 1e-3


def test_unknown_sampler_is_an_error():
    with pytest.raises(ValueError, match="sampler"):
        pixel_offsets("halton", 0, np.zeros(1, np.int64), np.zeros(1, np.int64), 1)


# ---------------------------------------------------------------- the other dimensions
def pixel_sets(pixels, spp, rays=1, rounds=1):
    """Keys of every point of ``pixels`` pixels: ``rounds * spp`` samples, ``rays`` each."""
    per_pixel = rounds * spp * rays
    pixel = np.repeat(np.arange(pixels, dtype=np.int64), per_pixel)
    sample = np.tile(np.repeat(np.arange(rounds * spp, dtype=np.int64), rays), pixels)
    ray = np.tile(np.arange(rays, dtype=np.int64), pixels * rounds * spp)
    return pixel, sample, ray


def cell_of(points, nx, ny):
    """Index of the cell of an ``nx x ny`` grid holding each point, (n,) int."""
    return (np.floor(points[:, 1] * ny) * nx + np.floor(points[:, 0] * nx)).astype(int)


@pytest.mark.parametrize("sampler", ["jittered", "regular"])
@pytest.mark.parametrize("spp, rays, grid", [
    (1, 16, (4, 4)), (4, 4, (4, 4)), (2, 8, (4, 4)), (6, 3, (6, 3)), (9, 2, (6, 3)), (16, 16, (16, 16)),
])
def test_the_spp_times_rays_points_of_a_pixel_are_one_stratified_set(sampler, spp, rays, grid):
    # ambient-occlusion and shadow rays: rays per hit x spp hits per pixel, every stratum
    # of the joint grid holds exactly one point, in every round of spp samples
    pixels, rounds = 40, 2
    pixel, sample, ray = pixel_sets(pixels, spp, rays, rounds)
    u = decorrelated_points(sampler, 3, pixel, sample, spp, Dim.AO + 2, ray, rays)
    assert ((u >= 0.0) & (u < 1.0)).all()
    cells = cell_of(u, *grid).reshape(pixels, rounds, spp * rays)
    assert (np.sort(cells, axis=2) == np.arange(spp * rays)).all()
    # and the rays of each hit are stratified among themselves, one in each of `rays` cells
    cells = cell_of(u, *strata_shape(rays)).reshape(pixels, rounds, spp, rays)
    assert (np.sort(cells, axis=3) == np.arange(rays)).all()
    # later rounds are fresh points, and pixels differ
    points = u.reshape(pixels, rounds, spp * rays, 2)
    assert not np.isin(points[:, 1, :, 0], points[:, 0, :, 0]).any()
    assert len(np.unique(points[:, 0, 0, 0])) == pixels


# zsobol's points of one pixel are a block of one image-wide sequence: the resolution of
# the tests' images of `pixels` pixels (more than needed: the pixels are the first row)
RESOLUTION = (64, 48)


@pytest.mark.parametrize("sampler", ["sobol", "zsobol"])
@pytest.mark.parametrize("spp, rays", [(1, 16), (4, 4), (2, 8), (16, 1)])
def test_sobol_points_of_a_pixel_and_each_hit_fill_every_elementary_interval(sampler, spp, rays):
    pixels, m = 40, int(np.log2(spp * rays))
    pixel, sample, ray = pixel_sets(pixels, spp, rays)
    u = decorrelated_points(sampler, 3, pixel, sample, spp, Dim.LIGHT, ray, rays, RESOLUTION)
    sets = u.reshape(pixels, spp * rays, 2)
    hits = u.reshape(pixels * spp, rays, 2)
    for points, k in [(sets, m), (hits, int(np.log2(rays)))]:
        for a in range(k + 1):  # the 2^a x 2^(k - a) grids
            cells = np.sort(cell_of(points.reshape(-1, 2), 2 ** a, 2 ** (k - a)).reshape(len(points), -1))
            assert (cells == np.arange(2 ** k)).all(), (k, a)


def test_sobol_prefixes_of_any_number_of_rounds_are_stratified():
    # adaptive sampling adds rounds of `spp` samples; the first 2^k samples of a pixel
    # (whatever the round size) are a (0, m, 2)-net in 2D and one value per 2^-k in time
    pixels, spp, rays = 20, 2, 4
    pixel, sample, ray = pixel_sets(pixels, spp, rays, rounds=8)
    u = decorrelated_points("sobol", 1, pixel, sample, spp, Dim.AO, ray, rays).reshape(pixels, -1, 2)
    t = stratified_values("sobol", 1, pixel[::rays], sample[::rays], spp, Dim.TIME).reshape(pixels, -1)
    for k in range(5):
        points = u[:, : 2 ** k * rays].reshape(-1, 2)
        m = k + 2
        for a in range(m + 1):
            cells = np.sort(cell_of(points, 2 ** a, 2 ** (m - a)).reshape(pixels, -1))
            assert (cells == np.arange(2 ** m)).all(), (k, a)
        strata = np.sort(np.floor(t[:, : 2 ** k] * 2 ** k).astype(int))
        assert (strata == np.arange(2 ** k)).all()


def test_zsobol_rounds_are_each_stratified():
    # zsobol continues a pixel's index past spp in rounds of spp samples (adaptive
    # sampling): each round is a (0, m, 2)-net of its own and one value per 1/spp in time
    # (the union of rounds is not a finer net, unlike sobol's prefixes: a pixel's next
    # points lie in the next round's blocks, above the Morton digits)
    pixels, spp, rays, rounds = 20, 2, 4, 4
    pixel, sample, ray = pixel_sets(pixels, spp, rays, rounds)
    u = decorrelated_points("zsobol", 1, pixel, sample, spp, Dim.AO, ray, rays, RESOLUTION)
    t = stratified_values("zsobol", 1, pixel[::rays], sample[::rays], spp, Dim.TIME, RESOLUTION)
    u, t = u.reshape(pixels, rounds, spp * rays, 2), t.reshape(pixels, rounds, spp)
    m = 3
    for r in range(rounds):
        for a in range(m + 1):
            cells = np.sort(cell_of(u[:, r].reshape(-1, 2), 2 ** a, 2 ** (m - a)).reshape(pixels, -1))
            assert (cells == np.arange(2 ** m)).all(), (r, a)
        assert (np.sort(np.floor(t[:, r] * spp).astype(int)) == np.arange(spp)).all()
    # the first round is the points of a render without rounds
    one_pixel, one_sample, one_ray = pixel_sets(pixels, spp, rays)
    first = decorrelated_points("zsobol", 1, one_pixel, one_sample, spp, Dim.AO, one_ray, rays, RESOLUTION)
    np.testing.assert_array_equal(u[:, 0].reshape(-1, 2), first)
    # later rounds are fresh points
    assert not np.isin(u[:, 1:, :, 0], u[:, 0, :, 0]).any()


@pytest.mark.parametrize("sampler", SAMPLERS)
def test_stratified_values_of_later_rounds_stay_in_the_unit_interval(sampler):
    # sample indices past spp (later adaptive rounds) once gave times above 1
    spp, pixels, rounds = (8 if sampler == "zsobol" else 6), 100, 4  # zsobol: powers of two
    pixel, sample, _ = pixel_sets(pixels, spp, rounds=rounds)
    t = stratified_values(sampler, 2, pixel, sample, spp, Dim.TIME, RESOLUTION)
    assert ((t >= 0.0) & (t < 1.0)).all()
    if sampler in ("jittered", "regular"):
        # each round of spp samples puts one value in each interval [k / spp, (k + 1) / spp)
        strata = np.sort(np.floor(t * spp).astype(int).reshape(pixels, rounds, spp), axis=2)
        assert (strata == np.arange(spp)).all()
    # and no two samples of a pixel share a time
    assert all(len(np.unique(row)) == rounds * spp for row in t.reshape(pixels, -1))


@pytest.mark.parametrize("sampler", SAMPLERS)
def test_points_are_a_pure_function_of_their_keys(sampler):
    # rays that survive to depth d are a subset of the samples: each keeps its point, and
    # the batch's composition and order do not matter
    pixel, sample, ray = pixel_sets(30, 4, 3, rounds=2)
    full = decorrelated_points(sampler, 8, pixel, sample, 4, Dim.GLOSSY, ray, 3, RESOLUTION)
    rows = np.random.default_rng(0).permutation(len(pixel))[:50]
    subset = decorrelated_points(sampler, 8, pixel[rows], sample[rows], 4, Dim.GLOSSY, ray[rows], 3, RESOLUTION)
    np.testing.assert_array_equal(subset, full[rows])
    one_ray = decorrelated_points(sampler, 8, pixel[rows], sample[rows], 4, Dim.GLOSSY, int(ray[rows[0]]), 3,
                                  RESOLUTION)
    same = ray[rows] == ray[rows[0]]
    np.testing.assert_array_equal(one_ray[same], full[rows][same])


# ---------------------------------------------------------------- uniform()
def test_uniform_values_are_in_the_half_open_unit_interval():
    pixel, sample = uniform_keys(200000)
    for dimension in (0, 1, Dim.AO, 12345):
        u = uniform(9, pixel, sample, dimension)
        assert u.dtype == np.float64
        assert ((u >= 0.0) & (u < 1.0)).all()


def test_uniform_is_roughly_uniform():
    pixel, sample = uniform_keys(160000)
    u = uniform(1, pixel, sample, 0)
    assert abs(u.mean() - 0.5) < 0.005
    assert abs(u.var() - 1.0 / 12.0) < 0.002
    counts, _ = np.histogram(u, bins=16, range=(0, 1))
    assert chi_square_p_value(counts) > 1e-3


@pytest.mark.parametrize("varying", ["pixel", "sample", "dimension", "seed"])
def test_uniform_is_uniform_along_each_key(varying):
    count = 20000
    keys = np.arange(count, dtype=np.int64)
    if varying == "pixel":
        u = uniform(5, keys, 3, 2)
    elif varying == "sample":
        u = uniform(5, 3, keys, 2)
    elif varying == "dimension":
        u = np.array([uniform(5, np.array([3]), 3, int(d))[0] for d in keys[:4000]])
    else:
        u = np.array([uniform(int(s), np.array([3]), 3, 2)[0] for s in keys[:4000]])
    counts, _ = np.histogram(u, bins=16, range=(0, 1))
    assert chi_square_p_value(counts) > 1e-3


def test_uniform_pairs_are_uncorrelated_across_dimensions_and_pixels():
    pixel, sample = uniform_keys(100000)
    pair = uniform2(2, pixel, sample, Dim.PIXEL)
    counts, _, _ = np.histogram2d(pair[:, 0], pair[:, 1], bins=8, range=[[0, 1], [0, 1]])
    assert chi_square_p_value(counts) > 1e-3
    # neighbouring pixels (the keys a render uses side by side) are independent too
    u = uniform(2, np.arange(100000), 0, 0)
    assert abs(np.corrcoef(u[:-1], u[1:])[0, 1]) < 0.02


def test_uniform_is_a_pure_function_of_its_keys():
    pixel, sample = uniform_keys(1000)
    first = uniform(11, pixel, sample, 4)
    # same keys, in another order and another batch size, give the same values
    order = np.random.default_rng(0).permutation(len(pixel))
    again = uniform(11, pixel[order], sample[order], 4)
    np.testing.assert_array_equal(again, first[order])
    np.testing.assert_array_equal(uniform(11, pixel[:10], sample[:10], 4), first[:10])
    np.testing.assert_array_equal(uniform(11, pixel[5], sample[5], 4), first[5])
    # changing any one key changes (nearly) every value
    for changed in (uniform(12, pixel, sample, 4), uniform(11, pixel + 1, sample, 4),
                    uniform(11, pixel, sample + 1, 4), uniform(11, pixel, sample, 5)):
        assert (changed != first).mean() > 0.99


def test_uniform_handles_large_and_negative_seeds():
    pixel, sample = uniform_keys(1000)
    for seed in (2 ** 63 - 1, 2 ** 64 - 1, -1, -12345):
        u = uniform(seed, pixel, sample, 0)
        assert ((u >= 0.0) & (u < 1.0)).all()
    assert not np.array_equal(uniform(-1, pixel, sample, 0), uniform(1, pixel, sample, 0))


# ---------------------------------------------------------------- warps
def test_concentric_disk_stays_in_the_unit_disk_and_reaches_its_rim():
    grid = (np.stack(np.meshgrid(np.arange(101), np.arange(101)), axis=-1).reshape(-1, 2)) / 100.0
    d = square_to_uniform_disk_concentric(grid)
    radius = np.linalg.norm(d, axis=1)
    assert np.isfinite(d).all()
    assert (radius <= 1.0 + 1e-12).all()
    # the square's boundary maps onto the circle, its centre onto the disk's centre
    on_edge = (grid == 0.0).any(axis=1) | (grid == 1.0).any(axis=1)
    np.testing.assert_allclose(radius[on_edge], 1.0, atol=1e-12)
    np.testing.assert_allclose(square_to_uniform_disk_concentric(np.array([[0.5, 0.5]])), 0.0,
                               atol=1e-15)


def test_concentric_disk_is_area_preserving():
    # uniform points in the square must land uniformly in the disk: count them in 8 rings of
    # equal area x 16 equal sectors
    rng = np.random.default_rng(1)
    d = square_to_uniform_disk_concentric(rng.random((200000, 2)))
    ring = np.minimum((np.sum(d * d, axis=1) * 8).astype(int), 7)
    sector = np.minimum(((np.arctan2(d[:, 1], d[:, 0]) + np.pi) / (2 * np.pi) * 16).astype(int), 15)
    counts = np.bincount(ring * 16 + sector, minlength=128)
    assert chi_square_p_value(counts) > 1e-3
    # deterministic version: cut the square into n x n cells; each mapped cell (its boundary
    # traced with many points, area by the shoelace formula) has area pi / n^2
    n, per_side = 16, 32
    s = np.arange(per_side) / per_side
    unit_boundary = np.concatenate([np.column_stack([s, 0 * s]), np.column_stack([1 + 0 * s, s]),
                                    np.column_stack([1 - s, 1 + 0 * s]), np.column_stack([0 * s, 1 - s])])
    cells = np.stack(np.meshgrid(np.arange(n), np.arange(n), indexing="ij"), -1).reshape(-1, 1, 2)
    boundary = (cells + unit_boundary[None]) / n  # (cells, points, 2)
    mapped = square_to_uniform_disk_concentric(boundary.reshape(-1, 2)).reshape(boundary.shape)
    x, y = mapped[..., 0], mapped[..., 1]
    area = 0.5 * np.abs((x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y).sum(axis=1))
    np.testing.assert_allclose(area * n * n, np.pi, rtol=0.01)


def test_cosine_hemisphere_directions_are_unit_and_above_the_surface():
    rng = np.random.default_rng(2)
    u = np.concatenate([rng.random((10000, 2)), [[0.0, 0.0], [0.5, 0.5], [1.0 - 2 ** -53, 0.0]]])
    w = square_to_cosine_hemisphere(u)
    assert np.isfinite(w).all()
    assert (w[:, 2] >= 0.0).all()
    np.testing.assert_allclose(np.linalg.norm(w, axis=1), 1.0, atol=1e-12)


def test_cosine_hemisphere_pdf_integrates_to_one():
    # midpoint rule over the whole sphere in (z, phi), where d omega = dz dphi: the pdf is
    # piecewise linear in z with its kink on a cell boundary, so the rule is exact
    z = -1.0 + (np.arange(2000) + 0.5) / 1000.0
    phi = (np.arange(64) + 0.5) * (2.0 * np.pi / 64)
    z, phi = np.repeat(z, 64), np.tile(phi, 2000)
    s = np.sqrt(1.0 - z * z)
    w = np.column_stack([s * np.cos(phi), s * np.sin(phi), z])
    pdf = square_to_cosine_hemisphere_pdf(w)
    assert pdf.sum() * (1.0 / 1000.0) * (2.0 * np.pi / 64) == pytest.approx(1.0, abs=1e-12)
    assert (pdf[w[:, 2] < 0.0] == 0.0).all()


def test_concentric_disk_pdf_integrates_to_one():
    # midpoint rule in polar coordinates over a disk of radius 1.5 (the cut at r = 1 falls
    # on a cell boundary): the density must be 1 / pi on the unit disk and 0 outside it
    r = (np.arange(1500) + 0.5) / 1000.0
    phi = (np.arange(32) + 0.5) * (2.0 * np.pi / 32)
    r, phi = np.repeat(r, 32), np.tile(phi, 1500)
    d = np.column_stack([r * np.cos(phi), r * np.sin(phi)])
    pdf = square_to_uniform_disk_concentric_pdf(d)
    integral = (pdf * r).sum() * (1.0 / 1000.0) * (2.0 * np.pi / 32)
    assert integral == pytest.approx(1.0, abs=1e-12)
    assert (pdf[r > 1.0] == 0.0).all()


def jacobian_determinant(warp, u, h=1e-6):
    """Area (or solid angle) scale of ``warp`` at ``u`` by central differences, (n,)."""
    du = [np.array([h, 0.0]), np.array([0.0, h])]
    d0, d1 = [(warp(u + e) - warp(u - e)) / (2.0 * h) for e in du]
    if d0.shape[1] == 2:
        return np.abs(d0[:, 0] * d1[:, 1] - d0[:, 1] * d1[:, 0])
    return np.linalg.norm(np.cross(d0, d1), axis=1)


def interior_points(count, seed, margin=1e-3):
    """Uniform points in the square away from its edges (where the hemisphere's z has an
    infinite derivative) and from the diagonals (where the concentric map switches between
    its pieces and has no derivative)."""
    u = np.random.default_rng(seed).uniform(margin, 1.0 - margin, size=(4 * count, 2))
    off_diagonals = (np.abs(u[:, 0] - u[:, 1]) > margin) & (np.abs(u[:, 0] + u[:, 1] - 1.0) > margin)
    return u[off_diagonals][:count]


@pytest.mark.parametrize("warp, pdf", [
    (square_to_uniform_disk_concentric, square_to_uniform_disk_concentric_pdf),
    (square_to_cosine_hemisphere, square_to_cosine_hemisphere_pdf),
])
def test_warp_density_is_the_inverse_of_its_jacobian(warp, pdf):
    # a warp whose pdf is p has |det J| p(warp(u)) = 1 everywhere: the pdf is the density
    # the samples really follow, not just a function integrating to one
    u = interior_points(2000, 5)
    np.testing.assert_allclose(jacobian_determinant(warp, u) * pdf(warp(u)), 1.0, rtol=1e-5)


@pytest.mark.parametrize("warp, inverse", [
    (square_to_uniform_disk_concentric, uniform_disk_concentric_to_square),
    (square_to_cosine_hemisphere, cosine_hemisphere_to_square),
])
def test_warps_round_trip_through_their_inverse(warp, inverse):
    rng = np.random.default_rng(6)
    # the square's centre, corners, edges and diagonals included (the pieces' seams)
    t = rng.random(500)
    special = np.concatenate([np.column_stack([t, t]), np.column_stack([t, 1.0 - t]),
                              np.column_stack([t, 0.0 * t]), np.column_stack([0.0 * t, t]),
                              [[0.5, 0.5], [0.0, 0.0], [0.0, 1.0 - 2 ** -53]]])
    u = np.concatenate([rng.random((20000, 2)), special])
    np.testing.assert_allclose(inverse(warp(u)), u, rtol=0, atol=1e-12)
    # and the other way: random points of the disk (or hemisphere) come back
    x = warp(rng.random((20000, 2)))
    np.testing.assert_allclose(warp(inverse(x)), x, rtol=0, atol=1e-12)


def test_cosine_hemisphere_samples_follow_their_pdf():
    # for density cos(theta) / pi, z^2 is uniform on [0, 1) and phi uniform on [0, 2 pi)
    rng = np.random.default_rng(4)
    w = square_to_cosine_hemisphere(rng.random((200000, 2)))
    z2_bin = np.minimum((w[:, 2] ** 2 * 8).astype(int), 7)
    phi_bin = np.minimum(((np.arctan2(w[:, 1], w[:, 0]) + np.pi) / (2 * np.pi) * 8).astype(int), 7)
    counts = np.bincount(z2_bin * 8 + phi_bin, minlength=64)
    assert chi_square_p_value(counts) > 1e-3
    # mean cosine under this density is 2/3
    assert w[:, 2].mean() == pytest.approx(2.0 / 3.0, abs=0.003)


@pytest.mark.parametrize("sampler", ["sobol", "zsobol"])
def test_sobol_pixel_samples_are_stratified_in_every_elementary_interval(sampler):
    from rtmesh.sampling.patterns import pixel_offsets

    spp, pixels = 16, 50
    pixel = np.repeat(np.arange(pixels), spp)
    sample = np.tile(np.arange(spp), pixels)
    offsets = np.asarray(pixel_offsets(sampler, 7, pixel, sample, spp, RESOLUTION)).reshape(pixels, spp, 2)
    for points in offsets:
        for a in range(5):  # 1x16, 2x8, 4x4, 8x2, 16x1 grids: one sample per cell
            cells = np.floor(points[:, 0] * 2 ** a) * 2 ** (4 - a) + np.floor(points[:, 1] * 2 ** (4 - a))
            assert sorted(cells.astype(int).tolist()) == list(range(16))
    # pixels are scrambled independently
    assert len(np.unique(offsets[:, 0, 0])) == pixels


@pytest.mark.parametrize("flip", [False, True])
def test_spherical_triangle_directions_are_uniform_inside_it(flip):
    from rtmesh.sampling.warps import spherical_triangle_area, square_to_spherical_triangle

    corners = [np.array(v, dtype=float) / np.linalg.norm(v) for v in ([1.0, 0.2, 0.3], [0.1, 1.0, 0.2], [0.3, 0.1, 1.0])]
    if flip:  # the winding does not matter
        corners = corners[::-1]
    n = 100_000
    a, b, c = (np.tile(x, (n, 1)) for x in corners)
    d, omega = square_to_spherical_triangle(np.random.default_rng(3).random((n, 2)), a, b, c)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-12)
    # inside: on the inner side of the three great circles
    A, B, C = corners
    for p, q, r in ((A, B, C), (B, C, A), (C, A, B)):
        assert (d @ np.cross(p, q) * np.dot(np.cross(p, q), r) >= -1e-12).all()
    # uniform: each of three sub-triangles (split at the centroid direction) gets its share
    m = (A + B + C) / np.linalg.norm(A + B + C)
    total = omega[0]
    for p, q in ((A, B), (B, C), (C, A)):
        share = spherical_triangle_area(p[None], q[None], m[None])[0] / total
        inside = ((d @ np.cross(p, m)) * np.dot(np.cross(p, m), q) >= 0) & ((d @ np.cross(m, q)) * np.dot(np.cross(m, q), p) >= 0)
        assert abs(inside.mean() - share) < 5 * np.sqrt(share * (1 - share) / n)
    # the map is a bijection: its inverse gives the square points back
    from rtmesh.sampling.warps import spherical_triangle_to_square
    u = np.random.default_rng(4).random((1000, 2))
    back = spherical_triangle_to_square(square_to_spherical_triangle(u, a[:1000], b[:1000], c[:1000])[0],
                                        a[:1000], b[:1000], c[:1000])
    np.testing.assert_allclose(back, u, atol=1e-7)
    # the solid angle: an octant is pi / 2; a tiny triangle keeps its digits (area / d^2)
    octant = spherical_triangle_area(*(np.eye(3)[i][None] for i in range(3)))
    assert octant[0] == pytest.approx(np.pi / 2, rel=1e-14)
    tiny = np.array([[0.0, 0.0, 1.0], [1e-6, 0.0, 1.0], [0.0, 1e-6, 1.0]])
    tiny /= np.linalg.norm(tiny, axis=1)[:, None]
    assert spherical_triangle_area(*(t[None] for t in tiny))[0] == pytest.approx(0.5e-12, rel=1e-5)


def test_concentric_disk_kernel_equals_the_numpy_formulation():
    # the compiled warp must give NumPy's points bit for bit (libm's and NumPy's cos and
    # sin agree on these angles), at the centre, on the diagonals and on the edges too
    from rtmesh.sampling.warps import square_to_uniform_disk_concentric

    rng = np.random.default_rng(12)
    u = rng.random((300000, 2))
    u[:6] = [[0.5, 0.5], [0.0, 0.0], [0.25, 0.25], [0.25, 0.75], [0.0, 0.7], [0.9, 0.5]]
    a, b = 2.0 * u[:, 0] - 1.0, 2.0 * u[:, 1] - 1.0
    use_a = np.abs(a) > np.abs(b)
    r = np.where(use_a, a, b)
    with np.errstate(divide="ignore", invalid="ignore"):
        phi = np.where(use_a, (np.pi / 4.0) * (b / a), (np.pi / 2.0) - (np.pi / 4.0) * (a / b))
    phi = np.nan_to_num(phi)
    expected = np.stack([r * np.cos(phi), r * np.sin(phi)], axis=1)
    np.testing.assert_array_equal(square_to_uniform_disk_concentric(u), expected)
    np.testing.assert_array_equal(square_to_uniform_disk_concentric(np.asfortranarray(u)), expected)


def test_spherical_triangle_rows_are_the_numpy_warp():
    """The compiled rows the path kernel samples triangle lights with
    (spherical_triangle_area_row, spherical_triangle_row) against the NumPy warp, over
    random triangles of every size down to the sampling threshold."""
    import numba

    from rtmesh.sampling.warps import (spherical_triangle_area, spherical_triangle_area_row, spherical_triangle_row,
                                       square_to_spherical_triangle)

    @numba.njit
    def rows(u, a, b, c):
        out, omega = np.zeros((len(u), 3)), np.zeros(len(u))
        for i in range(len(u)):
            omega[i] = spherical_triangle_area_row(a[i, 0], a[i, 1], a[i, 2], b[i, 0], b[i, 1], b[i, 2], c[i, 0],
                                                   c[i, 1], c[i, 2])
            out[i, 0], out[i, 1], out[i, 2] = spherical_triangle_row(u[i, 0], u[i, 1], a[i, 0], a[i, 1], a[i, 2], b[i, 0],
                                                                     b[i, 1], b[i, 2], c[i, 0], c[i, 1], c[i, 2], omega[i])
        return out, omega

    rng = np.random.default_rng(21)
    n = 5000
    centre = rng.normal(size=(n, 3))
    spread = 10.0 ** rng.uniform(-1.5, 0.3, size=(n, 1))
    a, b, c = (centre + spread * rng.normal(size=(n, 3)) for _ in range(3))
    a, b, c = (v / np.linalg.norm(v, axis=1, keepdims=True) for v in (a, b, c))
    u = rng.random((n, 2))
    expected, omega = square_to_spherical_triangle(u, a, b, c)
    ours, our_omega = rows(u, a, b, c)
    np.testing.assert_allclose(our_omega, spherical_triangle_area(a, b, c), rtol=1e-12)
    keep = omega > 1e-3  # where the path kernel samples in solid angle
    assert keep.sum() > n // 2
    np.testing.assert_allclose(ours[keep], expected[keep], atol=1e-9)
