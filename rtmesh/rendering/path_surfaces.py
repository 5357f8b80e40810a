"""What the path kernel reads at a surface hit, as compiled rows: the point and its normals,
texture coordinates, the material's parameters scaled by its textures and vertex colours,
normal maps, emission and opacity (alpha cut-outs).

The rows are inlined into the kernel (``inline_row``): a call of a compiled row takes and
releases a reference to every array of its record arguments (atomic instructions, some
fifteen arrays a record), which made them the kernel's largest cost.  The KHR layers' rows
(:func:`layer_textures`, :func:`orient_layers`) are the exception: called for layered
materials only, they are kept out of the kernel's compile.

The rows take two records (tuples of arrays) that :class:`rtmesh.rendering.path_stage.PathStage`
builds once per scene:

``geometry``: ``(triangles (F, 9), face_normals (F, 3), vertex_normals (V, 3) or (0, 3),
faces (F, 3), smooth (F,) or (0,), material_id (F,), face_uv (F, 6) or (0, 6),
face_colours (F, 12) or (0, 12), face_tangents (F, 6) or (0, 6))`` — corners and edges
(:func:`rtmesh.rendering.surface_textures.corner_and_edges`) of the UVs and vertex colours.

``surface``: ``(tags, params, transmissive, emission, absorption, unlit, albedo_table,
slots, textures (M, len(TEXTURE_COLUMNS)), metal_tint (M,), alpha_mode (M,), alpha_cutoff (M,),
opacity (M,), texels, texture_descriptors, ior (M,), twins (F,) or (0,))``: the material tables of :mod:`rtmesh.materials.models`, each
material's texture indices in the atlas (:data:`TEXTURE_COLUMNS`; -1 none) and its
Whitted metal tint, the atlas (:mod:`rtmesh.io.texture_atlas`), each material's index of
refraction, and each face's touching twin's material
(:func:`rtmesh.rendering.path_media.twin_material`; empty when no
two transmissive faces touch).

Texturing follows :mod:`rtmesh.rendering.surface_textures` (docs/MATERIALS.md): the base
colour texture and vertex colours scale the model's colour, its alpha and the opacity
texture the opacity, glTF's metallic-roughness texture the roughness (green) and metalness
(blue), the emission texture the emission; a Whitted material's ``metallic`` tints its
specular and mirror colours by the base texture.  The KHR layers' textures scale their
factors (:func:`layer_textures`, the channels their specifications name), and
:func:`orient_layers` turns a layered row's clear-coat normal (its own normal map) and
anisotropy direction (from the UV tangents) into the hit's local frame.
"""

import math

import numpy as np

from rtmesh.core.compiled import inline_row, row
from rtmesh.geometry import embree_packets
from rtmesh.geometry.float32_rays import offset_origin
from rtmesh.io.texture_atlas import texel
from rtmesh.lights import environment_table, light_table
from rtmesh.lights.environment import sample_direction
from rtmesh.lights.light_table import FACE
from rtmesh.lights.point_light_rows import illuminate_row
from rtmesh.materials import models
from rtmesh.materials.metallic_roughness import alpha_from_roughness_row
from rtmesh.materials.table import ALPHA_MODES
from rtmesh.rendering.path_media import interface_ratio, twin_material
from rtmesh.sampling.alias import alias_sample as _alias_sample

TEXTURE_COLUMNS = ("diffuse_texture", "metallic_roughness_texture", "normal_texture", "emission_texture",
                   "specular_texture", "opacity_texture",
                   # glTF's baked occlusion, which darkens the Whitted integrator's ambient term
                   "occlusion_texture",
                   # the KHR layers' textures (rtmesh.materials.gltf_layered.Layers.textures, by role)
                   "specularTexture", "specularColorTexture", "clearcoatTexture", "clearcoatRoughnessTexture",
                   "clearcoatNormalTexture", "sheenColorTexture", "sheenRoughnessTexture", "anisotropyTexture",
                   "iridescenceTexture", "iridescenceThicknessTexture")
(BASE_TEXTURE, MR_TEXTURE, NORMAL_TEXTURE, EMISSION_TEXTURE, SPECULAR_TEXTURE, OPACITY_TEXTURE, OCCLUSION_TEXTURE,
 SPECULAR_STRENGTH_TEXTURE, SPECULAR_COLOUR_TEXTURE, CLEARCOAT_TEXTURE, CLEARCOAT_ROUGHNESS_TEXTURE,
 CLEARCOAT_NORMAL_TEXTURE, SHEEN_COLOUR_TEXTURE, SHEEN_ROUGHNESS_TEXTURE, ANISOTROPY_TEXTURE, IRIDESCENCE_TEXTURE,
 IRIDESCENCE_THICKNESS_TEXTURE) = range(len(TEXTURE_COLUMNS))
# the first layer texture column: hits of materials with none skip the layers' lookups
LAYER_TEXTURES = SPECULAR_STRENGTH_TEXTURE
OPAQUE, MASK, BLEND = (ALPHA_MODES.index(name) for name in ("opaque", "mask", "blend"))


# Rows of other modules that take arrays, which the path and photon kernels call per lane,
# inlined by numba: a compiled call that passes arrays takes and releases a reference to
# each (atomic instructions), and LLVM stops inlining small rows into functions as large as
# the kernels (those calls doubled the path kernel's time); rows of numbers only stay calls
# (inlining them too cost compile time, no speed)
set_lane = inline_row(embree_packets.set_lane.py_func)
clear_hit = inline_row(embree_packets.clear_hit.py_func)
alias_sample = inline_row(_alias_sample.py_func)
environment_radiance_uv = inline_row(environment_table.environment_radiance_uv.py_func)
environment_sample = inline_row(sample_direction.py_func)
sample_area_point = inline_row(light_table.sample_area_point.py_func)
illuminate = inline_row(illuminate_row.py_func)


@inline_row
def environment_radiance(pixels, cos_rotation, sin_rotation, dx, dy, dz):
    """Background radiance along a unit direction: the map's ``(u, v)``
    (:func:`rtmesh.lights.environment_table.latlong_uv`) and its bilinear lookup, inlined."""
    u, v = environment_table.latlong_uv(cos_rotation, sin_rotation, dx, dy, dz)
    return environment_radiance_uv(pixels, u, v)
projector_incident = inline_row(light_table.projector_incident.py_func)


@inline_row
def load_lanes(alive, ray, words, valid, px, py, pz, dx, dy, dz, tfar):
    """Write the living lanes' rays (origins ``p``, directions ``d``: (LANES,) float64 each)
    into a packet with an empty hit and mark them valid for Embree (-1; 0 for the others).

    Returns
    -------
    int
        The lanes loaded.
    """
    active = 0
    for lane in range(embree_packets.LANES):
        if alive[lane]:
            set_lane(ray, words, lane, px[lane], py[lane], pz[lane], dx[lane], dy[lane], dz[lane], tfar)
            clear_hit(words, lane)
            valid[lane] = -1
            active += 1
        else:
            valid[lane] = 0
    return active



@inline_row
def surface_point(geometry, prim, bu, bv):
    """The hit point on the float32 triangle, its unit geometric normal (winding) and its
    unit shading normal (interpolated where the face is smooth)."""
    triangles, face_normals, vertex_normals, faces, smooth = geometry[0], geometry[1], geometry[2], geometry[3], geometry[4]
    tri = triangles[prim]
    hx = tri[0] + bu * tri[3] + bv * tri[6]
    hy = tri[1] + bu * tri[4] + bv * tri[7]
    hz = tri[2] + bu * tri[5] + bv * tri[8]
    gx, gy, gz = face_normals[prim, 0], face_normals[prim, 1], face_normals[prim, 2]
    nx, ny, nz = gx, gy, gz
    if len(smooth) and smooth[prim]:
        f0, f1, f2 = faces[prim, 0], faces[prim, 1], faces[prim, 2]
        w0 = 1.0 - bu - bv
        sx = w0 * vertex_normals[f0, 0] + bu * vertex_normals[f1, 0] + bv * vertex_normals[f2, 0]
        sy = w0 * vertex_normals[f0, 1] + bu * vertex_normals[f1, 1] + bv * vertex_normals[f2, 1]
        sz = w0 * vertex_normals[f0, 2] + bu * vertex_normals[f1, 2] + bv * vertex_normals[f2, 2]
        length = math.sqrt((sx * sx + sy * sy) + sz * sz)
        if length > 0.0:
            nx, ny, nz = sx / length, sy / length, sz / length
    return hx, hy, hz, gx, gy, gz, nx, ny, nz


@inline_row
def hit_uv(geometry, prim, bu, bv):
    """Texture coordinates of a hit ((0, 0) without UVs)."""
    face_uv = geometry[6]
    if not len(face_uv):
        return 0.0, 0.0
    r = face_uv[prim]
    return r[0] + bu * r[2] + bv * r[4], r[1] + bu * r[3] + bv * r[5]


@inline_row
def vertex_colour(geometry, prim, bu, bv):
    """Linear RGBA vertex colour of a hit (ones without vertex colours)."""
    colours = geometry[7]
    if not len(colours):
        return 1.0, 1.0, 1.0, 1.0
    r = colours[prim]
    return (r[0] + bu * r[4] + bv * r[8], r[1] + bu * r[5] + bv * r[9], r[2] + bu * r[6] + bv * r[10],
            r[3] + bu * r[7] + bv * r[11])


@inline_row
def is_transparent(surface, geometry, mat, prim, bu, bv, coin):
    """Whether a ray passes this hit of a cut-out material (mask: opacity below the cutoff;
    blend: with probability 1 - opacity, decided by ``coin`` in [0, 1))."""
    mode = surface[10][mat]
    if mode == OPAQUE:
        return False
    alpha = surface[12][mat] * vertex_colour(geometry, prim, bu, bv)[3]
    textures = surface[8]
    base, opacity = textures[mat, BASE_TEXTURE], textures[mat, OPACITY_TEXTURE]
    if (base >= 0) | (opacity >= 0):
        u, v = hit_uv(geometry, prim, bu, bv)
        texels, descriptors = surface[13], surface[14]
        if base >= 0 and (descriptors[base, 3] == 2.0 or descriptors[base, 3] == 4.0):
            alpha *= texel(texels, descriptors, base, u, v)[3]
        if opacity >= 0:
            alpha *= texel(texels, descriptors, opacity, u, v)[0]
    alpha = min(max(alpha, 0.0), 1.0)
    if mode == MASK:
        return alpha < surface[11][mat]
    return coin >= alpha


@inline_row
def textured_row(surface, geometry, mat, prim, bu, bv, scratch, lane):
    """Copy the material's parameter row into ``scratch[lane]`` with its textures and vertex
    colours applied; returns the emission (r, g, b) at the hit."""
    tags, params, emission, slots, textures = surface[0], surface[1], surface[3], surface[7], surface[8]
    for k in range(params.shape[1]):
        scratch[lane, k] = params[mat, k]
    er, eg, eb = emission[mat, 0], emission[mat, 1], emission[mat, 2]
    slot = slots[tags[mat]]
    cr, cg, cb, br, bg, bb = colour_tint(surface, geometry, mat, prim, bu, bv)
    if len(geometry[6]):
        texels, descriptors = surface[13], surface[14]
        u, v = hit_uv(geometry, prim, bu, bv)
        if textures[mat, BASE_TEXTURE] >= 0:
            m = surface[9][mat]
            if m > 0.0:
                for s in (slot[models.SPECULAR_SLOT], slot[models.MIRROR_SLOT]):
                    if s >= 0:
                        scratch[lane, s] *= (1.0 - m) + m * br
                        scratch[lane, s + 1] *= (1.0 - m) + m * bg
                        scratch[lane, s + 2] *= (1.0 - m) + m * bb
        t = textures[mat, SPECULAR_TEXTURE]
        s = slot[models.SPECULAR_SLOT]
        if t >= 0 and s >= 0:
            sr, sg, sb, _ = texel(texels, descriptors, t, u, v)
            scratch[lane, s] *= sr
            scratch[lane, s + 1] *= sg
            scratch[lane, s + 2] *= sb
        t = textures[mat, MR_TEXTURE]
        if t >= 0:
            _, green, blue, _ = texel(texels, descriptors, t, u, v)
            if slot[models.METALLIC_SLOT] >= 0:
                scratch[lane, slot[models.METALLIC_SLOT]] *= blue
            s = slot[models.ROUGHNESS_SLOT]
            if s >= 0:
                scratch[lane, s] *= green
                if slot[models.ALPHA_SLOT] >= 0:
                    scratch[lane, slot[models.ALPHA_SLOT]] = alpha_from_roughness_row(scratch[lane, s])
        er, eg, eb = emission_at(surface, geometry, mat, prim, bu, bv)
        if slot[models.COAT_NORMAL_SLOT] >= 0:
            layer_textures(textures, texels, descriptors, mat, slot, u, v, scratch, lane)
    s = slot[models.COLOUR_SLOT]
    if s >= 0:
        scratch[lane, s] *= cr
        scratch[lane, s + 1] *= cg
        scratch[lane, s + 2] *= cb
    return er, eg, eb


@inline_row
def colour_tint(surface, geometry, mat, prim, bu, bv):
    """What scales a material's colour at a point of a face: its vertex colour times its
    base texture's texel (r, g, b), and that texel alone (1 without a texture)."""
    cr, cg, cb, _ = vertex_colour(geometry, prim, bu, bv)
    br = bg = bb = 1.0
    t = surface[8][mat, BASE_TEXTURE]
    if t >= 0 and len(geometry[6]):
        u, v = hit_uv(geometry, prim, bu, bv)
        br, bg, bb, _ = texel(surface[13], surface[14], t, u, v)
        cr, cg, cb = cr * br, cg * bg, cb * bb
    return cr, cg, cb, br, bg, bb


@inline_row
def occlusion_at(surface, geometry, mat, prim, bu, bv, strength):
    """glTF's baked ambient occlusion at a point of a face: ``1 + strength (red - 1)`` of the
    material's occlusion texture (1 without one)."""
    t = surface[8][mat, OCCLUSION_TEXTURE]
    if t < 0 or not len(geometry[6]):
        return 1.0
    u, v = hit_uv(geometry, prim, bu, bv)
    red, _, _, _ = texel(surface[13], surface[14], t, u, v)
    return 1.0 + strength * (red - 1.0)


@inline_row
def emission_at(surface, geometry, mat, prim, bu, bv):
    """Emitted radiance (r, g, b) at a point of a face: the material's, times its emission
    texture."""
    emission = surface[3]
    er, eg, eb = emission[mat, 0], emission[mat, 1], emission[mat, 2]
    t = surface[8][mat, EMISSION_TEXTURE]
    if t >= 0 and len(geometry[6]):
        u, v = hit_uv(geometry, prim, bu, bv)
        tr, tg, tb, _ = texel(surface[13], surface[14], t, u, v)
        er, eg, eb = er * tr, eg * tg, eb * tb
    return er, eg, eb


@inline_row
def triangle_light_emission(surface, geometry, light, b1, b2):
    """The (textured) radiance an emissive-triangle light emits at the point of barycentric
    weights ``(b1, b2)`` (of its corners 1 and 2)."""
    face = np.int64(light[FACE])
    return emission_at(surface, geometry, geometry[5][face], face, b1, b2)


@inline_row
def face_tangents(geometry, instances, placement, prim):
    """A face's UV tangent and bitangent (:func:`rtmesh.rendering.surface_textures.face_tangents`,
    6 floats), carried to the world by the linear part of ``placement``'s transform (the
    kernel's ``instances`` record; -1: a face of the world-space scene)."""
    tb = geometry[8][prim]
    tx, ty, tz, bx, by, bz = tb[0], tb[1], tb[2], tb[3], tb[4], tb[5]
    if placement >= 0:
        m = instances[1][placement]
        tx, ty, tz = (m[0] * tx + m[1] * ty) + m[2] * tz, (m[3] * tx + m[4] * ty) + m[5] * tz, \
            (m[6] * tx + m[7] * ty) + m[8] * tz
        bx, by, bz = (m[0] * bx + m[1] * by) + m[2] * bz, (m[3] * bx + m[4] * by) + m[5] * bz, \
            (m[6] * bx + m[7] * by) + m[8] * bz
    return tx, ty, tz, bx, by, bz


@inline_row
def normal_mapped(surface, geometry, mat, prim, bu, bv, nx, ny, nz, instances, placement):
    """The shading normal (on the front side of the face) bent by the material's tangent-space
    normal map, as :meth:`rtmesh.rendering.surface_textures.SurfaceTextures.normal_mapped`
    (``instances``, ``placement``: :func:`face_tangents`)."""
    return normal_mapped_by(surface, geometry, surface[8][mat, NORMAL_TEXTURE], prim, bu, bv, nx, ny, nz, instances,
                            placement)


@inline_row
def normal_mapped_by(surface, geometry, t, prim, bu, bv, nx, ny, nz, instances, placement):
    """:func:`normal_mapped` by the normal map of atlas texture ``t`` (the base's, or a clear
    coat's)."""
    if t < 0 or not len(geometry[8]):
        return nx, ny, nz
    texels, descriptors = surface[13], surface[14]
    u, v = hit_uv(geometry, prim, bu, bv)
    lr, lg, lb, _ = texel(texels, descriptors, t, u, v)
    lx, ly, lz = 2.0 * lr - 1.0, 2.0 * lg - 1.0, 2.0 * lb - 1.0
    tx, ty, tz, bx, by, bz = face_tangents(geometry, instances, placement, prim)
    d = descriptors[t]
    a00, a01, a10, a11 = d[6], d[7], d[9], d[10]
    det = a00 * a11 - a01 * a10
    if (a00 != 1.0 or a01 != 0.0 or a10 != 0.0 or a11 != 1.0) and abs(det) >= 1e-20 \
            and (bx != 0.0 or by != 0.0 or bz != 0.0):
        # the image axes through the texture's UV transform (transformed_tangents)
        i00, i01, i10, i11 = a11 / det, -a01 / det, -a10 / det, a00 / det
        tx, ty, tz, bx, by, bz = (tx * i00 + bx * i10, ty * i00 + by * i10, tz * i00 + bz * i10,
                                  tx * i01 + bx * i11, ty * i01 + by * i11, tz * i01 + bz * i11)
    dn = (nx * tx + ny * ty) + nz * tz
    tx, ty, tz = tx - nx * dn, ty - ny * dn, tz - nz * dn
    length = math.sqrt((tx * tx + ty * ty) + tz * tz)
    if not length > 0.0:
        return nx, ny, nz
    tx, ty, tz = tx / length, ty / length, tz / length
    cx, cy, cz = ny * tz - nz * ty, nz * tx - nx * tz, nx * ty - ny * tx
    handed = -1.0 if (cx * bx + cy * by) + cz * bz < 0.0 else 1.0
    mx = lx * tx + handed * ly * cx + lz * nx
    my = lx * ty + handed * ly * cy + lz * ny
    mz = lx * tz + handed * ly * cz + lz * nz
    length2 = (mx * mx + my * my) + mz * mz
    if not length2 > 0.0:  # an unusable texel (zero vector) keeps the interpolated normal
        return nx, ny, nz
    inv = 1.0 / math.sqrt(length2)
    return mx * inv, my * inv, mz * inv


@inline_row
def textured_materials(surface, geometry):
    """Which materials' parameters vary over the surface (textures, vertex colours), (M,) bool:
    only their hits copy and scale a parameter row (the records' rows cost reference counting
    per call)."""
    tags, material_textures, slots = surface[0], surface[8], surface[7]
    textured = np.zeros(len(tags), np.bool_)
    for mat in range(len(tags)):
        # layered rows (KHR extensions) get their coat normal and anisotropy per hit too
        textured[mat] = len(geometry[7]) > 0 or (len(geometry[6]) > 0 and (material_textures[mat] >= 0).any()) \
            or slots[tags[mat], models.COAT_NORMAL_SLOT] >= 0
    return textured


@inline_row
def hit_parameters(surface, geometry, textured, mat, prim, bu, bv, scratch, lane, stack, media, entering):
    """A hit's BSDF parameters and emission: ``(table, row, er, eg, eb, in_scratch)``, the
    parameter row being the material's own, or (``in_scratch``) a copy in ``scratch[lane]``
    scaled by its textures and vertex colours (:func:`textured_row`), with a transmissive
    model's index ratio between the media on the interface's two sides
    (:func:`rtmesh.rendering.path_media.interface_ratio`; ``media`` the stack's depth, 0
    without transmissive materials; ``entering`` whether the ray meets the front)."""
    tags, params, transmissive, emission, slots, ior = surface[0], surface[1], surface[2], surface[3], surface[7], \
        surface[15]
    in_scratch = textured[mat]
    if in_scratch:
        er, eg, eb = textured_row(surface, geometry, mat, prim, bu, bv, scratch, lane)
        table, index = scratch, lane
    else:
        er, eg, eb = emission[mat, 0], emission[mat, 1], emission[mat, 2]
        table, index = params, mat
    slot = slots[tags[mat], models.IOR_SLOT]
    if media and transmissive[mat] and slot >= 0:
        if not in_scratch:
            for k in range(params.shape[1]):
                scratch[lane, k] = params[mat, k]
            table, index, in_scratch = scratch, lane, True
        scratch[lane, slot] = interface_ratio(stack, lane, mat, entering, ior, twin_material(surface, prim))
    return table, index, er, eg, eb, in_scratch


@inline_row
def shading_normals(surface, geometry, mat, prim, bu, bv, transmissive, gx, gy, gz, nx, ny, nz, ox, oy, oz, instances,
                    placement):
    """The geometric and shading normals a hit is shaded with, seen along ``o`` (unit,
    toward where the ray came from): the shading normal turned to the geometric normal's
    side and bent by a normal map; reflection-only models (``transmissive`` false) turn
    both to the viewer's side (and shade flat where a bent normal faces away from it),
    transmissive ones keep the outward side (then ``o`` below it means "inside").

    Returns
    -------
    gx, gy, gz, nx, ny, nz : float
    """
    if (nx * gx + ny * gy) + nz * gz < 0.0:
        nx, ny, nz = -nx, -ny, -nz
    if surface[8][mat, NORMAL_TEXTURE] >= 0:
        nx, ny, nz = normal_mapped(surface, geometry, mat, prim, bu, bv, nx, ny, nz, instances, placement)
    if not transmissive:
        if (gx * ox + gy * oy) + gz * oz < 0.0:
            gx, gy, gz, nx, ny, nz = -gx, -gy, -gz, -nx, -ny, -nz
        if not (nx * ox + ny * oy) + nz * oz > 0.0:
            # a bent shading normal facing away from the viewer: shade flat
            nx, ny, nz = gx, gy, gz
    return gx, gy, gz, nx, ny, nz


@inline_row
def hit_frame(surface, geometry, mat, prim, bu, bv, transmissive, scratch, lane, gx, gy, gz, nx, ny, nz, ox, oy,
              oz, instances, placement):
    """The hit's shading frame seen along ``o``: the normals of :func:`shading_normals` and
    the tangents of :func:`tangent_frame`; a layered row (``scratch[lane]``) gets its clear
    coat's normal and anisotropy direction in that frame (:func:`orient_layers`).  A hit on a
    placed mesh (``placement`` >= 0 in the ``instances`` record) takes its face's UV tangents
    carried to the world by the placement (:func:`face_tangents`).

    Returns
    -------
    gx, gy, gz, nx, ny, nz, tx, ty, tz, sx, sy, sz : float
    """
    # a clear coat's normal: the shading normal on the geometric front side, unbent by the
    # base's normal map
    cx, cy, cz = (nx, ny, nz) if (nx * gx + ny * gy) + nz * gz >= 0.0 else (-nx, -ny, -nz)
    gx, gy, gz, nx, ny, nz = shading_normals(surface, geometry, mat, prim, bu, bv, transmissive, gx, gy, gz, nx, ny,
                                             nz, ox, oy, oz, instances, placement)
    tx, ty, tz, sx, sy, sz = tangent_frame(nx, ny, nz)
    if surface[7][surface[0][mat], models.COAT_NORMAL_SLOT] >= 0:
        orient_layers(surface, geometry, mat, prim, bu, bv, scratch, lane, cx, cy, cz, gx, gy, gz, ox, oy, oz,
                      nx, ny, nz, tx, ty, tz, sx, sy, sz, instances, placement)
    return gx, gy, gz, nx, ny, nz, tx, ty, tz, sx, sy, sz


@inline_row
def to_world(wx, wy, wz, tx, ty, tz, sx, sy, sz, nx, ny, nz):
    """A local-frame direction (``z`` the shading normal ``n``, ``x`` and ``y`` the tangents
    ``t`` and ``s``) in world space, normalised."""
    dx = (wx * tx + wy * sx) + wz * nx
    dy = (wx * ty + wy * sy) + wz * ny
    dz = (wx * tz + wy * sz) + wz * nz
    length = math.sqrt((dx * dx + dy * dy) + dz * dz)
    return dx / length, dy / length, dz / length


@inline_row
def sampled_direction(wx, wy, wz, tx, ty, tz, sx, sy, sz, nx, ny, nz, gx, gy, gz, transmissive):
    """A BSDF sample's local direction ``w`` in world space (:func:`to_world`), its cosine
    with the geometric normal ``g``, and whether it is lost: a reflection-only model's
    sample below the geometric surface (the shading normal tilts the hemisphere).

    Returns
    -------
    dx, dy, dz, side : float
    below : bool
    """
    dx, dy, dz = to_world(wx, wy, wz, tx, ty, tz, sx, sy, sz, nx, ny, nz)
    side = (gx * dx + gy * dy) + gz * dz
    return dx, dy, dz, side, (not transmissive) and not side > 0.0


@inline_row
def leave_surface(hx, hy, hz, gx, gy, gz, wx, wy, wz, scale):
    """The origin of a ray that leaves the surface point ``h`` along ``w``: ``h`` moved off
    the side of the geometric normal ``g`` that ``w`` points to
    (:func:`rtmesh.geometry.float32_rays.offset_origin`), as float64 ``(x, y, z)``."""
    if (gx * wx + gy * wy) + gz * wz > 0.0:
        qx, qy, qz = offset_origin(hx, hy, hz, gx, gy, gz, wx, wy, wz, scale)
    else:
        qx, qy, qz = offset_origin(hx, hy, hz, -gx, -gy, -gz, wx, wy, wz, scale)
    return np.float64(qx), np.float64(qy), np.float64(qz)


@inline_row
def tangent_frame(nx, ny, nz):
    """Two unit tangents ``t, s`` completing the unit normal ``n`` to an orthonormal frame
    (Duff et al. 2017: no branch on the normal's direction but its sign)."""
    sign = 1.0 if nz >= 0.0 else -1.0
    fa = -1.0 / (sign + nz)
    fb = nx * ny * fa
    return 1.0 + sign * nx * nx * fa, sign * fb, -sign * nx, fb, sign + ny * ny * fa, -ny


@row
def _scale(textures, texels, descriptors, mat, column, channel, u, v, scratch, lane, s):
    """``scratch[lane, s] *=`` one channel of the material's texture in ``column`` (if any)."""
    t = textures[mat, column]
    if t >= 0 and s >= 0:
        scratch[lane, s] *= texel(texels, descriptors, t, u, v)[channel]


# layer_textures and orient_layers are rows the kernel calls, not inlined: only hits of
# layered materials pay for the call (reference counts of the arrays passed), and inlined
# they made the path kernel's first compile ~40 % longer
@row
def layer_textures(textures, texels, descriptors, mat, slot, u, v, scratch, lane):
    """The KHR layers' textures applied to a layered row (:mod:`rtmesh.materials.gltf_layered`):
    specular strength (alpha), specular colour (rgb), clear coat (red), clear-coat roughness
    (green), sheen colour (rgb), sheen roughness (alpha), anisotropy strength (blue; its
    direction in red-green is :func:`orient_layers`'), iridescence (red), film thickness
    (green: between the minimum and the maximum)."""
    _scale(textures, texels, descriptors, mat, SPECULAR_STRENGTH_TEXTURE, 3, u, v, scratch, lane,
           slot[models.SPECULAR_STRENGTH_SLOT])
    for c in range(3):
        _scale(textures, texels, descriptors, mat, SPECULAR_COLOUR_TEXTURE, c, u, v, scratch, lane,
               slot[models.SPECULAR_COLOUR_SLOT] + c)
        _scale(textures, texels, descriptors, mat, SHEEN_COLOUR_TEXTURE, c, u, v, scratch, lane,
               slot[models.SHEEN_COLOUR_SLOT] + c)
    _scale(textures, texels, descriptors, mat, CLEARCOAT_TEXTURE, 0, u, v, scratch, lane, slot[models.CLEARCOAT_SLOT])
    _scale(textures, texels, descriptors, mat, CLEARCOAT_ROUGHNESS_TEXTURE, 1, u, v, scratch, lane,
           slot[models.CLEARCOAT_ROUGHNESS_SLOT])
    _scale(textures, texels, descriptors, mat, SHEEN_ROUGHNESS_TEXTURE, 3, u, v, scratch, lane,
           slot[models.SHEEN_ROUGHNESS_SLOT])
    _scale(textures, texels, descriptors, mat, ANISOTROPY_TEXTURE, 2, u, v, scratch, lane, slot[models.ANISOTROPY_SLOT])
    _scale(textures, texels, descriptors, mat, IRIDESCENCE_TEXTURE, 0, u, v, scratch, lane,
           slot[models.IRIDESCENCE_SLOT])
    t = textures[mat, IRIDESCENCE_THICKNESS_TEXTURE]
    s = slot[models.IRIDESCENCE_THICKNESS_SLOT]
    if t >= 0 and s >= 0:
        # the row keeps the maximum at s and the minimum at s + 1 (gltf_layered.THICKNESS_MIN_AT)
        g = texel(texels, descriptors, t, u, v)[1]
        scratch[lane, s] = scratch[lane, s + 1] + (scratch[lane, s] - scratch[lane, s + 1]) * g


@row
def orient_layers(surface, geometry, mat, prim, bu, bv, scratch, lane, cx, cy, cz, gx, gy, gz, ox, oy, oz,
                  nx, ny, nz, tx, ty, tz, sx, sy, sz, instances, placement):
    """Write a layered row's clear-coat normal and anisotropy direction in the hit's local
    frame (``t, s, n``) into ``scratch[lane]``.

    ``c`` is the shading normal before the base's normal map, on the geometric front side:
    the clear coat's own normal map bends it (the specification: the coat does not share the
    base's normal map), then it is turned to the viewer's side with the frame (``g``, the
    frame's geometric normal), or replaced by ``n`` where it faces away from the viewer.  The
    anisotropy direction is ``anisotropyRotation`` (and the anisotropy texture's red-green
    direction) from the UV tangent, projected onto the local tangent plane; without UV
    tangents, the local frame's first axis.
    """
    slot = surface[7][surface[0][mat]]
    at = slot[models.COAT_NORMAL_SLOT]
    textures = surface[8]
    if scratch[lane, slot[models.CLEARCOAT_SLOT]] > 0.0:
        if textures[mat, CLEARCOAT_NORMAL_TEXTURE] >= 0:
            cx, cy, cz = normal_mapped_by(surface, geometry, textures[mat, CLEARCOAT_NORMAL_TEXTURE], prim, bu, bv,
                                          cx, cy, cz, instances, placement)
        if (cx * gx + cy * gy) + cz * gz < 0.0:
            cx, cy, cz = -cx, -cy, -cz
        if not (cx * ox + cy * oy) + cz * oz > 0.0:
            cx, cy, cz = nx, ny, nz
        scratch[lane, at] = (tx * cx + ty * cy) + tz * cz
        scratch[lane, at + 1] = (sx * cx + sy * cy) + sz * cz
        scratch[lane, at + 2] = (nx * cx + ny * cy) + nz * cz
    a = slot[models.ANISOTROPY_SLOT]
    tangents = geometry[8]
    if scratch[lane, a] > 0.0 and len(tangents):
        # the direction in the tangent plane of the UVs: (cos, sin) of the rotation, turned by
        # the texture's direction (red-green in [-1, 1]) when there is one
        angle = scratch[lane, a + 3]
        dx, dy = math.cos(angle), math.sin(angle)
        t = textures[mat, ANISOTROPY_TEXTURE]
        if t >= 0 and len(geometry[6]):
            u, v = hit_uv(geometry, prim, bu, bv)
            r, g, _, _ = texel(surface[13], surface[14], t, u, v)
            px, py = 2.0 * r - 1.0, 2.0 * g - 1.0
            dx, dy = px * dx - py * dy, px * dy + py * dx
        ux, uy, uz, vx, vy, vz = face_tangents(geometry, instances, placement, prim)
        wx = dx * ux + dy * vx
        wy = dx * uy + dy * vy
        wz = dx * uz + dy * vz
        lx = (tx * wx + ty * wy) + tz * wz
        ly = (sx * wx + sy * wy) + sz * wz
        if (lx != 0.0) | (ly != 0.0):
            scratch[lane, a + 1] = lx
            scratch[lane, a + 2] = ly
