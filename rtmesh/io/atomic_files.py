"""Files written whole or not at all: a temporary file in the same folder, renamed into place.

A reader never sees a partial file, and a killed writer leaves only a hidden temporary
(``.NAME.XXXX.tmp``, or ``.STEM.XXXX.tmp.EXT`` where the writer needs the extension) that
``rtmesh batch`` removes on its next run.  The file gets the permissions a normal file gets
(``0666 & ~umask``, where ``mkstemp`` alone would make it 0600).

Inside :func:`staged`, the rename is left to the caller: a batch worker writes an image's
files this way and the batch's submitting process renames them once it has recorded them
(:mod:`rtmesh.batch.publish`), so that one process alone puts images in place.
"""

import contextlib
import contextvars
import os
import re
import tempfile

# the pairs of the innermost ``staged()`` block of this thread (None outside one); a
# context variable, so that worker threads (Dask runs tasks on threads) never share one
_STAGED = contextvars.ContextVar("rtmesh_staged_files", default=None)

# ".STEM.XXXXXXXX.tmp.EXT" and ".NAME.XXXXXXXX.tmp": the names mkstemp gives below (its
# random part is 8 of [a-z0-9_])
_TEMPORARY = re.compile(r"^\.(?P<stem>.+)\.[a-z0-9_]{8}\.tmp(?P<ext>\.[^.]+)?$")


def replace_atomically(path, write, keep_extension=False):
    """Make ``path`` with ``write(temporary_path)`` and rename it into place.

    Inside a :func:`staged` block the file stays at its temporary name, and the pair
    ``(temporary_path, path)`` is added to the block's list instead.

    Parameters
    ----------
    path : str
    write : callable
        ``write(temporary_path)`` writes the whole file there.
    keep_extension : bool
        End the temporary name with ``path``'s extension (for writers that choose the
        format by it, such as OpenImageIO).
    """
    path = os.path.abspath(os.fspath(path))
    folder, name = os.path.split(path)
    stem, ext = os.path.splitext(name) if keep_extension else (name, "")
    # the leading dot of a hidden name is not doubled: ".run" -> ".run.XXXX.tmp"
    fd, tmp = tempfile.mkstemp(prefix=f".{stem.lstrip('.')}.", suffix=f".tmp{ext}", dir=folder)
    os.close(fd)
    try:
        write(tmp)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        pending = _STAGED.get()
        if pending is None:
            os.replace(tmp, path)
        else:
            pending.append((tmp, path))
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


@contextlib.contextmanager
def staged():
    """Leave the files written in this block (in this thread) at their temporary names.

    Yields
    ------
    list of (str, str)
        ``(temporary_path, path)`` of each file :func:`replace_atomically` wrote in the
        block, in order; renaming the temporary to the path completes the write.  If the
        block raises, its temporaries are removed.
    """
    pending = []
    token = _STAGED.set(pending)
    try:
        yield pending
    except BaseException:
        for tmp, _ in pending:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
        raise
    finally:
        _STAGED.reset(token)


def target_of(name):
    """The file name a temporary name of :func:`replace_atomically` stands for, or None.

    >>> target_of(".a.obj.k2j4_x9q.tmp.png"), target_of(".a.json.k2j4_x9q.tmp"), target_of("a.png")
    ('a.obj.png', 'a.json', None)

    A hidden target (``.run``) comes back without its dot; it is never a batch image.
    """
    match = _TEMPORARY.match(name)
    return match and match["stem"] + (match["ext"] or "")


def write_text(path, text):
    """Write ``text`` (UTF-8) to ``path`` atomically (see :func:`replace_atomically`)."""
    def write(tmp):
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(text)

    replace_atomically(path, write)
