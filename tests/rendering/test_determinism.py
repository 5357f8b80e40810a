"""Renders are bit-identical whatever the thread count and chunk size; the seed decides."""

import numpy as np
import pytest
from scenes import EVERY_STAGE_SETTINGS as SETTINGS
from scenes import every_stage_scene, render


@pytest.fixture(scope="module")
def reference():
    return render(every_stage_scene(), threads=1, chunk_samples=50000, **SETTINGS)


def test_reference_render_runs_every_stage(reference):
    stages = set(reference.stats.stages_enabled)
    for stage in ("ambient", "lights", "specular", "smooth_normals", "reflection", "refraction",
                  "absorption", "background", "ao"):
        assert stage in stages, stage
    for kind in ("camera", "shadow", "reflection", "refraction", "ao"):
        assert reference.stats.rays[kind] > 0, kind


@pytest.mark.parametrize("threads, chunk_samples", [(1, 1000), (2, 1000), (2, 50000), (2, 333), (2, 1)])
def test_image_is_bit_identical_for_any_threads_and_chunk_size(reference, threads, chunk_samples):
    if chunk_samples == 1:
        # one pixel per chunk: same answer, only slower; keep the image small
        settings = dict(SETTINGS, width=12, height=9)
        reference = render(every_stage_scene(), threads=1, chunk_samples=50000, **settings)
    else:
        settings = SETTINGS
    result = render(every_stage_scene(), threads=threads, chunk_samples=chunk_samples, **settings)
    np.testing.assert_array_equal(result.image, reference.image)
    np.testing.assert_array_equal(result.passes["ao"], reference.passes["ao"])
    np.testing.assert_array_equal(result.film.sum_sq, reference.film.sum_sq)
    assert result.stats.rays == reference.stats.rays
    assert result.stats.relative_error == reference.stats.relative_error


def test_thin_lens_render_is_bit_identical_across_threads():
    one = render(every_stage_scene(aperture=0.2), threads=1, chunk_samples=50000, **SETTINGS)
    two = render(every_stage_scene(aperture=0.2), threads=2, chunk_samples=700, **SETTINGS)
    np.testing.assert_array_equal(one.image, two.image)
    assert "lens" in one.stats.stages_enabled


def test_same_seed_gives_the_same_image(reference):
    again = render(every_stage_scene(), threads=1, chunk_samples=50000, **SETTINGS)
    np.testing.assert_array_equal(again.image, reference.image)


def test_different_seed_gives_a_different_image(reference):
    settings = dict(SETTINGS, seed=8)
    other = render(every_stage_scene(), threads=1, chunk_samples=50000, **settings)
    assert not np.array_equal(other.image, reference.image)
    # jitter and AO noise differ in most pixels, yet the two estimate the same image
    differing = np.any(other.image != reference.image, axis=2)
    assert differing.mean() > 0.5
    assert abs(float(other.image.mean() - reference.image.mean())) < 0.02 * float(reference.image.mean())


def test_regular_sampler_without_ao_ignores_the_seed():
    # nothing random remains: the seed must not change a single pixel
    settings = dict(width=32, height=24, spp=4, sampler="regular", max_depth=4)
    first = render(every_stage_scene(), seed=1, **settings)
    second = render(every_stage_scene(), seed=2, **settings)
    np.testing.assert_array_equal(first.image, second.image)


def test_renders_on_threads_restore_the_gil_switch_interval_even_side_by_side(monkeypatch):
    """In a tuned process multi-threaded renders shorten the (process-wide) GIL switch
    interval while they run and leave the caller's value behind, also when two run at once
    from two threads."""
    import sys
    import threading

    from scenes import settings, sphere_on_floor_scene

    from rtmesh.core import runtime
    from rtmesh.rendering.integrator import Integrator

    monkeypatch.setattr(runtime, "_tuned", runtime._tuned)  # untuned again afterwards
    runtime.tune_process()
    scene = sphere_on_floor_scene()
    previous = sys.getswitchinterval()
    seen = []

    def progress(done, total):
        seen.append(sys.getswitchinterval())

    try:
        sys.setswitchinterval(0.004)
        integrator = Integrator(scene, settings(threads=2, width=64, height=48))
        threads = [threading.Thread(target=integrator.render, args=(progress,)) for _ in range(2)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert seen and max(seen) <= runtime.RENDER_SWITCH_INTERVAL + 1e-12
        assert sys.getswitchinterval() == pytest.approx(0.004)
    finally:
        sys.setswitchinterval(previous)


def test_progress_on_threads_counts_up_to_every_chunk():
    from scenes import settings, sphere_on_floor_scene

    from rtmesh.rendering.integrator import Integrator

    seen = []
    integrator = Integrator(sphere_on_floor_scene(), settings(threads=2, width=64, height=48, chunk_samples=300))
    integrator.render(lambda done, total: seen.append((done, total)))
    totals = {total for _, total in seen}
    assert len(totals) == 1 and totals.pop() > 2
    assert seen[-1][0] == seen[-1][1]
    assert all(a[0] < b[0] for a, b in zip(seen, seen[1:]))


def test_a_failing_chunk_on_threads_raises_and_stops_the_other_workers(monkeypatch):
    from scenes import settings, sphere_on_floor_scene

    from rtmesh.rendering.integrator import Integrator

    integrator = Integrator(sphere_on_floor_scene(), settings(threads=2, width=64, height=48, chunk_samples=64))
    started = []
    render_chunk = Integrator.render_chunk

    def failing(self, pixels, first_sample, spp, film=None):
        started.append(len(pixels))
        if len(started) == 3:
            raise RuntimeError("chunk failed")
        return render_chunk(self, pixels, first_sample, spp, film)

    monkeypatch.setattr(Integrator, "render_chunk", failing)
    with pytest.raises(RuntimeError, match="chunk failed"):
        integrator.render()
    # 48 chunks: after the failure each worker finishes at most the chunk it is on
    assert len(started) <= 4


def test_kept_render_threads_are_made_anew_in_a_forked_child():
    import os

    from rtmesh.core import runtime

    pool = runtime._kept_pool(2)
    assert runtime._kept_pool(2) is pool
    assert pool.submit(lambda: 7).result(timeout=10) == 7
    child = os.fork()
    if child == 0:  # the child has none of the parent's threads: its pool must be new
        try:
            fresh = runtime._kept_pool(2)
            ok = fresh is not pool and fresh.submit(lambda: 7).result(timeout=10) == 7
        except BaseException:
            ok = False
        os._exit(0 if ok else 1)
    _, status = os.waitpid(child, 0)
    assert os.waitstatus_to_exitcode(status) == 0


def test_chunks_are_the_same_for_every_thread_count(monkeypatch):
    """Where two coplanar overlapping triangles are hit at exactly the same distance,
    Embree's packet traversal may report either, depending on the other rays of the packet,
    which come from the ray's chunk: the chunks must not depend on the thread count (see
    rtmesh.rendering.scheduler)."""
    from rtmesh.rendering.integrator import Integrator
    seen = {}
    real = Integrator.render_chunk

    def recording(self, pixels, first_sample, spp, film=None):
        seen[self.settings.thread_count].append((int(pixels[0]), len(pixels)))
        return real(self, pixels, first_sample, spp, film)

    monkeypatch.setattr(Integrator, "render_chunk", recording)
    for threads in (1, 2):
        seen[threads] = []
        # 96 x 72 x 3 samples: more than the smallest guided chunk, so the schedule has a tail
        render(every_stage_scene(), threads=threads, width=96, height=72, spp=3)
    assert len(seen[1]) > 2
    assert sorted(seen[1]) == sorted(seen[2])
