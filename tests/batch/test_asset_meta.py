"""Per-asset metadata in batch: counts, bounds, materials, textures found and missing, warnings."""

import json

import numpy as np
import pytest
from PIL import Image

import rtmesh


@pytest.fixture
def textured_obj(tmp_path):
    """Two quads with two materials: one's texture is there, the other's is missing."""
    src = tmp_path / "src"
    src.mkdir()
    Image.new("RGB", (4, 4), (200, 30, 30)).save(src / "wood.png")
    (src / "crate.mtl").write_text("newmtl wood\nKd 1 1 1\nmap_Kd wood.png\n"
                                   "newmtl metal\nKd 0.5 0.5 0.5\nmap_Kd missing.png\n")
    (src / "crate.obj").write_text(
        "mtllib crate.mtl\n"
        "v 0 0 0\nv 2 0 0\nv 2 1 0\nv 0 1 0\nv 0 0 3\nv 2 0 3\n"
        "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
        "usemtl wood\nf 1/1 2/2 3/3 4/4\nusemtl metal\nf 1/1 5/2 6/3 2/4\n")
    return src


@pytest.mark.usefixtures("in_process_jobs")
def test_asset_meta_json_says_what_the_asset_is_made_of(textured_obj, tmp_path):
    out = tmp_path / "out"
    report = rtmesh.batch_convert([textured_obj], out, workers=1, width=8, height=8, spp=1,
                                  asset_meta=True, normalize="unit-cube", progress="none")
    assert report.exit_code == 0
    meta = json.loads((out / "crate.obj.meta.json").read_text())
    assert meta["asset"] == "crate.obj" and meta["triangles"] == 4
    assert meta["vertices"] >= 6
    np.testing.assert_allclose(meta["bounds"], [[0, 0, 0], [2, 1, 3]], atol=1e-12)
    np.testing.assert_allclose(meta["bounds_world"], [[-1 / 3, -1 / 6, -0.5], [1 / 3, 1 / 6, 0.5]], atol=1e-12)
    names = {m["name"]: m["textures"] for m in meta["materials"]}
    assert set(names) == {"wood", "metal"}
    assert names["wood"] == {"diffuse_texture": meta["textures_found"][0]} and names["metal"] == {}
    assert "crate.mtl" in meta["files_read"] and "wood.png" in meta["files_read"]
    assert "missing.png" not in meta["files_read"]
    assert any("missing.png" in w and "not found" in w for w in meta["warnings"])
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(("rtmesh-batch", "."))) == [
        "crate.obj.meta.json", "crate.obj.png"]
