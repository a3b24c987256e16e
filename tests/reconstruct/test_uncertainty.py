"""The noise model of the sampled sides and the depth's error bar, piece by piece."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from scipy.ndimage import gaussian_filter

from colourhs.reconstruct.bayes.uncertainty import (
    correlated_gain,
    filled_sigma,
    flat_valley_sigma,
    rim_valley_pull,
    surface_depth_sigma,
    valley_sigma,
)
from colourhs.reconstruct.bayes.valley import walk_out
from colourhs.reconstruct.sides import (
    RIM_SUPPORT,
    HelmholtzSides,
    noise_correlation,
    sample_sides,
    side_maps,
)


def _pinhole_sides(J, V, blur_px, order=1):
    """Two sides of one pinhole camera (f = 100 px, centre (40, 30)) over maps J, V."""
    cam = SimpleNamespace(
        K=np.array([[100.0, 0, 40.0], [0, 100.0, 30.0], [0, 0, 1]]),
        dist=np.zeros(5),
        R=np.eye(3),
        t=np.zeros(3),
    )
    maps = [np.stack([J, V], axis=-1)] * 2
    return HelmholtzSides([cam, cam], np.zeros((2, 3)), maps, blur_px > 0, order, blur_px)


def test_sampled_variance_of_blurred_noise_is_exact():
    """A sample between blurred pixels averages partly independent noise: its
    variance is the blurred pixels' times the bilinear weights' gain on the
    correlated noise (1 at a pixel, (1 + exp(-1/4))^2 / 4 = 0.791 half-way at a
    1-pixel blur). 2000 noise fields, blurred, sampled at a pixel and half-way:
    the empirical variances against ``sample_sides``' (measured within 1 %)."""
    rng = np.random.default_rng(1)
    H, W = 60, 80
    fields = gaussian_filter(rng.standard_normal((2000, H, W)), (0, 1.0, 1.0))
    var_pixel = float(fields[:, 30, 40].var())
    V = np.full((H, W), var_pixel)
    for du, expected_gain in ((0.0, 1.0), (0.5, (1 + np.exp(-0.25)) ** 2 / 4)):
        u, v = 40 + du, 30 + du
        R = np.array([[(u - 40.0) / 100, (v - 30.0) / 100, 1.0]])
        sides = _pinhole_sides(np.ones((H, W)), V, 1.0)
        _, var, _, _, _ = sample_sides(sides, R, R)
        predicted = var[0, 0, 0] * float(np.sum(R * R)) ** 2
        a = du
        samples = (
            (1 - a) * (1 - a) * fields[:, 30, 40]
            + a * (1 - a) * (fields[:, 30, 41] + fields[:, 31, 40])
            + a * a * fields[:, 31, 41]
        )
        assert abs(predicted / var_pixel - expected_gain) < 1e-9
        assert abs(samples.var() / predicted - 1) < 0.04  # measured 0 and 1.0 %


def test_noise_correlation_and_its_lattice_gain():
    """exp(-k^2 / (4 s^2)) at k = 0..3 pixels, and its sum over the 2D lattice: 4 pi s^2
    for a smooth average of a blur of s pixels (12.566 at 1 px), 1 without blur."""
    assert np.allclose(noise_correlation(1.0), np.exp(-(np.arange(4.0) ** 2) / 4))
    assert abs(correlated_gain(SimpleNamespace(blurred=True, blur_px=1.0)) - 4 * np.pi) < 1e-3
    assert abs(correlated_gain(SimpleNamespace(blurred=True, blur_px=2.0)) - 16 * np.pi) < 1e-3
    assert correlated_gain(SimpleNamespace(blurred=False, blur_px=0.0)) == 1.0


def test_footprint_error_at_the_rims_of_unusable_regions():
    """``side_maps(footprint_px=0.15)`` adds (footprint_px |grad J|)^2 to the variance within reach
    of an unusable pixel (the rim of a dark marker or a silhouette, where the
    unusable pixels count as 0): a ramp of 2 per pixel keeps its variance
    away from the hole, and next to a hole at column 10 of row 5 the
    gradient jumps (to (0 - 16) / 2 = -8 per pixel at column 9)."""
    J = np.tile(np.arange(20.0) * 2, (10, 1))
    ramp = side_maps(J, np.full_like(J, 0.5), blur_px=0, footprint_px=0.15)
    assert np.allclose(ramp[..., 1], 0.5)  # no unusable pixel, no rim
    J[5, 10] = np.nan
    holed = side_maps(J, np.where(np.isfinite(J), 0.5, np.nan), blur_px=0, footprint_px=0.15)
    assert np.allclose(side_maps(J, np.full_like(J, 0.5), blur_px=0)[..., 1], 0.5)  # default 0
    assert np.isnan(holed[5, 10, 1])
    assert np.isclose(holed[5, 9, 1], 0.5 + 0.15**2 * (8**2 + 0**2))
    assert np.isclose(holed[4, 10, 1], 0.5 + 0.15**2 * (2**2 + 10**2))
    assert np.allclose(holed[:, :8, 1], 0.5) and np.allclose(holed[:, 12:, 1], 0.5)


def test_valley_sigma_is_the_scatter_of_the_minimum():
    """Blocks whose energies are parabolas c_g (x - m_g)^2 along the depth factor,
    their minima m_g scattered: the surface's minimum is the curvature-weighted
    mean of the m_g, and ``valley_sigma`` estimates its standard deviation from
    the blocks' slopes at the chosen depth. Over 400 draws of 200 blocks its
    estimates' RMS matches the minimum's actual scatter within 5 % (measured
    0.4 %); a valley that does not curve upwards gives inf."""
    rng = np.random.default_rng(3)
    deltas = np.array([-0.005, -0.00125, -0.00025, 0.0, 0.00025, 0.00125, 0.005])
    G, per = 200, 4
    groups = np.repeat(np.arange(G), per)
    minima, estimates = [], []
    for _ in range(400):
        c = rng.uniform(0.5, 2.0, G) * 1e6
        m = rng.normal(0, 1e-3, G)
        best = float(np.sum(c * m) / c.sum())
        tried = {}
        for d in deltas:
            e = c * (best + d - m) ** 2
            tried[best + d] = (np.repeat(e / per, per), 0.0, None)
        minima.append(best)
        estimates.append(valley_sigma(tried, best, groups, 0.005))
    actual = np.std(minima)
    assert abs(np.sqrt(np.mean(np.square(estimates))) / actual - 1) < 0.05
    flat = {d: (np.repeat(-(d**2) * np.ones(G), per), 0.0, None) for d in deltas}
    assert valley_sigma(flat, 0.0, groups, 0.005) == np.inf


def test_filled_sigma_extrapolates_the_nearest_measured_one():
    """A hole's pixels take twice the sigma of the nearest pixel that has one."""
    sigma = np.full((5, 6), np.nan)
    sigma[:, :2] = 1e-3
    sigma[:, 4:] = 3e-3
    hole = np.zeros((5, 6), bool)
    hole[:, 2:4] = True
    out = filled_sigma(sigma.ravel(), hole.ravel(), (5, 6))
    assert np.allclose(out.reshape(5, 2), [[2e-3, 6e-3]] * 5)


def test_flat_valley_sigma_is_half_the_depths_e_cannot_rule_out():
    """16 blocks whose energy differences from the best depth are mu(d) = 1e5 d^2
    plus +-1 alternating over the blocks (standard error sqrt(16 / 15 * 16) = 4.13):
    at 2 standard errors the depths within 0.0075 are not ruled out (mu 5.6) and
    those at 0.01 are (mu 10), so the sigma is 0.00375; a farther depth where E is
    lower is not ruled out either and widens it; one block gives inf."""
    G = 16
    groups = np.arange(G)
    noise = np.where(groups % 2 == 0, 1.0, -1.0)
    tried = {0.0: (np.zeros(G), 0.0, None)}
    for d in (-0.01, -0.0075, -0.005, 0.005, 0.0075, 0.01, 0.015):
        tried[d] = (1e5 * d**2 / G + noise, 0.0, None)
    assert np.isclose(flat_valley_sigma(tried, 0.0, groups), 0.00375)
    tried[0.02] = (-3.0 / G + noise, 0.0, None)
    assert np.isclose(flat_valley_sigma(tried, 0.0, groups), 0.01)
    assert flat_valley_sigma(tried, 0.0, np.zeros(G, np.int64)) == np.inf


def test_walk_out_tries_depths_until_e_rises_beyond_its_noise():
    """E flat (within +-1 per block, 16 blocks: standard error 4.13) out to 0.02 of
    the depth, then rising by 2000 per step: walking a step of 0.005 at a time from
    +-0.005, each side stops at the first depth E rules out (0.025), and the flat
    valley's sigma is half the farthest depth not ruled out (0.01); with one step
    per side it reaches 0.01 only, and the sigma (0.005) is a lower bound."""
    G, step = 16, 0.005
    groups = np.arange(G)
    noise = np.where(groups % 2 == 0, 1.0, -1.0)

    def energy(d):
        return 2000.0 * max(0.0, abs(d) - 0.02) / step / G + noise * (d != 0)

    for max_steps, sigma in ((12, 0.01), (1, 0.005)):
        tried = [{round(d, 9): (energy(d), 0.0, None) for d in (-step, 0.0, step)}]

        def run(deltas, record, tried=tried):
            for k in np.flatnonzero(record):
                tried[k][round(float(deltas[k]), 9)] = (energy(deltas[k]), 0.0, None)

        walk_out(tried, np.zeros(1), [groups], np.ones(1, bool), step, max_steps, run)
        assert np.isclose(flat_valley_sigma(tried[0], 0.0, groups), sigma)
        reach = 0.025 if max_steps == 12 else 0.01
        assert max(tried[0]) == reach and min(tried[0]) == -reach
    tried = [{0.0: (np.zeros(G), 0.0, None), step: (np.zeros(G), 0.0, None)}]
    walk_out(tried, np.zeros(1), [groups], np.zeros(1, bool), step, 12, None)  # not flat


def test_filled_sigma_inherits_an_infinite_one():
    """A hole nearest a surface without an error bar has none either, while one
    nearer a measured sigma takes twice that; with no sigma at all it is NaN."""
    sigma = np.full((3, 6), np.nan)
    sigma[:, 0] = np.inf
    sigma[:, 5] = 1e-3
    hole = np.zeros((3, 6), bool)
    hole[:, 1:5] = True
    out = filled_sigma(sigma.ravel(), hole.ravel(), (3, 6)).reshape(3, 4)
    np.testing.assert_array_equal(out[:, :2], np.inf)
    np.testing.assert_allclose(out[:, 2:], 2e-3)
    assert np.isnan(filled_sigma(np.full(4, np.nan), np.ones(4, bool), (2, 2))).all()


def test_a_surface_without_a_valley_sigma_has_no_error_bar():
    """Three surfaces: a measured depth mode (1 %), one E does not fix (inf) and a
    one-block fragment (NaN). The first's pixels add the local sigma and the mode's
    in quadrature, at least the robust pull, NaN where the rows were unusable; every
    pixel of the second is infinite and of the third NaN (left to
    :func:`filled_sigma`), whatever its local sigma."""
    surface = np.array([0, 0, 0, 1, 1, 2, 2])
    z = np.full(7, 0.8)
    local = np.array([6e-3, np.nan, 1e-3, 1e-3, np.nan, 1e-3, 1e-3])
    pull = np.array([0.0, 0.0, 0.02, 0.0, 0.0, 0.0, 0.0])
    out = surface_depth_sigma(local, z, np.array([0.01, np.inf, np.nan]), surface, pull)
    np.testing.assert_allclose(out[0], 0.01)  # hypot(6 mm, 8 mm)
    assert np.isnan(out[1])
    np.testing.assert_allclose(out[2], 0.02)  # the pull
    np.testing.assert_array_equal(out[3:5], np.inf)
    assert np.isnan(out[5:]).all()


def test_a_fragment_is_at_least_as_uncertain_as_its_gap_to_the_nearest_depth():
    """Two fragments beside a measured surface (sigma 1 mm at 0.8 m): one at its
    depth takes twice its sigma, one 50 mm nearer at least that gap."""
    sigma = np.full((4, 8), np.nan)
    z = np.full((4, 8), 0.8)
    sigma[:, :4] = 1e-3
    frag = np.zeros((4, 8), bool)
    frag[1:3, 5] = True
    frag[1:3, 7] = True
    z[1:3, 7] = 0.75
    out = filled_sigma(sigma.ravel(), frag.ravel(), (4, 8), z.ravel()).reshape(2, 2)
    np.testing.assert_allclose(out[:, 0], 2e-3)
    np.testing.assert_allclose(out[:, 1], 0.05)


def test_samples_clear_of_every_edge():
    """A half-plane of usable pixels (columns 10 on unusable): the 1-pixel blur
    keeps samples whose kernel has 90 % of its weight on usable pixels (up to
    column 8, whose kernel has 5.9 % on the unusable side; column 9 30 %) and,
    with ``RIM_SUPPORT``, only those clear of the edge to a thousandth (up to
    column 6, 0.013 %; column 7 0.46 %), with the same values where both keep
    them."""
    J = np.where(np.arange(20) < 10, 1.0 + 0.1 * np.arange(20), np.nan)[None, :].repeat(12, 0)
    var = np.where(np.isfinite(J), 0.5, np.nan)
    blurred = side_maps(J, var, blur_px=1.0)
    clear = side_maps(J, var, blur_px=1.0, min_support=RIM_SUPPORT)
    assert np.isfinite(blurred[6, :9, 0]).all() and np.isnan(blurred[6, 9:, 0]).all()
    assert np.isfinite(clear[6, :7, 0]).all() and np.isnan(clear[6, 7:, 0]).all()
    assert np.allclose(clear[:, :7], blurred[:, :7])


def test_rim_valley_pull_is_the_move_of_the_minimum_less_its_noise():
    """Pixels whose energies along the depth factor are parabolas with minima at
    1e-3 (four clear pixels, weights 1, 2, 3, 3) and at -2e-3 (one rim pixel,
    weight 2): E over all has its minimum at (9e-3 - 4e-3) / 11, over the clear
    pixels at 1e-3. With the clear pixels in three blocks of equal weight they
    agree (their minimum's scatter, ``valley_sigma``, is 0), so the bias is the
    whole distance (to 1e-12). Clear pixels that disagree among themselves
    (minima 3e-3, -1e-3, 1e-3: the same clear minimum) explain part of it by
    their own noise: the bias is ``sqrt(d^2 - (s_clear^2 - s_all^2))``, less
    than d, and 0 once their scatter exceeds d. 0 without rim pixels; NaN
    with fewer than three trial depths or an energy that does not curve
    upwards."""
    deltas = [-0.004, -0.001, 0.0, 0.001, 0.004]
    weight = np.array([1.0, 2.0, 3.0, 2.0, 3.0])
    clear = np.array([True, True, True, False, True])

    def tried(minimum):
        return {d: (weight * (d - np.asarray(minimum)) ** 2, 5.0) for d in deltas}

    agree = tried([1e-3, 1e-3, 1e-3, -2e-3, 1e-3])
    one_block = np.array([0, 0, 1, 3, 2])  # clear blocks of weight 3 each
    d = (9e-3 - 4e-3) / 11 - 1e-3  # the minimum over all less that over the clear
    assert abs(rim_valley_pull(agree, 0.0, 0.004, clear, one_block) - abs(d)) < 1e-12
    assert rim_valley_pull(agree, 0.0, 0.004, np.ones(5, bool), one_block) == 0.0
    blocks = np.arange(5)
    for spread, reduced in ((7e-3, True), (9e-3, False)):  # clear minimum still 1e-3
        t = tried([spread, (3e-3 - spread) / 2, 1e-3, -2e-3, 1e-3])
        s_all = valley_sigma(t, 0.0, blocks, 0.004)
        inner = {k: (np.where(clear, v[0], np.nan), v[1]) for k, v in t.items()}
        s_clear = valley_sigma(inner, 0.0, blocks, 0.004)
        expected = np.sqrt(max(0.0, d * d - max(0.0, s_clear**2 - s_all**2)))
        assert (0 < expected < abs(d)) if reduced else expected == 0.0
        assert abs(rim_valley_pull(t, 0.0, 0.004, clear, blocks) - expected) < 1e-12
    assert np.isnan(rim_valley_pull(agree, 0.0, 0.0005, clear, one_block))
    concave = {k: (-weight * k * k, 0.0) for k in deltas}
    assert np.isnan(rim_valley_pull(concave, 0.0, 0.004, clear, one_block))


def test_a_barely_curving_valley_is_flat_not_infinitely_wide():
    """16 blocks whose energies are ``a d^2 + b_g d`` along the depth factor, their
    slopes b_g +-200 (the noise): ``valley_sigma`` is sqrt(16 / 15 * 16) 200 / (32 a),
    which grows without bound as the curvature a falls to 0 from above (258 at
    a = 0.1: a corner sheet's depth mode got 300 times its depth as its 1-sigma),
    where a valley that does not curve at all gets a finite
    :func:`flat_valley_sigma`. Beyond every depth the search tries (12 steps of
    0.005) no trial measured it, and ``measured_valley_sigma`` calls the valley flat
    (inf: walk out); within it, the quadratic's stands (0.026 at a = 1e3, beyond
    the step but within the reach)."""
    from colourhs.reconstruct.bayes.uncertainty import measured_valley_sigma

    G, step, reach = 16, 0.005, 0.06
    groups = np.arange(G)
    slope = np.where(groups % 2 == 0, 200.0, -200.0)
    deltas = (-0.01, -0.005, -0.00125, 0.0, 0.00125, 0.005, 0.01)
    expected = np.sqrt(16 / 15 * 16) * 200 / 32
    for a, stands in ((1e5, True), (1e3, True), (1e2, False), (0.1, False)):
        tried = {d: (a * d**2 + slope * d, 0.0, None) for d in deltas}
        quadratic = valley_sigma(tried, 0.0, groups, step)
        assert np.isclose(quadratic, expected / a)
        measured = measured_valley_sigma(tried, 0.0, groups, step, reach)
        assert measured == (quadratic if stands else np.inf)
        # the flat valley's sigma: half the farthest trial E cannot rule out
        assert flat_valley_sigma(tried, 0.0, groups) <= 0.5 * max(deltas)
    few = {d: tried[d] for d in (-0.005, 0.005)}  # too few trials: a fragment's NaN stays
    assert np.isnan(measured_valley_sigma(few, 0.0, groups, step, reach))
