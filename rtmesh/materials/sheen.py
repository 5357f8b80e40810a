"""The sheen lobe of KHR_materials_sheen: the "Charlie" microfibre distribution and visibility
of Estevez and Kulla (2017, "Production Friendly Microfacet Sheen BRDF"), as the extension's
implementation notes give them, and its directional albedo ``E`` (tabulated, shipped as
``sheen_albedo.npy``) for the albedo scaling of the layer below.

Model
-----
With ``alpha = r^2`` (``r`` the sheen roughness), ``h = normalize(wo + wi)``::

    D(h)   = (2 + 1 / alpha) sin(theta_h)^(1 / alpha) / (2 pi)
    V      = 1 / ((1 + Lambda(mu_o) + Lambda(mu_i)) 4 mu_o mu_i)
    Lambda(mu) = exp(l(mu))                       mu < 0.5
               = exp(2 l(0.5) - l(1 - mu))        otherwise
    l(x)   = a / (1 + b x^c) + d x + e,  (a, b, c, d, e) interpolated in (1 - alpha)^2
    f_sheen = sheenColor D V

and the layer over a base BRDF ``f_base``::

    f = f_sheen + f_base min(1 - max3(sheenColor) E(mu_o), 1 - max3(sheenColor) E(mu_i))

(the extension's albedo scaling, symmetric in ``wo`` and ``wi``: the layered BRDF stays
reciprocal).  ``E(mu, r) = int D V mu_i dwi`` is the lobe's directional albedo for a white
sheen colour.

The table is :data:`ROUGHNESS_CELLS` x :data:`MU_CELLS` values on grids including both ends
of ``mu`` and ``r`` in [0, 1], made by :func:`tabulate` (``python -m rtmesh.materials.sheen``
writes it again); a test recomputes it and compares.
"""

import math
import os

import numpy as np

from rtmesh.core.compiled import kernel, row
from rtmesh.materials import lobes

# Below this roughness the distribution's exponent 1 / r^2 exceeds ~200: the lobe is a thin
# rim at grazing angles that a pixel cannot resolve, and pow(sin, 1 / alpha) of sampled
# directions underflows to 0 over most of the sphere.  The Khronos sample viewer floors it
# too (its lookup tables start at a small roughness).
MIN_ROUGHNESS = 0.07

MU_CELLS = 32
ROUGHNESS_CELLS = 32
# QUADRATURE^2 midpoint cells (uniform in cos theta_i and phi) per table entry
QUADRATURE = 256
TABLE_PATH = os.path.join(os.path.dirname(__file__), "sheen_albedo.npy")


@row
def sheen_alpha(roughness):
    """The distribution's ``alpha = r^2`` of a sheen roughness, ``r`` floored at :data:`MIN_ROUGHNESS`."""
    r = max(roughness, MIN_ROUGHNESS)
    return r * r


@row
def distribution(cos_h, alpha):
    """Charlie ``D(h)`` per unit projected area; ``cos_h = n.h``."""
    sin2 = max(0.0, 1.0 - cos_h * cos_h)
    inv = 1.0 / alpha
    return (2.0 + inv) * sin2 ** (0.5 * inv) / (2.0 * math.pi)


@row
def _l(x, alpha):
    """The fitted exponent of Lambda (Estevez and Kulla's table, interpolated)."""
    t = (1.0 - alpha) * (1.0 - alpha)
    a = 21.5473 + (25.3245 - 21.5473) * t
    b = 3.82987 + (3.32435 - 3.82987) * t
    c = 0.19823 + (0.16801 - 0.19823) * t
    d = -1.97760 + (-1.27393 + 1.97760) * t
    e = -4.32054 + (-4.85967 + 4.32054) * t
    return a / (1.0 + b * x ** c) + d * x + e


@row
def sheen_lambda(mu, alpha):
    """Charlie's ``Lambda(mu)``, mirrored about ``mu = 0.5`` as the fit prescribes."""
    mu = abs(mu)
    if mu < 0.5:
        return math.exp(_l(mu, alpha))
    return math.exp(2.0 * _l(0.5, alpha) - _l(1.0 - mu, alpha))


@row
def brdf(mu_o, mu_i, cos_h, alpha):
    """``D V`` of a white sheen (per steradian), for ``mu_o, mu_i > 0``."""
    v = 1.0 / ((1.0 + sheen_lambda(mu_o, alpha) + sheen_lambda(mu_i, alpha)) * (4.0 * mu_o * mu_i))
    return distribution(cos_h, alpha) * v


@kernel
def _albedo_at(mu, alpha, cells):
    """``E(mu)`` by the midpoint rule over ``cells^2`` cells of (cos theta_i, phi); ``wo`` in
    the xz plane."""
    ox, oz = math.sqrt(max(0.0, 1.0 - mu * mu)), mu
    total = 0.0
    for a in range(cells):
        wz = (a + 0.5) / cells
        s = math.sqrt(max(0.0, 1.0 - wz * wz))
        for b in range(cells):
            phi = 2.0 * math.pi * (b + 0.5) / cells
            wx, wy = s * math.cos(phi), s * math.sin(phi)
            hx, hy, hz = ox + wx, wy, oz + wz
            inv = 1.0 / math.sqrt(hx * hx + hy * hy + hz * hz)
            total += brdf(oz, wz, hz * inv, alpha) * wz
    return total * 2.0 * math.pi / (cells * cells)


@kernel
def tabulate(mu_cells, roughness_cells, cells, rows, columns):
    """Entries of the table of ``E(mu, r)`` (``mu`` 0 taken as 1e-4, ``r`` floored at
    :data:`MIN_ROUGHNESS`).

    Parameters
    ----------
    mu_cells, roughness_cells : int
        Grid points over ``mu`` and ``r``, both ends included.
    cells : int
        ``cells^2`` quadrature cells per value.
    rows, columns : (a,) int64, (b,) int64
        The roughness rows and ``mu`` columns of the grid wanted: all of them
        (``np.arange``) for the shipped table, a few to check its entries.

    Returns
    -------
    (a, b) float64
        Dimensionless albedos in [0, 1].
    """
    table = np.zeros((len(rows), len(columns)))
    for a in range(len(rows)):
        alpha = sheen_alpha(rows[a] / (roughness_cells - 1))
        for b in range(len(columns)):
            table[a, b] = _albedo_at(max(columns[b] / (mu_cells - 1), 1e-4), alpha, cells)
    return table


def table():
    """The shipped table, (ROUGHNESS_CELLS, MU_CELLS) float64 (read once)."""
    return lobes.shipped_table(TABLE_PATH)


@row
def albedo(albedo_table, mu, roughness):
    """``E(mu, r)`` of a white sheen, bilinear on the grid."""
    return lobes.bilinear(albedo_table, abs(mu), roughness, albedo_table.shape[1])


if __name__ == "__main__":
    np.save(TABLE_PATH, tabulate(MU_CELLS, ROUGHNESS_CELLS, QUADRATURE, np.arange(ROUGHNESS_CELLS), np.arange(MU_CELLS)))
