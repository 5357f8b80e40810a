"""The scene file's schema (rtmesh/loaders/scene_keys.py): the readers of key values."""

import pytest

from rtmesh.core.errors import SceneError
from rtmesh.loaders.scene_keys import RENDER_KEYS, TableReader


def test_passes_are_a_list_of_strings_kept_as_a_tuple():
    reader = TableReader("s.toml")
    assert reader.fields({"passes": ["depth", "normal"]}, RENDER_KEYS, "render") == {"passes": ("depth", "normal")}
    assert reader.fields({"passes": []}, RENDER_KEYS, "render") == {"passes": ()}
    for bad in ("depth", ["depth", 1], {"depth": True}):
        with pytest.raises(SceneError, match=r"^s\.toml: render\.passes: expected a list of strings$"):
            reader.fields({"passes": bad}, RENDER_KEYS, "render")
