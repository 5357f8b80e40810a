"""What the path kernel records of each camera ray's first shaded surface, for the
camera-hit passes (:data:`rtmesh.io.passes.REGISTRY`: ``depth``, ``normal``, ``albedo``,
``position``, ``uv``, ``alpha``, ``ao``).

The kernel's ``meet`` stage records the surface a lane's camera segment shades (after the
cut-out layers it passes; not a visible quad or disk light, which the passes do not see,
as Embree's scene does not hold them) in the lane's ``first_hit`` row, and with the ``ao``
pass ``sample_lights`` casts the ambient-occlusion rays there (those of the Whitted
ambient term, when it has them) and ``trace_shadows`` counts the rays that escape.  The
kernel hands the rows out per sample (:func:`rtmesh.rendering.path_kernel.trace_paths`'
``camera_hits``) and :class:`rtmesh.io.passes.PassRecorder` forms the passes from them, as
from the general path's surface records.

Columns of a row: the point (re-centred frame, scene units), the shading normal facing the
camera (the interpolated normal on the viewer's side, bent by a normal map, then
:func:`rtmesh.shading.surfaces.face_viewer_row`: the normal the general path's surface
records carry), the albedo (the pass's table times the base texture and vertex colour),
the texture coordinates, whether the ray shaded a surface (1) or not (0), and the
ambient-occlusion rays that escaped (a count), by :data:`HIT_POINT` ... :data:`HIT_FREE`;
:data:`HIT_AO_HERE` is scratch (whether the lane's current vertex casts the pass's rays).
"""

from rtmesh.core.compiled import inline_row, row
from rtmesh.geometry.embree_packets import LANES
from rtmesh.rendering.path_surfaces import NORMAL_TEXTURE, colour_tint, hit_uv, normal_mapped
from rtmesh.shading.surfaces import face_viewer_row

HIT_POINT, HIT_NORMAL, HIT_ALBEDO, HIT_UV, HIT_COVERED, HIT_FREE, HIT_AO_HERE = 0, 3, 6, 9, 11, 12, 13
CAMERA_HIT_WORDS = 13
# a lane's row: the record, then the scratch word
FIRST_HIT_WORDS = CAMERA_HIT_WORDS + 1


# a plain row, not inlined: it runs once a camera ray and only with passes, and inlined it
# added 1.7 s to the first compile of meet (20.7 -> 19.0 s of CPU as a row)
@row
def record_camera_hit(first_hit, lane, surface, geometry, pass_albedo, mat, prim, bu, bv, hx, hy, hz, gx, gy, gz,
                      nx, ny, nz, dx, dy, dz, instances, placement):
    """Record a camera segment's shaded surface in ``first_hit[lane]``.

    Parameters
    ----------
    first_hit : (WIDTH, FIRST_HIT_WORDS) float64
    lane : int
    surface, geometry : tuples
        The scene's records (:mod:`rtmesh.rendering.path_surfaces`).
    pass_albedo : (M, 3) float64
        Each material's albedo for the pass (:attr:`rtmesh.io.passes.PassRecorder.diffuse`).
    mat, prim : int
    bu, bv : float
        Embree's barycentrics of the hit.
    hx, hy, hz, gx, gy, gz, nx, ny, nz : float
        The point, the unit geometric normal (winding) and the unit interpolated normal.
    dx, dy, dz : float
        The camera ray's unit direction.
    instances : tuple
        The kernel's ``instances`` record.
    placement : int
        The placement hit (-1: none), whose transform carries the face's UV tangents.
    """
    # the shading normal as the general path's surface records form it: on the geometric
    # normal's side, bent by the normal map, both turned to the viewer, then the
    # terminator fix
    if (nx * gx + ny * gy) + nz * gz < 0.0:
        nx, ny, nz = -nx, -ny, -nz
    if surface[8][mat, NORMAL_TEXTURE] >= 0:
        nx, ny, nz = normal_mapped(surface, geometry, mat, prim, bu, bv, nx, ny, nz, instances, placement)
    if (gx * dx + gy * dy) + gz * dz > 0.0:
        gx, gy, gz, nx, ny, nz = -gx, -gy, -gz, -nx, -ny, -nz
    nx, ny, nz = face_viewer_row(nx, ny, nz, gx, gy, gz, dx, dy, dz)
    cr, cg, cb, _, _, _ = colour_tint(surface, geometry, mat, prim, bu, bv)
    u, v = hit_uv(geometry, prim, bu, bv)
    row = first_hit[lane]
    row[HIT_POINT], row[HIT_POINT + 1], row[HIT_POINT + 2] = hx, hy, hz
    row[HIT_NORMAL], row[HIT_NORMAL + 1], row[HIT_NORMAL + 2] = nx, ny, nz
    row[HIT_ALBEDO] = pass_albedo[mat, 0] * cr
    row[HIT_ALBEDO + 1] = pass_albedo[mat, 1] * cg
    row[HIT_ALBEDO + 2] = pass_albedo[mat, 2] * cb
    row[HIT_UV], row[HIT_UV + 1] = u, v
    row[HIT_COVERED] = 1.0


@inline_row
def count_escaped(shadow_valid, first_hit):
    """Count the pass's ambient-occlusion rays of a packet that escaped (``shadow_valid``
    (16,) after the occlusion query; ``first_hit`` the packet's rows)."""
    for lane in range(LANES):
        if shadow_valid[lane] and first_hit[lane, HIT_AO_HERE] > 0.0:
            first_hit[lane, HIT_FREE] += 1.0
