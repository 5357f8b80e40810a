"""Random combinations of features, rendered tiny: finite images, no warning, any thread count.

Hypothesis draws a scene description (a plain dict, printed as is when an example fails)
from every feature the renderer has: Blinn-Phong, mirror, glossy, glass with and without
absorption, nested media, a camera inside glass (and inside glass inside water), emissive
and unlit materials, textures (base colour with alpha, specular, normal and emission maps,
every wrap mode), vertex colours, alpha cut-outs (mask and blend, textured alpha), object
motion (translation and rotation) under open, closed and off-zero shutters, point, spot, projector,
directional, quad and disk lights, emissive objects, solid, gradient, environment (lighting the scene or not) and
transparent backgrounds, ambient light and AO, depth of field, every pass, adaptive
sampling (``target_error``; ``time_limit`` is left out: its rounds depend on the clock, so
its image may differ between thread counts by design) and every sampler.  rtmesh has no
camera motion (the camera stands still while the shutter is open), so there is none to
draw.  Every object has texture coordinates, as the ``uv`` pass warns without them.

Each description is rendered at 16 x 12 pixels with 1 thread and with 2 threads, both in
the same small chunks (so both threads take several), and the test asserts that

- the image, the alpha and every pass are finite (and the image is not negative),
- no warning of any kind is emitted: no Python warning (NumPy floating-point
  ``RuntimeWarning`` included) and no log record at WARNING or above,
- the two renders are bit-identical.

No combination is excluded: the defects the test found (a camera in clear glass beside an
absorbing medium, cut-outs under motion blur, packet hits on coplanar overlaps depending on
the thread count, a point on an emissive triangle sampling its own plane) are fixed, and
each has a regression test of its own.

The default run (100 examples, about 10-20 s) is derandomized and uses no example
database, so CI draws the same examples every time; the ``slow`` variant draws 1000.  The
scene is built by :func:`build_scene` from the description alone, so a failing example is
reproduced by passing the printed dict to :func:`check`.
"""

import logging
import types
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, event, given
from hypothesis import settings as hypothesis_settings
from hypothesis import strategies as st
from scenes import assert_finite, box, icosphere, settings

from rtmesh.geometry.motion import Motion
from rtmesh.io.passes import LIGHT_PATH_PASSES, PASS_NAMES
from rtmesh.io.texture_images import Texture
from rtmesh.lights.area_lights import DiskLight, QuadLight
from rtmesh.lights.point_lights import DirectionalLight, PointLight, SpotLight
from rtmesh.lights.projector import ProjectorLight
from rtmesh.materials.table import Material, as_colour
from rtmesh.rendering.integrator import Integrator
from rtmesh.sampling.patterns import SAMPLERS
from rtmesh.scene.background import EnvironmentBackground, GradientBackground, TransparentBackground
from rtmesh.scene.camera import Camera
from rtmesh.scene.model import MeshPart, Scene

WIDTH, HEIGHT = 16, 12
WRAPS = ("repeat", "clamp", "mirror")

# ---------------------------------------------------------------- strategies
# a few values each, so that a shrunk failing example reads well
levels = st.sampled_from([0.0, 0.2, 0.5, 1.0])
colours = st.one_of(levels, st.tuples(levels, levels, levels).map(list))
positive_levels = st.sampled_from([0.05, 0.5, 1.0])
positive_colours = st.one_of(positive_levels, st.tuples(positive_levels, positive_levels,
                                                        positive_levels).map(list))
# a texture is made from a seed by make_texture (arrays drawn element by element would cost
# hypothesis far more than the render)
textures = st.fixed_dictionaries({"seed": st.integers(0, 2**16), "size": st.sampled_from([1, 2, 4]),
                                  "wrap": st.one_of(st.sampled_from(WRAPS),
                                                    st.tuples(st.sampled_from(WRAPS),
                                                              st.sampled_from(WRAPS)))})
MATERIAL_KINDS = ("diffuse", "specular", "mirror", "glossy", "glass", "absorbing_glass",
                  "emissive", "unlit", "physical", "physical_glass")


@st.composite
def materials(draw, kinds=MATERIAL_KINDS, cutouts=True):
    """A material description: a kind, its colours, and optional textures and alpha."""
    kind = draw(st.sampled_from(kinds))
    m = {"kind": kind, "diffuse": draw(colours)}
    if kind == "specular":
        m["specular"] = draw(positive_colours)
        m["shininess"] = draw(st.sampled_from([1.0, 8.0, 64.0, 1000.0]))
    if kind in ("mirror", "glossy"):
        m["mirror"] = draw(positive_colours)
        m["metallic"] = draw(st.sampled_from([0.0, 1.0]))
    if kind == "glossy":
        m["roughness"] = draw(st.sampled_from([0.05, 0.3, 1.0]))
    if kind in ("glass", "absorbing_glass"):
        m["diffuse"] = 0.0
        m["transmission"] = draw(st.sampled_from([1.0, [0.9, 1.0, 0.8]]))
        m["ior"] = draw(st.sampled_from([1.0, 1.33, 1.5, 2.4]))
        m["roughness"] = draw(st.sampled_from([0.0, 0.0, 0.2]))
    if kind == "absorbing_glass":
        m["absorption"] = draw(st.sampled_from([0.5, [0.1, 0.8, 2.0]]))
    if kind == "emissive":
        m["emission"] = draw(positive_colours)
        if draw(st.booleans()):
            m["emission_texture"] = draw(textures)
    if kind == "unlit":
        m["unlit"] = True
    if kind in ("physical", "physical_glass"):
        # glTF's metallic-roughness model (path traced, MIS against the lights)
        m["model"] = "metallic_roughness"
        m["base_color"] = draw(colours)
        m["metallic"] = draw(st.sampled_from([0.0, 0.5, 1.0]))
        m["perceptual_roughness"] = draw(st.sampled_from([0.0, 0.3, 1.0]))
        if draw(st.booleans()):
            m["metallic_roughness_texture"] = draw(textures)
    if kind == "physical_glass":
        m["metallic"], m["diffuse"] = 0.0, 0.0
        m["transmission_factor"], m["transmission"] = 1.0, 1.0
        m["ior"] = draw(st.sampled_from([1.33, 1.5]))
    if draw(st.booleans()):
        m["diffuse_texture"] = draw(textures)
    if kind == "specular" and draw(st.booleans()):
        m["specular_texture"] = draw(textures)
    # rarer options are drawn as "== last value": hypothesis shrinks towards 0, without them
    if draw(st.integers(0, 3)) == 3:
        m["normal_texture"] = draw(textures)
    if cutouts and draw(st.integers(0, 2)) == 2:
        m["alpha_mode"] = draw(st.sampled_from(["mask", "blend"]))
        m["opacity"] = draw(st.sampled_from([0.0, 0.3, 0.7, 1.0]))
        m["alpha_cutoff"] = draw(st.sampled_from([0.25, 0.5]))
        if draw(st.booleans()):
            m["opacity_texture"] = draw(textures)
    return m


motions = st.one_of(
    st.none(),
    st.fixed_dictionaries({
        "translate": st.sampled_from([[0.5, 0.0, 0.0], [0.0, 0.3, 0.4], [-1.0, 0.5, 0.2]]),
        "axis": st.sampled_from([[0.0, 0.0, 1.0], [1.0, 1.0, 0.0]]),
        "degrees": st.sampled_from([0.0, 30.0, 180.0]),
    }),
)
OBJECT_SLOTS = ("ball", "block", "card")


@st.composite
def objects(draw):
    """One to three of the scene's objects, each with a material, motion and options."""
    chosen = draw(st.lists(st.sampled_from(OBJECT_SLOTS), min_size=1, max_size=3, unique=True))
    result = []
    for slot in sorted(chosen, key=OBJECT_SLOTS.index):
        o = {"slot": slot, "material": draw(materials()), "motion": draw(motions),
             "smooth": draw(st.booleans()), "vertex_colours": draw(st.booleans())}
        if slot == "ball" and o["material"]["kind"] in ("glass", "absorbing_glass"):
            # nested media: a smaller ball of another medium inside the glass one (or a
            # solid or glowing ball embedded in the glass)
            o["inner"] = draw(st.one_of(st.none(), materials(("glass", "absorbing_glass", "diffuse",
                                                              "emissive"), False)))
        result.append(o)
    return result


lights = st.lists(st.one_of(
    st.fixed_dictionaries({"type": st.just("point"), "intensity": st.sampled_from([5.0, [20.0, 10.0, 5.0]])}),
    st.fixed_dictionaries({"type": st.just("spot"), "intensity": st.sampled_from([10.0, 40.0]),
                           "angles": st.sampled_from([(0.0, 10.0), (20.0, 30.0), (45.0, 45.0)])}),
    st.fixed_dictionaries({"type": st.just("projector"), "intensity": st.sampled_from([20.0, [30.0, 20.0, 10.0]]),
                           "fov": st.sampled_from([25.0, 70.0]), "seed": st.integers(0, 3)}),
    st.fixed_dictionaries({"type": st.just("directional"), "irradiance": st.sampled_from([1.0, [2.0, 1.5, 1.0]]),
                           "direction": st.sampled_from([[0.0, 0.0, -1.0], [1.0, 2.0, -1.0]])}),
    st.fixed_dictionaries({"type": st.just("quad"), "radiance": st.sampled_from([2.0, [5.0, 4.0, 3.0]]),
                           "visible": st.booleans()}),
    st.fixed_dictionaries({"type": st.just("disk"), "radiance": st.sampled_from([3.0, [6.0, 5.0, 4.0]]),
                           "visible": st.booleans()}),
), max_size=3)

backgrounds = st.one_of(
    st.fixed_dictionaries({"type": st.just("solid"), "colour": colours}),
    st.fixed_dictionaries({"type": st.just("gradient"), "top": colours, "bottom": colours,
                           "lighting": st.booleans()}),
    st.fixed_dictionaries({"type": st.just("environment"), "seed": st.integers(0, 2**16),
                           "rotation": st.sampled_from([0.0, 90.0]),
                           "intensity": st.sampled_from([0.5, 2.0]), "lighting": st.booleans()}),
    st.fixed_dictionaries({"type": st.just("transparent")}),
)

camera_media = st.one_of(
    st.none(),
    # the camera inside a glass bubble, possibly inside a water bubble
    st.fixed_dictionaries({"glass": materials(("glass", "absorbing_glass"), False),
                           "water": st.one_of(st.none(), materials(("glass", "absorbing_glass"), False)),
                           "motion": motions}),
)


@st.composite
def render_settings(draw):
    """Render settings: sampler, spp, depth, passes, AO, adaptive sampling, chunks."""
    adaptive = draw(st.booleans())
    sampler = draw(st.sampled_from(SAMPLERS))
    spp = draw(st.integers(2 if adaptive else 1, 4))
    if sampler == "zsobol":  # a power of two: another is rounded up with a warning
        spp = 1 << (spp - 1).bit_length()
    s = {
        "sampler": sampler,
        "spp": spp,
        "max_depth": draw(st.integers(0, 6)),
        "cutoff": draw(st.sampled_from([1e-3, 0.0])),
        "seed": draw(st.integers(0, 1000)),
        "light_samples": draw(st.integers(1, 3)),
        "ao_samples": draw(st.sampled_from([0, 0, 1, 2])),
        "ao_distance": draw(st.sampled_from([None, 0.5])),
        "fresnel": draw(st.sampled_from(["schlick", "exact"])),
        "passes": tuple(draw(st.lists(st.sampled_from(PASS_NAMES), unique=True, max_size=len(PASS_NAMES)))),
    }
    if adaptive:
        s["target_error"] = draw(st.sampled_from([0.01, 0.1, 0.5]))
        s["max_spp"] = draw(st.sampled_from([spp, 2 * spp, 4 * spp]))
    # the chunk size of both renders: small, so both threads take several chunks (which of
    # two coplanar overlapping triangles a ray reports may depend on the rays sharing its
    # Embree packet, hence on the chunks: see rtmesh.rendering.scheduler)
    s["chunk_samples"] = draw(st.integers(16, 200))
    return s




@st.composite
def scene_descriptions(draw):
    """Everything one example renders: scene, camera, lights, background and settings, under
    either integrator."""
    d = {
        "objects": draw(objects()),
        "floor": draw(st.one_of(st.none(), materials(("diffuse", "specular", "mirror", "glossy")))),
        # the block's bottom in the floor's plane (coplanar overlapping triangles), or 0.01 above
        "block_on_floor": draw(st.booleans()),
        "lights": draw(lights),
        "ambient": draw(st.sampled_from([0.0, 0.1])),
        "background": draw(backgrounds),
        "camera_media": draw(camera_media),
        "aperture": draw(st.sampled_from([0.0, 0.0, 0.2])),
        "shutter": draw(st.sampled_from([(0.0, 0.0), (0.0, 1.0), (0.4, 0.4), (-0.5, 0.5)])),
        "settings": draw(render_settings()),
    }
    integrator = draw(st.sampled_from(["whitted", "path"]))
    d["settings"]["integrator"] = integrator
    if integrator == "path":
        # the keys only Whitted reads (path warns that it ignores them); light_samples is
        # read by both
        d["ambient"] = 0.0
        d["settings"].update(cutoff=1e-3, ao_samples=0)
    if integrator == "whitted":
        # the light-path passes exist under the path integrator only
        d["settings"]["passes"] = tuple(p for p in d["settings"]["passes"] if p not in LIGHT_PATH_PASSES)
    return d


# ---------------------------------------------------------------- building the scene
def make_texture(t, channels=4, normal_map=False):
    """A small random texture from a :data:`textures` description."""
    rng = np.random.default_rng(t["seed"])
    size = t["size"]
    if normal_map:
        # valid tangent-space normals (z > 0), encoded as 0.5 + 0.5 n
        n = rng.normal(size=(size, size, 3)) * [0.5, 0.5, 0.0] + [0.0, 0.0, 1.0]
        n /= np.linalg.norm(n, axis=2, keepdims=True)
        return Texture(0.5 + 0.5 * n, wrap=t["wrap"])
    pixels = rng.uniform(0.0, 1.0, size=(size, size, channels))
    # some fully transparent and some fully opaque texels (alpha, or map_d's first channel)
    alpha = pixels[..., -1] if channels == 4 else pixels[..., 0]
    alpha[alpha < 0.3] = 0.0
    alpha[alpha > 0.7] = 1.0
    return Texture(pixels, wrap=t["wrap"])


def make_material(m, name):
    """A :class:`Material` from a :func:`materials` description."""
    options = {key: m[key] for key in ("diffuse", "specular", "shininess", "mirror", "metallic",
                                       "roughness", "transmission", "ior", "absorption",
                                       "emission", "unlit", "alpha_mode", "opacity", "alpha_cutoff",
                                       "model", "base_color", "perceptual_roughness", "transmission_factor")
               if key in m}
    for key in ("diffuse_texture", "specular_texture", "emission_texture", "opacity_texture",
                "metallic_roughness_texture"):
        if key in m:
            options[key] = make_texture(m[key], channels=4 if key == "diffuse_texture" else 3)
    if "normal_texture" in m:
        options["normal_texture"] = make_texture(m["normal_texture"], normal_map=True)
    return Material(name, **options)


def planar_uv(vertices):
    """Texture coordinates u = x + y, v = z (the block's sides each get a gradient)."""
    return np.stack([vertices[:, 0] + vertices[:, 1], vertices[:, 2]], axis=1)


def sphere_uv(vertices, centre):
    """Latitude-longitude texture coordinates of a sphere around ``centre``."""
    d = vertices - centre
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return np.stack([np.arctan2(d[:, 1], d[:, 0]) / (2 * np.pi) + 0.5,
                     np.arcsin(np.clip(d[:, 2], -1.0, 1.0)) / np.pi + 0.5], axis=1)


def quad_mesh(corners):
    """Two triangles over four corners (counter-clockwise from the front), trimesh-like."""
    vertices = np.asarray(corners, dtype=np.float64)
    normal = np.cross(vertices[1] - vertices[0], vertices[2] - vertices[0])
    return types.SimpleNamespace(vertices=vertices, faces=np.array([[0, 1, 2], [0, 2, 3]]),
                                 vertex_normals=np.tile(normal / np.linalg.norm(normal), (4, 1)))


def mesh_part(name, mesh, material, smooth=False, uv=None, colours=None, motion=None):
    """A :class:`MeshPart` of a trimesh mesh (or :func:`quad_mesh`)."""
    vertices = np.array(mesh.vertices, dtype=np.float64)
    return MeshPart(name, vertices, np.array(mesh.faces), material,
                    np.array(mesh.vertex_normals) if smooth else None,
                    motion=motion, uv=uv, vertex_colors=colours)


CAMERA = np.array([0.2, -4.0, 2.2])
LOOK_AT = np.array([0.0, 0.0, 0.5])
BALL_CENTRE = np.array([-0.8, 0.3, 0.6])


def build_scene(d):
    """The :class:`Scene` of a :func:`scene_descriptions` example."""
    materials, parts = [], []

    def add_material(m, name):
        materials.append(make_material(m, name))
        return len(materials) - 1

    rng = np.random.default_rng(len(d["objects"]))
    for o in d["objects"]:
        slot = o["slot"]
        index = add_material(o["material"], slot)
        if slot == "ball":
            mesh = icosphere(2, 0.6, BALL_CENTRE)
            uv = sphere_uv(mesh.vertices, BALL_CENTRE)
        elif slot == "block":
            mesh = box((0.7, 0.7, 0.7), (0.8, 0.4, 0.35 if d["block_on_floor"] else 0.36))
            uv = planar_uv(mesh.vertices)
        else:  # a card standing upright, facing the camera
            mesh = quad_mesh([[-0.6, -0.6, 0.1], [0.6, -0.6, 0.1], [0.6, -0.6, 1.1], [-0.6, -0.6, 1.1]])
            uv = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
        colours = rng.uniform(0.2, 1.0, (len(mesh.vertices), 4)) if o["vertex_colours"] else None
        motion = Motion(**o["motion"]) if o["motion"] else None
        parts.append(mesh_part(slot, mesh, index, o["smooth"], uv, colours, motion))
        if o.get("inner"):
            inner = icosphere(2, 0.3, BALL_CENTRE)
            parts.append(mesh_part("inner", inner, add_material(o["inner"], "inner"), True,
                                   sphere_uv(inner.vertices, BALL_CENTRE), None, motion))
    if d["floor"] is not None:
        s = 4.0
        floor = quad_mesh([[-s, -s, 0.0], [s, -s, 0.0], [s, s, 0.0], [-s, s, 0.0]])
        parts.append(mesh_part("floor", floor, add_material(d["floor"], "floor"),
                               uv=floor.vertices[:, :2] / 2.0))
    if d["camera_media"] is not None:
        bubble = d["camera_media"]
        motion = Motion(**bubble["motion"]) if bubble["motion"] else None
        glass = icosphere(2, 0.4, CAMERA)
        parts.append(mesh_part("bubble", glass, add_material(bubble["glass"], "bubble"), True,
                               sphere_uv(glass.vertices, CAMERA), None, motion))
        if bubble["water"] is not None:
            water = icosphere(2, 0.7, CAMERA)
            parts.append(mesh_part("water", water, add_material(bubble["water"], "water"), True,
                                   sphere_uv(water.vertices, CAMERA), None, motion))

    scene_lights = []
    for light in d["lights"]:
        kind = light["type"]
        if kind == "point":
            scene_lights.append(PointLight([1.5, -2.0, 3.0], light["intensity"]))
        elif kind == "spot":
            inner, outer = light["angles"]
            scene_lights.append(SpotLight([-1.0, -2.0, 3.0], LOOK_AT - [-1.0, -2.0, 3.0], light["intensity"],
                                          inner, outer))
        elif kind == "projector":
            gobo = Texture(np.random.default_rng(light["seed"]).uniform(0.0, 1.0, (6, 9, 3)), wrap="clamp")
            scene_lights.append(ProjectorLight([0.5, -2.5, 3.0], LOOK_AT - [0.5, -2.5, 3.0], light["intensity"],
                                               gobo, light["fov"]))
        elif kind == "directional":
            scene_lights.append(DirectionalLight(light["direction"], light["irradiance"]))
        elif kind == "quad":
            # 1 x 0.8 panel above the scene, emitting down
            scene_lights.append(QuadLight([0.0, 0.0, 2.5], [1.0, 0.0, 0.0], [0.0, -0.8, 0.0],
                                          light["radiance"], light["visible"]))
        else:
            scene_lights.append(DiskLight([1.5, 1.0, 2.0], LOOK_AT - [1.5, 1.0, 2.0], 0.4,
                                          light["radiance"], light["visible"]))

    b = d["background"]
    if b["type"] == "solid":
        background = as_colour(b["colour"])
    elif b["type"] == "gradient":
        background = GradientBackground(as_colour(b["top"]), as_colour(b["bottom"]))
        background.lighting = b["lighting"]
    elif b["type"] == "environment":
        pixels = np.random.default_rng(b["seed"]).uniform(0.0, 1.0, (4, 8, 3))
        background = EnvironmentBackground(pixels, b["rotation"], b["intensity"])
        background.lighting = b["lighting"]
    else:
        background = TransparentBackground()

    aperture = d["aperture"]
    camera = Camera(CAMERA, LOOK_AT, [0.0, 0.0, 1.0], 50.0, aperture=aperture,
                    focus_distance=4.0 if aperture else None, shutter=d["shutter"])
    return Scene.from_parts(parts, materials, scene_lights, camera, ambient=np.full(3, d["ambient"]),
                            background=background)


# ---------------------------------------------------------------- rendering and checks
class _Records(logging.Handler):
    """Keeps every log record at WARNING or above."""

    def __init__(self):
        super().__init__(logging.WARNING)
        self.records = []

    def emit(self, record):
        self.records.append(record)


def render_quietly(d, threads, chunk_samples=None):
    """Render a description; fail on any Python warning or WARNING log record."""
    options = {k: v for k, v in d["settings"].items() if k != "chunk_samples"}
    if chunk_samples is not None:
        options["chunk_samples"] = chunk_samples
    records = _Records()
    root = logging.getLogger()
    root.addHandler(records)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            # NumPy's defaults, whatever an earlier test set: underflow to 0 is no error
            with np.errstate(divide="warn", over="warn", invalid="warn", under="ignore"):
                scene = build_scene(d)
                result = Integrator(scene, settings(width=WIDTH, height=HEIGHT, threads=threads,
                                                    **options)).render()
    finally:
        root.removeHandler(records)
    assert not caught, [f"{w.category.__name__}: {w.message} ({w.filename}:{w.lineno})" for w in caught]
    assert not records.records, [r.getMessage() for r in records.records]
    return result


def check(d):
    """Render ``d`` on 1 thread and on 2, in the same small chunks, and check both."""
    one = render_quietly(d, threads=1, chunk_samples=d["settings"]["chunk_samples"])
    assert_finite(one)
    assert set(one.passes) == set(d["settings"]["passes"])
    if one.alpha is not None:
        assert np.isfinite(one.alpha).all()
    two = render_quietly(d, threads=2, chunk_samples=d["settings"]["chunk_samples"])
    assert np.array_equal(one.image, two.image), "1 and 2 threads give different images"
    for name in one.passes:
        # (equal_nan: a miss is NaN in position_center and normal_center)
        assert np.array_equal(one.passes[name], two.passes[name], equal_nan=True), f"pass {name!r} differs"
    assert (one.alpha is None) == (two.alpha is None)
    if one.alpha is not None:
        assert np.array_equal(one.alpha, two.alpha)
    return one


# derandomized and without a database: every run draws the same examples; no "explain"
# phase (it reruns failing examples for coverage, slowly, and names only library lines)
COMMON = dict(deadline=None, database=None, derandomize=True, print_blob=True,
              phases=[Phase.explicit, Phase.reuse, Phase.generate, Phase.shrink],
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


@hypothesis_settings(max_examples=100, **COMMON)
@given(scene_descriptions())
def test_random_feature_combinations_render_finite_quiet_and_thread_independent(d):
    result = check(d)
    # what the examples exercised: pytest --hypothesis-show-statistics lists these
    for stage in result.stats.stages_enabled:
        event(f"stage {stage}")
    event(f"sampler {d['settings']['sampler']}")
    event(f"integrator {d['settings']['integrator']}")
    event("adaptive" if "target_error" in d["settings"] else "uniform")
    if d["camera_media"]:
        event("camera in glass" + (" in water" if d["camera_media"]["water"] else ""))


@pytest.mark.slow
@hypothesis_settings(max_examples=1000, **COMMON)
@given(scene_descriptions())
def test_many_random_feature_combinations(d):
    check(d)
