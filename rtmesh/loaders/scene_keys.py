"""The scene file's schema: what each key's value must be and which keys each table has.

Value readers (a number in the scene file's range, a colour, a vector, one of some names)
raise ``TypeError`` with what they expected; :class:`TableReader` checks a parsed table
against a schema of them and turns such errors into :class:`SceneError` lines that name the
file and the key.  The keys are documented in docs/SCENE_FORMAT.md; reading them into a
scene is :mod:`rtmesh.loaders.scene_file`'s.
"""

import math

import numpy as np

from rtmesh.core.errors import SceneError
from rtmesh.loaders.light_registry import LIGHT_TYPES
from rtmesh.materials.models import MODEL_NAMES
from rtmesh.rendering.settings import CAUSTICS, INTEGRATORS, LIGHT_SAMPLERS
from rtmesh.scene.background import BACKGROUND_TYPES

# ---------------------------------------------------------------- value types


# Every number of a scene file is finite and 0 or between these in magnitude: squares,
# products and reciprocals of coordinates, distances, intensities, roughnesses and indices
# of refraction then stay far inside float64, and a coordinate inside the float32 Embree
# holds (docs/LIMITS.md).
MIN_NUMBER, MAX_NUMBER = 1e-18, 1e18
_RANGE = f"0, or magnitude {MIN_NUMBER:g} to {MAX_NUMBER:g}"


def _is_number(v):
    return (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
            and (v == 0 or MIN_NUMBER <= abs(v) <= MAX_NUMBER))


def _float(v):
    if not _is_number(v):
        raise TypeError(f"expected a finite number ({_RANGE})")
    return float(v)


def _positive(v):
    v = _float(v)
    if v <= 0:
        raise TypeError("expected a number > 0")
    return v


def _fov(v):
    v = _float(v)
    if not 0.0 < v < 180.0:
        raise TypeError("expected degrees more than 0 and less than 180")
    return v


def _non_negative(v):
    v = _float(v)
    if v < 0:
        raise TypeError("expected a number >= 0")
    return v


def _int(v):
    if not isinstance(v, int) or isinstance(v, bool):
        raise TypeError("expected an integer")
    return v


def _bool(v):
    if not isinstance(v, bool):
        raise TypeError("expected true or false")
    return v


def _str(v):
    if not isinstance(v, str):
        raise TypeError("expected a string")
    return v


def _vector(n):
    def convert(v):
        if not (isinstance(v, list) and len(v) == n and all(_is_number(x) for x in v)):
            raise TypeError(f"expected a list of {n} numbers (finite; {_RANGE})")
        return np.array(v, dtype=np.float64)
    return convert


_vec2, _vec3 = _vector(2), _vector(3)


def _colour(v):
    """A number (grey) or [r, g, b], all >= 0."""
    c = np.full(3, _float(v)) if _is_number(v) else _vec3(v) if isinstance(v, list) else None
    if c is None:
        raise TypeError(f"expected a number or a list of 3 numbers (finite; {_RANGE})")
    if (c < 0).any():
        raise TypeError("colour components must be >= 0")
    return c


def _reflectance(v):
    """A colour whose components are at most 1: a weight of the path through a bounce (more
    would gain energy at every bounce, up to an infinite image)."""
    c = _colour(v)
    if (c > 1).any():
        raise TypeError("colour components must be between 0 and 1 (a reflectance)")
    return c


def _scale(v):
    s = np.full(3, _float(v)) if _is_number(v) else _vec3(v)
    if (s == 0).any():
        raise TypeError("scale must not be zero")
    return s


def _str_list(v):
    if not (isinstance(v, list) and all(isinstance(x, str) for x in v)):
        raise TypeError("expected a list of strings")
    return tuple(v)


def _shutter(v):
    """[open, close] with open <= close."""
    times = _vec2(v)
    if times[1] < times[0]:
        raise TypeError("expected [open, close] with open <= close")
    return times


def _table(v):
    if not isinstance(v, dict):
        raise TypeError("expected a table")
    return v


def _one_of(*choices):
    def convert(v):
        if v not in choices:
            raise TypeError("expected one of " + ", ".join(repr(c) for c in choices))
        return v
    return convert


# ---------------------------------------------------------------- schema

RENDER_KEYS = {
    "width": _int, "height": _int, "spp": _int, "sampler": _str, "max_depth": _int,
    "seed": _int, "threads": _int, "chunk_samples": _int, "cutoff": _non_negative,
    "fresnel": _str, "ao_samples": _int, "ao_distance": _positive, "passes": _str_list,
    "light_samples": _int,
    "exposure": _float, "tonemap": _str, "dither": _bool,
    "target_error": _positive, "time_limit": _positive, "max_spp": _int, "denoise": _bool,
    "integrator": _one_of(*INTEGRATORS), "clamp": _non_negative, "caustics": _one_of(*CAUSTICS), "photons": _int,
    "light_sampler": _one_of(*LIGHT_SAMPLERS),
}
CAMERA_KEYS = {
    "position": _vec3, "look_at": _vec3, "up": _vec3, "fov": _fov,
    "aperture": _non_negative, "focus_distance": _positive, "from_file": _str,
    "shutter": _shutter, "projection": _one_of("perspective", "orthographic"), "ortho_height": _positive,
}
ENVIRONMENT_KEYS = {"ambient": _colour, "background": _colour}
MATERIAL_KEYS = {
    "diffuse": _colour, "specular": _colour, "shininess": _non_negative, "ambient": _colour,
    "mirror": _reflectance, "transmission": _reflectance, "ior": _positive, "absorption": _colour,
    "emission": _colour, "roughness": _non_negative, "model": _one_of(*MODEL_NAMES),
}
OBJECT_KEYS = {
    "name": _str, "mesh": _str, "category": _str,
    "primitive": _one_of("icosphere", "box", "plane"),
    "subdivisions": _int, "radius": _positive, "extents": _vec3, "size": _vec2,
    "material": _str, "smooth": _bool,
    "translate": _vec3, "rotate": _vec3, "scale": _scale, "import_lights": _bool,
    "motion": _table, "instances": _str,
}
MOTION_KEYS = {"translate": _vec3, "rotate_axis": _vec3, "rotate_degrees": _float}
# the keys of every registered light type, read by their kind (see rtmesh.lights.light_types)
_KEY_READERS = {"vec3": _vec3, "colour": _colour, "positive": _positive, "non_negative": _non_negative,
                "bool": _bool, "path": _str}


def light_keys():
    """The keys a ``[[lights]]`` table may have, with their readers, from the registry."""
    return {"type": _one_of(*LIGHT_TYPES),
            **{key: _KEY_READERS[kind] for t in LIGHT_TYPES.values() for key, kind in t.keys.items()}}

BACKGROUND_KEYS = {
    "type": _one_of(*BACKGROUND_TYPES), "colour": _colour, "top": _colour, "bottom": _colour,
    "file": _str, "rotation": _float, "intensity": _non_negative, "lighting": _bool,
}
BACKGROUND_ALLOWED = {
    "solid": ("colour", "lighting"), "gradient": ("top", "bottom", "lighting"),
    "environment": ("file", "rotation", "intensity", "lighting"), "transparent": (),
}
BACKGROUND_REQUIRED = {"solid": ("colour",), "gradient": ("top", "bottom"), "environment": ("file",),
                       "transparent": ()}
TOP_LEVEL = ("render", "camera", "environment", "background", "materials", "objects", "lights")


class TableReader:
    """Validates tables of a parsed scene file, naming the file and key in errors."""

    def __init__(self, source):
        self.source = source

    def error(self, where, message):
        return SceneError(f"{self.source}: {where}: {message}")

    def table(self, value, where):
        if not isinstance(value, dict):
            raise self.error(where, "expected a table")
        return value

    def array_of_tables(self, value, where):
        if not (isinstance(value, list) and all(isinstance(v, dict) for v in value)):
            raise self.error(where, f"expected an array of tables ([[{where}]])")
        return value

    def fields(self, table, schema, where):
        """Convert every key of ``table`` with ``schema``; unknown keys are errors."""
        out = {}
        for key, value in table.items():
            path = f"{where}.{key}" if where else key
            if key not in schema:
                raise self.error(path, "unknown key (expected one of " + ", ".join(schema) + ")")
            try:
                out[key] = schema[key](value)
            except TypeError as exc:
                raise self.error(path, str(exc)) from None
        return out
