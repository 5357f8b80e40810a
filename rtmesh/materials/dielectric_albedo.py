"""The energy a rough dielectric interface scatters in one event, tabulated, for the energy
compensation of rough glass.

Single-scattering GGX transmission and reflection (:mod:`rtmesh.materials.dielectric`) lose
the light that would leave the microsurface after bouncing between microfacets, most of it
under total internal reflection: inside a glass sphere of roughness 0.5 in a white furnace,
where trapped paths meet the interface again and again, 18 % of the light was lost.

``E(mu, r, eta, side)`` is the fraction of the energy arriving from ``mu = |cos theta|`` on
the ``side`` (0: outside, 1: inside) of an interface of index ratio ``eta`` and roughness
``r`` that a single scattering event reflects or transmits (transmitted radiance counted
without its ``1 / eta'^2``: energy, not radiance).  With a visible normal ``h`` drawn for
``wo``, both events have the weight ``G2 / G1(wo)``, so

    E = E_h[ F(wo.h) G2(wo, wi_R) / G1(wo) [wi_R valid] + (1 - F(wo.h)) G2(wo, wi_T) / G1(wo) [wi_T valid] ]

(the reflected and refracted directions about ``h``; a direction on the wrong side is a lost
event).  The compensation divides the interface's BSDF by ``E(mu_o)`` (Turquin 2019's
energy-preserving scaling): every event then conserves energy exactly and a closed rough
glass object vanishes in a white furnace, at the price of reciprocity (``f(wo, wi) / E(mu_o)``
is not symmetric; the tests check reciprocity of the uncompensated interface).

The table ships with the package (``dielectric_albedo.npy``), made by :func:`tabulate`
(``python -m rtmesh.materials.dielectric_albedo`` writes it again); a test recomputes it.
"""

import math
import os

import numpy as np

from rtmesh.core.compiled import kernel, row
from rtmesh.materials import lobes
from rtmesh.materials.microfacet import SMOOTH_ALPHA, masking, masking_shadowing, sample_visible_normal

# grid points: |cos theta| and roughness from 0 to 1, and index ratios from ETA_MIN to
# ETA_MAX evenly in log(eta)
MU_POINTS = 16
ROUGHNESS_POINTS = 16
ETA_POINTS = 12
ETA_MIN, ETA_MAX = 1.01, 3.0
STRATA = 32
TABLE_PATH = os.path.join(os.path.dirname(__file__), "dielectric_albedo.npy")


@row
def _eta_at(k):
    return math.exp(math.log(ETA_MIN) + (math.log(ETA_MAX) - math.log(ETA_MIN)) * k / (ETA_POINTS - 1))


@kernel
def _albedo_at(mu, alpha, eta, inside, strata):
    """``E`` at one point of the grid (see the module notes)."""
    oz = max(mu, 1e-4)
    ox = math.sqrt(max(0.0, 1.0 - oz * oz))
    if inside:
        oz = -oz
    total = 0.0
    for a in range(strata):
        for b in range(strata):
            hx, hy, hz = sample_visible_normal(ox, 0.0, oz, alpha, (a + 0.5) / strata, (b + 0.5) / strata)
            o_dot_h = ox * hx + oz * hz
            f = lobes.fresnel_dielectric(o_dot_h, eta)
            g1 = masking(oz, alpha)
            c = 2.0 * o_dot_h
            rz = c * hz - oz
            if oz * rz > 0.0:
                total += f * masking_shadowing(oz, rz, alpha) / g1
            tx, ty, tz, _, ok = lobes.refract(ox, 0.0, oz, hx, hy, hz, eta)
            if ok and oz * tz < 0.0:
                total += (1.0 - f) * masking_shadowing(oz, tz, alpha) / g1
    return total / (strata * strata)


@kernel
def tabulate(strata):
    """The table, (2, ETA_POINTS, ROUGHNESS_POINTS, MU_POINTS) float64: side (outside,
    inside), index ratio, roughness, ``|cos theta|``."""
    table = np.ones((2, ETA_POINTS, ROUGHNESS_POINTS, MU_POINTS))
    for side in range(2):
        for k in range(ETA_POINTS):
            eta = _eta_at(k)
            for j in range(ROUGHNESS_POINTS):
                r = j / (ROUGHNESS_POINTS - 1)
                alpha = max(r * r, SMOOTH_ALPHA)
                for i in range(MU_POINTS):
                    table[side, k, j, i] = _albedo_at(i / (MU_POINTS - 1), alpha, eta, side == 1, strata)
    return table


def table():
    """The shipped table (read once)."""
    return lobes.shipped_table(TABLE_PATH)


@row
def albedo(albedo_table, mu, r, eta, inside):
    """``E`` at ``|cos theta| = mu``, roughness ``r``, index ratio ``eta`` (inside over
    outside), seen from inside or not: trilinear on the grid (``eta`` clamped to its range)."""
    side = 1 if inside else 0
    x = (math.log(min(max(eta, ETA_MIN), ETA_MAX)) - math.log(ETA_MIN)) / (math.log(ETA_MAX) - math.log(ETA_MIN))
    k, fk = lobes.grid_cell(x, ETA_POINTS)
    j, fj = lobes.grid_cell(r, ROUGHNESS_POINTS)
    i, fi = lobes.grid_cell(mu, MU_POINTS)
    out = 0.0
    for dk in range(2):
        wk = fk if dk else 1.0 - fk
        for dj in range(2):
            wj = fj if dj else 1.0 - fj
            low = albedo_table[side, k + dk, j + dj, i]
            high = albedo_table[side, k + dk, j + dj, i + 1]
            out += wk * wj * (low * (1.0 - fi) + high * fi)
    return out


@kernel
def _albedo_kernel(albedo_table, mu, r, eta, inside):
    return albedo(albedo_table, mu, r, eta, inside)


def albedo_of(mu, r, eta, inside):
    """:func:`albedo` of the shipped table, from Python (tests, documentation)."""
    return _albedo_kernel(table(), float(mu), float(r), float(eta), bool(inside))


if __name__ == "__main__":
    np.save(TABLE_PATH, tabulate(STRATA))
