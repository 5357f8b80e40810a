"""The Blinn-Phong reflection model in compiled code: the highlight cosine, the diffuse and
specular terms of a material (optionally texture-tinted) under one light.
"""

import math

import numpy as np

from rtmesh.core.compiled import kernel, row
from rtmesh.core.row_vectors import dot3

# ------------------------------------------------------------------ Blinn-Phong
# The factor is kd max(0, n.wi) + ks max(0, n.h)^shininess (the highlight only where
# n.wi > 0 and the material has one).  The power is the one operation LLVM cannot vectorise
# (a call of libm's pow); the kernels raise the cosines in loops of their own, over the
# samples that have a highlight, so that everything else stays vectorised.  Every path
# raises them with this pow (raise_highlight), so the paths agree to the bit.


@row
def raise_highlight(cosine, exponent):
    """``cosine ** exponent`` with libm's pow, as every kernel raises a highlight cosine."""
    return cosine ** exponent


@kernel
def raise_highlights(cosine, exponent):
    """:func:`raise_highlight` of each element, in place (returns ``cosine``).

    Parameters
    ----------
    cosine, exponent : (h,) float64
        Highlight cosines and their materials' shininess.
    """
    for i in range(len(cosine)):
        cosine[i] = raise_highlight(cosine[i], exponent[i])
    return cosine


@row
def highlight_cosine(nx, ny, nz, ox, oy, oz, wx, wy, wz):
    """``max(0, n.h)`` with ``h`` the normalised ``wo + wi``; 0 where ``n.wi <= 0`` (light
    below the shading horizon) or ``wo + wi = 0``."""
    hx, hy, hz = ox + wx, oy + wy, oz + wz
    h_len = math.sqrt(dot3(hx, hy, hz, hx, hy, hz))
    cos_h = max(dot3(nx, ny, nz, hx, hy, hz) / h_len, 0.0)
    return cos_h if (dot3(nx, ny, nz, wx, wy, wz) > 0.0) & (h_len > 0.0) else 0.0


@row
def blinn_phong_row(kd0, kd1, kd2, ks0, ks1, ks2, cos_i, power):
    """``kd max(0, cos_i) + ks power`` per channel (``power``: the raised highlight cosine,
    0 without a highlight)."""
    lam = max(cos_i, 0.0)
    return kd0 * lam + ks0 * power, kd1 * lam + ks1 * power, kd2 * lam + ks2 * power


@kernel
def blinn_phong_factors(n, wo, wi, diffuse, specular, shininess):
    """Blinn-Phong factor per row; see :func:`rtmesh.materials.table.blinn_phong`.

    ``specular`` and ``shininess`` may be empty (``(0, 3)``, ``(0,)``): no highlight.
    """
    k = len(n)
    out = np.empty((3, k))
    highlight = len(specular) > 0
    for i in range(k):
        power, ks0, ks1, ks2 = 0.0, 0.0, 0.0, 0.0
        if highlight:
            power = raise_highlight(highlight_cosine(n[i, 0], n[i, 1], n[i, 2], wo[i, 0], wo[i, 1], wo[i, 2],
                                                     wi[i, 0], wi[i, 1], wi[i, 2]), shininess[i])
            ks0, ks1, ks2 = specular[i, 0], specular[i, 1], specular[i, 2]
        out[0, i], out[1, i], out[2, i] = blinn_phong_row(
            diffuse[i, 0], diffuse[i, 1], diffuse[i, 2], ks0, ks1, ks2,
            dot3(n[i, 0], n[i, 1], n[i, 2], wi[i, 0], wi[i, 1], wi[i, 2]), power)
    return out.T


@row
def material_colour(table, m, tint, r):
    """Material ``m``'s colour in ``table`` (three numbers), times row ``r``'s texture tint
    where there is one (an empty ``tint``: none)."""
    c0, c1, c2 = table[m, 0], table[m, 1], table[m, 2]
    if len(tint):
        return c0 * tint[r, 0], c1 * tint[r, 1], c2 * tint[r, 2]
    return c0, c1, c2


@row
def shade_row(r, m, cos_i, power, diffuse, tint_d, specular, tint_s):
    """Blinn-Phong factor of hit row ``r`` with material ``m`` (and the row's tints) from
    ``n . wi`` and the raised highlight cosine (0 without a highlight)."""
    d0, d1, d2 = material_colour(diffuse, m, tint_d, r)
    s0, s1, s2 = material_colour(specular, m, tint_s, r)
    return blinn_phong_row(d0, d1, d2, s0, s1, s2, cos_i, power)


@kernel
def surface_reflectance(ns, d, wi, lit, mat, diffuse, tint_d, specular, tint_s, exponent):
    """Blinn-Phong factor of hits toward unit directions ``wi``.

    Parameters
    ----------
    ns, d : (k, 3) float
        Shading normals and incoming ray directions.
    wi : (k, 3) float
        Directions toward the light.
    lit : (k,) bool
        Rows that get a highlight (elsewhere only the diffuse term is formed).
    mat : (k,) intp
    diffuse, specular : (M, 3) float64
        Material colours.
    tint_d, tint_s : (k, 3) float or (0, 3)
        Texture tints of the colours, or empty.
    exponent : (M,) float64
        Shininess, negative for materials without a highlight.

    Returns
    -------
    (k, 3) float64
    """
    k = len(ns)
    out = np.empty((3, k))
    for i in range(k):
        m = mat[i]
        power = 0.0
        if lit[i] and exponent[m] >= 0.0:
            power = highlight_cosine(ns[i, 0], ns[i, 1], ns[i, 2], -d[i, 0], -d[i, 1], -d[i, 2],
                                      wi[i, 0], wi[i, 1], wi[i, 2])
            power = raise_highlight(power, exponent[m])
        out[0, i], out[1, i], out[2, i] = shade_row(
            i, m, dot3(ns[i, 0], ns[i, 1], ns[i, 2], wi[i, 0], wi[i, 1], wi[i, 2]), power,
            diffuse, tint_d, specular, tint_s)
    return out.T


def blinn_phong(n, wo, wi, diffuse, specular, shininess):
    """Blinn-Phong reflected-radiance factor for unit incident light.

    Parameters
    ----------
    n : (k, 3) float
        Unit shading normals.
    wo, wi : (k, 3) float
        Unit directions toward the viewer and toward the light.
    diffuse : (k, 3) float
        kd.
    specular : (k, 3) float or None
        ks; None for no highlight.
    shininess : (k,) float or None
        Specular exponent.

    Returns
    -------
    (k, 3) float
        ``kd * max(0, n.wi) + ks * max(0, n.h)^shininess`` (the specular term only where
        ``n.wi > 0``), to be multiplied by the light's intensity / distance^2 or irradiance.
    """
    n = np.asarray(n, dtype=np.float64)
    wo, wi, diffuse = (np.broadcast_to(np.asarray(a, dtype=np.float64), n.shape) for a in (wo, wi, diffuse))
    if specular is None:
        # empty arrays tell the kernel there is no highlight
        specular, shininess = np.zeros((0, 3)), np.zeros(0)
    else:
        specular = np.broadcast_to(np.asarray(specular, dtype=np.float64), n.shape)
        shininess = np.broadcast_to(np.asarray(shininess, dtype=np.float64), n.shape[:1])
    return blinn_phong_factors(n, wo, wi, diffuse, specular, shininess)
