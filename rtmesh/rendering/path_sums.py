"""What the path kernel adds up (rtmesh.rendering.path_kernel): a lane's radiance, the
light-path passes it is split into (:data:`rtmesh.io.passes.LIGHT_PATH_PASSES`, which sum
to the image: what the camera ray meets itself, light after the first vertex by the part of
the BSDF it came through, everything later by the first vertex's lobe), the clamp on
indirect light, and the light of the shadow rays that arrived."""

from rtmesh.core.compiled import inline_row, row
from rtmesh.geometry.embree_packets import LANES
from rtmesh.io.passes import LIGHT_PATH_PASSES
from rtmesh.materials import lobes

# light-path passes (rtmesh.io.passes.LIGHT_PATH_PASSES) and the first vertex's lobe categories
EMISSION, DIRECT, INDIRECT = 0, 1, 4
DIFFUSE_PATH, GLOSSY_PATH, TRANSMISSION_PATH = 0, 1, 2
LIGHT_PATHS = len(LIGHT_PATH_PASSES)


@row
def pass_bucket(depth, category):
    """The light-path pass of emission met at vertex ``depth`` of a path whose first lobe was
    ``category``."""
    if depth == 0:
        return EMISSION
    return (DIRECT if depth == 1 else INDIRECT) + category


@row
def lobe_category(flags):
    """The light-path category of a sampled lobe."""
    if flags & lobes.TRANSMISSION:
        return TRANSMISSION_PATH
    return DIFFUSE_PATH if flags & lobes.DIFFUSE else GLOSSY_PATH


@row
def clamped(r, g, b, limit):
    """``(r, g, b)`` scaled down so that its largest channel is at most ``limit`` (> 0)."""
    peak = max(r, max(g, b))
    if limit > 0.0 and peak > limit:
        s = limit / peak
        return r * s, g * s, b * s
    return r, g, b


@inline_row
def add_radiance(total, lane, r, g, b):
    total[lane, 0] += r
    total[lane, 1] += g
    total[lane, 2] += b


@inline_row
def add_to_pass(paths, split, lane, bucket, r, g, b):
    if split:
        paths[lane, bucket, 0] += r
        paths[lane, bucket, 1] += g
        paths[lane, bucket, 2] += b


@inline_row
def accept_shadows(shadow_valid, pending, pending_paths, split, total, paths):
    """Add the light of the lanes whose shadow rays arrived, element by element (an array
    assigned to a slice compiles numba's shape-mismatch message, string formatting that
    took seconds of a first run)."""
    for lane in range(LANES):
        if shadow_valid[lane]:
            add_radiance(total, lane, pending[lane, 0], pending[lane, 1], pending[lane, 2])
            if split:
                for bucket in range(LIGHT_PATHS):
                    for c in range(3):
                        paths[lane, bucket, c] += pending_paths[lane, bucket, c]
