"""Caustic photons, compiled: emission from every light, tracing through specular chains over
Embree packets, the hash grid they are stored in, and the density estimate the path kernel
gathers at its vertices (:mod:`rtmesh.rendering.caustics` runs the passes).

Photons carry the light paths a path tracer cannot find from a small or delta light: light
→ one or more delta bounces (mirrors, smooth glass) → a surface that scatters diffusely or
glossily (``L S+ D``).  A photon leaves a light chosen by power (the path kernel's alias
table), aimed at the bounding sphere of the scene's specular surfaces (the ``aim``: a cone
from a point or area light, a disk across the beam of a directional or environment light;
directions outside it cannot reach a specular surface first, so no caustic path is lost),
and is followed while the surfaces it meets scatter it by a delta lobe.  Where it meets a
surface with a non-delta part after at least one delta bounce, it is stored: position,
the direction back toward where it came from, its flux (W, for one photon of the pass) and
the surface's geometric normal.  It goes on only through a delta lobe.

Flux, not radiance, is transported (pbrt's ``TransportMode::Importance``): a delta
refraction's weight from the material seam carries radiance's ``1 / eta'^2``, undone here,
and the shading-normal correction ``|wo.ns| |wi.ng| / (|wo.ng| |wi.ns|)`` of Veach's adjoint
BSDF makes smooth-shaded glass scatter the same energy both ways.

Random numbers: each photon's key is ``path_key(pass_key, index, 0)``; its emission point and
direction are Owen-scrambled Sobol pairs over the photon index (stratified across the pass),
its light choice and bounces hashed numbers.  Chunks of photons are pure functions of their
indices, so the photons (and the image) do not depend on threads.

The grid: cells of ``cell_size``, hashed into a power-of-two table; photons sorted by bucket
(a counting sort, stable: photon order within a bucket is index order), so a query visits the
buckets of the cells its sphere overlaps and keeps photons of exactly those cells.
"""

import math

import numpy as np

from rtmesh.core.compiled import borrowed, keep_alive, inline_row, kernel, row
from rtmesh.geometry.embree_packets import (DEFAULT_TFAR, GEOM_ID, INVALID_ID, LANES, RTC_RAY_QUERY_FLAG_INCOHERENT,
                                            TFAR, U, V, lane_word, packet_buffers, query_packet)
from rtmesh.lights import light_table as lt
from rtmesh.materials import lambert, lobes, models
from rtmesh.rendering.path_packets import MAX_LAYERS, hit_face, placed
from rtmesh.rendering.path_surfaces import alias_sample, load_lanes
from rtmesh.rendering.path_surfaces import environment_radiance as _environment_radiance
from rtmesh.rendering.path_surfaces import environment_sample as _environment_sample
from rtmesh.rendering.path_surfaces import illuminate as _illuminate_row
from rtmesh.rendering.path_surfaces import projector_incident as _projector_incident
from rtmesh.rendering.path_surfaces import sample_area_point as _sample_area_point
from rtmesh.rendering.path_media import cross_interface, crossing_scale, twin_material
from rtmesh.rendering.path_surfaces import (hit_frame, hit_parameters, is_transparent, leave_surface, sampled_direction,
                                            surface_point, tangent_frame, textured_materials, triangle_light_emission)
from rtmesh.sampling.hashing import GOLDEN, mix64, path_key, uniform
from rtmesh.sampling.lowdiscrepancy import sobol_pair
from rtmesh.sampling.warps import concentric_disk_row, uniform_triangle_weights


# dimensions of a photon's hashed numbers: its light, then three a bounce
_CHOICE = 0
_LOBE, _U1, _U2, _COVERAGE = range(4)
DIMENSIONS_PER_BOUNCE = 4
# delta bounces a photon takes at most when max_depth does not bound them
MAX_BOUNCES = 64
# where the Lambert model keeps its albedo (the gather's shortcut for it)
_ALBEDO = lambert.SLOTS["colour"]
# a photon's stored fields: position, direction toward its origin, flux, normal (x, y, z each),
# and the segments of its path from the light (for max_depth)
POSITION, DIRECTION, FLUX, NORMAL, SEGMENTS = 0, 3, 6, 9, 12
FIELDS = 13


def empty_photon_map(materials):
    """The path kernel's ``photon_map`` record without photons (caustics off), for
    ``materials`` materials.

    The record: ``(on, photons (P, FIELDS) ordered by bucket, bucket starts (2**bits + 1,),
    cell size, bits, 1 / (pi * photons emitted), radius scale, footprint a, footprint b, largest
    radius, scatters (M,) bool)``; a vertex's gather radius is ``min(scale * (a + b * path
    length), largest)``.
    """
    return (False, np.zeros((0, FIELDS)), np.zeros(2, np.int64), 1.0, 0, 0.0, 0.0, 0.0, 0.0, 0.0,
            np.zeros(materials, np.bool_))


@row
def cone_direction(ax, ay, az, cos_max, u1, u2):
    """A uniform direction in the cone of half-angle ``acos(cos_max)`` around the unit axis
    ``a``; ``cos_max`` -1 is the whole sphere."""
    cos_t = 1.0 - u1 * (1.0 - cos_max)
    sin_t = math.sqrt(max(1.0 - cos_t * cos_t, 0.0))
    phi = 2.0 * math.pi * u2
    tx, ty, tz, sx, sy, sz = tangent_frame(ax, ay, az)
    x, y = sin_t * math.cos(phi), sin_t * math.sin(phi)
    return tx * x + sx * y + ax * cos_t, ty * x + sy * y + ay * cos_t, tz * x + sz * y + az * cos_t


@row
def aim_cone(px, py, pz, aim):
    """The cone from ``p`` around the aim sphere ``(cx, cy, cz, radius)``: its unit axis, the
    cosine of its half-angle and its solid angle (the whole sphere from inside it)."""
    wx, wy, wz = aim[0] - px, aim[1] - py, aim[2] - pz
    d = math.sqrt((wx * wx + wy * wy) + wz * wz)
    if not d > aim[3]:
        return 0.0, 0.0, 1.0, -1.0, 4.0 * math.pi
    s = aim[3] / d
    # 1 - cos of the half-angle without cancellation for small cones
    one_minus = s * s / (1.0 + math.sqrt(1.0 - s * s))
    return wx / d, wy / d, wz / d, 1.0 - one_minus, 2.0 * math.pi * one_minus


@inline_row
def sample_emission(light, env, texels, descriptors, aim, scene_sphere, u1, u2, u3, u4):
    """One photon leaving ``light`` toward the aim sphere: origin, unit direction and flux
    over the densities of the point and direction (not yet over the light's choice
    probability); flux 0 for a failed sample.  An emissive triangle's flux is for radiance 1:
    the caller multiplies it by the (textured) emission at the point.

    Point, spot and projector lights: a direction in the cone around the aim, intensity
    (the spot's falloff, the projector's texel there: ``texels, descriptors`` are the
    projectors' images) times the cone's solid angle.  Quad, disk and emissive-triangle
    lights: a uniform point, a direction in its cone, ``L cos * area * solid angle`` (0 from
    behind a one-sided light).  Directional and environment lights: a point on the disk of
    the aim's radius across the beam, placed outside the scene's bounding sphere,
    ``E * pi r^2`` (the environment: ``L / pdf``, its direction importance-sampled).
    """
    kind = light[0]
    if kind == 1.0 or kind == lt.ENVIRONMENT:  # directional (point_light_rows.DIRECTIONAL), environment
        if kind == 1.0:
            ex, ey, ez, _, fr, fg, fb = _illuminate_row(light, aim[0], aim[1], aim[2])
            density = 1.0
        else:
            (pixels, marginal, conditional, func, mean, cos_r, sin_r) = env
            ex, ey, ez, density = _environment_sample(marginal, conditional, func, mean, cos_r, sin_r, u3, u4)
            if not (density > 0.0 and density < math.inf):
                return 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0
            fr, fg, fb = _environment_radiance(pixels, cos_r, sin_r, ex, ey, ez)
        # (ex, ey, ez) points toward the light; photons travel the other way
        dx, dy, dz = -ex, -ey, -ez
        tx, ty, tz, sx, sy, sz = tangent_frame(dx, dy, dz)
        a, b = concentric_disk_row(u1, u2)
        a, b = a * aim[3], b * aim[3]
        cx, cy, cz = aim[0] - scene_sphere[0], aim[1] - scene_sphere[1], aim[2] - scene_sphere[2]
        back = math.sqrt((cx * cx + cy * cy) + cz * cz) + scene_sphere[3] + aim[3]
        ox = aim[0] + a * tx + b * sx - back * dx
        oy = aim[1] + a * ty + b * sy - back * dy
        oz = aim[2] + a * tz + b * sz - back * dz
        scale = math.pi * aim[3] * aim[3] / density
        return ox, oy, oz, dx, dy, dz, fr * scale, fg * scale, fb * scale
    if kind < lt.QUAD or kind == lt.PROJECTOR:  # point, spot, projector
        ox, oy, oz = light[1], light[2], light[3]
        ax, ay, az, cos_max, solid_angle = aim_cone(ox, oy, oz, aim)
        dx, dy, dz = cone_direction(ax, ay, az, cos_max, u3, u4)
        # the incident term one unit away along the direction: the intensity that way
        if kind == lt.PROJECTOR:
            _, _, _, _, fr, fg, fb = _projector_incident(light, texels, descriptors, ox + dx, oy + dy, oz + dz)
        else:
            _, _, _, _, fr, fg, fb = _illuminate_row(light, ox + dx, oy + dy, oz + dz)
        return ox, oy, oz, dx, dy, dz, fr * solid_angle, fg * solid_angle, fb * solid_angle
    ox, oy, oz = _sample_area_point(light, u1, u2)
    ax, ay, az, cos_max, solid_angle = aim_cone(ox, oy, oz, aim)
    dx, dy, dz = cone_direction(ax, ay, az, cos_max, u3, u4)
    cos_l = (light[4] * dx + light[5] * dy) + light[6] * dz
    if light[lt.TWO_SIDED] > 0.0:
        cos_l = abs(cos_l)
    if not cos_l > 0.0:
        return ox, oy, oz, dx, dy, dz, 0.0, 0.0, 0.0
    fr, fg, fb = (1.0, 1.0, 1.0) if kind == lt.TRIANGLE else (light[lt.RADIANCE], light[lt.RADIANCE + 1],
                                                               light[lt.RADIANCE + 2])
    scale = cos_l * light[lt.AREA] * solid_angle
    return ox, oy, oz, dx, dy, dz, fr * scale, fg * scale, fb * scale


@kernel
def trace_photons(intersect, scene, pass_key, sobol_keys, first, count, geometry, surface, lights, env, instances,
                  aim, scene_sphere, specular, scatters, options, photons, stored, counts):
    """Trace photons ``first .. first + count - 1`` of a pass and store where they land.

    Parameters
    ----------
    intersect : ctypes function object
        Embree's ``rtcIntersect16``.
    scene : int
        The committed ``RTCScene``.
    pass_key : uint64
        The pass's random key.
    sobol_keys : (2,) uint64
        Sequence keys of the pass's emission points and directions.
    first, count : int
        The photons to trace.
    geometry, surface, lights, env, instances : tuples
        The path kernel's records (:mod:`rtmesh.rendering.path_kernel`): a photon meeting a
        placed mesh meets its prototype's face at the placement's world-space point.
    aim : (4,) float64
        Centre and radius of the sphere bounding every specular surface.
    scene_sphere : (4,) float64
        Centre and radius of the scene's bounding sphere.
    specular, scatters : (M,) bool
        Per material: whether it can scatter by a delta lobe; whether it has a non-delta part.
    options : tuple
        ``(max_bounces, offset_scale, cutouts, media)``: delta bounces at most, the origin
        offset's scale, whether cut-outs exist, the media stack's depth (0: no
        transmissive materials).
    photons : (capacity, FIELDS) float64
        Output rows (:data:`POSITION`, :data:`DIRECTION`, :data:`FLUX`, :data:`NORMAL`,
        :data:`SEGMENTS`), flux per photon of the pass (divide by the pass's photon count).
    stored : (2,) int64
        Output: rows written, and rows the chunk needed (more than ``capacity``: call again
        with room for them).
    counts : (1,) int64
        Photon rays traced (active lanes), added to.
    """
    # views that own nothing: no reference counts in the per-lane rows (rtmesh.core.compiled.borrowed)
    geometry, surface, lights, env, instances, aim, scene_sphere, specular, scatters, sobol_keys, photons, stored, \
        counts = borrowed((geometry, surface, lights, env, instances, aim, scene_sphere, specular, scatters, sobol_keys,
                           photons, stored, counts))
    instance_faces, to_world, normal_to_world = instances
    static_faces = np.zeros(0, np.int64)  # (photon passes refuse moving objects: one static scene)
    max_bounces, offset_scale, cutouts, media = options
    material_id = geometry[5]
    tags, transmissive, absorption = surface[0], surface[2], surface[4]
    albedo_table, slots = surface[6], surface[7]
    textured = textured_materials(surface, geometry)
    light_rows, light_probability, light_alias, light_pmf = lights[0], lights[1], lights[2], lights[3]
    ray, words, valid, args = packet_buffers(np.int64(1), np.int64(RTC_RAY_QUERY_FLAG_INCOHERENT))
    scratch = np.zeros((LANES, lobes.PARAMETER_WIDTH))
    px, py, pz = np.zeros(LANES), np.zeros(LANES), np.zeros(LANES)
    dx, dy, dz = np.zeros(LANES), np.zeros(LANES), np.zeros(LANES)
    beta = np.zeros((LANES, 3))
    sigma = np.zeros((LANES, 3))
    keys = np.zeros(LANES, np.uint64)
    alive = np.zeros(LANES, np.bool_)
    bounces = np.zeros(LANES, np.int64)
    layers = np.zeros(LANES, np.int64)
    stack = np.full((LANES, max(media, 1)), -1, np.int64)
    owned = (ray, words, valid, args, scratch, px, py, pz, dx, dy, dz, beta, sigma, keys, alive, bounces, layers, stack,
             static_faces)
    (ray, words, valid, args, scratch, px, py, pz, dx, dy, dz, beta, sigma, keys, alive, bounces, layers, stack,
     static_faces) = borrowed(owned)
    capacity = photons.shape[0]
    written = 0
    needed = 0
    for start in range(first, first + count, LANES):
        for lane in range(LANES):
            index = start + lane
            alive[lane] = index < first + count
            if not alive[lane]:
                continue
            key = path_key(pass_key, np.uint64(index), np.uint64(0))
            keys[lane] = key
            chosen = alias_sample(light_probability, light_alias, uniform(key, _CHOICE))
            u1, u2 = sobol_pair(sobol_keys[0], index)
            u3, u4 = sobol_pair(sobol_keys[1], index)
            light = light_rows[chosen]
            ox, oy, oz, ex, ey, ez, fr, fg, fb = sample_emission(light, env, lights[7], lights[8], aim, scene_sphere,
                                                                 u1, u2, u3, u4)
            if light[0] == lt.TRIANGLE:
                # the emitter's own (textured) radiance at the point
                b1, b2 = uniform_triangle_weights(u1, u2)
                er, eg, eb = triangle_light_emission(surface, geometry, light, b1, b2)
                fr, fg, fb = fr * er, fg * eg, fb * eb
            p = light_pmf[chosen]
            if not ((fr > 0.0) | (fg > 0.0) | (fb > 0.0)) or not p > 0.0:
                alive[lane] = False
                continue
            px[lane], py[lane], pz[lane] = ox, oy, oz
            dx[lane], dy[lane], dz[lane] = ex, ey, ez
            beta[lane, 0], beta[lane, 1], beta[lane, 2] = fr / p, fg / p, fb / p
            sigma[lane, 0] = sigma[lane, 1] = sigma[lane, 2] = 0.0
            for k in range(media):
                stack[lane, k] = -1
            bounces[lane] = 0
            layers[lane] = 0
        while True:
            active = load_lanes(alive, ray, words, valid, px, py, pz, dx, dy, dz, DEFAULT_TFAR)
            if active == 0:
                break
            counts[0] += active
            query_packet(intersect, scene, valid, ray, args, 0)
            for lane in range(LANES):
                if not alive[lane]:
                    continue
                if words[lane_word(GEOM_ID, lane)] == INVALID_ID:
                    alive[lane] = False
                    continue
                key = keys[lane]
                base = DIMENSIONS_PER_BOUNCE * (bounces[lane] + 1)
                t = np.float64(ray[lane_word(TFAR, lane)])
                prim, placement = hit_face(words, lane, instance_faces, static_faces)
                bu = np.float64(ray[lane_word(U, lane)])
                bv = np.float64(ray[lane_word(V, lane)])
                if sigma[lane, 0] + sigma[lane, 1] + sigma[lane, 2] > 0.0:
                    for c in range(3):
                        beta[lane, c] *= math.exp(-sigma[lane, c] * t)
                mat = material_id[prim]
                hx, hy, hz, gx, gy, gz, nx, ny, nz = surface_point(geometry, prim, bu, bv)
                if placement >= 0:
                    hx, hy, hz, gx, gy, gz, nx, ny, nz = placed(to_world, normal_to_world, placement, hx, hy, hz, gx,
                                                                gy, gz, nx, ny, nz)
                if cutouts and layers[lane] + 1 < MAX_LAYERS and is_transparent(
                        surface, geometry, mat, prim, bu, bv,
                        uniform(mix64(key ^ np.uint64(layers[lane] + 1)), base + _COVERAGE)):
                    layers[lane] += 1
                    px[lane], py[lane], pz[lane] = leave_surface(hx, hy, hz, gx, gy, gz, dx[lane], dy[lane], dz[lane],
                                                                 offset_scale)
                    continue
                layers[lane] = 0
                ox, oy, oz = -dx[lane], -dy[lane], -dz[lane]
                entering = (gx * dx[lane] + gy * dy[lane]) + gz * dz[lane] < 0.0
                bsdf_params, bsdf_row, _, _, _, _ = hit_parameters(surface, geometry, textured, mat, prim, bu, bv, scratch,
                                                                lane, stack, media, entering)
                gx, gy, gz, nx, ny, nz, tx, ty, tz, sx, sy, sz = hit_frame(
                    surface, geometry, mat, prim, bu, bv, transmissive[mat], scratch, lane, gx, gy, gz, nx, ny, nz,
                    ox, oy, oz, instances, placement)
                if bounces[lane] > 0 and scatters[mat]:
                    if written < capacity:
                        # the normal of the side the photon arrived on
                        side = 1.0 if (gx * ox + gy * oy) + gz * oz > 0.0 else -1.0
                        row_ = photons[written]
                        row_[POSITION], row_[POSITION + 1], row_[POSITION + 2] = hx, hy, hz
                        row_[DIRECTION], row_[DIRECTION + 1], row_[DIRECTION + 2] = ox, oy, oz
                        row_[FLUX], row_[FLUX + 1], row_[FLUX + 2] = beta[lane, 0], beta[lane, 1], beta[lane, 2]
                        row_[NORMAL], row_[NORMAL + 1], row_[NORMAL + 2] = side * gx, side * gy, side * gz
                        row_[SEGMENTS] = bounces[lane] + 1
                        written += 1
                    needed += 1
                if not specular[mat] or bounces[lane] >= max_bounces:
                    alive[lane] = False
                    continue
                lox = (tx * ox + ty * oy) + tz * oz
                loy = (sx * ox + sy * oy) + sz * oz
                loz = (nx * ox + ny * oy) + nz * oz
                wx, wy, wz, wr, wg, wb, _, flags = models.sample(
                    tags[mat], bsdf_params, bsdf_row, albedo_table, lox, loy, loz, uniform(key, base + _LOBE),
                    uniform(key, base + _U1), uniform(key, base + _U2))
                if not (flags & lobes.DELTA) or not ((wr > 0.0) | (wg > 0.0) | (wb > 0.0)):
                    alive[lane] = False  # a photon goes on through delta lobes only
                    continue
                ndx, ndy, ndz, side, below = sampled_direction(wx, wy, wz, tx, ty, tz, sx, sy, sz, nx, ny, nz, gx, gy,
                                                               gz, transmissive[mat])
                if below:
                    alive[lane] = False
                    continue
                # the adjoint's shading-normal correction, and flux rather than radiance
                # through a refraction (undo the seam's 1 / eta'^2)
                o_g = abs((gx * ox + gy * oy) + gz * oz)
                i_n = abs(wz)
                if not (o_g > 0.0 and i_n > 0.0):
                    alive[lane] = False
                    continue
                adjoint = abs(loz) * abs(side) / (o_g * i_n)
                adjoint *= crossing_scale(slots, tags[mat], bsdf_params, bsdf_row, loz, flags)
                beta[lane, 0] *= wr * adjoint
                beta[lane, 1] *= wg * adjoint
                beta[lane, 2] *= wb * adjoint
                if transmissive[mat] and (flags & lobes.TRANSMISSION) and media:
                    top = cross_interface(stack, lane, mat, side < 0.0, twin_material(surface, prim))
                    for c in range(3):
                        sigma[lane, c] = absorption[top, c] if top >= 0 else 0.0
                px[lane], py[lane], pz[lane] = leave_surface(hx, hy, hz, gx, gy, gz, ndx, ndy, ndz, offset_scale)
                dx[lane], dy[lane], dz[lane] = ndx, ndy, ndz
                bounces[lane] += 1
    stored[0] = written
    stored[1] = needed
    keep_alive(owned)


@row
def cell_bucket(ix, iy, iz, mask):
    """The hash-table bucket of grid cell ``(ix, iy, iz)``."""
    h = mix64(np.uint64(ix) * GOLDEN ^ mix64(np.uint64(iy) + GOLDEN * np.uint64(2)) ^ mix64(
        np.uint64(iz) + GOLDEN * np.uint64(3)))
    return np.int64(h & np.uint64(mask))


@kernel
def photon_grid(photons, cell_size, bits):
    """Sort photons into the hash grid: the permutation that orders them by bucket (stable)
    and each bucket's first row.

    Parameters
    ----------
    photons : (P, FIELDS) float64
    cell_size : float
    bits : int
        The table has ``2**bits`` buckets.

    Returns
    -------
    order : (P,) int64
    start : (2**bits + 1,) int64
        Bucket ``b`` holds rows ``start[b] .. start[b + 1] - 1`` of the ordered photons.
    """
    n = photons.shape[0]
    size = 1 << bits
    mask = size - 1
    bucket = np.empty(n, np.int64)
    start = np.zeros(size + 1, np.int64)
    for i in range(n):
        b = cell_bucket(np.int64(math.floor(photons[i, POSITION] / cell_size)),
                        np.int64(math.floor(photons[i, POSITION + 1] / cell_size)),
                        np.int64(math.floor(photons[i, POSITION + 2] / cell_size)), mask)
        bucket[i] = b
        start[b + 1] += 1
    for b in range(size):
        start[b + 1] += start[b]
    fill = start[:size].copy()
    order = np.empty(n, np.int64)
    for i in range(n):
        order[fill[bucket[i]]] = i
        fill[bucket[i]] += 1
    return order, start


# what gather sums (its ``part``): the whole BSDF, its diffuse part, its transmitted part.
# NumPy integers, not Python ones: numba types a call's Python-int constant as a literal of
# its value and compiles the called kernel once per value (three more compiles of gather
# on a first run)
ALL_PARTS, DIFFUSE_PART, TRANSMITTED_PART = np.int64(0), np.int64(1), np.int64(2)


@kernel
def gather(photon_map, hx, hy, hz, gx, gy, gz, radius, segments, tag, bsdf_params, bsdf_row, albedo_table, tx, ty, tz, sx, sy,
           sz, nx, ny, nz, lox, loy, loz, part):
    """The caustic radiance toward ``wo`` at a surface point: the photons within ``radius``
    of it (on the side its geometric normal ``g`` faces), each ``f(wo, wi) |wi.ns| / |wi.ng|
    flux``, over ``pi radius^2`` and the pass's photon count.

    ``part`` :data:`ALL_PARTS` sums the whole BSDF; :data:`DIFFUSE_PART` and
    :data:`TRANSMITTED_PART` only its diffuse and transmitted parts
    (:func:`rtmesh.materials.models.parts`, for the light-path passes).  Photons whose paths
    have more than ``segments`` segments are left out (``max_depth``; -1: none).

    A kernel of its own, not inlined into the path kernel: it runs only with photon passes,
    and three inlined copies (the light-path passes' split) made the path kernel's first
    compile longer.
    """
    photons, start, cell_size, bits, scale = (photon_map[1], photon_map[2], photon_map[3], photon_map[4],
                                              photon_map[5])
    mask = (1 << bits) - 1
    r2 = radius * radius
    if not r2 > 0.0:
        return 0.0, 0.0, 0.0
    ix0, ix1 = np.int64(math.floor((hx - radius) / cell_size)), np.int64(math.floor((hx + radius) / cell_size))
    iy0, iy1 = np.int64(math.floor((hy - radius) / cell_size)), np.int64(math.floor((hy + radius) / cell_size))
    iz0, iz1 = np.int64(math.floor((hz - radius) / cell_size)), np.int64(math.floor((hz + radius) / cell_size))
    # a bucket may hold other cells' photons; only when two of the cells visited share a
    # bucket could one be counted twice, and only then is each photon's cell checked
    shared = False
    cells = (ix1 - ix0 + 1) * (iy1 - iy0 + 1) * (iz1 - iz0 + 1)
    if cells > 27:
        shared = True
    elif cells > 1:
        seen = np.empty(27, np.int64)
        count = 0
        for ix in range(ix0, ix1 + 1):
            for iy in range(iy0, iy1 + 1):
                for iz in range(iz0, iz1 + 1):
                    b = cell_bucket(ix, iy, iz, mask)
                    for other in range(count):
                        shared |= seen[other] == b
                    seen[count] = b
                    count += 1
    # the Lambert model's f is its albedo over pi: the photons' cosines are summed and the
    # albedo applied once (no call of the model per photon)
    lambertian = (part == ALL_PARTS) & (tag == models.LAMBERT)
    if lambertian and not loz > 0.0:
        return 0.0, 0.0, 0.0
    total_r = total_g = total_b = 0.0
    for ix in range(ix0, ix1 + 1):
        for iy in range(iy0, iy1 + 1):
            for iz in range(iz0, iz1 + 1):
                b = cell_bucket(ix, iy, iz, mask)
                for k in range(start[b], start[b + 1]):
                    qx, qy, qz = photons[k, POSITION], photons[k, POSITION + 1], photons[k, POSITION + 2]
                    ex, ey, ez = qx - hx, qy - hy, qz - hz
                    if (ex * ex + ey * ey) + ez * ez > r2:
                        continue
                    if shared and ((math.floor(qx / cell_size) != ix) | (math.floor(qy / cell_size) != iy) | (
                            math.floor(qz / cell_size) != iz)):
                        continue
                    if segments >= 0 and photons[k, SEGMENTS] > segments:
                        continue
                    if (photons[k, NORMAL] * gx + photons[k, NORMAL + 1] * gy) + photons[k, NORMAL + 2] * gz <= 0.0:
                        continue
                    wx, wy, wz = photons[k, DIRECTION], photons[k, DIRECTION + 1], photons[k, DIRECTION + 2]
                    cos_g = abs((wx * gx + wy * gy) + wz * gz)
                    if not cos_g > 0.0:
                        continue
                    liz = (nx * wx + ny * wy) + nz * wz
                    if lambertian:
                        if liz > 0.0:
                            c = liz / cos_g
                            total_r += c * photons[k, FLUX]
                            total_g += c * photons[k, FLUX + 1]
                            total_b += c * photons[k, FLUX + 2]
                        continue
                    lix = (tx * wx + ty * wy) + tz * wz
                    liy = (sx * wx + sy * wy) + sz * wz
                    if part == ALL_PARTS:
                        fr, fg, fb, _ = models.evaluate(tag, bsdf_params, bsdf_row, albedo_table, lox, loy, loz,
                                                        lix, liy, liz)
                    else:
                        dr, dg, db, ur, ug, ub = models.parts(tag, bsdf_params, bsdf_row, albedo_table, lox, loy,
                                                              loz, lix, liy, liz)
                        fr, fg, fb = (dr, dg, db) if part == DIFFUSE_PART else (ur, ug, ub)
                    total_r += fr * photons[k, FLUX] / cos_g
                    total_g += fg * photons[k, FLUX + 1] / cos_g
                    total_b += fb * photons[k, FLUX + 2] / cos_g
    if lambertian:
        k = 1.0 / math.pi
        total_r *= bsdf_params[bsdf_row, _ALBEDO] * k
        total_g *= bsdf_params[bsdf_row, _ALBEDO + 1] * k
        total_b *= bsdf_params[bsdf_row, _ALBEDO + 2] * k
    s = scale / r2
    return total_r * s, total_g * s, total_b * s
