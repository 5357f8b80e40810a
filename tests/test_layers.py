"""The package's layering (pyproject.toml, [tool.importlinter]) holds and covers every subpackage."""

import pathlib
import shutil
import subprocess
import sys

import pytest

if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib

ROOT = pathlib.Path(__file__).resolve().parent.parent


def _layers():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
    (contract,) = config["contracts"]
    return contract["layers"]


def test_every_subpackage_and_top_module_is_in_a_layer():
    package = ROOT / "rtmesh"
    members = {f"rtmesh.{p.name}" for p in package.iterdir() if (p / "__init__.py").exists()}
    members |= {f"rtmesh.{p.stem}" for p in package.glob("*.py") if p.stem != "__init__"}
    assert members == set(_layers())


def test_no_module_imports_from_a_layer_above_its_own():
    command = shutil.which("lint-imports")
    if command is None:
        pytest.fail("lint-imports is missing: install the test extra (pip install '.[test]')")
    result = subprocess.run([command, "--config", str(ROOT / "pyproject.toml")], cwd=ROOT,
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stdout[-3000:]
