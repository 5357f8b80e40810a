"""Real mesh files (copies in tests/data of ../shared/assets/real, the bunny in
assets/meshes): each renders with its materials and textures, or fails with one line and exit
status 2."""

import glob
import os

import numpy as np
import pytest
import scenes

from rtmesh.api import load_scene, render
from rtmesh.cli import main
from rtmesh.core.errors import MeshError

DATA = scenes.DATA
# every real file: the copies in tests/data plus the bundled bunny (the same file)
REAL_FILES = sorted(glob.glob(os.path.join(DATA, "*.obj")) + glob.glob(os.path.join(DATA, "*.glb"))
                    + [os.path.join(scenes.ASSETS, "meshes", "bunny.ply")])
TINY = dict(width=40, height=40, spp=1, threads=1)


def rendered(name, **settings):
    scene, _ = load_scene(os.path.join(DATA, name))
    return scene, render(scene, **{**TINY, **settings})


def test_box_textured_glb_shows_its_base_colour_texture():
    scene, result = rendered("BoxTextured.glb")
    assert scene.uv is not None and scene.materials.materials[0].diffuse_texture is not None
    # the texture (blue and green logo on white-ish): the albedo pass varies across the box
    albedo = render(scene, **TINY, passes=("albedo",)).passes["albedo"]
    covered = albedo.max(axis=2) > 0
    colours = albedo[covered]
    assert colours.std(axis=0).max() > 0.05
    # some texels are clearly blue-dominant, some green-dominant
    assert ((colours[:, 2] > 1.3 * colours[:, 0]) & (colours[:, 2] > colours[:, 1])).any()
    assert ((colours[:, 1] > 1.3 * colours[:, 0]) & (colours[:, 1] > colours[:, 2])).any()
    assert result.image.max() > 0.05


def test_fuze_obj_reads_map_kd_with_a_space_in_its_name():
    scene, result = rendered("fuze.obj")
    material = scene.materials.materials[0]
    assert material.diffuse_texture is not None and material.diffuse_texture.name == "fuze uv.jpg"
    # MeshLab writes "Ks 1 Ns 0 Tr 1": opaque and without a highlight covering the bottle
    assert material.alpha_mode == "opaque" and not material.specular.any()
    covered = result.image.max(axis=2) > 0
    assert covered.sum() > 50
    assert result.image[covered].std(axis=0).max() > 0.02  # the label, not a flat colour


def test_missing_material_library_warns_and_renders_grey(caplog):
    with caplog.at_level("WARNING"):
        scene, result = rendered("notenoughindices.obj")
    assert "surface.mtl not found" in caplog.text
    assert "1 faces with fewer than 3 vertices" in caplog.text
    assert len(scene.faces) == 1
    assert result.image.max() > 0.0


def test_nan_vertex_colour_warns_and_renders_without_colours(caplog):
    with caplog.at_level("WARNING"):
        scene, result = rendered("nancolor.obj")
    assert "NaN" in caplog.text and "vertex colours are ignored" in caplog.text
    assert scene.vertex_colors is None
    assert np.isfinite(result.image).all() and result.image.max() > 0.05


def test_missing_texture_file_warns_naming_it_and_uses_the_factor(tmp_path, caplog):
    (tmp_path / "m.mtl").write_text("newmtl m\nKd 0.2 0.4 0.6\nmap_Kd gone.png\n")
    (tmp_path / "t.obj").write_text("mtllib m.mtl\nusemtl m\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"
                                    "vt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n")
    with caplog.at_level("WARNING"):
        scene, _ = load_scene(str(tmp_path / "t.obj"))
    assert "gone.png not found" in caplog.text
    material = scene.materials.materials[0]
    assert material.diffuse_texture is None
    np.testing.assert_array_equal(material.diffuse, [0.2, 0.4, 0.6])


def test_corrupt_texture_is_a_one_line_cli_error(tmp_path, cli):
    # in this process (the cli fixture); tests/test_bad_inputs.py runs a corrupt texture's
    # command in a process of its own
    (tmp_path / "bad.png").write_bytes(b"\x89PNG\r\n\x1a\n not really")
    (tmp_path / "m.mtl").write_text("newmtl m\nmap_Kd bad.png\n")
    (tmp_path / "t.obj").write_text("mtllib m.mtl\nusemtl m\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"
                                    "vt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n")
    code, _, err = cli("render", tmp_path / "t.obj", "-o", tmp_path / "x.png", "-q")
    assert code == 2
    assert "bad.png" in err and "texture" in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not (tmp_path / "x.png").exists()


@pytest.mark.parametrize("name", ["BoxTextured.glb", "fuze.obj", "textured_tetrahedron.obj",
                                  "nancolor.obj", "notenoughindices.obj"])
def test_every_copied_asset_renders_something(name):
    _, result = rendered(name)
    assert np.isfinite(result.image).all()
    assert (result.image.max(axis=2) > 0.01).sum() > 4


def test_empty_obj_is_a_clear_error():
    with pytest.raises(MeshError, match="nothing to render"):
        load_scene(os.path.join(DATA, "empty.obj"))


def test_real_files_are_all_here():
    names = {os.path.basename(p) for p in REAL_FILES}
    assert names == {"BoxTextured.glb", "Duck.glb", "bunny.ply", "empty.obj", "fandisk.obj",
                     "fuze.obj", "monkey.glb", "nancolor.obj", "notenoughindices.obj",
                     "quadknot.obj", "rabbit.obj", "textured_tetrahedron.obj"}


@pytest.mark.parametrize("path", REAL_FILES, ids=os.path.basename)
def test_real_asset_renders_or_fails_with_one_line(path, tmp_path, capsys):
    # every real file either renders (exit 0) or is a one-line error (exit 2); in-process
    # (tests/test_bad_inputs.py runs the command in a process of its own)
    code = main(["render", path, "-o", str(tmp_path / "x.png"), "--width", "24", "--height", "24",
                 "--spp", "1", "--threads", "1", "-q"])
    err = capsys.readouterr().err
    if os.path.basename(path) == "empty.obj":
        assert code == 2 and len(err.strip().splitlines()) == 1
    else:
        assert code == 0, err
        assert (tmp_path / "x.png").exists()
