"""Small outputs of a batch (metadata, dataset files, movies, contact sheets), written whole
or not at all."""

import os
import tempfile


def write_text(path, text):
    """Write ``text`` to ``path`` atomically (see :func:`replace_atomically`)."""
    def write(tmp):
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(text)

    replace_atomically(path, write)


def replace_atomically(path, write):
    """Make ``path`` with ``write(temporary_path)`` and rename it into place: a reader never
    sees a partial file.  The file gets the permissions a normal file gets
    (``0666 & ~umask``); the temporary file is ``.NAME.XXXX.tmp`` in the same folder (a
    killed batch's are removed by the next run)."""
    folder, name = os.path.split(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix=f".{name}.", suffix=".tmp", dir=folder)
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
