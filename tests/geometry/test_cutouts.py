"""Alpha cut-outs: masked texels let camera and shadow rays through, blended ones a fraction."""

import numpy as np
import pytest

from rtmesh.api import render
from rtmesh.geometry.accel import Accel
from rtmesh.geometry.cutouts import CutoutAccel
from rtmesh.io.texture_images import Texture
from rtmesh.lights.point_lights import DirectionalLight
from rtmesh.materials.table import Material
from rtmesh.rendering.surface_textures import SurfaceTextures
from rtmesh.sampling.sampler import Sampler
from rtmesh.scene.camera import Camera
from rtmesh.scene.model import MeshPart, Scene

N = 4  # checker texels per side
SIZE = 32  # image pixels per side: 8 pixels per texel


def checker_alpha(n=N):
    """(n, n, 4) white texels, alpha 1 where column + row is even (row 0 at the top)."""
    rows, cols = np.mgrid[0:n, 0:n]
    alpha = ((rows + cols) % 2 == 0).astype(np.float64)
    return np.concatenate([np.ones((n, n, 3)), alpha[:, :, None]], axis=2)


def plane(name, z=0.0, half=1.0, material=0):
    """A square in the plane ``z`` facing +z, UVs (0, 0) at (-half, -half)."""
    vertices = np.array([[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]])
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    return MeshPart(name, vertices, np.array([[0, 1, 2], [0, 2, 3]]), material, uv=uv)


def front_camera():
    # 90 degrees at distance 1: the plane [-1, 1]^2 fills the image exactly
    return Camera(np.array([0.0, 0.0, 1.0]), np.zeros(3), np.array([0.0, 1.0, 0.0]), fov=90.0)


def checker_scene(mode="mask"):
    card = Material("card", diffuse=[1.0, 0.5, 0.25], unlit=True, alpha_mode=mode,
                    diffuse_texture=Texture(checker_alpha(), wrap="clamp"))
    return Scene.from_parts([plane("card")], [card], lights=[], camera=front_camera(),
                            background=np.array([0.0, 0.0, 1.0]))


def test_masked_checker_lets_exactly_the_transparent_texels_through():
    result = render(checker_scene(), width=SIZE, height=SIZE, spp=1, sampler="regular", threads=1)
    image = result.image
    rows, cols = np.mgrid[0:SIZE, 0:SIZE]
    solid = ((rows // (SIZE // N) + cols // (SIZE // N)) % 2 == 0)
    np.testing.assert_allclose(image[solid], np.broadcast_to([1.0, 0.5, 0.25], (solid.sum(), 3)))
    np.testing.assert_array_equal(image[~solid], np.broadcast_to([0.0, 0.0, 1.0], ((~solid).sum(), 3)))
    assert result.stats.rays["cutout"] == (~solid).sum()


def cutout_accel(mode="mask", opacity=1.0):
    """A checker card at z = 1 over a floor at z = 0, wrapped in a CutoutAccel."""
    card = Material("card", alpha_mode=mode, opacity=opacity,
                    diffuse_texture=Texture(checker_alpha(), wrap="clamp"))
    scene = Scene.from_parts([plane("floor", 0.0, 3.0, material=1), plane("card", 1.0)],
                             [card, Material("floor")], lights=[])
    m = scene.materials
    return CutoutAccel(Accel(scene.vertices, scene.faces), scene.face_normals, scene.material_id,
                       m.cutout, m.alpha_mode == 2, m.alpha_cutoff, SurfaceTextures(scene), 3.0,
                       Sampler("jittered", 0, 1))


def test_shadow_rays_pass_exactly_through_the_holes():
    accel = cutout_accel()
    # one shadow ray straight up from the floor under the centre of each texel
    centres = (np.arange(N) + 0.5) / N * 2.0 - 1.0
    x, y = np.meshgrid(centres, centres[::-1])  # row 0 of the texture is the top (+y)
    origins = np.stack([x.ravel(), y.ravel(), np.full(N * N, 1e-3)], axis=1)
    up = np.tile([0.0, 0.0, 1.0], (N * N, 1))
    occluded = accel.occluded(origins, up, np.full(N * N, 5.0))
    np.testing.assert_array_equal(occluded, checker_alpha()[:, :, 3].ravel() > 0.5)
    # and the closest hit of a ray through a hole is the floor below, at the right distance
    hits = accel.intersect(origins + [0, 0, 2.0], -up)
    through = ~occluded
    np.testing.assert_allclose(hits.t[through], 2.0 + 1e-3, rtol=1e-5)
    np.testing.assert_allclose(hits.t[~through], 1.0 + 1e-3, rtol=1e-5)


def test_shadows_of_a_masked_card_in_a_render_follow_the_checker():
    card = Material("card", alpha_mode="mask", diffuse_texture=Texture(checker_alpha(), wrap="clamp"))
    floor = Material("floor", diffuse=1.0)
    # light straight down through the card at z = 1 onto the floor; the camera sits between
    # them, under the card, looking down
    scene = Scene.from_parts([plane("floor", 0.0, 1.0, material=1), plane("card", 1.0)],
                             [card, floor], lights=[DirectionalLight([0.0, 0.0, -1.0], irradiance=1.0)],
                             camera=Camera(np.array([0.0, 0.0, 0.5]), np.zeros(3),
                                           np.array([0.0, 1.0, 0.0]), fov=90.0))
    image = render(scene, width=SIZE, height=SIZE, spp=1, sampler="regular", threads=1).image
    # the camera at z = 0.5 sees the floor region [-0.5, 0.5]^2: the middle 2 x 2 texels
    rows, cols = np.mgrid[0:SIZE, 0:SIZE]
    texel_row = 1 + rows // (SIZE // 2)
    texel_col = 1 + cols // (SIZE // 2)
    lit = checker_alpha()[texel_row, texel_col, 3] == 0.0
    assert (image[lit][:, 0] > 0.99).all() and (image[~lit][:, 0] == 0.0).all()


def test_blended_card_covers_its_opacity_on_average():
    card = Material("card", diffuse=1.0, unlit=True, alpha_mode="blend", opacity=0.25)
    scene = Scene.from_parts([plane("card")], [card], lights=[], camera=front_camera())
    result = render(scene, width=16, height=16, spp=16, threads=1)
    # 4096 independent coin flips: standard error 0.0068
    assert result.image.mean() == pytest.approx(0.25, abs=0.03)
    two_threads = render(scene, width=16, height=16, spp=16, threads=2, chunk_samples=256)
    np.testing.assert_array_equal(result.image, two_threads.image)


def test_blended_shadow_lets_through_one_minus_opacity():
    accel = cutout_accel("blend", opacity=0.3)
    rng = np.random.default_rng(1)
    n = 4000
    # rays up through the centre of a solid texel (texel alpha 1) of the card: opacity 0.3
    # each (distinct origins: the coin flip of a ray is keyed by the ray)
    origins = np.column_stack([-0.75 + rng.uniform(-1e-4, 1e-4, n), 0.75 + rng.uniform(-1e-4, 1e-4, n),
                               np.full(n, 1e-3)])
    occluded = accel.occluded(origins, np.tile([0.0, 0.0, 1.0], (n, 1)), np.full(n, 5.0))
    assert occluded.mean() == pytest.approx(0.3, abs=0.03)


def test_normal_map_tilts_the_shading_normal_along_the_uv_tangent():
    # a plane facing +z with u along +x and v along +y; a texel that encodes the tangent-space
    # normal (sin a, 0, cos a) gives the world normal (sin a, 0, cos a) on the front, and its
    # opposite on the back (the same tilted surface seen from the other side)
    a = 0.4
    texel = 0.5 + 0.5 * np.array([np.sin(a), 0.0, np.cos(a)])
    material = Material("bumpy", normal_texture=Texture(np.tile(texel, (2, 2, 1))))
    scene = Scene.from_parts([plane("p")], [material], lights=[])
    textures = SurfaceTextures(scene)
    prim = np.array([0, 1])
    u = v = np.array([0.25, 0.25])
    front = textures.normal_mapped(np.tile([0.0, 0.0, 1.0], (2, 1)), prim, u, v, np.zeros(2, np.intp),
                                   np.ones(2))
    np.testing.assert_allclose(front, np.tile([np.sin(a), 0.0, np.cos(a)], (2, 1)), atol=1e-12)
    back = textures.normal_mapped(np.tile([0.0, 0.0, -1.0], (2, 1)), prim, u, v, np.zeros(2, np.intp),
                                  -np.ones(2))
    np.testing.assert_allclose(back, np.tile([-np.sin(a), 0.0, -np.cos(a)], (2, 1)), atol=1e-12)


def moving_card_scene(card):
    """``card`` (a material) on a square moving 0.25 along +x while the shutter is open,
    over a blue background, seen head-on."""
    from rtmesh.geometry.motion import Motion
    moving = plane("card")
    moving.motion = Motion(np.array([0.25, 0.0, 0.0]))
    camera = Camera(np.array([0.0, 0.0, 1.0]), np.zeros(3), np.array([0.0, 1.0, 0.0]), fov=90.0,
                    shutter=(0.0, 1.0))
    return Scene.from_parts([moving], [card], lights=[], camera=camera, background=np.array([0.0, 0.0, 1.0]))


def test_cutouts_let_rays_through_under_motion_blur():
    """Cut-outs compose with motion blur: each ray meets the card where it stands at the
    ray's time and passes its transparent parts (they used to render opaque)."""
    invisible = Material("card", diffuse=[1.0, 0.5, 0.25], unlit=True, alpha_mode="blend", opacity=0.0)
    result = render(moving_card_scene(invisible), width=16, height=16, spp=2, sampler="jittered", threads=1)
    assert "motion" in result.stats.stages_enabled
    np.testing.assert_array_equal(result.image, np.broadcast_to([0.0, 0.0, 1.0], result.image.shape))
    checker = Material("card", diffuse=[1.0, 0.5, 0.25], unlit=True, alpha_mode="mask",
                       diffuse_texture=Texture(checker_alpha(), wrap="clamp"))
    result = render(moving_card_scene(checker), width=SIZE, height=SIZE, spp=16, sampler="jittered",
                    threads=1)
    # half the texels are transparent: about half of every pixel's samples see the background
    # (the card's trailing edge uncovers a strip on the left as it moves right)
    assert 0.4 < result.image[..., 2].mean() < 0.65
    assert result.stats.rays["cutout"] > 0
    same = render(moving_card_scene(checker), width=SIZE, height=SIZE, spp=16, sampler="jittered", threads=2,
                  chunk_samples=100)
    np.testing.assert_array_equal(same.image, result.image)


# ---------------------------------------------------------------- under the path integrator
def test_path_sees_moving_cutouts_as_whitted_does():
    """The moving checker card (mask, unlit) over the blue background under path: each ray
    meets the card where it is at the ray's time and passes its transparent texels (looked
    up at the rest pose's texture coordinates), as under whitted; an invisible blended card
    shows the background alone."""
    invisible = Material("card", diffuse=[1.0, 0.5, 0.25], unlit=True, alpha_mode="blend", opacity=0.0)
    result = render(moving_card_scene(invisible), width=16, height=16, spp=2, sampler="jittered", threads=1,
                    integrator="path")
    np.testing.assert_array_equal(result.image, np.broadcast_to([0.0, 0.0, 1.0], result.image.shape))
    checker = Material("card", diffuse=[1.0, 0.5, 0.25], unlit=True, alpha_mode="mask",
                       diffuse_texture=Texture(checker_alpha(), wrap="clamp"))
    images = {integrator: render(moving_card_scene(checker), width=SIZE, height=SIZE, spp=16, sampler="jittered",
                                 threads=1, integrator=integrator).image for integrator in ("path", "whitted")}
    assert 0.4 < images["path"][..., 2].mean() < 0.65
    # the same camera samples and times under both: the same coverage, sample for sample
    # (measured: every pixel), but where float32 texels and hit points could round a sample
    # across a texel's edge
    differ = np.abs(images["path"] - images["whitted"]).max(axis=2) > 1e-6
    assert differ.mean() < 0.01, differ.mean()
    blocks = lambda image: image.reshape(SIZE // 8, 8, SIZE // 8, 8, 3).mean(axis=(1, 3))
    np.testing.assert_allclose(blocks(images["path"]), blocks(images["whitted"]), atol=2e-3)


def moving_card_shadow_scene(model):
    """A lit checker card (mask) moving 0.25 along +x, 0.5 above a floor, a directional light
    slanting along +x: the card's shadow on the floor, seen from above, under the material
    conventions of ``model`` (``lambert`` for path, ``blinn_phong`` for whitted)."""
    from rtmesh.geometry.motion import Motion

    card = plane("card", z=0.5, half=0.5)
    card.motion = Motion(np.array([0.25, 0.0, 0.0]))
    floor = plane("floor", z=0.0, half=2.0, material=1)
    camera = Camera(np.array([0.0, 0.0, 2.0]), np.zeros(3), np.array([0.0, 1.0, 0.0]), fov=60.0,
                    shutter=(0.0, 1.0))
    materials = [Material("card", model=model, diffuse=0.5, alpha_mode="mask",
                          diffuse_texture=Texture(checker_alpha(), wrap="clamp")),
                 Material("floor", model=model, diffuse=0.8)]
    light = DirectionalLight(np.array([0.6, 0.0, -1.0]), irradiance=2.0)
    return Scene.from_parts([card, floor], materials, lights=[light], camera=camera, background=0.0, ambient=0.0)


def test_path_shadows_through_moving_cutouts_as_whitted_does():
    """Shadow rays pass a moving card's transparent texels where the card is at their time:
    pi times the path image (Lambert, direct light only) against whitted's (Blinn-Phong
    without 1/pi), both with the same camera samples and times: the same image but for
    float32 rounding (measured: block means within 1e-7 of the brightest pixel, no pixel
    off by 1e-5; the tolerances leave room for the odd sample whose ray crosses a texel's
    edge the other way)."""
    size = 32
    images = {}
    for integrator, model in (("path", "lambert"), ("whitted", "blinn_phong")):
        images[integrator] = render(moving_card_shadow_scene(model), width=size, height=size, spp=8,
                                    sampler="jittered", threads=1, integrator=integrator, max_depth=1).image
    path, whitted = np.pi * images["path"], images["whitted"]
    blocks = lambda image: image.reshape(size // 8, 8, size // 8, 8, 3).mean(axis=(1, 3))
    # the card's blurred shadow: blocks under it at half the lit floor
    assert blocks(whitted).max() > 1.0 and blocks(whitted).min() < 0.6 * blocks(whitted).max()
    np.testing.assert_allclose(blocks(path), blocks(whitted), rtol=0, atol=1e-4 * whitted.max())
    differ = np.abs(path - whitted).max(axis=2) > 1e-5 * whitted.max()
    assert differ.mean() < 0.01, differ.mean()
    # the same at two threads and other chunks, bit for bit
    again = render(moving_card_shadow_scene("lambert"), width=size, height=size, spp=8, sampler="jittered",
                   threads=2, chunk_samples=100, integrator="path", max_depth=1).image
    np.testing.assert_array_equal(again, images["path"])
