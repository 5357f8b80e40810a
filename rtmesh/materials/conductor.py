"""Conductors (metals): GGX microfacet reflection with Schlick's Fresnel toward a reflectance
``F0`` at normal incidence, and Kulla-Conty multiple-scattering compensation
(:mod:`rtmesh.materials.ggx_albedo`), so a white rough metal in a white furnace reflects 1
(single-scattering GGX alone reflects down to 0.31 at roughness 1).

Model
-----
``f_ss = D(h) G2(wo, wi) F(wo.h) / (4 mu_o mu_i)`` (isotropic GGX, ``alpha = r^2``),
plus ``f_ms`` of :mod:`~rtmesh.materials.ggx_albedo`.  Below roughness ~0.03 the lobe is a
perfect mirror (a delta lobe of weight ``F(mu_o)``).

Sampling: the visible-normal lobe with probability ``E(mu_o)`` (the single-scattering
albedo), the cosine lobe for ``f_ms`` otherwise; the density is the mixture.

Parameters: ``F0`` r, g, b, ``roughness``, ``compensate`` (1: add ``f_ms``, 0: single
scattering only, as Mitsuba's ``roughconductor``).
"""

import math

import numpy as np

from rtmesh.core.compiled import row
from rtmesh.materials import ggx_albedo, lobes
from rtmesh.materials.metallic_roughness import square_to_cosine_hemisphere_row
from rtmesh.materials.microfacet import SMOOTH_ALPHA, distribution, masking, masking_shadowing, sample_visible_normal

NAME = "conductor"
SLOTS = {"colour": 0}


def parameters(material):
    """``F0`` from the material's mirror colour (or its base colour when it has no mirror
    colour), its roughness clamped to [0, 1], compensation on."""
    f0 = material.mirror if (np.asarray(material.mirror) > 0).any() else material.base_color
    return [float(c) for c in f0] + [min(max(float(material.roughness), 0.0), 1.0), 1.0]


@row
def _compensation(table, oz, wz, r, f0):
    """``f_ms wi.z`` of one channel, and the probability of the single-scattering lobe."""
    e_o = ggx_albedo.albedo(table[0], oz, r)
    e_avg = ggx_albedo.average_albedo(table[0], r)
    f_avg = f0 + (1.0 - f0) / 21.0
    f_ms = f_avg * f_avg * e_avg / (1.0 - f_avg * (1.0 - e_avg))
    return (1.0 - e_o) * (1.0 - ggx_albedo.albedo(table[0], wz, r)) / (math.pi * max(1.0 - e_avg, 1e-7)) * f_ms * wz


@row
def ggx_reflection(table, ox, oy, oz, wx, wy, wz, r, f0r, f0g, f0b, compensate):
    """``f |wi.z|`` (r, g, b) and density of a rough conductor (``wo.z, wi.z > 0``)."""
    alpha = max(r * r, SMOOTH_ALPHA)
    hx, hy, hz = ox + wx, oy + wy, oz + wz
    inv = 1.0 / math.sqrt(hx * hx + hy * hy + hz * hz)
    hx, hy, hz = hx * inv, hy * inv, hz * inv
    o_dot_h = (ox * hx + oy * hy) + oz * hz
    dg = distribution(hz, alpha) * masking_shadowing(oz, wz, alpha) / (4.0 * oz)
    fr = dg * lobes.schlick(f0r, o_dot_h)
    fg = dg * lobes.schlick(f0g, o_dot_h)
    fb = dg * lobes.schlick(f0b, o_dot_h)
    pdf_ss = masking(oz, alpha) * distribution(hz, alpha) / (4.0 * oz)
    if compensate > 0.0:
        p_ss = ggx_albedo.albedo(table[0], oz, r)
        fr += _compensation(table, oz, wz, r, f0r)
        fg += _compensation(table, oz, wz, r, f0g)
        fb += _compensation(table, oz, wz, r, f0b)
        return fr, fg, fb, p_ss * pdf_ss + (1.0 - p_ss) * wz / math.pi
    return fr, fg, fb, pdf_ss


@row
def evaluate(params, m, table, ox, oy, oz, wx, wy, wz):
    """``f |wi.z|`` (r, g, b) and the density of :func:`sample` (see :mod:`~rtmesh.materials.lobes`)."""
    r = params[m, 3]
    if not ((oz > 0.0) & (wz > 0.0)) or r * r < SMOOTH_ALPHA:
        return 0.0, 0.0, 0.0, 0.0
    return ggx_reflection(table, ox, oy, oz, wx, wy, wz, r, params[m, 0], params[m, 1], params[m, 2], params[m, 4])


@row
def sample_reflection(table, ox, oy, oz, u0, u1, u2, r, f0r, f0g, f0b, compensate):
    """Draw ``wi`` from a conductor lobe (``wo.z > 0``): ``(wx, wy, wz, weight r, g, b, pdf, flags)``."""
    if r * r < SMOOTH_ALPHA:
        return (-ox, -oy, oz, lobes.schlick(f0r, oz), lobes.schlick(f0g, oz), lobes.schlick(f0b, oz), 1.0,
                lobes.DELTA)
    alpha = max(r * r, SMOOTH_ALPHA)
    p_ss = ggx_albedo.albedo(table[0], oz, r) if compensate > 0.0 else 1.0
    if u0 < p_ss:
        hx, hy, hz = sample_visible_normal(ox, oy, oz, alpha, u1, u2)
        c = 2.0 * (ox * hx + oy * hy + oz * hz)
        wx, wy, wz = c * hx - ox, c * hy - oy, c * hz - oz
    else:
        wx, wy, wz = square_to_cosine_hemisphere_row(u1, u2)
    if not wz > 0.0:
        return wx, wy, wz, 0.0, 0.0, 0.0, 0.0, lobes.FAILED
    fr, fg, fb, pdf = ggx_reflection(table, ox, oy, oz, wx, wy, wz, r, f0r, f0g, f0b, compensate)
    if not pdf > 0.0:
        return wx, wy, wz, 0.0, 0.0, 0.0, 0.0, lobes.FAILED
    return wx, wy, wz, fr / pdf, fg / pdf, fb / pdf, pdf, lobes.GLOSSY


@row
def sample(params, m, table, ox, oy, oz, u0, u1, u2):
    """Draw ``wi``: ``(wx, wy, wz, weight r, g, b, pdf, flags)``."""
    if not oz > 0.0:
        return 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, lobes.FAILED
    return sample_reflection(table, ox, oy, oz, u0, u1, u2, params[m, 3], params[m, 0], params[m, 1],
                             params[m, 2], params[m, 4])


@row
def parts(params, m, table, ox, oy, oz, wx, wy, wz):
    """The diffuse and transmitted parts of ``f |cos|`` (light-path passes): none, a metal
    is all glossy."""
    return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0


@row
def albedo(params, m):
    """``F0``, for the denoiser's guide."""
    return params[m, 0], params[m, 1], params[m, 2]
