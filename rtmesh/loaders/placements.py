"""A mesh that a loader places many times: kept once and placed by Embree instances, or
copied, by the rule of :func:`rtmesh.scene.instances.worth_instancing`.

The glTF loader (:func:`rtmesh.loaders.trimesh_parts.parts_from_trimesh`, node reuse and
``EXT_mesh_gpu_instancing``), scene files (objects that import one file several times,
``[[objects]] instances = "file.npy"``) and USD (point instancers, instanceable prims) decide
the same way and count the same memory before they take it.
"""

import numpy as np

from rtmesh.rendering import memory
from rtmesh.scene.instances import worth_instancing
from rtmesh.scene.model import MeshPart


def held_copies(triangles, placements):
    """How many copies of a mesh of ``triangles`` placed ``placements`` times a scene holds:
    one when it is instanced, else one a placement."""
    return 1 if worth_instancing(triangles, placements) else placements


def placed_estimate(vertices, triangles, placements):
    """Bytes a mesh placed ``placements`` times takes loaded
    (:func:`rtmesh.rendering.memory.load_estimate`): its copies held (:func:`held_copies`)
    and a record for every placement."""
    held = held_copies(triangles, placements)
    return memory.load_estimate(held * vertices, held * triangles, placements)


def copied(part, transforms, name=None):
    """One part holding a copy of ``part`` under each transform.

    Vertices are ``A v + t`` (``A`` the linear part), the winding is reversed under a
    mirroring transform and normals are carried by the inverse transpose (not normalised:
    the scene does that); texture coordinates and colours are repeated.

    Parameters
    ----------
    part : MeshPart
        In its own (model) coordinates.
    transforms : (k, 4, 4) float
        Model-to-world transforms, finite and non-singular.
    name : str, optional
        The copies' object name (default: the part's).

    Returns
    -------
    MeshPart
        ``k * v`` vertices and ``k * f`` faces, copy ``j`` at ``[j * v, (j + 1) * v)``.
    """
    matrices = np.asarray(transforms, dtype=np.float64).reshape(-1, 4, 4)
    vertices = np.asarray(part.vertices, dtype=np.float64)
    faces = np.asarray(part.faces)
    m, v = len(matrices), len(vertices)
    linear = matrices[:, :3, :3]
    determinant = np.linalg.det(linear)
    placed = np.einsum("mij,vj->mvi", linear, vertices) + matrices[:, None, :3, 3]
    normals = None
    if part.vertex_normals is not None:
        normal_matrices = np.linalg.inv(linear).transpose(0, 2, 1)
        normals = np.einsum("mij,vj->mvi", normal_matrices, part.vertex_normals).reshape(-1, 3)
    copies = np.where((determinant < 0.0)[:, None, None], faces[None, :, ::-1], faces[None])
    copies = copies + (np.arange(m) * v)[:, None, None]
    return MeshPart(part.name if name is None else name, placed.reshape(-1, 3), copies.reshape(-1, 3), part.material,
                    normals, uv=None if part.uv is None else np.tile(part.uv, (m, 1)),
                    vertex_colors=None if part.vertex_colors is None else np.tile(part.vertex_colors, (m, 1)),
                    category=part.category)
