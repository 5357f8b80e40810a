"""Normalising an asset before it is rendered: centre it and scale it to a unit size.

``rtmesh batch --normalize unit-cube|unit-sphere`` moves each asset so that collections of
models of any size and placement render alike (the usual preparation of multi-view
training sets).  The transform is uniform (one scale, one translation), so normals and the
shading are unchanged, and it is recorded in each image's camera JSON as
``asset_to_world`` (see :mod:`rtmesh.scene.camera_json`), so points of the original file
can still be projected.
"""

import numpy as np

NORMALIZE_MODES = ("unit-cube", "unit-sphere")


def asset_to_world(bounds, mode):
    """The 4x4 transform that normalises an asset with bounding box ``bounds``.

    Parameters
    ----------
    bounds : (2, 3) float
        Minimum and maximum corners of the asset, file units.
    mode : {"", "unit-cube", "unit-sphere"}
        ``unit-cube``: the box's centre goes to the origin and its longest side to length 1
        (the asset fits in [-0.5, 0.5]^3); ``unit-sphere``: the box's centre goes to the
        origin and its bounding sphere (half the diagonal) to radius 1.  ``""``: identity.

    Returns
    -------
    (4, 4) float64
        ``world = M @ [x, y, z, 1]``.  A single point (zero size) is only centred.

    Raises
    ------
    ValueError
        Unknown ``mode``.
    """
    if mode and mode not in NORMALIZE_MODES:
        raise ValueError(f"normalize: unknown {mode!r} (expected {', '.join(NORMALIZE_MODES)})")
    matrix = np.eye(4)
    if not mode:
        return matrix
    bounds = np.asarray(bounds, dtype=np.float64)
    size = (float(np.ptp(bounds, axis=0).max()) if mode == "unit-cube"
            else 0.5 * float(np.linalg.norm(bounds[1] - bounds[0])))
    scale = 1.0 / size if size > 0.0 else 1.0
    matrix[:3, :3] *= scale
    matrix[:3, 3] = -scale * bounds.mean(axis=0)
    return matrix


def transform_points(matrix, points):
    """``points`` (N, 3) moved by the affine 4x4 ``matrix``, as (N, 3) float64."""
    points = np.asarray(points, dtype=np.float64)
    return points @ matrix[:3, :3].T + matrix[:3, 3]
