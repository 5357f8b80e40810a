"""Per-asset metadata of a batch: what an asset is made of and what went wrong loading it.

``rtmesh batch ... --asset-meta`` writes ``<asset>.meta.json`` next to the asset's images
each time a job loads it, with

- ``asset``, ``path``: the asset's name in the batch and its mesh file;
- ``triangles``, ``vertices``: counts over all the asset's meshes as loaded, every
  placement of a mesh the file places many times counted as a copy (the flattened
  asset's counts), and ``placements`` for such meshes: per mesh its ``mesh`` name,
  ``triangles`` and how often it is ``placed`` (built once, placed by Embree instances);
- ``bounds``: ``[[xmin, ymin, zmin], [xmax, ymax, zmax]]`` in the file's units and axes,
  and ``asset_to_world`` (4x4) with ``bounds_world`` when ``--normalize`` moved it;
- ``materials``: per material its ``name`` and the ``textures`` it uses (slot -> image
  name, e.g. ``{"diffuse_texture": "wood.png"}``);
- ``textures_found``: names of the textures in use; ``files_read``: every file the
  importer read besides the mesh (material libraries, textures, buffers);
  ``files_missing``: files it tried to open and did not find (a texture that the importer
  looks up without opening it, as trimesh does for OBJ/MTL textures, shows up in the
  ``warnings`` instead: ``texture file ... not found``);
- ``warnings``: the warnings rtmesh logged while loading, one line each.
"""

import json
import logging
import os

import numpy as np

from rtmesh.batch.normalize import transform_points
from rtmesh.io.atomic_files import write_text
from rtmesh.materials.table import TEXTURE_FIELDS


class WarningLog(logging.Handler):
    """Collects the warnings of the ``rtmesh`` loggers while in a ``with`` block."""

    def __init__(self):
        super().__init__(logging.WARNING)
        self.lines = []

    def emit(self, record):
        self.lines.append(" ".join(record.getMessage().split()))

    def __enter__(self):
        logger = logging.getLogger("rtmesh")
        self._saved = logger.level, logger.propagate
        if logger.getEffectiveLevel() > logging.WARNING:
            # a process that hides warnings (a local batch worker): collect them here,
            # still without showing them
            logger.setLevel(logging.WARNING)
            logger.propagate = False
        logger.addHandler(self)
        return self

    def __exit__(self, *exc):
        logger = logging.getLogger("rtmesh")
        logger.removeHandler(self)
        logger.setLevel(self._saved[0])
        logger.propagate = self._saved[1]


def asset_meta(asset, path, parts, materials, bounds, to_world, inputs, warnings, placements=()):
    """The metadata document of one loaded asset (see the module notes).

    Parameters
    ----------
    asset, path : str
    parts : list of MeshPart
    materials : list of Material
    bounds : (2, 3) float
        The asset's bounds as rendered (after any normalisation).
    to_world : (4, 4) float
        The normalisation applied (identity without).
    inputs : list
        Entries ``[name, size, mtime_ns, checksum]`` of the files the load read
        (:class:`rtmesh.batch.identity.OpenedFiles`); size None for a missing file.
    warnings : list of str
    placements : list of Placement
        Meshes placed many times (see the module notes).

    Returns
    -------
    dict
        JSON-ready.
    """
    to_world = np.asarray(to_world, dtype=np.float64)
    moved = not np.array_equal(to_world, np.eye(4))
    file_bounds = transform_points(np.linalg.inv(to_world), bounds) if moved else np.asarray(bounds)
    used = []
    described = []
    for material in materials:
        textures = {}
        for slot in TEXTURE_FIELDS:
            texture = getattr(material, slot, None)
            if texture is not None:
                textures[slot] = getattr(texture, "name", "texture")
                used.append(textures[slot])
        described.append({"name": material.name, "textures": textures})
    meta = {
        "asset": asset, "path": path,
        "triangles": int(sum(len(p.faces) for p in parts) + sum(len(p.part.faces) * len(p.transforms)
                                                                 for p in placements)),
        "vertices": int(sum(len(p.vertices) for p in parts) + sum(len(p.part.vertices) * len(p.transforms)
                                                                  for p in placements)),
        "bounds": np.asarray(file_bounds, dtype=np.float64).tolist(),
        "materials": described,
        "textures_found": sorted(set(used)),
        "files_read": sorted(e[0] for e in inputs if e[0] and e[1] is not None),
        "files_missing": sorted(e[0] for e in inputs if e[0] and e[1] is None),
        "warnings": list(warnings),
    }
    if placements:
        meta["placements"] = [{"mesh": p.part.name, "triangles": len(p.part.faces), "placed": len(p.transforms)}
                              for p in placements]
    if moved:
        meta["asset_to_world"] = to_world.tolist()
        meta["bounds_world"] = np.asarray(bounds, dtype=np.float64).tolist()
    return meta


def write_meta(outdir, asset, meta):
    """Write ``meta`` to ``OUTDIR/<asset>.meta.json`` (atomically); returns the path."""
    path = os.path.join(outdir, asset + ".meta.json")
    os.makedirs(os.path.dirname(path), exist_ok=True)
    write_text(path, json.dumps(meta, indent=1) + "\n")
    return path
