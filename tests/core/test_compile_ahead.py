"""Kernel groups compiled ahead by a helper process on a first run (rtmesh.core.compile_ahead)."""

import fcntl
import logging
import os
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from numba import types
import scenes

import rtmesh
from rtmesh.core import compile_ahead
from rtmesh.core.compiled import kernel
from rtmesh.geometry import embree_packets
from rtmesh.geometry.build_kernels import BUILD_KERNELS
from rtmesh.io.images import read_image
from rtmesh.rendering.direct_stage import FUSED_KERNELS
from wavefront.kernels import GENERAL_KERNELS

ASSETS = scenes.ASSETS
PACKAGE_PARENT = os.path.dirname(os.path.dirname(os.path.abspath(rtmesh.__file__)))


@kernel
def _twice(x):
    return 2.0 * x


def test_renders_call_the_declared_kernels_with_the_declared_types():
    # a declared type that a render does not use would have the helper compile a version
    # nobody calls, while the render compiles its own
    from rtmesh.rendering.path_signatures import PATH_KERNELS

    groups = (BUILD_KERNELS, FUSED_KERNELS, GENERAL_KERNELS, embree_packets.QUERY_KERNELS, PATH_KERNELS)
    for group in groups:
        for dispatcher, signature in group.kernels:
            compile_ahead.compile_locked(dispatcher, signature)
    before = {id(d): len(d.signatures) for group in groups for d, _ in group.kernels}
    for spp in (1, 3):
        general = rtmesh.render(os.path.join(ASSETS, "showcase.toml"), width=40, height=30, spp=spp)
        fused = rtmesh.render(os.path.join(ASSETS, "meshes", "bunny.ply"), width=40, height=30, spp=spp)
    assert "fused_direct" not in general.stats.stages_enabled and "fused_direct" in fused.stats.stages_enabled
    after = {id(d): len(d.signatures) for group in groups for d, _ in group.kernels}
    grew = [d.py_func.__qualname__ for group in groups for d, _ in group.kernels if after[id(d)] != before[id(d)]]
    assert grew == []
    assert np.isfinite(general.image).all() and np.isfinite(fused.image).all()


def test_a_path_render_of_one_ray_calls_the_path_kernel_with_the_declared_types():
    # a chunk of one camera ray (its origins a read-only repeated row that NumPy calls
    # contiguous) once compiled the path kernel a second time, a minute of a first run
    from rtmesh.rendering.path_signatures import PATH_KERNELS

    for dispatcher, signature in PATH_KERNELS.kernels:
        compile_ahead.compile_locked(dispatcher, signature)
    before = {id(d): len(d.signatures) for d, _ in PATH_KERNELS.kernels}
    for width in (1, 3):
        result = rtmesh.render(os.path.join(ASSETS, "cornell_box.toml"), width=width, height=1, spp=1,
                               integrator="path")
        assert np.isfinite(result.image).all()
    grew = [d.py_func.__qualname__ for d, _ in PATH_KERNELS.kernels if len(d.signatures) != before[id(d)]]
    assert grew == []


def test_groups_have_unique_names_and_every_render_starts_with_the_build():
    assert BUILD_KERNELS.every_render
    assert not FUSED_KERNELS.every_render and not GENERAL_KERNELS.every_render
    with pytest.raises(ValueError, match="declared twice"):
        compile_ahead.KernelGroup(__name__, BUILD_KERNELS.name, [])


def _cached_in(cache_dir, module, group, path=()):
    """Whether ``group`` of ``module`` is in the disk cache at ``cache_dir`` (asked of a
    fresh process, which reads NUMBA_CACHE_DIR when numba is imported; ``path``: more
    folders to import from)."""
    code = f"import {module} as m, sys; from rtmesh.core import compile_ahead as c; " \
           f"sys.exit(0 if c._GROUPS[{group!r}].cached() else 3)"
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir), PYTHONPATH=os.pathsep.join([PACKAGE_PARENT, *map(str, path)]))
    return subprocess.run([sys.executable, "-c", code], env=env).returncode == 0


# a group of one small kernel in a module of its own, for the helper process to import
# and compile (a real group would cost the test several seconds of compiling)
TINY_GROUP = """
from numba import types
from rtmesh.core.compile_ahead import KernelGroup
from rtmesh.core.compiled import kernel

@kernel
def halve(x):
    return 0.5 * x

GROUP = KernelGroup(__name__, "test: tiny", [(halve, (types.float64,))])
"""


def test_the_helper_compiles_an_announced_group_into_the_shared_disk_cache(tmp_path):
    modules, cache = tmp_path / "modules", tmp_path / "cache"
    modules.mkdir()
    (modules / "tiny_group.py").write_text(TINY_GROUP)
    assert not _cached_in(cache, "tiny_group", "test: tiny", [modules])
    # started in a folder with another rtmesh (as `rtmesh render` run in the source tree
    # that `pip install .` installed from), the helper still imports this one
    (tmp_path / "rtmesh").mkdir()
    (tmp_path / "rtmesh" / "__init__.py").write_text("raise ImportError('the helper imported the wrong rtmesh')\n")
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), PYTHONPATH=str(modules))
    # what the render writes when it prepares the group; end of input ends the helper
    done = subprocess.run(compile_ahead.helper_command(), env=env, cwd=tmp_path, timeout=300,
                          input="tiny_group\ttest: tiny\n", text=True)
    assert done.returncode == 0
    assert _cached_in(cache, "tiny_group", "test: tiny", [modules])


def test_a_kernel_being_compiled_by_the_other_process_is_waited_for():
    signature = (types.float64,)
    lock_path = os.path.join(_twice._cache._cache_path, f"{__name__}._twice.compiling")
    os.makedirs(os.path.dirname(lock_path), exist_ok=True)
    with open(lock_path, "a") as held:
        fcntl.flock(held, fcntl.LOCK_EX)  # as the helper holds it while compiling
        waiter = threading.Thread(target=compile_ahead.compile_locked, args=(_twice, signature))
        waiter.start()
        time.sleep(0.3)
        assert waiter.is_alive() and signature not in _twice.overloads
        fcntl.flock(held, fcntl.LOCK_UN)
    waiter.join(timeout=120)
    assert not waiter.is_alive() and signature in _twice.overloads
    assert _twice(1.5) == 3.0


# run in a process of its own with an empty disk cache: ``outer``'s typing compiles
# ``inner`` (numba starts that compile, not rtmesh); it must wait for inner's lock file,
# held here on another file descriptor as another process would hold it while compiling
NESTED_COMPILE = """
import fcntl, os, sys, threading, time
from numba import types
from rtmesh.core.compiled import kernel

@kernel
def inner(x):
    return x + 1.0

@kernel
def outer(x):
    return 2.0 * inner(x)

signature = (types.float64,)
os.makedirs(inner._cache._cache_path, exist_ok=True)
lock_path = os.path.join(inner._cache._cache_path, __name__ + ".inner.compiling")
with open(lock_path, "a") as held:
    fcntl.flock(held, fcntl.LOCK_EX)
    waiter = threading.Thread(target=outer.compile, args=(signature,))
    waiter.start()
    time.sleep(0.5)
    assert waiter.is_alive() and signature not in inner.overloads, "inner compiled beside the lock"
    fcntl.flock(held, fcntl.LOCK_UN)
waiter.join(timeout=120)
assert not waiter.is_alive() and signature in inner.overloads
assert outer(1.5) == 5.0
"""


def test_a_kernel_that_another_calls_is_compiled_under_its_lock_file_too(tmp_path):
    script = tmp_path / "nested.py"
    script.write_text(NESTED_COMPILE)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), PYTHONPATH=PACKAGE_PARENT)
    done = subprocess.run([sys.executable, str(script)], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]


def test_without_a_helper_prepare_compiles_under_the_lock_and_starts_no_process(monkeypatch):
    # outside the test session's own helper block (tests/conftest.py): a group the cache
    # lacks is compiled under its lock files (a process compiling it meanwhile is waited
    # for), and no helper process starts
    monkeypatch.setattr(compile_ahead, "_enabled", False)
    monkeypatch.setattr(compile_ahead, "_helper", None)
    started, locked = [], []
    monkeypatch.setattr(compile_ahead, "_start", lambda: started.append(1))
    original_lock = compile_ahead._kernel_lock
    monkeypatch.setattr(compile_ahead, "_kernel_lock", lambda d: locked.append(d) or original_lock(d))
    group = compile_ahead.KernelGroup(__name__, "test: prepared without a helper", [(_twice, (types.int16,))])
    try:
        monkeypatch.setattr(group, "cached", lambda: True)
        group.prepare()  # cached: the kernels load on their first call
        assert (types.int16,) not in _twice.overloads and locked == []
        group._prepared = False
        monkeypatch.setattr(group, "cached", lambda: False)
        with compile_ahead.helper(enabled=False):
            group.prepare()
            group.prepare()  # once a process
        assert (types.int16,) in _twice.overloads and locked == [_twice] and not started
    finally:
        del compile_ahead._GROUPS[group.name]


def test_prepare_logs_each_group_it_compiles_and_nothing_for_a_cached_one(monkeypatch, caplog):
    # (the rtmesh command turns the first such record into one line for a user at a terminal)
    monkeypatch.setattr(compile_ahead, "_enabled", False)
    group = compile_ahead.KernelGroup(__name__, "test: logged", [(_twice, (types.uint8,))])
    try:
        with caplog.at_level(logging.INFO, logger=compile_ahead.__name__):
            monkeypatch.setattr(group, "cached", lambda: True)
            group.prepare()
            assert caplog.records == []
            group._prepared = False
            monkeypatch.setattr(group, "cached", lambda: False)
            with compile_ahead.helper(enabled=False):
                group.prepare()
        assert [r.getMessage() for r in caplog.records] == ["compiling the test: logged kernels for this machine"]
    finally:
        del compile_ahead._GROUPS[group.name]


def test_a_first_run_is_a_render_group_the_disk_cache_lacks(monkeypatch):
    every = [group for group in compile_ahead._GROUPS.values() if group.every_render]
    assert every  # the scene build's group
    for cached in (True, False):
        for group in every:
            monkeypatch.setattr(group, "cached", lambda cached=cached: cached)
        assert compile_ahead.first_run() is (not cached)


@pytest.mark.slow
def test_a_first_run_with_the_helper_renders_what_a_later_run_renders(tmp_path):
    # the command line from an empty cache: the helper compiles half of the build and
    # fused-stage groups, and the image is the one a run with everything cached gives
    # (slow: two processes compile a third of the kernels again, about 40 s of CPU; the
    # default suite covers the parts: the helper filling a cache from an announced group,
    # a kernel's lock waited for, the declared types that renders call)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), PYTHONPATH=PACKAGE_PARENT)
    code = "import sys; from rtmesh.cli import main; sys.exit(main())"
    images = []
    for name in ("first.exr", "later.exr"):
        out = tmp_path / name
        subprocess.run([sys.executable, "-c", code, "render", os.path.join(ASSETS, "meshes", "bunny.ply"),
                        "-o", str(out), "--width", "32", "--height", "24", "--spp", "2", "-q"],
                       env=env, check=True, timeout=300, stdout=subprocess.DEVNULL)
        images.append(read_image(str(out))[0])
        if name == "first.exr":
            # the render took each kernel's lock file while it compiled its half
            assert any(path.suffix == ".compiling" for path in (tmp_path / "cache").rglob("*"))
    assert np.array_equal(images[0], images[1])



def test_a_dask_workers_warm_up_runs_inside_a_helper_block(monkeypatch):
    """The first worker's warm-up on a host (its first compile) is where a helper process
    saves the most: the task runs it inside compile_ahead.helper()."""
    import contextlib

    from rtmesh.batch import dask_pool
    from rtmesh.core import runtime

    events = []

    @contextlib.contextmanager
    def recording_helper(enabled=True):
        events.append("helper on")
        yield
        events.append("helper off")

    monkeypatch.setattr(compile_ahead, "helper", recording_helper)
    monkeypatch.setattr(runtime, "tune_process", lambda: None)
    monkeypatch.setattr(dask_pool, "warm_up", lambda: events.append("warm up"))
    dask_pool._warm_up_task()
    assert events == ["helper on", "warm up", "helper off"]


def test_a_group_compiled_ahead_is_announced_only_within_a_helper_and_while_not_cached(monkeypatch):
    announced = []
    monkeypatch.setattr(compile_ahead, "_announce", announced.append)
    group = compile_ahead.KernelGroup(__name__, "test: compiled ahead", [(_twice, (types.complex128,))])
    try:
        monkeypatch.setattr(compile_ahead, "_enabled", False)
        group.compile_ahead()  # outside helper(): nothing
        assert announced == []
        monkeypatch.setattr(compile_ahead, "_enabled", True)
        monkeypatch.setattr(group, "cached", lambda: True)
        group.compile_ahead()
        assert announced == []
        monkeypatch.setattr(group, "cached", lambda: False)
        group.compile_ahead()
        assert announced == [group] and (types.complex128,) not in _twice.overloads
    finally:
        del compile_ahead._GROUPS[group.name]
