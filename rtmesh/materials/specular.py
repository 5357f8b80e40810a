"""Specular scattering: the mirror, glossy and smooth-dielectric lobes of the material table.

rtmesh's materials answer two questions.  *How much of the light arriving from a direction
leaves toward the viewer* is Blinn-Phong's (:mod:`rtmesh.materials.blinn_phong`), evaluated
toward the lights.  *Where do the rays the integrator follows go, and with what weight* is
this module's, for the lobes a Whitted integrator follows:

- the mirror lobe (``mirror`` colour, optionally texture-tinted): a delta lobe around the
  mirror direction, or, for a ``roughness`` > 0, the Phong lobe around it
  (:mod:`rtmesh.materials.glossy`), sampled exactly from its density so that every sample
  weighs ``kr``;
- the smooth dielectric (``transmission``): a delta reflection weighted by Fresnel (all of
  it under total internal reflection) added to the mirror lobe, and a delta refraction by
  Snell's law weighted ``(1 - F) transmission``.

:class:`SpecularScattering` offers ``sample`` (the rays), ``evaluate`` and ``pdf`` (of the
reflection lobe toward a given direction: zero and infinite for a delta lobe).  Both delta
lobes of a dielectric are followed (the Whitted split), not chosen between.
"""

from dataclasses import dataclass

import numpy as np

from rtmesh.core.rays import take_rows
from rtmesh.core.vecmath import dot, fresnel_dielectric, fresnel_schlick, orthonormal_basis, reflect, refract
from rtmesh.materials.glossy import roughness_exponent, sample_glossy_directions, square_to_phong_lobe_pdf


def fresnel_exact_or_schlick(mode):
    """The Fresnel function for a ``fresnel`` setting (``"exact"`` or ``"schlick"``)."""
    return fresnel_dielectric if mode == "exact" else fresnel_schlick


@dataclass
class Lobe:
    """The rays one lobe sends from a batch of hits.

    Attributes
    ----------
    rows : (j,) intp
        The hits (rows of the batch given to :meth:`SpecularScattering.sample`) that send one.
    directions : (j, 3) float64
        Unit directions of the rays.
    weight : (j, 3) float64
        Throughput factor of each ray: ``f |cos| / pdf`` (for a delta lobe its reflectance
        or transmittance).
    kept : (c,) bool
        Which of the lobe's candidate rows (those that could scatter into it) send a ray.
    """

    rows: np.ndarray
    directions: np.ndarray
    weight: np.ndarray
    kept: np.ndarray


class SpecularScattering:
    """The specular lobes of a material table.

    Parameters
    ----------
    materials : MaterialTable
    fresnel : {"schlick", "exact"}
        The dielectric's Fresnel reflectance.
    """

    def __init__(self, materials, fresnel="schlick"):
        self.mirror = materials.mirror
        self.transmission = materials.transmission
        self.roughness = materials.roughness
        self.reflective = (materials.mirror > 0).any(axis=1) | (materials.transmission > 0).any(axis=1)
        self.transmissive = (materials.transmission > 0).any(axis=1)
        # metallic-roughness materials reflect through their BRDF's GGX lobe: their
        # transmission spawns refracted rays (and totally reflected ones) only
        self.brdf_reflects = materials.physical
        self.fresnel = fresnel_exact_or_schlick(fresnel)

    def sample(self, wo, ns, ng, mat, mirror_tint, refracting, follow, glossy_points=None):
        """The reflected and refracted rays of hits on reflective materials.

        Parameters
        ----------
        wo : (k, 3) float64
            Unit directions toward the viewer (``-d``).
        ns, ng : (k, 3) float64
            Shading and geometric normals on the viewer's side.
        mat : (k,) intp
        mirror_tint : (k, 3) float64 or None
            Texture tint of the mirror colour.
        refracting : tuple of ((c,) intp, (c,) float64) or None
            The rows on transmissive materials and the relative index of refraction
            ``ior before / ior after`` of each (the caller knows the media).
        follow : callable
            ``follow(rows, weight) -> (c,) bool``: which candidate rays the caller follows,
            given their rows (None: all ``k``) and weights; directions are formed only for
            those.
        glossy_points : callable, optional
            ``glossy_points(rows) -> (r, 2)`` sample points in [0, 1)^2 for the glossy
            lobe of the given rows; None when no material is rough.

        Returns
        -------
        reflection : Lobe
        refraction : Lobe or None
            None without ``refracting`` rows.
        """
        reflect_weight = self.mirror[mat]
        if mirror_tint is not None:
            reflect_weight = reflect_weight * mirror_tint
        refraction = None
        if refracting is not None:
            j, eta = refracting
            cos_i = np.clip(dot(wo[j], ns[j]), 0.0, 1.0)
            fresnel = self.fresnel(cos_i, eta)
            wt, tir = refract(wo[j], ns[j], eta)
            # a shading normal can bend the refracted ray back to the incoming side of
            # the real surface; such rays cannot go through and are dropped
            ok = ~tir & (dot(wt, ng[j]) < 0.0)
            transmission = self.transmission[mat[j]]
            reflect_weight = reflect_weight.copy()
            reflected = np.where(tir, 1.0, np.where(self.brdf_reflects[mat[j]], 0.0, fresnel))
            reflect_weight[j] += reflected[:, None] * transmission
            w_t = (1.0 - fresnel)[:, None] * transmission
            keep = ok & follow(j, w_t)
            refraction = Lobe(j[keep], wt[keep], w_t[keep], keep)
        keep = follow(None, reflect_weight)
        rows = np.flatnonzero(keep)
        wr = reflect(wo[keep], ns[keep])
        # a shading normal can send the mirror direction under the real surface: fall back
        # to the geometric mirror direction there
        below = dot(wr, ng[keep]) <= 0.0
        if below.any():
            wr[below] = reflect(wo[keep][below], ng[keep][below])
        if glossy_points is not None:
            wr = self._glossy(wr, ng[keep], mat[keep], rows, glossy_points)
        return Lobe(rows, wr, reflect_weight[keep], keep), refraction

    def _glossy(self, mirror, ng, mat, rows, glossy_points):
        """Mirror directions of rough materials replaced by samples of their lobe."""
        roughness = self.roughness.take(mat)
        rough = np.flatnonzero(roughness > 0.0)
        if not len(rough):
            return mirror
        u = glossy_points(rows.take(rough))
        mirror[rough] = sample_glossy_directions(take_rows(mirror, rough), take_rows(ng, rough),
                                                 roughness.take(rough), u)
        return mirror

    def pdf(self, wo, ns, mat, wi, ng=None):
        """Solid-angle density with which :meth:`sample` draws ``wi`` in the reflection lobe.

        Infinite for smooth materials (a delta lobe: only the mirror direction); for rough
        ones the Phong lobe's density around the mirror direction, with the part of the
        lobe under the surface folded back above it as :meth:`sample` folds its directions
        (:mod:`rtmesh.materials.glossy`): above the surface the density at ``wi`` plus that
        at its mirror image below, zero below.

        Parameters
        ----------
        wo, ns : (k, 3) float64
        mat : (k,) intp
        wi : (k, 3) float64
            Unit directions.
        ng : (k, 3) float64, optional
            Geometric normals, about whose tangent plane directions are folded (default
            ``ns``).  (Where the shading normal's mirror direction falls under the surface,
            :meth:`sample` mirrors about ``ng`` instead; this density does not follow it.)

        Returns
        -------
        (k,) float64
        """
        ng = ns if ng is None else ng
        roughness = self.roughness.take(mat)
        rough = roughness > 0.0
        pdf = np.full(len(mat), np.inf)
        if rough.any():
            mirror = reflect(wo[rough], ns[rough])
            t, b = orthonormal_basis(mirror)
            exponent = roughness_exponent(roughness[rough])

            def lobe(directions):
                local = np.column_stack([dot(directions, t), dot(directions, b), dot(directions, mirror)])
                return square_to_phong_lobe_pdf(local, exponent)

            w, g = wi[rough], ng[rough]
            height = dot(w, g)
            pdf[rough] = np.where(height >= 0.0, lobe(w) + lobe(w - (2.0 * height)[:, None] * g), 0.0)
        return pdf

    def evaluate(self, wo, ns, mat, wi, ng=None):
        """``f(wo, wi) |cos|`` of the reflection lobe of a mirror or rough material.

        Zero for smooth materials (a delta lobe reflects toward no other direction); for
        rough ones ``kr * pdf``, as the lobe is sampled exactly from its density
        (so ``evaluate / pdf`` is the weight :meth:`sample` gives, ``kr``).

        Parameters
        ----------
        wo, ns : (k, 3) float64
        mat : (k,) intp
        wi : (k, 3) float64
        ng : (k, 3) float64, optional
            As for :meth:`pdf`.

        Returns
        -------
        (k, 3) float64
        """
        pdf = self.pdf(wo, ns, mat, wi, ng)
        density = np.where(np.isfinite(pdf), pdf, 0.0)
        return self.mirror[mat] * density[:, None]
