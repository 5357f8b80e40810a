"""The tile of blue-noise thresholds that 8-bit output is dithered with.

:mod:`rtmesh.io.images` quantises with it, but the io layer sits below sampling, so the tile
is made here, from the ``zsobol`` sampler, and ships with io as data
(``rtmesh/io/dither_tile.npy``, written by ``python -m rtmesh.sampling.dither_tile``);
a test checks that the shipped tile is what :func:`blue_noise_tile` computes.
"""

import numpy as np

from rtmesh.io.images import DITHER_TILE, DITHER_TILE_PATH
from rtmesh.sampling.patterns import Dim, stratified_values


def blue_noise_tile(size=DITHER_TILE):
    """Blue-noise dither thresholds: a (size, size) float64 tile of values in [0, 1).

    The ``zsobol`` sampler's values of one dimension (:attr:`Dim.DITHER`, seed 0) at one
    sample a pixel: every aligned 2x2, 4x4 ... block of the tile holds one value in each of
    its 4, 16 ... equal parts of [0, 1), in a random order (Ahmed & Wonka 2020's screen-space
    blue noise), so neighbouring pixels round in complementary directions and the
    quantisation error moves to high spatial frequencies.

    Parameters
    ----------
    size : int
        A power of two.

    Returns
    -------
    (size, size) float64
    """
    pixel = np.arange(size * size)
    values = stratified_values("zsobol", 0, pixel, np.zeros_like(pixel), 1, Dim.DITHER, resolution=(size, size))
    return values.reshape(size, size)


if __name__ == "__main__":
    np.save(DITHER_TILE_PATH, blue_noise_tile())
