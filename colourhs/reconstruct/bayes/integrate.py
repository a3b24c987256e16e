"""A smooth surface from the discrete labelling: the HS normals integrated.

Beyond the paper: the start of the Bayesian refinement
(:mod:`colourhs.reconstruct.bayes.surface`). The tangent plane of a pixel's HS
normal predicts its neighbours' depths (the depth-normal consistency of the
paper's prior, section III-E); :func:`refine_depth` integrates those
predictions into a surface in log-depth, anchored robustly to the labels,
and :func:`surface_links` cuts the links at depth edges, so that separate
surfaces stay separate (:func:`surface_components`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from colourhs.common.linalg import NearbySolver
from colourhs.reconstruct.dataterm import INVALID_COST


def surface_links(
    z: np.ndarray,
    normals: np.ndarray,
    rays: np.ndarray,
    mask: np.ndarray,
    shape: tuple[int, int],
    edge_m: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Directed 4-neighbour links (p, q) of one continuous surface.

    q is linked to p when both are in ``mask`` and q's depth is within
    ``edge_m`` (metres) of what p's tangent plane (its normal) predicts; the
    other links are depth edges, where the depth-normal prior is cut.

    Returns
    -------
    p, q : (L,) pixel indices. a_p, a_q : (L,) ``n_p . r_p`` and ``n_p . r_q``.
    """
    H, W = shape
    grid = np.arange(H * W).reshape(H, W)
    out = [[], [], [], []]
    for p_arr, q_arr in ((grid[:, :-1], grid[:, 1:]), (grid[:-1], grid[1:])):
        for p, q in ((p_arr.ravel(), q_arr.ravel()), (q_arr.ravel(), p_arr.ravel())):
            ok = mask[p] & mask[q]
            p, q = p[ok], q[ok]
            n = normals[p]
            a_q = np.sum(n * rays[q], axis=1)
            a_p = np.sum(n * rays[p], axis=1)
            with np.errstate(invalid="ignore", divide="ignore"):
                pred = z[p] * a_p / a_q
            keep = np.isfinite(pred) & (np.abs(pred - z[q]) < edge_m)
            for lst, arr in zip(out, (p, q, a_p, a_q), strict=True):
                lst.append(arr[keep])
    return tuple(np.concatenate(lst) for lst in out)


def surface_components(p: np.ndarray, q: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Label (N,) of each masked pixel's surface (linked by :func:`surface_links`); -1 outside."""
    from scipy.sparse.csgraph import connected_components

    pix = np.flatnonzero(mask)
    idx = np.full(len(mask), -1)
    idx[pix] = np.arange(len(pix))
    g = sp.coo_matrix((np.ones(len(p)), (idx[p], idx[q])), shape=(len(pix), len(pix)))
    _, lab = connected_components(g, directed=False)
    out = np.full(len(mask), -1)
    out[pix] = lab
    return out


def refine_depth(
    z0: np.ndarray,
    normals: np.ndarray,
    rays: np.ndarray,
    mask: np.ndarray,
    shape: tuple[int, int],
    data_weight: float = 0.05,
    edge_m: float = 0.004,
    anchor_scale: float | None = None,
    solver: NearbySolver | None = None,
    say=None,
) -> np.ndarray:
    """Integrate the normals into a surface, its depth anchored to ``z0``.

    The tangent plane of p's normal n_p passes through neighbour q when
    ``z_q (n_p . r_q) = z_p (n_p . r_p)`` (X = c + z r; the camera centre
    cancels), which is linear in the log-depths:
    ``log z_q - log z_p = log(n_p . r_p / n_p . r_q)``. Minimises, over the
    masked pixels, the squared misfit of that over 4-neighbours plus
    ``data_weight^2 sum_p (log z_p - log z0_p)^2``, skipping neighbours whose
    depths differ by more than ``edge_m`` from what p's tangent plane
    predicts (the truncation that keeps depth edges). In log-depth the
    problem is scale-invariant, so the weak anchor does not pull the
    surface towards the camera (as the same terms in metres would: they
    shrink with the depth). The normal equations are solved by ``solver``.
    With ``anchor_scale`` (a relative depth, e.g. two labels over the
    depth) the anchor is robust (Cauchy weights, three reweighted solves),
    so wrong labels do not move the surface.

    Parameters
    ----------
    z0 : (N,) discrete-solution depths of all pixels (N = H*W), metres.
    normals : (N, 3) unit normals of the discrete solution.
    rays : (N, 3) rays with unit z-depth.
    mask : (N,) pixels to refine.
    shape : (H, W).
    solver : solves the normal equations; pass one :class:`NearbySolver`
        to several calls (the passes of :func:`initial_surface`) so that
        each solve starts from the factors of an earlier one.
    say : called with a line of text before each solve (progress: a solve
        takes seconds at high resolution), if given.

    Returns
    -------
    (N,) refined depths (unchanged outside ``mask``).
    """
    H, W = shape
    idx = np.full(H * W, -1)
    pix = np.flatnonzero(mask)
    idx[pix] = np.arange(len(pix))
    p, q, a_p, a_q = surface_links(z0, normals, rays, mask, shape, edge_m)
    with np.errstate(invalid="ignore", divide="ignore"):
        target = np.log(a_p / a_q)
    keep = np.isfinite(target)
    p, q, target = p[keep], q[keep], target[keep]
    r = len(p)
    # Row i: +1 at q, -1 at p, columns in increasing order (built as CSR
    # directly: a conversion from COO would be a large share of each pass).
    iq, ip = idx[q], idx[p]
    sign = np.where(iq < ip, 1.0, -1.0)  # the first column's value
    A = sp.csr_matrix(
        (
            np.stack([sign, -sign], axis=1).ravel(),
            np.stack([np.minimum(iq, ip), np.maximum(iq, ip)], axis=1).ravel(),
            np.arange(0, 2 * r + 1, 2),
        ),
        shape=(r, len(pix)),
    )
    u0 = np.log(np.maximum(z0[pix], 1e-9))
    weight = np.ones(len(pix))
    solver = NearbySolver() if solver is None else solver
    u = u0
    AtA, Atb = A.T @ A, A.T @ target  # the same in every reweighted solve
    solves = 3 if anchor_scale else 1
    for i in range(solves):
        if say is not None:
            say(f"bayes: normal integration, solve {i + 1} of {solves} ({len(pix)} unknowns)")
        N = AtA + sp.diags(data_weight**2 * weight)
        u = solver.solve(N, Atb + data_weight**2 * weight * u0, x0=u)
        if anchor_scale:
            weight = 1.0 / (1.0 + ((u - u0) / anchor_scale) ** 2)
    out = z0.copy()
    out[pix] = np.exp(u)
    return out


def large_components(mask: np.ndarray, min_size: int) -> np.ndarray:
    """``mask`` (bool) without its 4-connected components smaller than ``min_size`` pixels."""
    from skimage.morphology import remove_small_objects

    # max_size (scikit-image >= 0.26) removes components of max_size pixels or fewer.
    return remove_small_objects(np.asarray(mask, bool), max_size=min_size - 1, connectivity=1)


@dataclass(frozen=True)
class IntegrationOptions:
    """How :func:`initial_surface` integrates the HS normals.

    Attributes
    ----------
    passes : integrations, each from the HS normals re-evaluated at the last
        one's depths.
    data_weight, edge_m, anchor_scale : :func:`refine_depth`'s anchor weight,
        depth-edge truncation (metres) and robust anchor scale (relative depth).
    link_m : tangent-plane misfit that still links two neighbours into one
        surface, metres (:func:`surface_links`).
    min_px : the fewest pixels a surface keeps.
    """

    passes: int
    data_weight: float
    edge_m: float
    anchor_scale: float | None
    link_m: float
    min_px: int


def initial_surface(z, nrm, ok, rays, pix, shape, evaluate, opts: IntegrationOptions, say=None):
    """A smooth surface from the labelling: the HS normals integrated (:func:`refine_depth`).

    Each pass re-evaluates the HS normals (``evaluate``, the data term of rays
    at depths) at the refined depths; pieces the tangent-plane links do not
    join to a surface of ``opts.min_px`` pixels are left out. Its depth is
    still the labelling's: it only starts the consistent surface
    (:func:`colourhs.reconstruct.bayes.refine.refine_surface`). ``say``, if
    given, is called with a line of text per pass and per solve (progress: a
    pass takes seconds at high resolution).
    """
    H, W = shape
    passes = opts.passes
    ok &= large_components(ok.reshape(H, W), opts.min_px).ravel()
    z = np.nan_to_num(z)
    solver = NearbySolver()
    for i in range(passes):
        if say is not None:
            say(f"bayes: normal integration, pass {i + 1} of {passes}")
        z = refine_depth(
            z, nrm, rays, ok, (H, W), opts.data_weight, opts.edge_m, opts.anchor_scale, solver, say
        )
        if i == passes - 1:
            if say is not None:
                say("bayes: the integrated depth's surfaces (links, components)")
            links = surface_links(z, nrm, rays, ok, (H, W), opts.link_m)
            labels = surface_components(links[0], links[1], ok)
            sizes = np.bincount(labels[ok])
            labels[ok] = np.where(sizes[labels[ok]] >= opts.min_px, labels[ok], -1)
            ok &= labels >= 0
        c, n = evaluate(rays[pix] * z[pix][:, None], np.ones(1))
        good = c[:, 0] < INVALID_COST  # else keep the previous normal
        nrm[pix[good]] = n[good, 0]
    return z, nrm, ok
