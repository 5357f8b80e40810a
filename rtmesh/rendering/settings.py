"""Render settings: what a render is asked to do, validated."""

import logging
import math
from dataclasses import dataclass

from rtmesh.core.runtime import usable_cores
from rtmesh.io.colour import TONEMAPS
from rtmesh.io.passes import LIGHT_PATH_PASSES, PASS_NAMES
from rtmesh.sampling.patterns import SAMPLERS
from rtmesh.sampling.zsobol import MAX_INDEX_BITS, index_bits, rounded_spp

log = logging.getLogger(__name__)

FRESNEL_MODES = ("schlick", "exact")
# "whitted": Blinn-Phong, lights and followed specular lobes (the values of scene files written
# for it); "path": physically based path tracing (rtmesh.rendering.path_stage)
INTEGRATORS = ("whitted", "path")
CAUSTICS = ("auto", "photons", "off")
# how next-event estimation chooses a light: by power (an alias table) or by its importance at
# the shading point (a light tree, rtmesh.lights.light_tree)
LIGHT_SAMPLERS = ("power", "tree")
# photons a pass may trace (a pass's photons take 104 bytes each)
MAX_PHOTONS = 1 << 26
# max_depth when it is not given: Whitted's bounces; the path integrator's "unlimited"
DEFAULT_MAX_DEPTH = {"whitted": 5, "path": -1}
# light_samples when it is not given: Whitted's shadow rays per area light; the path
# integrator's next-event estimates at a path's first vertex (one, as Mitsuba and pbrt-v4)
DEFAULT_LIGHT_SAMPLES = {"whitted": 4, "path": 1}
PASSES = PASS_NAMES
# adaptive sampling's cap on samples per pixel when max_spp is not given
DEFAULT_MAX_SPP = 1024

# The largest values a user may ask for (docs/LIMITS.md).  What fits in memory is usually
# far less and is checked before rendering (rtmesh.rendering.memory); these bound what the code can
# represent.  A pixel's sample index is a 64-bit hash input, but a 32-bit number for the
# Sobol sampler (its points would repeat beyond): 2**40 samples a pixel at most, 2**32 with
# Sobol (the memory check refuses far fewer: a pixel's samples are rendered in one chunk).
MAX_IMAGE_SIDE = 1 << 20
MAX_SPP = 1 << 40
MAX_SOBOL_SPP = 1 << 32
# bounces are depth levels of Python orchestration; lights, AO and threads beyond these are
# typing mistakes rather than wishes
MAX_DEPTH = 1024
MAX_RAYS_PER_HIT = 4096
MAX_THREADS = 1024
# 2 ** 64 overflows float32 tone mapping long before; 64 stops is already absurd
MAX_EXPOSURE_STOPS = 64.0


@dataclass
class RenderSettings:
    """How to render.

    Attributes
    ----------
    width, height : int
        Image size in pixels.
    spp : int
        Samples per pixel.
    sampler : {"regular", "random", "jittered", "sobol", "zsobol"}
        Sample pattern of every sampled dimension (pixel position with a box filter, lens,
        time, lights, BSDF, AO; docs/SAMPLERS.md).  ``zsobol`` takes a power-of-two
        ``spp``: another is rounded up, with a warning, when the settings are validated.
    integrator : {"whitted", "path"}
        The light transport (see :data:`INTEGRATORS`).
    max_depth : int or None
        Under ``whitted``, reflection/refraction bounces after the camera ray (default 5);
        under ``path``, segments after the camera ray (1: direct light only, 2: one indirect
        bounce; Mitsuba's ``max_depth`` is this + 1), -1 unlimited (the default: Russian
        roulette ends paths).  None takes the integrator's default when validated.
    seed : int
        Seed of every random number (same seed, same image).
    threads : int or None
        Worker threads; None uses every core.
    chunk_samples : int
        Pixel samples per work chunk; bounds memory, never changes the image (but for which of
        two coplanar overlapping triangles a ray reports).
    cutoff : float
        Paths whose largest throughput channel falls below this stop.
    fresnel : {"schlick", "exact"}
    ao_samples : int
        Ambient-occlusion rays per hit; 0 turns AO off (unless the ``ao`` pass is asked for).
    ao_distance : float or None
        Occluders farther than this do not count; None means 0.2 x the scene's diagonal.
    light_samples : int or None
        Under ``whitted``, shadow rays per (hit, area light) toward stratified points on the
        light (soft shadows; point, spot and directional lights always take one; default 4).
        Under ``path``, next-event estimates at a path's first vertex with a non-delta part
        (the camera ray's hit, or what it sees through mirrors and smooth glass): each a
        light chosen by power and a point on it, weighted against the BSDF sample by the
        power heuristic, their sum divided by this (default 1; later vertices take one).
        None takes the integrator's default when validated.
    passes : tuple of str
        Extra output passes (see :data:`rtmesh.io.passes.REGISTRY`).
    exposure : float
        Stops, applied when writing 8-bit images.
    tonemap : {"clamp", "reinhard", "aces", "pbr-neutral", "agx"}
        Operator for 8-bit images.
    dither : bool
        Quantise 8-bit images with blue-noise dithering instead of rounding to nearest
        (:func:`rtmesh.io.images.write_image`; EXR is not affected).
    target_error : float or None
        Adaptive sampling (see :mod:`rtmesh.rendering.adaptive`): render in rounds until every pixel's
        estimated display error is at most this (e.g. 0.01):
        standard error / sqrt(mean + 0.01) (:meth:`rtmesh.rendering.film.Film.pixel_display_error`),
        twice the standard error of the pixel on a square-root display scale with
        radiance 1 as white.  ``spp`` is then the samples of the first round.
    time_limit : float or None
        Adaptive sampling within a time budget, seconds: no round starts that would end
        after it (the first round always runs).  Alone, it refines the pixels noisier than
        the image's mean for as long as it allows.
    max_spp : int or None
        Most samples any pixel gets with adaptive sampling; None means
        ``DEFAULT_MAX_SPP`` (or ``spp``, if larger).
    clamp : float
        Path integrator: the largest channel any contribution after the first bounce may
        add to a sample (fireflies from rare bright paths; biased), 0 for none.
    caustics : {"auto", "photons", "off"}
        Path integrator: photon passes for caustics (:mod:`rtmesh.rendering.caustics`);
        ``auto`` runs them when a small or delta light can reach a specular surface.
    photons : int or None
        Photons a photon pass traces; None: a quarter of the pixel count, within 16384 .. 1048576.
    light_sampler : {"power", "tree"}
        Path integrator: how next-event estimation chooses a light, in proportion to its
        power, or to an estimate of its contribution at the shading point (distance,
        orientation: a light tree, :mod:`rtmesh.lights.light_tree`).
    denoise : bool
        Denoise the image with Intel Open Image Denoise, guided by the albedo and normal
        passes (see :mod:`rtmesh.io.denoising`; needs the ``denoise`` extra).
    """

    width: int = 640
    height: int = 480
    spp: int = 4
    sampler: str = "jittered"
    max_depth: int | None = None
    seed: int = 0
    threads: int | None = None
    chunk_samples: int = 32768
    cutoff: float = 1e-3
    fresnel: str = "schlick"
    ao_samples: int = 0
    ao_distance: float | None = None
    light_samples: int | None = None
    passes: tuple = ()
    exposure: float = 0.0
    tonemap: str = "reinhard"
    dither: bool = False
    target_error: float | None = None
    time_limit: float | None = None
    max_spp: int | None = None
    denoise: bool = False
    integrator: str = "whitted"
    clamp: float = 0.0
    caustics: str = "auto"
    photons: int | None = None
    light_sampler: str = "power"

    def validate(self):
        """Raise ValueError naming the first setting out of range (and the value given)."""
        def whole(value, low, high):
            # an integer (bool excluded), low <= value <= high (the messages say "integer"
            # only where the type is wrong: scene files and the command line check types)
            return isinstance(value, int) and not isinstance(value, bool) and low <= value <= high

        def real(value, low=-math.inf, high=math.inf):
            # a finite number, low < value < high
            return (isinstance(value, (int, float)) and not isinstance(value, bool)
                    and math.isfinite(value) and low < value < high)

        if self.max_depth is None and self.integrator in INTEGRATORS:
            self.max_depth = DEFAULT_MAX_DEPTH[self.integrator]
        if self.light_samples is None and self.integrator in INTEGRATORS:
            self.light_samples = DEFAULT_LIGHT_SAMPLES[self.integrator]
        lowest_depth = -1 if self.integrator == "path" else 0
        checks = [
            ("integrator", self.integrator in INTEGRATORS, f"one of {', '.join(INTEGRATORS)}"),
            ("width", whole(self.width, 1, MAX_IMAGE_SIDE), f">= 1 and <= {MAX_IMAGE_SIDE}"),
            ("height", whole(self.height, 1, MAX_IMAGE_SIDE), f">= 1 and <= {MAX_IMAGE_SIDE}"),
            ("spp", whole(self.spp, 1, MAX_SPP), f">= 1 and <= {MAX_SPP}"),
            ("sampler", self.sampler in SAMPLERS, f"one of {', '.join(SAMPLERS)}"),
            ("max_depth", whole(self.max_depth, lowest_depth, MAX_DEPTH),
             f">= {lowest_depth} and <= {MAX_DEPTH}"),
            ("clamp", real(self.clamp) and self.clamp >= 0, ">= 0 and finite (0: no clamp)"),
            ("caustics", self.caustics in CAUSTICS, f"one of {', '.join(CAUSTICS)}"),
            ("light_sampler", self.light_sampler in LIGHT_SAMPLERS, f"one of {', '.join(LIGHT_SAMPLERS)}"),
            ("photons", self.photons is None or whole(self.photons, 1, MAX_PHOTONS), f">= 1 and <= {MAX_PHOTONS}"),
            ("seed", whole(self.seed, -2**63, 2**64 - 1), ">= -2**63 and <= 2**64 - 1"),
            ("threads", self.threads is None or whole(self.threads, 1, MAX_THREADS),
             f">= 1 and <= {MAX_THREADS}"),
            ("chunk_samples", whole(self.chunk_samples, 1, 2**31 - 1), ">= 1 and <= 2**31 - 1"),
            ("cutoff", real(self.cutoff) and self.cutoff >= 0, ">= 0 and finite"),
            ("fresnel", self.fresnel in FRESNEL_MODES, f"one of {', '.join(FRESNEL_MODES)}"),
            ("ao_samples", whole(self.ao_samples, 0, MAX_RAYS_PER_HIT),
             f">= 0 and <= {MAX_RAYS_PER_HIT}"),
            ("ao_distance", self.ao_distance is None or real(self.ao_distance, 0.0), "> 0 and finite"),
            ("light_samples", whole(self.light_samples, 1, MAX_RAYS_PER_HIT),
             f">= 1 and <= {MAX_RAYS_PER_HIT}"),
            ("passes", all(p in PASSES for p in self.passes), f"among {', '.join(PASSES)}"),
            ("exposure", real(self.exposure) and abs(self.exposure) <= MAX_EXPOSURE_STOPS,
             f"a number of stops from {-MAX_EXPOSURE_STOPS:g} to {MAX_EXPOSURE_STOPS:g}"),
            ("tonemap", self.tonemap in TONEMAPS, f"one of {', '.join(TONEMAPS)}"),
            ("dither", isinstance(self.dither, bool), "true or false"),
            ("target_error", self.target_error is None or real(self.target_error, 0.0), "a number > 0 (finite)"),
            ("time_limit", self.time_limit is None or real(self.time_limit, 0.0),
             "a number of seconds > 0 (finite)"),
        ]
        for name, ok, expected in checks:
            if not ok:
                raise ValueError(f"{name} must be {expected} (got {getattr(self, name)!r})")
        if self.sampler == "zsobol" and rounded_spp(self.spp) != self.spp:
            rounded = rounded_spp(self.spp)
            # a max_spp between the two would refuse the render: it rises with spp
            raise_cap = whole(self.max_spp, self.spp, rounded - 1)
            log.warning("sampler 'zsobol' takes a power-of-two spp: %d rounded up to %d%s", self.spp, rounded,
                        " (max_spp too)" if raise_cap else "")
            self.spp = rounded
            if raise_cap:
                self.max_spp = rounded
        relations = [
            (self.max_spp is None or whole(self.max_spp, self.spp, MAX_SPP),
             f"max_spp must be >= spp and <= {MAX_SPP} (got {self.max_spp!r})"),
            (self.sampler not in ("sobol", "zsobol") or self.sample_cap <= MAX_SOBOL_SPP,
             f"spp and max_spp must be <= {MAX_SOBOL_SPP} with the {self.sampler} sampler (its sample index "
             f"is 32-bit; got {self.sample_cap})"),
            (self.sampler != "zsobol" or self.spp > MAX_SOBOL_SPP
             or index_bits(self.width, self.height, self.spp, max(self.light_samples, self.ao_samples, 1))
             <= MAX_INDEX_BITS,
             f"the zsobol sampler's index outgrows {MAX_INDEX_BITS} bits at {self.width}x{self.height} with "
             f"{self.spp} spp and {max(self.light_samples, self.ao_samples, 1)} rays a hit"),
            (self.max_spp is None or self.adaptive,
             "max_spp needs target_error or time_limit (adaptive sampling)"),
            (self.integrator == "path" or not set(self.passes) & set(LIGHT_PATH_PASSES),
             f"passes {', '.join(p for p in self.passes if p in LIGHT_PATH_PASSES)} need integrator 'path'"),
            (self.integrator == "path" or self.caustics != "photons",
             "caustics 'photons' needs integrator 'path'"),
            (self.integrator == "path" or self.light_sampler != "tree",
             "light_sampler 'tree' needs integrator 'path'"),
            (self.spp >= 2 or not self.adaptive,
             "spp must be >= 2 with target_error or time_limit (one sample gives no error estimate)"),
        ]
        for ok, message in relations:
            if not ok:
                raise ValueError(message)
        return self

    def header(self):
        """What an EXR's header records of the render: integrator, samples, seed, depth,
        sampler and the rtmesh version (``rtmesh:`` attributes)."""
        from importlib import metadata

        try:
            version = metadata.version("rtmesh")
        except metadata.PackageNotFoundError:  # running from a source tree
            version = "unknown"
        return {"rtmesh:version": version, "rtmesh:integrator": self.integrator, "rtmesh:spp": int(self.spp),
                "rtmesh:seed": str(self.seed), "rtmesh:max_depth": int(self.max_depth),
                "rtmesh:sampler": self.sampler}

    @property
    def adaptive(self):
        """True when the render refines noisy pixels in rounds (see :mod:`rtmesh.rendering.adaptive`)."""
        return self.target_error is not None or self.time_limit is not None

    @property
    def sample_cap(self):
        """Most samples per pixel an adaptive render may take."""
        return self.max_spp if self.max_spp is not None else max(self.spp, DEFAULT_MAX_SPP)

    @property
    def thread_count(self):
        """Threads to use: ``threads`` or the machine's usable cores."""
        return self.threads or usable_cores()
