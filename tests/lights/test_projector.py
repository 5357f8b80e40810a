"""The projector light: an image projected from a pinhole, added as one light module."""

import numpy as np
import pytest
import trimesh
from PIL import Image
from scenes import floor_quad, part, render, settings

from rtmesh.core.errors import SceneError
from rtmesh.io.texture_images import Texture
from rtmesh.lights.point_lights import SpotLight
from rtmesh.lights.projector import ProjectorLight
from rtmesh.loaders.scene_file import scene_from_dict
from rtmesh.materials.table import Material
from rtmesh.rendering.integrator import Integrator
from rtmesh.scene.camera import Camera
from rtmesh.scene.model import Scene

# a 2x2 image: top-left red, top-right green, bottom-left blue, bottom-right white
QUADRANTS = np.array([[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                      [[0.0, 0.0, 1.0], [1.0, 1.0, 1.0]]])


def projector_above_floor(image, fov=60.0, intensity=10.0):
    """Projector 2 units above the floor z = 0, looking down, image up = +y."""
    return ProjectorLight([0.0, 0.0, 2.0], [0.0, 0.0, -1.0], intensity, Texture(image, wrap="clamp"), fov,
                          up=[0.0, 1.0, 0.0])


def scalar_projection(light, point, image):
    """Incident term of ``light`` at one point, by the pinhole model written out (nearest texel)."""
    forward, right, up = light.frame()
    offset = np.asarray(point, dtype=float) - light.position
    depth = offset @ forward
    if depth <= 0:
        return np.zeros(3)
    tan_half = np.tan(np.radians(light.fov) / 2)
    height, width = image.shape[:2]
    x = (offset @ right) / depth / (tan_half * width / height)  # -1 .. 1 across the image
    y = (offset @ up) / depth / tan_half
    if abs(x) > 1 or abs(y) > 1:
        return np.zeros(3)
    column = min(int((x + 1) / 2 * width), width - 1)
    row = min(int((1 - y) / 2 * height), height - 1)  # image rows grow downward
    return light.intensity * image[row, column] / (offset @ offset)


def test_projector_lights_each_quadrant_of_the_floor_with_its_quadrant_of_the_image():
    light = projector_above_floor(QUADRANTS)
    # the 60-degree frustum meets the floor 2 units below within |x|, |y| < 2 tan(30 deg) = 1.15;
    # points at the centres of the quadrants, away from the bilinear blend at the middle
    points = np.array([[-0.8, 0.8, 0.0], [0.8, 0.8, 0.0], [-0.8, -0.8, 0.0], [0.8, -0.8, 0.0],
                       [0.0, 1.3, 0.0], [3.0, 0.0, 0.0], [0.0, 0.0, 3.0]])
    wi, distance, incident = light.illuminate(points)
    for i, point in enumerate(points):
        np.testing.assert_allclose(incident[i], scalar_projection(light, point, QUADRANTS), rtol=1e-12,
                                   err_msg=f"point {point}")
    assert (incident[4:] == 0).all()  # outside the frustum, and behind the projector
    np.testing.assert_allclose(np.linalg.norm(wi, axis=1), 1.0)
    np.testing.assert_allclose(distance, np.linalg.norm(points - light.position, axis=1))


def test_a_white_projector_equals_a_spot_light_inside_its_frustum():
    """With a white image, a projector is a spot light with a hard rectangular edge."""
    projector = projector_above_floor(np.ones((4, 4, 3)), fov=90.0, intensity=[3.0, 2.0, 1.0])
    spot = SpotLight([0.0, 0.0, 2.0], [0.0, 0.0, -1.0], [3.0, 2.0, 1.0], 89.0, 89.0)
    rng = np.random.default_rng(3)
    points = np.column_stack([rng.uniform(-1.9, 1.9, (200, 2)), np.zeros(200)])  # inside the 90-degree frustum
    for got, expected in zip(projector.illuminate(points), spot.illuminate(points)):
        np.testing.assert_allclose(got, expected, rtol=1e-12)


def projector_scene(image, material=None):
    vertices, faces = floor_quad(3.0)
    camera = Camera([0.0, 0.0, 4.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 60.0)
    light = projector_above_floor(image)
    return Scene.from_parts([part("floor", (vertices, faces))], [material or Material("floor", diffuse=0.8)], [light],
                            camera, ambient=0.0)


def test_a_rendered_floor_shows_the_projected_image_upright():
    """Camera above the projector, looking down with the same up: the picture appears as in
    the image (red top left, white bottom right), lit only inside the frustum."""
    scene = projector_scene(np.kron(QUADRANTS, np.ones((16, 16, 1))))  # 32x32: bilinear blends only mid-image
    integrator = Integrator(scene, settings(width=64, height=64))
    assert not integrator.plan.fused_direct  # no compiled row: the general path
    image = render(scene, width=64, height=64).image
    # the camera at z = 4 with fov 60 sees |x|, |y| < 2.31; the lit square |x|, |y| < 1.15
    # is the middle half of the image; sample each quadrant's centre
    top_left, top_right = image[24, 24], image[24, 40]
    bottom_left, bottom_right = image[40, 24], image[40, 40]
    assert top_left[0] > 0 and top_left[1] == top_left[2] == 0
    assert top_right[1] > 0 and top_right[0] == top_right[2] == 0
    assert bottom_left[2] > 0 and bottom_left[0] == bottom_left[1] == 0
    assert (bottom_right > 0).all()
    assert (image[2, 2] == 0).all() and (image[32, 2] == 0).all()  # outside the frustum: dark


def test_scene_files_name_the_projector_and_its_image_relative_to_the_file(tmp_path):
    Image.fromarray(np.uint8(QUADRANTS * 255)).save(tmp_path / "gobo.png")
    doc = {"camera": {"position": [0, 0, 4], "look_at": [0, 0, 0]},
           "objects": [{"primitive": "plane", "size": [6, 6]}],
           "lights": [{"type": "projector", "position": [0, 0, 2], "look_at": [0, 0, 0], "intensity": 5,
                       "image": "gobo.png", "fov": 40}]}
    scene, _ = scene_from_dict(doc, base_dir=str(tmp_path))
    (light,) = scene.lights
    assert isinstance(light, ProjectorLight) and light.fov == 40.0
    np.testing.assert_array_equal(light.image.pixels[0, 0, :3], [1.0, 0.0, 0.0])  # sRGB 255 -> 1
    doc["lights"][0]["image"] = "missing.png"
    with pytest.raises(SceneError, match=r"lights\[0\]\.image: no such file"):
        scene_from_dict(doc, base_dir=str(tmp_path))
    doc["lights"][0]["image"] = "gobo.png"
    doc["lights"][0]["fov"] = 200
    with pytest.raises(SceneError, match=r"lights\[0\]: projector fov must be in \(0, 180\)"):
        scene_from_dict(doc, base_dir=str(tmp_path))


def test_every_registered_light_type_builds_a_light_of_one_of_the_two_interfaces(tmp_path):
    """The renderer sorts lights by interface (point-like: illuminate; area: sample and
    intersect), so a registered type must build one or the other."""
    from rtmesh.lights.area_lights import is_area_light
    from rtmesh.lights.interface import AreaLight, PointLikeLight
    from rtmesh.loaders.light_registry import LIGHT_TYPES

    Image.fromarray(np.uint8(QUADRANTS * 255)).save(tmp_path / "gobo.png")
    values = {"position": np.array([0.0, 0.0, 2.0]), "direction": np.array([0.0, 0.0, -1.0]),
              "intensity": np.ones(3), "irradiance": np.ones(3), "radiance": np.ones(3), "radius": 0.5,
              "edge1": np.array([1.0, 0.0, 0.0]), "edge2": np.array([0.0, 1.0, 0.0]),
              "image": str(tmp_path / "gobo.png")}
    for name, light_type in LIGHT_TYPES.items():
        light = light_type.build({key: values[key] for key in light_type.keys if key in values})
        point_like, area = isinstance(light, PointLikeLight), isinstance(light, AreaLight)
        assert point_like != area, name
        assert is_area_light(light) == area, name


# ---------------------------------------------------------------- under the path integrator
def test_path_chooses_a_projector_by_its_image_and_its_frustum():
    """The light table's power of a projector is its intensity over the frustum's solid angle
    (4 asin(sin a sin b) for half-angles a, b), times the image's brightness: against a point
    light (power 4 pi I) the choice probabilities have that ratio."""
    from rtmesh.lights.light_table import LightTable
    from rtmesh.lights.point_lights import PointLight

    def ratio(image, fov):
        projector = projector_above_floor(image, fov=fov, intensity=2.0)
        table = LightTable([projector, PointLight([0.0, 0.0, 1.0], 1.0)], np.zeros((0, 9)), np.zeros((0, 3)),
                           np.zeros((0, 3)), None, 1.0)
        return table.pmf[0] / table.pmf[1]

    for fov, shape in ((60.0, (32, 32)), (90.0, (16, 48)), (20.0, (40, 30))):
        half_height = np.radians(fov) / 2
        half_width = np.arctan(np.tan(half_height) * shape[1] / shape[0])
        solid_angle = 4.0 * np.arcsin(np.sin(half_width) * np.sin(half_height))
        white = ratio(np.ones(shape + (3,)), fov)
        # midpoint rule over the texels: within 1e-3 of the closed form
        assert abs(white / (2.0 * solid_angle / (4.0 * np.pi)) - 1.0) < 1e-3, fov
        # the image's lower half black: half the power (the frustum is symmetric)
        half = np.ones(shape + (3,))
        half[shape[0] // 2:] = 0.0
        assert abs(ratio(half, fov) / white - 0.5) < 1e-9
        # a grey image: its luminance
        assert abs(ratio(np.full(shape + (1,), 0.25), fov) / white - 0.25) < 1e-9


def projector_floor_scene(image, model="lambert", diffuse=0.8):
    """The projector above the floor under the path integrator's conventions (a Lambert
    floor: albedo ``diffuse``), camera at z = 4 looking down, with the same image up."""
    return projector_scene(image, Material("floor", model=model, diffuse=diffuse))


@pytest.mark.parametrize("aim", ["down", "slanted"])
def test_path_lights_the_floor_with_the_projected_texel_times_cos_over_d_squared(aim):
    """One sample at each pixel centre, max_depth 1 (direct light only): the floor's radiance
    is ``(albedo / pi) I texel cos(theta) / d^2`` with the texel Whitted's projector looks up
    (ProjectorLight.illuminate, the NumPy mapping) at the point the pixel sees, at every
    pixel: the image's quadrants, the bilinear blends between them and the dark outside;
    looking straight down with a square image, and slanted, turned (its up along x + y) with
    an image twice as wide as high."""
    from scenes import pixel_centre_rays

    image = np.kron(QUADRANTS, np.ones((16, 16, 1))) * np.array([1.0, 0.6, 0.3])
    scene = projector_floor_scene(image)
    if aim == "slanted":
        scene.lights[0] = ProjectorLight([0.5, -0.3, 2.0], [-0.3, 0.4, -2.0], 10.0,
                                         Texture(np.kron(QUADRANTS, np.ones((8, 16, 1))), wrap="clamp"), 50.0,
                                         up=[1.0, 1.0, 0.0])
    size = 48
    result = render(scene, width=size, height=size, spp=1, sampler="regular", integrator="path", max_depth=1)
    origins, directions = pixel_centre_rays(scene.camera, size, size)
    points = origins - (origins[:, 2] / directions[:, 2])[:, None] * directions
    light = scene.lights[0]
    wi, _, incident = light.illuminate(points)
    expected = (0.8 / np.pi) * incident * wi[:, 2:3]  # the floor's normal is +z
    expected = expected.reshape(size, size, 3)
    lit = (expected > 0).any(axis=2)
    assert lit.sum() > 0.2 * size * size and (~lit).sum() > 0.1 * size * size
    # float32 texels and image, float32 hit points: agreement to 1e-5 of the brightest pixel
    # (measured: 1.4e-7 straight down, 2.6e-6 slanted, where float32 hit points meet the blends)
    np.testing.assert_allclose(result.image, expected, rtol=0, atol=1e-5 * expected.max())


def test_path_shows_the_projected_image_where_whitted_does():
    """8x8 block means of the path image (Lambert albedo 0.8, max_depth 1) times pi against
    Whitted's (diffuse 0.8, Blinn-Phong without 1/pi), 4 jittered samples a pixel placed
    alike under both integrators: the same picture, within float32 rounding (the path
    kernel's texels are float32)."""
    image = np.kron(QUADRANTS, np.ones((8, 8, 1))) + 0.1 * np.random.default_rng(5).uniform(size=(16, 16, 3))
    size = 32
    path = render(projector_floor_scene(image), width=size, height=size, spp=4, sampler="jittered",
                  integrator="path", max_depth=1).image
    whitted = render(projector_floor_scene(image, model="blinn_phong"), width=size, height=size, spp=4,
                     sampler="jittered", integrator="whitted").image
    blocks = lambda a: a.reshape(size // 8, 8, size // 8, 8, 3).mean(axis=(1, 3))
    assert blocks(whitted).max() > 1.0
    np.testing.assert_allclose(np.pi * blocks(path), blocks(whitted), rtol=1e-4, atol=1e-6)


def test_a_white_projector_throws_the_caustics_of_the_spot_light_it_equals():
    """Photon passes emit from a projector as from the point-like lights: a glass sphere on a
    floor, everything inside the projector's frustum, under a white projector or a spot
    light of the same intensity with a cone wider than the frustum (the two have the same
    incident term there): with the same photons (one light, the same random numbers) the
    caustic and the whole image are the same but for float32 rounding."""
    from rtmesh.lights.point_lights import SpotLight

    sphere = trimesh.creation.icosphere(subdivisions=2, radius=0.4)
    sphere.apply_translation((0.0, 0.0, 0.4))
    vertices, faces = floor_quad(1.2)  # inside the 90-degree frustum from 2 above: |x|, |y| < 2
    camera = Camera([0.0, -2.5, 2.5], [0.0, 0.0, 0.2], [0.0, 0.0, 1.0], 45.0)
    materials = [Material("floor", model="lambert", diffuse=0.8), Material("glass", model="dielectric", ior=1.5)]
    parts = [part("floor", (vertices, faces)), part("ball", sphere, material=1, smooth=True)]
    images = []
    for light in (SpotLight([0.0, 0.0, 2.0], [0.0, 0.0, -1.0], [3.0, 2.0, 1.0], 80.0, 80.0),
                  projector_above_floor(np.ones((8, 8, 3)), fov=90.0, intensity=[3.0, 2.0, 1.0])):
        scene = Scene.from_parts(parts, materials, [light], camera, background=0.0)
        result = render(scene, width=32, height=24, spp=4, sampler="jittered", integrator="path",
                        caustics="photons", photons=4096, max_depth=6)
        assert result.stats.photon_passes == 4
        images.append(result.image)
    # (measured: identical, the spot's cone and the projector's white texel both weigh 1)
    np.testing.assert_allclose(images[1], images[0], rtol=1e-4, atol=1e-5 * images[0].max())
    # and the photons carry a caustic the path tracer alone cannot find (measured: up to 0.14
    # more at a pixel of the image, whose brightest is 0.19)
    without = render(scene, width=32, height=24, spp=4, sampler="jittered", integrator="path", caustics="off",
                     max_depth=6).image
    assert (images[1] - without).max() > 0.05
