"""KTX2 textures (KHR_texture_basisu): without a decoder, one warning naming the texture and
the extension, and the material's factors used; a fallback image is read as usual."""

import logging

import gltf_codecs
import hostile_files
import numpy as np

from rtmesh.loaders.importers import load_trimesh
from rtmesh.loaders.trimesh_parts import parts_from_trimesh

# the identifier of a KTX2 file, then bytes no decoder here reads
KTX2 = b"\xabKTX 20\xbb\r\n\x1a\n" + bytes(range(64))


def _basisu_square(tmp_path, fallback):
    """The textured square of hostile_files with its texture's KTX2 image in
    KHR_texture_basisu and, if ``fallback``, its PNG as the texture's "source"."""
    doc, binary = gltf_codecs.split_glb(hostile_files.textured_square_glb(hostile_files.png_bytes(4, 4)))
    binary += b"\0" * (-len(binary) % 4)
    doc["bufferViews"].append({"buffer": 0, "byteOffset": len(binary), "byteLength": len(KTX2)})
    binary += KTX2
    doc["images"].append({"name": "paint.ktx2", "bufferView": len(doc["bufferViews"]) - 1,
                          "mimeType": "image/ktx2"})
    doc["textures"] = [{"extensions": {"KHR_texture_basisu": {"source": 1}}}]
    if fallback:
        doc["textures"][0]["source"] = 0
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"] = [0.2, 0.5, 0.8, 1.0]
    doc["extensionsUsed"] = ["KHR_texture_basisu"]
    if not fallback:
        doc["extensionsRequired"] = ["KHR_texture_basisu"]
    doc["buffers"][0]["byteLength"] = len(binary)
    path = tmp_path / f"basisu_{'fallback' if fallback else 'only'}.glb"
    path.write_bytes(gltf_codecs.join_glb(doc, binary))
    return path


def test_a_ktx2_texture_is_one_warning_and_the_factors_are_used(tmp_path, caplog):
    path = _basisu_square(tmp_path, fallback=False)
    with caplog.at_level(logging.WARNING):
        parts, materials = parts_from_trimesh(load_trimesh(path), str(path))
    assert [r.getMessage() for r in caplog.records] == [
        f"{path.name}: material 'painted': baseColorTexture 'paint.ktx2' is a KTX2 image (KHR_texture_basisu), "
        "which rtmesh does not decode; the material's factors are used without it"]
    (material,) = materials
    assert material.diffuse_texture is None
    assert np.allclose(material.base_color, [0.2, 0.5, 0.8])
    assert len(parts) == 1 and len(parts[0].faces) == 2


def test_a_ktx2_texture_with_a_fallback_image_uses_the_fallback_without_a_word(tmp_path, caplog):
    path = _basisu_square(tmp_path, fallback=True)
    with caplog.at_level(logging.WARNING):
        _, materials = parts_from_trimesh(load_trimesh(path), str(path))
    assert not caplog.records
    # the fallback PNG's texels: 4 x 4, black
    texture = materials[0].diffuse_texture
    assert texture.bytes.shape[:2] == (4, 4) and not texture.bytes[..., :3].any()
