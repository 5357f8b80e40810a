"""Whitted-style materials (MTL and scene-file Blinn-Phong fields) read physically, for the
path integrator: a mixture of four lobes, each weighted by its colour.

Model
-----
- diffuse ``kd``: Lambert, ``kd / pi`` (``kd`` is an albedo);
- specular ``ks``, ``shininess`` n: energy-normalised Blinn-Phong
  ``ks (n + 8) / (8 pi) (n.h)^n``, sampled by ``h`` with density ``(n + 1) / (2 pi) (n.h)^n``;
- mirror ``kr``: a perfect mirror of reflectance ``kr``, or with ``roughness`` > 0 a GGX
  lobe (``alpha = roughness``, the lobe's width in radians as the Whitted model reads it)
  with Schlick's Fresnel toward ``kr``;
- transmission ``kt``: a dielectric interface of index ``ior`` (smooth, or GGX of the same
  alpha), weighted by ``kt`` (:mod:`rtmesh.materials.dielectric`).

A lobe is chosen in proportion to the luminance of its colour; ``f`` and the density are the
sums over the lobes that are not deltas.  The sum of the colours should not exceed 1 for
the material to conserve energy; the model does not rescale them.

Parameters: ``kd`` (0-2), ``ks`` (3-5), ``shininess`` (6), ``kr`` (7-9), ``kt`` (10-12),
``ior`` (13), ``roughness`` (14).
"""

import math

import numpy as np

from rtmesh.core.compiled import row
from rtmesh.materials import conductor, dielectric, lobes
from rtmesh.materials.metallic_roughness import square_to_cosine_hemisphere_row

NAME = "blinn_phong"
SLOTS = {"colour": 0, "specular": 3, "mirror": 7, "ior": 13}


def parameters(material):
    """The material's Blinn-Phong, mirror and transmission fields."""
    return ([float(c) for c in material.diffuse] + [float(c) for c in material.specular]
            + [float(material.shininess)] + [float(c) for c in material.mirror]
            + [float(c) for c in material.transmission] + [float(material.ior), float(material.roughness)])


def transmissive(material):
    """Whether the material refracts (its frame must keep the outward side)."""
    return bool((np.asarray(material.transmission) > 0).any())


@row
def _weights(params, m):
    """Choice probabilities of the diffuse, specular, mirror and transmission lobes."""
    wd = lobes.luminance(params[m, 0], params[m, 1], params[m, 2])
    ws = lobes.luminance(params[m, 3], params[m, 4], params[m, 5])
    wr = lobes.luminance(params[m, 7], params[m, 8], params[m, 9])
    wt = lobes.luminance(params[m, 10], params[m, 11], params[m, 12])
    total = ((wd + ws) + wr) + wt
    if not total > 0.0:
        return 0.0, 0.0, 0.0, 0.0
    return wd / total, ws / total, wr / total, wt / total


@row
def _glossy_roughness(params, m):
    """The GGX roughness parameter whose alpha is the material's ``roughness``."""
    return math.sqrt(max(params[m, 14], 0.0))


@row
def evaluate(params, m, table, ox, oy, oz, wx, wy, wz):
    """``f |wi.z|`` (r, g, b) and the density of :func:`sample`."""
    pd, ps, pr, pt = _weights(params, m)
    fr = fg = fb = pdf = 0.0
    rough = _glossy_roughness(params, m)
    if (oz > 0.0) & (wz > 0.0):
        c = wz / math.pi
        fr, fg, fb, pdf = params[m, 0] * c, params[m, 1] * c, params[m, 2] * c, pd * c
        if ps > 0.0:
            n = params[m, 6]
            hx, hy, hz = ox + wx, oy + wy, oz + wz
            inv = 1.0 / math.sqrt(hx * hx + hy * hy + hz * hz)
            hz *= inv
            o_dot_h = ((ox * hx + oy * hy) * inv) + oz * hz
            lobe = hz ** n
            s = (n + 8.0) / (8.0 * math.pi) * lobe * wz
            fr += params[m, 3] * s
            fg += params[m, 4] * s
            fb += params[m, 5] * s
            pdf += ps * (n + 1.0) / (2.0 * math.pi) * lobe / (4.0 * o_dot_h)
        if pr > 0.0 and rough * rough >= dielectric.SMOOTH_ALPHA:
            gr, gg, gb, gp = conductor.ggx_reflection(table, ox, oy, oz, wx, wy, wz, rough, params[m, 7],
                                                      params[m, 8], params[m, 9], 0.0)
            fr, fg, fb, pdf = fr + gr, fg + gg, fb + gb, pdf + pr * gp
    if pt > 0.0 and rough * rough >= dielectric.SMOOTH_ALPHA:
        value, p, _ = dielectric.rough_interface(table, ox, oy, oz, wx, wy, wz, params[m, 13], rough, 1.0)
        fr += params[m, 10] * value
        fg += params[m, 11] * value
        fb += params[m, 12] * value
        # seen from inside the interface is the one lobe sample() draws
        pdf += (pt if oz > 0.0 else 1.0) * p
    return fr, fg, fb, pdf


@row
def sample(params, m, table, ox, oy, oz, u0, u1, u2):
    """Draw ``wi``: ``(wx, wy, wz, weight r, g, b, pdf, flags)``."""
    pd, ps, pr, pt = _weights(params, m)
    rough = _glossy_roughness(params, m)
    if u0 >= pd + ps + pr or not oz > 0.0:
        # transmission (the only lobe seen from inside)
        if not pt > 0.0:
            return 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, lobes.FAILED
        u = min(max((u0 - (pd + ps + pr)) / pt, 0.0), 1.0) if oz > 0.0 else u0
        wx, wy, wz, weight, pdf, flags = dielectric.sample_interface(table, ox, oy, oz, u, u1, u2, params[m, 13],
                                                                     rough, 1.0)
        if flags == lobes.FAILED:
            return wx, wy, wz, 0.0, 0.0, 0.0, 0.0, flags
        if flags & lobes.DELTA:
            scale = weight / pt if oz > 0.0 else weight
            return (wx, wy, wz, params[m, 10] * scale, params[m, 11] * scale, params[m, 12] * scale,
                    pdf * pt, flags)
    elif u0 < pd:
        wx, wy, wz = square_to_cosine_hemisphere_row(u1, u2)
        flags = lobes.DIFFUSE
    elif u0 < pd + ps:
        n = params[m, 6]
        cos_h = u1 ** (1.0 / (n + 1.0))
        sin_h = math.sqrt(max(0.0, 1.0 - cos_h * cos_h))
        phi = 2.0 * math.pi * u2
        hx, hy, hz = sin_h * math.cos(phi), sin_h * math.sin(phi), cos_h
        c = 2.0 * ((ox * hx + oy * hy) + oz * hz)
        wx, wy, wz = c * hx - ox, c * hy - oy, c * hz - oz
        flags = lobes.GLOSSY
    else:
        u = min(max((u0 - pd - ps) / pr, 0.0), 1.0)
        wx, wy, wz, gr, gg, gb, pdf, flags = conductor.sample_reflection(table, ox, oy, oz, u, u1, u2, rough,
                                                                          params[m, 7], params[m, 8], params[m, 9], 0.0)
        if flags & lobes.DELTA:
            # constant reflectance, as the Whitted model's mirror
            return wx, wy, wz, params[m, 7] / pr, params[m, 8] / pr, params[m, 9] / pr, pr, flags
        if flags == lobes.FAILED:
            return wx, wy, wz, 0.0, 0.0, 0.0, 0.0, flags
    fr, fg, fb, pdf = evaluate(params, m, table, ox, oy, oz, wx, wy, wz)
    return lobes.mixture_sample(wx, wy, wz, fr, fg, fb, pdf, flags, oz)


@row
def parts(params, m, table, ox, oy, oz, wx, wy, wz):
    """The diffuse and transmitted parts of ``f |cos|`` (light-path passes): the Lambert
    lobe, and the rough interface's transmission."""
    pd, ps, pr, pt = _weights(params, m)
    dr = dg = db = tr = tg = tb = 0.0
    if (oz > 0.0) & (wz > 0.0):
        c = wz / math.pi
        dr, dg, db = params[m, 0] * c, params[m, 1] * c, params[m, 2] * c
    rough = _glossy_roughness(params, m)
    if pt > 0.0 and oz * wz < 0.0 and rough * rough >= dielectric.SMOOTH_ALPHA:
        value, _, _ = dielectric.rough_interface(table, ox, oy, oz, wx, wy, wz, params[m, 13], rough, 1.0)
        tr, tg, tb = params[m, 10] * value, params[m, 11] * value, params[m, 12] * value
    return dr, dg, db, tr, tg, tb


@row
def albedo(params, m):
    """The diffuse colour plus the specular, mirror and transmission colours, for the guide."""
    return (params[m, 0] + params[m, 3] + params[m, 7] + params[m, 10],
            params[m, 1] + params[m, 4] + params[m, 8] + params[m, 11],
            params[m, 2] + params[m, 5] + params[m, 9] + params[m, 12])
