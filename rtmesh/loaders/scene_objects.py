"""The ``[[objects]]`` tables of a scene file as mesh parts: primitives, mesh files, their
transforms and motion, and the meshes placed more than once (shared files and
``instances``), kept as instances where worth it."""

import collections
import os

import numpy as np
import trimesh

from rtmesh.core.errors import RtmeshError
from rtmesh.geometry.motion import Motion
from rtmesh.loaders.importers import mesh_file_parts
from rtmesh.loaders.placements import copied
from rtmesh.loaders.scene_keys import MAX_NUMBER, MOTION_KEYS
from rtmesh.rendering import memory
from rtmesh.scene import instances
from rtmesh.scene.instances import worth_instancing
from rtmesh.scene.model import MeshPart, Placement


def object_parts(r, values, where, base_dir, materials, material_index, placing, index):
    """The mesh parts one ``[[objects]]`` table makes (its meshes placed by instances join
    ``placing``)."""
    has_mesh, has_primitive = "mesh" in values, "primitive" in values
    if has_mesh == has_primitive:
        raise r.error(where, "needs exactly one of 'mesh' or 'primitive'")
    material = None
    if "material" in values:
        if values["material"] not in material_index:
            raise r.error(f"{where}.material", f"unknown material {values['material']!r} "
                          "(define it in a [materials.NAME] table)")
        material = material_index[values["material"]]
    primitive_keys = {"icosphere": ("subdivisions", "radius"), "box": ("extents",), "plane": ("size",)}
    for key in ("subdivisions", "radius", "extents", "size"):
        if key in values and (not has_primitive or key not in primitive_keys[values["primitive"]]):
            raise r.error(f"{where}.{key}", "does not apply to this object"
                          + (f" (a {values['primitive']})" if has_primitive else " (a mesh file)"))
    transform = object_transform(values)
    motion = _motion(r, values["motion"], f"{where}.motion") if "motion" in values else None
    name = values.get("name")
    smooth = values.get("smooth")
    if has_mesh:
        parts = placing.file_parts(values, where, index, material, materials, material_index)
        if motion is not None:
            # the parts of one object turn about the centre of the whole object
            points = np.concatenate([p.vertices for p in parts]) if parts else np.zeros((1, 3))
            motion.centre = 0.5 * (points.min(axis=0) + points.max(axis=0))
            for part in parts:
                part.motion = motion
        return parts

    kind = values["primitive"]
    if kind == "icosphere":
        subdivisions = values.get("subdivisions", 3)
        if not 0 <= subdivisions <= 8:
            raise r.error(f"{where}.subdivisions", "expected an integer from 0 to 8")
        radius = values.get("radius", 1.0)
        if radius >= 1e-12:
            mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
        else:
            # trimesh moves the unit sphere's vertices by (radius - |v|) onto the radius,
            # which cancels to nothing this small: scale the unit sphere instead
            mesh = trimesh.creation.icosphere(subdivisions=subdivisions)
            mesh = trimesh.Trimesh(mesh.vertices * radius, mesh.faces, process=False)
        default_smooth = True
    elif kind == "box":
        mesh = trimesh.creation.box(extents=values.get("extents", np.ones(3)))
        default_smooth = False
    else:
        sx, sy = values.get("size", np.array([1.0, 1.0])) * 0.5
        if sx <= 0 or sy <= 0:
            raise r.error(f"{where}.size", "expected two numbers > 0")
        mesh = trimesh.Trimesh(
            vertices=[[-sx, -sy, 0], [sx, -sy, 0], [sx, sy, 0], [-sx, sy, 0]],
            faces=[[0, 1, 2], [0, 2, 3]], process=False)
        default_smooth = False
    smooth = default_smooth if smooth is None else smooth
    name = name or f"{kind}{where[7:]}"
    material = 0 if material is None else material
    rows = placing.rows[index]
    if rows is not None:
        # the primitive in its own coordinates, placed by each row, then by the object's transform
        model = MeshPart(name, np.asarray(mesh.vertices), np.asarray(mesh.faces), material,
                         np.asarray(mesh.vertex_normals) if smooth else None, category=values.get("category"))
        parts = placing.placed(model, transform @ rows, name, values.get("category"), index, moving=motion is not None)
        for part in parts:
            part.motion = motion
        return parts
    vertices = trimesh.transform_points(mesh.vertices, transform)
    faces = np.asarray(mesh.faces)
    if np.linalg.det(transform[:3, :3]) < 0:
        faces = faces[:, ::-1]
    normals = None
    if smooth:
        normals = np.asarray(mesh.vertex_normals) @ np.linalg.inv(transform[:3, :3])
    return [MeshPart(name, vertices, faces, material, normals, motion,
                     category=values.get("category"), to_world=transform)]


class MeshPlacing:
    """The meshes a scene file places more than once: a file that several objects import
    (with the same ``material`` and ``smooth``, not moving) or an object's ``instances``.

    Such a file is read once, in its own coordinates; each of its meshes that is worth
    instancing (:func:`rtmesh.scene.instances.worth_instancing`, counted over every
    placement in the scene) becomes one :class:`~rtmesh.scene.model.Placement` with a
    transform per placement (each row of ``instances``, then the object's transform), the
    others are copied (one part an object, :func:`rtmesh.loaders.placements.copied`).  A
    file imported once, or several times without a mesh worth instancing, and without
    ``instances``, is read by each object as before: by the object's transform (the same
    arithmetic, the same image).

    Attributes
    ----------
    rows : list of (k, 4, 4) float64 or None
        Each object's ``instances`` (None without).
    """

    def __init__(self, r, tables, base_dir):
        self.r, self.base_dir = r, base_dir
        self.rows = [_instance_rows(r, values, f"objects[{i}]", base_dir) if "instances" in values else None
                     for i, values in enumerate(tables)]
        # placements of each shared file in the whole scene
        self.uses = collections.Counter()
        for values, rows in zip(tables, self.rows):
            key = self._key(values)
            if key is not None:
                self.uses[key] += 1 if rows is None else len(rows)
        self.files = {}  # key -> (parts, placements) read once, in the file's coordinates
        # placed meshes: (key, piece) -> [part, transforms, names, categories]
        self.placed_meshes = {}

    def _key(self, values):
        """What makes two objects' meshes the same: the file, its material and smoothing;
        None for a primitive or a moving object (copied)."""
        if "mesh" not in values or "motion" in values:
            return None
        return os.path.realpath(object_mesh_path(values, self.base_dir)), values.get("material"), values.get("smooth")

    def _read(self, values, where, material, transform=None):
        """``[parts, placements, imported materials]`` of an object's mesh file
        (``transform`` applied; None: in the file's coordinates); placements (the file's own
        meshes placed many times) unless the object moves."""
        mesh_path = object_mesh_path(values, self.base_dir)
        inner = None if "motion" in values else []
        try:
            # trimesh's formats and USD (its meshes and materials; not its lights or cameras)
            parts, imported = mesh_file_parts(mesh_path, values.get("name") or os.path.basename(mesh_path),
                                              transform, material, values.get("smooth"), inner)
        except RtmeshError as exc:
            raise self.r.error(f"{where}.mesh", str(exc)) from None
        return [parts, inner or [], imported]

    @staticmethod
    def _adopt(read, materials, material_index):
        """Append the imported materials of a ``_read`` to ``materials`` (once) and point its
        parts at them: after the scene file's own, and one whose name a [materials.NAME]
        table defines replaced by that table.  Returns ``(parts, placements)``."""
        parts, inner, imported = read
        if imported:
            remap = [material_index.get(m.name, len(materials) + i) if m.name != "default"
                     else len(materials) + i for i, m in enumerate(imported)]
            for part in parts + [p.part for p in inner]:
                part.material = remap[part.material]
            materials.extend(imported)
            read[2] = []
        return parts, inner

    def _model(self, key, values, where, material):
        """An object's mesh file in its own coordinates, read once per ``key`` (every time
        for a None key: a moving object)."""
        if key is None:
            return self._read(values, where, material)
        if key not in self.files:
            self.files[key] = self._read(values, where, material)
        return self.files[key]

    def file_parts(self, values, where, index, material, materials, material_index):
        """The parts of a mesh object (its meshes placed by instances kept for
        :meth:`placements`)."""
        key, rows = self._key(values), self.rows[index]
        name, category = values.get("name"), values.get("category")
        shared = rows is not None
        if rows is None and key is not None and self.uses[key] > 1:
            # shared when the file places a mesh many times itself or one of its meshes is
            # worth instancing; else each object reads it as before (the same arithmetic)
            parts, inner, _ = self._model(key, values, where, material)
            shared = bool(inner) or any(worth_instancing(len(part.faces), self.uses[key]) for part in parts)
        if shared:
            parts, inner = self._adopt(self._model(key, values, where, material), materials, material_index)
        else:
            parts, inner = self._adopt(self._read(values, where, material, object_transform(values)), materials,
                                       material_index)
        single = len(parts) + sum(len(placement.names) for placement in inner) == 1  # one mesh, placed once

        def label(own):
            return (name if single else f"{name}/{own}") if name else own

        if not shared:
            for part in parts:
                part.category = category
                part.name = label(part.name)
            for placement in inner:
                placement.names = [label(n) for n in placement.names]
                placement.part.category = category
                self._add(("object", index, id(placement)), placement.part, placement.transforms, placement.names,
                          None)
            return parts
        transforms = object_transform(values)[None] if rows is None else object_transform(values) @ rows
        out = []
        for piece, part in enumerate(parts):
            own = label(part.name)
            out.extend(self.placed(part, transforms, own, category, index, None if key is None else (key, piece),
                                   moving="motion" in values))
        for piece, placement in enumerate(inner):
            # placed twice: the file's placement, then the object's (one level for Embree)
            combined = (transforms[:, None] @ placement.transforms[None]).reshape(-1, 4, 4)
            names = [label(n) if rows is None else f"{label(n)}[{j}]" for j in range(len(transforms))
                     for n in placement.names]
            self._add((key, "inner", piece), placement.part, combined, names,
                      [category or label(n) for _ in range(len(transforms)) for n in placement.names])
        return out

    def placed(self, part, transforms, name, category, index, key=None, moving=False):
        """``part`` (model coordinates) placed by ``transforms`` for object ``index``:
        held for an instance :class:`Placement` when worth it (``key`` names the mesh it
        shares with other objects; None: this object's alone), else copied into one part
        (always for a ``moving`` object, which the caller sets moving).

        Returns
        -------
        list of MeshPart
            The copies (one part), or empty.
        """
        k = len(transforms)
        count = self.uses[key[0]] if key is not None else k
        names = [f"{name}[{j}]" for j in range(k)] if self.rows[index] is not None else [name] * k
        if not moving and worth_instancing(len(part.faces), count):
            self._add(key if key is not None else ("object", index), part, transforms, names, [category or name] * k)
            return []
        memory.check_load(self.r.source, f"objects[{index}]: {k} copies of {len(part.faces)} triangles",
                          memory.load_estimate(k * len(part.vertices), k * len(part.faces), k))
        copies = copied(part, transforms, f"{name} ({k} copies)" if k > 1 else name)
        copies.category = category
        if k == 1:  # the object's pose (annotations): its file's node, then its transform
            copies.to_world = transforms[0] @ (np.eye(4) if part.to_world is None else part.to_world)
        return [copies]

    def _add(self, key, part, transforms, names, categories):
        held = self.placed_meshes.setdefault(key, [part, [], [], []])
        held[1].append(np.asarray(transforms, dtype=np.float64))
        held[2].extend(names)
        held[3].extend(categories if categories is not None else [part.category or n for n in names])

    def placements(self):
        """Every mesh placed by instances, one :class:`Placement` each."""
        return [Placement(part, np.concatenate(transforms), names, categories)
                for part, transforms, names, categories in self.placed_meshes.values()]


def _instance_rows(r, values, where, base_dir):
    """An object's ``instances``: the (k, 4, 4) float64 transforms of its ``.npy`` file.

    Raises
    ------
    SceneError
        ``scene.toml: objects[1].instances: trees.npy: ...``: the file is missing or not a
        ``.npy`` array of numbers of shape (k, 4, 4), or a transform is not finite, not
        affine, singular or beyond the scene file's range of numbers.
    """
    path = values["instances"]
    path = path if os.path.isabs(path) else os.path.join(base_dir, path)
    key = f"{where}.instances"
    try:
        with open(path, "rb") as f:
            try:
                version = np.lib.format.read_magic(f)
                read_header = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                               else np.lib.format.read_array_header_2_0)
                shape, _, dtype = read_header(f)
            except ValueError:
                raise r.error(key, f"{path}: not a NumPy .npy file") from None
            if dtype.kind not in "fiu" or dtype.fields is not None:
                raise r.error(key, f"{path}: holds {dtype} values, not numbers")
            if len(shape) != 3 or shape[1:] != (4, 4) or shape[0] < 1:
                raise r.error(key, f"{path}: an array of shape {shape}, expected (k, 4, 4) with k >= 1 "
                                   "(a model-to-world transform a row)")
            # a placement's records are counted before the file is read (its mesh with it later)
            memory.check_load(f"{r.source}: {key}: {path}", f"{shape[0]} instance transforms",
                              memory.load_estimate(0, 0, shape[0]))
            f.seek(0)
            try:
                rows = np.lib.format.read_array(f, allow_pickle=False).astype(np.float64)
            except ValueError as exc:
                raise r.error(key, f"{path}: truncated or corrupt ({exc})") from None
    except OSError as exc:
        raise r.error(key, f"cannot read {path}: {exc.strerror or exc}") from None
    problem = instances.check_transforms(rows, range(len(rows)), path)
    if problem is None and (np.abs(rows) > MAX_NUMBER).any():
        row = int(np.flatnonzero((np.abs(rows) > MAX_NUMBER).any(axis=(1, 2)))[0])
        problem = f"{path}: instance {row} has a number beyond {MAX_NUMBER:g} in magnitude"
    if problem is not None:
        raise r.error(key, problem)
    return rows


def object_mesh_path(values, base_dir):
    """An object's mesh file, resolved against the scene file's folder."""
    path = values["mesh"]
    return path if os.path.isabs(path) else os.path.join(base_dir, path)


def object_transform(values):
    """4x4 matrix: scale, then rotate (X, then Y, then Z, degrees), then translate."""
    matrix = np.diag(np.append(values.get("scale", np.ones(3)), 1.0))
    rx, ry, rz = np.radians(values.get("rotate", np.zeros(3)))
    rotation = (trimesh.transformations.rotation_matrix(rz, [0, 0, 1])
                @ trimesh.transformations.rotation_matrix(ry, [0, 1, 0])
                @ trimesh.transformations.rotation_matrix(rx, [1, 0, 0]))
    matrix = rotation @ matrix
    matrix[:3, 3] = values.get("translate", np.zeros(3))
    return matrix


def _motion(r, table, where):
    """A :class:`Motion` from an object's ``motion`` table."""
    values = r.fields(r.table(table, where), MOTION_KEYS, where)
    degrees = values.get("rotate_degrees", 0.0)
    if degrees != 0.0 and "rotate_axis" not in values:
        raise r.error(f"{where}.rotate_axis", "missing (needed by rotate_degrees)")
    try:
        return Motion(values.get("translate", np.zeros(3)),
                      values.get("rotate_axis", np.array([0.0, 1.0, 0.0])), degrees)
    except ValueError as exc:
        raise r.error(where, str(exc)) from None
