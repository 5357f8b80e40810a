"""What a batch job is: the views of an asset, its image tasks, the job a worker is handed.

Plain data that pickles, sent from the submitting process (:mod:`rtmesh.batch.runner`) to
a worker (:mod:`rtmesh.batch.worker`): the fixed views (``VIEWS``) and turntable frames
(:class:`View`), one image of an asset in its formats (:class:`ImageTask`) and one asset
with all its images (:class:`AssetJob`), and the suffixes of the files beside an image.
"""

import dataclasses
from dataclasses import dataclass

import numpy as np

# Directions from the subject towards the camera, and the camera's up vector.  "iso" is the
# automatic camera's direction (rtmesh.scene.camera.frame_bounds); top and bottom need another up
# vector, since +Y is parallel to their view.
VIEWS = {
    "iso": ((0.6, 0.45, 1.0), (0.0, 1.0, 0.0)),
    "front": ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0)),
    "back": ((0.0, 0.0, -1.0), (0.0, 1.0, 0.0)),
    "left": ((-1.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
    "right": ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
    "top": ((0.0, 1.0, 0.0), (0.0, 0.0, -1.0)),
    "bottom": ((0.0, -1.0, 0.0), (0.0, 0.0, 1.0)),
}
# the file next to an image that describes its camera (``--camera-json``), and the depth
# (16-bit PNG, millimetres) and mask (8-bit PNG) images of datasets (rtmesh.batch.datasets)
CAMERA_SUFFIX = ".camera.json"
DEPTH_PNG_SUFFIX, MASK_PNG_SUFFIX = ".depth.png", ".mask.png"


@dataclass(frozen=True)
class View:
    """Where one image is seen from.

    Attributes
    ----------
    name : str
        ``iso``, ``front``... or ``turn007`` for frame 7 of a turntable.
    direction : (3,) tuple of float
        From the centre of the asset's bounding sphere towards the camera.
    up : (3,) tuple of float
    light_direction : (3,) tuple of float
        Camera direction the default light rig is placed for: the view's own for fixed views
        (each is well lit), frame 0's for a turntable (lights stay put while the camera
        orbits, so the shading moves across the object as it would on a real turntable).
    orthographic : bool
        An orthographic camera whose view height fits the asset's bounding sphere (CAD
        views, ``--ortho``) instead of the perspective one.
    distance_scale : float
        The camera's distance from the centre, as a multiple of the auto-framed distance
        (radius jitter of view sets; 1 frames the bounding sphere exactly).
    """

    name: str
    direction: tuple
    up: tuple = (0.0, 1.0, 0.0)
    light_direction: tuple | None = None
    orthographic: bool = False
    distance_scale: float = 1.0

    def identity(self):
        """The view's fields for its images' fingerprint; fields added after rtmesh 0.1 are
        left out at their defaults, so the images of earlier batches keep their fingerprints."""
        fields = dataclasses.asdict(self)
        for name, default in (("orthographic", False), ("distance_scale", 1.0)):
            if fields[name] == default:
                del fields[name]
        return fields


def fixed_view(name):
    """The named fixed view (see ``VIEWS``); raises KeyError for an unknown name."""
    direction, up = VIEWS[name]
    return View(name, direction, up, direction)


def turntable_views(frames):
    """``frames`` views orbiting the vertical (+Y) axis at the ``iso`` view's elevation.

    Frame 0 is the ``iso`` view; the camera moves counter-clockwise seen from above.
    """
    (x, y, z), up = VIEWS["iso"]
    radius, start = np.hypot(x, z), np.arctan2(x, z)
    views = []
    for k in range(frames):
        angle = start + 2.0 * np.pi * k / frames
        direction = (float(radius * np.sin(angle)), y, float(radius * np.cos(angle)))
        views.append(View(f"turn{k:03d}", direction, up, (x, y, z)))
    return views


@dataclass(frozen=True)
class ImageTask:
    """One image of an asset: a view, written in one or more formats.

    Attributes
    ----------
    key : str
        Ledger key: output path relative to the output folder, without extension.
    view : View
    files : tuple of str
        Output files relative to the output folder, one per format.
    fingerprint : str
        Hash of everything the image depends on (input file, settings, view, formats).
    flow : tuple of (View or None)
        With ``--flow``: the views before and after this one in the asset's order (None at
        either end), whose flow passes the image gets (:mod:`rtmesh.batch.flow`); empty
        without.
    """

    key: str
    view: View
    files: tuple
    fingerprint: str
    flow: tuple = ()


@dataclass(frozen=True)
class AssetJob:
    """Everything a worker needs to convert one asset; plain data, so it pickles.

    Attributes
    ----------
    asset : str
        Asset name (relative path, for messages and the report).
    path : str
        Absolute mesh path.
    outdir : str
        Absolute output folder (shared with the workers).
    settings : dict
        :class:`~rtmesh.rendering.settings.RenderSettings` fields.
    images : tuple of ImageTask
        The views still to do.
    ground : bool
        Put a grey ground plane under the asset (it catches the asset's shadow); views from
        below leave it out (it would hide the asset).
    run : str
        Id of the batch run the job belongs to.
    run_file : str
        If set, the file naming the batch run that owns the output folder: the job stops,
        writing nothing more, once it names another run (a resumed batch has taken over).
    normalize : str
        ``""``, ``unit-cube`` or ``unit-sphere``: move the asset first (see
        :mod:`rtmesh.batch.normalize`).
    meta : bool
        Write ``<asset>.meta.json`` once the asset is loaded (:mod:`rtmesh.batch.asset_meta`).
    units : str
        The scene units of ``--dataset bop`` (``m``, ``cm`` or ``mm``).
    staged : bool
        Leave every file at its hidden temporary name and report that name (``staged`` and
        ``side_files`` in the results), for the submitting process to rename into place
        once it has recorded the image (:mod:`rtmesh.batch.publish`); False writes the
        files in place.

    Output files of an image ending in :data:`CAMERA_SUFFIX` get the camera JSON of the
    image (:func:`rtmesh.scene.camera_json.camera_record`), the others the image.
    """

    asset: str
    path: str
    outdir: str
    settings: dict
    images: tuple
    ground: bool = False
    run: str = ""
    run_file: str = ""
    normalize: str = ""
    meta: bool = False
    staged: bool = False
    units: str = "m"
