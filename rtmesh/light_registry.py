"""The light registry: every light type a scene file can name (see :mod:`rtmesh.light_types`)."""

from .area_lights import DISK, QUAD
from .lights import DIRECTIONAL, POINT, SPOT

LIGHT_TYPES = {t.name: t for t in (POINT, DIRECTIONAL, SPOT, QUAD, DISK)}
