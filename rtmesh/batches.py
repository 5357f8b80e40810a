"""Ray batches: structure-of-arrays records that share a leading dimension."""

from dataclasses import dataclass, fields

import numpy as np


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
    medium : (n,) int32
        Material whose interior the ray travels through; -1 outside every object.
    """

    origins: np.ndarray
    directions: np.ndarray
    sample: np.ndarray
    throughput: np.ndarray
    medium: np.ndarray

    def __len__(self):
        return len(self.sample)

    def subset(self, index):
        """The rays selected by a boolean mask or an index array."""
        return RayBatch(*(getattr(self, f.name)[index] for f in fields(self)))

    @staticmethod
    def concatenate(batches):
        """One batch holding the rays of several, in order."""
        batches = [b for b in batches if len(b)]
        if len(batches) == 1:
            return batches[0]
        if not batches:
            return RayBatch.empty()
        return RayBatch(*(np.concatenate([getattr(b, f.name) for b in batches])
                          for f in fields(RayBatch)))

    @staticmethod
    def empty():
        """A batch of no rays."""
        return RayBatch(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.int64),
                        np.zeros((0, 3)), np.zeros(0, np.int32))
