"""Tests for colourhs.synth.brdf: reciprocity, energy, horizon handling, known values."""

# ruff: noqa: E741  -- ``l`` (direction to the light) is the conventional name.
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from colourhs.synth.brdf import (
    Material,
    albedo_factors,
    blinn_phong,
    cook_torrance_ggx,
    evaluate_materials,
    evaluate_materials_bands,
    ggx_bands,
    lambertian,
    oren_nayar,
    ward,
)

N_RANDOM = 10_000
Z = np.array([0.0, 0.0, 1.0])


def _unit(rng: np.random.Generator, size: int) -> np.ndarray:
    x = rng.normal(size=(size, 3))
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


def _upper_triples(seed: int, size: int = N_RANDOM):
    """Random normals and two directions strictly in the upper hemisphere of each normal."""
    rng = np.random.default_rng(seed)
    n = _unit(rng, size)
    l = _unit(rng, size)
    v = _unit(rng, size)
    l *= np.sign(np.sum(n * l, axis=-1))[:, None]
    v *= np.sign(np.sum(n * v, axis=-1))[:, None]
    assert np.all(np.sum(n * l, axis=-1) > 0) and np.all(np.sum(n * v, axis=-1) > 0)
    return rng, n, l, v


MATERIALS = [
    Material(kd=0.8),
    Material(kd=0.3, specular="blinn_phong", ks=0.5, shininess=40.0),
    Material(kd=0.2, specular="ggx", ks=1.0, roughness=0.35, f0=0.04),
    Material(kd=0.1, specular="ward", ks=0.4, alpha=0.15),
    Material(kd=0.0, specular="ggx", ks=1.0, roughness=0.05, f0=0.9),
]


def _brdfs(rng: np.random.Generator, size: int):
    """(name, callable(n, l, v)) pairs, with scalar and per-point array parameters."""
    shin = rng.uniform(0.0, 500.0, size)
    rough = rng.uniform(0.02, 1.0, size)
    f0 = rng.uniform(0.0, 1.0, size)
    alpha = rng.uniform(0.02, 0.6, size)
    return [
        ("lambertian", lambda n, l, v: lambertian(n, l, v, 0.7)),
        ("blinn_phong", lambda n, l, v: blinn_phong(n, l, v, 30.0, 0.8)),
        ("blinn_phong_arr", lambda n, l, v: blinn_phong(n, l, v, shin)),
        ("blinn_phong_exact", lambda n, l, v: blinn_phong(n, l, v, shin, exact=True)),
        ("ggx", lambda n, l, v: cook_torrance_ggx(n, l, v, 0.4, 0.04)),
        ("ggx_arr", lambda n, l, v: cook_torrance_ggx(n, l, v, rough, f0)),
        ("ward", lambda n, l, v: ward(n, l, v, 0.2, 0.5)),
        ("ward_arr", lambda n, l, v: ward(n, l, v, alpha)),
    ] + [(f"material{i}", m.evaluate) for i, m in enumerate(MATERIALS)]


# --------------------------------------------------------------------------- reciprocity
def test_reciprocity_all_models():
    rng, n, l, v = _upper_triples(0)
    for name, f in _brdfs(rng, N_RANDOM):
        a = f(n, l, v)
        b = f(n, v, l)
        assert a.shape == (N_RANDOM,), name
        assert np.all(np.isfinite(a)), name
        assert np.any(a > 0), name
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=0.0, err_msg=name)


def test_reciprocity_evaluate_materials():
    rng, n, l, v = _upper_triples(1)
    ids = rng.integers(0, len(MATERIALS), N_RANDOM)
    a = evaluate_materials(ids, MATERIALS, n, l, v)
    b = evaluate_materials(ids, MATERIALS, n, v, l)
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=0.0)


# --------------------------------------------------------------------------- energy
def _directional_albedo(f, theta_i: float, n_theta: int = 1000, n_phi: int = 360) -> float:
    """Midpoint-rule quadrature of the directional albedo  int f(l, v) cos(theta_o) d omega_o.

    Normal ``n = z``, light in the x-z plane at polar angle ``theta_i``.
    """
    dt = 0.5 * np.pi / n_theta
    dp = 2.0 * np.pi / n_phi
    t = (np.arange(n_theta) + 0.5) * dt
    p = (np.arange(n_phi) + 0.5) * dp
    tt, pp = np.meshgrid(t, p, indexing="ij")
    v = np.stack([np.sin(tt) * np.cos(pp), np.sin(tt) * np.sin(pp), np.cos(tt)], axis=-1)
    l = np.array([np.sin(theta_i), 0.0, np.cos(theta_i)])
    w = np.sin(tt) * np.cos(tt) * dt * dp
    return float(np.sum(f(Z, l, v) * w))


@pytest.mark.parametrize("theta_i", [0.0, 0.7, 1.4])
def test_lambertian_albedo_is_one(theta_i):
    # The midpoint rule's own error: measured 4.1e-7.
    assert _directional_albedo(lambda n, l, v: lambertian(n, l, v, 1.0), theta_i) == (
        pytest.approx(1.0, rel=1e-6)
    )


def _bp_normal_albedo_closed_form(s: float) -> float:
    # (s+8)/(8 pi) divided by Giesen's exact normal-incidence factor (s+2)(s+4)/(8 pi (2^-s/2+s))
    return (s + 8.0) * (2.0 ** (-0.5 * s) + s) / ((s + 2.0) * (s + 4.0))


@pytest.mark.parametrize("s", [0.0, 1.0, 9.0, 100.0, 1000.0])
def test_blinn_phong_albedo_normal_incidence(s):
    """Normalised Blinn-Phong (ks=1) at normal incidence.

    Checks: quadrature == closed form; the (s+8)/(8 pi) lobe is within 2 % of unit albedo at
    s = 0 and s >= 100 but overshoots by at most ~7.5 % (peak near s ~ 9), i.e. the
    approximate normalisation is *not* strictly energy conserving; the exact normalisation
    gives albedo 1. Quadrature error measured 3.9e-7 to 2.6e-5 (at s = 1000); bound 5e-5.
    """
    albedo = _directional_albedo(lambda n, l, v: blinn_phong(n, l, v, s), 0.0)
    assert albedo == pytest.approx(_bp_normal_albedo_closed_form(s), rel=5e-5)
    assert albedo <= 1.076
    if s == 0.0 or s >= 100.0:
        assert albedo <= 1.02
    exact = _directional_albedo(lambda n, l, v: blinn_phong(n, l, v, s, exact=True), 0.0)
    assert exact == pytest.approx(1.0, rel=5e-5)


@pytest.mark.parametrize("theta_i", [0.5, 1.2])
def test_blinn_phong_exact_energy_conserving_oblique(theta_i):
    for s in (1.0, 9.0, 100.0):
        albedo = _directional_albedo(
            lambda n, l, v, s=s: blinn_phong(n, l, v, s, exact=True), theta_i
        )
        assert 0.0 < albedo <= 1.0 + 0.02


@pytest.mark.parametrize("roughness", [0.3, 0.5, 1.0])
@pytest.mark.parametrize("theta_i", [0.0, 0.8, 1.3])
def test_ggx_energy_conservation(roughness, theta_i):
    """GGX with f0 = 1 (perfect mirror microfacets): single-scattering albedo <= 1 (+2 %)."""
    albedo = _directional_albedo(
        lambda n, l, v: cook_torrance_ggx(n, l, v, roughness, 1.0), theta_i
    )
    assert 0.0 < albedo <= 1.02
    if roughness == 0.3 and theta_i == 0.0:
        # Low roughness loses little energy to multiple scattering: sanity of quadrature.
        assert albedo > 0.97


# --------------------------------------------------------------------------- horizon
def test_nonnegative_and_zero_below_horizon():
    rng = np.random.default_rng(2)
    n = _unit(rng, N_RANDOM)
    l = _unit(rng, N_RANDOM)
    v = _unit(rng, N_RANDOM)
    below = (np.sum(n * l, axis=-1) <= 0) | (np.sum(n * v, axis=-1) <= 0)
    assert 0 < below.sum() < N_RANDOM
    for name, f in _brdfs(rng, N_RANDOM):
        out = f(n, l, v)
        assert np.all(np.isfinite(out)), name
        assert np.all(out >= 0.0), name
        assert np.all(out[below] == 0.0), name
        if name == "lambertian":
            assert np.all(out[~below] > 0.0)


def test_exact_grazing_and_degenerate_inputs_are_finite_zero():
    n = np.array([0.0, 0.0, 1.0])
    grazing = np.array([1.0, 0.0, 0.0])
    up = np.array([0.0, 0.0, 1.0])
    tiny = np.array([np.sqrt(1 - 1e-30), 0.0, 1e-15])
    cases = [
        (grazing, up, True),
        (up, grazing, True),
        (grazing, -grazing, True),
        (-up, up, True),
        (tiny, tiny, False),
        (tiny, -tiny * np.array([1, 1, -1]), False),
        (up, up, False),
    ]
    with np.errstate(divide="raise", over="raise", invalid="raise"):
        for l, v, zero in cases:
            values = [
                lambertian(n, l, v),
                blinn_phong(n, l, v, 0.0),
                blinn_phong(n, l, v, 1e4),
                cook_torrance_ggx(n, l, v, 0.0, 1.0),
                cook_torrance_ggx(n, l, v, 1.0, 0.0),
                ward(n, l, v, 0.0),
                ward(n, l, v, 1.0),
            ]
            for val in values:
                assert np.isfinite(val) and val >= 0.0
                if zero:
                    assert val == 0.0


# --------------------------------------------------------------------------- known values
def test_lambertian_value():
    rng, n, l, v = _upper_triples(3, 100)
    albedo = rng.uniform(0, 1, 100)
    np.testing.assert_allclose(lambertian(n, l, v, albedo), albedo / np.pi, rtol=1e-15)
    assert lambertian(Z, Z, Z) == pytest.approx(1.0 / np.pi, rel=1e-15)


@pytest.mark.parametrize("roughness", [0.05, 0.3, 0.5, 1.0])
@pytest.mark.parametrize("f0", [0.04, 0.5, 1.0])
def test_ggx_peak_value(roughness, f0):
    alpha = roughness**2
    d0 = 1.0 / (np.pi * alpha**2)
    g = 1.0  # G_2 = 1 at normal incidence/exitance
    expected = d0 * f0 * g / 4.0
    assert cook_torrance_ggx(Z, Z, Z, roughness, f0) == pytest.approx(expected, rel=1e-12)


def test_blinn_phong_and_ward_peak_values():
    s = np.array([0.0, 10.0, 200.0])
    np.testing.assert_allclose(
        blinn_phong(Z, Z, Z, s, 0.5), 0.5 * (s + 8) / (8 * np.pi), rtol=1e-14
    )
    a = np.array([0.05, 0.2, 0.5])
    np.testing.assert_allclose(ward(Z, Z, Z, a, 0.3), 0.3 / (4 * np.pi * a**2), rtol=1e-14)


def _ggx_reference(n, l, v, roughness, f0):
    """Textbook GGX with an explicit half vector and the Lambda form of height-correlated G."""
    alpha = roughness**2
    h = l + v
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    nh, nl, nv, hv = (np.sum(a * b, axis=-1) for a, b in ((n, h), (n, l), (n, v), (h, v)))
    d = alpha**2 / (np.pi * (nh**2 * (alpha**2 - 1) + 1) ** 2)
    f = f0 + (1 - f0) * (1 - hv) ** 5

    def lam(c):
        tan2 = (1 - c**2) / c**2
        return 0.5 * (np.sqrt(1 + alpha**2 * tan2) - 1)

    g = 1.0 / (1.0 + lam(nl) + lam(nv))
    return d * f * g / (4 * nl * nv)


def _ward_reference(n, l, v, alpha, rho):
    h = l + v
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    theta_h = np.arccos(np.clip(np.sum(n * h, axis=-1), -1, 1))
    nl, nv = np.sum(n * l, axis=-1), np.sum(n * v, axis=-1)
    return (
        rho * np.exp(-(np.tan(theta_h) ** 2) / alpha**2) / (4 * np.pi * alpha**2 * np.sqrt(nl * nv))
    )


def test_ggx_and_ward_match_textbook_formulas():
    rng, n, l, v = _upper_triples(4, 2000)
    # keep away from grazing where the textbook forms lose precision
    ok = (np.sum(n * l, axis=-1) > 0.05) & (np.sum(n * v, axis=-1) > 0.05)
    n, l, v = n[ok], l[ok], v[ok]
    rough = rng.uniform(0.1, 1.0, ok.sum())
    f0 = rng.uniform(0.0, 1.0, ok.sum())
    np.testing.assert_allclose(
        cook_torrance_ggx(n, l, v, rough, f0), _ggx_reference(n, l, v, rough, f0), rtol=1e-9
    )
    alpha = rng.uniform(0.1, 0.6, ok.sum())
    np.testing.assert_allclose(
        ward(n, l, v, alpha, 0.7), _ward_reference(n, l, v, alpha, 0.7), rtol=1e-9, atol=1e-300
    )


def test_broadcasting_shapes():
    rng = np.random.default_rng(5)
    l = _unit(rng, 5)[:, None, :]
    v = _unit(rng, 4)[None, :, :]
    shin = np.linspace(1, 50, 4)
    assert blinn_phong(Z, l, v, shin).shape == (5, 4)
    assert cook_torrance_ggx(Z, l, v, np.full((5, 1), 0.3), 0.04).shape == (5, 4)
    assert ward(Z, l, v, 0.2).shape == (5, 4)
    assert lambertian(Z, l, v).shape == (5, 4)
    assert MATERIALS[2].evaluate(Z, l, v).shape == (5, 4)
    assert lambertian(Z, Z, Z).shape == ()


# --------------------------------------------------------------------------- materials
def test_material_is_mixture():
    rng, n, l, v = _upper_triples(6, 500)
    m = Material(kd=0.3, specular="ggx", ks=0.7, roughness=0.4, f0=0.1)
    expected = 0.3 / np.pi + 0.7 * cook_torrance_ggx(n, l, v, 0.4, 0.1)
    np.testing.assert_allclose(m.evaluate(n, l, v), expected, rtol=1e-14)
    np.testing.assert_allclose(
        Material(kd=0.6, ks=5.0).evaluate(n, l, v), np.full(500, 0.6 / np.pi), rtol=1e-15
    )


def test_material_validation_and_frozen():
    with pytest.raises(ValueError):
        Material(specular="phong")
    with pytest.raises(ValueError):
        Material(kd=-0.1)
    m = Material()
    with pytest.raises(dataclasses.FrozenInstanceError):
        m.kd = 0.1  # type: ignore[misc]


def test_evaluate_materials_matches_per_material():
    rng, n, l, v = _upper_triples(7)
    ids = rng.integers(0, len(MATERIALS), N_RANDOM)
    out = evaluate_materials(ids, MATERIALS, n, l, v)
    assert out.shape == (N_RANDOM,)
    for i, m in enumerate(MATERIALS):
        sel = ids == i
        assert sel.any()
        np.testing.assert_array_equal(out[sel], m.evaluate(n[sel], l[sel], v[sel]))
    # point-by-point for a few entries
    for k in range(0, N_RANDOM, 997):
        assert out[k] == pytest.approx(float(MATERIALS[ids[k]].evaluate(n[k], l[k], v[k])))
    # a single shared normal broadcasts to (N, 3)
    shared = evaluate_materials(ids[:10], MATERIALS, Z, np.tile(Z, (10, 1)), np.tile(Z, (10, 1)))
    expected = [MATERIALS[i].evaluate(Z, Z, Z) for i in ids[:10]]
    np.testing.assert_allclose(shared, expected, rtol=1e-15)


def test_evaluate_materials_errors_and_empty():
    with pytest.raises(ValueError):
        evaluate_materials(np.array([0, 5]), MATERIALS, Z, Z, Z)
    with pytest.raises(ValueError):
        evaluate_materials(np.array([-1]), MATERIALS, Z, Z, Z)
    with pytest.raises(ValueError):
        evaluate_materials(np.array([0.5]), MATERIALS, Z, Z, Z)
    empty = evaluate_materials(np.array([], dtype=int), MATERIALS, np.zeros((0, 3)), Z, Z)
    assert empty.shape == (0,)


# --------------------------------------------------------------------------- per-band materials
BAND_MATERIALS = [
    Material(kd=0.7),  # today's separable mode ("albedo" tint)
    Material(kd=1.0, specular="ggx", ks=1.0, roughness=0.2, f0=0.045, tint="white"),
    Material(
        kd=0.05, specular="ggx", ks=1.0, roughness=0.15, tint="fresnel", f0_rgb=(1.0, 0.71, 0.29)
    ),
    Material(kd=1.0, diffuse="oren_nayar", sigma=0.4),
    Material(
        kd=1.0,
        diffuse="oren_nayar",
        sigma=0.3,
        specular="blinn_phong",
        ks=0.2,
        shininess=20.0,
        tint="white",
    ),
]


def test_new_models_are_reciprocal_to_the_bit():
    rng, n, l, v = _upper_triples(8)
    sigma = rng.uniform(0.0, 0.6, N_RANDOM)
    rough = rng.uniform(0.02, 1.0, N_RANDOM)
    f0 = rng.uniform(0.0, 1.0, (N_RANDOM, 3))
    albedo = rng.uniform(0.0, 1.0, (N_RANDOM, 3))
    cases = [
        ("oren_nayar", lambda n, l, v: oren_nayar(n, l, v, 0.35, 0.8)),
        ("oren_nayar_arr", lambda n, l, v: oren_nayar(n, l, v, sigma)),
        ("ggx_bands", lambda n, l, v: ggx_bands(n, l, v, 0.3, (0.95, 0.64, 0.54))),
        ("ggx_bands_arr", lambda n, l, v: ggx_bands(n, l, v, rough, f0)),
    ] + [
        (f"bands{i}", lambda n, l, v, m=m: m.evaluate_bands(n, l, v, albedo))
        for i, m in enumerate(BAND_MATERIALS)
    ]
    for name, f in cases:
        a, b = f(n, l, v), f(n, v, l)
        assert np.all(np.isfinite(a)) and np.all(a >= 0) and np.any(a > 0), name
        np.testing.assert_array_equal(a, b, err_msg=name)
    ids = rng.integers(0, len(BAND_MATERIALS), N_RANDOM)
    np.testing.assert_array_equal(
        evaluate_materials_bands(ids, BAND_MATERIALS, n, l, v, albedo),
        evaluate_materials_bands(ids, BAND_MATERIALS, n, v, l, albedo),
    )


def test_new_models_vanish_below_the_horizon():
    rng = np.random.default_rng(9)
    n, l, v = (_unit(rng, N_RANDOM) for _ in range(3))
    below = (np.sum(n * l, axis=-1) <= 0) | (np.sum(n * v, axis=-1) <= 0)
    albedo = np.full(3, 0.5)
    for out in [oren_nayar(n, l, v, 0.4), ggx_bands(n, l, v, 0.2, (0.9, 0.8, 0.5))] + [
        m.evaluate_bands(n, l, v, albedo) for m in BAND_MATERIALS
    ]:
        assert np.all(np.isfinite(out)) and np.all(out >= 0)
        assert np.all(out[below] == 0.0)


def _oren_nayar_reference(n, l, v, sigma, rho):
    """Textbook Oren-Nayar with explicit polar and azimuth angles (normal = z)."""
    ti, to = np.arccos(l[..., 2]), np.arccos(v[..., 2])
    dphi = np.arctan2(l[..., 1], l[..., 0]) - np.arctan2(v[..., 1], v[..., 0])
    s2 = sigma**2
    a = 1 - 0.5 * s2 / (s2 + 0.33)
    b = 0.45 * s2 / (s2 + 0.09)
    alpha, beta = np.maximum(ti, to), np.minimum(ti, to)
    return rho / np.pi * (a + b * np.maximum(0, np.cos(dphi)) * np.sin(alpha) * np.tan(beta))


def test_oren_nayar_matches_textbook_and_lambert():
    rng, _, l, v = _upper_triples(10, 2000)
    l = l * np.sign(l[:, 2:3])
    v = v * np.sign(v[:, 2:3])
    ok = (l[:, 2] > 0.05) & (v[:, 2] > 0.05)
    l, v = l[ok], v[ok]
    for sigma in (0.15, 0.3, 0.5):
        np.testing.assert_allclose(
            oren_nayar(Z, l, v, sigma, 0.7), _oren_nayar_reference(Z, l, v, sigma, 0.7), rtol=1e-9
        )
    np.testing.assert_array_equal(oren_nayar(Z, l, v, 0.0, 0.6), lambertian(Z, l, v, 0.6))
    # At normal incidence the interreflection-free model reflects A = 1 - s2 / (2 (s2 + 0.33)).
    for sigma in (0.15, 0.5):
        albedo = _directional_albedo(lambda n, l, v, s=sigma: oren_nayar(n, l, v, s), 0.0)
        s2 = sigma**2
        # measured 4.1e-7 off (the quadrature's own error)
        assert albedo == pytest.approx(1 - 0.5 * s2 / (s2 + 0.33), rel=1e-6)


def test_ggx_bands_equal_f0_is_cook_torrance():
    rng, n, l, v = _upper_triples(11, 3000)
    for f0 in (0.04, 0.5, 1.0):
        per_band = ggx_bands(n, l, v, 0.3, (f0, f0, f0))
        for b in range(3):
            np.testing.assert_array_equal(per_band[:, b], cook_torrance_ggx(n, l, v, 0.3, f0))


def test_tints_combine_diffuse_and_specular_as_documented():
    rng, n, l, v = _upper_triples(12, 500)
    p = rng.uniform(0.05, 1.0, (500, 3))
    spec = cook_torrance_ggx(n, l, v, 0.2, 0.045)
    white = BAND_MATERIALS[1].evaluate_bands(n, l, v, p)
    np.testing.assert_allclose(white, p / np.pi + spec[:, None], rtol=1e-14)
    metal = BAND_MATERIALS[2].evaluate_bands(n, l, v, p)
    expected = 0.05 * p / np.pi + ggx_bands(n, l, v, 0.15, (1.0, 0.71, 0.29))
    np.testing.assert_allclose(metal, expected, rtol=1e-14)
    sep = BAND_MATERIALS[0]
    np.testing.assert_allclose(sep.evaluate_bands(n, l, v, p), p * sep.evaluate(n, l, v)[:, None])
    # factored rows leave p out; albedo_factors puts it back.
    ids = rng.integers(0, len(BAND_MATERIALS), 500)
    full = evaluate_materials_bands(ids, BAND_MATERIALS, n, l, v, p)
    part = evaluate_materials_bands(ids, BAND_MATERIALS, n, l, v, p, factored=True)
    np.testing.assert_allclose(part * albedo_factors(ids, BAND_MATERIALS, p), full, rtol=1e-14)


def test_band_material_validation():
    with pytest.raises(ValueError, match="tint"):
        Material(tint="gold")
    with pytest.raises(ValueError, match="ggx"):
        Material(specular="ward", tint="fresnel", f0_rgb=(0.9, 0.9, 0.9))
    with pytest.raises(ValueError, match="f0_rgb"):
        Material(specular="ggx", tint="fresnel", f0_rgb=(0.9, 1.2, 0.9))
    with pytest.raises(ValueError, match="diffuse"):
        Material(diffuse="minnaert")
    with pytest.raises(ValueError, match="evaluate_bands"):
        BAND_MATERIALS[2].evaluate(Z, Z, Z)


def test_cross_norm2_is_bit_identical_to_np_cross():
    """The geometry's |n x l + n x v|^2 without np.cross: the same bits (the
    rendered datasets must not change)."""
    from colourhs.synth.brdfmodels import _cross_norm2, _dot

    rng = np.random.default_rng(3)
    n, l, v = (rng.normal(size=(500, 3)) for _ in range(3))
    c = np.cross(n, l) + np.cross(n, v)
    assert np.array_equal(_cross_norm2(n, l, v), _dot(c, c))
    c = np.cross(n, l[:1]) + np.cross(n, v)  # a light direction broadcast over points
    assert np.array_equal(_cross_norm2(n, l[:1], v), _dot(c, c))
