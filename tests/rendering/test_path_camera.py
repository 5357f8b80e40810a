"""The path kernel's own camera rays (rtmesh.rendering.path_camera) against the rays the
integrator forms with Camera.generate_rays and hands to the kernel: the same image, bit for
bit, under every sampler, in both of the kernel's configurations."""

import dataclasses
import os

import numpy as np
import pytest

from rtmesh.api import load_scene
from rtmesh.rendering.integrator import Integrator
from rtmesh.rendering.path_stage import PathStage

from scenes import ASSETS


def _render(scene, settings, in_kernel, monkeypatch):
    built = PathStage.__init__

    def forced(self, it):
        built(self, it)
        self.camera_in_kernel = in_kernel
        self._camera = (in_kernel,) + self._camera[1:]

    with monkeypatch.context() as patch:
        patch.setattr(PathStage, "__init__", forced)
        integrator = Integrator(scene, settings)
        assert integrator.path_stage is not None and integrator.path_stage.camera_in_kernel == in_kernel
        return integrator.render()


@pytest.mark.parametrize("sampler", ["regular", "jittered", "random", "sobol", "zsobol"])
@pytest.mark.parametrize("source, integrator", [("showcase.toml", "whitted"), ("glass_edges.toml", "path"),
                                                ("effects/motion_blur.toml", "whitted"), ("effects/dof.toml", "path")])
def test_the_kernels_camera_rays_are_the_cameras(source, integrator, sampler, monkeypatch):
    scene, settings = load_scene(os.path.join(ASSETS, source), width=24, height=16, spp=2, sampler=sampler,
                                 integrator=integrator, passes=("depth", "normal"))
    ours = _render(scene, settings, True, monkeypatch)
    handed = _render(scene, settings, False, monkeypatch)
    assert np.array_equal(ours.image, handed.image)
    for name in ("depth", "normal"):
        assert np.array_equal(ours.passes[name], handed.passes[name]), name
    assert ours.stats.rays == handed.stats.rays


@pytest.mark.parametrize("source, feature", [("dof.toml", "lens"), ("motion_blur.toml", "motion")])
def test_a_thin_lens_and_moving_objects_leave_the_camera_rays_to_the_kernel(source, feature):
    # the chunk hands the kernel each sample's point on the aperture, or its time (the
    # camera does not move); an orthographic camera still hands it the rays.  (A pass keeps
    # the depth-of-field scene off the fused direct stage, which takes thin lenses too.)
    scene, settings = load_scene(os.path.join(ASSETS, "effects", source), width=16, height=12, spp=1,
                                 passes=("depth",))
    integrator = Integrator(scene, settings)
    assert getattr(integrator.plan, feature) and integrator.path_stage is not None
    assert integrator.path_stage.camera_in_kernel
    scene.camera = dataclasses.replace(scene.camera, projection="orthographic", aperture=0.0, ortho_height=2.0)
    assert not Integrator(scene, settings).path_stage.camera_in_kernel
