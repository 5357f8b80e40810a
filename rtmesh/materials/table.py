"""Materials: the Blinn-Phong surface model with mirror reflection and dielectric transmission.

A material's reflected radiance toward ``wo`` under a light of incident radiance-like term
``E`` (intensity / distance^2 for point lights, irradiance for directional lights) from
``wi`` is::

    L = emission + ambient * ambient_light * ao
        + sum over lights of E * (diffuse * cos(theta_i) + specular * max(0, n.h)^shininess)

(no 1/pi: ``diffuse`` is the classic Phong kd).  On top of that local term a material can
spawn a mirror-reflected ray weighted by ``mirror`` (a colour: metals tint their
reflections) and, when ``transmission`` > 0, behaves as a smooth dielectric of index
``ior``: it reflects with the Fresnel weight ``F * transmission`` and refracts with
``(1 - F) * transmission``; inside, light is attenuated by Beer-Lambert with ``absorption``
(per scene unit).
"""

from dataclasses import dataclass, field

import numpy as np

from rtmesh.materials.models import MODEL_NAMES


def as_colour(value):
    """A colour from a number (grey) or three numbers, as a (3,) float64 array."""
    a = np.asarray(value, dtype=np.float64)
    return np.repeat(a, 3) if a.ndim == 0 else a.reshape(3)


ALPHA_MODES = ("opaque", "mask", "blend")
# how a material reflects light toward the lights and which rays it sends (see Material.model);
# the path integrator's registry (rtmesh.materials.models) names them
MODELS = MODEL_NAMES
COLOUR_FIELDS = ("diffuse", "specular", "ambient", "mirror", "transmission", "absorption",
                 "emission", "base_color")
# the glTF models the Whitted integrator shades with the metallic-roughness BRDF
PHYSICAL_MODELS = ("metallic_roughness", "gltf_layered")
TEXTURE_FIELDS = ("diffuse_texture", "specular_texture", "opacity_texture", "normal_texture", "emission_texture",
                  "metallic_roughness_texture", "occlusion_texture")


@dataclass
class Material:
    """One surface material; colours are linear RGB.

    Attributes
    ----------
    name : str
    model : {"blinn_phong", "metallic_roughness"}
        ``blinn_phong`` (MTL and scene-file materials): the fields above the glTF ones,
        lit by the Whitted integrator (specular lobes followed, no diffuse bounce).
        ``metallic_roughness`` (glTF materials): the glTF 2.0 BRDF of
        :mod:`rtmesh.materials.metallic_roughness` with ``base_color``, ``metallic`` and
        ``perceptual_roughness`` (times the base-colour and metallic-roughness textures),
        sampled and path traced (the path kernel; ``tests/wavefront/physical_shading.py``, its NumPy reference); its
        ``diffuse`` is ``base_color (1 - metallic)``, kept for the albedo pass and the
        ambient term, and its Blinn-Phong fields are otherwise unused.
    diffuse : (3,) float
        Lambert reflectance kd.
    specular : (3,) float
        Blinn-Phong specular reflectance ks.
    shininess : float
        Blinn-Phong exponent (larger = smaller, sharper highlight).
    ambient : (3,) float or None
        Ambient reflectance ka; None means "same as diffuse".
    mirror : (3,) float
        Mirror reflectance kr (tinted for metals).
    transmission : (3,) float
        Fraction of light handled as a smooth dielectric; > 0 makes the material refract.
    ior : float
        Index of refraction of the interior.
    absorption : (3,) float
        Beer-Lambert absorption coefficient of the interior, 1 / scene unit.
    emission : (3,) float
        Emitted radiance.
    roughness : float
        Blur of the mirror (and dielectric) reflection: 0 is a perfect mirror, r > 0 a lobe
        about r radians wide around the mirror direction (see :mod:`rtmesh.materials.glossy`).
    opacity : float
        Coverage in [0, 1] (MTL ``d``, glTF base-colour alpha); used by ``alpha_mode``.
    alpha_mode : {"opaque", "mask", "blend"}
        "opaque" ignores opacity; "mask" lets rays through where opacity < ``alpha_cutoff``;
        "blend" lets them through with probability 1 - opacity (see :mod:`rtmesh.geometry.cutouts`).
    alpha_cutoff : float
        Threshold of the "mask" mode.
    unlit : bool
        Shows ``diffuse`` (times textures) as is, with no lighting, and lights nothing
        (MTL ``illum 0``, glTF KHR_materials_unlit).
    metallic : float
        In [0, 1]: how much the base-colour texture also tints ``specular`` and ``mirror``
        (metals reflect in their own colour); see :mod:`rtmesh.rendering.surface_textures`.
    double_sided : bool
        Kept from glTF for reference; both sides of every triangle are always shaded.
    base_color : (3,) float
        glTF ``baseColorFactor`` (linear RGB) of a ``metallic_roughness`` material.
    perceptual_roughness : float
        glTF ``roughnessFactor`` in [0, 1] of a ``metallic_roughness`` material (the GGX
        alpha is its square).
    transmission_factor : float
        KHR_materials_transmission's factor of a ``metallic_roughness`` material: that part
        of its dielectric diffuse term is transmitted instead, through the smooth
        refraction of ``transmission`` (= factor x base colour x (1 - metallic)) and ``ior``.
    occlusion_strength : float
        glTF ``occlusionTexture.strength``: the baked occlusion darkens the ambient term
        ``1 + strength (texel - 1)`` (traced light carries its own shadows).
    diffuse_texture, specular_texture, opacity_texture, normal_texture, emission_texture : Texture or None
        Image textures (:class:`rtmesh.io.texture_images.Texture`): base colour (multiplies
        ``diffuse`` and ``ambient``; its alpha multiplies ``opacity``), specular colour
        (multiplies ``specular``), opacity (first channel multiplies ``opacity``), a
        tangent-space normal map, and emitted colour (multiplies ``emission``, both where
        the surface is seen and where it lights others).
    metallic_roughness_texture, occlusion_texture : Texture or None
        glTF textures of a ``metallic_roughness`` material: roughness in the green channel
        and metalness in the blue one (multiplying ``perceptual_roughness`` and
        ``metallic``), and baked ambient occlusion in the red one.
    layers : rtmesh.materials.gltf_layered.Layers or None
        The KHR layer extensions (specular, clear coat, sheen, anisotropy, iridescence) of a
        ``gltf_layered`` material, with their textures; rendered under the path integrator
        only (Whitted shades such a material as ``metallic_roughness``).
    """

    name: str = "default"
    model: str = "blinn_phong"
    diffuse: np.ndarray = field(default_factory=lambda: np.full(3, 0.7))
    specular: np.ndarray = field(default_factory=lambda: np.zeros(3))
    shininess: float = 32.0
    ambient: np.ndarray | None = None
    mirror: np.ndarray = field(default_factory=lambda: np.zeros(3))
    transmission: np.ndarray = field(default_factory=lambda: np.zeros(3))
    ior: float = 1.5
    absorption: np.ndarray = field(default_factory=lambda: np.zeros(3))
    emission: np.ndarray = field(default_factory=lambda: np.zeros(3))
    roughness: float = 0.0
    opacity: float = 1.0
    alpha_mode: str = "opaque"
    alpha_cutoff: float = 0.5
    unlit: bool = False
    metallic: float = 0.0
    double_sided: bool = False
    diffuse_texture: object = None
    specular_texture: object = None
    opacity_texture: object = None
    normal_texture: object = None
    emission_texture: object = None
    base_color: np.ndarray = field(default_factory=lambda: np.ones(3))
    perceptual_roughness: float = 1.0
    transmission_factor: float = 0.0
    occlusion_strength: float = 1.0
    metallic_roughness_texture: object = None
    occlusion_texture: object = None
    layers: object = None

    def __post_init__(self):
        if self.model not in MODELS:
            raise ValueError(f"unknown material model {self.model!r}; expected one of " + ", ".join(MODELS))
        if self.alpha_mode not in ALPHA_MODES:
            raise ValueError(f"unknown alpha mode {self.alpha_mode!r}; expected one of "
                             + ", ".join(ALPHA_MODES))
        for name in COLOUR_FIELDS:
            value = getattr(self, name)
            if value is not None:
                setattr(self, name, as_colour(value))
        if self.ambient is None:
            self.ambient = self.diffuse.copy()


class MaterialTable:
    """The scene's materials as stacked arrays, indexed by material id.

    Attributes
    ----------
    materials : list of Material
    diffuse, specular, ambient, mirror, transmission, absorption, emission : (m, 3) float
    base_color : (m, 3) float
    shininess, ior, roughness, opacity, alpha_cutoff, metallic, perceptual_roughness, transmission_factor : (m,) float
    alpha_mode : (m,) int
        Index into :data:`ALPHA_MODES`.
    unlit : (m,) bool
    physical : (m,) bool
        Materials of the ``metallic_roughness`` model (and not unlit).
    """

    def __init__(self, materials):
        self.materials = list(materials)
        for name in COLOUR_FIELDS:
            setattr(self, name, np.array([getattr(m, name) for m in self.materials], dtype=np.float64).reshape(-1, 3))
        for name in ("shininess", "ior", "roughness", "opacity", "alpha_cutoff", "metallic",
                     "perceptual_roughness", "transmission_factor", "occlusion_strength"):
            setattr(self, name, np.array([getattr(m, name) for m in self.materials], dtype=np.float64))
        self.alpha_mode = np.array([ALPHA_MODES.index(m.alpha_mode) for m in self.materials], dtype=np.intp)
        self.unlit = np.array([m.unlit for m in self.materials], dtype=bool)
        self.physical = np.array([m.model in PHYSICAL_MODELS for m in self.materials], dtype=bool) & ~self.unlit

    def __len__(self):
        return len(self.materials)

    @property
    def any_physical(self):
        """True if any (lit) material has the glTF metallic-roughness model."""
        return bool(self.physical.any())

    @property
    def any_specular(self):
        """True if any material has a specular highlight."""
        return bool((self.specular > 0).any())

    @property
    def any_mirror(self):
        """True if any material spawns mirror-reflection rays."""
        return bool((self.mirror > 0).any())

    @property
    def any_transmission(self):
        """True if any material refracts."""
        return bool((self.transmission > 0).any())

    @property
    def any_glossy(self):
        """True if any material blurs the reflection rays it spawns (roughness > 0)."""
        reflects = (self.mirror > 0).any(axis=1) | (self.transmission > 0).any(axis=1)
        return bool(((self.roughness > 0) & reflects).any())

    @property
    def any_texture(self):
        """True if any material has an image texture."""
        return any(getattr(m, name) is not None for m in self.materials for name in TEXTURE_FIELDS)

    @property
    def cutout(self):
        """(m,) bool: materials that can let rays through (alpha mask or blend)."""
        return self.alpha_mode != ALPHA_MODES.index("opaque")

    @property
    def any_cutout(self):
        """True if any material can let rays through (see :mod:`rtmesh.geometry.cutouts`)."""
        return bool(self.cutout.any())

    @property
    def any_unlit(self):
        """True if any material shows its colour without lighting."""
        return bool(self.unlit.any())

    @property
    def any_emission(self):
        """True if any material emits."""
        return bool((self.emission > 0).any())

    @property
    def any_absorption(self):
        """True if any refracting material absorbs inside."""
        return bool(((self.absorption > 0).any(axis=1) & (self.transmission > 0).any(axis=1)).any())
