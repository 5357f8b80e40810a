"""Closed meshes are watertight to Embree: no ray slips through a shared edge or vertex.

For each closed mesh there is an analytic solid it must contain (the inscribed sphere of an
icosphere, a slightly shrunken box, a thinner torus or capsule): every ray that meets that
solid must hit the mesh.  Rays aimed exactly at vertices and along edges must hit as well.
"""

import math

import numpy as np
import pytest
import trimesh
from scenes import box, icosphere, part, pixel_centre_rays, ray_sphere_distances, render

from rtmesh.geometry.accel import Accel
from rtmesh.materials.table import Material
from rtmesh.scene.camera import Camera
from rtmesh.scene.model import Scene

VIEWS = 20
WIDTH = HEIGHT = 40


def random_cameras(centre, radius, count, seed):
    """Cameras on a sphere of directions around ``centre``, framing a ball of ``radius``."""
    rng = np.random.default_rng(seed)
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    cameras = []
    for direction in directions:
        up = [0.0, 0.0, 1.0] if abs(direction[2]) < 0.9 else [1.0, 0.0, 0.0]
        distance = 4.0 * radius
        fov = 2.0 * math.degrees(math.asin(radius / distance)) * 1.1
        cameras.append(Camera(centre + distance * direction, centre, up, fov))
    return cameras


def camera_rays(camera):
    return pixel_centre_rays(camera, WIDTH, HEIGHT)


# ---------------------------------------------------------------- analytic solids
def ray_hits_box(origins, directions, lower, upper):
    """Slab test: does each ray meet the axis-aligned box [lower, upper]?"""
    with np.errstate(divide="ignore", invalid="ignore"):
        inverse = 1.0 / directions
        t0 = (lower - origins) * inverse
        t1 = (upper - origins) * inverse
    near = np.nanmax(np.minimum(t0, t1), axis=1)
    far = np.nanmin(np.maximum(t0, t1), axis=1)
    return (far >= np.maximum(near, 0.0))


def line_to_segment_distance(origins, directions, start, end):
    """Distance from each (infinite) line to the segment start-end."""
    axis = end - start
    length2 = axis @ axis
    w = origins - start
    b = directions @ axis
    d = np.einsum("ij,ij->i", directions, w)
    e = w @ axis
    denominator = length2 - b * b  # directions are unit
    # segment parameter of the closest approach of the two infinite lines, clamped to the
    # segment (the distance is convex in it, so clamping gives the segment's closest point)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(denominator > 1e-12, (e - b * d) / denominator, 0.0)
    s = np.clip(s, 0.0, 1.0)
    closest_on_segment = start + s[:, None] * axis
    t = np.einsum("ij,ij->i", closest_on_segment - origins, directions)
    closest_on_line = origins + t[:, None] * directions
    return np.linalg.norm(closest_on_line - closest_on_segment, axis=1)


def line_to_circle_distance(origins, directions, major_radius, span):
    """Approximate distance from each line to the circle of ``major_radius`` in z = 0.

    Dense sampling along the line over ``span`` around its closest approach to the origin;
    the result overestimates the true distance by at most half a step.
    """
    closest = -np.einsum("ij,ij->i", origins, directions)
    steps = np.linspace(-span, span, 601)
    step = steps[1] - steps[0]
    distance = np.full(len(origins), np.inf)
    for chunk in range(0, len(origins), 200):
        o, d, c = origins[chunk:chunk + 200], directions[chunk:chunk + 200], closest[chunk:chunk + 200]
        points = o[:, None, :] + (c[:, None] + steps[None, :])[..., None] * d[:, None, :]
        radial = np.hypot(points[..., 0], points[..., 1]) - major_radius
        distance[chunk:chunk + 200] = np.hypot(radial, points[..., 2]).min(axis=1)
    return distance, 0.5 * step


# ---------------------------------------------------------------- shapes
def assert_every_ray_into_the_solid_hits(accel, origins, directions, must_hit, label):
    hits = accel.intersect(origins, directions)
    leaked = must_hit & ~hits.hit
    assert must_hit.sum() > 100, label
    assert not leaked.any(), f"{label}: {leaked.sum()} rays slipped through the mesh"
    return hits


def test_icosphere_silhouette_has_no_holes_from_any_direction():
    radius, centre = 1.3, np.array([0.2, -0.1, 0.4])
    mesh = icosphere(3, radius, centre)
    accel = Accel(mesh.vertices, mesh.faces)
    inscribed = np.min(np.einsum("ij,ij->i", mesh.triangles[:, 0] - centre, mesh.face_normals))
    for view, camera in enumerate(random_cameras(centre, radius, VIEWS, 0)):
        origins, directions = camera_rays(camera)
        must_hit = np.isfinite(ray_sphere_distances(origins, directions, centre, inscribed * (1 - 1e-6)))
        hits = assert_every_ray_into_the_solid_hits(accel, origins, directions, must_hit, f"view {view}")
        cannot_hit = ~np.isfinite(ray_sphere_distances(origins, directions, centre, radius * (1 + 1e-6)))
        assert not (hits.hit & cannot_hit).any()


def test_box_silhouette_has_no_holes_from_any_direction():
    extents, centre = np.array([1.0, 1.6, 0.7]), np.array([0.3, 0.0, -0.2])
    mesh = box(extents, centre)
    accel = Accel(mesh.vertices, mesh.faces)
    lower, upper = centre - extents / 2, centre + extents / 2
    shrink = 1e-5 * extents
    for view, camera in enumerate(random_cameras(centre, np.linalg.norm(extents) / 2, VIEWS, 1)):
        origins, directions = camera_rays(camera)
        must_hit = ray_hits_box(origins, directions, lower + shrink, upper - shrink)
        hits = assert_every_ray_into_the_solid_hits(accel, origins, directions, must_hit, f"view {view}")
        assert not (hits.hit & ~ray_hits_box(origins, directions, lower - shrink, upper + shrink)).any()


def test_torus_silhouette_has_no_holes_from_any_direction():
    major, minor, sections = 1.0, 0.35, (48, 24)
    mesh = trimesh.creation.torus(major_radius=major, minor_radius=minor,
                                  major_sections=sections[0], minor_sections=sections[1])
    assert mesh.is_watertight
    accel = Accel(mesh.vertices, mesh.faces)
    # the polygonal tube holds a round tube this much thinner: the minor polygon's inradius,
    # less how far the polygonal core strays from the circle
    safe_minor = (minor * math.cos(math.pi / sections[1])
                  - (major + minor) * (1 - math.cos(math.pi / sections[0])))
    for view, camera in enumerate(random_cameras(np.zeros(3), major + minor, VIEWS, 2)):
        origins, directions = camera_rays(camera)
        distance, error = line_to_circle_distance(origins, directions, major, 2.0 * (major + minor))
        must_hit = distance + error < 0.99 * safe_minor
        assert_every_ray_into_the_solid_hits(accel, origins, directions, must_hit, f"view {view}")


def test_capsule_silhouette_has_no_holes_from_any_direction():
    height, radius, count = 1.5, 0.5, (32, 32)
    mesh = trimesh.creation.capsule(height=height, radius=radius, count=count)
    assert mesh.is_watertight
    accel = Accel(mesh.vertices, mesh.faces)
    # the capsule's axis is z; its caps are centred one radius inside its ends
    z = mesh.vertices[:, 2]
    start = np.array([0.0, 0.0, z.min() + radius])
    end = np.array([0.0, 0.0, z.max() - radius])
    safe_radius = radius * math.cos(math.pi / min(count)) ** 2
    centre = 0.5 * (start + end)
    for view, camera in enumerate(random_cameras(centre, height / 2 + radius, VIEWS, 3)):
        origins, directions = camera_rays(camera)
        must_hit = line_to_segment_distance(origins, directions, start, end) < 0.99 * safe_radius
        assert_every_ray_into_the_solid_hits(accel, origins, directions, must_hit, f"view {view}")


def test_rays_from_inside_closed_meshes_always_hit_a_back_face():
    # a hole anywhere would let some of these rays escape
    rng = np.random.default_rng(4)
    directions = rng.normal(size=(20000, 3))
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    torus = trimesh.creation.torus(major_radius=1.0, minor_radius=0.3)
    cases = [
        (icosphere(3, 1.0), np.zeros(3)),
        (box((1.0, 2.0, 0.5)), np.array([0.1, -0.3, 0.05])),
        (trimesh.creation.capsule(height=1.0, radius=0.4), np.array([0.0, 0.0, 0.5])),
        (torus, np.array([1.0, 0.0, 0.0])),
    ]
    for mesh, inside in cases:
        assert mesh.is_watertight
        accel = Accel(mesh.vertices, mesh.faces)
        origins = np.broadcast_to(inside, directions.shape)
        hits = accel.intersect(origins, directions)
        assert hits.hit.all()
        assert (np.einsum("ij,ij->i", directions, mesh.face_normals[hits.prim]) > 0.0).all()


# ---------------------------------------------------------------- exact edges and vertices
def test_axis_aligned_rays_through_box_vertices_and_edges_hit():
    lower, upper = np.array([-0.5, -1.0, -0.25]), np.array([0.5, 1.0, 0.25])
    mesh = box(upper - lower, (lower + upper) / 2)
    accel = Accel(mesh.vertices, mesh.faces)
    for axis in range(3):
        for sign in (-1.0, 1.0):
            u, v = [a for a in range(3) if a != axis]
            # grid over the face seen along this axis, including its corners, edges and diagonal
            a = np.linspace(lower[u], upper[u], 9)
            b = np.linspace(lower[v], upper[v], 9)
            aa, bb = np.meshgrid(a, b)
            count = aa.size
            origins = np.zeros((count, 3))
            origins[:, u], origins[:, v] = aa.ravel(), bb.ravel()
            origins[:, axis] = -sign * 10.0
            directions = np.zeros((count, 3))
            directions[:, axis] = sign
            hits = accel.intersect(origins, directions)
            assert hits.hit.all(), f"axis {axis} sign {sign}: {(~hits.hit).sum()} misses"
            near_face = lower[axis] if sign > 0 else upper[axis]
            np.testing.assert_allclose(hits.t, 10.0 + sign * near_face, rtol=1e-6)


def test_rays_aimed_at_icosphere_vertices_and_edge_midpoints_hit_there():
    mesh = icosphere(2, 1.0)
    accel = Accel(mesh.vertices, mesh.faces)
    edges = mesh.edges_unique
    targets = np.concatenate([mesh.vertices, mesh.vertices[edges].mean(axis=1)])
    vertex_faces = [row[row >= 0] for row in mesh.vertex_faces]
    edge_faces = [np.intersect1d(vertex_faces[a], vertex_faces[b]) for a, b in edges]
    assert all(len(faces) == 2 for faces in edge_faces)
    target_faces = vertex_faces + edge_faces
    rng = np.random.default_rng(5)
    for _ in range(3):
        # from random viewpoints, aim at every target visible from there
        viewpoint = rng.normal(size=3)
        viewpoint = 5.0 * viewpoint / np.linalg.norm(viewpoint)
        directions = targets - viewpoint
        distance = np.linalg.norm(directions, axis=1)
        directions /= distance[:, None]
        # the ray must enter the solid at the target, not just touch it: every face around the
        # target faces the viewpoint (a ray grazing a vertex of a convex mesh may miss it)
        visible = np.array([(mesh.face_normals[faces] @ direction < 0.0).all()
                            for faces, direction in zip(target_faces, directions)])
        assert visible.sum() > 100
        hits = accel.intersect(np.broadcast_to(viewpoint, targets.shape)[visible], directions[visible])
        assert hits.hit.all()
        np.testing.assert_allclose(hits.t, distance[visible], rtol=0, atol=2e-4)


# ---------------------------------------------------------------- rendered
@pytest.mark.parametrize("shape", ["icosphere", "box"])
def test_rendered_closed_mesh_shows_no_background_inside_its_silhouette(shape):
    # a bright background makes any pixel that sees through the mesh stand out
    if shape == "icosphere":
        mesh, centre, size = icosphere(3, 1.0), np.zeros(3), 1.0
    else:
        mesh, centre, size = box((1.2, 1.2, 1.2)), np.zeros(3), 1.04
    material = Material("dark", diffuse=0.0, ambient=0.0)
    background = np.array([1.0, 2.0, 3.0])
    for view, camera in enumerate(random_cameras(centre, size, 4, 6)):
        scene = Scene.from_parts([part(shape, mesh)], [material], [], camera, background=background)
        image = render(scene, width=WIDTH, height=HEIGHT).image.reshape(-1, 3)
        origins, directions = camera_rays(camera)
        if shape == "icosphere":
            inscribed = np.min(np.einsum("ij,ij->i", mesh.triangles[:, 0], mesh.face_normals))
            inside = np.isfinite(ray_sphere_distances(origins, directions, centre, 0.999 * inscribed))
        else:
            inside = ray_hits_box(origins, directions, np.full(3, -0.5999), np.full(3, 0.5999))
        assert inside.sum() > 100
        np.testing.assert_array_equal(image[inside], 0.0)
        # and the background is really there outside
        assert (image[~inside] > 0).any()
