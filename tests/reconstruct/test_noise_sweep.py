"""Sensor noise widens the scatter but must not move the depth, and the error bar
must cover what it does to the depth: a noise sweep on a corner rig.

One ``corner-tiny`` rig (12-15 degree camera pairs, a board slanted 40-50
degrees to the reference camera, 5,000-8,000 e- full well, strong barrel
distortion) at 320x240, its plane rendered without noise and cross-talk,
the true calibration (gt/photometric.h5); the lights collocated (a light
beside its lens breaks Helmholtz reciprocity on glossy surfaces and makes
mu depend on depth, which is not what this measures). The
sensor noise is then added as the renderer makes it (Poisson electrons
and Gaussian read noise, :func:`colourhs.synth.simulated_rig.sensor`) with the noise
scaled by k = 0.5, 1, 2 and 4 (full well / k^2, read noise / k), three
realisations per level, and the noise model given exactly.
"""

from __future__ import annotations

import copy
import json
from dataclasses import replace

import numpy as np
import pytest
from capture_helpers import render_exact

from colourhs.common.ply import load_mesh
from colourhs.common.raycast import render_depth_normals
from colourhs.reconstruct.frame import load_frame, reconstruct
from colourhs.synth.randomranges import RANGES_BY_NAME
from colourhs.synth.synthesise import PRESETS

LEVELS = (0.5, 1.0, 2.0, 4.0)
REALISATIONS = 3


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    """Per level k (0: the exact render): a list of (signed median error, median
    sigma, |error| / sigma per pixel) over the realisations, millimetres."""
    name = "noise-sweep"
    ranges = replace(RANGES_BY_NAME["corner-tiny"], light_offset_m=(0.0, 0.0))
    preset = replace(
        PRESETS["corner-tiny"],
        name=name,
        width=320,
        height=240,
        supersample=2,
        n_poses=3,
        sheet_frames=1,
        random_ranges=name,
    )
    root = tmp_path_factory.mktemp("sweep") / "d"
    RANGES_BY_NAME[name] = ranges
    try:
        render_exact(root, preset, 0, ("plane",))
    finally:
        del RANGES_BY_NAME[name]
    model = json.loads((root / "gt" / "rig_model.json").read_text())["nuisances"]
    exact = load_frame(root, "plane", "000000", photometric_h5=root / "gt" / "photometric.h5")
    ref = exact.rig.cameras[0]
    truth, _ = render_depth_normals(*load_mesh(root / "scenes/plane/gt/000000.ply"), ref, 320, 240)
    out = {}
    for k in (0.0, *LEVELS):
        rows = []
        for r in range(REALISATIONS if k else 1):
            frame = copy.copy(exact)
            if k:
                rng = np.random.default_rng(r)
                well, read = model["full_well_e"] / k**2, model["read_noise_e"] / k
                i = np.clip(exact.images.astype(float), 0, None)
                noisy = (rng.poisson(i * well) + rng.normal(0, read, i.shape)) / well
                frame.images = noisy.astype(exact.images.dtype)
                var = np.clip(frame.images, 0, None) / well + (read / well) ** 2
                frame.variance = var.astype(np.float32)
            res = reconstruct(frame, "bayes")
            m = res.mask & np.isfinite(truth)
            err = (res.depth[m] - truth[m]) * 1e3
            sigma = res.depth_sigma[m] * 1e3
            assert m.sum() > 0.85 * np.isfinite(truth).sum()  # measured 0.91-0.95
            rows.append((float(np.median(err)), float(np.median(sigma)), np.abs(err) / sigma))
            print(f"k {k} r {r}: signed {rows[-1][0]:.4f} mm, sigma {rows[-1][1]:.4f} mm")
        out[k] = rows
    return out


def test_noise_moves_the_scatter_not_the_expectation(sweep):
    """Measured (signed median per realisation, mm; mean sigma): exact 0.013
    (0.11); k 0.5: 0.332, 0.118, 0.309 (0.82); k 1: -0.067, 0.007, -0.116
    (1.30); k 2: 0.073, -0.246, -0.698 (1.09); k 4: 0.410, -0.186, 0.292 (1.75).

    Exact data: within 0.1 mm (its sigma 0.09 mm: on this corner the
    plane's depth is weakly determined even without noise). Under noise the
    plane's depth along the ray (the one mode E fixes weakly on a uniform
    board) scatters between realisations by up to a millimetre at these
    full wells. Its offset
    stays within its own error bar: every realisation within two of its
    sigmas (measured at most 0.60), and each level's mean within 0.05 mm
    plus two standard errors that the sigmas predict for a mean of three.
    """
    (exact,) = sweep[0.0]
    assert abs(exact[0]) < 0.1
    for k in LEVELS:
        signed = np.array([row[0] for row in sweep[k]])
        sigma = np.array([row[1] for row in sweep[k]])
        assert np.all(np.abs(signed) <= 2 * sigma), (k, signed, sigma)
        assert abs(signed.mean()) <= 0.05 + 2 * sigma.mean() / np.sqrt(len(signed)), (k, signed)
    # The error bar widens with the noise.
    mean_sigma = {k: np.mean([row[1] for row in sweep[k]]) for k in sweep}
    assert mean_sigma[0.0] < mean_sigma[1.0] < mean_sigma[4.0], mean_sigma


def test_depth_sigma_covers_the_errors(sweep):
    """The shares of pixels within 1, 2 and 3 sigma of the truth, pooled over the
    noisy levels: measured 0.627, 0.903, 0.982, against 0.683, 0.954, 0.997 for
    a calibrated Gaussian error (the target: within 0.1 of each)."""
    ratio = np.concatenate([row[2] for k in LEVELS for row in sweep[k]])
    within = np.array([np.mean(ratio <= c) for c in (1, 2, 3)])
    assert np.all(np.abs(within - [0.683, 0.954, 0.997]) < [0.08, 0.08, 0.03]), within
