"""What a scene builds once for every view of it: the scene in the re-centred frame, its
Embree scene (moving objects, placements and cut-outs included), textures, emissive
triangles, per-face and per-material tables, and the path kernel's scene records.

:class:`rtmesh.rendering.integrator.Integrator` renders one view (camera, lights,
background, passes, film) of a :class:`BuiltScene`; :meth:`Integrator.with_view` renders
another view of the same build, so that N views of one asset cost one build and N renders
(``rtmesh batch``).
"""

import dataclasses
import functools
import logging

import numpy as np

from rtmesh.geometry.accel import Accel
from rtmesh.geometry.cutouts import CutoutAccel
from rtmesh.geometry.motion import MotionAccel, blurs, object_motions, scene_at_time, swept_bounds
from rtmesh.io import denoising
from rtmesh.lights.environment import EnvironmentLighting
from rtmesh.lights.mesh_lights import emissive_mesh_light
from rtmesh.materials.table import ALPHA_MODES
from rtmesh.rendering import memory
from rtmesh.rendering.media import Media
from rtmesh.rendering.shading_tables import ShadingTables
from rtmesh.rendering.surface_textures import SurfaceTextures
from rtmesh.scene import instances

log = logging.getLogger(__name__)


def recentred(vertices, placed, shift):
    """What an Embree scene of ``vertices`` is built from in the frame re-centred on
    ``shift``: world-space vertices moved by ``-shift``; the prototypes of placed meshes
    left in their own coordinates, their placements' translations moved instead.

    Parameters
    ----------
    vertices : (V, 3) float64
    placed : rtmesh.scene.instances.Instances or None
        Where the prototypes' vertices start and the placements.
    shift : (3,) float64

    Returns
    -------
    shifted : (V, 3) float64
        A new array.
    placed : Instances or None
        ``placed`` with its transforms moved (a copy).
    """
    shifted = vertices - shift
    if placed is None:
        return shifted, None
    shifted[placed.first_vertex:] = vertices[placed.first_vertex:]
    transforms = placed.transforms.copy()
    transforms[:, :3, 3] -= shift
    return shifted, dataclasses.replace(placed, transforms=transforms)


class BuiltScene:
    """A scene built for rendering, shared by its views.

    Parameters
    ----------
    scene : Scene
    settings : RenderSettings
        Validated.
    sampler : rtmesh.sampling.sampler.Sampler
        The render's sampler (alpha-blend cut-outs draw their coverage from it).
    flatten_for : list of str
        Why the scene's placements cannot be traced as Embree instances (empty: they
        are); when not empty, the placed meshes are flattened into copies, within the
        loading memory limit.

    Attributes
    ----------
    scene : Scene
        The scene as built: at the shutter's opening when nothing blurs, placements
        flattened where ``flatten_for`` says.
    scene_bounds : (2, 3) float
        ``scene.bounds`` (world units).
    shift : (3,) float64
        The re-centring: the frame every stage works in is the world moved by ``-shift``.
    motion : MotionAccel or None
        Moving objects' Embree scenes (objects that move during the shutter).
    instances : rtmesh.scene.instances.Instances or None
        The placements, in the re-centred frame.
    accel : Accel, MotionAccel or CutoutAccel
        What every query traces.
    offset_scale : float
        The scene's size in the re-centred frame (scene units), for ray-origin offsets.
    textures : SurfaceTextures
    cutouts : CutoutAccel or None
    emitters : MeshLight or None
        The emissive triangles as a light.
    tables : ShadingTables
    ao_distance : float
        Ambient-occlusion ray length (scene units).
    ao_samples : int
        Ambient-occlusion rays a hit takes (the ``ao`` pass alone asks for 16).
    shaded_any, ambient_on, stochastic_coverage : bool
        Whether any material takes light; whether an ambient term lights any; whether
        alpha-blend materials let camera rays through at random.
    path_tables : tuple or None
        The path kernel's ``geometry`` and ``surface`` records and the faces' emission,
        formed by the first :class:`rtmesh.rendering.path_stage.PathStage` of any view.
    media : Media or None
        The media of the materials with a Whitted transmission colour (None: none).
    path_media : Media or None
        The medium tables of the path integrator's transmissive models where they are
        not the Whitted integrator's (:meth:`Integrator.media_of`).
    """

    def __init__(self, scene, settings, sampler, flatten_for):
        moving = [] if scene.instances is None else np.flatnonzero(np.isin(scene.instances.object_id,
                                                                           list(object_motions(scene))))
        if len(moving) and not flatten_for:
            # a moving placement is copied into the world (its own Embree scene, traced in
            # its rest frame, as every moving object); the others stay placed
            log.info("%d moving placements copied into the world (moving objects have Embree scenes of their own)",
                     len(moving))
            memory.check_flattening(instances.subset(scene.instances, moving), "moving objects")
            scene = instances.flattened(scene, moving)
        if object_motions(scene) and not blurs(scene):
            # an instantaneous shutter: moving objects stand still where the shutter finds them
            scene = scene_at_time(scene, scene.camera.shutter[0])
        if scene.instances is not None and flatten_for:
            # the copies: the general wavefront (a test reference) reads world-space faces
            log.info("placed meshes flattened into %d copies (instances are not traced with %s)",
                     len(scene.instances), ", ".join(flatten_for))
            memory.check_flattening(scene.instances, ", ".join(flatten_for))  # within a loading limit
            scene = instances.flattened(scene)
        self.scene = scene
        self.settings = settings
        # Re-centre the scene on the origin before it meets float32: float32 resolution is
        # relative to the size of the coordinates, so a model 1e6 units from the origin would
        # otherwise be traced on a grid of 1/16 unit.  Shading sees the same shifted frame.
        scene_bounds = self.scene_bounds = scene.bounds  # a pass over every vertex: formed once
        self.shift = scene_bounds.mean(axis=0)
        # moving objects get Embree scenes of their own, traced at each ray's time
        # placed meshes: the prototypes stay in their own coordinates, their placements move
        shifted, self.instances = recentred(scene.vertices, scene.instances, self.shift)
        self.motion = None
        if blurs(scene):
            motions = {k: m.shifted(self.shift) for k, m in object_motions(scene).items()}
            self.motion = MotionAccel(shifted, scene.faces, scene.object_id, motions, scene.camera.shutter,
                                      self.instances)
        self.accel = self.motion or Accel(shifted, scene.faces, instances=self.instances)
        # the scene's size in the re-centred frame bounds the triangles' size, which sets
        # part of the origin offset (see offset_ray_origins); it cannot be zero for a scene
        # that renders.  With motion,
        # the size of the space the objects sweep during the shutter.
        bounds = swept_bounds(scene) if self.motion else scene_bounds
        self.offset_scale = max(float(np.abs(bounds - self.shift).max()), 1e-30)
        m = scene.materials
        # textures and vertex colours, looked up per hit only where the scene has them
        self.textures = SurfaceTextures(scene)
        self.cutouts = None
        if m.any_cutout:
            # every query (camera, secondary, shadow, area-light, AO rays) sees the cut-outs,
            # at each ray's time when objects move
            self.cutouts = CutoutAccel(self.accel, scene.face_normals, scene.material_id, m.cutout,
                                       m.alpha_mode == ALPHA_MODES.index("blend"), m.alpha_cutoff,
                                       self.textures, self.offset_scale, sampler)
            self.accel = self.cutouts
        # faces that emit (the path kernel's light table makes each a light)
        self.emits = bool(m.any_emission and (m.emission[scene.material_id] > 0).any())
        lit = ~m.unlit[:, None]
        self.shaded_any = bool((((m.diffuse > 0) | (m.specular > 0)) & lit).any()) or m.any_physical
        self.ao_distance = settings.ao_distance or 0.2 * float(np.linalg.norm(np.ptp(scene_bounds, axis=0)))
        self.ambient_on = bool((scene.ambient > 0).any() and (m.ambient > 0).any())
        if settings.denoise:
            denoising.require()  # before any work: one line naming the extra when it is missing
        # alpha-blend materials are let through at random: camera hits then vary per sample
        self.stochastic_coverage = bool((m.alpha_mode == ALPHA_MODES.index("blend")).any())
        # the AO pass alone asks for 16 rays per camera hit unless ao_samples says otherwise
        self.ao_samples = settings.ao_samples or (16 if "ao" in settings.passes else 0)
        # what the stages read per hit (per-material colours and flags, per-face rows)
        self.tables = ShadingTables.build(scene, self.accel.triangles, self.offset_scale)
        # nested dielectric media (rtmesh.rendering.media), only for scenes that refract
        self.media = (Media(m, scene.material_id, scene.vertices, scene.faces, scene.face_normals,
                            instances=self.instances)
                      if m.any_transmission else None)
        self.path_tables = None
        self.path_media = None
        self._lit_background = (None, None)

    @functools.cached_property
    def emitters(self):
        """The emissive faces of the world as one :class:`~rtmesh.lights.mesh_lights.MeshLight`
        (None without any), the NumPy estimator's (the tests' wavefront); formed on first use."""
        scene, m = self.scene, self.scene.materials
        if not self.emits:
            return None
        tint = mean_tint = None
        if self.textures.emission_textured:
            material_id = scene.material_id

            def emission_tint(prim, u, v):
                return self.textures.emission_tints(prim, u, v, material_id[prim])

            tint = emission_tint
            mean_tint = self.textures.mean_emission_tints()[material_id]
        emission = m.emission[scene.material_id]
        if self.instances is not None:
            # placed emitters are the path kernel's lights (one per placement,
            # rtmesh.lights.light_table.LightTable); these are the world's faces only
            emission[self.instances.first_face:] = 0.0
        return emissive_mesh_light(self.accel.triangles, scene.face_normals, emission, tint, mean_tint)

    def environment_lighting(self, background, source):
        """The light sampler of ``background`` (an object of :mod:`rtmesh.scene.background`)
        when it lights the scene, else None; formed once for the same ``source`` (what the
        view's scene names as its background), so views that keep the background share it.

        It lights the scene when asked (scene files: ``[background] lighting``); unset
        (None), it lights scenes with physically based materials, which are made to be
        seen under their environment, and no others (whose images stay as they were).
        """
        lighting = self.scene.materials.any_physical if background.lighting is None else background.lighting
        if not lighting or background.is_black:
            return None
        if self._lit_background[0] is not source:
            self._lit_background = (source, EnvironmentLighting(background, self.accel, self.settings,
                                                                self.offset_scale))
        return self._lit_background[1]
