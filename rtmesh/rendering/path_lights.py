"""The path kernel's light rows: one light's sample toward a point (``sample_li``), a
light's row at a lane's time (an emissive triangle of a moving object), and the densities
emission met by a BSDF sample is weighed with.  The ``lights`` and ``env`` records are
described in :mod:`rtmesh.rendering.path_kernel`; the rows they call are
:mod:`rtmesh.lights.light_table`'s, inlined (:mod:`rtmesh.rendering.path_surfaces`).
"""

import math

import numpy as np

from rtmesh.core.compiled import inline_row
from rtmesh.geometry.float32_rays import F32_MAX, offset_origin
from rtmesh.lights import environment_table
from rtmesh.lights import light_table as lt
from rtmesh.rendering.path_packets import mover_to_world
from rtmesh.rendering.path_surfaces import environment_radiance as _environment_radiance
from rtmesh.rendering.path_surfaces import environment_sample as _environment_sample
from rtmesh.rendering.path_surfaces import illuminate as _illuminate_row
from rtmesh.rendering.path_surfaces import projector_incident as _projector_incident

# The rows taking arrays that the kernel calls per lane, inlined by numba: a compiled call that
# passes arrays takes and releases a reference to each (atomic instructions), and LLVM stops
# inlining small rows into a function this large (those calls doubled the kernel's time);
# rows of numbers only stay calls (inlining them too cost compile time, no speed)
area_pdf = inline_row(lt.area_pdf.py_func)
hit_analytic = inline_row(lt.hit_analytic.py_func)
environment_pdf_uv = inline_row(environment_table.environment_pdf_uv.py_func)


@inline_row
def sample_li(light, env, texels, descriptors, px, py, pz, u1, u2):
    """One light's ``sample_li`` at a point: ``(wx, wy, wz, distance, Lr, Lg, Lb, pdf, delta,
    b1, b2)`` with the incident radiance (delta lights: their incident term), the solid-angle
    density (delta lights: 1; 0 for a failed sample) and, for a triangle light, the point's
    barycentric weights of its corners 1 and 2 (for textured emission).  A triangle seen
    under a large solid angle is sampled in it (:func:`rtmesh.lights.light_table.solid_angle_sampled`),
    others by area.  ``texels, descriptors``: the projectors' images (the ``lights`` record's
    atlas)."""
    kind = light[0]
    if kind < lt.QUAD:
        wx, wy, wz, distance, er, eg, eb = _illuminate_row(light, px, py, pz)
        return wx, wy, wz, distance, er, eg, eb, 1.0, True, 0.0, 0.0
    if kind == lt.PROJECTOR:
        wx, wy, wz, distance, er, eg, eb = _projector_incident(light, texels, descriptors, px, py, pz)
        return wx, wy, wz, distance, er, eg, eb, 1.0, True, 0.0, 0.0
    if kind == lt.ENVIRONMENT:
        (pixels, marginal, conditional, func, mean, cos_r, sin_r) = env
        dx, dy, dz, pdf = _environment_sample(marginal, conditional, func, mean, cos_r, sin_r, u1, u2)
        if not (pdf > 0.0 and pdf < math.inf):
            return dx, dy, dz, math.inf, 0.0, 0.0, 0.0, 0.0, False, 0.0, 0.0
        lr, lg, lb = _environment_radiance(pixels, cos_r, sin_r, dx, dy, dz)
        return dx, dy, dz, math.inf, lr, lg, lb, pdf, False, 0.0, 0.0
    dx, dy, dz, distance, pdf, b1, b2 = lt.sample_area(light, px, py, pz, u1, u2)
    if not pdf > 0.0:
        return dx, dy, dz, distance, 0.0, 0.0, 0.0, 0.0, False, b1, b2
    return (dx, dy, dz, distance, light[lt.RADIANCE], light[lt.RADIANCE + 1], light[lt.RADIANCE + 2], pdf, False,
            b1, b2)


@inline_row
def light_at(light_rows, index, face_mover, moves, time, moved, lane):
    """Light ``index``'s row at ``time``: its own row, or for an emissive triangle of a moving
    object the row carried by the object's motion to ``time`` (written into ``moved[lane]``:
    corner, edges and normal; the motion is rigid, so the area, the radiance and the face
    stay)."""
    light = light_rows[index]
    if light[0] != lt.TRIANGLE or not len(face_mover):
        return light
    j = face_mover[np.int64(light[lt.FACE])]
    if j < 0:
        return light
    out = moved[lane]
    for k in range(lt.WIDTH):
        out[k] = light[k]
    # the corner as a point, the edges and the normal as directions
    out[1], out[2], out[3], out[10], out[11], out[12], out[13], out[14], out[15] = mover_to_world(
        moves, j, time, light[1], light[2], light[3], light[10], light[11], light[12], light[13], light[14],
        light[15])
    _, _, _, out[4], out[5], out[6], _, _, _ = mover_to_world(moves, j, time, 0.0, 0.0, 0.0, light[4], light[5], light[6],
                                                         light[4], light[5], light[6])
    return out


# shadow rays toward a point light (no surface to move off) stop this fraction short of it
POINT_SHADOW_SHORTEN = 1.0 - 1e-4


@inline_row
def shadow_segment(hx, hy, hz, gx, gy, gz, wx, wy, wz, distance, delta, light, scale):
    """The shadow ray of a light sample seen from ``h`` (geometric normal ``g``) along unit
    ``w`` at ``distance``: ``(ox, oy, oz, dx, dy, dz, length)``.

    It leaves ``h`` as every spawned ray does (:func:`rtmesh.geometry.float32_rays.offset_origin`);
    toward an area light's point it ends at that point moved off the light toward ``h`` by
    the same float32 offset (the ray run backwards, as the Whitted stages'
    :func:`rtmesh.lights.area_lighting.shadow_segments`), so an emissive triangle cannot
    occlude its own sample, and a point beside a lamp, or a ceiling flush with one, is not
    hidden by it at any distance; toward a point light it stops a fraction short; toward a
    light at infinity it runs to the float32 maximum.
    """
    if (gx * wx + gy * wy) + gz * wz > 0.0:
        ox, oy, oz = offset_origin(hx, hy, hz, gx, gy, gz, wx, wy, wz, scale)
    else:
        ox, oy, oz = offset_origin(hx, hy, hz, -gx, -gy, -gz, wx, wy, wz, scale)
    ox, oy, oz = np.float64(ox), np.float64(oy), np.float64(oz)
    if math.isinf(distance):
        return ox, oy, oz, wx, wy, wz, F32_MAX
    if delta:
        return ox, oy, oz, wx, wy, wz, distance * POINT_SHADOW_SHORTEN
    # the light's normal turned toward h
    nx, ny, nz = light[4], light[5], light[6]
    if (nx * wx + ny * wy) + nz * wz > 0.0:
        nx, ny, nz = -nx, -ny, -nz
    ex, ey, ez = offset_origin(hx + wx * distance, hy + wy * distance, hz + wz * distance, nx, ny, nz, -wx, -wy, -wz,
                               scale)
    sx, sy, sz = np.float64(ex) - ox, np.float64(ey) - oy, np.float64(ez) - oz
    length = math.sqrt((sx * sx + sy * sy) + sz * sz)
    if not length > 0.0:
        return ox, oy, oz, wx, wy, wz, 0.0
    return ox, oy, oz, sx / length, sy / length, sz / length, length
