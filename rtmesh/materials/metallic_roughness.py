"""The glTF 2.0 metallic-roughness BRDF in compiled code: evaluation, density and sampling,
batched over hits with per-hit parameters (they come from textures, per texel).

Model
-----
The BRDF of the glTF 2.0 specification, Appendix B ("BRDF Implementation"), for a base
colour ``b`` (linear RGB), a metalness ``m`` and ``alpha = roughness^2``::

    D(h)  = alpha^2 / (pi ((n.h)^2 (alpha^2 - 1) + 1)^2)                  Trowbridge-Reitz (GGX)
    V     = 0.5 / (NL sqrt(NV^2 (1 - alpha^2) + alpha^2)
                   + NV sqrt(NL^2 (1 - alpha^2) + alpha^2))               Smith height-correlated,
                                                                          = G2 / (4 NL NV)
    F_d   = 0.04 + 0.96 (1 - |V.H|)^5                                      Schlick, dielectric
    F_m   = b + (1 - b) (1 - |V.H|)^5                                      Schlick, metal
    dielectric = (1 - F_d) b / pi + F_d V D
    metal      = F_m V D
    f     = (1 - m) dielectric + m metal                                   mix(dielectric, metal, m)

with ``h = normalize(wo + wi)``, ``NL = n.wi``, ``NV = n.wo``, ``V.H = wo.h``.  The model is
physically normalised: the diffuse term carries the ``1/pi`` (rtmesh's Blinn-Phong does not),
so a white Lambertian surface under unit irradiance reflects radiance ``1/pi``.

Sampling
--------
A mixture of two lobes, chosen by the first random number:

- the GGX lobe, through the distribution of visible normals (Heitz 2018, "Sampling the GGX
  Distribution of Visible Normals", JCGT 7(4)): in the frame with ``ns`` as z, ``wo`` is
  stretched by ``alpha``, a point is drawn on the half-disk-warped unit disk seen from it
  and projected onto the hemisphere, the normal is unstretched, and ``wo`` is reflected
  about it.  The density of the reflected direction is
  ``G1(wo) D(h) / (4 NV) = D(h) / (2 (NV + sqrt(NV^2 (1 - alpha^2) + alpha^2)))``
  (visible-normal density ``G1(wo) max(0, wo.h) D(h) / NV`` times the Jacobian
  ``1 / (4 wo.h)`` of the reflection);
- a cosine-weighted lobe for the diffuse term (``NL / pi``; Shirley-Chiu's concentric
  disk lifted to the hemisphere, as :func:`rtmesh.sampling.warps.square_to_cosine_hemisphere`).

The GGX lobe is chosen with probability ``p_spec`` (:func:`specular_probability`), a function
of ``(wo, ns, base, metallic)`` only, so that :func:`pdf` can form the same mixture::

    pdf(wi) = p_spec G1(wo) D(h) / (4 NV) + (1 - p_spec) NL / pi

Reflected directions below the shading horizon (grazing ``wo``, rough surfaces) are failed
samples: weight 0 and pdf 0, the energy the single-scattering model does not reflect.

Energy
------
Single-scattering GGX loses the light that would leave the microsurface after more than one
bounce between microfacets.  Directional albedo ``int f cos dwi`` at normal incidence, base
colour 1 (Gauss-Legendre quadrature; the metal's checked in the tests against an independent
Monte Carlo of ``D G2`` with normals drawn from ``D (n.h)``):

=========  ==========  ==========
roughness  metallic 1  metallic 0
=========  ==========  ==========
0.1        0.99990     0.99992
0.3        0.99067     0.99955
0.7        0.69775     0.98788
1.0        0.30685     0.97223
=========  ==========  ==========

At roughness 1, single-scattering GGX reflects ``1 - ln 2 = 0.307`` of the incident light at
normal incidence (``D = 1/pi`` and ``G2 = 2 NL / (1 + NL)`` there); at roughness 0.7 it
reflects 0.698, at 0.3 0.991, at 0.1 0.9999.  Away from normal incidence the metal's albedo
changes (roughness 1: 0.45 at 60 degrees, 0.93 at 89; roughness 0.3: 0.89 at 85) and stays
below 1 at every angle: its sample weight ``F G2(wo, wi) / G1(wo)`` is at most 1.  Half of
the visible-normal samples of roughness 1 at normal incidence are reflected below the
horizon (failed samples, part of the lost energy).

The white dielectric (metallic 0) reflects less than 1 at normal incidence, but not at every
angle: the diffuse term is weighted by ``1 - F_d(V.H)`` per direction, not by one minus the
specular lobe's albedo, so at grazing views, where the specular lobe reflects most of the
light (``V.H`` small near the mirror direction) while ``V.H`` stays large toward most other
directions, the sum exceeds 1.  Its albedo is 1.025 at 60 degrees for roughness 0.1 and 0.3,
1.35 (0.1) and 1.22 (0.3) at 80 degrees, 1.57 at 85 degrees (0.1); 1.0025 at 70 degrees
(0.7); 1.010 at 89 degrees (1.0).  This is the specification's model, kept as it is.

Conventions
-----------
- ``wo``: unit direction toward the viewer (away from the surface); ``wi``: unit direction
  toward the light (or the sampled direction), also away from the surface;
- ``ns``: unit shading normal on ``wo``'s side; everything is 0 where ``ns.wo <= 0`` or
  ``ns.wi <= 0`` (the BRDF is a reflection-only model);
- :func:`evaluate` gives ``f(wo, wi) max(0, ns.wi)``, the factor of incident radiance (or of
  a light's ``intensity / distance^2``), per RGB channel;
- the *weight* of a sample is ``f(wo, wi) (ns.wi) / pdf(wi)``, the throughput factor of the
  followed ray; :func:`pdf` and the pdf :func:`sample` returns are densities per steradian;
- ``alpha = roughness^2`` (glTF's perceptual roughness squared), floored at
  :data:`MIN_ALPHA` (:func:`alpha_from_roughness`);
- vectors are (k, 3) float64 arrays of any memory layout (C, Fortran, strided, broadcast),
  per-hit scalars (k,).

The scalar ``@row`` helpers (:func:`brdf_cos_row`, :func:`pdf_row`, :func:`brdf_cos_pdf_row`,
:func:`sample_row`) are what other compiled code calls per hit; the batched kernels are thin
loops over them.
"""

import functools
import math
import threading

import numpy as np
from numba import types

from rtmesh.core.compiled import fix_signatures, kernel, row
from rtmesh.core.row_vectors import dot3, normalized3, tangent_frame
from rtmesh.materials.lobes import LUMA_B, LUMA_G, LUMA_R

# Smallest alpha (= roughness^2) the model is evaluated with.  As alpha -> 0 GGX becomes a
# delta: the peak D = 1 / (pi alpha^2) grows without bound, and D's denominator
# (n.h)^2 (alpha^2 - 1) + 1 is about alpha^2 near the peak while (n.h)^2 carries an absolute
# rounding error of ~1e-16, so D and the pdf of sampled directions lose relative precision
# as 1e-16 / alpha^2 (and n.h of the sampled h, 1 - O(alpha^2), rounds to 1 below alpha
# ~1e-8: every sample then gets the peak density).  At 1e-3 (roughness ~0.032) that error
# is ~1e-10 and the peak 3.2e5; such a lobe is 2e-3 rad wide, already a mirror at the
# resolution of images.
MIN_ALPHA = 1e-3

# Luminance (lobes.LUMA_*) weighs the two lobes of an RGB BRDF with one number; the weights
# sum to 1, so luminance(b + (1 - b) w) = L + (1 - L) w.

# Bounds of the probability of the GGX lobe when both lobes reflect something.  A lobe drawn
# with probability p gets weights up to 1 / p times its own f cos / density; where the
# luminance estimate misjudges a lobe (a saturated base colour; Fresnel at n.wo stands for
# Fresnel at V.H), 0.1 caps that factor at 10 instead of letting it become fireflies.
P_SPEC_MIN, P_SPEC_MAX = 0.1, 0.9


# ------------------------------------------------------------------ parameters
def alpha_from_roughness(roughness):
    """GGX ``alpha`` of glTF roughness: ``roughness^2``, at least :data:`MIN_ALPHA`.

    Parameters
    ----------
    roughness : (k,) float or float
        glTF ``roughnessFactor`` times the texture's green channel, in [0, 1].

    Returns
    -------
    (k,) float64 or float64
        ``max(roughness^2, MIN_ALPHA)`` (dimensionless).
    """
    return np.maximum(np.square(np.asarray(roughness, dtype=np.float64)), MIN_ALPHA)


@row
def alpha_from_roughness_row(roughness):
    """:func:`alpha_from_roughness` of one number, for compiled code."""
    return max(roughness * roughness, MIN_ALPHA)


# ------------------------------------------------------------------ terms of the model
@row
def schlick_weight(cos):
    """``(1 - cos)^5``, the angular factor of Schlick's Fresnel, with ``cos`` clamped to
    [0, 1] (rounding can put a cosine of unit vectors a hair outside)."""
    m = 1.0 - min(max(cos, 0.0), 1.0)
    # by multiplications: a float power is a libm call that LLVM cannot vectorise
    m2 = m * m
    return m2 * m2 * m


@row
def ggx_distribution(nh, a2):
    """Trowbridge-Reitz (GGX) normal distribution ``D(h)`` per steradian of ``h``, for
    ``nh = n.h > 0`` and ``a2 = alpha^2``; ``int D(h) (n.h) dh = 1`` over the hemisphere."""
    # the specification's form; near the peak the denominator is ~a2 and (n.h)^2 rounds by
    # ~1e-16 absolute, which MIN_ALPHA keeps below 1e-10 relative
    d = nh * nh * (a2 - 1.0) + 1.0
    return a2 / (math.pi * d * d)


@row
def smith_root(cos, a2):
    """``sqrt(cos^2 (1 - a2) + a2)`` = ``cos sqrt(1 + a2 tan^2)``: Smith's ``Lambda`` of GGX
    is ``(smith_root / cos - 1) / 2``."""
    return math.sqrt(cos * cos * (1.0 - a2) + a2)


@row
def smith_visibility(nl, nv, a2):
    """Height-correlated Smith visibility ``V = G2(wo, wi) / (4 NL NV)`` of GGX, for
    ``nl, nv > 0``: the masking-shadowing term with the ``1 / (4 NL NV)`` of the microfacet
    BRDF folded in, so ``D V`` is the specular BRDF (per steradian) before Fresnel."""
    return 0.5 / (nl * smith_root(nv, a2) + nv * smith_root(nl, a2))


@row
def specular_probability(nv, b0, b1, b2, metallic, transmission):
    """Probability ``p_spec`` with which :func:`sample_row` draws from the GGX lobe.

    ``S / (S + W)`` with ``S`` the luminance of the Schlick Fresnel at ``n.wo`` (the mix of
    ``F_d`` and ``F_m``) and ``W`` the diffuse weight ``(1 - metallic) (1 - transmission) (1 - F_d) luminance(base)``, clamped to
    [:data:`P_SPEC_MIN`, :data:`P_SPEC_MAX`]; 1 where the diffuse weight is 0 (metals, black
    base colour), so that no sample is spent on a lobe that reflects nothing.  Fresnel at the
    viewing angle stands for the lobe's albedo, which has no closed form; any value in (0, 1]
    keeps the mixture unbiased, only the variance depends on it.

    Parameters
    ----------
    nv : float
        ``ns.wo`` (> 0).
    b0, b1, b2 : float
        Linear base colour.
    metallic : float
        In [0, 1].
    transmission : float
        In [0, 1]: the part of the dielectric's diffuse term that is transmitted instead.

    Returns
    -------
    float
        In [P_SPEC_MIN, 1].
    """
    w = schlick_weight(nv)
    f_d = 0.04 + 0.96 * w
    lum = (LUMA_R * b0 + LUMA_G * b1) + LUMA_B * b2
    specular = (1.0 - metallic) * f_d + metallic * (lum + (1.0 - lum) * w)
    diffuse = (1.0 - metallic) * (1.0 - transmission) * (1.0 - f_d) * lum
    if not diffuse > 0.0:
        return 1.0
    return min(max(specular / (specular + diffuse), P_SPEC_MIN), P_SPEC_MAX)


@row
def half_vector_cosines(ox, oy, oz, nx, ny, nz, wx, wy, wz):
    """``(n.wo, n.wi, n.h, |wo.h|)`` with ``h = normalize(wo + wi)``; the last two are
    meaningful where both of the first two are > 0 (then ``wo + wi != 0``)."""
    nv = dot3(nx, ny, nz, ox, oy, oz)
    nl = dot3(nx, ny, nz, wx, wy, wz)
    hx, hy, hz = normalized3(ox + wx, oy + wy, oz + wz, 1.0)
    return nv, nl, dot3(nx, ny, nz, hx, hy, hz), abs(dot3(ox, oy, oz, hx, hy, hz))


@row
def brdf_cos_from_cosines(nv, nl, nh, vh, b0, b1, b2, metallic, alpha, transmission):
    """``f max(0, NL)`` per channel from the cosines of :func:`half_vector_cosines`; 0 where
    ``nv <= 0`` or ``nl <= 0``."""
    if not ((nl > 0.0) & (nv > 0.0)):
        return 0.0, 0.0, 0.0
    a = max(alpha, MIN_ALPHA)
    a2 = a * a
    dv = ggx_distribution(nh, a2) * smith_visibility(nl, nv, a2)
    w = schlick_weight(vh)
    f_d = 0.04 + 0.96 * w
    # the channel-independent parts of (1 - m) dielectric + m metal
    dielectric = 1.0 - metallic
    # KHR_materials_transmission: that part of the diffuse base is transmitted instead (a
    # delta lobe of the secondary-ray stage, not part of this BRDF)
    diffuse = dielectric * (1.0 - transmission) * (1.0 - f_d) / math.pi
    specular = dielectric * f_d * dv
    metal = metallic * dv
    return ((diffuse * b0 + specular + metal * (b0 + (1.0 - b0) * w)) * nl,
            (diffuse * b1 + specular + metal * (b1 + (1.0 - b1) * w)) * nl,
            (diffuse * b2 + specular + metal * (b2 + (1.0 - b2) * w)) * nl)


@row
def pdf_from_cosines(nv, nl, nh, p_spec, alpha):
    """Mixture density per steradian from the cosines of :func:`half_vector_cosines` and
    :func:`specular_probability`; 0 where ``nv <= 0`` or ``nl <= 0``."""
    if not ((nl > 0.0) & (nv > 0.0)):
        return 0.0
    a = max(alpha, MIN_ALPHA)
    a2 = a * a
    # G1(wo) D / (4 NV) with G1(wo) = 2 NV / (NV + smith_root(NV)): the NV cancels, so
    # grazing views divide by nothing small
    specular = ggx_distribution(nh, a2) / (2.0 * (nv + smith_root(nv, a2)))
    return p_spec * specular + (1.0 - p_spec) * nl / math.pi


# ------------------------------------------------------------------ one hit
@row
def brdf_cos_row(ox, oy, oz, nx, ny, nz, wx, wy, wz, b0, b1, b2, metallic, alpha, transmission):
    """``f(wo, wi) max(0, ns.wi)`` of one hit, three channels.

    Parameters
    ----------
    ox, oy, oz : float
        Unit ``wo`` (toward the viewer).
    nx, ny, nz : float
        Unit shading normal on ``wo``'s side.
    wx, wy, wz : float
        Unit ``wi`` (toward the light).
    b0, b1, b2 : float
        Linear base colour.
    metallic, alpha : float
        Metalness in [0, 1]; ``roughness^2`` (values below :data:`MIN_ALPHA` count as it).
    transmission : float
        KHR_materials_transmission's factor in [0, 1]: the part of the dielectric's diffuse
        term that is transmitted (0 for opaque materials).

    Returns
    -------
    (float, float, float)
        Per steradian; 0 where ``ns.wo <= 0`` or ``ns.wi <= 0``.
    """
    nv, nl, nh, vh = half_vector_cosines(ox, oy, oz, nx, ny, nz, wx, wy, wz)
    return brdf_cos_from_cosines(nv, nl, nh, vh, b0, b1, b2, metallic, alpha, transmission)


@row
def pdf_row(ox, oy, oz, nx, ny, nz, wx, wy, wz, b0, b1, b2, metallic, alpha, transmission):
    """Solid-angle density with which :func:`sample_row` draws ``wi`` (arguments as
    :func:`brdf_cos_row`); 0 where ``ns.wo <= 0`` or ``ns.wi <= 0``."""
    nv, nl, nh, vh = half_vector_cosines(ox, oy, oz, nx, ny, nz, wx, wy, wz)
    if not ((nl > 0.0) & (nv > 0.0)):
        return 0.0
    return pdf_from_cosines(nv, nl, nh, specular_probability(nv, b0, b1, b2, metallic, transmission), alpha)


@row
def brdf_cos_pdf_row(ox, oy, oz, nx, ny, nz, wx, wy, wz, b0, b1, b2, metallic, alpha, transmission):
    """:func:`brdf_cos_row` and :func:`pdf_row` with one half vector (for multiple importance
    sampling of light samples): ``(f0, f1, f2, pdf)``."""
    nv, nl, nh, vh = half_vector_cosines(ox, oy, oz, nx, ny, nz, wx, wy, wz)
    if not ((nl > 0.0) & (nv > 0.0)):
        return 0.0, 0.0, 0.0, 0.0
    f0, f1, f2 = brdf_cos_from_cosines(nv, nl, nh, vh, b0, b1, b2, metallic, alpha, transmission)
    return f0, f1, f2, pdf_from_cosines(nv, nl, nh, specular_probability(nv, b0, b1, b2, metallic, transmission), alpha)


@row
def sample_ggx_visible_normal(vx, vy, vz, alpha, u1, u2):
    """A GGX microfacet normal drawn from the normals visible from ``v`` (Heitz 2018, listing 1).

    Parameters
    ----------
    vx, vy, vz : float
        Unit direction toward the viewer in the local frame (z = the normal), ``vz > 0``.
    alpha : float
        GGX alpha (isotropic), >= :data:`MIN_ALPHA`.
    u1, u2 : float
        Uniform numbers in [0, 1).

    Returns
    -------
    (float, float, float)
        Unit normal ``h`` (local frame, ``h.z >= 0``), density ``G1(v) max(0, v.h) D(h) / v.z``
        per steradian.
    """
    return sample_ggx_visible_normal_anisotropic(vx, vy, vz, alpha, alpha, u1, u2)


@row
def sample_ggx_visible_normal_anisotropic(vx, vy, vz, alpha_x, alpha_y, u1, u2):
    """:func:`sample_ggx_visible_normal` of an anisotropic GGX, widths ``alpha_x`` along the
    local x axis and ``alpha_y`` along y (Heitz 2018 stretches by both; with equal widths the
    arithmetic is the isotropic one, bit for bit)."""
    # the view in the stretched space, where the GGX microsurface is the unit hemisphere
    sx, sy, sz = normalized3(alpha_x * vx, alpha_y * vy, vz, 1.0)
    # a frame around it; at normal incidence any tangent does
    lensq = sx * sx + sy * sy
    if lensq > 0.0:
        inv = 1.0 / math.sqrt(lensq)
        t1x, t1y = -sy * inv, sx * inv
    else:
        t1x, t1y = 1.0, 0.0
    # T2 = cross(S, T1) with T1.z = 0
    t2x, t2y, t2z = -sz * t1y, sz * t1x, sx * t1y - sy * t1x
    # a uniform point on the unit disk (polar: the half-disk warp below needs no continuity
    # across sectors), then the half of the disk hidden from the view squeezed away
    r = math.sqrt(u1)
    phi = 2.0 * math.pi * u2
    p1, p2 = r * math.cos(phi), r * math.sin(phi)
    s = 0.5 * (1.0 + sz)
    p2 = (1.0 - s) * math.sqrt(1.0 - p1 * p1) + s * p2
    # lifted onto the hemisphere, then back from the stretched space
    pz = math.sqrt(max(0.0, 1.0 - p1 * p1 - p2 * p2))
    mx = p1 * t1x + p2 * t2x + pz * sx
    my = p1 * t1y + p2 * t2y + pz * sy
    mz = p2 * t2z + pz * sz
    return normalized3(alpha_x * mx, alpha_y * my, max(0.0, mz), 1.0)


@row
def square_to_cosine_hemisphere_row(u1, u2):
    """Cosine-weighted unit direction around +z, density ``z / pi``: the concentric map of
    :func:`rtmesh.sampling.warps.square_to_cosine_hemisphere`, for one point."""
    a = 2.0 * u1 - 1.0
    b = 2.0 * u2 - 1.0
    if (a == 0.0) & (b == 0.0):
        return 0.0, 0.0, 1.0
    if abs(a) > abs(b):
        r, phi = a, (math.pi / 4.0) * (b / a)
    else:
        r, phi = b, (math.pi / 2.0) - (math.pi / 4.0) * (a / b)
    x, y = r * math.cos(phi), r * math.sin(phi)
    return x, y, math.sqrt(max(0.0, 1.0 - (x * x + y * y)))


@row
def sample_row(ox, oy, oz, nx, ny, nz, u0, u1, u2, b0, b1, b2, metallic, alpha, transmission):
    """Draw ``wi`` for one hit from the mixture of the GGX visible-normal lobe and the
    cosine lobe (see the module notes).

    Parameters
    ----------
    ox, oy, oz, nx, ny, nz, b0, b1, b2, metallic, alpha, transmission : float
        As :func:`brdf_cos_row`.
    u0, u1, u2 : float
        Uniform numbers in [0, 1): ``u0`` chooses the lobe, ``u1, u2`` the direction in it.

    Returns
    -------
    (wx, wy, wz, g0, g1, g2, pdf) : 7 floats
        Unit ``wi``; weight ``f (ns.wi) / pdf`` per channel; the density per steradian,
        exactly :func:`pdf_row` of ``wi``.  A failed sample (``ns.wi <= 0``, or ``ns.wo <= 0``,
        when ``wi`` is the mirror direction of ``wo``) has weight 0 and pdf 0.
    """
    nv = dot3(nx, ny, nz, ox, oy, oz)
    if not nv > 0.0:
        # viewed from below the shading horizon: the mirror direction, itself below
        return (2.0 * nv * nx - ox, 2.0 * nv * ny - oy, 2.0 * nv * nz - oz, 0.0, 0.0, 0.0, 0.0)
    a = max(alpha, MIN_ALPHA)
    tx, ty, tz, sx, sy, sz = tangent_frame(nx, ny, nz)
    p_spec = specular_probability(nv, b0, b1, b2, metallic, transmission)
    if u0 < p_spec:
        vx, vy = dot3(tx, ty, tz, ox, oy, oz), dot3(sx, sy, sz, ox, oy, oz)
        hx, hy, hz = sample_ggx_visible_normal(vx, vy, nv, a, u1, u2)
        c = 2.0 * dot3(vx, vy, nv, hx, hy, hz)
        lx, ly, lz = c * hx - vx, c * hy - vy, c * hz - nv
    else:
        lx, ly, lz = square_to_cosine_hemisphere_row(u1, u2)
    wx = (lx * tx + ly * sx) + lz * nx
    wy = (lx * ty + ly * sy) + lz * ny
    wz = (lx * tz + ly * sz) + lz * nz
    # weight and density from the world direction, through the rows of evaluate and pdf, so
    # that the three agree to the last bit
    nv, nl, nh, vh = half_vector_cosines(ox, oy, oz, nx, ny, nz, wx, wy, wz)
    if not nl > 0.0:
        return wx, wy, wz, 0.0, 0.0, 0.0, 0.0
    f0, f1, f2 = brdf_cos_from_cosines(nv, nl, nh, vh, b0, b1, b2, metallic, a, transmission)
    density = pdf_from_cosines(nv, nl, nh, p_spec, a)
    return wx, wy, wz, f0 / density, f1 / density, f2 / density, density


# ------------------------------------------------------------------ batches
@kernel
def brdf_cos_rows(wo, ns, wi, base, metallic, alpha, transmission):
    """:func:`brdf_cos_row` of every row, (k, 3) (see :func:`evaluate`)."""
    k = len(wo)
    out = np.empty((3, k))
    for i in range(k):
        out[0, i], out[1, i], out[2, i] = brdf_cos_row(
            wo[i, 0], wo[i, 1], wo[i, 2], ns[i, 0], ns[i, 1], ns[i, 2], wi[i, 0], wi[i, 1], wi[i, 2],
            base[i, 0], base[i, 1], base[i, 2], metallic[i], alpha[i], transmission[i])
    return out.T


@kernel
def pdf_rows(wo, ns, wi, base, metallic, alpha, transmission):
    """:func:`pdf_row` of every row, (k,) (see :func:`pdf`)."""
    k = len(wo)
    out = np.empty(k)
    for i in range(k):
        out[i] = pdf_row(wo[i, 0], wo[i, 1], wo[i, 2], ns[i, 0], ns[i, 1], ns[i, 2], wi[i, 0], wi[i, 1], wi[i, 2],
                         base[i, 0], base[i, 1], base[i, 2], metallic[i], alpha[i], transmission[i])
    return out


@kernel
def brdf_cos_pdf_rows(wo, ns, wi, base, metallic, alpha, transmission):
    """:func:`brdf_cos_pdf_row` of every row: ``((k, 3), (k,))`` (see :func:`evaluate_and_pdf`)."""
    k = len(wo)
    out = np.empty((3, k))
    density = np.empty(k)
    for i in range(k):
        out[0, i], out[1, i], out[2, i], density[i] = brdf_cos_pdf_row(
            wo[i, 0], wo[i, 1], wo[i, 2], ns[i, 0], ns[i, 1], ns[i, 2], wi[i, 0], wi[i, 1], wi[i, 2],
            base[i, 0], base[i, 1], base[i, 2], metallic[i], alpha[i], transmission[i])
    return out.T, density


@kernel
def sample_rows(wo, ns, u, base, metallic, alpha, transmission):
    """:func:`sample_row` of every row: ``(wi (k, 3), weight (k, 3), pdf (k,))`` (see :func:`sample`)."""
    k = len(wo)
    wi = np.empty((3, k))
    weight = np.empty((3, k))
    density = np.empty(k)
    for i in range(k):
        (wi[0, i], wi[1, i], wi[2, i], weight[0, i], weight[1, i], weight[2, i], density[i]) = sample_row(
            wo[i, 0], wo[i, 1], wo[i, 2], ns[i, 0], ns[i, 1], ns[i, 2], u[i, 0], u[i, 1], u[i, 2],
            base[i, 0], base[i, 1], base[i, 2], metallic[i], alpha[i], transmission[i])
    return wi.T, weight.T, density


# chunk threads may make the first call together; fixing a kernel's signatures twice would
# find its compilation already disabled
_FIXING = threading.Lock()


def _kernels():
    """The batch kernels (evaluate, pdf, sample, evaluate-and-pdf), each compiled once for
    read-only float64 arrays of any layout (C, Fortran, strided, broadcast), on first use
    rather than at import."""
    with _FIXING:
        return _fixed_kernels()


@functools.cache
def _fixed_kernels():
    vectors = types.Array(types.float64, 2, "A", readonly=True)
    values = types.Array(types.float64, 1, "A", readonly=True)
    signature = (vectors, vectors, vectors, vectors, values, values, values)
    for dispatcher in (brdf_cos_rows, pdf_rows, sample_rows, brdf_cos_pdf_rows):
        fix_signatures(dispatcher, [signature])
    return brdf_cos_rows, pdf_rows, sample_rows, brdf_cos_pdf_rows


def _batch(wo, ns, third, base, metallic, alpha, transmission):
    """The arguments as float64 arrays of the kernels' shapes (scalars and rows broadcast)."""
    wo = np.asarray(wo, dtype=np.float64)
    k = len(wo)
    vectors = tuple(np.broadcast_to(np.asarray(a, dtype=np.float64), (k, 3)) for a in (ns, third, base))
    values = tuple(np.broadcast_to(np.asarray(a, dtype=np.float64), (k,)) for a in (metallic, alpha, transmission))
    return (wo,) + vectors + values


def evaluate(wo, ns, wi, base, metallic, alpha, transmission=0.0):
    """``f(wo, wi) max(0, ns.wi)`` of the metallic-roughness BRDF.

    Parameters
    ----------
    wo : (k, 3) float
        Unit directions toward the viewer.
    ns : (k, 3) float
        Unit shading normals on ``wo``'s side.
    wi : (k, 3) float
        Unit directions toward the light.
    base : (k, 3) float
        Linear base colour.
    metallic : (k,) float
        Metalness in [0, 1].
    alpha : (k,) float
        GGX alpha, ``roughness^2`` (:func:`alpha_from_roughness`).
    transmission : (k,) float, optional
        KHR_materials_transmission's factor: the part of the dielectric diffuse term
        transmitted instead of reflected (default 0).

    Returns
    -------
    (k, 3) float64
        Per steradian (times the incident radiance: reflected radiance); 0 where
        ``ns.wo <= 0`` or ``ns.wi <= 0``.
    """
    return _kernels()[0](*_batch(wo, ns, wi, base, metallic, alpha, transmission))


def pdf(wo, ns, wi, base, metallic, alpha, transmission=0.0):
    """Solid-angle density with which :func:`sample` draws ``wi``.

    Parameters
    ----------
    wo, ns, wi, base, metallic, alpha
        As :func:`evaluate`.

    Returns
    -------
    (k,) float64
        Per steradian; 0 where ``ns.wo <= 0`` or ``ns.wi <= 0`` (its integral over the
        hemisphere is 1 minus the probability of a failed sample).
    """
    return _kernels()[1](*_batch(wo, ns, wi, base, metallic, alpha, transmission))


def evaluate_and_pdf(wo, ns, wi, base, metallic, alpha, transmission=0.0):
    """:func:`evaluate` and :func:`pdf` in one pass (one half vector per row): what a light
    sample weighed against BSDF sampling needs.

    Returns
    -------
    value : (k, 3) float64
    pdf : (k,) float64
    """
    return _kernels()[3](*_batch(wo, ns, wi, base, metallic, alpha, transmission))


def sample(wo, ns, u, base, metallic, alpha, transmission=0.0):
    """Directions drawn from the mixture of the GGX visible-normal and cosine lobes.

    Parameters
    ----------
    wo, ns, base, metallic, alpha
        As :func:`evaluate`.
    u : (k, 3) float
        Uniform numbers in [0, 1): column 0 chooses the lobe, columns 1-2 warp the direction.

    Returns
    -------
    wi : (k, 3) float64
        Unit directions (toward where the light comes from).
    weight : (k, 3) float64
        ``f(wo, wi) (ns.wi) / pdf``; 0 for a failed sample (``wi`` below the shading horizon).
    pdf : (k,) float64
        Density per steradian, equal to :func:`pdf` of ``wi``; 0 for a failed sample.
    """
    return _kernels()[2](*_batch(wo, ns, u, base, metallic, alpha, transmission))
