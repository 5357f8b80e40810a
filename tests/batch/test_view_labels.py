"""rtmesh.batch.view_labels: the pixel-centre passes a batch view's labels read, traced only
when asked for and not rendered already."""

from types import SimpleNamespace

import numpy as np
import pytest
from scenes import settings, sphere_on_floor_scene

from rtmesh.batch.bop import BOP_SUFFIXES
from rtmesh.batch.coco import COCO_SUFFIX
from rtmesh.batch.view_labels import label_passes
from rtmesh.rendering.integrator import Integrator


@pytest.fixture(scope="module")
def rendered():
    integrator = Integrator(sphere_on_floor_scene(), settings(width=16, height=12, spp=1,
                                                              passes=("object_id", "depth")))
    return integrator, integrator.render()


@pytest.mark.parametrize("files, flow, traced", [
    (("v.png",), (), set()),
    (("v.png", "v" + COCO_SUFFIX), (), set()),  # object_id was rendered: not traced again
    (("v.png", "v" + BOP_SUFFIXES[0]), (), {"depth_center"}),
    (("v.png",), (None, "front"), {"position_center"}),
])
def test_only_the_missing_centre_passes_are_traced(rendered, files, flow, traced):
    integrator, result = rendered
    labels = label_passes(integrator, result, SimpleNamespace(files=files, flow=flow))
    assert set(labels) == set(result.passes) | traced
    # the render's own passes are handed on as they are, not traced again
    assert all(labels[name] is result.passes[name] for name in result.passes)
    hit = result.passes["object_id"][..., 0] >= 0  # (misses read inf or NaN)
    for name in traced:
        assert labels[name].shape[:2] == (12, 16) and hit.any() and np.isfinite(labels[name][hit]).all()
