"""A reciprocal pair's eq. (5) row and its predicted noise (colourhs.reconstruct.constraint)."""

from __future__ import annotations

import numpy as np
from hs_constraint import constraint_vector

from colourhs.reconstruct.constraint import hs_row, row_variance


def test_row_is_the_oracles_and_vanishes_on_the_surface():
    """The row of two Helmholtz cameras at a point of a Lambertian plane is the
    oracle's (tests/hs_constraint.py) and orthogonal to the plane's normal."""
    x = np.array([0.01, -0.02, 0.5])
    n = np.array([0.2, -0.1, -1.0]) / np.linalg.norm([0.2, -0.1, -1.0])
    c_a, c_b = np.array([-0.1, 0.0, 0.0]), np.array([0.12, 0.05, 0.01])
    d_a, d_b = c_a - x, c_b - x
    r_a, r_b = np.linalg.norm(d_a), np.linalg.norm(d_b)
    v_a, v_b = d_a / r_a, d_b / r_b
    # Reciprocal intensities of a Lambertian surface: albedo x cosine / distance^2
    i_a, i_b = 0.7 * (v_b @ n) / r_b**2, 0.7 * (v_a @ n) / r_a**2
    s_a, s_b = i_a / r_a**2, i_b / r_b**2
    w = np.array(hs_row(s_a, s_b, *v_a, *v_b))
    assert np.allclose(w, constraint_vector(x, c_a, c_b, i_a, i_b), rtol=1e-14, atol=0)
    assert abs(w @ n) < 1e-12 * np.linalg.norm(w)


def test_row_variance_predicts_the_scatter_of_the_residual():
    """var_a (v_a . n)^2 + var_b (v_b . n)^2 against the residual w . n of
    200,000 noisy samples of both sides: within 1 % (the sampling error is 0.3 %)."""
    rng = np.random.default_rng(3)
    v_a, v_b = rng.normal(size=3), rng.normal(size=3)
    n = rng.normal(size=3)
    n /= np.linalg.norm(n)
    var_a, var_b = 0.04, 0.01
    s_a = 1.5 + np.sqrt(var_a) * rng.normal(size=200_000)
    s_b = 0.8 + np.sqrt(var_b) * rng.normal(size=200_000)
    w = np.stack(hs_row(s_a, s_b, *v_a, *v_b), axis=-1)
    predicted, ca, cb = row_variance(var_a, var_b, *v_a, *v_b, *n)
    assert np.isclose(ca, v_a @ n) and np.isclose(cb, v_b @ n)
    assert abs(np.var(w @ n) / predicted - 1.0) < 0.01
