"""Colour transfer for display: tone mapping and the sRGB transfer function.

Images are rendered in linear radiance; 8-bit outputs are tone-mapped to [0, 1] and
sRGB-encoded, and 8-bit textures are decoded back to linear.
"""

import numpy as np

TONEMAPS = ("clamp", "reinhard", "aces")


def tonemap(image, exposure=0.0, operator="reinhard"):
    """Map linear radiance to display values in [0, 1] (still linear, not sRGB-encoded).

    Parameters
    ----------
    image : (h, w, 3) float
        Linear radiance.
    exposure : float
        Exposure in stops: the image is scaled by ``2**exposure`` first.
    operator : {"clamp", "reinhard", "aces"}
        ``clamp`` cuts at 1; ``reinhard`` is ``x / (1 + x)`` per channel; ``aces`` is
        Narkowicz's fit of the ACES filmic curve.

    Returns
    -------
    (h, w, 3) float32
    """
    x = np.maximum(np.asarray(image, dtype=np.float32) * np.float32(2.0 ** exposure), 0.0)
    if operator == "clamp":
        y = x
    elif operator == "reinhard":
        y = x / (1.0 + x)
    elif operator == "aces":
        y = (x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14)
    else:
        raise ValueError(f"unknown tonemap {operator!r}; expected one of {', '.join(TONEMAPS)}")
    return np.clip(y, 0.0, 1.0).astype(np.float32)


def linear_to_srgb(x):
    """sRGB transfer function (IEC 61966-2-1) of linear values in [0, 1]."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def srgb_to_linear(x):
    """Inverse of :func:`linear_to_srgb`."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.04045, x / 12.92, np.power((x + 0.055) / 1.055, 2.4))
