"""Files written whole or not at all: a temporary file in the same folder, renamed into place.

A reader never sees a partial file, and a killed writer leaves only a hidden temporary
(``.NAME.XXXX.tmp``, or ``.STEM.XXXX.tmp.EXT`` where the writer needs the extension) that
``rtmesh batch`` removes on its next run.  The file gets the permissions a normal file gets
(``0666 & ~umask``, where ``mkstemp`` alone would make it 0600).
"""

import os
import tempfile


def replace_atomically(path, write, keep_extension=False):
    """Make ``path`` with ``write(temporary_path)`` and rename it into place.

    Parameters
    ----------
    path : str
    write : callable
        ``write(temporary_path)`` writes the whole file there.
    keep_extension : bool
        End the temporary name with ``path``'s extension (for writers that choose the
        format by it, such as OpenImageIO).
    """
    folder, name = os.path.split(os.path.abspath(os.fspath(path)))
    stem, ext = os.path.splitext(name) if keep_extension else (name, "")
    # the leading dot of a hidden name is not doubled: ".run" -> ".run.XXXX.tmp"
    fd, tmp = tempfile.mkstemp(prefix=f".{stem.lstrip('.')}.", suffix=f".tmp{ext}", dir=folder)
    os.close(fd)
    try:
        write(tmp)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def write_text(path, text):
    """Write ``text`` (UTF-8) to ``path`` atomically (see :func:`replace_atomically`)."""
    def write(tmp):
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(text)

    replace_atomically(path, write)
