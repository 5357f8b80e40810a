"""Render settings and render statistics."""

import math
import os
from dataclasses import dataclass, field

from .aov import PASS_NAMES
from .film import TONEMAPS
from .sampling import SAMPLERS

FRESNEL_MODES = ("schlick", "exact")
PASSES = PASS_NAMES
# adaptive sampling's cap on samples per pixel when max_spp is not given
DEFAULT_MAX_SPP = 1024


@dataclass
class RenderSettings:
    """How to render.

    Attributes
    ----------
    width, height : int
        Image size in pixels.
    spp : int
        Samples per pixel.
    sampler : {"regular", "random", "jittered"}
        Pixel sample pattern (box filter).
    max_depth : int
        Number of reflection/refraction bounces after the camera ray.
    seed : int
        Seed of every random number (same seed, same image).
    threads : int or None
        Worker threads; None uses every core.
    chunk_samples : int
        Pixel samples per work chunk; bounds memory, never changes the image.
    cutoff : float
        Paths whose largest throughput channel falls below this stop.
    fresnel : {"schlick", "exact"}
    ao_samples : int
        Ambient-occlusion rays per hit; 0 turns AO off (unless the ``ao`` pass is asked for).
    ao_distance : float or None
        Occluders farther than this do not count; None means 0.2 x the scene's diagonal.
    light_samples : int
        Shadow rays per (hit, area light) toward stratified points on the light (soft
        shadows); point, spot and directional lights always take one.
    passes : tuple of str
        Extra output passes (see :data:`rtmesh.aov.REGISTRY`).
    exposure : float
        Stops, applied when writing 8-bit images.
    tonemap : {"clamp", "reinhard", "aces"}
        Operator for 8-bit images.
    target_error : float or None
        Adaptive sampling (see :mod:`rtmesh.adaptive`): render in rounds until every pixel's
        estimated display error is at most this (e.g. 0.01):
        standard error / sqrt(mean + 0.01) (:meth:`rtmesh.film.Film.pixel_display_error`),
        twice the standard error of the pixel on a square-root display scale with
        radiance 1 as white.  ``spp`` is then the samples of the first round.
    time_limit : float or None
        Adaptive sampling within a time budget, seconds: no round starts that would end
        after it (the first round always runs).  Alone, it refines the pixels noisier than
        the image's mean for as long as it allows.
    max_spp : int or None
        Most samples any pixel gets with adaptive sampling; None means
        ``DEFAULT_MAX_SPP`` (or ``spp``, if larger).
    """

    width: int = 640
    height: int = 480
    spp: int = 4
    sampler: str = "jittered"
    max_depth: int = 5
    seed: int = 0
    threads: int | None = None
    chunk_samples: int = 32768
    cutoff: float = 1e-3
    fresnel: str = "schlick"
    ao_samples: int = 0
    ao_distance: float | None = None
    light_samples: int = 4
    passes: tuple = ()
    exposure: float = 0.0
    tonemap: str = "reinhard"
    target_error: float | None = None
    time_limit: float | None = None
    max_spp: int | None = None

    def validate(self):
        """Raise ValueError naming the first setting out of range."""
        checks = [
            (self.width >= 1 and self.height >= 1, "width and height must be >= 1"),
            (self.spp >= 1, "spp must be >= 1"),
            (self.sampler in SAMPLERS, f"sampler must be one of {', '.join(SAMPLERS)}"),
            (self.max_depth >= 0, "max_depth must be >= 0"),
            (self.threads is None or self.threads >= 1, "threads must be >= 1"),
            (self.chunk_samples >= 1, "chunk_samples must be >= 1"),
            (self.cutoff >= 0, "cutoff must be >= 0"),
            (self.fresnel in FRESNEL_MODES, f"fresnel must be one of {', '.join(FRESNEL_MODES)}"),
            (self.ao_samples >= 0, "ao_samples must be >= 0"),
            (self.ao_distance is None or self.ao_distance > 0, "ao_distance must be > 0"),
            (self.light_samples >= 1, "light_samples must be >= 1"),
            (all(p in PASSES for p in self.passes), f"passes must be among {', '.join(PASSES)}"),
            (self.tonemap in TONEMAPS, f"tonemap must be one of {', '.join(TONEMAPS)}"),
            (self.target_error is None or 0 < self.target_error < math.inf,
             "target_error must be a number > 0"),
            (self.time_limit is None or 0 < self.time_limit < math.inf,
             "time_limit must be a number of seconds > 0"),
            (self.max_spp is None or self.max_spp >= self.spp, "max_spp must be >= spp"),
            (self.max_spp is None or self.adaptive,
             "max_spp needs target_error or time_limit (adaptive sampling)"),
            (self.spp >= 2 or not self.adaptive,
             "spp must be >= 2 with target_error or time_limit (one sample gives no error estimate)"),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(message)
        return self

    @property
    def adaptive(self):
        """True when the render refines noisy pixels in rounds (see :mod:`rtmesh.adaptive`)."""
        return self.target_error is not None or self.time_limit is not None

    @property
    def sample_cap(self):
        """Most samples per pixel an adaptive render may take."""
        return self.max_spp if self.max_spp is not None else max(self.spp, DEFAULT_MAX_SPP)

    @property
    def thread_count(self):
        """Threads to use: ``threads`` or the machine's usable cores."""
        if self.threads:
            return self.threads
        try:
            return len(os.sched_getaffinity(0))
        except AttributeError:  # not on Linux
            return os.cpu_count() or 1


# "shadow": one per (hit, point/spot/directional light); "area_shadow": light_samples per
# (hit, area light or emissive object); "cutout": rays traced again beyond a cut-out surface
RAY_KINDS = ("camera", "shadow", "area_shadow", "reflection", "refraction", "ao", "cutout")
STAGES = ("camera", "intersect", "shade", "passes", "shadow", "ao", "spawn", "direct", "film")


@dataclass
class RenderStats:
    """What a render did.

    Attributes
    ----------
    rays : dict of str to int
        Rays traced per kind (see ``RAY_KINDS``).
    stage_seconds : dict of str to float
        Time per stage summed over threads (thread-seconds).
    stages_enabled : list of str
        Stages the scene needed (others never ran).
    wall_seconds : float
    threads : int
    relative_error : float
        Mean relative standard error estimated from the samples (NaN at 1 spp).
    samples : int
        Camera samples taken over the whole image.
    pixels : int
        Pixels in the image.
    rounds : list of RoundStats
        One record per adaptive round (a uniform render is one round).
    stop_reason : str
        Why an adaptive render stopped: ``"target"`` (every pixel at or below
        ``target_error``), ``"time_limit"``, ``"max_spp"`` (every pixel still above target
        is at the cap); ``"uniform"`` for a render without adaptive sampling.
    """

    rays: dict = field(default_factory=lambda: dict.fromkeys(RAY_KINDS, 0))
    stage_seconds: dict = field(default_factory=lambda: dict.fromkeys(STAGES, 0.0))
    stages_enabled: list = field(default_factory=list)
    wall_seconds: float = 0.0
    threads: int = 1
    relative_error: float = float("nan")
    samples: int = 0
    pixels: int = 0
    rounds: list = field(default_factory=list)
    stop_reason: str = "uniform"

    def merge(self, other):
        """Add another (per-chunk) record's ray counts and stage times into this one."""
        for k, v in other.rays.items():
            self.rays[k] += v
        for k, v in other.stage_seconds.items():
            self.stage_seconds[k] += v

    @property
    def mean_spp(self):
        """Camera samples per pixel, averaged over the image."""
        return self.samples / self.pixels if self.pixels else 0.0

    @property
    def total_rays(self):
        return sum(self.rays.values())

    @property
    def rays_per_second(self):
        return self.total_rays / self.wall_seconds if self.wall_seconds > 0 else 0.0


@dataclass
class RoundStats:
    """One round of an adaptive render.

    Attributes
    ----------
    pixels : int
        Pixels that took new samples in the round.
    samples : int
        Camera samples the round took.
    seconds : float
        Wall time of the round.
    error : float
        The image's mean estimated display error after the round (what ``target_error``
        bounds, :meth:`rtmesh.film.Film.pixel_display_error`); NaN for the single round of a
        uniform render, which does not estimate per-pixel errors.
    above_target : int
        Pixels whose estimated error was still above target after the round (above the
        image's mean error when no target is set).
    """

    pixels: int
    samples: int
    seconds: float
    error: float
    above_target: int
