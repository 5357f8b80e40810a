"""Render settings: what a render is asked to do, validated."""

import math
import os
from dataclasses import dataclass

from rtmesh.io.colour import TONEMAPS
from rtmesh.io.passes import PASS_NAMES
from rtmesh.sampling.patterns import SAMPLERS

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
        Extra output passes (see :data:`rtmesh.io.passes.REGISTRY`).
    exposure : float
        Stops, applied when writing 8-bit images.
    tonemap : {"clamp", "reinhard", "aces", "pbr-neutral", "agx"}
        Operator for 8-bit images.
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
    denoise : bool
        Denoise the image with Intel Open Image Denoise, guided by the albedo and normal
        passes (see :mod:`rtmesh.io.denoising`; needs the ``denoise`` extra).
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
    denoise: bool = False

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
        """True when the render refines noisy pixels in rounds (see :mod:`rtmesh.rendering.adaptive`)."""
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
