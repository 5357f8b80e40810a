"""``rtmesh batch --dither``: blue-noise dithered PNGs, the option in the fingerprint only when given."""

import types

import numpy as np
import pytest
import trimesh

from rtmesh.batch import jobs, runner, worker
from rtmesh.batch.inputs import InputError
from rtmesh.batch.options import BatchOptions
from rtmesh.cli import main
from rtmesh.io.images import read_image


def test_dither_reaches_the_workers_png(tmp_path, monkeypatch):
    asked = {}

    def recording(inputs, outdir, **options):
        asked.update(options)
        return types.SimpleNamespace(counts={"not_attempted": 0}, summary=lambda: "", exit_code=0)

    monkeypatch.setattr(runner, "batch_convert", recording)
    mesh = tmp_path / "ball.obj"
    trimesh.creation.icosphere(2).export(mesh)
    assert main(["batch", str(mesh), "-o", str(tmp_path / "out"), "--dither", "-q"]) == 0
    fields = BatchOptions(**dict(asked, width=32, height=24, threads=1)).validate().render_fields({})
    assert fields["dither"] is True
    # without the option the fields, and so the fingerprints of earlier images, are as before
    assert "dither" not in BatchOptions().render_fields({})
    task = jobs.ImageTask("iso", jobs.fixed_view("iso"), ("iso.png",), "")
    steps = []
    for dither in (True, False):
        folder = tmp_path / str(dither)
        settings = dict(fields, dither=dither)
        (image,) = worker.run_job(jobs.AssetJob("ball.obj", str(mesh), str(folder), settings, (task,)))["images"]
        assert image["status"] == "done", image
        steps.append(np.round(read_image(folder / "iso.png")[0] * 255.0))
    difference = steps[0] - steps[1]
    assert (difference != 0).any() and np.abs(difference).max() == 1.0 and abs(difference.mean()) < 0.1


def test_a_bad_dither_is_refused_before_anything_runs():
    with pytest.raises(InputError, match=r"^dither must be true or false \(got 'yes'\)$"):
        BatchOptions(dither="yes").validate()
