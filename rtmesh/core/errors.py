"""User-facing errors.

Everything a user can cause (a bad scene file, a broken mesh, an unwritable output path)
raises :class:`RtmeshError` or a subclass.  The command line prints its message on one line
and exits with status 2; anything else is a bug, reported on one line as an internal error
(exit status 70) whose traceback ``--debug`` or ``RTMESH_DEBUG=1`` shows (see
:func:`rtmesh.cli.main`).
"""


class RtmeshError(Exception):
    """An error caused by the user's input, reported as one line without a traceback."""


class SceneError(RtmeshError):
    """A scene file or scene description is invalid (unknown key, wrong type, bad value)."""


class CameraError(SceneError, ValueError):
    """A camera that cannot form an image (position at look_at, up along the view, a field of
    view outside (0, 180) degrees); a ValueError too, as it was before it was a user error."""


class MeshError(RtmeshError):
    """A mesh file cannot be read or holds nothing renderable."""


class OutputError(RtmeshError):
    """An output image cannot be written."""


class MissingExtraError(RtmeshError):
    """An optional capability was asked for whose extra is not installed (names the pip command)."""


class ResourceError(RtmeshError):
    """A render would need more memory than is available or allowed (see :mod:`rtmesh.rendering.memory`)."""
