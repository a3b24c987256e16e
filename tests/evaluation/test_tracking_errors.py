"""colourhs.evaluation.tracking_errors: the tracking's positions against the true ones."""

from __future__ import annotations

import numpy as np
import pytest
from capture_helpers import pinhole

from colourhs.evaluation.tracking_errors import (
    position_summary,
    same_triangulation,
    true_positions,
)

W, H = 80, 60
CAMERA = pinhole(100.0, 40.0, 30.0)


def _square(z: float, half: float, shift=(0.0, 0.0)):
    """A square of side 2 * half at depth z facing the camera, as two triangles."""
    x, y = shift
    v = np.array([[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]])
    return v + [x, y, 0.0], np.array([[0, 1, 2], [0, 2, 3]])


def test_a_translated_plane_moves_every_point_by_its_image_shift():
    """A plane at 1 m moved 5 cm sideways: each pixel's point was 5 px (f 100 px)
    to the left in the chromatic frame, exactly (to rounding)."""
    now = _square(1.0, 0.4, shift=(0.05, 0.0))
    before = _square(1.0, 0.4)
    truth = true_positions(now, before, CAMERA, W, H)
    gx, gy = np.meshgrid(np.arange(W), np.arange(H))
    on = np.all(np.isfinite(truth), axis=-1)
    assert on.mean() > 0.9
    assert np.allclose(truth[on, 0], gx[on] - 5.0, atol=1e-3)
    assert np.allclose(truth[on, 1], gy[on], atol=1e-3)
    s = position_summary(np.stack([gx, gy], -1).astype(float), truth)
    assert s["motion_median_px"] == pytest.approx(5.0, abs=1e-3)
    assert s["position_median_px"] == pytest.approx(5.0, abs=1e-3)  # no motion tracked
    assert s["position_known"] == 1.0


def test_a_point_hidden_in_the_chromatic_frame_has_no_true_position():
    """A small square 0.5 m in front of the plane in the chromatic frame, moved out of
    view in the frame: the plane's points it hid have no true position; the others do."""
    plane, small = _square(1.0, 0.4), _square(0.5, 0.05)
    tri = np.vstack([plane[1], small[1] + 4])
    before = (np.vstack([plane[0], small[0]]), tri)
    now = (np.vstack([plane[0], small[0] + [5.0, 0.0, 0.0]]), tri)
    truth = true_positions(now, before, CAMERA, W, H)
    on = np.all(np.isfinite(truth), axis=-1)
    # the small square covers |x| < 0.05 m at 0.5 m: 10 px either side of the centre
    assert not on[30, 40] and not on[25, 35] and on[30, 55] and on[5, 40]
    assert 19**2 <= (~on[5:55, 5:75]).sum() <= 21**2  # a 20 x 20 px square, edges either way


def test_meshes_of_two_triangulations_are_refused():
    a, b = _square(1.0, 0.4), _square(1.0, 0.4)
    b = (b[0], b[1][:, ::-1])
    assert same_triangulation(a, a) and not same_triangulation(a, b)
    with pytest.raises(ValueError, match="triangulation"):
        true_positions(a, b, CAMERA, W, H)


def test_position_summary_by_hand():
    truth = np.full((2, 2, 2), np.nan)
    truth[0, 0], truth[0, 1], truth[1, 0] = (0.0, 0.0), (4.0, 0.0), (0.0, 4.0)
    pos = np.full((2, 2, 2), np.nan)
    pos[0, 0], pos[0, 1] = (3.0, 4.0), (4.0, 0.0)
    s = position_summary(pos, truth)
    assert s["position_median_px"] == pytest.approx(2.5)  # distances 5 and 0
    assert s["motion_median_px"] == pytest.approx(3.0)  # motions 0, 3 and 3
    assert s["position_known"] == pytest.approx(2 / 3)
    assert np.isnan(position_summary(pos, np.full((2, 2, 2), np.nan))["position_median_px"])


def test_position_summary_pools_cameras_on_a_leading_axis():
    """Two cameras' maps stacked: each pixel's motion is from its own camera's grid."""
    gx, gy = np.meshgrid(np.arange(4.0), np.arange(3.0))
    grid = np.stack([gx, gy], -1)
    truth = np.stack([grid + [1.0, 0.0], grid + [0.0, 2.0]])
    s = position_summary(np.stack([grid, grid]), truth)
    assert s["motion_median_px"] == pytest.approx(1.5)  # 12 motions of 1, 12 of 2
    assert s["position_median_px"] == pytest.approx(1.5)
