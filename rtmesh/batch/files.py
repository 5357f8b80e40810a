"""Small text outputs of a batch (metadata, dataset files), written whole or not at all."""

import os
import tempfile


def write_text(path, text):
    """Write ``text`` to ``path`` atomically (a reader never sees a partial file), with the
    permissions a normal file gets (``0666 & ~umask``).  The temporary file is
    ``.NAME.XXXX.tmp`` in the same folder (a killed batch's are removed by the next run)."""
    folder, name = os.path.split(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix=f".{name}.", suffix=".tmp", dir=folder)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
