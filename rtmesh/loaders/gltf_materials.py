"""Materials of glTF files: the metallic-roughness model and its extensions mapped onto
rtmesh's :class:`~rtmesh.materials.table.Material`.

The glTF table of docs/MATERIALS.md describes the mapping; the functions here are its only
implementation.  glTF materials come from trimesh's ``PBRMaterial`` (with the images it
decoded) plus the extensions of the file's JSON, which trimesh does not keep.  MTL
materials are in :mod:`rtmesh.loaders.mtl_materials`.
"""


import logging

import numpy as np

from rtmesh.core.errors import MeshError
from rtmesh.io.texture_images import Texture
from rtmesh.materials.gltf_layered import Layers
from rtmesh.materials.table import Material

log = logging.getLogger(__name__)


def _factor(value, default):
    """A glTF factor as a float64 array; trimesh's 8-bit colours rescaled to [0, 1]."""
    if value is None:
        return np.asarray(default, dtype=np.float64)
    raw = np.asarray(value)
    return raw.astype(np.float64) / 255.0 if raw.dtype.kind in "ui" else raw.astype(np.float64)


def _gltf_factors(pbr, doc):
    """The factors of a material: from the file's JSON when known (full precision), else
    from trimesh's ``PBRMaterial`` (which keeps the base colour in 8 bits)."""
    doc = doc or {}
    mr = doc.get("pbrMetallicRoughness", {}) or {}

    def pick(json_value, trimesh_value, default):
        if json_value is not None:  # JSON numbers are factors in [0, 1], integers included
            return np.asarray(json_value, dtype=np.float64)
        return _factor(trimesh_value, default)

    return dict(
        base=pick(mr.get("baseColorFactor"), pbr.baseColorFactor, [1.0, 1.0, 1.0, 1.0]),
        metallic=float(pick(mr.get("metallicFactor"), pbr.metallicFactor, 1.0)),
        roughness=float(pick(mr.get("roughnessFactor"), pbr.roughnessFactor, 1.0)),
        emission=pick(doc.get("emissiveFactor"), pbr.emissiveFactor, [0.0, 0.0, 0.0])[:3],
        mode=str(doc.get("alphaMode") or pbr.alphaMode or "OPAQUE").lower(),
        cutoff=float(pick(doc.get("alphaCutoff"), pbr.alphaCutoff, 0.5)),
        double_sided=bool(doc.get("doubleSided", pbr.doubleSided)),
        extensions=doc.get("extensions", {}) or {},
    )


def gltf_material(pbr, json_material=None, name="gltf", source=None):
    """A glTF metallic-roughness material as rtmesh's :class:`~rtmesh.materials.table.Material`
    (see docs/MATERIALS.md).

    Lit materials keep the model the format defines: ``model="metallic_roughness"`` with
    the base colour, metallic and roughness factors and the base-colour,
    metallic-roughness, occlusion, normal and emissive textures, evaluated per texel
    (:mod:`rtmesh.materials.metallic_roughness`).  Alpha mode, cutoff and base-colour
    alpha give the opacity; KHR_materials_emissive_strength scales the emission;
    KHR_materials_transmission / ior / volume make part of the dielectric's diffuse term a
    smooth refraction into an absorbing interior (:func:`_transmission`).
    KHR_materials_unlit shows the base colour without lighting.  KHR_materials_specular,
    _clearcoat, _sheen, _anisotropy and _iridescence (:func:`khr_layers`) make the model
    ``gltf_layered`` (:mod:`rtmesh.materials.gltf_layered`).

    Parameters
    ----------
    pbr : trimesh.visual.material.PBRMaterial
    json_material : dict, optional
        The material's object in the file's JSON: its factors (full precision) and its
        ``extensions``, which trimesh does not keep.
    name : str
        Used when the material has no name.
    source : str, optional
        The file, for warnings about unusable values.

    Returns
    -------
    Material
    """
    _check_decoded(pbr, json_material, pbr.name or name, source)
    where = f"{source}: material '{pbr.name or name}'" if source else f"material '{pbr.name or name}'"
    f = _gltf_factors(pbr, json_material)
    ext = f["extensions"]
    base = _rgba(f["base"])
    colour = base[:3]

    def texture(role, srgb):
        return _gltf_texture(pbr, json_material, role, srgb, name)

    emission = _emission(f, where)
    common = dict(
        name=pbr.name or name,
        emission=emission,
        opacity=float(base[3]),
        alpha_mode=f["mode"] if f["mode"] in ("mask", "blend") else "opaque",
        alpha_cutoff=f["cutoff"],
        double_sided=f["double_sided"],
        diffuse_texture=texture("baseColorTexture", True),
        emission_texture=texture("emissiveTexture", True) if (emission > 0).any() else None,  # factor x texture
    )
    if "KHR_materials_unlit" in ext:
        # the base colour as is: metallic and roughness do not apply
        return Material(diffuse=colour, unlit=True, **common)
    metallic, roughness = float(np.clip(f["metallic"], 0, 1)), float(np.clip(f["roughness"], 0, 1))
    factor, ior, absorption = _transmission(ext, where)
    occlusion = (json_material or {}).get("occlusionTexture") or {}
    layers = khr_layers(ext, where, json_material, name)
    return Material(
        # the KHR layers' model only where a material uses one: plain materials keep the
        # metallic-roughness rows (their speed, their images bit for bit)
        model="gltf_layered" if layers is not None else "metallic_roughness",
        layers=layers,
        base_color=colour,
        metallic=metallic,
        perceptual_roughness=roughness,
        # kept for the ambient term and the albedo pass (see Material.model)
        diffuse=colour * (1.0 - metallic) * (1.0 - factor),
        specular=np.zeros(3),
        transmission=factor * colour * (1.0 - metallic),
        transmission_factor=factor,
        ior=ior,
        absorption=absorption,
        # glTF: roughness in green, metalness in blue, occlusion in red, all linear
        metallic_roughness_texture=texture("metallicRoughnessTexture", False),
        occlusion_texture=texture("occlusionTexture", False),
        occlusion_strength=float(occlusion.get("strength", 1.0)),
        normal_texture=texture("normalTexture", False),
        **common,
    )


# KHR layer extensions: per extension, its number keys (default, low, high), its colour keys
# (default, low, high) and its textures (role, sRGB); the specifications' defaults and ranges
LAYER_EXTENSIONS = {
    "KHR_materials_specular": (
        {"specularFactor": (1.0, 0.0, 1.0)}, {"specularColorFactor": ((1.0, 1.0, 1.0), 0.0, np.inf)},
        (("specularTexture", False), ("specularColorTexture", True))),
    "KHR_materials_clearcoat": (
        {"clearcoatFactor": (0.0, 0.0, 1.0), "clearcoatRoughnessFactor": (0.0, 0.0, 1.0)}, {},
        (("clearcoatTexture", False), ("clearcoatRoughnessTexture", False), ("clearcoatNormalTexture", False))),
    "KHR_materials_sheen": (
        {"sheenRoughnessFactor": (0.0, 0.0, 1.0)}, {"sheenColorFactor": ((0.0, 0.0, 0.0), 0.0, 1.0)},
        (("sheenColorTexture", True), ("sheenRoughnessTexture", False))),
    "KHR_materials_anisotropy": (
        {"anisotropyStrength": (0.0, 0.0, 1.0), "anisotropyRotation": (0.0, -np.inf, np.inf)}, {},
        (("anisotropyTexture", False),)),
    "KHR_materials_iridescence": (
        {"iridescenceFactor": (0.0, 0.0, 1.0), "iridescenceIor": (1.3, 1.0, np.inf),
         "iridescenceThicknessMinimum": (100.0, 0.0, np.inf), "iridescenceThicknessMaximum": (400.0, 0.0, np.inf)},
        {}, (("iridescenceTexture", False), ("iridescenceThicknessTexture", False))),
}
# the texture roles of the layer extensions, and whether each is sRGB
LAYER_TEXTURE_ROLES = {role: (extension, srgb) for extension, (_, _, roles) in LAYER_EXTENSIONS.items()
                       for role, srgb in roles}
# where gltf_json_materials puts a material's decoded layer images ({role: PIL image})
LAYER_TEXTURES_KEY = "rtmesh:layer images"


def _layer_value(table, extension, key, default, low, high, where):
    """One factor of a layer extension: the default when absent, else finite numbers in
    [low, high] (a number, or three for a colour); MeshError otherwise (one line)."""
    value = table.get(key, default)
    count = 1 if np.ndim(default) == 0 else len(default)
    try:
        numbers = _numbers(value, count, f"{extension} {key}")
    except ValueError as exc:
        raise MeshError(f"{where}: {exc}") from None
    if (numbers < low).any() or (numbers > high).any():
        bounds = f"[{low}, {high}]" if np.isfinite(high) else f">= {low}"
        raise MeshError(f"{where}: {extension} {key} {value!r} is out of range (expected {bounds})")
    return float(numbers[0]) if count == 1 else numbers


def khr_layers(ext, where, json_material=None, name="gltf"):
    """The KHR layer extensions of a glTF material as :class:`~rtmesh.materials.gltf_layered.Layers`.

    Parameters
    ----------
    ext : dict
        The material's ``extensions``.
    where : str
        The file and material, for messages.
    json_material : dict, optional
        The material's object of :func:`gltf_json_materials`: the decoded images of the
        layers' textures by role (:data:`LAYER_TEXTURES_KEY`) and their wrap modes and
        transforms (:func:`texture_options`).
    name : str
        For the textures' names.

    Returns
    -------
    Layers or None
        None when the material uses none of :data:`LAYER_EXTENSIONS`.

    Raises
    ------
    MeshError
        A factor is not a number (or three), or is outside the specification's range.
    """
    used = [extension for extension in LAYER_EXTENSIONS if extension in ext]
    if not used:
        return None
    values, textures = {}, {}
    images = (json_material or {}).get(LAYER_TEXTURES_KEY, {})
    for extension in used:
        table = ext[extension]
        if not isinstance(table, dict):
            raise MeshError(f"{where}: {extension} is not an object")
        numbers, colours, roles = LAYER_EXTENSIONS[extension]
        for key, (default, low, high) in {**numbers, **colours}.items():
            values[key] = _layer_value(table, extension, key, default, low, high, where)
        for role, srgb in roles:
            if images.get(role) is not None:
                textures[role] = Texture.from_pil(images[role], srgb=srgb, name=f"{name} {role}",
                                                  **texture_options(json_material, role))
    # the defaults of the extensions a material does not use
    for extension, (numbers, colours, _) in LAYER_EXTENSIONS.items():
        for key, (default, _, _) in {**numbers, **colours}.items():
            values.setdefault(key, np.asarray(default, dtype=np.float64) if np.ndim(default) else float(default))
    return Layers(
        specular=values["specularFactor"], specular_colour=values["specularColorFactor"],
        clearcoat=values["clearcoatFactor"], clearcoat_roughness=values["clearcoatRoughnessFactor"],
        sheen_colour=values["sheenColorFactor"], sheen_roughness=values["sheenRoughnessFactor"],
        anisotropy=values["anisotropyStrength"], anisotropy_rotation=values["anisotropyRotation"],
        iridescence=values["iridescenceFactor"], iridescence_ior=values["iridescenceIor"],
        thickness_min=values["iridescenceThicknessMinimum"], thickness_max=values["iridescenceThicknessMaximum"],
        textures=textures, extensions=tuple(used))


def _transmission(ext, name):
    """KHR_materials_transmission / ior / volume of a material's extensions.

    Parameters
    ----------
    ext : dict
        The material's ``extensions``.
    name : str
        The file and material, for warnings.

    Returns
    -------
    factor : float
        ``transmissionFactor`` in [0, 1] (0 without the extension).
    ior : float
        ``KHR_materials_ior`` (1.5 by default, as the extension says); at least 1.
    absorption : (3,) float
        ``-ln(attenuationColor) / attenuationDistance`` per scene unit (0 without a finite
        positive distance).
    """
    factor = _extension_number(ext, "KHR_materials_transmission", "transmissionFactor", 0.0, name, 0.0, 1.0)
    # an index below 1 (or 0, which the extension reserves for "infinite") is not a
    # dielectric this model can refract through: 1.5, the extension's default
    ior = _extension_number(ext, "KHR_materials_ior", "ior", 1.5, name, 1.0, np.inf, invalid_below=1.0)
    absorption = np.zeros(3)
    distance = _extension_number(ext, "KHR_materials_volume", "attenuationDistance", np.inf, name, 0.0, np.inf)
    if factor > 0 and np.isfinite(distance) and distance > 0:
        try:
            tint = np.asarray(ext["KHR_materials_volume"].get("attenuationColor", [1.0, 1.0, 1.0]), dtype=np.float64)
            tint = np.clip(np.nan_to_num(tint.reshape(3), nan=1.0), 1e-6, 1.0)
        except (TypeError, ValueError):
            log.warning("%s: KHR_materials_volume attenuationColor is not three numbers; not used", name)
            tint = np.ones(3)
        absorption = -np.log(tint) / distance
    return factor, ior, absorption


def _extension_number(ext, extension, key, default, name, low, high, invalid_below=None):
    """``ext[extension][key]`` as a float clipped to [low, high]; ``default`` (with a warning
    naming the material, extension and key) when it is not a finite number, or is below
    ``invalid_below``."""
    table = ext.get(extension)
    value = table.get(key, default) if isinstance(table, dict) else default
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = np.nan
    if np.isnan(number) or (np.isinf(number) and number != default) or (
            invalid_below is not None and number < invalid_below):
        log.warning("%s: %s %s = %r is not usable; %s used", name, extension, key, value, default)
        return float(default)
    return float(np.clip(number, low, high))


def _gltf_texture(pbr, json_material, role, srgb, name):
    """The :class:`Texture` of one texture role (``"baseColorTexture"``, ...) of a glTF
    material, with its sampler's wrap modes and its KHR_texture_transform; None when the
    material has none."""
    image = getattr(pbr, role)
    if image is None:
        return None
    return Texture.from_pil(image, srgb=srgb, name=f"{name} {role}", **texture_options(json_material, role))


def _rgba(base):
    """A glTF base colour factor as RGBA (alpha 1 when the factor has three values)."""
    return np.append(base, 1.0) if len(base) == 3 else np.resize(base, 4)


def _emission(factors, name):
    """Emitted radiance: ``emissiveFactor`` (clipped to [0, 1], as the specification bounds
    it) times KHR_materials_emissive_strength (finite, >= 0)."""
    strength = _extension_number(factors["extensions"], "KHR_materials_emissive_strength", "emissiveStrength", 1.0,
                                 name, 0.0, float(np.finfo(np.float32).max))
    return np.clip(np.nan_to_num(factors["emission"], nan=0.0), 0.0, 1.0) * strength


# glTF sampler wrap modes (the OpenGL enums) as Texture wrap modes; glTF's default is REPEAT
_GLTF_WRAP = {33071: "clamp", 33648: "mirror", 10497: "repeat"}
# the texture roles of a glTF material, each a textureInfo ("pbr." ones under pbrMetallicRoughness)
TEXTURE_ROLES = ("baseColorTexture", "metallicRoughnessTexture", "normalTexture", "occlusionTexture",
                 "emissiveTexture")
_PBR_ROLES = ("baseColorTexture", "metallicRoughnessTexture")
# where gltf_json_materials puts, per texture role of a material object, the keyword
# arguments of Texture.from_pil that the file's JSON holds and trimesh drops: the sampler's
# wrap modes and the KHR_texture_transform (see texture_options)
OPTIONS_KEY = "rtmesh:texture options"
# ... and each texture's image (label, mime type), to tell images trimesh could not decode
IMAGES_KEY = "rtmesh:images"
# the extension's name, in textureInfo.extensions and in the file's extensionsRequired
TEXTURE_TRANSFORM = "KHR_texture_transform"


def _texture_wrap(doc, texture_info):
    """(wrap_u, wrap_v) of a glTF textureInfo through its texture's sampler."""
    try:
        texture = doc["textures"][texture_info["index"]]
        sampler = doc["samplers"][texture["sampler"]] if "sampler" in texture else {}
    except (KeyError, IndexError, TypeError):
        return ("repeat", "repeat")
    return tuple(_GLTF_WRAP.get(sampler.get(axis, 10497), "repeat") for axis in ("wrapS", "wrapT"))


def _numbers(value, count, what):
    """``count`` finite floats from a JSON number (count 1) or array; ValueError naming
    ``what`` otherwise."""
    values = [value] if count == 1 else value
    if (not isinstance(values, (list, tuple)) or len(values) != count
            or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in values)
            or not np.isfinite(np.asarray(values, dtype=np.float64)).all()):
        raise ValueError(f"{what} {value!r} (expected {'a number' if count == 1 else f'{count} numbers'})")
    return np.asarray(values, dtype=np.float64)


def khr_texture_transform(extension):
    """The UV transform of a KHR_texture_transform object, in :class:`Texture`'s convention.

    The extension maps glTF UVs (origin at the top left of the image, v down) by
    ``T(offset) R(rotation) S(scale)`` with ``R = [[cos, sin], [-sin, cos]]`` acting on
    column vectors: the spec's sample code read row by row (GLSL's ``mat3()`` fills columns,
    which would give the transpose), and the direction its worked example needs ("the lower
    left quadrant of the source image, rotated clockwise 90 degrees"); counter-clockwise as
    the image is seen, since v points down.  trimesh flips v on import and :class:`Texture`
    reads v upward, so the map ``M`` is conjugated by the flip ``F(u, v) = (u, 1 - v)``: the
    lookup reads ``F(M(F(uv)))``, i.e. ``A' = D A D``, ``b' = D (A e + offset) + e`` with
    ``A = R S``, ``D = diag(1, -1)``, ``e = (0, 1)``.

    Parameters
    ----------
    extension : dict
        ``offset`` (default [0, 0]), ``rotation`` (radians, default 0) and ``scale``
        (default [1, 1]); ``texCoord`` is not read here (see :func:`gltf_json_materials`).

    Returns
    -------
    (2, 3) float64 or None
        ``[A' | b']`` for :class:`Texture`'s ``transform``; None for the identity.

    Raises
    ------
    ValueError
        A value is not a finite number or pair of numbers (the message names it).
    """
    if not isinstance(extension, dict):
        raise ValueError(f"{extension!r} (expected an object)")
    ox, oy = _numbers(extension.get("offset", [0.0, 0.0]), 2, "offset")
    (angle,) = _numbers(extension.get("rotation", 0.0), 1, "rotation")
    sx, sy = _numbers(extension.get("scale", [1.0, 1.0]), 2, "scale")
    c, s = np.cos(angle), np.sin(angle)
    a = np.array([[c * sx, s * sy], [-s * sx, c * sy]])  # R S, in glTF's UV space
    matrix = np.array([[a[0, 0], -a[0, 1], ox + a[0, 1]],
                       [-a[1, 0], a[1, 1], 1.0 - a[1, 1] - oy]])
    return None if np.array_equal(matrix, [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]) else matrix


def _texture_options(doc, info):
    """:func:`texture_options` of one glTF textureInfo, its texture-coordinate set (the
    extension's ``texCoord`` overrides the textureInfo's) and the malformed transform, if
    any (then the transform is ignored)."""
    options = {"wrap": _texture_wrap(doc, info), "transform": None}
    extensions = info.get("extensions")
    extension = extensions.get(TEXTURE_TRANSFORM) if isinstance(extensions, dict) else None
    coord, problem = info.get("texCoord", 0), None
    if extension is not None:
        try:
            options["transform"] = khr_texture_transform(extension)
        except ValueError as exc:
            problem = str(exc)
        if isinstance(extension, dict):
            coord = extension.get("texCoord", coord)
    return options, coord, problem


def texture_options(json_material, role):
    """The keyword arguments of :meth:`Texture.from_pil` that a glTF material's JSON gives
    one of its textures: ``wrap`` (the sampler's, default repeat) and ``transform``
    (KHR_texture_transform, None for none).

    Parameters
    ----------
    json_material : dict or None
        A material object of :func:`gltf_json_materials` (None: no JSON known).
    role : str
        One of :data:`TEXTURE_ROLES`, e.g. ``"baseColorTexture"``.

    Returns
    -------
    dict
        A new dict, ``Texture.from_pil(image, ..., **texture_options(json_material, role))``.
    """
    options = (json_material or {}).get(OPTIONS_KEY, {}).get(role)
    return dict(options) if options else {"wrap": "repeat", "transform": None}


def _texture_image(doc, texture_info):
    """(label, mime type) of the image a glTF textureInfo shows: its name, URI or index."""
    try:
        texture = doc["textures"][texture_info["index"]]
        # KHR_texture_basisu: the KTX2 image in the extension, a PNG or JPEG fallback (which
        # trimesh reads) in "source" where the file has one
        basisu = (texture.get("extensions") or {}).get(BASISU) or {}
        source = texture.get("source", basisu.get("source"))
        image = doc["images"][source]
        label = image.get("name") or image.get("uri", "")[:60] or f"image {source}"
        mime = image.get("mimeType", "")
        if "source" in basisu and source == basisu["source"] or str(image.get("uri", "")).lower().endswith(".ktx2"):
            mime = "image/ktx2"
        return label, mime
    except (KeyError, IndexError, TypeError, AttributeError):
        return "an image", ""


BASISU = "KHR_texture_basisu"


# images above PIL's decompression-bomb limit (89478485 pixels) are dropped by trimesh
# like corrupt ones; smaller ones above rtmesh.io.texture_images.MAX_TEXTURE_PIXELS are refused
# by name when their texture is made
PIL_LIMIT = 89478485


def _check_decoded(pbr, json_material, name, source=None):
    """Raise MeshError for a texture the file's JSON gives a material but trimesh could not
    decode (it drops such an image without a word): a corrupt texture is an error, as for
    MTL files (docs/MATERIALS.md).  KTX2 images (KHR_texture_basisu) without a fallback
    image are one warning a material naming them: rtmesh does not decode them (libktx's
    Python interface, pyktx, has no wheel to install), and the material's factors are used
    without them (docs/ASSETS.md)."""
    images = (json_material or {}).get(IMAGES_KEY, {})
    ktx2 = []
    for slot, (label, mime) in images.items():
        if getattr(pbr, slot, None) is not None:
            continue
        if mime == "image/ktx2":
            ktx2.append(f"{slot} '{label}'")
            continue
        raise MeshError(f"{label}: corrupt or unreadable texture, or one of more than {PIL_LIMIT} "
                        f"pixels ({slot} of material '{name}')")
    if ktx2:
        log.warning("%smaterial '%s': %s %s a KTX2 image (%s), which rtmesh does not decode; the "
                    "material's factors are used without %s", f"{source}: " if source else "", name,
                    ", ".join(ktx2), "is" if len(ktx2) == 1 else "are", BASISU, "it" if len(ktx2) == 1 else "them")


def gltf_json_materials(doc, source="glTF", images=None):
    """``{material name: material object}`` of a glTF JSON document (unnamed ones skipped).

    Each object is a copy with, under :data:`OPTIONS_KEY`, per texture role of
    :data:`TEXTURE_ROLES` it has, the keyword arguments of :meth:`Texture.from_pil` that
    trimesh drops: the sampler's wrap modes and the KHR_texture_transform
    (``{"baseColorTexture": {"wrap": (u, v), "transform": (2, 3) array or None}, ...}``,
    read with :func:`texture_options`); and the image of each of those textures under
    :data:`IMAGES_KEY`
    (``{"baseColorTexture": (label, mime type), ...}``), to tell an image trimesh could not
    decode.

    A texture that reads a texture-coordinate set other than 0 (``texCoord``, or the
    extension's override) uses set 0: trimesh loads TEXCOORD_0 only.  That, and a malformed
    KHR_texture_transform (ignored), is one warning for the file, naming the materials.
    KHR_texture_transform may be in the file's ``extensionsRequired``: it is read.

    The textures of the KHR layer extensions (:data:`LAYER_TEXTURE_ROLES`, inside the
    material's ``extensions``) get options likewise, and their images, decoded by
    ``images``, under :data:`LAYER_TEXTURES_KEY` (``{"clearcoatTexture": PIL image, ...}``).

    Parameters
    ----------
    doc : dict
        The file's JSON.
    source : str
        The file, for messages.
    images : rtmesh.loaders.gltf_images.GltfImages, optional
        Decodes the layer textures' images (None: they are not read).

    Returns
    -------
    dict of str to dict
    """
    out, other_sets, malformed = {}, [], []
    for material in doc.get("materials", []) or []:
        if isinstance(material, dict) and isinstance(material.get("name"), str):
            pbr = material.get("pbrMetallicRoughness") or {}
            infos = {role: (pbr if role in _PBR_ROLES else material).get(role) for role in TEXTURE_ROLES}
            infos = {role: info for role, info in infos.items() if isinstance(info, dict)}
            core = set(infos)
            extensions = material.get("extensions") if isinstance(material.get("extensions"), dict) else {}
            for role, (extension, _) in LAYER_TEXTURE_ROLES.items():
                info = extensions.get(extension, {}).get(role) if isinstance(extensions.get(extension), dict) else None
                if isinstance(info, dict):
                    infos[role] = info
            options = {}
            for role, info in infos.items():
                options[role], coord, problem = _texture_options(doc, info)
                where = f"material '{material['name']}' {role}"
                if coord != 0:
                    other_sets.append(f"{where} (set {coord!r})")
                if problem:
                    malformed.append(f"{where}: {problem}")
            labels = {role: _texture_image(doc, info) for role, info in infos.items() if role in core}
            layer_images = {role: _layer_image(doc, info, images, f"material '{material['name']}' {role}")
                            for role, info in infos.items() if role not in core and images is not None}
            out[material["name"]] = {**material, OPTIONS_KEY: options, IMAGES_KEY: labels,
                                     LAYER_TEXTURES_KEY: layer_images}
    if other_sets:
        log.warning("%s: texture coordinate sets other than 0 are not read (trimesh loads "
                    "TEXCOORD_0 only); set 0 used for %s", source, _listed(other_sets))
    if malformed:
        log.warning("%s: malformed %s ignored (texture shown untransformed): %s", source,
                    TEXTURE_TRANSFORM, _listed(malformed))
    return out


def _layer_image(doc, info, images, label):
    """The decoded image of a layer texture's textureInfo (MeshError naming it otherwise)."""
    try:
        source = doc["textures"][info["index"]]["source"]
    except (KeyError, IndexError, TypeError):
        raise MeshError(f"{images.path}: {label}: texture {info.get('index')!r} is missing or has no image") from None
    return images.image(source, label)


def _listed(items, shown=4):
    """The first ``shown`` of ``items`` joined by "; ", then how many more."""
    more = f"; and {len(items) - shown} more" if len(items) > shown else ""
    return "; ".join(items[:shown]) + more
