"""Random and low-discrepancy numbers as pure functions of (seed, pixel, sample, dimension): pixel patterns, warps, the render's sampler object."""
