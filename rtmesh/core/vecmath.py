"""Vectorised vector maths on arrays of 3-vectors.

All functions take arrays of shape ``(n, 3)`` (float64) and work row by row.  Directions
follow the convention used throughout rtmesh: ``wo`` and ``wi`` point *away* from the
surface, ``n`` is a unit normal.
"""

import numpy as np


def dot(a, b):
    """Row-wise dot product.

    Parameters
    ----------
    a, b : (n, 3) float

    Returns
    -------
    (n,) float
    """
    # The sum is always (x + y) + z, whatever the memory layout, so that a result does not
    # depend on how an array happens to be stored (a one-row batch is both C- and
    # F-contiguous; renders must be bit-identical for any chunking).  On component-major
    # input einsum accumulates the components in exactly that order without the (n, 3)
    # temporary of (a * b).sum(axis=1); on row-major input it uses an unrolled reduction
    # that rounds differently, so the explicit form is used there.
    if a.strides[0] == a.itemsize and b.strides[0] == b.itemsize:
        return np.einsum("ij,ij->i", a, b)
    return (a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1]) + a[:, 2] * b[:, 2]


def norm(a):
    """Row-wise Euclidean length of ``a`` (n, 3) -> (n,)."""
    return np.sqrt(dot(a, a))


def normalize(a, scale=None):
    """Unit vectors along the rows of ``a``.

    Rows of zero length stay zero instead of becoming NaN, so a degenerate input never
    poisons the image.

    Parameters
    ----------
    a : (n, 3) float
    scale : (n,) float, optional
        Factor for each result row, folded into the per-row multiplier (one pass over
        ``a`` instead of two); with ``scale = +-1`` (flipping) the result is exactly
        ``normalize(a) * scale[:, None]``.

    Returns
    -------
    (n, 3) float
    """
    length = norm(a)
    inv = 1.0 / np.where(length > 0.0, length, np.inf)
    if scale is not None:
        inv *= scale
    return a * inv[:, None]


def reflect(wo, n):
    """Mirror direction of ``wo`` about ``n``.

    Parameters
    ----------
    wo : (n, 3) float
        Unit directions pointing away from the surface.
    n : (n, 3) float
        Unit normals.

    Returns
    -------
    (n, 3) float
        Unit reflected directions, pointing away from the surface: ``2 (wo.n) n - wo``.
    """
    return 2.0 * dot(wo, n)[:, None] * n - wo


def transmitted_cosine(cos_i, eta):
    """Cosine of the refracted angle by Snell's law, and where none exists.

    Parameters
    ----------
    cos_i : (n,) float
        Cosine of the incident angle, in [0, 1].
    eta : (n,) float
        Relative index of refraction ``eta_incident / eta_transmitted``.

    Returns
    -------
    cos_t : (n,) float
        Cosine of the transmitted angle (0 under total internal reflection).
    tir : (n,) bool
        True where ``sin_t = eta sin_i >= 1``: total internal reflection.
    """
    # the clamps keep rounding (|cos_i| a hair above 1) from producing NaN
    sin2_t = eta * eta * np.maximum(0.0, 1.0 - cos_i * cos_i)
    tir = sin2_t >= 1.0
    return np.sqrt(np.maximum(0.0, 1.0 - sin2_t)), tir


def refract(wo, n, eta):
    """Refracted direction by Snell's law, with a total-internal-reflection mask.

    Parameters
    ----------
    wo : (n, 3) float
        Unit directions pointing away from the surface, on the same side as ``n``.
    n : (n, 3) float
        Unit normals on the side of ``wo`` (the incident side).
    eta : (n,) float or float
        Relative index of refraction ``eta_incident / eta_transmitted``.

    Returns
    -------
    wt : (n, 3) float
        Unit transmitted directions pointing into the far side (zero where ``tir``).
    tir : (n,) bool
        True where the ray is totally internally reflected (no transmitted direction).
    """
    cos_i = dot(wo, n)
    eta = np.broadcast_to(np.asarray(eta, dtype=np.float64), cos_i.shape)
    cos_t, tir = transmitted_cosine(cos_i, eta)
    wt = -eta[:, None] * wo + (eta * cos_i - cos_t)[:, None] * n
    wt[tir] = 0.0
    return wt, tir


def fresnel_schlick(cos_i, eta):
    """Schlick's approximation of the unpolarised dielectric reflectance.

    Parameters
    ----------
    cos_i : (n,) float
        Cosine of the incident angle, in [0, 1].
    eta : (n,) float or float
        Relative index of refraction ``eta_incident / eta_transmitted``.

    Returns
    -------
    (n,) float
        Reflectance in [0, 1]; 1 under total internal reflection.

    Notes
    -----
    Going from the denser medium the cosine in Schlick's formula must be the one on the
    less dense side (the transmitted cosine), otherwise the curve does not reach 1 at the
    critical angle.
    """
    cos_i = np.asarray(cos_i, dtype=np.float64)
    eta = np.broadcast_to(np.asarray(eta, dtype=np.float64), cos_i.shape)
    r0 = ((1.0 - eta) / (1.0 + eta)) ** 2
    cos_t, tir = transmitted_cosine(cos_i, eta)
    cos = np.where(eta > 1.0, cos_t, cos_i)
    f = r0 + (1.0 - r0) * (1.0 - cos) ** 5
    # at eta == 1 there is no interface, but Schlick's curve still rises toward grazing
    # angles: an index-matched object must be invisible, so reflect nothing there
    f = np.where(eta == 1.0, 0.0, f)
    return np.where(tir, 1.0, f)


def fresnel_dielectric(cos_i, eta):
    """Exact unpolarised Fresnel reflectance of a smooth dielectric interface.

    Parameters
    ----------
    cos_i : (n,) float
        Cosine of the incident angle, in [0, 1].
    eta : (n,) float or float
        Relative index of refraction ``eta_incident / eta_transmitted``.

    Returns
    -------
    (n,) float
        Mean of the s- and p-polarised reflectances; 1 under total internal reflection.
    """
    cos_i = np.asarray(cos_i, dtype=np.float64)
    eta = np.broadcast_to(np.asarray(eta, dtype=np.float64), cos_i.shape)
    cos_t, tir = transmitted_cosine(cos_i, eta)
    # with n_i = eta * n_t: r_s = (eta cos_i - cos_t) / (eta cos_i + cos_t), likewise r_p
    with np.errstate(divide="ignore", invalid="ignore"):
        r_s = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
        r_p = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    f = 0.5 * (r_s * r_s + r_p * r_p)
    return np.where(tir, 1.0, np.nan_to_num(f, nan=1.0))


def orthonormal_basis(n):
    """Two unit tangents completing each unit normal to a right-handed frame.

    Uses the branchless construction of Duff et al. (2017), which stays accurate for
    normals near -z where the classic Frisvad method breaks down.

    Parameters
    ----------
    n : (n, 3) float
        Unit normals.

    Returns
    -------
    t, b : (n, 3) float
        Unit tangents with ``t x b = n``.
    """
    sign = np.where(n[:, 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + n[:, 2])
    b_ = n[:, 0] * n[:, 1] * a
    t = np.stack([1.0 + sign * n[:, 0] ** 2 * a, sign * b_, -sign * n[:, 0]], axis=1)
    b = np.stack([b_, sign + n[:, 1] ** 2 * a, -n[:, 1]], axis=1)
    return t, b
