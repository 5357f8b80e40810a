"""The fused direct-lighting stage renders exactly what the general wavefront renders."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given
from hypothesis import settings as hypothesis_settings
from hypothesis import strategies as st
from scenes import assert_finite, box, floor_quad, icosphere, part, settings, sphere_on_floor_scene

from rtmesh.geometry import embree_library
from rtmesh.lights.point_lights import DirectionalLight, PointLight, SpotLight
from rtmesh.materials.table import Material
from rtmesh.rendering.integrator import Integrator
from rtmesh.scene.background import GradientBackground
from rtmesh.scene.camera import Camera
from rtmesh.scene.model import Scene
import wavefront

pytestmark = pytest.mark.skipif(embree_library.packet_library() is None,
                                reason="the fused stage traces Embree packets")


def lit_scene(background=None, ambient=None):
    """Smooth and flat meshes, highlights of every kind (none, shininess 0, ordinary, huge),
    a black object that reflects nothing, and one light of each point-like kind.  (An
    emissive material makes its mesh an area light, which the fused stage leaves to the
    general path.)"""
    parts = [part("ball", icosphere(3, 1.0, (0.0, 0.0, 1.0)), 0, smooth=True),
             part("box", box((1.0, 1.0, 1.5), (1.8, 0.5, 0.75)), 1),
             part("floor", floor_quad(6.0), 2),
             part("soot", icosphere(1, 0.3, (-1.5, 1.0, 0.4)), 3)]
    materials = [Material("ball", diffuse=[0.6, 0.3, 0.2], specular=0.5, shininess=40.0),
                 Material("box", diffuse=0.5, specular=[0.2, 0.4, 0.6], shininess=0.0),
                 Material("floor", diffuse=0.5, specular=0.3, shininess=5000.0),
                 Material("soot", diffuse=0.0, ambient=[0.3, 0.2, 0.1])]
    lights = [PointLight([2.0, -1.0, 6.0], 30.0),
              DirectionalLight([-0.3, 0.4, -1.0], [0.4, 0.5, 0.6]),
              SpotLight([-2.0, -3.0, 4.0], [0.4, 0.6, -0.7], [40.0, 30.0, 20.0], 10.0, 25.0)]
    camera = Camera([0.5, -6.0, 4.0], [0.3, 0.0, 0.6], [0.0, 0.0, 1.0], 45.0)
    return Scene.from_parts(parts, materials, lights, camera, ambient=ambient, background=background)


def render_both(scene, **overrides):
    fused = Integrator(scene, settings(**overrides))
    assert fused.direct_stage is not None
    general = Integrator(scene, settings(**overrides))
    general.direct_stage = None
    wavefront.attach(general)
    a, b = fused.render(), general.render()
    assert_finite(a)
    return a, b


def assert_same(a, b):
    np.testing.assert_array_equal(a.image, b.image)
    assert a.stats.rays == b.stats.rays
    assert a.stats.samples == b.stats.samples


@pytest.mark.parametrize("sampler", ["regular", "random", "jittered", "sobol", "zsobol"])
@pytest.mark.parametrize("spp", [1, 3])
def test_fused_stage_matches_the_general_path(sampler, spp):
    a, b = render_both(lit_scene(), width=37, height=29, spp=spp, sampler=sampler)
    assert_same(a, b)
    assert a.image.max() > 0.1  # lit, not a black frame


@pytest.mark.parametrize("sampler", ["jittered", "sobol", "zsobol"])
def test_a_thin_lens_renders_as_the_general_path(sampler):
    """A thin lens's rays leave the aperture points the integrator hands the stage, for the
    plane of focus: the general path's image and ray counts to the bit, and blurred away
    from that plane (a pinhole's image differs)."""
    import dataclasses

    scene = lit_scene()
    pinhole = Integrator(scene, settings(width=31, height=23, spp=4, sampler=sampler)).render()
    scene.camera = dataclasses.replace(scene.camera, aperture=0.6, focus_distance=4.0)
    a, b = render_both(scene, width=31, height=23, spp=4, sampler=sampler)
    assert_same(a, b)
    assert not np.array_equal(a.image, pinhole.image)


def test_ambient_and_a_solid_background():
    scene = lit_scene(background=[0.2, 0.3, 0.4], ambient=[0.05, 0.1, 0.02])
    a, b = render_both(scene, width=40, height=30, spp=2)
    assert_same(a, b)
    assert (a.image[0, 0] > 0).all()  # the corner sees the background


def test_adaptive_rounds():
    a, b = render_both(lit_scene(), width=24, height=20, spp=2, target_error=0.02, max_spp=32)
    assert_same(a, b)
    assert len(a.stats.rounds) > 1


def test_thread_count_does_not_change_the_image():
    scene = sphere_on_floor_scene(smooth=True)
    one = Integrator(scene, settings(width=64, height=48, spp=2, threads=1)).render()
    two = Integrator(scene, settings(width=64, height=48, spp=2, threads=2, chunk_samples=1000)).render()
    np.testing.assert_array_equal(one.image, two.image)


def assert_same_film(a, b):
    """The film's sums, squares and counts, not only the image: the fused stage adds its
    samples to the film itself."""
    for name in ("sum", "sum_sq", "count"):
        np.testing.assert_array_equal(getattr(a.film, name), getattr(b.film, name))


@pytest.mark.parametrize("highlights", [True, False])
@pytest.mark.parametrize("overrides", [dict(spp=3, sampler="jittered"), dict(spp=1, sampler="sobol"),
                                       dict(spp=2, target_error=0.02, max_spp=16),
                                       dict(spp=5, threads=2, chunk_samples=70)])
def test_the_film_the_fused_stage_adds_to_is_the_general_paths(highlights, overrides):
    """The kernel adds each sample to its pixel's film sums as it forms it, with highlights
    (raised in the kernel) or without; chunks of 70 samples at 5 spp: pixels straddle blocks
    (their sums carried from one block to the next) and chunks end inside blocks."""
    scene = lit_scene() if highlights else sphere_on_floor_scene(smooth=True)
    a, b = render_both(scene, width=23, height=17, **overrides)
    assert_same(a, b)
    assert_same_film(a, b)


def test_scenes_needing_more_take_the_general_path():
    scene = lit_scene()
    assert Integrator(scene, settings()).plan.fused_direct
    assert Integrator(scene, settings(passes=("depth",))).direct_stage is None
    # ambient occlusion only where there is ambient light to occlude
    assert Integrator(scene, settings(ao_samples=2)).direct_stage is not None
    assert Integrator(lit_scene(ambient=[0.1, 0.1, 0.1]), settings(ao_samples=2)).direct_stage is None
    gradient = lit_scene(background=GradientBackground([0.1, 0.1, 0.1], [0.5, 0.6, 0.9]))
    assert Integrator(gradient, settings()).direct_stage is None
    lamp = lit_scene()
    lamp.materials = type(lamp.materials)(
        [Material("ball", emission=1.0), Material("box"), Material("floor"), Material("soot")])
    assert Integrator(lamp, settings()).direct_stage is None  # an emissive mesh is an area light
    mirror = lit_scene()
    mirror.materials = type(mirror.materials)(
        [Material("ball", diffuse=0.2, mirror=0.5), Material("box"), Material("floor"), Material("soot")])
    assert Integrator(mirror, settings()).direct_stage is None
    # a mirror with no bounces left renders direct light only
    assert Integrator(mirror, settings(max_depth=0)).direct_stage is not None


# ---------------------------------------------------------------- random scenes
LIGHT_KINDS = {"point": lambda i: PointLight([2.0 - i, -1.0, 5.0], [30.0, 20.0, 10.0 + i]),
               "directional": lambda i: DirectionalLight([-0.3, 0.4 + 0.1 * i, -1.0], 0.5),
               "spot": lambda i: SpotLight([-2.0, -3.0, 4.0 + i], [0.4, 0.6, -0.7], 40.0, 10.0, 25.0 + i)}
SHININESS = (-1.0, 0.0, 7.5, 40.0, 5000.0)  # -1: no highlight


fused_cases = st.fixed_dictionaries({
    "lights": st.lists(st.sampled_from(sorted(LIGHT_KINDS)), min_size=1, max_size=3),
    "shininess": st.lists(st.sampled_from(SHININESS), min_size=3, max_size=3),
    "smooth": st.booleans(),
    "ambient": st.sampled_from([None, [0.05, 0.1, 0.02]]),
    "background": st.sampled_from([None, [0.2, 0.3, 0.4]]),
    "spp": st.integers(1, 20),
    "sampler": st.sampled_from(["regular", "random", "jittered", "sobol", "zsobol"]),
    "chunk_samples": st.integers(1, 300),
    "threads": st.sampled_from([1, 2]),
    "seed": st.integers(0, 3),
    "adaptive": st.booleans(),
    "aperture": st.sampled_from([0.0, 0.0, 0.5]),  # a pinhole, or a thin lens
})


def check_fused_case(case):
    """A scene the fused stage takes (point-like lights of the kinds drawn, materials with
    and without highlights, ambient and a solid background or not) rendered with settings
    that move block, pixel and chunk boundaries (spp, chunk size, threads, sampler, rounds),
    through a pinhole or a thin lens."""
    materials = [Material(f"m{i}", diffuse=0.5, specular=0.0 if s < 0 else 0.4, shininess=max(s, 0.0))
                 for i, s in enumerate(case["shininess"])]
    parts = [part("ball", icosphere(2, 1.0, (0.0, 0.0, 1.0)), 0, smooth=case["smooth"]),
             part("box", box((1.0, 1.0, 1.5), (1.8, 0.5, 0.75)), 1),
             part("floor", floor_quad(6.0), 2)]
    camera = Camera([0.5, -6.0, 4.0], [0.3, 0.0, 0.6], [0.0, 0.0, 1.0], 45.0, aperture=case["aperture"])
    scene = Scene.from_parts(parts, materials, [LIGHT_KINDS[k](i) for i, k in enumerate(case["lights"])],
                             camera, ambient=case["ambient"], background=case["background"])
    overrides = {name: case[name] for name in ("spp", "sampler", "chunk_samples", "threads", "seed")}
    if case["adaptive"]:  # an error estimate needs two samples a pixel
        overrides.update(spp=max(2, case["spp"]), target_error=0.05, max_spp=2 * case["spp"] + 8)
    a, b = render_both(scene, width=19, height=13, **overrides)
    assert_same(a, b)
    assert_same_film(a, b)


# derandomized, without an example database: every run draws the same scenes
@hypothesis_settings(max_examples=12, deadline=None, derandomize=True, database=None,
                     suppress_health_check=[HealthCheck.too_slow])
@given(fused_cases)
def test_random_scenes_render_alike_on_both_paths(case):
    """Any scene and settings the fused stage takes give the general path's image, ray
    counts and film sums to the bit."""
    check_fused_case(case)


@pytest.mark.slow
@hypothesis_settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(fused_cases)
def test_random_scenes_render_alike_on_both_paths_many(case):
    check_fused_case(case)
