"""Compiled kernels share one disk-cache stamp covering every module with compiled code; a
kernel called by its entry point runs only for its signature."""

import math
import pathlib
import re
import shutil

import numba
import numpy as np

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


@numba.njit
def _add_scaled(out, pair, k):
    x, y = pair
    for i in range(len(out)):
        out[i] += x[i] * y[i] + k


@numba.njit
def _call_twice(address, token, out, pair, k):
    called = compiled.call_at(address, token, (out, pair, k))
    called &= compiled.call_at(address, token, (out, pair, k))
    return called


def test_a_kernel_called_at_its_entry_point_runs_only_with_its_signature_token():
    out, pair = np.zeros(3), (np.arange(3.0), np.full(3, 2.0))
    signature = (numba.typeof(out), numba.typeof(pair), numba.types.int64)
    address, token = compiled.entry_point(_add_scaled, signature)
    assert token == compiled.signature_token(signature)
    assert _call_twice(address, token, out, pair, 1)
    np.testing.assert_array_equal(out, 2 * (np.arange(3.0) * 2.0 + 1))
    # a token for other types: nothing is called
    other = compiled.signature_token((numba.typeof(out), numba.typeof(pair), numba.types.float64))
    assert not _call_twice(address, other, out, pair, 1)
    np.testing.assert_array_equal(out, 2 * (np.arange(3.0) * 2.0 + 1))


@compiled.row
def _offset(base, k):
    return base * 16 + k


@compiled.row
def _item(record, k):
    return record[k]  # a heterogeneous tuple: typed only with k's value


@numba.njit
def _constants(base):
    record = (1.5, 7)
    return _offset(base, 3) + _offset(base, 9) + _offset(base, 17), _item(record, 0) + _item(record, 1)


def test_a_row_called_with_constants_compiles_once_for_their_type():
    # numba compiles a callee once per constant argument it is passed; a row is compiled
    # for the types (one compile), unless it needs the value (a tuple's index: one each)
    assert _constants(2) == (3 * 32 + 3 + 9 + 17, 8.5)
    assert [tuple(map(str, s)) for s in _offset.signatures] == [("int64", "int64")]
    assert len(_item.signatures) == 2


def _bulky(x):
    # enough libm calls and branches that LLVM's own measure keeps it a call
    s = 0.0
    for k in range(4):
        s += math.sin(x + k) * math.exp(-x * k) + math.atan2(x, k + 1.0) * math.sqrt(x * x + k)
        if s > 10.0:
            s = math.log(s) + math.cos(s)
    return s


_inlined = compiled.inline_row(_bulky)
_called = compiled.row(_bulky)


@numba.njit
def _use_inlined(xs, out):
    for i in range(len(xs)):
        out[i] = _inlined(xs[i]) + _inlined(xs[i] * 2.0)


@numba.njit
def _use_called(xs, out):
    for i in range(len(xs)):
        out[i] = _called(xs[i]) + _called(xs[i] * 2.0)


def _mentions(caller, row):
    """How often the caller's machine code names the row's function (its calls)."""
    (signature,) = row.signatures
    return caller.inspect_asm(caller.signatures[0]).count(row.overloads[signature].fndesc.llvm_func_name)


def test_an_inline_row_is_compiled_once_and_inlined_by_llvm_into_each_call():
    xs = np.linspace(0.0, 3.0, 7)
    inlined, called = np.zeros(7), np.zeros(7)
    _use_inlined(xs, inlined)
    _use_called(xs, called)
    np.testing.assert_array_equal(inlined, called)
    # one compile for both call sites (numba's own inlining types a copy at each), and no
    # call left in the caller, where the same row as a plain row stays a call
    assert len(_inlined.signatures) == 1
    assert _mentions(_use_inlined, _inlined) == 0
    assert _mentions(_use_called, _called) > 0
