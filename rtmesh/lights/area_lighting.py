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

import math

import numpy as np

from rtmesh.core.compiled import by_component, kernel
from rtmesh.core.rays import take_rows
from rtmesh.core.row_vectors import dot3
from rtmesh.geometry.float32_rays import offset_origin
from rtmesh.lights.light_table import FLUSH_MARGIN
from rtmesh.sampling.sampler import Sampler



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
        # one normal for the whole light (a quad, a disk) travels as a single column
        normals_t = (np.ascontiguousarray(np.reshape(n_light, (3, 1)), dtype=np.float64) if n_light.ndim == 1
                     else by_component(np.asfortranarray(n_light, dtype=np.float64)))
        wi_t, distance2, cos_light, rows, start_t, direction_t, length = shadow_segments(
            *(by_component(np.asfortranarray(v, dtype=np.float64)) for v in (p, ng, y)), normals_t,
            light.two_sided, np.float32(self.offset_scale))
        if not len(rows):
            return None
        clock.lap("shade")
        if time is None:
            occluded = self.accel.occluded(start_t.T, direction_t.T, length)
        else:
            occluded = self.accel.occluded(start_t.T, direction_t.T, length, time=time[rows])
        stats.rays["area_shadow"] += len(rows)
        clock.lap("shadow")
        visible = np.zeros(len(distance2), dtype=bool)
        visible[rows[~occluded]] = True
        if not visible.any():
            return None
        weight = np.zeros(len(distance2))
        v = np.flatnonzero(visible)
        inv = inverse_pdf if np.ndim(inverse_pdf) == 0 else inverse_pdf[v]
        weight[v] = cos_light[v] * inv / distance2[v]
        # the sample's solid-angle density, for reflectances that weigh it against BSDF sampling
        pdf = np.full(len(distance2), np.inf)
        pdf[v] = 1.0 / weight[v]
        value = reflectance(wi_t.T, visible, pdf)
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
            closer = (t < np.inf) & (t <= nearest * FLUSH_MARGIN)
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


@kernel
def shadow_segments(points_t, normals_t, samples_t, light_normals_t, two_sided, scale):
    """The directions toward one light sample per hit, and the shadow segments of the hits
    it lights.

    The shadow ray leaves the hit like every spawned ray, and ends just short of the sampled
    point: the point is moved off the light toward the hit by the same float32 ulp offset
    (:func:`rtmesh.geometry.float32_rays.offset_origin`, the ray run backwards), so an
    emissive triangle, which is in Embree, cannot occlude its own sample, and a light flush
    with a ceiling is not hidden by it, even at grazing angles.

    Parameters
    ----------
    points_t, normals_t : (3, n) float64
        The hits and their geometric normals (facing the side the light is sampled from),
        by component (:func:`rtmesh.core.compiled.by_component`).
    samples_t : (3, n) float64
        The sampled points on the light.
    light_normals_t : (3, n) or (3, 1) float64
        The light's unit normal at each sample, or one for all.
    two_sided : bool
        The light emits from both faces.
    scale : float32
        Scene size, for the offsets.

    Returns
    -------
    wi_t : (3, n) float64
        Unit directions toward the samples (0 for a sample at the hit).
    distance2 : (n,) float64
        Squared distances to the samples.
    cos_light : (n,) float64
        Cosine at the light (its absolute value for a two-sided light).
    rows : (k,) int64
        The hits the sample lights: the light faces them and they face the light.
    start_t, direction_t : (3, k) float64
        Shadow-ray origins (float32 values) and unit directions.
    length : (k,) float64
        Shadow-ray lengths, in scene units.

    Notes
    -----
    Each dot product sums ``(x + y) + z`` (:func:`rtmesh.core.row_vectors.dot3`) and each
    quotient divides, as :func:`rtmesh.core.vecmath.dot` and NumPy's division do.
    """
    n = points_t.shape[1]
    one_normal = light_normals_t.shape[1] == 1
    wi_t = np.empty((3, n))
    distance2, cos_light, facing_light = np.empty(n), np.empty(n), np.empty(n, np.bool_)
    lit = np.empty(n, np.bool_)
    for i in range(n):
        tx, ty, tz = samples_t[0, i] - points_t[0, i], samples_t[1, i] - points_t[1, i], samples_t[2, i] - points_t[2, i]
        d2 = dot3(tx, ty, tz, tx, ty, tz)
        distance = math.sqrt(d2)
        divisor = distance if distance > 0.0 else np.inf
        wx, wy, wz = tx / divisor, ty / divisor, tz / divisor
        j = 0 if one_normal else i
        facing = -dot3(wx, wy, wz, light_normals_t[0, j], light_normals_t[1, j], light_normals_t[2, j])
        cosine = abs(facing) if two_sided else facing
        wi_t[0, i], wi_t[1, i], wi_t[2, i] = wx, wy, wz
        distance2[i], cos_light[i], facing_light[i] = d2, cosine, facing > 0.0
        lit[i] = cosine > 0.0 and dot3(wx, wy, wz, normals_t[0, i], normals_t[1, i], normals_t[2, i]) > 0.0
    rows = np.flatnonzero(lit)
    k = len(rows)
    start_t, direction_t, length = np.empty((3, k)), np.empty((3, k)), np.empty(k)
    for r in range(k):
        i = rows[r]
        wx, wy, wz = wi_t[0, i], wi_t[1, i], wi_t[2, i]
        sx, sy, sz = offset_origin(points_t[0, i], points_t[1, i], points_t[2, i], normals_t[0, i], normals_t[1, i],
                                   normals_t[2, i], wx, wy, wz, scale)
        # the light's normal turned toward the hit
        toward = 1.0 if facing_light[i] else -1.0
        j = 0 if one_normal else i
        ex, ey, ez = offset_origin(samples_t[0, i], samples_t[1, i], samples_t[2, i], light_normals_t[0, j] * toward,
                                   light_normals_t[1, j] * toward, light_normals_t[2, j] * toward, -wx, -wy, -wz,
                                   scale)
        gx, gy, gz = np.float64(ex) - np.float64(sx), np.float64(ey) - np.float64(sy), np.float64(ez) - np.float64(sz)
        segment = math.sqrt(dot3(gx, gy, gz, gx, gy, gz))
        divisor = segment if segment > 0.0 else np.inf
        start_t[0, r], start_t[1, r], start_t[2, r] = sx, sy, sz
        direction_t[0, r], direction_t[1, r], direction_t[2, r] = gx / divisor, gy / divisor, gz / divisor
        length[r] = segment
    return wi_t, distance2, cos_light, rows, start_t, direction_t, length
