"""Output passes (arbitrary output variables): the registry, the per-sample producers, and
the 8-bit display mapping of each pass.

A pass is described once, in :data:`REGISTRY`: its EXR channel names, how the film reduces
a pixel's samples to one value, the value a camera ray that sees no surface contributes, and
the producer that computes it from the hits of the camera rays.  The integrator only calls
:meth:`PassRecorder.record` with those hits; everything else about passes lives here, so a
new pass is a producer function and a registry entry (and a case in
:func:`display_values` if its PNG needs more than the generic mapping).

EXR naming (one OpenEXR layer per pass, ``layer.channel``)::

    pass         channels                       reduction  value
    ao           ao.Y                           mean       misses count as unoccluded (1)
    depth        depth.Z                        min        z-depth; 0 where no sample hits
    normal       normal.X normal.Y normal.Z     mean       world shading normal, camera side
    albedo       albedo.R albedo.G albedo.B     mean       diffuse reflectance (tinted; base colour of
                                                           metallic-roughness materials)
    position     position.X position.Y position.Z  mean    world-space hit point
    uv           uv.U uv.V                      mean       texture coordinates
    alpha        A                              mean       camera-ray coverage (image alpha)
    variance     variance.R variance.G variance.B  film   estimated variance of the pixel mean
    spp          spp.Y                          film       samples taken in the pixel
    object_id    object_id.id                   centre     Scene.object_names index; -1 none
    material_id  material_id.id                 centre     material index; -1 none
    instance_id  instance_id.id                 centre     placement index (= object_id today); -1
    depth_center depth_center.Z                 centre     z-depth; +inf where the ray misses
    position_center  position_center.X .Y .Z    centre     world-space hit point; NaN misses
    normal_center    normal_center.X .Y .Z      centre     shading normal facing the camera; NaN misses
    motion       motion.X motion.Y              centre     pixels moved, shutter open to close; 0 misses

``variance`` and ``spp`` are derived passes (:data:`DERIVED_PASSES`): the film computes them
from its per-pixel sums and sample counts after the render, nothing is recorded per sample.
The ``centre`` passes (:data:`CENTRE_PASSES`) are exact labels: one extra unjittered ray
through each pixel centre (the ray the exported ``K`` describes, through the centre of a
thin lens, at the time the shutter opens), traced after the render by
:mod:`rtmesh.rendering.centre_rays`; no sample of the image is read or changed.

``mean`` averages every sample of the pixel, misses included with their miss value, so
``normal``, ``albedo``, ``position`` and ``uv`` are premultiplied by coverage (divide by
``A`` to un-premultiply).  ``first`` keeps the pixel's sample 0 (no registry pass uses it
since the ids became centre passes: an average of two integer ids is no id, and sample 0
is a jittered position).  ``min`` keeps the nearest surface any sample saw: an average of a near and a
far depth at a silhouette is a distance where nothing is, and the nearest is what depth
compositing needs.
"""

import colorsys
import logging
from dataclasses import dataclass

import numpy as np

from rtmesh.core.rays import take_rows

log = logging.getLogger(__name__)

REDUCTIONS = ("mean", "first", "min")


class CameraHits:
    """What a producer may read about the camera rays that hit: one row per hit.

    Attributes
    ----------
    p : (k, 3) float64
        Hit points in the integrator's re-centred frame.
    ns : (k, 3) float64
        Unit shading normals facing the camera.
    albedo : (k, 3) float64
        Each material's pass albedo (:attr:`PassRecorder.diffuse`) times its texture and
        vertex-colour tint.
    uv : (k, 2) float64 or float
        Texture coordinates (0.0 where the scene has none).
    recorder : PassRecorder
        Scene-wide tables (camera frame, shift).
    """

    __slots__ = ("p", "ns", "albedo", "uv", "recorder")

    def __init__(self, p, ns, albedo, uv, recorder):
        self.p, self.ns, self.albedo, self.uv, self.recorder = p, ns, albedo, uv, recorder

    @classmethod
    def of_records(cls, srf, hits, rows, recorder):
        """The hits from the general path's surface records (``srf``; ``hits`` the camera
        rays' Embree hits, ``rows`` those that hit in the order of ``srf``, None for all)."""
        albedo = take_rows(recorder.diffuse, srf.mat)
        tints = getattr(srf, "tints", None)  # texture and vertex-colour multipliers
        if tints is not None and getattr(tints, "diffuse", None) is not None:
            albedo = albedo * tints.diffuse
        uv = 0.0
        if recorder.uv is not None and "uv" in recorder.names:
            corners = recorder.faces[take_rows(hits.prim, rows).astype(np.intp)]
            u, v = take_rows(hits.u, rows), take_rows(hits.v, rows)
            uv0, uv1, uv2 = (recorder.uv[corners[:, i]] for i in range(3))
            uv = uv0 + u[:, None] * (uv1 - uv0) + v[:, None] * (uv2 - uv0)
        return cls(srf.p, srf.ns, albedo, uv, recorder)


# ---------------------------------------------------------------- producers
# Each returns the pass values of the hits, (k, width) or (k,) for one channel, or a
# scalar for all of them.

def _depth(h):
    # distance from the lens plane along the view axis: the same for a pinhole and a thin
    # lens, whose ray origins all lie in that plane
    rec = h.recorder
    return (h.p - rec.eye) @ rec.forward


def _normal(h):
    return h.ns


def _albedo(h):
    return h.albedo


def _position(h):
    return h.p + h.recorder.shift


def _uv(h):
    return h.uv


def _covered(h):
    return 1.0


@dataclass(frozen=True)
class PassSpec:
    """One pass of the registry.

    Attributes
    ----------
    name : str
    channels : tuple of str
        EXR channel names, written as ``name.channel`` (a channel ``A`` is the image's own
        alpha channel and is written without the layer prefix).
    reduction : {"mean", "first", "min"}
        How the film combines a pixel's samples (see the module docstring).
    miss : float
        What a camera ray that hits nothing contributes.
    producer : callable or None
        ``producer(CameraHits) -> values`` for the camera rays that hit; None for a pass
        another stage writes (``ao``: the integrator's AO stage).
    doc : str
        One line for the documentation.
    """

    name: str
    channels: tuple
    reduction: str
    miss: float
    producer: object
    doc: str

    @property
    def width(self):
        return len(self.channels)

    def exr_names(self):
        """EXR channel names of this pass, in order."""
        return [c if c == "A" else f"{self.name}.{c}" for c in self.channels]


# the path integrator's light-path passes, written by its kernel (producer None)
_LIGHT_PATHS = (
    ("emission", "path: light seen straight from the camera (emitters, lights, the background)"),
    ("direct_diffuse", "path: light from a light after one diffuse reflection"),
    ("direct_glossy", "path: light from a light after one glossy or mirror reflection"),
    ("direct_transmission", "path: light from a light after one transmission"),
    ("indirect_diffuse", "path: light after more bounces, the first diffuse"),
    ("indirect_glossy", "path: light after more bounces, the first glossy or mirror"),
    ("indirect_transmission", "path: light after more bounces, the first a transmission"),
)

REGISTRY = {
    spec.name: spec for spec in (
        PassSpec("ao", ("Y",), "mean", 1.0, None,
                 "ambient occlusion: unoccluded fraction of the hemisphere"),
        PassSpec("depth", ("Z",), "min", np.inf, _depth,
                 "z-depth: distance along the view axis to the nearest hit"),
        PassSpec("normal", ("X", "Y", "Z"), "mean", 0.0, _normal,
                 "world-space unit shading normal facing the camera"),
        PassSpec("albedo", ("R", "G", "B"), "mean", 0.0, _albedo,
                 "diffuse reflectance (texture-tinted)"),
        PassSpec("position", ("X", "Y", "Z"), "mean", 0.0, _position, "world-space hit point"),
        PassSpec("uv", ("U", "V"), "mean", 0.0, _uv, "texture coordinates (0 without UVs)"),
        PassSpec("alpha", ("A",), "mean", 0.0, _covered, "coverage of camera rays by geometry"),
    ) + tuple(PassSpec(name, ("R", "G", "B"), "mean", 0.0, None, doc) for name, doc in _LIGHT_PATHS)
}
# the path integrator's light-path passes (they sum to the image), in the order of its kernel's
# categories (rtmesh.rendering.path_kernel)
LIGHT_PATH_PASSES = tuple(name for name, _ in _LIGHT_PATHS)
# the passes of the camera rays' first surfaces (the producers', and the ao pass)
CAMERA_HIT_PASSES = tuple(name for name, spec in REGISTRY.items() if spec.producer is not None) + ("ao",)


@dataclass(frozen=True)
class DerivedPass:
    """A pass the film computes from its per-pixel sums after the render (not per sample).

    Attributes
    ----------
    name : str
    channels : tuple of str
        EXR channel names, written as ``name.channel``.
    compute : callable
        ``compute(film) -> (height, width, k) float32``.
    doc : str
    """

    name: str
    channels: tuple
    compute: object
    doc: str


DERIVED_PASSES = {
    spec.name: spec for spec in (
        DerivedPass("variance", ("R", "G", "B"), lambda film: film.variance_of_mean(),
                    "estimated variance of each pixel's mean radiance (sample variance / spp)"),
        DerivedPass("spp", ("Y",), lambda film: film.spp_image(), "samples taken in each pixel"),
    )
}


@dataclass(frozen=True)
class CentrePass:
    """A pass traced from one unjittered ray through each pixel centre after the render.

    Attributes
    ----------
    name : str
    channels : tuple of str
        EXR channel names, written as ``name.channel``.
    miss : float
        The value of a pixel whose centre ray hits nothing.
    doc : str
    """

    name: str
    channels: tuple
    miss: float
    doc: str


CENTRE_PASSES = {
    spec.name: spec for spec in (
        CentrePass("object_id", ("id",), -1.0, "object index (Scene.object_names) at the pixel centre, -1 for none"),
        CentrePass("material_id", ("id",), -1.0, "material index at the pixel centre, -1 for none"),
        CentrePass("instance_id", ("id",), -1.0,
                   "placement of a mesh at the pixel centre (the object index: every placement is an object)"),
        CentrePass("depth_center", ("Z",), np.inf, "z-depth of the pixel-centre ray's hit, +inf for none"),
        CentrePass("position_center", ("X", "Y", "Z"), np.nan,
                   "world-space hit point of the pixel-centre ray, NaN for none"),
        CentrePass("normal_center", ("X", "Y", "Z"), np.nan,
                   "world-space unit shading normal facing the camera at the pixel centre, NaN for none"),
        CentrePass("motion", ("X", "Y"), 0.0,
                   "image-space motion (pixels, +x right, +y down) of the surface point at the pixel "
                   "centre from shutter open to shutter close; 0 for none"),
    )
}
# channels of the per-view passes a batch adds to its EXR files (rtmesh.batch.flow)
VIEW_PASS_CHANNELS = {"flow_forward": ("X", "Y", "valid"), "flow_backward": ("X", "Y", "valid")}
PASS_NAMES = tuple(REGISTRY) + tuple(DERIVED_PASSES) + tuple(CENTRE_PASSES)


def pass_width(name):
    """Channels of the registry, derived or centre pass ``name``."""
    for table in (REGISTRY, DERIVED_PASSES, CENTRE_PASSES):
        if name in table:
            return len(table[name].channels)
    raise KeyError(name)


def derived_pass(name, film):
    """(height, width, k) float32: the derived pass ``name`` of ``film``."""
    return DERIVED_PASSES[name].compute(film)


def exr_channel_names(name, width):
    """EXR channel names of a pass of ``width`` channels (registry or generic scheme)."""
    if name in REGISTRY and REGISTRY[name].width == width:
        return REGISTRY[name].exr_names()
    table = DERIVED_PASSES if name in DERIVED_PASSES else CENTRE_PASSES
    channels = table[name].channels if name in table else VIEW_PASS_CHANNELS.get(name)
    if channels is None or len(channels) != width:
        channels = ("Y",) if width == 1 else ("X", "Y", "Z") if width == 3 else tuple(map(str, range(width)))
    return [f"{name}.{c}" for c in channels]


class PassSink:
    """The per-sample pass buffers of one chunk, written by pass name.

    Every stage that produces a pass value writes it here (the camera-hit passes through
    :meth:`PassRecorder.record`, the ambient-occlusion stage its ``ao``); a pass that was
    not asked for has no buffer and :meth:`wants` says so, so its stage computes nothing.

    Parameters
    ----------
    buffers : dict of str to (n, k) float64
        Filled with each pass's miss value (see :meth:`PassRecorder.buffers`).
    """

    __slots__ = ("buffers",)

    def __init__(self, buffers):
        self.buffers = buffers

    def __bool__(self):
        return bool(self.buffers)

    def wants(self, name):
        """True when the pass ``name`` is recorded in this render."""
        return name in self.buffers

    def write(self, name, rows, values):
        """Set pass ``name`` of the samples ``rows`` ((k,) int) to ``values`` ((k,) or (k, c))."""
        values = np.asarray(values, dtype=np.float64)
        self.buffers[name][rows] = values[:, None] if values.ndim == 1 else values


class PassRecorder:
    """Computes the requested passes for the camera rays of one render.

    Parameters
    ----------
    scene : Scene
    names : iterable of str
        Passes to compute; names not in :data:`REGISTRY` are ignored (the film derives
        them).  Nothing is computed for a pass that is not named.
    camera : Camera
        The camera in the integrator's shifted frame.
    shift : (3,) float
        The integrator's re-centring shift (world = shifted + ``shift``).
    """

    def __init__(self, scene, names, camera, shift):
        self.names = tuple(n for n in dict.fromkeys(names) if n in REGISTRY)
        self.specs = [REGISTRY[n] for n in self.names]
        self.shift = np.asarray(shift, dtype=np.float64)
        self.forward = camera.frame()[0]
        self.eye = camera.position
        self.faces = scene.faces
        self.uv = getattr(scene, "uv", None)
        if "uv" in self.names and self.uv is None:
            log.warning("the uv pass is zero: the scene has no texture coordinates")
        m = scene.materials
        # a metallic-roughness material's albedo is its base colour: the diffuse albedo of a
        # dielectric, the reflectance at normal incidence of a metal (what a denoiser's
        # albedo guide expects for both)
        self.diffuse = np.where(m.physical[:, None], m.base_color, m.diffuse) if len(m) else m.diffuse

    def __bool__(self):
        return bool(self.names)

    def film_passes(self):
        """``{name: (channels, reduction)}`` for :class:`rtmesh.rendering.film.Film`."""
        return {s.name: (s.width, s.reduction) for s in self.specs}

    def buffers(self, n):
        """Per-sample buffers for ``n`` camera rays, filled with each pass's miss value.

        Returns
        -------
        PassSink
        """
        return PassSink({s.name: np.full((n, s.width), s.miss) for s in self.specs})

    def record(self, sink, srf, hits, rows):
        """Write the passes of the camera rays that hit something.

        Parameters
        ----------
        sink : PassSink
            From :meth:`buffers`; rows are camera samples.
        srf : rtmesh.rendering.chunk_state.SurfaceRecords
            Shading records of the hits (``sample`` gives their rows in ``buffers``).
        hits : Hits
            Embree hits of every camera ray.
        rows : (k,) int or None
            Rays of ``hits`` that hit, in the order of ``srf``; None when all did.
        """
        self.record_hits(sink, srf.sample, CameraHits.of_records(srf, hits, rows, self))

    def record_hits(self, sink, rows, camera_hits):
        """Write every producer's pass of ``camera_hits`` (a :class:`CameraHits`) to the
        sink's ``rows`` ((k,) int: the camera samples that hit)."""
        for spec in self.specs:
            if spec.producer is not None:
                sink.write(spec.name, rows, spec.producer(camera_hits))

    def per_pixel(self, sink, m, spp):
        """The sink's buffers as ``(m, spp, k)`` for :meth:`Film.add_tile`."""
        return {name: b.reshape(m, spp, -1) for name, b in sink.buffers.items()}

    def per_sample(self, sink, n):
        """The sink's buffers as ``(n, k)`` for :meth:`Film.add_samples`."""
        return {name: b.reshape(n, -1) for name, b in sink.buffers.items()}


# ---------------------------------------------------------------- display (PNG) mapping


def display_values(name, values, coverage=None):
    """Map a pass to displayable values in [0, 1] for an 8-bit image.

    Parameters
    ----------
    name : str
        Pass name.
    values : (h, w, k) float
        The pass as the film returns it.
    coverage : (h, w) float, optional
        The alpha pass, when available: pixels with no coverage stay black in the
        normalised passes (depth, position).

    Returns
    -------
    display : (h, w, 3) float
        In [0, 1].
    srgb : bool
        True when ``display`` is linear colour to be sRGB-encoded (albedo); False for data
        written as is (normals as ``0.5 + 0.5 n``, grey ramps, id colours).

    Notes
    -----
    ``normal``: ``0.5 + 0.5 n`` per component (the normal-map convention), black where
    ``coverage`` is 0.  ``depth``: the
    nearest covered depth white, the farthest dark grey (0.1), no hit black.  ``position``:
    each axis normalised over the covered pixels' range.  ``uv``: (u, v, 0) wrapped to
    [0, 1).  The centre passes as their sampled twins, misses black.
    ``object_id``/``material_id``/``instance_id``: a distinct colour per id (golden-ratio hues),
    -1 black.  ``alpha``, ``ao``: grey.  Anything else: each channel divided by its maximum.
    """
    values = np.asarray(values, dtype=np.float64)
    h, w, k = values.shape
    if name in ("depth_center", "position_center", "normal_center"):
        # misses are +inf or NaN: shown black, as the sampled passes show them
        hit = np.isfinite(values).all(axis=2)
        return display_values(name[:-len("_center")], np.where(hit[:, :, None], values, 0.0), hit.astype(np.float64))
    if name == "depth" or name == "position":
        covered = values.any(axis=2) if coverage is None else coverage > 0
        out = np.zeros((h, w, k))
        if covered.any():
            lo = values[covered].min(axis=0)
            hi = values[covered].max(axis=0)
            span = np.where(hi > lo, hi - lo, 1.0)
            x = (values - lo) / span
            if name == "depth":
                x = 1.0 - 0.9 * x  # near white, far dark grey; black stays "no hit"
            out = np.where(covered[:, :, None], np.clip(x, 0.0, 1.0), 0.0)
        return _rgb(out), False
    if name == "normal":
        shown = np.clip(0.5 + 0.5 * values, 0.0, 1.0)
        if coverage is not None:  # no surface, no normal: black rather than mid grey
            shown = np.where(coverage[:, :, None] > 0, shown, 0.0)
        return shown, False
    if name == "albedo":
        return np.clip(values, 0.0, 1.0), True
    if name == "uv":
        return np.concatenate([np.mod(values, 1.0), np.zeros((h, w, 1))], axis=2), False
    if name in ("object_id", "material_id", "instance_id"):
        return id_colours(values[:, :, 0]), False
    if name in ("alpha", "ao"):
        return _rgb(np.clip(values, 0.0, 1.0)), False
    top = np.abs(values).reshape(-1, k).max(axis=0)
    return _rgb(np.clip(values / np.where(top > 0, top, 1.0), 0.0, 1.0)), False


def id_colours(ids):
    """Distinct colours for integer ids: hue steps of the golden ratio, id -1 black.

    Parameters
    ----------
    ids : (h, w) float
        Integer-valued ids.

    Returns
    -------
    (h, w, 3) float in [0, 1]
    """
    ids = np.rint(ids).astype(np.int64)
    unique = np.unique(ids)
    # a small table of colours, one per id present (colorsys is scalar; ids are few)
    table = np.array([(0.0, 0.0, 0.0) if i < 0 else
                      colorsys.hsv_to_rgb((i * 0.6180339887498949) % 1.0, 0.65, 0.95)
                      for i in unique])
    return table[np.searchsorted(unique, ids)]


def _rgb(values):
    """A one-channel image as grey RGB, anything else cut or padded to three channels."""
    k = values.shape[2]
    if k == 1:
        return np.repeat(values, 3, axis=2)
    if k >= 3:
        return values[:, :, :3]
    return np.concatenate([values, np.zeros(values.shape[:2] + (3 - k,))], axis=2)
