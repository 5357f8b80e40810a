"""The memory a render will need, estimated before it starts, and the refusal of one that
does not fit.

A render holds its film for the whole render and, while chunks are rendered, the
temporaries of one chunk per thread (``benchmarks/bench_memory.py``, docs/BENCHMARKS.md): the
film grows with the image, the chunks with ``chunk_samples`` and with the samples of one
pixel (a chunk never splits a pixel, so a chunk holds up to ``chunk_samples + spp - 1``
samples).  :func:`estimate` adds these up from the settings alone, with a margin over
what the benchmark measured; the scene's meshes and their acceleration structure are not
counted here: the loaders check them as they read a file (:func:`check_load`, within
:func:`loading_limit`), before they take the memory.  :func:`check` refuses a render whose estimate
exceeds the memory available (``MemAvailable`` of ``/proc/meminfo``) or a given limit, with
one line saying what was asked, the estimate, the limit and how to change it.
"""

import contextlib
import contextvars
import os
from dataclasses import dataclass

import numpy as np

from rtmesh.core.errors import ResourceError
from rtmesh.io.passes import pass_width

# Film: float64 sums and sums of squares of 3 channels, an int64 count, the float32 image
# (bench_memory: 68 bytes a pixel), plus what writing the image makes (a tone-mapped
# float32 copy and the 8-bit or half-float output: 24 bytes a pixel).
FILM_BYTES_PER_PIXEL = 68 + 24
# a pass: float64 sums and a float32 output image per channel
PASS_BYTES_PER_CHANNEL = 8 + 4
# adaptive rounds: per-pixel error estimates, sample counts and the pixels of a round
ADAPTIVE_BYTES_PER_PIXEL = 32
# Temporaries of a chunk per pixel sample in flight: rays, hits, surface records, shadow
# rays and radiance.  bench_memory measured about 350 bytes for a scene of one light
# (23 MB for 2 x 32768 samples); each extra ray per hit (AO rays, area-light samples) and
# each pass channel adds its own arrays.
BYTES_PER_SAMPLE = 512
BYTES_PER_EXTRA_RAY = 64
BYTES_PER_PASS_CHANNEL_SAMPLE = 16


@dataclass(frozen=True)
class MemoryEstimate:
    """Bytes a render will need, by part.

    Attributes
    ----------
    film : int
        The film, its passes and the written image (grows with the image).
    chunks : int
        Chunk temporaries of every thread (grows with the samples of a chunk).
    """

    film: int
    chunks: int

    @property
    def total(self):
        return self.film + self.chunks


def estimate(settings):
    """The memory a render with these settings will need (see the module docstring).

    Parameters
    ----------
    settings : RenderSettings
        Validated.

    Returns
    -------
    MemoryEstimate
    """
    pixels = settings.width * settings.height
    channels = sum(pass_width(name) for name in settings.passes)
    per_pixel = FILM_BYTES_PER_PIXEL + PASS_BYTES_PER_CHANNEL * channels
    if settings.adaptive:
        per_pixel += ADAPTIVE_BYTES_PER_PIXEL
    # a chunk holds whole pixels: up to chunk_samples + (samples of one pixel) - 1
    pixel_samples = settings.sample_cap if settings.adaptive else settings.spp
    in_flight = min(settings.thread_count * (settings.chunk_samples + pixel_samples - 1),
                    pixels * pixel_samples)
    per_sample = (BYTES_PER_SAMPLE + BYTES_PER_EXTRA_RAY * (settings.ao_samples + settings.light_samples)
                  + BYTES_PER_PASS_CHANNEL_SAMPLE * channels)
    return MemoryEstimate(film=pixels * per_pixel, chunks=in_flight * per_sample)


def available_memory():
    """Bytes of memory available to a new allocation, or None when unknown.

    ``MemAvailable`` of ``/proc/meminfo`` (Linux: free memory plus what the kernel can
    reclaim), else free physical pages (``os.sysconf``).
    """
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def format_bytes(n):
    """``1.5 GiB``, ``640 MiB``: a size for messages."""
    for unit, size in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{n} B"


def check(settings, limit=None, option="--memory-limit"):
    """Refuse a render that would not fit in memory.

    Parameters
    ----------
    settings : RenderSettings
        Validated.
    limit : int, optional
        Bytes the render may use; None means the memory available now
        (:func:`available_memory`; no check where that is unknown), 0 turns the check off.
    option : str
        How the user changes the limit, for the message.

    Returns
    -------
    MemoryEstimate

    Raises
    ------
    ResourceError
        The estimate exceeds the limit; the message says what was asked, the estimate,
        the limit and how to change it.
    """
    needed = estimate(settings)
    if limit == 0:
        return needed
    source = f"{option} is {format_bytes(limit)}" if limit is not None else None
    if limit is None:
        limit = available_memory()
        source = f"{format_bytes(limit)} is available" if limit is not None else None
    if limit is not None and needed.total > limit:
        samples = (f"up to {settings.sample_cap} spp" if settings.adaptive else f"{settings.spp} spp")
        raise ResourceError(
            f"a {settings.width}x{settings.height} render at {samples} on {settings.thread_count} "
            f"threads needs about {format_bytes(needed.total)} of memory (film "
            f"{format_bytes(needed.film)}, chunks {format_bytes(needed.chunks)}) but {source}: ask "
            f"for fewer pixels, samples, passes or threads, or set {option} (0 = no check)")
    return needed


# What a vertex and a triangle of a loaded scene take until the render starts: the loader's
# arrays, the parts, the scene's flattened arrays, Embree's build and the shading tables.
# Measured: a GLB of 200 nodes placing one 5120-triangle sphere (2562 vertices) peaks
# 3.08 MB a copy above one copy's render (32x24, 1 spp, 1 thread).
LOAD_BYTES_PER_VERTEX = 300
LOAD_BYTES_PER_TRIANGLE = 450
# A placement of an instanced mesh (or any object): its transform (the loader's, the
# scene's, the object's and Embree's), its object name and category.  Measured: a scene
# file placing an 80-triangle sphere by 100,000 and 200,000 rows of `instances` peaks
# 1.0 and 1.1 KiB a placement above two placements' render (32x24, 1 spp, 1 thread).
LOAD_BYTES_PER_PLACEMENT = 1200


def load_estimate(vertices, triangles, placements=0):
    """Bytes a scene of ``vertices`` and ``triangles`` (all copies counted) takes loaded, with
    ``placements`` placements of instanced meshes (their transforms, names and Embree's
    instance records)."""
    return (LOAD_BYTES_PER_VERTEX * int(vertices) + LOAD_BYTES_PER_TRIANGLE * int(triangles)
            + LOAD_BYTES_PER_PLACEMENT * int(placements))


# the limit loaders check against (loading_limit): (bytes or None, option name), or None
_LOAD_LIMIT = contextvars.ContextVar("rtmesh_load_limit", default=None)


@contextlib.contextmanager
def loading_limit(limit=None, option="--memory-limit"):
    """Within the block, loaders refuse files whose estimated memory exceeds ``limit``
    (:func:`check_load`).

    Parameters
    ----------
    limit : int, optional
        Bytes; None means the memory available when a loader checks, 0 no check.
    option : str
        How the user changes the limit, for the message.
    """
    token = _LOAD_LIMIT.set((limit, option))
    try:
        yield
    finally:
        _LOAD_LIMIT.reset(token)


def check_load(source, what, needed):
    """Refuse loading ``needed`` bytes when they exceed the limit of :func:`loading_limit`
    (outside such a block, nothing is checked).

    Parameters
    ----------
    source : str
        The file, for the message.
    what : str
        What would take the memory (``"12 meshes placed 10000 times"``).
    needed : int
        Estimated bytes.

    Raises
    ------
    ResourceError
        ``file: what would need about 22 GiB of memory but --memory-limit is 4 GiB ...``.
    """
    entry = _LOAD_LIMIT.get()
    if entry is None or entry[0] == 0:
        return
    limit, option = entry
    told = f"{option} is {format_bytes(limit)}" if limit is not None else None
    if limit is None:
        limit = available_memory()
        told = f"{format_bytes(limit)} is available" if limit is not None else None
    if limit is not None and needed > limit:
        raise ResourceError(f"{source}: {what} would need about {format_bytes(needed)} of memory to "
                            f"load but {told}: stopped before taking it (set {option}, 0 = no check)")


def check_flattening(placed, why):
    """Refuse, like :func:`check_load`, flattening a scene's instances into copies (what a
    render that cannot trace instances does, :func:`rtmesh.scene.instances.flattened`)
    when the copies would exceed the loading limit.

    Parameters
    ----------
    placed : rtmesh.scene.instances.Instances
    why : str
        What cannot trace instances, for the message.

    Raises
    ------
    ResourceError
        ``the scene: 10000 placements flattened into copies (instances are not traced with
        integrator 'whitted') would need about 280 GiB ...``.
    """
    if _LOAD_LIMIT.get() is None:
        return
    counts = np.bincount(placed.prototype, minlength=len(placed.prototype_faces) - 1)
    vertices = int(counts @ np.diff(placed.prototype_vertices))
    triangles = int(counts @ np.diff(placed.prototype_faces))
    check_load("the scene", f"{len(placed)} placements flattened into copies of {triangles} triangles in all "
               f"(instances are not traced with {why})",
               load_estimate(vertices, triangles, len(placed)))
