"""COCO run-length masks: binary masks as the compressed RLE that ``pycocotools.mask.encode``
writes, and boxes of masks as ``pycocotools.mask.toBbox`` gives them.

A mask of ``h`` rows and ``w`` columns is read column by column (Fortran order, as
pycocotools reads it); its runs alternate between 0 and 1, starting with a run of zeros
(of length 0 when the first pixel is set).  COCO's compressed string stores each run
length, from the fourth on as the difference from the run two before, in groups of 5 bits,
least significant first, each group a character ``48 + bits`` with ``0x20`` set when
another group follows (the sign of the last group's bit ``0x10`` extends).
"""

import numpy as np

# 64-bit run lengths take at most 13 groups of 5 bits
_GROUPS = 13


def run_lengths(mask):
    """The run lengths of a mask read column by column.

    Parameters
    ----------
    mask : (h, w) bool

    Returns
    -------
    (k,) int64
        Alternating runs of 0 and 1, the first a run of 0 (possibly of length 0); they
        sum to ``h * w``.
    """
    flat = np.asarray(mask, dtype=bool).ravel(order="F")
    if not flat.size:
        return np.zeros(0, dtype=np.int64)
    # run starts: 0, every change, and the end
    changes = np.flatnonzero(flat[1:] != flat[:-1]) + 1
    edges = np.concatenate([[0], changes, [flat.size]])
    runs = np.diff(edges).astype(np.int64)
    return np.concatenate([[0], runs]) if flat[0] else runs


def compress(runs):
    """COCO's compressed string of run lengths (``rleToString`` of pycocotools' maskApi).

    Parameters
    ----------
    runs : (k,) int
        Run lengths, as :func:`run_lengths` gives them.

    Returns
    -------
    str
    """
    runs = np.asarray(runs, dtype=np.int64)
    x = runs.copy()
    if len(x) > 3:
        x[3:] -= runs[1:-2]  # maskApi's "if (i > 2) x -= cnts[i - 2]"
    shifts = 5 * np.arange(_GROUPS, dtype=np.int64)
    rest = x[:, None] >> shifts[None, :]  # arithmetic shift: negatives keep their sign
    groups = rest & 0x1F
    after = x[:, None] >> (shifts[None, :] + 5)
    done = np.where((groups & 0x10) != 0, after == -1, after == 0)
    count = np.argmax(done, axis=1) + 1  # groups each value needs (the first that ends it)
    used = np.arange(_GROUPS)[None, :] < count[:, None]
    more = np.arange(_GROUPS)[None, :] < (count - 1)[:, None]
    chars = (groups | np.where(more, 0x20, 0)) + 48
    return chars[used].astype(np.uint8).tobytes().decode("ascii")


def encode(mask):
    """A mask as COCO compressed RLE, ``{"size": [h, w], "counts": str}`` (JSON-ready).

    Parameters
    ----------
    mask : (h, w) bool
    """
    h, w = np.shape(mask)
    return {"size": [int(h), int(w)], "counts": compress(run_lengths(mask))}


def mask_box(mask):
    """``[x, y, width, height]`` of a mask's set pixels, in pixels (as ``toBbox``: the
    left column, the top row, and the counts of columns and rows they span); zeros for an
    empty mask.

    Parameters
    ----------
    mask : (h, w) bool
    """
    rows, columns = np.flatnonzero(np.any(mask, axis=1)), np.flatnonzero(np.any(mask, axis=0))
    if not len(rows):
        return [0.0, 0.0, 0.0, 0.0]
    return [float(columns[0]), float(rows[0]), float(columns[-1] - columns[0] + 1), float(rows[-1] - rows[0] + 1)]
