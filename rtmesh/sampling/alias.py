"""Choosing one of many items in proportion to a weight in constant time: Walker's alias
method, with Vose's construction (numerically stable).

The path integrator chooses a light per vertex this way (lights by power), so a scene with
a hundred thousand emissive triangles costs one table lookup per choice.
"""

import numpy as np

from rtmesh.core.compiled import kernel, row


@kernel
def _vose(weights):
    n = len(weights)
    probability = np.zeros(n)
    alias = np.arange(n)
    total = 0.0
    for w in weights:
        total += w
    scaled = weights * (n / total)
    small = np.empty(n, np.int64)
    large = np.empty(n, np.int64)
    ns = nl = 0
    for i in range(n):
        if scaled[i] < 1.0:
            small[ns] = i
            ns += 1
        else:
            large[nl] = i
            nl += 1
    while ns > 0 and nl > 0:
        ns -= 1
        s = small[ns]
        nl -= 1
        g = large[nl]
        probability[s] = scaled[s]
        alias[s] = g
        scaled[g] = (scaled[g] + scaled[s]) - 1.0
        if scaled[g] < 1.0:
            small[ns] = g
            ns += 1
        else:
            large[nl] = g
            nl += 1
    # what is left is 1 up to rounding
    for k in range(nl):
        probability[large[k]] = 1.0
    for k in range(ns):
        probability[small[k]] = 1.0
    return probability, alias


def alias_table(weights):
    """The alias table of non-negative weights (not all zero).

    Parameters
    ----------
    weights : (n,) float

    Returns
    -------
    probability : (n,) float64
        Probability of keeping column ``i`` rather than taking its alias.
    alias : (n,) int64
    pmf : (n,) float64
        ``weights / sum(weights)``, the probability of each item.
    """
    weights = np.ascontiguousarray(weights, dtype=np.float64)
    if not len(weights):
        return np.zeros(0), np.zeros(0, np.int64), np.zeros(0)
    probability, alias = _vose(weights)
    return probability, alias, weights / weights.sum()


@row
def alias_sample(probability, alias, u):
    """The item chosen by a uniform ``u`` in [0, 1) (one number: column and coin from it)."""
    n = len(probability)
    x = u * n
    column = min(int(x), n - 1)
    return column if x - column < probability[column] else alias[column]


# the largest float64 below 1: a remapped number stays in [0, 1) despite rounding
_ONE_MINUS_EPSILON = 1.0 - 2.0 ** -53


@row
def alias_sample_remapped(probability, alias, u):
    """The item chosen by a uniform ``u`` in [0, 1), as :func:`alias_sample`, and ``u``
    rescaled to [0, 1) within the part of [0, 1) that chose it (as pbrt-v4's
    ``AliasTable::Sample``): one number picks an item and then serves again, so the
    stratification of a point set carries over to the chosen item's own sampling.

    Returns
    -------
    item : int
    u_remapped : float
    """
    n = len(probability)
    x = u * n
    column = min(int(x), n - 1)
    coin = x - column
    keep = probability[column]
    if coin < keep:
        return column, min(coin / keep, _ONE_MINUS_EPSILON)
    return alias[column], min((coin - keep) / (1.0 - keep), _ONE_MINUS_EPSILON)
