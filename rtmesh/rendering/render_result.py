"""What a render returns: the image, its passes, statistics and the film."""

from dataclasses import dataclass

import numpy as np

from rtmesh.io.images import write_image
from rtmesh.rendering.film import Film
from rtmesh.rendering.settings import RenderSettings
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
    settings : RenderSettings or None
        The settings the image was rendered with (:meth:`write` writes it by them).
    """

    image: np.ndarray
    passes: dict
    stats: RenderStats
    film: Film
    alpha: np.ndarray | None = None
    noisy: np.ndarray | None = None
    settings: RenderSettings | None = None

    def write(self, path):
        """Write the image as ``rtmesh render`` writes it
        (:func:`rtmesh.io.images.write_image`): EXR with the passes, the alpha channel and
        the settings in its header; PNG and JPEG with the settings' ``exposure``,
        ``tonemap`` and ``dither``.

        Parameters
        ----------
        path : str or os.PathLike
            ``.exr``, ``.png``, ``.jpg`` or ``.jpeg``.

        Raises
        ------
        OutputError
            If the file cannot be written; nothing is left at ``path``.
        """
        # a result made without settings (by hand) is written by the defaults
        s = self.settings if self.settings is not None else RenderSettings()
        write_image(path, self.image, self.passes, s.exposure, s.tonemap, alpha=self.alpha,
                    header=None if self.settings is None else s.header(), dither=s.dither)
