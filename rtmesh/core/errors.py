"""User-facing errors.

Everything a user can cause (a bad scene file, a broken mesh, an unwritable output path)
raises :class:`RtmeshError` or a subclass.  The command line prints its message on one line
and exits with status 2; anything else is a bug and keeps its traceback.
"""


class RtmeshError(Exception):
    """An error caused by the user's input, reported as one line without a traceback."""


class SceneError(RtmeshError):
    """A scene file or scene description is invalid (unknown key, wrong type, bad value)."""


class MeshError(RtmeshError):
    """A mesh file cannot be read or holds nothing renderable."""


class OutputError(RtmeshError):
    """An output image cannot be written."""


class MissingExtraError(RtmeshError):
    """An optional capability was asked for whose extra is not installed (names the pip command)."""
