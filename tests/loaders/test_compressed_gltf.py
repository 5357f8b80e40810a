"""Compressed and quantised glTF geometry (rtmesh/loaders/gltf_compression.py).

A plain GLB (a textured ball over a floor, written by trimesh) is Draco-compressed by
DracoPy, meshopt-compressed by meshoptimizer's codecs and quantised to normalised integers
(tests/gltf_codecs.py); each renders the image of the plain file.  Broken compressed
buffers and missing codecs are one line, exit 2, nothing written.
"""

import builtins
import json
import logging

import gltf_codecs
import numpy as np
import pytest
import trimesh
from PIL import Image

from rtmesh.api import render
from rtmesh.cli import main
from rtmesh.core.errors import MissingExtraError
from rtmesh.loaders.importers import load_trimesh
from rtmesh.loaders.trimesh_parts import parts_from_trimesh

SIZE = dict(width=32, height=24, spp=4)


def _plain_glb():
    ball = trimesh.creation.icosphere(2, radius=0.6)
    uv = ball.vertices[:, :2] * (0.5 / 0.6) + 0.5
    checker = (np.indices((8, 8)).sum(0) % 2)[..., None] * np.array([200, 60, 30]) + 40
    ball.visual = trimesh.visual.TextureVisuals(uv=uv, material=trimesh.visual.material.PBRMaterial(
        baseColorTexture=Image.fromarray(checker.astype(np.uint8)), metallicFactor=0.0, roughnessFactor=0.5))
    floor = trimesh.creation.box(extents=[2.5, 0.2, 2.5])
    floor.apply_translation([0.2, -0.8, 0.1])
    floor.visual = trimesh.visual.TextureVisuals(material=trimesh.visual.material.PBRMaterial(
        baseColorFactor=[0.3, 0.6, 0.9, 1.0], metallicFactor=0.0, roughnessFactor=0.7))
    scene = trimesh.Scene()
    scene.add_geometry(ball, node_name="ball", transform=trimesh.transformations.rotation_matrix(0.3, [0, 1, 0]))
    scene.add_geometry(floor, node_name="floor")
    return trimesh.exchange.gltf.export_glb(scene, include_normals=True)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("compressed")
    plain = _plain_glb()
    out = {}
    for name, data in (("plain", plain), ("draco", gltf_codecs.draco_glb(plain)),
                       ("meshopt", gltf_codecs.meshopt_glb(plain)), ("quantised", gltf_codecs.quantised_glb(plain))):
        out[name] = folder / f"{name}.glb"
        out[name].write_bytes(data)
    return out


@pytest.fixture(scope="module")
def plain_image(files):
    return render(str(files["plain"]), **SIZE).image


@pytest.mark.parametrize("name", ["draco", "meshopt", "quantised"])
def test_a_compressed_glb_renders_the_plain_files_image(files, plain_image, name):
    # the files really are compressed: trimesh alone does not read the geometry of this one
    doc, _ = gltf_codecs.split_glb(files[name].read_bytes())
    assert doc["extensionsRequired"]
    image = render(str(files[name]), **SIZE).image
    assert plain_image.mean() > 0.05
    difference = np.abs(image.astype(np.float64) - plain_image).mean()
    assert difference <= 0.01 * plain_image.mean(), (difference, plain_image.mean())


@pytest.mark.parametrize("name", ["draco", "meshopt", "quantised"])
def test_decoded_geometry_matches_the_plain_files(files, name):
    plain, _ = parts_from_trimesh(load_trimesh(files["plain"]), "plain")
    decoded, materials = parts_from_trimesh(load_trimesh(files[name]), name)
    assert [p.name for p in decoded] == [p.name for p in plain]
    for a, b in zip(plain, decoded):
        extent = np.ptp(a.vertices, axis=0).max()
        assert np.abs(a.vertices - b.vertices).max() < 1e-4 * extent
        assert len(a.faces) == len(b.faces)
        # the same triangles (meshopt may start a triangle at another corner)
        assert sorted(map(tuple, np.sort(a.faces, axis=1).tolist())) == \
            sorted(map(tuple, np.sort(b.faces, axis=1).tolist()))
        if a.uv is not None:
            assert np.abs(a.uv - b.uv).max() < 1e-4
        unit = [n / np.linalg.norm(n, axis=1, keepdims=True) for n in (a.vertex_normals, b.vertex_normals)]
        assert np.abs(unit[0] - unit[1]).max() < 0.02  # int8 normals: 1/127 a component
    assert any(m.diffuse_texture is not None for m in materials)


def _cli(path, tmp_path, capsys, caplog):
    out = tmp_path / "out.png"
    with caplog.at_level(logging.WARNING):
        status = main(["render", str(path), "-o", str(out), "--width", "24", "--height", "18", "-q"])
    return status, capsys.readouterr().err, out


def _rewrite(path, tmp_path, change):
    doc, binary = gltf_codecs.split_glb(path.read_bytes())
    change(doc)
    broken = tmp_path / f"broken_{path.name}"
    broken.write_bytes(gltf_codecs.join_glb(doc, binary))
    return broken


def _truncate_draco(doc):
    spec = doc["meshes"][0]["primitives"][0]["extensions"]["KHR_draco_mesh_compression"]
    doc["bufferViews"][spec["bufferView"]]["byteLength"] //= 2


def _miscount_meshopt(doc):
    doc["bufferViews"][1]["extensions"]["EXT_meshopt_compression"]["count"] += 7


@pytest.mark.parametrize("name, change, message", [
    ("draco", _truncate_draco, "meshes[0].primitives[0].extensions.KHR_draco_mesh_compression: the Draco "
                               "data does not decode"),
    ("meshopt", _miscount_meshopt, "bufferViews[1].extensions.EXT_meshopt_compression: the compressed data does "
                                   "not decode to 169 elements of 12 bytes"),
])
def test_a_broken_compressed_buffer_is_one_line_and_nothing_written(files, tmp_path, capsys, caplog, name,
                                                                    change, message):
    broken = _rewrite(files[name], tmp_path, change)
    status, err, out = _cli(broken, tmp_path, capsys, caplog)
    assert status == 2 and not out.exists()
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert err.startswith(f"rtmesh: error: {broken}: {message}"), err


@pytest.mark.parametrize("name, module, extension", [("draco", "DracoPy", "KHR_draco_mesh_compression"),
                                                     ("meshopt", "meshopt", "EXT_meshopt_compression")])
def test_a_missing_codec_names_the_extension_and_the_extra(files, monkeypatch, name, module, extension):
    real_import = builtins.__import__

    def without(name_, *args, **kwargs):
        if name_ == module:
            raise ImportError(f"No module named {module!r}")
        return real_import(name_, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", without)
    with pytest.raises(MissingExtraError) as caught:
        load_trimesh(files[name])
    assert str(caught.value) == (f"{files[name]}: uses {extension}, which needs "
                                 f"{'DracoPy' if module == 'DracoPy' else 'the meshopt package'}: "
                                 "pip install 'rtmesh[compressed]'")


def test_a_quantised_accessor_past_its_view_is_one_line(files, tmp_path, capsys, caplog):
    def overrun(doc):
        accessor = doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]
        doc["accessors"][accessor]["count"] += 1000

    status, err, out = _cli(_rewrite(files["quantised"], tmp_path, overrun), tmp_path, capsys, caplog)
    assert status == 2 and not out.exists() and len(err.strip().splitlines()) == 1
    assert "meshes[0].primitives[0].attributes.POSITION: 1162 elements of 8 bytes run past the end" in err


def test_plain_files_are_read_by_trimesh_as_they_are(files, monkeypatch):
    from rtmesh.loaders import gltf_compression

    def refuse(*args):
        raise AssertionError("a plain file was rewritten")

    monkeypatch.setattr(gltf_compression, "plain_glb", refuse)
    assert parts_from_trimesh(load_trimesh(files["plain"]), "plain")[0]
    assert json.loads(json.dumps(gltf_codecs.split_glb(files["plain"].read_bytes())[0])).get("extensionsUsed") is None


def test_gpu_instances_are_flattened_into_a_copy_each(files, tmp_path):
    from rtmesh.loaders.gltf_nodes import flattened_size, read_gltf_json

    rng = np.random.default_rng(3)
    translations = rng.uniform(-2, 2, (5, 3))
    rotations = rng.normal(size=(5, 4))
    rotations /= np.linalg.norm(rotations, axis=1, keepdims=True)
    scales = rng.uniform(0.5, 1.5, (5, 3))
    path = tmp_path / "instanced.glb"
    path.write_bytes(gltf_codecs.gpu_instanced_glb(files["plain"].read_bytes(), 0, translations, rotations, scales))
    assert flattened_size(read_gltf_json(path))[0] == 5 + 1  # five balls and the floor
    plain, _ = parts_from_trimesh(load_trimesh(files["plain"]), "plain")
    ball = next(p for p in plain if p.name == "ball")
    node = trimesh.transformations.rotation_matrix(0.3, [0, 1, 0])
    local = trimesh.transform_points(ball.vertices, np.linalg.inv(node))
    parts, _ = parts_from_trimesh(load_trimesh(path), "instanced")
    placed = {p.name: p for p in parts}
    assert sorted(placed) == ["ball[0]", "ball[1]", "ball[2]", "ball[3]", "ball[4]", "floor"]
    for k in range(5):
        x, y, z, w = np.round(rotations[k] * 32767) / 32767
        matrix = (node @ trimesh.transformations.translation_matrix(translations[k])
                  @ trimesh.transformations.quaternion_matrix([w, x, y, z]) @ np.diag([*scales[k], 1.0]))
        assert np.allclose(placed[f"ball[{k}]"].vertices, trimesh.transform_points(local, matrix), atol=1e-5)


def test_a_compressed_glb_without_its_binary_chunk_is_one_line(files, tmp_path, capsys, caplog):
    doc, _ = gltf_codecs.split_glb(files["draco"].read_bytes())
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    cut = tmp_path / "cut.glb"
    cut.write_bytes(files["draco"].read_bytes()[:20 + len(text)])
    status, err, out = _cli(cut, tmp_path, capsys, caplog)
    assert status == 2 and not out.exists()
    assert err == f"rtmesh: error: {cut}: buffers[0]: cannot read (no URI, and no GLB binary chunk holds it)\n"
