"""The path integrator's stage: what a scene builds once for the compiled path kernel
(:mod:`rtmesh.rendering.path_kernel`) and what each chunk hands it.

The scene's part (material tables, emission, geometry rows) is formed once per
:class:`~rtmesh.rendering.integrator.Integrator`; the view's part (the light table, with
the lights and the background of the view) once per view.  Per chunk, the camera rays come
from the camera (every sampler, depth of field, orthographic), then one kernel call traces
every path of the chunk.

What the path integrator does not render yet gives one clear error when the render is set
up (a :class:`~rtmesh.core.errors.SceneError`), never a wrong image: motion blur, alpha
cut-outs, image textures and normal maps, projector lights.
"""

import numpy as np

from rtmesh.core.errors import SceneError
from rtmesh.lights.environment import EnvironmentLighting
from rtmesh.lights.light_table import EnvironmentTables, LightTable
from rtmesh.lights.mesh_lights import MeshLight
from rtmesh.materials import ggx_albedo
from rtmesh.materials.models import material_rows
from rtmesh.rendering.path_kernel import BOUNCE, CAMERA, SHADOW, trace_paths
from rtmesh.sampling.hashing import mix64, path_key

# vertices a path takes before Russian roulette may end it (pbrt-v4 starts at its second)
RR_DEPTH = 3


def unsupported(it):
    """What of the scene and settings the path integrator cannot render yet (a list of
    phrases, empty when it can render everything)."""
    m = it.scene.materials
    missing = []
    if it.motion is not None:
        missing.append("motion blur")
    if it.cutouts is not None:
        missing.append("alpha cut-outs")
    if m.any_texture or bool(it.textures):
        missing.append("image textures and vertex colours")
    if not it.accel.packets:
        missing.append("the single-ray Embree path (RTMESH_EMBREE=run)")
    if any(not isinstance(light, MeshLight) and not hasattr(light, "corner") and not hasattr(light, "radius")
           and light.kernel_row() is None for light in it.view_lights):
        missing.append("projector lights")
    return missing


class PathStage:
    """The path kernel's tables for one view of a built scene.

    Parameters
    ----------
    it : Integrator
        Built with ``settings.integrator == "path"``.

    Raises
    ------
    SceneError
        The scene needs something the path integrator does not render yet.
    """

    def __init__(self, it):
        missing = unsupported(it)
        if missing:
            raise SceneError("integrator 'path' does not render " + ", ".join(missing)
                             + " yet; use integrator = 'whitted'")
        self.it = it
        scene, settings = it.scene, it.settings
        m = scene.materials
        self.tags, self.params, self.transmissive = material_rows(m.materials)
        self.emission = np.ascontiguousarray(m.emission)
        self.absorption = np.ascontiguousarray(m.absorption)
        self.unlit = np.zeros((len(m), 4))
        self.unlit[:, 0] = m.unlit
        self.unlit[:, 1:] = m.diffuse
        accel = it.accel
        self.triangles = np.ascontiguousarray(accel.triangles)
        self.face_normals = np.ascontiguousarray(scene.face_normals, dtype=np.float64)
        self.faces = np.ascontiguousarray(accel.faces)
        self.material_id = np.ascontiguousarray(scene.material_id, dtype=np.int32)
        if scene.vertex_normals is not None:
            self.vertex_normals = np.ascontiguousarray(scene.vertex_normals, dtype=np.float64)
            self.smooth = (np.ones(len(self.faces), bool) if scene.smooth is None
                           else np.ascontiguousarray(scene.smooth, dtype=bool))
        else:
            self.vertex_normals = np.zeros((0, 3))
            self.smooth = np.zeros(0, bool)
        self.albedo_table = ggx_albedo.table()
        background = it.background
        lights_scene = background.lighting is not False and not background.is_black
        environment = None
        if not background.is_black:
            environment = EnvironmentTables(EnvironmentLighting(background, accel, settings, it.offset_scale),
                                            background)
        self.environment = environment
        self.lights = LightTable([light for light in it.view_lights if not isinstance(light, MeshLight)],
                                 self.triangles, self.face_normals, self.emission[self.material_id],
                                 environment if lights_scene else None, it.offset_scale)
        if environment is None:
            self._env = (np.zeros((1, 3, 3)), np.zeros(2), np.zeros((1, 2)), np.ones((1, 1)), 1.0, 1.0, 0.0)
        else:
            e = environment
            self._env = (e.pixels, e.marginal, e.conditional, e.func, e.mean, e.cos_rotation, e.sin_rotation)
        with np.errstate(over="ignore"):  # the hash's products wrap modulo 2**64 by design
            self._seed_key = mix64(np.uint64(settings.seed % (1 << 64)) ^ np.uint64(0x5A17_7ACE_D00D_F00D))
        library = accel._shared.library
        self._queries = (library.intersect16, library.occluded16, accel._shared.handle)

    def render(self, origins, directions, pixel, sample, stats):
        """Radiance of the camera rays of one chunk.

        Parameters
        ----------
        origins, directions : (n, 3) float
            Camera rays in the re-centred frame.
        pixel, sample : (n,) int64
            Each ray's pixel and global sample index.
        stats : RenderStats
            Ray counts are added to it.

        Returns
        -------
        (n, 3) float64
        """
        it, s = self.it, self.it.settings
        n = len(pixel)
        with np.errstate(over="ignore"):
            keys = path_key(self._seed_key, pixel.astype(np.uint64), sample.astype(np.uint64))
        radiance = np.zeros((n, 3))
        counts = np.zeros(3, np.int64)
        lights = self.lights
        intersect16, occluded16, handle = self._queries
        trace_paths(intersect16, occluded16, handle, np.ascontiguousarray(origins, dtype=np.float64),
                    np.ascontiguousarray(directions, dtype=np.float64), keys, True,
                    self.triangles, self.face_normals, self.vertex_normals, self.faces, self.smooth, self.material_id,
                    self.tags, self.params, self.transmissive, self.emission, self.absorption, self.unlit,
                    self.albedo_table, lights.rows, lights.probability, lights.alias, lights.pmf, lights.face_light,
                    lights.analytic, lights.environment, *self._env, not it.background.transparent,
                    s.max_depth, RR_DEPTH, float(s.clamp), np.float32(it.offset_scale), radiance, counts)
        stats.rays["camera"] += int(counts[CAMERA])
        stats.rays["bounce"] += int(counts[BOUNCE])
        stats.rays["shadow"] += int(counts[SHADOW])
        return radiance
