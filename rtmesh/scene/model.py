"""The scene: one triangle soup with per-face material and object ids (meshes placed many
times kept once, :mod:`rtmesh.scene.instances`)."""

import collections
import dataclasses
import logging
from dataclasses import dataclass, field

import numpy as np

from rtmesh.core.errors import MeshError
from rtmesh.geometry import build_kernels
from rtmesh.lights.point_lights import DirectionalLight
from rtmesh.materials.table import Material, MaterialTable
from rtmesh.scene import instances
from rtmesh.scene.camera import Camera, frame_bounds, framing_bounds
from rtmesh.scene.studio import studio_background

log = logging.getLogger(__name__)

# the largest coordinate Embree's float32 vertices can hold
FLOAT32_MAX = float(np.finfo(np.float32).max)


@dataclass
class MeshPart:
    """One mesh placed in the scene, before flattening.

    Attributes
    ----------
    name : str
        Object name (for messages and the object-id pass).
    vertices : (v, 3) float
        World-space positions.
    faces : (f, 3) int
        Vertex indices, counter-clockwise seen from the outside.
    material : int
        Index into the scene's material list.
    vertex_normals : (v, 3) float or None
        Unit normals for smooth shading; None shades flat.
    motion : rtmesh.geometry.motion.Motion or None
        Rigid motion during the shutter (see :mod:`rtmesh.geometry.motion`); None stands still.
    uv : (v, 2) float or None
        Texture coordinates per vertex ((0, 0) the bottom-left corner of an image).
    vertex_colors : (v, 4) float or None
        Linear RGBA per vertex, multiplying the material's base colour and opacity.
    category : str or None
        What the object is, for dataset annotations (a scene file's ``category`` key);
        None: its ``name``.
    to_world : (4, 4) float or None
        The transform that placed the object's model (its file's or primitive's own
        coordinates) in the world; None: the identity.
    """

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    material: int = 0
    vertex_normals: np.ndarray | None = None
    motion: object = None
    uv: np.ndarray | None = None
    vertex_colors: np.ndarray | None = None
    category: str | None = None
    to_world: np.ndarray | None = None


@dataclass
class Placement:
    """One mesh placed many times: built once, placed by Embree instances
    (:mod:`rtmesh.scene.instances`).

    Attributes
    ----------
    part : MeshPart
        The mesh in its own (model) coordinates (``to_world`` and ``motion`` unused).
    transforms : (k, 4, 4) float
        Each placement's model-to-world transform.
    names : list of str
        Each placement's object name.
    categories : list of str or None
        Each placement's category (dataset annotations); None: the part's ``category``,
        else each placement's name.
    """

    part: MeshPart
    transforms: np.ndarray
    names: list
    categories: list | None = None


@dataclass
class Scene:
    """Everything the renderer needs, as flat arrays.

    Attributes
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int32
    face_normals : (F, 3) float64
        Unit geometric normals from the winding order.
    vertex_normals : (V, 3) float64 or None
        Unit shading normals; None when no object is smooth-shaded.
    smooth : (F,) bool or None
        Which faces interpolate ``vertex_normals``; None when none do.
    material_id : (F,) int32
    object_id : (F,) int32
    object_names : list of str
    materials : MaterialTable
    lights : list
    camera : Camera
    ambient : (3,) float
        Ambient light colour multiplying every material's ``ambient`` reflectance.
    background : (3,) float or background object
        What rays that leave the scene see: a radiance, or one of the backgrounds of
        :mod:`rtmesh.scene.background` (gradient, environment image, transparent).
    motions : dict of int to rtmesh.geometry.motion.Motion
        Motion of each moving object (by object index); static objects are absent.
    uv : (V, 2) float64 or None
        Texture coordinates per vertex; None when no object has any (objects without
        them read (0, 0)).
    vertex_colors : (V, 4) float64 or None
        Linear RGBA per vertex; None when no object has any (the others read white).
    object_categories : list of str
        Each object's category (:attr:`MeshPart.category`, else its name); empty for a
        scene not made by :meth:`from_parts`.
    object_to_world : list of (4, 4) float
        Each object's model-to-world transform (:attr:`MeshPart.to_world`).
    instances : rtmesh.scene.instances.Instances or None
        Meshes placed many times: their faces (after the world-space ones) are in model
        coordinates, built once and placed by Embree instances (see
        :mod:`rtmesh.scene.instances`); None: every face is in the world.
    """

    vertices: np.ndarray
    faces: np.ndarray
    face_normals: np.ndarray
    vertex_normals: np.ndarray | None
    smooth: np.ndarray | None
    material_id: np.ndarray
    object_id: np.ndarray
    object_names: list
    materials: MaterialTable
    lights: list
    camera: Camera
    ambient: np.ndarray = field(default_factory=lambda: np.zeros(3))
    background: np.ndarray = field(default_factory=lambda: np.zeros(3))
    motions: dict = field(default_factory=dict)
    uv: np.ndarray | None = None
    vertex_colors: np.ndarray | None = None
    object_categories: list = field(default_factory=list)
    object_to_world: list = field(default_factory=list)
    instances: object = None

    @property
    def bounds(self):
        """(2, 3) float: axis-aligned bounds of the geometry (every placement of an
        instanced mesh included)."""
        faces = self.faces if self.instances is None else self.faces[:self.instances.first_face]
        # a mask, not np.unique: sorting a million faces' indices takes seconds
        used = np.zeros(len(self.vertices), dtype=bool)
        used[faces.ravel()] = True
        points = self.vertices if used.all() else self.vertices[used]
        bounds = (np.stack([points.min(axis=0), points.max(axis=0)]) if len(points)
                  else np.array([np.full(3, np.inf), np.full(3, -np.inf)]))
        if self.instances is not None:
            placed = self.instances.bounds(self.vertices)
            bounds = np.stack([np.minimum(bounds[0], placed[0]), np.maximum(bounds[1], placed[1])])
        return bounds

    def _keep_faces(self, keep):
        """Keep only the faces ``keep`` (indices) and their per-face data."""
        self.faces, self.face_normals = self.faces[keep], self.face_normals[keep]
        self.material_id, self.object_id = self.material_id[keep], self.object_id[keep]
        if self.smooth is not None:
            self.smooth = self.smooth[keep]
        # an object left without faces no longer moves (nothing of it is traced)
        left = set(np.unique(self.object_id).tolist())
        self.motions = {k: m for k, m in self.motions.items() if k in left}

    @classmethod
    def from_parts(cls, parts, materials=None, lights=None, camera=None, ambient=None,
                   background=None, source="scene", aspect=1.0, physical=False, placements=()):
        """Flatten mesh parts into one scene, dropping faces that cannot render.

        Faces that touch a non-finite vertex or have zero area are removed with a warning
        naming the object; an object with nothing left is dropped; a scene with nothing left
        is an error.

        Parameters
        ----------
        parts : list of MeshPart
        materials : list of Material, optional
            Defaults to a single grey material.
        lights : list, optional
            Defaults to :func:`default_lights` (a three-light rig), or, for materials of
            the metallic-roughness model with no ``background`` given, to no lights and the
            studio environment (:func:`rtmesh.scene.studio.studio_background`).
        camera : Camera, optional
            Defaults to one framing the bounds (:func:`rtmesh.scene.camera.frame_bounds`).
        ambient : (3,) float, optional
        background : (3,) float or background object, optional
            A radiance, or a background of :mod:`rtmesh.scene.background`.
        source : str
            Where the parts came from, for error messages.
        aspect : float
            Image width / height the automatic camera frames the bounds for.
        physical : bool
            The scene is rendered by the path integrator: the default rig's irradiances
            are multiplied by pi (its Lambert term has the 1/pi the Whitted one lacks, so a
            white surface under the key light looks the same) and, without a ``background``,
            the studio environment lights the scene as well (no ambient term).

        Raises
        ------
        MeshError
            If no renderable triangle remains.
        """
        materials = list(materials) if materials else [Material()]
        if not physical:
            _warn_layers_ignored(materials, source)
        vertices, faces, normals, vnormals, smooth, mat_ids, obj_ids, names = ([] for _ in range(8))
        categories, to_world = [], []
        uvs, colours = [], []
        motions = {}
        offset = 0
        build_kernels.BUILD_KERNELS.prepare()
        # faces dropped by kind: (object, count); one warning a kind, after the loop
        dropped = collections.defaultdict(list)
        empty = []
        for placement in placements:
            problem = instances.check_transforms(placement.transforms, placement.names, source)
            if problem:
                raise MeshError(problem)
        # the placed meshes' prototypes come last (rtmesh.scene.instances); per prototype its
        # first face and vertex, its placements' transforms and object indices
        prototypes, first = [], None
        face_count = 0
        for part, placement in [(part, None) for part in parts] + [(p.part, p) for p in placements]:
            if placement is not None and first is None:
                first = (face_count, offset)
            # row-major, as most loaders give it: the build passes are compiled for one layout
            v = np.ascontiguousarray(part.vertices, dtype=np.float64).reshape(-1, 3)
            f = np.asarray(part.faces, dtype=np.int64).reshape(-1, 3)
            if len(f) and (f.min() < 0 or f.max() >= len(v)):
                raise MeshError(f"{source}: object '{part.name}' has face indices out of range")
            if part.material < 0 or part.material >= len(materials):
                raise MeshError(f"{source}: object '{part.name}' uses unknown material {part.material}")
            # one compiled pass each (see rtmesh.geometry.build_kernels): the finite-vertex test, and
            # cross(v1 - v0, v2 - v0) over its length, rounded as NumPy rounds them
            keep = build_kernels.finite_faces(v, f)
            if not keep.all():
                dropped["faces with NaN/Inf vertices"].append((part.name, int((~keep).sum())))
                f = f[keep]
            # Embree holds float32: a coordinate beyond its range would become infinite
            beyond = np.abs(v).max(axis=1, initial=0.0) > FLOAT32_MAX  # False for NaN
            if beyond.any():
                far = beyond[f].any(axis=1)
                if far.any():
                    dropped[f"faces with coordinates beyond float32's range ({FLOAT32_MAX:.3g}), which the "
                            "ray tracer cannot hold"].append((part.name, int(far.sum())))
                    f = f[~far]
            face_normals, area2 = build_kernels.face_crosses(v, f)
            nondegenerate = area2 > 0.0
            if not nondegenerate.all():
                dropped["zero-area faces"].append((part.name, int((~nondegenerate).sum())))
                f, face_normals = f[nondegenerate], face_normals[nondegenerate]
            if not len(f):
                empty.append(part.name)
                continue
            # non-finite (or beyond float32) vertices that no face uses are harmless but must
            # not reach Embree
            vertices.append(np.where(np.isfinite(v) & (np.abs(v) <= FLOAT32_MAX), v, 0.0))
            faces.append(f + offset)
            normals.append(face_normals)
            vn, face_smooth = _unit_vertex_normals(part.vertex_normals, v, f)
            vnormals.append(vn)
            smooth.append(face_smooth)
            uvs.append(_vertex_attribute(part.uv, len(v), 2, 0.0, "texture coordinates",
                                         source, part.name))
            colours.append(_vertex_attribute(part.vertex_colors, len(v), 4, 1.0, "vertex colours",
                                             source, part.name))
            mat_ids.append(np.full(len(f), part.material, dtype=np.int32))
            obj_ids.append(np.full(len(f), len(names), dtype=np.int32))
            if placement is not None:
                k = len(placement.names)
                prototypes.append((face_count, offset, np.asarray(placement.transforms, dtype=np.float64),
                                   np.arange(len(names), len(names) + k, dtype=np.int32)))
                names.extend(placement.names)
                categories.extend(placement.categories if placement.categories is not None else
                                  placement.names if part.category is None else [part.category] * k)
                to_world.extend(np.asarray(placement.transforms, dtype=np.float64))
            else:
                if part.motion is not None:
                    motions[len(names)] = _with_centre(part.motion, v[np.unique(f)])
                names.append(part.name)
                categories.append(part.name if part.category is None else part.category)
                to_world.append(np.eye(4) if part.to_world is None else np.asarray(part.to_world, dtype=np.float64))
            offset += len(v)
            face_count += len(f)
        _warn_dropped(source, dropped, empty)
        if not faces:
            raise MeshError(f"{source}: nothing to render (no non-degenerate triangles with finite vertices)")
        smooth_faces = np.concatenate(smooth)
        if smooth_faces.any():
            vertex_normals = np.concatenate(vnormals)
        else:
            # flat shading everywhere: no normal interpolation stage at all
            vertex_normals, smooth_faces = None, None
        uv = None if all(a is None for a in uvs) else np.concatenate(
            [np.zeros((len(v), 2)) if a is None else a for v, a in zip(vertices, uvs)])
        vertex_colors = None if all(a is None for a in colours) else np.concatenate(
            [np.ones((len(v), 4)) if a is None else a for v, a in zip(vertices, colours)])
        vertices = np.concatenate(vertices)
        faces = np.concatenate(faces).astype(np.int32)
        scene = cls(
            vertices=vertices,
            faces=faces,
            face_normals=np.concatenate(normals),
            vertex_normals=vertex_normals,
            smooth=smooth_faces,
            material_id=np.concatenate(mat_ids),
            object_id=np.concatenate(obj_ids),
            object_names=names,
            materials=MaterialTable(materials),
            lights=list(lights) if lights is not None else [],
            camera=camera,
            ambient=np.asarray(ambient if ambient is not None else np.zeros(3), dtype=np.float64),
            background=(background if hasattr(background, "radiance") else
                        np.asarray(background if background is not None else np.zeros(3), dtype=np.float64)),
            motions=motions,
            uv=uv,
            vertex_colors=vertex_colors,
            object_categories=categories,
            object_to_world=to_world,
        )
        if prototypes:
            scene.instances = instances.Instances(
                first_face=first[0], first_vertex=first[1],
                prototype_faces=np.array([p[0] for p in prototypes] + [face_count], dtype=np.int64),
                prototype_vertices=np.array([p[1] for p in prototypes] + [offset], dtype=np.int64),
                transforms=np.concatenate([p[2] for p in prototypes]),
                prototype=np.concatenate([np.full(len(p[3]), j, np.int64) for j, p in enumerate(prototypes)]),
                object_id=np.concatenate([p[3] for p in prototypes]))
            bounds, keep = scene.bounds, None
        else:
            bounds, keep = framing_bounds(scene.vertices, scene.faces,
                                          None if camera is None else camera.look_at)
        if keep is not None:
            # the rest would be far below a pixel (and below float32's grid once the renderer
            # centres the scene on its bounds): drop the far faces, saying so (with a camera
            # of the scene's own, the rest is the part it looks at)
            whole = scene.bounds
            log.warning("%s: dropped %d of %d faces that lie far from the rest (the scene "
                        "spans %.3g, the rest %.3g)", source, len(scene.faces) - len(keep),
                        len(scene.faces), float(np.max(whole[1] - whole[0])),
                        float(np.max(bounds[1] - bounds[0])))
            scene._keep_faces(keep)
        if camera is None:
            scene.camera = frame_bounds(bounds, aspect=aspect)
        if lights is None:
            if scene.materials.any_physical and background is None:
                scene.lights, scene.background = [], studio_background(scene.camera)
            elif physical:
                scene.lights = default_lights(scene.camera, physical=True)
                if background is None:
                    scene.background = studio_background(scene.camera)
            else:
                scene.lights = default_lights(scene.camera)
        return scene


def _vertex_attribute(values, count, width, fill, what, source, name):
    """A per-vertex attribute as ``(count, width)`` float64, or None if absent or unusable.

    Non-finite entries are replaced by ``fill`` with a warning naming the object; an
    attribute with the wrong number of rows is dropped with a warning.  Colours with three
    channels get an opaque alpha.
    """
    if values is None:
        return None
    a = np.asarray(values, dtype=np.float64)
    if a.ndim != 2 or len(a) != count or a.shape[1] not in (width, width - 1 if width == 4 else width):
        log.warning("%s: object '%s': %s do not match the vertices; ignored", source, name, what)
        return None
    if a.shape[1] < width:
        a = np.concatenate([a, np.full((len(a), width - a.shape[1]), 1.0)], axis=1)
    finite = np.isfinite(a)
    if not finite.all():
        log.warning("%s: object '%s': %d non-finite %s replaced by %g", source, name,
                    int((~finite.all(axis=1)).sum()), what, fill)
        a = np.where(finite, a, fill)
    return a


def _with_centre(motion, points):
    """``motion`` rotating about the centre of ``points``' bounds unless it has a centre."""
    if motion.centre is not None:
        return motion
    return dataclasses.replace(motion, centre=0.5 * (points.min(axis=0) + points.max(axis=0)))


def _unit_vertex_normals(vertex_normals, vertices, faces):
    """Unit vertex normals and the faces that can use them.

    Returns
    -------
    normals : (v, 3) float
        Unit normals (zero rows where the input was unusable).
    smooth : (f,) bool
        True for faces whose three vertex normals are all usable; the others shade flat.
    """
    if vertex_normals is None:
        return np.zeros_like(vertices), np.zeros(len(faces), dtype=bool)
    vn = np.ascontiguousarray(vertex_normals, dtype=np.float64).reshape(-1, 3)
    if len(vn) < len(vertices) and len(faces) and faces.max() >= len(vn):
        raise IndexError(f"{len(vn)} vertex normals for faces using {faces.max() + 1} vertices")
    # vn / |vn| where the length is finite and positive, else 0, in one compiled pass
    return build_kernels.unit_rows(vn, faces)


def default_lights(camera, physical=False):
    """A three-light rig (key, fill, rim) of directional lights placed relative to the camera.

    Directional lights make the rig independent of the scene's scale.

    Parameters
    ----------
    camera : Camera
    physical : bool
        For the path integrator: irradiances times pi (its Lambert term has the 1/pi the
        Whitted one lacks, so a white surface under the key light looks the same).

    Returns
    -------
    list of DirectionalLight
    """
    forward, right, up = camera.frame()
    key = forward - 0.8 * right - 0.9 * up  # from upper left, in front of the subject
    fill = forward + 0.9 * right - 0.2 * up  # from the right, weaker
    rim = -forward - 0.3 * right - 0.8 * up  # from behind, separates the silhouette
    scale = np.pi if physical else 1.0
    return [
        DirectionalLight(key, irradiance=np.full(3, 1.0 * scale)),
        DirectionalLight(fill, irradiance=np.full(3, 0.35 * scale)),
        DirectionalLight(rim, irradiance=np.full(3, 0.5 * scale)),
    ]


def _warn_dropped(source, dropped, empty, most=5):
    """One warning a kind of dropped face, and one for the objects left empty, naming up to
    ``most`` objects: ``scene.glb: object 'a': dropped 2 zero-area faces`` or
    ``scene.glb: dropped 7 zero-area faces in 3 objects: 'a' (3), 'b' (2), 'c' (2)``.

    Parameters
    ----------
    source : str
    dropped : dict of str to list of (str, int)
        Kind of face -> (object name, faces dropped).
    empty : list of str
        Objects with no renderable triangle left.
    """
    for kind, objects in dropped.items():
        if len(objects) == 1:
            log.warning("%s: object '%s': dropped %d %s", source, objects[0][0], objects[0][1], kind)
            continue
        listed = ", ".join(f"'{name}' ({count})" for name, count in objects[:most])
        more = f" and {len(objects) - most} more" if len(objects) > most else ""
        log.warning("%s: dropped %d %s in %d objects: %s%s", source, sum(c for _, c in objects), kind,
                    len(objects), listed, more)
    if len(empty) == 1:
        log.warning("%s: object '%s' has no renderable triangles; skipped", source, empty[0])
    elif empty:
        more = f" and {len(empty) - most} more" if len(empty) > most else ""
        log.warning("%s: %d objects have no renderable triangles (%s%s); skipped", source, len(empty),
                    ", ".join(f"'{n}'" for n in empty[:most]), more)


def _warn_layers_ignored(materials, source):
    """One warning naming the KHR layer extensions (clear coat, sheen, ...) that the
    materials of ``source`` use, which only the path integrator renders."""
    used = sorted({name for material in materials if material.layers is not None
                   for name in material.layers.extensions})
    if used:
        log.warning("%s: %s rendered by integrator 'path' only; integrator 'whitted' shades these materials "
                    "as plain metallic-roughness", source, ", ".join(used) + (" is" if len(used) == 1 else " are"))
