"""The results contract's depth file (colourhs.common.depthfile): writing and reading it,
with and without the depth's uncertainty (``depth_sigma``, ``uncertain``) and why a
pixel has no depth (``dropped``)."""

from __future__ import annotations

import json
from types import SimpleNamespace

import h5py
import numpy as np
import pytest

from colourhs.common.depthfile import DATASETS, DROP_REASONS, DepthResult, read_depth, write_depth

H, W = 24, 32
CAMERA = SimpleNamespace(
    name="cam1",
    K=np.array([[40.0, 0.0, 15.5], [0.0, 40.0, 11.5], [0.0, 0.0, 1.0]]),
    R=np.eye(3),
    t=np.array([0.0, 0.0, 0.5]),
    dist=np.zeros(5),
)


def _result(with_sigma: bool) -> DepthResult:
    """A frame whose right quarter is flagged uncertain (left out of the mask, no depth)."""
    rng = np.random.default_rng(3)
    depth = rng.uniform(0.4, 0.6, (H, W)).astype(np.float32)
    uncertain = np.zeros((H, W), bool)
    uncertain[:, 3 * W // 4 :] = True
    depth[uncertain] = np.nan
    sigma = rng.uniform(2e-4, 3e-3, (H, W)).astype(np.float32)
    sigma[0, 0] = np.nan  # a reconstructed pixel without a sigma
    normal = np.broadcast_to(np.float32([0.0, 0.0, -1.0]), (H, W, 3)).copy()
    mask = np.isfinite(depth)
    return DepthResult(
        depth,
        normal,
        mask.astype(np.float32),
        mask,
        {},
        depth_sigma=sigma if with_sigma else None,
        uncertain=uncertain if with_sigma else None,
    )


def test_depth_file_round_trips_sigma_and_uncertain(tmp_path):
    res = _result(with_sigma=True)
    write_depth(tmp_path / "d.h5", res, CAMERA, {"method": "bayes"})
    with h5py.File(tmp_path / "d.h5") as f:
        assert f["depth_sigma"].dtype == np.float32 and f["uncertain"].dtype == bool
        assert f["depth_sigma"].compression == f["uncertain"].compression == "gzip"
    dm = read_depth(tmp_path / "d.h5")
    assert dm.depth_sigma.dtype == np.float32 and dm.uncertain.dtype == bool
    np.testing.assert_array_equal(dm.depth_sigma, res.depth_sigma)  # NaN at (0, 0) too
    np.testing.assert_array_equal(dm.uncertain, res.uncertain)
    assert dm.uncertain.sum() == H * (W // 4) and not np.any(dm.mask & dm.uncertain)
    np.testing.assert_array_equal(dm.depth, res.depth)
    assert dm.method == "bayes"


def test_depth_file_without_sigma_reads_none(tmp_path):
    write_depth(tmp_path / "d.h5", _result(with_sigma=False), CAMERA, {"method": "ml"})
    with h5py.File(tmp_path / "d.h5") as f:
        assert sorted(f) == ["confidence", "depth", "mask", "normal"]
    dm = read_depth(tmp_path / "d.h5")
    assert dm.depth_sigma is None and dm.uncertain is None and dm.dropped is None


def test_old_style_depth_file_reads_with_none(tmp_path):
    """A file as written before the sigma datasets existed (datasets and attributes
    only: no dist, method or params) still reads, without a sigma."""
    res = _result(with_sigma=False)
    with h5py.File(tmp_path / "old.h5", "w") as f:
        for name in ("depth", "normal", "confidence", "mask"):
            f[name] = getattr(res, name)
        f.attrs.update({"camera": "cam1", "K": CAMERA.K, "R": CAMERA.R, "t": CAMERA.t})
    dm = read_depth(tmp_path / "old.h5")
    assert dm.depth_sigma is None and dm.uncertain is None and dm.dropped is None
    assert dm.method == "" and dm.params == {} and dm.depth.shape == (H, W)


def test_sigma_of_another_shape_is_refused(tmp_path):
    res = _result(with_sigma=True)
    res.depth_sigma = res.depth_sigma[:, :-1]
    write_depth(tmp_path / "d.h5", res, CAMERA, {})
    with pytest.raises(ValueError, match=r"dataset 'depth_sigma' has shape \(24, 31\)"):
        read_depth(tmp_path / "d.h5")


# --------------------------------------------------------------------------- dropped


def _codes() -> np.ndarray:
    """Codes of :func:`_result`'s frame: its right quarter (no depth) ``uncertain``,
    codes 1 to 9 (each reason once) on the left of row 0, 0 (a depth) elsewhere."""
    codes = np.zeros((H, W), np.uint8)
    codes[:, 3 * W // 4 :] = DROP_REASONS.index("uncertain") + 1
    codes[0, : len(DROP_REASONS)] = np.arange(1, len(DROP_REASONS) + 1)
    return codes


def _dropped_result() -> DepthResult:
    res = _result(with_sigma=True)
    res.dropped = _codes()
    res.depth[res.dropped > 0] = np.nan
    return res


def test_depth_file_round_trips_dropped(tmp_path):
    """``dropped`` is written as uint8 (gzip) with its reasons by name and reads back
    code for code; the reasons are the nine of the contract, in its order."""
    assert DROP_REASONS == (
        "outside",
        "dark",
        "saturated",
        "no_chromaticity",
        "data_term",
        "surface",
        "refinement",
        "uncertain",
        "rims",
    )
    assert "dropped" in DATASETS
    res = _dropped_result()
    write_depth(tmp_path / "d.h5", res, CAMERA, {"method": "bayes"})
    with h5py.File(tmp_path / "d.h5") as f:
        assert f["dropped"].dtype == np.uint8 and f["dropped"].compression == "gzip"
        assert json.loads(f["dropped"].attrs["reasons"]) == list(DROP_REASONS)
    dm = read_depth(tmp_path / "d.h5")
    assert dm.dropped.dtype == np.uint8
    np.testing.assert_array_equal(dm.dropped, res.dropped)
    counts = np.bincount(dm.dropped.ravel(), minlength=10)
    # row 0: one pixel of each reason; uncertain also the right quarter, 8 columns x 24 rows
    assert counts.tolist() == [H * W - 9 - 8 * H, 1, 1, 1, 1, 1, 1, 1, 8 * H + 1, 1]
    assert not np.any(np.isfinite(dm.depth) & (dm.dropped > 0))


def test_dropped_read_by_the_names_of_its_reasons(tmp_path):
    """A file whose ``reasons`` list another order reads in the contract's numbering;
    an unknown reason, a code past its reasons or another shape is refused."""
    res = _dropped_result()
    write_depth(tmp_path / "d.h5", res, CAMERA, {})
    with h5py.File(tmp_path / "d.h5", "r+") as f:
        f["dropped"].attrs["reasons"] = json.dumps(list(DROP_REASONS[::-1]))
    dm = read_depth(tmp_path / "d.h5")  # code k + 1 now names DROP_REASONS[8 - k]
    expected = np.where(res.dropped > 0, len(DROP_REASONS) + 1 - res.dropped.astype(int), 0)
    np.testing.assert_array_equal(dm.dropped, expected)
    assert dm.dropped[0, 0] == DROP_REASONS.index("rims") + 1
    with h5py.File(tmp_path / "d.h5", "r+") as f:
        f["dropped"].attrs["reasons"] = json.dumps(["outside", "glare"])
    with pytest.raises(ValueError, match=r"unknown reasons \['glare'\]"):
        read_depth(tmp_path / "d.h5")
    with h5py.File(tmp_path / "d.h5", "r+") as f:
        f["dropped"].attrs["reasons"] = json.dumps(["outside", "dark"])
    with pytest.raises(ValueError, match="codes 0 to 9, expected 0 to 2"):
        read_depth(tmp_path / "d.h5")
    res.dropped = res.dropped[:-1]
    write_depth(tmp_path / "e.h5", res, CAMERA, {})
    with pytest.raises(ValueError, match=r"dataset 'dropped' has shape \(23, 32\)"):
        read_depth(tmp_path / "e.h5")
