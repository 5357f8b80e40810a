"""Output passes against known geometry: depth, normals, positions, ids, coverage, UVs, and
the film reductions, EXR channel names and PNG mappings behind them."""

import numba
import numpy as np
import pytest
from scenes import box, part, pixel_centre_rays, quad, render

from rtmesh.cli import main
from rtmesh.io.images import read_image, write_image
from rtmesh.io.passes import LIGHT_PATH_PASSES, PASS_NAMES, display_values, exr_channel_names, id_colours, pass_width
from rtmesh.materials.table import Material
from rtmesh.rendering import film_sums
from rtmesh.rendering.film import Film
from rtmesh.sampling.patterns import pixel_offsets
from rtmesh.scene.camera import Camera
from rtmesh.scene.model import Scene

LOOK_DOWN_Z = Camera([0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0], 60.0)


def wall_scene(distance, half_size=100.0):
    """A wall facing +Z at z = -distance, filling the view of LOOK_DOWN_Z."""
    s = half_size
    wall = quad([[-s, -s, -distance], [s, -s, -distance], [s, s, -distance], [-s, s, -distance]])
    return Scene.from_parts([part("wall", wall)], [Material("m")], [], LOOK_DOWN_Z)


def box_scene():
    """A unit box at the origin seen along a diagonal, from the +X, +Y, +Z side."""
    camera = Camera([3.0, 2.5, 4.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 20.0)
    return Scene.from_parts([part("box", box())], [Material("m")], [], camera)


def slab_hits(origins, directions, lo=-0.5, hi=0.5):
    """Entry distance and the outward normal of the entered face of an axis-aligned box.

    Returns (t, normal, margin): t = inf for misses; margin is how far the entry point is
    from the nearest edge of its face (hits within float noise of an edge are ambiguous).
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (lo - origins) / directions
        t2 = (hi - origins) / directions
    t_near = np.minimum(t1, t2)
    t_enter = t_near.max(axis=1)
    t_exit = np.maximum(t1, t2).min(axis=1)
    hit = (t_enter <= t_exit) & (t_exit > 0)
    axis = t_near.argmax(axis=1)
    normal = np.zeros_like(origins)
    rows = np.arange(len(origins))
    normal[rows, axis] = -np.sign(directions[rows, axis])
    p = origins + t_enter[:, None] * directions
    others = np.abs(p)
    others[rows, axis] = -np.inf
    margin = 0.5 - others.max(axis=1)
    return np.where(hit, t_enter, np.inf), normal, margin


# ---------------------------------------------------------------- depth
@pytest.mark.parametrize("spp, sampler", [(1, "regular"), (4, "jittered")])
def test_depth_of_a_wall_facing_the_camera_is_its_distance_in_every_pixel(spp, sampler):
    # z-depth, not ray distance: the corner pixels see the wall 1/cos(angle) farther along
    # their rays, yet its depth along the view axis is the same everywhere
    distance = 3.75
    result = render(wall_scene(distance), width=12, height=8, spp=spp, sampler=sampler,
                    passes=("depth",))
    depth = result.passes["depth"]
    assert depth.shape == (8, 12, 1)
    np.testing.assert_allclose(depth, distance, rtol=1e-6)


def test_depth_is_the_nearest_sample_at_a_silhouette_and_zero_where_nothing_is_hit():
    # a small near quad in front of a far wall, 16 samples per pixel: a pixel on the quad's
    # edge holds the near depth (the minimum), never a blend of the two
    near = quad([[-0.3, -0.3, -2.0], [0.3, -0.3, -2.0], [0.3, 0.3, -2.0], [-0.3, 0.3, -2.0]])
    scene = Scene.from_parts([part("near", near)], [Material("m")], [], LOOK_DOWN_Z)
    result = render(scene, width=16, height=16, spp=16, sampler="jittered", passes=("depth", "alpha"))
    depth, alpha = result.passes["depth"][..., 0], result.passes["alpha"][..., 0]
    np.testing.assert_allclose(depth[alpha > 0], 2.0, rtol=1e-6)
    assert (depth[alpha == 0] == 0.0).all()
    assert ((alpha > 0) & (alpha < 1)).any()


# ---------------------------------------------------------------- normals and positions
def test_box_normals_are_exactly_the_normal_of_the_face_each_pixel_sees():
    scene = box_scene()
    w, h = 40, 32
    result = render(scene, width=w, height=h, passes=("normal", "position", "depth"))
    origins, directions = pixel_centre_rays(scene.camera, w, h)
    t, normal, margin = slab_hits(origins, directions)
    hit = np.isfinite(t)
    got = result.passes["normal"].reshape(-1, 3)
    assert hit.sum() > 200
    # the three visible faces all appear, and no pixel off the box has a normal
    clear = hit & (margin > 1e-4)
    np.testing.assert_array_equal(got[clear], normal[clear])
    assert {tuple(n) for n in normal[clear]} == {(1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)}
    assert (got[~hit] == 0).all()
    # positions are the slab hit points
    position = result.passes["position"].reshape(-1, 3)
    expected = origins + t[:, None] * directions
    np.testing.assert_allclose(position[hit], expected[hit], atol=2e-6)
    # and depth is the hit point's distance along the view axis
    forward = -scene.camera.position / np.linalg.norm(scene.camera.position)
    depth = result.passes["depth"].reshape(-1)
    np.testing.assert_allclose(depth[hit], (expected[hit] - scene.camera.position) @ forward, rtol=1e-6)


def test_position_is_world_space_far_from_the_origin():
    # the integrator re-centres the scene; the pass must undo that shift
    shift = np.array([1000.0, -2000.0, 500.0])
    mesh = box(centre=shift)
    camera = Camera(shift + [3.0, 2.5, 4.0], shift, [0.0, 1.0, 0.0], 30.0)
    scene = Scene.from_parts([part("box", mesh)], [Material("m")], [], camera)
    result = render(scene, width=16, height=16, passes=("position",))
    origins, directions = pixel_centre_rays(camera, 16, 16)
    t, _, _ = slab_hits(origins - shift, directions)
    hit = np.isfinite(t)
    expected = origins + t[:, None] * directions
    np.testing.assert_allclose(result.passes["position"].reshape(-1, 3)[hit], expected[hit], atol=1e-3)


# ---------------------------------------------------------------- ids and coverage
def two_quads_scene():
    """Two quads side by side (left: object 0 material 2, right: object 1 material 1)."""
    left = quad([[-1.2, -0.5, -3.0], [-0.1, -0.5, -3.0], [-0.1, 0.5, -3.0], [-1.2, 0.5, -3.0]])
    right = quad([[0.1, -0.5, -3.0], [1.2, -0.5, -3.0], [1.2, 0.5, -3.0], [0.1, 0.5, -3.0]])
    materials = [Material("unused"), Material("b"), Material("a")]
    return Scene.from_parts([part("left", left, material=2), part("right", right, material=1)],
                            materials, [], LOOK_DOWN_Z)


def film_sample_screen(width, height, spp, sampler, sample, fov=60.0, seed=0):
    """Screen-plane coordinates (x, y at unit distance) of sample ``sample`` of every pixel."""
    pixel = np.arange(width * height)
    offsets = np.asarray(pixel_offsets(sampler, seed, pixel, np.full(pixel.size, sample), spp))
    fx = pixel % width + offsets[:, 0]
    fy = pixel // width + offsets[:, 1]
    tan_half = np.tan(np.radians(fov) / 2)
    return ((2 * fx / width - 1) * tan_half * width / height, (1 - 2 * fy / height) * tan_half)


def test_ids_are_the_pixel_centre_rays_object_and_material_exact_integers():
    w, h, spp = 24, 12, 4
    scene = two_quads_scene()
    result = render(scene, width=w, height=h, spp=spp, sampler="jittered",
                    passes=("object_id", "material_id", "instance_id"))
    # where each pixel's centre ray meets the wall plane z = -3
    origins, directions = pixel_centre_rays(scene.camera, w, h)
    p = origins + (3.0 / -directions[:, 2])[:, None] * directions
    x, y = p[:, 0], p[:, 1]
    inside_y = np.abs(y) < 0.5
    expected_object = np.where(inside_y & (x > -1.2) & (x < -0.1), 0,
                               np.where(inside_y & (x > 0.1) & (x < 1.2), 1, -1))
    expected_material = np.select([expected_object == 0, expected_object == 1], [2, 1], -1)
    got_object = result.passes["object_id"].reshape(-1)
    np.testing.assert_array_equal(got_object, expected_object)
    np.testing.assert_array_equal(result.passes["material_id"].reshape(-1), expected_material)
    # no mesh is placed twice: an instance is its object
    np.testing.assert_array_equal(result.passes["instance_id"].reshape(-1), expected_object)
    assert {-1, 0, 1} <= set(got_object.tolist())
    # the ids are not the jittered sample 0's: some pixel's sample 0 lands on another object
    x0, y0 = film_sample_screen(w, h, spp, "jittered", 0)
    x0, y0 = 3 * x0, 3 * y0
    first = np.where((np.abs(y0) < 0.5) & (x0 > -1.2) & (x0 < -0.1), 0,
                     np.where((np.abs(y0) < 0.5) & (x0 > 0.1) & (x0 < 1.2), 1, -1))
    assert (first != expected_object).any()


def test_centre_geometry_passes_are_the_pixel_centre_rays_hits_with_marked_misses():
    scene = box_scene()
    w, h = 32, 24
    result = render(scene, width=w, height=h, spp=3,
                    passes=("depth_center", "position_center", "normal_center", "object_id"))
    origins, directions = pixel_centre_rays(scene.camera, w, h)
    t, normal, margin = slab_hits(origins, directions)
    hit = np.isfinite(t)
    assert hit.any() and (~hit).any()
    depth = result.passes["depth_center"].reshape(-1)
    position = result.passes["position_center"].reshape(-1, 3)
    shading = result.passes["normal_center"].reshape(-1, 3)
    np.testing.assert_array_equal(result.passes["object_id"].reshape(-1) == 0, hit)
    # misses: +inf depth, NaN position and normal
    assert np.isposinf(depth[~hit]).all() and np.isnan(position[~hit]).all() and np.isnan(shading[~hit]).all()
    expected = origins + t[:, None] * directions
    np.testing.assert_allclose(position[hit], expected[hit], atol=2e-6)
    forward = -scene.camera.position / np.linalg.norm(scene.camera.position)
    np.testing.assert_allclose(depth[hit], (expected[hit] - scene.camera.position) @ forward, rtol=1e-6)
    clear = hit & (margin > 1e-4)  # away from the box's edges, where the face is certain
    np.testing.assert_allclose(shading[clear], normal[clear], atol=1e-6)


def test_centre_passes_keep_inf_and_nan_in_the_exr(tmp_path):
    result = render(box_scene(), width=16, height=12, passes=("depth_center", "position_center"))
    path = tmp_path / "centre.exr"
    write_image(path, result.image, result.passes)
    pixels, names = read_image(path)
    depth = pixels[..., names.index("depth_center.Z")]
    np.testing.assert_array_equal(depth, result.passes["depth_center"][..., 0])
    assert np.isposinf(depth).any()
    assert np.isnan(pixels[..., names.index("position_center.X")]).any()


def test_alpha_is_the_fraction_of_samples_that_hit():
    w, h, spp = 24, 12, 4
    result = render(two_quads_scene(), width=w, height=h, spp=spp, sampler="jittered", passes=("alpha",))
    hits = np.zeros(w * h)
    for sample in range(spp):
        x, y = film_sample_screen(w, h, spp, "jittered", sample)
        x, y = 3 * x, 3 * y
        inside = (np.abs(y) < 0.5) & (((x > -1.2) & (x < -0.1)) | ((x > 0.1) & (x < 1.2)))
        hits += inside
    alpha = result.passes["alpha"].reshape(-1)
    np.testing.assert_allclose(alpha, hits / spp, atol=1e-7)
    assert (alpha == 1).any() and (alpha == 0).any() and ((alpha > 0) & (alpha < 1)).any()


# ---------------------------------------------------------------- uv and albedo
def test_uv_pass_interpolates_the_scenes_texture_coordinates():
    scene = wall_scene(2.0, half_size=4.0)
    # u runs 0 -> 1 left to right over the wall, v 0 -> 1 bottom to top (set by hand: the
    # UVs of imported meshes reach Scene.uv through the importers)
    scene.uv = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    w, h = 8, 6
    result = render(scene, width=w, height=h, passes=("uv",))
    origins, directions = pixel_centre_rays(scene.camera, w, h)
    p = origins + (2.0 / -directions[:, 2])[:, None] * directions
    expected = np.stack([(p[:, 0] + 4.0) / 8.0, (p[:, 1] + 4.0) / 8.0], axis=1)
    np.testing.assert_allclose(result.passes["uv"].reshape(-1, 2), expected, atol=1e-6)


def test_albedo_is_the_diffuse_colour_of_the_material_hit():
    scene = two_quads_scene()
    scene.materials.diffuse[1] = [0.1, 0.2, 0.3]
    scene.materials.diffuse[2] = [0.9, 0.5, 0.25]
    result = render(scene, width=24, height=12, passes=("albedo", "material_id"))
    albedo = result.passes["albedo"].reshape(-1, 3)
    material = result.passes["material_id"].reshape(-1).astype(int)
    for index, colour in ((1, [0.1, 0.2, 0.3]), (2, [0.9, 0.5, 0.25])):
        rows = albedo[material == index]
        assert len(rows)
        np.testing.assert_allclose(rows, np.broadcast_to(colour, rows.shape), rtol=1e-6)
    assert (albedo[material == -1] == 0).all()


# ---------------------------------------------------------------- only what is asked
def test_only_requested_passes_are_computed_and_stored():
    scene = box_scene()
    plain = render(scene, width=16, height=16)
    assert plain.passes == {} and plain.film.pass_sums == {}
    assert "passes" not in plain.stats.stages_enabled
    assert plain.stats.stage_seconds["passes"] == 0.0
    asked = render(scene, width=16, height=16, passes=("depth", "object_id"))
    # object_id is traced from the pixel centres after the render: the film holds depth alone
    assert set(asked.passes) == {"depth", "object_id"} and set(asked.film.pass_sums) == {"depth"}
    assert "passes" in asked.stats.stages_enabled
    # passes never change the image
    np.testing.assert_array_equal(asked.image, plain.image)


@pytest.mark.parametrize("integrator", ["whitted", "path"])
def test_passes_are_bit_identical_across_threads_and_chunk_sizes(integrator):
    scene = box_scene()
    # the light-path passes exist under the path integrator only
    names = tuple(n for n in PASS_NAMES if n != "ao" and (integrator == "path" or n not in LIGHT_PATH_PASSES))
    a = render(scene, width=20, height=14, spp=4, sampler="jittered", passes=names, threads=1, integrator=integrator)
    b = render(scene, width=20, height=14, spp=4, sampler="jittered", passes=names, threads=2,
               chunk_samples=28, integrator=integrator)
    for name in names:
        np.testing.assert_array_equal(a.passes[name], b.passes[name], err_msg=name)


# ---------------------------------------------------------------- film reductions
def test_one_pass_film_writes_each_tiles_image_values_as_it_is_added():
    rng = np.random.default_rng(3)
    radiance = rng.random((6 * 5, 3, 3))
    lazy, eager = Film(6, 5), Film(6, 5, one_pass=True)
    lazy.add_tile(0, radiance)
    # tiles in any order, one of them given by an index array
    eager.add_tile(slice(20, 30), radiance[20:])
    eager.add_tile(np.array([0, 1, 2, 3, 4, 5, 6, 7, 8, 9]), radiance[:10])
    eager.add_tile(slice(10, 20), radiance[10:20])
    np.testing.assert_array_equal(eager.image(), lazy.image())
    np.testing.assert_allclose(eager.image().reshape(-1, 3), radiance.mean(axis=1), rtol=1e-6)


@numba.njit
def add_pixel(total, total_sq, count, image, px, radiance):
    """Add one pixel's samples to a film's kernel arrays as the fused stage adds them."""
    t0, t1, t2, q0, q1, q2 = film_sums.pixel_sums(total, total_sq, count, px)
    for s in range(len(radiance)):
        r0, r1, r2 = radiance[s, 0], radiance[s, 1], radiance[s, 2]
        t0, t1, t2 = t0 + r0, t1 + r1, t2 + r2
        q0, q1, q2 = q0 + r0 * r0, q1 + r1 * r1, q2 + r2 * r2
    count[px] += len(radiance)
    film_sums.store_pixel(total, total_sq, image, px, count[px], t0, t1, t2, q0, q1, q2)


def test_a_one_pass_films_uncleared_sums_start_from_zero_at_each_pixels_first_sample():
    rng = np.random.default_rng(4)
    radiance = rng.random((6 * 5, 3, 3))
    cleared = Film(6, 5)
    cleared.add_tile(0, radiance)
    ways = []
    for way in ("add_tile", "pixel_sums", "add_samples"):
        film = Film(6, 5, one_pass=True)
        film.sum[:] = np.nan  # what uncleared memory may hold
        film.sum_sq[:] = -1.0
        if way == "add_tile":
            film.add_tile(0, radiance)
        elif way == "pixel_sums":  # as the fused stage adds a pixel
            add_pixel(*film.kernel_arrays(), 7, radiance[7])
            rest = np.array([p for p in range(30) if p != 7])
            film.add_tile(rest, radiance[rest])
        else:
            film.add_samples(np.arange(30), np.full(30, 3), radiance.reshape(-1, 3))
        ways.append(film)
    for film in ways:
        np.testing.assert_array_equal(film.sum, cleared.sum)
        np.testing.assert_array_equal(film.sum_sq, cleared.sum_sq)
        np.testing.assert_array_equal(film.count, cleared.count)


def test_film_first_keeps_sample_zero_across_rounds_and_min_keeps_the_smallest():
    film = Film(2, 1, {"id": (1, "first"), "z": (1, "min"), "m": 1})
    film.add_tile(slice(0, 2), np.zeros((2, 2, 3)),
                  {"id": np.array([[[5.0], [7.0]], [[3.0], [9.0]]]),
                   "z": np.array([[[2.0], [np.inf]], [[np.inf], [np.inf]]]),
                   "m": np.array([[[1.0], [0.0]], [[1.0], [1.0]]])})
    # a later round (adaptive sampling) adds samples but never replaces the first
    film.add_tile(slice(0, 2), np.zeros((2, 1, 3)),
                  {"id": np.array([[[1.0]], [[1.0]]]), "z": np.array([[[1.5]], [[np.inf]]]),
                   "m": np.array([[[1.0]], [[0.0]]])})
    np.testing.assert_array_equal(film.pass_image("id")[0, :, 0], [5.0, 3.0])
    np.testing.assert_array_equal(film.pass_image("z")[0, :, 0], [1.5, 0.0])
    np.testing.assert_allclose(film.pass_image("m")[0, :, 0], [2 / 3, 2 / 3])


# ---------------------------------------------------------------- files
def test_exr_holds_every_pass_under_its_layer_names_and_pngs_map_them(tmp_path):
    scene_file = tmp_path / "box.toml"
    scene_file.write_text(
        '[render]\nwidth = 20\nheight = 16\nspp = 1\nsampler = "regular"\nthreads = 1\nintegrator = "path"\n'
        '[camera]\nposition = [3.0, 2.5, 4.0]\nlook_at = [0.0, 0.0, 0.0]\nfov = 30\n'
        '[[objects]]\nprimitive = "box"\n')
    out = tmp_path / "out.exr"
    assert main(["render", str(scene_file), "-o", str(out), "--passes", ",".join(PASS_NAMES),
                 "--pass-png", "-q"]) == 0
    pixels, names = read_image(out)
    expected = ["R", "G", "B", "A"]
    for name in PASS_NAMES:
        if name != "alpha":
            expected += exr_channel_names(name, pass_width(name))
    # OpenEXR stores channels sorted by name; the image's own R, G, B, A come first
    assert names[:4] == ["R", "G", "B", "A"] and sorted(names) == sorted(expected)
    assert "depth.Z" in names and "normal.X" in names and "object_id.id" in names
    # the EXR's channels are the passes of the same render
    from rtmesh.api import render as api_render
    result = api_render(str(scene_file), passes=PASS_NAMES)
    normal = pixels[..., names.index("normal.X"):names.index("normal.Z") + 1]
    np.testing.assert_array_equal(normal, result.passes["normal"])
    np.testing.assert_array_equal(pixels[..., 3], result.passes["alpha"][..., 0])
    # PNGs beside it: normals as 0.5 + 0.5 n, ids as colours, every pass present
    for name in PASS_NAMES:
        assert (tmp_path / f"out_{name}.png").is_file(), name
    png, _ = read_image(tmp_path / "out_normal.png")
    expected = np.round(255 * (0.5 + 0.5 * result.passes["normal"])) / 255
    expected = np.where(result.passes["alpha"] > 0, expected, 0.0)  # black off the model
    np.testing.assert_allclose(png, expected, atol=1e-6)
    ids, _ = read_image(tmp_path / "out_object_id.png")
    assert (ids[result.passes["object_id"][..., 0] < 0] == 0).all()
    assert (ids[result.passes["object_id"][..., 0] == 0].max(axis=-1) > 0.5).all()


def test_display_mappings():
    depth = np.array([[[2.0], [4.0], [0.0]]])
    shown, srgb = display_values("depth", depth, coverage=np.array([[1.0, 1.0, 0.0]]))
    assert not srgb
    np.testing.assert_allclose(shown[0, :, 0], [1.0, 0.1, 0.0])
    colours = id_colours(np.array([[0.0, 1.0, 2.0, -1.0]]))
    assert len({tuple(c) for c in colours[0]}) == 4 and (colours[0, 3] == 0).all()
    _, srgb = display_values("albedo", np.zeros((1, 1, 3)))
    assert srgb


def test_unknown_pass_is_a_one_line_error(tmp_path, capsys):
    scene_file = tmp_path / "s.toml"
    scene_file.write_text('[[objects]]\nprimitive = "box"\n')
    with pytest.raises(SystemExit) as exit_info:
        main(["render", str(scene_file), "-o", str(tmp_path / "o.exr"), "--passes", "depth,zdepth"])
    assert exit_info.value.code == 2
    assert "zdepth" in capsys.readouterr().err


def test_motion_is_where_each_centre_hit_lands_when_the_shutter_closes():
    # a box spinning and sliding in front of a still wall, shutter open from 0.25 to 0.75
    import dataclasses

    from rtmesh.geometry.motion import Motion
    from rtmesh.scene.camera_json import camera_record

    spinner = part("spinner", box(centre=(0.0, 0.0, -4.0)))
    spinner.motion = Motion([0.6, -0.3, 0.2], [0.2, 1.0, 0.3], 40.0)
    wall = part("wall", quad([[-9, -9, -8.0], [9, -9, -8.0], [9, 9, -8.0], [-9, 9, -8.0]]))
    camera = dataclasses.replace(LOOK_DOWN_Z, shutter=(0.25, 0.75))
    scene = Scene.from_parts([spinner, wall], [Material("m")], [], camera)
    w, h = 32, 24
    result = render(scene, width=w, height=h, spp=2, passes=("motion", "position_center", "object_id"))
    motion = result.passes["motion"].reshape(-1, 2).astype(np.float64)
    position = result.passes["position_center"].reshape(-1, 3).astype(np.float64)
    on_box = result.passes["object_id"].reshape(-1) == 0
    assert on_box.sum() > 20 and (~on_box).sum() > 20
    assert (motion[~on_box] == 0).all()  # the wall stands still
    m = scene.motions[0]
    rest = m.to_rest(position[on_box], np.full(on_box.sum(), 0.25))
    closed = m.to_world(rest, np.full(on_box.sum(), 0.75))
    record = camera_record(camera, w, h, scene.bounds)
    w2c, k = np.array(record["world_to_camera_opencv"]), np.array(record["K"])
    p = (closed @ w2c[:3, :3].T + w2c[:3, 3]) @ k.T
    pixel = np.arange(w * h)[on_box]
    start = np.column_stack([pixel % w + 0.5, pixel // w + 0.5])
    np.testing.assert_allclose(start + motion[on_box], p[:, :2] / p[:, 2:], atol=1e-3)
    # it moves right and down in the image (+x right, +y down) on average: the sign convention
    assert motion[on_box, 0].mean() > 1 and motion[on_box, 1].mean() > 0
