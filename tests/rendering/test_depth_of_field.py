"""Depth of field: the thin-lens camera against the circle of confusion.

Derivation used by the reference.  The camera sits at the origin looking down -z; the lens
is the disk of diameter A around it in the plane z = 0, and the ray of lens point
``(lx, ly, 0)`` through the film position with image-plane coordinates ``(sx, sy)`` (at
unit distance) passes through the focus point ``(f sx, f sy, -f)``.  At depth d it is at
``x = lx + (f sx - lx) d / f = sx d + lx (1 - d / f)``.  A vertical edge ``x = x_e`` at depth
d is crossed where ``sx = x_e / d - lx (1/d - 1/f)``: every lens point sees the edge
shifted by ``lx (1/d - 1/f)`` in image-plane units.  Over the lens, the edge is blurred by
the distribution of ``lx`` (a disk's marginal) scaled by ``|1/d - 1/f|``: a circle of
confusion of diameter ``A |d - f| / (d f)`` image-plane units, i.e. ``A |d - f| / d`` on the
focus plane, or ``A |d - f| / (d f) * H / (2 tan(fov / 2))`` pixels.  At d = f it vanishes.
"""

import numpy as np
import pytest
from scenes import part, quad, render

from rtmesh.materials.table import Material
from rtmesh.scene.camera import Camera
from rtmesh.scene.model import Scene

WIDTH, HEIGHT = 96, 12
# the image spans sx in [-0.6, 0.6] (80 pixels per image-plane unit)
FOV = 2.0 * np.degrees(np.arctan(0.6 * HEIGHT / WIDTH))
EDGE_SX = 0.4  # the edge is seen off-axis (column 80 of 96)


def edge_scene(depth, aperture=0.0, focus=None):
    """An emissive half-plane x >= x_e at depth ``depth`` (fronto-parallel), black elsewhere."""
    x_edge = EDGE_SX * depth
    far = 100.0 * depth
    half_plane = part("half plane", quad([[x_edge, -far, -depth], [far, -far, -depth],
                                          [far, far, -depth], [x_edge, far, -depth]]), 0)
    camera = Camera([0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0], FOV, aperture=aperture,
                    focus_distance=focus)
    light = Material(diffuse=0.0, ambient=0.0, emission=1.0)
    return Scene.from_parts([half_plane], [light], [], camera)


def disk_marginal_cdf(a):
    """P(x <= a) for x the first coordinate of a uniform point of the unit disk."""
    a = np.clip(a, -1.0, 1.0)
    return 0.5 + (a * np.sqrt(1.0 - a * a) + np.arcsin(a)) / np.pi


def edge_profile(coc_px, grid=400):
    """Expected value of each pixel column: the edge (in column coordinates at
    ``EDGE_SX``) blurred by a disk of diameter ``coc_px`` pixels, averaged over the pixel."""
    edge_column = (EDGE_SX + 0.6) / 1.2 * WIDTH
    x = np.arange(WIDTH)[:, None] + (np.arange(grid) + 0.5)[None, :] / grid
    if coc_px == 0:
        return (x >= edge_column).mean(axis=1)
    return disk_marginal_cdf((x - edge_column) / (0.5 * coc_px)).mean(axis=1)


def column_profile(result):
    return result.image[:, :, 0].mean(axis=0)


def circle_of_confusion_px(aperture, depth, focus):
    tan_half = np.tan(np.radians(FOV) / 2.0)
    return aperture * abs(depth - focus) / (depth * focus) * HEIGHT / (2.0 * tan_half)


def test_an_edge_on_the_focus_plane_is_as_sharp_as_with_a_pinhole():
    # off-axis, so that a lens focusing on a sphere of radius f instead of the plane at
    # depth f (1.5 pixels of blur here) would fail
    pinhole = render(edge_scene(4.0), width=WIDTH, height=HEIGHT, spp=16, sampler="jittered",
                     max_depth=0)
    lens = render(edge_scene(4.0, aperture=1.0, focus=4.0), width=WIDTH, height=HEIGHT, spp=16,
                  sampler="jittered", max_depth=0)
    assert "lens" in lens.stats.stages_enabled
    # both see the same film positions; every lens ray through one meets the pinhole ray
    # on the edge's plane, so only rounding at the edge itself can differ
    assert np.abs(lens.image - pinhole.image).max() <= 1.0 / 16 + 1e-6
    np.testing.assert_allclose(column_profile(pinhole), edge_profile(0.0), atol=0.05)
    np.testing.assert_allclose(column_profile(lens), edge_profile(0.0), atol=0.05)


@pytest.mark.parametrize("focus", [2.5, 8.0])
def test_an_out_of_focus_edge_blurs_by_the_circle_of_confusion(focus):
    aperture, depth = 0.4, 4.0
    coc = circle_of_confusion_px(aperture, depth, focus)
    assert coc > 2.5  # several pixels: the blur is measurable
    result = render(edge_scene(depth, aperture, focus), width=WIDTH, height=HEIGHT, spp=64,
                    sampler="jittered", max_depth=0)
    measured = column_profile(result)
    np.testing.assert_allclose(measured, edge_profile(coc), atol=0.04)
    # the blur diameter that fits the measured profile best is the thin-lens one
    candidates = np.linspace(0.5 * coc, 1.5 * coc, 101)
    errors = [np.square(measured - edge_profile(c, grid=100)).sum() for c in candidates]
    fitted = candidates[int(np.argmin(errors))]
    assert fitted == pytest.approx(coc, rel=0.05)
