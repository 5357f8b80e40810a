"""The light registry: every light type a scene file can name (see :mod:`rtmesh.lights.light_types`)."""

from rtmesh.lights.area_lights import DISK, QUAD
from rtmesh.lights.point_lights import DIRECTIONAL, POINT, SPOT
from rtmesh.lights.projector import PROJECTOR

LIGHT_TYPES = {t.name: t for t in (POINT, DIRECTIONAL, SPOT, PROJECTOR, QUAD, DISK)}
