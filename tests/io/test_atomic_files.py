"""Atomic writes: whole files or none, and staged files whose rename is left to the caller."""

import os
import threading

import pytest

from rtmesh.io.atomic_files import staged, target_of, write_text


def test_a_write_is_renamed_into_place_and_leaves_nothing_else(tmp_path):
    write_text(tmp_path / "a.json", "{}\n")
    assert os.listdir(tmp_path) == ["a.json"]
    assert (tmp_path / "a.json").read_text() == "{}\n"


def test_staged_files_stay_at_their_temporary_names_until_renamed(tmp_path):
    (tmp_path / "a.json").write_text("old\n")
    with staged() as pending:
        write_text(tmp_path / "a.json", "new\n")
        write_text(tmp_path / "b.json", "b\n")
    assert (tmp_path / "a.json").read_text() == "old\n"  # not replaced yet
    assert [os.path.basename(path) for _, path in pending] == ["a.json", "b.json"]
    for tmp, path in pending:
        name = os.path.basename(tmp)
        assert name.startswith(".") and target_of(name) == os.path.basename(path)
        os.replace(tmp, path)
    assert sorted(os.listdir(tmp_path)) == ["a.json", "b.json"]
    assert (tmp_path / "a.json").read_text() == "new\n"
    # outside the block, writes go straight into place again
    write_text(tmp_path / "c.json", "c\n")
    assert sorted(os.listdir(tmp_path)) == ["a.json", "b.json", "c.json"]


def test_a_staged_block_that_raises_removes_its_temporaries(tmp_path):
    with pytest.raises(KeyError):
        with staged():
            write_text(tmp_path / "a.json", "a\n")
            assert len(os.listdir(tmp_path)) == 1
            raise KeyError("stop")
    assert os.listdir(tmp_path) == []


def test_staging_belongs_to_the_thread_that_opened_the_block(tmp_path):
    """Dask runs tasks on threads: one task's block must not catch another's writes."""
    other = threading.Thread(target=write_text, args=(tmp_path / "other.json", "x\n"))
    with staged() as pending:
        other.start()
        other.join()
    assert pending == [] and os.listdir(tmp_path) == ["other.json"]


def test_target_of_names_the_file_a_temporary_stands_for():
    assert target_of(".a.obj.turn003.k2j4_x9q.tmp.png") == "a.obj.turn003.png"
    assert target_of(".a.obj.camera.json.k2j4_x9q.tmp") == "a.obj.camera.json"
    assert target_of("a.obj.png") is None and target_of(".a.obj.png") is None
