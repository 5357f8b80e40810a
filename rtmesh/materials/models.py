"""The material models of the path integrator: one module per model, one registry entry each,
and the compiled dispatch by a small integer tag (as pbrt-v4 dispatches its BxDFs by tag).

A model module (:mod:`~rtmesh.materials.lambert`, :mod:`~rtmesh.materials.oren_nayar`,
:mod:`~rtmesh.materials.conductor`, :mod:`~rtmesh.materials.dielectric`,
:mod:`~rtmesh.materials.gltf_pbr`, :mod:`~rtmesh.materials.gltf_layered`,
:mod:`~rtmesh.materials.phong`) provides

- ``NAME``: the name a material's ``model`` field (scene files: ``[materials.X] model``) holds;
- ``parameters(material)``: its float row (at most :data:`~rtmesh.materials.lobes.PARAMETER_WIDTH`)
  from a :class:`~rtmesh.materials.table.Material`;
- optionally ``transmissive(material)``: whether light passes through it (default: no);
- ``SLOTS``: which parameters image textures scale per hit (:data:`SLOT_NAMES`: the colour
  the base-colour texture and vertex colours multiply, the specular and mirror colours,
  glTF's metallic, roughness and the alpha formed from it, the KHR layers' factors their
  textures scale), where a transmissive model's index of refraction is (the path kernel
  sets the ratio of the media on both sides there, for nested media), and where a layered
  model wants its clear coat's normal and anisotropy direction in the local frame
  (``coat_normal``: :func:`rtmesh.rendering.path_surfaces.orient_layers` writes them per hit);
- compiled rows (``@row``) taking the parameter table, the material's row index, the pair of
  energy tables (:func:`tables`) and local-frame directions:
  ``evaluate(params, m, table, wo..., wi...) -> f|cos| r, g, b, pdf``,
  ``sample(params, m, table, wo..., u0, u1, u2) -> wi..., weight r, g, b, pdf, flags``,
  ``parts(params, m, table, wo..., wi...) -> diffuse r, g, b, transmission r, g, b``, the
  diffuse and transmitted parts of ``evaluate``'s ``f |cos|`` (the rest is glossy; for the
  light-path passes),
  ``albedo(params, m) -> r, g, b`` (conventions in :mod:`~rtmesh.materials.lobes`).

Adding a model: its module, one line in :data:`MODULES` and one branch in each of the four
dispatch rows below (numba has no virtual calls; the branches are the tag switch).
"""

from dataclasses import dataclass

import numpy as np

from rtmesh.core.compiled import kernel, row
from rtmesh.materials import (conductor, dielectric, dielectric_albedo, ggx_albedo, gltf_layered, gltf_pbr, lambert,
                              lobes, oren_nayar, phong, sheen)

# the order gives the tags: 0 .. len - 1
MODULES = (phong, gltf_pbr, lambert, oren_nayar, conductor, dielectric, gltf_layered)
BLINN_PHONG, METALLIC_ROUGHNESS, LAMBERT, OREN_NAYAR, CONDUCTOR, DIELECTRIC, GLTF_LAYERED = range(len(MODULES))


@dataclass(frozen=True)
class MaterialModel:
    """One registered model: its name, tag and module."""

    name: str
    tag: int
    module: object

    def parameters(self, material):
        """The model's parameter row of ``material``, padded to the table's width."""
        values = list(self.module.parameters(material))
        if len(values) > lobes.PARAMETER_WIDTH:
            raise ValueError(f"material model {self.name!r} has more than {lobes.PARAMETER_WIDTH} parameters")
        return values + [0.0] * (lobes.PARAMETER_WIDTH - len(values))

    def transmissive(self, material):
        """Whether light passes through ``material`` under this model."""
        test = getattr(self.module, "transmissive", None)
        return bool(test(material)) if test is not None else self.module is dielectric


# the parameters a hit's textures scale, by model tag: column k holds the index of the first
# parameter of SLOT_NAMES[k] in the model's row, or -1 (rtmesh.rendering.path_kernel)
SLOT_NAMES = ("colour", "specular", "mirror", "metallic", "roughness", "alpha", "ior",
              # the KHR layers of glTF (rtmesh.materials.gltf_layered)
              "specular_colour", "specular_strength", "clearcoat", "clearcoat_roughness", "coat_normal",
              "sheen_colour", "sheen_roughness", "anisotropy", "iridescence", "iridescence_thickness")
SLOTS = np.array([[module.SLOTS.get(name, -1) for name in SLOT_NAMES] for module in MODULES], dtype=np.int64)
(COLOUR_SLOT, SPECULAR_SLOT, MIRROR_SLOT, METALLIC_SLOT, ROUGHNESS_SLOT, ALPHA_SLOT, IOR_SLOT,
 SPECULAR_COLOUR_SLOT, SPECULAR_STRENGTH_SLOT, CLEARCOAT_SLOT, CLEARCOAT_ROUGHNESS_SLOT, COAT_NORMAL_SLOT,
 SHEEN_COLOUR_SLOT, SHEEN_ROUGHNESS_SLOT, ANISOTROPY_SLOT, IRIDESCENCE_SLOT, IRIDESCENCE_THICKNESS_SLOT) = range(
    len(SLOT_NAMES))

REGISTRY = {module.NAME: MaterialModel(module.NAME, tag, module) for tag, module in enumerate(MODULES)}
MODEL_NAMES = tuple(REGISTRY)


def tables():
    """The energy tables the models read, as the one ``table`` argument of the rows: the GGX
    albedo of :mod:`~rtmesh.materials.ggx_albedo` (rough metals), the interface albedo of
    :mod:`~rtmesh.materials.dielectric_albedo` (rough glass) and the sheen albedo of
    :mod:`~rtmesh.materials.sheen` (KHR_materials_sheen's albedo scaling)."""
    return ggx_albedo.table(), dielectric_albedo.table(), sheen.table()


def material_rows(materials, names=None):
    """The tables the path integrator reads per hit.

    Parameters
    ----------
    materials : sequence of Material
    names : sequence of str, optional
        The model of each material (default: its ``model``).

    Returns
    -------
    tags : (m,) int64
        Each material's model tag.
    params : (m, PARAMETER_WIDTH) float64
    transmissive : (m,) bool
    """
    models = [REGISTRY[name] for name in (names or [material.model for material in materials])]
    tags = np.array([model.tag for model in models], dtype=np.int64)
    params = np.array([model.parameters(material) for model, material in zip(models, materials)],
                      dtype=np.float64).reshape(len(models), lobes.PARAMETER_WIDTH)
    transmissive = np.array([model.transmissive(material) for model, material in zip(models, materials)],
                            dtype=bool)
    return tags, params, transmissive


# evaluate and sample are kernels of their own (cached on disk), not rows inlined into every
# caller: a first run's helper process compiles them while the render compiles the path
# kernel that calls them (rtmesh.rendering.path_signatures.PATH_KERNELS)
@kernel
def evaluate(tag, params, m, table, ox, oy, oz, wx, wy, wz):
    """``f(wo, wi) |wi.z|`` (r, g, b) and the density with which :func:`sample` draws ``wi``."""
    if tag == BLINN_PHONG:
        return phong.evaluate(params, m, table, ox, oy, oz, wx, wy, wz)
    if tag == METALLIC_ROUGHNESS:
        return gltf_pbr.evaluate(params, m, table, ox, oy, oz, wx, wy, wz)
    if tag == LAMBERT:
        return lambert.evaluate(params, m, table, ox, oy, oz, wx, wy, wz)
    if tag == OREN_NAYAR:
        return oren_nayar.evaluate(params, m, table, ox, oy, oz, wx, wy, wz)
    if tag == CONDUCTOR:
        return conductor.evaluate(params, m, table, ox, oy, oz, wx, wy, wz)
    if tag == GLTF_LAYERED:
        return gltf_layered.evaluate(params, m, table, ox, oy, oz, wx, wy, wz)
    return dielectric.evaluate(params, m, table, ox, oy, oz, wx, wy, wz)


@kernel
def sample(tag, params, m, table, ox, oy, oz, u0, u1, u2):
    """Draw ``wi``: ``(wx, wy, wz, weight r, g, b, pdf, flags)``."""
    if tag == BLINN_PHONG:
        return phong.sample(params, m, table, ox, oy, oz, u0, u1, u2)
    if tag == METALLIC_ROUGHNESS:
        return gltf_pbr.sample(params, m, table, ox, oy, oz, u0, u1, u2)
    if tag == LAMBERT:
        return lambert.sample(params, m, table, ox, oy, oz, u0, u1, u2)
    if tag == OREN_NAYAR:
        return oren_nayar.sample(params, m, table, ox, oy, oz, u0, u1, u2)
    if tag == CONDUCTOR:
        return conductor.sample(params, m, table, ox, oy, oz, u0, u1, u2)
    if tag == GLTF_LAYERED:
        return gltf_layered.sample(params, m, table, ox, oy, oz, u0, u1, u2)
    return dielectric.sample(params, m, table, ox, oy, oz, u0, u1, u2)


@kernel
def parts(tag, params, m, table, ox, oy, oz, wx, wy, wz):
    """The diffuse and transmitted parts (r, g, b each) of :func:`evaluate`'s ``f |cos|``."""
    if tag == BLINN_PHONG:
        return phong.parts(params, m, table, ox, oy, oz, wx, wy, wz)
    if tag == METALLIC_ROUGHNESS:
        return gltf_pbr.parts(params, m, table, ox, oy, oz, wx, wy, wz)
    if tag == LAMBERT:
        return lambert.parts(params, m, table, ox, oy, oz, wx, wy, wz)
    if tag == OREN_NAYAR:
        return oren_nayar.parts(params, m, table, ox, oy, oz, wx, wy, wz)
    if tag == CONDUCTOR:
        return conductor.parts(params, m, table, ox, oy, oz, wx, wy, wz)
    if tag == GLTF_LAYERED:
        return gltf_layered.parts(params, m, table, ox, oy, oz, wx, wy, wz)
    return dielectric.parts(params, m, table, ox, oy, oz, wx, wy, wz)


@kernel
def parts_many(tag, params, m, table, wo, wi):
    """:func:`parts` of rows of local directions ((k, 3) each) -> (k, 3) diffuse, (k, 3) transmitted."""
    k = wo.shape[0]
    diffuse = np.zeros((k, 3))
    transmitted = np.zeros((k, 3))
    for i in range(k):
        (diffuse[i, 0], diffuse[i, 1], diffuse[i, 2], transmitted[i, 0], transmitted[i, 1],
         transmitted[i, 2]) = parts(tag, params, m, table, wo[i, 0], wo[i, 1], wo[i, 2], wi[i, 0], wi[i, 1], wi[i, 2])
    return diffuse, transmitted


@row
def albedo(tag, params, m):
    """The model's albedo (r, g, b), for the denoiser's guide."""
    if tag == BLINN_PHONG:
        return phong.albedo(params, m)
    if tag == METALLIC_ROUGHNESS:
        return gltf_pbr.albedo(params, m)
    if tag == LAMBERT:
        return lambert.albedo(params, m)
    if tag == OREN_NAYAR:
        return oren_nayar.albedo(params, m)
    if tag == CONDUCTOR:
        return conductor.albedo(params, m)
    if tag == GLTF_LAYERED:
        return gltf_layered.albedo(params, m)
    return dielectric.albedo(params, m)


# ------------------------------------------------------------------ batches (tests, tables)
@kernel
def evaluate_many(tag, params, m, table, wo, wi):
    """:func:`evaluate` of rows of local directions ((k, 3) each) -> (k, 3) ``f |cos|``, (k,) pdf."""
    k = wo.shape[0]
    f = np.zeros((k, 3))
    pdf = np.zeros(k)
    for i in range(k):
        f[i, 0], f[i, 1], f[i, 2], pdf[i] = evaluate(tag, params, m, table, wo[i, 0], wo[i, 1], wo[i, 2],
                                                     wi[i, 0], wi[i, 1], wi[i, 2])
    return f, pdf


@kernel
def sample_many(tag, params, m, table, wo, u):
    """:func:`sample` of rows of local ``wo`` (k, 3) with numbers ``u`` (k, 3) -> (k, 3) ``wi``,
    (k, 3) weights, (k,) pdf, (k,) flags."""
    k = wo.shape[0]
    wi = np.zeros((k, 3))
    weight = np.zeros((k, 3))
    pdf = np.zeros(k)
    flags = np.zeros(k, np.int64)
    for i in range(k):
        (wi[i, 0], wi[i, 1], wi[i, 2], weight[i, 0], weight[i, 1], weight[i, 2], pdf[i],
         flags[i]) = sample(tag, params, m, table, wo[i, 0], wo[i, 1], wo[i, 2], u[i, 0], u[i, 1], u[i, 2])
    return wi, weight, pdf, flags
