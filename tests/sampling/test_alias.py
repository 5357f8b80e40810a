"""Alias tables: items drawn in proportion to their weights, and the remapped number that
lets one uniform number pick an item and then sample it."""

import numba
import numpy as np
from scipy import stats

from rtmesh.sampling.alias import alias_sample, alias_sample_remapped, alias_table


@numba.njit
def _draw(probability, alias, us):
    items = np.empty(len(us), np.int64)
    plain = np.empty(len(us), np.int64)
    remapped = np.empty(len(us))
    for k in range(len(us)):
        items[k], remapped[k] = alias_sample_remapped(probability, alias, us[k])
        plain[k] = alias_sample(probability, alias, us[k])
    return items, plain, remapped


def test_the_remapped_draw_picks_as_the_plain_one_and_its_number_is_uniform_within_the_item():
    weights = np.array([0.5, 3.0, 0.0, 1.5, 2.0, 0.25])
    probability, alias, pmf = alias_table(weights)
    us = (np.arange(60_000) + 0.5) / 60_000  # a stratified set of [0, 1)
    items, plain, remapped = _draw(probability, alias, us)
    assert np.array_equal(items, plain)
    # each item in proportion to its weight (exactly, for a stratified set: up to one stratum per column)
    counts = np.bincount(items, minlength=len(weights))
    np.testing.assert_allclose(counts / len(us), pmf, atol=2 * len(weights) / len(us))
    assert counts[2] == 0
    # within each item the remapped numbers stay in [0, 1) and are uniform there
    assert remapped.min() >= 0.0 and remapped.max() < 1.0
    for item in np.flatnonzero(counts):
        assert stats.kstest(remapped[items == item], "uniform").pvalue > 1e-3
    # a single item keeps the number as it is (a light alone in its group samples as before)
    one_probability, one_alias, _ = alias_table(np.array([2.0]))
    _, _, kept = _draw(one_probability, one_alias, us[:100])
    assert np.array_equal(kept, us[:100])
