"""What a mesh file must be before trimesh reads it: a readable regular file whose first
bytes can start a file of its format.

trimesh reports a directory, a symbolic link loop, binary garbage or a lying STL header with
whatever exception its parser meets first (``No module named 'charset_normalizer'`` for bytes
that are not UTF-8, an empty scene for garbage in an STL); these checks name the problem in
one line instead (docs/LIMITS.md).  They read at most the first 4096 bytes of a file.
"""

import errno
import os

from rtmesh.core.errors import MeshError


def check_file(path, what="mesh file"):
    """Raise MeshError unless ``path`` is a readable regular file, saying what it is instead.

    Parameters
    ----------
    path : str
    what : str
        What the file should be, in messages (``mesh file``, ``scene file``, ``manifest``).

    Raises
    ------
    MeshError
        Missing, a directory, a symbolic link loop or a broken link, not a regular file, or
        not readable.
    """
    if os.path.isfile(path):
        if not os.access(path, os.R_OK):
            raise MeshError(f"{path}: cannot read the {what} (permission denied)")
        return
    if os.path.isdir(path):
        raise MeshError(f"{path}: is a directory, not a {what}")
    if os.path.islink(path):
        try:
            os.stat(path)
        except OSError as exc:
            if exc.errno == errno.ELOOP:
                raise MeshError(f"{path}: symbolic link loop, not a {what}") from None
            raise MeshError(f"{path}: broken symbolic link (to {os.readlink(path)}), no such {what}") from None
    if os.path.exists(path):
        raise MeshError(f"{path}: not a regular file")
    raise MeshError(f"{path}: no such {what}")


def format_name(ext):
    """``.obj`` -> ``OBJ``, ``.glb`` -> ``GLB``: a format's name in messages."""
    return {".gltf": "glTF", ".glb": "GLB"}.get(ext, ext[1:].upper())


# text formats: binary data in their first bytes means the file is something else
_TEXT_FORMATS = (".obj", ".off", ".gltf")
_SNIFF_BYTES = 4096


def check_content(path, ext):
    """Raise MeshError for a file whose first bytes cannot start a file of its format (binary
    data in a text format, a GLB without its magic, a PLY without its header, an STL that is
    neither ASCII nor a binary STL of the file's size), instead of whatever trimesh makes of
    it.

    Parameters
    ----------
    path : str
        An existing regular file (:func:`check_file`).
    ext : str
        Its lower-case extension, one of :data:`rtmesh.loaders.importers.MESH_EXTENSIONS`.

    Raises
    ------
    MeshError
        ``not a valid FORMAT file (why)``.
    """
    size = os.path.getsize(path)
    with open(path, "rb") as f:
        head = f.read(_SNIFF_BYTES)
    name = format_name(ext)
    problem = None
    if ext in _TEXT_FORMATS:
        control = sum(head.count(bytes([c])) for c in range(32) if c not in (9, 10, 11, 12, 13))
        if control > 0.01 * len(head):
            problem = "binary data, not text"
    elif ext == ".glb" and head[:4] != b"glTF":
        problem = "no glTF header"
    elif ext == ".ply" and not head.startswith(b"ply"):
        problem = "no 'ply' header"
    elif ext == ".stl":
        ascii_stl = head.lstrip()[:5].lower() == b"solid" and b"\0" not in head
        if not ascii_stl:
            count = int.from_bytes(head[80:84], "little") if len(head) >= 84 else None
            if count is None:
                problem = f"{size} bytes: too short for a binary STL and not ASCII"
            elif size < 84 + 50 * count:
                problem = (f"not ASCII, and its binary header announces {count} triangles "
                           f"({84 + 50 * count} bytes) in a file of {size} bytes")
    if problem:
        raise MeshError(f"{path}: not a valid {name} file ({problem})")
