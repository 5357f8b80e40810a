"""Film: per-pixel accumulation, error estimates and output passes."""

import numpy as np

from rtmesh.core.compiled import by_component
from rtmesh.core.rays import rows_as_float32
from rtmesh.rendering import film_sums

# added to a pixel's mean before dividing its standard error by it (relative errors)
ERROR_FLOOR = 0.01
# Pixels per block of the whole-film reductions (image, variance, relative error): 16384
# pixels make 0.4 MB float64 (m, 3) temporaries, large enough that the per-block Python
# overhead is invisible (~500 blocks at 4K), small enough that the few temporaries alive
# at once stay a small fraction of any sizeable film.
BLOCK_PIXELS = 16384
# blocks of Film.image on a thread pool: a few per thread balance any small thread count
_MEAN_BLOCKS = 8
# "no image values" for film_sums.accumulate_samples
_NO_IMAGE = np.zeros((0, 3), dtype=np.float32)


class Film:
    """Per-pixel sums of sample radiance and of its square, plus requested passes.

    Parameters
    ----------
    width, height : int
    passes : dict of str to int or (int, str)
        Name and channel count of each extra pass (e.g. ``{"ao": 1}``), optionally with
        how a pixel's samples are reduced: ``"mean"`` (the default), ``"first"`` (the
        pixel's first sample, e.g. integer ids) or ``"min"`` (e.g. the nearest depth).
    one_pass : bool
        Every pixel is added exactly once, by :meth:`add_tile` (a render without later
        rounds): each add also writes its pixels' image values, on the thread that adds
        them, and :meth:`image` returns those instead of making a pass over the film.

    Attributes
    ----------
    sum, sum_sq : (height * width, 3) float64
        Sum over samples of radiance and radiance squared, per pixel (row-major pixel
        order; stored component-major like the integrator's radiance, see
        :mod:`rtmesh.core.rays`).  In a ``one_pass`` film, undefined for pixels with no
        sample yet (``count`` 0).
    count : (height * width,) int64
        Samples per pixel so far.
    pass_sums : dict of str to (height * width, k) float64
        Sums for ``mean`` passes; the kept value for ``first`` and ``min`` passes.
    pass_reductions : dict of str to str
    """

    def __init__(self, width, height, passes=None, one_pass=False):
        self.width, self.height = int(width), int(height)
        n = self.width * self.height
        # A one_pass film's sums are not cleared: each is set when its pixel is first added
        # (film_sums: a pixel with no samples starts from 0), so no pass writes zeros over
        # 48 bytes a pixel first (in a process tuned for rendering, np.zeros reuses freed
        # memory and clears it with memset: 4 % of a 1-spp frame on bench_core's scene).
        # Other films are cleared: for a large film np.zeros maps pages the kernel zeroes on
        # first touch, which the threads that render the pixels do (no serial pass).
        clear = np.empty if one_pass else np.zeros
        self.sum = clear((n, 3), order="F")
        self.sum_sq = clear((n, 3), order="F")
        self.count = np.zeros(n, dtype=np.int64)
        self._image = np.empty((n, 3), dtype=np.float32) if one_pass else None
        specs = {name: (v, "mean") if isinstance(v, int) else tuple(v) for name, v in (passes or {}).items()}
        self.pass_reductions = {name: reduction for name, (_, reduction) in specs.items()}
        # a min pass starts above every sample; +inf left over means "no sample"
        self.pass_sums = {name: np.full((n, k), np.inf if reduction == "min" else 0.0)
                          for name, (k, reduction) in specs.items()}

    @property
    def nbytes(self):
        """Bytes held by the film's arrays: sums, squares, counts, passes and, for a
        ``one_pass`` film, the image it fills."""
        arrays = [self.sum, self.sum_sq, self.count, *self.pass_sums.values()]
        return sum(a.nbytes for a in arrays) + (0 if self._image is None else self._image.nbytes)

    def add_tile(self, pixels, radiance, passes=None):
        """Add the samples of a set of pixels.

        Parameters
        ----------
        pixels : int, slice or (m,) int array
            Linear indices of the ``m`` pixels: an array of distinct indices (e.g. the
            pixels an adaptive round refines), a slice, or the first index of a run of
            consecutive pixels.
        radiance : (m, spp, 3) float
            Radiance of every sample of the ``m`` pixels, in sample order.
        passes : dict of str to (m, spp, k) float, optional
        """
        m, spp = radiance.shape[:2]
        if isinstance(pixels, (slice, np.ndarray)):
            px = pixels
        else:
            px = slice(int(pixels), int(pixels) + m)
        # add samples one index at a time so each pixel's sum has the same rounding
        # whatever the tile size or thread count (bit-identical renders)
        mean_passes = self._keep_min_and_first(px, passes, lambda v: v.min(axis=1),
                                               lambda v: v[:, 0])
        index = px if isinstance(px, np.ndarray) else np.arange(px.start, px.stop)
        # a one_pass film's pixels are final: their image values are written with the sums,
        # on this thread, instead of in a serial pass after the render
        film_sums.accumulate_samples(by_component(self.sum), by_component(self.sum_sq), self.count, index,
                                     radiance, _NO_IMAGE if self._image is None else self._image)
        for s in range(spp):
            for name, values in mean_passes.items():
                self.pass_sums[name][px] += values[:, s]
        self.count[px] += spp

    def kernel_arrays(self):
        """The arrays a kernel that adds samples to the film itself updates
        (:func:`rtmesh.rendering.film_sums.pixel_sums`, :func:`~rtmesh.rendering.film_sums.store_pixel`;
        the fused stage), for a film without passes.

        Returns
        -------
        total, total_sq : (3, P) float64
            :attr:`sum` and :attr:`sum_sq` transposed (row-major views of them).
        count : (P,) int64
        image : (P, 3) float32 or (0, 3)
            The image a ``one_pass`` film fills as pixels are added; (0, 3) otherwise.
        """
        return (by_component(self.sum), by_component(self.sum_sq), self.count,
                _NO_IMAGE if self._image is None else self._image)

    def add_samples(self, pixels, counts, radiance, passes=None):
        """Add a different number of samples to each of a set of pixels.

        Accumulates exactly as :meth:`add_tile` would pixel by pixel (each pixel's samples
        in order), so sums do not depend on how pixels are grouped into calls.

        Parameters
        ----------
        pixels : (m,) int array
            Distinct linear pixel indices.
        counts : (m,) int array
            Samples of each pixel, each >= 1.
        radiance : (sum(counts), 3) float
            The samples, pixel by pixel in sample order.
        passes : dict of str to (sum(counts), k) float, optional
        """
        pixels = np.asarray(pixels, dtype=np.int64)
        counts = np.asarray(counts, dtype=np.int64)
        starts = np.cumsum(counts) - counts
        # pixels by decreasing count: the pixels taking a k-th sample are a prefix, so
        # the k-th samples of all pixels are one vectorised add (max(counts) adds in all)
        order = np.argsort(-counts, kind="stable")
        px_sorted, starts_sorted = pixels[order], starts[order]
        # taking[k]: pixels with more than k samples
        taking = len(counts) - np.searchsorted(counts[order][::-1], np.arange(counts.max(initial=0)),
                                               side="right")
        mean_passes = self._keep_min_and_first(
            pixels, passes, lambda v: np.minimum.reduceat(v, starts, axis=0), lambda v: v[starts])
        fresh = pixels[self.count[pixels] == 0]  # a one_pass film's sums are not cleared
        self.sum[fresh] = 0.0
        self.sum_sq[fresh] = 0.0
        for k, active in enumerate(taking):
            px = px_sorted[:active]
            rows = starts_sorted[:active] + k
            r = radiance[rows]
            self.sum[px] += r
            self.sum_sq[px] += r * r
            for name, values in mean_passes.items():
                self.pass_sums[name][px] += values[rows]
        self.count[pixels] += counts

    def _keep_min_and_first(self, px, passes, smallest, first):
        """Update the ``min`` and ``first`` passes of the pixels ``px`` with new samples.

        Parameters
        ----------
        px : slice or (m,) int array
        passes : dict of str to array, or None
            New samples of each pass, in the caller's layout.
        smallest, first : callable
            Map a pass's new samples to (m, k) per pixel: their minimum, and the pixel's
            first new sample (kept only by pixels that had no sample yet).

        Returns
        -------
        dict of str to array
            The ``mean`` passes, left for the caller to sum sample by sample.
        """
        mean_passes = {}
        for name, values in (passes or {}).items():
            reduction = self.pass_reductions[name]
            if reduction == "mean":
                mean_passes[name] = values
            elif reduction == "min":
                self.pass_sums[name][px] = np.minimum(self.pass_sums[name][px], smallest(values))
            else:
                fresh = (self.count[px] == 0)[:, None]
                self.pass_sums[name][px] = np.where(fresh, first(values), self.pass_sums[name][px])
        return mean_passes

    def _blocks(self):
        """Pixel slices of at most ``BLOCK_PIXELS`` covering the film, in order."""
        n = self.width * self.height
        return (slice(a, min(a + BLOCK_PIXELS, n)) for a in range(0, n, BLOCK_PIXELS))

    def _divisor(self, px):
        """(m, 1) float64: the sample count of the pixels ``px``, at least 1 (exact
        integers; as floats the broadcast division runs several times faster than with
        int64)."""
        return np.maximum(self.count[px], 1).astype(np.float64)[:, None]

    def _to_image(self, per_block, channels):
        """(height, width, channels) float32 filled block by block from ``per_block(px)``.

        Whole-film expressions would make float64 temporaries of the film's full size
        (hundreds of MB at 4K); blocks keep the extra memory at a few MB whatever the
        resolution.
        """
        out = np.zeros((self.width * self.height, channels), dtype=np.float32)
        for px in self._blocks():
            out[px] = rows_as_float32(per_block(px))
        return out.reshape(self.height, self.width, channels)

    def image(self, pool=None):
        """(height, width, 3) float32: mean radiance per pixel (box filter).

        Parameters
        ----------
        pool : concurrent.futures.Executor, optional
            Threads to average blocks of pixels on (the kernel runs without the GIL): the
            last serial pass of a render otherwise.  Not used by a ``one_pass`` film,
            whose image is written as the pixels are added.
        """
        if self._image is not None:
            return self._image.reshape(self.height, self.width, 3)
        return self._means(self.sum, pool).reshape(self.height, self.width, 3)

    def _means(self, sums, pool=None):
        """(P, k) float32: ``sums / max(count, 1)`` per pixel, in blocks on ``pool``."""
        out = np.empty(sums.shape, dtype=np.float32)
        if pool is None:
            film_sums.mean_image(sums, self.count, out)
            return out
        bounds = np.linspace(0, len(out), _MEAN_BLOCKS + 1).astype(int)

        def block(a, b):
            film_sums.mean_image(sums[a:b], self.count[a:b], out[a:b])

        list(pool.map(block, bounds[:-1], bounds[1:]))
        return out

    def _variance_of_mean_rows(self, px):
        """(m, 3) float64: :meth:`variance_of_mean` of the pixels ``px``."""
        n = self.count[px, None].astype(np.float64)
        mean = self.sum[px] / np.maximum(n, 1)
        var = (self.sum_sq[px] - n * mean * mean) / np.maximum(n - 1, 1)
        return np.where(n > 1, np.maximum(var, 0.0), 0.0) / np.maximum(n, 1)

    def variance_of_mean(self):
        """(height, width, 3) float32: estimated variance of each pixel's mean.

        The unbiased sample variance divided by the sample count; zero where a pixel has
        fewer than two samples (no estimate possible).  For stratified samplers the samples
        of a pixel are not independent and this overestimates the true variance of the mean.
        """
        return self._to_image(self._variance_of_mean_rows, 3)

    def _pixel_error_rows(self, px, floor, power):
        """(m,) float64: mean over channels of the pixels' standard error divided by
        ``(|mean| + floor) ** power`` (``power`` 1 or 0.5); NaN below two samples.

        ``px`` is a slice of pixels (see :meth:`_blocks`); one compiled pass
        (:func:`rtmesh.shading.film_sums.pixel_errors`), which adaptive sampling runs over the whole
        film after every round.
        """
        return film_sums.pixel_errors(self.sum, self.sum_sq, self.count, px.start, px.stop, floor, power != 1)

    def _per_pixel(self, floor, power):
        """(height * width,) float64 :meth:`_pixel_error_rows` of every pixel, block by
        block: the result is the only array of the film's size."""
        error = np.zeros(self.width * self.height)
        for px in self._blocks():
            error[px] = self._pixel_error_rows(px, floor, power)
        return error

    def pixel_relative_error(self, floor=ERROR_FLOOR):
        """Estimated relative standard error of each pixel's mean.

        Parameters
        ----------
        floor : float
            Added to the mean before dividing, so that the error of near-black pixels is
            measured against ``floor`` instead of blowing up (a 1e-4 error on a 1e-5 pixel
            is invisible).

        Returns
        -------
        (height * width,) float64
            ``mean over channels of sqrt(variance_of_mean) / (|mean| + floor)``, row-major;
            NaN for pixels with fewer than two samples.
        """
        return self._per_pixel(floor, 1)

    def pixel_display_error(self, floor=ERROR_FLOOR):
        """Estimated standard error of each pixel on a display (square-root) scale: what
        adaptive sampling steers by.

        ``sqrt(variance_of_mean) / sqrt(|mean| + floor)``, averaged over channels.  A
        display encoding ``y = sqrt(x)`` (close to sRGB's x^(1/2.2)) turns a standard error
        ``s`` at radiance ``x`` into ``s / (2 sqrt(x))``, so this is twice the standard
        error a viewer sees (radiance 1 displayed as 1).  It sits between the relative
        error, which spends samples on dark pixels whose noise is invisible and barely
        counts in an absolute error, and the absolute error, which ignores that the eye
        judges brightness differences relative to the brightness.  Cycles' adaptive
        sampling normalises its per-pixel error the same way (error / sqrt(intensity),
        after Dammertz et al. 2009, "A hierarchical automatic stopping condition for Monte
        Carlo global illumination").

        Parameters
        ----------
        floor : float
            Added under the square root, so black pixels are judged against
            ``sqrt(floor)`` (0.1 for the default 0.01) instead of dividing by zero.

        Returns
        -------
        (height * width,) float64
            Row-major; NaN for pixels with fewer than two samples.
        """
        return self._per_pixel(floor, 0.5)

    def relative_error(self):
        """Mean relative standard error of the image, a scalar estimate of its own error.

        The average of :meth:`pixel_relative_error` over all pixels (the standard error of
        each channel's mean divided by the mean plus 0.01, so near-black pixels do not
        dominate).  NaN when pixels have fewer than two samples.  Summed block by block,
        with no temporary of the film's size.
        """
        if self.count.min() < 2:
            return float("nan")
        total = sum(float(self._pixel_error_rows(px, ERROR_FLOOR, 1).sum()) for px in self._blocks())
        return total / (self.width * self.height)

    def spp_image(self):
        """(height, width, 1) float32: samples taken in each pixel."""
        return self._to_image(lambda px: self.count[px, None].astype(np.float64), 1)

    def pass_image(self, name):
        """(height, width, k) float32: a pass reduced per pixel (mean, first sample or
        minimum; a minimum no sample set is 0)."""
        values = self.pass_sums[name]
        reduction = self.pass_reductions[name]
        if reduction == "mean":
            return self._means(values).reshape(self.height, self.width, values.shape[1])
        if reduction == "min":
            return self._to_image(lambda px: np.where(np.isfinite(values[px]), values[px], 0.0),
                                  values.shape[1])
        return self._to_image(lambda px: values[px], values.shape[1])
