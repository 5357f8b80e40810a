"""The render plan: which optional stages a scene and its settings need, decided once.

The integrator looks at the scene and the settings before rendering and turns on only the
stages that can contribute (no refraction stage without transmissive materials, no texture
lookups without textures, no pass buffers nobody asked for); the plan is the frozen record
of that decision, and a render's stats list the stages it enabled.
"""

import dataclasses
from dataclasses import dataclass


@dataclass(frozen=True)
class RenderPlan:
    """Which optional stages run.

    Attributes
    ----------
    emission : bool
        Some material emits light (seen directly; emissive meshes also light as area lights).
    ambient : bool
        The scene's ambient light meets a material that reflects it.
    lights : bool
        Point, directional or spot lights reach materials that reflect light.
    area_lights : bool
        Area or emissive-mesh lights reach materials that reflect light.
    area_light_visibility : bool
        Area lights are seen by rays (they end rays that meet them first).
    environment_lighting : bool
        The background lights the scene (importance-sampled, with shadow rays) and reaches
        materials that reflect light.
    specular : bool
        Some material has a Blinn-Phong highlight.
    smooth_normals : bool
        Faces interpolate vertex normals.
    textures, normal_maps : bool
        Image textures or vertex colours, and normal maps, are looked up per hit.
    cutouts : bool
        Rays pass through cut-out (alpha mask or blend) surfaces.
    unlit : bool
        Some material shows its colour unlit.
    physical : bool
        Some material has the glTF metallic-roughness model
        (the path kernel).
    reflection, glossy, refraction : bool
        Mirror, dielectric or BSDF-sampled rays are spawned (``max_depth > 0``), glossy
        lobes sampled, refraction rays traced.
    absorption : bool
        Some medium absorbs light (Beer-Lambert).
    background : bool
        Rays that leave the scene see a background that is not black.
    passes : bool
        Output passes are recorded.
    ao : bool
        Ambient-occlusion rays are traced.
    lens : bool
        Thin-lens depth of field.
    motion : bool
        Objects or the camera move during the shutter.
    fused_direct : bool
        The fused direct-lighting stage (:mod:`rtmesh.rendering.direct_stage`) renders every chunk.
    """

    emission: bool = False
    ambient: bool = False
    lights: bool = False
    area_lights: bool = False
    area_light_visibility: bool = False
    environment_lighting: bool = False
    specular: bool = False
    smooth_normals: bool = False
    textures: bool = False
    normal_maps: bool = False
    cutouts: bool = False
    unlit: bool = False
    physical: bool = False
    reflection: bool = False
    glossy: bool = False
    refraction: bool = False
    absorption: bool = False
    background: bool = False
    passes: bool = False
    ao: bool = False
    lens: bool = False
    motion: bool = False
    fused_direct: bool = False

    def __post_init__(self):
        for field in dataclasses.fields(self):
            # plain bools, so that a plan compares and prints as what it says
            object.__setattr__(self, field.name, bool(getattr(self, field.name)))

    def enabled(self):
        """Names of the stages that run, in declaration order (list of str)."""
        return [field.name for field in dataclasses.fields(self) if getattr(self, field.name)]

    def needs(self):
        """What the render needs (the enabled stages but ``fused_direct``, which is the
        decision taken on them): frozenset of str, for a stage to compare with what it can
        render (:data:`rtmesh.rendering.direct_stage.FUSED_CAN_RENDER`)."""
        return frozenset(self.enabled()) - {"fused_direct"}
