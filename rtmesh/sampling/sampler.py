"""The render's sampler: one object bound to (kind, seed, spp) that owns the dimensions.

Every random number of a render is a point of the render's sampler in some dimension (see
:class:`rtmesh.sampling.patterns.Dim`).  Which dimension a stage draws from (the pixel, the lens,
the shutter time, ambient occlusion and glossy lobes per path depth, each area light per
path depth) is decided here and nowhere else, so stages ask for "the glossy points at
depth 2" instead of passing the kind, the seed, the spp and a dimension sum around.
"""

from dataclasses import dataclass

import numpy as np

from rtmesh.sampling.patterns import Dim, decorrelated_points, pixel_offsets, stratified_values, uniform


@dataclass(frozen=True)
class Sampler:
    """A render's sampler.

    Parameters
    ----------
    kind : {"regular", "random", "jittered", "sobol", "zsobol"}
    seed : int
    spp : int
        Samples per stratified set (the render's samples per pixel).
    resolution : (int, int) or None
        Image width and height: ``zsobol`` orders its points along a Morton curve over the
        image (:mod:`rtmesh.sampling.zsobol`); the other kinds ignore it.

    Notes
    -----
    Every method takes ``pixel`` and ``sample`` (linear pixel index and sample index within
    the pixel, global across adaptive rounds), arrays of one length ``n``, and returns
    points in [0, 1)^2 as ``(n, 2)`` float64 (component-major) or values in [0, 1) as
    ``(n,)``: pure functions of (seed, pixel, sample, dimension).
    """

    kind: str
    seed: int
    spp: int
    resolution: tuple | None = None

    @classmethod
    def for_settings(cls, settings):
        """The sampler of a :class:`rtmesh.rendering.settings.RenderSettings`."""
        return cls(settings.sampler, settings.seed, settings.spp, (settings.width, settings.height))

    def _points(self, pixel, sample, dimension, ray=0, rays=1):
        """:func:`rtmesh.sampling.patterns.decorrelated_points` of this sampler."""
        return decorrelated_points(self.kind, self.seed, pixel, sample, self.spp, dimension, ray, rays,
                                   self.resolution)

    def _values(self, pixel, sample, dimension):
        """:func:`rtmesh.sampling.patterns.stratified_values` of this sampler."""
        return stratified_values(self.kind, self.seed, pixel, sample, self.spp, dimension, self.resolution)

    def pixel(self, pixel, sample):
        """Positions inside the pixel (see :func:`rtmesh.sampling.patterns.pixel_offsets`)."""
        return pixel_offsets(self.kind, self.seed, pixel, sample, self.spp, self.resolution)

    def lens(self, pixel, sample):
        """Points on the thin-lens aperture (before the disk warp)."""
        return self._points(pixel, sample, Dim.LENS)

    def time(self, pixel, sample):
        """Times in the shutter interval, as fractions of it (one value per sample)."""
        return self._values(pixel, sample, Dim.TIME)

    def ambient_occlusion(self, pixel, sample, depth, ray, rays):
        """Directions of ambient-occlusion ray ``ray`` of ``rays`` per hit at path ``depth``."""
        return self._points(pixel, sample, Dim.AO + 2 * depth, ray, rays)

    def glossy(self, pixel, sample, depth):
        """Glossy-lobe directions of the rays spawned at path ``depth``."""
        return self._points(pixel, sample, Dim.GLOSSY + 2 * depth)

    def bsdf(self, pixel, sample, depth):
        """(n, 3) numbers for the BSDF-sampled rays spawned at path ``depth``: column 0
        chooses the lobe, columns 1-2 warp the direction (see
        :func:`rtmesh.materials.metallic_roughness.sample`)."""
        direction = self._points(pixel, sample, Dim.BSDF + 4 * depth)
        lobe = self._values(pixel, sample, Dim.BSDF + 4 * depth + 2)
        return np.column_stack([lobe, direction])

    def area_light(self, pixel, sample, depth, light_index, light_count, ray, rays):
        """Points on area light ``light_index`` of ``light_count`` for sample ``ray`` of
        ``rays`` per hit at path ``depth`` (see :func:`light_dimension`)."""
        return self._points(pixel, sample, light_dimension(depth, light_index, light_count), ray, rays)

    def environment(self, pixel, sample, depth, ray, rays):
        """Points for environment-light direction ``ray`` of ``rays`` per hit at path ``depth``
        (see :class:`rtmesh.lights.environment.EnvironmentLighting`)."""
        return self._points(pixel, sample, Dim.ENVIRONMENT + 2 * depth, ray, rays)

    def alpha_coin(self, ray_key, layer):
        """Uniform numbers deciding whether rays pass a blended cut-out at crossing ``layer``.

        Keyed by the ray itself (``ray_key``, :func:`rtmesh.geometry.cutouts.ray_keys`),
        not by pixel and sample: cut-outs are resolved inside accel queries, which see rays
        only.  Rays are pure functions of (seed, pixel, sample), so the numbers are too.

        Parameters
        ----------
        ray_key : (k,) uint64
        layer : int

        Returns
        -------
        (k,) float64
        """
        return uniform(self.seed, ray_key, layer, Dim.ALPHA)


def light_dimension(depth, light_index, light_count):
    """First sample dimension of one light's samples at one path depth.

    Each (depth, light) pair gets its own pair of dimensions from :attr:`Dim.LIGHT` upward,
    so the samples of different lights and bounces are independent.  The 2^23 pairs below
    the next reserved range wrap around (only past millions of lights x bounces).
    """
    pair = (depth * light_count + light_index) % (1 << 23)
    return int(Dim.LIGHT) + 2 * pair
