"""The bilinear footprint: one definition for NumPy arrays and numba kernels."""

from __future__ import annotations

import numba as nb
import numpy as np

from colourhs.common.sampling import (
    bilinear_footprint,
    bilinear_weights,
    footprint_jit,
    sample_bilinear,
    weights_jit,
)

W, H = 7, 5


@nb.njit
def _compiled(u, v, width, height):
    out = np.empty((len(u), 9))
    for i in range(len(u)):
        inside, u0, v0, a, b = footprint_jit(u[i], v[i], width, height)
        w = weights_jit(a, b)
        out[i, 0], out[i, 1], out[i, 2], out[i, 3], out[i, 4] = inside, u0, v0, a, b
        out[i, 5], out[i, 6], out[i, 7], out[i, 8] = w
    return out


def _positions(rng, n=4000):
    u = rng.uniform(-2.0, W + 1.0, n)
    v = rng.uniform(-2.0, H + 1.0, n)
    u[:8] = [0.0, W - 1.0, 0.0, W - 1.0, np.nan, -0.0, 3.0, W - 1.0 + 1e-12]
    v[:8] = [0.0, H - 1.0, H - 1.0, 0.0, 1.0, np.nan, 2.0, 1.0]
    return u, v


def test_compiled_footprint_is_the_numpy_one_to_the_bit():
    u, v = _positions(np.random.default_rng(0))
    inside, u0, v0, a, b = bilinear_footprint(u, v, W, H)
    expected = np.stack([inside, u0, v0, a, b, *bilinear_weights(a, b)], axis=1)
    assert np.array_equal(_compiled(u, v, W, H), expected)


def test_footprint_is_a_valid_texel_with_fractions_in_the_unit_square():
    u, v = _positions(np.random.default_rng(1))
    inside, u0, v0, a, b = bilinear_footprint(u, v, W, H)
    assert np.all((u0 >= 0) & (u0 <= W - 2) & (v0 >= 0) & (v0 <= H - 2))
    assert np.all((a >= 0) & (a <= 1) & (b >= 0) & (b <= 1))
    ok = np.isfinite(u) & np.isfinite(v)
    assert np.array_equal(inside, ok & (u >= 0) & (u <= W - 1) & (v >= 0) & (v <= H - 1))
    # inside, the footprint reproduces the position; the far border is the last texel's a = 1
    assert np.array_equal((u0 + a)[inside], u[inside]) and np.array_equal(
        (v0 + b)[inside], v[inside]
    )
    assert bilinear_footprint(W - 1.0, H - 1.0, W, H)[1:] == (W - 2.0, H - 2.0, 1.0, 1.0)
    assert np.allclose(np.sum(bilinear_weights(a, b), axis=0), 1.0, rtol=0, atol=1e-15)


def test_sample_bilinear_is_exact_on_an_affine_image_and_nan_outside():
    rng = np.random.default_rng(2)
    rows, cols = np.mgrid[0:H, 0:W]
    image = np.stack([0.3 + 0.25 * cols - 0.5 * rows, 2.0 - 0.125 * cols], axis=-1)
    u, v = _positions(rng)
    got = sample_bilinear(image, np.stack([u, v], axis=-1))
    inside = bilinear_footprint(u, v, W, H)[0]
    want = np.stack([0.3 + 0.25 * u - 0.5 * v, 2.0 - 0.125 * u], axis=-1)
    assert np.abs(got[inside] - want[inside]).max() < 1e-13
    assert np.all(np.isnan(got[~inside]))
    assert sample_bilinear(image[..., 0], np.array([[3.0, 2.0]]))[0] == image[2, 3, 0]
