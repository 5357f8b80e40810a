"""Batch inputs: mesh files, folders searched recursively, and manifests.

A manifest is a text file with one mesh path per line (``#`` starts a comment), or a CSV
file whose header names a ``path`` column and optionally per-asset overrides
(``width``, ``height``, ``spp``, ``views``, ``turntable``, ``formats``, ``passes``, ``seed``).
Relative paths in a manifest are resolved against the manifest's folder.

Every asset gets an output name that mirrors the input tree: its path relative to the
deepest folder that holds every input (a folder input, a file's folder, a manifest's folder
for the entries under it), with its extension kept (``chairs/oak.obj``), so two
files that differ only by extension or by folder never share an output.
"""

import csv
import os
from dataclasses import dataclass, field

from rtmesh.core.errors import RtmeshError
from rtmesh.loaders.importers import MESH_EXTENSIONS

LINE_MANIFEST_EXTENSIONS = (".txt", ".lst", ".list", ".manifest")
CSV_MANIFEST_EXTENSIONS = (".csv",)

# CSV columns and how to read them; "views" and "formats" hold names separated by
# spaces, ";" or "," (a quoted CSV field may contain commas)
_INT_COLUMNS = ("width", "height", "spp", "turntable", "seed")
_LIST_COLUMNS = ("views", "formats", "passes")
CSV_COLUMNS = ("path",) + _INT_COLUMNS + _LIST_COLUMNS


class InputError(RtmeshError):
    """A batch input (file, folder or manifest) is missing or malformed."""


@dataclass(frozen=True)
class Asset:
    """One mesh file to convert.

    Attributes
    ----------
    path : str
        Absolute path of the mesh file (it may not exist: manifests can name missing files,
        which fail on their own without stopping the batch).
    name : str
        Output name relative to the output folder, ``/``-separated, extension kept
        (``"chairs/oak.obj"``).
    overrides : dict
        Per-asset settings from a CSV manifest (``width``, ``views``...).
    """

    path: str
    name: str
    overrides: dict = field(default_factory=dict, compare=False, hash=False)


def discover(inputs):
    """Find every asset named by the inputs.

    Parameters
    ----------
    inputs : sequence of str or os.PathLike
        Mesh files, folders (searched recursively for ``MESH_EXTENSIONS``, hidden entries
        skipped) and manifests (``.txt``/``.lst``/``.list``/``.manifest`` or ``.csv``).

    Returns
    -------
    list of Asset
        In input order, each folder's files sorted; a file named twice is kept once (its
        first mention wins).

    Raises
    ------
    InputError
        A command-line input that does not exist, has an unknown extension, or a manifest
        that cannot be read or has a bad value.  Nothing has run yet when this is raised.
    """
    found = []  # (absolute path, root folder the output name is relative to, overrides)
    for item in inputs:
        path = os.path.abspath(os.fspath(item))
        ext = os.path.splitext(path)[1].lower()
        if os.path.isdir(path):
            found.extend((p, path, {}) for p in _walk(path))
        elif not os.path.exists(path):
            raise InputError(f"{item}: no such file or folder")
        elif ext in MESH_EXTENSIONS:
            found.append((path, os.path.dirname(path), {}))
        elif ext in CSV_MANIFEST_EXTENSIONS:
            found.extend((p, _manifest_root(path, p), o) for p, o in read_csv_manifest(path))
        elif ext in LINE_MANIFEST_EXTENSIONS:
            found.extend((p, _manifest_root(path, p), {}) for p in read_line_manifest(path))
        else:
            raise InputError(
                f"{item}: not a mesh file ({', '.join(MESH_EXTENSIONS)}), a folder or a manifest "
                f"({', '.join(LINE_MANIFEST_EXTENSIONS + CSV_MANIFEST_EXTENSIONS)})")
    unique, seen = [], set()
    for path, root, overrides in found:
        if path not in seen:
            seen.add(path)
            unique.append((path, root, overrides))
    if not unique:
        return []
    # Names relative to the deepest folder above every root: distinct paths give distinct
    # names, and for one folder input the base is the folder itself, so files added to it
    # later never rename the ones already converted.
    base = os.path.commonpath([root for _, root, _ in unique])
    return [Asset(path, os.path.relpath(path, base).replace(os.sep, "/"), overrides)
            for path, _, overrides in unique]


def _manifest_root(manifest, path):
    """The folder a manifest entry's name is relative to: the manifest's folder when the
    entry lies under it (so ``m/a.obj`` is named ``m/a.obj``), else the entry's own folder."""
    folder = os.path.dirname(manifest)
    if os.path.commonpath([folder, path]) == folder:
        return folder
    return os.path.dirname(path)


def _walk(folder):
    """Mesh files under ``folder``, recursively, in a stable (sorted) order."""
    paths = []
    for here, dirs, files in os.walk(folder):
        # hidden folders hold editor and VCS files, and our own temporary files start with "."
        dirs[:] = sorted(d for d in dirs if not d.startswith("."))
        paths.extend(os.path.join(here, f) for f in sorted(files)
                     if not f.startswith(".") and os.path.splitext(f)[1].lower() in MESH_EXTENSIONS)
    return paths


def read_line_manifest(path):
    """Mesh paths listed one per line; blank lines and ``#`` comments are skipped.

    Returns
    -------
    list of str
        Absolute paths (relative ones resolved against the manifest's folder).
    """
    folder = os.path.dirname(path)
    try:
        with open(path, encoding="utf-8") as f:
            lines = f.read().splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read manifest: {exc}") from None
    entries = (line.split("#", 1)[0].strip() for line in lines)
    return [os.path.abspath(os.path.join(folder, os.path.expanduser(e))) for e in entries if e]


def read_csv_manifest(path):
    """Mesh paths and per-asset overrides from a CSV manifest with a header row.

    Returns
    -------
    list of (str, dict)
        Absolute path and overrides (empty cells mean "batch default").
    """
    folder = os.path.dirname(path)
    try:
        with open(path, encoding="utf-8", newline="") as f:
            rows = list(csv.reader(f))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise InputError(f"{path}: cannot read manifest: {exc}") from None
    rows = [(n, r) for n, r in enumerate(rows, 1) if any(c.strip() for c in r)]
    if not rows:
        return []
    header = [c.strip().lower() for c in rows[0][1]]
    unknown = [c for c in header if c not in CSV_COLUMNS]
    if unknown:
        raise InputError(f"{path}: line 1: unknown column {unknown[0]!r} "
                         f"(expected {', '.join(CSV_COLUMNS)})")
    if "path" not in header:
        raise InputError(f"{path}: line 1: the header needs a 'path' column")
    entries = []
    for line, row in rows[1:]:
        if len(row) > len(header):
            raise InputError(f"{path}: line {line}: {len(row)} cells for {len(header)} columns")
        cells = dict(zip(header, (c.strip() for c in row)))
        if not cells.get("path"):
            raise InputError(f"{path}: line {line}: empty path")
        overrides = {}
        for column, text in cells.items():
            if column == "path" or not text:
                continue
            if column in _INT_COLUMNS:
                try:
                    value = int(text)
                except ValueError:
                    raise InputError(f"{path}: line {line}: {column}: expected an integer, "
                                     f"got {text!r}") from None
                if value < (0 if column == "seed" else 1):
                    raise InputError(f"{path}: line {line}: {column}: must be >= 1, got {value}")
                overrides[column] = value
            else:
                overrides[column] = tuple(split_names(text))
        entries.append((os.path.abspath(os.path.join(folder, os.path.expanduser(cells["path"]))),
                        overrides))
    return entries


def split_names(text):
    """Names separated by commas, semicolons or spaces: ``"front, top;iso"``."""
    return [n for n in text.replace(";", " ").replace(",", " ").split() if n]
