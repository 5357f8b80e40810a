"""The BOP layout for pose estimation (``rtmesh batch ... --dataset bop``).

Each asset becomes one BOP scene, ``OUTDIR/<asset>.bop/``, whose one object (``obj_id`` 1)
is the asset (the ground plane of ``--ground`` occludes but is not an object):

- ``scene_camera.json``: per image id (``"0"``, ``"1"``... in view order) ``cam_K`` (3x3
  row-major, pixels), ``cam_R_w2c`` (3x3 row-major), ``cam_t_w2c`` (mm) and
  ``depth_scale`` (the depth PNG's millimetres per unit stored);
- ``scene_gt.json``: per image a list with one ``{"cam_R_m2c", "cam_t_m2c" (mm),
  "obj_id"}``, the model-to-camera pose (OpenCV axes);
- ``scene_gt_info.json``: per image ``bbox_obj``, ``bbox_visib`` (``[x, y, w, h]`` with
  ``w = x_max - x_min`` as the BOP toolkit's ``calc_2d_bbox``; ``bbox_obj`` not clipped to
  the image), ``px_count_all`` (the object's pixels if nothing occluded it, counted on a
  canvas three times the image's width and height, as the toolkit renders it),
  ``px_count_valid`` (those in the image with a depth), ``px_count_visib`` and
  ``visib_fract`` = ``px_count_visib / px_count_all``;
- ``rgb/000000.png`` (or ``.jpg``), ``depth/000000.png`` (uint16, depth in mm =
  value x ``depth_scale``, 0 where nothing is hit), ``mask/000000_000000.png`` (the
  object's pixels in the image as if nothing occluded it) and ``mask_visib/...`` (its
  visible pixels), 8-bit, 255 on the object;
- ``models/obj_000001.ply`` (the model in mm) and ``models/models_info.json``
  (``diameter``, ``min_x|y|z``, ``size_x|y|z``, mm);
- ``scene_info.json`` (rtmesh's own): the scene units (``--units m|cm|mm``, default m) and
  millimetres per unit.

Every label comes from the pixel-centre rays (:mod:`rtmesh.rendering.centre_rays`): the
visible mask from ``object_id``, depth from ``depth_center``, the amodal masks traced
against the asset alone (:func:`rtmesh.batch.coco.amodal_mask`).  The model frame is the
asset file's, scaled by ``--normalize``'s uniform scale (BOP poses are rigid), so a model
vertex ``X`` (mm) lands at ``K (R X + t)``.  ``depth_scale`` is the smallest of 0.01,
0.02, 0.05, 0.1, ... mm that holds the scene's farthest point in 16 bits.
"""

import json
import os
import shutil

import numpy as np

from rtmesh.batch.coco import amodal_mask, instance_geometry
from rtmesh.core.errors import OutputError
from rtmesh.io.atomic_files import replace_atomically, write_text
from rtmesh.io.images import DEPTH_PNG_MAX, write_depth_png, write_display_image

UNITS = {"m": 1000.0, "cm": 10.0, "mm": 1.0}
BOP_SUFFIXES = (".bop.json", ".bop_depth.png", ".bop_mask.png", ".bop_mask_visib.png")
OBJ_ID = 1


def depth_scale(far_mm):
    """The smallest of 0.01, 0.02, 0.05, 0.1, 0.2... mm per stored unit that holds ``far_mm``."""
    steps = np.array([1.0, 2.0, 5.0])
    for exponent in range(-2, 12):
        for step in steps * 10.0 ** exponent:
            if far_mm / step <= DEPTH_PNG_MAX:
                return float(step)
    raise OutputError(f"depth_scale: a depth of {far_mm:.6g} mm does not fit a 16-bit PNG")


def rigid_part(to_world):
    """``(rigid, scale)``: a model-to-world transform with a uniform scale as the rigid
    transform of the scaled model and that scale."""
    to_world = np.asarray(to_world, dtype=np.float64)
    scale = float(np.cbrt(np.linalg.det(to_world[:3, :3])))
    rigid = to_world.copy()
    rigid[:3, :3] /= scale
    return rigid, scale


def write_view_files(paths, it, labels, record, objects, units, accels=None):
    """Write one view's BOP ingredients: the ``.bop.json`` fragment and the depth and mask
    PNGs (``paths``: suffix of :data:`BOP_SUFFIXES` -> file).

    Parameters
    ----------
    paths : dict of str to str
    it : rtmesh.rendering.integrator.Integrator
        The integrator that rendered the view.
    labels : dict of str to (h, w, k) float
        The view's ``object_id`` and ``depth_center`` passes (and others).
    record : dict
        The view's camera record (with ``asset_to_world``, the model's frame).
    objects : tuple of int
        The scene objects that make the asset.
    units : str
        A key of :data:`UNITS`.
    accels : dict, optional
        The Embree scenes of the amodal masks, kept between views
        (:func:`rtmesh.batch.coco.amodal_mask`).
    """
    s, scene = it.settings, it.scene
    h, w = s.height, s.width
    mm = UNITS[units]
    visible = np.isin(np.rint(labels["object_id"][..., 0]).astype(np.int64), objects)
    depth = labels["depth_center"][..., 0].astype(np.float64)
    geometry = instance_geometry(scene, objects, accels)
    canvas = amodal_mask(it, geometry.vertices, geometry.faces, geometry.bounds, record, margin=1, accels=accels,
                         seen=visible, placed=geometry.placed)
    mask = canvas[h:2 * h, w:2 * w]
    scale = depth_scale(record["far"] * mm)
    w2c = np.array(record["world_to_camera_opencv"])
    m2c = w2c @ rigid_part(record["asset_to_world"])[0]
    fragment = {
        "camera": {"cam_K": np.array(record["K"]).ravel().tolist(), "cam_R_w2c": w2c[:3, :3].ravel().tolist(),
                   "cam_t_w2c": (w2c[:3, 3] * mm).tolist(), "depth_scale": scale},
        "gt": [{"cam_R_m2c": m2c[:3, :3].ravel().tolist(), "cam_t_m2c": (m2c[:3, 3] * mm).tolist(),
                "obj_id": OBJ_ID}],
        "gt_info": [{"bbox_obj": _box(canvas, -w, -h), "bbox_visib": _box(visible, 0, 0),
                     "px_count_all": int(canvas.sum()), "px_count_valid": int((mask & np.isfinite(depth)).sum()),
                     "px_count_visib": int(visible.sum()),
                     "visib_fract": float(visible.sum() / canvas.sum()) if canvas.any() else 0.0}],
    }
    write_text(paths[".bop.json"], json.dumps(fragment) + "\n")
    write_depth_png(paths[".bop_depth.png"], depth, mm / scale)
    write_display_image(paths[".bop_mask.png"], mask[:, :, None].astype(np.float64))
    write_display_image(paths[".bop_mask_visib.png"], visible[:, :, None].astype(np.float64))


def _box(mask, dx, dy):
    """The BOP toolkit's ``calc_2d_bbox`` of a mask's pixels, moved by ``(dx, dy)``;
    ``[-1, -1, -1, -1]`` for an empty mask."""
    ys, xs = np.nonzero(mask)
    if not len(xs):
        return [-1, -1, -1, -1]
    return [int(xs.min() + dx), int(ys.min() + dy), int(xs.max() - xs.min()), int(ys.max() - ys.min())]


def write_bop_scene(outdir, asset, frames, model, units):
    """Assemble the asset's BOP scene folder from its views' files.

    Parameters
    ----------
    outdir : str
    asset : str
    frames : list of (dict, str, list of str)
        Per view in order: its camera record, its picture (PNG or JPEG, relative to
        ``outdir``) and all its files.
    model : (vertices, faces)
        The asset's mesh in its file's frame, file units.
    units : str

    Returns
    -------
    list of str
        The files written.
    """
    target = os.path.join(outdir, asset + ".bop")
    for folder in ("rgb", "depth", "mask", "mask_visib", "models"):
        os.makedirs(os.path.join(target, folder), exist_ok=True)
    cameras, gt, info, written = {}, {}, {}, []
    for i, (record, picture, files) in enumerate(frames):
        by_suffix = {suffix: os.path.join(outdir, f) for f in files for suffix in BOP_SUFFIXES if f.endswith(suffix)}
        with open(by_suffix[".bop.json"], encoding="utf-8") as f:
            fragment = json.load(f)
        cameras[str(i)], gt[str(i)], info[str(i)] = fragment["camera"], fragment["gt"], fragment["gt_info"]
        copies = ((os.path.join(outdir, picture), f"rgb/{i:06d}{os.path.splitext(picture)[1].lower()}"),
                  (by_suffix[".bop_depth.png"], f"depth/{i:06d}.png"),
                  (by_suffix[".bop_mask.png"], f"mask/{i:06d}_000000.png"),
                  (by_suffix[".bop_mask_visib.png"], f"mask_visib/{i:06d}_000000.png"))
        for source, name in copies:
            written.append(os.path.join(target, name))
            _copy(source, written[-1])
    mm = UNITS[units]
    _, scale = rigid_part(frames[0][0]["asset_to_world"])
    vertices, faces = model
    vertices = np.asarray(vertices, dtype=np.float64) * (scale * mm)
    documents = {"scene_camera.json": cameras, "scene_gt.json": gt, "scene_gt_info.json": info,
                 "scene_info.json": {"units": units, "mm_per_unit": mm, "asset": asset},
                 "models/models_info.json": {str(OBJ_ID): model_info(vertices)}}
    for name, document in documents.items():
        written.append(os.path.join(target, name))
        write_text(written[-1], json.dumps(document, indent=1) + "\n")
    written.append(os.path.join(target, "models", f"obj_{OBJ_ID:06d}.ply"))
    replace_atomically(written[-1], lambda tmp: _write_ply(tmp, vertices, faces))
    return written


def model_info(vertices):
    """``models_info.json``'s entry of a model: ``diameter`` (the largest distance between
    two of its vertices), ``min_x|y|z`` and ``size_x|y|z``, in the vertices' units."""
    from scipy.spatial import ConvexHull, QhullError
    from scipy.spatial.distance import pdist

    points = np.unique(np.asarray(vertices, dtype=np.float64), axis=0)
    try:  # the farthest pair lies on the convex hull
        points = points[ConvexHull(points).vertices]
    except (QhullError, ValueError):
        pass  # flat or tiny models: every vertex
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    return {"diameter": float(pdist(points).max()) if len(points) > 1 else 0.0,
            "min_x": float(lo[0]), "min_y": float(lo[1]), "min_z": float(lo[2]),
            "size_x": float(hi[0] - lo[0]), "size_y": float(hi[1] - lo[1]), "size_z": float(hi[2] - lo[2])}


def _write_ply(path, vertices, faces):
    """A binary little-endian PLY of a triangle mesh (``x y z`` float, ``vertex_indices``)."""
    faces = np.asarray(faces, dtype=np.int32)
    header = ("ply\nformat binary_little_endian 1.0\ncomment rtmesh BOP model, millimetres\n"
              f"element vertex {len(vertices)}\nproperty float x\nproperty float y\nproperty float z\n"
              f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n")
    rows = np.empty(len(faces), dtype=[("n", "u1"), ("v", "<i4", (3,))])
    rows["n"], rows["v"] = 3, faces
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(np.asarray(vertices, dtype="<f4").tobytes())
        f.write(rows.tobytes())


def _copy(source, destination):
    """``destination`` as a hard link to ``source`` where the file system allows, else a copy."""
    tmp = destination + ".rtmesh-tmp"
    if os.path.lexists(tmp):
        os.unlink(tmp)
    try:
        os.link(source, tmp)
    except OSError:
        shutil.copyfile(source, tmp)
    os.replace(tmp, destination)
    if os.path.lexists(tmp):
        # rename(2) between two links to one file does nothing (a resume linking an image
        # already linked): the destination is that file already
        os.unlink(tmp)
