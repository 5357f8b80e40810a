"""--memory-limit while loading: a glTF whose nodes would flatten into more copies than the
limit allows stops with one line naming the file and the estimate, before reading its
geometry, under ``rtmesh render`` and in a batch's workers (the USD case is in
tests/loaders/test_usd_files.py)."""

import base64
import json
import shutil
import sqlite3

import numpy as np
import pytest
import trimesh

import rtmesh
from rtmesh.batch.books import REPORT_NAME
from rtmesh.batch.ledger import LEDGER_NAME, decode
from rtmesh.cli import main
from rtmesh.core.errors import ResourceError
from rtmesh.loaders.gltf_nodes import flattened_size, read_gltf_json
from rtmesh.loaders.importers import load_trimesh
from rtmesh.rendering import memory


def write_forest(path, nodes, distinct=False):
    """A glTF of ``nodes`` nodes placing one 5120-triangle sphere (2562 vertices), which is
    instanced (rtmesh.scene.instances); ``distinct``: each node places a mesh of its own
    (all of them reading the same accessors), which nothing instances."""
    ball = trimesh.creation.icosphere(subdivisions=4)
    positions = ball.vertices.astype("<f4").tobytes()
    indices = ball.faces.astype("<u4").tobytes()
    data = positions + indices
    doc = {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": list(range(nodes))}],
        "nodes": [{"mesh": i if distinct else 0, "translation": [3.0 * (i % 100), 3.0 * (i // 100), 0.0]}
                  for i in range(nodes)],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}] * (nodes if distinct else 1),
        "buffers": [{"byteLength": len(data),
                     "uri": "data:application/octet-stream;base64," + base64.b64encode(data).decode()}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": len(positions)},
                        {"buffer": 0, "byteOffset": len(positions), "byteLength": len(indices)}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": len(ball.vertices), "type": "VEC3",
                       "min": [-1, -1, -1], "max": [1, 1, 1]},
                      {"bufferView": 1, "componentType": 5125, "count": 3 * len(ball.faces), "type": "SCALAR"}],
    }
    path.write_text(json.dumps(doc))
    return path


@pytest.fixture(scope="module")
def forest(tmp_path_factory):
    """10,000 copies: each node places a mesh of its own."""
    return write_forest(tmp_path_factory.mktemp("forest") / "forest.gltf", 10_000, distinct=True)


def test_flattened_size_counts_every_copy_and_an_instanced_mesh_once(forest, tmp_path):
    assert flattened_size(read_gltf_json(forest)) == (10_000, 10_000 * 2562, 10_000 * 5120)
    instanced = write_forest(tmp_path / "instanced.gltf", 10_000)
    assert flattened_size(read_gltf_json(instanced)) == (10_000, 2562, 5120)


def test_ten_thousand_copies_beyond_the_limit_stop_before_the_memory_is_taken(forest, tmp_path, capsys,
                                                                             monkeypatch):
    out = tmp_path / "out.png"

    def no_geometry(*args, **kwargs):
        raise AssertionError("the geometry was read")

    # refused from the JSON: trimesh never decodes the buffers, no copy is made
    monkeypatch.setattr(trimesh, "load", no_geometry)
    status = main(["render", str(forest), "-o", str(out), "--width", "32", "--height", "24", "-q",
                   "--memory-limit", "4G"])
    err = capsys.readouterr().err
    assert status == 2 and not out.exists()
    assert err == (f"rtmesh: error: {forest}: 10000 mesh nodes of 51200000 triangles in all, copied where not "
                   "instanced would need about 28.6 GiB of memory to load but --memory-limit is 4 GiB: stopped "
                   "before taking it (set --memory-limit, 0 = no check)\n")


def test_a_batch_worker_fails_an_asset_beyond_its_limit_at_the_load_stage(forest, tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    shutil.copy(forest, src / "forest.gltf")
    write_forest(src / "small.gltf", 3)
    out = tmp_path / "out"
    report = rtmesh.batch_convert([src], out, workers=1, memory_limit=2 * 2**30, width=16, height=12, spp=1,
                                  quiet=True)
    message = (f"{src / 'forest.gltf'}: 10000 mesh nodes of 51200000 triangles in all, copied where not instanced "
               "would need about 28.6 GiB of memory to load but --memory-limit is 2 GiB: stopped before "
               "taking it (set --memory-limit, 0 = no check)")
    (failed,) = report.failed
    assert failed["asset"] == "forest.gltf"
    assert [(e["stage"], e["message"]) for e in failed["errors"]] == [("load", message)]
    lines = {line["asset"]: line for line in map(json.loads, (out / REPORT_NAME).read_text().splitlines())}
    assert lines["small.gltf"]["status"] == "done" and (out / "small.gltf.png").exists()
    assert lines["forest.gltf"]["status"] == "failed" and not (out / "forest.gltf.png").exists()
    # the ledger records it as any load failure: stage and the one line, the file as an input
    db = sqlite3.connect(out / LEDGER_NAME)
    try:
        rows = db.execute("SELECT status, stage, message, inputs FROM images WHERE asset = ?",
                          ("forest.gltf",)).fetchall()
    finally:
        db.close()
    assert [(status, stage, text) for status, stage, text, _ in rows] == [("failed", "load", message)]
    # with the file among its inputs: a smaller file there is a new attempt
    assert [entry[0] for entry in decode(rows[0][3])] == [""]


def test_files_within_the_limit_load_and_no_limit_is_checked_outside_the_command(tmp_path):
    small = write_forest(tmp_path / "small.gltf", 3, distinct=True)
    with memory.loading_limit(10_000_000):
        assert len(load_trimesh(small).graph.nodes_geometry) == 3
    with memory.loading_limit(1_000_000), pytest.raises(ResourceError, match="3 mesh nodes of 15360 triangles"):
        load_trimesh(small)
    with memory.loading_limit(0):
        load_trimesh(small)
    load_trimesh(small)  # the Python API: no limit
    assert np.isfinite(memory.load_estimate(2562, 5120))


def test_ten_thousand_placements_of_a_large_mesh_render_within_a_small_limit(tmp_path, capsys):
    """The file that grew to 22 GB as copies: the mesh is built once, placed by instances."""
    forest = write_forest(tmp_path / "instanced.gltf", 10_000)
    out = tmp_path / "out.png"
    status = main(["render", str(forest), "-o", str(out), "--width", "32", "--height", "24", "--spp", "1", "-q",
                   "--memory-limit", "2G"])
    assert status == 0 and out.exists(), capsys.readouterr().err
