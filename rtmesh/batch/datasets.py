"""Dataset files for multi-view renders: nerfstudio ``transforms.json``, COLMAP text and the
BOP layout (:mod:`rtmesh.batch.bop`).

``rtmesh batch ... --dataset nerfstudio|colmap`` writes, per finished asset, the files
that reconstruction tools read beside the images, built from each image's camera JSON
(:mod:`rtmesh.scene.camera_json`, written next to the images with the dataset):

- ``nerfstudio``: ``<asset>.transforms.json`` in the asset's image folder (the nerfstudio /
  instant-ngp layout): ``camera_model`` ``"OPENCV"`` (no distortion: ``k1 k2 p1 p2`` 0),
  or ``"ORTHOPHOTO"`` for orthographic views (``--ortho``), ``fl_x``, ``fl_y``, ``cx``,
  ``cy`` (pixels, pixel centres at +0.5), ``w``, ``h`` (at the top level when every frame
  shares them, else in each frame only: nerfstudio ignores per-frame intrinsics when
  top-level ones exist) and ``frames``: ``file_path`` (relative to the JSON file) and ``transform_matrix``, the
  camera-to-world matrix in the OpenGL convention (+x right, +y up, -z forward); with
  ``--passes depth`` each frame has ``depth_file_path`` (16-bit PNG, millimetres: depth in
  scene units times 1000, nerfstudio's default ``depth_unit_scale_factor`` 1e-3), with
  ``--passes alpha`` a ``mask_path`` (8-bit PNG, 255 where the asset covers the pixel).
  ``nerfstudio`` also accepts the JSON file itself as ``--data``.
- ``colmap``: ``<asset>.colmap/cameras.txt`` (one ``PINHOLE`` camera: ``fx fy cx cy``),
  ``images.txt`` (per image ``IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME``: the
  world-to-camera rotation as a unit quaternion, scalar first, ``QW >= 0``, and translation
  in COLMAP's camera axes, which are OpenCV's; an empty line of 2D points follows each) and
  an empty ``points3D.txt``.  ``NAME`` is relative to the asset's image folder (COLMAP's
  ``--image_path``).
"""

import json
import os

import numpy as np

from rtmesh.batch.bop import BOP_SUFFIXES, write_bop_scene
from rtmesh.batch.jobs import CAMERA_SUFFIX
from rtmesh.batch.jobs import DEPTH_PNG_SUFFIX as DEPTH_SUFFIX
from rtmesh.batch.jobs import MASK_PNG_SUFFIX as MASK_SUFFIX
from rtmesh.core.errors import OutputError
from rtmesh.io.atomic_files import write_text
from rtmesh.loaders.importers import mesh_file_parts

DATASETS = ("nerfstudio", "colmap", "bop")
# image formats a dataset's frames point at, by preference
_FRAME_FORMATS = (".png", ".jpg", ".exr")


def dataset_suffixes(dataset, passes):
    """Extra files per image a dataset needs: the camera JSON, depth and mask images."""
    if not dataset:
        return []
    suffixes = [CAMERA_SUFFIX]
    if dataset == "nerfstudio":
        suffixes += [DEPTH_SUFFIX] * ("depth" in passes) + [MASK_SUFFIX] * ("alpha" in passes)
    if dataset == "bop":
        suffixes += list(BOP_SUFFIXES)
    return suffixes


def write_dataset(dataset, outdir, asset, images, source=None, units="m"):
    """Write the dataset files of one asset.

    Parameters
    ----------
    dataset : {"nerfstudio", "colmap", "bop"}
    outdir : str
        The batch's output folder.
    asset : str
        The asset's name (its path relative to its input root, as in the image names).
    images : list of dict
        The asset's finished images (``key``, ``files``: names relative to ``outdir``), in
        view order; each has a camera JSON among its files.
    source : str, optional
        The asset's mesh file (``bop``: its model is written in millimetres).
    units : str
        ``bop``: the scene units (:data:`rtmesh.batch.bop.UNITS`).

    Returns
    -------
    list of str
        The files written (absolute paths).
    """
    frames = []
    for image in images:
        files = image["files"]
        pictures = sorted((f for f in files if os.path.splitext(f)[1].lower() in _FRAME_FORMATS
                           and not f.endswith((DEPTH_SUFFIX, MASK_SUFFIX) + BOP_SUFFIXES)),
                          key=lambda f: _FRAME_FORMATS.index(os.path.splitext(f)[1].lower()))
        with open(os.path.join(outdir, image["key"] + CAMERA_SUFFIX), encoding="utf-8") as f:
            record = json.load(f)
        frames.append((record, pictures[0], files))
    if not frames:
        return []
    if dataset == "bop":
        # the geometry alone: no materials read, no vertices split for smooth shading
        parts, _ = mesh_file_parts(source, material=0, smooth=False)
        offsets = np.cumsum([0] + [len(p.vertices) for p in parts])
        model = (np.concatenate([p.vertices for p in parts]),
                 np.concatenate([np.asarray(p.faces) + o for p, o in zip(parts, offsets)]))
        return write_bop_scene(outdir, asset, frames, model, units)
    if dataset == "nerfstudio":
        path = os.path.join(outdir, asset + ".transforms.json")
        write_text(path, json.dumps(nerfstudio_transforms(frames, path), indent=2) + "\n")
        return [path]
    target = os.path.join(outdir, asset + ".colmap")
    os.makedirs(target, exist_ok=True)
    cameras, images_txt = colmap_text(frames)
    written = []
    for name, text in (("cameras.txt", cameras), ("images.txt", images_txt),
                       ("points3D.txt", "# 3D point list: none (rendered views, no reconstruction)\n")):
        written.append(os.path.join(target, name))
        write_text(written[-1], text)
    return written


_INTRINSICS = (("fl_x", "fx"), ("fl_y", "fy"), ("cx", "cx"), ("cy", "cy"), ("w", "width"), ("h", "height"))


def nerfstudio_transforms(frames, where="transforms.json"):
    """The ``transforms.json`` document of ``frames`` ((record, image, files) tuples).

    Intrinsics go to the top level when every frame shares them, else into each frame
    only: nerfstudio reads the top-level keys whenever they exist (``fx_fixed = "fl_x" in
    meta``) and then ignores per-frame ones.  Perspective views are ``"OPENCV"`` (zero
    distortion), orthographic ones ``"ORTHOPHOTO"`` (``fl_x`` in pixels per scene unit).

    Raises
    ------
    OutputError
        The frames mix orthographic and perspective views (one ``camera_model`` per file);
        the message names ``where``.
    """
    projections = {record["projection"] for record, _, _ in frames}
    if len(projections) > 1:
        raise OutputError(f"{where}: camera_model: nerfstudio has one camera model per file, and these "
                          f"views mix orthographic and perspective cameras")
    model = "ORTHOPHOTO" if projections == {"orthographic"} else "OPENCV"
    document = {"camera_model": model}
    intrinsics = [{key: record[field] for key, field in _INTRINSICS} for record, _, _ in frames]
    shared = all(i == intrinsics[0] for i in intrinsics)
    if shared:
        document.update(intrinsics[0])
    if model == "OPENCV":
        document.update(k1=0.0, k2=0.0, p1=0.0, p2=0.0)
    document["frames"] = []
    for (record, picture, files), own in zip(frames, intrinsics):
        frame = {"file_path": os.path.basename(picture),
                 "transform_matrix": record["camera_to_world_opengl"]}
        if not shared:
            frame.update(own)
        for suffix, field in ((DEPTH_SUFFIX, "depth_file_path"), (MASK_SUFFIX, "mask_path")):
            extra = [f for f in files if f.endswith(suffix)]
            if extra:
                frame[field] = os.path.basename(extra[0])
        document["frames"].append(frame)
    return document


def colmap_text(frames):
    """``cameras.txt`` and ``images.txt`` of ``frames`` (one PINHOLE camera per image size)."""
    cameras, camera_ids, lines = [], {}, []
    for i, (record, picture, _) in enumerate(frames, start=1):
        intrinsics = (record["width"], record["height"], record["fx"], record["fy"], record["cx"], record["cy"])
        if intrinsics not in camera_ids:
            camera_ids[intrinsics] = len(camera_ids) + 1
            w, h, fx, fy, cx, cy = intrinsics
            cameras.append(f"{camera_ids[intrinsics]} PINHOLE {w} {h} {fx!r} {fy!r} {cx!r} {cy!r}")
        w2c = np.array(record["world_to_camera_opencv"])
        q = rotation_to_quaternion(w2c[:3, :3])
        t = w2c[:3, 3]
        values = " ".join(repr(float(x)) for x in (*q, *t))
        lines.append(f"{i} {values} {camera_ids[intrinsics]} {os.path.basename(picture)}\n")
    header = ("# Camera list with one line of data per camera:\n"
              "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
              f"# Number of cameras: {len(cameras)}\n")
    image_header = ("# Image list with two lines of data per image:\n"
                    "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
                    "#   POINTS2D[] as (X, Y, POINT3D_ID)\n"
                    f"# Number of images: {len(lines)}, mean observations per image: 0\n")
    return header + "\n".join(cameras) + "\n", image_header + "".join(line + "\n" for line in lines)


def rotation_to_quaternion(rotation):
    """The unit quaternion ``(w, x, y, z)`` (Hamilton, ``w >= 0``) of a 3x3 rotation matrix."""
    r = np.asarray(rotation, dtype=np.float64)
    trace = np.trace(r)
    # Shepperd's method: divide by the largest of the four candidate components
    candidates = np.array([trace, r[0, 0], r[1, 1], r[2, 2]])
    k = int(np.argmax(candidates))
    if k == 0:
        s = 2.0 * np.sqrt(1.0 + trace)
        q = [0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s]
    elif k == 1:
        s = 2.0 * np.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2])
        q = [(r[2, 1] - r[1, 2]) / s, 0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s]
    elif k == 2:
        s = 2.0 * np.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2])
        q = [(r[0, 2] - r[2, 0]) / s, (r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1])
        q = [(r[1, 0] - r[0, 1]) / s, (r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s]
    q = np.array(q) / np.linalg.norm(q)
    return q if q[0] >= 0.0 else -q
