"""Materials of OBJ files: MTL statements mapped onto rtmesh's
:class:`~rtmesh.materials.table.Material`.

The MTL table of docs/MATERIALS.md describes the mapping; the functions here are its only
implementation.  MTL files are read here: trimesh keeps only ``map_Kd`` of the texture maps
and drops a texture it cannot find without a word.  glTF materials are in
:mod:`rtmesh.loaders.gltf_materials`.
"""


import logging
import os
import re

import numpy as np

from rtmesh.io.texture_images import load_texture
from rtmesh.materials.table import Material

log = logging.getLogger(__name__)

# ---------------------------------------------------------------- OBJ / MTL

# illum models of the MTL specification -> (lit, specular, mirror, transmissive)
ILLUM = {
    0: (False, False, False, False),  # colour on, lighting off: Kd shown as is (unlit)
    1: (True, False, False, False),  # diffuse only
    2: (True, True, False, False),  # Blinn-Phong
    3: (True, True, True, False),  # + ray-traced reflection (Ks)
    4: (True, True, True, True),  # glass: reflection + transparency (1 - d)
    5: (True, True, True, False),  # reflection with Fresnel (treated as mirror Ks)
    6: (True, True, True, True),  # reflection + refraction (Ni)
    7: (True, True, True, True),  # reflection + refraction with Fresnel
    8: (True, True, True, False),  # reflection, not ray traced (treated as 3)
    9: (True, True, True, True),  # glass, not ray traced (treated as 4)
    10: (True, True, False, False),  # shadow matte (treated as 2)
}
# texture-map options and how many values follow each (the MTL specification's list)
_MAP_OPTIONS = {"-blendu": 1, "-blendv": 1, "-bm": 1, "-boost": 1, "-cc": 1, "-clamp": 1,
                "-imfchan": 1, "-mm": 2, "-o": 3, "-s": 3, "-t": 3, "-texres": 1}
_MTLLIB = re.compile(rb"^[ \t]*mtllib[ \t]+(.+?)[ \t]*$", re.M)
# a face statement with fewer than three vertex references
_SHORT_FACE = re.compile(rb"^[ \t]*f(?:[ \t]+\S+){0,2}[ \t]*$", re.M)
# a vertex statement with NaN among its colour values (after x y z)
_NAN_COLOUR = re.compile(rb"^[ \t]*v(?:[ \t]+\S+){3}[ \t]+[^\n]*\bnan\b", re.M | re.I)


def scan_obj(path):
    """What trimesh does not report about an OBJ file: its material libraries and defects.

    Parameters
    ----------
    path : str

    Returns
    -------
    mtl_paths : list of str
        The ``mtllib`` files, resolved against the OBJ's folder (missing ones included).
    short_faces : int
        Face statements with fewer than three vertices (trimesh drops them silently).
    nan_colours : int
        Vertex statements with NaN among their colour values (trimesh turns a NaN colour
        into black).  NaN coordinates are counted where their faces are dropped
        (:func:`rtmesh.loaders.mesh_processing.process`).
    """
    with open(path, "rb") as f:
        text = f.read()
    folder = os.path.dirname(os.path.abspath(path))
    mtl_paths = [os.path.join(folder, m.decode("utf-8", "replace").strip()) for m in _MTLLIB.findall(text)]
    return mtl_paths, len(_SHORT_FACE.findall(text)), len(_NAN_COLOUR.findall(text))


def parse_mtl(path):
    """The materials of an MTL file as raw statements.

    Parameters
    ----------
    path : str

    Returns
    -------
    dict of str to dict of str to str
        Material name -> lower-case keyword -> the rest of its line (the last statement of
        a keyword wins); under :data:`LINES`, keyword -> its line number (for messages).
    """
    materials, current = {}, None
    with open(path, "r", encoding="utf-8", errors="replace") as f:
        for number, line in enumerate(f, start=1):
            line = line.split("#", 1)[0].strip()
            if not line:
                continue
            key, _, rest = line.partition(" ") if " " in line else line.partition("\t")
            key, rest = key.lower(), rest.strip()
            if key == "newmtl":
                current = materials.setdefault(rest, {})
            elif current is not None:
                current[key] = rest
                current.setdefault(LINES, {})[key] = number
    return materials


# where parse_mtl keeps the line number of each statement (no keyword holds a '#')
LINES = "#lines"
# what each numeric MTL statement must hold beyond finite numbers: (test, what it expects)
_RANGES = {
    "ni": (lambda v: v > 0.0, "a number > 0"),
    "illum": (lambda v: v == int(v) and int(v) in ILLUM, "an illumination model from 0 to 10"),
}


def _floats(statements, key, count, problems=None):
    """A float (count 1) or colour statement, or None if absent or malformed.

    A malformed statement (not finite numbers, a colour below 0, a value out of
    :data:`_RANGES`) is appended to ``problems`` as ``(line, keyword, text, expected)``.
    """
    text = statements.get(key)
    if text is None:
        return None
    expected = "numbers" if count > 1 else "a number"
    try:
        values = np.array([float(x) for x in text.split()[:count]], dtype=np.float64)
        ok = len(values) > 0 and np.isfinite(values).all()
    except ValueError:
        ok = False
    if ok and count > 1:
        expected = "numbers >= 0"
        ok = bool((values >= 0.0).all())
    elif ok and key in _RANGES:
        test, expected = _RANGES[key]
        ok = test(values[0])
    if not ok:
        if problems is not None:
            problems.append((statements.get(LINES, {}).get(key), key, text, expected))
        return None
    return float(values[0]) if count == 1 else np.resize(values, count)


def map_statement(text):
    """Split a texture-map statement into its file name and options.

    Parameters
    ----------
    text : str
        What follows the keyword, e.g. ``"-clamp on -bm 0.5 bricks normal.png"``.

    Returns
    -------
    file_name : str
        The rest after the options (it may hold spaces: ``fuze uv.jpg``).
    options : dict of str to list of str
    """
    rest, options = text.strip(), {}
    while True:
        first = rest.split(None, 1)
        if not first or first[0].lower() not in _MAP_OPTIONS:
            break
        count = _MAP_OPTIONS[first[0].lower()]
        fields = rest.split(None, count + 1)
        options[first[0].lower()] = fields[1:count + 1]
        rest = fields[count + 1] if len(fields) > count + 1 else ""
    return rest.strip(), options


def _map_texture(statements, keys, folder, cache, srgb, source, kind="colour", problems=None):
    """The texture of the first of ``keys`` present, or None (missing file: warning; a
    malformed ``-bm`` is reported to ``problems`` and reads as 1)."""
    for key in keys:
        if key in statements:
            name, options = map_statement(statements[key])
            if not name:
                return None
            path = name if os.path.isabs(name) else os.path.join(folder, name)
            wrap = "clamp" if options.get("-clamp", ["off"])[0].lower() == "on" else "repeat"
            if not os.path.isfile(path):
                log.warning("%s: texture file %s not found (%s); using the factor colour",
                            source, name, key)
                return None
            if kind == "bump":
                option = f"{key} -bm"
                bm = {option: " ".join(options.get("-bm", ["1"])) or "?",
                      LINES: {option: statements.get(LINES, {}).get(key)}}
                strength = _floats(bm, option, 1, problems)
                strength = 1.0 if strength is None else strength
                return load_texture(path, srgb=False, wrap=wrap, cache=cache, signed=True).height_to_normals(strength)
            return load_texture(path, srgb=srgb, wrap=wrap, cache=cache, signed=kind == "normal")
    return None


def mtl_material(statements, name, folder, cache=None, source="mtl", problems=None):
    """Map one MTL material onto rtmesh's model (see docs/MATERIALS.md).

    Ka, Kd, Ks, Ke, Ns and Ni map to ambient, diffuse, specular, emission, shininess and
    ior.  ``illum`` chooses lighting (0: unlit), highlights, mirror reflection (weight Ks)
    and refraction (weight Tf, times 1 - d for the "glass" models 4 and 9).  Opacity is
    ``d`` (1 = opaque); ``Tr`` is read only when ``d`` is absent, as ``1 - Tr``
    (Assimp, three.js), except that ``Tr 1`` means opaque: MeshLab and others write Tr as
    an opacity, and a model that vanishes is the worse failure.  Opacity below 1 on a
    non-glass model is rendered as blended transparency; ``map_d`` does the same per texel.
    ``Ns`` below 1 turns the highlight off: ``Ks 1 Ns 0`` (MeshLab's default) would
    otherwise add the full specular colour to every lit point (Blender reads Ns 0 as
    roughness 1, no visible highlight).

    Parameters
    ----------
    statements : dict of str to str
        One material of :func:`parse_mtl`.
    name : str
    folder : str
        Folder that texture file names are resolved against.
    cache : dict, optional
        Textures already loaded, by (path, srgb, wrap); shared across the materials of a
        file so that each image is read once.
    source : str
        For messages.
    problems : list, optional
        Collects the malformed statements, whose defaults are used instead (see
        :func:`_floats`), for one warning per file (:func:`obj_materials`).

    Returns
    -------
    Material
    """
    cache = {} if cache is None else cache
    diffuse = _floats(statements, "kd", 3, problems)
    diffuse = np.full(3, 0.7) if diffuse is None else diffuse
    ambient = _floats(statements, "ka", 3, problems)
    specular = _floats(statements, "ks", 3, problems)
    specular = np.zeros(3) if specular is None else specular
    emission = _floats(statements, "ke", 3, problems)
    shininess = _floats(statements, "ns", 1, problems)
    shininess = 32.0 if shininess is None else shininess
    illum_value = _floats(statements, "illum", 1, problems)
    illum = 2 if illum_value is None else int(illum_value)
    lit, has_specular, has_mirror, transmissive = ILLUM.get(illum, ILLUM[2])
    if shininess < 1.0:
        has_specular = False
    opacity = _floats(statements, "d", 1, problems)
    if opacity is None:
        tr = _floats(statements, "tr", 1, problems)
        opacity = 1.0 if tr is None or tr >= 1.0 else 1.0 - tr
    opacity = float(np.clip(opacity, 0.0, 1.0))
    transmission = np.zeros(3)
    glass = illum in (4, 9)
    if transmissive:
        tf = _floats(statements, "tf", 3, problems)
        transmission = tf if tf is not None else np.ones(3)
        if glass:
            # "transparency" models: how much passes is the dissolve
            transmission = transmission * (1.0 - opacity)
    texture = lambda keys, srgb=True, kind="colour": _map_texture(  # noqa: E731
        statements, keys, folder, cache, srgb, source, kind, problems)
    opacity_texture = texture(("map_d",), srgb=False)
    normal_texture = texture(("norm",), srgb=False, kind="normal")
    if normal_texture is None:
        normal_texture = texture(("bump", "map_bump"), kind="bump")
    blended = not glass and (opacity < 1.0 or opacity_texture is not None)
    # map_Ke multiplies Ke; an emission map without Ke shows the map's own colours
    emission_texture = texture(("map_ke",))
    if emission_texture is not None and emission is None:
        emission = np.ones(3)
    return Material(
        name=name,
        diffuse=diffuse,
        ambient=diffuse if ambient is None else ambient,
        specular=specular if has_specular else np.zeros(3),
        shininess=float(np.clip(shininess, 1.0, 10000.0)),
        mirror=specular if has_mirror else np.zeros(3),
        transmission=np.clip(transmission, 0.0, 1.0),
        ior=_floats(statements, "ni", 1, problems) or 1.5,
        emission=np.zeros(3) if emission is None else np.maximum(emission, 0.0),
        unlit=not lit,
        opacity=opacity if blended else 1.0,
        alpha_mode="blend" if blended else "opaque",
        diffuse_texture=texture(("map_kd",)),
        specular_texture=texture(("map_ks",)) if has_specular else None,
        opacity_texture=opacity_texture,
        normal_texture=normal_texture,
        emission_texture=emission_texture,
    )


def obj_materials(path):
    """The materials of an OBJ file's MTL libraries, with warnings for what is missing.

    Parameters
    ----------
    path : str
        The OBJ file.

    Returns
    -------
    materials : dict of str to Material
    nan_colours : int
        Vertex statements with NaN colours (see :func:`scan_obj`).
    """
    mtl_paths, short_faces, nan_colours = scan_obj(path)
    source = os.path.basename(path)
    if short_faces:
        log.warning("%s: %d faces with fewer than 3 vertices skipped", source, short_faces)
    materials, cache = {}, {}
    for mtl_path in mtl_paths:
        if not os.path.isfile(mtl_path):
            log.warning("%s: material library %s not found; its materials render in the "
                        "default grey", source, os.path.basename(mtl_path))
            continue
        folder = os.path.dirname(mtl_path)
        problems = []
        for name, statements in parse_mtl(mtl_path).items():
            materials[name] = mtl_material(statements, name, folder, cache, source, problems)
        if problems:
            log.warning("%s: %s", os.path.basename(mtl_path), malformed_statements(problems))
    return materials, nan_colours


def malformed_statements(problems, shown=4):
    """One sentence for the malformed statements of an MTL file (see :func:`_floats`)."""
    parts = [f"line {line}: {key} {text!r} (expected {expected})" for line, key, text, expected
             in sorted(problems, key=lambda p: (p[0] is None, p[0] or 0))]
    more = f"; and {len(parts) - shown} more" if len(parts) > shown else ""
    return ("malformed values ignored, defaults used: " + "; ".join(parts[:shown]) + more)
