"""Compiled kernels share one disk-cache stamp covering every module with compiled code."""

import pathlib
import re
import shutil

from rtmesh.core import compiled
from rtmesh.geometry import embree_packets
from rtmesh.shading import surfaces

PACKAGE = pathlib.Path(compiled.__file__).parent.parent


def test_every_module_with_kernels_is_stamped():
    jitted = {path.relative_to(PACKAGE).as_posix() for path in PACKAGE.rglob("*.py")
              if "__pycache__" not in path.parts and re.search(r"@(kernel|row|cached|numba\.njit)\b", path.read_text())}
    assert {"shading/surfaces.py", "geometry/embree_packets.py", "lights/point_light_rows.py"} <= jitted
    assert jitted <= set(compiled.kernel_modules())


def test_a_new_module_with_kernels_joins_the_stamp_without_a_list(tmp_path):
    (tmp_path / "lights").mkdir()
    (tmp_path / "lights" / "plain.py").write_text("import numpy\n")
    (tmp_path / "lights" / "projector.py").write_text("from rtmesh.core.compiled import kernel, row\n")
    assert compiled.kernel_modules(str(tmp_path)) == ("lights/projector.py",)


def test_kernels_are_cached_under_the_package_stamp():
    for dispatcher in (surfaces.surface_records, embree_packets.intersect_rays):
        locator = dispatcher._cache._impl.locator
        assert locator.get_source_stamp() == compiled.package_stamp()


def test_the_stamp_changes_with_any_kernel_module(tmp_path, monkeypatch):
    modules = compiled.kernel_modules()
    for name in modules:
        (tmp_path / name).parent.mkdir(exist_ok=True)
        shutil.copy(PACKAGE / name, tmp_path / name)
    monkeypatch.setattr(compiled, "_PACKAGE", str(tmp_path))
    stamps = []
    for name in modules:
        compiled.package_stamp.cache_clear()
        stamps.append(compiled.package_stamp())
        with open(tmp_path / name, "a") as source:
            source.write("\n# edited\n")
    compiled.package_stamp.cache_clear()
    stamps.append(compiled.package_stamp())
    monkeypatch.undo()
    compiled.package_stamp.cache_clear()
    assert len(set(stamps)) == len(stamps)
