"""Why a pixel of the reference camera has no depth (beyond the paper).

The accounting a rig owner needs to see where coverage goes: the depth file's
``dropped`` codes (:data:`colourhs.common.depthfile.DROP_REASONS`), from the reference
camera's own causes and the stages of the reconstruction
(:func:`colourhs.reconstruct.frame.reconstruct`).
"""

from __future__ import annotations

import numpy as np

from colourhs.common.depthfile import DROP_REASONS
from colourhs.reconstruct.inputs import Frame


def reference_unusable(frame: Frame, ref: int) -> list[tuple[str, np.ndarray]]:
    """The reference camera's own reasons (H*W,) why a pixel cannot have a depth:
    saturated in some channel, no chromaticity p in some channel (coloured objects)."""
    out = [("saturated", frame.saturated[ref].ravel())]
    if frame.chroma is not None:
        p = frame.chroma[ref]
        out.append(("no_chromaticity", ~np.all(np.isfinite(p) & (p > 0), axis=0).ravel()))
    return out


def drop_codes(obj, fg, unusable, stages, ok) -> np.ndarray:
    """Why each pixel (H*W,) has no depth: codes of :data:`colourhs.common.depthfile.DROP_REASONS`.

    Beyond the paper (the accounting a rig owner needs to see where coverage
    goes). ``obj`` is the object's silhouette or lit region, ``fg`` the
    foreground reconstructed (``obj`` without the pixels too dark to
    measure), ``unusable`` (reason, mask) pairs of the reference camera's
    own causes, ``stages`` (reason, kept) pairs in the order the
    reconstruction applied them, ``ok`` the pixels with a depth. A pixel
    without depth gets the first of: ``outside`` (not in ``obj``), ``dark``
    (not in ``fg``), the first of ``unusable`` that holds, else the last
    stage that removed it (a hole filled at one stage and eroded at a later
    one is the later's). Code 0: the pixel has a depth.
    """
    code = np.zeros(len(ok), np.uint8)
    previous = fg
    for reason, kept in stages:  # the last loss wins
        code[previous & ~kept] = DROP_REASONS.index(reason) + 1
        previous = kept
    for reason, where in reversed([("outside", ~obj), ("dark", ~fg), *unusable]):
        code[where] = DROP_REASONS.index(reason) + 1  # the first cause wins
    code[ok] = 0
    return code
