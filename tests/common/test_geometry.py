"""Projection, back-projection, planes and triangulation against known answers.

Bounds of 1e-9 and below check exact formulas: they sit far above the measured
round-off (1e-13 px, 1e-16 m) on purpose, as libm, BLAS and OpenCV builds differ
in the last bits; they would still catch any error in the maths.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from colourhs.common import geometry as g

K = np.array([[1250.0, 0.0, 321.3], [0.0, 1248.0, 238.7], [0.0, 0.0, 1.0]])
DIST = np.array([-0.09, 0.07, 3e-4, -2e-4, 0.01])


def _cameras():
    out = []
    for ang in np.deg2rad([90.0, 210.0, 330.0]):
        c = np.array([0.25 * np.cos(ang), 0.25 * np.sin(ang), -0.76])
        R, t = g.look_at(c, [0.0, 0.0, 0.0])
        out.append((K, DIST, R, t))
    return out


def _points(n=500, seed=0):
    return np.random.default_rng(seed).uniform(-0.1, 0.1, (n, 3))


def test_look_at_is_a_rotation_facing_the_target():
    R, t = g.look_at([0.2, -0.1, -0.75], [0.01, 0.02, 0.0])
    assert np.allclose(R @ R.T, np.eye(3)) and np.isclose(np.linalg.det(R), 1)
    assert np.allclose(g.world_to_camera([0.01, 0.02, 0.0], R, t)[:2], 0, atol=1e-12)
    assert np.allclose(g.camera_centre(R, t), [0.2, -0.1, -0.75])


def test_light_centre_offset():
    R, t = g.look_at([0.0, 0.0, -0.8], [0.0, 0.0, 0.0])
    assert np.allclose(g.light_centre(R, t, [0.0, 0.0, 0.0]), g.camera_centre(R, t))
    assert np.allclose(g.light_centre(R, t, [0.01, 0.0, 0.0]), [0.01, 0.0, -0.8])


def test_distortion_matches_opencv_model():
    """project() equals an independent implementation of OpenCV's model."""
    _, _, R, t = _cameras()[0]
    X = _points()
    xc = g.world_to_camera(X, R, t)
    x, y = xc[:, 0] / xc[:, 2], xc[:, 1] / xc[:, 2]
    k1, k2, p1, p2, k3 = DIST
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    expected = np.stack([K[0, 0] * xd + K[0, 2], K[1, 1] * yd + K[1, 2]], axis=1)
    assert np.allclose(g.project(X, K, DIST, R, t), expected, atol=1e-9)
    rvec, _ = cv2.Rodrigues(R)
    cv_uv, _ = cv2.projectPoints(X, rvec, t, K, DIST)
    assert np.allclose(g.project(X, K, DIST, R, t), cv_uv.reshape(-1, 2), atol=1e-9)


LONG = {  # OpenCV's longer models: rational (8) and thin prism (12)
    8: np.array([-0.09, 0.07, 3e-4, -2e-4, 0.01, 0.05, -0.03, 0.02]),
    12: np.array([-0.09, 0.07, 3e-4, -2e-4, 0.01, 0.05, -0.03, 0.02, 1e-3, -5e-4, 8e-4, 2e-4]),
}
SKEWED = K + np.array([[0.0, 9.5, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])


@pytest.mark.parametrize("n", [8, 12])
def test_long_distortion_models_match_opencv(n):
    """Without skew, project() is cv2.projectPoints for 8 and 12 coefficients."""
    _, _, R, t = _cameras()[2]
    X = _points()
    rvec, _ = cv2.Rodrigues(R)
    cv_uv, _ = cv2.projectPoints(X, rvec, t, K, LONG[n])
    assert np.abs(g.project(X, K, LONG[n], R, t) - cv_uv.reshape(-1, 2)).max() < 1e-9


def test_skew_is_applied_and_inverted():
    """K[0, 1] shifts u by skew * y_d (which OpenCV's own functions ignore), and
    normalised_coordinates inverts project() on a skewed, distorted camera."""
    _, _, R, t = _cameras()[0]
    X = _points()
    plain, skewed = g.project(X, K, LONG[12], R, t), g.project(X, SKEWED, LONG[12], R, t)
    yd = (plain[:, 1] - K[1, 2]) / K[1, 1]
    assert np.abs(skewed[:, 0] - plain[:, 0] - 9.5 * yd).max() < 1e-9
    assert np.allclose(skewed[:, 1], plain[:, 1], atol=1e-12)
    xc = g.world_to_camera(X, R, t)
    xy = g.normalised_coordinates(skewed, SKEWED, LONG[12])
    assert np.abs(xy - xc[:, :2] / xc[:, 2:]).max() < 1e-12


def test_undistortion_falls_back_to_the_strict_iteration(monkeypatch):
    """Points the fast fixed-point pass leaves more than UNDISTORT_TOL_PX off are
    iterated to 1e-14: with a one-iteration fast pass (every point off) the
    result is still the strict one (measured 4e-17 apart, 1.1e-13 px reprojected)."""
    _, _, R, t = _cameras()[0]
    X = _points()
    uv = g.project(X, SKEWED, LONG[12], R, t)
    xy = g.normalised_coordinates(uv, SKEWED, LONG[12])
    monkeypatch.setattr(g, "_UNDISTORT_FAST", (cv2.TERM_CRITERIA_COUNT, 1, 0.0))
    slow = g.normalised_coordinates(uv, SKEWED, LONG[12])
    assert np.abs(slow - xy).max() < 1e-13
    u, v = g.pixels_of(slow[:, 0], slow[:, 1], SKEWED, LONG[12])
    assert np.hypot(u - uv[:, 0], v - uv[:, 1]).max() < g.UNDISTORT_TOL_PX


def test_compiled_projection_is_geometry_project():
    """The numba kernels' projection (dataterm.to_pixel, used by the data term
    and by sample_sides) equals geometry.project to 1e-9 px on a skewed camera
    with 12 coefficients, and the 14-coefficient tilted model is refused."""
    from colourhs.reconstruct.dataterm import to_pixel

    _, _, R, t = _cameras()[1]
    X = _points()
    xc = g.world_to_camera(X, R, t)
    d = g.model_coefficients(LONG[12])
    uv = np.array([to_pixel(a / c, b / c, SKEWED, d) for a, b, c in xc])
    assert np.abs(uv - g.project(X, SKEWED, LONG[12], R, t)).max() < 1e-9
    with pytest.raises(ValueError, match="tilted-sensor"):
        g.model_coefficients(np.r_[LONG[12], 0.01, 0.0])


def test_project_backproject_round_trip():
    _, _, R, t = _cameras()[1]
    X = _points()
    uv = g.project(X, K, DIST, R, t)
    origin, d = g.backproject(uv, K, DIST, R, t)
    assert np.allclose(np.linalg.norm(d, axis=1), 1)
    # Every point lies on its ray (distance below 1 nm).
    dist = np.linalg.norm(np.cross(X - origin, d), axis=1)
    assert dist.max() < 1e-9
    # And pixel -> ray -> pixel returns the pixel over the whole image, within
    # the undistortion's own tolerance (measured 2.3e-13 px; bound 1e-9 px).
    grid = g.pixel_grid(640, 480).reshape(-1, 2)[::97]
    o, d = g.backproject(grid, K, DIST, R, t)
    assert np.abs(g.project(o + 0.8 * d, K, DIST, R, t) - grid).max() < g.UNDISTORT_TOL_PX


def test_points_behind_the_camera_are_nan():
    R, t = g.look_at([0.0, 0.0, -0.8], [0.0, 0.0, 0.0])
    uv = g.project(np.array([[0.0, 0.0, -1.0], [0.0, 0.0, 0.0]]), K, DIST, R, t)
    assert np.isnan(uv[0]).all() and np.isfinite(uv[1]).all()


def test_pixel_grid_centres_and_supersamples():
    grid = g.pixel_grid(4, 3)
    assert grid.shape == (3, 4, 1, 2)
    assert np.array_equal(grid[2, 3, 0], [3.0, 2.0])  # pixel (0, 0) at the top-left centre
    ss = g.pixel_grid(4, 3, 2)
    assert np.allclose(ss[0, 0, :, 0], [-0.25, 0.25, -0.25, 0.25])
    assert np.allclose(ss.mean(axis=2), grid[:, :, 0])


def test_ray_plane_intersection():
    o = np.array([0.0, 0.0, -1.0])
    d = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.6, 0.0, 0.8]])
    p, s = g.ray_plane_intersection(o, d, [0.0, 0.0, 0.5], [0.0, 0.0, 1.0])
    assert np.allclose(p[0], [0, 0, 0.5]) and np.isclose(s[0], 1.5)
    assert np.isnan(s[1])
    assert np.allclose(p[2], [1.125, 0.0, 0.5])


def test_triangulation_is_exact_without_noise():
    cams = _cameras()
    X = _points(300, seed=3)
    uvs = np.stack([g.project(X, *c) for c in cams])
    uvs[0, :100] = np.nan  # a third of the points seen by two cameras only
    uvs[1, 250:] = np.nan
    uvs[2, 200:220] = np.nan  # ... and these by one camera alone: NaN
    uvs[1, 200:220] = np.nan
    Ks, dists, Rs, ts = zip(*cams, strict=True)
    got = g.triangulate(uvs, Ks, dists, Rs, ts)
    seen = np.isfinite(uvs[..., 0]).sum(0) >= 2
    assert np.isnan(got[~seen]).all()
    assert np.abs(got[seen] - X[seen]).max() < 1e-9


@pytest.mark.parametrize("sigma_px", [0.1, 0.5])
def test_triangulation_error_scales_with_noise(sigma_px):
    cams = _cameras()
    X = _points(2000, seed=4)
    rng = np.random.default_rng(5)
    uvs = np.stack([g.project(X, *c) + rng.normal(0, sigma_px, (len(X), 2)) for c in cams])
    Ks, dists, Rs, ts = zip(*cams, strict=True)
    err = np.linalg.norm(g.triangulate(uvs, Ks, dists, Rs, ts) - X, axis=1)
    # About sigma * depth / focal / sin(baseline angle) = 0.64 mm per pixel at 0.8 m.
    assert np.sqrt(np.mean(err**2)) < 2.0e-3 * sigma_px


def test_mesh_volume_and_outward_winding():
    """One signed volume (geometry.mesh_volume), which the hull and the
    synthetic scenes both orient their meshes by (outward_triangles): a unit cube
    corner's tetrahedron is 1/6 m^3 wound outward, -1/6 inward, and is turned."""
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    outward = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    inward = outward[:, ::-1]
    assert g.mesh_volume(v, outward) == pytest.approx(1 / 6, abs=1e-15)
    assert g.mesh_volume(v, inward) == pytest.approx(-1 / 6, abs=1e-15)
    assert g.outward_triangles(v, outward) is outward
    assert np.array_equal(g.outward_triangles(v, inward), outward)
