"""USD meshes (``UsdGeom.Mesh``, and implicit cubes and spheres tessellated) to rtmesh's
mesh parts: fan triangulation, holes, orientation, primvars of every interpolation (texture
coordinates, normals, ``displayColor``) welded per corner, the memory check before
flattening, and meshes placed many times (point instancers, instance proxies) kept once
as instances where worth it, else copied."""

import numpy as np
import trimesh

from rtmesh.core.errors import MeshError
from rtmesh.geometry.smoothing import CREASE_ANGLE, smooth_vertex_normals
from rtmesh.loaders.placements import copied, held_copies, placed_estimate
from rtmesh.loaders.usd_stage import quiet_stderr, usd_array, usd_number
from rtmesh.rendering import memory
from rtmesh.scene.instances import worth_instancing
from rtmesh.scene.model import MeshPart, Placement


class UsdMeshReader:
    """The USD reader's meshes: each placed once per copy, instanced or copied.

    A part of the reader (:class:`rtmesh.loaders.usd_files._Reader`): it reads the stage
    through the reader's ``path``, ``time`` and ``pxr`` modules, fills its ``content``
    (parts and placements), gathers instance proxies in ``proxies`` until the end of the
    walk, counts the memory flattened so far in ``estimated``, and takes materials from
    :class:`rtmesh.loaders.usd_materials.UsdMaterialReader`.
    """

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
        with np.errstate(all="ignore"):
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
        with np.errstate(all="ignore"):
            keep = np.isfinite(matrices).all(axis=(1, 2)) & (np.abs(matrices) <= 1e18).all(axis=(1, 2))
            determinant = np.linalg.det(np.where(keep[:, None, None], matrices, 1.0)[:, :3, :3])
            keep &= np.isfinite(determinant) & (determinant != 0.0)
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
        with np.errstate(all="ignore"):
            matrices = self._kept(prim, placements @ local[None])
        group["slots"].append((len(self.content.parts), matrices, prim))
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
        from rtmesh.loaders.scene_keys import _positive

        if prim.IsA(UsdGeom.Cube):
            size = usd_number(UsdGeom.Cube(prim).GetSizeAttr().Get(self.time), f"{where}.size", _positive)
            shape = trimesh.creation.box(extents=[size] * 3)
            points, counts, indices = shape.vertices, np.full(len(shape.faces), 3), shape.faces.ravel()
            left_handed, normals_spec = False, None
        elif prim.IsA(UsdGeom.Sphere):
            radius = usd_number(UsdGeom.Sphere(prim).GetRadiusAttr().Get(self.time), f"{where}.radius", _positive)
            shape = trimesh.creation.icosphere(subdivisions=3, radius=radius)
            points, counts, indices = shape.vertices, np.full(len(shape.faces), 3), shape.faces.ravel()
            left_handed, normals_spec = False, ("vertex", shape.vertices / radius)
        else:
            mesh = UsdGeom.Mesh(prim)
            points = usd_array(mesh.GetPointsAttr().Get(self.time), f"{where}.points", 3, finite=False)
            counts = usd_array(mesh.GetFaceVertexCountsAttr().Get(self.time), f"{where}.faceVertexCounts",
                               integer=True)
            indices = usd_array(mesh.GetFaceVertexIndicesAttr().Get(self.time), f"{where}.faceVertexIndices",
                                integer=True)
            left_handed = mesh.GetOrientationAttr().Get(self.time) == UsdGeom.Tokens.leftHanded
            normals_spec = None
            holes = usd_array(mesh.GetHoleIndicesAttr().Get(self.time), f"{where}.holeIndices", integer=True)
            if (counts < 0).any():
                raise MeshError(f"{where}.faceVertexCounts: a negative count ({int(counts.min())})")
        if not len(counts):
            return None
        if counts.sum() != len(indices):
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
        where = f"{self.path}: {primvar.GetAttr().GetPath()}"
        with quiet_stderr():
            authored = primvar.Get(self.time)
            indices = primvar.GetIndices(self.time) if primvar.IsIndexed() else None
            if indices is not None and len(indices):
                indices = np.asarray(indices, dtype=np.int64)
                size = 0 if authored is None else len(authored)
                if indices.min() < 0 or indices.max() >= size:
                    bad = int(indices[(indices < 0) | (indices >= size)][0])
                    raise MeshError(f"{where}: index {bad} in its indices refers to a value it does not have "
                                    f"({size} values)")
            values = primvar.ComputeFlattened(self.time)
        if values is None:
            return None
        values = np.asarray(values)
        if not len(values):
            return None
        if values.dtype.kind not in "fiu":
            raise MeshError(f"{where}: expected numbers (got a value of type {primvar.GetTypeName()})")
        values = usd_array(values.astype(np.float64).reshape(len(values), -1), where, values.size // max(len(values), 1))
        if what in ("colour", "opacity") and (values < 0).any():
            raise MeshError(f"{where}: a negative {what} ({float(values.min()):g}); colours are >= 0")
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
        values = usd_array(attribute.Get(self.time), f"{self.path}: {attribute.GetPath()}", 3)
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
