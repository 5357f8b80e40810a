"""The scheduler: cutting a round of pixel samples into chunks and running them on threads.

A chunk is a run of whole pixels (never a pixel split between chunks), so each pixel's
sum is formed by one thread in sample order.  The chunks do not depend on the thread
count either: Embree's packet traversal reports, of two triangles hit at exactly the same
distance (coplanar overlapping faces), the one its traversal of the whole packet meets
first, so such a ray's hit can depend on the other rays traced with it, which come from
its chunk.  With the same chunks for every thread count, the same rays share packets and
the image is bit-identical for any thread count.  The threads pull their next chunk
themselves; the calling thread renders chunks too and reports progress between them.
"""

import threading
from concurrent.futures import wait

import numpy as np

from rtmesh.rendering.stats import RenderStats

# Smallest chunk (pixel samples) of a multi-threaded render, unless the settings' chunk
# size is smaller.  Every chunk costs Python between its kernel calls, and on several
# threads also waits for the GIL at those points: at 512x512 on 2 threads a chunk cost
# ~0.6 ms of thread time more than on one thread (a schedule with tail chunks down to 2048
# samples, 18 chunks, kept the threads 7 ms busier than 8 chunks of 32768).  Interleaved
# runs of schedules on that frame: guided down to 2048, 4096, 8192 and 16384 samples gave
# 1.82, 1.86, 1.91 and 1.93x over one thread, fixed 32768-sample chunks 1.91x (one run of
# 25; in a slower phase of the machine 1.64-1.69x for all but the first).
MIN_CHUNK_SAMPLES = 8192
# Chunks shrink towards the end ("guided" scheduling): each takes 1 / (GUIDE *
# SCHEDULE_THREADS) of the samples left.  Chunks differ in cost (rows of sky against rows
# of geometry) and a thread that draws the last long chunk works on alone; small last
# chunks let the threads finish together, large first ones keep the number of chunks (and
# their Python cost) low.  The schedule is the one measured best for two threads, whatever
# the thread count (see the module docstring for why it may not depend on it).
GUIDE = 2
SCHEDULE_THREADS = 2


def sample_indices(pixels, first_sample, spp):
    """The pixel and the sample index of every sample of a chunk, pixel by pixel in sample
    order.

    Parameters
    ----------
    pixels : range or (m,) int array
    first_sample : int or (m,) int array
        Index of each pixel's first sample (one for all, or per pixel).
    spp : int or (m,) int array
        Samples of each pixel (one for all, or per pixel).

    Returns
    -------
    pixel, sample : (n,) int64
    """
    if isinstance(pixels, range):
        pixels = np.arange(pixels.start, pixels.stop, pixels.step, dtype=np.int64)
    pixels = np.asarray(pixels, dtype=np.int64)
    # (isinstance, not np.ndim: this runs per chunk with the GIL held)
    if isinstance(spp, np.ndarray) or isinstance(first_sample, np.ndarray):
        counts = np.broadcast_to(np.asarray(spp, dtype=np.int64), pixels.shape)
        first = np.broadcast_to(np.asarray(first_sample, dtype=np.int64), pixels.shape)
        n = int(counts.sum())
        # global index: the pixel's first sample plus the position in its run of rows
        row_start = np.cumsum(counts) - counts
        return np.repeat(pixels, counts), np.repeat(first - row_start, counts) + np.arange(n, dtype=np.int64)
    m = len(pixels)
    pixel = np.repeat(pixels, spp) if spp > 1 else pixels
    sample = (np.full(m, first_sample, dtype=np.int64) if spp == 1 else
              np.tile(np.arange(first_sample, first_sample + spp, dtype=np.int64), m))
    return pixel, sample


def chunk_starts(total, chunk_samples):
    """Where the chunks of a batch of ``total`` pixel samples start, in samples.

    Each chunk takes ``1 / (GUIDE * SCHEDULE_THREADS)`` of the samples left, between
    ``MIN_CHUNK_SAMPLES`` and ``chunk_samples``, so the last chunks are small and the
    threads end close together.

    Parameters
    ----------
    total : int
    chunk_samples : int
        Largest chunk (it bounds the memory of a chunk).

    Returns
    -------
    (k,) int64
        Ascending sample positions, the first 0 (none for ``total == 0``).
    """
    starts, position = [], 0
    while position < total:
        starts.append(position)
        guided = -(-(total - position) // (GUIDE * SCHEDULE_THREADS))
        position += min(chunk_samples, max(MIN_CHUNK_SAMPLES, guided))
    return np.array(starts, dtype=np.int64)


def pixel_chunks(spp, n_pixels, chunk_samples):
    """Cut a run of pixels into chunks at :func:`chunk_starts`, never splitting a pixel.

    A chunk starts at the first pixel whose samples begin at or after its cut, so a chunk
    holds at most ``chunk_samples + max(spp) - 1`` samples.

    Parameters
    ----------
    spp : int or (n_pixels,) int array
        Samples of every pixel, or of each.
    n_pixels : int
    chunk_samples : int
        See :func:`chunk_starts`.

    Returns
    -------
    list of (int, int)
        ``(start, stop)`` pixel ranges covering ``0 .. n_pixels`` in order.
    """
    if np.ndim(spp) == 0:
        cuts = chunk_starts(n_pixels * spp, chunk_samples)
        starts = np.unique(-(-cuts // spp))
    else:
        before = np.cumsum(spp) - spp  # samples ahead of each pixel
        total = int(before[-1] + spp[-1]) if n_pixels else 0
        starts = np.unique(np.searchsorted(before, chunk_starts(total, chunk_samples)))
    starts = starts[starts < n_pixels]  # a cut inside the last pixel starts no chunk
    return list(zip(starts.tolist(), starts[1:].tolist() + [n_pixels]))


def run_on_threads(work, bounds, threads, pool, stats, progress=None):
    """Run ``work(a, b)`` for every ``(a, b)`` of ``bounds`` on the calling thread and
    ``threads - 1`` workers of ``pool``, adding the returned :class:`RenderStats` into
    ``stats``.

    Each thread takes the next chunk itself as soon as it is done with one and sums its own
    statistics, so no thread wakes up for another's chunks.  The calling thread renders
    too: it is running already, where a pool worker waits to be woken (on a virtual
    machine an idle CPU can take long to wake), and it reports progress between its
    chunks.  When a chunk fails or the caller is interrupted (Ctrl-C), the other threads
    stop after their current chunk and the exception is raised.
    """
    lock = threading.Lock()
    state = {"next": 0, "done": 0, "shown": 0, "stop": False}

    def worker(report=None):
        own = RenderStats()
        while True:
            with lock:
                i = state["next"]
                if state["stop"] or i == len(bounds):
                    return own
                state["next"] = i + 1
            try:
                own.merge(work(*bounds[i]))
            except BaseException:
                state["stop"] = True
                raise
            with lock:
                state["done"] += 1
                done = state["done"]
            if report is not None:
                report(done, len(bounds))
                state["shown"] = done

    futures = [pool.submit(worker) for _ in range(threads - 1)]
    try:
        stats.merge(worker(progress))
        for future in futures:
            stats.merge(future.result())
    except BaseException:
        state["stop"] = True
        wait(futures)
        raise
    if progress is not None and state["shown"] < len(bounds):
        progress(len(bounds), len(bounds))  # the last chunks were the other threads'
