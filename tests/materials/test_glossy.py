"""Glossy reflection: the Phong lobe warp, its use by the integrator, and its energy."""

import numpy as np
import pytest
from scenes import floor_quad, icosphere, part, render, settings
from scipy import integrate, stats

from rtmesh.core.errors import SceneError
from rtmesh.loaders.scene_file import scene_from_dict
from rtmesh.materials.glossy import (phong_lobe_to_square, roughness_exponent, sample_glossy_directions,
                                     square_to_phong_lobe, square_to_phong_lobe_pdf)
from rtmesh.materials.specular import SpecularScattering
from rtmesh.materials.table import Material, MaterialTable
from rtmesh.rendering.integrator import Integrator
from rtmesh.sampling.patterns import Dim, decorrelated_points
from rtmesh.scene.camera import Camera
from rtmesh.scene.model import Scene
from wavefront.secondary_rays import SecondaryRays

EXPONENTS = [0.0, 1.0, 7.5, 100.0, 1e4]


def lobe_points(count, seed=0):
    return np.random.default_rng(seed).random((count, 2))


# ---------------------------------------------------------------- the warp
@pytest.mark.parametrize("exponent", EXPONENTS)
def test_phong_lobe_round_trips_through_its_inverse(exponent):
    u = lobe_points(5000)
    w = square_to_phong_lobe(u, exponent)
    np.testing.assert_allclose(np.linalg.norm(w, axis=1), 1.0, atol=1e-12)
    assert (w[:, 2] > 0.0).all()
    back = phong_lobe_to_square(w, exponent)
    # u0 near 1 maps to the horizon, where cos^(n+1) loses relative precision
    ok = u[:, 0] < 0.999
    np.testing.assert_allclose(back[ok], u[ok], atol=1e-7)


@pytest.mark.parametrize("exponent", EXPONENTS)
def test_phong_lobe_pdf_integrates_to_one(exponent):
    def density(theta, phi):
        w = np.array([[np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)]])
        return square_to_phong_lobe_pdf(w, exponent)[0] * np.sin(theta)

    # the narrow lobes are integrated where they live; the rest of the hemisphere holds
    # less than 1e-12 of their mass
    theta_max = np.pi / 2 if exponent < 100 else min(np.pi / 2, 12.0 / np.sqrt(exponent))
    total, _ = integrate.dblquad(lambda theta, phi: density(theta, phi), 0, 2 * np.pi, 0, theta_max,
                                 epsabs=1e-10, epsrel=1e-9)
    assert total == pytest.approx(1.0, abs=1e-6)
    # nothing below the horizon
    assert square_to_phong_lobe_pdf(np.array([[0.6, 0.0, -0.8]]), exponent)[0] == 0.0


@pytest.mark.parametrize("exponent", [1.0, 20.0, 400.0])
def test_phong_lobe_samples_pass_a_chi_square_test_against_the_pdf(exponent):
    # Mitsuba/PBRT style: bin sampled directions on a (cos theta, phi) grid and compare with
    # the counts the pdf predicts, integrated numerically over every bin
    n = 200000
    w = square_to_phong_lobe(lobe_points(n, seed=3), exponent)
    theta_max = min(np.pi / 2, 6.0 / np.sqrt(exponent + 1.0))
    theta_bins, phi_bins = 10, 12
    theta_edges = np.linspace(0.0, theta_max, theta_bins + 1)
    phi_edges = np.linspace(-np.pi, np.pi, phi_bins + 1)
    theta = np.arccos(np.clip(w[:, 2], -1, 1))
    phi = np.arctan2(w[:, 1], w[:, 0])
    inside = theta < theta_max
    counts, _, _ = np.histogram2d(theta[inside], phi[inside], bins=[theta_edges, phi_edges])
    expected = np.zeros_like(counts)
    for i in range(theta_bins):
        # pdf * sin(theta) integrated over the ring's theta range and its 2 pi of phi
        mass, _ = integrate.quad(lambda t: 2 * np.pi * square_to_phong_lobe_pdf(
            np.array([[np.sin(t), 0.0, np.cos(t)]]), exponent)[0] * np.sin(t),
            theta_edges[i], theta_edges[i + 1])
        expected[i, :] = n * mass / phi_bins
    # pool the sparse tail into one bin as the warp tests of Mitsuba do
    keep = expected > 5
    observed, predicted = counts[keep], expected[keep]
    if n - predicted.sum() > 5:
        observed = np.append(observed, n - observed.sum())
        predicted = np.append(predicted, n - predicted.sum())
    np.testing.assert_allclose(predicted.sum(), n, rtol=1e-9)
    assert keep.sum() > 60
    assert stats.chisquare(observed, predicted).pvalue > 1e-3


def test_glossy_directions_are_a_lobe_around_the_mirror_folded_above_the_surface():
    rng = np.random.default_rng(2)
    k = 40000
    ng = np.tile([0.0, 0.0, 1.0], (k, 1))
    # grazing mirror direction: 5 degrees above the surface
    mirror = np.tile([np.cos(np.radians(5)), 0.0, np.sin(np.radians(5))], (k, 1))
    roughness = np.full(k, 0.2)
    wi = sample_glossy_directions(mirror, ng, roughness, rng.random((k, 2)))
    np.testing.assert_allclose(np.linalg.norm(wi, axis=1), 1.0, atol=1e-12)
    assert (wi @ [0, 0, 1] >= 0.0).all()
    # the in-plane spread is the lobe's: for small angles, standard deviation ~ roughness
    assert np.std(wi[:, 1]) == pytest.approx(0.2, rel=0.1)
    assert roughness_exponent(np.array([0.1]))[0] == pytest.approx(100.0)


# ---------------------------------------------------------------- in the renderer
def rough_mirror_floor(roughness, mirror=0.8, background=1.0):
    """A mirror floor under a uniform sky, seen at a grazing angle."""
    floor = part("floor", floor_quad(50.0), 0)
    camera = Camera([0.0, -6.0, 1.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 40.0)
    material = Material(diffuse=0.0, ambient=0.0, mirror=mirror, roughness=roughness)
    return Scene.from_parts([floor], [material], [], camera, background=np.full(3, background))


@pytest.mark.parametrize("roughness", [0.05, 0.5, 2.0])
def test_rough_mirror_under_a_uniform_sky_reflects_exactly_its_reflectance(roughness):
    # every sampled direction carries the weight kr and (folded above the surface) sees the
    # sky, so each pixel of the floor is kr * sky exactly, even at grazing angles where
    # much of the lobe lies under the surface: energy is neither lost nor created
    result = render(rough_mirror_floor(roughness), width=24, height=24, spp=4, sampler="jittered")
    assert "glossy" in result.stats.stages_enabled
    floor_rows = result.image[14:]  # below the horizon of the image
    np.testing.assert_allclose(floor_rows, 0.8, rtol=1e-6)


def glossy_ball_scene(roughness):
    ball = part("ball", icosphere(3, 1.0, (0.0, 0.0, 1.0)), 1)
    floor_vertices, floor_faces = floor_quad(4.0)
    checker = part("floor", (floor_vertices, floor_faces), 0)
    camera = Camera([0.0, -5.0, 2.0], [0.0, 0.0, 0.8], [0.0, 0.0, 1.0], 40.0)
    materials = [Material("floor", diffuse=0.0, emission=[1.0, 0.5, 0.2]),
                 Material("ball", diffuse=0.1, mirror=0.85, roughness=roughness)]
    return Scene.from_parts([checker, ball], materials, [], camera,
                            background=np.array([0.2, 0.3, 0.8]))


def test_roughness_to_zero_reproduces_the_mirror_image():
    mirror = render(glossy_ball_scene(0.0), spp=4, sampler="jittered")
    assert "glossy" not in mirror.stats.stages_enabled
    nearly = render(glossy_ball_scene(1e-7), spp=4, sampler="jittered")
    assert "glossy" in nearly.stats.stages_enabled
    np.testing.assert_allclose(nearly.image, mirror.image, atol=1e-4)
    rough = render(glossy_ball_scene(0.3), spp=4, sampler="jittered")
    assert np.abs(rough.image - mirror.image).max() > 0.1


def test_integrator_draws_glossy_directions_from_the_lobe_with_the_renders_sampler():
    # the directions the integrator spawns: angle to the mirror direction follows the lobe
    # (cos^(n+1) of the angle is uniform), and each pixel's samples are stratified
    integrator = Integrator(glossy_ball_scene(0.25), settings(spp=16, sampler="jittered"))
    pixels, spp = 2000, 16
    pixel = np.repeat(np.arange(pixels), spp)
    sample_in_pixel = np.tile(np.arange(spp), pixels)
    k = pixels * spp
    mirror = np.tile([0.0, 0.0, 1.0], (k, 1))
    ng = mirror.copy()
    mat = np.full(k, 1, dtype=np.intp)
    reflection, _ = SecondaryRays(integrator).scattering.sample(
        mirror, mirror, ng, mat, None, None, lambda rows, weight: np.ones(len(weight), dtype=bool),
        lambda rows: integrator.sampler.glossy(pixel.take(rows), sample_in_pixel.take(rows), 2))
    wi = reflection.directions
    np.testing.assert_array_equal(reflection.weight, 0.85)  # the lobe is sampled exactly: weight kr
    n = roughness_exponent(0.25)
    u0 = 1.0 - wi[:, 2] ** (n + 1.0)
    counts, _ = np.histogram(u0, bins=20, range=(0, 1))
    assert stats.chisquare(counts).pvalue > 1e-3
    # the same numbers as the sampler's, for dimension GLOSSY + 2 * depth
    u = decorrelated_points("jittered", 0, pixel, sample_in_pixel, spp, Dim.GLOSSY + 4)
    np.testing.assert_allclose(u0, u[:, 0], atol=1e-9)


def test_roughness_scene_key_is_validated():
    base = {"objects": [{"primitive": "box", "material": "m"}],
            "lights": [{"type": "point", "position": [0, 0, 5], "intensity": 1}]}
    scene, _ = scene_from_dict({**base, "materials": {"m": {"mirror": 0.9, "roughness": 0.2}}})
    assert scene.materials.roughness[1] == 0.2 and scene.materials.any_glossy
    with pytest.raises(SceneError, match=r"materials\.m\.roughness: expected a number >= 0"):
        scene_from_dict({**base, "materials": {"m": {"roughness": -0.1}}})
    # roughness without anything to reflect enables nothing
    scene, _ = scene_from_dict({**base, "materials": {"m": {"roughness": 0.5}}})
    assert not scene.materials.any_glossy


def test_glossy_depth_of_field_render_is_bit_identical_across_threads_and_chunks():
    scene = glossy_ball_scene(0.2)
    scene.camera.aperture, scene.camera.focus_distance = 0.3, 5.0
    for sampler in ("jittered", "sobol"):
        one = render(scene, spp=4, sampler=sampler, threads=1, chunk_samples=100000)
        two = render(scene, spp=4, sampler=sampler, threads=2, chunk_samples=200)
        assert {"glossy", "lens"} <= set(one.stats.stages_enabled)
        np.testing.assert_array_equal(one.image, two.image)


def test_the_glossy_lobe_weight_is_its_value_over_its_density_and_the_density_integrates_to_one():
    """SpecularScattering's three answers agree: sample's weight = evaluate / pdf, and pdf is
    a density (its integral over the sphere, by uniform sphere sampling, is 1)."""
    materials = MaterialTable([Material("default"), Material("rough", mirror=[0.8, 0.6, 0.4], roughness=0.3),
                               Material("smooth", mirror=0.5)])
    scattering = SpecularScattering(materials)
    rng = np.random.default_rng(11)
    k = 200_000
    ns = np.tile([0.0, 0.0, 1.0], (k, 1))
    wo = np.tile([0.6, 0.0, 0.8], (k, 1))
    wi = rng.normal(size=(k, 3))
    wi /= np.linalg.norm(wi, axis=1)[:, None]
    rough, smooth = np.full(k, 1, dtype=np.intp), np.full(k, 2, dtype=np.intp)
    pdf = scattering.pdf(wo, ns, rough, wi)
    assert abs(pdf.mean() * 4.0 * np.pi - 1.0) < 0.02
    value = scattering.evaluate(wo, ns, rough, wi)
    inside = pdf > 0
    np.testing.assert_allclose(value[inside] / pdf[inside, None], np.broadcast_to([0.8, 0.6, 0.4], value[inside].shape))
    # a smooth mirror is a delta lobe: no value toward any other direction, infinite density
    assert (scattering.evaluate(wo[:10], ns[:10], smooth[:10], wi[:10]) == 0).all()
    assert np.isinf(scattering.pdf(wo[:10], ns[:10], smooth[:10], wi[:10])).all()


def test_lobe_kernel_equals_the_numpy_formulation():
    # the compiled frame, lobe and fold must round as the NumPy they replaced: the same
    # directions, bit for bit, for any mirror direction (both hemispheres, the poles) and
    # roughness (exponents from 1 to 1e12)
    from rtmesh.core.vecmath import dot, orthonormal_basis

    rng = np.random.default_rng(11)
    k = 5000
    mirror = rng.normal(size=(k, 3))
    mirror[:4] = [[0, 0, 1], [0, 0, -1], [1e-9, 0, -1], [0, 1, 0]]
    mirror /= np.sqrt(dot(mirror, mirror))[:, None]
    ng = rng.normal(size=(k, 3))
    ng /= np.sqrt(dot(ng, ng))[:, None]
    roughness = 10.0 ** rng.uniform(-6, 0, k)
    u = rng.random((k, 2))
    u[:3, 0] = [0.0, np.nextafter(1.0, 0.0), 0.5]

    log_cos = np.log1p(-u[:, 0]) / (roughness_exponent(roughness) + 1.0)
    one_minus_cos = -np.expm1(log_cos)
    cos_theta = 1.0 - one_minus_cos
    sin_theta = np.sqrt(np.maximum(one_minus_cos * (1.0 + cos_theta), 0.0))
    phi = 2.0 * np.pi * u[:, 1]
    local = np.stack([sin_theta * np.cos(phi), sin_theta * np.sin(phi), cos_theta], axis=1)
    t, b = orthonormal_basis(mirror)
    wi = t * local[:, :1] + b * local[:, 1:2] + mirror * local[:, 2:3]
    fold = np.minimum(dot(wi, ng), 0.0)
    expected = wi - (2.0 * fold)[:, None] * ng

    np.testing.assert_array_equal(sample_glossy_directions(mirror, ng, roughness, u), expected)
    np.testing.assert_array_equal(square_to_phong_lobe(u, roughness_exponent(roughness)), local)


# ---------------------------------------------------------------- the lobe as a BSDF
def _rough_mirror(roughness=0.3):
    """SpecularScattering of a table whose material 1 is a rough mirror (kr 0.8)."""
    return SpecularScattering(MaterialTable([Material("default"), Material("rough", mirror=0.8,
                                                                            roughness=roughness)]))


def test_the_glossy_lobe_is_not_reciprocal_by_design():
    """Not reciprocal, by design (rtmesh.materials.glossy): the lobe is sampled exactly from its
    density so that every sample weighs kr, hence evaluate = f(wo, wi) |cos wi| = kr pdf(wi),
    the Phong density about the mirror direction R(wo).  That density is symmetric,
    wi . R(wo) = 2 (wo.n)(wi.n) - wo.wi = wo . R(wi), so f |cos wi| is, and f itself is not:
    f(wo, wi) / f(wi, wo) = cos wo / cos wi.  (The Phong lobe is reciprocal where f, not f cos,
    is the cos^n lobe: Lafortune and Willems 1994.)"""
    scattering = _rough_mirror()
    rng = np.random.default_rng(43)
    k = 5000
    wo, wi = (v / np.linalg.norm(v, axis=1)[:, None] for v in (rng.normal(size=(k, 3)), rng.normal(size=(k, 3))))
    wo[:, 2], wi[:, 2] = np.abs(wo[:, 2]), np.abs(wi[:, 2])
    ns, mat = np.tile([0.0, 0.0, 1.0], (k, 1)), np.full(k, 1, dtype=np.intp)
    forward, backward = scattering.evaluate(wo, ns, mat, wi), scattering.evaluate(wi, ns, mat, wo)
    assert np.count_nonzero(forward[:, 0]) > k // 4
    np.testing.assert_allclose(forward, backward, rtol=1e-9, atol=1e-15)
    # so f = evaluate / cos wi differs both ways by the ratio of the cosines
    f_forward, f_backward = forward / wi[:, 2:3], backward / wo[:, 2:3]
    np.testing.assert_allclose(f_forward * wi[:, 2:3], f_backward * wo[:, 2:3], rtol=1e-9, atol=1e-15)
    seen = forward[:, 0] > 1e-3
    assert np.max(np.abs(f_forward[seen, 0] / f_backward[seen, 0] - 1.0)) > 0.5


@pytest.mark.parametrize("theta_o", [0.0, 80.0])
def test_glossy_samples_pass_a_chi_square_test_against_the_pdf(theta_o):
    """What sample() returns (directions under the surface folded back above it) against
    pdf(), over the whole sphere, at normal and grazing incidence (roughness 0.3: at 80 degrees
    over a quarter of the unfolded lobe lies under the surface).  No sample fails, so the
    expected counts are pdf's integral over each bin, not rescaled to the drawn total: a pdf
    that put mass where sample() sends nothing fails."""
    scattering = _rough_mirror(0.3)
    n = 200_000
    rng = np.random.default_rng(47)
    wo = np.array([np.sin(np.radians(theta_o)), 0.0, np.cos(np.radians(theta_o))])
    ns = np.tile([0.0, 0.0, 1.0], (n, 1))
    reflection, _ = scattering.sample(np.tile(wo, (n, 1)), ns, ns, np.full(n, 1, dtype=np.intp), None, None,
                                      lambda rows, weight: np.ones(len(weight), dtype=bool),
                                      lambda rows: rng.random((len(rows), 2)))
    wi = reflection.directions
    assert len(wi) == n
    theta_bins, phi_bins, k = 10, 20, 24
    cos_edges, phi_edges = np.linspace(-1.0, 1.0, theta_bins + 1), np.linspace(-np.pi, np.pi, phi_bins + 1)
    observed, _, _ = np.histogram2d(wi[:, 2], np.arctan2(wi[:, 1], wi[:, 0]), [cos_edges, phi_edges])
    # pdf over each bin by a k x k midpoint rule, uniform in cos theta and phi (dw = dcos dphi)
    c = (cos_edges[:-1, None] + (np.arange(k) + 0.5) * (2.0 / theta_bins / k)).ravel()
    p = (phi_edges[:-1, None] + (np.arange(k) + 0.5) * (2.0 * np.pi / phi_bins / k)).ravel()
    cc, pp = np.meshgrid(c, p, indexing="ij")
    s = np.sqrt(1.0 - cc ** 2)
    directions = np.stack([s * np.cos(pp), s * np.sin(pp), cc], axis=-1).reshape(-1, 3)
    m = len(directions)
    density = scattering.pdf(np.tile(wo, (m, 1)), np.tile([0.0, 0.0, 1.0], (m, 1)), np.full(m, 1, dtype=np.intp),
                             directions)
    cell = (2.0 / theta_bins / k) * (2.0 * np.pi / phi_bins / k)
    expected = n * cell * density.reshape(theta_bins, k, phi_bins, k).sum(axis=(1, 3))
    o, e = observed.ravel(), expected.ravel()
    # bins expecting fewer than 5 samples pooled into one
    sparse = e < 5.0
    o, e = np.append(o[~sparse], o[sparse].sum()), np.append(e[~sparse], e[sparse].sum())
    if e[-1] < 5.0:
        o, e = o[:-1], e[:-1]
    assert len(e) > 20
    statistic = float(np.sum((o - e) ** 2 / e))
    assert stats.chi2.sf(statistic, len(e) - 1) > 1e-3, (
        f"chi2 {statistic:.0f} over {len(e)} bins; pdf's mass under the surface "
        f"{expected[:theta_bins // 2].sum() / n:.4f}, samples there {observed[:theta_bins // 2].sum() / n:.4f}")
