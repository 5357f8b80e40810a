"""Caustics under the path integrator: photon passes whose photons the path kernel gathers
(stochastic progressive photon mapping, Hachisuka & Jensen 2009, with the memoryless radius
rule of Knaus & Zwicker 2011).

When caustics are on, a render's samples run in passes: pass ``k`` traces a fresh set of
photons (:func:`rtmesh.rendering.photon_kernel.trace_photons`), sorts them into a hash grid
and renders sample ``k`` of every pixel that takes one, whose camera paths gather the
photons near each vertex with a non-delta part (:func:`rtmesh.rendering.photon_kernel.gather`).
Each pass is an independent density estimate, its radius shrinking as

    r_k^2 = r_0^2 * prod_{i=1..k} (i + alpha) / (i + 1),   alpha = 0.7

so that the average over passes converges to the right answer: the bias (proportional to
``r^2``) goes to zero while the photons gathered per pass, ``N pi r_k^2``, still grows
without bound in total (Knaus & Zwicker's rule; SPPM's per-pixel statistics shrink at the
same rate on average).  The radius is per camera vertex: ``RADIUS_PIXELS`` pixel footprints
at the path's length from the camera, so a caustic is blurred by about as much on screen
wherever it is seen.  Only one pass's photons exist at a time.

The per-pixel error estimate (the film's sample variance) covers the passes' variance, not
their bias; adaptive rounds continue each pixel's passes.

``caustics = "auto"`` turns the passes on when the scene has a surface that can scatter by a
delta lobe (a mirror, smooth glass: found by sampling each material) and a light a path
tracer cannot find through it: a point, spot or directional light, or an area light that
looks small from the specular surfaces (under ``SMALL_LIGHT`` sr).  Environment light alone
does not turn them on (ask with ``caustics = "photons"``).
"""

import logging
import math
import time

import numpy as np

from rtmesh.core import runtime
from rtmesh.core.compile_ahead import KernelGroup
from rtmesh.core.compiled import kernel
from rtmesh.core.errors import SceneError
from rtmesh.lights import light_table as lt
from rtmesh.materials import lobes, models
from rtmesh.rendering.path_signatures import no_instances, small_records
from rtmesh.rendering.photon_kernel import FIELDS, MAX_BOUNCES, photon_grid, trace_photons
from rtmesh.sampling.hashing import mix64
from rtmesh.sampling.patterns import Dim, sequence_key

log = logging.getLogger(__name__)

# the radius rule's alpha (the fraction of new photons a pass keeps, in SPPM's terms)
ALPHA = 0.7
# the first pass's gather radius, in pixel footprints at the vertex
RADIUS_PIXELS = 1.0
# a query sphere wider than this many grid cells is cut to it (far vertices)
MAX_RADIUS_CELLS = 4.0
# an area light smaller than this solid angle (sr) seen from the specular surfaces turns
# "auto" on
SMALL_LIGHT = 0.1
# photons a pass traces by default: a quarter of the pixel count, within these bounds (at
# 320x240 a quarter reached the same error in about half the time of the full count: the
# gather's cost grows with the photons near each vertex; docs/BENCHMARKS.md, Caustics)
DEFAULT_PHOTONS = (1 << 14, 1 << 20)
PHOTONS_PER_PIXEL = 0.25
# photons a thread traces at a time
CHUNK_PHOTONS = 8192


@kernel
def lobe_census(tags, params, table):
    """Which materials can scatter by a delta lobe and which have a non-delta part, found by
    sampling each material's BSDF on a fixed grid of directions (both sides) and numbers.

    Returns
    -------
    specular, scatters : (M,) bool
    """
    m = len(tags)
    specular = np.zeros(m, np.bool_)
    scatters = np.zeros(m, np.bool_)
    for mat in range(m):
        for side in range(2):
            for c in range(3):
                oz = (0.15 + 0.4 * c) * (1.0 if side == 0 else -1.0)
                ox = math.sqrt(1.0 - oz * oz)
                # lobe choices 1/256 apart: a delta lobe chosen with a few per cent (a clear coat's
                # Fresnel) is found
                for i in range(256):
                    for j in range(4):
                        for k in range(4):
                            _, _, _, wr, wg, wb, _, flags = models.sample(
                                tags[mat], params, mat, table, ox, 0.0, oz, (i + 0.5) / 256.0, (j + 0.5) / 4.0,
                                (k + 0.5) / 4.0)
                            if flags == lobes.FAILED or not ((wr > 0.0) | (wg > 0.0) | (wb > 0.0)):
                                continue
                            if flags & lobes.DELTA:
                                specular[mat] = True
                            else:
                                scatters[mat] = True
    return specular, scatters


def _photon_signatures():
    """The signatures a caustics render calls its kernels with (
    :func:`~rtmesh.rendering.photon_kernel.trace_photons`,
    :func:`~rtmesh.rendering.photon_kernel.photon_grid`), from the path kernel's small records."""
    import numba
    from numba import types

    from rtmesh.geometry.embree_packets import numba_typeof_query

    energy, geometry, surface, lights, env = small_records()
    f64, i64 = types.float64, types.int64
    vector, rows = types.Array(f64, 1, "C"), types.Array(f64, 2, "C")
    flags, counts = types.Array(types.bool_, 1, "C"), types.Array(i64, 1, "C")
    options = numba.typeof((0, np.float32(1.0), False, 0))
    trace = (numba_typeof_query(), i64, types.uint64, types.Array(types.uint64, 1, "C"), i64, i64) + tuple(
        numba.typeof(record) for record in (geometry, surface, lights, env, no_instances())) + (
        vector, vector, flags, flags, options, rows, counts, counts)
    return [(trace_photons, trace), (photon_grid, (rows, f64, i64))]


# the kernels of photon passes, prepared when a render turns them on (and compiled ahead by a
# test session); the small lobe census, which every path render calls, is not in it
PHOTON_KERNELS = KernelGroup(__name__, "photons", _photon_signatures())


def radius_factor(k):
    """The pass-``k`` (0-based) radius over the first pass's: ``sqrt(prod_{i=1..k} (i + alpha) / (i + 1))``,
    through log-gamma (no product of thousands of factors)."""
    return math.exp(0.5 * (math.lgamma(k + 1 + ALPHA) - math.lgamma(1 + ALPHA) - math.lgamma(k + 2)))


def _specular_corners(triangles, faces, placed):
    """World-space points whose bounding sphere holds every specular face: the corners of
    the world-space ones and, for each placement of a prototype with specular faces, the
    eight corners of their box carried to the world (one box a placement, not its copy).

    Parameters
    ----------
    triangles : (F, 9) float
        Per face: a corner and the two edges from it (the path kernel's ``geometry[0]``).
    faces : (m,) int
        The specular faces.
    placed : rtmesh.scene.instances.Instances or None
        The placements (re-centred).

    Returns
    -------
    (n, 3) float64
    """
    tri = triangles[faces].astype(np.float64)
    corners = np.concatenate([tri[:, 0:3], tri[:, 0:3] + tri[:, 3:6], tri[:, 0:3] + tri[:, 6:9]]).reshape(3, -1, 3)
    if placed is None:
        return corners.reshape(-1, 3)
    world = faces < placed.first_face
    points = [corners[:, world].reshape(-1, 3)]
    prototype = np.searchsorted(placed.prototype_faces, faces, side="right") - 1
    for p in np.unique(prototype[~world]):
        own = corners[:, prototype == p].reshape(-1, 3)
        low, high = own.min(axis=0), own.max(axis=0)
        box = np.array([[(low, high)[i >> k & 1][k] for k in range(3)] for i in range(8)])
        where = np.flatnonzero(placed.prototype == p)
        points.append(placed.world_points(np.tile(box, (len(where), 1)), np.repeat(where, 8)))
    return np.concatenate(points)


def _bounding_sphere(points):
    """A sphere enclosing ``points`` ((n, 3)): centred on their box, as wide as the farthest
    point (for a round object much tighter than the box's half-diagonal, so fewer photons
    miss it)."""
    low, high = points.min(axis=0), points.max(axis=0)
    centre = (low + high) / 2.0
    radius = float(np.sqrt(((points - centre) ** 2).sum(axis=1).max()))
    # a hair wider: the float32 triangles Embree traces may lie an ulp outside
    return np.concatenate([centre, [max(radius * (1.0 + 1e-6), 1e-9)]])


class Caustics:
    """The photon passes of one view under the path integrator.

    Parameters
    ----------
    stage : PathStage
        Its records (geometry, surface, lights, environment).
    it : Integrator
        The view (settings, camera, threads).

    Attributes
    ----------
    enabled : bool
        Whether the render runs photon passes.
    photons : int
        Photons a pass traces.
    """

    def __init__(self, stage, it):
        s = it.settings
        self.it, self.stage = it, stage
        self.enabled = False
        if s.caustics == "off" or s.integrator != "path":
            return
        geometry, surface = stage.geometry, stage.surface
        tags, params = surface[0], surface[1]
        specular, scatters = lobe_census(tags, params, surface[6])
        # textures can make a material's parameters anything: count a textured material as
        # both (photons then try it; a gather at a pure-delta texel finds nothing)
        textured = (surface[8] >= 0).any(axis=1) | (len(geometry[7]) > 0)
        self.specular = np.ascontiguousarray(specular | textured)
        self.scatters = np.ascontiguousarray(scatters | textured)
        material_id = geometry[5]
        triangles = geometry[0]
        faces = np.flatnonzero(self.specular[material_id])
        lights = stage.lights
        reason = None
        if it.motion is not None:
            reason = "moving objects"
            if s.caustics == "photons":
                raise SceneError("caustics = 'photons' does not render scenes with moving objects yet; "
                                 "use caustics = 'off'")
        elif not len(faces):
            reason = "no surface scatters by a delta lobe (mirror, smooth glass)"
        elif not len(lights.rows):
            reason = "no lights"
        self.aim = _bounding_sphere(_specular_corners(triangles, faces, it.instances)) if len(faces) else np.zeros(4)
        if reason is None and s.caustics == "auto" and not self._small_light(lights):
            reason = "every light is large seen from the specular surfaces"
        if reason is not None:
            if s.caustics == "photons":
                log.warning("caustics = 'photons': no photon pass (%s)", reason)
            return
        self.enabled = True
        PHOTON_KERNELS.prepare()
        # the scene's box in the re-centred frame the triangles are in, and a sphere around it
        self.scene_sphere = np.array([0.0, 0.0, 0.0, float(np.linalg.norm(np.ptp(it.scene_bounds, axis=0))) / 2.0])
        self.photons = s.photons or int(np.clip(PHOTONS_PER_PIXEL * s.width * s.height, *DEFAULT_PHOTONS))
        self.max_bounces = MAX_BOUNCES if s.max_depth < 0 else max(s.max_depth - 1, 0)
        # one pixel's footprint: a + b * distance (perspective: the pixel's angle; orthographic:
        # its size)
        camera = it.camera
        if camera.orthographic:
            self.footprint = (camera.ortho_height / s.height, 0.0)
        else:
            self.footprint = (0.0, 2.0 * math.tan(math.radians(camera.fov) / 2.0) / s.height)
        distance = float(np.linalg.norm(np.asarray(camera.position, dtype=np.float64) - self.aim[:3]))
        self.reference_radius = RADIUS_PIXELS * (self.footprint[0] + self.footprint[1] * distance)
        with np.errstate(over="ignore"):  # the hash's products wrap modulo 2**64 by design
            self._seed_key = mix64(np.uint64(s.seed % (1 << 64)) ^ np.uint64(0xCA05_71C5_0F1E_1D5A))
        self._map_pass = None
        self._map = None

    def _small_light(self, lights):
        """Whether a delta light or a small area light exists (seen from the aim's centre)."""
        kinds = lights.rows[:, 0]
        if ((kinds < lt.QUAD) | (kinds == lt.PROJECTOR)).any():
            return True
        centre = self.aim[:3]
        solid = []
        emissive = 0.0
        for row in lights.rows[(kinds == lt.QUAD) | (kinds == lt.DISK) | (kinds == lt.TRIANGLE)]:
            if row[0] == lt.QUAD:
                middle = row[1:4] + 0.5 * (row[10:13] + row[13:16])
            elif row[0] == lt.DISK:
                middle = row[1:4]
            else:
                middle = row[1:4] + (row[10:13] + row[13:16]) / 3.0
            d2 = max(float(np.sum((middle - centre) ** 2)), 1e-30)
            angle = row[lt.AREA] / d2
            if row[0] == lt.TRIANGLE:
                emissive += angle  # the emissive triangles as one light
            else:
                solid.append(angle)
        if emissive > 0.0:
            solid.append(emissive)
        return any(a < SMALL_LIGHT for a in solid)

    def photon_map(self, k, stats, pool=None):
        """The path kernel's ``photon_map`` record of pass ``k`` (traced once, kept until
        another pass is asked for); a pass traced is added to the render's ``stats``
        (:class:`~rtmesh.rendering.stats.RenderStats`: passes, photons, rays, time)."""
        if self._map_pass == k:
            return self._map
        self._map = None  # one pass's photons at a time
        t0 = time.perf_counter()
        photons, rays = self._trace(k, pool)
        cell = self.reference_radius * radius_factor(k)
        bits = max(10, int(math.ceil(math.log2(max(2 * len(photons), 1)))))
        order, start = photon_grid(photons, cell, bits)
        photons = np.ascontiguousarray(photons[order])
        self._map = (True, photons, start, cell, bits, 1.0 / (math.pi * self.photons), RADIUS_PIXELS * radius_factor(k),
                     self.footprint[0], self.footprint[1], MAX_RADIUS_CELLS * cell, self.scatters)
        self._map_pass = k
        stats.photon_passes += 1
        stats.photons = self.photons
        stats.photons_stored += len(photons)
        stats.rays["photon"] += rays
        stats.photon_seconds += time.perf_counter() - t0
        return self._map

    def _trace(self, k, pool):
        """Trace pass ``k``'s photons in chunks on the render's threads; their stored rows in
        photon order, and the rays traced."""
        stage, s = self.stage, self.it.settings
        with np.errstate(over="ignore"):
            pass_key = mix64(self._seed_key ^ (np.uint64(k) * np.uint64(0x9E3779B97F4A7C15)))
        sobol_keys = np.array([sequence_key(s.seed, np.array([k]), Dim.PHOTON_POINT)[0],
                               sequence_key(s.seed, np.array([k]), Dim.PHOTON_DIRECTION)[0]], dtype=np.uint64)
        intersect, _, handle = stage._queries
        options = (self.max_bounces, np.float32(self.it.offset_scale), stage.cutouts, len(stage._camera_media))

        def chunk(first):
            count = min(CHUNK_PHOTONS, self.photons - first)
            capacity = 2 * count
            while True:
                rows = np.zeros((capacity, FIELDS))
                stored = np.zeros(2, np.int64)
                counts = np.zeros(1, np.int64)
                trace_photons(intersect, handle, pass_key, sobol_keys, first, count, stage.geometry,
                              stage.surface, stage.light_record, stage._env, stage._instances, self.aim,
                              self.scene_sphere,
                              self.specular, self.scatters, options, rows, stored, counts)
                if stored[1] <= capacity:
                    return rows[:stored[0]], int(counts[0])
                capacity = int(stored[1])

        starts = range(0, self.photons, CHUNK_PHOTONS)
        with runtime.render_pool(s.thread_count, pool) as workers:
            results = list(workers.map(chunk, starts)) if workers is not None else [chunk(a) for a in starts]
        photons = np.concatenate([r[0] for r in results]) if results else np.zeros((0, FIELDS))
        return photons, sum(r[1] for r in results)
