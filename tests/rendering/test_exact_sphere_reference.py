"""Whole renders of icospheres against the exact analytic sphere (benchmarks/analytic_sphere.py).

The reference intersects the true sphere in closed form and uses its exact normal, so the
difference is the tessellation error alone: it must fall steadily as subdivision rises, for
a lit Blinn-Phong sphere and for an absorbing glass sphere (refraction, Fresnel, total
internal reflection and Beer absorption all take part).
"""

import numpy as np
import pytest

from benchmarks.analytic_sphere import AnalyticSphere, intersect_sphere, render_analytic_image
from benchmarks.sphere_study import AMBIENT, BACKGROUND, CAMERA, CASES, LIGHTS, icosphere_scene
from rtmesh.rendering.integrator import Integrator
from rtmesh.rendering.settings import RenderSettings

SIZE = 64


def test_intersect_sphere_matches_scalar_quadratic():
    rng = np.random.default_rng(3)
    origins = rng.normal(size=(200, 3)) * 3
    directions = rng.normal(size=(200, 3))
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    t = intersect_sphere(origins, directions, np.zeros(3), 1.0)
    for o, d, ti in zip(origins, directions, t):
        b = o @ d
        c = o @ o - 1.0
        disc = b * b - c
        roots = [] if disc < 0 else [r for r in (-b - disc ** 0.5, -b + disc ** 0.5) if r > 1e-9]
        expected = min(roots) if roots else np.inf
        assert ti == pytest.approx(expected, rel=1e-9, abs=1e-12)


@pytest.mark.parametrize("case", sorted(CASES))
def test_icosphere_render_converges_to_exact_sphere(case):
    material = CASES[case]
    reference = render_analytic_image(
        AnalyticSphere(np.zeros(3), 1.0, material, LIGHTS, AMBIENT, BACKGROUND), CAMERA, SIZE, SIZE)
    scale = np.sqrt(np.mean(reference.astype(np.float64) ** 2))
    errors = []
    for subdivisions in (1, 3, 5):
        settings = RenderSettings(width=SIZE, height=SIZE, spp=1, sampler="regular", max_depth=5)
        image = Integrator(icosphere_scene(material, subdivisions), settings).render().image
        assert np.isfinite(image).all()
        errors.append(np.sqrt(np.mean((image.astype(np.float64) - reference) ** 2)) / scale)
    assert errors[0] > errors[1] > errors[2]
    # at 20480 triangles the image is within half a percent of the exact sphere
    assert errors[2] < 5e-3
