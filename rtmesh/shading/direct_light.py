"""Direct light from point-like lights in compiled code: the lit hits and their shadow rays
(:func:`light_samples`), then, once the shadow rays are traced, the lights' Blinn-Phong
terms (:func:`add_light`).
"""


import numpy as np

from rtmesh.core.compiled import inline_row, kernel, row
from rtmesh.core.row_vectors import dot3
from rtmesh.geometry.float32_rays import F32_MAX, offset_origin
from rtmesh.materials.blinn_phong import highlight_cosine, shade_row


# ------------------------------------------------------------------ point-like lights
@row
def light_reaches(wx, wy, wz, er, eg, eb, gx, gy, gz):
    """Whether a light with direction ``w`` and incident term ``e`` (see
    :meth:`rtmesh.lights.interface.PointLikeLight.illuminate`)
    lights a point with geometric normal ``g``: it is on the side the ray came from
    (``wi . ng > 0``: no leaks through the surface) and its term is not zero."""
    # bitwise operators: short-circuits are branches, which stop vectorisation
    return (dot3(wx, wy, wz, gx, gy, gz) > 0.0) & ((er > 0.0) | (eg > 0.0) | (eb > 0.0))


@inline_row
def light_sample(px, py, pz, gx, gy, gz, nx, ny, nz, vx, vy, vz, wx, wy, wz, distance, er, eg, eb, scale, shorten,
                 highlights):
    """What :func:`light_samples` and the fused stage's light step
    (:func:`rtmesh.rendering.direct_blocks.light_block`) keep of one light at one surface
    record (point ``p``, geometric and shading normals ``g``, ``n``, ray direction ``v``)
    from the light's direction ``w``, distance and incident term ``e``: whether it lights
    the point, ``ns . wi``, ``e``, the highlight cosine (0 without ``highlights``) and the
    shadow ray (float32 offset origin, direction and length).  Numbers only, and inlined:
    the loops that call it vectorise."""
    lit = light_reaches(wx, wy, wz, er, eg, eb, gx, gy, gz)
    cosine = highlight_cosine(nx, ny, nz, -vx, -vy, -vz, wx, wy, wz) if highlights else 0.0
    # the shadow ray's direction in float32, as Embree will see it, also sets the offset
    dx, dy, dz = np.float32(wx), np.float32(wy), np.float32(wz)
    ox, oy, oz = offset_origin(px, py, pz, gx, gy, gz, dx, dy, dz, scale)
    return (lit, dot3(nx, ny, nz, wx, wy, wz), er, eg, eb, cosine, ox, oy, oz, dx, dy, dz,
            np.float32(min(distance * shorten, F32_MAX)))


@row
def highlight_to_raise(exponent, cosine, visible_from):
    """The cosine a highlight raises to ``exponent`` (a power of 0 is 1 whatever the
    cosine, 0 ** 0 included), and whether it is raised at all: the material has a
    highlight (``exponent >= 0``) and the cosine is positive and at least ``visible_from``
    (:func:`highlight_thresholds`).  Branch-free, for vectorised loops."""
    c = 1.0 if exponent == 0.0 else cosine
    return c, (exponent >= 0.0) & (c > 0.0) & (c >= visible_from)


# Shadow rays to point and spot lights stop this fraction short of the light, so a light
# placed exactly on a surface does not count that surface as an occluder.
SHADOW_SHORTEN = 1.0 - 1e-5
# rows per block of light_samples: its scratch arrays (~70 bytes a row) stay in L1
_BLOCK = 256


@kernel
def light_samples(wi_t, distance, incident_t, p_t, ng_t, ns_t, d_t, mat, exponent, visible_from, scale, shorten):
    """One point-like light at every hit: the lit hits, their shadow rays, and what shading
    them needs once the shadow rays are traced (see :func:`add_light`).

    The vectors come by component, (3, k) (:func:`rtmesh.core.compiled.by_component`).

    Parameters
    ----------
    wi_t : (3, k) float64
        Unit directions toward the light (see
        :meth:`rtmesh.lights.interface.PointLikeLight.illuminate`).
    distance : (k,) float64
        Distances to the light.
    incident_t : (3, k) float64
        The light's incident term at each hit.
    p_t, ng_t, ns_t, d_t : (3, k) float64
        Surface records: points, geometric and shading normals, incoming directions.
    mat : (k,) intp
    exponent : (M,) float64
        Shininess per material, negative for materials without a highlight.
    visible_from : (M,) float64
        Per material, the smallest highlight cosine whose power is kept (see
        :func:`highlight_thresholds`).
    scale : float32
        Scene size, for the origin offset.
    shorten : float
        Shadow rays end this fraction of the way to the light.

    Returns
    -------
    lit : (j,) intp
        The lit rows: the light is on the side the ray came from and reaches them.
    origins, directions : (j, 3) float32
        Row-major shadow rays, origins offset off the surface.
    t_max : (j,) float32
        Shadow ray lengths (clamped to the float32 range).
    cos_i : (j,) float64
        ``ns . wi``.
    incident : (j, 3) float64
        The light's incident term.
    highlight_rows : (h,) intp
        The lit rows (indices into the arrays above) with a highlight worth raising.
    highlight, power_exponent : (h,) float64
        ``highlight ** power_exponent`` is the highlight's power there (``max(0, ns . h)``
        and the shininess); it is 0 on the other lit rows.  Raised afterwards by
        :func:`rtmesh.materials.blinn_phong.raise_highlights` (libm's pow, as the fused
        stage raises them), only on the rows that have a highlight worth raising.

    Notes
    -----
    A block of rows is formed by a loop without branches, gathers or calls, which LLVM
    vectorises; a second loop over the block keeps the lit rows.
    """
    wi, incident_all, p, ng, ns, d = wi_t.T, incident_t.T, p_t.T, ng_t.T, ns_t.T, d_t.T
    k = len(p)
    lit = np.empty(k, np.intp)
    origins, directions = np.empty((k, 3), np.float32), np.empty((k, 3), np.float32)
    t_max = np.empty(k, np.float32)
    cos_i, incident = np.empty(k), np.empty((k, 3))
    highlight_rows, highlight, power_exponent = np.empty(k, np.intp), np.empty(k), np.empty(k)
    block_incident, block_cos = np.empty((3, _BLOCK)), np.empty((2, _BLOCK))
    block_ray = np.empty((6, _BLOCK), np.float32)
    block_length, block_lit = np.empty(_BLOCK, np.float32), np.empty(_BLOCK, np.bool_)
    j = h = 0
    for start in range(0, k, _BLOCK):
        n = min(_BLOCK, k - start)
        for b in range(n):
            i = start + b
            (block_lit[b], block_cos[0, b], block_incident[0, b], block_incident[1, b], block_incident[2, b],
             block_cos[1, b], block_ray[0, b], block_ray[1, b], block_ray[2, b], block_ray[3, b], block_ray[4, b],
             block_ray[5, b], block_length[b]) = light_sample(
                p[i, 0], p[i, 1], p[i, 2], ng[i, 0], ng[i, 1], ng[i, 2], ns[i, 0], ns[i, 1], ns[i, 2], d[i, 0],
                d[i, 1], d[i, 2], wi[i, 0], wi[i, 1], wi[i, 2], distance[i], incident_all[i, 0],
                incident_all[i, 1], incident_all[i, 2], scale, shorten, True)
        for b in range(n):
            if not block_lit[b]:
                continue
            i = start + b
            for c in range(3):
                origins[j, c] = block_ray[c, b]
                directions[j, c] = block_ray[3 + c, b]
                incident[j, c] = block_incident[c, b]
            t_max[j] = block_length[b]
            cos_i[j] = block_cos[0, b]
            m = mat[i]
            c, raised = highlight_to_raise(exponent[m], block_cos[1, b], visible_from[m])
            if raised:
                highlight_rows[h], highlight[h], power_exponent[h] = j, c, exponent[m]
                h += 1
            lit[j] = i
            j += 1
    return (lit[:j], origins[:j], directions[:j], t_max[:j], cos_i[:j], incident[:j], highlight_rows[:h],
            highlight[:h], power_exponent[:h])


def highlight_thresholds(exponent):
    """Per material, the smallest highlight cosine whose power :func:`light_samples` keeps.

    Below ``2 ** (-1000 / shininess)`` the power is under ``2 ** -1000`` (1e-301), nothing
    an image can show, and NumPy's pow would take its slow underflow path; 0 for a
    shininess of 0 (a power of 1), inf without a highlight.

    Parameters
    ----------
    exponent : (M,) float
        Shininess, negative without a highlight.

    Returns
    -------
    (M,) float64
    """
    exponent = np.asarray(exponent, dtype=np.float64)
    with np.errstate(divide="ignore"):
        threshold = np.exp2(-1000.0 / exponent)
    return np.where(exponent > 0.0, threshold, np.where(exponent == 0.0, 0.0, np.inf))


@kernel
def add_light(total_t, target, lit, occluded, cos_i, incident, highlight_rows, power, mat, diffuse, tint_d,
              specular, tint_s):
    """Add one light's Blinn-Phong term to the lit rows whose shadow rays are clear.

    Parameters
    ----------
    total_t : (3, K) float64
        Accumulated direct light by component (:func:`rtmesh.core.compiled.by_component`;
        updated in place).
    target : (j,) intp
        Row of ``total`` for each lit row.
    lit : (j,) intp
        The lit rows of ``mat`` and the tints (see :func:`light_samples`).
    occluded : (j,) bool
        Shadow-ray results.
    cos_i : (j,) float64
        ``ns . wi``.
    incident : (j, 3) float64
    highlight_rows : (h,) intp
        Ascending lit rows with a highlight.
    power : (h,) float64
        The raised highlight cosine of those rows (0 on the others).
    mat : (k,) intp
    diffuse, specular : (M, 3) float64
        Material colours.
    tint_d, tint_s : (k, 3) float or (0, 3)
        Texture tints of the colours, or empty.
    """
    total = total_t.T
    q = 0  # next highlight row: both lists are ascending
    for j in range(len(lit)):
        highlight = 0.0
        if q < len(highlight_rows) and highlight_rows[q] == j:
            highlight = power[q]
            q += 1
        if occluded[j]:
            continue
        i, r = lit[j], target[j]
        f0, f1, f2 = shade_row(i, mat[i], cos_i[j], highlight, diffuse, tint_d, specular, tint_s)
        total[r, 0] += f0 * incident[j, 0]
        total[r, 1] += f1 * incident[j, 1]
        total[r, 2] += f2 * incident[j, 2]
