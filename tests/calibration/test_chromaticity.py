"""Surface chromaticity calibration (colourhs.calibration.chromaticity, section III-D,
eqs. 9-12)."""

from __future__ import annotations

import json
import shutil

import cv2
import h5py
import numpy as np
import pytest

from colourhs.calibration.chromaticity import (
    NORMALISATION,
    chromaticity_error,
    chromaticity_map,
    chromaticity_maps,
    chromaticity_ratios,
    log_sigma,
    log_sigma_coverage,
    normalise,
    object_silhouette,
    signal_mask,
    solve_chromaticity,
)
from colourhs.capture import COLOURS, CaptureFormatError, open_dataset, read_mask
from colourhs.report.figures import chromaticity_figure, chromaticity_rgb

# Median relative error bound on the tiny preset (all nuisances on). The demo preset's target
# is 2 % (measured there: toy 0.85-0.86 %, statue 1.28-1.36 %). The statue's error is shot
# noise (a capture at half of full scale has ~1.2 % noise, and eq. 12 combines six), the same
# at any resolution; tiny's 4x larger pixels mix more parts of the toy (its 90th percentile
# rises from 2.4 % to 2.9 %), so the bound gets 0.5 % on top of the demo's target.
# Measured on tiny: toy 0.88-0.92 %, statue 1.28-1.34 %.
TINY_MEDIAN_BOUND = 0.025


def _captures(p, geometry, white_geometry, gains, white_albedo=0.8):
    """Eq. (9) without cross-talk: i_b = k_b p_b G, white i_b^w = k_b p^w G^w."""
    obj = {c: gains[k] * p[..., k] * geometry for k, c in enumerate(COLOURS)}
    white = {c: gains[k] * white_albedo * white_geometry for k, c in enumerate(COLOURS)}
    return obj, white


@pytest.fixture
def known():
    rng = np.random.default_rng(3)
    shape = (7, 9)
    p = rng.uniform(0.05, 1.0, shape + (3,))
    obj, white = _captures(
        p, rng.uniform(0.1, 1.0, shape), rng.uniform(0.3, 1.0, shape), (0.9, 1.3, 0.6)
    )
    return p, obj, white


# ------------------------------------------------------------------------------ pure functions


def test_ratios_are_equation_12(known):
    p, obj, white = known
    r = chromaticity_ratios(obj, white)
    assert r.shape == p.shape
    np.testing.assert_allclose(r[..., 0], p[..., 0] / p[..., 1], rtol=1e-12)
    np.testing.assert_allclose(r[..., 1], p[..., 0] / p[..., 2], rtol=1e-12)
    np.testing.assert_allclose(r[..., 2], p[..., 1] / p[..., 2], rtol=1e-12)


def test_solve_recovers_known_chromaticity(known):
    p, obj, white = known
    est = solve_chromaticity(chromaticity_ratios(obj, white))
    assert est.dtype == np.float32 and est.shape == p.shape
    # float32: measured 5.5e-8 and 8e-8 relative; bounds about two ulps
    np.testing.assert_allclose(est, 3 * p / p.sum(axis=-1, keepdims=True), rtol=2e-7)
    np.testing.assert_allclose(est.sum(axis=-1), 3.0, rtol=2e-7)
    assert np.nanmax(chromaticity_error(est, p)) < 1e-7  # float32: measured 3.8e-8


def test_log_sigma_is_the_spread_of_log_p_under_the_noise(known):
    """Beyond the paper: each band's sigma of log p (eq. 12's six intensities' noise,
    propagated through the normalisation to sum 3) against the spread of log p over
    6,000 noisy draws of the same captures (noise up to a few per cent of the signal,
    where the first order holds): within 5 % on every pixel and band (the draws' own
    error is 0.9 %; measured 2.5 % at most)."""
    p, obj, white = known
    rng = np.random.default_rng(0)
    var = {c: 1e-5 * (0.2 + obj[c]) for c in COLOURS}  # shot and read noise
    wvar = {c: 1e-5 * (0.2 + white[c]) for c in COLOURS}
    n = 6000

    def draw(i, v):
        return {c: i[c] + np.sqrt(v[c]) * rng.standard_normal((n,) + i[c].shape) for c in COLOURS}

    logp = np.log(solve_chromaticity(chromaticity_ratios(draw(obj, var), draw(white, wvar))))
    spread = np.std(logp.astype(float), axis=0)
    pred = log_sigma(solve_chromaticity(chromaticity_ratios(obj, white)), obj, white, var, wvar)
    assert pred.dtype == np.float32 and pred.shape == p.shape
    print("largest relative difference", np.max(np.abs(spread / pred - 1)))
    np.testing.assert_allclose(spread, pred, rtol=0.05)
    zero = {c: np.zeros_like(obj[c]) for c in COLOURS}
    assert np.all(log_sigma(p, obj, white, zero, zero) == 0)
    p[0, 0] = np.nan
    assert np.isnan(log_sigma(p, obj, white, var, wvar)[0, 0]).all()


def test_solve_small_cases():
    # p = (4, 2, 1): R/G = 2, R/B = 4, G/B = 2; white is (1, 1, 1).
    got = solve_chromaticity(np.array([[2.0, 4.0, 2.0], [1.0, 1.0, 1.0]]))
    np.testing.assert_allclose(got, [[12 / 7, 6 / 7, 3 / 7], [1, 1, 1]], rtol=2e-7)  # f32: 1e-8
    # Inconsistent ratios still give a positive triplet of sum 3.
    got = solve_chromaticity(np.array([2.0, 3.0, 2.0]))
    assert got.sum() == pytest.approx(3.0) and np.all(got > 0)
    assert got[0] > got[1] > got[2]


def test_solve_masks_invalid_pixels():
    ratios = np.ones((2, 3, 3))
    ratios[0, 0, 1] = np.nan
    ratios[0, 1, 0] = np.inf
    ratios[0, 2, 2] = 0.0
    valid = np.ones((2, 3), bool)
    valid[1, 1] = False
    got = solve_chromaticity(ratios, valid)
    finite = np.isfinite(got).all(axis=-1)
    np.testing.assert_array_equal(finite, [[False, False, False], [True, False, True]])
    np.testing.assert_allclose(got[finite], 1.0)
    assert np.isnan(solve_chromaticity(ratios, np.zeros((2, 3), bool))).all()
    with pytest.raises(ValueError, match="valid has shape"):
        solve_chromaticity(ratios, np.ones((3, 2), bool))
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 3\)"):
        solve_chromaticity(np.ones((4, 2)))


def test_ratio_inputs_are_checked(known):
    _, obj, white = known
    with pytest.raises(ValueError, match="object: missing intensity of colour.*green"):
        chromaticity_ratios({"red": obj["red"], "blue": obj["blue"]}, white)
    with pytest.raises(ValueError, match="differ in shape"):
        chromaticity_ratios({**obj, "blue": obj["blue"][:3]}, white)
    zero = {**white, "green": np.zeros_like(white["green"])}
    assert np.isnan(chromaticity_ratios(obj, zero)[..., [0, 2]]).all()


def test_signal_mask_needs_every_matching_channel(known):
    _, obj, white = known
    obj = {c: np.full((2, 2), 0.2) for c in COLOURS}
    white = {c: np.full((2, 2), 0.4) for c in COLOURS}
    obj["green"][0, 0] = 0.009  # object too dark in one channel
    white["blue"][1, 1] = 0.005  # white reference too dark
    np.testing.assert_array_equal(signal_mask(obj, white, 0.01), [[False, True], [True, False]])
    assert signal_mask(obj, white, 0.001).all()


def test_normalise_and_error():
    np.testing.assert_allclose(normalise([2.0, 2.0, 2.0]), [1, 1, 1])
    assert np.isnan(normalise([0.0, 0.0, 0.0])).all()
    truth = np.array([[[0.8, 0.4, 0.2], [np.nan, 1, 1]]])
    est = np.array([[[1.6, 0.8, 0.4], [1, 1, 1]]])  # same direction, another scale
    err = chromaticity_error(est, truth)
    assert err[0, 0] == pytest.approx(0.0, abs=1e-12) and np.isnan(err[0, 1])
    assert chromaticity_error(np.array([1.1, 1.0, 0.9]), np.ones(3)) == pytest.approx(
        np.sqrt(0.02) / np.sqrt(3)
    )


def test_display_image():
    p = np.array([[[3.0, 0.0, 0.0], [1.0, 1.0, 1.0], [np.nan, np.nan, np.nan]]])
    np.testing.assert_allclose(chromaticity_rgb(p), [[[1, 0, 0], [1, 1, 1], [0, 0, 0]]])


# ------------------------------------------------------------------------------ tiny dataset


def _tiny_copy(tiny_dataset, tmp_path):
    copy = tmp_path / "ds"
    shutil.copytree(tiny_dataset, copy)
    return copy


@pytest.mark.parametrize("obj", ["statue", "toy"])
def test_tiny_maps_match_ground_truth(tiny_dataset, tmp_path, obj):
    out = tmp_path / "calib" / "chromaticity" / f"{obj}.h5"
    png = tmp_path / "calib" / "chromaticity" / f"{obj}.png"
    result = chromaticity_maps(tiny_dataset, obj, out)
    maps = result.maps
    chromaticity_figure(result.intensity, maps, png, title=obj, intensity_label=result.camera)
    ds = open_dataset(tiny_dataset)
    assert list(maps) == list(ds.rig.camera_names)
    assert sorted(p.name for p in out.parent.iterdir()) == [f"{obj}.h5", f"{obj}.png"]
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with (
        h5py.File(out) as f,
        h5py.File(tiny_dataset / "scenes" / obj / "gt" / "chromaticity.h5") as g,
    ):
        assert f.attrs["normalisation"] == NORMALISATION
        assert f.attrs["min_signal"] == 0.01
        inputs = json.loads(f.attrs["inputs"])
        assert len(inputs) == 3 * 7  # per camera: 3 object, 3 white captures and a silhouette
        assert f"chromatic/{obj}/red/cam1.png" in inputs
        assert len(f.attrs["inputs_sha256"]) == 64
        for cam, p in maps.items():
            stored = f[cam][...]
            assert stored.dtype == np.float32 and stored.shape == (120, 160, 3)
            np.testing.assert_array_equal(stored, p)
            assert f[cam].attrs["mask"] == f"scenes/{obj}/masks/000000/{cam}.png"
            valid = np.isfinite(p).all(axis=-1)
            # float32 sums: measured 8e-8 relative
            np.testing.assert_allclose(p[valid].sum(axis=-1), 3.0, rtol=2e-7)
            silhouette = read_mask(object_silhouette(ds, obj, cam), ds.rig.image)
            assert not (valid & ~silhouette).any()
            truth = g[cam][...]
            err = chromaticity_error(p, truth)
            lit = np.isfinite(err)
            assert lit.sum() > 0.6 * np.isfinite(truth[..., 0]).sum()
            assert np.median(err[lit]) < TINY_MEDIAN_BOUND, (obj, cam)


def test_sigma_of_log_p_is_calibrated_against_the_truth(tiny_dataset, tmp_path):
    """Beyond the paper: with the rig's noise model (colourhs noise) the maps carry each
    band's sigma of log p (:func:`log_sigma`), and the errors of log p against the
    ground truth, in the map's own gauge (:func:`log_sigma_coverage`), fall within 1, 2
    and 3 of their sigma as often as a Gaussian's would (0.68, 0.95, 0.997) on the
    statue, whose map without noise is its albedo (RMS log 0.0013) and whose error is
    shot noise. Measured over the three cameras: 0.683, 0.956, 0.998 (sigma median
    0.015). The toy: :func:`test_the_toys_error_bar_is_its_noise_not_its_model_error`."""
    from colourhs.calibration.noise import calibrate_noise

    obj = "statue"

    noise = tmp_path / "noise.json"
    calibrate_noise(tiny_dataset, noise)
    out = tmp_path / f"{obj}.h5"
    maps = chromaticity_maps(tiny_dataset, obj, out, noise_json=noise).maps
    est, true, sig = [], [], []
    with (
        h5py.File(out) as f,
        h5py.File(tiny_dataset / "scenes" / obj / "gt" / "chromaticity.h5") as g,
    ):
        assert f.attrs["noise_model"].startswith(str(noise))
        for cam, p in maps.items():
            sigma = f[f"sigma/{cam}"][...]
            assert sigma.dtype == np.float32 and sigma.shape == p.shape
            np.testing.assert_array_equal(np.isfinite(sigma), np.isfinite(p))
            est.append(p)
            true.append(g[cam][...])
            sig.append(sigma)
    median, within = log_sigma_coverage(*(np.concatenate(x) for x in (est, true, sig)))
    print(obj, "sigma median", median, "within 1/2/3", within)
    assert 0.64 < within[0] < 0.72 and within[1] > 0.93 and within[2] > 0.99
    # The map's error bar only: a reconstruction reads the same frame with it or without.
    from colourhs.reconstruct.inputs import load_frame

    plain = tmp_path / f"{obj}_plain.h5"
    chromaticity_maps(tiny_dataset, obj, plain)
    a = load_frame(tiny_dataset, obj, "000000", chromaticity_h5=out, noise_json=noise)
    b = load_frame(tiny_dataset, obj, "000000", chromaticity_h5=plain, noise_json=noise)
    np.testing.assert_array_equal(a.variance, b.variance)
    np.testing.assert_array_equal(a.chroma, b.chroma)


def test_the_toys_error_bar_is_its_noise_not_its_model_error(tiny_dataset, tmp_path):
    """Beyond the paper: the toy's map misses its albedo beyond its error bar, and the
    misses are the map's own definition, not its noise. Eq. (12) gives the chromaticity
    "under white light of our definition", the object's response to each light from the
    chromatic captures' geometry (the paper: it "may not exactly correspond to the
    absolute objects colours"): the toy's white specular lobe and its mirror disc add to
    a pure colour's dark band where the albedo has almost none. The same captures
    without sensor noise give the map that definition asks for; against it the error
    bar, which is the sensor noise's (:func:`log_sigma`), is a Gaussian's. Measured
    (three cameras): against the noise-free map 0.684, 0.955, 0.997 within 1, 2, 3
    sigma; against the albedo 0.656, 0.921, 0.964, the noise-free map itself RMS log
    0.096 from the albedo (the statue's 0.0013)."""
    from colourhs.calibration.chromaticity import log_ratio_rms
    from colourhs.calibration.noise import calibrate_noise
    from colourhs.synth.synthesise import noise_free_chromatic

    noise = tmp_path / "noise.json"
    calibrate_noise(tiny_dataset, noise)
    noisy = chromaticity_maps(tiny_dataset, "toy", tmp_path / "toy.h5", noise_json=noise).maps
    noise_free = noise_free_chromatic(tiny_dataset, tmp_path, "tiny", scenes=("toy",), workers=1)
    exact = chromaticity_maps(noise_free, "toy", tmp_path / "exact.h5").maps
    with (
        h5py.File(tmp_path / "toy.h5") as f,
        h5py.File(tiny_dataset / "scenes" / "toy" / "gt" / "chromaticity.h5") as g,
    ):
        sigma = np.concatenate([f[f"sigma/{cam}"][...] for cam in noisy])
        albedo = np.concatenate([g[cam][...] for cam in noisy])
    est, ref = (np.concatenate(list(m.values())) for m in (noisy, exact))
    _, against_exact = log_sigma_coverage(est, ref, sigma)
    _, against_albedo = log_sigma_coverage(est, albedo, sigma)
    model = log_ratio_rms(ref, albedo)
    print("within 1/2/3 sigma: exact", against_exact, "albedo", against_albedo, "model", model)
    assert 0.64 < against_exact[0] < 0.72 and against_exact[1] > 0.93
    assert against_exact[2] > 0.99
    # The albedo: the model's error, which no sensor noise explains, misses the bar.
    assert against_albedo[2] < 0.975 and 0.08 < model < 0.12


def test_saturated_and_dark_pixels_are_masked(tiny_dataset, tmp_path):
    copy = _tiny_copy(tiny_dataset, tmp_path)
    ds = open_dataset(copy)
    before = chromaticity_map(ds, "toy", "cam2")
    ys, xs = np.nonzero(np.isfinite(before[..., 0]))
    y, x = ys[len(ys) // 2], xs[len(xs) // 2]
    path = copy / "chromatic" / "toy" / "blue" / "cam2.png"
    raw = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    raw[y, x, 2] = ds.rig.image.white_level  # saturate the red channel (BGR) under blue light
    cv2.imwrite(str(path), raw)
    after = chromaticity_map(ds, "toy", "cam2")
    assert np.isnan(after[y, x]).all()
    same = np.ones(before.shape[:2], bool)
    same[y, x] = False
    np.testing.assert_array_equal(after[same], before[same])
    # A higher signal floor masks more pixels, and only pixels valid before.
    strict = np.isfinite(chromaticity_map(ds, "toy", "cam2", min_signal=0.05)[..., 0])
    assert 0 < strict.sum() < np.isfinite(after[..., 0]).sum()
    assert not (strict & ~np.isfinite(after[..., 0])).any()


def test_without_silhouettes_a_threshold_finds_the_object(tiny_dataset, tmp_path):
    copy = _tiny_copy(tiny_dataset, tmp_path)
    ds = open_dataset(copy)
    with_masks = chromaticity_map(ds, "toy", "cam1")
    shutil.rmtree(copy / "scenes" / "toy" / "masks")
    ds = open_dataset(copy)
    assert object_silhouette(ds, "toy", "cam1") is None
    maps = chromaticity_maps(ds, "toy", tmp_path / "toy.h5").maps
    with h5py.File(tmp_path / "toy.h5") as f:
        assert f["cam1"].attrs["mask"].startswith("threshold")
    a = np.isfinite(with_masks[..., 0])
    b = np.isfinite(maps["cam1"][..., 0])
    assert (a & b).sum() > 0.95 * a.sum()
    # partly covered edge pixels only: measured 12 of 2042 (0.6 %)
    assert (b & ~a).sum() < 0.012 * a.sum()
    np.testing.assert_allclose(maps["cam1"][a & b], with_masks[a & b])


# ------------------------------------------------------------------------------ errors


def test_unknown_object_or_camera(tiny_dataset, tmp_path):
    out = tmp_path / "x.h5"
    with pytest.raises(CaptureFormatError, match="chromatic object 'slinky' not in the dataset"):
        chromaticity_maps(tiny_dataset, "slinky", out)
    ds = open_dataset(tiny_dataset)
    with pytest.raises(CaptureFormatError, match="slinky"):
        chromaticity_map(ds, "slinky", "cam1")
    with pytest.raises(KeyError, match="cam9"):
        chromaticity_map(ds, "toy", "cam9")
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_missing_colour_capture_names_the_file(tiny_dataset, tmp_path):
    copy = _tiny_copy(tiny_dataset, tmp_path)
    ds = open_dataset(copy)
    missing = copy / "chromatic" / "toy" / "green" / "cam2.png"
    missing.unlink()
    with pytest.raises(CaptureFormatError, match="green light") as err:
        chromaticity_map(ds, "toy", "cam2")
    assert err.value.path == missing
    out = tmp_path / "out" / "toy.h5"
    with pytest.raises(CaptureFormatError) as err:
        chromaticity_maps(copy, "toy", out)
    assert str(missing) in str(err.value)
    assert not out.exists()


def test_all_samples_masked_leaves_no_output(tiny_dataset, tmp_path):
    out = tmp_path / "toy.h5"
    out.write_bytes(b"previous result")
    with pytest.raises(ValueError, match="all samples masked") as err:
        chromaticity_maps(tiny_dataset, "toy", out, min_signal=1.5)
    assert "toy" in str(err.value) and "cam1" in str(err.value)
    assert out.read_bytes() == b"previous result"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["toy.h5"]


def test_command_draws_the_figure_and_leaves_neither_file_when_it_fails(tiny_dataset, tmp_path):
    """The figure is the command's (calibration modules do not import figures): written
    beside the maps; a figure that cannot be written removes the maps too."""
    from colourhs.cli.parser import main

    out, png = tmp_path / "toy.h5", tmp_path / "toy.png"
    assert main(["chromaticity", str(tiny_dataset), "toy", str(out), "--figure", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.exists()
    blocked = tmp_path / "file"
    blocked.write_text("a file, not a folder")
    out2 = tmp_path / "toy2.h5"
    fig = str(blocked / "toy.png")
    assert main(["chromaticity", str(tiny_dataset), "toy", str(out2), "--figure", fig]) == 1
    assert not out2.exists() and not any(p.name.startswith(".toy") for p in tmp_path.iterdir())
