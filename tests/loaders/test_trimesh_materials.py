"""trimesh's materials as rtmesh's (rtmesh/loaders/trimesh_materials.py): materials built in
code, not read from a file."""

import types

import numpy as np
from PIL import Image
from trimesh.visual import TextureVisuals
from trimesh.visual.material import SimpleMaterial

from rtmesh.loaders.trimesh_materials import _simple_material, material_from_trimesh


def test_a_simple_material_built_in_code_keeps_its_colour_and_image():
    image = Image.new("RGB", (4, 2), (255, 0, 0))
    material = material_from_trimesh(TextureVisuals(material=SimpleMaterial(image=image, diffuse=[255, 255, 255],
                                                                            name="paint")), "mesh")
    assert material.name == "paint"
    assert np.allclose(material.diffuse, 1.0)
    assert material.diffuse_texture is not None and material.diffuse_texture.name == "paint image"


def test_trimeshs_stand_in_for_a_missing_material_is_no_texture():
    # no name, no statements and an image of at most four pixels: what trimesh makes up
    stand_in = types.SimpleNamespace(name=None, kwargs={}, image=Image.new("RGB", (2, 2), (255, 255, 255)),
                                     diffuse=None, ambient=None, specular=None)
    assert _simple_material(stand_in, "mesh").diffuse_texture is None
    named = types.SimpleNamespace(**{**vars(stand_in), "name": "paint"})
    assert _simple_material(named, "mesh").diffuse_texture is not None
    larger = types.SimpleNamespace(**{**vars(stand_in), "image": Image.new("RGB", (3, 2))})
    assert _simple_material(larger, "mesh").diffuse_texture is not None
