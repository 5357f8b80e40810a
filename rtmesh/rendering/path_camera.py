"""The path kernel's camera rays, formed in the kernel for a pinhole or thin-lens camera: each lane's
position in its pixel from the sampler (:func:`rtmesh.sampling.pixel_samples.sample_positions`,
the compiled twin of :meth:`rtmesh.sampling.sampler.Sampler.pixel`) and its direction
through the image plane (:mod:`rtmesh.scene.camera_rays`' rows), the same numbers
:meth:`rtmesh.scene.camera.Camera.generate_rays` gives; an orthographic camera and a camera
class with rays of its own hand the kernel theirs instead.  With moving objects the chunk
hands it each sample's time.

``camera = (on, code, keys, corners, size, spp, width, frame, eye, focus, pixels, samples,
lens)``: whether the kernel forms the camera rays; the
:class:`~rtmesh.sampling.pixel_samples.PixelSampler`'s ``code``, ``keys``, ``corners``,
``size`` and ``spp``; the image width (pixels); ``frame`` (13,) the image-plane map
``(ax, bx, ay, by)`` (:meth:`rtmesh.scene.camera.Camera.image_plane`) and the camera frame
(forward, right, up); ``eye`` (3,) the camera's position in the re-centred frame; the focus
distance; and, the chunk's, each sample's pixel and index in it (``(n,)`` int64) and its
point on a thin lens's aperture (``(n, 2)`` float64, :meth:`rtmesh.scene.camera.Camera.lens_disk`
of the sampler's lens dimension; ``(0, 2)`` for a pinhole camera).
"""

import numpy as np

from rtmesh.core.compiled import inline_row
from rtmesh.sampling.pixel_samples import pixel_keys, sample_positions
from rtmesh.scene.camera_rays import image_plane_xy, pinhole_xyz, thin_lens_xyz


@inline_row
def camera_lanes(camera, start, count, sequence, index, xy, px, py, pz, dx, dy, dz):
    """The origins and unit directions of the camera rays of samples ``start .. start +
    count - 1`` into lanes ``0 .. count - 1`` of ``px, py, pz`` and ``dx, dy, dz``
    (``sequence`` (2, WIDTH) uint64, ``index`` (WIDTH,) uint64 and ``xy`` (2, WIDTH) float64
    are scratch)."""
    code, keys, corners, size, spp, width, frame, eye, focus, pixels, samples, lens = (
        camera[1], camera[2], camera[3], camera[4], camera[5], camera[6], camera[7], camera[8], camera[9],
        camera[10], camera[11], camera[12])
    for b in range(count):
        sequence[0, b], sequence[1, b] = pixel_keys(code, keys, pixels[start + b])
        index[b] = np.uint64(samples[start + b])
    sample_positions(code, keys, corners, size, spp, index, sequence, count, xy)
    inverse_width = 1.0 / width
    for b in range(count):
        sx, sy = image_plane_xy(xy[0, b], xy[1, b], pixels[start + b], width, inverse_width, frame[0], frame[1],
                                frame[2], frame[3])
        if len(lens):
            px[b], py[b], pz[b], dx[b], dy[b], dz[b] = thin_lens_xyz(
                sx, sy, lens[start + b, 0], lens[start + b, 1], eye[0], eye[1], eye[2], frame[4], frame[5],
                frame[6], frame[7], frame[8], frame[9], frame[10], frame[11], frame[12], focus)
        else:
            px[b], py[b], pz[b] = eye[0], eye[1], eye[2]
            dx[b], dy[b], dz[b] = pinhole_xyz(sx, sy, frame[4], frame[5], frame[6], frame[7], frame[8], frame[9],
                                              frame[10], frame[11], frame[12])
