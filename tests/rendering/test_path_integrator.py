"""The path integrator against closed forms: furnaces, white furnaces, glass; its options
and its determinism."""

import numpy as np
import pytest
import trimesh

from rtmesh.materials.table import Material
from rtmesh.rendering.integrator import Integrator
from rtmesh.rendering.settings import RenderSettings
from rtmesh.scene.camera import Camera
from rtmesh.scene.model import MeshPart, Scene


@pytest.fixture(scope="module")
def sphere():
    return trimesh.creation.icosphere(subdivisions=3, radius=1.0)


def _inside(sphere, material):
    """Camera at the centre of a closed sphere whose faces look inward (under path, emission
    leaves the front side only)."""
    camera = Camera(np.zeros(3), np.array([0.0, 0.0, -1.0]), np.array([0.0, 1.0, 0.0]), fov=90.0)
    return Scene.from_parts([MeshPart("s", sphere.vertices, sphere.faces[:, ::-1], 0)], materials=[material], lights=[],
                            camera=camera, background=0.0)


def _outside(sphere, material, background=1.0):
    """A sphere filling the view, in a uniform environment."""
    camera = Camera(np.array([0.0, 0.0, 3.2]), np.zeros(3), np.array([0.0, 1.0, 0.0]), fov=30.0)
    return Scene.from_parts([MeshPart("s", sphere.vertices, sphere.faces, 0, vertex_normals=sphere.vertex_normals)],
                            materials=[material], lights=[], camera=camera, background=background)


def _mean(scene, spp=64, size=24, **settings):
    settings = RenderSettings(width=size, height=size, spp=spp, threads=2, **settings)
    return Integrator(scene, settings).render().image


@pytest.mark.parametrize("rho", [0.5, 0.8])
def test_glowing_closed_sphere_settles_at_e_over_one_minus_rho(sphere, rho):
    """A closed diffuse sphere emitting E = 1: L = E / (1 - rho) with interreflection."""
    image = _mean(_inside(sphere, Material("wall", model="lambert", diffuse=rho, emission=1.0)),
                  integrator="path")
    assert abs(image.mean() / (1.0 / (1.0 - rho)) - 1.0) < 0.005


def test_whitted_keeps_its_one_plus_pi_rho(sphere):
    image = _mean(_inside(sphere, Material("wall", diffuse=0.5, emission=1.0)), spp=16, integrator="whitted")
    assert abs(image.mean() / (1.0 + np.pi * 0.5) - 1.0) < 0.005


def test_max_depth_counts_segments_after_the_camera_ray(sphere):
    """max_depth 1: emission plus light sampled once, rho E; 2: one bounce more, rho^2 E."""
    rho = 0.5
    for depth, expected in ((0, 1.0), (1, 1.0 + rho), (2, 1.0 + rho + rho * rho)):
        image = _mean(_inside(sphere, Material("wall", model="lambert", diffuse=rho, emission=1.0)),
                      integrator="path", max_depth=depth)
        assert abs(image.mean() / expected - 1.0) < 0.005, depth


@pytest.mark.parametrize("material", [
    Material("lambert", model="lambert", diffuse=1.0),
    Material("eon", model="oren-nayar", diffuse=1.0, roughness=1.0),
    Material("metal", model="conductor", mirror=1.0, roughness=0.05),
    Material("metal", model="conductor", mirror=1.0, roughness=0.5),
    Material("metal", model="conductor", mirror=1.0, roughness=1.0),
    Material("glass", model="dielectric", ior=1.5),
], ids=["lambert", "eon", "metal-0.05", "metal-0.5", "metal-1", "glass"])
def test_white_furnace(sphere, material):
    """In a uniform environment of radiance 1 an energy-conserving white object vanishes."""
    image = _mean(_outside(sphere, material), spp=32, integrator="path")
    assert abs(image.mean() - 1.0) < 0.01


@pytest.mark.parametrize("roughness", [0.1, 0.3, 0.6, 1.0])
def test_rough_glass_in_a_white_furnace(sphere, roughness):
    """A closed rough glass sphere vanishes in a white furnace: the interface's energy
    compensation (rtmesh.materials.dielectric_albedo) gives back what single-scattering GGX
    loses, most under total internal reflection, where paths trapped inside lose it at every
    bounce (without it: 0.965 at roughness 0.3, 0.82 at 0.5, 0.37 at 1)."""
    image = _mean(_outside(sphere, Material("glass", model="dielectric", ior=1.5, roughness=roughness)), spp=32,
                  integrator="path")
    assert abs(image.mean() - 1.0) < 0.02


def test_a_camera_inside_absorbing_glass_sees_through_it(sphere):
    """Camera at the centre of a closed smooth glass sphere of the dielectric model (which has
    no Whitted transmission colour), absorbing sigma = 0.5 per unit, in a uniform environment
    of radiance 1.  At normal incidence (R = 0.04) each ray leaves the glass with the radiance
    scaled by n^2 (L / n^2 is invariant across the interface), after e^-sigma on its way out
    and e^-2 sigma more per internal reflection: n^2 e^-sigma (1 - R) / (1 - R e^-2 sigma).
    The camera's own segment is absorbed only if the camera is known to sit in the glass."""
    sigma, n = 0.5, 1.5
    reflectance = ((n - 1.0) / (n + 1.0)) ** 2
    expected = n * n * np.exp(-sigma) * (1.0 - reflectance) / (1.0 - reflectance * np.exp(-2.0 * sigma))
    camera = Camera(np.zeros(3), np.array([0.0, 0.0, -1.0]), np.array([0.0, 1.0, 0.0]), fov=60.0)
    glass = Material("glass", model="dielectric", ior=n, absorption=sigma)
    scene = Scene.from_parts([MeshPart("s", sphere.vertices, sphere.faces, 0, vertex_normals=sphere.vertex_normals)],
                             materials=[glass], lights=[], camera=camera, background=1.0)
    image = _mean(scene, spp=16, integrator="path")
    assert abs(image.mean() / expected - 1.0) < 0.01


def test_paths_trapped_by_total_internal_reflection_end():
    """A camera off the centre of a clear, non-absorbing glass ball (smooth shading): rays
    that meet its surface beyond the critical angle stay inside, and the throughput of
    such a path never falls, so roulette alone let it on for ever under max_depth -1 (this
    render did not end).  A path survives with at most path_scatter.SURVIVAL, so paths end
    about 20 vertices past rr_depth (measured: 23 bounce rays a sample)."""
    from rtmesh.loaders.scene_file import scene_from_dict
    from rtmesh.rendering.path_scatter import SURVIVAL

    doc = {"render": {"width": 8, "height": 6, "spp": 4, "integrator": "path", "caustics": "off", "threads": 1},
           "camera": {"position": [0.5, 0.0, 0.0], "look_at": [0.0, 0.0, 5.0], "fov": 50},
           "materials": {"glass": {"transmission": [1, 1, 1], "ior": 1.5, "diffuse": 0}},
           "lights": [{"type": "directional", "direction": [-0.3, -1, -0.4], "irradiance": 3}],
           "objects": [{"primitive": "icosphere", "subdivisions": 2, "radius": 0.6, "material": "glass"}]}
    scene, settings = scene_from_dict(doc)
    result = Integrator(scene, settings).render()
    assert SURVIVAL < 1.0 and np.isfinite(result.image).all()
    assert result.stats.rays["bounce"] < 60 * 8 * 6 * 4


def test_images_do_not_depend_on_the_thread_count(sphere):
    scene = _outside(sphere, Material("m", model="conductor", mirror=(0.9, 0.6, 0.3), roughness=0.4))
    one = Integrator(scene, RenderSettings(width=16, height=12, spp=8, threads=1, integrator="path",
                                           chunk_samples=256)).render().image
    two = Integrator(scene, RenderSettings(width=16, height=12, spp=8, threads=2, integrator="path",
                                           chunk_samples=256)).render().image
    assert np.array_equal(one, two)


def _moving_sphere(sphere, shutter, motion):
    from rtmesh.geometry.motion import Motion

    floor = trimesh.creation.box(extents=(8.0, 0.1, 8.0))
    floor.apply_translation((0.0, -1.05, 0.0))
    camera = Camera(np.array([0.0, 1.5, 5.0]), np.zeros(3), np.array([0.0, 1.0, 0.0]), fov=45.0, shutter=shutter)
    parts = [MeshPart("s", sphere.vertices, sphere.faces, 0, vertex_normals=sphere.vertex_normals,
                      motion=Motion(**motion)),
             MeshPart("floor", floor.vertices, floor.faces, 1)]
    materials = [Material("m", model="conductor", mirror=(0.9, 0.6, 0.3), roughness=0.3),
                 Material("g", model="lambert", diffuse=0.6)]
    from rtmesh.lights.point_lights import PointLight
    return Scene.from_parts(parts, materials=materials, lights=[PointLight((2.0, 4.0, 2.0), 30.0)], camera=camera,
                            background=0.4)


def test_motion_blur_is_the_average_of_the_instants(sphere):
    """A sphere sliding over a floor (shadow and reflections move with it): the blurred image
    is the mean of the scene frozen at eight instants of the shutter."""
    from rtmesh.geometry.motion import scene_at_time

    blurred_scene = _moving_sphere(sphere, (0.0, 1.0), {"translate": (1.5, 0.0, 0.0)})
    blurred = _mean(blurred_scene, spp=128, size=32, integrator="path")
    frozen = np.mean([_mean(scene_at_time(blurred_scene, (k + 0.5) / 8), spp=16, size=32, integrator="path")
                      for k in range(8)], axis=0)
    blocks = lambda image: image.reshape(4, 8, 4, 8, 3).mean(axis=(1, 3))
    error = np.sqrt(np.mean((blocks(blurred) - blocks(frozen)) ** 2)) / blocks(frozen).mean()
    assert error < 0.02
    # and blur is there: the blurred image differs from either end of the shutter
    start = _mean(scene_at_time(blurred_scene, 0.0), spp=16, size=32, integrator="path")
    assert np.abs(blocks(blurred) - blocks(start)).max() > 0.05


def test_a_sphere_spinning_about_its_centre_looks_still(sphere):
    still = _mean(_moving_sphere(sphere, (0.0, 0.0), {}), spp=64, size=24, integrator="path")
    spinning = _mean(_moving_sphere(sphere, (0.0, 1.0), {"axis": (0.0, 1.0, 0.0), "degrees": 90.0,
                                                         "centre": (0.0, 0.0, 0.0)}),
                     spp=64, size=24, integrator="path")
    assert abs(spinning.mean() / still.mean() - 1.0) < 0.01


def test_motion_blur_does_not_depend_on_the_thread_count(sphere):
    scene = _moving_sphere(sphere, (0.0, 1.0), {"translate": (1.0, 0.0, 0.5), "axis": (0.0, 0.0, 1.0),
                                                "degrees": 40.0})
    one = Integrator(scene, RenderSettings(width=16, height=12, spp=4, threads=1, integrator="path",
                                           chunk_samples=128)).render().image
    two = Integrator(scene, RenderSettings(width=16, height=12, spp=4, threads=2, integrator="path",
                                           chunk_samples=128)).render().image
    assert np.array_equal(one, two)


def _moving_lamp(shutter, motion):
    """A square lamp (emission 4, facing down) 1.2 above a Lambert floor, the camera looking
    down at the floor from the side; the lamp's back (black Lambert) faces the camera."""
    from rtmesh.geometry.motion import Motion

    floor = trimesh.creation.box(extents=(8.0, 0.1, 8.0))
    floor.apply_translation((0.0, -0.05, 0.0))
    lamp = np.array([[-0.4, 1.2, -0.4], [0.4, 1.2, -0.4], [0.4, 1.2, 0.4], [-0.4, 1.2, 0.4]])
    camera = Camera(np.array([0.0, 3.0, 4.0]), np.array([0.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), fov=50.0,
                    shutter=shutter)
    parts = [MeshPart("lamp", lamp, np.array([[0, 1, 2], [0, 2, 3]]), 0, motion=Motion(**motion)),
             MeshPart("floor", floor.vertices, floor.faces, 1)]
    materials = [Material("lamp", model="lambert", diffuse=0.0, emission=4.0),
                 Material("floor", model="lambert", diffuse=0.8)]
    return Scene.from_parts(parts, materials=materials, lights=[], camera=camera, background=0.0)


MOVING_LAMP = {"translate": (1.5, 0.0, 0.0), "axis": (0.0, 0.0, 1.0), "degrees": 60.0, "centre": (0.0, 1.2, 0.0)}


def test_a_moving_emitter_lights_the_floor_where_it_is_at_each_instant():
    """A lamp sliding and tilting (60 degrees about z) over a floor, direct light only
    (max_depth 1: light sampling and BSDF samples meeting the lamp, MIS-weighted): the blurred
    image is the mean of the scene frozen at eight instants.  Light sampling toward the lamp's
    rest pose would light the floor where the lamp is not (the blurred floor differs from the
    rest pose's by 119 % of the image mean), and densities from its rest normal would weigh
    the two strategies wrongly by the tilt's cosine.

    The tolerance is the noise, measured: relative RMSE of the 8x8 block means 0.68 % here
    (two blurred renders of different seeds differ by 0.21 %; the frozen mean, each instant
    with a seed of its own, and the eight instants' quadrature of the light pool the lamp's
    moving silhouette cuts add the rest, up to 1.6 % in single blocks under the lamp); 1.5 %
    is twice that, and the lamp's rest pose misses it by two orders.
    """
    from rtmesh.geometry.motion import scene_at_time

    scene = _moving_lamp((0.0, 1.0), MOVING_LAMP)
    blurred = _mean(scene, spp=512, size=32, integrator="path", max_depth=1)
    frozen = np.mean([_mean(scene_at_time(scene, (k + 0.5) / 8), spp=64, size=32, integrator="path", max_depth=1,
                            seed=k + 1) for k in range(8)], axis=0)
    blocks = lambda image: image.reshape(4, 8, 4, 8, 3).mean(axis=(1, 3))
    error = np.sqrt(np.mean((blocks(blurred) - blocks(frozen)) ** 2)) / blocks(frozen).mean()
    assert error < 0.015, error
    # the light moves: the blurred floor differs from the lamp's rest pose
    start = _mean(scene_at_time(scene, 0.0), spp=16, size=32, integrator="path", max_depth=1)
    assert np.sqrt(np.mean((blocks(blurred) - blocks(start)) ** 2)) / blocks(frozen).mean() > 0.5


def _textured_sphere(sphere, **material):
    """The sphere with UVs (from its positions) and a material holding textures."""
    uv = 0.5 + 0.5 * sphere.vertices[:, :2]
    camera = Camera(np.array([0.0, 0.0, 3.2]), np.zeros(3), np.array([0.0, 1.0, 0.0]), fov=30.0)
    part = MeshPart("s", sphere.vertices, sphere.faces, 0, vertex_normals=sphere.vertex_normals, uv=uv)
    return Scene.from_parts([part], materials=[Material("m", **material)], lights=[], camera=camera,
                            background=1.0)


def test_a_uniform_texture_renders_as_its_colour(sphere):
    from rtmesh.io.texture_images import Texture

    colour = np.array([0.8, 0.4, 0.2])
    textured = _textured_sphere(sphere, model="lambert", diffuse=1.0,
                                diffuse_texture=Texture(np.tile(colour, (4, 4, 1))))
    plain = _textured_sphere(sphere, model="lambert", diffuse=colour)
    a, b = _mean(textured, spp=4, integrator="path"), _mean(plain, spp=4, integrator="path")
    np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6)


def test_a_flat_normal_map_changes_nothing(sphere):
    from rtmesh.io.texture_images import Texture

    flat = Texture(np.tile([0.5, 0.5, 1.0], (4, 4, 1)))
    a = _mean(_textured_sphere(sphere, model="conductor", mirror=0.9, roughness=0.3, normal_texture=flat), spp=4,
              integrator="path")
    b = _mean(_textured_sphere(sphere, model="conductor", mirror=0.9, roughness=0.3), spp=4, integrator="path")
    np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("mode", ["mask", "blend"])
def test_a_fully_cut_out_object_is_invisible(sphere, mode):
    scene = _textured_sphere(sphere, model="lambert", diffuse=0.2, opacity=0.0, alpha_mode=mode)
    image = _mean(scene, spp=4, integrator="path")
    assert np.abs(image - 1.0).max() < 1e-6


def test_half_opaque_blend_lets_half_the_light_through(sphere):
    """A black sphere of opacity 0.5 before a white background: each surface crossed keeps
    half, two crossings through the middle leave a quarter of the background."""
    scene = _textured_sphere(sphere, model="lambert", diffuse=0.0, opacity=0.5, alpha_mode="blend")
    image = _mean(scene, spp=256, size=16, integrator="path")
    centre = image[6:10, 6:10].mean()
    assert abs(centre - 0.25) < 0.02


def test_emission_leaves_the_front_side_only(sphere):
    """Faces looking outward: the camera inside sees their back sides, which do not emit."""
    camera = Camera(np.zeros(3), np.array([0.0, 0.0, -1.0]), np.array([0.0, 1.0, 0.0]), fov=90.0)
    scene = Scene.from_parts([MeshPart("s", sphere.vertices, sphere.faces, 0)],
                             materials=[Material("wall", model="lambert", diffuse=0.5, emission=1.0)], lights=[],
                             camera=camera, background=0.0)
    # (light samples on the shading point's own plane meet it at a cosine of rounding size,
    # ~1e-14 of the emission: nothing else may arrive)
    assert _mean(scene, spp=4, integrator="path").max() < 1e-9


def test_max_depth_defaults_follow_the_integrator():
    assert RenderSettings(integrator="path").validate().max_depth == -1
    assert RenderSettings().validate().max_depth == 5
    with pytest.raises(ValueError, match="max_depth"):
        RenderSettings(max_depth=-1).validate()
    with pytest.raises(ValueError, match="integrator"):
        RenderSettings(integrator="bidirectional").validate()


def test_the_exr_header_records_the_render_settings(tmp_path, sphere):
    import OpenImageIO as oiio

    from rtmesh.io.images import write_image

    settings = RenderSettings(width=4, height=4, spp=3, seed=11, integrator="path").validate()
    path = tmp_path / "out.exr"
    write_image(path, np.zeros((4, 4, 3)), header=settings.header())
    spec = oiio.ImageInput.open(str(path)).spec()
    assert spec.getattribute("rtmesh:integrator") == "path"
    assert spec.getattribute("rtmesh:spp") == 3
    assert spec.getattribute("rtmesh:seed") == "11"
    assert spec.getattribute("rtmesh:max_depth") == -1


LIGHT_PATHS = ("emission", "direct_diffuse", "direct_glossy", "direct_transmission", "indirect_diffuse",
               "indirect_glossy", "indirect_transmission")


def test_light_path_passes_sum_to_the_image(sphere):
    """A Blinn-Phong sphere (diffuse, highlight, mirror) on a diffuse floor under a point
    light and a sky: the seven passes add up to the image sample by sample."""
    from rtmesh.lights.point_lights import PointLight

    floor = trimesh.creation.box(extents=(6.0, 0.1, 6.0))
    floor.apply_translation((0.0, -1.05, 0.0))
    parts = [MeshPart("s", sphere.vertices, sphere.faces, 0, vertex_normals=sphere.vertex_normals),
             MeshPart("floor", floor.vertices, floor.faces, 1)]
    materials = [Material("s", diffuse=0.4, specular=0.2, shininess=30.0, mirror=0.3),
                 Material("g", model="lambert", diffuse=0.6)]
    camera = Camera(np.array([0.0, 1.0, 4.0]), np.zeros(3), np.array([0.0, 1.0, 0.0]), fov=50.0)
    scene = Scene.from_parts(parts, materials=materials, lights=[PointLight((2.0, 3.0, 2.0), 20.0)],
                             camera=camera, background=0.3)
    result = Integrator(scene, RenderSettings(width=20, height=16, spp=8, integrator="path", threads=2,
                                              passes=LIGHT_PATHS)).render()
    total = sum(result.passes[name] for name in LIGHT_PATHS)
    np.testing.assert_allclose(total, result.image, rtol=1e-5, atol=1e-6)
    for name in ("emission", "direct_diffuse", "direct_glossy", "indirect_diffuse", "indirect_glossy"):
        assert result.passes[name].max() > 0, name
    assert not result.passes["direct_transmission"].any()


def test_light_path_passes_need_the_path_integrator():
    with pytest.raises(ValueError, match="need integrator 'path'"):
        RenderSettings(passes=("direct_diffuse",)).validate()


def _nested(sphere, inner_ior):
    """A water sphere (ior 1.33) holding a smaller sphere of index ``inner_ior`` (None: none),
    before a sky brighter at the top."""
    from rtmesh.scene.background import GradientBackground

    parts = [MeshPart("water", sphere.vertices, sphere.faces, 0, vertex_normals=sphere.vertex_normals)]
    materials = [Material("water", model="dielectric", ior=1.33)]
    if inner_ior is not None:
        parts.append(MeshPart("inner", 0.5 * sphere.vertices, sphere.faces, 1, vertex_normals=sphere.vertex_normals))
        materials.append(Material("inner", model="dielectric", ior=inner_ior))
    camera = Camera(np.array([0.0, 0.0, 3.2]), np.zeros(3), np.array([0.0, 1.0, 0.0]), fov=30.0)
    return Scene.from_parts(parts, materials=materials, lights=[], camera=camera,
                            background=GradientBackground((2.0, 2.0, 2.0), (0.1, 0.1, 0.1)))


def test_an_interface_between_media_of_one_index_is_invisible(sphere):
    """Nested media: inside water, a sphere of index 1.33 bends nothing (the ratio at its
    surface is 1), one of 1.5 does."""
    blocks = lambda image: image.reshape(4, 6, 4, 6, 3).mean(axis=(1, 3))
    alone = blocks(_mean(_nested(sphere, None), spp=64, integrator="path"))
    same = blocks(_mean(_nested(sphere, 1.33), spp=64, integrator="path"))
    denser = blocks(_mean(_nested(sphere, 1.5), spp=64, integrator="path"))
    error = lambda a: np.sqrt(np.mean((a - alone) ** 2)) / alone.mean()
    assert error(same) < 0.02
    assert error(denser) > 3 * error(same)


def test_whitted_only_keys_are_ignored_under_path_with_one_warning(sphere, caplog):
    scene = _outside(sphere, Material("m", model="lambert"))
    scene.ambient = np.full(3, 0.2)
    with caplog.at_level("WARNING"):
        Integrator(scene, RenderSettings(width=8, height=8, spp=1, integrator="path", cutoff=0.01,
                                         light_samples=16)).render()
    warnings = [r.getMessage() for r in caplog.records if "ignores" in r.getMessage()]
    # light_samples means next-event estimates at the first vertex under path
    # (tests/rendering/test_light_samples.py): not ignored
    assert len(warnings) == 1 and "ambient, cutoff" in warnings[0] and "light_samples" not in warnings[0]
    caplog.clear()
    with caplog.at_level("WARNING"):
        Integrator(_outside(sphere, Material("m", model="lambert")),
                   RenderSettings(width=8, height=8, spp=1, integrator="path")).render()
    assert not [r for r in caplog.records if "ignores" in r.getMessage()]


def test_a_moving_emitter_keeps_the_power_choice_under_the_light_tree(caplog):
    """The light tree bounds emitters where they rest: with an emitter on a moving object the
    choice stays by power (the same image, bit for bit) and one warning says so."""
    scene = _moving_lamp((0.0, 1.0), MOVING_LAMP)
    power = _mean(scene, spp=4, size=16, integrator="path", max_depth=1)
    with caplog.at_level("WARNING"):
        tree = _mean(scene, spp=4, size=16, integrator="path", max_depth=1, light_sampler="tree")
    np.testing.assert_array_equal(tree, power)
    assert [r.message for r in caplog.records].count(
        "light_sampler 'tree' does not bound emitters on moving objects: lights are chosen by power") == 1
