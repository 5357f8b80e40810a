"""Hard geometry for whole renders: rays along shared edges and vertices of glass cubes,
mirror corridors with glass between them, degenerate triangles and normals, a light on a
surface.

Every render goes through ``scenes.render``, which fails on NaN, Inf or negative values.
"""

from dataclasses import dataclass

import numpy as np
import pytest
import trimesh
from scenes import box, floor_quad, part, quad, render

from rtmesh.lights.point_lights import PointLight
from rtmesh.materials.table import Material
from rtmesh.scene.camera import Camera
from rtmesh.scene.model import MeshPart, Scene


@dataclass
class OrthographicCamera(Camera):
    """Parallel rays along the view direction from a square of side ``2 * half_width``.

    Pixel centres land on a grid of pitch ``2 * half_width / width`` centred on the view
    axis, so with an odd width the rays pass exactly through chosen edges and vertices.
    """

    half_width: float = 1.0

    def generate_rays(self, film_xy, width, height, lens_uv=None, pixels=None, frame=None):
        if pixels is not None:  # positions inside the pixels
            film_xy = film_xy + np.column_stack([pixels % width, pixels // width])
        forward, right, up = self.frame()
        pitch = 2.0 * self.half_width / width
        sx = (film_xy[:, 0] - 0.5 * width) * pitch
        sy = (0.5 * height - film_xy[:, 1]) * pitch
        origins = self.position + sx[:, None] * right + sy[:, None] * up
        return origins, np.tile(forward, (len(film_xy), 1))


# ---------------------------------------------------------------- shared edges and vertices
AXES = [(axis, sign) for axis in range(3) for sign in (-1.0, 1.0)]


def cube(lower, upper):
    """An axis-aligned box whose faces are split along the same diagonal on both sides.

    A face at x = c of one cube and the face at x = c of its neighbour are then the same two
    triangles (wound oppositely), which rtmesh.rendering.media crosses as one interface; boxes split
    along different diagonals would only overlap.
    """
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    vertices, faces = [], []
    for axis in range(3):
        u, v = (axis + 1) % 3, (axis + 2) % 3
        for side, level in ((1, upper[axis]), (-1, lower[axis])):
            corners = []
            for a, b in ((0, 0), (1, 0), (1, 1), (0, 1)):  # counter-clockwise about +axis
                point = np.zeros(3)
                point[axis], point[u], point[v] = level, (lower, upper)[a][u], (lower, upper)[b][v]
                corners.append(point)
            first = len(vertices)
            vertices += corners
            triangles = [[0, 1, 2], [0, 2, 3]] if side > 0 else [[0, 2, 1], [0, 3, 2]]
            faces += [[first + k for k in t] for t in triangles]
    return np.array(vertices), np.array(faces)


@pytest.mark.parametrize("axis, sign", AXES)
def test_rays_through_shared_edges_and_vertices_of_glass_cubes_cross_each_cube_once(axis, sign):
    # Eight unit cubes of absorbing, index-matched glass form a 2x2x2 block [-1, 1]^3; cubes
    # share faces (coincident twins), edges and vertices.  Parallel rays along an axis on a
    # 1/8 grid pass exactly through the shared edges (x or y = 0), the eight-cube vertex
    # (0, 0), the triangles' diagonals and the outer edges.  A crack would let a ray skip
    # a surface, a double hit would push a medium twice; either changes the absorption, and
    # a stack that is not empty again on leaving absorbs the ray completely.
    sigma = np.array([0.3, 0.6, 0.9])
    background = np.array([1.0, 2.0, 3.0])
    corners = np.stack(np.meshgrid(*[[-1.0, 0.0]] * 3), -1).reshape(-1, 3)
    cubes = [part(f"cube{i}", cube(c, c + 1.0)) for i, c in enumerate(corners)]
    assert trimesh.Trimesh(*cube(corners[0], corners[0] + 1.0)).is_volume  # closed, outward
    glass = Material("glass", diffuse=0.0, transmission=1.0, ior=1.0, absorption=sigma)
    forward = np.zeros(3)
    forward[axis] = sign
    up = np.zeros(3)
    up[(axis + 1) % 3] = 1.0
    width = 21  # pitch 1/8: offsets -1.25 .. 1.25 across the view axis
    camera = OrthographicCamera(-5.0 * forward, np.zeros(3), up, half_width=width / 16.0)
    scene = Scene.from_parts(cubes, [glass], [], camera, background=background)
    # in, through the shared face, out: three surfaces
    result = render(scene, width=width, height=width, max_depth=3)
    image = result.image.reshape(-1, 3)
    offsets = (np.arange(width) - width // 2) / 8.0
    u, v = np.meshgrid(offsets, -offsets)
    u, v = u.ravel(), v.ravel()
    inside = (np.abs(u) < 1.0) & (np.abs(v) < 1.0)
    outside = (np.abs(u) > 1.0) | (np.abs(v) > 1.0)
    through = background * np.exp(-2.0 * sigma)
    assert inside.sum() == 15 * 15
    np.testing.assert_allclose(image[inside], np.broadcast_to(through, (inside.sum(), 3)),
                               rtol=1e-5)
    np.testing.assert_array_equal(image[outside], np.broadcast_to(background.astype(np.float32),
                                                                   (outside.sum(), 3)))
    # rays along the block's outer faces lie in their planes: either they meet the block or
    # not, but never more than all of it, and never less
    boundary = ~inside & ~outside
    assert (image[boundary] >= through.astype(np.float32) * (1 - 1e-5)).all()
    assert (image[boundary] <= background.astype(np.float32)).all()
    # every inside ray crossed exactly three surfaces
    assert result.stats.rays["refraction"] >= 3 * inside.sum()


# ---------------------------------------------------------------- mirror corridors
def corridor_ray_counts(max_depth):
    """Exact reflection and refraction ray counts per camera ray in the glass corridor.

    States are (region, heading): A (between the left mirror and the glass), G (in the glass),
    B (between the glass and the right mirror), heading +x or -x.  Each hit on the glass
    spawns a reflection and a refraction ray, each mirror hit one reflection.
    """
    states = ["A+", "A-", "G+", "G-", "B+", "B-"]
    # state -> [(spawned state, kind)]
    spawns = {"A+": [("A-", "reflection"), ("G+", "refraction")],
              "A-": [("A+", "reflection")],
              "G+": [("G-", "reflection"), ("B+", "refraction")],
              "G-": [("G+", "reflection"), ("A-", "refraction")],
              "B+": [("B-", "reflection")],
              "B-": [("B+", "reflection"), ("G-", "refraction")]}
    count = dict.fromkeys(states, 0)
    count["A+"] = 1
    totals = {"reflection": 0, "refraction": 0}
    for _ in range(max_depth):
        spawned = dict.fromkeys(states, 0)
        for state, rays in count.items():
            for target, kind in spawns[state]:
                spawned[target] += rays
                totals[kind] += rays
        count = spawned
    return totals


@pytest.mark.parametrize("max_depth", [1, 4, 8])
def test_glass_between_facing_mirrors_traces_exactly_the_ray_tree(max_depth):
    # mirrors at x = -1 and x = 1, a glass plate 0.2..0.4 between them, camera at x = -0.5
    # looking toward +x: every ray stays between the mirrors forever, so the ray counts are
    # exactly those of the tree above (it grows by at most 2 per level), and the image is black
    size = 1e3
    left = quad([[-1, -size, -size], [-1, size, -size], [-1, size, size], [-1, -size, size]])
    right = quad([[1, -size, -size], [1, -size, size], [1, size, size], [1, size, -size]])
    plate = box((0.2, 2 * size, 2 * size), (0.3, 0.0, 0.0))
    materials = [Material("mirror", diffuse=0.0, mirror=1.0),
                 Material("glass", diffuse=0.0, transmission=1.0, ior=1.5)]
    camera = Camera([-0.5, 0.0, 0.0], [1.0, 0.3, 0.1], [0.0, 0.0, 1.0], 30.0)
    parts = [part("left", left, 0), part("right", right, 0), part("plate", plate, 1)]
    scene = Scene.from_parts(parts, materials, [], camera, background=[1.0, 1.0, 1.0])
    result = render(scene, width=12, height=10, max_depth=max_depth, cutoff=0.0)
    camera_rays = result.stats.rays["camera"]
    expected = corridor_ray_counts(max_depth)
    assert result.stats.rays["reflection"] == expected["reflection"] * camera_rays
    assert result.stats.rays["refraction"] == expected["refraction"] * camera_rays
    assert sum(expected.values()) <= 2 ** (max_depth + 1) - 2
    np.testing.assert_array_equal(result.image, 0.0)


# ---------------------------------------------------------------- degenerate input
def dirty_box():
    """A unit box plus faces that cannot render, and unusable vertex normals.

    Returns the clean box (smooth, with zero normals at three corners, so the faces there
    shade flat) and the same box with, appended: a triangle on one point, a triangle along
    an edge (collinear), a sliver 1e-12 wide along an edge (non-zero area in float64, none
    in float32), and at those three corners normals that are zero, NaN and infinite.
    """
    mesh = box((1.0, 1.0, 1.0), (0.0, 0.0, 0.5))
    corner, other = mesh.vertices[0], mesh.vertices[1]
    extra = np.array([corner, corner, corner,
                      corner, 0.5 * (corner + other), other,
                      corner, other, 0.5 * (corner + other) + [1e-12, 1e-12, 1e-12]])
    vertices = np.concatenate([mesh.vertices, extra])
    faces = np.concatenate([mesh.faces, np.arange(9).reshape(3, 3) + len(mesh.vertices)])
    normals = np.concatenate([mesh.vertex_normals, np.zeros((9, 3))])
    normals[0] = 0.0
    normals[1] = np.nan
    normals[2] = [np.inf, 0.0, 0.0]
    clean_normals = mesh.vertex_normals.copy()
    clean_normals[:3] = 0.0
    return (MeshPart("clean", mesh.vertices, mesh.faces, 0, clean_normals),
            MeshPart("dirty", vertices, faces, 0, normals))


@pytest.mark.parametrize("kind", ["diffuse", "glass"])
def test_degenerate_triangles_and_normals_change_nothing(kind, caplog):
    clean, dirty = dirty_box()
    material = (Material("m", diffuse=0.6, specular=0.3) if kind == "diffuse" else
                Material("m", diffuse=0.1, transmission=0.9, ior=1.5, absorption=0.2))
    floor = part("floor", floor_quad(5.0), 1)
    camera = Camera([1.5, -2.5, 2.0], [0.0, 0.0, 0.3], [0.0, 0.0, 1.0], 45.0)
    light = [PointLight([2.0, -1.0, 4.0], 20.0)]

    def image(box_part):
        scene = Scene.from_parts([box_part, floor], [material, Material("f", diffuse=0.5)], light,
                                 camera, background=[0.1, 0.2, 0.3])
        return scene, render(scene, width=40, height=30, max_depth=4).image

    reference_scene, reference = image(clean)
    scene, result = image(dirty)
    # the zero-area faces are dropped by name; the sliver survives in float64 ...
    assert "dropped 2 zero-area faces" in caplog.text
    assert len(scene.faces) == len(reference_scene.faces) + 1
    # ... but is never hit, and faces touching unusable normals shade flat
    np.testing.assert_array_equal(scene.smooth[:12], reference_scene.smooth[:12])
    assert 0 < reference_scene.smooth[:12].sum() < 12
    np.testing.assert_array_equal(result, reference)


def test_degenerate_mesh_normals_from_trimesh_stay_finite():
    # trimesh gives zero normals to vertices used only by zero-area faces; smooth shading
    # must not turn them into NaN anywhere
    mesh = trimesh.creation.icosphere(2)
    vertices = np.concatenate([mesh.vertices, [[0.0, 0.0, 0.0]] * 3])
    faces = np.concatenate([mesh.faces, [[len(mesh.vertices)] * 3]])
    normals = np.concatenate([mesh.vertex_normals, np.zeros((3, 3))])
    scene = Scene.from_parts([MeshPart("ball", vertices, faces, 0, normals)],
                             [Material("m", diffuse=0.5, mirror=0.3)],
                             [PointLight([2.0, -2.0, 3.0], 10.0)],
                             Camera([0.0, -4.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 40.0))
    assert np.isfinite(scene.vertex_normals).all()
    result = render(scene, width=24, height=24)
    assert result.image.max() > 0.0


# ---------------------------------------------------------------- a light on a surface
def test_point_light_on_a_box_face_lights_only_what_faces_it():
    # A point light exactly at the centre of the +x face of an opaque box standing on a
    # floor.  Floor points in front of that face (x > 0.5) are lit exactly as by a free
    # point light; those behind it are in the box's shadow; the box itself is dark (the
    # light lies in the plane of the face it sits on, and below the top).
    box_part = part("box", box((1.0, 1.0, 1.0), (0.0, 0.0, 0.5)), 0)
    floor = part("floor", floor_quad(4.0), 1)
    light_position = np.array([0.5, 0.0, 0.5])
    intensity = 3.0
    camera = Camera([0.0, 0.0, 8.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 40.0)
    materials = [Material("box", diffuse=0.7), Material("f", diffuse=0.5)]
    scene = Scene.from_parts([box_part, floor], materials, [PointLight(light_position, intensity)],
                             camera)
    width = height = 64
    result = render(scene, width=width, height=height)
    # floor points of the pixel centres, from the pinhole model
    half = np.tan(np.radians(20.0))
    column, row = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    x = (2.0 * column / width - 1.0) * half * 8.0
    y = (1.0 - 2.0 * row / height) * half * 8.0
    image = result.image[..., 0]
    # seen straight from above only the box top shows, where the ray is at 7/8 of its
    # floor offset (z = 1); a margin keeps pixels on its edge out of both sets
    top = (np.abs(x) * 7.0 / 8.0 < 0.49) & (np.abs(y) * 7.0 / 8.0 < 0.49)
    on_box = (np.abs(x) * 7.0 / 8.0 < 0.51) & (np.abs(y) * 7.0 / 8.0 < 0.51)
    np.testing.assert_array_equal(image[top], 0.0)
    to_light = np.stack([light_position[0] - x, light_position[1] - y, np.full_like(x, 0.5)], -1)
    distance = np.linalg.norm(to_light, axis=-1)
    expected = 0.5 * intensity * 0.5 / distance ** 3  # kd I cos / d^2, cos = 0.5 / d
    in_front = (x > 0.52) & ~on_box
    behind = (x < 0.48) & ~on_box & (np.abs(y) < 3.9)
    assert in_front.sum() > 500 and behind.sum() > 500
    np.testing.assert_allclose(image[in_front], expected[in_front], rtol=1e-5)
    np.testing.assert_array_equal(image[behind], 0.0)
