"""Denoising of the beauty image by Intel Open Image Denoise (the ``rtmesh[denoise]`` extra).

OIDN's ``RT`` filter takes the noisy linear image with two guides rendered alongside it,
the albedo and the shading normals (the ``albedo`` and ``normal`` passes, computed for it
even when they are not written), and returns an image that keeps edges and texture while
removing the noise of the light estimate.  It is biased: the error estimate of a render
(film variance) describes the noisy image it started from, and rtmesh reports that one.
"""

import numpy as np

from rtmesh.core.errors import MissingExtraError

INSTALL = "pip install 'rtmesh[denoise]'"


def _pyoidn():
    try:
        import pyoidn
    except ImportError:
        raise MissingExtraError(f"denoising needs Intel Open Image Denoise: {INSTALL}") from None
    return pyoidn


def require():
    """Raise :class:`MissingExtraError` (one line, with the pip command) unless the denoiser is installed."""
    _pyoidn()


def denoise(image, albedo, normal, clean_guides=False):
    """The denoised beauty image.

    Parameters
    ----------
    image : (h, w, 3) float
        Linear radiance (HDR: any non-negative values).
    albedo : (h, w, 3) float
        Diffuse reflectance in [0, 1] (coverage-weighted, as the ``albedo`` pass is).
    normal : (h, w, 3) float
        Unit world-space shading normals, components in [-1, 1].
    clean_guides : bool
        The guides are free of noise (OIDN's ``cleanAux``: it then trusts them instead of
        filtering them first, and keeps more detail).  Averages of camera hits over a
        pixel are, unless the hits themselves are random (depth of field, motion blur,
        stochastic transparency).

    Returns
    -------
    (h, w, 3) float32
    """
    pyoidn = _pyoidn()
    prepared = [np.ascontiguousarray(a, dtype=np.float32) for a in (image, albedo, normal)]
    prepared[1] = np.clip(prepared[1], 0.0, 1.0)
    prepared[2] = np.clip(prepared[2], -1.0, 1.0)
    return np.maximum(pyoidn.denoise(*prepared, hdr=True, clean_aux=bool(clean_guides)), 0.0)
