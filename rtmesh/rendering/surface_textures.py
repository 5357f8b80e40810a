"""Per-hit texturing: UVs and vertex colours interpolated from the hit barycentrics, image
textures looked up per material, normal maps applied in a tangent frame from the UVs.

What a hit reads (see docs/MATERIALS.md)::

    diffuse  = material.diffuse  * base texel RGB * vertex colour RGB      (tints.diffuse)
    specular = material.specular * map_Ks texel   * ((1 - m) + m * base)   (tints.specular)
    mirror   = material.mirror   * ((1 - m) + m * base texel)              (tints.mirror)
    opacity  = material.opacity  * base texel alpha * map_d texel * vertex alpha

with ``m`` the material's ``metallic`` (metals reflect in their own, textured, colour).
A material without textures and a scene without vertex colours read 1 for every factor,
and the integrator skips this module entirely when no material has a texture and no
object has vertex colours.

Tables are built once per scene and packed like the integrator's face tables: per face the
value at vertex 0 and its changes toward vertices 1 and 2, so one gather and two
multiply-adds give the value at a hit.  Materials are a Python loop over the few textured
materials present in a batch, never over rays.
"""

import numpy as np

from rtmesh.core.rays import component_major, take_rows
from rtmesh.core.vecmath import dot, normalize
from rtmesh.materials.table import TEXTURE_FIELDS


def corner_and_edges(values, faces):
    """Per-face ``[a0, a1 - a0, a2 - a0]`` of a per-vertex attribute, component-major.

    Parameters
    ----------
    values : (V, c) float
    faces : (F, 3) int

    Returns
    -------
    (F, 3 c) float64
    """
    a0, a1, a2 = (values[faces[:, k]] for k in range(3))
    return component_major(np.concatenate([a0.T, (a1 - a0).T, (a2 - a0).T]))


def interpolate(table, u, v):
    """Value at barycentrics ``(u, v)`` from gathered rows of :func:`corner_and_edges`.

    Parameters
    ----------
    table : (k, 3 c) float
    u, v : (k,) float

    Returns
    -------
    (k, c) float64
    """
    c = table.shape[1] // 3
    return table[:, :c] + u[:, None] * table[:, c:2 * c] + v[:, None] * table[:, 2 * c:]


def face_tangents(vertices, faces, uv):
    """Per-face tangent and bitangent: the derivatives of position with respect to u and v.

    Solves ``e1 = du1 T + dv1 B``, ``e2 = du2 T + dv2 B`` for each face.  Faces whose UVs
    are degenerate (zero area in UV space) get a tangent from the edge ``e1`` and a zero
    bitangent; :meth:`SurfaceTextures.normal_mapped` then builds the frame from the normal.

    Returns
    -------
    (F, 6) float64
        ``[T, B]`` (not normalised).
    """
    p0, p1, p2 = (vertices[faces[:, k]] for k in range(3))
    t0, t1, t2 = (uv[faces[:, k]] for k in range(3))
    e1, e2 = p1 - p0, p2 - p0
    d1, d2 = t1 - t0, t2 - t0
    det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    ok = np.abs(det) > 1e-20
    r = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)[:, None]
    tangent = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) * r
    bitangent = (e2 * d1[:, 0:1] - e1 * d2[:, 0:1]) * r
    tangent = np.where(ok[:, None], tangent, e1)
    return np.concatenate([tangent, bitangent], axis=1)


def transformed_tangents(tb, transform):
    """Per-face ``[T, B]`` of :func:`face_tangents` for UVs mapped by a texture's transform.

    A texture with ``transform = [A | b]`` reads ``uv' = A uv + b``, so its image axes lie
    along ``dp/duv' = [T B] A^-1`` on the surface: a normal map rotated by
    KHR_texture_transform bends normals in its rotated frame (the frame of the UVs the
    lookup reads, since rtmesh derives tangents from UVs).  Faces with degenerate UVs (zero
    bitangent) and a singular ``A`` keep their frame.

    Parameters
    ----------
    tb : (k, 6) float
    transform : (2, 3) float

    Returns
    -------
    (k, 6) float64
    """
    linear = np.asarray(transform, dtype=np.float64)[:, :2]
    if abs(np.linalg.det(linear)) < 1e-20:
        return tb
    inverse = np.linalg.inv(linear)
    t, b = tb[:, :3], tb[:, 3:]
    out = np.concatenate([t * inverse[0, 0] + b * inverse[1, 0], t * inverse[0, 1] + b * inverse[1, 1]], axis=1)
    degenerate = ~b.any(axis=1)
    out[degenerate] = tb[degenerate]
    return out


def _colour(texels):
    """(k, 3) colours of texels with any channel count (grey from one or two channels)."""
    return texels[:, :3] if texels.shape[1] >= 3 else np.repeat(texels[:, :1], 3, axis=1)


class Tints:
    """Per-hit multipliers of the material colours; None means "all ones".

    Attributes
    ----------
    diffuse, specular, mirror, emission : (k, 3) float or None
        ``diffuse`` also multiplies a metallic-roughness material's base colour.
    metallic_roughness : (k, 3) float or None
        Roughness, metallic and ambient-occlusion factors of metallic-roughness materials
        (see :meth:`SurfaceTextures.metallic_roughness`).
    """

    __slots__ = ("diffuse", "specular", "mirror", "emission", "metallic_roughness")

    def __init__(self, diffuse=None, specular=None, mirror=None, emission=None, metallic_roughness=None):
        self.diffuse, self.specular, self.mirror, self.emission = diffuse, specular, mirror, emission
        self.metallic_roughness = metallic_roughness


class SurfaceTextures:
    """A scene's texture and vertex-colour tables.

    Parameters
    ----------
    scene : Scene

    Attributes
    ----------
    uv : (F, 6) float or None
        :func:`corner_and_edges` of the scene's UVs.
    colours : (F, 12) float or None
        The same for the vertex colours (linear RGBA).
    textured : (m,) bool
        Materials with any image texture.
    """

    def __init__(self, scene):
        self.materials = scene.materials.materials
        # the Blinn-Phong metal tint of specular and mirror (metallic-roughness materials
        # use their metallic factor in their own BRDF, see metallic_roughness below)
        self.metallic = np.where(scene.materials.physical, 0.0, scene.materials.metallic)
        self.occlusion_strength = scene.materials.occlusion_strength
        self.opacity = scene.materials.opacity
        self.uv = None if scene.uv is None else corner_and_edges(scene.uv, scene.faces)
        self.colours = (None if scene.vertex_colors is None
                        else corner_and_edges(scene.vertex_colors, scene.faces))
        self.textured = np.array([any(getattr(m, f) is not None for f in TEXTURE_FIELDS)
                                  for m in self.materials], dtype=bool)
        self.physical_textured = any(m.metallic_roughness_texture is not None or m.occlusion_texture is not None
                                     for m in self.materials)
        self.normal_mapped_any = any(m.normal_texture is not None for m in self.materials)
        self.tangents = None
        if self.normal_mapped_any and scene.uv is not None:
            self.tangents = face_tangents(scene.vertices, scene.faces, scene.uv)

    def __bool__(self):
        return bool(self.colours is not None or (self.uv is not None and self.textured.any()))

    def uv_at(self, prim, u, v):
        """(k, 2) texture coordinates of hits; zeros without UVs."""
        if self.uv is None:
            return np.zeros((len(prim), 2))
        return interpolate(take_rows(self.uv, prim), u, v)

    def _groups(self, mat, field):
        """``(material, rows)`` for each material in ``mat`` with a texture in ``field``."""
        present = np.unique(mat)
        for i in present:
            texture = getattr(self.materials[i], field)
            if texture is not None:
                yield texture, np.flatnonzero(mat == i), i

    def tints(self, prim, u, v, mat):
        """Texture and vertex-colour multipliers of hits.

        Parameters
        ----------
        prim : (k,) intp
            Triangles hit.
        u, v : (k,) float
            Barycentrics of the hits.
        mat : (k,) intp
            Materials.

        Returns
        -------
        Tints
        """
        k = len(mat)
        diffuse = specular = mirror = None
        if self.colours is not None:
            diffuse = interpolate(take_rows(self.colours, prim), u, v)[:, :3]
        if self.uv is None:
            return Tints(diffuse)
        uv = None
        for texture, rows, i in self._groups(mat, "diffuse_texture"):
            uv = self.uv_at(prim, u, v) if uv is None else uv
            base = _colour(texture.sample(uv[rows]))
            if diffuse is None:
                diffuse = np.ones((k, 3))
            diffuse[rows] *= base
            m = self.metallic[i]
            if m > 0.0:
                metal_tint = (1.0 - m) + m * base
                specular = np.ones((k, 3)) if specular is None else specular
                mirror = np.ones((k, 3)) if mirror is None else mirror
                specular[rows] *= metal_tint
                mirror[rows] *= metal_tint
        for texture, rows, _ in self._groups(mat, "specular_texture"):
            uv = self.uv_at(prim, u, v) if uv is None else uv
            specular = np.ones((k, 3)) if specular is None else specular
            specular[rows] *= _colour(texture.sample(uv[rows]))
        return Tints(diffuse, specular, mirror, self.emission_tints(prim, u, v, mat, uv),
                     self.metallic_roughness(prim, u, v, mat, uv) if self.physical_textured else None)

    def metallic_roughness(self, prim, u, v, mat, uv=None):
        """Per-hit multipliers of metallic-roughness materials' factors from their textures.

        Parameters
        ----------
        prim : (k,) intp
        u, v : (k,) float
            Barycentrics of the hits.
        mat : (k,) intp
        uv : (k, 2) float, optional
            The hits' texture coordinates, when already looked up.

        Returns
        -------
        (k, 3) float64 or None
            Columns: the roughness factor (the metallic-roughness texture's green channel),
            the metallic factor (its blue channel) and the occlusion of the ambient term
            (``1 + strength (red - 1)`` of the occlusion texture); None when no hit's
            material has either texture (or the scene has no UVs).
        """
        if self.uv is None:
            return None
        factors = None
        for field, columns in (("metallic_roughness_texture", (1, 2)), ("occlusion_texture", (0,))):
            for texture, rows, i in self._groups(mat, field):
                uv = self.uv_at(prim, u, v) if uv is None else uv
                texels = texture.sample(uv[rows])
                if factors is None:
                    factors = np.ones((len(mat), 3))
                if len(columns) == 2:
                    # glTF: roughness in green, metalness in blue (grey images: every channel)
                    green, blue = (texels[:, min(c, texels.shape[1] - 1)] for c in columns)
                    factors[rows, 0] = green
                    factors[rows, 1] = blue
                else:
                    factors[rows, 2] = 1.0 + self.occlusion_strength[i] * (texels[:, 0] - 1.0)
        return factors

    @property
    def emission_textured(self):
        """Whether any material's emission varies over its surface (a texture and UVs)."""
        return self.uv is not None and any(m.emission_texture is not None for m in self.materials)

    def emission_tints(self, prim, u, v, mat, uv=None):
        """Multipliers of the materials' emission at points (their emission textures).

        Parameters
        ----------
        prim, u, v, mat : (k,) arrays
            As in :meth:`tints`.
        uv : (k, 2) float, optional
            :meth:`uv_at` of the points, if the caller has it.

        Returns
        -------
        (k, 3) float or None
            None when no point's material has an emission texture.
        """
        if self.uv is None:
            return None
        out = None
        for texture, rows, _ in self._groups(mat, "emission_texture"):
            uv = self.uv_at(prim, u, v) if uv is None else uv
            out = np.ones((len(mat), 3)) if out is None else out
            out[rows] = _colour(texture.sample(uv[rows]))
        return out

    def mean_emission_tints(self):
        """(m, 3) float: per material, the mean of its emission texture over the image (ones
        without one): what a triangle emits on average, for choosing where to sample."""
        return np.array([np.ones(3) if m.emission_texture is None else
                         _colour(m.emission_texture.pixels.reshape(-1, m.emission_texture.channels)).mean(axis=0)
                         for m in self.materials]).reshape(-1, 3)

    def opacities(self, prim, u, v, mat):
        """Opacity of hits in [0, 1] (see the module notes).

        Parameters
        ----------
        prim, u, v, mat : (k,) arrays
            As in :meth:`tints`.

        Returns
        -------
        (k,) float64
        """
        alpha = self.opacity.take(mat)
        if self.colours is not None:
            alpha = alpha * interpolate(take_rows(self.colours, prim), u, v)[:, 3]
        if self.uv is None:
            return alpha
        uv = None
        for field in ("diffuse_texture", "opacity_texture"):
            for texture, rows, _ in self._groups(mat, field):
                if field == "diffuse_texture" and texture.channels not in (2, 4):
                    continue  # no alpha channel
                uv = self.uv_at(prim, u, v) if uv is None else uv
                texel = texture.sample(uv[rows])
                alpha[rows] *= texel[:, -1] if field == "diffuse_texture" else texel[:, 0]
        return np.clip(alpha, 0.0, 1.0)

    def normal_mapped(self, ns, prim, u, v, mat, flip, tangents=None):
        """Shading normals perturbed by the materials' tangent-space normal maps.

        The map's texel ``t`` in [0, 1]^3 is the normal ``2 t - 1`` in the frame (T, B, N)
        with N the interpolated shading normal and T, B the face's UV derivatives made
        orthogonal to N (Gram-Schmidt; B keeps the handedness of the UV mapping), taken
        through the map's UV transform if it has one (:func:`transformed_tangents`).  On the
        back of a face (``flip`` -1) the frame is mirrored with the normal.

        Parameters
        ----------
        ns : (k, 3) float
            Unit shading normals, on the side the ray came from.
        prim, u, v, mat : (k,) arrays
        flip : (k,) float
            +1 where the ray hit the front of the face, -1 at the back.
        tangents : (k, 6) float, optional
            The hits' UV tangents and bitangents in the world (hits on placed meshes: their
            face's carried by the placement, :meth:`Instances.world_tangents`); default: the
            faces' own.

        Returns
        -------
        (k, 3) float
            Unit normals (``ns`` itself where no normal map applies).
        """
        if self.tangents is None:
            return ns
        out = None
        for texture, rows, _ in self._groups(mat, "normal_texture"):
            texel = texture.sample(self.uv_at(prim[rows], u[rows], v[rows]))
            local = 2.0 * texel[:, :3] - 1.0
            n = np.ascontiguousarray(ns[rows])
            tb = self.tangents[prim[rows]] if tangents is None else tangents[rows]
            if texture.transformed:
                tb = transformed_tangents(tb, texture.transform)
            t = tb[:, :3] - n * dot(n, tb[:, :3])[:, None]
            t = normalize(t)
            b = np.cross(n, t)
            handed = np.where(dot(b, tb[:, 3:]) < 0.0, -1.0, 1.0)
            f = flip[rows][:, None]
            bent = normalize(f * (local[:, :1] * t + (handed[:, None] * local[:, 1:2]) * b) + local[:, 2:3] * n)
            # an unusable texel (zero vector) keeps the interpolated normal
            bad = ~(dot(bent, bent) > 0.5)
            bent[bad] = n[bad]
            if out is None:
                out = np.array(ns, order="F", copy=True)
            out[rows] = bent
        return ns if out is None else out
