"""USD lights (rtmesh/loaders/usd_lights_cameras.py): a dome light as the background."""

import logging

import numpy as np
from PIL import Image
from pxr import Usd, UsdGeom, UsdLux

from rtmesh.loaders.usd_files import read_usd
from rtmesh.scene.background import EnvironmentBackground, SolidBackground


def _dome_stage(path, texture=None):
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    dome = UsdLux.DomeLight.Define(stage, "/Sky")
    dome.CreateColorAttr((0.5, 0.25, 1.0))
    dome.CreateIntensityAttr(2.0)
    if texture is not None:
        dome.CreateTextureFileAttr().Set(texture)
    stage.GetRootLayer().Save()
    return path


def test_a_dome_without_a_texture_is_a_solid_background_that_lights_the_scene(tmp_path):
    content = read_usd(_dome_stage(tmp_path / "dome.usda"))
    assert content.lights == []
    assert type(content.background) is SolidBackground and content.background.lighting is True
    assert np.allclose(content.background.colour, [1.0, 0.5, 2.0])  # colour x intensity


def test_a_domes_texture_is_the_environment_image_at_the_mean_radiance(tmp_path):
    Image.new("RGB", (8, 4), (255, 255, 255)).save(tmp_path / "sky.png")
    content = read_usd(_dome_stage(tmp_path / "dome.usda", "sky.png"))
    background = content.background
    assert isinstance(background, EnvironmentBackground) and background.lighting is True
    assert background.name == str(tmp_path / "sky.png")
    assert np.allclose(background.radiance(np.array([[0.0, 1.0, 0.0]])), 7.0 / 6.0)  # white x mean(1, 0.5, 2)


def test_a_dome_texture_that_cannot_be_read_leaves_a_solid_colour_with_a_warning(tmp_path, caplog):
    with caplog.at_level(logging.WARNING):
        content = read_usd(_dome_stage(tmp_path / "dome.usda", "missing.exr"))
    assert type(content.background) is SolidBackground and content.background.lighting is True
    assert np.allclose(content.background.colour, [1.0, 0.5, 2.0])
    assert "1 dome textures that cannot be read (a solid colour used): /Sky" in caplog.text
