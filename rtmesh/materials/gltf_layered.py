"""The glTF 2.0 material with its KHR layer extensions under the path integrator:
KHR_materials_specular, _clearcoat, _sheen, _anisotropy and _iridescence on the
metallic-roughness base (with KHR_materials_transmission / ior as in
:mod:`~rtmesh.materials.gltf_pbr`), in one model whose row carries every layer's parameters,
so that a material combining several extensions is one row and one evaluation.  Materials
without any of these extensions keep the ``metallic_roughness`` model (the glTF loader
chooses), whose arithmetic and speed they keep.

Model (the specifications' layering, docs/MATERIALS.md)
-------------------------------------------------------
With ``h = normalize(wo + wi)``, ``w = (1 - |wo.h|)^5`` and GGX's ``D``, ``G2`` (anisotropic:
``alpha_t = mix(alpha, 1, anisotropy^2)`` along the anisotropy direction, ``alpha_b = alpha``)::

    spec    = D G2 / (4 mu_o mu_i)
    F_d     = f0_d + (f90_d - f0_d) w,  f0_d = min(f0(ior) specularColor, 1) specular,
              f90_d = specular                                   (KHR_materials_specular)
    F_m     = base + (1 - base) w
    F_*     = mix(F_*, thin_film(|wo.h|), iridescence)           (KHR_materials_iridescence)
    base_f  = (1 - m) (F_d spec + (1 - max3(F_d)) (1 - t) base / pi) + m F_m spec
    sheen_f = sheenColor D_c V_c / max(1, E(mu_o), E(mu_i))
              + base_f min(1 - max3(sheenColor) E(mu_o), 1 - max3(sheenColor) E(mu_i))
                                                                 (KHR_materials_sheen)
    f       = (1 - c F_c) sheen_f + c F_c D_cc G2_cc / (4 |n_c.wo| |n_c.wi|)
              F_c = 0.04 + 0.96 (1 - |n_c.wo|)^5                 (KHR_materials_clearcoat)

plus ``t (1 - c F_c) s f_interface`` for KHR_materials_transmission (``t = transmission
(1 - m)``, ``s`` the sheen's albedo scaling, the rough interface of
:mod:`~rtmesh.materials.dielectric` tinted by the base colour where light passes, as
:mod:`~rtmesh.materials.gltf_pbr`); seen from inside, the interface alone.  ``n_c`` is the clear
coat's own normal (its normal map, else the unbent shading normal), ``E`` the sheen albedo
of :mod:`~rtmesh.materials.sheen` (clamped to 1).

Reciprocity: every term but the clear coat's blend is symmetric in ``wo`` and ``wi``; the
specification's coat weighs the layers by Fresnel at ``n_c.wo`` (not at the half vector),
so a material with a clear coat is not reciprocal.

Sampling: the coat lobe (visible normals about ``n_c``) with probability ``c F_c``, the sheen
lobe (cosine-weighted) with ``max3(sheenColor) E(mu_o)`` of the rest, then the base: the
transmission interface with probability ``t``, else GGX visible normals (anisotropic) or the
cosine lobe as :func:`~rtmesh.materials.metallic_roughness.specular_probability`; the
density is the whole mixture.

Parameters: see the ``*_AT`` indices below (the first eight are ``gltf_pbr``'s).
"""

import math
from dataclasses import dataclass, field

import numpy as np

from rtmesh.core.compiled import row
from rtmesh.core.row_vectors import tangent_frame
from rtmesh.materials import dielectric, lobes, sheen, thin_film
from rtmesh.materials.metallic_roughness import (MIN_ALPHA, alpha_from_roughness, schlick_weight,
                                                 specular_probability, square_to_cosine_hemisphere_row)
from rtmesh.materials.microfacet import (distribution_anisotropic, masking_anisotropic,
                                         masking_shadowing_anisotropic, sample_visible_normal_anisotropic)

NAME = "gltf_layered"

# the row: gltf_pbr's eight, then each layer's
(BASE_AT, METALLIC_AT, ALPHA_AT, ROUGHNESS_AT, TRANSMISSION_AT, IOR_AT) = (0, 3, 4, 5, 6, 7)
SPECULAR_COLOUR_AT, SPECULAR_AT = 8, 11
CLEARCOAT_AT, CLEARCOAT_ROUGHNESS_AT, COAT_NORMAL_AT = 12, 13, 14
SHEEN_COLOUR_AT, SHEEN_ROUGHNESS_AT = 17, 20
ANISOTROPY_AT, ANISOTROPY_DIRECTION_AT, ANISOTROPY_ROTATION_AT = 21, 22, 24
IRIDESCENCE_AT, IRIDESCENCE_IOR_AT, THICKNESS_AT, THICKNESS_MIN_AT = 25, 26, 27, 28
WIDTH = 29

SLOTS = {"colour": BASE_AT, "metallic": METALLIC_AT, "alpha": ALPHA_AT, "roughness": ROUGHNESS_AT, "ior": IOR_AT,
         "specular_colour": SPECULAR_COLOUR_AT, "specular_strength": SPECULAR_AT, "clearcoat": CLEARCOAT_AT,
         "clearcoat_roughness": CLEARCOAT_ROUGHNESS_AT, "coat_normal": COAT_NORMAL_AT,
         "sheen_colour": SHEEN_COLOUR_AT, "sheen_roughness": SHEEN_ROUGHNESS_AT, "anisotropy": ANISOTROPY_AT,
         "iridescence": IRIDESCENCE_AT, "iridescence_thickness": THICKNESS_AT}

# The clear coat's index (KHR_materials_clearcoat fixes it): F0 = ((1.5 - 1) / (1.5 + 1))^2
COAT_F0 = 0.04
# Smallest probability of a lobe that reflects something: a lobe drawn with probability p
# gets weights up to 1 / p times its own; as metallic_roughness.P_SPEC_MIN
P_MIN = 0.05


@dataclass(eq=False)  # compared by identity, as the textures it holds
class Layers:
    """The KHR layer extensions of one glTF material (factors; textures by role).

    Attributes
    ----------
    specular : float
        KHR_materials_specular ``specularFactor`` in [0, 1].
    specular_colour : (3,) float
        ``specularColorFactor`` (linear, >= 0).
    clearcoat, clearcoat_roughness : float
        KHR_materials_clearcoat factors in [0, 1].
    sheen_colour : (3,) float
        KHR_materials_sheen ``sheenColorFactor`` (linear, [0, 1]).
    sheen_roughness : float
        In [0, 1].
    anisotropy : float
        KHR_materials_anisotropy ``anisotropyStrength`` in [0, 1].
    anisotropy_rotation : float
        Radians, counter-clockwise from the UV tangent.
    iridescence, iridescence_ior : float
        KHR_materials_iridescence factor in [0, 1] and the film's index (>= 1).
    thickness_min, thickness_max : float
        Film thickness in nanometres (the thickness texture's green channel mixes them;
        without it the maximum is the thickness).
    textures : dict of str to Texture
        By the extension's texture role: ``specularTexture``, ``specularColorTexture``,
        ``clearcoatTexture``, ``clearcoatRoughnessTexture``, ``clearcoatNormalTexture``,
        ``sheenColorTexture``, ``sheenRoughnessTexture``, ``anisotropyTexture``,
        ``iridescenceTexture``, ``iridescenceThicknessTexture``.
    extensions : tuple of str
        The extension names the material uses (warnings, docs).
    """

    specular: float = 1.0
    specular_colour: np.ndarray = field(default_factory=lambda: np.ones(3))
    clearcoat: float = 0.0
    clearcoat_roughness: float = 0.0
    sheen_colour: np.ndarray = field(default_factory=lambda: np.zeros(3))
    sheen_roughness: float = 0.0
    anisotropy: float = 0.0
    anisotropy_rotation: float = 0.0
    iridescence: float = 0.0
    iridescence_ior: float = 1.3
    thickness_min: float = 100.0
    thickness_max: float = 400.0
    textures: dict = field(default_factory=dict)
    extensions: tuple = ()


def parameters(material):
    """The row of a glTF material with layers (``material.layers``; defaults without)."""
    layers = material.layers if material.layers is not None else Layers()
    roughness = min(max(float(material.perceptual_roughness), 0.0), 1.0)
    row_ = np.zeros(WIDTH)
    row_[BASE_AT:BASE_AT + 3] = material.base_color
    row_[METALLIC_AT] = material.metallic
    row_[ALPHA_AT] = alpha_from_roughness(roughness)
    row_[ROUGHNESS_AT] = roughness
    row_[TRANSMISSION_AT] = material.transmission_factor
    row_[IOR_AT] = material.ior
    row_[SPECULAR_COLOUR_AT:SPECULAR_COLOUR_AT + 3] = layers.specular_colour
    row_[SPECULAR_AT] = layers.specular
    row_[CLEARCOAT_AT] = layers.clearcoat
    row_[CLEARCOAT_ROUGHNESS_AT] = layers.clearcoat_roughness
    row_[COAT_NORMAL_AT + 2] = 1.0  # the shading normal until the path kernel orients the row
    row_[SHEEN_COLOUR_AT:SHEEN_COLOUR_AT + 3] = layers.sheen_colour
    row_[SHEEN_ROUGHNESS_AT] = layers.sheen_roughness
    row_[ANISOTROPY_AT] = layers.anisotropy
    row_[ANISOTROPY_DIRECTION_AT] = 1.0  # the frame's x axis, likewise
    row_[ANISOTROPY_ROTATION_AT] = layers.anisotropy_rotation
    row_[IRIDESCENCE_AT] = layers.iridescence
    row_[IRIDESCENCE_IOR_AT] = layers.iridescence_ior
    row_[THICKNESS_AT] = layers.thickness_max
    row_[THICKNESS_MIN_AT] = layers.thickness_min
    return [float(v) for v in row_]


def transmissive(material):
    """Whether the material lets light through (its frame must keep the outward side)."""
    return material.transmission_factor > 0.0 and material.metallic < 1.0


# ------------------------------------------------------------------ terms
@row
def _max3(r, g, b):
    return max(r, max(g, b))


@row
def _to_anisotropy(x, y, ax, ay):
    """Local (x, y) in the frame whose x axis is the anisotropy direction ``(ax, ay)``."""
    return x * ax + y * ay, y * ax - x * ay


@row
def _widths(params, m):
    """GGX widths along and across the anisotropy direction, and that direction (unit)."""
    alpha = max(params[m, ALPHA_AT], MIN_ALPHA)
    s = params[m, ANISOTROPY_AT]
    ax, ay = params[m, ANISOTROPY_DIRECTION_AT], params[m, ANISOTROPY_DIRECTION_AT + 1]
    length = math.sqrt(ax * ax + ay * ay)
    if not length > 0.0:
        ax, ay, length = 1.0, 0.0, 1.0
    return alpha + (1.0 - alpha) * (s * s), alpha, ax / length, ay / length


@row
def _coat(params, m, ox, oy, oz, wx, wy, wz):
    """The clear coat: ``(c F_c, its BRDF D G2 / (4 |n_c.wo| |n_c.wi|), its sampling density)``."""
    c = params[m, CLEARCOAT_AT]
    if not c > 0.0:
        return 0.0, 0.0, 0.0
    nx, ny, nz = params[m, COAT_NORMAL_AT], params[m, COAT_NORMAL_AT + 1], params[m, COAT_NORMAL_AT + 2]
    co = (nx * ox + ny * oy) + nz * oz
    if not co > 0.0:
        return 0.0, 0.0, 0.0
    k = c * lobes.schlick(COAT_F0, co)
    ci = (nx * wx + ny * wy) + nz * wz
    if not ci > 0.0:
        return k, 0.0, 0.0
    r = params[m, CLEARCOAT_ROUGHNESS_AT]
    alpha = max(r * r, MIN_ALPHA)
    hx, hy, hz = ox + wx, oy + wy, oz + wz
    inv = 1.0 / math.sqrt((hx * hx + hy * hy) + hz * hz)
    ch = ((nx * hx + ny * hy) + nz * hz) * inv
    # the coat's frame: only cosines with n_c enter an isotropic lobe
    tx, ty, tz, sx, sy, sz = tangent_frame(nx, ny, nz)
    ox_ = (tx * ox + ty * oy) + tz * oz
    oy_ = (sx * ox + sy * oy) + sz * oz
    wx_ = (tx * wx + ty * wy) + tz * wz
    wy_ = (sx * wx + sy * wy) + sz * wz
    hx_ = ((tx * hx + ty * hy) + tz * hz) * inv
    hy_ = ((sx * hx + sy * hy) + sz * hz) * inv
    d = distribution_anisotropic(hx_, hy_, ch, alpha, alpha)
    g2 = masking_shadowing_anisotropic(ox_, oy_, co, wx_, wy_, ci, alpha, alpha)
    pdf = masking_anisotropic(ox_, oy_, co, alpha, alpha) * d / (4.0 * co)
    return k, d * g2 / (4.0 * co * ci), pdf


@row
def _sheen_terms(params, m, table, oz, wz, hz):
    """``(sheen f r, g, b, albedo scaling of the base)`` for ``oz, wz`` of either sign
    (cosines taken absolute; the lobe itself is 0 unless both are > 0)."""
    cr, cg, cb = params[m, SHEEN_COLOUR_AT], params[m, SHEEN_COLOUR_AT + 1], params[m, SHEEN_COLOUR_AT + 2]
    c = _max3(cr, cg, cb)
    if not c > 0.0:
        return 0.0, 0.0, 0.0, 1.0
    r = params[m, SHEEN_ROUGHNESS_AT]
    e_o = sheen.albedo(table[2], abs(oz), r)
    e_i = sheen.albedo(table[2], abs(wz), r)
    scale = min(1.0 - c * min(e_o, 1.0), 1.0 - c * min(e_i, 1.0))
    if not ((oz > 0.0) & (wz > 0.0)):
        return 0.0, 0.0, 0.0, scale
    # the fitted Lambda lets a smooth sheen reflect more than 1 at grazing angles (E up to
    # ~2.7 at mu -> 0, r -> 0); dividing by max(1, E) both ways keeps it below 1, reciprocal
    f = sheen.brdf(oz, wz, hz, sheen.sheen_alpha(r)) / max(1.0, max(e_o, e_i))
    return cr * f, cg * f, cb * f, scale


@row
def _fresnel(params, m, vh):
    """The dielectric's ``F_d`` (r, g, b) and the metal's ``F_m`` (r, g, b) at ``|wo.h| = vh``
    (specular colour and strength, iridescence)."""
    w = schlick_weight(vh)
    eta = params[m, IOR_AT]
    q = (eta - 1.0) / (eta + 1.0)
    f0 = q * q
    s = params[m, SPECULAR_AT]
    d0r = min(f0 * params[m, SPECULAR_COLOUR_AT], 1.0) * s
    d0g = min(f0 * params[m, SPECULAR_COLOUR_AT + 1], 1.0) * s
    d0b = min(f0 * params[m, SPECULAR_COLOUR_AT + 2], 1.0) * s
    br, bg, bb = params[m, BASE_AT], params[m, BASE_AT + 1], params[m, BASE_AT + 2]
    fdr, fdg, fdb = d0r + (s - d0r) * w, d0g + (s - d0g) * w, d0b + (s - d0b) * w
    fmr, fmg, fmb = br + (1.0 - br) * w, bg + (1.0 - bg) * w, bb + (1.0 - bb) * w
    k = params[m, IRIDESCENCE_AT]
    eta2, thickness = params[m, IRIDESCENCE_IOR_AT], params[m, THICKNESS_AT]
    if k > 0.0 and thickness > 0.0:  # a film of thickness 0 is none (the specification)
        ir, ig, ib = thin_film.fresnel(eta2, vh, thickness, d0r, d0g, d0b)
        fdr, fdg, fdb = fdr + k * (ir - fdr), fdg + k * (ig - fdg), fdb + k * (ib - fdb)
        ir, ig, ib = thin_film.fresnel(eta2, vh, thickness, br, bg, bb)
        fmr, fmg, fmb = fmr + k * (ir - fmr), fmg + k * (ig - fmg), fmb + k * (ib - fmb)
    return fdr, fdg, fdb, fmr, fmg, fmb


@row
def _base(params, m, ox, oy, oz, wx, wy, wz):
    """The base BRDF times ``wi.z`` (r, g, b), its diffuse part (r, g, b) and the density of
    its specular lobe (visible normals, reflection), for ``oz, wz > 0``."""
    at, ab, ax, ay = _widths(params, m)
    hx, hy, hz = ox + wx, oy + wy, oz + wz
    inv = 1.0 / math.sqrt((hx * hx + hy * hy) + hz * hz)
    hx, hy, hz = hx * inv, hy * inv, hz * inv
    vh = abs((ox * hx + oy * hy) + oz * hz)
    px, py = _to_anisotropy(ox, oy, ax, ay)
    qx, qy = _to_anisotropy(wx, wy, ax, ay)
    gx, gy = _to_anisotropy(hx, hy, ax, ay)
    d = distribution_anisotropic(gx, gy, hz, at, ab)
    spec = d * masking_shadowing_anisotropic(px, py, oz, qx, qy, wz, at, ab) / (4.0 * oz)  # times wi.z
    pdf = masking_anisotropic(px, py, oz, at, ab) * d / (4.0 * oz)
    fdr, fdg, fdb, fmr, fmg, fmb = _fresnel(params, m, vh)
    metal = params[m, METALLIC_AT]
    diffuse = (1.0 - metal) * (1.0 - params[m, TRANSMISSION_AT]) * (1.0 - _max3(fdr, fdg, fdb)) / math.pi * wz
    dr, dg, db = diffuse * params[m, BASE_AT], diffuse * params[m, BASE_AT + 1], diffuse * params[m, BASE_AT + 2]
    dielectric_ = 1.0 - metal
    return (dr + (dielectric_ * fdr + metal * fmr) * spec, dg + (dielectric_ * fdg + metal * fmg) * spec,
            db + (dielectric_ * fdb + metal * fmb) * spec, dr, dg, db, pdf)


@row
def _probabilities(params, m, table, ox, oy, oz):
    """The lobe choice, a function of ``wo`` alone: ``(p_coat, p_sheen, p_interface,
    p_specular, p_diffuse)``, summing to 1 (seen from inside, the interface alone)."""
    t = params[m, TRANSMISSION_AT] * (1.0 - params[m, METALLIC_AT])
    if not oz > 0.0:
        return 0.0, 0.0, 1.0 if t > 0.0 else 0.0, 0.0, 0.0
    k, _, _ = _coat(params, m, ox, oy, oz, 0.0, 0.0, 1.0)
    p_coat = min(max(k, P_MIN), 1.0 - P_MIN) if k > 0.0 else 0.0
    c = _max3(params[m, SHEEN_COLOUR_AT], params[m, SHEEN_COLOUR_AT + 1], params[m, SHEEN_COLOUR_AT + 2])
    q = 0.0
    if c > 0.0:
        q = min(max(c * min(sheen.albedo(table[2], oz, params[m, SHEEN_ROUGHNESS_AT]), 1.0), P_MIN), 1.0 - P_MIN)
    rest = (1.0 - p_coat) * (1.0 - q)
    p_spec = specular_probability(oz, params[m, BASE_AT], params[m, BASE_AT + 1], params[m, BASE_AT + 2],
                                  params[m, METALLIC_AT], params[m, TRANSMISSION_AT])
    return (p_coat, (1.0 - p_coat) * q, rest * t, rest * (1.0 - t) * p_spec, rest * (1.0 - t) * (1.0 - p_spec))


@row
def _interface_weight(params, m, oz):
    """What the transmission interface's value is weighed by: ``t = transmission (1 - m)``
    from outside; 1 from inside, where light meets nothing but the interface (not
    reciprocal by that factor; :mod:`~rtmesh.materials.gltf_pbr` weighs its inside by ``t``
    too and absorbs the rest)."""
    t = params[m, TRANSMISSION_AT] * (1.0 - params[m, METALLIC_AT])
    return t if (oz > 0.0) | (t <= 0.0) else 1.0


@row
def _interface(params, m, table, ox, oy, oz, wx, wy, wz):
    """The KHR transmission interface: ``(value, density, transmitted)`` (0 without)."""
    t = _interface_weight(params, m, oz)
    if t > 0.0 and params[m, ROUGHNESS_AT] * params[m, ROUGHNESS_AT] >= dielectric.SMOOTH_ALPHA:
        value, p, transmitted = dielectric.rough_interface(table, ox, oy, oz, wx, wy, wz, params[m, IOR_AT],
                                                           params[m, ROUGHNESS_AT], 1.0)
        return t * value, p, transmitted
    return 0.0, 0.0, oz * wz < 0.0


@row
def _terms(params, m, table, ox, oy, oz, wx, wy, wz):
    """``f |wi.z|`` (r, g, b), density, diffuse part (r, g, b), transmitted part (r, g, b)."""
    p_coat, p_sheen, p_interface, p_spec, p_diffuse = _probabilities(params, m, table, ox, oy, oz)
    k, coat, coat_pdf = _coat(params, m, ox, oy, oz, wx, wy, wz)
    hx, hy, hz = ox + wx, oy + wy, oz + wz
    length = math.sqrt((hx * hx + hy * hy) + hz * hz)
    sr, sg, sb, scale = _sheen_terms(params, m, table, oz, wz, hz / length if length > 0.0 else 0.0)
    if not oz > 0.0:
        scale = 1.0  # seen from inside: the interface alone
    fr = fg = fb = dr = dg = db = tr = tg = tb = 0.0
    pdf = 0.0
    if (oz > 0.0) & (wz > 0.0):
        br, bg, bb, dr, dg, db, spec_pdf = _base(params, m, ox, oy, oz, wx, wy, wz)
        fr, fg, fb = sr * wz + scale * br, sg * wz + scale * bg, sb * wz + scale * bb
        dr, dg, db = scale * dr, scale * dg, scale * db
        pdf = p_sheen * wz / math.pi + p_spec * spec_pdf + p_diffuse * wz / math.pi
    value, p, transmitted = _interface(params, m, table, ox, oy, oz, wx, wy, wz)
    if value > 0.0:
        if transmitted:
            tr, tg, tb = scale * value * params[m, BASE_AT], scale * value * params[m, BASE_AT + 1], \
                scale * value * params[m, BASE_AT + 2]
            fr, fg, fb = fr + tr, fg + tg, fb + tb
        elif oz < 0.0:
            # reflected inside; outside the specular layer is the interface's reflection
            # (rtmesh.materials.gltf_pbr: counted once)
            fr, fg, fb = fr + scale * value, fg + scale * value, fb + scale * value
    pdf += p_interface * p
    # the coat over everything
    keep = 1.0 - k
    fr, fg, fb = keep * fr, keep * fg, keep * fb
    if wz > 0.0:  # a coat normal bent past the shading normal reflects nothing below the latter
        fr, fg, fb = fr + k * coat * wz, fg + k * coat * wz, fb + k * coat * wz
    pdf += p_coat * coat_pdf
    return fr, fg, fb, pdf, keep * dr, keep * dg, keep * db, keep * tr, keep * tg, keep * tb


# ------------------------------------------------------------------ the seam's rows
@row
def evaluate(params, m, table, ox, oy, oz, wx, wy, wz):
    """``f |wi.z|`` (r, g, b) and the density of :func:`sample`."""
    fr, fg, fb, pdf, _, _, _, _, _, _ = _terms(params, m, table, ox, oy, oz, wx, wy, wz)
    return fr, fg, fb, pdf


@row
def _reflect_about(ox, oy, oz, nx, ny, nz, u1, u2, at, ab, ax, ay):
    """``wo`` reflected about a GGX visible normal drawn in the frame of normal ``n`` whose
    tangent is the local direction ``(ax, ay)`` projected (widths ``at`` along it, ``ab`` across)."""
    tx, ty, tz, sx, sy, sz = tangent_frame(nx, ny, nz)
    # the anisotropy direction in n's tangent plane (n = z in the base's own use: exact)
    ux, uy = (tx * ax + ty * ay), (sx * ax + sy * ay)
    length = math.sqrt(ux * ux + uy * uy)
    if length > 0.0:
        ux, uy = ux / length, uy / length
    else:
        ux, uy = 1.0, 0.0
    vx0 = (tx * ox + ty * oy) + tz * oz
    vy0 = (sx * ox + sy * oy) + sz * oz
    vz = (nx * ox + ny * oy) + nz * oz
    vx, vy = _to_anisotropy(vx0, vy0, ux, uy)
    hx, hy, hz = sample_visible_normal_anisotropic(vx, vy, vz, at, ab, u1, u2)
    # back to n's frame, then to the local frame
    gx, gy = hx * ux - hy * uy, hx * uy + hy * ux
    c = 2.0 * ((vx0 * gx + vy0 * gy) + vz * hz)
    lx, ly, lz = c * gx - vx0, c * gy - vy0, c * hz - vz
    return (lx * tx + ly * sx) + lz * nx, (lx * ty + ly * sy) + lz * ny, (lx * tz + ly * sz) + lz * nz


@row
def sample(params, m, table, ox, oy, oz, u0, u1, u2):
    """Draw ``wi``: ``(wx, wy, wz, weight r, g, b, pdf, flags)``."""
    p_coat, p_sheen, p_interface, p_spec, p_diffuse = _probabilities(params, m, table, ox, oy, oz)
    if u0 < p_coat:
        r = params[m, CLEARCOAT_ROUGHNESS_AT]
        alpha = max(r * r, MIN_ALPHA)
        wx, wy, wz = _reflect_about(ox, oy, oz, params[m, COAT_NORMAL_AT], params[m, COAT_NORMAL_AT + 1],
                                    params[m, COAT_NORMAL_AT + 2], u1, u2, alpha, alpha, 1.0, 0.0)
        flags = lobes.GLOSSY
    elif u0 < p_coat + p_sheen:
        wx, wy, wz = square_to_cosine_hemisphere_row(u1, u2)
        flags = lobes.GLOSSY
    elif u0 < p_coat + p_sheen + p_interface or not oz > 0.0:
        if not p_interface > 0.0:
            return 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, lobes.FAILED
        u = min((u0 - p_coat - p_sheen) / p_interface, 1.0)
        wx, wy, wz, weight, pdf, flags = dielectric.sample_interface(table, ox, oy, oz, u, u1, u2,
                                                                     params[m, IOR_AT], params[m, ROUGHNESS_AT], 1.0)
        if flags & lobes.DELTA or flags == lobes.FAILED:
            # a smooth interface: its delta lobes, weighed by the layers over it and the choice
            k, _, _ = _coat(params, m, ox, oy, oz, wx, wy, wz)
            _, _, _, scale = _sheen_terms(params, m, table, oz, wz, 0.0)
            if not oz > 0.0:
                scale = 1.0
            weight *= (1.0 - k) * scale * _interface_weight(params, m, oz) / p_interface
            if flags & lobes.TRANSMISSION:
                return (wx, wy, wz, weight * params[m, BASE_AT], weight * params[m, BASE_AT + 1],
                        weight * params[m, BASE_AT + 2], pdf * p_interface, flags)
            if oz < 0.0:
                return wx, wy, wz, weight, weight, weight, pdf * p_interface, flags
            return wx, wy, wz, 0.0, 0.0, 0.0, 0.0, lobes.FAILED
    elif u0 < p_coat + p_sheen + p_interface + p_spec:
        at, ab, ax, ay = _widths(params, m)
        wx, wy, wz = _reflect_about(ox, oy, oz, 0.0, 0.0, 1.0, u1, u2, at, ab, ax, ay)
        flags = lobes.GLOSSY
    else:
        wx, wy, wz = square_to_cosine_hemisphere_row(u1, u2)
        flags = lobes.DIFFUSE
    fr, fg, fb, pdf = evaluate(params, m, table, ox, oy, oz, wx, wy, wz)
    return lobes.mixture_sample(wx, wy, wz, fr, fg, fb, pdf, flags, oz)


@row
def parts(params, m, table, ox, oy, oz, wx, wy, wz):
    """The diffuse and transmitted parts of ``f |cos|`` (light-path passes): the base's
    Lambert term and what the transmission interface lets through, under the layers above."""
    _, _, _, _, dr, dg, db, tr, tg, tb = _terms(params, m, table, ox, oy, oz, wx, wy, wz)
    return dr, dg, db, tr, tg, tb


@row
def albedo(params, m):
    """The base colour, for the denoiser's guide."""
    return params[m, BASE_AT], params[m, BASE_AT + 1], params[m, BASE_AT + 2]
