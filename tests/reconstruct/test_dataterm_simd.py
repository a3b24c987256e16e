"""The data term's bilinear footprint, LLVM intrinsic or plain numba loop
(:mod:`colourhs.reconstruct.simd`): the same numbers either way.

Run as a script (``python tests/reconstruct/test_dataterm_simd.py DATASET OUT.npz``) it
writes the data term of :func:`_data_term` to OUT.npz: the test runs it so
with ``COLOURHS_NO_SIMD=1``, since the kernel's footprint is chosen at import.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from numba import njit

from colourhs.reconstruct import simd
from colourhs.reconstruct.dataterm import _kernel, data_term, pair_arrays, prepare_images
from colourhs.reconstruct.frame import load_frame, reference_rays, working_depth


def _data_term(root):
    """Cost and normals of the tiny statue, chromaticity, mu maps and masks on:
    every pixel, 48 hypotheses over the working range."""
    root = Path(root)
    fr = load_frame(
        root,
        "statue",
        "000000",
        photometric_h5=root / "gt" / "photometric.h5",
        chromaticity_h5=root / "scenes/statue/gt/chromaticity.h5",
    )
    rig, ref = fr.rig, fr.rig.cameras[0]
    rays = reference_rays(ref, rig.image.width, rig.image.height)
    zc = working_depth(rig, ref)
    pairs = pair_arrays(rig)
    prep = prepare_images(fr.images, fr.saturated, pairs, fr.mu, fr.chroma, fr.silhouettes)
    depths = np.linspace(0.75 * zc, 1.25 * zc, 48)
    return data_term(rays, ref.centre, depths, rig.cameras, prep, pairs)


def test_intrinsic_and_loop_give_the_same_data_term(tiny_dataset, tmp_path):
    """The kernel with the intrinsic (this process) and with the loop (a
    process with ``COLOURHS_NO_SIMD=1``). Measured: bit-identical costs and
    normals (max difference 0; 76,362 of the 921,600 hypotheses valid), as
    on the tiny statue's whole frame with 96 hypotheses with and without
    chromaticity, and both bit-identical to the kernel before its
    move. 9.5 s with both kernels cached, on 2 cores under a load of 10
    (about 60 s more on a fresh checkout: the subprocess compiles the
    loop's kernel)."""
    if not simd.SIMD:
        pytest.skip(
            "the SIMD intrinsic is not in use here (COLOURHS_NO_SIMD, or it does not build)"
        )
    cost, normals = _data_term(tiny_dataset)
    out = tmp_path / "loop.npz"
    package_root = str(Path(simd.__file__).resolve().parents[2])
    path = os.pathsep.join(filter(None, [package_root, os.environ.get("PYTHONPATH")]))
    env = {**os.environ, simd.ENV_NO_SIMD: "1", "PYTHONPATH": path}
    subprocess.run([sys.executable, __file__, str(tiny_dataset), str(out)], env=env, check=True)
    loop = np.load(out)
    # The loop chosen there, and a kernel cached under its own name (numba's
    # cache files are named after the qualified name).
    assert not loop["simd"] and "_kernel_loop_" in str(loop["kernel"])
    assert "_kernel_simd_" in _kernel.py_func.__qualname__
    valid = cost < 1
    assert 60_000 < valid.sum() < 95_000  # measured 76,362
    assert np.array_equal(loop["cost"] < 1, valid)
    np.testing.assert_allclose(loop["cost"], cost, rtol=1e-6, atol=0)
    assert np.abs(loop["normals"] - normals).max() <= 1e-6  # measured 0


@njit(fastmath=True)  # as in the kernel (the intrinsic's own arithmetic is always fast-math)
def _both(src, i, dx, dy, w, dst1, dst2, j, step):
    simd.bilinear4_llvm(src, i, dx, dy, w[0], w[1], w[2], w[3], dst1, j, step)
    simd.bilinear4_loop(src, i, dx, dy, w[0], w[1], w[2], w[3], dst2, j, step)


@pytest.mark.skipif(not simd.SIMD, reason="the SIMD intrinsic is not in use here")
def test_loop_has_the_intrinsics_semantics():
    """Flat indices into a 1-D ``src`` and a 3-D ``dst``, float64 weights
    rounded to float32, every footprint of a random 5 x 6 x 8 block into
    4 x 8 x 5 with step 5: identical results, nothing else written (under
    fastmath, as in the kernel; without it they differ by 1 ulp)."""
    rng = np.random.default_rng(0)
    src = rng.random(5 * 6 * 8).astype(np.float32)
    w = rng.random(4)
    for y in range(4):
        for x in range(5):
            dst1 = np.full((4, 8, 5), -7.0, np.float32)
            dst2 = dst1.copy()
            _both(src, (y * 6 + x) * 8 + 4, 8, 48, w, dst1, dst2, 3 + 40 * y, 5)
            assert np.array_equal(dst1, dst2)
            assert np.sum(dst1 != -7.0) == 4
    i = (3 * 6 + 4) * 8 + 4  # the last footprint's first slot: dst index 3 + 120 = (3, 0, 3)
    assert dst1[3, 0, 3] == pytest.approx(w @ src[[i, i + 8, i + 48, i + 56]], rel=1e-6)


def test_a_failing_intrinsic_falls_back_with_a_warning(monkeypatch):
    def broken(src, dst):
        raise RuntimeError("no such LLVM")

    monkeypatch.setattr(simd, "_probe", broken)
    with pytest.warns(RuntimeWarning, match="does not build here.*no such LLVM"):
        assert simd._intrinsic_works() is False


if __name__ == "__main__":
    cost, normals = _data_term(sys.argv[1])
    np.savez(
        sys.argv[2], cost=cost, normals=normals, simd=simd.SIMD, kernel=_kernel.py_func.__qualname__
    )
