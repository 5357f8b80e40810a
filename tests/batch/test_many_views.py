"""Many views, one build: views of one asset share one loaded, built scene."""

import dataclasses

import numpy as np
import OpenImageIO as oiio
from scenes import settings, sphere_on_floor_scene

from rtmesh.batch import jobs, view_scenes, worker
from rtmesh.geometry import accel as accel_module
from rtmesh.lights.point_lights import DirectionalLight
from rtmesh.rendering.integrator import Integrator
from rtmesh.rendering.settings import RenderSettings
from rtmesh.scene.camera import Camera


def _other_camera():
    return Camera(np.array([5.0, 4.0, 3.0]), np.array([0.0, 0.0, 0.5]), [0.0, 0.0, 1.0], 40.0)


def test_with_view_renders_what_a_fresh_build_renders():
    """Bit for bit, with passes (camera-dependent depth) and with other lights."""
    scene = sphere_on_floor_scene(smooth=True)
    s = settings(width=24, height=18, spp=2, sampler="jittered", passes=("depth", "position", "normal"))
    built = Integrator(scene, s)
    camera = _other_camera()
    lights = [DirectionalLight(np.array([0.3, -0.2, -1.0]), 2.0)]
    fresh = Integrator(dataclasses.replace(scene, camera=camera, lights=lights), s).render()
    shared = built.with_view(camera, lights)
    # one build (rtmesh.rendering.built_scene): the Embree scene, tables and kernel records
    assert shared.built is built.built and shared.accel is built.accel and shared.tables is built.tables
    again = shared.render()
    np.testing.assert_array_equal(again.image, fresh.image)
    for name in ("depth", "position", "normal"):
        np.testing.assert_array_equal(again.passes[name], fresh.passes[name])
    # the original view is untouched by the new one
    np.testing.assert_array_equal(built.render().image, Integrator(scene, s).render().image)


def test_orthographic_and_fused_views_match_fresh_builds():
    scene = sphere_on_floor_scene()
    s = settings(width=20, height=20, spp=1)
    built = Integrator(scene, s)
    for camera in (_other_camera(),
                   Camera(np.array([0.0, -6.0, 5.0]), np.zeros(3), [0.0, 0.0, 1.0],
                          projection="orthographic", ortho_height=6.0)):
        fresh = Integrator(dataclasses.replace(scene, camera=camera), s)
        shared = built.with_view(camera)
        assert (shared.direct_stage is None) == (fresh.direct_stage is None)
        np.testing.assert_array_equal(shared.render().image, fresh.render().image)


def test_a_batch_job_loads_once_and_builds_once_per_ground_variant(tmp_path, monkeypatch):
    """Eight turntable frames: one load, one Embree build; images as from fresh builds."""
    mesh = tmp_path / "a.obj"
    mesh.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n")
    builds, loads = [], []
    real_accel, real_load = accel_module.Accel.__init__, view_scenes.mesh_file_parts

    def counting_accel(self, *args, **kwargs):
        builds.append(1)
        return real_accel(self, *args, **kwargs)

    def counting_load(*args, **kwargs):
        loads.append(1)
        return real_load(*args, **kwargs)

    monkeypatch.setattr(accel_module.Accel, "__init__", counting_accel)
    monkeypatch.setattr(view_scenes, "mesh_file_parts", counting_load)
    views = jobs.turntable_views(8) + [jobs.fixed_view("bottom")]
    tasks = tuple(jobs.ImageTask(v.name, v, (f"{v.name}.exr",), "") for v in views)
    fields = {"width": 16, "height": 12, "spp": 1, "threads": 1}
    result = worker.run_job(jobs.AssetJob("a.obj", str(mesh), str(tmp_path), fields, tasks, ground=True))
    assert [i["status"] for i in result["images"]] == ["done"] * 9
    # one load; one build with the ground plane (the turntable), one without (from below)
    assert len(loads) == 1 and len(builds) == 2

    loaded = view_scenes.load_asset(jobs.AssetJob("a.obj", str(mesh), str(tmp_path), fields, ()))
    rs = RenderSettings(**fields).validate()
    for view in (views[3], views[-1]):
        fresh = Integrator(view_scenes._scene_for_view(loaded, view, rs, True), rs).render()
        written = oiio.ImageInput.open(str(tmp_path / f"{view.name}.exr")).read_image("float")
        np.testing.assert_array_equal(written[..., :3], fresh.image[..., :3])


def test_physical_assets_get_the_studio_turned_to_each_view(tmp_path):
    """A glTF metallic-roughness asset in a batch: no lights, the studio environment turned to
    each fixed view's rig camera; the shared build renders what a fresh build renders."""
    import trimesh
    from trimesh.visual.material import PBRMaterial

    from rtmesh.scene.studio import STUDIO_PATH

    sphere = trimesh.creation.icosphere(subdivisions=2)
    sphere.visual = trimesh.visual.TextureVisuals(
        material=PBRMaterial(name="m", baseColorFactor=[0.9, 0.6, 0.3, 1.0], metallicFactor=1.0, roughnessFactor=0.4))
    mesh = tmp_path / "ball.glb"
    sphere.export(mesh)
    views = [jobs.fixed_view("iso"), jobs.fixed_view("left")]
    tasks = tuple(jobs.ImageTask(v.name, v, (f"{v.name}.exr",), "") for v in views)
    fields = {"width": 12, "height": 12, "spp": 2, "threads": 1}
    result = worker.run_job(jobs.AssetJob("ball.glb", str(mesh), str(tmp_path), fields, tasks))
    assert [i["status"] for i in result["images"]] == ["done"] * 2
    loaded = view_scenes.load_asset(jobs.AssetJob("ball.glb", str(mesh), str(tmp_path), fields, ()))
    # a glTF asset in a batch renders with the path integrator unless the batch says otherwise
    rs = RenderSettings(**fields, integrator="path").validate()
    rotations = []
    for view in views:
        scene = view_scenes._scene_for_view(loaded, view, rs, False)
        assert scene.lights == [] and scene.background.name == STUDIO_PATH and scene.background.lighting
        rotations.append(scene.background.rotation)
        fresh = Integrator(scene, rs).render()
        written = oiio.ImageInput.open(str(tmp_path / f"{view.name}.exr")).read_image("float")
        np.testing.assert_array_equal(written[..., :3], fresh.image[..., :3])
    assert abs(rotations[0] - rotations[1]) > 1.0


def test_views_that_keep_the_background_share_its_light_sampler():
    """A lit environment is built once per background a view names, not once per view."""
    from rtmesh.scene.background import background_from_option

    def lighting_map():
        background = background_from_option("rtmesh/scene/studio.exr")
        background.lighting = True  # as a scene file's [background] lighting = true
        return background

    scene = dataclasses.replace(sphere_on_floor_scene(), background=lighting_map())
    s = settings(width=16, height=12, spp=1)
    built = Integrator(scene, s)
    assert built.environment_lighting is not None
    assert built.with_view(_other_camera()).environment_lighting is built.environment_lighting
    other = built.with_view(_other_camera(), background=lighting_map())
    assert other.environment_lighting is not None and other.environment_lighting is not built.environment_lighting
