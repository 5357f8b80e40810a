"""The camera of a render as data for other tools: intrinsics and poses in every convention.

One JSON object per image (``rtmesh render --camera-json PATH``), with

- ``width``, ``height``: image size in pixels;
- ``K`` (3x3), ``fx``, ``fy``, ``cx``, ``cy``: pinhole intrinsics in pixels, with pixel
  centres at half-integers (the centre of the top-left pixel is ``(0.5, 0.5)``), so a point
  ``X`` (camera frame, OpenCV axes) lands at ``K X / X_z``; the principal point is the
  image centre and pixels are square (``fx == fy``);
- ``fov_y_degrees``: the vertical field of view;
- ``camera_to_world_opencv`` (4x4; camera axes +x right, +y down, +z forward),
  ``camera_to_world_opengl`` (4x4; +x right, +y up, -z forward: the Blender, nerfstudio
  and instant-ngp convention) and ``world_to_camera_opencv`` (its inverse, the COLMAP
  and OpenCV extrinsics ``[R | t]``);
- ``projection``: ``"perspective"`` or ``"orthographic"``; an orthographic camera has
  ``ortho_height`` and ``ortho_width`` (scene units), no ``fov_y_degrees`` (null), and its
  ``K`` maps camera-frame coordinates without the division by depth: ``u = fx x + cx``,
  ``v = fy y + cy`` (``fx = height / ortho_height`` pixels per scene unit);
- ``near``, ``far``: the nearest and farthest distance along the view axis of the scene's
  bounding box (``near`` at least 1e-6 of ``far``), for depth-buffer ranges;
- ``aperture``, ``focus_distance``: the thin lens (aperture 0 for a pinhole);
- ``asset_to_world`` (4x4): the transform applied to the asset file's coordinates before
  rendering (identity when rtmesh moved nothing), so points of the original file can be
  projected: ``K [R | t] asset_to_world X``.

World coordinates are the scene's own (rtmesh re-centres scenes for tracing internally;
that shift is not part of the exported pose).
"""

import json

import numpy as np

from rtmesh.core.errors import OutputError
from rtmesh.io.atomic_files import write_text


def camera_record(camera, width, height, bounds, asset_to_world=None):
    """The camera description of one image.

    Parameters
    ----------
    camera : Camera
    width, height : int
        Image size in pixels.
    bounds : (2, 3) float
        The scene's bounding box (minimum and maximum corners), world units.
    asset_to_world : (4, 4) float, optional
        What was applied to the asset's coordinates (default identity).

    Returns
    -------
    dict
        JSON-ready (lists of floats); see the module notes for every key.
    """
    forward, right, up = camera.frame()
    cx, cy = 0.5 * width, 0.5 * height
    # perspective: pixels per unit of image-plane height at unit distance; orthographic:
    # pixels per scene unit (u = f x + cx, with x the camera-frame coordinate itself)
    f = (height / camera.ortho_height if camera.orthographic
         else 0.5 * height / np.tan(np.radians(camera.fov) * 0.5))
    opencv = np.eye(4)
    opencv[:3, :3] = np.column_stack([right, -up, forward])
    opencv[:3, 3] = camera.position
    opengl = opencv.copy()
    opengl[:3, :3] = np.column_stack([right, up, -forward])
    world_to_camera = np.eye(4)
    world_to_camera[:3, :3] = opencv[:3, :3].T
    world_to_camera[:3, 3] = -opencv[:3, :3].T @ camera.position
    corners = np.array([[x, y, z] for x in bounds[:, 0] for y in bounds[:, 1] for z in bounds[:, 2]])
    depth = (corners - camera.position) @ forward
    far = float(max(depth.max(), 0.0))
    near = float(max(depth.min(), 1e-6 * far))
    record = {
        "width": int(width), "height": int(height),
        "K": [[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]],
        "fx": f, "fy": f, "cx": cx, "cy": cy,
        "fov_y_degrees": None if camera.orthographic else float(camera.fov),
        "camera_to_world_opencv": opencv.tolist(),
        "camera_to_world_opengl": opengl.tolist(),
        "world_to_camera_opencv": world_to_camera.tolist(),
        "projection": camera.projection,
        "near": near, "far": far,
        "aperture": float(camera.aperture), "focus_distance": float(camera.focus),
        "asset_to_world": (np.eye(4) if asset_to_world is None else np.asarray(asset_to_world)).tolist(),
    }
    if camera.orthographic:
        record["ortho_height"] = float(camera.ortho_height)
        record["ortho_width"] = float(camera.ortho_height * width / height)
    return record


def project_points(record, points):
    """Pixel positions of world points in the view a camera record describes.

    Parameters
    ----------
    record : dict
        From :func:`camera_record`.
    points : (n, 3) float
        World points.

    Returns
    -------
    uv : (n, 2) float64
        Pixel positions (pixel centres at +0.5): ``K X / X_z``, or ``K`` without the
        division for an orthographic camera; not finite for a point in a perspective
        camera's plane.
    z : (n,) float64
        Distance along the view axis (camera-frame z); a perspective camera sees only
        points with ``z > 0``.
    """
    w2c, k = np.array(record["world_to_camera_opencv"]), np.array(record["K"])
    p = np.asarray(points, dtype=np.float64) @ w2c[:3, :3].T + w2c[:3, 3]
    z = p[:, 2]
    xy = p[:, :2]
    if record["projection"] != "orthographic":
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = xy / z[:, None]
    return xy @ k[:2, :2].T + k[:2, 2], z


def write_camera_json(path, record):
    """Write ``record`` as JSON, atomically (see :func:`rtmesh.io.atomic_files.write_text`).

    Raises
    ------
    OutputError
        The folder does not exist or cannot be written (one line naming the file).
    """
    try:
        write_text(path, json.dumps(record, indent=2) + "\n")
    except OSError as exc:
        raise OutputError(f"{path}: cannot write the camera file ({exc.strerror})") from None
