"""The render plan is a frozen record of the stages a render needs."""

import dataclasses

import numpy as np
import pytest
from scenes import settings, sphere_on_floor_scene

from rtmesh.rendering.integrator import Integrator
from rtmesh.rendering.render_plan import RenderPlan


def test_plan_is_frozen_and_lists_what_runs():
    plan = RenderPlan(lights=1, background=np.bool_(True))
    assert plan.enabled() == ["lights", "background"]
    assert plan.lights is True
    with pytest.raises(dataclasses.FrozenInstanceError):
        plan.lights = False


def test_a_render_reports_its_plan():
    integrator = Integrator(sphere_on_floor_scene(smooth=True), settings(width=8, height=8))
    assert integrator.plan.smooth_normals and integrator.plan.lights and not integrator.plan.reflection
    result = integrator.render()
    assert result.stats.stages_enabled == integrator.plan.enabled()


def test_the_fused_stage_takes_only_what_it_can_render():
    """Its choice is a capability list: every need of the plan beyond it (each other flag,
    and one a later feature might add) sends the render to the path kernel."""
    from rtmesh.rendering.direct_stage import FUSED_CAN_RENDER

    plan = RenderPlan(lights=True, smooth_normals=True, fused_direct=True)
    assert plan.needs() == {"lights", "smooth_normals"} and plan.needs() <= FUSED_CAN_RENDER
    scene = sphere_on_floor_scene(smooth=True)
    assert Integrator(scene, settings(width=8, height=8)).direct_stage is not None
    for name in (f.name for f in dataclasses.fields(RenderPlan)):
        if name not in FUSED_CAN_RENDER | {"fused_direct"}:
            assert not dataclasses.replace(plan, **{name: True}).needs() <= FUSED_CAN_RENDER
