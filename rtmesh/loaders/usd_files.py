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
"""

import contextlib
import io
import logging
import math
import os
import re
import sys
from dataclasses import dataclass, field

import numpy as np
import trimesh

from rtmesh.core.errors import MeshError, MissingExtraError, RtmeshError
from rtmesh.geometry.smoothing import CREASE_ANGLE, smooth_vertex_normals
from rtmesh.lights.area_lights import DiskLight, QuadLight
from rtmesh.lights.point_lights import DirectionalLight, PointLight
from rtmesh.loaders.gltf_materials import OPTIONS_KEY, gltf_material
from rtmesh.loaders.mesh_files import check_file
from rtmesh.loaders.placements import copied, held_copies, placed_estimate
from rtmesh.rendering import memory
from rtmesh.scene.background import SolidBackground, read_environment
from rtmesh.scene.camera import Camera
from rtmesh.scene.instances import worth_instancing
from rtmesh.scene.model import MeshPart, Placement

log = logging.getLogger(__name__)

USD_EXTENSIONS = (".usd", ".usda", ".usdc", ".usdz")
EXTRA = "rtmesh[usd]"
_WRAP = {"repeat": "repeat", "mirror": "mirror", "clamp": "clamp", "black": "clamp", "useMetadata": "repeat"}


def _pxr():
    """The modules of usd-core, or MissingExtraError naming the extra."""
    try:
        from pxr import Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade
    except ImportError:
        raise MissingExtraError(f"USD files need usd-core: pip install '{EXTRA}'") from None
    return Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade


@contextlib.contextmanager
def _quiet_stderr():
    """USD prints its diagnostics on the process's standard error (file descriptor 2); the
    loader reports them itself, in one line, so they are sent to nothing meanwhile."""
    try:
        saved = os.dup(2)
    except OSError:
        yield
        return
    try:
        with open(os.devnull, "wb") as sink:
            os.dup2(sink.fileno(), 2)
            yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


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


def open_stage(path):
    """Open a USD file, refusing unreadable files and composition errors in one line.

    The layer files it composed are announced as read (:func:`_announce_layers`), so a
    batch records them among the asset's inputs.

    Parameters
    ----------
    path : str

    Returns
    -------
    pxr.Usd.Stage

    Raises
    ------
    MeshError
        The file cannot be read, or its composition has an error (a cycle of references,
        a reference to a missing file).
    MissingExtraError
        usd-core is not installed.
    """
    _, _, Tf, Usd, _, _, _ = _pxr()
    check_file(path)
    with _quiet_stderr():
        try:
            stage = Usd.Stage.Open(path)
        except Tf.ErrorException as exc:
            raise MeshError(f"{path}: cannot read USD: {_tf_message(exc)}") from None
        if stage is None:
            raise MeshError(f"{path}: cannot read USD")
        errors = stage.GetCompositionErrors()
    _announce_layers(stage)
    if errors:
        more = f" (and {len(errors) - 1} more composition errors)" if len(errors) > 1 else ""
        raise MeshError(f"{path}: {_composition_message(errors[0])}{more}")
    return stage


def _announce_layers(stage):
    """Announce each layer file the stage composed (the root layer, its sublayers, references
    and payloads, at any depth) as Python's own ``open`` does: USD reads them natively, where
    Python's audit hooks cannot see them, and whoever records the files a load reads (the
    batch's change detection, :class:`rtmesh.batch.identity.OpenedFiles`) must see these too.
    Textures are read through Python (:meth:`_Reader._image`) or OpenImageIO, which announces
    its reads itself."""
    for layer in stage.GetUsedLayers():
        if layer.anonymous or not layer.realPath:
            continue
        # a layer inside a USDZ package (``a.usdz[inner.usdc]``) is read from the package
        real = layer.realPath
        sys.audit("open", real.split("[", 1)[0] if real.endswith("]") else real, "rb", 0)


def _tf_message(exc):
    """The commentary of a USD error (``... : 'Failed to open layer @x.usda@'``), one line."""
    text = " ".join(str(exc).split())
    found = re.search(r" : '(.*)'$", text) or re.search(r" : '(.*?)'", text)
    return found.group(1) if found else (text or type(exc).__name__)


def _composition_message(error):
    """One line for a composition error; a cycle lists the layers and prims that form it."""
    text = str(error)
    if type(error).__name__ == "ErrorArcCycle":
        sites = [f"{os.path.basename(layer)}{prim}"
                 for layer, prim in re.findall(r"@([^@,]+)@(?:,@[^@]*@)?(<[^>]*>)", text)]
        cycle = []
        for site in sites:
            cycle.append(site)
            if cycle.count(site) > 1:
                break
        return f"a cycle of references: {' -> '.join(cycle)} (USD cannot compose it)"
    return "composition error: " + " ".join(text.split())


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
        raise MeshError(f"{path}: cannot read USD: {_tf_message(exc)}") from None


class _Reader:
    """One pass over a stage, collecting parts, materials, lights and the camera."""

    def __init__(self, path, stage, physical=True):
        self.path, self.stage = path, stage
        # point-like lights in the Whitted integrator's units: no 1/pi in its Lambert term
        self.point_units = 1.0 if physical else 1.0 / math.pi
        self.Gf, self.Sdf, self.Tf, self.Usd, self.UsdGeom, self.UsdLux, self.UsdShade = _pxr()
        Usd, UsdGeom = self.Usd, self.UsdGeom
        self.time = stage.GetStartTimeCode() if stage.HasAuthoredTimeCodeRange() else Usd.TimeCode.Default()
        self.cache = UsdGeom.XformCache(self.time)
        # stage frame -> rtmesh frame: metres, Y up
        scale = float(UsdGeom.GetStageMetersPerUnit(stage))
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

    # ------------------------------------------------------------ traversal

    def read(self):
        self._walk(self.stage.GetPseudoRoot(), None, self.frame[None])
        self._place_proxies()
        for kind, paths in self.skipped.items():
            names = ", ".join(sorted(paths)[:5]) + (f" and {len(paths) - 5} more" if len(paths) > 5 else "")
            log.warning("%s: %d %s: %s", self.path, len(paths), kind, names)
        return self.content

    def _world(self, prim):
        """A prim's local-to-world transform, column vectors (USD's matrices are row vectors)."""
        return np.array(self.cache.GetLocalToWorldTransform(prim), dtype=np.float64).T

    def _skip(self, kind, prim):
        self.skipped.setdefault(kind, []).append(str(prim.GetPath()))

    def _walk(self, root, relative_to, placements):
        """Collect what is under ``root``.

        ``placements`` (m, 4, 4) maps the space of ``relative_to`` (a prim whose world
        transform is divided out; None: the world) to rtmesh's frame, once per copy.
        """
        Usd, UsdGeom, UsdLux = self.Usd, self.UsdGeom, self.UsdLux
        base = None if relative_to is None else np.linalg.inv(self._world(relative_to))
        prims = iter(Usd.PrimRange(root, Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)))
        for prim in prims:
            if prim.IsA(UsdGeom.Imageable):
                imageable = UsdGeom.Imageable(prim)
                if (imageable.ComputeVisibility(self.time) == UsdGeom.Tokens.invisible
                        or imageable.ComputePurpose() in (UsdGeom.Tokens.guide, UsdGeom.Tokens.proxy)):
                    prims.PruneChildren()
                    continue
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
        """A point instancer's prototypes, flattened once per instance."""
        UsdGeom = self.UsdGeom
        instancer = UsdGeom.PointInstancer(prim)
        where = f"{self.path}: {prim.GetPath()}"
        indices = np.asarray(instancer.GetProtoIndicesAttr().Get(self.time) or [], dtype=np.int64)
        targets = instancer.GetPrototypesRel().GetTargets()
        if len(indices) and (indices.min() < 0 or indices.max() >= len(targets)):
            raise MeshError(f"{where}: protoIndices name prototypes the instancer does not have "
                            f"({len(targets)} prototypes)")
        rows = instancer.ComputeInstanceTransformsAtTime(self.time, self.time)
        instances = np.array([np.array(m, dtype=np.float64).T for m in rows]).reshape(-1, 4, 4)
        if len(instances) != len(indices):
            raise MeshError(f"{where}: {len(indices)} protoIndices but {len(instances)} instance transforms")
        if not np.isfinite(instances).all():
            raise MeshError(f"{where}: instance transforms that are not finite")
        for k, target in enumerate(targets):
            chosen = instances[indices == k]
            prototype = self.stage.GetPrimAtPath(target)
            if not len(chosen) or not prototype:
                continue
            # prototype space (its root's own transform included) -> instancer -> rtmesh frame
            copies = (placements[:, None] @ local[None, None] @ chosen[None]).reshape(-1, 4, 4)
            self._walk(prototype, prototype.GetParent(), copies)

    # ------------------------------------------------------------ meshes

    def _mesh(self, prim, local, placements):
        """A mesh placed once per row of ``placements @ local`` (rtmesh's frame): built once
        and placed by instances when it is worth it (:mod:`rtmesh.loaders.placements`), else
        one part of all its copies.  An instance proxy (a prim under an instanceable prim)
        waits for the end of the traversal (:meth:`_place_proxies`), where every instance of
        its prototype's prim is known."""
        if prim.IsInstanceProxy():
            self._proxy(prim, local, placements)
            return
        geometry = self._prepared(prim, len(placements))
        if geometry is None:
            return
        matrices = self._kept(prim, placements @ local[None])
        name = str(prim.GetPath())
        if worth_instancing(len(geometry.faces), len(matrices)):
            names = [f"{name}[{j}]" for j in range(len(matrices))]
            self.content.placements.append(Placement(geometry, matrices, names))
        elif len(matrices):
            self.content.parts.append(copied(geometry, matrices,
                                             name + (f" ({len(matrices)} copies)" if len(matrices) > 1 else "")))

    def _prepared(self, prim, copies, geometry=None):
        """A mesh's geometry in its own space as a MeshPart (normals smoothed by angle where
        it has none), after the memory check for ``copies`` placements; None for an empty
        mesh.  ``geometry``: what :meth:`_geometry` read of it already (an instance proxy's,
        read from its prototype's prim once)."""
        geometry = self._geometry(prim) if geometry is None else geometry
        if geometry is None:
            return None
        vertices, faces, normals, uv, colours, material = geometry
        self._check_memory(prim, copies, len(vertices), len(faces))
        if normals is None:
            vertices, faces, normals, original = smooth_vertex_normals(vertices, faces, CREASE_ANGLE)
            uv = None if uv is None else uv[original]
            colours = None if colours is None else colours[original]
        return MeshPart(str(prim.GetPath()), vertices, faces, material, normals, uv=uv, vertex_colors=colours)

    def _kept(self, prim, matrices):
        """The placements (m, 4, 4) that can place a mesh: finite and non-singular (the others
        skipped with a warning), their bottom row ``0 0 0 1`` (copies ignore it)."""
        keep = np.isfinite(matrices).all(axis=(1, 2)) & (np.linalg.det(matrices[:, :3, :3]) != 0.0)
        if not keep.all():
            self._skip("copies with a zero scale or a non-finite transform (not rendered)", prim)
        matrices = matrices[keep]
        matrices[:, 3] = (0.0, 0.0, 0.0, 1.0)
        return matrices

    def _proxy(self, prim, local, placements):
        """An instance proxy's mesh: its prototype's geometry read once (per bound material),
        a slot kept in the parts where its copies go should they be copied."""
        material, _ = self._material(prim)
        key = (str(prim.GetPrimInPrototype().GetPath()), None if material is None else str(material.GetPath()))
        group = self.proxies.get(key)
        if group is None:
            group = self.proxies[key] = dict(geometry=self._geometry(prim), slots=[], prim=prim)
        group["slots"].append((len(self.content.parts), self._kept(prim, placements @ local[None]), prim))
        self.content.parts.append(None)

    def _place_proxies(self):
        """Every instanceable prim's meshes: a prototype mesh placed by all the instances of
        its prototype built once and placed by instances when worth it, else copied into
        each proxy's own slot (as each proxy was read before)."""
        for group in self.proxies.values():
            if group["geometry"] is None:
                continue
            slots = group["slots"]
            count = sum(len(matrices) for _, matrices, _ in slots)
            faces = len(group["geometry"][1])
            if worth_instancing(faces, count):
                part = self._prepared(group["prim"], count, group["geometry"])
                names = [str(prim.GetPath()) + (f"[{j}]" if len(matrices) > 1 else "")
                         for _, matrices, prim in slots for j in range(len(matrices))]
                self.content.placements.append(Placement(part, np.concatenate([m for _, m, _ in slots]), names))
                continue
            for index, matrices, prim in slots:
                part = self._prepared(prim, len(matrices), group["geometry"])
                if len(matrices):
                    self.content.parts[index] = copied(part, matrices, part.name + (
                        f" ({len(matrices)} copies)" if len(matrices) > 1 else ""))
        self.content.parts = [part for part in self.content.parts if part is not None]

    def _check_memory(self, prim, copies, vertices, faces):
        """Refuse, before flattening, copies whose memory exceeds the loading limit (a mesh
        worth instancing counts once, :func:`rtmesh.loaders.placements.placed_estimate`)."""
        self.estimated += placed_estimate(vertices, faces, copies)
        held = held_copies(faces, copies)
        here = (f"{copies} copies of {faces} triangles here" if held == copies
                else f"{copies} instances of one mesh of {faces} triangles here")
        memory.check_load(self.path, f"{prim.GetPath()} and the prims before it, flattened ({here})",
                          self.estimated)

    def _geometry(self, prim):
        """(vertices, faces, normals or None, uv or None, colours or None, material index) of
        a mesh, cube or sphere prim, in its own space; None for an empty one."""
        UsdGeom = self.UsdGeom
        where = f"{self.path}: {prim.GetPath()}"
        if prim.IsA(UsdGeom.Cube):
            size = float(UsdGeom.Cube(prim).GetSizeAttr().Get(self.time))
            shape = trimesh.creation.box(extents=[size] * 3)
            points, counts, indices = shape.vertices, np.full(len(shape.faces), 3), shape.faces.ravel()
            left_handed, normals_spec = False, None
        elif prim.IsA(UsdGeom.Sphere):
            radius = float(UsdGeom.Sphere(prim).GetRadiusAttr().Get(self.time))
            shape = trimesh.creation.icosphere(subdivisions=3, radius=radius)
            points, counts, indices = shape.vertices, np.full(len(shape.faces), 3), shape.faces.ravel()
            left_handed, normals_spec = False, ("vertex", shape.vertices / radius if radius else None)
        else:
            mesh = UsdGeom.Mesh(prim)
            points = np.asarray(mesh.GetPointsAttr().Get(self.time) or [], dtype=np.float64).reshape(-1, 3)
            counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get(self.time) or [], dtype=np.int64)
            indices = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(self.time) or [], dtype=np.int64)
            left_handed = mesh.GetOrientationAttr().Get(self.time) == UsdGeom.Tokens.leftHanded
            normals_spec = None
            holes = np.asarray(mesh.GetHoleIndicesAttr().Get(self.time) or [], dtype=np.int64)
        if not len(counts):
            return None
        if counts.sum() != len(indices) or (counts < 0).any():
            raise MeshError(f"{where}: faceVertexCounts add up to {int(counts.sum())} but there are "
                            f"{len(indices)} faceVertexIndices")
        if len(indices) and (indices.min() < 0 or indices.max() >= len(points)):
            raise MeshError(f"{where}: faceVertexIndices refer to points the mesh does not have "
                            f"({len(points)} points)")
        # fan triangulation: face f of c corners starting at s gives (s, s+k, s+k+1), k = 1..c-2
        per_face = np.maximum(counts - 2, 0)
        if prim.IsA(UsdGeom.Mesh) and len(holes):
            per_face[holes[(holes >= 0) & (holes < len(counts))]] = 0
        starts = np.cumsum(counts) - counts
        face_of = np.repeat(np.arange(len(counts)), per_face)
        k = np.arange(len(face_of)) - np.repeat(np.cumsum(per_face) - per_face, per_face) + 1
        corners = np.stack([starts[face_of], starts[face_of] + k, starts[face_of] + k + 1], axis=1)
        if left_handed:
            corners = corners[:, ::-1]
        if not len(corners):
            return None
        point_of = indices[corners]  # (t, 3)
        shape_of = dict(face=face_of, corner=corners, point=point_of, faces=len(counts),
                        corners=len(indices), points=len(points))
        api = self.UsdGeom.PrimvarsAPI(prim)
        material, uv_name = self._material(prim)
        uv = self._uv(api, uv_name, shape_of)
        if normals_spec is not None:
            normals = normals_spec[1][point_of] if normals_spec[1] is not None else None
        else:
            normals = self._normals(prim, api, shape_of)
        colours = self._colours(api, shape_of, material)
        columns = [point_of.reshape(-1, 1).astype(np.float64)]
        for values in (uv, normals, colours):
            if values is not None:
                columns.append(values.reshape(len(point_of) * 3, -1))
        keys = np.hstack(columns)
        unique, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
        vertices = points[point_of.reshape(-1)[first]]
        faces = inverse.reshape(-1, 3)

        def welded(values):
            return None if values is None else values.reshape(len(point_of) * 3, -1)[first]

        return (vertices, faces, welded(normals), welded(uv), welded(colours), self._material_index(material, prim))

    def _primvar(self, primvar, shape_of, width, what):
        """A primvar's values at every triangle corner, (t, 3, width), or None (with a
        warning) for one whose length does not fit its interpolation."""
        if not primvar or not primvar.HasValue():
            return None
        values = primvar.ComputeFlattened(self.time)
        if values is None:
            return None
        values = np.asarray(values, dtype=np.float64).reshape(len(values), -1)
        if values.shape[1] < width:
            return None
        values = values[:, :width]
        interpolation = primvar.GetInterpolation()
        index = {"constant": None, "uniform": "face", "vertex": "point", "varying": "point",
                 "faceVarying": "corner"}.get(interpolation)
        needed = {None: 1, "face": shape_of["faces"], "point": shape_of["points"],
                  "corner": shape_of["corners"]}[index]
        if len(values) < needed or not len(values):
            self._skip("primvars shorter than their interpolation needs (ignored)",
                       primvar.GetAttr())
            return None
        if index is None:
            return np.broadcast_to(values[0], (len(shape_of["point"]), 3, width))
        rows = shape_of[index]
        if index == "face":
            rows = np.repeat(rows[:, None], 3, axis=1)
        return values[rows]

    def _uv(self, api, name, shape_of):
        primvar = api.GetPrimvar(name) if name else None
        if not primvar or not primvar.HasValue():
            primvar = next((p for p in api.GetPrimvarsWithValues()
                            if p.GetTypeName() in (self.Sdf.ValueTypeNames.TexCoord2f, self.Sdf.ValueTypeNames.Float2)
                            or p.GetPrimvarName() == "st"), None)
        return None if primvar is None else self._primvar(primvar, shape_of, 2, "uv")

    def _normals(self, prim, api, shape_of):
        primvar = api.GetPrimvar("normals")
        if primvar and primvar.HasValue():
            return self._primvar(primvar, shape_of, 3, "normals")
        mesh = self.UsdGeom.Mesh(prim)
        attribute = mesh.GetNormalsAttr()
        if not attribute.HasValue():
            return None
        # the normals attribute, with its own interpolation
        values = np.asarray(attribute.Get(self.time), dtype=np.float64).reshape(-1, 3)
        interpolation = mesh.GetNormalsInterpolation()
        index = {"uniform": "face", "vertex": "point", "varying": "point", "faceVarying": "corner"}.get(
            interpolation, "point")
        needed = {"face": shape_of["faces"], "point": shape_of["points"], "corner": shape_of["corners"]}[index]
        if len(values) < needed:
            self._skip("normals shorter than their interpolation needs (ignored)", prim)
            return None
        rows = shape_of[index]
        if index == "face":
            rows = np.repeat(rows[:, None], 3, axis=1)
        return values[rows]

    def _colours(self, api, shape_of, material):
        """displayColor (and displayOpacity) as linear RGBA per corner, where it varies and
        no material is bound (a constant one becomes the material's colour)."""
        if material is not None:
            return None
        colour = self._primvar(api.GetPrimvar("displayColor"), shape_of, 3, "colour")
        if colour is None or colour.strides[0] == 0:  # constant
            return None
        opacity = self._primvar(api.GetPrimvar("displayOpacity"), shape_of, 1, "opacity")
        alpha = np.ones(colour.shape[:2] + (1,)) if opacity is None else opacity
        return np.concatenate([colour, alpha], axis=2)

    # ------------------------------------------------------------ materials

    def _material(self, prim):
        """(bound UsdShade.Material or None, the texture-coordinate primvar its textures read)."""
        bound = self.UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()[0]
        if not bound:
            return None, "st"
        return bound, self._uv_name(bound) or "st"

    def _uv_name(self, material):
        for shader in self._shaders(material):
            if shader.GetIdAttr().Get() == "UsdPrimvarReader_float2":
                value = self._input_value(shader, "varname")
                if value:
                    return str(value)
        return None

    def _shaders(self, material):
        out = []
        for prim in self.Usd.PrimRange(material.GetPrim()):
            if prim.IsA(self.UsdShade.Shader):
                out.append(self.UsdShade.Shader(prim))
        return out

    def _input_value(self, shader, name):
        """An input's value through connections to material interface inputs; None unset."""
        shade_input = shader.GetInput(name)
        if not shade_input:
            return None
        for attribute in shade_input.GetValueProducingAttributes():
            if self.UsdShade.Input.IsInput(attribute):
                return attribute.Get(self.time)
        return None

    def _texture_source(self, shader, name):
        """(UsdUVTexture shader, output name) an input is connected to, or None."""
        shade_input = shader.GetInput(name)
        if not shade_input:
            return None
        for attribute in shade_input.GetValueProducingAttributes():
            if self.UsdShade.Output.IsOutput(attribute):
                source = self.UsdShade.Shader(attribute.GetPrim())
                if source.GetIdAttr().Get() == "UsdUVTexture":
                    return source, self.UsdShade.Output(attribute).GetBaseName()
        return None

    def _material_index(self, material, prim):
        UsdGeom = self.UsdGeom
        if material is None:
            primvar = UsdGeom.PrimvarsAPI(prim).GetPrimvar("displayColor")
            colour = self._primvar(primvar, dict(point=np.zeros((1, 3), int), faces=1, points=1, corners=1,
                                                 face=np.zeros(1, int), corner=np.zeros((1, 3), int)), 3, "colour")
            base = (0.18, 0.18, 0.18) if colour is None else tuple(float(c) for c in colour[0, 0])
            if colour is not None and primvar.GetInterpolation() != UsdGeom.Tokens.constant:
                base = (1.0, 1.0, 1.0)  # the vertex colours carry it (glTF's COLOR_0 times the base)
            key = ("displayColor", base)
            if key not in self.material_ids:
                pbr = trimesh.visual.material.PBRMaterial(
                    name=f"displayColor {base}", baseColorFactor=[*base, 1.0], metallicFactor=0.0,
                    roughnessFactor=0.5)
                self._add_material(key, gltf_material(pbr, {"name": pbr.name}, pbr.name, self.path))
            return self.material_ids[key]
        key = str(material.GetPath())
        if key not in self.material_ids:
            self._add_material(key, self._preview_surface(material))
        return self.material_ids[key]

    def _add_material(self, key, material):
        self.material_ids[key] = len(self.content.materials)
        self.content.materials.append(material)

    def _preview_surface(self, material):
        """A UsdPreviewSurface as the glTF metallic-roughness material."""
        name = material.GetPrim().GetName()
        shader = None
        source = material.ComputeSurfaceSource()
        if source and source[0]:
            shader = source[0]
        if shader is None or shader.GetIdAttr().Get() != "UsdPreviewSurface":
            self._skip("materials without a UsdPreviewSurface (grey used)", material.GetPrim())
            pbr = trimesh.visual.material.PBRMaterial(name=name, baseColorFactor=[0.18, 0.18, 0.18, 1.0],
                                                      metallicFactor=0.0, roughnessFactor=0.5)
            return gltf_material(pbr, {"name": name}, name, self.path)

        def number(key, default):
            value = self._input_value(shader, key)
            return default if value is None else float(value)

        def colour(key, default):
            value = self._input_value(shader, key)
            return list(default) if value is None else [float(c) for c in value]

        if number("useSpecularWorkflow", 0.0):
            self._skip("materials in the specular workflow (read as metallic-roughness)", material.GetPrim())
        opacity = number("opacity", 1.0)
        threshold = number("opacityThreshold", 0.0)
        options, images = {}, {}
        base = colour("diffuseColor", (0.18, 0.18, 0.18))
        emissive = colour("emissiveColor", (0.0, 0.0, 0.0))
        metallic, roughness = number("metallic", 0.0), number("roughness", 0.5)

        diffuse = self._texture(shader, "diffuseColor", name)
        if diffuse is not None:
            images["baseColorTexture"], options["baseColorTexture"], scale = diffuse
            base = list(scale[:3])
        emission = self._texture(shader, "emissiveColor", name)
        if emission is not None:
            images["emissiveTexture"], options["emissiveTexture"], scale = emission
            emissive = list(scale[:3])
        normal = self._texture(shader, "normal", name)
        if normal is not None:
            images["normalTexture"], options["normalTexture"], _ = normal
        rough, metal = self._texture(shader, "roughness", name), self._texture(shader, "metallic", name)
        if rough is not None or metal is not None:
            images["metallicRoughnessTexture"], options["metallicRoughnessTexture"] = _packed(rough, metal)
            roughness = 1.0 if rough is not None else roughness
            metallic = 1.0 if metal is not None else metallic
        mode = "OPAQUE"
        if threshold > 0.0:
            mode = "MASK"
        elif opacity < 1.0:
            mode = "BLEND"
        pbr = trimesh.visual.material.PBRMaterial(
            name=name, baseColorFactor=[*base, opacity], metallicFactor=metallic, roughnessFactor=roughness,
            emissiveFactor=emissive, alphaMode=mode, alphaCutoff=threshold if threshold > 0.0 else None,
            doubleSided=True, **images)
        json_material = {"name": name, "pbrMetallicRoughness": {"baseColorFactor": [*base, opacity],
                                                                "metallicFactor": metallic,
                                                                "roughnessFactor": roughness},
                         "emissiveFactor": emissive, "alphaMode": mode, "doubleSided": True,
                         OPTIONS_KEY: options}
        if threshold > 0.0:
            json_material["alphaCutoff"] = threshold
        return gltf_material(pbr, json_material, name, self.path)

    def _texture(self, shader, key, material_name):
        """(PIL image of the channels the input reads, texture options, scale (4,)) of a
        UsdUVTexture connected to ``key``, or None."""
        found = self._texture_source(shader, key)
        if found is None:
            return None
        texture, output = found
        asset = self._input_value(texture, "file")
        image = self._image(asset, f"material '{material_name}' {key}")
        if image is None:
            return None
        wrap = tuple(_WRAP.get(str(self._input_value(texture, axis) or "useMetadata"), "repeat")
                     for axis in ("wrapS", "wrapT"))
        scale = self._input_value(texture, "scale")
        scale = np.ones(4) if scale is None else np.asarray(scale, dtype=np.float64)
        channels = {"r": "R", "g": "G", "b": "B", "a": "A"}
        if output in channels:
            image = image.convert("RGBA").getchannel(channels[output])
        return image, {"wrap": wrap, "transform": None}, scale

    def _image(self, asset, what):
        """A texture's PIL image from its asset path (a file, or a file inside a USDZ
        package); None with a warning when it is missing."""
        from PIL import Image

        if asset is None:
            return None
        resolved = getattr(asset, "resolvedPath", "") or ""
        authored = getattr(asset, "path", str(asset))
        try:
            if resolved.endswith("]") and "[" in resolved:
                package, inner = resolved[:-1].split("[", 1)
                zip_file = getattr(self.Sdf, "ZipFile", None) or self.Usd.ZipFile  # Usd's before 24.11
                data = zip_file.Open(package).GetFile(inner)
                if data is None:
                    raise OSError("not in the package")
                data = bytes(data)
            elif resolved:
                with open(resolved, "rb") as f:
                    data = f.read()
            else:
                raise OSError("not found")
        except OSError as exc:
            log.warning("%s: %s: texture %s cannot be read (%s); not used", self.path, what, authored, exc)
            return None
        try:
            image = Image.open(io.BytesIO(data))
            image.load()
        except Exception as exc:  # PIL raises many types for corrupt images
            raise MeshError(f"{self.path}: {what}: texture {authored}: corrupt or unreadable "
                            f"({type(exc).__name__})") from None
        return image

    # ------------------------------------------------------------ lights and cameras

    def _light(self, prim, world):
        UsdLux = self.UsdLux
        light = UsdLux.LightAPI(prim)

        def get(attribute, default):
            value = attribute.Get(self.time) if attribute and attribute.HasValue() else None
            return default if value is None else value

        radiance = (np.asarray(get(light.GetColorAttr(), (1.0, 1.0, 1.0)), dtype=np.float64)
                    * float(get(light.GetIntensityAttr(), 1.0)) * 2.0 ** float(get(light.GetExposureAttr(), 0.0)))
        normalize = bool(get(light.GetNormalizeAttr(), False))
        position = world[:3, 3]
        forward = world[:3, :3] @ np.array([0.0, 0.0, -1.0])
        lengths = np.linalg.norm(world[:3, :3], axis=0)
        if not (np.isfinite(world).all() and (lengths > 0).all()):
            self._skip("lights with a zero scale or a non-finite transform (skipped)", prim)
            return
        if prim.IsA(UsdLux.DistantLight):
            self.content.lights.append(DirectionalLight(forward, radiance * self.point_units))
        elif prim.IsA(UsdLux.SphereLight):
            radius = float(get(UsdLux.SphereLight(prim).GetRadiusAttr(), 0.5)) * float(lengths.mean())
            area = 4.0 * math.pi * radius ** 2
            scale = 1.0 / area if normalize and area > 0 else 1.0
            self.content.lights.append(PointLight(position, radiance * scale * math.pi * radius ** 2
                                                  * self.point_units))
        elif prim.IsA(UsdLux.RectLight):
            rect = UsdLux.RectLight(prim)
            width, height = float(get(rect.GetWidthAttr(), 1.0)), float(get(rect.GetHeightAttr(), 1.0))
            edge1 = world[:3, :3] @ np.array([0.0, height, 0.0])
            edge2 = world[:3, :3] @ np.array([width, 0.0, 0.0])
            area = float(np.linalg.norm(np.cross(edge1, edge2)))
            self.content.lights.append(QuadLight(position, edge1, edge2,
                                                 radiance / area if normalize and area > 0 else radiance))
        elif prim.IsA(UsdLux.DiskLight):
            radius = float(get(UsdLux.DiskLight(prim).GetRadiusAttr(), 0.5)) * float(lengths[:2].mean())
            area = math.pi * radius ** 2
            self.content.lights.append(DiskLight(position, forward, radius,
                                                 radiance / area if normalize and area > 0 else radiance))
        elif prim.IsA(UsdLux.DomeLight):
            self.content.background = self._dome(prim, radiance)
        else:
            self._skip("lights of types rtmesh does not have (skipped)", prim)

    def _dome(self, prim, radiance):
        asset = self.UsdLux.DomeLight(prim).GetTextureFileAttr().Get(self.time)
        resolved = getattr(asset, "resolvedPath", "") if asset else ""
        if resolved and "[" not in resolved:
            background = read_environment(resolved, 0.0, float(np.mean(radiance)))
        else:
            if asset and getattr(asset, "path", ""):
                self._skip("dome textures that cannot be read (a solid colour used)", prim)
            background = SolidBackground(radiance)
        background.lighting = True
        return background

    def _camera(self, prim, world):
        UsdGeom = self.UsdGeom
        camera = UsdGeom.Camera(prim)

        def get(attribute, default):
            value = attribute.Get(self.time) if attribute else None
            return default if value is None else float(value)

        position = world[:3, 3]
        forward = world[:3, :3] @ np.array([0.0, 0.0, -1.0])
        up = world[:3, :3] @ np.array([0.0, 1.0, 0.0])
        if not (np.isfinite(world).all() and np.linalg.norm(forward) > 0 and np.linalg.norm(up) > 0):
            self._skip("cameras with a zero scale or a non-finite transform (skipped)", prim)
            return None
        forward = forward / np.linalg.norm(forward)
        focal = get(camera.GetFocalLengthAttr(), 50.0)
        vertical = get(camera.GetVerticalApertureAttr(), 15.2908)
        # apertures and focal length are in tenths of a scene unit
        tenth = 0.1 * self.meters
        if camera.GetProjectionAttr().Get(self.time) == UsdGeom.Tokens.orthographic:
            height = vertical * tenth * float(np.linalg.norm(up))
            return Camera(position, position + forward, up, projection="orthographic", ortho_height=height)
        fov = math.degrees(2.0 * math.atan(0.5 * vertical / focal))
        f_stop, focus = get(camera.GetFStopAttr(), 0.0), get(camera.GetFocusDistanceAttr(), 0.0)
        aperture = focal * tenth / f_stop if f_stop > 0 and focus > 0 else 0.0
        return Camera(position, position + forward, up, fov=fov, aperture=aperture,
                      focus_distance=focus * self.meters if aperture > 0 else None)


def _packed(rough, metal):
    """glTF's metallic-roughness texture (roughness in green, metalness in blue) of a
    preview surface's separate one-channel roughness and metallic textures."""
    from PIL import Image

    images = [t[0] for t in (rough, metal) if t is not None]
    size = max((image.size for image in images), key=lambda s: s[0] * s[1])
    zero = Image.new("L", size, 0)
    green = rough[0].convert("L").resize(size) if rough is not None else Image.new("L", size, 255)
    blue = metal[0].convert("L").resize(size) if metal is not None else Image.new("L", size, 255)
    options = (rough or metal)[1]
    return Image.merge("RGB", (zero, green, blue)), options


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
