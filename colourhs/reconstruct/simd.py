"""The data term's 4-slot bilinear footprint: a hand-written LLVM intrinsic, or plain numba.

The package's only LLVM code: this is the one module that imports llvmlite,
``numba.core.cgutils`` and ``numba.extending.intrinsic``, which reach into
numba's internals and may break with a numba or llvmlite release. Both
implementations have the same signature and the same numbers (see
:func:`bilinear4_loop`); :data:`bilinear4` is the one the data-term kernel
calls.

Switch
------
- The intrinsic (:func:`bilinear4_llvm`: <4 x float> loads and arithmetic) is
  used when it builds on this numba and llvmlite: at import a tiny function
  that calls it is compiled and run on exact numbers; on any exception, or
  a wrong answer, :data:`bilinear4` falls back to
  :func:`bilinear4_loop` and a ``RuntimeWarning`` says so (once per process).
- ``COLOURHS_NO_SIMD=1`` in the environment forces the loop (no probe).

:data:`SIMD` says which one was chosen. The choice is made once, at import:
numba freezes a kernel's globals when it compiles it. Numba's on-disk cache
does not see that choice (nor a change of this file): a kernel that calls
:data:`bilinear4` is decorated through :func:`cache_tagged`, which names its
cache after the choice and this file's contents, so the cache never serves an
intrinsic-compiled kernel to the loop or the other way round.

The intrinsic is the faster of the two (the loop is a fallback); the data
term is bit-identical either way.
"""

from __future__ import annotations

import hashlib
import os
import warnings
from pathlib import Path

import numba as nb
import numpy as np
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

__all__ = ["LANES", "SIMD", "bilinear4", "bilinear4_llvm", "bilinear4_loop", "cache_tagged"]

LANES = 4  # slots per footprint call: the packed images hold a multiple of 4 per pixel
ENV_NO_SIMD = "COLOURHS_NO_SIMD"


@intrinsic
def bilinear4_llvm(typingctx, src, i, dx, dy, w00, w01, w10, w11, dst, j, step):
    """``dst[j + s * step] = w00 src[i + s] + w01 src[i + dx + s]
    + w10 src[i + dy + s] + w11 src[i + dx + dy + s]`` for s < 4, with flat
    indices into C-contiguous float32 arrays and <4 x float> loads and
    arithmetic: one bilinear footprint of a group of 4 packed slots. (Numba
    leaves LLVM's SLP vectoriser off, and the loop vectoriser would need
    gathers. No bounds checks: the caller keeps the footprint inside.)"""
    sig = types.void(src, i, dx, dy, w00, w01, w10, w11, dst, j, step)

    def codegen(context, builder, signature, args):
        src_v, i_v, dx_v, dy_v = args[:4]
        weights, dst_v, j_v, step_v = args[4:8], args[8], args[9], args[10]
        v4 = ir.VectorType(ir.FloatType(), LANES)
        sdata = cgutils.create_struct_proxy(signature.args[0])(context, builder, src_v).data
        ddata = cgutils.create_struct_proxy(signature.args[8])(context, builder, dst_v).data

        def texel(off):
            ptr = builder.gep(sdata, [off], inbounds=True)
            return builder.load(builder.bitcast(ptr, v4.as_pointer()), align=4)

        def splat(w, ty):
            x = context.cast(builder, w, ty, types.float32)
            x = builder.insert_element(ir.Constant(v4, ir.Undefined), x, ir.IntType(32)(0))
            zeros = ir.Constant(ir.VectorType(ir.IntType(32), LANES), [0] * LANES)
            return builder.shuffle_vector(x, ir.Constant(v4, ir.Undefined), zeros)

        i_dy = builder.add(i_v, dy_v)
        offs = (i_v, builder.add(i_v, dx_v), i_dy, builder.add(i_dy, dx_v))
        acc = None
        for off, w, ty in zip(offs, weights, signature.args[4:8], strict=True):
            term = builder.fmul(texel(off), splat(w, ty), flags=("fast",))
            acc = term if acc is None else builder.fadd(acc, term, flags=("fast",))
        for s in range(LANES):  # scattered: the next pass reads each slot over k
            off = builder.add(j_v, builder.mul(step_v, step_v.type(s)))
            lane = builder.extract_element(acc, ir.IntType(32)(s))
            builder.store(lane, builder.gep(ddata, [off], inbounds=True))
        return context.get_dummy_value()

    return sig, codegen


@nb.njit(cache=True, inline="always")
def bilinear4_loop(src, i, dx, dy, w00, w01, w10, w11, dst, j, step):
    """:func:`bilinear4_llvm` in plain numba: the same flat indices, float32
    weights and order of operations, one lane at a time (``src`` is 1-D;
    ``dst`` any C-contiguous array, indexed through a flat view)."""
    a, b, c, d = np.float32(w00), np.float32(w01), np.float32(w10), np.float32(w11)
    at = src.flat
    for s in range(LANES):
        dst.flat[j + s * step] = (
            a * at[i + s] + b * at[i + dx + s] + c * at[i + dy + s] + d * at[i + dx + dy + s]
        )


@nb.njit(cache=True)
def _probe(src, dst):
    """One call of the intrinsic on a 4 x 4 x 4 block, into 4 x 4 (step 4)."""
    bilinear4_llvm(src, 20, 4, 16, 0.125, 0.25, 0.375, 0.25, dst, 1, 4)


def _intrinsic_works() -> bool:
    """Whether :func:`bilinear4_llvm` compiles here and gives the formula's
    numbers (small integers and weights in eighths: exact in any order); if
    not, says so with a ``RuntimeWarning``."""
    src = np.arange(64, dtype=np.float32)
    dst = np.zeros(16, np.float32)
    s = np.arange(LANES)
    want = 0.125 * src[20 + s] + 0.25 * src[24 + s] + 0.375 * src[36 + s] + 0.25 * src[40 + s]
    try:
        _probe(src, dst)
        why = None if np.array_equal(dst[1::4], want) and not dst[0::4].any() else f"gives {dst}"
    except Exception as exc:  # any failure to build: the loop
        why = f"does not build here ({exc!r})"
    if why:
        msg = f"colourhs: the SIMD bilinear intrinsic {why}; the data term uses the plain loop"
        warnings.warn(msg, RuntimeWarning, stacklevel=2)
    return why is None


#: Whether :data:`bilinear4` is the intrinsic (True) or the loop (False).
SIMD = os.environ.get(ENV_NO_SIMD, "") in ("", "0") and _intrinsic_works()
#: The footprint the data-term kernel calls.
bilinear4 = bilinear4_llvm if SIMD else bilinear4_loop
_TAG = ("simd_" if SIMD else "loop_") + hashlib.sha256(Path(__file__).read_bytes()).hexdigest()[:8]


def cache_tagged(fn):
    """Rename ``fn`` (a Python function that calls :data:`bilinear4`) after the
    implementation chosen and this file's contents, before ``numba.njit(cache=True)``
    wraps it (put it below the ``njit`` decorator): numba names a function's
    cache files after its qualified name, so each choice gets its own cache."""
    fn.__qualname__ = f"{fn.__qualname__}_{_TAG}"
    return fn
