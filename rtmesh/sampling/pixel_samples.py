"""Pixel sample positions in compiled code: the twin of :func:`rtmesh.sampling.patterns.pixel_offsets`
for kernels that make camera rays.

The arithmetic is that of :mod:`rtmesh.sampling.patterns` and :mod:`rtmesh.sampling.hashing`, operation for
operation (64-bit integer hashing wraps in both; the float conversions and divisions are
the same), so a kernel that forms its positions here renders bit for bit what it would
render from positions formed by NumPy (tests/sampling/test_pixel_samples.py).  The Sobol samplers'
points come from the rows their NumPy paths call too (:func:`rtmesh.sampling.lowdiscrepancy.sobol_pair`,
:func:`rtmesh.sampling.zsobol.zsobol_pair`).
"""

import numpy as np

from rtmesh.core.compiled import kernel, row
from rtmesh.core.row_vectors import floor_quotient
from rtmesh.sampling.hashing import M1, mix64, pixel_sequence
from rtmesh.sampling.lowdiscrepancy import sobol_pair
from rtmesh.sampling.patterns import Dim, _cell_grids, dimension_key
from rtmesh.sampling.zsobol import block_bits, check_layout, morton_code, zorder_levels, zsobol_pair

REGULAR, JITTERED, RANDOM, SOBOL, ZSOBOL = 0, 1, 2, 3, 4
SAMPLER_CODES = {"regular": REGULAR, "jittered": JITTERED, "random": RANDOM, "sobol": SOBOL, "zsobol": ZSOBOL}
# what PixelSampler.keys holds after the two dimension keys: the zsobol layout
WIDTH, LEVELS, LOG2_SPP = 2, 3, 4
_ONE = np.uint64(1)
_TO_UNIT = 1.0 / 9007199254740992.0  # 2 ** -53: the top 53 bits as a double in [0, 1)


class PixelSampler:
    """What :func:`sample_positions` needs for one render's sampler, formed once.

    Parameters
    ----------
    sampler : {"regular", "jittered", "random", "sobol", "zsobol"}
    seed : int
    spp : int
        Samples per stratified set (the render's samples per pixel).
    resolution : (int, int), optional
        Image width and height (``zsobol`` needs them).

    Attributes
    ----------
    code : int
        :data:`REGULAR`, :data:`JITTERED`, :data:`RANDOM`, :data:`SOBOL` or :data:`ZSOBOL`.
    spp : int
    keys : (5,) uint64
        The seed's key of the two pixel dimensions (``Dim.PIXEL`` and the next), before
        the pixel is mixed in (see :func:`rtmesh.sampling.patterns.sequence_key`); Sobol
        and zsobol take both coordinates from the first.  Then zsobol's layout: the image
        width, :func:`rtmesh.sampling.zsobol.zorder_levels` and ``log2(spp)`` (at
        :data:`WIDTH`, :data:`LEVELS`, :data:`LOG2_SPP`; zeros for the other samplers).
    corners : (spp, 2) float64
        Column and row of each stratum (jittered), or the stratum centres already divided
        by the grid size (regular).
    size : (2,) float64
        Strata per row and per column.
    """

    def __init__(self, sampler, seed, spp, resolution=None):
        self.code = SAMPLER_CODES[sampler]
        self.spp = int(spp)
        layout = [0, 0, 0]
        if self.code == ZSOBOL:
            if resolution is None:
                raise ValueError("the zsobol sampler needs the image resolution")
            check_layout(*resolution, self.spp)
            layout = [resolution[0], zorder_levels(*resolution), block_bits(self.spp)]
        self.keys = np.array([dimension_key(seed, d) for d in (Dim.PIXEL, Dim.PIXEL + 1)] + layout, dtype=np.uint64)
        (cx, cy), (sx, sy), table = _cell_grids(1, self.spp, 2)
        self.size = np.array([cx * sx, cy * sy], dtype=np.float64)
        table = np.ascontiguousarray(table)
        # regular: as rtmesh.sampling.patterns._stratified forms the stratum centres
        self.corners = np.ascontiguousarray((table + 0.5) / self.size) if self.code == REGULAR else table

    @classmethod
    def for_settings(cls, settings):
        """The sampler of ``settings``."""
        return cls(settings.sampler, settings.seed, settings.spp, (settings.width, settings.height))


@row
def pixel_keys(code, keys, pixel):
    """What :func:`sample_positions` needs of one pixel (uint64), which a kernel forms once
    per pixel: the pixel's sequence keys of the two pixel dimensions
    (:func:`rtmesh.sampling.hashing.pixel_sequence`), or under zsobol its Morton code (and 0)."""
    if code == ZSOBOL:
        return morton_code(np.uint64(pixel), keys[WIDTH]), np.uint64(0)
    return pixel_sequence(keys[0], pixel), pixel_sequence(keys[1], pixel)


@row
def sequence_uniform(sequence, sample):
    """Sample ``sample`` (uint64) of a pixel's sequence (:func:`rtmesh.sampling.hashing.pixel_sequence`): a uniform
    number in [0, 1) with 53 random bits.  Branch-free, so loops over samples vectorise."""
    x = mix64(sequence ^ (sample * M1 + _ONE))
    return np.float64(x >> np.uint64(11)) * _TO_UNIT


@row
def stratum_of(sample, spp, inverse_spp):
    """``sample % spp`` (uint64 ``sample``; ``inverse_spp`` is ``1.0 / spp``): the sample's
    stratum, 0 for one sample per pixel, without an integer division."""
    i = np.int64(sample)
    return i - floor_quotient(i, spp, inverse_spp) * spp


@row
def sample_positions(code, keys, corners, size, spp, sample, sequence, count, xy):
    """Writes into ``xy`` (2, m) the positions of samples ``0 .. count - 1`` in their pixels:
    offsets ``(x, y)`` in [0, 1)^2 from the pixel's top-left corner, as
    :func:`rtmesh.sampling.patterns.pixel_offsets` gives them.

    Parameters
    ----------
    code, keys, corners, size, spp
        The :class:`PixelSampler`'s.
    sample : (m,) uint64
        Each sample's index in its pixel.
    sequence : (2, m) uint64
        Its pixel's :func:`pixel_keys`, which a kernel forms once per pixel.
    count : int
    xy : (2, m) float64

    Notes
    -----
    Each loop is branch-free and has no integer division, so LLVM vectorises the hashing;
    the strata's corners (regular: their centres) are read in a loop of their own, as their
    gathers would keep the hashing from vectorising.
    """
    if code == RANDOM:
        for b in range(count):
            xy[0, b] = sequence_uniform(sequence[0, b], sample[b])
            xy[1, b] = sequence_uniform(sequence[1, b], sample[b])
        return
    if code == SOBOL:  # the pixel's points of its (0,2)-sequence (rays = 1: index = sample)
        for b in range(count):
            xy[0, b], xy[1, b] = sobol_pair(sequence[0, b], sample[b])
        return
    if code == ZSOBOL:  # the pixel's block of the image's sequence (rays = 1)
        key, levels, log2_spp = keys[0], keys[LEVELS], keys[LOG2_SPP]
        for b in range(count):
            xy[0, b], xy[1, b] = zsobol_pair(key, sequence[0, b], sample[b], np.uint64(0), log2_spp, np.uint64(1),
                                             levels, log2_spp)
        return
    inverse_spp = 1.0 / spp
    for b in range(count):
        stratum = stratum_of(sample[b], spp, inverse_spp)
        xy[0, b], xy[1, b] = corners[stratum, 0], corners[stratum, 1]
    if code != REGULAR:
        s0, s1 = size[0], size[1]
        for b in range(count):
            xy[0, b] = (xy[0, b] + sequence_uniform(sequence[0, b], sample[b])) / s0
            xy[1, b] = (xy[1, b] + sequence_uniform(sequence[1, b], sample[b])) / s1


@kernel
def pixel_positions(code, keys, corners, size, spp, pixel, sample):
    """:func:`sample_positions` of samples given by pixel and index, (n, 2) float64.

    Parameters
    ----------
    code, keys, corners, size, spp
        The :class:`PixelSampler`'s.
    pixel, sample : (n,) int
        Each sample's pixel (linear index) and index in it.
    """
    n = len(pixel)
    sequence = np.empty((2, n), np.uint64)
    index = np.empty(n, np.uint64)
    for i in range(n):
        sequence[0, i], sequence[1, i] = pixel_keys(code, keys, pixel[i])
        index[i] = np.uint64(sample[i])
    xy = np.empty((2, n))
    sample_positions(code, keys, corners, size, spp, index, sequence, n, xy)
    return xy.T
