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

What it costs: only the pixels of the scene's projected bounding box are traced (in whole
packets of the image, so each ray's hit is the one a trace of every pixel gives), on the
render's threads; depth and position of a still scene are interpolated from the hit's
barycentrics alone, without the rest of a shading record.
"""

import numpy as np

from rtmesh.core import runtime
from rtmesh.core.rays import RayBatch, repeated_row
from rtmesh.geometry.accel import barycentric_interpolate
from rtmesh.geometry.embree_packets import LANES
from rtmesh.geometry.motion import object_motions
from rtmesh.io.passes import CENTRE_PASSES
from rtmesh.scene.camera_json import camera_record, project_points

# pixel-centre rays traced at once (bounds the memory of a large image's label passes)
CHUNK_RAYS = 1 << 16
# fewer rays than this are not split between threads (a multiple of LANES)
_MIN_CHUNK = 1 << 12
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


def box_pixels(record, bounds, width, height):
    """The pixel rectangle that holds every pixel whose centre ray can meet a box.

    Parameters
    ----------
    record : dict
        The view's camera record (:func:`rtmesh.scene.camera_json.camera_record`).
    bounds : (2, 3) float
        The box's minimum and maximum, world units.
    width, height : int
        The canvas (pixels ``0 .. width - 1``, ``0 .. height - 1``).

    Returns
    -------
    c0, c1, r0, r1 : int
        Columns ``c0 .. c1 - 1`` and rows ``r0 .. r1 - 1``: the pixels whose centre lies
        inside the projection of the box's corners, and one more on each side, clipped to
        the canvas; the whole canvas when part of the box is behind a perspective camera.
        Empty (``c1 <= c0`` or ``r1 <= r0``) when the box is outside it.
    """
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)])
    lo, hi = np.asarray(bounds[0], dtype=np.float64), np.asarray(bounds[1], dtype=np.float64)
    uv, z = project_points(record, lo + corners * (hi - lo))
    c0, c1, r0, r1 = 0, width, 0, height
    if record["projection"] != "perspective" or (z > 0).all():
        c0, r0 = (int(x) for x in np.maximum(np.floor(uv.min(axis=0) - 0.5).astype(int) - 1, (c0, r0)))
        c1, r1 = (int(x) for x in np.minimum(np.ceil(uv.max(axis=0) - 0.5).astype(int) + 2, (c1, r1)))
    return c0, c1, r0, r1


def _traced_pixels(it):
    """(n,) int64: the pixels whose centre rays :func:`centre_passes` traces, row-major.

    Only the pixels of the scene's projected bounding box (:func:`box_pixels`) can see
    anything; the rest are misses without a ray.  Whole packets of :data:`LANES`
    consecutive pixels of the image are kept (those that hold a pixel of the box), so every
    ray travels in the same packet as when the whole image is traced: the hits are the same
    bit for bit.  Every pixel where objects move (their bounds at the shutter's opening
    are not the scene's).
    """
    s, scene = it.settings, it.scene
    total = s.width * s.height
    if it.motion is not None or not len(scene.faces):
        return np.arange(total)
    bounds = it.scene_bounds
    c0, c1, r0, r1 = box_pixels(camera_record(scene.camera, s.width, s.height, bounds), bounds, s.width, s.height)
    if c1 <= c0 or r1 <= r0:
        return np.zeros(0, dtype=np.int64)
    rows = np.arange(r0, r1, dtype=np.int64)
    first, last = (rows * s.width + c0) // LANES, (rows * s.width + c1 - 1) // LANES
    packets = np.zeros((total + LANES - 1) // LANES + 1, dtype=np.int64)  # +1 at a first, -1 after a last
    np.add.at(packets, first, 1)
    np.add.at(packets, last + 1, -1)
    starts = np.flatnonzero(np.cumsum(packets[:-1]) > 0) * LANES
    pixels = (starts[:, None] + np.arange(LANES)).ravel()
    return pixels[pixels < total]


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
    # points alone (depth, position) of a still scene: the surface kernel's interpolation
    # without its normals, materials and textures (the same rounding, see below); a
    # placement's points are carried to the world by the surface stage
    points_only = it.motion is None and it.instances is None and "normal_center" not in out
    record = camera_record(scene.camera, s.width, s.height, it.scene_bounds) if motions else None
    forward = it.camera_frame[0]

    def trace(pixels):
        origins, directions, time, hits = centre_hits(it, pixels % s.width, pixels // s.width)
        rows = np.flatnonzero(hits.prim >= 0)
        if not len(rows):
            return
        prim, dest = hits.prim[rows].astype(np.intp), pixels[rows]
        objects = None
        if hits.instance is not None and any(name != "material_id" for name, _ in ids):
            # a placement is an object of its own; its prototype's faces name only the first
            objects = it.instances.hit_objects(scene.object_id, prim, hits.instance[rows])
        for name, table in ids:
            out[name][dest, 0] = table[prim] if objects is None or name == "material_id" else objects
        if points_only and geometry:
            # (u e1 + v0) + v e2 on the rows of the face table the surface kernel reads:
            # rtmesh.shading.surfaces.surface_from_rows rounds exactly so; component-major like
            # the kernel's points, so that the depth's product below sums alike
            points = np.asfortranarray(barycentric_interpolate(it.tables.faces[prim], hits.u[rows], hits.v[rows]))
        elif geometry:
            n = len(pixels)
            rays = RayBatch(origins, directions, np.arange(n, dtype=np.int64), repeated_row(_UNIT, n),
                            repeated_row(it._camera_medium, n))
            srf = it.surface_stage.records(rays, hits, rows, time)
            points = srf.p
        if geometry:
            if "depth_center" in out:
                out["depth_center"][dest, 0] = (points - it.camera.position) @ forward
            if "position_center" in out:
                out["position_center"][dest] = points + it.shift
            if "normal_center" in out:
                out["normal_center"][dest] = srf.ns
            if motions:
                out["motion"][dest] = _motion(points + it.shift, scene.object_id[prim], motions,
                                              scene.camera.shutter, record)

    # chunks of whole packets, one or more per render thread, each writing its own pixels
    traced = _traced_pixels(it)
    size = -(-len(traced) // s.thread_count)
    size = min(CHUNK_RAYS, max(-(-size // LANES) * LANES, _MIN_CHUNK))
    chunks = [traced[start:start + size] for start in range(0, len(traced), size)]
    with runtime.render_pool(min(s.thread_count, len(chunks)) or 1) as workers:
        later = [workers.submit(trace, chunk) for chunk in chunks[1:]] if workers else []
        for chunk in chunks[:1] if workers else chunks:
            trace(chunk)
        for future in later:
            future.result()
    return {name: values.reshape(s.height, s.width, -1) for name, values in out.items()}
