"""What a render returns: the image, its passes, statistics and the film."""

from dataclasses import dataclass

import numpy as np

from rtmesh.rendering.film import Film
from rtmesh.rendering.stats import RenderStats


@dataclass
class RenderResult:
    """Output of :func:`render`.

    Attributes
    ----------
    image : (height, width, 3) float32
        Linear radiance, row 0 at the top.
    passes : dict of str to (height, width, k) float32
        Requested extra passes (see :mod:`rtmesh.io.passes`).
    stats : RenderStats
    film : Film
        The accumulation buffers (sums, sums of squares) for error estimates.
    alpha : (height, width, 1) float32 or None
        Coverage, when the background is transparent (``image`` is then premultiplied).
    noisy : (height, width, 3) float32 or None
        With ``denoise``, the image before denoising (``image`` is the denoised one; the
        film's error estimate describes this one).
    """

    image: np.ndarray
    passes: dict
    stats: RenderStats
    film: Film
    alpha: np.ndarray | None = None
    noisy: np.ndarray | None = None
