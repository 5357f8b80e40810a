"""The film's per-pixel sums in compiled code: adding samples in order, the mean image and the
per-pixel error estimate (see :class:`rtmesh.rendering.film.Film`).
"""

import math

import numpy as np

from rtmesh.core.compiled import kernel


# ------------------------------------------------------------------ film
@kernel
def accumulate_samples(total, total_sq, count, pixels, radiance, image):
    """Add samples and their squares to per-pixel sums, each pixel's samples in order.

    A pixel without samples yet (``count`` 0) starts from sums of 0 whatever they hold (a
    ``one_pass`` :class:`rtmesh.rendering.film.Film` does not clear them).  With
    an ``image``, each pixel's mean is written too, while its sums are in registers (a film
    whose pixels are final once added, instead of a pass over the film at the end).

    Parameters
    ----------
    total, total_sq : (P, 3) float64
        Sums over samples of radiance and of radiance squared (updated in place).
    count : (P,) int
        Samples per pixel before these (not updated here).
    pixels : (m,) int
        Distinct pixel indices.
    radiance : (m, spp, 3) float
        The new samples of each pixel.
    image : (P, 3) float32 or (0, 3)
        Receives the added pixels' means, as :func:`mean_image` forms them; (0, 3): none.
    """
    means = image.shape[0] > 0
    for i in range(len(pixels)):
        px = pixels[i]
        if count[px] == 0:  # a one_pass film's sums start uncleared (Film)
            for c in range(3):
                total[px, c] = 0.0
                total_sq[px, c] = 0.0
        for s in range(radiance.shape[1]):
            for c in range(3):
                r = radiance[i, s, c]
                total[px, c] += r
                total_sq[px, c] += r * r
        if means:
            inverse = 1.0 / np.float64(count[px] + radiance.shape[1])
            for c in range(3):
                image[px, c] = np.float32(total[px, c] * inverse)


@kernel
def add_pixels(total, total_sq, count, image, radiance, pixel_list, first_pixel, m, counts, done, row, end):
    """Add a chunk's pixels to the film, from its ``done``-th on, while their samples lie
    before row ``end`` of ``radiance``; as :func:`accumulate_samples` adds them (each sum
    in sample order, from the value it had), with each pixel's mean written where
    ``image`` has rows and its sample count raised (as :class:`rtmesh.rendering.film.Film`
    does after :func:`accumulate_samples`).  A pixel without samples yet starts from sums
    of 0, as in :func:`accumulate_samples`.

    For kernels that produce a chunk's samples themselves and add each pixel while its
    samples are in the cache (:mod:`rtmesh.rendering.direct_stage`).  It takes a run of
    pixels, not one: numba takes and releases a reference to each array argument of a call
    (atomic instructions), which cost about 60 cycles per call, more than the adding.

    Parameters
    ----------
    total, total_sq : (3, P) float64
        The film's sums, transposed (:attr:`Film.sum` is column-major (P, 3)).
    count : (P,) int64
        Updated in place: each pixel's count is raised by its samples.
    image : (P, 3) float32 or (0, 3)
        Receives the pixels' means; (0, 3): none.
    radiance : (n, 3) float64
        The chunk's samples, pixel by pixel in sample order.
    pixel_list : (m,) int64 or (0,)
        The chunk's pixels; empty: the ``m`` pixels from ``first_pixel`` on.
    first_pixel, m : int
    counts : (m,) or (1,) int64
        Samples of each pixel (one entry: the same for all).
    done, row : int
        The first pixel to add (its place in the chunk) and the row of its first sample.
    end : int
        Rows before ``end`` are final.

    Returns
    -------
    done, row : int
        The next pixel not added, and the row of its first sample.
    """
    one_count, listed = len(counts) == 1, len(pixel_list) > 0
    means = image.shape[0] > 0
    while done < m:
        samples = counts[0] if one_count else counts[done]
        if row + samples > end:
            break
        px = pixel_list[done] if listed else first_pixel + done
        if samples > 0:
            # the six sums stay in registers over the samples: added through the arrays,
            # each add would wait for the store of the one before
            fresh = count[px] == 0  # a one_pass film's sums start uncleared (Film)
            t0 = 0.0 if fresh else total[0, px]
            t1 = 0.0 if fresh else total[1, px]
            t2 = 0.0 if fresh else total[2, px]
            q0 = 0.0 if fresh else total_sq[0, px]
            q1 = 0.0 if fresh else total_sq[1, px]
            q2 = 0.0 if fresh else total_sq[2, px]
            for s in range(row, row + samples):
                r0, r1, r2 = radiance[s, 0], radiance[s, 1], radiance[s, 2]
                t0, t1, t2 = t0 + r0, t1 + r1, t2 + r2
                q0, q1, q2 = q0 + r0 * r0, q1 + r1 * r1, q2 + r2 * r2
            total[0, px], total[1, px], total[2, px] = t0, t1, t2
            total_sq[0, px], total_sq[1, px], total_sq[2, px] = q0, q1, q2
            n = count[px] + samples
            if means:
                inverse = 1.0 / np.float64(n)
                image[px, 0] = np.float32(t0 * inverse)
                image[px, 1] = np.float32(t1 * inverse)
                image[px, 2] = np.float32(t2 * inverse)
            count[px] = n
        row += samples
        done += 1
    return done, row


@kernel
def add_rows(target, rows, values):
    """``target[rows] += values`` for distinct ``rows``.

    Parameters
    ----------
    target : (n, k) float64
        Updated in place.
    rows : (m,) int
        Distinct row indices.
    values : (m, k) float
    """
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
