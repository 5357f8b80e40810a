"""View sets: many cameras around an asset for multi-view datasets.

``rtmesh batch --views SPEC`` with

- ``fibonacci:N``: N directions evenly spread on the sphere (the Fibonacci lattice:
  heights evenly spaced, azimuths advancing by the golden angle);
- ``random:N``: N directions uniform on the sphere, or within an elevation band
  (``--elevation MIN,MAX``), drawn from the batch ``seed``;
- ``rings:E1,E2,...xK``: K azimuths evenly spaced at each elevation ``E`` (degrees).

Elevation is the angle above the horizontal plane (+Y is up, degrees); azimuth 0 looks at
the asset's front (camera on +Z) and grows towards +X.  Each view is auto-framed on the
asset's bounding sphere; ``radius_jitter`` J moves the camera away by a factor drawn
uniformly in [1, 1 + J] per view (never closer: the asset stays whole in view).  The
lights stay put for the whole set (placed as for the ``iso`` view, like a turntable's), as
reconstruction methods expect of one scene seen from many places.
"""

import re

import numpy as np

from rtmesh.batch.jobs import VIEWS, View

VIEW_SET_KINDS = ("fibonacci", "random", "rings")
MAX_VIEWS = 100_000
_GOLDEN_ANGLE = np.pi * (3.0 - np.sqrt(5.0))
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)"


def is_view_set(spec):
    """True when ``spec`` names a view set (``KIND:...``) rather than fixed views."""
    return isinstance(spec, str) and spec.split(":", 1)[0] in VIEW_SET_KINDS and ":" in spec


def parse_elevation(text):
    """``"MIN,MAX"`` (degrees) as a pair of floats; raises ValueError naming the flag."""
    parts = str(text).split(",")
    try:
        low, high = (float(p) for p in parts)
    except ValueError:
        raise ValueError(f"elevation: expected MIN,MAX in degrees, got {text!r}") from None
    if not -90.0 <= low <= high <= 90.0:
        raise ValueError(f"elevation: need -90 <= MIN <= MAX <= 90, got {text!r}")
    return low, high


def view_set(spec, seed=0, elevation=(-90.0, 90.0), radius_jitter=0.0):
    """The views of a view set.

    Parameters
    ----------
    spec : str
        ``fibonacci:N``, ``random:N`` or ``rings:E1,E2,...xK`` (see the module notes).
    seed : int
        Seeds ``random`` directions and the radius jitter (the same seed, the same views).
    elevation : (2,) float
        Band of elevations, degrees, for ``random`` views.
    radius_jitter : float
        >= 0; the camera distance is multiplied by a factor uniform in [1, 1 + J].

    Returns
    -------
    list of View
        Named ``fib000``..., ``rand000``..., ``ring0_000``... (ring index, azimuth index).

    Raises
    ------
    ValueError
        A malformed spec or value, one line naming it.
    """
    kind, _, rest = str(spec).partition(":")
    if not radius_jitter >= 0.0 or not np.isfinite(radius_jitter):
        raise ValueError(f"radius jitter: must be >= 0, got {radius_jitter!r}")
    rng = np.random.default_rng([int(seed), 17])
    if kind in ("fibonacci", "random"):
        count = _count(spec, rest)
        if kind == "fibonacci":
            directions, prefix = fibonacci_directions(count), "fib"
        else:
            directions, prefix = random_directions(count, rng, *elevation), "rand"
        names = [f"{prefix}{i:03d}" for i in range(count)]
    elif kind == "rings":
        match = re.fullmatch(rf"({_NUMBER}(?:,{_NUMBER})*)x(\d+)", rest.replace(" ", ""))
        if not match:
            raise ValueError(f"views: expected rings:E1,E2,...xK (degrees, azimuths per ring), got {spec!r}")
        elevations = [float(e) for e in match.group(1).split(",")]
        per_ring = _count(spec, match.group(2))
        if any(not -90.0 <= e <= 90.0 for e in elevations) or len(elevations) * per_ring > MAX_VIEWS:
            raise ValueError(f"views: ring elevations must be within [-90, 90] degrees and the rings "
                             f"at most {MAX_VIEWS} views, got {spec!r}")
        directions = np.concatenate([ring_directions(e, per_ring) for e in elevations])
        names = [f"ring{r}_{k:03d}" for r in range(len(elevations)) for k in range(per_ring)]
    else:
        raise ValueError(f"views: unknown view set {spec!r} (expected fibonacci:N, random:N or "
                         f"rings:E1,E2,...xK)")
    scales = 1.0 + radius_jitter * rng.random(len(directions)) if radius_jitter else np.ones(len(directions))
    light = VIEWS["iso"][0]
    return [View(name, tuple(map(float, d)), _up(d), light, distance_scale=float(s))
            for name, d, s in zip(names, directions, scales)]


def fibonacci_directions(count):
    """``count`` unit directions, (count, 3), evenly spread on the sphere (Fibonacci lattice)."""
    i = np.arange(count)
    y = 1.0 - (2.0 * i + 1.0) / count
    ring = np.sqrt(np.maximum(1.0 - y * y, 0.0))
    azimuth = i * _GOLDEN_ANGLE
    return np.column_stack([ring * np.sin(azimuth), y, ring * np.cos(azimuth)])


def random_directions(count, rng, low=-90.0, high=90.0):
    """``count`` unit directions, (count, 3), uniform on the sphere's band of elevations
    [low, high] degrees (uniform height y is uniform area, Archimedes' hat-box theorem)."""
    y = rng.uniform(np.sin(np.radians(low)), np.sin(np.radians(high)), count)
    azimuth = rng.uniform(0.0, 2.0 * np.pi, count)
    ring = np.sqrt(np.maximum(1.0 - y * y, 0.0))
    return np.column_stack([ring * np.sin(azimuth), y, ring * np.cos(azimuth)])


def ring_directions(elevation, count):
    """``count`` unit directions, (count, 3), at ``elevation`` degrees, azimuths 0, 360/count..."""
    e = np.radians(elevation)
    azimuth = 2.0 * np.pi * np.arange(count) / count
    y = np.full(count, np.sin(e))
    return np.column_stack([np.cos(e) * np.sin(azimuth), y, np.cos(e) * np.cos(azimuth)])


def _up(direction):
    """+Y, or the top and bottom views' up vectors where the view looks along Y."""
    if abs(direction[1]) > 0.999:
        return VIEWS["top" if direction[1] > 0 else "bottom"][1]
    return (0.0, 1.0, 0.0)


def _count(spec, text):
    try:
        count = int(text)
    except ValueError:
        count = 0
    if not 1 <= count <= MAX_VIEWS:
        raise ValueError(f"views: {spec!r} needs a whole number of views from 1 to {MAX_VIEWS}")
    return count
