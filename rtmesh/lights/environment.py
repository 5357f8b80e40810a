"""Light from the background: an environment image (or a solid or gradient sky) lighting the
scene, importance-sampled, with shadows.

Sampling
--------
The background's radiance is tabulated on its latitude-longitude grid (an environment
image's own texels; a 64 x 32 grid for a solid or gradient background) and directions are
drawn from the piecewise-constant 2D density proportional to ``luminance x sin(theta)``,
the luminance of a cell being the largest of its 3 x 3 neighbourhood (the bilinear lookup
reaches that far)
(pbrt's ``Distribution2D``): a row (elevation) from the marginal distribution with the first
number, a column (azimuth) within the row with the second, so stratified points of the
square stay stratified over the sphere.  The sin(theta) factor is the area of a row's
texels on the sphere, so bright texels are drawn in proportion to the light they send.
With ``p(u, v)`` the density over the image, the solid-angle density is

    pdf(w) = p(u, v) / (2 pi^2 sin(theta))

A small floor (1e-3 of the mean) keeps the density positive everywhere, so texels that the
bilinear lookup lights from a bright neighbour are still reached: the estimator stays
unbiased.

Estimator
---------
Per hit, ``light_samples`` directions ``w_j``, each with a shadow ray that must escape::

    (1 / N) sum_j V(p, w_j) f(w_j) L(w_j) / pdf(w_j)

``f`` is the material's Blinn-Phong factor toward ``w_j`` (``kd cos`` + highlight, no 1/pi,
as for every rtmesh light: a white diffuse surface under a uniform sky of radiance ``L``
reflects ``pi L``).  The Whitted integrator samples no diffuse bounce, so there is no
second strategy to weigh against (multiple importance sampling comes with a BSDF that is
sampled, such as glTF's metallic-roughness model); mirrors and glass see the environment
through their followed rays, as before.
"""

import math

import numpy as np

from rtmesh.core.compiled import kernel, row
from rtmesh.core.rays import take_rows
from rtmesh.core.vecmath import dot
from rtmesh.geometry.accel import offset_ray_origins
from rtmesh.materials.lobes import LUMA
from rtmesh.sampling.sampler import Sampler
from rtmesh.sampling.warps import direction_to_latlong, latlong_direction, latlong_to_direction

# relative weight of the density's floor (see the module notes)
_FLOOR = 1e-3
# the tabulation of a background without an image of its own
_GRID = (32, 64)


class EnvironmentLighting:
    """Importance-sampled light from a background.

    Parameters
    ----------
    background : SolidBackground, GradientBackground or EnvironmentBackground
        Any object with ``radiance(directions)``; an environment image is tabulated on its
        own grid (``width``, its rotation through ``uv``).
    accel : Accel
        Traces the shadow rays.
    settings : RenderSettings
        ``light_samples`` and the sampler.
    offset_scale : float
        Scene size for :func:`rtmesh.geometry.accel.offset_ray_origins`.
    """

    def __init__(self, background, accel, settings, offset_scale):
        self.background = background
        self.accel = accel
        self.samples = settings.light_samples
        self.sampler = Sampler.for_settings(settings)
        self.offset_scale = offset_scale
        self.rotation = getattr(background, "rotation", 0.0)
        width = getattr(background, "width", None)
        height, width = (_GRID if width is None else (max(width // 2, 1), width))
        self.height, self.width = height, width
        v = 1.0 - (np.arange(height) + 0.5) / height  # texture v: 1 at the top row
        u = (np.arange(width) + 0.5) / width
        directions = self.directions(np.stack(np.meshgrid(u, v), axis=2).reshape(-1, 2))
        radiance = np.asarray(background.radiance(directions), dtype=np.float64).reshape(height, width, 3)
        luminance = radiance @ LUMA
        # the bilinear lookup spreads a texel's radiance over its neighbours' cells: sample
        # each cell by the brightest of the 3 x 3 texels around it, so the weight L / pdf
        # stays bounded next to a small bright source (with the texel's own value, a sample
        # at the edge of a dark cell beside the sun would weigh hundreds of times the rest)
        luminance = _neighbourhood_max(luminance)
        sin_theta = np.cos((v - 0.5) * math.pi)[:, None]
        func = luminance * sin_theta
        func = func + _FLOOR * max(float(func.mean()), 1e-300)
        self._func = func
        self._mean = float(func.mean())
        rows = func.sum(axis=1)
        self._marginal = np.concatenate([[0.0], np.cumsum(rows)]) / rows.sum()
        conditional = np.concatenate([np.zeros((height, 1)), np.cumsum(func, axis=1)], axis=1) / rows[:, None]
        self._conditional = conditional

    def directions(self, uv):
        """Unit directions of image coordinates ((k, 2) -> (k, 3)), with the background's
        rotation (see :func:`rtmesh.sampling.warps.latlong_to_direction`)."""
        return latlong_to_direction(uv, self.rotation)

    def sample(self, points):
        """Directions drawn from the density, and their solid-angle pdf.

        Parameters
        ----------
        points : (k, 2) float
            Points of [0, 1)^2.

        Returns
        -------
        wi : (k, 3) float64
        pdf : (k,) float64
            Solid-angle density of each direction; ``inf`` exactly at a pole (where
            ``sin(theta)`` is 0 the sample carries no weight).
        """
        angle = math.radians(self.rotation)
        return _sample_directions(np.ascontiguousarray(points, dtype=np.float64), self._marginal, self._conditional,
                                  self._func, self._mean, math.cos(angle), math.sin(angle))

    def pdf(self, directions):
        """Solid-angle density of :meth:`sample` at unit ``directions`` ((k, 3) -> (k,))."""
        uv = direction_to_latlong(directions, self.rotation)
        row = np.clip(((1.0 - uv[:, 1]) * self.height).astype(np.int64), 0, self.height - 1)
        column = np.clip((uv[:, 0] * self.width).astype(np.int64), 0, self.width - 1)
        return self._solid_angle_pdf(row, column, np.sqrt(np.maximum(1.0 - directions[:, 1] ** 2, 0.0)))

    def _solid_angle_pdf(self, row, column, sin_theta):
        """``p(u, v) / (2 pi^2 sin(theta))`` of the cells ``(row, column)``; ``inf`` at the poles."""
        with np.errstate(divide="ignore"):
            return np.where(sin_theta > 0.0, self._func[row, column] / self._mean / (2.0 * math.pi ** 2 * sin_theta),
                            np.inf)

    def direct(self, p, ng, reflectance, pixel, sample, depth, stats, clock, time=None):
        """Light from the background at every hit, ``light_samples`` shadow rays per hit:
        :meth:`rtmesh.lights.interface.SampledLighting.direct`, with shadow rays counted as
        ``environment``."""
        n = self.samples
        total = None
        for j in range(n):
            wi, pdf = self.sample(self.sampler.environment(pixel, sample, depth, j, n))
            # the radiance is looked up only where the shadow ray escapes (below): about half
            # the directions are below the surface, and some of the rest are blocked
            lit = (dot(wi, ng) > 0.0) & np.isfinite(pdf)
            rows = np.flatnonzero(lit)
            if not len(rows):
                continue
            wi_rows = take_rows(wi, rows)
            origins = offset_ray_origins(take_rows(p, rows), take_rows(ng, rows), scale=self.offset_scale,
                                         directions=wi_rows)
            clock.lap("shade")
            occluded = self.accel.occluded(origins, wi_rows, np.full(len(rows), np.inf),
                                           time=None if time is None else take_rows(time, rows))
            stats.rays["environment"] += len(rows)
            clock.lap("shadow")
            seen = rows[~occluded]
            if not len(seen):
                continue
            visible = np.zeros(len(p), dtype=bool)
            visible[seen] = True
            weight = np.zeros((len(p), 3))
            weight[seen] = self.background.radiance(take_rows(wi, seen)) / pdf[seen, None]
            contribution = reflectance(wi, visible, pdf) * weight
            total = contribution if total is None else total + contribution
        if total is not None:
            total *= 1.0 / n
        return total


@kernel
def _sample_directions(points, marginal, conditional, func, mean, cos_rotation, sin_rotation):
    """:meth:`EnvironmentLighting.sample` in one compiled pass per point: a row from the
    marginal cdf, a column from the row's conditional cdf (binary searches), the position
    within the cell by inverting the cdf linearly, the direction of that image point
    (:func:`rtmesh.sampling.warps.latlong_direction`, turned about +Y) and its
    solid-angle density ``p(u, v) / (2 pi^2 sin(theta))`` (``inf`` exactly at a pole).

    Parameters
    ----------
    points : (k, 2) float64
    marginal : (h + 1,) float64
        The rows' cdf, from 0 to 1.
    conditional : (h, w + 1) float64
        Each row's cdf over its columns, from 0 to 1.
    func : (h, w) float64
        The tabulated density (unnormalised); ``mean`` its mean.
    cos_rotation, sin_rotation : float

    Returns
    -------
    wi : (k, 3) float64
    pdf : (k,) float64
    """
    k = points.shape[0]
    wi = np.empty((k, 3))
    pdf = np.empty(k)
    for i in range(k):
        wi[i, 0], wi[i, 1], wi[i, 2], pdf[i] = sample_direction(marginal, conditional, func, mean, cos_rotation,
                                                                 sin_rotation, points[i, 0], points[i, 1])
    return wi, pdf


@row
def sample_direction(marginal, conditional, func, mean, cos_rotation, sin_rotation, u1, u2):
    """One direction of :func:`_sample_directions` and its solid-angle density (``inf`` at a
    pole), for one point ``(u1, u2)`` of the square; the path kernel calls it too."""
    h, w = func.shape
    row_index = min(max(np.searchsorted(marginal, u1, side="right") - 1, 0), h - 1)
    low, high = marginal[row_index], marginal[row_index + 1]
    dv = min(max((u1 - low) / (high - low), 0.0), 1.0)
    cdf = conditional[row_index]
    column = min(max(np.searchsorted(cdf, u2, side="right") - 1, 0), w - 1)
    low, high = cdf[column], cdf[column + 1]
    du = min(max((u2 - low) / (high - low), 0.0), 1.0)
    dx, dy, dz, cos_el = latlong_direction((column + du) / w, 1.0 - (row_index + dv) / h, cos_rotation, sin_rotation)
    pdf = func[row_index, column] / mean / (2.0 * math.pi ** 2 * cos_el) if cos_el > 0.0 else np.inf
    return dx, dy, dz, pdf


def _neighbourhood_max(values):
    """Largest value of each texel's 3 x 3 neighbourhood, (h, w) -> (h, w): columns wrap
    around (azimuth), rows clamp at the poles."""
    padded = np.concatenate([values[:, -1:], values, values[:, :1]], axis=1)
    padded = np.concatenate([padded[:1], padded, padded[-1:]], axis=0)
    h, w = values.shape
    return np.max([padded[i:i + h, j:j + w] for i in range(3) for j in range(3)], axis=0)
