"""The camera's frame: refused where the view has no direction."""

import numpy as np
import pytest

from rtmesh.scene.camera import Camera, CameraError


@pytest.mark.parametrize("position, look_at", [
    ((1.0, 2.0, 3.0), (1.0, 2.0, 3.0)),
    # apart, but by less than the renderer's re-centred frame resolves (1e-36 of their size)
    ((1e18, -1e18, 1e-18), (1e18, -1e18, 0.0)),
])
def test_a_camera_looking_at_its_own_position_is_refused(position, look_at):
    with pytest.raises(CameraError, match="camera position and look_at coincide"):
        Camera(position, look_at, (0.0, 1.0, 0.0)).frame()


def test_a_far_camera_looking_a_short_way_has_its_frame():
    forward, right, up = Camera((1e6, 0.0, 0.0), (1e6, 0.0, -1e-3), (0.0, 1.0, 0.0)).frame()
    np.testing.assert_allclose(forward, [0.0, 0.0, -1.0], atol=1e-9)
    np.testing.assert_allclose(right, [1.0, 0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(up, [0.0, 1.0, 0.0], atol=1e-9)


def test_up_along_the_view_is_refused():
    with pytest.raises(CameraError, match="camera up is parallel to the viewing direction"):
        Camera((0.0, 0.0, 0.0), (0.0, 2.0, 0.0), (0.0, 1.0, 0.0)).frame()
