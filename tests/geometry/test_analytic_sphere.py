"""Icospheres traced through Embree against the exact sphere they approximate.

An icosphere's vertices lie on its sphere (radius r), so the mesh is a convex polyhedron
between two spheres: the circumscribed one (radius r) and the inscribed one, whose radius is
the smallest distance from the centre to a face plane.  Every exact statement below comes
from that sandwich.
"""

import math

import numpy as np
import pytest
from scenes import icosphere, part, pixel_centre_rays, ray_sphere_distance, ray_sphere_distances, render

from rtmesh.geometry.accel import Accel
from rtmesh.lights.point_lights import DirectionalLight, PointLight
from rtmesh.materials.table import Material
from rtmesh.scene.camera import Camera
from rtmesh.scene.model import Scene

CENTRE = np.array([0.3, -0.2, 0.1])
RADIUS = 1.5
SUBDIVISIONS = [2, 3, 4, 5]


def inscribed_radius(mesh, centre):
    """Smallest distance from ``centre`` to the plane of any face."""
    normals = mesh.face_normals
    return float(np.min(np.einsum("ij,ij->i", mesh.triangles[:, 0] - centre, normals)))


def rays_towards_sphere(count, seed, aim_radius):
    """Rays from a shell of radius 4 r around the sphere, aimed at points within ``aim_radius``."""
    rng = np.random.default_rng(seed)
    start = rng.normal(size=(count, 3))
    start = CENTRE + 4.0 * RADIUS * start / np.linalg.norm(start, axis=1)[:, None]
    target = rng.normal(size=(count, 3))
    target = target / np.linalg.norm(target, axis=1)[:, None]
    target = CENTRE + target * aim_radius * rng.random((count, 1)) ** (1.0 / 3.0)
    directions = target - start
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    return start, directions


def test_vectorised_sphere_reference_matches_scalar_reference():
    rng = np.random.default_rng(0)
    origins = rng.normal(size=(300, 3)) * 3.0
    directions = rng.normal(size=(300, 3))
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    t = ray_sphere_distances(origins, directions, CENTRE, RADIUS)
    for i in range(len(origins)):
        expected = ray_sphere_distance(origins[i].tolist(), directions[i].tolist(), CENTRE.tolist(), RADIUS)
        if expected is None:
            assert np.isinf(t[i])
        else:
            assert t[i] == pytest.approx(expected, rel=1e-12)
    # closed form for a ray through the centre
    assert ray_sphere_distance([0.0, 0.0, -5.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0], 2.0) == 3.0


def test_camera_rays_through_pixel_centres_match_the_pinhole_model():
    camera = Camera([1.0, -4.0, 2.0], [0.0, 0.5, 0.2], [0.0, 0.0, 1.0], 38.0)
    width, height = 9, 6
    column, row = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    film_xy = np.column_stack([column.ravel(), row.ravel()])
    origins, directions = camera.generate_rays(film_xy, width, height)
    expected_origins, expected_directions = pixel_centre_rays(camera, width, height)
    np.testing.assert_allclose(origins, expected_origins, atol=1e-15)
    np.testing.assert_allclose(directions, expected_directions, atol=1e-14)
    # the middle of the film looks at look_at; row 0 is the top of the image
    middle = camera.generate_rays(np.array([[width / 2, height / 2]]), width, height)[1][0]
    forward = (camera.look_at - camera.position) / np.linalg.norm(camera.look_at - camera.position)
    np.testing.assert_allclose(middle, forward, atol=1e-14)
    assert directions[0, 2] > directions[-1, 2]


@pytest.mark.parametrize("subdivisions", SUBDIVISIONS)
def test_icosphere_hits_lie_between_the_inscribed_and_the_exact_sphere(subdivisions):
    mesh = icosphere(subdivisions, RADIUS, CENTRE)
    inner = inscribed_radius(mesh, CENTRE)
    assert 0.9 * RADIUS < inner < RADIUS
    accel = Accel(mesh.vertices, mesh.faces)
    origins, directions = rays_towards_sphere(4000, subdivisions, 0.999 * inner)
    hits = accel.intersect(origins, directions)
    # every ray that meets the inscribed sphere must hit the mesh
    assert hits.hit.all()
    outer_t = ray_sphere_distances(origins, directions, CENTRE, RADIUS)
    inner_t = ray_sphere_distances(origins, directions, CENTRE, inner)
    # float32 tracing: allow a few ulps of the coordinates (|p| ~ 6)
    slack = 4e-6 * 4.0 * RADIUS
    assert (hits.t >= outer_t - slack).all()
    assert (hits.t <= inner_t + slack).all()
    # the hit point Accel reconstructs lies on the triangle it reports, in the same shell
    points = accel.hit_points(hits)
    distance = np.linalg.norm(points - CENTRE, axis=1)
    assert (distance >= inner - 1e-5).all() and (distance <= RADIUS + 1e-5).all()
    np.testing.assert_allclose(points, origins + hits.t[:, None] * directions, atol=1e-4)


@pytest.mark.parametrize("subdivisions", SUBDIVISIONS)
def test_icosphere_face_normals_are_within_the_tessellation_angle(subdivisions):
    mesh = icosphere(subdivisions, RADIUS, CENTRE)
    accel = Accel(mesh.vertices, mesh.faces)
    origins, directions = rays_towards_sphere(3000, 10 + subdivisions, 0.9 * RADIUS)
    hits = accel.intersect(origins, directions)
    hit = hits.hit
    prim = hits.prim[hit]
    points = accel.hit_points(hits, hit)
    exact_normals = (points - CENTRE) / np.linalg.norm(points - CENTRE, axis=1)[:, None]
    face_normals = mesh.face_normals[prim]
    angle = np.arccos(np.clip(np.einsum("ij,ij->i", exact_normals, face_normals), -1.0, 1.0))
    # on a face at distance d from the centre the radial direction strays from the face normal
    # by at most acos(d / r) (reached at the vertices)
    face_distance = np.einsum("ij,ij->i", mesh.triangles[prim, 0] - CENTRE, face_normals)
    bound = np.arccos(np.clip(face_distance / RADIUS, -1.0, 1.0))
    assert (angle <= bound + 1e-5).all()
    # and the rays hit the outside of the faces they report
    assert (np.einsum("ij,ij->i", directions[hit], face_normals) < 0.0).all()


def hit_errors(subdivisions):
    """Max |t_mesh - t_exact| for head-on-ish rays, and the tessellation bound r - d_min."""
    mesh = icosphere(subdivisions, RADIUS, CENTRE)
    accel = Accel(mesh.vertices, mesh.faces)
    origins, directions = rays_towards_sphere(4000, 99, 0.3 * RADIUS)
    hits = accel.intersect(origins, directions)
    exact = ray_sphere_distances(origins, directions, CENTRE, RADIUS)
    return np.abs(hits.t - exact).max(), RADIUS - inscribed_radius(mesh, CENTRE)


def test_icosphere_hit_distance_error_falls_with_subdivision():
    errors, bounds = zip(*(hit_errors(s) for s in SUBDIVISIONS))
    for error, bound, subdivisions in zip(errors, bounds, SUBDIVISIONS):
        # these rays meet the sphere within ~17 degrees of its normal
        assert error <= bound / math.cos(math.radians(20.0)) + 1e-5, subdivisions
    # halving the edges divides the sagitta by about 4
    for coarse, fine in zip(errors, errors[1:]):
        assert fine < coarse / 2.5
    for coarse, fine in zip(bounds, bounds[1:]):
        assert 3.5 < coarse / fine < 4.5


# ---------------------------------------------------------------- rendered sphere
def analytic_lit_sphere(camera, width, height, light_direction, irradiance, diffuse):
    """Per-pixel Lambert radiance of the exact sphere under a directional light, black elsewhere."""
    origins, directions = pixel_centre_rays(camera, width, height)
    t = ray_sphere_distances(origins, directions, CENTRE, RADIUS)
    hit = np.isfinite(t)
    points = origins + np.where(hit, t, 0.0)[:, None] * directions
    normals = (points - CENTRE) / RADIUS
    to_light = -np.asarray(light_direction, dtype=np.float64)
    to_light /= np.linalg.norm(to_light)
    cosine = np.maximum(normals @ to_light, 0.0)
    radiance = np.where(hit[:, None], diffuse * irradiance * cosine[:, None], 0.0)
    return radiance.reshape(height, width, 3), hit.reshape(height, width)


def render_lit_sphere(subdivisions, smooth, width=64, height=64):
    light_direction = np.array([-1.0, 0.6, -0.8])
    camera = Camera(CENTRE + np.array([0.0, -6.0, 1.5]), CENTRE, [0.0, 0.0, 1.0], 35.0)
    mesh = icosphere(subdivisions, RADIUS, CENTRE)
    diffuse = np.array([0.8, 0.6, 0.4])
    scene = Scene.from_parts([part("sphere", mesh, smooth=smooth)], [Material("s", diffuse=diffuse)],
                             [DirectionalLight(light_direction, 1.5)], camera)
    image = render(scene, width=width, height=height, spp=1, sampler="regular").image
    expected, hit = analytic_lit_sphere(camera, width, height, light_direction, 1.5, diffuse)
    return image, expected, hit


def test_rendered_smooth_sphere_converges_to_the_analytic_image():
    errors = []
    for subdivisions in SUBDIVISIONS:
        image, expected, _ = render_lit_sphere(subdivisions, smooth=True)
        errors.append(np.abs(image - expected).mean())
    assert errors[-1] < 2e-4
    for coarse, fine in zip(errors, errors[1:]):
        assert fine < coarse
    assert errors[-1] < errors[0] / 20.0


def test_rendered_sphere_interior_matches_analytic_lambert_closely():
    # away from the silhouette (where tessellation moves the edge) and the terminator (where
    # the geometric normal decides what is lit), smooth shading of a fine icosphere matches the
    # exact sphere to within the normal interpolation error
    image, expected, hit = render_lit_sphere(5, smooth=True)
    camera = Camera(CENTRE + np.array([0.0, -6.0, 1.5]), CENTRE, [0.0, 0.0, 1.0], 35.0)
    origins, directions = pixel_centre_rays(camera, 64, 64)
    interior = np.isfinite(ray_sphere_distances(origins, directions, CENTRE, 0.95 * RADIUS)).reshape(64, 64)
    well_lit = expected[..., 0] > 0.1 * expected[..., 0].max()
    mask = interior & well_lit
    assert mask.sum() > 500
    np.testing.assert_allclose(image[mask], expected[mask], rtol=5e-3, atol=1e-4)
    # and outside the exact silhouette there is only background
    assert (image[~hit] == 0.0).all()


def test_smooth_normals_beat_flat_normals_against_the_analytic_sphere():
    smooth_image, expected, _ = render_lit_sphere(3, smooth=True)
    flat_image, _, _ = render_lit_sphere(3, smooth=False)
    smooth_error = np.abs(smooth_image - expected).mean()
    flat_error = np.abs(flat_image - expected).mean()
    assert smooth_error < 0.5 * flat_error


def test_rendered_point_lit_sphere_matches_inverse_square_lambert():
    # a point light: the analytic reference includes the distance to each hit point
    light_position = CENTRE + np.array([2.0, -3.0, 2.5])
    camera = Camera(CENTRE + np.array([0.0, -6.0, 0.0]), CENTRE, [0.0, 0.0, 1.0], 35.0)
    scene = Scene.from_parts([part("sphere", icosphere(5, RADIUS, CENTRE), smooth=True)],
                             [Material("s", diffuse=0.7)], [PointLight(light_position, 20.0)], camera)
    width = height = 48
    image = render(scene, width=width, height=height).image.reshape(-1, 3)
    origins, directions = pixel_centre_rays(camera, width, height)
    t = ray_sphere_distances(origins, directions, CENTRE, RADIUS)
    interior = np.isfinite(ray_sphere_distances(origins, directions, CENTRE, 0.95 * RADIUS))
    points = origins + np.where(np.isfinite(t), t, 0.0)[:, None] * directions
    normals = (points - CENTRE) / RADIUS
    to_light = light_position - points
    distance = np.linalg.norm(to_light, axis=1)
    cosine = np.einsum("ij,ij->i", normals, to_light) / distance
    falloff = 0.7 * 20.0 / distance ** 2
    mask = interior & (cosine > 0.1)
    assert mask.sum() > 200
    # divide out kd I / d^2 and compare cosines: smooth normals of a subdivision-5 icosphere
    # are within ~2e-3 of the exact normal
    np.testing.assert_allclose(image[mask, 0] / falloff[mask], cosine[mask], atol=2e-3)
