"""The Whitted integrator as a configuration of the path kernel: the rows that read a
Blinn-Phong material as the Whitted model does (:mod:`rtmesh.rendering.path_kernel` calls
them under ``integrator = "whitted"``).

Model (docs/SCENE_FORMAT.md, the Whitted conventions)
------------------------------------------------------
- Light from a light: ``kd max(0, n.wi) + ks (n.h)^shininess`` times the light's incident
  term (:func:`light_factor`): a Lambert term without ``1 / pi`` and an unnormalised
  highlight, as :mod:`rtmesh.materials.blinn_phong` forms it for the fused stage.
- The rays a hit sends on (:func:`branches`): the mirror reflection weighted ``kr`` (a Phong
  lobe around it for ``roughness`` > 0, :mod:`rtmesh.materials.glossy`), and for a
  transmission colour ``kt`` a smooth dielectric whose Fresnel reflectance (Schlick's or the
  exact one, the ``fresnel`` setting) adds ``F kt`` to the reflection and sends ``(1 - F) kt``
  through by Snell's law; total internal reflection reflects all of ``kt``.  Both rays are
  followed (the Whitted split): the kernel continues one and keeps the other on the lane's
  stack of branches (:func:`push_branch`, :func:`pop_branch`).

The rows work in world space on the normals turned to the viewer's side, as
:class:`rtmesh.materials.specular.SpecularScattering` does: a mirror direction that a
shading normal sends under the geometric surface falls back to the geometric mirror
direction, a refracted direction that stays on the incoming side is dropped, and glossy
directions under the surface are folded back above it.
"""

import math

import numpy as np

from rtmesh.core.compiled import inline_row, row
from rtmesh.core.row_vectors import tangent_frame
from rtmesh.materials import lobes
from rtmesh.materials.blinn_phong import blinn_phong_row, highlight_cosine, raise_highlight
from rtmesh.materials.glossy import lobe_direction

# the Blinn-Phong row of a material (rtmesh.materials.phong.parameters)
_KD, _KS, _SHININESS, _KR, _KT, _IOR, _ROUGHNESS = 0, 3, 6, 7, 10, 13, 14
# a branch on a lane's stack: origin, direction, throughput and depth (then its media)
BRANCH_WORDS = 10


@row
def light_factor(params, m, ox, oy, oz, wx, wy, wz):
    """Whitted's factor ``kd max(0, cos_i) + ks (n.h)^n`` (r, g, b) toward a light in
    direction ``w`` seen along ``o`` (unit, local frame of the shading normal; a
    transmissive material's frame keeps its outward side, so a hit from inside is turned
    to the viewer's side first).  The highlight needs ``n.wi > 0``; an exponent of 0 raises
    every cosine to 1."""
    if oz < 0.0:
        oz, wz = -oz, -wz
    if not wz > 0.0:
        return 0.0, 0.0, 0.0
    ks_r, ks_g, ks_b = params[m, _KS], params[m, _KS + 1], params[m, _KS + 2]
    power = 0.0
    if (ks_r > 0.0) | (ks_g > 0.0) | (ks_b > 0.0):
        exponent = params[m, _SHININESS]
        cosine = 1.0 if exponent == 0.0 else highlight_cosine(0.0, 0.0, 1.0, ox, oy, oz, wx, wy, wz)
        if cosine > 0.0:
            power = raise_highlight(cosine, exponent)
    return blinn_phong_row(params[m, _KD], params[m, _KD + 1], params[m, _KD + 2], ks_r, ks_g, ks_b, wz, power)


@row
def fresnel(cos_i, eta, exact):
    """The Whitted model's dielectric reflectance at ``cos_i`` (in [0, 1], on the incident
    side) for ``eta`` = incident index over transmitted index: Schlick's approximation (with
    the transmitted cosine going out of the denser medium, 0 at ``eta`` = 1) or, with
    ``exact``, the exact unpolarised reflectance; 1 under total internal reflection (as
    :func:`rtmesh.core.vecmath.fresnel_schlick` and ``fresnel_dielectric``)."""
    sin2_t = eta * eta * (1.0 - cos_i * cos_i)
    if sin2_t >= 1.0:
        return 1.0
    if exact:
        return lobes.fresnel_dielectric(cos_i, 1.0 / eta)
    if eta == 1.0:
        return 0.0
    r0 = ((1.0 - eta) / (1.0 + eta)) ** 2
    cos_t = math.sqrt(max(0.0, 1.0 - sin2_t))
    c = cos_t if eta > 1.0 else cos_i
    return r0 + (1.0 - r0) * (1.0 - c) ** 5


@row
def branches(params, m, ox, oy, oz, nx, ny, nz, gx, gy, gz, entering, exact, u1, u2):
    """The reflected and refracted rays of a Whitted hit (world space).

    Parameters
    ----------
    params : (M, PARAMETER_WIDTH) float64
        Blinn-Phong rows (textured: the hit's own row); the ``ior`` slot holds the index of
        the material's inside over that of its outside (the kernel's media).
    m : int
        The row.
    ox, oy, oz : float
        Unit direction toward the viewer.
    nx, ny, nz, gx, gy, gz : float
        Unit shading and geometric normals (either side).
    entering : bool
        Whether the ray meets the material from outside.
    exact : bool
        Exact Fresnel reflectance instead of Schlick's.
    u1, u2 : float
        The glossy lobe's sample point.

    Returns
    -------
    tuple
        ``(rx, ry, rz, reflect r, g, b, tx, ty, tz, transmit r, g, b)``: the reflected
        direction and weight (zero weight: no reflection), the refracted direction and
        weight (zero: none).
    """
    # both normals on the viewer's side
    if (gx * ox + gy * oy) + gz * oz < 0.0:
        gx, gy, gz = -gx, -gy, -gz
    if (nx * gx + ny * gy) + nz * gz < 0.0:
        nx, ny, nz = -nx, -ny, -nz
    cos_o = (nx * ox + ny * oy) + nz * oz
    wr, wg, wb = params[m, _KR], params[m, _KR + 1], params[m, _KR + 2]
    kt_r, kt_g, kt_b = params[m, _KT], params[m, _KT + 1], params[m, _KT + 2]
    tx = ty = tz = tr = tg = tb = 0.0
    if (kt_r > 0.0) | (kt_g > 0.0) | (kt_b > 0.0):
        eta = 1.0 / params[m, _IOR] if entering else params[m, _IOR]
        cos_i = min(max(cos_o, 0.0), 1.0)
        f = fresnel(cos_i, eta, exact)
        sin2_t = eta * eta * (1.0 - cos_i * cos_i)
        if sin2_t < 1.0:
            cos_t = math.sqrt(max(0.0, 1.0 - sin2_t))
            k = eta * cos_o - cos_t
            tx, ty, tz = -eta * ox + k * nx, -eta * oy + k * ny, -eta * oz + k * nz
            # a shading normal can bend the refracted ray back to the incoming side
            if (tx * gx + ty * gy) + tz * gz < 0.0:
                tr, tg, tb = (1.0 - f) * kt_r, (1.0 - f) * kt_g, (1.0 - f) * kt_b
        wr, wg, wb = wr + f * kt_r, wg + f * kt_g, wb + f * kt_b
    rx, ry, rz = 2.0 * cos_o * nx - ox, 2.0 * cos_o * ny - oy, 2.0 * cos_o * nz - oz
    if not (rx * gx + ry * gy) + rz * gz > 0.0:
        c = (gx * ox + gy * oy) + gz * oz
        rx, ry, rz = 2.0 * c * gx - ox, 2.0 * c * gy - oy, 2.0 * c * gz - oz
    roughness = params[m, _ROUGHNESS]
    if roughness > 0.0 and ((wr > 0.0) | (wg > 0.0) | (wb > 0.0)):
        # the Phong lobe of exponent 1 / r^2 around the mirror direction
        # (rtmesh.materials.glossy: 1 - cos theta by expm1 / log1p, folded above the surface)
        one_minus_cos = -math.expm1(math.log1p(-u1) / (1.0 / (roughness * roughness) + 1.0))
        lx, ly, lz = lobe_direction(one_minus_cos, u2)
        ax, ay, az, bx, by, bz = tangent_frame(rx, ry, rz)
        rx, ry, rz = (ax * lx + bx * ly) + rx * lz, (ay * lx + by * ly) + ry * lz, (az * lx + bz * ly) + rz * lz
        below = (rx * gx + ry * gy) + rz * gz
        fold = 0.0 if below > 0.0 else below
        rx, ry, rz = rx - (2.0 * fold) * gx, ry - (2.0 * fold) * gy, rz - (2.0 * fold) * gz
    return rx, ry, rz, wr, wg, wb, tx, ty, tz, tr, tg, tb


@inline_row
def push_branch(branch, branch_media, branch_top, lane, qx, qy, qz, dx, dy, dz, br, bg, bb, depth, stack):
    """Keep a ray for lane ``lane`` to follow later (its origin, direction, throughput,
    depth and media stack); False when the lane's stack of branches is full."""
    top = branch_top[lane]
    if top >= branch.shape[1]:
        return False
    row_ = branch[lane, top]
    row_[0], row_[1], row_[2], row_[3], row_[4], row_[5] = qx, qy, qz, dx, dy, dz
    row_[6], row_[7], row_[8], row_[9] = br, bg, bb, np.float64(depth)
    for k in range(stack.shape[1]):
        branch_media[lane, top, k] = stack[lane, k]
    branch_top[lane] = top + 1
    return True


@inline_row
def pop_branch(branch, branch_media, branch_top, lane, px, py, pz, dx, dy, dz, beta, lane_depth, stack):
    """Load lane ``lane`` with the ray last kept by :func:`push_branch` (its stack is not
    empty); returns the ray's innermost medium (-1: none)."""
    top = branch_top[lane] - 1
    branch_top[lane] = top
    row_ = branch[lane, top]
    px[lane], py[lane], pz[lane], dx[lane], dy[lane], dz[lane] = row_[0], row_[1], row_[2], row_[3], row_[4], row_[5]
    beta[lane, 0], beta[lane, 1], beta[lane, 2] = row_[6], row_[7], row_[8]
    lane_depth[lane] = np.int64(row_[9])
    for k in range(stack.shape[1]):
        stack[lane, k] = branch_media[lane, top, k]
    return stack[lane, 0]
