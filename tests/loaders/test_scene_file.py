"""Scene files: every kind of mistake is an error naming the file and the key."""

import re
from pathlib import Path

import numpy as np
import pytest
import scenes

from rtmesh.core.errors import SceneError
from rtmesh.lights.point_lights import DirectionalLight, PointLight, SpotLight
from rtmesh.loaders.scene_file import read_scene_file, scene_from_dict

BASE = {
    "objects": [{"primitive": "icosphere", "subdivisions": 1}],
    "lights": [{"type": "point", "position": [0, 0, 5], "intensity": 10}],
}


def with_(**tables):
    doc = {k: (list(v) if isinstance(v, list) else dict(v)) for k, v in BASE.items()}
    doc.update(tables)
    return doc


@pytest.mark.parametrize(
    "doc, where",
    [
        (with_(rendr={}), "rendr: unknown key"),
        (with_(render={"spp": "4"}), "render.spp: expected an integer"),
        (with_(render={"spp": 0}), "render: spp must be >= 1"),
        (with_(render={"sampler": "halton"}), "render: sampler must be one of"),
        (with_(render={"width": 1.5}), "render.width: expected an integer"),
        (with_(camera={"position": [0, 0], "look_at": [0, 0, 0]}), "camera.position: expected a list of 3 numbers"),
        (with_(camera={"position": [0, 0, 1], "look_at": [0, 0, 1]}), "camera: camera position and look_at coincide"),
        (with_(materials={"m": {"difuse": 0.5}}), "materials.m.difuse: unknown key"),
        (with_(materials={"m": {"diffuse": -1}}), "materials.m.diffuse: colour components must be >= 0"),
        (with_(objects=[{"primitive": "cone"}]), "objects[0].primitive: expected one of"),
        (with_(objects=[{"primitive": "box", "material": "nope"}]), "objects[0].material: unknown material 'nope'"),
        (with_(objects=[{"primitive": "box", "radius": 2}]), "objects[0].radius: does not apply"),
        (with_(objects=[{"mesh": "a.obj", "primitive": "box"}]), "objects[0]: needs exactly one of"),
        (with_(objects=[{"mesh": "missing.obj"}]), "objects[0].mesh:"),
        (with_(objects=[]), "objects: the scene has no objects"),
        (with_(objects=[{"primitive": "box", "scale": 0}]), "objects[0].scale: scale must not be zero"),
        (with_(lights=[{"type": "point", "position": [0, 0, 1]}]), "lights[0].intensity: missing"),
        (with_(lights=[{"type": "point", "position": [0, 0, 1], "intensity": 1, "irradiance": 1}]),
         "lights[0].irradiance: does not apply to a point light"),
        (with_(lights=[{"position": [0, 0, 1]}]), "lights[0].type: missing"),
        (with_(lights=[{"type": "directional", "direction": [0, 0, 0], "irradiance": 1}]),
         "lights[0]: directional light direction has zero length"),
        (with_(environment={"ambient": "grey"}), "environment.ambient: expected a number or a list of 3 numbers"),
        (with_(render={"cutoff": float("nan")}), "render.cutoff: expected a finite number"),
    ],
)
def test_invalid_scene_names_file_and_key(doc, where):
    with pytest.raises(SceneError) as info:
        scene_from_dict(doc, source="s.toml")
    assert str(info.value).startswith(f"s.toml: {where}")


def test_toml_syntax_error_names_the_file(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text("[render\nwidth = 3")
    with pytest.raises(SceneError, match=f"{path}: TOML syntax error"):
        read_scene_file(path)


def test_scene_builds_objects_materials_lights_and_transforms():
    doc = {
        "render": {"width": 20, "height": 10, "spp": 3},
        "camera": {"position": [0, -5, 0], "look_at": [0, 0, 0], "up": [0, 0, 1], "fov": 30},
        "environment": {"ambient": 0.2, "background": [0.1, 0.2, 0.3]},
        "materials": {"glass": {"transmission": 1, "ior": 1.33, "diffuse": 0}},
        "objects": [
            {"primitive": "box", "extents": [2, 2, 2], "translate": [10, 0, 0], "material": "glass"},
            {"primitive": "plane", "size": [4, 2], "rotate": [90, 0, 0], "scale": 2},
        ],
        "lights": [
            {"type": "point", "position": [0, 0, 5], "intensity": [1, 2, 3]},
            {"type": "directional", "direction": [0, 0, -2], "irradiance": 0.5},
            {"type": "spot", "position": [0, 0, 5], "look_at": [0, 0, 0], "intensity": 4},
        ],
    }
    scene, settings = scene_from_dict(doc)
    assert (settings.width, settings.height, settings.spp) == (20, 10, 3)
    assert scene.object_names == ["box[0]", "plane[1]"]
    box = scene.vertices[np.unique(scene.faces[scene.object_id == 0])]
    np.testing.assert_allclose(box.min(axis=0), [9, -1, -1])
    np.testing.assert_allclose(box.max(axis=0), [11, 1, 1])
    # the plane (4 x 2, scaled 2, rotated 90 degrees about X) lies in the XZ plane
    plane = scene.vertices[np.unique(scene.faces[scene.object_id == 1])]
    np.testing.assert_allclose(np.ptp(plane, axis=0), [8, 0, 4], atol=1e-12)
    np.testing.assert_allclose(np.abs(scene.face_normals[scene.object_id == 1]), [[0, 1, 0]] * 2, atol=1e-12)
    assert scene.materials.materials[scene.material_id[0]].name == "glass"
    assert scene.materials.ior[scene.material_id[0]] == 1.33
    assert [type(light) for light in scene.lights] == [PointLight, DirectionalLight, SpotLight]
    np.testing.assert_allclose(scene.lights[2].direction, [0, 0, -1])
    np.testing.assert_allclose(scene.background, [0.1, 0.2, 0.3])


def test_command_line_overrides_scene_settings():
    _, settings = scene_from_dict(with_(render={"spp": 8, "width": 30}), overrides={"spp": 2, "height": None})
    assert settings.spp == 2 and settings.width == 30 and settings.height == 480


@pytest.mark.parametrize("table", ["RENDER_KEYS", "CAMERA_KEYS", "ENVIRONMENT_KEYS", "MATERIAL_KEYS",
                                   "OBJECT_KEYS", "MOTION_KEYS", "light_keys", "BACKGROUND_KEYS"])
def test_every_scene_key_is_documented(table):
    # docs/SCENE_FORMAT.md promises to list every key: a key added to the schema without
    # its documentation fails here
    import rtmesh.loaders.scene_keys as scene_keys

    doc = (Path(scenes.ROOT) / "docs" / "SCENE_FORMAT.md").read_text()
    keys = getattr(scene_keys, table)
    missing = [key for key in (keys() if callable(keys) else keys) if f"`{key}`" not in doc]
    assert not missing, f"{table} keys missing from docs/SCENE_FORMAT.md: {missing}"


def test_a_registered_light_type_is_read_from_scene_files_without_touching_the_reader(monkeypatch):
    """A new light is its module plus its registry entry: the scene-file reader takes its
    keys, required keys and builder from the registry."""
    from rtmesh.lights.light_types import LightType
    from rtmesh.loaders import light_registry, scene_file

    lamp = LightType("lamp", {"position": "vec3", "watts": "non_negative"}, ("position",),
                     lambda v: PointLight(v["position"], v.get("watts", 1.0) / 10.0))
    monkeypatch.setitem(light_registry.LIGHT_TYPES, "lamp", lamp)
    assert scene_file.LIGHT_TYPES is light_registry.LIGHT_TYPES
    scene, _ = scene_from_dict(with_(lights=[{"type": "lamp", "position": [1, 2, 3], "watts": 40}]))
    (light,) = scene.lights
    assert isinstance(light, PointLight) and np.allclose(light.intensity, 4.0)
    with pytest.raises(SceneError, match=r"lights\[0\]\.watts: expected a"):
        scene_from_dict(with_(lights=[{"type": "lamp", "position": [1, 2, 3], "watts": "x"}]))
    with pytest.raises(SceneError, match=r"lights\[0\]\.intensity: does not apply to a lamp light"):
        scene_from_dict(with_(lights=[{"type": "lamp", "position": [1, 2, 3], "intensity": 1}]))


@pytest.mark.parametrize(
    "render, message",
    [
        ({"width": 0}, "render: width must be >= 1 and <= 1048576 (got 0)"),
        ({"height": 2**21}, "render: height must be >= 1 and <= 1048576 (got 2097152)"),
        ({"spp": 2**41}, "render: spp must be >= 1 and <= 1099511627776 (got 2199023255552)"),
        ({"spp": 2**33, "sampler": "sobol"}, "render: spp and max_spp must be <= 4294967296 with the sobol sampler"),
        ({"max_depth": 10**6}, "render: max_depth must be >= 0 and <= 1024"),
        ({"seed": 2**64}, "render: seed must be"),
        ({"threads": 0}, "render: threads must be >= 1"),
        ({"chunk_samples": 2**40}, "render: chunk_samples must be >= 1 and <= 2**31 - 1"),
        ({"ao_samples": 10**5}, "render: ao_samples must be >= 0 and <= 4096"),
        ({"light_samples": 10**5}, "render: light_samples must be >= 1 and <= 4096"),
        ({"exposure": 1000.0}, "render: exposure must be a number of stops from -64 to 64 (got 1000.0)"),
        ({"exposure": float("nan")}, "render.exposure: expected a finite number"),
        ({"target_error": float("inf")}, "render.target_error: expected a finite number"),
        ({"max_spp": 2**41, "target_error": 0.1}, "render: max_spp must be >= spp and <= 1099511627776"),
    ],
)
def test_render_settings_out_of_range_name_the_key_and_value(render, message):
    with pytest.raises(SceneError) as info:
        scene_from_dict(with_(render=render), source="s.toml")
    assert f"s.toml: {message}" in str(info.value)


@pytest.mark.parametrize("fov", [0, 180, 270, -10, float("inf")])
def test_camera_fov_must_be_between_0_and_180_degrees(fov):
    camera = {"position": [0, -5, 0], "look_at": [0, 0, 0], "fov": fov}
    with pytest.raises(SceneError, match=r"s.toml: camera.fov: expected (a finite number|degrees more than 0 and less than 180)"):
        scene_from_dict(with_(camera=camera), source="s.toml")


def test_api_settings_and_cameras_refuse_non_finite_and_out_of_range_values():
    from rtmesh.rendering.settings import RenderSettings
    from rtmesh.scene.camera import Camera

    for bad in (dict(exposure=float("nan")), dict(exposure=float("inf")), dict(cutoff=float("nan")),
                dict(ao_distance=float("inf")), dict(time_limit=float("nan")), dict(width=True)):
        with pytest.raises(ValueError, match=next(iter(bad))):
            RenderSettings(**bad).validate()
    for fov in (0.0, 180.0, 270.0, float("nan")):
        with pytest.raises(ValueError, match="fov must be more than 0 and less than 180"):
            Camera([0, 0, 0], [0, 0, 1], [0, 1, 0], fov=fov)
    RenderSettings(exposure=-64.0, width=1 << 20, spp=1 << 40).validate()
    RenderSettings(sampler="sobol", spp=1 << 32).validate()
    Camera([0, 0, 0], [0, 0, 1], [0, 1, 0], fov=179.9)


def test_cli_exposure_nan_is_a_one_line_error(tmp_path, capsys):
    from rtmesh.cli import main

    mesh = Path(scenes.DATA) / "quadknot.obj"
    out = tmp_path / "x.png"
    assert main(["render", str(mesh), "-o", str(out), "--exposure", "nan", "-q"]) == 2
    err = capsys.readouterr().err
    assert err == "rtmesh: error: render settings: exposure must be a number of stops from -64 to 64 (got nan)\n"
    assert not out.exists()


@pytest.mark.parametrize("doc, where", [
    (with_(camera={"position": [0, 0, 1e300], "look_at": [0, 0, 0]}), "camera.position"),
    (with_(lights=[{"type": "point", "position": [0, 0, 5], "intensity": 1e19}]), "lights[0].intensity"),
    (with_(objects=[{"primitive": "box", "translate": [1e30, 0, 0]}]), "objects[0].translate"),
    (with_(objects=[{"primitive": "icosphere", "radius": 1e300}]), "objects[0].radius"),
    (with_(materials={"m": {"roughness": 5e-324}}), "materials.m.roughness"),
    (with_(materials={"m": {"ior": 1e-30}}), "materials.m.ior"),
])
def test_numbers_beyond_1e18_or_below_1e_18_are_refused_naming_the_key(doc, where):
    # squares, products and reciprocals of such numbers overflow (and coordinates leave float32)
    with pytest.raises(SceneError, match=re.escape(f"s.toml: {where}: expected a ") + r".*0, or magnitude 1e-18 to 1e\+18"):
        scene_from_dict(doc, source="s.toml")
    # within the bounds a scene reads
    scene_from_dict(with_(objects=[{"primitive": "box", "translate": [1e18, 1e-18, 0]}]), source="s.toml")


def test_an_object_far_from_what_the_camera_looks_at_is_dropped_with_a_warning(caplog):
    import logging

    from rtmesh.rendering.integrator import Integrator

    doc = with_(camera={"position": [0, -5, 1], "look_at": [0, 0, 0], "up": [0, 0, 1]},
                objects=[{"primitive": "icosphere", "subdivisions": 1},
                         {"primitive": "icosphere", "subdivisions": 3, "radius": 1e12,
                          "translate": [0, 0, -1e17]}],
                render={"width": 16, "height": 12, "spp": 1})
    with caplog.at_level(logging.WARNING):
        scene, settings = scene_from_dict(doc, source="s.toml")
    # the far sphere has more faces, but the camera looks at the near one
    assert "s.toml: dropped 1280 of 1360 faces that lie far from the rest" in caplog.text
    image = Integrator(scene, settings).render().image
    assert np.isfinite(image).all() and image.max() > 0


def test_a_moving_object_dropped_for_lying_far_away_no_longer_moves():
    from rtmesh.rendering.integrator import Integrator

    doc = with_(camera={"position": [0, -5, 1], "look_at": [0, 0, 0], "up": [0, 0, 1], "shutter": [0, 1]},
                objects=[{"primitive": "icosphere", "subdivisions": 1},
                         {"primitive": "icosphere", "radius": 1e12, "translate": [0, 0, -1e17],
                          "motion": {"translate": [1e12, 0, 0]}}],
                render={"width": 16, "height": 12, "spp": 2})
    scene, settings = scene_from_dict(doc, source="s.toml")
    assert scene.motions == {}
    assert np.isfinite(Integrator(scene, settings).render().image).all()


@pytest.mark.parametrize("key", ["mirror", "transmission"])
def test_bounce_weights_above_one_are_refused(key):
    # a weight above 1 gains energy at every bounce (1e9 made an infinite image)
    with pytest.raises(SceneError, match=f"s.toml: materials.m.{key}: colour components must be between 0 and 1"):
        scene_from_dict(with_(materials={"m": {key: [1e9, 0.5, 0.5]}}), source="s.toml")
    scene_from_dict(with_(materials={"m": {key: 1}}), source="s.toml")


def test_a_tiny_icosphere_is_a_sphere():
    scene, _ = scene_from_dict(with_(objects=[{"primitive": "icosphere", "subdivisions": 2, "radius": 1e-18}]),
                               source="s.toml")
    np.testing.assert_allclose(np.linalg.norm(scene.vertices, axis=1), 1e-18, rtol=1e-12)
    assert len(scene.faces) == 320
