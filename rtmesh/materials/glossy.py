"""Glossy (blurry) reflection: reflection directions sampled in a lobe around the mirror direction.

Lobe
----
A material's ``roughness`` r > 0 turns its mirror reflection into a Phong lobe around the
mirror direction ``wr``, the lobe of the original distribution ray tracer (Cook, Porter and
Carpenter 1984; Lafortune and Willems 1994)::

    pdf(wi) = (n + 1) / (2 pi) * cos(alpha)^n     (solid angle; alpha = angle(wi, wr) < 90 deg)

with the exponent ``n = 1 / r^2``.  For small angles ``cos^n(alpha) ~ exp(-n alpha^2 / 2)``, a
Gaussian whose standard deviation per axis is ``1 / sqrt(n) = r`` radians: roughness is the
angular blur of the reflection, and r -> 0 gives the mirror back.

Why this lobe and not a GGX microfacet model: rtmesh's material model is Blinn-Phong plus
a mirror term whose reflectance ``kr`` does not depend on the angle (no Fresnel on
metals, no shadowing-masking).  A microfacet BRDF sampled through its visible normals would
bring a weight ``G1(wi)`` and an angle-dependent reflectance that the rest of the model does
not have, so the blurred reflection of a rough surface would not converge to the sharp
reflection of the same material at r = 0.  The Phong lobe is sampled exactly from its own
normalised density, so every sample carries the weight ``kr``: the estimator adds no
variance from weights, and its expected weight is exactly the mirror reflectance.

Directions under the surface
----------------------------
Near grazing incidence part of the lobe lies below the geometric surface.  Those directions
are *folded* back above it (mirrored in the tangent plane of the geometric normal,
``wi - 2 (wi . ng) ng``) and keep their weight: the surface still reflects exactly ``kr``
of the light at every angle, only the shape of the lobe is clipped at the horizon.
Dropping them instead would darken rough surfaces at grazing angles by the fraction of the
lobe below the horizon (up to one half), which the mirror model (r = 0) never does.
"""

import numpy as np
from numba.extending import register_jitable

from rtmesh.core.compiled import by_component, kernel
from rtmesh.core.row_vectors import dot3, tangent_frame


def roughness_exponent(roughness):
    """Phong exponent of the lobe of a roughness, ``n = 1 / r^2``.

    Parameters
    ----------
    roughness : (k,) float
        > 0; the angular standard deviation of the lobe in radians (for small r).

    Returns
    -------
    (k,) float
    """
    return 1.0 / np.square(roughness)


def square_to_phong_lobe(u, exponent):
    """Directions around +z with density ``(n + 1) / (2 pi) cos^n(theta)``.

    ``cos(theta) = (1 - u0)^(1 / (n + 1))``, ``phi = 2 pi u1`` (inverting the cumulative
    distribution of ``cos^(n+1)``).  ``1 - cos(theta)`` is formed with ``expm1`` so that the
    lobes of tiny roughness (n up to ~1e12) keep their small angles instead of rounding to
    the pole.

    Parameters
    ----------
    u : (k, 2) float
        Points in [0, 1)^2.
    exponent : (k,) float or float
        Phong exponent n >= 0.

    Returns
    -------
    (k, 3) float
        Unit directions with z > 0.
    """
    return np.stack(lobe_direction(_one_minus_cos(u[:, 0], exponent), u[:, 1]), axis=1)


def _one_minus_cos(u0, exponent):
    """``1 - cos(theta)`` of :func:`square_to_phong_lobe` from its first number, (k,).

    NumPy's SIMD ``log1p`` and ``expm1``, which round differently from libm's: kept out of
    the kernels so that every path draws the same directions."""
    log_cos = np.log1p(-u0) / (np.asarray(exponent) + 1.0)
    return -np.expm1(log_cos)


@register_jitable
def lobe_direction(one_minus_cos, u1):
    """The lobe direction around +z of :func:`square_to_phong_lobe` from ``1 - cos(theta)``
    and its second number, ``(x, y, z)``: for arrays, and for numbers in compiled code
    (:func:`lobe_directions`)."""
    cos_theta = 1.0 - one_minus_cos
    sin_theta = np.sqrt(np.maximum(one_minus_cos * (1.0 + cos_theta), 0.0))
    phi = 2.0 * np.pi * u1
    return sin_theta * np.cos(phi), sin_theta * np.sin(phi), cos_theta


def phong_lobe_to_square(w, exponent):
    """Inverse of :func:`square_to_phong_lobe`, (k, 3) -> (k, 2)."""
    cos_theta = np.clip(w[:, 2], 0.0, 1.0)
    u0 = -np.expm1((np.asarray(exponent) + 1.0) * np.log(cos_theta))
    phi = np.arctan2(w[:, 1], w[:, 0])
    return np.stack([u0, np.mod(phi, 2.0 * np.pi) / (2.0 * np.pi)], axis=1)


def square_to_phong_lobe_pdf(w, exponent):
    """Solid-angle density of :func:`square_to_phong_lobe`; 0 for ``z <= 0``."""
    cos_theta = np.maximum(w[:, 2], 0.0)
    return np.where(w[:, 2] > 0.0, (np.asarray(exponent) + 1.0) / (2.0 * np.pi)
                    * cos_theta ** np.asarray(exponent), 0.0)


def sample_glossy_directions(mirror, ng, roughness, u):
    """Reflection directions in the lobe around each mirror direction.

    Parameters
    ----------
    mirror : (k, 3) float
        Unit mirror directions, above the surface (``mirror . ng > 0``).
    ng : (k, 3) float
        Unit geometric normals on the side the ray leaves toward.
    roughness : (k,) float
        > 0.
    u : (k, 2) float
        Sample points in [0, 1)^2.

    Returns
    -------
    (k, 3) float
        Unit directions with ``wi . ng >= 0`` (directions drawn under the surface are
        folded back above it, see the module notes); each carries the weight ``kr``.
    """
    one_minus_cos = np.ascontiguousarray(_one_minus_cos(u[:, 0], roughness_exponent(roughness)), dtype=np.float64)
    return lobe_directions(*(by_component(np.asfortranarray(v, dtype=np.float64)) for v in (mirror, ng)),
                           one_minus_cos, np.ascontiguousarray(u[:, 1], dtype=np.float64)).T


@kernel
def lobe_directions(mirror_t, ng_t, one_minus_cos, u1):
    """:func:`sample_glossy_directions` once the lobe's ``1 - cos(theta)`` is formed.

    Parameters
    ----------
    mirror_t, ng_t : (3, k) float64
        Mirror directions and geometric normals by component
        (:func:`rtmesh.core.compiled.by_component`).
    one_minus_cos, u1 : (k,) float64
        ``1 - cos(theta)`` (:func:`_one_minus_cos`) and the second sample number.

    Returns
    -------
    (3, k) float64
        Directions ``(t x + b y) + wr z`` in the mirror direction's frame
        (:func:`rtmesh.core.row_vectors.tangent_frame`), folded above the surface:
        ``wi - (2 min(wi . ng, 0)) ng``, each rounding as the NumPy formulation does.
    """
    k = len(one_minus_cos)
    out = np.empty((3, k))
    for i in range(k):
        lx, ly, lz = lobe_direction(one_minus_cos[i], u1[i])
        mx, my, mz = mirror_t[0, i], mirror_t[1, i], mirror_t[2, i]
        tx, ty, tz, bx, by, bz = tangent_frame(mx, my, mz)
        wx, wy, wz = (tx * lx + bx * ly) + mx * lz, (ty * lx + by * ly) + my * lz, (tz * lx + bz * ly) + mz * lz
        gx, gy, gz = ng_t[0, i], ng_t[1, i], ng_t[2, i]
        below = dot3(wx, wy, wz, gx, gy, gz)
        fold = 0.0 if below > 0.0 else below  # np.minimum(below, 0.0): NaN stays NaN
        out[0, i], out[1, i], out[2, i] = wx - (2.0 * fold) * gx, wy - (2.0 * fold) * gy, wz - (2.0 * fold) * gz
    return out
