"""colourhs.evaluation.rig_errors: a calibrated rig against the true one."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from colourhs.evaluation.rig_errors import rig_errors

SIZE = (640, 480)
F = 1200.0


def _rig(turn_deg=((0, 0, 0), (0, 20, 0), (-18, 0, 0))) -> list:
    """Three cameras 0.8 m from the origin, looking at it, with a little distortion."""
    cams = []
    for k, angles in enumerate(turn_deg):
        R = Rotation.from_euler("xyz", angles, degrees=True).as_matrix()
        K = np.array([[F, 0, 319.5], [0, F, 239.5], [0, 0, 1]])
        dist = np.array([-0.1, 0.05, 2e-4, -1e-4, 0.0])
        cams.append(SimpleNamespace(name=f"c{k}", K=K, dist=dist, R=R, t=np.array([0, 0, 0.8])))
    return cams


def _copy(cams) -> list:
    return [SimpleNamespace(**{k: np.copy(v) for k, v in vars(c).items()}) for c in cams]


def test_a_rig_against_itself_and_in_another_world_frame_has_no_error():
    true = _rig()
    moved = _copy(true)
    Q = Rotation.from_rotvec([0.3, -0.2, 0.5]).as_matrix()  # X' = Q X + b: another world
    b = np.array([0.1, -0.2, 0.05])
    for c in moved:
        c.R, c.t = c.R @ Q.T, c.t - c.R @ Q.T @ b
    for est in (true, moved):
        for e in rig_errors(true, est, SIZE).values():
            assert max(e.values()) < 1e-9


def test_a_principal_point_traded_against_a_rotation_leaves_the_rays():
    """Camera c1's principal point 3 px to the right and the camera turned so its central
    ray stays: pp_px 3 and rotation_deg 3/f rad, but its rays move by a second-order
    amount only (ray_deg); uncompensated, they move by about 3/f."""
    true = _rig()
    shifted, traded = _copy(true), _copy(true)
    for cams in (shifted, traded):
        cams[1].K[0, 2] += 3.0
    turn = Rotation.from_rotvec([0, -np.arctan(3.0 / F), 0]).as_matrix()
    traded[1].R, traded[1].t = turn @ traded[1].R, turn @ traded[1].t
    pixel_deg = np.degrees(3.0 / F)
    e = rig_errors(true, shifted, SIZE)["c1"]
    assert e["pp_px"] == pytest.approx(3.0) and e["rotation_deg"] < 1e-9
    assert 0.3 * pixel_deg < e["ray_deg"] < 1.1 * pixel_deg
    t = rig_errors(true, traded, SIZE)["c1"]
    assert t["pp_px"] == pytest.approx(3.0)
    assert t["rotation_deg"] == pytest.approx(pixel_deg, rel=1e-3)
    print("ray error, shifted", e["ray_deg"], "traded", t["ray_deg"], "one pixel", pixel_deg / 3)
    assert t["ray_deg"] < 0.1 * e["ray_deg"]
    assert t["aligned_centre_mm"] < 0.01 and t["centre_mm"] < 1e-9  # the turn of the whole
