"""Optical flow between a batch's ordered views (``rtmesh batch ... --flow``).

For view ``i`` of an asset's ordered views (turntable frames, a view set, a ``--views``
list), ``flow_forward`` maps each pixel to where its surface point is in view ``i + 1`` and
``flow_backward`` to where it is in view ``i - 1``: three channels per pixel,

- ``X``, ``Y``: the other view's pixel position of the point the pixel-centre ray of view
  ``i`` hits (``position_center``, :mod:`rtmesh.rendering.centre_rays`), minus the pixel
  centre, in pixels (+x right, +y down), projected with the other view's exported ``K``
  and pose (:func:`rtmesh.scene.camera_json.project_points`);
- ``valid``: 1 where the point lands inside the other image and the other camera sees it:
  the ray from the other camera towards it (from its eye, or for an orthographic camera
  from its image plane) first meets the scene within a tolerance of the point's distance
  (``1e-4`` of it plus ``1e-6`` of the scene's size); 0 where the pixel sees nothing, the
  point leaves the other image, lies behind the other camera or is hidden there (``X`` and
  ``Y`` are then 0).

The first view has no backward flow and the last no forward flow (all invalid).  The flow
goes into the view's EXR as the layers ``flow_forward`` and ``flow_backward``; with
``--flow-format flo`` also as Middlebury ``.flo`` files (:func:`write_flo`), whose invalid
pixels hold 1e10 in both components, Middlebury's "unknown".
"""

import os

import numpy as np

from rtmesh.io.atomic_files import replace_atomically
from rtmesh.scene.camera_json import project_points

FLOW_PASSES = ("flow_forward", "flow_backward")
FLOW_FORMATS = ("exr", "flo")
# Middlebury .flo: the tag (the bytes "PIEH" as a little-endian float) and "unknown"
FLO_TAG = 202021.25
FLO_UNKNOWN = 1e10


def flow_suffix(name):
    """``.flow_forward.flo``: the file of one flow pass next to an image."""
    return f".{name}.flo"


def seen_points(position):
    """The pixels of a view that see a surface, and the points they see.

    Parameters
    ----------
    position : (h, w, 3) float
        The view's ``position_center`` pass (NaN where the pixel sees nothing).

    Returns
    -------
    rows : (k,) intp
        Flat pixel indices (row-major) whose point is finite.
    points : (k, 3) float64
        Their points.
    """
    position = np.asarray(position)
    flat = position.reshape(-1, position.shape[-1])
    # finite in the pass's own precision (float32 -> float64 keeps every value), one
    # channel at a time (a reduction along a row of three costs ten times more)
    finite = np.isfinite(flat[:, 0])
    for channel in range(1, flat.shape[1]):
        finite &= np.isfinite(flat[:, channel])
    rows = np.flatnonzero(finite)
    return rows, flat[rows].astype(np.float64)


def view_flow(position, other, record, seen=None):
    """The flow of one view to another.

    Parameters
    ----------
    position : (h, w, 3) float
        The view's ``position_center`` pass (NaN where the pixel sees nothing).
    other : rtmesh.rendering.integrator.Integrator or None
        The integrator of the other view (its camera and scene); None: no other view.
    record : dict or None
        The other view's camera record.
    seen : tuple, optional
        :func:`seen_points` of ``position``, when the caller has it (a view's forward and
        backward flow share it).

    Returns
    -------
    (h, w, 3) float32
        ``X``, ``Y``, ``valid`` (see the module notes).
    """
    h, w = position.shape[:2]
    out = np.zeros((h * w, 3), dtype=np.float32)
    if other is None:
        return out.reshape(h, w, 3)
    rows, points = seen_points(position) if seen is None else seen
    uv, z = project_points(record, points)
    inside = (z > 0 if record["projection"] == "perspective" else np.ones(len(z), dtype=bool))
    inside &= (uv[:, 0] >= 0) & (uv[:, 0] < record["width"]) & (uv[:, 1] >= 0) & (uv[:, 1] < record["height"])
    rows, points, uv = rows[inside], points[inside], uv[inside]
    seen = _seen(other, points)
    rows, uv = rows[seen], uv[seen]
    centres = np.column_stack([rows % w + 0.5, rows // w + 0.5])
    out[rows, :2] = uv - centres
    out[rows, 2] = 1.0
    return out.reshape(h, w, 3)


def _seen(it, points):
    """(k,) bool: whether the camera of ``it`` sees the world ``points`` (nothing nearer on
    the ray from it to each)."""
    camera = it.camera  # in the integrator's shifted frame
    target = points - it.shift
    forward = it.camera_frame[0]
    if camera.orthographic:
        origins = target - ((target - camera.position) @ forward)[:, None] * forward
    else:
        origins = np.broadcast_to(camera.position, target.shape)
    offset = target - origins
    distance = np.linalg.norm(offset, axis=1)
    directions = offset / np.maximum(distance, 1e-300)[:, None]
    hits = it.accel.intersect(np.ascontiguousarray(origins), directions,
                              None if it.motion is None else np.full(len(target), camera.shutter[0]))
    tolerance = 1e-4 * distance + 1e-6 * it.offset_scale
    return (hits.prim >= 0) & (np.abs(hits.t - distance) <= tolerance)


def write_flo(path, flow):
    """Write a flow pass as a Middlebury ``.flo`` file, atomically.

    Parameters
    ----------
    path : str
    flow : (h, w, 3) float
        ``X``, ``Y``, ``valid``; invalid pixels are written as 1e10, 1e10.
    """
    h, w = flow.shape[:2]
    uv = np.where(flow[:, :, 2:3] > 0, flow[:, :, :2], FLO_UNKNOWN).astype("<f4")
    data = (np.array([FLO_TAG], "<f4").tobytes() + np.array([w, h], "<i4").tobytes()
            + np.ascontiguousarray(uv).tobytes())

    def write(tmp):
        with open(tmp, "wb") as f:
            f.write(data)

    replace_atomically(os.fspath(path), write)
