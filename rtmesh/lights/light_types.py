"""What a light type declares to the scene-file reader: its name, its keys, how it is built.

A light type is one :class:`LightType`, declared next to the light's class (its own
module), and one entry in :data:`rtmesh.loaders.light_registry.LIGHT_TYPES`.  The scene-file reader
knows nothing of the individual lights: it checks a ``[[lights]]`` table against its
type's keys and required keys and hands the values to the type's builder, so a new light
is its module, its registry entry, its documentation and its tests.

Key kinds name how the scene file's value is read: ``"vec3"`` (three numbers),
``"colour"`` (a number or three, linear), ``"positive"`` and ``"non_negative"`` (one
number), ``"bool"``, ``"path"`` (a file name, relative to the scene file's folder; the
builder gets it as a path it can open).
"""

from dataclasses import dataclass
from typing import Callable

import numpy as np

KEY_KINDS = ("vec3", "colour", "positive", "non_negative", "bool", "path")


@dataclass(frozen=True)
class LightType:
    """One kind of light a scene file can name.

    Attributes
    ----------
    name : str
        The scene file's ``type``.
    keys : dict of str to str
        Every key the light takes (besides ``type``) and its kind (see :data:`KEY_KINDS`).
    required : tuple of str
        The keys it cannot do without.
    build : callable
        ``build(values) -> light`` from the read values (a dict of the keys given);
        raises ValueError for values that cannot make a light.
    """

    name: str
    keys: dict
    required: tuple
    build: Callable

    def __post_init__(self):
        unknown = {kind for kind in self.keys.values() if kind not in KEY_KINDS}
        if unknown or not set(self.required) <= set(self.keys):
            raise ValueError(f"light type {self.name!r}: bad key kinds {unknown} or required keys")


def aim(values, name):
    """The direction of a light given ``direction`` or ``look_at`` (exactly one).

    Parameters
    ----------
    values : dict
        The light's read keys, with ``position``.
    name : str
        The light type, for the message.

    Returns
    -------
    (3,) float64
    """
    if ("direction" in values) == ("look_at" in values):
        raise ValueError(f"a {name} light needs exactly one of direction or look_at")
    if "direction" in values:
        return np.asarray(values["direction"], dtype=np.float64)
    return np.asarray(values["look_at"], dtype=np.float64) - values["position"]
