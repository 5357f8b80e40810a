"""Batch identity and change detection: what an image depends on, and whether it changed.

An image of a batch is redone when anything it was made from changed:

- its **fingerprint**, a hash of the render settings (threads excepted: they never change
  an image), the view, the output files' names and formats, the ground option and the
  rtmesh version (:func:`image_fingerprint`);
- its **inputs**: the mesh file and every file the importer read while loading it (MTL
  libraries, textures, a glTF's external buffers), found by watching the files the load
  opens (:class:`OpenedFiles`), so this module never repeats the importers' own path
  resolution.  A file the importer looked for but did not find is recorded as missing,
  so creating it later redoes the image;
- its **outputs**: each written file must still be there with the recorded size and
  checksum (a truncated or overwritten image is redone).

Files are compared by content (a BLAKE2b checksum) by default; ``trust_mtime`` compares
size and modification time instead, which reads no file.

An entry (:func:`describe`) is ``[name, size, mtime_ns, checksum]``; ``size`` is None for a
missing file.  Input names are relative to the mesh file's folder (``""`` is the mesh file
itself), so a library reached through another path (a symlink, another mount point) keeps
its entries.
"""

import hashlib
import json
import os
import stat
import re
import sys
import threading

from rtmesh import __version__

# bumped when the meaning of a fingerprint changes: every image is redone once
FINGERPRINT_FORMAT = 2
_CHUNK = 1 << 20


def checksum(path):
    """BLAKE2b-128 of a file's content, as 32 hex digits.

    Raises
    ------
    OSError
        The file cannot be read.
    """
    h = hashlib.blake2b(digest_size=16)
    with open(path, "rb", buffering=0) as f:
        while True:
            block = f.read(_CHUNK)
            if not block:
                return h.hexdigest()
            h.update(block)


def describe(path, name):
    """The entry ``[name, size, mtime_ns, checksum]`` of a file (size None if missing, or
    not a regular file: a device or a pipe is never read, it could go on for ever)."""
    try:
        st = os.stat(path)
        if not stat.S_ISREG(st.st_mode):
            return [name, None, None, None]
        return [name, st.st_size, st.st_mtime_ns, checksum(path)]
    except (OSError, ValueError):  # (ValueError: a path holding a NUL character)
        return [name, None, None, None]


def unchanged(entry, path, trust_mtime=False):
    """True when the file at ``path`` still matches its recorded ``entry``.

    Parameters
    ----------
    entry : list
        ``[name, size, mtime_ns, checksum]`` from :func:`describe`.
    path : str
    trust_mtime : bool
        Equal size and modification time are enough (no read); otherwise equal size and
        content.
    """
    _, size, mtime_ns, digest = entry
    try:
        st = os.stat(path)
    except OSError:
        return size is None
    if size is None or st.st_size != size:
        return False
    if trust_mtime:
        return st.st_mtime_ns == mtime_ns
    try:
        return checksum(path) == digest
    except OSError:
        return False


def inputs_unchanged(entries, mesh_path, trust_mtime=False):
    """True when every recorded input of an asset (see the module docstring) is unchanged."""
    folder = os.path.dirname(mesh_path)
    return all(unchanged(e, mesh_path if not e[0] else os.path.join(folder, e[0]), trust_mtime)
               for e in entries)


def image_fingerprint(settings, view, files, ground, extra=None):
    """Hash of everything that makes an image other than its input files.

    Parameters
    ----------
    settings : dict
        RenderSettings fields (``threads`` is ignored).
    view : dict
        The view's fields.
    files : sequence of str
        Output file names (they carry the formats).
    ground : bool
    extra : dict, optional
        Options added after rtmesh 0.1 that change the image or its files (normalisation,
        camera JSON...), only those not at their defaults: an image made without them
        keeps its earlier fingerprint.
    """
    identity = {"format": FINGERPRINT_FORMAT, "rtmesh": __version__,
                "settings": {**settings, "threads": None}, "view": view, "files": list(files),
                "ground": bool(ground)}
    if extra:
        identity["extra"] = extra
    return hashlib.sha1(json.dumps(identity, sort_keys=True).encode()).hexdigest()


# ------------------------------------------------------------------------ files a load reads

_local = threading.local()
_hook_lock = threading.Lock()
_hook_installed = False
_WRITE_FLAGS = os.O_WRONLY | os.O_RDWR | os.O_CREAT | os.O_APPEND | os.O_TRUNC
# Python's own files (lazy imports during a load), compiled-kernel caches, the OS's
_IGNORED_SUFFIXES = (".py", ".pyc", ".so", ".pyd", ".pth", ".nbi", ".nbc", ".dylib", ".dll")
_IGNORED_PREFIXES = ("/proc/", "/sys/", "/dev/")
# rtmesh's own files (lazily read data), wherever it is installed
_PACKAGE = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# installed packages' metadata, which a lazy entry-point lookup reads (an editable install's
# egg-info lies outside the Python prefix)
_METADATA = re.compile(r"\.(dist|egg)-info(/|\\)")


def _audit(event, args):
    # runs for every audited event of the process: keep it cheap and never raise
    if event != "open":
        return
    paths = getattr(_local, "paths", None)
    if paths is None:
        return
    try:
        path, mode, flags = args
        if isinstance(path, int):
            return
        if mode is not None:
            if any(c in mode for c in "wax+"):
                return
        elif flags and flags & _WRITE_FLAGS:
            return
        paths.append(os.fsdecode(path))
    except Exception:  # noqa: BLE001 - an audit hook must not break the open it watches
        pass


class OpenedFiles:
    """Context manager collecting the files this thread opens for reading.

    >>> with OpenedFiles() as opened:  # doctest: +SKIP
    ...     load_trimesh("chair.obj")
    >>> opened.entries("chair.obj")  # doctest: +SKIP
    [['', 1234, 1700000000000000000, '...'], ['chair.mtl', ...], ['wood.png', ...]]

    Uses a process-wide audit hook (:func:`sys.addaudithook`, installed once and idle when
    nothing is being recorded), so it sees every ``open`` made from Python by trimesh,
    PIL and rtmesh alike.  Files that native libraries open on their own are seen where
    rtmesh announces them (:func:`rtmesh.io.images.read_image` raises the same ``open``
    event for the images OpenImageIO reads: EXR and HDR textures and environments).
    """

    def __enter__(self):
        global _hook_installed
        with _hook_lock:
            if not _hook_installed:
                sys.addaudithook(_audit)
                _hook_installed = True
        self.paths = []
        _local.paths = self.paths
        return self

    def __exit__(self, *exc):
        _local.paths = None

    def entries(self, mesh_path):
        """Entries of the mesh file (name ``""``) and of every other file read, by name
        relative to the mesh file's folder."""
        mesh_path = os.path.abspath(mesh_path)
        folder = os.path.dirname(mesh_path)
        ignored = tuple(p + os.sep for p in {sys.prefix, sys.base_prefix, sys.exec_prefix})
        ignored += _IGNORED_PREFIXES + (_PACKAGE + os.sep,)
        found = [describe(mesh_path, "")]
        seen = {mesh_path}
        for path in self.paths:
            path = os.path.abspath(path)
            if (path in seen or path.endswith(_IGNORED_SUFFIXES) or path.startswith(ignored)
                    or "__pycache__" in path or _METADATA.search(path) or os.path.isdir(path)):
                continue
            seen.add(path)
            name = os.path.relpath(path, folder)
            found.append(describe(path, name))
        return found
