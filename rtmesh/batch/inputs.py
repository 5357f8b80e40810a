"""Batch inputs: mesh files, folders searched recursively, and manifests.

A manifest is a text file with one mesh path per line (``#`` starts a comment), or a CSV
file whose header names a ``path`` column and optionally per-asset overrides
(``width``, ``height``, ``spp``, ``views``, ``turntable``, ``formats``, ``passes``, ``seed``).
Relative paths in a manifest are resolved against the manifest's folder.

An asset's identity, its output name, is its path relative to the input root it was
found under (a folder input for the files in it, a file input's own folder, a manifest's
folder for the entries under it), with its extension kept (``chairs/oak.obj``): adding
other inputs to a batch never renames the assets already there, and a library reached
through another path (a symlink, another mount point) keeps its names.  Two assets with
the same relative path under two roots: the first keeps the name, the next gets a short
suffix (``oak.obj-1a2b3c4d``) derived from its root's folder name and relative path.
Symbolic links to folders are followed (each real folder once).
"""

import csv
import hashlib
import io
import logging
import os
import re
from dataclasses import dataclass, field

from rtmesh.core.errors import MeshError, RtmeshError
from rtmesh.batch.view_sets import MAX_VIEWS
from rtmesh.loaders.importers import MESH_EXTENSIONS
from rtmesh.loaders.mesh_files import check_file

LINE_MANIFEST_EXTENSIONS = (".txt", ".lst", ".list", ".manifest")
CSV_MANIFEST_EXTENSIONS = (".csv",)

# CSV columns and how to read them; "views" and "formats" hold names separated by
# spaces, ";" or "," (a quoted CSV field may contain commas)
_INT_COLUMNS = ("width", "height", "spp", "turntable", "seed")
_LIST_COLUMNS = ("views", "formats", "passes")
CSV_COLUMNS = ("path",) + _INT_COLUMNS + _LIST_COLUMNS
# a comment: "#" at the start of a line or after white space ("a#b.obj" is a file name)
_COMMENT = re.compile(r"(^|\s)#.*$")
# The largest manifest read: a million paths of a few hundred bytes; a larger file (or a
# device such as /dev/zero) would otherwise be read into memory without limit.
MAX_MANIFEST_BYTES = 1 << 30

log = logging.getLogger(__name__)


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
        The asset's identity and output name: its path relative to its input root,
        ``/``-separated, extension kept (``"chairs/oak.obj"``).
    overrides : dict
        Per-asset settings from a CSV manifest (``width``, ``views``...).
    source : str
        Where the overrides come from, for messages (``m.csv: line 3``; empty without).
    """

    path: str
    name: str
    overrides: dict = field(default_factory=dict, compare=False, hash=False)
    source: str = field(default="", compare=False, hash=False)


def discover(inputs, skip=()):
    """Find every asset named by the inputs.

    Parameters
    ----------
    inputs : sequence of str or os.PathLike
        Mesh files, folders (searched recursively for ``MESH_EXTENSIONS``, hidden entries
        skipped) and manifests (``.txt``/``.lst``/``.list``/``.manifest`` or ``.csv``).
    skip : sequence of str, optional
        Folders a search does not enter (the batch's output folder, when it lies inside an
        input folder: its BOP models would be found as assets on the next run).

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
    found = []  # (absolute path, root folder, name relative to the root, overrides, their source)
    for item in inputs:
        path = os.path.abspath(os.fspath(item))
        ext = os.path.splitext(path)[1].lower()
        if os.path.isdir(path):
            found.extend((p, path, name, {}, "") for p, name in _walk(path, skip))
        elif not os.path.exists(path):
            raise InputError(f"{item}: no such file or folder")
        elif ext in MESH_EXTENSIONS:
            found.append((path, os.path.dirname(path), None, {}, ""))
        elif ext in CSV_MANIFEST_EXTENSIONS:
            found.extend((p, _manifest_root(path, p), None, o, f"{path}: line {n}")
                         for p, o, n in read_csv_manifest(path))
        elif ext in LINE_MANIFEST_EXTENSIONS:
            found.extend((p, _manifest_root(path, p), None, {}, "") for p in read_line_manifest(path))
        else:
            raise InputError(
                f"{item}: not a mesh file ({', '.join(MESH_EXTENSIONS)}), a folder or a manifest "
                f"({', '.join(LINE_MANIFEST_EXTENSIONS + CSV_MANIFEST_EXTENSIONS)})")
    assets, seen, names, real_folders = [], set(), set(), {}
    for path, root, name, overrides, source in found:
        # a file reached twice (two inputs, a link) is the same real folder and file name
        folder, base = os.path.split(path)
        real = real_folders.get(folder)
        if real is None:
            real = real_folders[folder] = os.path.realpath(folder)
        if (real, base) in seen:
            continue
        seen.add((real, base))
        if name is None:
            name = os.path.relpath(path, root).replace(os.sep, "/")
        # names differing only by case would share a file on case-insensitive systems
        if name.lower() in names:
            tag = f"{os.path.basename(root)}/{name}".encode()
            name = f"{name}-{hashlib.sha1(tag).hexdigest()[:8]}"
        names.add(name.lower())
        assets.append(Asset(path, name, overrides, source))
    return assets


def _manifest_root(manifest, path):
    """The folder a manifest entry's name is relative to: the manifest's folder when the
    entry lies under it (so ``m/a.obj`` is named ``m/a.obj``), else the entry's own folder."""
    folder = os.path.dirname(manifest)
    if os.path.commonpath([folder, path]) == folder:
        return folder
    return os.path.dirname(path)


def _walk(folder, skip=()):
    """Mesh files under ``folder``, recursively, in a stable (sorted) order, the folders
    ``skip`` names left out.

    Returns
    -------
    list of (str, str)
        Each file's path and its name relative to ``folder`` (``/``-separated).
    """
    paths, visited = [], {os.path.realpath(folder)}
    skipped = {os.path.realpath(os.fspath(s)) for s in skip}
    for here, dirs, files in os.walk(folder, followlinks=True):
        prefix = os.path.relpath(here, folder).replace(os.sep, "/") + "/" if here != folder else ""
        # hidden folders hold editor and VCS files, and our own temporary files start with ".";
        # a linked folder seen before (a loop, or a second link to it) is walked once
        kept = []
        for d in sorted(d for d in dirs if not d.startswith(".")):
            real = os.path.realpath(os.path.join(here, d))
            if real in skipped:
                continue
            if real in visited:
                log.warning("%s: links to a folder already searched; skipped", os.path.join(here, d))
                continue
            visited.add(real)
            kept.append(d)
        dirs[:] = kept
        paths.extend((os.path.join(here, f), prefix + f) for f in sorted(files)
                     if not f.startswith(".") and os.path.splitext(f)[1].lower() in MESH_EXTENSIONS)
    return paths


def read_line_manifest(path):
    """Mesh paths listed one per line; blank lines and comments are skipped.

    A comment starts with ``#`` at the beginning of a line or after white space, so a file
    name may hold ``#`` (``part#2.obj``).

    Returns
    -------
    list of str
        Absolute paths (relative ones resolved against the manifest's folder).
    """
    folder = os.path.dirname(path)
    lines = _manifest_text(path).splitlines()
    entries = [(n, _COMMENT.sub("", line).strip()) for n, line in enumerate(lines, 1)]
    return [_entry_path(path, n, folder, e) for n, e in entries if e]


def _manifest_text(path):
    """A manifest's text: a regular file of at most :data:`MAX_MANIFEST_BYTES`, UTF-8."""
    try:
        check_file(path, "manifest")
        with open(path, "rb") as f:
            # at most one byte beyond the limit (a file may grow while it is read)
            data = f.read(MAX_MANIFEST_BYTES + 1)
    except MeshError as exc:
        raise InputError(str(exc)) from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read manifest: {exc.strerror}") from None
    if len(data) > MAX_MANIFEST_BYTES:
        raise InputError(f"{path}: manifest larger than rtmesh reads ({MAX_MANIFEST_BYTES >> 20} MiB)")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: cannot read manifest: not UTF-8 text (byte {exc.start})") from None


def _entry_path(manifest, line, folder, entry):
    """The absolute path a manifest's entry names (relative to the manifest's folder)."""
    if "\0" in entry:
        raise InputError(f"{manifest}: line {line}: the path holds a NUL character")
    return os.path.abspath(os.path.join(folder, os.path.expanduser(entry)))


def read_csv_manifest(path):
    """Mesh paths and per-asset overrides from a CSV manifest with a header row.

    Returns
    -------
    list of (str, dict, int)
        Absolute path, overrides (empty cells mean "batch default") and the line.
    """
    folder = os.path.dirname(path)
    try:
        rows = list(csv.reader(io.StringIO(_manifest_text(path), newline="")))
    except csv.Error as exc:
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
                least = 0 if column == "seed" else 1
                if value < least or column == "turntable" and value > MAX_VIEWS:
                    most = f" and <= {MAX_VIEWS}" if column == "turntable" else ""
                    raise InputError(f"{path}: line {line}: {column}: must be >= {least}{most}, got {value}")
                overrides[column] = value
            else:
                overrides[column] = tuple(split_names(text))
        entries.append((_entry_path(path, line, folder, cells["path"]), overrides, line))
    return entries


def split_names(text):
    """Names separated by commas, semicolons or spaces: ``"front, top;iso"``."""
    return [n for n in text.replace(";", " ").replace(",", " ").split() if n]
