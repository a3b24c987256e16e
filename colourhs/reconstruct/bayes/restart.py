"""Surfaces restarted at their neighbours' depth (beyond the paper).

Under strong noise the labelling's start can leave a surface far outside the
reach of the depth search (:mod:`colourhs.reconstruct.bayes.valley`): a
depth mode E determines weakly is then fitted to a local minimum of E, with
a small valley sigma. The pieces of one continuous object, split by depth
edges in a wrong start or by dark pure-colour patches between them, each
find their own depth, and some find the truth. These functions give each
surface the depths of its better-fitting neighbours as second starts, and
a surface with no such neighbour starts 2 % nearer and farther than its own
depth, where E may hold a lower minimum behind a rise (:func:`with_scan`);
:func:`colourhs.reconstruct.bayes.refine.refine_surface` refines from each
and keeps whichever start ends at the lowest E (a scanned start only beyond
E's noise, :data:`RESTART_TEST`).
"""

from __future__ import annotations

import numpy as np

RESTART_GAP = 0.015  # surfaces closer than this share of the focal length (pixels) are neighbours
RESTART_MIN = 0.01  # a neighbour's depth differs by less than this share: no second start
RESTART_STARTS = 3  # at most this many neighbours' depths are tried per surface and round
RESTART_TEST = 2.0  # E must prefer one depth by this many standard errors to rule the other out
SCAN_STARTS = (0.98, 1.02)  # depth factors tried on a surface without a better neighbour
"""Why these values hold on any rig:

- ``RESTART_GAP``: two points of one surface ``g`` pixels apart differ in
  depth by at most ``tan(slant) g / f`` of it (``f`` the focal length in
  pixels); at ``0.015 f`` and a slant of 60 degrees that is 2.6 %, inside
  the depth search's reach (6 %), so the neighbour's depth is a start from
  which the search finds the surface's own; a share of the focal length is
  a fixed field angle, the same on any rig and at any resolution.
- ``RESTART_MIN``: a relative depth, two of the depth search's steps: a
  start that close is within the search's own walk.
- ``RESTART_STARTS``: a count of starts. A surface's neighbour that fits
  better can still be wrong (it fits its own local minimum well): each of
  the three with the longest borders is tried, and E picks.
- ``RESTART_TEST``: in standard errors of E's difference between the two
  depths (:func:`energy_difference`), which are in the data's own noise
  units on any rig: a difference under two (a 5 % two-sided test) does
  not rule the other depth out, and the surface's sigma must cover it.
- ``SCAN_STARTS``: relative depths, so the same at any working distance.
  The depth search walks downhill from its start and stops where E rises,
  so a local minimum of E along the valley can hold a surface a few per
  cent off, behind a rise, with a worse fit than the truth's. A start 2 %
  (four search steps) either side is past such a rise, and its own search
  walks on for 6 %, so starts farther out add cost and no reach.
"""


def surface_median(values, usable, surface, n_surfaces: int) -> np.ndarray:
    """The median of ``values`` (n,) over each surface's ``usable`` (n,) pixels
    (n_surfaces,); NaN where a surface (``surface`` (n,)) has none."""
    from scipy.ndimage import median

    out = np.full(n_surfaces, np.nan)
    has = np.bincount(surface[usable], minlength=n_surfaces) > 0
    if has.any():
        med = np.asarray(median(values[usable], surface[usable], np.arange(n_surfaces)), float)
        out[has] = med[has]
    return out


def surface_fit_levels(chi2, usable, surface, n_surfaces: int, pairs: int) -> np.ndarray:
    """How well each surface (n_surfaces,) fits eq. (5): the median chi2 of its usable
    pixels per degree of freedom, in units of the predicted noise (1 on the noise
    model; NaN without a usable pixel).

    ``chi2`` (n,), ``usable`` (n,) and ``surface`` (n,) as
    :func:`colourhs.reconstruct.bayes.surface.hs_residuals` and
    :class:`~colourhs.reconstruct.bayes.surface.SurfaceGraph` give them;
    ``pairs`` rows per pixel (the median of a chi-square with P degrees of
    freedom is about P - 2/3).
    """
    return surface_median(chi2, usable, surface, n_surfaces) / (pairs - 2.0 / 3.0)


def neighbour_factors(
    graph, z: np.ndarray, level: np.ndarray, gap_px: float, starts: int = RESTART_STARTS
) -> np.ndarray:
    """Per surface of ``graph``, the depth factors (n_surfaces, ``starts``) that put it at
    the depths of its neighbours that fit better; NaN where there are fewer.

    A neighbour of surface s is a surface with a pixel within ``gap_px``
    (pixels) of one of s's; it qualifies where its ``level``
    (:func:`surface_fit_levels`) is below s's. Its factor is the median,
    over s's pixels within ``gap_px`` of it, of the nearest neighbour
    pixel's depth over the pixel's own (``z`` (n,), the graph's pixels'
    depths). The neighbours come in the order of those pixels' count (the
    longest common border first); factors within ``RESTART_MIN`` of 1 or
    of one before are left out.
    """
    from scipy.ndimage import distance_transform_edt

    H, W = graph.shape
    lab = np.full((H, W), -1)
    lab[graph.rows, graph.cols] = graph.surface
    depth = np.zeros((H, W))
    depth[graph.rows, graph.cols] = z
    fit = np.where(np.isfinite(level), level, np.inf)
    out = np.full((graph.n_surfaces, starts), np.nan)
    reach = int(np.ceil(gap_px)) + 1
    order = np.argsort(graph.surface, kind="stable")
    bounds = np.searchsorted(graph.surface[order], np.arange(graph.n_surfaces + 1))
    for s in np.flatnonzero(np.isfinite(level)):
        mine = order[bounds[s] : bounds[s + 1]]
        r, c = graph.rows[mine], graph.cols[mine]
        # Only pixels within the gap of the surface can be its neighbours:
        # the distance transform runs over its box grown by the gap.
        r0, c0 = max(r.min() - reach, 0), max(c.min() - reach, 0)
        r1, c1 = min(r.max() + reach + 1, H), min(c.max() + reach + 1, W)
        box = lab[r0:r1, c0:c1]
        better = (box >= 0) & (fit[np.maximum(box, 0)] < fit[s])
        if not better.any():
            continue
        dist, (ii, jj) = distance_transform_edt(~better, return_indices=True)
        r, c = r - r0, c - c0
        near = dist[r, c] <= gap_px
        if not near.any():
            continue
        ni, nj = ii[r[near], c[near]] + r0, jj[r[near], c[near]] + c0
        nb = lab[ni, nj]
        ratio = depth[ni, nj] / z[mine][near]
        counts = np.bincount(nb)
        found = [1.0]
        for t in np.argsort(-counts, kind="stable")[: int(np.count_nonzero(counts))]:
            f = float(np.median(ratio[nb == t]))
            if min(abs(f - g) for g in found) > RESTART_MIN and len(found) <= starts:
                out[s, len(found) - 1] = f
                found.append(f)
    return out


def with_scan(factors: np.ndarray, scan=SCAN_STARTS) -> np.ndarray:
    """:func:`neighbour_factors`' ``factors`` (n_surfaces, k), with the relative
    depths ``scan`` as the starts of each surface that has no neighbour's
    (n_surfaces, max(k, len(scan)))."""
    n, k = factors.shape
    out = np.full((n, max(k, len(scan))), np.nan)
    out[:, :k] = factors
    lone = ~np.isfinite(factors).any(axis=1)
    out[np.ix_(lone, np.arange(len(scan)))] = scan
    return out


def energy_difference(rho0, rho1, prior0, prior1, surface, groups, n_surfaces: int):
    """E's difference between two states of the surfaces, with its standard error.

    ``rho0``, ``rho1`` (n,) each pixel's robust energy in the two states
    (NaN where unusable), ``prior0``, ``prior1`` (n_surfaces,) the prior
    energies, ``surface`` (n,) each pixel's surface and ``groups`` (n,) its
    block (:func:`~colourhs.reconstruct.bayes.uncertainty.valley_blocks`).
    Over the pixels usable in both, each surface's difference
    ``D = sum_g D_g + prior1 - prior0`` of its blocks' differences ``D_g``
    has the cluster-robust standard error
    ``sqrt(G / (G - 1) sum_g (D_g - mean D_g)^2)`` (blocks about
    independent, as in :func:`~colourhs.reconstruct.bayes.uncertainty.valley_sigma`).
    Returns D and its standard error (n_surfaces,) (inf with fewer than two blocks).
    """
    common = np.isfinite(rho0) & np.isfinite(rho1)
    s, g = surface[common], groups[common]
    _, cell = np.unique(s * (int(groups.max(initial=0)) + 1) + g, return_inverse=True)
    n_cells = int(cell.max()) + 1 if len(cell) else 0
    d_cell = np.bincount(cell, rho1[common] - rho0[common], n_cells)
    cell_surface = np.zeros(n_cells, np.int64)
    cell_surface[cell] = s
    G = np.bincount(cell_surface, minlength=n_surfaces).astype(float)
    total = np.bincount(cell_surface, d_cell, n_surfaces)
    mean = np.where(G > 0, total / np.maximum(G, 1), 0.0)
    ss = np.bincount(cell_surface, (d_cell - mean[cell_surface]) ** 2, n_surfaces)
    with np.errstate(divide="ignore", invalid="ignore"):
        se = np.where(G >= 2, np.sqrt(G / (G - 1) * ss), np.inf)
    return total + np.asarray(prior1) - np.asarray(prior0), se
