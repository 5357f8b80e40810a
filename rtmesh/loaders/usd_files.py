"""USD files (``.usd``, ``.usda``, ``.usdc``, ``.usdz``) to rtmesh parts, materials, lights
and a camera, through Pixar's ``usd-core`` (the ``rtmesh[usd]`` extra).

What is read (docs/ASSETS.md has the full mapping):

* **Meshes** (``UsdGeom.Mesh``) as their control cage (no subdivision), polygons
  fan-triangulated, holes dropped, left-handed ones flipped; implicit cubes and spheres
  (``UsdGeom.Cube``, ``UsdGeom.Sphere``) tessellated.  Primvars of every interpolation
  (constant, uniform, vertex, varying, faceVarying; indexed or not) for texture
  coordinates, normals and ``displayColor``: every triangle corner gets its values and
  corners with equal point and values are one vertex again.
* **Transforms** composed by ``UsdGeom.XformCache``; the stage's ``upAxis`` (Z-up stages
  are turned to rtmesh's Y-up) and ``metersPerUnit`` (scenes are in metres) honoured.
* **Point instancers** and **instanceable prims**: a prototype mesh placed more than once
  and large enough (:func:`rtmesh.scene.instances.worth_instancing`) is read once and
  placed by Embree instances (:attr:`UsdContent.placements`, every instance an object);
  smaller ones are copied (one part per prototype mesh and instancer, all its instances in
  it; one part per instance proxy).  Nested instancing is multiplied out to one level.
  Prims under a point instancer render only through it.
* **Materials**: ``UsdPreviewSurface`` (with ``UsdUVTexture`` textures read through
  ``UsdPrimvarReader_float2``) mapped onto the glTF metallic-roughness model that glTF
  files load as (:func:`rtmesh.loaders.gltf_materials.gltf_material`); a prim without a
  material shows its ``displayColor`` (roughness 0.5, as the preview surface's default).
* **Lights** (``UsdLux``): distant -> directional (irradiance = colour x intensity x
  2^exposure), sphere -> point (intensity = radiance x pi r^2, W/sr), rect -> quad and
  disk -> disk (radiance), dome -> the background, lighting the scene (its texture as the
  environment image, else a solid colour); ``normalize`` divides by the light's area.
  These are the path integrator's (physical) units; for the Whitted integrator, whose
  Lambert term has no 1/pi, point and directional lights are divided by pi, as glTF's
  lights are (:mod:`rtmesh.loaders.gltf_nodes`).
* **Cameras** (``UsdGeom.Camera``): the first one, perspective (vertical field of view
  from ``verticalAperture`` and ``focalLength``, a lens from ``fStop`` and
  ``focusDistance``) or orthographic.

Bad input is one line naming the file (and the prim): unreadable files, composition
errors such as a cycle of references, meshes whose indices do not fit their points.

The stage is opened by :mod:`rtmesh.loaders.usd_stage` and walked here (:func:`read_usd`);
its meshes are read by :mod:`rtmesh.loaders.usd_meshes`, its materials by
:mod:`rtmesh.loaders.usd_materials`, its lights and cameras by
:mod:`rtmesh.loaders.usd_lights_cameras`.
"""

import logging
import math
import os
from dataclasses import dataclass, field

import numpy as np

from rtmesh.core.errors import MeshError, RtmeshError
from rtmesh.loaders.usd_lights_cameras import UsdLightCameraReader
from rtmesh.loaders.usd_materials import UsdMaterialReader
from rtmesh.loaders.usd_meshes import UsdMeshReader
from rtmesh.loaders.usd_stage import open_stage, pxr_modules, quiet_stderr, tf_message, usd_array, usd_number

log = logging.getLogger(__name__)


@dataclass
class UsdContent:
    """What a USD file holds, in rtmesh's frame (Y up, metres).

    Attributes
    ----------
    parts : list of MeshPart
        World-space meshes (copies of small placed meshes among them).
    placements : list of Placement
        Meshes placed by point instancers or instanceable prims and worth instancing
        (:mod:`rtmesh.loaders.placements`): each once, in its own space, with every copy's
        transform to rtmesh's frame.
    materials : list of Material
        Indexed by the parts' ``material``.
    lights : list
        rtmesh lights.
    camera : Camera or None
        The first camera.
    background : background object or None
        A dome light.
    """

    parts: list = field(default_factory=list)
    placements: list = field(default_factory=list)
    materials: list = field(default_factory=list)
    lights: list = field(default_factory=list)
    camera: object = None
    background: object = None


def read_usd(path, physical=True):
    """Everything rtmesh renders of a USD file (module docstring).

    Parameters
    ----------
    path : str or os.PathLike
    physical : bool
        Lights in the path integrator's units; False: the Whitted integrator's (point and
        directional lights divided by pi).

    Returns
    -------
    UsdContent

    Raises
    ------
    MeshError
        Unreadable file, composition error, malformed mesh or texture.
    ResourceError
        Its meshes and their copies would take more memory than a loading limit allows
        (:func:`rtmesh.rendering.memory.check_load`; an instanced mesh counts once).
    """
    path = os.fspath(path)
    stage = open_stage(path)
    try:
        return _Reader(path, stage, physical).read()
    except RtmeshError:
        raise
    except Exception as exc:  # pxr raises Tf.ErrorException, RuntimeError, ValueError...
        raise MeshError(f"{path}: cannot read USD: {tf_message(exc)}") from None


class _Reader(UsdMeshReader, UsdMaterialReader, UsdLightCameraReader):
    """One pass over a stage, collecting parts, materials, lights and the camera (its
    meshes, materials, lights and cameras read by the classes it is made of)."""

    def __init__(self, path, stage, physical=True):
        self.path, self.stage = path, stage
        # point-like lights in the Whitted integrator's units: no 1/pi in its Lambert term
        self.point_units = 1.0 if physical else 1.0 / math.pi
        self.Gf, self.Sdf, self.Tf, self.Usd, self.UsdGeom, self.UsdLux, self.UsdShade = pxr_modules()
        Usd, UsdGeom = self.Usd, self.UsdGeom
        self.time = stage.GetStartTimeCode() if stage.HasAuthoredTimeCodeRange() else Usd.TimeCode.Default()
        self.cache = UsdGeom.XformCache(self.time)
        # stage frame -> rtmesh frame: metres, Y up
        from rtmesh.loaders.scene_keys import _positive

        scale = usd_number(UsdGeom.GetStageMetersPerUnit(stage), f"{path}: metersPerUnit", _positive)
        self.meters = scale
        frame = np.eye(4)
        if UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z:
            frame[:3, :3] = [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]
        frame[:3, :3] *= scale
        self.frame = frame
        self.content = UsdContent()
        # instance proxies' meshes by (prototype prim, bound material), placed after the walk
        self.proxies = {}
        self.material_ids = {}
        self.skipped = {}
        self.estimated = 0
        # the point instancers being walked (outermost first): a prototype holding one is a cycle
        self.instancing = []

    # ------------------------------------------------------------ traversal

    def read(self):
        self._walk(self.stage.GetPseudoRoot(), None, self.frame[None])
        self._place_proxies()
        for kind, paths in self.skipped.items():
            names = ", ".join(sorted(paths)[:5]) + (f" and {len(paths) - 5} more" if len(paths) > 5 else "")
            log.warning("%s: %d %s: %s", self.path, len(paths), kind, names)
        return self.content

    def _world(self, prim):
        """A prim's local-to-world transform, column vectors (USD's matrices are row vectors).

        Its own transform must be finite and at most 1e18 (the scene file's limit) in
        magnitude: else a MeshError naming the prim and the xformOp.  The composed one is
        computed without NumPy warnings; a non-finite product is left to :meth:`_kept`."""
        local = np.array(self.cache.GetLocalTransformation(prim)[0], dtype=np.float64)
        if not (np.isfinite(local).all() and np.abs(local).max() <= 1e18):
            self._bad_transform(prim)
        return np.array(self.cache.GetLocalToWorldTransform(prim), dtype=np.float64).T

    def _bad_transform(self, prim):
        name = "xformOpOrder"
        xformable = self.UsdGeom.Xformable(prim)
        for op in (xformable.GetOrderedXformOps() if xformable else []):
            try:
                usd_array(np.ravel(np.asarray(op.Get(self.time), dtype=np.float64)), "", None)
            except (MeshError, TypeError, ValueError):
                name = op.GetOpName()
                break
        raise MeshError(f"{self.path}: {prim.GetPath()}.{name}: a transform that is not finite or is "
                        "more than 1e18 in magnitude")

    def _skip(self, kind, prim):
        self.skipped.setdefault(kind, []).append(str(prim.GetPath()))

    def _walk(self, root, relative_to, placements):
        """Collect what is under ``root``.

        ``placements`` (m, 4, 4) maps the space of ``relative_to`` (a prim whose world
        transform is divided out; None: the world) to rtmesh's frame, once per copy.
        """
        Usd, UsdGeom, UsdLux = self.Usd, self.UsdGeom, self.UsdLux
        with np.errstate(all="ignore"):
            base = None if relative_to is None else np.linalg.inv(self._world(relative_to))
        prims = iter(Usd.PrimRange(root, Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)))
        for prim in prims:
            if prim.IsA(UsdGeom.Imageable):
                imageable = UsdGeom.Imageable(prim)
                if (imageable.ComputeVisibility(self.time) == UsdGeom.Tokens.invisible
                        or imageable.ComputePurpose() in (UsdGeom.Tokens.guide, UsdGeom.Tokens.proxy)):
                    prims.PruneChildren()
                    continue
            with np.errstate(all="ignore"):
                local = self._world(prim) if base is None else base @ self._world(prim)
            if prim.IsA(UsdGeom.PointInstancer):
                self._instancer(prim, local, placements)
                prims.PruneChildren()
            elif prim.IsA(UsdGeom.Mesh) or prim.IsA(UsdGeom.Cube) or prim.IsA(UsdGeom.Sphere):
                self._mesh(prim, local, placements)
            elif prim.IsA(UsdGeom.Gprim):
                self._skip("prims that are neither meshes, cubes nor spheres (not rendered)", prim)
            elif prim.HasAPI(UsdLux.LightAPI) or prim.IsA(UsdLux.BoundableLightBase) \
                    or prim.IsA(UsdLux.NonboundableLightBase):
                if relative_to is None:
                    self._light(prim, self.frame @ self._world(prim))
            elif prim.IsA(UsdGeom.Camera) and relative_to is None and self.content.camera is None:
                self.content.camera = self._camera(prim, self.frame @ self._world(prim))

    def _instancer(self, prim, local, placements):
        """A point instancer's prototypes, flattened once per instance (its invisible and
        inactive instances left out).  Its arrays are checked here (lengths, values) and USD's
        own warnings about them silenced; a prototype that holds the instancer, or one being
        walked around it, is a cycle and refused."""
        UsdGeom = self.UsdGeom
        instancer = UsdGeom.PointInstancer(prim)
        where = f"{self.path}: {prim.GetPath()}"
        indices = usd_array(instancer.GetProtoIndicesAttr().Get(self.time), f"{where}.protoIndices", integer=True)
        targets = instancer.GetPrototypesRel().GetTargets()
        if len(indices) and (indices.min() < 0 or indices.max() >= len(targets)):
            raise MeshError(f"{where}: protoIndices name prototypes the instancer does not have "
                            f"({len(targets)} prototypes)")
        for target in targets:
            for walked in self.instancing + [prim.GetPath()]:
                if walked.HasPrefix(target):
                    raise MeshError(f"{where}.prototypes: prototype {target} holds the point instancer {walked} "
                                    "(a cycle of instancing)")
        positions = usd_array(instancer.GetPositionsAttr().Get(self.time), f"{where}.positions", 3)
        if len(positions) != len(indices):
            raise MeshError(f"{where}.positions: {len(positions)} positions but {len(indices)} protoIndices")
        for name, attribute, width in (("scales", instancer.GetScalesAttr(), 3),
                                       ("orientations", instancer.GetOrientationsAttr(), None)):
            value = attribute.Get(self.time)
            if value is not None and len(value) and len(value) != len(indices):
                raise MeshError(f"{where}.{name}: {len(value)} {name} but {len(indices)} protoIndices")
            if width and value is not None:
                usd_array(value, f"{where}.{name}", width)
        with quiet_stderr():
            mask = instancer.ComputeMaskAtTime(self.time)
            rows = instancer.ComputeInstanceTransformsAtTime(self.time, self.time)
        if mask is not None and len(mask):
            indices = indices[np.asarray(mask, dtype=bool)]
        instances = np.array([np.array(m, dtype=np.float64).T for m in rows]).reshape(-1, 4, 4)
        if len(instances) != len(indices):
            raise MeshError(f"{where}: {len(indices)} protoIndices but {len(instances)} instance transforms")
        if not (np.isfinite(instances).all() and (not len(instances) or np.abs(instances).max() <= 1e18)):
            raise MeshError(f"{where}: instance transforms that are not finite or are more than 1e18 in magnitude")
        self.instancing.append(prim.GetPath())
        try:
            for k, target in enumerate(targets):
                chosen = instances[indices == k]
                prototype = self.stage.GetPrimAtPath(target)
                if not len(chosen) or not prototype:
                    continue
                # prototype space (its root's own transform included) -> instancer -> rtmesh frame
                with np.errstate(all="ignore"):
                    copies = (placements[:, None] @ local[None, None] @ chosen[None]).reshape(-1, 4, 4)
                self._walk(prototype, prototype.GetParent(), copies)
        finally:
            self.instancing.pop()

def load_usd_scene(path, physical=True, **scene_options):
    """A renderable :class:`Scene` of a USD file: its camera and lights when it has them,
    else the automatic camera and the lighting of physically based assets.

    Parameters
    ----------
    path : str or os.PathLike
    physical : bool
        For the path integrator (light units, :func:`read_usd`; the default rig).
    **scene_options
        Passed to :meth:`Scene.from_parts`.
    """
    from rtmesh.scene.model import Scene

    content = read_usd(path, physical)
    scene_options["physical"] = physical
    if not content.parts and not content.placements:
        raise MeshError(f"{os.fspath(path)}: nothing to render (no meshes)")
    if content.camera is not None:
        scene_options.setdefault("camera", content.camera)
    if content.lights:
        scene_options.setdefault("lights", content.lights)
    if content.background is not None:
        scene_options.setdefault("background", content.background)
        scene_options.setdefault("lights", [])
    return Scene.from_parts(content.parts, content.materials, source=os.fspath(path), placements=content.placements,
                            **scene_options)
