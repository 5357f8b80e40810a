"""Every light of a scene as one table of rows for the path integrator: one light interface
(``sample_li``, ``pdf_li``, ``power``) over every light type, and the choice of a light by
power through an alias table, so that many lights (emissive meshes hold one light per
triangle) cost one table lookup per vertex, not a loop.

Rows
----
A row is :data:`WIDTH` float64 words.  Point, spot and directional lights keep the row of
:mod:`rtmesh.lights.point_light_rows` (kinds 0-2, their incident term ``E`` from
``illuminate_row``: ``I / d^2`` in W/sr, irradiance in W/m^2); area lights add:

=============  ==================================================================
QUAD (3)       corner (1-3), normal (4-6), radiance (7-9), edge1 (10-12), edge2 (13-15)
DISK (4)       centre (1-3), normal (4-6), radiance (7-9), radius x tangents (10-15)
TRIANGLE (5)   corner v0 (1-3), normal (4-6), radiance (7-9), e1 (10-12), e2 (13-15)
ENVIRONMENT (6) the background (its tables are
               :class:`rtmesh.lights.environment_table.EnvironmentTables`)
PROJECTOR (7)  pinhole (1-3), forward (4-6), intensity (7-9), image right (10-12), image
               up (13-15), its image in the lights' atlas (:data:`IMAGE`), the half-width
               and half-height of the image plane at unit distance (:data:`HALF_WIDTH`,
               :data:`HALF_HEIGHT`)
=============  ==================================================================

with the area (:data:`AREA`), whether it emits on both sides (:data:`TWO_SIDED`) and whether
rays see it (:data:`VISIBLE`; emissive triangles are seen as geometry).  ``sample_li``
returns the direction toward the light, the distance, the incident radiance (for delta
lights the incident term) and the solid-angle density (1 for delta lights, flagged).

The projectors' images are packed into one atlas of the view's lights
(:class:`rtmesh.io.texture_atlas.TextureAtlas`: ``LightTable.texels``, ``LightTable.descriptors``),
looked up by :func:`projector_incident` as :meth:`rtmesh.lights.projector.ProjectorLight.illuminate`
maps them.
"""

import math

import numpy as np

from rtmesh.core.compiled import row
from rtmesh.core.row_vectors import normalized3
from rtmesh.io.texture_atlas import TextureAtlas, texel
from rtmesh.lights import point_light_rows
from rtmesh.lights.area_lights import DiskLight, QuadLight
from rtmesh.lights.projector import ProjectorLight
from rtmesh.materials.lobes import LUMA as _LUMA
from rtmesh.sampling.alias import alias_table
from rtmesh.sampling.warps import (concentric_disk_row, spherical_triangle_area_row, spherical_triangle_row,
                                   uniform_triangle_weights)

QUAD, DISK, TRIANGLE, ENVIRONMENT, PROJECTOR = 3, 4, 5, 6, 7
# A triangle light seen under a solid angle in this range is sampled uniformly in that solid
# angle (Arvo's spherical triangles), not by area: beside a lamp, area samples weigh the near
# part by 1 / d^2 (rare, very bright values).  Below the range the angle sums lose their
# digits and area sampling is as good; above it the triangle covers nearly a hemisphere,
# where the construction degenerates (pbrt-v4's Triangle::Sample bounds, 3e-4 and 6.22 sr).
SOLID_ANGLE_FROM, SOLID_ANGLE_TO = 1e-3, 6.22
# Rays meeting a visible light and a surface at the same distance (a light placed flush on a
# ceiling) see the light: Embree's float32 distance to the surface carries a relative error
# of a few 1e-7, so the light wins within this relative margin.
FLUSH_MARGIN = 1.0 + 1e-5
WIDTH = 24
RADIANCE = 7
AREA, TWO_SIDED, VISIBLE, FACE = 16, 17, 18, 19
IMAGE, HALF_WIDTH, HALF_HEIGHT = 20, 21, 22


def _luminance(colour):
    return float(np.dot(_LUMA, np.asarray(colour, dtype=np.float64)))


# memory of one light: its row, its alias table entry and its choice probability (bytes)
BYTES_PER_LIGHT = WIDTH * 8 + 24


class _Blocks:
    """Rows gathered one by one (``append``) or in blocks (``extend``), joined once."""

    def __init__(self):
        self._blocks, self._count = [], 0

    def append(self, row):
        self.extend(np.asarray(row, dtype=np.float64)[None, :])

    def extend(self, block):
        self._blocks.append(block)
        self._count += len(block)

    def __len__(self):
        return self._count

    def array(self):
        """(L, WIDTH) float64."""
        return np.concatenate(self._blocks) if self._blocks else np.zeros((0, WIDTH))


def placed_light_count(instances, face_emission):
    """How many lights the placements of emissive prototype faces make in a
    :class:`LightTable` (at most: faces of zero area make none), for a memory estimate
    (:data:`BYTES_PER_LIGHT` each)."""
    emits = np.concatenate([[0], np.cumsum((face_emission[instances.first_face:] > 0).any(axis=1))])
    bounds = instances.prototype_faces - instances.first_face
    per_prototype = emits[bounds[1:]] - emits[bounds[:-1]]
    return int(per_prototype[instances.prototype].sum())


def _triangle_block(corner, e1, e2, normals, emission, faces, two_sided, keep_all=False):
    """Rows of emissive triangles (corner, edges, normals and radiance as (n, 3) arrays,
    ``faces`` their faces in the per-face tables) and the faces kept: those of non-zero area
    (all of them with ``keep_all``)."""
    area = 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1)
    if not keep_all and not (area > 0.0).all():
        keep = area > 0.0
        corner, e1, e2, normals, emission, faces, area = (a[keep] for a in (corner, e1, e2, normals, emission,
                                                                            faces, area))
    block = np.empty((len(area), WIDTH))
    block[:, 0] = TRIANGLE
    block[:, 1:4], block[:, 10:13], block[:, 13:16] = corner, e1, e2
    block[:, 4:7], block[:, 7:10] = normals, emission
    # one-sided, toward the winding's normal (as pbrt's and Mitsuba's area lights), or
    # on both sides (the Whitted convention, rtmesh.lights.mesh_lights)
    block[:, AREA], block[:, TWO_SIDED], block[:, VISIBLE], block[:, FACE] = area, float(two_sided), 1.0, faces
    block[:, FACE + 1:] = 0.0
    return block, faces


def _row(kind, point, normal, radiance, a, b, area, two_sided, visible, face=-1.0):
    r = np.zeros(WIDTH)
    r[0] = kind
    r[1:4], r[4:7], r[7:10], r[10:13], r[13:16] = point, normal, radiance, a, b
    r[AREA], r[TWO_SIDED], r[VISIBLE], r[FACE] = area, two_sided, visible, face
    return r


class LightTable:
    """The lights of one view, as rows, with the alias table that chooses among them.

    Parameters
    ----------
    lights : list
        Point, spot, directional, quad and disk lights (in the re-centred frame).
    triangles : (F, 9) float64
        ``[v0, e1, e2]`` of every triangle as Embree traces them.
    face_normals : (F, 3) float64
    face_emission : (F, 3) float64
        Emitted radiance of each face (zero for most).
    environment : rtmesh.lights.environment_table.EnvironmentTables or None
        The background, when it lights the scene.
    scene_radius : float
        Bounds the power of lights at infinity (directional, environment): what falls on
        the scene.
    two_sided_emitters : bool
        Emissive triangles emit on both sides (the Whitted integrator's convention), not
        toward their winding's normal only.
    instances : rtmesh.scene.instances.Instances, optional
        The scene's placements: ``triangles`` from ``instances.first_face`` on are the
        prototypes' (model coordinates), and every placement of an emissive prototype face
        is a light of its own, its triangle carried to the world.

    Attributes
    ----------
    rows : (L, WIDTH) float64
    probability, alias : (L,) float64, (L,) int64
        The alias table (:mod:`rtmesh.sampling.alias`).
    pmf : (L,) float64
        Each light's choice probability.
    power : (L,) float64
        What the choice weighs each light by (its power; the lights at infinity: what falls
        on the scene).
    face_light : (F,) int64
        The light of each emissive face, -1 elsewhere; for a prototype's face, its rank among
        its prototype's emissive faces (the light is ``placement_light[j]`` plus the rank).
    placement_light : (k,) int64
        Each placement's first light (its prototype's emissive faces in order), -1 where the
        prototype emits nothing; empty without placements.
    environment : int
        The environment's row, or -1.
    analytic : (k,) int64
        The rows of the quad and disk lights that rays see (tested along every ray).
    texels, descriptors : (n,) float32, (p, DESCRIPTOR_WIDTH) float64
        The projectors' images (:class:`rtmesh.io.texture_atlas.TextureAtlas`; one texel of
        zero without projectors).
    """

    def __init__(self, lights, triangles, face_normals, face_emission, environment, scene_radius,
                 two_sided_emitters=False, instances=None):
        # blocks of rows and their powers (emissive triangles come in blocks of many)
        rows, power = _Blocks(), []
        images = []
        for light in lights:
            if isinstance(light, ProjectorLight) and not any(light.image is known for known in images):
                images.append(light.image)
        atlas = TextureAtlas(images)
        self.texels, self.descriptors = atlas.texels, atlas.descriptors
        for light in lights:
            if isinstance(light, ProjectorLight):
                forward, right, up = light.frame()
                half_height = math.tan(math.radians(light.fov) / 2.0)
                height, width = light.image.shape[:2]
                r = _row(PROJECTOR, light.position, forward, light.intensity, right, up, 0.0, 0.0, 0.0)
                r[IMAGE], r[HALF_WIDTH], r[HALF_HEIGHT] = atlas.index(light.image), half_height * width / height, \
                    half_height
                rows.append(r)
                power.append(_projector_power(light, r[HALF_WIDTH], half_height))
            elif isinstance(light, QuadLight):
                rows.append(_row(QUAD, light.corner, light.normal, light.radiance, light.edge1, light.edge2,
                                 light.area, 0.0, float(light.visible)))
                power.append(math.pi * light.area * _luminance(light.radiance))
            elif isinstance(light, DiskLight):
                rows.append(_row(DISK, light.position, light.normal, light.radiance, light._tangents[0],
                                 light._tangents[1], light.area, 0.0, float(light.visible)))
                power.append(math.pi * light.area * _luminance(light.radiance))
            else:
                packed = light.kernel_row() if hasattr(light, "kernel_row") else None
                if packed is None:
                    raise ValueError(f"the path integrator cannot sample a {type(light).__name__} yet")
                r = np.zeros(WIDTH)
                r[:len(packed)] = packed
                rows.append(r)
                power.append(_delta_power(packed, scene_radius))
        emissive = np.flatnonzero((face_emission > 0).any(axis=1))
        first_placed = len(triangles) if instances is None else instances.first_face
        self.face_light = np.full(len(triangles), -1, dtype=np.int64)
        self.placement_light = np.full(0 if instances is None else len(instances), -1, dtype=np.int64)
        world = emissive[emissive < first_placed]
        if len(world):
            block, world = _triangle_block(triangles[world, 0:3], triangles[world, 3:6], triangles[world, 6:9],
                                           face_normals[world], face_emission[world], world, two_sided_emitters)
            self.face_light[world] = len(rows) + np.arange(len(world))
            rows.extend(block)
            power.append(math.pi * block[:, AREA] * (block[:, RADIANCE:RADIANCE + 3] @ _LUMA))
        prototype_emitters = emissive[emissive >= first_placed]
        if len(prototype_emitters):
            self._place_emitters(instances, prototype_emitters, triangles, face_normals, face_emission,
                                 two_sided_emitters, rows, power)
        self.environment = -1
        if environment is not None:
            self.environment = len(rows)
            rows.append(_row(ENVIRONMENT, np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3),
                             0.0, 0.0, 1.0))
            power.append(environment.power(scene_radius))
        self.rows = rows.array()
        power = np.maximum(np.concatenate([np.atleast_1d(np.asarray(p, dtype=np.float64)) for p in power])
                           if power else np.zeros(0), 0.0)
        if len(power) and not power.sum() > 0.0:
            power = np.ones_like(power)
        self.power = power
        self.probability, self.alias, self.pmf = alias_table(power)
        kinds = self.rows[:, 0] if len(self.rows) else np.zeros(0)
        self.analytic = np.flatnonzero(((kinds == QUAD) | (kinds == DISK)) & (self.rows[:, VISIBLE] > 0)
                                       if len(self.rows) else np.zeros(0, bool)).astype(np.int64)

    def _place_emitters(self, instances, faces, triangles, face_normals, face_emission, two_sided, rows, power):
        """Append a light for every placement of every emissive prototype face in ``faces``
        (ascending), carried to the world by the placement's transform (as
        :meth:`~rtmesh.scene.instances.Instances.world_points` and ``world_normals`` carry
        the traced surface); set :attr:`face_light` (ranks) and :attr:`placement_light`."""
        # faces of zero area emit nothing (as in the world)
        e1, e2 = triangles[faces, 3:6], triangles[faces, 6:9]
        faces = faces[np.linalg.norm(np.cross(e1, e2), axis=1) > 0.0]
        prototype_of = np.searchsorted(instances.prototype_faces, faces, side="right") - 1
        first_of = np.searchsorted(prototype_of, np.arange(len(instances.prototype_faces) - 1))
        count_of = np.bincount(prototype_of, minlength=len(first_of))
        self.face_light[faces] = np.arange(len(faces)) - first_of[prototype_of]
        counts = count_of[instances.prototype]
        total = int(counts.sum())
        block_start = np.cumsum(counts) - counts
        self.placement_light = np.where(counts > 0, len(rows) + block_start, -1).astype(np.int64)
        placement = np.repeat(np.arange(len(counts)), counts)
        face = faces[np.repeat(first_of[instances.prototype], counts) + np.arange(total) - np.repeat(block_start,
                                                                                                     counts)]
        corner = instances.world_points(triangles[face, 0:3], placement)
        edges = [instances.world_vectors(triangles[face, k:k + 3], placement) for k in (3, 6)]
        normals = instances.world_normals(face_normals[face], placement)
        block, _ = _triangle_block(corner, edges[0], edges[1], normals, face_emission[face], face, two_sided,
                                   keep_all=True)
        rows.extend(block)
        power.append(math.pi * block[:, AREA] * (block[:, RADIANCE:RADIANCE + 3] @ _LUMA))

    def __len__(self):
        return len(self.rows)

    def light_groups(self):
        """The lights as the Whitted integrator samples them: every delta light (point, spot,
        directional, projector) once; each quad and disk light, the environment, and the
        emissive triangles together (one light, their faces by power), ``light_samples``
        times each.

        Returns
        -------
        delta_rows : (D,) int64
            The delta lights' rows.
        group_start : (G + 1,) int64
            Group ``g`` holds the rows ``order[group_start[g]:group_start[g + 1]]``.
        order : (L - D,) int64
            The rows of the groups, group by group.
        probability, alias : (L - D,) float64, int64
            Each group's alias table over its rows (aliases are positions within the group).
        pmf : (L,) float64
            Each row's probability within its group (0 for delta lights).
        """
        kinds = self.rows[:, 0]
        triangles = np.flatnonzero(kinds == TRIANGLE)
        alone = (kinds == QUAD) | (kinds == DISK) | (kinds == ENVIRONMENT)
        delta_rows = np.flatnonzero(~alone & (kinds != TRIANGLE)).astype(np.int64)
        groups = [[row] for row in np.flatnonzero(alone)] + ([triangles] if len(triangles) else [])
        order, probability, alias, start = [], [], [], [0]
        pmf = np.zeros(len(self.rows))
        for rows in groups:
            rows = np.asarray(rows, dtype=np.int64)
            weights = self.pmf[rows] if self.pmf[rows].sum() > 0.0 else np.ones(len(rows))
            p, a, pmf[rows] = alias_table(weights)
            order.append(rows), probability.append(p), alias.append(a)
            start.append(start[-1] + len(rows))
        cat = (lambda parts, dtype: np.concatenate(parts).astype(dtype) if parts else np.zeros(0, dtype))
        return (delta_rows, np.array(start, dtype=np.int64), cat(order, np.int64), cat(probability, np.float64),
                cat(alias, np.int64), pmf)


def _delta_power(packed, scene_radius):
    """Power of a point, spot or directional light (for choosing among lights)."""
    kind = packed[point_light_rows.KIND]
    colour = packed[point_light_rows.POWER:point_light_rows.POWER + 3]
    if kind == point_light_rows.DIRECTIONAL:
        return math.pi * scene_radius * scene_radius * _luminance(colour)
    if kind == point_light_rows.SPOT:
        cos_inner, cos_outer = packed[point_light_rows.COS_INNER], packed[point_light_rows.COS_OUTER]
        return 2.0 * math.pi * (1.0 - 0.5 * (cos_inner + cos_outer)) * _luminance(colour)
    return 4.0 * math.pi * _luminance(colour)


def _projector_power(light, half_width, half_height):
    """Power of a projector (W, luminance): its intensity times each texel's colour over the
    solid angle the texel subtends, summed over the image (the image's mean and its cone:
    a white image gives ``I * 4 asin(sin a sin b)`` of the frustum's half-angles ``a, b``).

    The image plane at unit distance holds ``(2 half_width) x (2 half_height)``; a texel of
    area ``dA`` at ``(x, y)`` on it subtends ``dA / (1 + x^2 + y^2)^(3/2)`` (midpoint rule, whose
    error on the frustum's solid angle is below 1e-3 for images of 8 texels or more).
    """
    pixels = np.asarray(light.image.pixels, dtype=np.float64)
    height, width, channels = pixels.shape
    colour = pixels[..., :3] if channels >= 3 else np.repeat(pixels[..., :1], 3, axis=2)
    x = ((np.arange(width) + 0.5) / width * 2.0 - 1.0) * half_width
    y = ((np.arange(height) + 0.5) / height * 2.0 - 1.0) * half_height
    texel_area = (2.0 * half_width / width) * (2.0 * half_height / height)
    solid_angle = texel_area / (1.0 + x[None, :] ** 2 + y[:, None] ** 2) ** 1.5
    return float(np.sum((colour @ (_LUMA * light.intensity)) * solid_angle))


# ------------------------------------------------------------------ compiled rows
@row
def area_pdf(light, px, py, pz, dx, dy, dz, distance):
    """Solid-angle density of ``sample_li`` reaching a point of an area light from ``p``
    along unit ``d`` at ``distance``; 0 from behind a one-sided light.  A triangle that
    :func:`solid_angle_sampled` says is sampled in solid angle has ``1 / omega``."""
    cos_l = _facing_cosine(light, dx, dy, dz)
    omega = 0.0
    if light[0] == TRIANGLE and cos_l > 0.0:
        omega = triangle_solid_angle(light, px, py, pz)
    return _area_density(light, omega, cos_l, distance)


@row
def _facing_cosine(light, dx, dy, dz):
    """Cosine between an area light's emitting side and the reverse of unit ``d`` (its
    absolute value for a two-sided light)."""
    cos_l = -((light[4] * dx + light[5] * dy) + light[6] * dz)
    return abs(cos_l) if light[TWO_SIDED] > 0.0 else cos_l


@row
def _area_density(light, omega, cos_l, distance):
    """:func:`area_pdf` given the solid angle ``omega`` a triangle light subtends from the
    point (quads and disks: not read), as :func:`sample_area` knows it, and the light's
    :func:`_facing_cosine` toward the point."""
    if not cos_l > 0.0:
        return 0.0
    if light[0] == TRIANGLE and solid_angle_sampled(omega):
        return 1.0 / omega
    return distance * distance / (light[AREA] * cos_l)


@row
def _corner_directions(light, px, py, pz):
    """The unit directions from ``p`` to a triangle light's three corners (nine numbers)."""
    ax, ay, az = light[1] - px, light[2] - py, light[3] - pz
    bx, by, bz = ax + light[10], ay + light[11], az + light[12]
    cx, cy, cz = ax + light[13], ay + light[14], az + light[15]
    return normalized3(ax, ay, az, 1.0) + normalized3(bx, by, bz, 1.0) + normalized3(cx, cy, cz, 1.0)


@row
def triangle_solid_angle(light, px, py, pz):
    """Solid angle (sr) a triangle light's row subtends from ``p``."""
    ax, ay, az, bx, by, bz, cx, cy, cz = _corner_directions(light, px, py, pz)
    return spherical_triangle_area_row(ax, ay, az, bx, by, bz, cx, cy, cz)


@row
def solid_angle_sampled(omega):
    """Whether a triangle light seen under ``omega`` sr is sampled in solid angle."""
    return (omega > SOLID_ANGLE_FROM) & (omega < SOLID_ANGLE_TO)


@row
def sample_triangle_solid_angle(light, px, py, pz, u1, u2, omega, corners):
    """A point of a triangle light uniform in the solid angle ``omega`` it subtends from
    ``p``, whose corners lie in the unit directions ``corners`` from ``p``
    (:func:`_corner_directions`, nine numbers): ``(wx, wy, wz, distance, b1, b2, ok)``, the
    unit direction, the distance to the point and its barycentric weights of the corners 1
    and 2 (least squares on the edges); ``ok`` False where the direction misses the
    triangle's plane (seen edge-on)."""
    ax, ay, az, bx, by, bz, cx, cy, cz = corners
    wx, wy, wz = spherical_triangle_row(u1, u2, ax, ay, az, bx, by, bz, cx, cy, cz, omega)
    nx, ny, nz = light[4], light[5], light[6]
    cos = (wx * nx + wy * ny) + wz * nz
    if cos == 0.0:
        return wx, wy, wz, 0.0, 0.0, 0.0, False
    ax, ay, az = light[1] - px, light[2] - py, light[3] - pz  # the corner, not its direction
    t = ((ax * nx + ay * ny) + az * nz) / cos
    if not (t > 0.0 and t < math.inf):
        return wx, wy, wz, 0.0, 0.0, 0.0, False
    # barycentrics of the point, for textured emission
    rx, ry, rz = t * wx - ax, t * wy - ay, t * wz - az
    e1x, e1y, e1z, e2x, e2y, e2z = light[10], light[11], light[12], light[13], light[14], light[15]
    d00 = (e1x * e1x + e1y * e1y) + e1z * e1z
    d01 = (e1x * e2x + e1y * e2y) + e1z * e2z
    d11 = (e2x * e2x + e2y * e2y) + e2z * e2z
    d20 = (rx * e1x + ry * e1y) + rz * e1z
    d21 = (rx * e2x + ry * e2y) + rz * e2z
    det = d00 * d11 - d01 * d01
    b1 = min(max((d11 * d20 - d01 * d21) / det, 0.0), 1.0)
    b2 = min(max((d00 * d21 - d01 * d20) / det, 0.0), 1.0 - b1)
    return wx, wy, wz, t, b1, b2, True


@row
def sample_area(light, px, py, pz, u1, u2):
    """A quad, disk or triangle light's sample toward ``p``: ``(wx, wy, wz, distance, pdf, b1,
    b2)``, the unit direction, the distance, the solid-angle density (0: no sample, e.g. from
    behind a one-sided light) and, for a triangle, the point's barycentric weights of the
    corners 1 and 2 (textured emitters).  A triangle is sampled uniformly in the solid angle
    it subtends where :func:`solid_angle_sampled` (and the direction meets its plane), every
    light by area elsewhere (:func:`sample_area_point`)."""
    b1 = b2 = 0.0
    # a triangle's solid angle from p, and its corners' directions, computed once for the
    # choice, the sample and its density (each an atan2 and three normalisations)
    omega = 0.0
    if light[0] == TRIANGLE:
        corners = _corner_directions(light, px, py, pz)
        omega = spherical_triangle_area_row(*corners)
        if solid_angle_sampled(omega):
            dx, dy, dz, distance, b1, b2, ok = sample_triangle_solid_angle(light, px, py, pz, u1, u2, omega,
                                                                           corners)
            if ok:
                return dx, dy, dz, distance, _sample_density(light, omega, dx, dy, dz, distance), b1, b2
        b1, b2 = uniform_triangle_weights(u1, u2)
    qx, qy, qz = sample_area_point(light, u1, u2)
    dx, dy, dz = qx - px, qy - py, qz - pz
    distance = math.sqrt((dx * dx + dy * dy) + dz * dz)
    if not distance > 0.0:
        return 0.0, 0.0, 1.0, 0.0, 0.0, b1, b2
    dx, dy, dz = dx / distance, dy / distance, dz / distance
    return dx, dy, dz, distance, _sample_density(light, omega, dx, dy, dz, distance), b1, b2


@row
def _sample_density(light, omega, dx, dy, dz, distance):
    """:func:`area_pdf` of :func:`sample_area`'s sample along unit ``d`` at ``distance``,
    given the solid angle ``omega`` of a triangle light it computed (0: not a triangle)."""
    return _area_density(light, omega, _facing_cosine(light, dx, dy, dz), distance)


@row
def sample_area_point(light, u1, u2):
    """A uniform point on a quad, disk or triangle light."""
    kind = light[0]
    if kind == QUAD:
        return (light[1] + u1 * light[10] + u2 * light[13], light[2] + u1 * light[11] + u2 * light[14],
                light[3] + u1 * light[12] + u2 * light[15])
    if kind == DISK:
        a, b = concentric_disk_row(u1, u2)
        return (light[1] + a * light[10] + b * light[13], light[2] + a * light[11] + b * light[14],
                light[3] + a * light[12] + b * light[15])
    b1, b2 = uniform_triangle_weights(u1, u2)
    return (light[1] + b1 * light[10] + b2 * light[13], light[2] + b1 * light[11] + b2 * light[14],
            light[3] + b1 * light[12] + b2 * light[15])


@row
def hit_analytic(light, ox, oy, oz, dx, dy, dz, t_max):
    """Distance at which a ray meets a quad or disk light (from its emitting side for a
    one-sided light), or inf."""
    nx, ny, nz = light[4], light[5], light[6]
    denom = (nx * dx + ny * dy) + nz * dz
    if not denom < 0.0:
        return math.inf
    t = ((nx * (light[1] - ox) + ny * (light[2] - oy)) + nz * (light[3] - oz)) / denom
    if not (t > 0.0 and t < t_max):
        return math.inf
    qx, qy, qz = ox + t * dx - light[1], oy + t * dy - light[2], oz + t * dz - light[3]
    if light[0] == QUAD:
        # coordinates along the edges through the dual basis (edge . edge Gram matrix)
        e11 = (light[10] * light[10] + light[11] * light[11]) + light[12] * light[12]
        e22 = (light[13] * light[13] + light[14] * light[14]) + light[15] * light[15]
        e12 = (light[10] * light[13] + light[11] * light[14]) + light[12] * light[15]
        q1 = (qx * light[10] + qy * light[11]) + qz * light[12]
        q2 = (qx * light[13] + qy * light[14]) + qz * light[15]
        det = e11 * e22 - e12 * e12
        a = (q1 * e22 - q2 * e12) / det
        b = (q2 * e11 - q1 * e12) / det
        return t if (a >= 0.0) & (a <= 1.0) & (b >= 0.0) & (b <= 1.0) else math.inf
    r2 = (light[10] * light[10] + light[11] * light[11]) + light[12] * light[12]
    return t if (qx * qx + qy * qy) + qz * qz <= r2 else math.inf


@row
def projector_incident(light, texels, descriptors, px, py, pz):
    """A projector's direction, distance and incident term at a point, as
    :meth:`rtmesh.lights.projector.ProjectorLight.illuminate` (its mapping, written for one
    point): ``(wx, wy, wz, distance, Er, Eg, Eb)`` with ``E = intensity * texel / d^2`` inside
    the image's frustum, 0 outside it or behind the projector; the texel is the bilinear
    lookup of the image (``texels``, ``descriptors``: the lights' atlas) where the line from
    the pinhole to the point crosses the image plane."""
    tx, ty, tz = light[1] - px, light[2] - py, light[3] - pz
    distance = math.sqrt((tx * tx + ty * ty) + tz * tz)
    # a point exactly at the pinhole is lit from nowhere, as for a point light
    safe = distance if distance > 0.0 else math.inf
    wx, wy, wz = tx / safe, ty / safe, tz / safe
    depth = -((wx * light[4] + wy * light[5]) + wz * light[6])
    if not depth > 0.0:
        return wx, wy, wz, distance, 0.0, 0.0, 0.0
    u = 0.5 - ((wx * light[10] + wy * light[11]) + wz * light[12]) / depth / (2.0 * light[HALF_WIDTH])
    v = 0.5 - ((wx * light[13] + wy * light[14]) + wz * light[15]) / depth / (2.0 * light[HALF_HEIGHT])
    if not ((u >= 0.0) & (u <= 1.0) & (v >= 0.0) & (v <= 1.0)):
        return wx, wy, wz, distance, 0.0, 0.0, 0.0
    r, g, b, _ = texel(texels, descriptors, np.int64(light[IMAGE]), u, v)
    d2 = safe * safe
    return wx, wy, wz, distance, light[7] * r / d2, light[8] * g / d2, light[9] * b / d2
