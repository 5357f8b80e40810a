"""Dielectrics (glass, water): a smooth interface (delta reflection and refraction with the
exact Fresnel reflectance) or a rough one (GGX microfacet reflection and transmission,
Walter et al. 2007, "Microfacet Models for Refraction through Rough Surfaces"; the form of
pbrt-v4's ``DielectricBxDF``).

Model
-----
With ``eta'`` the ratio of the indices across the interface, ``h`` the generalised half
vector ``normalize(eta' wi + wo)`` turned to the outside, ``F`` the Fresnel reflectance at
``wo.h``::

    reflection:    f = D(h) G2 F / (4 |mu_o mu_i|)
    transmission:  f = (1 - F) D(h) G2 |wi.h wo.h| / (|mu_o mu_i| (wi.h + wo.h / eta')^2) / eta'^2

(the last ``1 / eta'^2`` transports radiance; pbrt's ``TransportMode::Radiance``).
Sampling draws a visible normal, then reflection with probability ``F``, refraction
otherwise; a smooth interface draws the mirror or refracted direction the same way.
``tint`` multiplies transmitted light (coloured glass without a volume).  The interior's
Beer-Lambert absorption is the path integrator's, not the interface's.

Energy: single-scattering GGX loses light at rough interfaces, most under total internal
reflection; with ``compensate`` the interface's BSDF is divided by its single-scattering
energy albedo at ``wo`` (:mod:`rtmesh.materials.dielectric_albedo`), so every event conserves
energy (a closed rough glass object vanishes in a white furnace) and the model is no longer
reciprocal.

Parameters: ``ior`` (inside over outside), ``roughness``, ``tint`` r, g, b, ``compensate``.
"""

import math

from rtmesh.core.compiled import row
from rtmesh.materials import dielectric_albedo, lobes
from rtmesh.materials.microfacet import (SMOOTH_ALPHA, distribution, masking_shadowing, sample_visible_normal,
                                         visible_normal_pdf)

NAME = "dielectric"
SLOTS = {"colour": 2, "ior": 0}


def parameters(material):
    """``ior``, ``roughness`` (clamped to [0, 1]) and the transmission colour as the tint."""
    return [float(material.ior), min(max(float(material.roughness), 0.0), 1.0), 1.0, 1.0, 1.0, 1.0]


# the parameter that turns the energy compensation on (1) or off (0)
COMPENSATE = 5


@row
def rough_interface(table, ox, oy, oz, wx, wy, wz, eta, roughness, compensate):
    """``f |wi.z|`` (one channel, untinted), density, and whether ``wi`` is transmitted, of
    a rough interface (divided by its energy albedo at ``wo`` when ``compensate`` > 0;
    ``table`` is the models' table pair, :func:`rtmesh.materials.models.tables`)."""
    alpha = roughness * roughness
    if (oz == 0.0) | (wz == 0.0):
        return 0.0, 0.0, False
    reflect = oz * wz > 0.0
    etap = 1.0
    if not reflect:
        etap = eta if oz > 0.0 else 1.0 / eta
    hx, hy, hz = wx * etap + ox, wy * etap + oy, wz * etap + oz
    length2 = hx * hx + hy * hy + hz * hz
    if not length2 > 0.0:
        return 0.0, 0.0, not reflect
    inv = 1.0 / math.sqrt(length2)
    if hz < 0.0:
        inv = -inv
    hx, hy, hz = hx * inv, hy * inv, hz * inv
    i_dot_h = (wx * hx + wy * hy) + wz * hz
    o_dot_h = (ox * hx + oy * hy) + oz * hz
    # microfacets seen from behind contribute nothing
    if (i_dot_h * wz < 0.0) | (o_dot_h * oz < 0.0):
        return 0.0, 0.0, not reflect
    f = lobes.fresnel_dielectric(o_dot_h, eta)
    d = distribution(hz, alpha)
    g = masking_shadowing(oz, wz, alpha)
    visible = visible_normal_pdf(oz, hz, o_dot_h, alpha)
    scale = 1.0 / dielectric_albedo.albedo(table[1], abs(oz), roughness, eta, oz < 0.0) if compensate > 0.0 else 1.0
    if reflect:
        return d * g * f / (4.0 * abs(oz)) * scale, visible / (4.0 * abs(o_dot_h)) * f, False
    denom = i_dot_h + o_dot_h / etap
    denom *= denom
    value = (1.0 - f) * d * g * abs(i_dot_h * o_dot_h / (oz * denom)) / (etap * etap)
    return value * scale, visible * abs(i_dot_h) / denom * (1.0 - f), True


@row
def sample_interface(table, ox, oy, oz, u0, u1, u2, eta, roughness, compensate):
    """Draw ``wi`` at a smooth or rough interface: ``(wx, wy, wz, weight, pdf, flags)``, the
    weight one number (untinted)."""
    alpha = roughness * roughness
    if alpha < SMOOTH_ALPHA:
        f = lobes.fresnel_dielectric(oz, eta)
        if u0 < f:
            return -ox, -oy, oz, 1.0, f, lobes.DELTA
        tx, ty, tz, etap, ok = lobes.refract(ox, oy, oz, 0.0, 0.0, 1.0, eta)
        if not ok:  # unreachable: F = 1 under total internal reflection
            return -ox, -oy, oz, 1.0, 1.0, lobes.DELTA
        return tx, ty, tz, 1.0 / (etap * etap), 1.0 - f, lobes.DELTA | lobes.TRANSMISSION
    hx, hy, hz = sample_visible_normal(ox, oy, oz, alpha, u1, u2)
    o_dot_h = (ox * hx + oy * hy) + oz * hz
    f = lobes.fresnel_dielectric(o_dot_h, eta)
    if u0 < f:
        c = 2.0 * o_dot_h
        wx, wy, wz = c * hx - ox, c * hy - oy, c * hz - oz
        if not oz * wz > 0.0:
            return wx, wy, wz, 0.0, 0.0, lobes.FAILED
        flags = lobes.GLOSSY
    else:
        wx, wy, wz, etap, ok = lobes.refract(ox, oy, oz, hx, hy, hz, eta)
        if (not ok) or not oz * wz < 0.0:
            return wx, wy, wz, 0.0, 0.0, lobes.FAILED
        flags = lobes.GLOSSY | lobes.TRANSMISSION
    value, pdf, _ = rough_interface(table, ox, oy, oz, wx, wy, wz, eta, roughness, compensate)
    if not pdf > 0.0:
        return wx, wy, wz, 0.0, 0.0, lobes.FAILED
    return wx, wy, wz, value / pdf, pdf, flags


@row
def evaluate(params, m, table, ox, oy, oz, wx, wy, wz):
    """``f |wi.z|`` (r, g, b) and density (0 for a smooth interface: delta lobes only)."""
    alpha = params[m, 1] * params[m, 1]
    if alpha < SMOOTH_ALPHA:
        return 0.0, 0.0, 0.0, 0.0
    value, pdf, transmitted = rough_interface(table, ox, oy, oz, wx, wy, wz, params[m, 0], params[m, 1],
                                              params[m, COMPENSATE])
    if transmitted:
        return value * params[m, 2], value * params[m, 3], value * params[m, 4], pdf
    return value, value, value, pdf


@row
def sample(params, m, table, ox, oy, oz, u0, u1, u2):
    """Draw ``wi``: ``(wx, wy, wz, weight r, g, b, pdf, flags)``."""
    wx, wy, wz, weight, pdf, flags = sample_interface(table, ox, oy, oz, u0, u1, u2, params[m, 0], params[m, 1],
                                                      params[m, COMPENSATE])
    if flags & lobes.TRANSMISSION:
        return wx, wy, wz, weight * params[m, 2], weight * params[m, 3], weight * params[m, 4], pdf, flags
    return wx, wy, wz, weight, weight, weight, pdf, flags


@row
def parts(params, m, table, ox, oy, oz, wx, wy, wz):
    """The diffuse and transmitted parts of ``f |cos|`` (light-path passes): light through
    the interface is transmission, its reflection glossy."""
    if oz * wz < 0.0:
        fr, fg, fb, _ = evaluate(params, m, table, ox, oy, oz, wx, wy, wz)
        return 0.0, 0.0, 0.0, fr, fg, fb
    return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0


@row
def albedo(params, m):
    """The tint, for the denoiser's guide (what shows through the interface)."""
    return params[m, 2], params[m, 3], params[m, 4]
