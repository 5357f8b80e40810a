"""Process-wide tuning for rendering processes, off unless a program turns it on.

A library must not change the state of the process it is imported into: ``import rtmesh``
and building or running a renderer leave the C library's allocator, the interpreter's GIL
switch interval and the set of running threads as they were.  Programs that own their
process and spend it on rendering (the ``rtmesh`` command, the batch worker processes)
call :func:`tune_process` once, which

* keeps freed memory in glibc's heap (:func:`_keep_freed_memory`),
* shortens the GIL switch interval while multi-threaded renders run (:func:`gil_handoff`),
* keeps the render threads between renders, one pool per thread count
  (:func:`render_pool`).

Such a program ends its process with :func:`end_process` once its work is done, without
the interpreter's teardown.

Without it a render on several threads makes its threads (or uses the pool the caller
passes) and shuts them down when it ends, and leaves the switch interval alone.  Either
way the image is the same, bit for bit: the tuning changes only the speed.
"""

import contextlib
import ctypes
import functools
import logging
import os
import sys
import threading
from concurrent.futures import ThreadPoolExecutor

_tuned = False  # set by tune_process


def usable_cores():
    """The cores this process may run on (its CPU affinity where the system tells it, as
    under a cluster's CPU set), else the machine's."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def tune_process():
    """Tune this process for rendering (idempotent; there is no undo).

    Call it from a program that owns its process (a command line, a worker process), not
    from library code: the changes are process-wide.  See the module docstring.
    """
    global _tuned
    _keep_freed_memory()
    _tuned = True


def end_process(status):
    """End this process with exit status ``status`` now, without the interpreter's teardown.

    For a program that owns its process, once its work is done (its files closed, its
    helper processes stopped): the teardown frees every object of the imported libraries
    one by one (numba's compiled functions and types, trimesh, SciPy, OpenImageIO's
    bindings), a quarter to half a second that nobody waits for.  The log handlers and the
    standard streams are flushed first; a reader that has gone away (a closed pipe) loses
    only what it no longer reads.
    """
    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe or stream: nobody reads it any more
            pass
    os._exit(status)


def process_tuned():
    """True once :func:`tune_process` has run in this process (or its forked parent)."""
    return _tuned


@functools.cache
def _keep_freed_memory():
    """Stop glibc from handing the memory of freed temporaries back to the kernel.

    A chunk of samples allocates and frees a few hundred temporaries of up to a few MB.
    With glibc's default, adaptive thresholds, blocks that size are mmap'ed or trimmed off
    the heap when freed, and every new one is faulted in again page by page: ~20000 page
    faults per 512x512 frame, a third of the render time, and with several threads they
    queue on the kernel's memory-map lock, so threads barely speed the render up.  Blocks up
    to 32 MB (the largest chunk temporary is ~6 MB) now come from the heap, and the heap is
    trimmed only above 256 MB of free memory.  Process-wide and done once; a no-op where
    the C library is not glibc.
    """
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return
    m_trim_threshold, m_mmap_threshold = -1, -3  # from glibc's malloc.h
    mallopt(m_mmap_threshold, 32 << 20)
    mallopt(m_trim_threshold, 256 << 20)


# ---------------------------------------------------------------- render threads
_pools = {}  # thread count -> the process's ThreadPoolExecutor of that many workers
_pools_lock = threading.Lock()
# a forked child has the pools but none of their threads: it makes its own
os.register_at_fork(after_in_child=_pools.clear)


def _kept_pool(threads):
    """The process's pool of ``threads`` workers, made on first use and kept.

    The pool outlives the render, as the thread pools of Embree, OpenMP or TBB do.  Threads
    made afresh for every render were slower: measured at 512x512 on 2 threads, a render
    following a 1-thread render took 43.7 ms with new threads and 38.2 ms with kept ones
    (medians of 15; back to back both took 38 ms).  Renders running side by side share the
    pool: their chunks queue for the same workers instead of oversubscribing the cores.
    """
    with _pools_lock:
        if threads not in _pools:
            _pools[threads] = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="rtmesh-render")
        return _pools[threads]


@contextlib.contextmanager
def render_pool(threads, pool=None):
    """The workers a render of ``threads`` threads runs on, for the ``with`` block.

    Parameters
    ----------
    threads : int
        The render's thread count (the calling thread is one of them).
    pool : concurrent.futures.Executor, optional
        The caller's workers: used as they are and left running.

    Yields
    ------
    concurrent.futures.Executor or None
        ``pool`` if given; None for one thread; in a tuned process (:func:`tune_process`)
        its kept pool of ``threads`` workers; otherwise a pool of ``threads`` workers made
        for the block and shut down (its threads joined) when the block ends.
    """
    if pool is not None or threads == 1:
        yield pool
    elif _tuned:
        yield _kept_pool(threads)
    else:
        with ThreadPoolExecutor(max_workers=threads, thread_name_prefix="rtmesh-render") as own:
            yield own


# ---------------------------------------------------------------- GIL switch interval
# GIL switch interval while a render's threads run, seconds (CPython's default is 5 ms).
# A thread coming back from Embree or a kernel (both run without the GIL) waits for the
# GIL until its holder releases it or the interval runs out; with the default, 2 threads
# rendered a 512x512 frame ~1.55x faster than one, with 0.5 ms ~1.65x (0.1 ms: no better).
RENDER_SWITCH_INTERVAL = 5e-4

_handoff_lock = threading.Lock()
_handoff_renders = 0  # multi-threaded renders holding the short interval now
_handoff_previous = None  # the switch interval before the first of them


@contextlib.contextmanager
def gil_handoff(threads):
    """Shorten the GIL switch interval while multi-threaded renders run, in a tuned process.

    Does nothing for one thread or when :func:`tune_process` has not run.  The interval is
    process-wide: the first render to start sets it and the last to finish restores the
    caller's value, so renders running side by side (from several threads of the caller)
    do not leave it changed.
    """
    global _handoff_renders, _handoff_previous
    if threads == 1 or not _tuned:
        yield
        return
    with _handoff_lock:
        if _handoff_renders == 0:
            _handoff_previous = sys.getswitchinterval()
            sys.setswitchinterval(min(_handoff_previous, RENDER_SWITCH_INTERVAL))
        _handoff_renders += 1
    try:
        yield
    finally:
        with _handoff_lock:
            _handoff_renders -= 1
            if _handoff_renders == 0:
                sys.setswitchinterval(_handoff_previous)
