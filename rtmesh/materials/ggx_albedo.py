"""The directional albedo of single-scattering GGX reflection, tabulated, for the energy
compensation of rough conductors (Kulla and Conty 2017, "Revisiting Physically Based
Shading at Imageworks").

``E(mu, r)`` is the fraction of light a white (``F = 1``) GGX microsurface of roughness
``r`` (``alpha = r^2``) reflects in a single scattering event when lit from ``mu = cos
theta``; ``E_avg(r) = 2 int E mu dmu``.  Single scattering loses ``1 - E`` (up to 69 % at
``r = 1``, normal incidence); the compensation lobe

    f_ms(wo, wi) = (1 - E(mu_o)) (1 - E(mu_i)) / (pi (1 - E_avg)) F_ms,
    F_ms = F_avg^2 E_avg / (1 - F_avg (1 - E_avg)),  F_avg = F0 + (1 - F0) / 21 (Schlick)

returns it: with ``F = 1`` the sum reflects exactly 1 at every angle.

The table ships with the package (``ggx_albedo.npy``, :data:`ROUGHNESS_CELLS` x :data:`MU_CELLS`
grid points plus the ``E_avg`` column), made by :func:`tabulate` (``python -m rtmesh.materials.ggx_albedo``
writes it again); a test recomputes it and compares.
"""

import math
import os

import numpy as np

from rtmesh.core.compiled import kernel, row
from rtmesh.materials import lobes
from rtmesh.materials.microfacet import SMOOTH_ALPHA, masking, masking_shadowing, sample_visible_normal

MU_CELLS = 32
ROUGHNESS_CELLS = 32
# STRATA^2 stratified samples per table entry
STRATA = 64
TABLE_PATH = os.path.join(os.path.dirname(__file__), "ggx_albedo.npy")


@kernel
def _albedo_at(mu, alpha, strata):
    """``E`` at one ``(mu, alpha)`` by stratified visible-normal sampling: the weight of a
    sample is ``G2 / G1(wo)`` (``F = 1``), 0 below the horizon."""
    ox, oz = math.sqrt(max(0.0, 1.0 - mu * mu)), mu
    total = 0.0
    for a in range(strata):
        for b in range(strata):
            hx, hy, hz = sample_visible_normal(ox, 0.0, oz, alpha, (a + 0.5) / strata, (b + 0.5) / strata)
            c = 2.0 * (ox * hx + oz * hz)
            wz = c * hz - oz
            if wz > 0.0:
                total += masking_shadowing(oz, wz, alpha) / masking(oz, alpha)
    return total / (strata * strata)


@kernel
def tabulate(mu_cells, roughness_cells, strata):
    """The table: ``E`` on a grid including both ends of ``mu`` and ``r`` in [0, 1]
    (``mu`` 0 is taken as 1e-4), and ``E_avg`` in the last column (midpoint rule over 64
    values of ``mu``).

    Parameters
    ----------
    mu_cells, roughness_cells : int
        Grid points over ``mu`` and ``r``.
    strata : int
        ``strata^2`` samples per value.

    Returns
    -------
    (roughness_cells, mu_cells + 1) float64
    """
    table = np.zeros((roughness_cells, mu_cells + 1))
    for j in range(roughness_cells):
        r = j / (roughness_cells - 1)
        alpha = max(r * r, SMOOTH_ALPHA)
        for i in range(mu_cells):
            table[j, i] = _albedo_at(max(i / (mu_cells - 1), 1e-4), alpha, strata)
        average = 0.0
        for i in range(64):
            mu = (i + 0.5) / 64
            average += 2.0 * _albedo_at(mu, alpha, strata) * mu / 64
        table[j, mu_cells] = average
    return table


def table():
    """The shipped table, (ROUGHNESS_CELLS, MU_CELLS + 1) float64 (read once)."""
    return lobes.shipped_table(TABLE_PATH)


@row
def albedo(albedo_table, mu, r):
    """``E(mu, r)``, bilinear on the grid (the last column, ``E_avg``, left out)."""
    return lobes.bilinear(albedo_table, mu, r, albedo_table.shape[1] - 1)


@row
def average_albedo(albedo_table, r):
    """``E_avg(r)``, linear on the grid."""
    j, fr = lobes.grid_cell(r, albedo_table.shape[0])
    last = albedo_table.shape[1] - 1
    return albedo_table[j, last] * (1.0 - fr) + albedo_table[j + 1, last] * fr


if __name__ == "__main__":
    np.save(TABLE_PATH, tabulate(MU_CELLS, ROUGHNESS_CELLS, STRATA))
