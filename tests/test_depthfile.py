"""The results contract's depth file (colourhs.depthfile): writing and reading it,
with and without the depth's uncertainty (``depth_sigma``, ``uncertain``)."""

from __future__ import annotations

from types import SimpleNamespace

import h5py
import numpy as np
import pytest

from colourhs.depthfile import DepthResult, read_depth, write_depth

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
    assert dm.depth_sigma is None and dm.uncertain is None


def test_old_style_depth_file_reads_with_none(tmp_path):
    """A file as written before the sigma datasets existed (datasets and attributes
    only: no dist, method or params) still reads, without a sigma."""
    res = _result(with_sigma=False)
    with h5py.File(tmp_path / "old.h5", "w") as f:
        for name in ("depth", "normal", "confidence", "mask"):
            f[name] = getattr(res, name)
        f.attrs.update({"camera": "cam1", "K": CAMERA.K, "R": CAMERA.R, "t": CAMERA.t})
    dm = read_depth(tmp_path / "old.h5")
    assert dm.depth_sigma is None and dm.uncertain is None
    assert dm.method == "" and dm.params == {} and dm.depth.shape == (H, W)


def test_sigma_of_another_shape_is_refused(tmp_path):
    res = _result(with_sigma=True)
    res.depth_sigma = res.depth_sigma[:, :-1]
    write_depth(tmp_path / "d.h5", res, CAMERA, {})
    with pytest.raises(ValueError, match=r"dataset 'depth_sigma' has shape \(24, 31\)"):
        read_depth(tmp_path / "d.h5")
