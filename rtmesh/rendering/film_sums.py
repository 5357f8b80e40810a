"""The film's per-pixel sums in compiled code: adding samples in order, the mean image and the
per-pixel error estimate (see :class:`rtmesh.rendering.film.Film`).
"""

import math

import numpy as np

from rtmesh.core.compiled import inline_row, kernel


# ------------------------------------------------------------------ film
@inline_row
def pixel_sums(total, total_sq, count, px):
    """The sums a pixel's new samples are added to: ``t0, t1, t2, q0, q1, q2``, its sums of
    radiance and of radiance squared, or 0 for a pixel without samples yet whatever the
    arrays hold (a ``one_pass`` :class:`rtmesh.rendering.film.Film` does not clear them).

    ``total``, ``total_sq`` are the film's sums by component, (3, P)
    (:meth:`rtmesh.rendering.film.Film.kernel_arrays`); ``count`` (P,) its sample counts.
    The caller adds the samples to these six numbers in sample order, in registers (added
    through the arrays, each add would wait for the store of the one before), and stores
    them with :func:`store_pixel`.  Inlined: a row called with array arguments takes and
    releases a reference to each (atomic instructions), more than the adding costs.
    """
    fresh = count[px] == 0
    return (0.0 if fresh else total[0, px], 0.0 if fresh else total[1, px], 0.0 if fresh else total[2, px],
            0.0 if fresh else total_sq[0, px], 0.0 if fresh else total_sq[1, px], 0.0 if fresh else total_sq[2, px])


@inline_row
def store_pixel(total, total_sq, image, px, n, t0, t1, t2, q0, q1, q2):
    """Store a pixel's sums (see :func:`pixel_sums`) and, where ``image`` (P, 3) float32
    has rows, its mean over its ``n`` samples in all; the caller raises its count."""
    total[0, px], total[1, px], total[2, px] = t0, t1, t2
    total_sq[0, px], total_sq[1, px], total_sq[2, px] = q0, q1, q2
    if image.shape[0] > 0:
        # one division per pixel: the float64 product differs from the quotient by at most
        # an ulp, far below float32's
        inverse = 1.0 / np.float64(n)
        image[px, 0] = np.float32(t0 * inverse)
        image[px, 1] = np.float32(t1 * inverse)
        image[px, 2] = np.float32(t2 * inverse)


@kernel
def accumulate_samples(total, total_sq, count, pixels, radiance, image):
    """Add samples and their squares to per-pixel sums, each pixel's samples in order
    (:func:`pixel_sums`, :func:`store_pixel`).

    With an ``image``, each pixel's mean is written too, while its sums are in registers
    (a film whose pixels are final once added, instead of a pass over the film at the end).

    Parameters
    ----------
    total, total_sq : (3, P) float64
        Sums over samples of radiance and of radiance squared, by component (updated in
        place).
    count : (P,) int
        Samples per pixel before these (not updated here).
    pixels : (m,) int
        Distinct pixel indices.
    radiance : (m, spp, 3) float
        The new samples of each pixel.
    image : (P, 3) float32 or (0, 3)
        Receives the added pixels' means, as :func:`mean_image` forms them; (0, 3): none.
    """
    spp = radiance.shape[1]
    for i in range(len(pixels)):
        px = pixels[i]
        t0, t1, t2, q0, q1, q2 = pixel_sums(total, total_sq, count, px)
        for s in range(spp):
            r0, r1, r2 = radiance[i, s, 0], radiance[i, s, 1], radiance[i, s, 2]
            t0, t1, t2 = t0 + r0, t1 + r1, t2 + r2
            q0, q1, q2 = q0 + r0 * r0, q1 + r1 * r1, q2 + r2 * r2
        store_pixel(total, total_sq, image, px, count[px] + spp, t0, t1, t2, q0, q1, q2)


@kernel
def add_rows(target_t, rows, values_t):
    """``target[rows] += values`` for distinct ``rows``, the arrays given by component
    (:func:`rtmesh.core.compiled.by_component`).

    Parameters
    ----------
    target_t : (k, n) float64
        Updated in place.
    rows : (m,) int
        Distinct row indices.
    values_t : (k, m) float
    """
    target, values = target_t.T, values_t.T
    for c in range(target.shape[1]):
        for i in range(len(rows)):
            target[rows[i], c] += values[i, c]


@kernel
def mean_image(total, count, out):
    """Per-pixel means of sample sums, as float32 rows.

    Parameters
    ----------
    total : (P, k) float64
        Sums over each pixel's samples.
    count : (P,) int
        Samples per pixel; pixels without any give 0.
    out : (P, k) float32
        Receives ``total / max(count, 1)``.
    """
    for i in range(total.shape[0]):
        # one division per pixel (the pass is bound by division throughput): the float64
        # product differs from the quotient by at most an ulp, far below float32's
        inverse = 1.0 / np.float64(max(count[i], 1))
        for c in range(total.shape[1]):
            out[i, c] = np.float32(total[i, c] * inverse)


@kernel
def pixel_errors(total, total_sq, count, start, stop, floor, display):
    """Per-pixel standard error of the mean, relative to the pixel's brightness, for the
    pixels ``start .. stop - 1`` (see :meth:`rtmesh.rendering.film.Film.pixel_relative_error` and
    :meth:`~rtmesh.rendering.film.Film.pixel_display_error`).

    Each value is formed as the NumPy expressions of ``Film`` formed it, operation for
    operation (sample variance, clamped at 0, over ``n``; its square root; divided by
    ``|mean| + floor`` or its square root; the three channels summed in order and divided
    by 3), in one pass instead of a dozen passes over the film.

    Parameters
    ----------
    total, total_sq : (P, 3) float64
        Per-pixel sums of the samples and of their squares.
    count : (P,) int
        Samples per pixel.
    start, stop : int
    floor : float
    display : bool
        Divide by ``sqrt(|mean| + floor)`` (the display scale) instead of ``|mean| + floor``.

    Returns
    -------
    (stop - start,) float64
        NaN for pixels with fewer than two samples.
    """
    out = np.empty(stop - start)
    for j in range(stop - start):
        i = start + j
        n = np.float64(count[i])
        at_least_one = max(n, 1.0)
        error = 0.0
        for c in range(3):
            mean = total[i, c] / at_least_one
            variance = (total_sq[i, c] - n * mean * mean) / max(n - 1.0, 1.0)
            # np.maximum(variance, 0) keeps a NaN; np.where(n > 1, ..., 0)
            clamped = variance if (variance >= 0.0) | (variance != variance) else 0.0
            std_err = math.sqrt((clamped if n > 1.0 else 0.0) / at_least_one)
            scale = abs(mean) + floor
            term = std_err / (math.sqrt(scale) if display else scale)
            error = term if c == 0 else error + term
        out[j] = error / 3.0 if count[i] >= 2 else np.nan
    return out
