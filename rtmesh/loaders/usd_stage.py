"""Opening USD stages through Pixar's ``usd-core`` (the ``rtmesh[usd]`` extra): the file
extensions, the ``pxr`` modules (or the missing extra named), unreadable files and
composition errors (a cycle of references, a missing reference) refused in one line naming
the file, and the layer files a stage composed announced as read, for the batch's change
detection.  What a stage holds is read by :mod:`rtmesh.loaders.usd_files`."""

import contextlib
import os
import re
import sys

import numpy as np

from rtmesh.core.errors import MeshError, MissingExtraError
from rtmesh.loaders.mesh_files import check_file

USD_EXTENSIONS = (".usd", ".usda", ".usdc", ".usdz")
EXTRA = "rtmesh[usd]"


def pxr_modules():
    """The modules of usd-core, or MissingExtraError naming the extra."""
    try:
        from pxr import Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade
    except ImportError:
        raise MissingExtraError(f"USD files need usd-core: pip install '{EXTRA}'") from None
    return Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade


@contextlib.contextmanager
def quiet_stderr():
    """USD prints its diagnostics on the process's standard error (file descriptor 2); the
    loader reports them itself, in one line, so they are sent to nothing meanwhile."""
    try:
        saved = os.dup(2)
    except OSError:
        yield
        return
    try:
        with open(os.devnull, "wb") as sink:
            os.dup2(sink.fileno(), 2)
            yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def usd_number(value, where, reader=None):
    """A number of a USD attribute held to the scene file's range (finite; 0 or of a
    magnitude from 1e-18 to 1e18, :mod:`rtmesh.loaders.scene_keys`), read by one of its
    readers (``_float`` by default, ``_positive``, ``_non_negative``).

    Raises
    ------
    MeshError
        ``m.usda: /World/Cam.focalLength: expected a number > 0 (got 0.0)``: ``where`` names
        the file, the prim and the attribute.
    """
    from rtmesh.loaders.scene_keys import _float

    reader = reader or _float
    if isinstance(value, (bool, str)) or not isinstance(value, (int, float, np.number)):
        raise MeshError(f"{where}: expected a number (got {value!r})")
    try:
        return reader(float(value))
    except TypeError as exc:
        raise MeshError(f"{where}: {exc} (got {float(value)!r})") from None


def usd_array(value, where, width=None, integer=False, limit=None, finite=True):
    """A USD array attribute's value as a NumPy array, its type and values checked: numbers
    (integers where ``integer``), ``width`` of them an element (None: scalars), finite (unless
    not ``finite``: a mesh's points, whose faces on non-finite points are dropped later with a
    warning, as every mesh format's) and at most ``limit`` (the scene file's 1e18 by default)
    in magnitude.  None is an empty array.

    Raises
    ------
    MeshError
        One line naming ``where`` (``m.usda: /World/Cube.points``) and what is wrong.
    """
    from rtmesh.loaders.scene_keys import MAX_NUMBER

    limit = MAX_NUMBER if limit is None else limit
    shape = "integers" if integer else (f"{width}-vectors of numbers" if width else "numbers")
    if value is None:
        return np.zeros((0,) if width is None else (0, width), np.int64 if integer else np.float64)
    try:
        array = np.asarray(value)
    except Exception:  # a value NumPy cannot hold as an array
        raise MeshError(f"{where}: expected an array of {shape} (got {type(value).__name__})") from None
    kinds = "iu" if integer else "fiu"
    expected_ndim = 1 if width is None else 2
    if array.dtype.kind not in kinds or array.ndim != expected_ndim or (width and array.shape[1] != width):
        got = (f"{array.shape[1]} numbers an element" if array.ndim == 2 and array.dtype.kind in "fiu"
               else f"a value of type {type(value).__name__}")
        raise MeshError(f"{where}: expected an array of {shape} (got {got})")
    if integer:
        return array.astype(np.int64)
    array = array.astype(np.float64)
    if not finite:
        return array
    bad = ~np.isfinite(array)
    if bad.any():
        raise MeshError(f"{where}: {int(bad.sum())} values that are NaN or infinite (of {array.size})")
    if array.size and np.abs(array).max() > limit:
        raise MeshError(f"{where}: values up to {float(np.abs(array).max()):g} in magnitude, more than "
                        f"rtmesh takes ({limit:g})")
    return array


def open_stage(path):
    """Open a USD file, refusing unreadable files and composition errors in one line.

    The layer files it composed are announced as read (:func:`_announce_layers`), so a
    batch records them among the asset's inputs.

    Parameters
    ----------
    path : str

    Returns
    -------
    pxr.Usd.Stage

    Raises
    ------
    MeshError
        The file cannot be read, or its composition has an error (a cycle of references,
        a reference to a missing file).
    MissingExtraError
        usd-core is not installed.
    """
    _, _, Tf, Usd, _, _, _ = pxr_modules()
    check_file(path)
    with quiet_stderr():
        try:
            stage = Usd.Stage.Open(path)
        except Tf.ErrorException as exc:
            raise MeshError(f"{path}: cannot read USD: {tf_message(exc)}") from None
        if stage is None:
            raise MeshError(f"{path}: cannot read USD")
        errors = stage.GetCompositionErrors()
    _announce_layers(stage)
    if errors:
        more = f" (and {len(errors) - 1} more composition errors)" if len(errors) > 1 else ""
        raise MeshError(f"{path}: {_composition_message(errors[0])}{more}")
    return stage


def _announce_layers(stage):
    """Announce each layer file the stage composed (the root layer, its sublayers, references
    and payloads, at any depth) as Python's own ``open`` does: USD reads them natively, where
    Python's audit hooks cannot see them, and whoever records the files a load reads (the
    batch's change detection, :class:`rtmesh.batch.identity.OpenedFiles`) must see these too.
    Textures are read through Python
    (:meth:`rtmesh.loaders.usd_materials.UsdMaterialReader._image`) or OpenImageIO, which
    announces its reads itself."""
    for layer in stage.GetUsedLayers():
        if layer.anonymous or not layer.realPath:
            continue
        # a layer inside a USDZ package (``a.usdz[inner.usdc]``) is read from the package
        real = layer.realPath
        sys.audit("open", real.split("[", 1)[0] if real.endswith("]") else real, "rb", 0)


def tf_message(exc):
    """The commentary of a USD error (``... : 'Failed to open layer @x.usda@'``), one line."""
    text = " ".join(str(exc).split())
    found = re.search(r" : '(.*)'$", text) or re.search(r" : '(.*?)'", text)
    return found.group(1) if found else (text or type(exc).__name__)


def _composition_message(error):
    """One line for a composition error; a cycle lists the layers and prims that form it."""
    text = str(error)
    if type(error).__name__ == "ErrorArcCycle":
        sites = [f"{os.path.basename(layer)}{prim}"
                 for layer, prim in re.findall(r"@([^@,]+)@(?:,@[^@]*@)?(<[^>]*>)", text)]
        cycle = []
        for site in sites:
            cycle.append(site)
            if cycle.count(site) > 1:
                break
        return f"a cycle of references: {' -> '.join(cycle)} (USD cannot compose it)"
    return "composition error: " + " ".join(text.split())
