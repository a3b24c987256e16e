"""The sensor noise model (colourhs.calibration.noise) against known answers."""

from __future__ import annotations

import numpy as np
import pytest

from colourhs.calibration.noise import (
    NoiseModel,
    estimate_noise,
    fit_affine_noise,
    neighbour_residuals,
)


def _shaded(rng, h=240, w=320):
    """A smooth shading (a tilted quadratic), like a lit board: locally linear."""
    y, x = np.mgrid[0:h, 0:w] / max(h, w)
    return 0.15 + 0.6 * x + 0.2 * y - 0.3 * (x - 0.5) ** 2


@pytest.mark.parametrize("full_well, read_e", [(8000.0, 2.0), (20000.0, 10.0)])
def test_affine_noise_recovered_from_smooth_images(full_well, read_e):
    """Shot plus read noise: var = i / full_well + (read / full_well)^2.

    Measured: gain within 3.2 % of 1 / full_well; the offset is weakly
    determined where shot noise dominates (0 to 5x the truth), but the
    predicted variance at 10 % and 50 % of full scale is within 2.4 %.
    """
    rng = np.random.default_rng(3)
    clean = np.stack([_shaded(rng) * f for f in (1.0, 0.8, 0.6)], axis=-1)
    images = []
    for _ in range(4):
        e = rng.poisson(clean * full_well) + rng.normal(0, read_e, clean.shape)
        images.append(e / full_well)
    gain, offset = estimate_noise(images)
    assert np.allclose(gain, 1 / full_well, rtol=0.04)
    for i in (0.1, 0.5):
        truth = i / full_well + (read_e / full_well) ** 2
        assert np.allclose(gain * i + offset, truth, rtol=0.04)


@pytest.mark.parametrize("full_well, read_e", [(5000.0, 9.0), (15000.0, 3.0)])
def test_8_bit_noise_recovered_despite_the_quantised_residuals(full_well, read_e):
    """8-bit data of the renderer's sensor (black 2, white 255): a residual is a multiple
    of a quarter step, so a bin's MAD moves by whole quarter steps unless each residual
    is spread over its own (``fit_affine_noise``'s ``floor``). Measured: the predicted
    variance at 10, 30 and 50 % of full scale within 5.3 % of the truth (the quantisation's
    in it); 15.4 % with the MADs of the raw residuals."""
    from colourhs.calibration.noise import quantisation_variance
    from colourhs.synth.simulated_rig import Nuisances, sensor

    rng = np.random.default_rng(3)
    clean = np.stack([_shaded(rng) * f for f in (1.0, 0.8, 0.6)], axis=-1)
    nuisances = Nuisances(full_well_e=full_well, read_noise_e=read_e)
    images = [(sensor(clean, rng, nuisances, 8, 2, 255) - 2.0) / 253.0 for _ in range(4)]
    floor = quantisation_variance(2, 255)
    gain, offset = estimate_noise(images, floor)
    for i in (0.1, 0.3, 0.5):
        truth = i / full_well + (read_e / full_well) ** 2 + floor
        assert np.allclose(gain * i + offset, truth, rtol=0.065)


def test_the_renders_noise_is_found_beside_the_boards_markers(tiny_dataset, monkeypatch):
    """The noise model of the tiny preset (160 x 120, whose board markers and outlines
    make edges of a large share of the lit pixels) against the renderer's sensor
    (``gt/rig_model.json``: full well and read noise). Measured, every camera and
    channel, the predicted variance over the truth: 0.965-1.017 at 20 % and 50 % of full
    scale, 0.962-1.038 at 3 %, 0.926-1.145 at 1 %, where the fit has the fewest bins
    (each pixel binned at its own noisy level: 0.944-0.971, 0.928-0.955, 0.893-0.947);
    1.08-1.16 at 20 % and 50 % from the fit of every pixel (no structure masked), which
    the MAD cannot hold against that many edges (1.3-1.7 binned at its own level)."""
    import json

    import colourhs.calibration.noise as noise

    gt = json.loads((tiny_dataset / "gt" / "rig_model.json").read_text())["nuisances"]
    spec = json.loads((tiny_dataset / "rig.json").read_text())["image"]
    floor = noise.quantisation_variance(spec["black_level"], spec["white_level"])

    def ratios(model, levels):
        out = []
        for i in levels:
            truth = i / gt["full_well_e"] + (gt["read_noise_e"] / gt["full_well_e"]) ** 2 + floor
            for cam in model.gain:
                out.extend((model.gain[cam] * i + model.offset[cam]) / truth)
        return np.array(out)

    model = noise.calibrate_noise(tiny_dataset)
    bright, dim, dark = ratios(model, (0.2, 0.5)), ratios(model, (0.03,)), ratios(model, (0.01,))
    print("masked", [(r.min(), r.max()) for r in (bright, dim, dark)])
    assert 0.95 < bright.min() and bright.max() < 1.03
    assert 0.95 < dim.min() and dim.max() < 1.05
    assert 0.9 < dark.min() and dark.max() < 1.17
    monkeypatch.setattr(noise, "STRUCTURE_ROUNDS", 0)
    unmasked = ratios(noise.calibrate_noise(tiny_dataset), (0.2, 0.5))
    print("unmasked", unmasked.min(), unmasked.max())
    assert unmasked.min() > 1.06


def test_neighbour_residual_is_zero_on_linear_images():
    y, x = np.mgrid[0:20, 0:30].astype(float)
    assert np.allclose(neighbour_residuals(0.1 + 0.01 * x - 0.02 * y), 0.0)


def test_too_few_pixels_is_an_error():
    with pytest.raises(ValueError, match="usable pixels"):
        fit_affine_noise(np.full(10, 0.5), np.zeros(10))


def test_variance_of_the_model():
    m = NoiseModel({"a": np.array([1e-4, 2e-4, 3e-4])}, {"a": np.array([1e-6, 0, 0])})
    img = np.full((2, 2, 3), 0.5)
    assert np.allclose(m.variance("a", img)[0, 0], [0.5e-4 + 1e-6, 1e-4, 1.5e-4])
    # One channel's intensities alone: that channel's gain and offset.
    one = np.array([[0.5, -0.1], [0.2, 1.0]])
    np.testing.assert_allclose(
        m.variance("a", one, channel=0), [[0.5e-4 + 1e-6, 1e-6], [0.2e-4 + 1e-6, 1e-4 + 1e-6]]
    )
    np.testing.assert_allclose(m.variance("a", one, channel=2), 3e-4 * np.clip(one, 0, None))


def test_noise_free_captures_give_the_quantisation_floor():
    """Images with no noise but rounding, evenly lit (a synthetic capture with
    noise, vignetting and light fall-off off: the nuisance ladder's 'none'
    rung): every bin's spread is 0, and the fit failed with a NaN in its least
    squares. With the quantisation's variance as a floor the model is that
    floor; without one it is a clear error, although the panels' edges, binned at
    their diagonal neighbours' level between two panels, have a spread."""
    from colourhs.calibration.noise import quantisation_variance

    white = 255.0
    y, x = np.mgrid[0:240, 0:320]
    levels = np.where(x < 100, 0.2, np.where(x < 200, 0.45, 0.7))  # three flat panels
    clean = np.stack([levels * f for f in (1.0, 0.9, 0.8)], axis=-1)
    images = [np.round(clean * white) / white] * 2
    floor = quantisation_variance(0.0, white)
    assert floor == pytest.approx(1 / (12 * white**2))
    with pytest.raises(ValueError, match="no measurable noise"):
        estimate_noise(images)
    gain, offset = estimate_noise(images, floor)
    for i in (0.2, 0.7):
        assert np.allclose(gain * i + offset, floor, rtol=1e-6)


def test_an_image_that_is_structure_throughout_keeps_the_fit_of_every_pixel(monkeypatch):
    """A noise-free image textured everywhere (a scene frame rendered exact, rounded to
    16 bit): the mask calls nearly every pixel structure, and a fit of the few left
    would stand for nothing (on the exact statue's frames it kept 1-3 % of the lit pixels
    and moved the depth's signed median from -0.024 to -0.075 mm). Below
    ``MIN_KEPT_SHARE`` the fit of every pixel stays. Here a smooth corner of 6 % is
    left, whose fit is the rounding alone (the floor; the texture's own fit is millions
    of times that)."""
    import cv2

    import colourhs.calibration.noise as noise

    rng = np.random.default_rng(5)
    texture = 0.45 + 2.0 * cv2.GaussianBlur(rng.random((120, 160)) - 0.5, (0, 0), 1.5)
    texture[:30, :40] = np.linspace(0.3, 0.6, 40)  # 6 % of it smooth shading
    clean = np.stack([texture * f for f in (1.0, 0.8, 0.6)], axis=-1)
    images = [np.round(clean * 65023) / 65023]
    floor = noise.quantisation_variance(512, 65535)
    gain, offset = noise.estimate_noise(images, floor)
    monkeypatch.setattr(noise, "STRUCTURE_ROUNDS", 0)
    np.testing.assert_array_equal(noise.estimate_noise(images, floor), (gain, offset))
    monkeypatch.setattr(noise, "STRUCTURE_ROUNDS", 2)
    monkeypatch.setattr(noise, "MIN_KEPT_SHARE", 0.0)
    masked = noise.estimate_noise(images, floor)  # the rounding of the smooth corner alone
    assert np.all(masked[0] * 0.5 + masked[1] < 0.1 * (gain * 0.5 + offset))


def test_a_dim_channel_is_read_at_its_noise_where_its_levels_begin():
    """A channel whose levels begin at 2.5 % of full scale (a dark band's cross-talk, a
    dim corner): binned at each pixel's own noisy level, the lowest bins hold the
    pixels whose noise lifted them in, and read low (0.88-0.95 of the sensor's
    variance at 3 % and 5 %); binned at the diagonal neighbours' level, which shares
    none of the residual's noise, 0.97-1.03. Read noise is a third of the variance at
    3 %, so a low offset would show."""
    from colourhs.calibration.noise import quantisation_variance

    rng = np.random.default_rng(3)
    full_well, read_e = 5000.0, 15.0
    y, x = np.mgrid[0:240, 0:320]
    base = 0.025 + 0.06 * (x / 320) ** 2 + 0.01 * np.sin(y / 30.0)
    clean = np.stack([base * 8, base, base * 1.5], axis=-1)
    images = []
    for _ in range(4):
        sigma = np.sqrt(clean / full_well + (read_e / full_well) ** 2)
        images.append(np.round((clean + sigma * rng.normal(size=clean.shape)) * 65535) / 65535)
    gain, offset = estimate_noise(images, quantisation_variance(0, 65535))
    for i in (0.03, 0.05):
        ratio = (gain * i + offset) / (i / full_well + (read_e / full_well) ** 2)
        print(i, ratio)
        assert np.all((0.95 < ratio) & (ratio < 1.05)), (i, ratio)
