"""Exact label passes: one unjittered ray through each pixel centre.

The sampled passes (:mod:`rtmesh.io.passes`) average or pick among a pixel's jittered
samples; the labels a dataset needs are the surface seen by the one ray that the exported
intrinsics ``K`` describe (:mod:`rtmesh.scene.camera_json`): the ray through the pixel
centre ``(column + 0.5, row + 0.5)``, from the centre of a thin lens, at the time the
shutter opens.  :func:`centre_passes` traces that ray for every pixel after the render (the
image and its samples are untouched) and writes the passes of
:data:`rtmesh.io.passes.CENTRE_PASSES`: ``object_id``, ``material_id``, ``instance_id``,
``depth_center``, ``position_center``, ``normal_center`` and ``motion`` (where the point
the ray hits when the shutter opens is in the image when it closes, minus where it was:
the motion of moving objects; the camera does not move during one render).

:func:`centre_hits` is the same ray for any set of pixels and any scene to trace against
(the amodal masks of :mod:`rtmesh.batch.coco` trace an object alone).
"""

import numpy as np

from rtmesh.core.rays import RayBatch, repeated_row
from rtmesh.geometry.motion import object_motions
from rtmesh.io.passes import CENTRE_PASSES
from rtmesh.scene.camera_json import camera_record, project_points

# pixel-centre rays traced at once (bounds the memory of a large image's label passes)
CHUNK_RAYS = 1 << 16
_UNIT = np.ones(3)
_GEOMETRY = ("depth_center", "position_center", "normal_center")


def _motion(points, objects, motions, shutter, record):
    """(k, 2): how far the world ``points`` (on ``objects``, at the shutter's opening) move
    in the image until it closes, pixels; 0 on objects that stand still."""
    opened, closed = shutter
    moved = points.copy()
    for k, motion in motions.items():
        rows = np.flatnonzero(objects == k)
        if len(rows):
            rest = motion.to_rest(points[rows], np.full(len(rows), opened))
            moved[rows] = motion.to_world(rest, np.full(len(rows), closed))
    start, _ = project_points(record, points)
    end, _ = project_points(record, moved)
    return end - start


def centre_hits(it, columns, rows, accel=None):
    """Trace the rays through the centres of pixels ``(columns, rows)``.

    Parameters
    ----------
    it : rtmesh.rendering.integrator.Integrator
        Its camera (in the integrator's shifted frame), image size and scene.
    columns, rows : (n,) int
        Pixel coordinates; they may lie outside the image (the same camera on a larger
        canvas, as the BOP toolkit renders whole objects).
    accel : Accel, optional
        What to trace against (default the integrator's scene); it must answer
        ``intersect(origins, directions, time)`` in the integrator's shifted frame.

    Returns
    -------
    origins, directions : (n, 3) float64
        The rays, in the integrator's shifted frame (directions unit length).
    time : (n,) float or None
        The shutter's opening time where objects move, else None.
    hits : Hits
        Embree's hits (``prim`` -1 where the ray meets nothing).
    """
    s = it.settings
    centres = np.column_stack([np.asarray(columns, dtype=np.float64) + 0.5, np.asarray(rows, dtype=np.float64) + 0.5])
    origins, directions = it.camera.generate_rays(centres, s.width, s.height, None, None, it.camera_frame)
    time = np.full(len(centres), it.camera.shutter[0]) if it.motion is not None else None
    hits = (it.accel if accel is None else accel).intersect(origins, directions, time)
    return origins, directions, time, hits


def centre_passes(it, names):
    """The centre-ray passes among ``names``, as images.

    Parameters
    ----------
    it : rtmesh.rendering.integrator.Integrator
    names : iterable of str
        Requested passes; names that are not centre passes are ignored, and nothing is
        traced when none is.

    Returns
    -------
    dict of str to (height, width, k) float32
        ``object_id``, ``material_id``, ``instance_id``: exact integer indices, -1 where
        the ray meets nothing; ``depth_center``: distance along the view axis (scene
        units), +inf for a miss; ``position_center``: world-space hit point, NaN for a miss;
        ``normal_center``: world-space unit shading normal facing the ray, NaN for a miss;
        ``motion``: pixels the hit point moves between the shutter's opening and closing
        (+x right, +y down), 0 where nothing moves or nothing is hit.
    """
    specs = [CENTRE_PASSES[n] for n in dict.fromkeys(names) if n in CENTRE_PASSES]
    if not specs:
        return {}
    s, scene = it.settings, it.scene
    total = s.width * s.height
    out = {spec.name: np.full((total, len(spec.channels)), spec.miss, dtype=np.float32) for spec in specs}
    ids = [(name, table) for name, table in (("object_id", scene.object_id), ("material_id", scene.material_id),
                                             ("instance_id", scene.object_id)) if name in out]
    motions = object_motions(scene) if "motion" in out and it.motion is not None else {}
    geometry = any(name in out for name in _GEOMETRY) or bool(motions)
    record = camera_record(scene.camera, s.width, s.height, scene.bounds) if motions else None
    forward = it.camera_frame[0]
    for start in range(0, total, CHUNK_RAYS):
        pixels = np.arange(start, min(start + CHUNK_RAYS, total))
        origins, directions, time, hits = centre_hits(it, pixels % s.width, pixels // s.width)
        rows = np.flatnonzero(hits.prim >= 0)
        if not len(rows):
            continue
        prim, dest = hits.prim[rows].astype(np.intp), pixels[rows]
        for name, table in ids:
            out[name][dest, 0] = table[prim]
        if geometry:
            n = len(pixels)
            rays = RayBatch(origins, directions, np.arange(n, dtype=np.int64), repeated_row(_UNIT, n),
                            repeated_row(it._camera_medium, n))
            srf = it.surface_stage.records(rays, hits, rows, time)
            if "depth_center" in out:
                out["depth_center"][dest, 0] = (srf.p - it.camera.position) @ forward
            if "position_center" in out:
                out["position_center"][dest] = srf.p + it.shift
            if "normal_center" in out:
                out["normal_center"][dest] = srf.ns
            if motions:
                out["motion"][dest] = _motion(srf.p + it.shift, scene.object_id[prim], motions,
                                              scene.camera.shutter, record)
    return {name: values.reshape(s.height, s.width, -1) for name, values in out.items()}
