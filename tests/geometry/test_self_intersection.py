"""Spawned rays never re-hit the surface they leave (accel.offset_ray_origins).

Points are taken on many triangles of an icosphere and a box, both convex, so the right
answer for a ray leaving a surface point is known exactly: a ray leaving to the outside
must miss everything, and a ray leaving to the inside must run to the far side of the
solid, exactly where the convex polyhedron's planes say it exits.  Each case is repeated
with the geometry scaled and moved far from the origin (Accel does not re-centre).
"""

import numpy as np
import pytest
from scenes import box, icosphere, pixel_centre_rays, ray_sphere_distances, render, sphere_on_floor_scene

from rtmesh.geometry.accel import Accel, float32_ulp, offset_ray_origins

SHAPES = {
    "icosphere": lambda: icosphere(3, 1.0),
    "box": lambda: box((1.0, 1.4, 0.8)),
}

# (translation, scale) of the geometry handed to Accel
PLACEMENTS = {
    "unit": (0.0, 1.0),
    "scaled-1e-3": (0.0, 1e-3),
    "scaled-1e3": (0.0, 1e3),
    "translated-1e5-scaled-1e3": (1e5, 1e3),
    "translated-1e5": (1e5, 1.0),
}
POINT_SOURCES = ["inside", "edges", "ray-hits"]


def cases():
    """(shape, translation, scale, point_source) parameters."""
    return [pytest.param(shape, translation, scale, source, id=f"{shape}-{placement}-{source}")
            for shape in SHAPES
            for placement, (translation, scale) in PLACEMENTS.items()
            for source in POINT_SOURCES]


def placed_accel(mesh, translation, scale):
    """Accel over the mesh scaled about the origin, then translated along (1, 1, 1)."""
    vertices = mesh.vertices * scale + translation * np.array([1.0, 0.7, -0.4])
    return Accel(vertices, mesh.faces)


def unit_geometric_normals(accel, prim):
    """Outward unit normals of the float32 triangles Embree traces."""
    tri = accel.vertices[accel.faces[prim]]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    return n / np.linalg.norm(n, axis=1)[:, None]


def surface_points(accel, count, seed, where="inside"):
    """Points on random triangles, at random barycentrics.

    ``where`` is "inside" (strictly inside the triangles) or "edges" (half on an edge, half
    at a vertex, where the point also lies on the neighbouring triangles).
    """
    rng = np.random.default_rng(seed)
    prim = rng.integers(0, len(accel.faces), count)
    barycentric = rng.random((count, 3)) + 1e-3
    if where == "edges":
        half = count // 2
        barycentric[:half, 0] = 0.0
        barycentric[half:] = np.eye(3)[rng.integers(0, 3, count - half)]
    barycentric /= barycentric.sum(axis=1)[:, None]
    tri = accel.vertices[accel.faces[prim]]
    points = np.einsum("ij,ijk->ik", barycentric, tri)
    return points, prim


def hit_surface_points(accel, count, seed):
    """Points where rays from outside hit the mesh, reconstructed as the integrator does."""
    rng = np.random.default_rng(seed)
    centre = accel.vertices.mean(axis=0)
    size = np.ptp(accel.vertices, axis=0).max()
    start = rng.normal(size=(count, 3))
    start = centre + 3.0 * size * start / np.linalg.norm(start, axis=1)[:, None]
    target = centre + (rng.random((count, 3)) - 0.5) * 0.5 * size
    directions = target - start
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    hits = accel.intersect(start, directions)
    assert hits.hit.all()
    return accel.hit_points(hits), hits.prim


def random_directions_on_side(normals, seed):
    """Uniform random unit directions in the hemisphere around ``normals``."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=normals.shape)
    d /= np.linalg.norm(d, axis=1)[:, None]
    return np.where((np.einsum("ij,ij->i", d, normals) < 0.0)[:, None], -d, d)


def convex_exit_distance(accel, origins, directions):
    """Exact distance to where rays starting inside a convex mesh leave it (float64 planes)."""
    tri = accel.vertices[accel.faces]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    offsets = np.einsum("ij,ij->i", normals, tri[:, 0])
    exit_t = np.full(len(origins), np.inf)
    for start in range(0, len(origins), 500):
        o, d = origins[start:start + 500], directions[start:start + 500]
        facing = d @ normals.T  # (rays, faces)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (offsets[None, :] - o @ normals.T) / facing
        t = np.where(facing > 0.0, t, np.inf)
        exit_t[start:start + 500] = t.min(axis=1)
    return exit_t


def signed_plane_distance(accel, points, prim):
    normals = unit_geometric_normals(accel, prim)
    return np.einsum("ij,ij->i", points - accel.vertices[accel.faces[prim, 0]], normals)


def size_of(accel):
    return float(np.ptp(accel.vertices, axis=0).max())


@pytest.mark.parametrize("shape, translation, scale, point_source", cases())
def test_spawned_rays_leaving_outward_never_reintersect(shape, translation, scale, point_source):
    accel = placed_accel(SHAPES[shape](), translation, scale)
    if point_source != "ray-hits":
        points, prim = surface_points(accel, 4000, 1, point_source)
    else:
        points, prim = hit_surface_points(accel, 4000, 2)
    normals = unit_geometric_normals(accel, prim)
    directions = random_directions_on_side(normals, 3)
    origins = offset_ray_origins(points, normals, directions=directions)
    # the offset lands on the side the ray leaves toward, and is exactly float32
    assert (signed_plane_distance(accel, origins, prim) > 0.0).all()
    np.testing.assert_array_equal(origins, origins.astype(np.float32).astype(np.float64))
    # a convex solid seen from outside its own surface: nothing to hit
    hits = accel.intersect(origins, directions)
    assert not hits.hit.any(), f"{hits.hit.sum()} of {len(hits)} reflection rays re-hit the surface"
    # shadow rays toward lights at any distance are never blocked by the surface they leave
    for t_max in (np.full(len(origins), 10.0 * size_of(accel)), np.full(len(origins), np.inf)):
        assert not accel.occluded(origins, directions, t_max).any()


@pytest.mark.parametrize("shape, translation, scale, point_source", cases())
def test_spawned_rays_leaving_inward_reach_the_far_side(shape, translation, scale, point_source):
    accel = placed_accel(SHAPES[shape](), translation, scale)
    if point_source != "ray-hits":
        points, prim = surface_points(accel, 2000, 4, point_source)
    else:
        points, prim = hit_surface_points(accel, 2000, 5)
    normals = unit_geometric_normals(accel, prim)
    directions = random_directions_on_side(-normals, 6)
    # from an edge or vertex, half of those directions leave the solid at once through a
    # neighbouring face (the exit is at t = 0); only rays that really go into the solid,
    # by more than the offset, must reach the far side
    exit_distance = convex_exit_distance(accel, points, directions)
    into = exit_distance > 1e-3 * size_of(accel)
    assert into.mean() > (0.4 if point_source == "edges" else 0.99)
    # nor can a ray that leaves within a few float32 grid steps of the coordinates (1/128
    # at |x| ~ 1e5): rounding the point to float32 already moves it that much
    into &= exit_distance > 4.0 * np.spacing(np.float32(np.abs(accel.vertices).max()))
    points, prim, normals, directions = points[into], prim[into], normals[into], directions[into]
    # the integrator's scale: the size of the (re-centred) scene
    origins = offset_ray_origins(points, -normals, scale=0.5 * size_of(accel), directions=directions)
    # the origin moved inside the solid, not through it
    assert (signed_plane_distance(accel, origins, prim) < 0.0).all()
    assert (convex_exit_distance(accel, origins, normals) < np.inf).all()
    hits = accel.intersect(origins, directions)
    assert hits.hit.all(), f"{(~hits.hit).sum()} refraction rays escaped the solid"
    assert not (hits.prim == prim).any(), "a refraction ray re-hit the triangle it left"
    # never a hit on the plane the ray left (a box face is two coplanar triangles)
    same_plane = np.abs(np.einsum("ij,ij->i", unit_geometric_normals(accel, hits.prim), normals) - 1.0) < 1e-6
    assert not same_plane.any()
    # and the hit is where the ray really leaves the convex solid
    expected = convex_exit_distance(accel, origins, directions)
    tolerance = 1e-5 * (abs(translation) + size_of(accel))
    np.testing.assert_allclose(hits.t, expected, rtol=0, atol=tolerance)
    # rays heading well into the sphere (within 60 degrees of the inward face normal, which
    # is within ~6 degrees of the radial one) cross a good part of it: chord 2 r cos(66 deg)
    steep = np.einsum("ij,ij->i", directions, -normals) > 0.5
    if shape == "icosphere":
        assert (hits.t[steep] > 0.4 * size_of(accel)).all()


def test_rays_leaving_a_concave_edge_away_from_the_wall_escape():
    # an L: floor z = 0 for x >= 0, wall x = 0 for z >= 0, meeting along the y axis
    vertices = np.array([[0, -5, 0], [5, -5, 0], [5, 5, 0], [0, 5, 0],
                         [0, -5, 0], [0, 5, 0], [0, 5, 5], [0, -5, 5]], dtype=np.float64)
    faces = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    accel = Accel(vertices, faces)
    rng = np.random.default_rng(7)
    count = 500
    points = np.column_stack([np.zeros(count), rng.uniform(-4.0, 4.0, count), np.zeros(count)])
    up = np.tile([0.0, 0.0, 1.0], (count, 1))
    # every direction above the floor and away from the wall (+x) sees open sky, down to
    # rays that leave the wall at a thousandth of a radian
    directions = np.abs(rng.normal(size=(count, 3))) * np.array([1.0, np.sign(rng.normal()), 1.0])
    directions[:50, 0] = 1e-3
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    origins = offset_ray_origins(points, up, directions=directions)
    hits = accel.intersect(origins, directions)
    assert not hits.hit.any(), f"{hits.hit.sum()} of {count} rays hit the wall at t = {hits.t[hits.hit][:3]}"


def test_rays_leaving_near_a_concave_edge_away_from_the_wall_escape():
    # the same, a thousandth of a unit from the wall: the offset guard works there
    vertices = np.array([[0, -5, 0], [5, -5, 0], [5, 5, 0], [0, 5, 0],
                         [0, -5, 0], [0, 5, 0], [0, 5, 5], [0, -5, 5]], dtype=np.float64)
    faces = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    accel = Accel(vertices, faces)
    rng = np.random.default_rng(8)
    count = 500
    points = np.column_stack([np.full(count, 1e-3), rng.uniform(-4.0, 4.0, count), np.zeros(count)])
    up = np.tile([0.0, 0.0, 1.0], (count, 1))
    directions = np.abs(rng.normal(size=(count, 3))) + np.array([0.05, 0.0, 0.0])
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    assert not accel.intersect(offset_ray_origins(points, up, directions=directions), directions).hit.any()
    # and toward the wall they do hit it, at the right distance
    toward = directions * np.array([-1.0, 1.0, 1.0])
    origins = offset_ray_origins(points, up, directions=toward)
    hits = accel.intersect(origins, toward)
    assert hits.hit.all()
    np.testing.assert_allclose(hits.t, origins[:, 0] / directions[:, 0], rtol=1e-4)


# ---------------------------------------------------------------- rendered: no shadow acne
def floor_reference(scene, width, height):
    """Expected floor radiance per pixel, and which pixels see the floor fully lit.

    A floor pixel counts only if its camera ray misses the sphere and the segment from its
    floor point to the light passes clear of the sphere (circumscribed radius plus a margin).
    """
    camera = scene.camera
    light = scene.lights[0]
    origins, directions = pixel_centre_rays(camera, width, height)
    floor_z = scene.bounds[0, 2]
    t = (floor_z - origins[:, 2]) / directions[:, 2]
    points = origins + t[:, None] * directions
    sphere_vertices = scene.vertices[np.unique(scene.faces[scene.object_id == 0])]
    sphere_centre = sphere_vertices.mean(axis=0)
    radius = 1.05 * np.linalg.norm(sphere_vertices - sphere_centre, axis=1).max()

    def segment_misses_sphere(starts, ends):
        along = ends - starts
        length = np.linalg.norm(along, axis=1)
        along = along / length[:, None]
        s = np.clip(np.einsum("ij,ij->i", sphere_centre - starts, along), 0.0, length)
        closest = starts + s[:, None] * along
        return np.linalg.norm(closest - sphere_centre, axis=1) > radius

    visible = (t > 0) & segment_misses_sphere(origins, points)
    lit = segment_misses_sphere(points, np.broadcast_to(light.position, points.shape))
    inside_floor = (np.abs(points[:, :2] - sphere_centre[:2]) < 7.9).all(axis=1)
    to_light = light.position - points
    distance = np.linalg.norm(to_light, axis=1)
    cosine = to_light[:, 2] / distance
    expected = 0.5 * light.intensity[None, :] * (cosine / distance ** 2)[:, None]
    return expected.reshape(height, width, 3), (visible & lit & inside_floor).reshape(height, width)


def test_lit_floor_beside_a_sphere_shows_no_shadow_acne():
    width, height = 96, 72
    scene = sphere_on_floor_scene()
    image = render(scene, width=width, height=height).image
    expected, lit_floor = floor_reference(scene, width, height)
    assert lit_floor.sum() > 3000
    assert (image[lit_floor] > 0.0).all()
    np.testing.assert_allclose(image[lit_floor], expected[lit_floor], rtol=1e-6)
    # the sphere's shadow is there (the shadow rays do hit the sphere)
    shadowed = (~lit_floor) & (image[..., 0] == 0.0)
    assert shadowed.sum() > 50


def test_lit_sphere_shows_no_shadow_acne():
    width = height = 128
    scene = sphere_on_floor_scene(subdivisions=4, smooth=True)
    camera = scene.camera
    origins, directions = pixel_centre_rays(camera, width, height)
    centre, light = np.array([0.0, 0.0, 1.0]), scene.lights[0].position
    inscribed = 0.99  # well inside the tessellated surface
    t = ray_sphere_distances(origins, directions, centre, 1.0)
    interior = np.isfinite(ray_sphere_distances(origins, directions, centre, inscribed))
    points = origins + np.where(np.isfinite(t), t, 0.0)[:, None] * directions
    normals = points - centre
    to_light = light - points
    cosine = np.einsum("ij,ij->i", normals, to_light) / np.linalg.norm(to_light, axis=1)
    facing_light = interior & (cosine > 0.3)
    assert facing_light.sum() > 300
    image = render(scene, width=width, height=height).image.reshape(-1, 3)
    # every pixel of the sphere that faces the light is lit, as the exact sphere would be
    # (smooth normals of a subdivision-4 icosphere: within a few per cent)
    expected = 0.6 * 30.0 * cosine / np.linalg.norm(to_light, axis=1) ** 2
    ratio = image[facing_light, 0] / expected[facing_light]
    assert ratio.min() > 0.97 and ratio.max() < 1.03


def test_scene_far_from_the_origin_renders_like_the_scene_at_the_origin():
    width, height = 64, 48
    near = render(sphere_on_floor_scene(), width=width, height=height).image
    far = render(sphere_on_floor_scene(shift=(1e5, -2e5, 1e5)), width=width, height=height).image
    expected, lit_floor = floor_reference(sphere_on_floor_scene(), width, height)
    # the integrator re-centres the scene, so float32 sees the same small coordinates
    np.testing.assert_allclose(far[lit_floor], expected[lit_floor], rtol=1e-5)
    differing = np.abs(far - near) > 1e-4 * (near.max())
    assert differing.mean() < 0.002
    assert np.abs(far - near).mean() < 1e-5


def test_float32_ulp_is_numpy_spacing_for_normal_floats():
    rng = np.random.default_rng(3)
    x = (rng.normal(size=(1000, 3)) * 10.0 ** rng.integers(-30, 30, size=(1000, 3))).astype(np.float32)
    x = np.concatenate([x, np.float32([[1.0, -2.0, 2.0 ** -126], [3e38, -0.5, 1e-20]])])
    assert np.array_equal(float32_ulp(x), np.spacing(np.abs(x)))
    assert float32_ulp(np.asfortranarray(x)).flags.f_contiguous
    assert float32_ulp(np.float32([0.0]))[0] == 0.0
