"""Cut-outs: surfaces that let rays through where their opacity says so.

A material with ``alpha_mode`` "mask" is solid where its opacity (factor x texture alpha x
vertex alpha, see :mod:`rtmesh.rendering.surface_textures`) is at least ``alpha_cutoff`` and absent
elsewhere; with "blend" a ray passes with probability ``1 - opacity`` (stochastic
transparency: the expected image is the opacity-weighted blend, with no sorting and no
extra ray per layer).

:class:`CutoutAccel` wraps the scene's :class:`~rtmesh.geometry.accel.Accel` and offers the same two
queries, so every ray the integrator traces -- camera, reflection, refraction, shadow, area
light and AO rays -- sees the cut-outs.  A hit that lets the ray through is traced again
from just beyond the surface: the origin is the hit point offset by
:func:`~rtmesh.geometry.accel.offset_ray_origins` to the side the ray is heading to (the usual
self-intersection rule), and the distances add up.  The loop runs on the shrinking set of
rays that passed, vectorised, at most :data:`MAX_LAYERS` times; a ray still passing after
that stops at its last surface (a closest-hit ray) or counts as occluded (a shadow ray),
which errs toward dark rather than light leaks.

Random numbers
--------------
"blend" needs one uniform number per (ray, layer), from the render's sampler
(:meth:`rtmesh.sampling.sampler.Sampler.alpha_coin`).  It is keyed by the ray itself -- the
float32 bits of the origin Embree receives and of the direction -- hashed with the layer
index in dimension :attr:`rtmesh.sampling.patterns.Dim.ALPHA` of the render's seed.  Rays are pure
functions of (seed, pixel, sample), so the decision is too: the image does not depend on
the thread count or chunk size, and no query needs to carry sample keys.

Motion blur: a cut-out wraps a :class:`rtmesh.geometry.motion.MotionAccel` like a static
one; the point past a cut-out is formed on the rest pose and moved to the ray's time.
"""

import threading

import numpy as np

from rtmesh.core.rays import take_rows
from rtmesh.geometry.accel import barycentric_interpolate, offset_ray_origins
from rtmesh.sampling.hashing import mix64

# a ray crosses at most this many cut-out surfaces before it stops (foliage cards rarely
# stack deeper; each layer is one more vectorised Embree query on the rays still passing)
MAX_LAYERS = 16


def ray_keys(origins, directions):
    """A 64-bit key per ray from the float32 bits of its origin and direction, (n,) uint64."""
    o = np.ascontiguousarray(origins, dtype=np.float32).view(np.uint32).astype(np.uint64)
    d = np.ascontiguousarray(directions, dtype=np.float32).view(np.uint32).astype(np.uint64)
    key = np.zeros(len(o), dtype=np.uint64)
    with np.errstate(over="ignore"):
        for c in range(3):
            key = mix64(key ^ ((o[:, c] << np.uint64(32)) | d[:, c]))
    return key


class CutoutAccel:
    """An :class:`~rtmesh.geometry.accel.Accel` whose queries pass through cut-out surfaces.

    Parameters
    ----------
    accel : Accel or rtmesh.geometry.motion.MotionAccel
        The scene; with a :class:`~rtmesh.geometry.motion.MotionAccel` the queries take each ray's
        time, and the rays re-traced beyond a cut-out start where the surface stands then.
    face_normals : (F, 3) float
        Unit geometric normals (for the offset of re-traced rays).
    material_id : (F,) int
    cutout : (m,) bool
        Materials that can let rays through.
    mode_blend : (m,) bool
        Materials whose opacity is a probability (else a threshold).
    cutoff : (m,) float
        Thresholds of the "mask" materials.
    textures : rtmesh.rendering.surface_textures.SurfaceTextures
        Gives the opacity of each hit.
    offset_scale : float
        Scene size for :func:`offset_ray_origins`.
    seed : int
        Render seed (for "blend").

    Attributes
    ----------
    layers_traced : int
        Rays re-traced beyond a cut-out so far (all threads), the ``cutout`` ray count.
    """

    def __init__(self, accel, face_normals, material_id, cutout, mode_blend, cutoff, textures,
                 offset_scale, sampler):
        self.accel = accel
        self.triangles = accel.triangles
        self.face_normals = face_normals
        self.material_id = np.asarray(material_id, dtype=np.intp)
        self.cutout_face = np.asarray(cutout)[self.material_id]
        self.blend, self.cutoff = np.asarray(mode_blend), np.asarray(cutoff, dtype=np.float64)
        self.textures = textures
        self.offset_scale = offset_scale
        self.sampler = sampler
        self.layers_traced = 0
        self._lock = threading.Lock()

    def passes(self, hits, rows, keys, layer):
        """Which of the hits ``rows`` let the ray through, (k,) bool.

        Parameters
        ----------
        hits : Hits
        rows : (k,) intp
            Rays that hit a cut-out face.
        keys : (n,) uint64
            :func:`ray_keys` of every ray of the query.
        layer : int
            How many cut-outs the rays have passed already.
        """
        prim = hits.prim[rows].astype(np.intp)
        mat = self.material_id[prim]
        alpha = self.textures.opacities(prim, hits.u[rows], hits.v[rows], mat)
        blend = self.blend[mat]
        through = ~blend & (alpha < self.cutoff[mat])
        if blend.any():
            b = np.flatnonzero(blend)
            u = self.sampler.alpha_coin(keys[rows[b]], layer)
            through[b] = u >= alpha[b]
        return through

    def _beyond(self, hits, rows, directions, time):
        """Origins just past the hits ``rows``, on the side their rays head to."""
        prim = hits.prim[rows].astype(np.intp)
        p = barycentric_interpolate(take_rows(self.triangles, prim), hits.u[rows], hits.v[rows])
        d = take_rows(directions, rows)
        ng = self.face_normals[prim]  # a gathered copy, which may be changed in place
        if time is not None:
            # the triangles and normals are the rest pose: move them to the rays' time
            p, ng, _ = self.accel.surfaces_to_world(prim, time[rows], p, ng, ng)
        if getattr(hits, "instance", None) is not None:
            # a placed prototype's face: its point and normal carried to the world
            placed, instance = self.accel.instances, hits.instance[rows]
            p, ng = placed.world_points(p, instance), placed.world_normals(ng, instance)
        ng = ng * np.where((ng * d).sum(axis=1) < 0.0, -1.0, 1.0)[:, None]
        return offset_ray_origins(p, ng, np.float64, self.offset_scale, d)

    def intersect(self, origins, directions, time=None):
        """Closest hit of each ray that does not let it through; see :meth:`Accel.intersect`."""
        hits = self._hits_from(origins, directions, None, time)
        return self._resolve(hits, origins, directions, None, time)

    def occluded(self, origins, directions, t_max, rows=None, time=None):
        """Whether an opaque part of a surface lies on each segment; see :meth:`Accel.occluded`."""
        if rows is not None:
            origins, directions, t_max = take_rows(origins, rows), take_rows(directions, rows), t_max[rows]
            time = None if time is None else time[rows]
        if len(t_max) == 0:
            return np.zeros(0, dtype=bool)
        # closest hits up to t_max: the first surface decides whether to look further
        hits = self._hits_from(origins, directions, t_max, time)
        return self._resolve(hits, origins, directions, t_max, time).prim >= 0

    def _resolve(self, hits, origins, directions, t_max, time):
        """Re-trace the rays whose hit lets them through until each stops or escapes."""
        keys = None
        travelled = np.zeros(len(hits))
        retraced = 0
        active = np.arange(len(hits))  # rays whose latest hit is still to be decided
        for layer in range(MAX_LAYERS + 1):
            prim = hits.prim[active]
            on_cutout = active[(prim >= 0) & self.cutout_face[np.maximum(prim, 0)]]
            if not len(on_cutout):
                break
            if keys is None:
                keys = ray_keys(origins, directions)
            through = on_cutout[self.passes(hits, on_cutout, keys, layer)]
            if not len(through) or layer == MAX_LAYERS:
                break  # too deep: stop at this surface (a shadow ray counts as occluded)
            start = self._beyond(hits, through, directions, time)
            step = self._hits_from(start, take_rows(directions, through),
                                   None if t_max is None else t_max[through] - travelled[through] - hits.t[through],
                                   None if time is None else time[through])
            retraced += len(through)
            travelled[through] += hits.t[through]
            hits.prim[through], hits.u[through], hits.v[through] = step.prim, step.u, step.v
            if getattr(hits, "instance", None) is not None:
                hits.instance[through] = step.instance
            hits.t[through] = step.t
            active = through
        with self._lock:
            self.layers_traced += retraced
        hits.t = hits.t + travelled
        return hits

    def _hits_from(self, origins, directions, t_max, time):
        """Closest hits (at the rays' ``time``), as misses beyond ``t_max`` (None: no limit)."""
        hits = self.accel.intersect(origins, directions, time)
        if t_max is not None:
            hits.prim = np.where(hits.t > t_max, -1, hits.prim)
        return hits
