"""COCO instance annotations of rendered images (``--annotations``).

For each image, every annotated instance with at least one visible pixel gets one
annotation, computed from the exact pixel-centre labels (:mod:`rtmesh.rendering.centre_rays`):

- ``segmentation``: the pixels whose centre ray sees the instance, as COCO compressed RLE
  (:mod:`rtmesh.io.rle`: what ``pycocotools.mask.encode`` writes); ``area`` its pixel
  count and ``bbox`` its ``[x, y, width, height]`` (as ``pycocotools.mask.toBbox``);
  ``iscrowd`` 0;
- ``bbox_amodal``: the box of the instance's pixels had nothing occluded it, traced as one
  pixel-centre ray per pixel of its projected bounding box against the instance alone
  (clipped to the image, so it contains ``bbox``); ``area_amodal`` its pixel count and
  ``visible_fraction`` = ``area / area_amodal``;
- ``keypoints_3d_box``: the 8 corners of the instance's model-space bounding box projected
  with ``K`` (corner ``i`` at ``(x[i & 1], y[i >> 1 & 1], z[i >> 2 & 1])`` of the box's
  minimum and maximum), in COCO's keypoint layout ``[u, v, flag] * 8``: flag 2 inside the
  image, 1 in front of the camera but outside it, 0 (and ``u = v = 0``) behind the camera;
  pixel positions in rtmesh's convention (pixel centres at +0.5, docs/CAMERAS.md);
- ``pose``: the 4x4 model-to-camera transform, OpenCV camera axes (``world_to_camera_opencv
  @ model_to_world``; the model frame is the object's own file or primitive frame, for a
  batch asset its file's frame).

Categories come from an object's ``category`` key in scene files, else its name (a glTF
node's name), and are the asset name in a batch.  Ids: images and annotations from 1 in
image order, categories from 1 in name order (COCO's ids start at 1).

A batch (:func:`write_batch_annotations`) writes a fragment ``<image key>.coco.json`` per
image and merges every finished image's fragment into one ``annotations.coco.json`` per
output folder at the end of each run; the merge reads only the fragments, so a resumed run
writes the same file again (idempotent).
"""

import dataclasses
import json
import os
from dataclasses import dataclass

import numpy as np

from rtmesh.geometry.accel import Accel
from rtmesh.geometry.motion import object_motions, scene_at_time
from rtmesh.io.atomic_files import write_text
from rtmesh.io.rle import encode, mask_box
from rtmesh.rendering.centre_rays import centre_hits, centre_passes
from rtmesh.rendering.built_scene import recentred
from rtmesh.scene.camera_json import project_points
from rtmesh.scene.instances import object_geometry

COCO_SUFFIX = ".coco.json"
MERGED_NAME = "annotations.coco.json"
BOX_KEYPOINTS = [f"box_{i}" for i in range(8)]
# the 12 edges of the box, COCO's 1-based skeleton
BOX_SKELETON = [[a + 1, b + 1] for a in range(8) for b in range(a + 1, 8) if bin(a ^ b).count("1") == 1]


@dataclass(frozen=True)
class Instance:
    """One annotated thing in the images: some objects of the scene.

    Attributes
    ----------
    name : str
    category : str
    objects : tuple of int
        Its object indices (``Scene.object_names``).
    to_world : (4, 4) float
        Its model-to-world transform.
    """

    name: str
    category: str
    objects: tuple
    to_world: np.ndarray


def scene_instances(scene):
    """One instance per object of ``scene``, with its category and transform."""
    categories = scene.object_categories or scene.object_names
    to_world = scene.object_to_world or [np.eye(4)] * len(scene.object_names)
    return [Instance(name, category, (i,), np.asarray(matrix, dtype=np.float64))
            for i, (name, category, matrix) in enumerate(zip(scene.object_names, categories, to_world))]


def image_annotations(it, record, instances, object_id=None, accels=None):
    """The annotations of one rendered view.

    Parameters
    ----------
    it : rtmesh.rendering.integrator.Integrator
        The integrator that rendered the view (its scene, camera and image size).
    record : dict
        The view's camera record (:func:`rtmesh.scene.camera_json.camera_record`).
    instances : list of Instance
    object_id : (h, w) or (h, w, 1) float, optional
        The view's ``object_id`` centre pass, when the render has it; traced otherwise.
    accels : dict, optional
        Where to keep each instance's faces, bounds (:func:`instance_geometry`) and own
        Embree scene (:func:`amodal_mask`) between views of one built scene; None forms
        them for this view alone.

    Returns
    -------
    list of dict
        One per instance with a visible pixel, with ``category`` (a name) instead of
        ``category_id`` and without ids (:func:`coco_document` numbers them).
    """
    s = it.settings
    h, w = s.height, s.width
    if object_id is None:
        object_id = centre_passes(it, ("object_id",))["object_id"]
    ids = np.rint(np.asarray(object_id).reshape(h, w)).astype(np.int64)
    scene, moving = it.scene, {}
    if it.motion is not None:  # the labels are traced when the shutter opens
        moving = object_motions(scene)
        scene = scene_at_time(scene, it.camera.shutter[0])
    instance_of = np.full(len(scene.object_names) + 1, -1, dtype=np.int64)  # index -1: no object
    for k, instance in enumerate(instances):
        instance_of[list(instance.objects)] = k
    labels = instance_of[ids]
    w2c = np.array(record["world_to_camera_opencv"])
    annotations = []
    # the instances seen, in order (a count per instance: no sort of the pixels)
    for k in np.flatnonzero(np.bincount(labels[labels >= 0], minlength=len(instances))):
        instance = instances[k]
        to_world = instance.to_world
        if instance.objects[0] in moving:  # its place when the shutter opens
            to_world = moving[instance.objects[0]].matrix(it.camera.shutter[0]) @ to_world
        mask = labels == k
        geometry = instance_geometry(scene, instance.objects, accels)
        amodal = amodal_mask(it, geometry.vertices, geometry.faces, geometry.bounds, record, accels=accels,
                             seen=mask, placed=geometry.placed)
        area, area_amodal = int(mask.sum()), int(amodal.sum())
        annotations.append({
            "category": instance.category, "object_name": instance.name, "instance_id": int(k),
            "bbox": mask_box(mask), "area": area, "segmentation": encode(mask), "iscrowd": 0,
            "bbox_amodal": mask_box(amodal), "area_amodal": area_amodal,
            "visible_fraction": area / area_amodal,
            "keypoints_3d_box": _box_keypoints(geometry.model_box(to_world), to_world, record),
            "pose": (w2c @ to_world).tolist(),
        })
    return annotations


class InstanceGeometry:
    """The faces of some objects of a scene and their bounds, kept between the views of one
    built scene (see :func:`instance_geometry`).

    Attributes
    ----------
    vertices : (V, 3) float
        The vertices ``faces`` index: the scene's, or the objects' own where one of them is
        the one placement of a mesh kept once among them (copied:
        :func:`rtmesh.scene.instances.object_geometry`).
    faces : (F, 3) int
        The objects' faces (indices into ``vertices``).
    placed : rtmesh.scene.instances.Instances or None
        Where the objects hold several placements of meshes kept once: the scene's
        prototypes, ``faces[placed.first_face:]`` (model coordinates), and those placements,
        traced as Embree instances instead of copies (:func:`instance_geometry`); None:
        every face is in the world.
    bounds : (2, 3) float
        The minimum and maximum of their world points.
    """

    def __init__(self, vertices, faces, placed=None):
        self.vertices, self.faces, self.placed = vertices, faces, placed
        # the world faces' points, with repeats (only their bounds are read), kept for the
        # first model box only
        points = self._points = vertices[self._world_faces().ravel()]
        self.bounds = _extent(points, placed, vertices)
        self._model_boxes = {}

    def _world_faces(self):
        return self.faces if self.placed is None else self.faces[:self.placed.first_face]

    def model_box(self, to_world):
        """(2, 3): the minimum and maximum of the points in the model frame of ``to_world``
        (4x4 model-to-world), computed once per transform."""
        key = np.asarray(to_world, dtype=np.float64).tobytes()
        box = self._model_boxes.get(key)
        if box is None:
            points = self.vertices[self._world_faces().ravel()] if self._points is None else self._points
            self._points = None
            model = (points - to_world[:3, 3]) @ np.linalg.inv(to_world[:3, :3]).T
            placed = self.placed
            if placed is not None:  # the placements seen from the model frame
                placed = dataclasses.replace(placed, transforms=np.linalg.inv(to_world) @ placed.transforms)
            box = self._model_boxes[key] = _extent(model, placed, self.vertices)
        return box


def _extent(points, placed, vertices):
    """(2, 3): the minimum and maximum of ``points`` and of every placement of ``placed``
    (:meth:`rtmesh.scene.instances.Instances.bounds` of the prototypes' ``vertices``)."""
    boxes = [np.stack([points.min(axis=0), points.max(axis=0)])] if len(points) or placed is None else []
    if placed is not None:
        boxes.append(placed.bounds(vertices))
    return np.stack([np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)])


def instance_geometry(scene, objects, cache=None):
    """The :class:`InstanceGeometry` of ``objects`` of ``scene``.

    Parameters
    ----------
    scene : Scene
    objects : iterable of int
        Object indices.
    cache : dict, optional
        Where to keep it for other views of the same built scene (by the identity of the
        scene's vertices, which the entry holds while it lives, and the objects); the
        views of a batch asset share one.  None computes it for this view alone.

    Returns
    -------
    InstanceGeometry
    """
    objects = tuple(int(k) for k in objects)
    key = ("instance", id(scene.vertices), objects)
    held = None if cache is None else cache.get(key)
    if held is not None and held[0] is scene.vertices:
        return held[1]
    entry = InstanceGeometry(*_placed_geometry(scene, objects))
    if cache is not None:
        cache[key] = (scene.vertices, entry)
    return entry


def _placed_geometry(scene, objects):
    """``(vertices, faces, placed)`` of :class:`InstanceGeometry` for ``objects``: where they
    hold several placements of meshes kept once, the scene's vertices, the objects' world
    faces followed by the prototypes' and those placements (an Embree instance each: the
    asset of a batch placing a mesh 10,000 times costs no copy); else, with one placement
    copied, what :func:`rtmesh.scene.instances.object_geometry` gives, and None."""
    inst = scene.instances
    chosen = None if inst is None else np.isin(inst.object_id, objects)
    if chosen is None or chosen.sum() < 2:
        return (*object_geometry(scene, objects), None)
    f0 = inst.first_face
    world = scene.faces[:f0][np.isin(scene.object_id[:f0], objects)]
    faces = np.ascontiguousarray(np.concatenate([world, scene.faces[f0:]]), dtype=np.int32)
    placed = dataclasses.replace(inst, first_face=len(world), prototype_faces=inst.prototype_faces + (len(world) - f0),
                                 transforms=inst.transforms[chosen], prototype=inst.prototype[chosen],
                                 object_id=inst.object_id[chosen])
    return scene.vertices, faces, placed


def amodal_mask(it, vertices, faces, points, record, margin=0, accels=None, seen=None, placed=None):
    """The pixels whose centre ray meets ``faces`` traced alone.

    One ray per pixel of the faces' projected bounding box (the whole canvas when part of
    the box is behind a perspective camera).

    Parameters
    ----------
    it : rtmesh.rendering.integrator.Integrator
    vertices : (V, 3) float
        World vertices ``faces`` index.
    faces : (F, 3) int
    points : (k, 3) float
        The world points of ``faces`` (their bounding box is projected).
    record : dict
        The view's camera record.
    margin : int
        Canvas margin, in image sizes: 0 for the image, 1 for the BOP toolkit's canvas of
        three times the image's width and height with the image in its middle.
    accels : dict, optional
        A cache of the faces' Embree scene for other views of the same built scene (by
        the identity of the ``vertices`` and ``faces`` arrays, which it holds: pass the
        same arrays for every view, as :func:`instance_geometry` keeps them): the views of
        a batch asset share one.
    seen : (h, w) bool, optional
        Image pixels known to see the faces (the visible mask): set without a ray.
    placed : rtmesh.scene.instances.Instances, optional
        ``faces[placed.first_face:]`` are prototypes in model coordinates, traced as
        Embree instances placed by it (:attr:`InstanceGeometry.placed`).

    Returns
    -------
    (h * (1 + 2 margin), w * (1 + 2 margin)) bool
    """
    s = it.settings
    h, w = s.height, s.width
    mh, mw = margin * h, margin * w
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)])
    lo, hi = points.min(axis=0), points.max(axis=0)
    uv, z = project_points(record, lo + corners * (hi - lo))
    c0, c1, r0, r1 = -mw, w + mw, -mh, h + mh
    if record["projection"] != "perspective" or (z > 0).all():
        # pixels whose centre lies inside the box's projection, and one more on each side
        c0, r0 = np.maximum(np.floor(uv.min(axis=0) - 0.5).astype(int) - 1, (c0, r0))
        c1, r1 = np.minimum(np.ceil(uv.max(axis=0) - 0.5).astype(int) + 2, (c1, r1))
    mask = np.zeros((h + 2 * mh, w + 2 * mw), dtype=bool)
    if seen is not None:
        mask[mh:mh + h, mw:mw + w] = seen
    if c1 <= c0 or r1 <= r0:
        return mask
    rows, columns = np.mgrid[r0:r1, c0:c1]
    rows, columns = rows.ravel(), columns.ravel()
    if seen is not None:  # a visible pixel's centre ray meets the faces alone too
        todo = ~mask[rows + mh, columns + mw]
        rows, columns = rows[todo], columns[todo]
    # (the cache holds the arrays too, so that their ids name them while it lives)
    key = ("accel", id(vertices), id(faces))
    _, _, alone = (None, None, None) if accels is None else accels.get(key, (None, None, None))
    if alone is None:
        scene = it.scene
        everything = placed is None if scene.instances is None else placed is not None and len(placed) == len(
            scene.instances)
        if (type(it.accel) is Accel and everything and vertices is scene.vertices and len(faces) == len(scene.faces)
                and np.array_equal(faces, scene.faces)):
            # the faces are the whole scene (a batch asset without its ground): the
            # integrator's Embree scene is the one they would get, without a second build
            alone = it.accel
        elif placed is not None:
            shifted, placed = recentred(vertices, placed, it.shift)
            alone = Accel(shifted, faces, instances=placed)
        else:
            alone = Accel(vertices - it.shift, faces)
        if accels is not None:
            accels[key] = (vertices, faces, alone)
    _, _, _, hits = centre_hits(it, columns, rows, alone)
    hit = hits.prim >= 0
    mask[rows[hit] + mh, columns[hit] + mw] = True
    return mask


def _box_keypoints(model_box, to_world, record):
    """``[u, v, flag] * 8`` of the model-space bounding box's corners (see the module notes),
    from its minimum and maximum ``model_box`` (:meth:`InstanceGeometry.model_box`)."""
    lo, hi = model_box
    corners = np.array([[(i >> a) & 1 for a in range(3)] for i in range(8)])
    world = (lo + corners * (hi - lo)) @ to_world[:3, :3].T + to_world[:3, 3]
    uv, z = project_points(record, world)
    front = z > 0 if record["projection"] == "perspective" else np.ones(8, dtype=bool)
    inside = front & (uv[:, 0] >= 0) & (uv[:, 0] <= record["width"]) & (uv[:, 1] >= 0) & (uv[:, 1] <= record["height"])
    flags = np.where(inside, 2, np.where(front, 1, 0))
    uv = np.where(front[:, None], uv, 0.0)
    return np.column_stack([uv, flags]).ravel().tolist()


def image_entry(file_name, record):
    """The COCO ``images`` entry of a view (without its id)."""
    return {"file_name": file_name, "width": int(record["width"]), "height": int(record["height"])}


def coco_document(views):
    """A COCO document of rendered views.

    Parameters
    ----------
    views : list of (dict, list of dict)
        Each view's :func:`image_entry` and :func:`image_annotations`, in image order.

    Returns
    -------
    dict
        ``info``, ``images``, ``annotations``, ``categories`` (COCO's detection layout, with
        the keypoint names and skeleton of the box corners), JSON-ready.
    """
    names = sorted({a["category"] for _, annotations in views for a in annotations})
    category_id = {name: i + 1 for i, name in enumerate(names)}
    images, annotations = [], []
    for image_id, (entry, items) in enumerate(views, start=1):
        images.append({"id": image_id, **entry})
        for item in items:
            item = dict(item)
            annotations.append({"id": len(annotations) + 1, "image_id": image_id,
                                "category_id": category_id[item.pop("category")], **item})
    categories = [{"id": category_id[name], "name": name, "supercategory": "object",
                   "keypoints": BOX_KEYPOINTS, "skeleton": BOX_SKELETON} for name in names]
    return {"info": {"description": "rtmesh renders", "version": "1.0"}, "images": images,
            "annotations": annotations, "categories": categories}


def annotate_render(path, it, result, image_name, record):
    """Write the COCO file of one ``rtmesh render`` image (``--annotations PATH``): every
    object of the scene an instance.

    Parameters
    ----------
    path : str
    it : rtmesh.rendering.integrator.Integrator
    result : rtmesh.rendering.render_result.RenderResult
        Its ``object_id`` pass is used when it has one.
    image_name : str
        The image's ``file_name`` in the document.
    record : dict
        The image's camera record.
    """
    annotations = image_annotations(it, record, scene_instances(it.scene), result.passes.get("object_id"))
    write_coco(path, coco_document([(image_entry(image_name, record), annotations)]))


def write_coco(path, document):
    """Write a COCO document (or a fragment) as JSON, atomically."""
    write_text(path, json.dumps(document, separators=(",", ":")) + "\n")


def write_batch_annotations(outdir, images):
    """Merge the fragments of finished images into one ``annotations.coco.json`` per folder.

    Parameters
    ----------
    outdir : str
    images : iterable of (str, list of str)
        ``(key, files)`` of each finished image (done or skipped), names relative to
        ``outdir``; those without a ``.coco.json`` fragment are left out.

    Returns
    -------
    list of str
        The files written.
    """
    folders = {}
    for key, files in images:
        fragments = [f for f in files if f.endswith(COCO_SUFFIX)]
        if fragments:
            folders.setdefault(os.path.dirname(key), {})[key] = fragments[0]
    written = []
    for folder, fragments in sorted(folders.items()):
        views = []
        for key in sorted(fragments):
            with open(os.path.join(outdir, fragments[key]), encoding="utf-8") as f:
                fragment = json.load(f)
            entry = dict(fragment["image"])
            entry["file_name"] = os.path.relpath(os.path.join(os.path.dirname(key), entry["file_name"]), folder)
            views.append((entry, fragment["annotations"]))
        path = os.path.join(outdir, folder, MERGED_NAME)
        write_coco(path, coco_document(views))
        written.append(path)
    return written
