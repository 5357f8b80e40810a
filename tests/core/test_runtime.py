"""Process-wide tuning (rtmesh.core.runtime) is off in the library and on where it is turned on.

``import rtmesh`` and rendering through the library change nothing process-wide (no GIL
switch interval, no kept threads, no allocator setting); a tuned process keeps its render
threads between renders.  The image is the same either way.
"""

import os
import subprocess
import sys
import threading

import numpy as np
import pytest
from scenes import EVERY_STAGE_SETTINGS as SETTINGS
from scenes import DATA, TESTS, every_stage_scene, settings, sphere_on_floor_scene

from rtmesh.core import runtime
from rtmesh.rendering.integrator import Integrator

# Runs in a fresh interpreter: the test process may have been tuned by tests that call
# the command line's main() in-process.
LIBRARY_RENDER = r"""
import sys, threading
sys.path.insert(0, TESTS)
sys.setswitchinterval(0.003)
import rtmesh
from rtmesh.core import runtime
assert sys.getswitchinterval() == 0.003
from scenes import settings, sphere_on_floor_scene
seen = []
def progress(done, total):
    seen.append((sys.getswitchinterval(), sorted(t.name for t in threading.enumerate())))
result = rtmesh.render(sphere_on_floor_scene(), settings(threads=2, width=64, height=48,
                                                         chunk_samples=100), progress)
assert result.stats.threads == 2 and seen
# the render ran on threads of its own, made for it ...
assert any(any(n.startswith("rtmesh-render") for n in names) for _, names in seen), seen
# ... with the caller's switch interval, and left nothing behind
assert all(interval == 0.003 for interval, _ in seen), seen
assert sys.getswitchinterval() == 0.003
assert not any(t.name.startswith("rtmesh-render") for t in threading.enumerate())
assert runtime._pools == {} and not runtime.process_tuned()
assert runtime._keep_freed_memory.cache_info().currsize == 0  # no mallopt
print("ok")
"""


def test_import_and_library_render_change_no_process_state():
    env = dict(os.environ, PYTHONWARNINGS="error::RuntimeWarning")
    code = LIBRARY_RENDER.replace("TESTS", repr(TESTS))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "ok"


@pytest.fixture
def tuned(monkeypatch):
    """This process tuned as the rtmesh command tunes it, untuned again afterwards (the
    allocator setting stays: it changes only the speed)."""
    monkeypatch.setattr(runtime, "_tuned", runtime._tuned)
    runtime.tune_process()


@pytest.fixture
def untuned(monkeypatch):
    monkeypatch.setattr(runtime, "_tuned", False)


def _render_threads():
    return {t for t in threading.enumerate() if t.name.startswith("rtmesh-render")}


def test_a_tuned_process_keeps_its_render_threads_between_renders(tuned):
    assert runtime.process_tuned()
    integrator = Integrator(sphere_on_floor_scene(), settings(threads=2, width=64, height=48,
                                                              chunk_samples=100))
    integrator.render()
    pool = runtime._pools[2]
    workers = _render_threads()
    assert workers and all(t.is_alive() for t in workers)
    integrator.render()
    assert runtime._pools[2] is pool
    assert _render_threads() == workers  # the same threads, none made or ended


def test_an_untuned_render_joins_its_threads_and_keeps_no_pool(untuned):
    before_pools, before_threads = dict(runtime._pools), _render_threads()
    previous = sys.getswitchinterval()
    seen = []

    def progress(done, total):
        seen.append((sys.getswitchinterval(), _render_threads() - before_threads))

    integrator = Integrator(sphere_on_floor_scene(), settings(threads=2, width=64, height=48,
                                                              chunk_samples=100))
    integrator.render(progress)
    assert any(made for _, made in seen)  # threads of its own ...
    assert _render_threads() == before_threads  # ... joined at the end
    assert runtime._pools == before_pools
    assert all(interval == previous for interval, _ in seen) and sys.getswitchinterval() == previous


def test_a_pool_the_caller_passes_is_used_and_left_running(untuned):
    from concurrent.futures import ThreadPoolExecutor

    before_pools = dict(runtime._pools)
    names = set()

    def progress(done, total):
        names.update(t.name for t in threading.enumerate())

    with ThreadPoolExecutor(max_workers=2, thread_name_prefix="caller") as pool:
        integrator = Integrator(sphere_on_floor_scene(), settings(threads=2, width=64, height=48,
                                                                  chunk_samples=100))
        integrator.render(progress, pool=pool)
        assert any(name.startswith("caller") for name in names)
        assert pool.submit(lambda: 7).result(timeout=10) == 7  # not shut down
    assert runtime._pools == before_pools


@pytest.mark.parametrize("mode", ["library", "tuned", "caller pool"])
def test_the_image_does_not_depend_on_the_tuning(request, mode):
    from concurrent.futures import ThreadPoolExecutor

    one = Integrator(every_stage_scene(), settings(threads=1, chunk_samples=50000, **SETTINGS)).render()
    request.getfixturevalue("tuned" if mode == "tuned" else "untuned")
    two = Integrator(every_stage_scene(), settings(threads=2, chunk_samples=700, **SETTINGS))
    if mode == "caller pool":
        with ThreadPoolExecutor(max_workers=3) as pool:
            result = two.render(pool=pool)
    else:
        result = two.render()
    np.testing.assert_array_equal(result.image, one.image)
    np.testing.assert_array_equal(result.passes["ao"], one.passes["ao"])


def test_the_render_command_tunes_its_process(untuned, tmp_path):
    from rtmesh.cli import main

    mesh = os.path.join(DATA, "BoxTextured.glb")
    out = tmp_path / "box.png"
    assert main(["render", mesh, "-o", str(out), "--width", "40", "--height", "30", "--spp", "1",
                 "--threads", "2", "-q"]) == 0
    assert runtime.process_tuned() and 2 in runtime._pools
