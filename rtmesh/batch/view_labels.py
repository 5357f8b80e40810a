"""The labels of one batch view: its pixel-centre passes, COCO fragment and optical flow.

What a batch job (:mod:`rtmesh.batch.worker`) adds to a view's render for the files beside
its image: the centre passes its annotations, BOP files and flow read
(:func:`label_passes`), the view's COCO fragment (:func:`image_fragment`,
:mod:`rtmesh.batch.coco`) and its flow towards the views before and after it
(:func:`neighbour_flows`, :mod:`rtmesh.batch.flow`).
"""

import os

import numpy as np

from rtmesh.batch.bop import BOP_SUFFIXES
from rtmesh.batch.coco import COCO_SUFFIX, Instance, image_annotations, image_entry
from rtmesh.batch.flow import FLOW_PASSES, seen_points, view_flow
from rtmesh.batch.jobs import DEPTH_PNG_SUFFIX, MASK_PNG_SUFFIX
from rtmesh.batch.view_scenes import asset_objects, integrator_for_view
from rtmesh.core import runtime
from rtmesh.rendering.centre_rays import centre_passes
from rtmesh.scene.camera_json import camera_record


def label_passes(integrator, result, task):
    """The render's passes and the pixel-centre passes a view's annotations, BOP files and
    flow read (:mod:`rtmesh.rendering.centre_rays`), each traced once, only those asked for
    and not rendered already; they go to no image unless the passes named them."""
    wanted = set()
    if any(f.endswith((COCO_SUFFIX,) + BOP_SUFFIXES) for f in task.files):
        wanted.add("object_id")
    if any(f.endswith(BOP_SUFFIXES) for f in task.files):
        wanted.add("depth_center")
    if task.flow:
        wanted.add("position_center")
    return {**centre_passes(integrator, sorted(wanted - set(result.passes))), **result.passes}


def image_fragment(integrator, labels, task, settings, loaded, asset, ground, accels=None):
    """The COCO fragment of one batch image (:mod:`rtmesh.batch.coco`): the asset
    (:class:`~rtmesh.batch.view_scenes.LoadedAsset` ``loaded``, named ``asset``) is one
    instance of category ``asset``, its model frame the asset file's; the ground plane is
    not annotated (:func:`~rtmesh.batch.view_scenes.asset_objects`)."""
    scene = integrator.scene
    to_world = loaded.to_world
    record = camera_record(scene.camera, settings.width, settings.height, integrator.scene_bounds, to_world)
    objects = asset_objects(scene, ground, task.view, loaded)
    pictures = [f for f in task.files if f.endswith((".png", ".jpg", ".exr"))
                and not f.endswith((DEPTH_PNG_SUFFIX, MASK_PNG_SUFFIX))]
    instance = Instance(asset, asset, objects, np.asarray(to_world, dtype=np.float64))
    annotations = image_annotations(integrator, record, [instance], labels["object_id"], accels)
    return {"image": image_entry(os.path.basename(pictures[0]), record), "annotations": annotations}


def neighbour_flows(labels, task, built, loaded, settings, ground):
    """``flow_forward`` and ``flow_backward`` of one view (see :mod:`rtmesh.batch.flow`),
    towards the views of ``task.flow``, each traced in its own view's scene; the two run
    side by side on the render's threads (their rays go to Embree without the GIL)."""
    position = labels["position_center"]
    seen = seen_points(position)  # the view's points, for both directions
    calls = {}
    for name, view in zip(("flow_backward", "flow_forward"), task.flow):
        other = record = None
        if view is not None:
            other = integrator_for_view(built, loaded, view, settings, ground)
            scene = other.scene
            record = camera_record(scene.camera, settings.width, settings.height, other.scene_bounds,
                                   loaded.to_world)
        calls[name] = (position, other, record, seen)
    traced = [name for name, call in calls.items() if call[1] is not None]
    flows = {name: view_flow(*call) for name, call in calls.items() if name not in traced}
    with runtime.render_pool(min(settings.thread_count, len(traced))) as workers:
        later = {name: workers.submit(view_flow, *calls[name]) for name in traced[1:]} if workers else {}
        for name in traced:
            if name not in later:
                flows[name] = view_flow(*calls[name])
        flows.update({name: future.result() for name, future in later.items()})
    return {name: flows[name] for name in FLOW_PASSES}
