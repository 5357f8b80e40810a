"""Colour transfer for display: tone mapping and the sRGB transfer function.

Images are rendered in linear radiance; 8-bit outputs are tone-mapped to [0, 1] and
sRGB-encoded, and 8-bit textures are decoded back to linear.
"""

import numpy as np

TONEMAPS = ("clamp", "reinhard", "aces", "pbr-neutral", "agx")

# Khronos PBR Neutral: highlights are compressed above this peak (0.8 minus the F90 = 0.04
# of ordinary dielectrics), and desaturate at this speed
_NEUTRAL_START = 0.8 - 0.04
_NEUTRAL_DESATURATION = 0.15
# AgX ("minimal AgX", a polynomial fit of Sobotka's sigmoid): the inset matrix (rows: the
# contribution of input R, G, B to each output channel), its inverse, and the exposure
# range (stops around middle grey) that the log encoding maps onto [0, 1]
_AGX_INSET = np.array([[0.842479062253094, 0.0423282422610123, 0.0423756549057051],
                       [0.0784335999999992, 0.878468636469772, 0.0784336],
                       [0.0792237451477643, 0.0791661274605434, 0.879142973793104]])
_AGX_OUTSET = np.array([[1.19687900512017, -0.0528968517574562, -0.0529716355144438],
                        [-0.0980208811401368, 1.15190312990417, -0.0980434501171241],
                        [-0.0990297440797205, -0.0989611768448433, 1.15107367264116]])
_AGX_MIN_EV, _AGX_MAX_EV = -12.47393, 4.026069


def tonemap(image, exposure=0.0, operator="reinhard"):
    """Map linear radiance to display values in [0, 1] (still linear, not sRGB-encoded).

    Parameters
    ----------
    image : (h, w, 3) float
        Linear radiance.
    exposure : float
        Exposure in stops: the image is scaled by ``2**exposure`` first.
    operator : {"clamp", "reinhard", "aces", "pbr-neutral", "agx"}
        ``clamp`` cuts at 1; ``reinhard`` is ``x / (1 + x)`` per channel; ``aces`` is
        Narkowicz's fit of the ACES filmic curve; ``pbr-neutral`` is the Khronos PBR
        Neutral tone mapper (:func:`pbr_neutral`: colours up to 0.76 pass unchanged but for
        a small offset, so base colours of products stay true); ``agx`` is AgX
        (:func:`agx`: a log-encoded sigmoid that desaturates highlights like film).

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
    elif operator == "pbr-neutral":
        y = pbr_neutral(x)
    elif operator == "agx":
        y = agx(x)
    else:
        raise ValueError(f"unknown tonemap {operator!r}; expected one of {', '.join(TONEMAPS)}")
    return np.clip(y, 0.0, 1.0).astype(np.float32)


def pbr_neutral(x):
    """The Khronos PBR Neutral tone mapper, (..., 3) linear Rec. 709 -> linear [0, 1].

    From the Khronos specification (KhronosGroup/ToneMapping, PBR_Neutral): subtract an
    offset ``f`` (the darkest channel's toe, at most ``F90 = 0.04``); if the brightest
    channel ``p`` is then above ``Ks = 0.76``, compress it to ``pn = 1 - (1 - Ks)^2 /
    (p + 1 - 2 Ks)`` and mix toward grey ``pn`` by ``1 - g``, ``g = 1 / (Kd (p - pn) + 1)``.

    Parameters
    ----------
    x : (..., 3) float
        Non-negative linear colours.

    Returns
    -------
    (..., 3) float, same dtype
    """
    low = np.min(x, axis=-1, keepdims=True)
    offset = np.where(low < 0.08, low - 6.25 * low * low, 0.04)
    x = x - offset
    peak = np.max(x, axis=-1, keepdims=True)
    d = 1.0 - _NEUTRAL_START
    new_peak = 1.0 - d * d / (peak + d - _NEUTRAL_START)
    # the ratio is only used where peak >= start > 0
    compressed = x * (new_peak / np.maximum(peak, _NEUTRAL_START))
    g = 1.0 / (_NEUTRAL_DESATURATION * (peak - new_peak) + 1.0)
    mixed = compressed * g + new_peak * (1.0 - g)
    return np.where(peak < _NEUTRAL_START, x, mixed).astype(x.dtype, copy=False)


def agx(x):
    """AgX tone mapping, (..., 3) linear Rec. 709 -> linear [0, 1] (to be sRGB-encoded).

    The inset matrix, a log2 encoding of ``[min_ev, max_ev]`` stops onto [0, 1], the
    polynomial fit of AgX's default-contrast sigmoid (the "minimal AgX" of Wrensch, after
    Sobotka's AgX) and the outset matrix give display-encoded values; they are decoded
    with the sRGB curve here, so that the sRGB encoding of the output writes AgX's display
    values.

    Parameters
    ----------
    x : (..., 3) float
        Non-negative linear colours.

    Returns
    -------
    (..., 3) float64
    """
    inset = np.asarray(x, dtype=np.float64) @ _AGX_INSET
    # log2 of 0 would be -inf: anything below the encoded range maps to its bottom anyway
    stops = np.log2(np.maximum(inset, 2.0 ** _AGX_MIN_EV))
    v = (np.clip(stops, _AGX_MIN_EV, _AGX_MAX_EV) - _AGX_MIN_EV) / (_AGX_MAX_EV - _AGX_MIN_EV)
    v2 = v * v
    v4 = v2 * v2
    curve = (15.5 * v4 * v2 - 40.14 * v4 * v + 31.96 * v4 - 6.868 * v2 * v + 0.4298 * v2 + 0.1191 * v
             - 0.00232)
    return srgb_to_linear(curve @ _AGX_OUTSET)


def linear_to_srgb(x):
    """sRGB transfer function (IEC 61966-2-1) of linear values in [0, 1]."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def srgb_to_linear(x):
    """Inverse of :func:`linear_to_srgb`."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.04045, x / 12.92, np.power((x + 0.055) / 1.055, 2.4))
