"""The kernels a direct-lighting render on the general path calls, as one group.

The general path (:mod:`rtmesh.rendering.integrator`) runs a chunk as a sequence of stages,
each one or more kernels.  This group lists the kernels every general-path render with
point-like lights calls, with the argument types it calls them with, in the order it first
calls them, so that a first run can compile them in two processes
(:mod:`rtmesh.core.compile_ahead`).  Scenes with more features (textures, area lights,
reflection) call further kernels, or these with other argument types; those compile on
their first call as usual.  ``tests/core/test_compile_ahead.py`` checks that the listed types
are the ones a render calls.
"""

from numba import types

from rtmesh.core.compile_ahead import KernelGroup
from rtmesh.geometry.float32_rays import offset_origins
from rtmesh.lights.point_light_rows import illuminate
from rtmesh.materials.blinn_phong import raise_highlights
from rtmesh.rendering.film_sums import accumulate_samples, add_rows, pixel_errors
from rtmesh.scene.camera_rays import camera_rays
from rtmesh.shading.direct_light import add_light, light_samples
from rtmesh.shading.surfaces import surface_records

_ROWS = types.float64[:, ::1]  # row-major (n, 3)
_VECTORS = types.float64[::1, :]  # component-major (n, 3), as RayBatch keeps them
_COMPONENTS = types.float64[:, ::1]  # their (3, n) transpose (rtmesh.core.compiled.by_component)
_NUMBERS = types.float64[::1]
_INDICES = types.int64[::1]
_NO_ROWS = types.Array(types.float64, 2, "C", readonly=True)  # the shared empty (0, 3)

GENERAL_KERNELS = KernelGroup(__name__, "general direct", [
    (offset_origins, (_COMPONENTS, _COMPONENTS, _COMPONENTS, types.float32)),
    (camera_rays, (_VECTORS, _INDICES, types.int64, _ROWS, _NUMBERS, _NUMBERS, _NUMBERS, _NUMBERS, _NUMBERS,
                   types.float64)),
    (add_rows, (_COMPONENTS, _INDICES, _COMPONENTS)),
    # the (pixels, spp, 3) view of the radiance: strided, or column-major at 1 spp
    (accumulate_samples, (_COMPONENTS, _COMPONENTS, _INDICES, _INDICES, types.float64[:, :, :], types.float32[:, ::1])),
    (accumulate_samples, (_COMPONENTS, _COMPONENTS, _INDICES, _INDICES, types.float64[::1, :, :],
                          types.float32[:, ::1])),
    (surface_records, (types.int32[::1], _NUMBERS, _NUMBERS, _INDICES, _COMPONENTS, _NO_ROWS, _ROWS, _ROWS,
                       types.boolean[::1], _INDICES, types.boolean)),
    (illuminate, (_NUMBERS, _COMPONENTS)),
    (light_samples, (_COMPONENTS, _NUMBERS, _COMPONENTS, _COMPONENTS, _COMPONENTS, _COMPONENTS, _COMPONENTS, _INDICES,
                     _NUMBERS, _NUMBERS, types.float32, types.float64)),
    (raise_highlights, (_NUMBERS, _NUMBERS)),
    (add_light, (_COMPONENTS, _INDICES, _INDICES, types.boolean[::1], _NUMBERS, _ROWS, _INDICES, _NUMBERS, _INDICES,
                 _VECTORS, _NO_ROWS, _VECTORS, _NO_ROWS)),
    (pixel_errors, (_VECTORS, _VECTORS, _INDICES, types.int64, types.int64, types.float64, types.boolean)),
])
