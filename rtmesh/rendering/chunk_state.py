"""What one chunk of pixel samples carries through the stages of the general path, and the
base of those stages.

:class:`ChunkState` is the chunk's state: its radiance and pass buffers, the keys of its
samples (pixel and sample index, which key every random number), its statistics and stage
clock, and the time of each sample with motion blur.  Stages take it as one argument.
:class:`SurfaceRecords` are the shading records of one depth level's hits.  The row helpers
below add stage results into the chunk's buffers.
"""

import time

import numpy as np

from rtmesh.core.compiled import by_component
from rtmesh.core.rays import take_rows
from rtmesh.rendering.film_sums import add_rows


class Stage:
    """A stage of the general path, for one integrator's scene.

    Parameters
    ----------
    integrator : rtmesh.rendering.integrator.Integrator
        After its tables are formed; the stage reads them (``self.it``).
    """

    def __init__(self, integrator):
        self.it = integrator


class ChunkState:
    """The state of one chunk as it goes through the stages.

    Attributes
    ----------
    radiance : (n, 3) float64
        Component-major radiance of the chunk's samples, added to by every stage.
    passes : PassSink
        Per-sample pass buffers, written by pass name (see :class:`rtmesh.io.passes.PassSink`).
    pixel, sample_in_pixel : (n,) int64
        Each sample's linear pixel index and its global index within the pixel: with the
        render's seed they key every random number of the sample.
    stats : RenderStats
        Ray counts and stage times of the chunk.
    clock : Clock
        Adds elapsed time to ``stats.stage_seconds`` by stage.
    sample_time : (n,) float64 or None
        Shutter time of each sample (motion blur), None without.
    """

    __slots__ = ("radiance", "passes", "pixel", "sample_in_pixel", "stats", "clock", "sample_time")

    def __init__(self, radiance, passes, pixel, sample_in_pixel, stats, clock, sample_time=None):
        self.radiance, self.passes = radiance, passes
        self.pixel, self.sample_in_pixel = pixel, sample_in_pixel
        self.stats, self.clock, self.sample_time = stats, clock, sample_time

    @property
    def keys(self):
        """``(pixel, sample_in_pixel)``, the random-number keys of the samples."""
        return self.pixel, self.sample_in_pixel


class SurfaceRecords:
    """Shading records of the rays that hit something (one row per hit).

    ``p``, ``ng``, ``ns`` and ``d`` (the incoming ray direction; ``wo = -d`` is formed only
    where it is needed) are (k, 3) component-major arrays (see :mod:`rtmesh.core.rays`).
    ``ng`` and ``ns`` are flipped to the side the ray came from; ``front`` says whether
    that is the outer side of the triangle (counter-clockwise winding).  ``mat`` (intp) is
    the material, ``prim`` (int) the face hit, ``sample`` the pixel sample each hit
    contributes to, ``time`` (float, None without motion blur) the time of the ray (see
    :mod:`rtmesh.geometry.motion`).  ``tints`` (:class:`rtmesh.rendering.surface_textures.Tints` or None) holds the
    texture and vertex-colour multipliers of the material colours.  ``pdf`` ((k,) float or
    None) is the BSDF density of the incoming rays (see :attr:`rtmesh.core.rays.RayBatch.pdf`),
    ``origin`` ((k, 3) or None, set with ``pdf``) where they started.  ``physical`` is the
    metallic-roughness stage's rows and BRDF parameters of these hits, formed on first use
    (the tests' wavefront, ``tests/wavefront/physical_shading.py``; None until then).
    """

    __slots__ = ("p", "ng", "ns", "d", "front", "mat", "prim", "sample", "time", "tints", "pdf", "origin",
                 "physical")


def rows_at(time, *row_sets):
    """``time`` gathered by successive row selections (None rows: all); None stays None."""
    if time is None:
        return None
    for rows in row_sets:
        time = take_rows(time, rows)
    return time


def scatter_add(target, index, values, unique=False):
    """``target[index] += values`` with repeated indices accumulating, in index order.

    Parameters
    ----------
    target : (n, 3) float
    index : (k,) int or None
        Rows of ``target``; None means all rows in order (``k == n``).
    values : (k, 3) float
    unique : bool
        The caller guarantees no repeated index (e.g. camera rays, one per sample), so a
        plain fancy-index add gives the same sums as the much slower ``np.add.at``.
    """
    if index is None:
        target += values
    elif unique:
        add_rows_or_all(target, index, values)
    else:
        for c in range(target.shape[1]):
            np.add.at(target[:, c], index, values[:, c])


def add_rows_or_all(target, rows, values):
    """``target[rows] += values`` for distinct ``rows`` (None: all rows); returns ``target``.

    Column by column, so a component-major ``target`` is updated along contiguous columns.
    """
    if rows is None:
        target += values
    else:
        # one pass without temporaries (a NumPy fancy-index add gathers, adds and
        # scatters each column)
        # by component, so that a one-row target or batch of values compiles no variant of
        # its own (values of either layout are taken as they are: no copy on this path)
        add_rows(by_component(target), rows, by_component(values))
    return target


class Clock:
    """Adds the time since the previous lap to a named stage."""

    __slots__ = ("seconds", "last")

    def __init__(self, seconds):
        self.seconds = seconds
        self.last = time.perf_counter()

    def lap(self, stage):
        now = time.perf_counter()
        self.seconds[stage] += now - self.last
        self.last = now
