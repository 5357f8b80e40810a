"""Compiled per-hit kernels of shading: surface records, light evaluation, Blinn-Phong, direct-light sums, film sums."""
