"""Exact data gives exact answers: random rigs, noise and
cross-talk off, the true calibration (gt/photometric.h5).

Every other nuisance stays on (LED profiles, vignetting and colour shading,
16 bit with a black level, exact masks), since the true mu maps undo them.
Five random rigs (the random-tiny ranges at 320x240, 3 board poses), the
plane and the sheet; ML and Bayesian HS against the rendered ground truth;
and one rig's statue, a curved object.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from capture_helpers import render_exact
from hs_constraint import numpy_data_term

from colourhs.common.ply import load_mesh
from colourhs.common.raycast import render_depth_normals
from colourhs.reconstruct.frame import load_frame, reconstruct
from colourhs.synth.synthesise import PRESETS

EXACT = replace(
    PRESETS["random-tiny"],
    name="exact",
    width=320,
    height=240,
    supersample=2,
    n_poses=3,
    sheet_frames=1,
)
SEEDS = (1, 2, 3, 4, 5)
#: Seed 5's rig has lenses beyond the others' (one camera model end to
#: end): a skew of up to 1 % of f and 12 distortion coefficients (rational k4-k6,
#: thin prism s1-s4; the ranges ``random-tiny-lens``).
LENS_SEED = 5
#: ML HS runs on the plane of three of the rigs (the lens rig, the worst and the
#: best ML plane of the five measured below), for the suite's 15 minutes: each ML
#: pass costs about 12 s.
ML_SEEDS = (1, 3, LENS_SEED)


@pytest.fixture(scope="module")
def exact_rigs(tmp_path_factory):
    """The five rigs' datasets (plane and sheet only)."""
    out = {}
    for seed in SEEDS:
        root = tmp_path_factory.mktemp(f"exact{seed}") / "d"
        preset = replace(EXACT, random_ranges="random-tiny-lens") if seed == LENS_SEED else EXACT
        render_exact(root, preset, seed, ("plane", "sheet"))
        out[seed] = root
    cams = load_frame(out[LENS_SEED], "plane", "000000").rig.cameras
    assert all(len(c.dist) == 12 and abs(c.K[0, 1]) > 0 for c in cams)
    return out


@pytest.fixture(scope="module")
def reconstructed():
    """The module's reconstructions of the rigs' frames with the true mu, each made
    once: (root, scene, method) -> (frame, result)."""
    return {}


def _reconstruction(reconstructed, root, scene, method):
    key = (root, scene, method)
    if key not in reconstructed:
        fr = load_frame(root, scene, "000000", photometric_h5=root / "gt" / "photometric.h5")
        reconstructed[key] = fr, reconstruct(fr, method)
    return reconstructed[key]


def _errors(reconstructed, root, scene, method):
    fr, res = _reconstruction(reconstructed, root, scene, method)
    ref = fr.rig.camera(res.info["reference"])
    v, t, n = load_mesh(root / "scenes" / scene / "gt" / "000000.ply")
    gd, gn = render_depth_normals(v, t, n, ref, fr.rig.image.width, fr.rig.image.height)
    m = res.mask & np.isfinite(gd)
    signed = (res.depth[m] - gd[m]) * 1e3
    ang = np.degrees(np.arccos(np.clip(np.sum(res.normal[m] * gn[m], axis=1), -1, 1)))
    cov = m.sum() / np.isfinite(gd).sum()
    return float(np.median(np.abs(signed))), float(np.median(ang)), cov, float(np.median(signed))


@pytest.mark.parametrize("scene", ["plane", "sheet"])
def test_exact_data_exact_answers(exact_rigs, reconstructed, scene):
    """Measured (depth median mm / normal median deg, seeds 1-5; seed 5 the
    skewed rational thin-prism lenses):

    - Bayesian HS: plane 0.011, 0.011, 0.035, 0.013, 0.008 mm, sheet
      0.019, 0.011, 0.008, 0.009, 0.019 mm; normals <= 0.061 deg; coverage
      0.89-0.96 (before E compared each pixel's rows with its pixel normal
      instead of its four triangles' normals: plane 0.008-0.032, sheet
      0.012-0.026 mm, normals <= 0.075 deg) (seed 1's board reaches 209 mm in front of the fixation
      point: with the former fixed +-0.15 m depth range 34 % of it was out
      of range; its median was 0.037, seed 2's 0.035 before the search's
      third parabola). The targets' 0.05 mm and 0.3 deg: every case.
    - ML HS: plane 0.063, 0.105, 0.108, 0.066, 0.025 mm (was 0.41 on seed 1
      with the fixed range: the true root was out of range on a third of
      the board), sheet 0.09-0.27 mm (earlier seeds); normals <= 0.05 deg.
      A pixel's own root moves by ~0.1 mm under image errors of 1e-4
      (interpolation, the renderer's pixel integration): the target's
      0.05 mm is not reached by ML.
    - Bayesian never worse than ML: every case.
    - No bias: signed medians, Bayesian plane -0.009, 0.010, 0.031,
      0.013, 0.008 mm, sheet 0.017, 0.001, 0.002, 0.001, 0.007 mm; ML plane
      -0.006, 0.023, 0.008 mm. The project holds ML on exact data to
      |signed median| <= 0.05 mm and a median within 0.15 mm (its narrow-baseline
      corner rigs are reported by benchmarks/generalisation.py, not held).

    ML runs on the plane of ``ML_SEEDS`` only (the sheet's ML, 0.09-0.27 mm, was
    measured above, every seed worse than Bayesian): the suite stays under 15
    minutes.
    """
    rows = []
    for seed, root in exact_rigs.items():
        bayes = _errors(reconstructed, root, scene, "bayes")
        with_ml = scene == "plane" and seed in ML_SEEDS
        ml = _errors(reconstructed, root, scene, "ml") if with_ml else (np.inf, np.inf, 1.0, 0.0)
        print(f"seed {seed} {scene}: bayes {bayes} ml {ml}")
        rows.append(bayes + ml)
    b_mm, b_deg, b_cov, b_signed, m_mm, m_deg, _, m_signed = np.array(rows).T
    assert np.all(b_mm <= m_mm)
    assert np.median(b_mm) < 0.02  # measured 0.011 (plane), 0.011 (sheet)
    assert b_mm.max() < 0.045  # measured 0.035 (plane), 0.019 (sheet)
    assert b_deg.max() < 0.08 and b_cov.min() > 0.85  # measured 0.061 deg, 0.89
    assert np.abs(b_signed).max() < 0.04  # measured 0.031 (plane), 0.017 (sheet)
    if scene == "plane":
        m_mm, m_deg = m_mm[np.isfinite(m_mm)], m_deg[np.isfinite(m_deg)]
        assert len(m_mm) == len(ML_SEEDS)
        assert np.median(m_mm) < 0.1 and m_mm.max() < 0.15  # measured 0.063, 0.108
        assert np.abs(m_signed).max() <= 0.05  # measured 0.023 (0 where ML did not run)
        assert m_deg.max() < 0.07  # measured 0.032 (0.046 before)


@pytest.fixture(scope="module")
def exact_statue(tmp_path_factory):
    """Rig 1's statue (glossy plaster with dirt), exact as above, with its true
    chromaticity; plane and sheet are flat or gently curved, the statue is not."""
    root = tmp_path_factory.mktemp("exact_statue") / "d"
    render_exact(root, EXACT, 1, ("statue",), ("photometric", "scenes", "chromatic"))
    return root


def _statue_errors(root):
    """Signed depth errors (mm) and normal errors (deg) of the statue's Bayesian HS
    with the true mu and chromaticity, and its coverage."""
    fr = load_frame(
        root,
        "statue",
        "000000",
        photometric_h5=root / "gt" / "photometric.h5",
        chromaticity_h5=root / "scenes" / "statue" / "gt" / "chromaticity.h5",
    )
    res = reconstruct(fr, "bayes")
    ref = fr.rig.camera(res.info["reference"])
    v, t, n = load_mesh(root / "scenes" / "statue" / "gt" / "000000.ply")
    gd, gn = render_depth_normals(v, t, n, ref, fr.rig.image.width, fr.rig.image.height)
    m = res.mask & np.isfinite(gd)
    err = (res.depth[m] - gd[m]) * 1e3
    ang = np.degrees(np.arccos(np.clip(np.sum(res.normal[m] * gn[m], axis=1), -1, 1)))
    return err, ang, m.sum() / np.isfinite(gd).sum()


def test_exact_curved_object(exact_statue):
    """A curved object on exact data: Bayesian HS within a fraction of a millimetre.

    E compares each pixel's eq. (5) rows, sampled at the pixel's point, with
    the depth map's normal at that pixel (central differences). It compared
    them with the normals of the pixel's four triangles, which on a surface
    of radius r lie ~ footprint / (3 r) either side of it: a floor of E that
    shrinks as the surface flattens, so E preferred flatter surfaces, moved
    towards the camera. Measured on this statue (depth median |error|,
    signed median, normal median): 0.61 mm, -0.61 mm, 1.19 deg before; 0.098
    mm, -0.026 mm, 0.42 deg after (benchmark probes at 320x240, the true
    calibration: other rigs' statues 1.60 -> 0.23 and 1.60 -> 0.26 mm, a
    white Lambertian ellipsoid 6.3 -> 0.21 and 7.1 -> 0.18 mm). 18 s.
    """
    err, ang, cov = _statue_errors(exact_statue)
    print(f"statue: {np.median(np.abs(err)):.3f} {np.median(err):+.3f} mm {np.median(ang):.3f} deg")
    assert np.median(np.abs(err)) < 0.2  # measured 0.098 (0.61 before)
    assert abs(np.median(err)) < 0.05  # measured -0.025 (-0.026, -0.61 before)
    assert np.median(ang) < 0.7  # measured 0.42 deg (1.19 before)
    assert cov > 0.88  # measured 0.91


def _term_pair(root, scene, chroma=False, punch=None):
    """The compiled and the NumPy data term on every 7th foreground pixel, 96 hypotheses
    (``punch(chroma)``, if given, edits the (C, 3, H, W) chromaticity first)."""
    from colourhs.reconstruct.dataterm import data_term, pair_arrays, prepare_images
    from colourhs.reconstruct.frame import reference_rays, working_depth

    gt = root / "gt" / "photometric.h5"
    ch = root / "scenes" / scene / "gt" / "chromaticity.h5" if chroma else None
    fr = load_frame(
        root, scene, "000000", photometric_h5=gt if gt.exists() else None, chromaticity_h5=ch
    )
    rig, ref = fr.rig, fr.rig.cameras[0]
    rays = reference_rays(ref, rig.image.width, rig.image.height)
    pix = np.flatnonzero(fr.silhouettes[0].ravel())[::7][:2000]
    zc = working_depth(rig, ref)
    depths = np.linspace(0.75 * zc, 1.25 * zc, 96)
    pairs = pair_arrays(rig)
    p = fr.chroma if punch is None else punch(np.array(fr.chroma, np.float32))
    prep = prepare_images(
        fr.images, fr.saturated, pairs, fr.mu, p, fr.silhouettes, borrow_p=punch is not None
    )
    args = (rays[pix], ref.centre, depths, rig.cameras, prep, pairs)
    return data_term(*args), numpy_data_term(*args)


def test_compiled_data_term_equals_the_numpy_oracle(exact_rigs, tiny_dataset):
    """The numba kernel against the plain NumPy oracle (hs_constraint.numpy_data_term),
    on seed 5's skewed rational thin-prism lenses and on a chromatic toy: costs
    and normals agree to float32 where both are valid
    (the toy's costs above 0.5 differ more: the kernel's Halley iteration is
    exact to float32 below 0.6 only, by design); validity differs on 0.5 % of
    the lens rig's hypotheses (footprints that touch an unusable pixel with a
    weight rounding makes 0 or not) and 2.5 % of the toy's."""
    for root, scene, chroma, share in (
        (exact_rigs[LENS_SEED], "plane", False, 0.006),
        (tiny_dataset, "toy", True, 0.03),
    ):
        (c1, n1), (c2, n2) = _term_pair(root, scene, chroma)
        v1, v2 = c1 < 1, c2 < 1
        assert v1.sum() > 5000 and np.mean(v1 != v2) * v1.size / v1.sum() < share
        _agree(c1, n1, c2, n2)


def _agree(c1, n1, c2, n2):
    """Costs and normals of two data terms agree to float32 where both are valid
    and the cost is under 0.5."""
    good = (c1 < 0.5) & (c2 < 1)
    assert good.sum() > 1000
    assert np.abs(c1[good] - c2[good]).max() < 1e-6
    assert np.abs(n1[good] - n2[good]).max() < 6e-6


def _holes(chroma, cams):
    """``chroma`` with no p in the left half of each camera in ``cams``."""
    chroma[list(cams), :, :, : chroma.shape[-1] // 2] = np.nan
    return chroma


def _term_on_the_surface(root, scene, punch=None):
    """The compiled data term of every reference pixel whose ray meets the
    ground-truth mesh, at that point only (the ray scaled to its true depth, one
    hypothesis at 1), with the true chromaticity (edited by ``punch``), and which
    pixels the reference camera's left half holds."""
    from colourhs.reconstruct.dataterm import data_term, pair_arrays, prepare_images
    from colourhs.reconstruct.frame import reference_rays

    ch = root / "scenes" / scene / "gt" / "chromaticity.h5"
    fr = load_frame(
        root, scene, "000000", photometric_h5=root / "gt" / "photometric.h5", chromaticity_h5=ch
    )
    rig, ref = fr.rig, fr.rig.cameras[0]
    W, H = rig.image.width, rig.image.height
    v, t, n = load_mesh(root / "scenes" / scene / "gt" / "000000.ply")
    gd, _ = render_depth_normals(v, t, n, ref, W, H)
    pix = np.flatnonzero(np.isfinite(gd.ravel()))
    rays = reference_rays(ref, W, H)[pix] * gd.ravel()[pix, None]
    pairs = pair_arrays(rig)
    p = np.array(fr.chroma, np.float32)
    p = p if punch is None else punch(p)
    prep = prepare_images(fr.images, fr.saturated, pairs, fr.mu, p, fr.silhouettes, borrow_p=True)
    cost, _ = data_term(rays, ref.centre, np.ones(1), rig.cameras, prep, pairs)
    return cost[:, 0], pix % W < W // 2


def test_p_unknown_in_a_camera_is_the_reference_pixels(tiny_dataset):
    """Where a camera other than the reference has no chromaticity p, the data term takes
    the reference pixel's p (a step beyond the paper). On the chromatic toy with its
    true p, at the true surface: with the left halves of cameras 1 and 2 without p,
    13 % of the valid pixels change cost (at least as many sample a hole: before,
    all of those were invalid); 97.5 % of the valid pixels stay valid and their
    median cost does not rise (0.0480 against 0.0490). Without the reference pixel's
    p too (its left half), its pixels are invalid. The NumPy oracle agrees on every
    hypothesis of the holed data."""
    full, _ = _term_on_the_surface(tiny_dataset, "toy")
    holed, _ = _term_on_the_surface(tiny_dataset, "toy", lambda c: _holes(c, (1, 2)))
    v0, v1 = full < 1, holed < 1
    moved = np.mean((np.abs(holed - full) > 1e-6)[v0])
    kept, c0, c1 = np.mean(v1[v0]), np.median(full[v0]), np.median(holed[v1])
    print(f"sampling a hole {moved:.3f}, kept {kept:.4f}, median cost {c0:.4f} -> {c1:.4f}")
    assert moved > 0.11 and kept > 0.965 and c1 < 1.01 * c0
    both, left = _term_on_the_surface(tiny_dataset, "toy", lambda c: _holes(c, (0, 1, 2)))
    assert np.all(both[left] == 1) and np.mean(both[~left] < 1) > 0.9 * np.mean(v0[~left])
    (c1, n1), (c2, n2) = _term_pair(tiny_dataset, "toy", True, lambda c: _holes(c, (1, 2)))
    v1, v2 = c1 < 1, c2 < 1
    assert np.mean(v1 != v2) * v1.size / v1.sum() < 0.03
    _agree(c1, n1, c2, n2)


def _sides_on_the_surface(root, scene, punch, reference):
    """Eq. (5) sides sampled at the true surface points of the reference camera's
    pixels (:func:`colourhs.reconstruct.sides.sample_sides`), with the true
    chromaticity edited by ``punch``; ``reference`` as in ``helmholtz_sides``."""
    from colourhs.reconstruct.dataterm import pair_arrays
    from colourhs.reconstruct.frame import reference_rays
    from colourhs.reconstruct.sides import helmholtz_sides, sample_sides

    ch = root / "scenes" / scene / "gt" / "chromaticity.h5"
    fr = load_frame(
        root, scene, "000000", photometric_h5=root / "gt" / "photometric.h5", chromaticity_h5=ch
    )
    ref = fr.rig.cameras[0]
    W, H = fr.rig.image.width, fr.rig.image.height
    v, t, n = load_mesh(root / "scenes" / scene / "gt" / "000000.ply")
    gd, _ = render_depth_normals(v, t, n, ref, W, H)
    pix = np.flatnonzero(np.isfinite(gd.ravel()))
    rays = reference_rays(ref, W, H)[pix]
    fr = replace(fr, chroma=punch(np.array(fr.chroma, np.float32)))
    sides = helmholtz_sides(fr, fr.variance, pair_arrays(fr.rig), reference=reference)
    s, var, _, ds, _ = sample_sides(sides, ref.centre + rays * gd.ravel()[pix, None], rays)
    return s, var, ds


def test_sides_without_p_take_the_reference_pixels(tiny_dataset):
    """The ML cost's and the refinement's samples (:mod:`colourhs.reconstruct.sides`)
    follow the data term: on the chromatic toy with its true p, at the true surface,
    with the left halves of cameras 1 and 2 without p, a side there takes the
    reference pixel's p (``reference=0``): 98 % of the samples that are usable with
    every p stay usable (76 % without it). Those the fallback gives move by a median
    of 1.1 % in value, 2.5 % in variance and 14 % in their derivative along the ray:
    the reference pixel's p is one constant where the camera's own varies over the
    footprint, and near the hole's edge its blur has less support."""
    full = _sides_on_the_surface(tiny_dataset, "toy", lambda c: c, 0)
    holed = _sides_on_the_surface(tiny_dataset, "toy", lambda c: _holes(c, (1, 2)), 0)
    before = _sides_on_the_surface(tiny_dataset, "toy", lambda c: _holes(c, (1, 2)), None)
    ok = np.isfinite(full[0])
    kept, kept_before = np.mean(np.isfinite(holed[0])[ok]), np.mean(np.isfinite(before[0])[ok])
    both = ok & np.isfinite(holed[0]) & ~np.isfinite(before[0])  # the fallback's samples
    moves = [np.median(np.abs(h[both] / f[both] - 1)) for f, h in zip(full, holed, strict=True)]
    print(f"kept {kept:.3f} (without the reference {kept_before:.3f}), moves {moves}")
    assert kept > 0.95 and kept_before < 0.85 and both.sum() > 200
    assert moves[0] < 0.015 and moves[1] < 0.035 and moves[2] < 0.2


def test_holes_in_other_cameras_p_keep_the_surface(tiny_dataset):
    """Bayesian HS of the statue with its true p, and with the left halves of
    cameras 1 and 2 without p (a tracked map's holes): the reference pixels' p
    (data term and refinement) keep the coverage (0.830 against 0.828; 0.38
    before, when every depth whose point met a hole was invalid) at 3.55 mm
    against 2.90 mm."""
    root = tiny_dataset
    ch = root / "scenes" / "statue" / "gt" / "chromaticity.h5"
    fr = load_frame(
        root, "statue", "000000", photometric_h5=root / "gt" / "photometric.h5", chromaticity_h5=ch
    )
    v, t, n = load_mesh(root / "scenes" / "statue" / "gt" / "000000.ply")
    out = []
    for cams in ((), (1, 2)):
        res = reconstruct(
            replace(fr, chroma=_holes(np.array(fr.chroma, np.float32), cams), chroma_tracked=True),
            "bayes",
        )
        ref = fr.rig.camera(res.info["reference"])
        gd, _ = render_depth_normals(v, t, n, ref, fr.rig.image.width, fr.rig.image.height)
        m = res.mask & np.isfinite(gd)
        out.append((np.median(np.abs(res.depth[m] - gd[m])) * 1e3, m.sum() / np.isfinite(gd).sum()))
    print(
        f"full {out[0][0]:.3f} mm, coverage {out[0][1]:.3f}; holed {out[1][0]:.3f}, {out[1][1]:.3f}"
    )
    assert out[0][0] < 3.2 and out[1][0] < 4.0
    assert out[1][1] > 0.98 * out[0][1]


def test_subsampled_depth_search_on_a_curved_object(exact_statue, monkeypatch):
    """The depth search on every 2nd pixel in rows and columns (what
    :func:`colourhs.reconstruct.bayes.valley.search_stride` gives from 1200 pixels
    wide) finds the statue's depth as the full search does, here at 320 x 240
    where that keeps only 4 of a control cell's 16 pixels (a harder case
    than the paper preset's 28 of 114)."""
    from colourhs.reconstruct.bayes import refine

    monkeypatch.setattr(refine, "search_stride", lambda spacing: 2)
    err, ang, _ = _statue_errors(exact_statue)
    print(
        f"stride 2: {np.median(np.abs(err)):.3f} {np.median(err):+.3f} mm {np.median(ang):.3f} deg"
    )
    assert np.median(np.abs(err)) < 0.15  # measured 0.076 (0.099 with every pixel)
    assert abs(np.median(err)) < 0.05  # measured -0.025 (-0.026)
    assert np.median(ang) < 0.6  # measured 0.396 deg (0.420)


def test_the_ratio_term_of_the_error_bar_predicts_the_depths_move(exact_rigs, reconstructed):
    """A pair's ratio mu_a / mu_b off by 0.2 % moves the sheet of an exact rig
    (seed 1) as a whole: the error bar's ratio term (the depth search's gain on
    that ratio, :func:`colourhs.reconstruct.bayes.uncertainty.ratio_sensitivity`, times a
    given 0.2 % uncertainty) predicts how far. Measured: the depth moves by
    0.103 mm, the term says 0.108 mm (with a finite 0.1 % step instead of the
    derivative the term said 2.19 mm: on exact data the rows sit on the robust
    function's knee).

    Without the given uncertainty the error bar still sees the move, through the
    jackknife over the pairs (:func:`colourhs.reconstruct.bayes.uncertainty.pair_jackknife`):
    0.39 mm with pair 0 off, 0.013 mm on the exact data. It is larger than the move:
    a surface refitted on two pairs holds its depth mode less firmly, so pair 0's
    error moves it further. And through the depth mode's sigma: the pairs' uniform
    disagreement that the moved surface leaves
    (:func:`colourhs.reconstruct.bayes.uncertainty.pair_disagreement`) through the
    same gain adds 0.29 mm."""
    import copy

    fr, base = _reconstruction(reconstructed, exact_rigs[1], "sheet", "bayes")
    eps = 0.002
    off = copy.copy(fr)
    off.mu = fr.mu.copy()
    off.mu[0, 0] *= np.float32(1 + eps)  # pair 0's side a
    moved = reconstruct(off, "bayes")
    barred = copy.copy(fr)
    barred.mu_ratio_sigma = np.array([eps, 0.0, 0.0])
    bar = reconstruct(barred, "bayes")
    m = base.mask & moved.mask & bar.mask
    assert np.array_equal(bar.depth[m], base.depth[m])  # the same data: the same depth
    shift = float(np.median(moved.depth[m] - base.depth[m])) * 1e3
    term = float(np.median(np.sqrt(bar.depth_sigma[m] ** 2 - base.depth_sigma[m] ** 2))) * 1e3
    print(f"ratio off by {eps}: depth moved {shift:.4f} mm, the ratio term {term:.4f} mm")
    assert abs(shift) > 0.05
    assert term == pytest.approx(abs(shift), rel=0.1)
    # Without the ratio's sigma, the pairs' jackknife sees the move: the three pairs
    # agree on exact data, and pair 0's error bends the surface refitted without it
    # differently from those refitted with it.
    exact, off_pair = (_largest_jackknife(r) * 1e3 for r in (base, moved))
    print(f"pair jackknife: exact {exact:.4f} mm, pair 0 off {off_pair:.4f} mm")
    assert exact < 0.02  # measured 0.013
    assert abs(shift) < off_pair < 5 * abs(shift)  # measured 0.39 against 0.10
    # And the depth mode's sigma sees it through the pairs' uniform disagreement that
    # the surface leaves (uncertainty.pair_disagreement): 0.0005-0.0009 in log ratio
    # over the three pairs, where the exact data's is 1e-5. It is larger than the move:
    # the gain, linearised on the depth search's trials, is less steady on data
    # whose rows disagree.
    seen = _mode_sigma_mm(moved, base)
    print(f"pair disagreement through the mode's gain: {seen:.4f} mm")
    assert abs(shift) < seen < 5 * abs(shift)  # measured 0.29 against 0.10


def _mode_sigma_mm(result, base) -> float:
    """The most that ``result``'s depth-mode sigma adds in variance to ``base``'s over
    their surfaces (the same data, one surface's depth moved), mm at the median depth."""
    dfs = [np.asarray(r.info["surface"]["depth_factor_sigma"], float) for r in (result, base)]
    added = np.sqrt(np.clip(dfs[0] ** 2 - dfs[1] ** 2, 0.0, None))
    return float(np.nanmax(added)) * float(np.nanmedian(result.depth)) * 1e3


def _largest_jackknife(result) -> float:
    """The largest of a Bayesian result's per-surface median pair jackknifes (metres)."""
    jack = [j for j in result.info["surface"]["pair_jackknife_m"] if j is not None]
    return max(jack)
