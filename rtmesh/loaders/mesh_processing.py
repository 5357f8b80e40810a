"""What trimesh's processing (``Trimesh.process``) does to a loaded mesh, done here faster
and without losing geometry silently or at extreme scales: faces with bad indices or
non-finite vertices dropped with a warning, duplicate vertices merged at a precision the
mesh's scale allows (see :func:`process`)."""

import logging

import numpy as np
import trimesh

from rtmesh.core.errors import MeshError
from rtmesh.geometry import build_kernels

log = logging.getLogger(__name__)


def process(mesh, source="mesh"):
    """What ``trimesh.load`` does to each mesh by default (``Trimesh.process``), faster and
    without losing geometry silently or at extreme scales.

    trimesh's processing drops non-finite vertices and merges duplicate ones (equal after
    rounding to ``trimesh.tol.merge``, with equal texture coordinates and normals).  Here:

    - faces that use a vertex with a NaN or infinite coordinate are dropped with a warning
      that counts them (trimesh drops them without a word);
    - vertices merge as trimesh merges them (:func:`merge_vertices`), but at a precision
      relative to the mesh's scale where ``tol.merge`` would be coarse for it (a model
      measured in nanometres), and without trimesh's conversion to 64-bit integers, which
      overflows for coordinates beyond about 1e10 and collapsed every vertex of such a
      model;
    - most files have no duplicate vertices: one hash-table pass
      (:func:`rtmesh.geometry.build_kernels.rows_distinct`) shows that the merge would keep every
      vertex where it is, and the merge (a sort, 0.4 s for a million triangles) runs only
      where it would not.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Loaded with ``process=False``; processed in place.
    source : str
        Names the mesh in warnings.
    """
    build_kernels.BUILD_KERNELS.prepare()
    faces = mesh.faces.view(np.ndarray)
    if mesh.vertices.ndim != 2 or mesh.vertices.shape[1] != 3:
        # trimesh reads every vertex with the column count of some line: one short line
        # (a truncated file) makes all of them 2D
        raise MeshError(f"{source}: vertices of {mesh.vertices.shape[-1]} coordinates, not 3 (a "
                        "vertex statement with too few values: a truncated file?)")
    if mesh.is_empty or faces.ndim != 2 or not len(faces):
        mesh.metadata["processed"] = True  # nothing to process (parts_from_trimesh skips it)
        return
    drop_bad_index_faces(mesh, source)
    _drop_non_finite_faces(mesh, source)
    if not len(mesh.faces):
        # every face used a non-finite vertex: nothing to merge (parts_from_trimesh skips it)
        mesh.metadata["processed"] = True
        return
    digits = merge_digits(mesh.vertices.view(np.ndarray), mesh.faces.view(np.ndarray))
    if not _merge_keeps_everything(mesh, digits):
        # as Trimesh.process: the cache lock keeps the file's normals across the merge
        with mesh._cache:
            merge_vertices(mesh, digits)
            mesh._cache.clear(exclude={"face_normals", "vertex_normals"})
    mesh.metadata["processed"] = True


def drop_bad_index_faces(mesh, source):
    """Drop the faces that refer to vertices the file does not have, saying how many."""
    faces = mesh.faces.view(np.ndarray)
    if not faces.size or (faces.min() >= 0 and faces.max() < len(mesh.vertices)):
        return
    bad = ((faces < 0) | (faces >= len(mesh.vertices))).any(axis=1)
    if bad.any():
        log.warning("%s: dropped %d of %d faces that refer to vertices the file does not have",
                    source, int(bad.sum()), len(faces))
        mesh.faces = faces[~bad]


def _drop_non_finite_faces(mesh, source):
    """Drop the faces that use a vertex with a NaN or infinite coordinate, saying how many."""
    vertices, faces = mesh.vertices.view(np.ndarray), mesh.faces.view(np.ndarray)
    if np.isfinite(vertices).all():
        return
    finite = np.isfinite(vertices).all(axis=1)
    bad = ~finite[faces].all(axis=1)
    log.warning("%s: dropped %d of %d faces that use vertices with NaN or infinite coordinates "
                "(%d such vertices)", source, int(bad.sum()), len(faces), int((~finite).sum()))
    mesh.remove_infinite_values()


def merge_digits(vertices, faces):
    """Decimal digits at which vertices merge: trimesh's (``tol.merge``), or finer for a
    mesh whose typical edge is not long against it.

    The tolerance is at most ``MERGE_FRACTION`` of the median edge length (of up to 4096
    faces evenly spread), so merging never collapses the edges of a small model; for every
    model with a typical edge longer than 1e-3 it is trimesh's.

    Parameters
    ----------
    vertices : (v, 3) float
        Finite.
    faces : (f, 3) int

    Returns
    -------
    int
    """
    digits = trimesh.util.decimal_to_digits(trimesh.tol.merge)
    if not len(faces):
        return digits
    sample = faces[::max(1, len(faces) // 4096)]
    corners = vertices[sample]
    lengths = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2)
    lengths = lengths[lengths > 0.0]
    if not len(lengths):
        return digits
    tolerance = min(trimesh.tol.merge, MERGE_FRACTION * float(np.median(lengths)))
    return max(digits, trimesh.util.decimal_to_digits(tolerance))


# a merge tolerance at most this fraction of a mesh's median edge (see merge_digits)
MERGE_FRACTION = 1e-5


def _merge_keys(mesh, digits, with_attributes=True):
    """The rows trimesh's merge compares (position, and texture coordinates and normals
    unless ``with_attributes`` is False), rounded as it rounds them, as int64: converted as
    trimesh converts them where they fit, else the bits of the rounded floats (equal rounded
    values have equal bits once ``+ 0.0`` turns -0.0 into 0.0), so that no conversion
    overflows at any scale."""
    stacked = [mesh.vertices.view(np.ndarray) * (10.0**digits)]
    if with_attributes:
        visual = mesh.visual
        if (visual.defined and visual.kind == "texture" and visual.uv is not None
                and len(visual.uv) == len(mesh.vertices)):
            stacked.append(np.asarray(visual.uv, dtype=np.float64) * 1e4)  # trimesh: 4 digits
        normals = mesh._cache["vertex_normals"]
        if np.shape(normals) == mesh.vertices.shape:
            stacked.append(np.asarray(normals, dtype=np.float64) * 1e2)  # trimesh: 2 digits
    keys = np.column_stack(stacked).round()
    if -2.0**62 < keys.min() and keys.max() < 2.0**62:  # False for NaN (texture coordinates)
        return keys.astype(np.int64)  # trimesh's keys exactly (and its fast hashing of them)
    return np.ascontiguousarray(keys + 0.0).view(np.int64)


def merge_vertices(mesh, digits):
    """``trimesh.grouping.merge_vertices`` at ``digits`` (same groups, same order), with the
    rows compared by :func:`_merge_keys` instead of as int64 conversions.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Finite vertices; merged in place.
    digits : int
    """
    referenced = np.zeros(len(mesh.vertices), dtype=bool)
    referenced[mesh.faces] = True
    keys = _merge_keys(mesh, digits)
    unique, inverse_referenced = trimesh.grouping.unique_rows(keys[referenced], keep_order=True)
    inverse = np.zeros(len(mesh.vertices), dtype=np.int64)
    inverse[referenced] = inverse_referenced
    mesh.update_vertices(mask=np.nonzero(referenced)[0][unique], inverse=inverse)


def _merge_keeps_everything(mesh, digits=None):
    """True when the merge would change nothing: every vertex finite and used by a face, and
    no two vertices at the same position as the merge rounds positions (at ``digits``;
    None: :func:`merge_digits`) (distinct positions make distinct rows whatever texture
    coordinates or normals it also compares).
    """
    vertices, faces = mesh.vertices.view(np.ndarray), mesh.faces.view(np.ndarray)
    if not build_kernels.referenced_and_finite(vertices, faces):
        return False
    if digits is None:
        digits = merge_digits(vertices, faces)
    return build_kernels.rows_distinct(_merge_keys(mesh, digits, with_attributes=False))
