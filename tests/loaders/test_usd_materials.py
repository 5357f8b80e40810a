"""USD materials (rtmesh/loaders/usd_materials.py): a preview surface's separate roughness and
metallic textures packed as glTF's metallic-roughness texture."""

import numpy as np
from PIL import Image

from rtmesh.loaders.usd_materials import _packed

OPTIONS = {"wrap": ("repeat", "repeat"), "transform": None}


def test_roughness_goes_to_green_and_metalness_to_blue_at_the_larger_size():
    rough = (Image.new("L", (4, 4), 100), OPTIONS, np.ones(4))
    metal = (Image.new("RGB", (2, 2), (200, 200, 200)), {**OPTIONS, "wrap": ("clamp", "clamp")}, np.ones(4))
    image, options = _packed(rough, metal)
    assert image.mode == "RGB" and image.size == (4, 4)
    red, green, blue = (np.asarray(channel) for channel in image.split())
    assert (red == 0).all() and (green == 100).all() and (blue == 200).all()
    assert options is rough[1]  # the roughness texture's sampling


def test_a_missing_texture_is_full_white_so_its_factor_applies_alone():
    metal = (Image.new("L", (2, 2), 200), OPTIONS, np.ones(4))
    image, options = _packed(None, metal)
    red, green, blue = (np.asarray(channel) for channel in image.split())
    assert image.size == (2, 2) and (red == 0).all() and (green == 255).all() and (blue == 200).all()
    assert options is metal[1]
    rough = (Image.new("L", (3, 3), 50), OPTIONS, np.ones(4))
    _, green, blue = _packed(rough, None)[0].split()
    assert (np.asarray(green) == 50).all() and (np.asarray(blue) == 255).all()
