"""What the stages read per hit: a built scene's per-material and per-face tables.

Formed once per scene (:class:`rtmesh.rendering.integrator.Integrator` builds them with the
Embree scene) and shared by every view of it, the general path's stages
(:mod:`rtmesh.rendering.surface_stage`, the tests' wavefront (``tests/wavefront``)) and the
fused direct-lighting stage (:mod:`rtmesh.rendering.direct_stage`) read them by name.
"""

from dataclasses import dataclass

import numpy as np

from rtmesh.core.rays import component_major
from rtmesh.geometry.build_kernels import corner_rows, face_rows
from rtmesh.shading.direct_light import highlight_thresholds


@dataclass(frozen=True, eq=False)
class ShadingTables:
    """Per-material and per-face tables of one built scene.

    Attributes
    ----------
    shaded : (m,) bool
        Blinn-Phong materials that reflect light (diffuse or specular, not unlit); the
        metallic-roughness ones are shaded by the path kernel.
    all_shaded : bool
        Every material is ``shaded``: no per-hit lookup is needed.
    diffuse, specular, emission, ambient_light : (m, 3) float64
        Component-major, so that gathering them per hit keeps the fast layout;
        ``ambient_light`` is the material's ambient colour times the scene's ambient light.
    highlight_exponent : (m,) float64
        Blinn-Phong shininess; negative for materials without a highlight.
    highlight_from : (m,) float64
        The smallest highlight cosine whose power is kept
        (:func:`rtmesh.shading.direct_light.highlight_thresholds`).
    faces : (F, 12) float64
        Row-major: the triangle ``[v0, v1 - v0, v2 - v0]`` as Embree saw it and the unit
        geometric normal (the surface kernels read whole rows).
    vertex_normals : (F, 9) float64
        Row-major ``[n0, n1 - n0, n2 - n0]`` of each face's vertex normals; ``(0, 9)``
        without smooth shading.
    smooth : (F,) bool
        Faces that interpolate their vertex normals.
    material_id : (F,) intp
        (intp: NumPy gathers with int32 indices are ~10x slower.)
    offset_scale32 : float32
        The scene size of the ray-origin offsets, as the compiled kernels take it.
    """

    shaded: np.ndarray
    all_shaded: bool
    diffuse: np.ndarray
    specular: np.ndarray
    emission: np.ndarray
    ambient_light: np.ndarray
    highlight_exponent: np.ndarray
    highlight_from: np.ndarray
    faces: np.ndarray
    vertex_normals: np.ndarray
    smooth: np.ndarray
    material_id: np.ndarray
    offset_scale32: np.float32

    @classmethod
    def build(cls, scene, triangles, offset_scale):
        """The tables of ``scene``.

        Parameters
        ----------
        scene : Scene
            Its materials, ambient light, faces, normals and material ids.
        triangles : (F, 9) float
            :attr:`rtmesh.geometry.accel.Accel.triangles` (the re-centred triangles).
        offset_scale : float
        """
        m = scene.materials
        shaded = ((m.diffuse > 0).any(axis=1) | (m.specular > 0).any(axis=1)) & ~m.unlit & ~m.physical
        exponent = np.where((m.specular > 0).any(axis=1), m.shininess, -1.0)
        # compiled passes writing the rows directly (filling the columns of a row-major
        # table from component-major ones took NumPy ~0.5 s on a million faces)
        faces = face_rows(triangles, scene.face_normals)
        vertex_normals = (np.zeros((0, 9)) if scene.vertex_normals is None
                          else corner_rows(scene.vertex_normals, scene.faces))
        return cls(
            shaded=shaded,
            all_shaded=bool(shaded.all()),
            diffuse=component_major(m.diffuse.T),
            specular=component_major(m.specular.T),
            emission=component_major(m.emission.T),
            ambient_light=component_major((m.ambient * scene.ambient).T),
            highlight_exponent=exponent,
            highlight_from=highlight_thresholds(exponent),
            faces=faces,
            vertex_normals=vertex_normals,
            smooth=(np.zeros(len(scene.faces), dtype=bool) if scene.smooth is None
                    else np.ascontiguousarray(scene.smooth, dtype=bool)),
            material_id=scene.material_id.astype(np.intp),
            offset_scale32=np.float32(offset_scale),
        )
