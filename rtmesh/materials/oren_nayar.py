"""Energy-preserving Oren-Nayar (EON; Portsmouth, Kutz and Hill 2024, "EON: A practical
energy-preserving rough diffuse BRDF", the diffuse model of OpenPBR).

Model
-----
Fujii's Oren-Nayar (FON) single-scattering lobe plus a multiple-scattering lobe that gives
back what FON loses, so a white surface (``rho = 1``) reflects exactly 1 at every angle::

    A = 1 / (1 + c1 r),  c1 = 1/2 - 2 / (3 pi),  c2 = 2/3 - 28 / (15 pi)
    s = wi.wo - mu_i mu_o,  s/t = s / max(mu_i, mu_o) if s > 0 else s
    f_ss = rho / pi  A (1 + r s/t)
    E(mu) = A + (r A / pi) (S (acos mu - S mu) + 2/3 ((S / mu) (1 - S^3) - S)),  S = sqrt(1 - mu^2)
    E_avg = A (1 + c2 r)
    rho_ms = rho^2 E_avg / (1 - rho (1 - E_avg))
    f_ms = rho_ms / pi  (1 - E(mu_o)) (1 - E(mu_i)) / (1 - E_avg)

with ``r`` the roughness in [0, 1] (0 is Lambert).  ``E`` is the directional albedo of
``f_ss`` at ``rho = 1``, in closed form (the paper's "exact" variant).

Sampling is cosine-weighted (density ``mu_i / pi``); the weight ``f mu_i / pdf`` stays
bounded (at most ``1 + r`` times the albedo's largest channel).

Parameters: ``rho`` r, g, b, ``roughness``.
"""

import math

from rtmesh.core.compiled import row
from rtmesh.materials import lobes
from rtmesh.materials.metallic_roughness import square_to_cosine_hemisphere_row

NAME = "oren-nayar"
SLOTS = {"colour": 0}
_C1 = 0.5 - 2.0 / (3.0 * math.pi)
_C2 = 2.0 / 3.0 - 28.0 / (15.0 * math.pi)
# keeps the multiple-scattering lobe's divisions finite where FON's albedo reaches 1
_EPS = 1e-7


def parameters(material):
    """``rho`` (the diffuse colour) and ``roughness`` (the material's, clamped to [0, 1])."""
    return [float(c) for c in material.diffuse] + [min(max(float(material.roughness), 0.0), 1.0)]


@row
def fon_albedo(mu, r):
    """Directional albedo of the FON lobe for ``rho = 1`` at ``mu = cos(theta)`` (closed form)."""
    mu = min(max(mu, 1e-7), 1.0)
    a = 1.0 / (1.0 + _C1 * r)
    b = r * a
    s = math.sqrt(max(0.0, 1.0 - mu * mu))
    g = s * (math.acos(mu) - s * mu) + (2.0 / 3.0) * ((s / mu) * (1.0 - s * s * s) - s)
    return a + (b / math.pi) * g


@row
def _channel(rho, f_ss_factor, ms_factor, e_avg):
    rho_ms = rho * rho * e_avg / (1.0 - rho * (1.0 - e_avg))
    return rho * f_ss_factor + rho_ms * ms_factor


@row
def evaluate(params, m, table, ox, oy, oz, wx, wy, wz):
    """``f |wi.z|`` (r, g, b) and the cosine density (see :mod:`~rtmesh.materials.lobes`)."""
    if not ((oz > 0.0) & (wz > 0.0)):
        return 0.0, 0.0, 0.0, 0.0
    r = params[m, 3]
    s = (ox * wx + oy * wy + oz * wz) - wz * oz
    s_over_t = s / max(wz, oz) if s > 0.0 else s
    a = 1.0 / (1.0 + _C1 * r)
    e_avg = a * (1.0 + _C2 * r)
    ss = a * (1.0 + r * s_over_t) / math.pi * wz
    ms = (max(_EPS, 1.0 - fon_albedo(oz, r)) * max(_EPS, 1.0 - fon_albedo(wz, r))
          / max(_EPS, 1.0 - e_avg)) / math.pi * wz
    return (_channel(params[m, 0], ss, ms, e_avg), _channel(params[m, 1], ss, ms, e_avg),
            _channel(params[m, 2], ss, ms, e_avg), wz / math.pi)


@row
def sample(params, m, table, ox, oy, oz, u0, u1, u2):
    """A cosine-distributed ``wi`` with its weight ``f wi.z / pdf``."""
    if not oz > 0.0:
        return 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, lobes.FAILED
    wx, wy, wz = square_to_cosine_hemisphere_row(u1, u2)
    fr, fg, fb, pdf = evaluate(params, m, table, ox, oy, oz, wx, wy, wz)
    if not pdf > 0.0:
        return wx, wy, wz, 0.0, 0.0, 0.0, 0.0, lobes.FAILED
    return wx, wy, wz, fr / pdf, fg / pdf, fb / pdf, pdf, lobes.DIFFUSE


@row
def parts(params, m, table, ox, oy, oz, wx, wy, wz):
    """The diffuse and transmitted parts of ``f |cos|`` (light-path passes): all diffuse."""
    fr, fg, fb, _ = evaluate(params, m, table, ox, oy, oz, wx, wy, wz)
    return fr, fg, fb, 0.0, 0.0, 0.0


@row
def albedo(params, m):
    """``rho`` (the model's hemispherical albedo tends to it), for the denoiser's guide."""
    return params[m, 0], params[m, 1], params[m, 2]
