"""OBJ faces of five or more corners, triangulated by ear clipping before trimesh reads them.

trimesh's OBJ reader splits a quad along one diagonal and every larger polygon as a fan
from its first corner, which covers the openings of a concave polygon (a wall with a door
written as one face).  :func:`triangulate_polygons` rewrites each concave face statement of
five or more corners as the triangles of an ear clipping (``mapbox_earcut``, the library trimesh
itself uses for 2D polygons) of the polygon projected onto its plane, keeping every
corner's ``v/vt/vn`` reference as written; trimesh then reads triangles only.  Quads stay as
trimesh splits them (a file's quads keep their shading), and a file without larger polygons
is read from its path as before.
"""

import re

import numpy as np

# a face statement of five or more corners
_POLYGON = re.compile(rb"^[ \t]*f(?:[ \t]+[^ \t\r\n]+){5,}[ \t]*\r?$", re.M)
_VERTEX = re.compile(rb"^[ \t]*v[ \t]+([^ \t\r\n]+)[ \t]+([^ \t\r\n]+)[ \t]+([^ \t\r\n]+)", re.M)


def triangulate_polygons(data):
    """An OBJ file's text with its concave polygons of five or more corners ear-clipped
    (convex ones are left to trimesh's fan, which is right for them).

    Parameters
    ----------
    data : bytes
        The file's content.

    Returns
    -------
    bytes or None
        The rewritten text, or None when the file has no such polygon (or its vertices
        cannot be read: trimesh then reports the file as it does).  Each polygon statement
        is examined in Python (not a per-ray loop: once per polygon of five or more
        corners, on loading).
    """
    polygons = list(_POLYGON.finditer(data))
    if not polygons:
        return None
    vertex_matches = list(_VERTEX.finditer(data))
    try:
        positions = np.array([[float(x) for x in m.groups()] for m in vertex_matches], dtype=np.float64)
    except ValueError:
        return None
    positions = positions.reshape(-1, 3)
    # OBJ's negative indices count back from the vertices defined before the statement
    vertex_starts = np.array([m.start() for m in vertex_matches], dtype=np.int64)
    pieces, end = [], 0
    for match in polygons:
        tokens = match.group(0).split()[1:]
        defined = int(np.searchsorted(vertex_starts, match.start()))
        triangles = _ear_clip(tokens, positions, defined)
        if triangles is None:
            continue  # left to trimesh's fan (convex, degenerate or unreadable)
        pieces.append(data[end:match.start()])
        pieces.append(b"\n".join(b"f " + b" ".join(tokens[i] for i in t) for t in triangles))
        end = match.end()
    if not pieces:
        return None
    pieces.append(data[end:])
    return b"".join(pieces)


def _ear_clip(tokens, positions, defined):
    """Triangles ((k - 2, 3) corner indices) of one polygon face, or None."""
    import mapbox_earcut

    try:
        index = np.array([int(t.split(b"/")[0]) for t in tokens], dtype=np.int64)
    except ValueError:
        return None
    index = np.where(index < 0, defined + index, index - 1)
    if ((index < 0) | (index >= len(positions))).any():
        return None
    corners = positions[index]
    if not np.isfinite(corners).all():
        return None
    # Newell's normal of the polygon; project along its largest component
    following = np.roll(corners, -1, axis=0)
    normal = np.array([np.sum((corners[:, 1] - following[:, 1]) * (corners[:, 2] + following[:, 2])),
                       np.sum((corners[:, 2] - following[:, 2]) * (corners[:, 0] + following[:, 0])),
                       np.sum((corners[:, 0] - following[:, 0]) * (corners[:, 1] + following[:, 1]))])
    axis = int(np.argmax(np.abs(normal)))
    if normal[axis] == 0.0:
        return None
    keep = [a for a in range(3) if a != axis]
    flat = np.ascontiguousarray(corners[:, keep])
    edges = np.roll(flat, -1, axis=0) - flat
    turns = edges[:, 0] * np.roll(edges, -1, axis=0)[:, 1] - edges[:, 1] * np.roll(edges, -1, axis=0)[:, 0]
    if (turns >= 0.0).all() or (turns <= 0.0).all():
        return None  # convex: trimesh's fan is right, and keeps the file's triangles as they were
    triangles = mapbox_earcut.triangulate_float64(flat, np.array([len(flat)], dtype=np.uint32))
    if len(triangles) != 3 * (len(flat) - 2):
        return None
    triangles = triangles.reshape(-1, 3)
    # ear clipping may wind triangles either way: keep the face's winding (its normal)
    edge1 = corners[triangles[:, 1]] - corners[triangles[:, 0]]
    edge2 = corners[triangles[:, 2]] - corners[triangles[:, 0]]
    flip = np.cross(edge1, edge2) @ normal < 0.0
    triangles[flip] = triangles[flip][:, ::-1]
    return triangles.tolist()
