"""Adaptive sampling: render in rounds, spending new samples only where the image is noisy.

Round 0 takes ``spp`` samples in every pixel (a render without adaptive settings stops
there).  Every later round looks at each pixel's estimated error on a display scale
(:meth:`rtmesh.rendering.film.Film.pixel_display_error`: the standard error of the mean over the
square root of the mean plus a floor of 0.01) and doubles the samples of the pixels above
``target_error`` and of their eight neighbours.

Why the square root: an error judged relative to the pixel's brightness (standard error /
mean) spends most samples on dark pixels, whose noise neither shows on screen nor counts in
an absolute error measure, and an absolute error ignores that brightness differences are
seen relative to the brightness.  On a square-root display scale (near sRGB's gamma) a
pixel's visible error is its standard error over twice the root of its mean, so the
criterion weights pixels as a viewer does; Cycles' adaptive sampler normalises the same
way.  The estimate is the per-pixel sample variance (``count - 1`` degrees of freedom per
channel, steady from round 0's few samples).  A half-buffer estimate (the difference of
two halves of the samples, as Cycles uses) would follow the faster convergence of
stratified samplers, but has one degree of freedom per channel, so a noisy pixel often
looks converged by chance; with the sample variance a stratified render simply meets its
target with a margin (the estimate is 1.5-3x high for Sobol, see docs/BENCHMARKS.md).  The neighbours are there
because an error estimate from few samples can miss a feature every one of a pixel's
samples happened to miss (a thin highlight, the edge of a penumbra) while its neighbour
caught it; renderers with adaptive sampling widen the noisy set the same way (Cycles and
pbrt's adaptive samplers dilate or filter the error image).

Samples keep global indices across rounds: a pixel at ``c`` samples takes samples ``c ..
2c - 1`` next, so the new samples continue its sequences (a fresh stratified set for the
jittered sampler, the next power-of-two block of the Sobol sequence) instead of repeating
its first ones.

Without ``target_error`` (a time limit alone) the threshold is the image's mean error,
recomputed every round.  The render stops when no pixel is above it, when every pixel above has
``max_spp`` samples, or when ``time_limit`` is reached: a round that would end after the
limit (predicted from the time per sample so far) is cut down to the noisiest pixels that
fit, and is the last.  Without a time limit the rounds, and so the image, depend only on
the samples, so the image is the same for any thread count.
"""

import time

import numpy as np

from rtmesh.rendering.stats import RoundStats


def render_rounds(integrator, film, stats, progress=None, pool=None):
    """Render into ``film`` in rounds until the settings' stopping rule says so.

    Parameters
    ----------
    integrator : rtmesh.rendering.integrator.Integrator
        Renders the samples (:meth:`~rtmesh.rendering.integrator.Integrator.render_samples`).
    film : Film
        Empty film of the image.
    stats : RenderStats
        Receives the ray counts, ``rounds`` and ``stop_reason``.
    progress : callable, optional
        ``progress(chunks_done, chunks_total)``, restarted every round.
    pool : concurrent.futures.ThreadPoolExecutor, optional
        The render's threads, shared by the rounds.
    """
    s = integrator.settings
    start = time.perf_counter()
    deadline = None if s.time_limit is None else start + s.time_limit
    cap = s.sample_cap

    # a range, not an index array: each chunk makes its own small slice of it, so memory
    # beyond the film does not grow with the image (8 bytes a pixel at 4K is 66 MB)
    all_pixels = range(film.count.size)
    error = _run_round(integrator, film, stats, all_pixels, 0, s.spp, s.target_error, progress, pool)
    if not s.adaptive:
        stats.stop_reason = "uniform"
        return
    while True:
        noisy = error > _threshold(error, s.target_error)
        if not noisy.any():
            stats.stop_reason = "target"
            return
        active = dilate(noisy.reshape(film.height, film.width)).ravel() & (film.count < cap)
        if not active.any():
            stats.stop_reason = "max_spp"
            return
        pixels = np.flatnonzero(active)
        # each pixel doubles its samples, up to the cap
        new = np.minimum(film.count[pixels], cap - film.count[pixels])
        cut = False
        if deadline is not None:
            chosen = _within_budget(pixels, new, error, stats, deadline - time.perf_counter())
            if chosen is None:
                stats.stop_reason = "time_limit"
                return
            cut = len(chosen[0]) < len(pixels)
            pixels, new = chosen
        # one batch for the whole round, each pixel continuing its own sequence from its
        # count (splitting the round by count made small batches, which cost more per sample)
        error = _run_round(integrator, film, stats, pixels, film.count[pixels], new,
                           s.target_error, progress, pool)
        if cut:
            stats.stop_reason = "time_limit"
            return


def _threshold(error, target):
    """The error above which a pixel is refined: the target, or without one (a time limit
    alone) the image's mean error, so each round works on the pixels noisier than average
    and the errors even out, instead of doubling nearly clean pixels along with the rest."""
    return target if target is not None else float(np.mean(error))


def dilate(mask):
    """3x3 dilation of a boolean image: each pixel and its eight neighbours.

    Parameters
    ----------
    mask : (h, w) bool

    Returns
    -------
    (h, w) bool
    """
    rows = mask.copy()
    rows[1:] |= mask[:-1]
    rows[:-1] |= mask[1:]
    out = rows.copy()
    out[:, 1:] |= rows[:, :-1]
    out[:, :-1] |= rows[:, 1:]
    return out


def _within_budget(pixels, new, error, stats, seconds_left):
    """The noisiest of ``pixels`` whose new samples fit in ``seconds_left``.

    The time per sample is the larger of the render's average and the last round's: later
    rounds sample the hard pixels (glass, edges), which cost more than the average one.

    Returns
    -------
    (pixels, new) : two (k,) int arrays, or None
        The selection in ascending pixel order; None when not one pixel fits.
    """
    done = [r for r in stats.rounds if r.samples]
    per_sample = max(sum(r.seconds for r in done) / sum(r.samples for r in done),
                     done[-1].seconds / done[-1].samples)
    affordable = seconds_left / per_sample
    if new.sum() <= affordable:
        return pixels, new
    # noisiest first (dilated neighbours by their own error), ties in pixel order
    order = np.argsort(-error[pixels], kind="stable")
    fits = order[np.cumsum(new[order]) <= affordable]
    if not len(fits):
        return None
    fits.sort()
    return pixels[fits], new[fits]


def _run_round(integrator, film, stats, pixels, first_sample, spp, target, progress, pool=None):
    """Render one round (see :meth:`~rtmesh.rendering.integrator.Integrator.render_samples`) and
    record it; returns the pixels' display errors after it, (n,) float."""
    t0 = time.perf_counter()
    integrator.render_samples(film, pixels, first_sample, spp, stats, progress, pool)
    seconds = time.perf_counter() - t0
    # len(), not np.shape(): the shape of a range is found by building its array
    samples = len(pixels) * spp if np.ndim(spp) == 0 else int(np.sum(spp))
    if not integrator.settings.adaptive:
        # a uniform render has one round and nothing to steer: the per-pixel error (a
        # whole-film pass, ~10% of a 1-spp frame) is not computed; stats.relative_error
        # still reports the render's error
        stats.rounds.append(RoundStats(len(pixels), samples, seconds, float("nan"), 0))
        return None
    error = film.pixel_display_error()
    above = np.count_nonzero(error > _threshold(error, target))
    stats.rounds.append(RoundStats(
        pixels=len(pixels),
        samples=samples,
        seconds=seconds,
        error=float(np.mean(error)),
        above_target=int(above),
    ))
    return error
