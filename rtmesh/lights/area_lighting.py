"""The soft shadows of area lights: the direct-light estimator of quad, disk and mesh lights
(:mod:`rtmesh.lights.area_lights`, :mod:`rtmesh.lights.mesh_lights`), and where rays meet
the visible ones.

Estimator
---------
Per (hit, light), ``N = light_samples`` points ``y_j`` are drawn uniformly by area (pdf
``1 / A``; all the emissive triangles of a scene form one light, on which a triangle is
chosen in proportion to its power, area x mean emission, then a point uniformly on it) and
each gets a shadow ray::

    (1 / N) sum_j V(p, y_j) f(wi_j) L(y_j) cos_l,j / (d_j^2 pdf_A(y_j))

Area sampling is unbiased and maps the sampler's strata straight onto equal parts of the
light (a jittered set of N samples puts one in each of N equal cells of a quad), which is
what makes penumbrae smooth at small N.  Its variance grows only for points closer to the
light than the light's own size, where ``1 / d^2`` varies strongly over the light;
solid-angle sampling (Urena et al. 2013 for rectangles) would remove that.

The sample points come from the render's sampler (:meth:`rtmesh.sampling.sampler.Sampler.area_light`,
keyed by seed, pixel, sample, ray and dimension), in dimensions from :attr:`rtmesh.sampling.patterns.Dim.LIGHT` upward:
the ``spp * N`` points a pixel's samples send to one light are one stratified set, and the
``N`` of each hit are stratified among themselves.
"""

import numpy as np

from rtmesh.core.rays import take_rows
from rtmesh.core.vecmath import dot
from rtmesh.geometry.accel import offset_ray_origins
from rtmesh.sampling.sampler import Sampler

# Rays meeting a visible light and a surface at the same distance (a light placed flush on a
# ceiling) see the light: Embree's float32 distance to the surface carries a relative error
# of a few 1e-7, so the light wins within this relative margin.
_FLUSH_MARGIN = 1.0 + 1e-5


class AreaLighting:
    """Soft shadows and camera visibility of a scene's area lights.

    Parameters
    ----------
    lights : list of QuadLight, DiskLight or MeshLight
        In the integrator's (re-centred) frame.
    accel : Accel
        Traces the shadow rays.
    settings : RenderSettings
        ``light_samples``, ``sampler``, ``seed`` and ``spp`` (the size of the sets of pixel
        samples whose light samples are stratified together).
    offset_scale : float
        Scene size for :func:`rtmesh.geometry.accel.offset_ray_origins`.
    """

    def __init__(self, lights, accel, settings, offset_scale):
        self.lights = list(lights)
        self.accel = accel
        self.samples = settings.light_samples
        self.sampler = Sampler.for_settings(settings)
        self.offset_scale = offset_scale
        self.visible = [light for light in self.lights if light.visible]
        # the scene's emissive triangles (one MeshLight, see emissive_mesh_light), if any
        self.emitters = next((light for light in self.lights if getattr(light, "scene_faces", None) is not None),
                             None)

    def direct(self, p, ng, reflectance, pixel, sample, depth, stats, clock, time=None):
        """Direct light from every area light, ``light_samples`` shadow rays per (hit, light):
        :meth:`rtmesh.lights.interface.SampledLighting.direct`, with shadow rays counted as
        ``area_shadow`` (``accel`` is a :class:`rtmesh.geometry.motion.MotionAccel` when the
        hits have times)."""
        n = self.samples
        total = None
        for light_index, light in enumerate(self.lights):
            for j in range(n):
                u = self.sampler.area_light(pixel, sample, depth, light_index, len(self.lights), j, n)
                contribution = self._one_sample(p, ng, reflectance, light, u, stats, clock, time)
                if contribution is not None:
                    total = contribution if total is None else total + contribution
        if total is not None:
            total *= 1.0 / n
        return total

    def _one_sample(self, p, ng, reflectance, light, u, stats, clock, time=None):
        """One light sample per hit: ``V f L cos_l / (d^2 pdf_A)``, (k, 3) or None."""
        y, n_light, radiance, inverse_pdf = light.sample(u, p)
        to_light = y - p
        distance2 = dot(to_light, to_light)
        distance = np.sqrt(distance2)
        wi = to_light / np.where(distance > 0.0, distance, np.inf)[:, None]
        facing = -(wi @ n_light) if n_light.ndim == 1 else -dot(wi, n_light)
        cos_light = np.abs(facing) if light.two_sided else facing
        lit = (cos_light > 0.0) & (dot(wi, ng) > 0.0)
        rows = np.flatnonzero(lit)
        if not len(rows):
            return None
        # The shadow ray leaves the hit like every spawned ray, and ends just short of the
        # sampled point: the point is moved off the light toward the hit by the same float32
        # ulp offset (the ray run backwards), so an emissive triangle, which is in Embree,
        # cannot occlude its own sample, and a light flush with a ceiling is not hidden by
        # it, even at grazing angles.
        wi_rows = take_rows(wi, rows)
        start = offset_ray_origins(take_rows(p, rows), take_rows(ng, rows), scale=self.offset_scale,
                                   directions=wi_rows)
        toward = np.where(facing > 0.0, 1.0, -1.0)
        n_rows = (n_light[None, :] if n_light.ndim == 1 else take_rows(n_light, rows)) * toward[rows, None]
        target = offset_ray_origins(take_rows(y, rows), n_rows, scale=self.offset_scale,
                                    directions=-wi_rows)
        segment = target - start
        length = np.sqrt(dot(segment, segment))
        direction = segment / np.where(length > 0.0, length, np.inf)[:, None]
        clock.lap("shade")
        if time is None:
            occluded = self.accel.occluded(start, direction, length)
        else:
            occluded = self.accel.occluded(start, direction, length, time=time[rows])
        stats.rays["area_shadow"] += len(rows)
        clock.lap("shadow")
        visible = np.zeros(len(lit), dtype=bool)
        visible[rows[~occluded]] = True
        if not visible.any():
            return None
        weight = np.zeros(len(lit))
        v = np.flatnonzero(visible)
        inv = inverse_pdf if np.ndim(inverse_pdf) == 0 else inverse_pdf[v]
        weight[v] = cos_light[v] * inv / distance2[v]
        # the sample's solid-angle density, for reflectances that weigh it against BSDF sampling
        pdf = np.full(len(lit), np.inf)
        pdf[v] = 1.0 / weight[v]
        value = reflectance(wi, visible, pdf)
        value *= radiance
        value *= weight[:, None]
        return value

    def intersect(self, origins, directions, hits):
        """End rays on the visible quad and disk lights they meet before any surface.

        Parameters
        ----------
        origins, directions : (n, 3) float
        hits : Hits
            Closest surface hits of the rays; rows that meet a light first are changed in
            place to ``t`` = distance to the light and ``prim = -2`` (neither a surface nor
            a miss).

        Returns
        -------
        rows : (m,) intp
            Rays that ended on a light.
        emitted : (m, 3) float
            The radiance each of them sees.
        lights : (m,) intp
            Which light (index into :attr:`visible`) each met.
        """
        nearest = hits.t
        which = None
        for index, light in enumerate(self.visible):
            t = light.intersect(origins, directions)
            closer = (t < np.inf) & (t <= nearest * _FLUSH_MARGIN)
            if closer.any():
                nearest = np.where(closer, t, nearest)
                which = np.where(closer, index, -1 if which is None else which)
        if which is None:
            return np.zeros(0, dtype=np.intp), np.zeros((0, 3)), np.zeros(0, dtype=np.intp)
        rows = np.flatnonzero(which >= 0)
        hits.t = nearest
        hits.prim = np.where(which >= 0, -2, hits.prim).astype(hits.prim.dtype)
        radiance = np.stack([light.radiance for light in self.visible])
        return rows, radiance[which[rows]], which[rows]

    def pdf_of_visible(self, lights, origins, directions, t):
        """Solid-angle density of light sampling toward points on the visible lights that
        rays met (:meth:`intersect`), (m,): each light's :meth:`rtmesh.lights.area_lights.QuadLight.pdf`."""
        pdf = np.empty(len(lights))
        for index in np.unique(lights):
            rows = np.flatnonzero(lights == index)
            pdf[rows] = self.visible[index].pdf(origins[rows], directions[rows], t[rows])
        return pdf

    def pdf_of_emitters(self, origins, prim, points):
        """Solid-angle density of light sampling toward ``points`` on the emissive scene
        triangles ``prim``, from ``origins``, (k,) (0 for triangles that are not emitters)."""
        pdf = np.zeros(len(prim))
        if self.emitters is None:
            return pdf
        faces = self.emitters.scene_faces[prim]
        rows = np.flatnonzero(faces >= 0)
        if len(rows):
            pdf[rows] = self.emitters.pdf(take_rows(origins, rows), faces[rows], take_rows(points, rows))
        return pdf
