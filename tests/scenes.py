"""Tiny scenes built in code, scalar reference functions, and a checked render helper.

Everything here is shared by several test modules.  The scalar references are written
for readability (one ray at a time, whole-word names), not speed: the vectorised rtmesh
code is compared against them.
"""

import math
import os

import numpy as np
import trimesh

from rtmesh.lights.point_lights import PointLight
from rtmesh.materials.table import Material
from rtmesh.rendering.integrator import Integrator
from rtmesh.rendering.settings import RenderSettings
from rtmesh.scene.background import EnvironmentBackground, latlong_directions
from rtmesh.scene.camera import Camera
from rtmesh.scene.model import MeshPart, Scene


# the test folder (this file's), its data, the repository and its assets: test modules live
# in subfolders that mirror the package, and reach these through here
TESTS = os.path.dirname(os.path.abspath(__file__))
DATA = os.path.join(TESTS, "data")
ROOT = os.path.dirname(TESTS)
ASSETS = os.path.join(ROOT, "assets")


# ---------------------------------------------------------------- geometry builders
def icosphere(subdivisions=3, radius=1.0, centre=(0.0, 0.0, 0.0)):
    """A trimesh icosphere of ``radius`` around ``centre`` (vertices exactly on the sphere)."""
    mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    mesh.apply_translation(centre)
    return mesh


def box(extents=(1.0, 1.0, 1.0), centre=(0.0, 0.0, 0.0)):
    """An axis-aligned trimesh box of ``extents`` around ``centre``."""
    mesh = trimesh.creation.box(extents=extents)
    mesh.apply_translation(centre)
    return mesh


def quad(corners):
    """Two triangles spanning four corners given counter-clockwise seen from the front.

    Returns
    -------
    vertices : (4, 3) float
    faces : (2, 3) int
    """
    vertices = np.asarray(corners, dtype=np.float64).reshape(4, 3)
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    return vertices, faces


def floor_quad(half_size=10.0, height=0.0):
    """A square in the plane z = ``height`` facing +z."""
    s = half_size
    return quad([[-s, -s, height], [s, -s, height], [s, s, height], [-s, s, height]])


def part(name, mesh_or_arrays, material=0, smooth=False):
    """A MeshPart from a trimesh mesh or a (vertices, faces) pair."""
    if isinstance(mesh_or_arrays, trimesh.Trimesh):
        vertices, faces = mesh_or_arrays.vertices, mesh_or_arrays.faces
        normals = mesh_or_arrays.vertex_normals if smooth else None
    else:
        vertices, faces = mesh_or_arrays
        normals = None
    return MeshPart(name, np.array(vertices, dtype=np.float64), np.array(faces), material, normals)


def sphere_on_floor_scene(shift=(0.0, 0.0, 0.0), subdivisions=3, smooth=False):
    """A diffuse sphere resting on a diffuse floor, lit by one point light, seen from above.

    ``shift`` moves everything (geometry, camera and light) by the same vector.
    """
    shift = np.asarray(shift, dtype=np.float64)
    sphere = icosphere(subdivisions, 1.0, np.array([0.0, 0.0, 1.0]) + shift)
    floor_vertices, floor_faces = floor_quad(8.0)
    parts = [part("sphere", sphere, 0, smooth), part("floor", (floor_vertices + shift, floor_faces), 1)]
    materials = [Material("sphere", diffuse=0.6), Material("floor", diffuse=0.5)]
    lights = [PointLight(np.array([2.0, -1.0, 6.0]) + shift, 30.0)]
    camera = Camera(np.array([0.0, -7.0, 6.0]) + shift, np.array([0.0, 0.0, 0.0]) + shift,
                    [0.0, 0.0, 1.0], 50.0)
    return Scene.from_parts(parts, materials, lights, camera)


# ---------------------------------------------------------------- scalar references
def scattered_transforms(count, seed=3):
    """(count, 4, 4) model-to-world transforms: random rotations, non-uniform scales (every
    seventh mirroring) and positions over a floor (instancing tests)."""
    rng = np.random.default_rng(seed)
    out = np.tile(np.eye(4), (count, 1, 1))
    for j in range(count):
        s = rng.uniform(0.3, 0.7)
        rotation = trimesh.transformations.rotation_matrix(rng.uniform(0, 2 * np.pi), rng.normal(size=3))
        scale = np.diag([s * (-1 if j % 7 == 0 else 1), s * rng.uniform(0.7, 1.3), s, 1.0])
        out[j] = trimesh.transformations.translation_matrix(
            [rng.uniform(-5, 5), s + 0.1, rng.uniform(-5, 5)]) @ rotation @ scale
    return out


def reusing_glb(path, count=50, subdivisions=3, instancing=False):
    """A GLB whose ``count`` nodes place one textured, smooth sphere (1280 triangles at 3
    subdivisions) over a floor; with ``instancing`` one node places it by
    EXT_mesh_gpu_instancing instead (instancing tests)."""
    from PIL import Image

    ball = trimesh.creation.icosphere(subdivisions, radius=0.6)
    uv = ball.vertices[:, :2] * (0.5 / 0.6) + 0.5
    checker = (np.indices((8, 8)).sum(0) % 2)[..., None] * np.array([200, 60, 30]) + 40
    ball.visual = trimesh.visual.TextureVisuals(uv=uv, material=trimesh.visual.material.PBRMaterial(
        baseColorTexture=Image.fromarray(checker.astype(np.uint8)), metallicFactor=0.0, roughnessFactor=0.5))
    floor = trimesh.creation.box(extents=[14, 0.2, 14])
    floor.visual = trimesh.visual.TextureVisuals(material=trimesh.visual.material.PBRMaterial(
        baseColorFactor=[0.3, 0.6, 0.9, 1.0], metallicFactor=0.0, roughnessFactor=0.7))
    scene = trimesh.Scene()
    scene.add_geometry(floor, node_name="floor", transform=trimesh.transformations.translation_matrix([0, -0.1, 0]))
    transforms = scattered_transforms(count)
    scene.add_geometry(ball, node_name="ball0", geom_name="ball", transform=np.eye(4) if instancing else transforms[0])
    for j in range(1, 1 if instancing else count):
        scene.graph.update(frame_to=f"ball{j}", frame_from=scene.graph.base_frame, geometry="ball",
                           matrix=transforms[j])  # the same mesh again
    data = trimesh.exchange.gltf.export_glb(scene, include_normals=True)
    if instancing:
        import gltf_codecs

        doc, _ = gltf_codecs.split_glb(data)
        node = next(k for k, n in enumerate(doc["nodes"]) if n.get("name") == "ball0")
        quaternions = np.array([trimesh.transformations.quaternion_from_matrix(t) for t in transforms])
        data = gltf_codecs.gpu_instanced_glb(data, node, transforms[:, :3, 3], quaternions[:, [1, 2, 3, 0]],
                                             np.full((count, 3), 0.5))
    path.write_bytes(data)
    return path


def block_means(image, size=8):
    """(h // size, w // size, c): the means of ``size`` x ``size`` pixel blocks of an image."""
    h, w = image.shape[0] // size * size, image.shape[1] // size * size
    return image[:h, :w].reshape(h // size, size, w // size, size, -1).mean(axis=(1, 3))


def ray_sphere_distance(origin, direction, centre, radius):
    """Distance to the first hit of a ray with a sphere, or None when it misses.

    Hits behind the origin do not count; a ray starting inside returns the exit distance.
    """
    oc = [origin[i] - centre[i] for i in range(3)]
    a = sum(d * d for d in direction)
    half_b = sum(oc[i] * direction[i] for i in range(3))
    c = sum(x * x for x in oc) - radius * radius
    discriminant = half_b * half_b - a * c
    if discriminant < 0.0:
        return None
    root = math.sqrt(discriminant)
    for t in ((-half_b - root) / a, (-half_b + root) / a):
        if t > 0.0:
            return t
    return None


def ray_sphere_distances(origins, directions, centre, radius):
    """Vectorised closed-form ray-sphere distance; ``inf`` for misses.

    Used for whole images, after it has been checked against :func:`ray_sphere_distance`.
    """
    oc = origins - np.asarray(centre, dtype=np.float64)
    a = np.einsum("ij,ij->i", directions, directions)
    half_b = np.einsum("ij,ij->i", oc, directions)
    c = np.einsum("ij,ij->i", oc, oc) - radius * radius
    discriminant = half_b * half_b - a * c
    root = np.sqrt(np.maximum(discriminant, 0.0))
    near = (-half_b - root) / a
    far = (-half_b + root) / a
    t = np.where(near > 0.0, near, far)
    return np.where((discriminant >= 0.0) & (t > 0.0), t, np.inf)


def pixel_centre_rays(camera, width, height):
    """Camera rays through every pixel centre, row-major (row 0 at the top).

    Written from the pinhole model, independently of :meth:`Camera.generate_rays`.
    """
    forward = camera.look_at - camera.position
    forward = forward / np.linalg.norm(forward)
    right = np.cross(forward, camera.up)
    right = right / np.linalg.norm(right)
    up = np.cross(right, forward)
    half_height = math.tan(math.radians(camera.fov) / 2.0)
    half_width = half_height * width / height
    column, row = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    screen_x = (2.0 * column.ravel() / width - 1.0) * half_width
    screen_y = (1.0 - 2.0 * row.ravel() / height) * half_height
    directions = forward + screen_x[:, None] * right + screen_y[:, None] * up
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    origins = np.broadcast_to(camera.position, directions.shape).copy()
    return origins, directions


# ---------------------------------------------------------------- rendering
def settings(**overrides):
    """Small, fast, deterministic render settings; keyword arguments override."""
    values = dict(width=32, height=32, spp=1, sampler="regular", max_depth=5, seed=0, threads=1)
    values.update(overrides)
    return RenderSettings(**values)


def render(scene, **overrides):
    """Render with :func:`settings` and check the image and every pass are finite.

    Every render in the suite goes through here, so no test can pass on a NaN image.
    """
    result = Integrator(scene, settings(**overrides)).render()
    assert_finite(result)
    return result


def assert_finite(result):
    """No NaN or Inf in the image or in any pass of a RenderResult."""
    assert result.image.dtype == np.float32
    assert np.isfinite(result.image).all(), "rendered image holds NaN or Inf"
    assert (result.image >= 0.0).all(), "rendered image holds negative radiance"
    for name, image in result.passes.items():
        if name == "depth_center":  # +inf marks a pixel-centre ray that meets nothing
            assert not np.isnan(image).any() and (image > 0).all(), "depth_center holds NaN or <= 0"
        elif name in ("position_center", "normal_center"):  # NaN in every channel of a miss
            miss = np.isnan(image)
            assert (miss == miss[..., :1]).all() and np.isfinite(image[~miss]).all(), f"pass {name!r}"
        else:
            assert np.isfinite(image).all(), f"pass {name!r} holds NaN or Inf"


# ---------------------------------------------------------------- scenes shared by several test folders
def every_stage_scene(aperture=0.0):
    """Diffuse floor, a specular sphere, a mirror box and an absorbing glass sphere."""
    parts = [
        part("floor", floor_quad(6.0), 0),
        part("diffuse", icosphere(2, 0.6, (-1.4, 0.5, 0.6)), 1, smooth=True),
        part("mirror", box((0.8, 0.8, 1.6), (0.0, 1.2, 0.8)), 2),
        part("glass", icosphere(3, 0.7, (1.3, -0.4, 0.7)), 3, smooth=True),
    ]
    materials = [
        Material("floor", diffuse=[0.6, 0.55, 0.5]),
        Material("plastic", diffuse=[0.2, 0.4, 0.8], specular=0.4, shininess=40.0),
        Material("mirror", diffuse=0.05, mirror=[0.9, 0.85, 0.8]),
        Material("glass", diffuse=0.0, transmission=1.0, ior=1.5, absorption=[0.1, 0.3, 0.6]),
    ]
    camera = Camera([0.5, -5.0, 3.0], [0.0, 0.3, 0.6], [0.0, 0.0, 1.0], 50.0, aperture=aperture,
                    focus_distance=5.5 if aperture else None)
    return Scene.from_parts(parts, materials, [PointLight([2.0, -3.0, 5.0], 40.0)], camera,
                            ambient=[0.2, 0.2, 0.25], background=[0.3, 0.4, 0.6])


# settings that run every stage of every_stage_scene (the determinism tests')
EVERY_STAGE_SETTINGS = dict(width=48, height=36, spp=4, sampler="jittered", ao_samples=3, ao_distance=2.0,
                            passes=("ao",), seed=7, max_depth=4)


def sun_sky(width=64):
    """A dim blue sky with a small bright sun 50 degrees above the horizon (+Z is not up here:
    rtmesh's environments have +Y up; the environment-lighting tests' floors use a +Y-up frame
    for them)."""
    height = width // 2
    directions = latlong_directions(width, height)
    sun = np.array([0.3, math.sin(math.radians(50.0)), 0.5])
    sun /= np.linalg.norm(sun)
    pixels = np.broadcast_to([0.2, 0.3, 0.5], (height, width, 3)).copy()
    pixels[directions @ sun > math.cos(math.radians(6.0))] = [200.0, 180.0, 150.0]
    return EnvironmentBackground(pixels, rotation=30.0)
