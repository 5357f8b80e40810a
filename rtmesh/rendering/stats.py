"""Render statistics: what a render did (rays of each kind, stage times, adaptive rounds)."""

from dataclasses import dataclass, field

# "shadow": one per (hit, point/spot/directional light); "area_shadow": light_samples per
# (hit, area light or emissive object); "cutout": rays traced again beyond a cut-out surface;
# "bsdf": rays drawn from a metallic-roughness BRDF (the path kernel)
# "bounce": the path integrator's BSDF-sampled segments (its shadow rays count as "shadow");
# "photon": the segments of its photon passes (caustics)
RAY_KINDS = ("camera", "shadow", "area_shadow", "environment", "reflection", "refraction", "bsdf", "ao", "cutout",
             "bounce", "photon")
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
    photon_passes, photons, photons_stored : int
        Photon passes run for caustics, photons each traced, photons stored in all of them.
    photon_seconds : float
        Wall time of the photon passes (tracing and sorting).
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
    photon_passes: int = 0
    photons: int = 0
    photons_stored: int = 0
    photon_seconds: float = 0.0

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
        bounds, :meth:`rtmesh.rendering.film.Film.pixel_display_error`); NaN for the single round of a
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
