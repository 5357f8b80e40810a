"""Backgrounds: the lat-long orientation convention, bilinear lookup across the seam,
gradient and environment values seen by camera and mirror rays, transparent output, and the
scene-file keys."""

import os

import numpy as np
import pytest
from scenes import part, pixel_centre_rays, quad, render
import scenes

from rtmesh.cli import main
from rtmesh.core.errors import SceneError
from rtmesh.io.images import read_image
from rtmesh.loaders.scene_file import scene_from_dict
from rtmesh.materials.table import Material
from rtmesh.scene.background import (EnvironmentBackground, GradientBackground, TransparentBackground,
                                     latlong_directions, read_environment)
from rtmesh.scene.camera import Camera
from rtmesh.scene.model import Scene

ASSETS = scenes.ASSETS
SKY = os.path.join(ASSETS, "environments", "sky.exr")


def octant_map(width=64, height=32):
    """A lat-long map whose texels are coloured by the octant of their centre direction:
    R, G, B = 1 where x, y, z > 0, else 0."""
    d = latlong_directions(width, height)
    return (d > 0).astype(np.float64)


def octant_colour(d):
    return (np.asarray(d) > 0).astype(np.float64)


# ---------------------------------------------------------------- orientation
def test_axis_directions_map_to_the_documented_image_positions():
    env = EnvironmentBackground(np.zeros((8, 16, 3)))
    axes = np.array([[1, 0, 0], [0, 0, -1], [0, 0, 1], [-1, 0, 0], [0, 1, 0], [0, -1, 0]], dtype=float)
    uv = env.uv(axes)
    # +X at the centre, -Z a quarter in, +Z three quarters in, -X on the seam; v: +Y top
    np.testing.assert_allclose(uv[:4, 0], [0.5, 0.25, 0.75, 1.0], atol=1e-12)
    np.testing.assert_allclose(uv[:4, 1], 0.5, atol=1e-12)
    np.testing.assert_allclose(uv[4:, 1], [1.0, 0.0], atol=1e-12)


def test_every_octant_reads_its_own_colour():
    env = EnvironmentBackground(octant_map())
    rng = np.random.default_rng(3)
    d = rng.normal(size=(2000, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    # away from the octant boundaries (where bilinear filtering blends two octants)
    clear = (np.abs(d) > 0.15).all(axis=1)
    np.testing.assert_array_equal(env.radiance(d[clear]), octant_colour(d[clear]))


def test_texel_centre_directions_read_that_texel_exactly():
    rng = np.random.default_rng(5)
    pixels = rng.uniform(size=(6, 10, 3))
    env = EnvironmentBackground(pixels)
    d = latlong_directions(10, 6).reshape(-1, 3)
    np.testing.assert_allclose(env.radiance(d), pixels.reshape(-1, 3), atol=1e-12)


def test_bilinear_lookup_blends_across_the_seam_and_clamps_at_the_poles():
    pixels = np.zeros((4, 8, 3))
    pixels[:, 0] = 1.0  # first column
    pixels[:, -1] = 3.0  # last column
    env = EnvironmentBackground(pixels)
    # -X is exactly on the seam between the last and first columns: their average
    np.testing.assert_allclose(env.radiance(np.array([[-1.0, 0.0, 0.0]])), [[2.0, 2.0, 2.0]])
    # straight up reads the top row only (no wrap to the bottom row)
    pixels = np.zeros((4, 8, 3))
    pixels[0] = 5.0
    up = np.array([[0.0, 1.0, 0.0]])
    np.testing.assert_allclose(EnvironmentBackground(pixels).radiance(up), [[5.0] * 3])


def test_rotation_and_intensity():
    env = EnvironmentBackground(octant_map(), rotation=90.0, intensity=2.0)
    plain = EnvironmentBackground(octant_map())
    # a right-handed turn of 90 degrees about +Y: what was seen along +X is seen along -Z
    d = np.array([[0.3, 0.4, -0.8]])
    turned_back = np.array([[0.8, 0.4, 0.3]])  # rotate d by -90 degrees about +Y
    np.testing.assert_allclose(env.radiance(d), 2.0 * plain.radiance(turned_back))


# ---------------------------------------------------------------- renders
def horizon_camera(fov=60.0):
    return Camera([0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0], fov)


def empty_scene(background, camera):
    """A tiny quad behind the camera (a scene needs geometry) and nothing in view."""
    behind = quad([[-0.1, -0.1, 5.0], [-0.1, 0.1, 5.0], [0.1, 0.1, 5.0], [0.1, -0.1, 5.0]])
    return Scene.from_parts([part("behind", behind)], [Material("m")], [], camera, background=background)


def test_gradient_rows_match_the_closed_form_of_their_ray_directions():
    top, bottom = np.array([0.2, 0.4, 1.0]), np.array([0.3, 0.2, 0.1])
    camera = horizon_camera()
    result = render(empty_scene(GradientBackground(top, bottom), camera), width=12, height=10)
    _, d = pixel_centre_rays(camera, 12, 10)
    expected = (bottom + (top - bottom) * (0.5 + 0.5 * d[:, 1:2])).reshape(10, 12, 3)
    # (the path kernel reads a gradient from a 256 x 512 table, bilinear in latitude: within
    # 1e-4 of the closed form)
    np.testing.assert_allclose(result.image[0], expected[0], rtol=1e-4)
    np.testing.assert_allclose(result.image[-1], expected[-1], rtol=1e-4)
    # the top row is bluer than the bottom row, the middle straddles the horizon average
    assert (result.image[0, :, 2] > result.image[-1, :, 2]).all()


def test_environment_is_seen_by_camera_rays_and_in_a_mirror():
    env = read_environment(SKY)
    camera = Camera([0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0], 60.0)
    # the left half of the view is a mirror (x < 0, at z = -3, facing +Z); the right sees the sky
    mirror = quad([[-10.0, -10.0, -3.0], [0.0, -10.0, -3.0], [0.0, 10.0, -3.0], [-10.0, 10.0, -3.0]])
    scene = Scene.from_parts([part("mirror", mirror)], [Material("m", diffuse=0.0, mirror=1.0)], [],
                             camera, background=env)
    result = render(scene, width=16, height=12, max_depth=1)
    _, d = pixel_centre_rays(camera, 16, 12)
    reflected = d * np.array([1.0, 1.0, -1.0])
    on_mirror = (d[:, 0] < 0).reshape(12, 16)
    expected = np.where(on_mirror[:, :, None], env.radiance(reflected).reshape(12, 16, 3),
                        env.radiance(d).reshape(12, 16, 3))
    # away from the mirror's edge column
    keep = np.ones((12, 16), dtype=bool)
    keep[:, 7:9] = False
    np.testing.assert_allclose(result.image[keep], expected[keep], rtol=1e-5)
    assert result.stats.rays["reflection"] > 0


def test_shipped_sky_is_finite_and_brightest_at_the_sun():
    env = read_environment(SKY)
    pixels, _ = read_image(SKY)
    assert pixels.shape == (128, 256, 3) and np.isfinite(pixels).all() and (pixels >= 0).all()
    sun = np.array([[0.45, 0.55, -0.70]])
    sun /= np.linalg.norm(sun)
    assert env.radiance(sun)[0, 0] > 10 * env.radiance(np.array([[0.0, 1.0, 0.0]]))[0, 0]
    # the sky is bluer at the zenith than at the horizon, the ground darker than both
    zenith, horizon, ground = env.radiance(np.array([[0.0, 1.0, 0.0], [0.0, 0.05, 1.0], [0.0, -1.0, 0.0]]))
    assert zenith[2] / zenith[0] > horizon[2] / horizon[0] and ground.sum() < horizon.sum()


# ---------------------------------------------------------------- transparent output
TRANSPARENT_SCENE = """
[render]
width = 24
height = 16
spp = 4
threads = 1
[camera]
position = [0.0, 0.0, 4.0]
look_at = [0.0, 0.0, 0.0]
[background]
type = "transparent"
[[objects]]
primitive = "icosphere"
radius = 0.8
[[lights]]
type = "directional"
direction = [0.0, 0.0, -1.0]
irradiance = 1.0
"""


def test_transparent_background_writes_rgba_png_with_straight_and_exr_with_premultiplied_alpha(tmp_path):
    scene_file = tmp_path / "t.toml"
    scene_file.write_text(TRANSPARENT_SCENE)
    png, exr = tmp_path / "t.png", tmp_path / "t.exr"
    assert main(["render", str(scene_file), "-o", str(png), "-q"]) == 0
    assert main(["render", str(scene_file), "-o", str(exr), "-q"]) == 0
    rgba, names = read_image(png)
    assert rgba.shape == (16, 24, 4)
    assert rgba[0, 0, 3] == 0.0 and rgba[8, 12, 3] == 1.0
    linear, names = read_image(exr)
    assert names == ["R", "G", "B", "A"]
    alpha = linear[..., 3]
    assert ((alpha > 0) & (alpha < 1)).any()
    # premultiplied: no colour where nothing is covered, never more than coverage allows
    assert (linear[alpha == 0, :3] == 0).all()
    # straight alpha in the PNG: a half-covered pixel has (about) the colour of a covered one
    edge = (alpha > 0.2) & (alpha < 0.8)
    assert edge.any()
    assert (rgba[edge, 3] == np.round(alpha[edge] * 255) / 255).all()


def test_transparent_render_result_carries_coverage_and_no_background():
    camera = horizon_camera()
    near = quad([[-0.5, -0.5, -2.0], [0.5, -0.5, -2.0], [0.5, 0.5, -2.0], [-0.5, 0.5, -2.0]])
    scene = Scene.from_parts([part("q", near)], [Material("m", emission=1.0, diffuse=0.0)], [], camera,
                             background=TransparentBackground())
    result = render(scene, width=16, height=16, spp=4, sampler="jittered")
    assert result.alpha is not None and result.passes == {}
    # an emitter of radiance 1 over nothing: the premultiplied colour is the coverage
    np.testing.assert_allclose(result.image[..., 0], result.alpha[..., 0], atol=1e-6)


# ---------------------------------------------------------------- scene-file keys
def doc(background):
    return {"objects": [{"primitive": "box"}], "background": background}


def test_scene_file_background_tables():
    scene, _ = scene_from_dict(doc({"type": "gradient", "top": [0, 0, 1], "bottom": 0.5}))
    assert isinstance(scene.background, GradientBackground)
    scene, _ = scene_from_dict(doc({"type": "environment", "file": "environments/sky.exr",
                                    "rotation": 30, "intensity": 0.5}), base_dir=ASSETS)
    assert isinstance(scene.background, EnvironmentBackground) and scene.background.rotation == 30
    scene, _ = scene_from_dict(doc({"colour": [0.1, 0.2, 0.3]}))
    np.testing.assert_allclose(scene.background.radiance(np.zeros((1, 3))), [[0.1, 0.2, 0.3]])


@pytest.mark.parametrize("background, message", [
    ({"type": "sky"}, "background.type: expected one of"),
    ({"type": "gradient", "top": 1.0}, "background.bottom: missing"),
    ({"type": "solid", "colour": 1.0, "file": "x.exr"}, "background.file: does not apply to a solid"),
    ({"type": "environment", "file": "missing.exr"}, "no such environment image"),
    ({"type": "environment", "file": "environments/sky.exr", "intensity": -1}, "background.intensity"),
    ({"type": "transparent", "colour": 1.0}, "does not apply to a transparent"),
])
def test_bad_background_tables_are_one_line_errors(background, message):
    with pytest.raises(SceneError, match=message) as info:
        scene_from_dict(doc(background), source="s.toml", base_dir=ASSETS)
    assert "\n" not in str(info.value) and str(info.value).startswith("s.toml: background")


def test_background_given_twice_is_an_error():
    d = doc({"colour": 1.0})
    d["environment"] = {"background": 0.5}
    with pytest.raises(SceneError, match="not both"):
        scene_from_dict(d, source="s.toml")


def test_corrupt_environment_file_is_an_error(tmp_path):
    bad = tmp_path / "bad.exr"
    bad.write_bytes(b"not an image")
    with pytest.raises(SceneError, match="cannot read environment image"):
        read_environment(bad)


def test_shipped_passes_scene_renders_with_its_environment():
    from scenes import assert_finite

    from rtmesh.api import load_scene
    from rtmesh.rendering.integrator import Integrator

    scene, settings = load_scene(os.path.join(ASSETS, "passes.toml"), width=32, height=24, spp=1,
                                 threads=1, passes=("depth",))
    assert isinstance(scene.background, EnvironmentBackground)
    result = Integrator(scene, settings).render()
    assert_finite(result)
    # the top row sees the sky (no geometry there: depth 0), lit by the environment
    assert (result.passes["depth"][0] == 0).all() and (result.image[0] > 0.1).all()


def test_background_option_makes_a_bare_mesh_render_transparent(tmp_path):
    bunny = os.path.join(ASSETS, "meshes", "bunny.ply")
    out = tmp_path / "bunny.png"
    assert main(["render", bunny, "-o", str(out), "--width", "24", "--height", "18", "--spp", "1",
                 "--background", "transparent", "-q"]) == 0
    rgba, _ = read_image(out)
    assert rgba.shape == (18, 24, 4) and rgba[0, 0, 3] == 0.0 and rgba[9, 12, 3] == 1.0
    out = tmp_path / "sky.exr"
    assert main(["render", bunny, "-o", str(out), "--width", "24", "--height", "18", "--spp", "1",
                 "--background", SKY, "-q"]) == 0
    sky, names = read_image(out)
    assert names == ["R", "G", "B"] and sky[0, 0].min() > 0.05


@pytest.mark.parametrize("value", ["1,2", "-1", "missing.exr"])
def test_bad_background_option_is_exit_status_2(tmp_path, capsys, value):
    bunny = os.path.join(ASSETS, "meshes", "bunny.ply")
    out = tmp_path / "x.png"
    assert main(["render", bunny, "-o", str(out), "--background", value, "-q"]) == 2
    assert "error" in capsys.readouterr().err and not out.exists()


def test_environment_is_seen_through_refraction():
    # a slab of index 1 bends nothing and reflects nothing (Fresnel 0): through it the
    # environment looks exactly as it does without it, but only via refracted rays
    env = read_environment(SKY)
    camera = horizon_camera()
    from scenes import box
    slab = Material("clear", diffuse=0.0, transmission=1.0, ior=1.0)
    scene = Scene.from_parts([part("slab", box(extents=(20.0, 20.0, 0.5), centre=(0.0, 0.0, -3.0)))],
                             [slab], [], camera, background=env)
    result = render(scene, width=12, height=8, max_depth=2)
    _, d = pixel_centre_rays(camera, 12, 8)
    np.testing.assert_allclose(result.image.reshape(-1, 3), env.radiance(d), rtol=1e-5)
    assert result.stats.rays["refraction"] == 2 * 12 * 8
