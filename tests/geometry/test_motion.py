"""Motion blur: rigid object motion over the shutter, traced at each ray's time."""

import dataclasses

import numpy as np
import pytest
from scenes import box, floor_quad, icosphere, part, quad, render

from rtmesh.core.errors import SceneError
from rtmesh.geometry.accel import Accel
from rtmesh.geometry.motion import Motion, MotionAccel, rotate, scene_at_time
from rtmesh.lights.area_lights import QuadLight
from rtmesh.lights.point_lights import PointLight
from rtmesh.loaders.scene_file import scene_from_dict
from rtmesh.materials.table import Material
from rtmesh.sampling.patterns import Dim, shuffled_strata, stratified_values
from rtmesh.scene.camera import Camera
from rtmesh.scene.model import Scene


# ---------------------------------------------------------------- the transforms
def test_rays_to_rest_keep_every_point_at_the_same_distance_along_the_ray():
    # a point t along a world ray at time tau is, in the rest frame, t along the rest ray
    rng = np.random.default_rng(2)
    motion = Motion([0.5, -1.0, 2.0], [0.3, -0.5, 0.8], 70.0, centre=np.array([1.0, 2.0, 3.0]))
    origins, directions = rng.normal(size=(40, 3)), rng.normal(size=(40, 3))
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    time, t = rng.uniform(0.0, 1.0, 40), rng.uniform(0.0, 5.0, 40)
    o, d = motion.rays_to_rest(origins, directions, time)
    np.testing.assert_allclose(o + t[:, None] * d,
                               motion.to_rest(origins + t[:, None] * directions, time), atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-12)


def test_rotate_matches_the_rotation_matrix_and_motion_inverts_exactly():
    rng = np.random.default_rng(1)
    axis = np.array([0.3, -0.5, 0.8])
    axis /= np.linalg.norm(axis)
    angle = rng.uniform(-3.0, 3.0, 50)
    v = rng.normal(size=(50, 3))
    rotated = rotate(v, axis, angle)
    for i in range(50):
        # the matrix form of Rodrigues' formula, written independently
        k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        matrix = np.eye(3) + np.sin(angle[i]) * k + (1 - np.cos(angle[i])) * k @ k
        np.testing.assert_allclose(rotated[i], matrix @ v[i], atol=1e-12)
    motion = Motion([0.5, -1.0, 2.0], axis, 70.0, centre=np.array([1.0, 2.0, 3.0]))
    time = rng.uniform(0.0, 1.0, 50)
    world = motion.to_world(v, time)
    np.testing.assert_allclose(motion.to_rest(world, time), v, atol=1e-12)
    # the centre moves by the translation alone, distances are preserved
    np.testing.assert_allclose(motion.to_world(np.tile(motion.centre, (50, 1)), time),
                               motion.centre + time[:, None] * motion.translate, atol=1e-12)
    # at one time the motion is rigid: distances between points are preserved
    same_time = motion.to_world(v, np.full(50, 0.37))
    np.testing.assert_allclose(np.linalg.norm(same_time[1:] - same_time[:-1], axis=1),
                               np.linalg.norm(v[1:] - v[:-1], axis=1), rtol=1e-12)
    turned = motion.rotate_vectors(v, time)
    np.testing.assert_allclose(motion.rotate_vectors(turned, time, inverse=True), v, atol=1e-12)


def test_times_are_stratified_per_pixel():
    spp, pixels = 12, 300
    pixel = np.repeat(np.arange(pixels), spp)
    sample = np.tile(np.arange(spp), pixels)
    for sampler in ("jittered", "regular"):
        t = stratified_values(sampler, 3, pixel, sample, spp, Dim.TIME)
        strata = np.sort(np.floor(t * spp).astype(int).reshape(pixels, spp), axis=1)
        assert (strata == np.arange(spp)).all()
        # and the strata are not handed out in the order of the pixel strata
        first = np.floor(t * spp).astype(int).reshape(pixels, spp)[:, 0]
        assert len(np.unique(first)) == spp
    pixel, sample = np.repeat(np.arange(pixels), 16), np.tile(np.arange(16), pixels)
    t = stratified_values("sobol", 3, pixel, sample, 16, Dim.TIME)
    strata = np.sort(np.floor(t * 16).astype(int).reshape(pixels, 16), axis=1)
    assert (strata == np.arange(16)).all()


# ---------------------------------------------------------------- scenes
# the strip scene's field of view: the image spans x_world in [-1.5, 1.5] at 48 x 4 pixels
STRIP_FOV = 2.0 * np.degrees(np.arctan(1.5 / (5.0 * 12.0)))


def sliding_quad_scene(translate=(1.0, 0.0, 0.0), shutter=(0.0, 1.0), width=0.3):
    """An emissive strip ``|x| <= width`` at z = 0 facing a camera on the +z axis, sliding."""
    vertices, faces = quad([[-width, -5, 0], [width, -5, 0], [width, 5, 0], [-width, 5, 0]])
    strip = part("strip", (vertices, faces), 0)
    strip.motion = Motion(translate)
    camera = Camera([0.0, 0.0, 5.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], STRIP_FOV, shutter=shutter)
    return Scene.from_parts([strip], [Material("light", diffuse=0.0, emission=1.0)], [], camera)


def moving_box_over_floor(translate=(1.5, 0.0, 0.0), shutter=(0.0, 1.0), degrees=0.0):
    """A diffuse box above a floor, lit from above by a point light, seen from above."""
    floor = part("floor", floor_quad(6.0), 0)
    block = part("box", box((1.0, 1.0, 0.6), (-0.75, 0.0, 1.5)), 1)
    block.motion = Motion(translate, [0.0, 0.0, 1.0], degrees)
    camera = Camera([0.0, -0.01, 9.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 40.0, shutter=shutter)
    # the light stands off to +x so that the box's shadow falls beside it, in view
    return Scene.from_parts([floor, block], [Material("floor", diffuse=0.8, ambient=0.0),
                                             Material("box", diffuse=0.5, ambient=0.0)],
                            [PointLight([2.5, 0.0, 6.0], 40.0)], camera)


def strip_coverage(scene, width_px, height_px, half_width=0.3, travel=1.0, grid=400):
    """Exact time-and-pixel-averaged coverage of each pixel column by the sliding strip.

    The pinhole maps film x to x_world = 5 * tan(fov/2) * aspect * (2 x / W - 1) on z = 0;
    the strip covers x_world at time t iff |x_world - travel * t| <= half_width.
    """
    half = 5.0 * np.tan(np.radians(STRIP_FOV / 2.0)) * width_px / height_px
    s = (np.arange(grid) + 0.5) / grid
    columns = []
    for column in range(width_px):
        x_world = half * (2.0 * (column + s[:, None]) / width_px - 1.0)
        covered = np.abs(x_world - travel * s[None, :]) <= half_width
        columns.append(covered.mean())
    return np.array(columns)


# ---------------------------------------------------------------- renders
def test_sliding_strip_coverage_matches_the_time_average():
    width, height, spp = 48, 4, 256
    result = render(sliding_quad_scene(), width=width, height=height, spp=spp, sampler="jittered",
                    max_depth=0)
    assert "motion" in result.stats.stages_enabled
    expected = strip_coverage(sliding_quad_scene(), width, height)
    measured = result.image[:, :, 0].mean(axis=0)
    # partly covered pixels exist (the blur), and each matches the exact average within
    # 4 standard errors of 2 * 256 independent-ish samples
    assert ((expected > 0.05) & (expected < 0.95)).sum() >= 10
    sigma = np.sqrt(expected * (1 - expected) / (height * spp)) + 1e-3
    assert (np.abs(measured - expected) <= 4 * sigma).all(), np.abs(measured - expected).max()
    assert abs(measured.sum() - expected.sum()) < 0.02 * expected.sum()


def test_zero_motion_and_closed_shutter_are_the_static_render():
    static = render(moving_box_over_floor(translate=(0.0, 0.0, 0.0)), spp=4, sampler="jittered")
    assert "motion" not in static.stats.stages_enabled
    closed = render(moving_box_over_floor(shutter=(0.0, 0.0)), spp=4, sampler="jittered")
    assert "motion" not in closed.stats.stages_enabled
    np.testing.assert_array_equal(static.image, closed.image)
    # a closed shutter at t = 0.5 sees the object half-way, standing still
    half = render(moving_box_over_floor(shutter=(0.5, 0.5)), spp=4, sampler="jittered")
    moved = render(moving_box_over_floor(translate=(0.0, 0.0, 0.0)), spp=4, sampler="jittered")
    assert not np.array_equal(half.image, moved.image)
    baked = render(scene_at_time(moving_box_over_floor(), 0.5), spp=4, sampler="jittered")
    np.testing.assert_array_equal(half.image, baked.image)


def test_motion_path_with_zero_motion_is_bit_identical_to_the_static_path(monkeypatch):
    # force the rest-frame tracing path on an object that does not move: separate Embree
    # scenes, per-ray transforms, prim remapping and the surface transforms must all be exact
    size = dict(spp=2, sampler="jittered", width=24, height=24)
    static = render(moving_box_over_floor(translate=(0.0, 0.0, 0.0)), **size)
    monkeypatch.setattr(Motion, "moves", property(lambda self: True))
    forced = render(moving_box_over_floor(translate=(0.0, 0.0, 0.0)), **size)
    assert "motion" in forced.stats.stages_enabled
    np.testing.assert_array_equal(forced.image, static.image)


def test_rotating_object_matches_the_average_of_static_renders():
    scene = moving_box_over_floor(translate=(0.5, 0.0, 0.0), degrees=60.0)
    size = dict(width=24, height=24, sampler="jittered", max_depth=1)
    blurred = render(scene, spp=64, **size).image
    times = (np.arange(16) + 0.5) / 16
    average = np.mean([render(scene_at_time(scene, t), spp=16, **size).image for t in times],
                      axis=0)
    # same expectation; the difference is Monte Carlo noise of both estimates
    assert abs(blurred.mean() - average.mean()) < 0.01 * average.mean()
    error = np.abs(blurred - average).mean()
    assert error < 0.01
    # and it is not the static picture at any one time
    instant = render(scene_at_time(scene, 0.5), spp=16, **size).image
    assert np.abs(blurred - instant).mean() > 3 * error


def test_shadow_of_a_moving_object_is_blurred_like_the_time_average():
    # The camera looks straight down at the floor beside the box (the box never enters the
    # view).  The light at (2.5, 0, 6) casts the box's top edge x = -1.25 + t * dx, z = 1.8
    # onto the floor at x_edge(t) = 2.5 + (x - 2.5) * 6 / 4.2; a floor point x right of the
    # shadow's left edge is shadowed.  So at t in [0, 1] the visible fraction of x is the
    # fraction of the shutter during which x < x_edge(t): a linear ramp.
    dx = -1.0
    scene = moving_box_over_floor(translate=(dx, 0.0, 0.0))
    floor_only = Scene.from_parts([part("floor", floor_quad(6.0), 0)],
                                  [Material("floor", diffuse=0.8, ambient=0.0)],
                                  scene.lights, scene.camera)
    centre, fov, width = -4.0, 20.0, 40
    for s in (scene, floor_only):
        s.camera = dataclasses.replace(s.camera, position=np.array([centre, 0.0, 9.0]),
                                       look_at=np.array([centre, 0.0, 0.0]), fov=fov)
    size = dict(width=width, height=width, spp=64, sampler="jittered", max_depth=0)
    lit = render(floor_only, **size).image[:, :, 0]
    moving = render(scene, **size).image[:, :, 0]
    still = render(scene_at_time(scene, 0.0), **size).image[:, :, 0]
    rows = slice(width // 2 - 4, width // 2 + 4)  # |y| < 0.32: inside the shadow's y extent
    visible = (moving[rows] / lit[rows]).mean(axis=0)
    # exact reference, averaged over each pixel's width and the shutter
    half = 9.0 * np.tan(np.radians(fov / 2.0))
    s = (np.arange(200) + 0.5) / 200
    x = centre + half * (2.0 * (np.arange(width)[:, None] + s[None, :]) / width - 1.0)
    x_edge = 2.5 + (-1.25 + dx * s[:, None, None] - 2.5) * 6.0 / 4.2
    expected = (x[None] < x_edge).mean(axis=(0, 2))
    ramp = (expected > 0.02) & (expected < 0.98)
    assert ramp.sum() >= 8  # the blur spans many pixels...
    still_visible = (still[rows] / lit[rows]).mean(axis=0)
    assert ((still_visible > 0.02) & (still_visible < 0.98)).sum() <= 2  # ...the still edge one
    np.testing.assert_allclose(visible, expected, atol=0.05)


def test_sliding_floor_has_no_self_intersection():
    # a floor sliding along itself looks the same at every time: any re-hit of the surface
    # a shadow ray leaves (offsets valid in world space only) would show as dark acne
    floor = part("floor", floor_quad(50.0), 0)
    ball = part("ball", box((1.0, 1.0, 1.0), (0.0, 0.0, 0.5)), 0)
    camera = Camera([0.0, -6.0, 4.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0], 50.0, shutter=(0.0, 1.0))
    lights = [PointLight([3.0, -2.0, 6.0], 40.0)]
    still = Scene.from_parts([floor, ball], [Material(diffuse=0.7, mirror=0.2)], lights, camera)
    floor.motion = Motion([7.3, 3.1, 0.0], [0.0, 0.0, 1.0], 5.0)
    sliding = Scene.from_parts([floor, ball], [Material(diffuse=0.7, mirror=0.2)], lights, camera)
    a = render(still, spp=2, sampler="jittered").image
    b = render(sliding, spp=2, sampler="jittered")
    assert "motion" in b.stats.stages_enabled
    # the floor's edges stay far out of view; only floating-point noise may differ
    np.testing.assert_allclose(b.image, a, atol=2e-4)


@pytest.mark.parametrize("sampler", ["jittered", "sobol", "random"])
def test_motion_blur_is_bit_identical_across_threads_and_chunks(sampler):
    scene = moving_box_over_floor(degrees=30.0)
    one = render(scene, spp=4, sampler=sampler, threads=1, chunk_samples=100000)
    two = render(scene, spp=4, sampler=sampler, threads=2, chunk_samples=300)
    np.testing.assert_array_equal(one.image, two.image)


def test_motion_accel_queries_agree_with_baked_scenes():
    scene = moving_box_over_floor(degrees=45.0)
    motions = {k: m for k, m in scene.motions.items()}
    accel = MotionAccel(scene.vertices, scene.faces, scene.object_id, motions)
    rng = np.random.default_rng(4)
    n = 2000
    origins = np.column_stack([rng.uniform(-3, 3, n), rng.uniform(-3, 3, n), np.full(n, 5.0)])
    directions = np.tile([0.0, 0.0, -1.0], (n, 1))
    for t in (0.0, 0.3, 1.0):
        time = np.full(n, t)
        baked = scene_at_time(scene, t)
        reference = Accel(baked.vertices, baked.faces)
        expected = reference.intersect(origins, directions)
        hits = accel.intersect(origins, directions, time)
        np.testing.assert_array_equal(hits.prim >= 0, expected.prim >= 0)
        np.testing.assert_allclose(hits.t[hits.prim >= 0], expected.t[expected.prim >= 0],
                                   atol=1e-5)
        np.testing.assert_array_equal(scene.object_id[hits.prim], scene.object_id[expected.prim])
        occluded = accel.occluded(origins, directions, np.full(n, 4.0), time=time)
        expected_occluded = reference.occluded(origins, directions, np.full(n, 4.0))
        np.testing.assert_array_equal(occluded, expected_occluded)


# ---------------------------------------------------------------- scene files
SCENE_BASE = {"lights": [{"type": "point", "position": [0, 0, 5], "intensity": 1}],
              "camera": {"position": [0, -5, 1], "look_at": [0, 0, 0], "shutter": [0.0, 0.5]}}


def test_motion_and_shutter_scene_keys():
    doc = dict(SCENE_BASE, objects=[
        {"primitive": "box", "translate": [1, 2, 3],
         "motion": {"translate": [0.5, 0, 0], "rotate_axis": [0, 0, 2], "rotate_degrees": 90}},
        {"primitive": "plane"}])
    scene, _ = scene_from_dict(doc)
    assert scene.camera.shutter == (0.0, 0.5)
    assert list(scene.motions) == [0]
    motion = scene.motions[0]
    np.testing.assert_array_equal(motion.translate, [0.5, 0, 0])
    np.testing.assert_array_equal(motion.axis, [0, 0, 1])
    np.testing.assert_allclose(motion.centre, [1, 2, 3])  # the box's bounds centre
    assert motion.degrees == 90.0


@pytest.mark.parametrize("camera, motion, message", [
    ({"shutter": [1.0, 0.0]}, None,
     r"camera\.shutter: expected \[open, close\] with open <= close"),
    ({"shutter": [0.0]}, None, r"camera\.shutter: expected a list of 2 numbers"),
    ({}, {"translat": [1, 0, 0]}, r"objects\[0\]\.motion\.translat: unknown key"),
    ({}, {"rotate_degrees": 10}, r"objects\[0\]\.motion\.rotate_axis: missing"),
    ({}, {"rotate_axis": [0, 0, 0], "rotate_degrees": 10},
     r"objects\[0\]\.motion: a rotating motion needs"),
    ({}, [1, 0, 0], r"objects\[0\]\.motion: expected a table"),
])
def test_bad_motion_keys_name_the_key(camera, motion, message):
    obj = {"primitive": "box"}
    if motion is not None:
        obj["motion"] = motion
    doc = dict(SCENE_BASE, camera={**SCENE_BASE["camera"], **camera}, objects=[obj])
    with pytest.raises(SceneError, match=message):
        scene_from_dict(doc)


def test_area_light_shadows_see_moving_objects_at_the_rays_time():
    scene = moving_box_over_floor(degrees=40.0)
    # a small quad light facing down, where the point light was
    scene.lights = [QuadLight([2.5, 0.0, 6.0], [0.6, 0.0, 0.0], [0.0, -0.6, 0.0], 110.0,
                              visible=False)]
    size = dict(width=24, height=24, sampler="jittered", max_depth=0, light_samples=2)
    blurred = render(scene, spp=64, **size)
    assert {"motion", "area_lights"} <= set(blurred.stats.stages_enabled)
    times = (np.arange(16) + 0.5) / 16
    average = np.mean([render(scene_at_time(scene, t), spp=16, **size).image for t in times],
                      axis=0)
    assert np.abs(blurred.image - average).mean() < 0.01
    instant = render(scene_at_time(scene, 0.5), spp=16, **size).image
    assert np.abs(blurred.image - instant).mean() > 3 * np.abs(blurred.image - average).mean()


def test_shuffled_strata_permute_each_set_of_samples():
    spp, pixels = 6, 200
    pixel = np.repeat(np.arange(pixels), 3 * spp)
    sample = np.tile(np.arange(3 * spp), pixels)  # three rounds of spp samples
    permuted = shuffled_strata(5, pixel, sample, spp, Dim.TIME).reshape(pixels, 3, spp)
    # each set of spp samples maps onto itself, one to one
    expected = np.arange(3 * spp).reshape(3, spp)
    assert (np.sort(permuted, axis=2) == expected).all()
    # and later rounds get fresh jitter: no two samples of a pixel share a time
    t = stratified_values("jittered", 5, pixel, sample, spp, Dim.TIME).reshape(pixels, 3 * spp)
    assert all(len(np.unique(row)) == 3 * spp for row in t)


def test_a_smooth_ball_spinning_about_its_centre_looks_still():
    # its shading normals (interpolated in the rest pose) must turn with it: lit from one
    # side, a spinning ball keeps its terminator where the light puts it
    def scene(degrees):
        ball = part("ball", icosphere(4, 1.0, (0.0, 0.0, 1.0)), 0, smooth=True)
        ball.motion = Motion([0.0, 0.0, 0.0], [0.3, 1.0, 0.2], degrees)
        floor = part("floor", floor_quad(8.0), 0)
        camera = Camera([0.0, -6.0, 2.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], 35.0,
                        shutter=(0.0, 1.0))
        return Scene.from_parts([ball, floor], [Material(diffuse=0.7, specular=0.3, shininess=40)],
                                [PointLight([4.0, -3.0, 5.0], 50.0)], camera)

    size = dict(width=32, height=32, spp=8, sampler="jittered")
    still = render(scene(0.0), **size).image
    spinning = render(scene(120.0), **size)
    assert "motion" in spinning.stats.stages_enabled
    assert np.abs(spinning.image - still).mean() < 2e-3
    assert np.abs(spinning.image - still).max() < 0.05


def test_sphere_test_kernel_keeps_the_rows_the_numpy_formulation_keeps():
    # the bounding-sphere test of a moving object: the same rows as the NumPy expressions
    # it replaced, for rays from inside, outside, behind and tangent to the sphere
    from rtmesh.core.compiled import by_component
    from rtmesh.core.vecmath import dot
    from rtmesh.geometry.motion import rays_near_sphere

    rng = np.random.default_rng(4)
    n = 20000
    centre, radius2 = np.array([0.5, -1.0, 2.0]), 1.7 ** 2
    origins = np.asfortranarray(rng.uniform(-6, 6, (n, 3)))
    directions = rng.normal(size=(n, 3))
    directions = np.asfortranarray(directions / np.sqrt(dot(directions, directions))[:, None])
    origins[:2] = centre + [1.7, 0.0, 0.0]  # on the sphere, grazing and leaving
    directions[:2] = [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]
    t_max = rng.uniform(0.0, 12.0, n)
    t_max[::7] = np.inf

    oc = origins - centre
    b = dot(oc, directions)
    disc = b * b - (dot(oc, oc) - radius2)
    root = np.sqrt(np.maximum(disc, 0.0))
    expected = np.flatnonzero((disc >= 0.0) & (root - b >= 0.0) & (-b - root <= t_max))
    rows = rays_near_sphere(by_component(origins), by_component(directions), t_max, centre, radius2)
    assert 0 < len(rows) < n
    np.testing.assert_array_equal(rows, expected)
