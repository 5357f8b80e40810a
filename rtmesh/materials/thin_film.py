"""Thin-film interference (KHR_materials_iridescence): the Fresnel reflectance of a base
coated with a film a few hundred nanometres thick, after Belcour and Barla (2017, "A
Practical Extension to Microfacet Theory for the Modeling of Varying Iridescence"), in the
form the extension's specification and the Khronos sample viewer give it.

Model
-----
Light crossing the film (index ``eta2``, thickness ``d`` in nm) from outside (index 1)
reflects off the film (``R12``, Schlick at ``cos theta1``) and off the base (``R23``, Schlick
at the refracted ``cos theta2`` toward the base's index, found from its ``F0``); the
reflections interfere with the optical path difference ``OPD = 2 eta2 d cos theta2`` and the
phase shifts of reflections off denser media (pi).  The Airy sum is kept to its first two
orders, and each order's spectral integral against the CIE XYZ matching functions is a
Gaussian fit in Fourier space (Belcour and Barla's supplemental), converted to linear
Rec. 709 RGB::

    I = R12 + T121^2 R23 / (1 - R12 R23)
        + sum_{m=1,2} (r123^m) (Rs - T121) 2 S(m OPD, m phi)

with ``S`` the fitted sensitivity.  The film's index fades to the outside's over its first
0.03 nm (the specification's smoothstep, which keeps the function continuous at 0); a film of
thickness 0 is no film (the caller then leaves the base's Fresnel term as it is, as the
specification says).  The result is clamped to [0, 1]: the two-order sum and
the fit can overshoot by a few per cent where the interference is strongest, and a Fresnel
term above 1 would create energy.
"""

import math

from rtmesh.core.compiled import row
from rtmesh.materials import lobes

# XYZ -> linear Rec. 709 (sRGB primaries, D65)
_XYZ_TO_RGB = ((3.2404542, -1.5371385, -0.4985314),
               (-0.9692660, 1.8760108, 0.0415560),
               (0.0556434, -0.2040259, 1.0572252))
# F0 of the base is clamped below 1 before it becomes an index (F0 = 1 is an infinite index)
_MAX_F0 = 0.9999


@row
def _sensitivity(opd, shift):
    """The fitted XYZ sensitivity of one Airy order as linear RGB: ``opd`` in nm, ``shift``
    the phase in radians."""
    phase = 2.0 * math.pi * opd * 1.0e-9
    p2 = phase * phase
    x = 5.4856e-13 * math.sqrt(2.0 * math.pi * 4.3278e9) * math.cos(1.6810e6 * phase + shift) * math.exp(-4.3278e9 * p2)
    y = 4.4201e-13 * math.sqrt(2.0 * math.pi * 9.3046e9) * math.cos(1.7953e6 * phase + shift) * math.exp(-9.3046e9 * p2)
    z = 5.2481e-13 * math.sqrt(2.0 * math.pi * 6.6121e9) * math.cos(2.2084e6 * phase + shift) * math.exp(-6.6121e9 * p2)
    x += 9.7470e-14 * math.sqrt(2.0 * math.pi * 4.5282e9) * math.cos(2.2399e6 * phase + shift) * math.exp(-4.5282e9 * p2)
    x, y, z = x / 1.0685e-7, y / 1.0685e-7, z / 1.0685e-7
    m = _XYZ_TO_RGB
    return (m[0][0] * x + m[0][1] * y + m[0][2] * z, m[1][0] * x + m[1][1] * y + m[1][2] * z,
            m[2][0] * x + m[2][1] * y + m[2][2] * z)


@row
def _channel(r12, t121, phi21, cos2, eta2, f0, opd):
    """The Airy sum's terms of one channel: ``(C0, C1, C2 coefficients, phi)``."""
    f0 = min(max(f0, 0.0), _MAX_F0)
    s = math.sqrt(f0)
    base_ior = (1.0 + s) / (1.0 - s)
    q = (base_ior - eta2) / (base_ior + eta2)
    r23 = lobes.schlick(q * q, cos2)
    phi23 = math.pi if base_ior < eta2 else 0.0
    r123 = min(max(r12 * r23, 1e-5), 0.9999)
    root = math.sqrt(r123)
    rs = t121 * t121 * r23 / (1.0 - r123)
    return r12 + rs, (rs - t121) * root, (rs - t121) * root * root, phi21 + phi23


@row
def fresnel(eta2, cos1, thickness, f0r, f0g, f0b):
    """Reflectance (r, g, b) of a base of normal-incidence reflectance ``f0`` under a thin film.

    Parameters
    ----------
    eta2 : float
        The film's index of refraction (``iridescenceIor``), the outside's being 1.
    cos1 : float
        Cosine of the incident direction with the (micro)surface normal, in [0, 1].
    thickness : float
        Film thickness in nanometres.
    f0r, f0g, f0b : float
        The base's Fresnel reflectance at normal incidence (dielectric F0, or a metal's base colour).

    Returns
    -------
    (float, float, float)
        In [0, 1].
    """
    # the film's index fades into the outside medium's as the film vanishes (smoothstep over
    # 0.03 nm, as the specification)
    x = min(max(thickness / 0.03, 0.0), 1.0)
    eta = 1.0 + (eta2 - 1.0) * (x * x * (3.0 - 2.0 * x))
    sin2 = (1.0 - cos1 * cos1) / (eta * eta)
    cos2sq = 1.0 - sin2
    if cos2sq < 0.0:
        return 1.0, 1.0, 1.0  # total internal reflection inside the film
    cos2 = math.sqrt(cos2sq)
    q = (eta - 1.0) / (eta + 1.0)
    r12 = lobes.schlick(q * q, cos1)
    t121 = 1.0 - r12
    phi21 = 0.0 if eta < 1.0 else math.pi  # pi - phi12, phi12 = pi for a film less dense than outside
    opd = 2.0 * eta * thickness * cos2
    out = [0.0, 0.0, 0.0]
    for c in range(3):
        f0 = f0r if c == 0 else (f0g if c == 1 else f0b)
        c0, c1, c2, phi = _channel(r12, t121, phi21, cos2, eta, f0, opd)
        s1 = _sensitivity(opd, phi)
        s2 = _sensitivity(2.0 * opd, 2.0 * phi)
        out[c] = min(max(c0 + c1 * 2.0 * s1[c] + c2 * 2.0 * s2[c], 0.0), 1.0)
    return out[0], out[1], out[2]
