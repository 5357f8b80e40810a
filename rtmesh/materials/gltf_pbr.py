"""The glTF 2.0 metallic-roughness material under the path integrator: the BRDF of
:mod:`rtmesh.materials.metallic_roughness` (evaluated in the local frame, its rows shared),
plus KHR_materials_transmission's part as a dielectric interface
(:mod:`rtmesh.materials.dielectric`) tinted by the base colour.

Model
-----
``f = f_brdf + t f_transmitted`` with ``t = transmission (1 - metallic)``: the BRDF (its
specular layer over the diffuse base) already leaves out the transmitted part of its
diffuse term, and KHR_materials_transmission replaces only that base, so of the interface
only what it lets through is added; its reflection is the specular layer's, counted once
(with both, a clear ball in a white furnace returned 1.036), but inside (``wo.z < 0``),
where the one-sided BRDF has nothing, the interface reflects (and totally reflects) itself,
weighed by ``t`` as from outside (reciprocal: the rest meets the opaque base's back and is
absorbed).  Sampling chooses the interface with probability ``t`` (inside: absorbs
otherwise), the BRDF otherwise; the density is the mixture (a reflection the
interface draws outside is weighed by ``f`` over that density; a smooth interface's delta
reflection outside, which ``f`` does not have, gives no sample).

Parameters: ``base`` r, g, b, ``metallic``, ``alpha`` (roughness squared), ``roughness``,
``transmission``, ``ior``.
"""

import math

from rtmesh.core.compiled import row
from rtmesh.materials import dielectric, lobes
from rtmesh.materials.metallic_roughness import (alpha_from_roughness, brdf_cos_pdf_row, half_vector_cosines,
                                                 sample_row, schlick_weight)

NAME = "metallic_roughness"
SLOTS = {"colour": 0, "metallic": 3, "alpha": 4, "roughness": 5, "ior": 7}


def parameters(material):
    """The glTF factors (textures are applied per hit by the path integrator)."""
    roughness = min(max(float(material.perceptual_roughness), 0.0), 1.0)
    return [float(c) for c in material.base_color] + [
        float(material.metallic), float(alpha_from_roughness(roughness)), roughness,
        float(material.transmission_factor), float(material.ior)]


def transmissive(material):
    """Whether the material lets light through (its frame must keep the outward side)."""
    return material.transmission_factor > 0.0 and material.metallic < 1.0


@row
def evaluate(params, m, table, ox, oy, oz, wx, wy, wz):
    """``f |wi.z|`` (r, g, b) and the density of :func:`sample`."""
    t = params[m, 6] * (1.0 - params[m, 3])
    fr = fg = fb = pdf = 0.0
    if (oz > 0.0) & (wz > 0.0):
        fr, fg, fb, pdf = brdf_cos_pdf_row(ox, oy, oz, 0.0, 0.0, 1.0, wx, wy, wz, params[m, 0], params[m, 1],
                                           params[m, 2], params[m, 3], params[m, 4], params[m, 6])
        pdf *= 1.0 - t
    if t > 0.0 and params[m, 5] * params[m, 5] >= dielectric.SMOOTH_ALPHA:
        value, p, transmitted = dielectric.rough_interface(table, ox, oy, oz, wx, wy, wz, params[m, 7],
                                                           params[m, 5], 1.0)
        if transmitted:
            fr += t * value * params[m, 0]
            fg += t * value * params[m, 1]
            fb += t * value * params[m, 2]
        elif oz < 0.0:
            # reflected inside: the one-sided BRDF has no part there
            fr += t * value
            fg += t * value
            fb += t * value
        pdf += t * p
    return fr, fg, fb, pdf


@row
def sample(params, m, table, ox, oy, oz, u0, u1, u2):
    """Draw ``wi``: ``(wx, wy, wz, weight r, g, b, pdf, flags)``."""
    t = params[m, 6] * (1.0 - params[m, 3])
    if u0 < t or not oz > 0.0:
        if not u0 < t:
            # inside, the rest (1 - t) of the light meets the back of the opaque base: absorbed
            return 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, lobes.FAILED
        wx, wy, wz, weight, pdf, flags = dielectric.sample_interface(table, ox, oy, oz, min(u0 / t, 1.0), u1, u2,
                                                                     params[m, 7], params[m, 5], 1.0)
        if flags & lobes.DELTA or flags == lobes.FAILED:
            if flags & lobes.TRANSMISSION:
                return wx, wy, wz, weight * params[m, 0], weight * params[m, 1], weight * params[m, 2], pdf, flags
            if oz < 0.0:
                return wx, wy, wz, weight, weight, weight, pdf, flags
            return wx, wy, wz, 0.0, 0.0, 0.0, 0.0, lobes.FAILED
    else:
        u = (u0 - t) / (1.0 - t)
        wx, wy, wz, g0, g1, g2, pdf = sample_row(ox, oy, oz, 0.0, 0.0, 1.0, u, u1, u2, params[m, 0], params[m, 1],
                                                 params[m, 2], params[m, 3], params[m, 4], params[m, 6])
        if not pdf > 0.0:
            return wx, wy, wz, 0.0, 0.0, 0.0, 0.0, lobes.FAILED
        flags = lobes.GLOSSY
    fr, fg, fb, pdf = evaluate(params, m, table, ox, oy, oz, wx, wy, wz)
    return lobes.mixture_sample(wx, wy, wz, fr, fg, fb, pdf, flags, oz)


@row
def parts(params, m, table, ox, oy, oz, wx, wy, wz):
    """The diffuse and transmitted parts of ``f |cos|`` (light-path passes): the BRDF's
    Lambert term, and what the KHR transmission interface lets through."""
    dr = dg = db = tr = tg = tb = 0.0
    if (oz > 0.0) & (wz > 0.0):
        nv, nl, nh, vh = half_vector_cosines(ox, oy, oz, 0.0, 0.0, 1.0, wx, wy, wz)
        d = (1.0 - params[m, 3]) * (1.0 - params[m, 6]) * (1.0 - (0.04 + 0.96 * schlick_weight(vh))) / math.pi * nl
        dr, dg, db = d * params[m, 0], d * params[m, 1], d * params[m, 2]
    t = params[m, 6] * (1.0 - params[m, 3])
    if t > 0.0 and oz * wz < 0.0 and params[m, 5] * params[m, 5] >= dielectric.SMOOTH_ALPHA:
        value, _, _ = dielectric.rough_interface(table, ox, oy, oz, wx, wy, wz, params[m, 7], params[m, 5], 1.0)
        tr, tg, tb = t * value * params[m, 0], t * value * params[m, 1], t * value * params[m, 2]
    return dr, dg, db, tr, tg, tb


@row
def albedo(params, m):
    """The base colour, for the denoiser's guide."""
    return params[m, 0], params[m, 1], params[m, 2]
