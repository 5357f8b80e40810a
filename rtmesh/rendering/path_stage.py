"""The path integrator's stage: what a scene builds once for the compiled path kernel
(:mod:`rtmesh.rendering.path_kernel`) and what each chunk hands it.

The scene's part (material, texture and geometry tables: the kernel's ``geometry`` and
``surface`` records) is formed once per :class:`~rtmesh.rendering.integrator.Integrator`;
the view's part (the light table, with the lights and the background of the view) once per
view.  Per chunk, the camera rays come from the camera (every sampler, depth of field,
orthographic), then one kernel call traces every path of the chunk.

What the path integrator cannot render gives one clear error when the render is set up (a
:class:`~rtmesh.core.errors.SceneError`), never a wrong image: the single-ray Embree path
(its kernel traces packets) and lights of a type without a row in the light table.
"""

import logging

import numpy as np

from rtmesh.core.errors import SceneError
from rtmesh.core.rays import kernel_input
from rtmesh.geometry import embree_library
from rtmesh.geometry.cutouts import CutoutAccel
from rtmesh.io.texture_atlas import TextureAtlas
from rtmesh.lights.environment import EnvironmentLighting
from rtmesh.lights import light_table as lt
from rtmesh.lights.environment_table import EnvironmentTables
from rtmesh.lights.light_table import BYTES_PER_LIGHT, LightTable, placed_light_count
from rtmesh.lights.light_tree import NO_TREE, LightTree
from rtmesh.lights.mesh_lights import MeshLight
from rtmesh.lights.projector import ProjectorLight
from rtmesh.materials.models import SLOTS, material_rows, tables
from rtmesh.materials.table import PHYSICAL_MODELS
from rtmesh.io.passes import CAMERA_HIT_PASSES, LIGHT_PATH_PASSES, CameraHits
from rtmesh.rendering import memory
from rtmesh.rendering.caustics import Caustics
from rtmesh.rendering.photon_kernel import empty_photon_map
from rtmesh.rendering import path_camera_hits as ch
from rtmesh.rendering.path_kernel import trace_paths
from rtmesh.rendering.path_signatures import PATH_KERNELS, no_camera, no_instances, no_whitted, stage_entries
from rtmesh.rendering.path_sums import LIGHT_PATHS
from rtmesh.rendering.path_packets import COUNTER_NAMES
from rtmesh.rendering.path_surfaces import TEXTURE_COLUMNS
from rtmesh.rendering.settings import RenderSettings
from rtmesh.rendering.surface_textures import corner_and_edges, face_tangents
from rtmesh.sampling.hashing import mix64, path_keys
from rtmesh.sampling.patterns import Dim
from rtmesh.sampling.zsobol import block_bits, sequence_keys
from rtmesh.scene.camera import Camera

log = logging.getLogger(__name__)

# vertices a path takes before Russian roulette may end it (pbrt-v4 starts at its second)
RR_DEPTH = 3
# the Whitted integrator's rays end by max_depth and the cutoff only
NO_ROULETTE = 1 << 30


def unsupported(it):
    """What of the scene and settings the path integrator cannot render yet (a list of
    phrases, empty when it can render everything)."""
    missing = []
    if not embree_library.packet_library():
        missing.append(f"without Embree's packet queries ({embree_library.packet_failure()})")
    return missing + unsupported_lights(it.view_lights)


def unsupported_lights(lights):
    """Which of ``lights`` the path kernel has no rows for (phrases naming their types)."""
    others = sorted({type(light).__name__ for light in lights
                     if not isinstance(light, (MeshLight, ProjectorLight)) and not hasattr(light, "corner")
                     and not hasattr(light, "radius") and light.kernel_row() is None})
    return [f"lights of type {name} (no compiled row: kernel_row() is None)" for name in others]


def _packet_accel(accel):
    """The Embree scene under a cut-out wrapper (the kernel handles cut-outs itself)."""
    return accel.accel if isinstance(accel, CutoutAccel) else accel


def motion_record(it):
    """The kernel's ``motion`` record (:mod:`rtmesh.rendering.path_kernel`) and the handle
    of the static scene: everything static without moving objects."""
    z = np.zeros
    m = it.motion
    if m is None:
        return (True, z(0, np.int64), z(0, np.int64), z(0, np.int64), z(1, np.int64), z((0, 10)),
                z(0, np.int64)), _packet_accel(it.accel)._shared.handle
    moves = np.zeros((len(m.movers), 10))
    for j, mover in enumerate(m.movers):
        motion = mover.motion
        moves[j, 0:3] = motion.translate
        if motion.rotates:
            moves[j, 3:6], moves[j, 6], moves[j, 7:10] = motion.axis, np.radians(motion.degrees), motion.centre
    faces = [np.asarray(mover.faces, dtype=np.int64) for mover in m.movers]
    offsets = np.concatenate([[0], np.cumsum([len(f) for f in faces])]).astype(np.int64)
    record = (m.static is not None, np.ascontiguousarray(m.static_faces, dtype=np.int64),
              np.array([mover.accel._shared.handle for mover in m.movers], dtype=np.int64),
              np.concatenate(faces) if faces else z(0, np.int64), offsets, moves,
              np.ascontiguousarray(m.face_mover, dtype=np.int64))
    return record, (m.static._shared.handle if m.static is not None else 0)


def instance_record(it):
    """The kernel's ``instances`` record (:mod:`rtmesh.rendering.path_kernel`): the
    placements of meshes built once, in the re-centred frame."""
    placed = it.instances
    if placed is None:
        return no_instances()
    return placed.world_rows()


def _twin_materials(media, faces):
    """Each face's touching twin's material (``media.twin`` with the opposite winding: two
    media touching; faces of one winding at one place are two copies of one surface, not two
    media), -1 for none; an empty array when no face has one.

    Parameters
    ----------
    media : Media or None
        The medium tables of the path models' transmissive materials (None: none transmits).
    faces : int
        The scene's face count.

    Returns
    -------
    (F,) or (0,) int64
    """
    touching = None if media is None else (media.twin >= 0) & media.twin_opposite
    if touching is None or not touching.any():
        return np.zeros(0, np.int64)
    twins = np.full(faces, -1, np.int64)
    twins[touching] = media.material_id[media.twin[touching]]
    return twins


def whitted_model(material):
    """The path kernel's model of a material under the Whitted integrator: glTF's
    metallic-roughness (its KHR layers shaded as plain metallic-roughness, as the Whitted
    stages did), every other model read by its Blinn-Phong fields."""
    return "metallic_roughness" if material.model in PHYSICAL_MODELS else "blinn_phong"


def scene_tables(scene, accel, media_of, whitted=False):
    """What the path kernel reads of a scene, formed once and shared by every view: its
    ``geometry`` and ``surface`` records (see :mod:`rtmesh.rendering.path_surfaces`) and the
    per-face emission the light table chooses by.

    Parameters
    ----------
    scene : Scene
    accel : Accel or CutoutAccel
        The built Embree scene (its float32 triangles).
    media_of : callable
        ``media_of(transmissive)``: the medium tables of these materials
        (:meth:`rtmesh.rendering.integrator.Integrator.media_of`).
    whitted : bool
        Tables for the Whitted integrator (:func:`whitted_model`; glTF's baked occlusion).

    Returns
    -------
    geometry, surface : tuples
    face_emission : (F, 3) float64
    """
    triangles, faces = _packet_accel(accel).triangles, np.ascontiguousarray(scene.faces, dtype=np.int32)
    m = scene.materials
    tags, params, transmissive = material_rows(m.materials, [whitted_model(material) for material in m.materials]
                                               if whitted else None)
    unlit = np.zeros((len(m), 4))
    unlit[:, 0] = m.unlit
    unlit[:, 1:] = m.diffuse
    textures = []
    for material in m.materials:
        for name in TEXTURE_COLUMNS:
            texture = _texture(material, name, whitted)
            if texture is not None and not any(texture is known for known in textures):
                textures.append(texture)
    atlas = TextureAtlas(textures)
    material_textures = np.array([[atlas.index(_texture(material, name, whitted)) for name in TEXTURE_COLUMNS]
                                  for material in m.materials], dtype=np.int64).reshape(len(m), len(TEXTURE_COLUMNS))
    if scene.uv is None:
        material_textures[:] = -1  # no coordinates to read them with
    # the Whitted metal tint of specular and mirror colours (glTF materials use metallic in their BRDF)
    metal_tint = np.where(m.physical, 0.0, m.metallic)
    if scene.vertex_normals is not None:
        vertex_normals = np.ascontiguousarray(scene.vertex_normals, dtype=np.float64)
        smooth = (np.ones(len(faces), bool) if scene.smooth is None else np.ascontiguousarray(scene.smooth, dtype=bool))
    else:
        vertex_normals, smooth = np.zeros((0, 3)), np.zeros(0, bool)
    face_uv = np.zeros((0, 6)) if scene.uv is None else np.ascontiguousarray(corner_and_edges(scene.uv, scene.faces))
    face_colours = (np.zeros((0, 12)) if scene.vertex_colors is None
                    else np.ascontiguousarray(corner_and_edges(scene.vertex_colors, scene.faces)))
    # UV tangents for normal maps (the base's and clear coats') and anisotropy directions
    normal_mapped = scene.uv is not None and (
        (material_textures[:, [TEXTURE_COLUMNS.index("normal_texture"),
                               TEXTURE_COLUMNS.index("clearcoatNormalTexture")]] >= 0).any()
        or any(material.layers is not None and material.layers.anisotropy > 0 for material in m.materials))
    tangents = (np.ascontiguousarray(face_tangents(scene.vertices, scene.faces, scene.uv)) if normal_mapped
                else np.zeros((0, 6)))
    material_id = np.ascontiguousarray(scene.material_id, dtype=np.int32)
    geometry = (np.ascontiguousarray(triangles), np.ascontiguousarray(scene.face_normals, dtype=np.float64),
                vertex_normals, np.ascontiguousarray(faces), smooth, material_id, face_uv, face_colours, tangents)
    surface = (tags, params, transmissive, np.ascontiguousarray(m.emission), np.ascontiguousarray(m.absorption),
               unlit, tables(), SLOTS, material_textures, np.ascontiguousarray(metal_tint, dtype=np.float64),
               np.ascontiguousarray(m.alpha_mode, dtype=np.int64), np.ascontiguousarray(m.alpha_cutoff),
               np.ascontiguousarray(m.opacity), atlas.texels, atlas.descriptors,
               np.ascontiguousarray(m.ior, dtype=np.float64),
               _twin_materials(media_of(transmissive) if transmissive.any() else None, len(faces)))
    # what each face emits on average (emission textures by their mean), for choosing lights by power
    # (a grey texture's one channel tints all three)
    mean_tint = np.array([np.ones(3) if material.emission_texture is None or scene.uv is None else
                          np.broadcast_to(np.asarray(material.emission_texture.pixels, dtype=np.float64).reshape(
                              -1, material.emission_texture.channels)[:, :3].mean(axis=0), 3)
                          for material in m.materials]).reshape(-1, 3)
    face_emission = (m.emission * mean_tint)[material_id]
    return geometry, surface, face_emission


def _texture(material, column, whitted):
    """The texture of a material in one of :data:`TEXTURE_COLUMNS`: a field of the material,
    or one of its KHR layers' textures (by the extension's role name); None for none (and
    for the baked occlusion but under the Whitted integrator, whose ambient term it darkens)."""
    if column == "occlusion_texture" and not whitted:
        return None
    if hasattr(material, column):
        return getattr(material, column)
    return material.layers.textures.get(column) if material.layers is not None else None


class PathStage:
    """The path kernel's tables for one view of a built scene.

    Parameters
    ----------
    it : Integrator
        Under ``integrator = "path"``, or ``"whitted"`` for the kernel's Whitted configuration.

    Raises
    ------
    SceneError
        The scene needs what the kernel does not render (:func:`unsupported`): Embree's
        packet queries are not available, or a light has no compiled row.
    """

    def _light_tree(self, settings):
        """The lights' tree record (``light_sampler = "tree"``, rtmesh.lights.light_tree), or
        :data:`~rtmesh.lights.light_tree.NO_TREE`: lights chosen by power."""
        rows = self.lights.rows
        if settings.light_sampler != "tree" or self.whitted or not len(rows):
            return NO_TREE
        face_mover = self._motion[6]
        triangles = rows[:, 0] == lt.TRIANGLE
        if len(face_mover) and (face_mover[rows[triangles, lt.FACE].astype(np.int64)] >= 0).any():
            # the tree would bound these emitters where they rest
            log.warning("light_sampler 'tree' does not bound emitters on moving objects: lights are chosen by "
                        "power")
            return NO_TREE
        return LightTree(rows, self.lights.power).record

    def __init__(self, it):
        missing = unsupported(it)
        if missing:
            raise SceneError("rtmesh cannot render " + ", ".join(missing))
        self.it = it
        scene, settings = it.scene, it.settings
        self.whitted = settings.integrator == "whitted"
        ignored = [] if self.whitted else [name for name, unused in (
            ("ambient", bool((np.asarray(scene.ambient) > 0).any())),
            ("cutoff", settings.cutoff != RenderSettings.cutoff),
            ("ao_samples", settings.ao_samples > 0 and "ao" not in settings.passes)) if unused]
        if ignored:
            log.warning("integrator 'path' ignores %s (it has no ambient term, ends paths by Russian roulette "
                        "and takes its light from the lights and the background)", ", ".join(ignored))
        if it.built.path_tables is None:
            # formed with the integrator's first view; views made by with_view share them
            it.built.path_tables = scene_tables(scene, it.accel, it.media_of, self.whitted)
        self.geometry, self.surface, face_emission = it.built.path_tables
        self.cutouts = it.cutouts is not None
        background = it.background
        # (whitted: when it lights the scene under the Whitted stages' rule, Integrator._set_background)
        lights_scene = (it.environment_lighting is not None if self.whitted
                        else background.lighting is not False and not background.is_black)
        environment = None
        if not background.is_black:
            # the Whitted stages' sampling tables of this background when the view has them
            lighting = it.environment_lighting or EnvironmentLighting(background, it.accel, settings,
                                                                      it.offset_scale)
            environment = EnvironmentTables(lighting, background)
        if it.instances is not None:
            # a light for every placement of an emissive prototype face
            placed = placed_light_count(it.instances, face_emission)
            memory.check_load("the scene", f"{placed} placed emissive triangles as lights",
                              placed * BYTES_PER_LIGHT)
        self.lights = LightTable([light for light in it.view_lights if not isinstance(light, MeshLight)],
                                 self.geometry[0], self.geometry[1], face_emission,
                                 environment if lights_scene else None, it.offset_scale, self.whitted, it.instances)
        # the ao pass's rays at the camera rays' surfaces (rtmesh.rendering.path_camera_hits)
        self._ao_pass = "ao" in settings.passes and it.ao_samples > 0
        self._pass_albedo = np.ascontiguousarray(it.passes.diffuse, dtype=np.float64).reshape(-1, 3)
        self._whitted = self._whitted_record() if self.whitted else no_whitted(
            len(self.surface[0]), *self._ao_rays() if self._ao_pass else ())
        if environment is None:
            self._env = (np.zeros((1, 3, 3), np.float32), np.zeros(2), np.zeros((1, 2)), np.ones((1, 1)), 1.0, 1.0,
                         0.0)
        else:
            e = environment
            self._env = (e.pixels, e.marginal, e.conditional, e.func, e.mean, e.cos_rotation, e.sin_rotation)
        # the media the camera sits in, by the transmissive materials of the path's own
        # models (a glass of model = "dielectric" as much as one with a Whitted transmission
        # colour); no stack at all without transmissive materials
        transmissive = self.surface[2]
        self._camera_media = (kernel_input(it.camera_media(transmissive), np.int64) if transmissive.any()
                              else np.zeros(0, np.int64))
        # the first vertex's light, BSDF and (whitted) AO points and light choice (rtmesh.rendering.path_kernel)
        self._sobol_keys = sequence_keys("zsobol" if settings.sampler == "zsobol" else "sobol", settings.seed,
                                         (Dim.PATH_LIGHT, Dim.PATH_BSDF, Dim.AO, Dim.PATH_CHOICE), settings.spp,
                                         (settings.width, settings.height))
        with np.errstate(over="ignore"):  # the hash's products wrap modulo 2**64 by design
            self._seed_key = mix64(np.uint64(settings.seed % (1 << 64)) ^ np.uint64(0x5A17_7ACE_D00D_F00D))
        library = embree_library.packet_library()
        self._motion, handle = motion_record(it)
        # the kernels' ``lights`` record (rtmesh.rendering.path_kernel), formed once a view
        # (the tree after the motion record, which says whether an emitter moves)
        lights = self.lights
        self.light_record = (lights.rows, lights.probability, lights.alias, lights.pmf, lights.face_light,
                             lights.analytic, lights.environment, lights.texels, lights.descriptors,
                             lights.placement_light, self._light_tree(settings))
        self._instances = instance_record(it)
        self._queries = (library.intersect, library.occluded, handle)
        # a pinhole or thin-lens camera's rays are formed in the kernel
        # (rtmesh.rendering.path_camera; the chunk hands it each sample's point on the
        # aperture, and with moving objects its time: the camera does not move); an
        # orthographic camera and a camera class with rays of its own hand it theirs
        camera = it.camera
        self.camera_in_kernel = not (camera.orthographic or type(camera).generate_rays is not Camera.generate_rays)
        sampler = it.pixel_sampler
        self._camera = (self.camera_in_kernel, sampler.code, sampler.keys, sampler.corners, sampler.size, sampler.spp,
                        int(settings.width),
                        np.concatenate([camera.image_plane(settings.width, settings.height), *it.camera_frame]),
                        np.ascontiguousarray(camera.position, dtype=np.float64), float(camera.focus))
        PATH_KERNELS.prepare()
        # the kernel's and its stages' libraries, loaded from the disk cache once a process
        # (about 0.25 s) as the scene is set up, not within the first render
        stage_entries()
        # photon passes for caustics, and the photons the chunks gather (the current pass's)
        self.caustics = Caustics(self, it)
        self.photon_map = empty_photon_map(len(self.surface[0]))

    def _whitted_record(self):
        """The kernel's ``whitted`` record (:mod:`rtmesh.rendering.path_kernel`): the lights
        as Whitted samples them (:meth:`~rtmesh.lights.light_table.LightTable.light_groups`),
        each material's ambient light (its ambient colour times the scene's; none for
        unlit materials) and baked-occlusion strength, the cutoff, the Fresnel reflectance,
        the depth of a lane's stack of split rays (at most one a bounce), and the ambient
        occlusion rays a hit's ambient term takes (0: none), their length and the
        :func:`~rtmesh.sampling.zsobol.block_bits` of the first vertex's (spp x ao_samples)."""
        it, s = self.it, self.it.settings
        m = it.scene.materials
        ao_rays = self._ao_rays() if it.plan.ao else (0, float(it.ao_distance), block_bits(s.spp, 1))
        ambient = np.where(m.unlit[:, None], 0.0, m.ambient * np.asarray(it.scene.ambient, dtype=np.float64))
        return (True, *self.lights.light_groups(), np.ascontiguousarray(ambient, dtype=np.float64),
                np.ascontiguousarray(m.occlusion_strength, dtype=np.float64), float(s.cutoff), s.fresnel == "exact",
                max(int(s.max_depth), 1), *ao_rays)

    def _ao_rays(self):
        """The ambient-occlusion rays a surface takes (the Whitted ambient term's, and the ao
        pass's): ``(ao_samples, ao_distance, block_bits(spp, ao_samples))``."""
        it = self.it
        return int(it.ao_samples), float(it.ao_distance), block_bits(it.settings.spp, int(it.ao_samples))

    def _sobol(self, pixel, sample):
        """The kernel's Sobol arguments from the chunk's pixels and sample indices ((n,)
        int64 each): those and the sequences' record
        (:func:`rtmesh.sampling.zsobol.sequence_keys`: zsobol's points under zsobol, sobol's
        under the other samplers); empty under the ``random`` sampler (white noise
        everywhere, as it promises)."""
        if self.it.settings.sampler == "random":
            return np.zeros(0, np.int64), np.zeros(0, np.int64), self._sobol_keys
        return pixel, sample, self._sobol_keys

    def _record_surfaces(self, passes, camera_hits):
        """Write the camera-hit passes from the kernel's records of the camera rays' first
        shaded surfaces (``camera_hits`` (n, CAMERA_HIT_WORDS), :mod:`rtmesh.rendering.path_camera_hits`)."""
        rows = np.flatnonzero(camera_hits[:, ch.HIT_COVERED] > 0.0)
        if not len(rows):
            return
        hit = camera_hits[rows]
        self.it.passes.record_hits(passes, rows, CameraHits(
            hit[:, ch.HIT_POINT:ch.HIT_POINT + 3], hit[:, ch.HIT_NORMAL:ch.HIT_NORMAL + 3],
            hit[:, ch.HIT_ALBEDO:ch.HIT_ALBEDO + 3], hit[:, ch.HIT_UV:ch.HIT_UV + 2], self.it.passes))
        if passes.wants("ao") and self._ao_pass:
            # the fraction of the surface's ambient-occlusion rays that escaped
            passes.write("ao", rows, hit[:, ch.HIT_FREE] / self.it.ao_samples)

    def render(self, origins, directions, pixel, sample, stats, passes=None, times=None, lens=None):
        """Radiance of the camera rays of one chunk.

        Parameters
        ----------
        origins, directions : (n, 3) float, or None
            Camera rays in the re-centred frame; None where the kernel forms them
            (:attr:`camera_in_kernel`).
        pixel, sample : (n,) int64
            Each ray's pixel and global sample index.
        stats : RenderStats
            Ray counts are added to it.
        passes : PassSink, optional
            The chunk's pass buffers: the light-path and camera-hit passes it wants are
            written to it (:meth:`rtmesh.io.passes.PassRecorder.record_hits`).
        times : (n,) float, optional
            Each ray's time in the shutter (scenes with moving objects).
        lens : (n, 2) float, optional
            Where the kernel forms the camera rays of a thin lens: each sample's point on the
            aperture (:meth:`rtmesh.scene.camera.Camera.lens_disk`).

        Returns
        -------
        (n, 3) float64
        """
        it, s = self.it, self.it.settings
        n = len(pixel)
        pixel_index, sample_index = kernel_input(pixel, np.int64), kernel_input(sample, np.int64)
        keys = path_keys(self._seed_key, pixel_index, sample_index)
        radiance = np.zeros((n, 3))
        counts = np.zeros(len(COUNTER_NAMES), np.int64)
        intersect, occluded, handle = self._queries
        split = passes is not None and any(passes.wants(name) for name in LIGHT_PATH_PASSES)
        record_hits = passes is not None and any(passes.wants(name) for name in CAMERA_HIT_PASSES)
        # whitted: max_depth counts the bounces (one segment more: the light of the last hit),
        # no roulette
        options = (s.max_depth + 1 if self.whitted else s.max_depth, NO_ROULETTE if self.whitted else RR_DEPTH,
                   float(s.clamp), np.float32(it.offset_scale),
                   not it.background.transparent, self.cutouts, split, self._camera_media, int(s.light_samples),
                   block_bits(s.spp, s.light_samples), record_hits, record_hits and self._ao_pass,
                   self._pass_albedo)
        light_paths = np.zeros((n if split else 0, LIGHT_PATHS, 3))
        camera_hits = np.zeros((n if record_hits else 0, ch.CAMERA_HIT_WORDS))
        if origins is None:
            lens = np.zeros((0, 2)) if lens is None else np.ascontiguousarray(lens, dtype=np.float64)
            camera, origins = self._camera + (pixel_index, sample_index, lens), np.zeros((0, 3))
            directions = origins
        else:
            camera = no_camera()
            origins, directions = kernel_input(origins, np.float64), kernel_input(directions, np.float64)
        complete = trace_paths(intersect, occluded, handle, camera, origins, directions, keys,
                               *self._sobol(pixel_index, sample_index),
                               np.zeros(0) if times is None else kernel_input(times, np.float64),
                               self.geometry, self.surface, self.light_record, self._env, options, self._whitted,
                               self._motion, self._instances, self.photon_map, stage_entries(), radiance,
                               light_paths, camera_hits, counts)
        if not complete:
            raise RuntimeError("the path kernel's vertex stages were compiled for other argument types than it passes "
                               "(rtmesh.rendering.path_signatures declares them)")
        if split:
            for k, name in enumerate(LIGHT_PATH_PASSES):
                if passes.wants(name):
                    passes.write(name, slice(None), light_paths[:, k])
        if record_hits:
            self._record_surfaces(passes, camera_hits)
        for name, count in zip(COUNTER_NAMES, counts):
            if count:
                stats.rays[name] += int(count)
        return radiance
