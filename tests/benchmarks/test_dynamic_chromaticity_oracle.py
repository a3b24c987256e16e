"""benchmarks/dynamic_chromaticity.py's oracles and truths: a tracked map with the true p
in its holes or where it has a p, the calibrated map at the true positions, the carried
truth's chroma error (the floor of any carried map), the tracking's position error, and
a map source run once per scene. Nothing is rendered."""

from __future__ import annotations

import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks"))

import dynamic_chromaticity as dyn  # noqa: E402

from colourhs.calibration.chromaticity_tracking import POSITION_SIGMA_PX, log_p_jump  # noqa: E402

NAN = np.nan
#: One camera's 1 x 3 map: a tracked p, a hole, and a p off the object (no truth).
TRACKED = np.array([[[1.2, 0.9, 0.9], [NAN, NAN, NAN], [0.5, 1.0, 1.5]]], np.float32)
TRUTH = np.array([[[1.0, 1.0, 1.0], [2.0, 0.5, 0.5], [NAN, NAN, NAN]]], np.float32)


def _maps(tmp_path: Path) -> tuple[Path, Path]:
    tracked, truth = tmp_path / "tracked.h5", tmp_path / "truth.h5"
    with h5py.File(tracked, "w") as f:
        f.attrs["frame"], f.attrs["chromatic_frame"] = "000005", "000000"
        f["cam1"] = TRACKED
        f["sigma/cam1"] = np.array([[0.02, NAN, 0.03]], np.float32)
    with h5py.File(truth, "w") as f:
        f["cam1"] = TRUTH
    return tracked, truth


@pytest.mark.parametrize(
    "part, expected",
    [
        ("holes", [[1.2, 0.9, 0.9], [2.0, 0.5, 0.5], [0.5, 1.0, 1.5]]),
        ("known", [[1.0, 1.0, 1.0], [NAN, NAN, NAN], [0.5, 1.0, 1.5]]),
    ],
)
def test_the_truth_goes_into_one_part_of_the_tracked_map_only(tmp_path, part, expected):
    tracked, truth = _maps(tmp_path)
    out = dyn.put_truth(tracked, truth, tmp_path / "out" / "000005.h5", part)
    with h5py.File(out) as f:
        np.testing.assert_array_equal(f["cam1"][()], np.array([expected], np.float32))
        # the rest is the tracked map's: its sigma and that the frame has moved
        np.testing.assert_array_equal(f["sigma/cam1"][()], np.float32([[0.02, NAN, 0.03]]))
        assert (f.attrs["frame"], f.attrs["chromatic_frame"]) == ("000005", "000000")
    with h5py.File(tracked) as f:  # the tracked map itself is untouched
        np.testing.assert_array_equal(f["cam1"][()], TRACKED)


def test_an_unknown_part_is_refused(tmp_path):
    tracked, truth = _maps(tmp_path)
    with pytest.raises(ValueError, match="'holes' or 'known'"):
        dyn.put_truth(tracked, truth, tmp_path / "out.h5", "all")


def test_a_source_shared_by_the_oracles_runs_once_per_scene(tmp_path):
    calls = []

    def source(data, scene, files):
        calls.append((data, scene))
        return {"000000": tmp_path / f"{scene}.h5"}

    once = dyn.once_per_scene(source)
    first = once(tmp_path, "cloth", {})
    assert once(tmp_path, "cloth", {}) is first
    once(tmp_path, "moving-toy", {})
    assert calls == [(tmp_path, "cloth"), (tmp_path, "moving-toy")]


W, H = 80, 60
#: A plane at 1 m seen by one pinhole camera (f 100 px): moved 5 cm along x between
#: the chromatic frame 000000 and frame 000001, 5 px in the image.
SHIFT_PX = 5


def _moved_plane(tmp_path: Path):
    """The plane's ground-truth meshes under ``tmp_path/scenes/plane/gt`` and a one-camera
    rig (``camera_names``, ``image``, ``camera``) that sees them."""
    from types import SimpleNamespace

    from capture_helpers import pinhole

    from colourhs.common.ply import write_ply

    cam = pinhole(100.0, 40.0, 30.0)
    rig = SimpleNamespace(
        camera_names=("A",), image=SimpleNamespace(width=W, height=H), camera=lambda name: cam
    )
    gt = tmp_path / "scenes" / "plane" / "gt"
    gt.mkdir(parents=True)
    v = np.array([[-0.4, -0.4, 1.0], [0.4, -0.4, 1.0], [0.4, 0.4, 1.0], [-0.4, 0.4, 1.0]])
    tri = np.array([[0, 1, 2], [0, 2, 3]])
    write_ply(gt / "000000.ply", v, tri)
    write_ply(gt / "000001.ply", v + [SHIFT_PX / 100.0, 0.0, 0.0], tri)
    return rig


def _pattern(shift: int = 0) -> np.ndarray:
    """A map (H, W, 3) of vertical stripes, each column its own colour, moved ``shift``
    columns to the right (NaN where nothing moved in)."""
    x = np.arange(W) - shift
    p = np.stack([1.0 + 0.5 * np.sin(x), np.ones(W), 1.0 + 0.5 * np.cos(0.7 * x)], -1)
    p[x < 0] = np.nan
    return np.broadcast_to(p, (H, W, 3)).astype(np.float32).copy()


def test_position_error_of_a_tracked_map_against_the_meshes(tmp_path):
    """dyn.position_error: a tracked map that saw no motion is 5 px off, one that
    followed it 0 px; a map without positions (the calibrated one), or a frame without
    true positions, has none."""
    rig = _moved_plane(tmp_path)
    gx, gy = np.meshgrid(np.arange(W, dtype=np.float32), np.arange(H, dtype=np.float32))
    for name, dx in (("still", 0.0), ("followed", -SHIFT_PX)):
        with h5py.File(tmp_path / f"{name}.h5", "w") as m:
            m["A"] = np.ones((H, W, 3), np.float32)
            m["position/A"] = np.stack([gx + dx, gy], axis=-1)
    truth = dyn.true_position_maps(tmp_path, "plane", "000001", "000000", rig)
    args = (truth, rig.camera_names)
    still = dyn.position_error(tmp_path / "still.h5", *args)
    assert still["track_position_px"] == pytest.approx(SHIFT_PX, abs=1e-3)
    assert still["track_motion_px"] == pytest.approx(SHIFT_PX, abs=1e-3)
    assert still["track_position_known"] == 1.0
    followed = dyn.position_error(tmp_path / "followed.h5", *args)
    assert followed["track_position_px"] == pytest.approx(0.0, abs=1e-3)
    with h5py.File(tmp_path / "calibrated.h5", "w") as m:
        m["A"] = np.ones((H, W, 3), np.float32)
    none = dyn.position_error(tmp_path / "calibrated.h5", *args)
    assert none == dict.fromkeys(dyn.POSITION_COLUMNS)
    untold = dyn.position_error(tmp_path / "followed.h5", None, rig.camera_names)
    assert untold == dict.fromkeys(dyn.POSITION_COLUMNS)


def test_the_calibrated_map_is_sampled_where_each_point_truly_was(tmp_path):
    """dyn.at_true_positions: on the moved frame each pixel takes the calibrated p (and
    its error bar, with the nearest sampling's position error at the map's jumps) 5 px
    to its left, where its point was in the chromatic frame, with
    the tracking's sigma 0; nothing where the point was outside the image; the tracked
    map's attributes kept and its file untouched."""
    rig = _moved_plane(tmp_path)
    calibrated, tracked = tmp_path / "calibrated.h5", tmp_path / "tracked.h5"
    error_bar = np.broadcast_to(np.linspace(0.01, 0.08, W)[:, None], (W, 3))
    with h5py.File(calibrated, "w") as f:
        f["A"] = _pattern()
        f["sigma/A"] = np.broadcast_to(error_bar, (H, W, 3)).astype(np.float32)
    with h5py.File(tracked, "w") as f:
        f.attrs["frame"], f.attrs["chromatic_frame"] = "000001", "000000"
        f["A"] = np.full((H, W, 3), 2.0, np.float32)
        for key, shape in (("position", (H, W, 2)), ("position_sigma", (H, W))):
            f[f"{key}/A"] = np.full(shape, 9.0, np.float32)
        f["sigma/A"] = np.full((H, W), 0.3, np.float32)
        f["p_sigma/A"] = np.full((H, W, 3), 0.3, np.float32)
    truth = dyn.true_position_maps(tmp_path, "plane", "000001", "000000", rig)
    out = dyn.at_true_positions(tracked, calibrated, truth, tmp_path / "out" / "000001.h5")
    with h5py.File(out) as f:
        np.testing.assert_allclose(f["A"][()], _pattern(SHIFT_PX), atol=1e-6)
        known = np.isfinite(f["A"][()]).all(-1)
        assert known[:, SHIFT_PX:].all() and not known[:, :SHIFT_PX].any()
        np.testing.assert_array_equal(f["sigma/A"][()][known], 0.0)
        assert np.isnan(f["sigma/A"][()][~known]).all()
        np.testing.assert_allclose(
            f["position/A"][()][..., 0][known], np.nonzero(known)[1] - SHIFT_PX, atol=1e-4
        )
        # the calibrated error bar there and the nearest sampling's position error at
        # the stripes' log p jumps beyond that bar's noise (each column its own
        # colour), in quadrature
        bars = np.broadcast_to(error_bar, (H, W, 3))
        jump = POSITION_SIGMA_PX * log_p_jump(_pattern(), bars)[:, : W - SHIFT_PX]
        expected_bar = np.hypot(error_bar[: W - SHIFT_PX], jump[..., None])
        np.testing.assert_allclose(f["p_sigma/A"][()][:, SHIFT_PX:], expected_bar, rtol=1e-5)
        assert np.mean(jump > 0.01) > 0.5  # most columns an edge beyond the noise
        assert (f.attrs["frame"], f.attrs["chromatic_frame"]) == ("000001", "000000")
    with h5py.File(tracked) as f:
        np.testing.assert_array_equal(f["A"][()], 2.0)


def _truths(tmp_path: Path, moved: np.ndarray) -> None:
    folder = tmp_path / "scenes" / "plane" / "gt" / "chromaticity"
    folder.mkdir(parents=True, exist_ok=True)
    for frame, p in (("000000", _pattern()), ("000001", moved)):
        with h5py.File(folder / f"{frame}.h5", "w") as f:
            f["A"] = p


def test_the_chroma_floor_is_the_carried_truths_error(tmp_path):
    """dyn.chroma_floor: a truth that moved with the plane is carried exactly (floor 0);
    one drawn where the plane was not (the chromatic frame's pattern unmoved) costs the
    carried pattern's error against it; the chromatic frame's floor is 0, and a moved
    frame without true positions has none."""
    rig = _moved_plane(tmp_path)
    _truths(tmp_path, _pattern(SHIFT_PX))
    truth = dyn.true_position_maps(tmp_path, "plane", "000001", "000000", rig)
    args = (tmp_path, "plane", "000001", "000000", truth, rig.camera_names)
    assert dyn.chroma_floor(*args) == pytest.approx(0.0, abs=1e-6)
    home = (tmp_path, "plane", "000000", "000000", None, rig.camera_names)
    assert dyn.chroma_floor(*home) == 0.0
    assert dyn.chroma_floor(*args[:4], None, rig.camera_names) is None
    _truths(tmp_path, _pattern())
    from colourhs.calibration.chromaticity import log_ratio_rms

    expected = log_ratio_rms(_pattern(SHIFT_PX), _pattern())
    assert expected > 0.2
    assert dyn.chroma_floor(*args) == pytest.approx(expected, rel=1e-5)


def test_a_map_is_scored_against_the_noise_free_map_where_its_points_truly_were(tmp_path):
    """dyn.noise_free_error: the noise-free map carried 5 px by the true motion is what a
    moved map is compared with; a map equal to it has RMS 0 (every pixel within its
    error bar), and a map left where the chromatic frame was misses the moved stripes.
    A pure colour's map with Gaussian errors of its own sigma of log p in its dark band
    (the bright bands move only by the sum-3 scale, and their sigma says so) falls
    within 1 and 3 of it as an honest Gaussian (0.68, 0.997). On the chromatic frame
    the noise-free map itself is the reference; a moved frame without true positions
    has none."""
    rig = _moved_plane(tmp_path)
    truth = dyn.true_position_maps(tmp_path, "plane", "000001", "000000", rig)
    cams = rig.camera_names
    sigma = 0.05
    pure = np.broadcast_to(np.float32([0.03, 1.485, 1.485]), (H, W, 3))
    rng = np.random.default_rng(0)
    noisy = pure * np.stack([np.exp(rng.normal(0.0, sigma, (H, W))), *[np.ones((H, W))] * 2], -1)
    noisy = 3 * noisy / noisy.sum(-1, keepdims=True)
    # the bright bands' log error is the dark band's times its share of the sum
    bars = np.float32([sigma, sigma * 0.01, sigma * 0.01])
    for name, reference, p in (
        ("exact", _pattern(), _pattern(SHIFT_PX)),
        ("unmoved", _pattern(), _pattern()),
        ("noisy", pure, noisy),
    ):
        with h5py.File(tmp_path / f"{name}_nf.h5", "w") as f:
            f["A"] = reference
        with h5py.File(tmp_path / f"{name}.h5", "w") as f:
            f["A"] = p.astype(np.float32)
            f["p_sigma/A"] = np.broadcast_to(bars, (H, W, 3))

    def error(name, positions=truth, home=False):
        map_h5, nf_h5 = tmp_path / f"{name}.h5", tmp_path / f"{name}_nf.h5"
        return dyn.noise_free_error(map_h5, nf_h5, positions, home, cams)

    exact = error("exact")
    assert exact["chroma_nf_rms_log"] == pytest.approx(0.0, abs=1e-6)
    assert exact["chroma_nf_within_1"] == 1.0
    unmoved = error("unmoved")
    assert unmoved["chroma_nf_rms_log"] > 0.2 and unmoved["chroma_nf_within_3"] < 0.5
    noisy_err = error("noisy")  # 0.677 / 0.998 measured: H x (W - 5) pixels
    assert 0.65 < noisy_err["chroma_nf_within_1"] < 0.71
    assert noisy_err["chroma_nf_within_3"] > 0.99
    home = error("unmoved", None, True)
    assert home["chroma_nf_rms_log"] == pytest.approx(0.0, abs=1e-6)
    assert error("exact", None) == dict.fromkeys(dyn.NOISE_FREE_COLUMNS)


def test_the_noise_free_maps_model_error_is_against_the_frames_truth(tmp_path):
    """dyn.carried_error of the noise-free map (``nf_model_rms_log``): a noise-free map
    equal to the chromatic frame's truth, carried by the true motion, has no error
    against a truth that moved with the plane, and the unmoved pattern's error against
    one that did not; None without true positions on a moved frame."""
    rig = _moved_plane(tmp_path)
    noise_free = tmp_path / "noise_free.h5"
    with h5py.File(noise_free, "w") as f:
        f["A"] = _pattern()
    truth = dyn.true_position_maps(tmp_path, "plane", "000001", "000000", rig)
    folder = tmp_path / "scenes" / "plane" / "gt" / "chromaticity"
    _truths(tmp_path, _pattern(SHIFT_PX))
    cams = rig.camera_names
    args = (noise_free, folder / "000001.h5")
    assert dyn.carried_error(*args, truth, False, cams) == pytest.approx(0.0, abs=1e-6)
    assert dyn.carried_error(*args, None, False, cams) is None
    _truths(tmp_path, _pattern())
    from colourhs.calibration.chromaticity import log_ratio_rms

    expected = log_ratio_rms(_pattern(SHIFT_PX), _pattern())
    assert dyn.carried_error(*args, truth, False, cams) == pytest.approx(expected, rel=1e-5)
    home = dyn.carried_error(noise_free, folder / "000000.h5", None, True, cams)
    assert home == pytest.approx(0.0, abs=1e-6)
