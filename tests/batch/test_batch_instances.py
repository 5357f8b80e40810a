"""A batch of an asset that places one mesh many times: the worker builds the mesh once and
places it by Embree instances, as ``rtmesh render`` does, and writes the images, labels and
metadata of the asset's copies."""

import json

import numpy as np
import pytest
from scenes import block_means, reusing_glb

from rtmesh.batch import coco, jobs, view_scenes, worker
from rtmesh.batch.bop import BOP_SUFFIXES
from rtmesh.batch.coco import COCO_SUFFIX
from rtmesh.io.images import read_image
from rtmesh.rendering import memory
from rtmesh.rendering.built_scene import recentred
from rtmesh.rendering.settings import RenderSettings
from rtmesh.scene import instances

PLACED = 8
VIEWS = ("iso", "front", "bottom")
# every file a view of a batch can hold that depends on the geometry: the image, the EXR
# with the flow, the COCO fragment, the camera, the BOP ingredients and the coverage mask
SUFFIXES = (".png", ".exr", COCO_SUFFIX, jobs.CAMERA_SUFFIX, jobs.MASK_PNG_SUFFIX) + BOP_SUFFIXES
FIELDS = {"width": 32, "height": 24, "spp": 2, "threads": 1, "caustics": "off", "passes": ("alpha",)}


def _convert(folder, mesh, monkeypatch, copied):
    """One job over ``mesh`` (two views with the ground plane and the flow between them, one
    from below, without the plane), its mesh placed (or ``copied``, below the instancing
    size); the integrators it built and how many amodal masks traced placements."""
    built, placed = [], []

    class Recording(view_scenes.Integrator):
        def __init__(self, scene, settings):
            super().__init__(scene, settings)
            built.append(self)

    def recording_placed(*args):
        placed.append(1)
        return recentred(*args)

    with monkeypatch.context() as patch:
        patch.setattr(view_scenes, "Integrator", Recording)
        patch.setattr(coco, "recentred", recording_placed)
        if copied:
            patch.setattr(instances, "MIN_TRIANGLES", 10 ** 9)
        views = [jobs.fixed_view(name) for name in VIEWS]
        flows = [(None, views[1]), (views[0], None), ()]
        tasks = tuple(jobs.ImageTask(v.name, v, tuple(v.name + s for s in SUFFIXES), "", flow)
                      for v, flow in zip(views, flows))
        job = jobs.AssetJob("reuse.glb", str(mesh), str(folder), FIELDS, tasks, ground=True,
                            normalize="unit-cube", meta=True)
        result = worker.run_job(job)
    assert [image["status"] for image in result["images"]] == ["done"] * len(VIEWS), result
    return built, len(placed)


@pytest.fixture(scope="module")
def converted(tmp_path_factory):
    folder = tmp_path_factory.mktemp("batch-instances")
    mesh = reusing_glb(folder / "reuse.glb", count=PLACED, subdivisions=2)
    with pytest.MonkeyPatch.context() as monkeypatch:
        placed = _convert(folder / "placed", mesh, monkeypatch, copied=False)
        copies = _convert(folder / "copies", mesh, monkeypatch, copied=True)
    return folder, placed, copies


def test_the_worker_traces_the_placements_as_instances(converted):
    _, (placed, amodal), (copies, copied_amodal) = converted
    # one build with the ground plane, one without (the view from below); path traced
    assert len(placed) == len(copies) == 2
    # the asset traced alone for its amodal masks: its placements (once for the two views
    # with the ground plane; without it, the view's own scene), not a copy
    assert (amodal, copied_amodal) == (1, 0)
    for it in placed:
        assert it.settings.integrator == "path" and it.instances is not None
        assert len(it.scene.instances) == PLACED and len(it.scene.faces) < 2 * 320
    assert all(it.scene.instances is None and len(it.scene.faces) > PLACED * 320 for it in copies)


def test_instanced_batch_images_are_those_of_the_copies(converted):
    folder, _, _ = converted
    for view in VIEWS:
        a, b = (read_image(folder / kind / f"{view}.png")[0] for kind in ("placed", "copies"))
        assert a.std() > 0.05  # something to compare
        a, b = block_means(a), block_means(b)
        assert (np.abs(a - b) <= 0.01 * np.maximum(b, 0.05)).all(), view


def _close(a, b, where=""):
    """JSON documents equal: numbers to 1e-9 relative (the placed and the copied vertices
    round differently), everything else exactly."""
    if isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for key in a:
            _close(a[key], b[key], f"{where}.{key}")
    elif isinstance(a, list) and a and not all(isinstance(x, (int, float)) for x in a):
        assert len(a) == len(b), where
        for k, (x, y) in enumerate(zip(a, b)):
            _close(x, y, f"{where}[{k}]")
    elif isinstance(a, float) or (isinstance(a, list) and any(isinstance(x, float) for x in a)):
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9, err_msg=where)
    else:
        assert a == b, where


def test_instanced_batch_labels_are_those_of_the_copies(converted):
    folder, _, _ = converted
    placed, copies = folder / "placed", folder / "copies"
    for view in VIEWS:
        for suffix in (COCO_SUFFIX, jobs.CAMERA_SUFFIX, ".bop.json"):
            documents = [json.loads((kind / f"{view}{suffix}").read_text()) for kind in (placed, copies)]
            _close(*documents, where=f"{view}{suffix}")
        coco = json.loads((placed / f"{view}{COCO_SUFFIX}").read_text())
        # the asset, its ground plane left out, is one instance, seen and partly hidden
        (annotation,) = coco["annotations"]
        assert annotation["object_name"] == "reuse.glb" and 0 < annotation["visible_fraction"] <= 1
        for suffix in (jobs.MASK_PNG_SUFFIX, ".bop_mask.png", ".bop_mask_visib.png", ".bop_depth.png"):
            a, b = (read_image(kind / f"{view}{suffix}")[0] for kind in (placed, copies))
            assert np.array_equal(a, b), f"{view}{suffix}"
    # the flow between the two views with the ground plane: the placements' points are the copies'
    for view, layer in (("iso", "flow_forward"), ("front", "flow_backward")):
        (a, names), (b, _) = (read_image(kind / f"{view}.exr") for kind in (placed, copies))
        x, y, valid = (names.index(f"{layer}.{c}") for c in ("X", "Y", "valid"))
        assert np.array_equal(a[..., valid], b[..., valid]) and a[..., valid].sum() > 20, (view, layer)
        # pixel positions of the same points, rounded differently (measured: 1e-6 pixels apart)
        np.testing.assert_allclose(a[..., [x, y]], b[..., [x, y]], atol=1e-4, err_msg=f"{view} {layer}")
    meta = [json.loads((kind / "reuse.glb.meta.json").read_text()) for kind in (placed, copies)]
    # the placed asset's counts are its copies', and it says what it places
    (placement,) = meta[0].pop("placements")
    assert placement["mesh"].startswith("ball") and (placement["triangles"], placement["placed"]) == (320, PLACED)
    _close(*meta, where="meta")


def test_copies_beyond_a_workers_limit_fail_the_asset_in_one_line(tmp_path, monkeypatch):
    """When the view's build flattens the placements (here by fiat: a scene the kernel cannot
    trace through instances, as transmissive ones), a local worker refuses copies beyond
    its limit before taking the memory (the load itself, instanced, fits)."""
    from rtmesh.scene import instances

    mesh = reusing_glb(tmp_path / "reuse.glb", count=PLACED, subdivisions=2)
    fields = dict(FIELDS, integrator="path", passes=())
    # the render's own memory fits (the worker checks it first, as rtmesh render does)
    render_bytes = memory.estimate(RenderSettings(**fields).validate()).total
    monkeypatch.setattr(view_scenes, "LOAD_LIMIT", render_bytes + 100_000)  # the copies need 1.55 MB
    monkeypatch.setattr(instances, "unsupported", lambda scene, settings: ["transmissive materials (media)"])
    task = jobs.ImageTask("iso", jobs.fixed_view("iso"), ("iso.png",), "")
    (image,) = worker.run_job(jobs.AssetJob("reuse.glb", str(mesh), str(tmp_path), fields, (task,)))["images"]
    assert (image["status"], image["stage"]) == ("failed", "render")
    assert "\n" not in image["message"] and f"{PLACED} placements flattened into copies" in image["message"]
    assert not (tmp_path / "iso.png").exists()
