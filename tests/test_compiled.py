"""Compiled kernels share one disk-cache stamp covering every module with compiled code."""

import pathlib
import re
import shutil

from rtmesh.core import compiled
from rtmesh.geometry import embree_packets
from rtmesh.shading import kernels

PACKAGE = pathlib.Path(compiled.__file__).parent.parent


def test_every_module_with_kernels_is_stamped():
    with_kernels = {path.relative_to(PACKAGE).as_posix() for path in PACKAGE.rglob("*.py")
                    if re.search(r"^from rtmesh\.core\.compiled import|^import numba|^from numba", path.read_text(), re.M)}
    assert "shading/kernels.py" in with_kernels
    assert with_kernels <= set(compiled.KERNEL_MODULES)


def test_kernels_are_cached_under_the_package_stamp():
    for dispatcher in (kernels.surface_records, embree_packets.intersect_rays):
        locator = dispatcher._cache._impl.locator
        assert locator.get_source_stamp() == compiled.package_stamp()


def test_the_stamp_changes_with_any_kernel_module(tmp_path, monkeypatch):
    for name in compiled.KERNEL_MODULES:
        (tmp_path / name).parent.mkdir(exist_ok=True)
        shutil.copy(PACKAGE / name, tmp_path / name)
    monkeypatch.setattr(compiled, "_PACKAGE", str(tmp_path))
    stamps = []
    for name in compiled.KERNEL_MODULES:
        compiled.package_stamp.cache_clear()
        stamps.append(compiled.package_stamp())
        with open(tmp_path / name, "a") as source:
            source.write("\n# edited\n")
    compiled.package_stamp.cache_clear()
    stamps.append(compiled.package_stamp())
    monkeypatch.undo()
    compiled.package_stamp.cache_clear()
    assert len(set(stamps)) == len(stamps)
