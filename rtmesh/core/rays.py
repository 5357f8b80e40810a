"""Ray batches: structure-of-arrays records that share a leading dimension.

Memory layout
-------------
Arrays of 3-vectors have shape ``(n, 3)`` everywhere, but on the renderer's hot path they
are stored *component-major* (Fortran order: the n x components, then the n y, then the n z
are each contiguous).  NumPy then runs every elementwise operation, row-wise dot product and
per-row scaling ``a * s[:, None]`` as long contiguous loops, which is several times faster
than on the row-major layout, where each row is a run of only three numbers.  Results do not
depend on the layout; :func:`component_major` and :func:`take_rows` create and preserve it.
"""

from dataclasses import dataclass, fields

import numpy as np

# Media a ray can be nested in at once (see rtmesh.rendering.media): glass in water in a tank is 3;
# deeper nesting drops the outermost.  Scenes without transmissive materials carry none.
STACK_DEPTH = 4
# an empty (0, 3) array stands for "none" in the kernels' optional vector arguments
NO_VECTORS = np.zeros((0, 3))
NO_VECTORS.flags.writeable = False


def component_major(components):
    """An ``(n, 3)`` view of component rows, stored component-major.

    Parameters
    ----------
    components : (3, n) float
        x, y and z as rows.

    Returns
    -------
    (n, 3) float
        ``components.T`` (made contiguous first if it is not).
    """
    return np.ascontiguousarray(components).T


def repeated_row(row, n):
    """A read-only ``(n, k)`` view of one row repeated ``n`` times (row stride 0).

    What ``np.broadcast_to(row, (n, k))`` gives, for half its Python cost: it is made for
    every chunk (camera origins, unit throughputs), with the GIL held.

    Parameters
    ----------
    row : (k,) contiguous array
    n : int

    Returns
    -------
    (n, k) array
    """
    view = np.ndarray((n, row.shape[0]), dtype=row.dtype, buffer=row, strides=(0, row.itemsize))
    view.flags.writeable = False
    return view


def take_rows(array, rows):
    """``array[rows]`` that keeps a component-major ``(n, k)`` array component-major.

    Parameters
    ----------
    array : (n,) or (n, k) array
    rows : (m,) int or None
        Row indices; None selects every row and returns ``array`` itself (no copy).

    Returns
    -------
    (m,) or (m, k) array
    """
    if rows is None:
        return array
    if array.ndim == 2 and array.shape[1] > 1 and array.flags.f_contiguous:
        # gather each contiguous component row; the transpose back is free
        return array.T.take(rows, axis=1).T
    return array.take(rows, axis=0)


def rows_as_float32(array):
    """A C-contiguous (row-major) float32 copy of an ``(n, k)`` array.

    Built column by column: NumPy's transposing copy of a component-major array is several
    times slower than ``k`` strided column writes.

    Parameters
    ----------
    array : (n, k) float

    Returns
    -------
    (n, k) float32
    """
    if array.flags.c_contiguous:
        return array.astype(np.float32)
    return np.stack([array[:, c] for c in range(array.shape[1])], axis=1, dtype=np.float32)


@dataclass
class RayBatch:
    """Rays in flight, one row each.

    Attributes
    ----------
    origins : (n, 3) float64
    directions : (n, 3) float64
        Unit directions.
    sample : (n,) int64
        Index of the pixel sample (within the current tile) the ray contributes to.
    throughput : (n, 3) float64
        Product of the weights along the path so far (``beta``).
    medium : (n, k) int32
        The media the ray is nested in, innermost first (see :mod:`rtmesh.rendering.media`):
        column 0 is the transmissive material whose interior the ray travels through, -1
        outside every object; -1 pads unused entries.  ``k`` is :data:`STACK_DEPTH` in
        scenes with transmissive materials and 0 in the others.
    pdf : (n,) float64 or None
        Solid-angle density (1/sr) with which each ray's direction was drawn by BSDF
        sampling, for the multiple-importance weights where it meets a light; ``inf`` for
        camera rays and the rays of delta lobes (mirror, smooth glass), which no light
        sampling could have produced.  None: ``inf`` for every ray.
    """

    origins: np.ndarray
    directions: np.ndarray
    sample: np.ndarray
    throughput: np.ndarray
    medium: np.ndarray
    pdf: np.ndarray | None = None

    def __post_init__(self):
        # one layout for the vectors of every batch (camera rays are born component-major,
        # secondary rays row-major from their kernels and np.concatenate): a kernel
        # compiles once per layout it is called with, about a second each on a first run
        self.origins, self.directions, self.throughput = (
            np.asfortranarray(a) for a in (self.origins, self.directions, self.throughput))

    def __len__(self):
        return len(self.sample)

    def subset(self, index):
        """The rays selected by a boolean mask or an index array."""
        if index is not None and np.asarray(index).dtype == bool:
            index = np.flatnonzero(index)
        return RayBatch(*(None if getattr(self, f.name) is None else take_rows(getattr(self, f.name), index)
                          for f in fields(self)))

    @staticmethod
    def concatenate(batches):
        """One batch holding the rays of several, in order."""
        batches = [b for b in batches if len(b)]
        if len(batches) == 1:
            return batches[0]
        if not batches:
            return RayBatch.empty()
        pdf = None
        if any(b.pdf is not None for b in batches):
            pdf = np.concatenate([np.full(len(b), np.inf) if b.pdf is None else b.pdf for b in batches])
        return RayBatch(*(np.concatenate([getattr(b, f.name) for b in batches])
                          for f in fields(RayBatch) if f.name != "pdf"), pdf)

    @staticmethod
    def empty():
        """A batch of no rays."""
        return RayBatch(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.int64),
                        np.zeros((0, 3)), np.zeros((0, STACK_DEPTH), np.int32))


def kernel_input(values, dtype):
    """``values`` as a C-contiguous, writeable array of ``dtype`` (a copy only where it is
    not one already), the one array type a kernel's signature declares for an input.

    numba types a read-only array apart from a writeable one and compiles the kernel again
    for it: a one-ray tail of a pinhole camera's origins (a repeated row, a read-only view
    that NumPy calls contiguous) compiled the path kernel a second time, a minute of one
    core on a first run.

    Parameters
    ----------
    values : array_like
    dtype : numpy dtype

    Returns
    -------
    ndarray
    """
    return np.require(values, dtype, ("C", "W"))
