"""Why a pixel has no depth: the reconstruction's accounting (drop_codes)."""

from __future__ import annotations

import numpy as np

from colourhs.common.depthfile import DROP_REASONS
from colourhs.reconstruct.drops import drop_codes


def _code(name):
    return DROP_REASONS.index(name) + 1


def test_each_pixel_gets_its_first_cause_or_its_last_stage():
    """Ten pixels through the causes and stages by hand: outside beats dark,
    dark beats saturated, the reference camera's causes beat the stages, the
    last stage that removed a pixel wins over an earlier one (a hole filled by
    the refinement and eroded at the rims is the rims'), and a pixel with a
    depth is 0 whatever happened to it."""
    obj = np.array([0, 1, 1, 1, 1, 1, 1, 1, 1, 1], bool)
    fg = np.array([0, 0, 1, 1, 1, 1, 1, 1, 1, 1], bool)
    saturated = np.array([1, 1, 1, 0, 0, 0, 0, 0, 0, 0], bool)
    data = np.array([0, 0, 0, 1, 0, 1, 1, 1, 1, 1], bool)  # kept after the data term
    surface = np.array([0, 0, 0, 1, 0, 0, 1, 1, 1, 1], bool)
    refined = np.array([0, 0, 0, 1, 1, 0, 0, 1, 1, 1], bool)  # pixel 4 filled
    rims = np.array([0, 0, 0, 1, 0, 0, 0, 1, 1, 1], bool)
    ok = np.array([0, 0, 0, 1, 0, 0, 0, 1, 0, 1], bool)  # pixel 8 flagged uncertain
    stages = [
        ("data_term", data),
        ("surface", surface),
        ("refinement", refined),
        ("rims", rims),
        ("uncertain", ok),
    ]
    code = drop_codes(obj, fg, [("saturated", saturated)], stages, ok)
    names = ["" if c == 0 else DROP_REASONS[c - 1] for c in code]
    assert names == [
        "outside",
        "dark",
        "saturated",
        "",
        "rims",
        "surface",
        "refinement",
        "",
        "uncertain",
        "",
    ]
    assert code.dtype == np.uint8 and (code[ok] == 0).all() and (code[~ok] > 0).all()
    assert code[0] == _code("outside")


def test_the_depth_search_of_no_surface_returns_what_it_was_given():
    """A frame whose every pixel was dropped before the refinement leaves it no surface:
    the depth search (beyond the paper) then has nothing to walk and returns the control
    points unchanged (it once raised on the empty list of surfaces)."""
    from types import SimpleNamespace

    from colourhs.reconstruct.bayes.valley import depth_search

    c = np.zeros(0)
    out, factors, sigma = depth_search(SimpleNamespace(n=0), c)
    assert out is c and factors.shape == (0,) and sigma.shape == (0,)
