"""Minimising the depth-normal consistency energy E (:mod:`colourhs.reconstruct.bayes.surface`).

Beyond the paper. Each connected surface's depth map is a cubic B-spline
(:mod:`colourhs.reconstruct.bayes.spline`). Levenberg-Marquardt fits its shape;
its depth, the one mode E determines weakly, comes from a search along E's
valley (:func:`colourhs.reconstruct.bayes.valley.depth_search`), and second
starts at the better-fitting neighbours' depths, or a few per cent either side of
its own (:func:`restart_round`), where the labelling left a surface beyond the
search's reach or at a local minimum of E; holes are filled
(:func:`~colourhs.reconstruct.bayes.surface.fill_holes`).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from colourhs.common.linalg import solve_spd
from colourhs.reconstruct.bayes.gram import SplineGram
from colourhs.reconstruct.bayes.restart import (
    RESTART_GAP,
    RESTART_TEST,
    energy_difference,
    neighbour_factors,
    surface_fit_levels,
    surface_median,
    with_scan,
)
from colourhs.reconstruct.bayes.spline import SplineSurface, default_spacing
from colourhs.reconstruct.bayes.surface import (
    EDGE_FOOTPRINTS,
    ROBUST,
    SurfaceGraph,
    fill_holes,
    hs_residuals,
    robust_energy,
    surface_normals,
)
from colourhs.reconstruct.bayes.uncertainty import (
    SIGMA_SAMPLES,
    depth_sigma,
    filled_sigma,
    pair_jackknife,
    robust_scale_pull,
    surface_depth_sigma,
    valley_blocks,
)
from colourhs.reconstruct.bayes.valley import depth_search, search_stride
from colourhs.reconstruct.inputs import RayGrid
from colourhs.reconstruct.sides import HelmholtzSides

CURVATURE_TOL_PER_M = 100.0  # weak prior on the spline: curvature radii under 1 cm cost
LM_START, LM_MIN = 1e-3, 1e-9  # Levenberg-Marquardt damping, relative to diag(A)
LM_UP, LM_DOWN, LM_TRIES = 10.0, 0.3, 8
COARSE = 8.0  # the first fit's control spacing, in units of the final spacing
CONVERGED = 1e-6  # predicted decrease of E (chi2 units) below which a surface has converged
LM_SETTLED = 1e-2  # settled: a step moves E and its robust scale by less than this share
LM_MAX_STEPS = 40  # at most this many LM steps in a stage that must settle
RESTART_ROUNDS = 4  # rounds of second starts at a neighbour's depth (refine_surface)
RESTART_KEEP = 0.9  # a second start must keep this share of a surface's usable pixels
"""Why these values hold on any rig:

- ``CURVATURE_TOL_PER_M``: the prior's unit is a curvature (1/m) times the
  data's own noise level (:meth:`_Problem.prior`), so it neither depends on
  the resolution nor on how close the data are to the noise model; 100 /m
  (a 1 cm radius) is far sharper than the objects' curvature, so the prior
  only decides where there are no data.
- ``LM_*``: dimensionless (relative to the Gauss-Newton diagonal).
- ``CONVERGED``: E is in units of the noise (chi2), so 1e-6 is a millionth
  of one pixel's noise-level residual on any rig: nothing any estimate
  could notice. Without it a converged surface (a one-pixel surface, say,
  whose E is at rounding level) would raise its damping ``LM_TRIES`` times
  per step, one solve each.
- ``LM_SETTLED``: a share of E and of its robust scale, so free of units
  and of the rig's noise level. The depth search compares E at depths a
  step apart (:data:`~colourhs.reconstruct.bayes.valley.SEARCH_STEP`),
  where E differs by about a per cent of itself near the minimum; a shape
  whose E (or scale, which sets which rows count) still moves by more per
  LM step is not converged, and a search started from it reads the fall
  as a valley.
- ``LM_MAX_STEPS``: a count of steps, each a solve of the same cost on any
  rig; a start far from E's minimum (a discrete depth map pulled off by a
  wrong calibration on whole regions) settles in a few tens of steps on
  the coarse spline, and a final stage that has not settled by then is
  reported (its depths' sigma is infinite).
- ``RESTART_ROUNDS``: a count of hops, each passing a depth from one
  surface to the next (:mod:`colourhs.reconstruct.bayes.restart`), so free of
  the rig; a round refines only the surfaces restarted, and only the first
  scans the depths around the surfaces that have no better neighbour.
- ``RESTART_KEEP``: a share of pixels. E compares two depths over the
  pixels usable at both (:meth:`_Problem.compare`); a depth where a surface
  loses more than a tenth of them to the other views' silhouettes and
  shadows is compared on what is left, and such depths hold false minima.
- ``COARSE``: a ratio of spacings, so free of units. The fine spline's
  first LM steps cannot pull in a part of a surface whose start is several
  millimetres off (its residuals are far beyond the robust scale, so it has
  no weight, and the fine spline lets it keep its own shape); on the coarse
  spline its control points are shared with the rest of the surface, which
  carries it.
"""


def _problem(graph, R, sides, c_ref, spacing, footprint, robust) -> _Problem:
    """E over a spline of control spacing ``spacing`` (pixels) on ``graph``'s surfaces;
    ``footprint`` is the pixels' median lateral size (metres), the prior's unit."""
    spline = SplineSurface(graph.rows, graph.cols, graph.surface, spacing)
    D, prior_surface = spline.second_differences()
    Dw = D * (1.0 / (CURVATURE_TOL_PER_M * (spacing * footprint) ** 2))
    return _Problem(graph, R, sides, c_ref, spline, Dw, prior_surface, robust, footprint)


class _Problem:
    """E of the spline's control points, per surface (the surfaces are independent:
    no triangle or prior row joins two), and its Levenberg-Marquardt steps."""

    def __init__(self, graph, R, sides, c_ref, spline, Dw, prior_surface, robust, footprint):
        self.graph, self.R, self.sides, self.c_ref = graph, R, sides, c_ref
        self.footprint = footprint
        self.spline, self.B, self.Dw, self.robust = spline, spline.basis, Dw, robust
        self.Bt = spline.basis.T.tocsr()  # B^T, once: every step multiplies by it
        self.active = None  # every pixel's rows count
        self.gram = self._gram()
        self.DtD = (Dw.T @ Dw).tocsr()  # the prior's normal matrix at level 1
        self.ctrl_surface = spline.surface_of
        self.prior_surface = prior_surface
        self.n = graph.n_surfaces
        self.pixel_weight = None

    def subsampled(self, stride: int) -> _Problem:
        """The same E over every ``stride``-th pixel in rows and columns.

        Beyond the paper (speed). Each kept pixel's robust energy, rows and
        Jacobian count ``n_k / kept_k`` times (its surface's pixels over those
        kept), so the data keep their weight against the prior and E its
        scale; the kept pixels' normals still come from their four
        neighbours. A surface that would keep fewer pixels than one control
        cell holds at full resolution keeps all of its pixels.
        """
        if stride <= 1:
            return self
        g = self.graph
        active = (g.rows % stride == 0) & (g.cols % stride == 0)
        kept = np.bincount(g.surface[active], minlength=self.n)
        small = kept < self.spline.spacing**2
        active |= small[g.surface]
        kept = np.bincount(g.surface[active], minlength=self.n)
        total = np.bincount(g.surface, minlength=self.n)
        out = copy.copy(self)
        out.active = active
        out.pixel_weight = np.where(active, total[g.surface] / np.maximum(kept[g.surface], 1), 0)
        out.gram = out._gram()
        return out

    def with_sides(self, sides: HelmholtzSides) -> _Problem:
        """The same E over other ``sides`` (another set of reciprocal pairs) on the
        same spline and pixels: its control points are this problem's."""
        out = copy.copy(self)
        out.sides = sides
        out.gram = out._gram()
        return out

    def _gram(self) -> SplineGram:
        """The Gauss-Newton matrix's assembly for this problem's pairs and active pixels."""
        return SplineGram(
            self.B, self.spline.grid_coords, self.graph.neighbours, self.sides.pairs, self.active
        )

    def restricted(self, keep) -> _Problem:
        """E over the surfaces ``keep`` (n_surfaces,) bool alone; its control points
        are this problem's ``c[keep[self.ctrl_surface]]`` (a surface's control
        grid depends on its own pixels alone)."""
        sub = self.graph.subset(keep)
        spacing = self.spline.spacing
        return _problem(
            sub, self.R[sub.index], self.sides, self.c_ref, spacing, self.footprint, self.robust
        )

    def _residuals(self, c, **kw):
        """:func:`hs_residuals` at control points ``c`` over the counted pixels."""
        return hs_residuals(
            self.B @ c, self.graph, self.R, self.sides, self.c_ref, active=self.active, **kw
        )

    def _weighted(self, rho):
        return rho if self.pixel_weight is None else rho * self.pixel_weight

    def state(self, c, scale, info=None) -> tuple[np.ndarray, np.ndarray]:
        """Each pixel's robust energy rho (NaN where unusable) and each surface's
        prior energy (n_surfaces,), at Geman-McClure ``scale``; ``info`` from
        :func:`hs_residuals` at ``c`` saves sampling the images again."""
        if info is None:
            _, rho, _ = self._residuals(c, jacobian=False, scale=scale)
        else:
            rho = robust_energy(info["chi2"], info["valid"], scale)
        prior = self.prior(scale) @ c
        return self._weighted(rho), np.bincount(self.prior_surface, prior * prior, self.n)

    def prior(self, scale) -> sp.csr_matrix:
        """The prior's rows in the data's units at Geman-McClure ``scale``.

        The data's chi2 is in units of the predicted noise, or of the residuals'
        own level where that is larger (``scale / (robust^2 P)``, see
        :func:`hs_residuals`): the prior is scaled by the same level, so that
        its weight against the data does not depend on how far the data are
        from the noise model (on exact data the predicted noise is only the
        quantisation, and an unscaled prior would leave the holes' control
        points to rounding errors).
        """
        level = scale / (self.robust**2 * self.sides.pairs)
        return self.Dw * np.sqrt(level)

    def compare(self, states) -> np.ndarray:
        """(len(states), n_surfaces) energies of several states over the pixels
        usable in all of them.

        A pixel whose samples are unusable at a depth (off an image, outside a
        silhouette, in a shadow) carries no information on that depth, so it
        must neither cost (at rho's ceiling: it would pull a surface towards
        the depth where more of its rim stays inside the other views'
        silhouettes) nor pay (nothing, or the mean of the others: it would
        pull the other way): energies compare over the pixels usable in every
        state compared.
        """
        common = np.all([np.isfinite(rho) for rho, _ in states], axis=0)
        surf = self.graph.surface[common]
        return np.stack([np.bincount(surf, rho[common], self.n) + prior for rho, prior in states])

    def scale(self, c) -> float:
        """The Geman-McClure scale of the residuals at ``c`` (see :func:`hs_residuals`)."""
        return self._residuals(c, robust=self.robust, jacobian=False)[2]["scale"]

    def lm(self, c, iterations: int, scale=None, lam=LM_START, say=None, settle=False):
        """``iterations`` Levenberg-Marquardt steps, each kept per surface where it
        lowers that surface's energy (else its damping rises and it tries again,
        up to ``LM_TRIES`` times; a kept step lowers it). The damping is
        relative to the diagonal of the Gauss-Newton matrix, so it has no unit.

        Beyond plain Gauss-Newton: the sampled intensities make E non-linear in
        the depth, and the damping keeps each step where the linear model holds.
        ``scale`` fixes the robust scale (default: from the residuals at each
        step). With ``settle``, steps go on after ``iterations`` until E has
        settled: the robust scale moved by at most ``LM_SETTLED`` of itself and
        the last step lowered E, at one scale, by at most ``LM_SETTLED`` of it;
        at most ``LM_MAX_STEPS`` steps in all (beyond the paper: a fixed count
        leaves a start far from E's minimum unconverged, and the depth search
        then reads E's fall as a valley).
        ``say(text)``, if given, is called before each step (progress:
        a step takes seconds at high resolution). Returns the control points,
        the total energy after each step, :meth:`state` at the returned
        control points at the last step's scale (the same numbers a new
        :meth:`state` call gives: a pixel's energy depends on its own
        surface's control points alone; None without steps) and whether E
        settled (False without ``settle``).
        """
        lam = np.full(self.n, float(lam))
        history, s0, rows, drop, last_sc, calm = [], None, None, np.inf, np.nan, False
        for step in range(max(iterations, LM_MAX_STEPS) if settle else iterations):
            if say is not None:
                say(f"refinement: LM step {step + 1} of {iterations}{'+' if settle else ''}")
            if rows is None:
                rows = self._residuals(c, robust=self.robust, scale=scale)
            Jz, r, info = rows
            # With the scale fixed, a pixel's rows depend on its own surface's
            # control points alone: the next step's rows are, pixel by pixel,
            # those of the try kept for its surface (or of this step), so the
            # tries compute them and the next step does not sample E again.
            reuse = scale is not None and step + 1 < iterations
            sc = info["scale"]
            if settle and step >= iterations:
                calm = abs(sc - last_sc) <= LM_SETTLED * sc and drop <= LM_SETTLED
                if calm:
                    break
            last_sc = sc
            s0 = self.state(c, sc, info)
            before = _energy(s0)
            Dw = self.prior(sc)
            level = sc / (self.robust**2 * self.sides.pairs)  # Dw = self.Dw sqrt(level)
            vals = info["jacobian_values"]
            if self.pixel_weight is not None:  # rows and residuals times sqrt(weight)
                w = np.repeat(self.pixel_weight[self.active], self.sides.pairs)
                vals, r = vals * np.sqrt(w)[:, None], r * w
            A = self.gram.matrix(vals) + self.DtD * level
            g = self.Bt @ (Jz.T @ r) + Dw.T @ (Dw @ c)
            diag = A.diagonal() + 1e-12 * max(A.diagonal().mean(), 1e-300)
            pending = np.ones(self.n, bool)
            for _ in range(LM_TRIES):
                damp = sp.diags(lam[self.ctrl_surface] * diag)
                h = solve_spd(A + damp, -g)
                cc = c + h
                if reuse:
                    tried = self._residuals(cc, robust=self.robust, scale=sc)
                    s1 = self.state(cc, sc, tried[2])
                else:
                    s1 = self.state(cc, sc)
                e0, e = self.compare([s0, s1])
                better = pending & (e < e0)
                if reuse and better.any():
                    rows = _kept_rows(
                        rows, tried, better[self.graph.surface], self.sides.pairs, self.active
                    )
                # A surface whose quadratic model predicts no decrease worth
                # noticing has converged: more damping cannot make it improve.
                predicted = np.bincount(self.ctrl_surface, -h * (g + 0.5 * (A @ h)), self.n)
                pending &= predicted > CONVERGED
                c = np.where(better[self.ctrl_surface], cc, c)
                s0 = (
                    np.where(better[self.graph.surface], s1[0], s0[0]),
                    np.where(better, s1[1], s0[1]),
                )
                lam = np.where(better, np.maximum(lam * LM_DOWN, LM_MIN), lam)
                pending &= ~better
                lam = np.where(pending, lam * LM_UP, lam)
                if not pending.any():
                    break
            history.append(_energy(s0))
            drop = (before - history[-1]) / max(abs(history[-1]), 1e-300)  # at one scale
            if not reuse:
                rows = None
        return c, history, s0, calm

    def fit(self, z) -> np.ndarray:
        """Control points whose spline is the least-squares fit to depths ``z`` (n,)."""
        BtB = (self.B.T @ self.B).tocsc()
        eps = 1e-9 * BtB.diagonal().mean() * sp.identity(self.B.shape[1], format="csc")
        return solve_spd(BtB + eps, self.B.T @ z)

    def scaled(self, c, factor) -> np.ndarray:
        """Control points with each surface k's depths multiplied by ``factor[k]``."""
        return c * factor[self.ctrl_surface]


def _energy(state) -> float:
    """E of a :meth:`_Problem.state`: its pixels' robust energies and the priors."""
    return float(np.nansum(state[0]) + state[1].sum())


def _kept_rows(rows, tried, take, pairs: int, active=None):
    """:func:`hs_residuals`' output ``(J, r, info)`` at the control points kept:
    ``tried``'s rows for the pixels ``take`` (n,), ``rows``' for the others
    (both evaluated over the pixels ``active``, default all).

    Exact: each pixel's rows, weight and chi2 depend only on its own
    surface's control points (and, with the scale fixed, not on the others'
    residuals), so they equal a new evaluation at the kept points.
    """
    J, r, info = rows
    _, r1, info1 = tried
    row = np.repeat(take if active is None else take[active], pairs)
    vals = np.where(row[:, None], info1["jacobian_values"], info["jacobian_values"])
    kept = {k: np.where(take, info1[k], info[k]) for k in ("valid", "weights", "chi2")}
    kept.update(scale=info["scale"], jacobian_values=vals)
    J = sp.csr_matrix((vals.ravel(), J.indices, J.indptr), shape=J.shape)
    return J, np.where(row, r1, r), kept


def restart_round(
    problem, c, factors, valley, focal_px, iterations, search_kw, say=None, scan=False
):
    """One round of second starts: each surface restarted at the depths of its
    neighbours that fit better (:func:`.restart.neighbour_factors`) and, with
    ``scan``, one without such a neighbour at :data:`.restart.SCAN_STARTS`
    times its own depth (:func:`.restart.with_scan`).

    Beyond the paper. For each neighbour's depth in turn, the surfaces that
    have one are refined again from it (``iterations`` LM steps,
    :func:`.valley.depth_search` with ``search_kw``, LM steps until E settles),
    alone and at the robust scale of the residuals at ``c``; a surface keeps
    the new depth where its E over the pixels usable at both is lower than
    its best so far and it keeps ``RESTART_KEEP`` of its usable pixels; a
    scanned surface's E must be lower by ``RESTART_TEST`` standard errors
    (its start is a guess: a lower E within E's noise would trade one depth
    the data support for another, adding scatter, not accuracy).
    ``focal_px``: the reference camera's focal length, pixels (the
    neighbours' gap, :data:`~colourhs.reconstruct.bayes.restart.RESTART_GAP`).

    Where E's difference between the two depths is within ``RESTART_TEST``
    of its standard error (:func:`.restart.energy_difference`), the data do
    not rule either out; where E prefers the other depth beyond that but the
    surface loses too many pixels there to take it, they contest its own
    (:func:`restart_verdicts`). Either way half their relative distance is the
    surface's ``spread``, which joins its depth factor's sigma.

    Returns the control points, the depth factors and their relative sigmas
    (n_surfaces,; the new search's where a surface was restarted), the
    surfaces restarted (n_surfaces,) bool, whether the restarted surfaces'
    E settled, and each surface's relative ``spread`` (n_surfaces,).
    """
    from scipy.ndimage import median

    g = problem.graph
    _, _, info = problem._residuals(c, robust=problem.robust, jacobian=False)
    sc = info["scale"]
    level = surface_fit_levels(
        info["chi2"], info["valid"], g.surface, problem.n, problem.sides.pairs
    )
    f = neighbour_factors(g, problem.B @ c, level, RESTART_GAP * focal_px)
    # A scanned surface has no better neighbour: its start is a guess, not another
    # surface's evidence, and must win beyond E's noise (below).
    scanned = ~np.isfinite(f).any(axis=1) if scan else np.zeros(problem.n, bool)
    if scan:
        f = with_scan(f)
    taken = np.zeros(problem.n, bool)
    start, start_factors = c, np.asarray(factors)
    spread = np.zeros(problem.n)
    factors, valley = factors.copy(), valley.copy()
    settled_all = True
    for j in range(f.shape[1]):
        cand = np.isfinite(f[:, j])
        if not cand.any():
            break
        if say is not None:
            say(f"refinement: {int(cand.sum())} surfaces restarted at another depth")
        sub = problem.restricted(cand)
        mine = cand[problem.ctrl_surface]
        c0 = c[mine]
        alt = sub.scaled(start[mine], f[cand, j])  # each start from the round's depths
        alt, _, _, _ = sub.lm(alt, iterations, scale=sc, say=say)
        stride = search_stride(sub.spline.spacing)
        alt, fa, va = depth_search(sub.subsampled(stride), alt, scale=sc, say=say, **search_kw)
        alt, _, _, settled = sub.lm(alt, iterations, scale=sc, say=say, settle=True)
        s0, s1 = sub.state(c0, sc), sub.state(alt, sc)
        e0, e1 = sub.compare([s0, s1])
        u0 = np.bincount(sub.graph.surface, np.isfinite(s0[0]), sub.n)
        u1 = np.bincount(sub.graph.surface, np.isfinite(s1[0]), sub.n)
        sg = sub.graph
        blocks = valley_blocks(sg.rows, sg.cols, sg.shape[1], sub.spline.spacing)
        diff, se = energy_difference(s0[0], s1[0], s0[1], s1[1], sg.surface, blocks, sub.n)
        better, unsettled = restart_verdicts(u0, u1, e1 < e0, diff, se, scanned[cand])
        z0, z1 = sub.B @ c0, sub.B @ alt
        apart = np.abs(median(z1 / z0 - 1.0, sg.surface, np.arange(sub.n)))
        spread[cand] = np.maximum(spread[cand], np.where(unsettled, 0.5 * apart, 0.0))
        c = c.copy()
        c[mine] = np.where(better[sub.ctrl_surface], alt, c0)
        taken[cand] |= better
        moved = start_factors[cand] * f[cand, j] * fa
        factors[cand] = np.where(better, moved, factors[cand])
        valley[cand] = np.where(better, va, valley[cand])
        settled_all &= bool(settled or not better.any())
    return c, factors, valley, taken, settled_all, spread


def restart_verdicts(u0, u1, lower, diff, se, scanned) -> tuple[np.ndarray, np.ndarray]:
    """What :func:`restart_round` makes of each surface's second start (beyond the paper).

    ``u0``, ``u1`` (n,): the surface's usable pixels at its own depth and at the
    start's end; ``lower`` (n,): E is lower there (:meth:`_Problem.compare`);
    ``diff``, ``se`` (n,): E's difference (the start's less its own) over the pixels
    usable at both and its standard error (:func:`.restart.energy_difference`);
    ``scanned`` (n,): the start is a scan's guess (:func:`.restart.with_scan`).

    Returns ``better`` (n,), the start is taken: E is lower, the surface keeps
    ``RESTART_KEEP`` of its usable pixels (a depth compared on what is left of
    them holds false minima), and a scanned start wins beyond E's noise
    (``RESTART_TEST`` standard errors); and ``unsettled`` (n,): the data do not settle
    the surface at its depth, so its sigma must cover the other: E's difference is
    within its noise where the two are comparable (a tie), or E prefers the start
    beyond its noise where the surface loses too many pixels there to take it (a
    contest: the surface keeps a depth the pixels usable at both reject).
    """
    comparable = (u1 >= RESTART_KEEP * u0) & (u1 > 0)
    clear = ~scanned | (diff < -RESTART_TEST * se)
    better = lower & comparable & clear
    tied = comparable & (np.abs(diff) < RESTART_TEST * se)
    contested = ~comparable & (u1 > 0) & (diff < -RESTART_TEST * se)
    return better, tied | contested


def explained_surfaces(chi2, usable, surface, scale) -> np.ndarray:
    """Which surfaces (n_surfaces,) the model explains: the median chi2 of a
    surface's usable pixels is under the Geman-McClure ``scale``.

    Beyond the paper. Where it is not, most of the surface's pixels have
    less than a quarter of their weight (rho'(chi2) = 1 / (1 + chi2 /
    scale)^2): the rows of eq. (5) do not agree with any shape near its
    depth (the white cells inside a marker, say, whose footprints mix with
    its black: no depth explains them). Such a surface is left out
    (its pixels may still be filled as a hole of a surface around it)
    rather than reported at a depth the data do not support.
    """
    n = int(surface.max()) + 1 if len(surface) else 0
    med = surface_median(chi2, usable, surface, n)
    return med < scale  # NaN (no usable pixel): not explained


@dataclass(frozen=True)
class RefineOptions:
    """How :func:`refine_surface` fits the consistent surface.

    Attributes
    ----------
    spacing_px : spline control spacing, pixels (default
        :func:`colourhs.reconstruct.bayes.spline.default_spacing`, scaled by the
        image's width).
    iterations : Levenberg-Marquardt steps per stage; the coarse and the
        final stage go on until E settles (:meth:`_Problem.lm`), the one
        before the depth search does not (its steps creep along E's valley,
        which the search walks instead).
    robust : Geman-McClure scale, in units of each row's predicted noise
        (:data:`~colourhs.reconstruct.bayes.surface.ROBUST`).
    edge_footprints : depth jump between neighbours that separates surfaces,
        in pixel footprints (:data:`~colourhs.reconstruct.bayes.surface.EDGE_FOOTPRINTS`).
    search : whether :func:`.valley.depth_search` sets each surface's depth.
    sigma_samples : draws of :func:`depth_sigma` (0: no uncertainty, all NaN).
    restarts : rounds of :func:`restart_round` after the search (with ``search``;
        the first also scans :data:`.restart.SCAN_STARTS`).
    """

    spacing_px: float | None = None
    iterations: int = 3
    robust: float = ROBUST
    edge_footprints: float = EDGE_FOOTPRINTS
    search: bool = True
    sigma_samples: int = SIGMA_SAMPLES
    restarts: int = RESTART_ROUNDS


def refine_surface(
    z0: np.ndarray,
    mask: np.ndarray,
    grid: RayGrid,
    sides: HelmholtzSides,
    footprint: np.ndarray,
    opts: RefineOptions = RefineOptions(),
    fill: np.ndarray | None = None,
    clear_sides: HelmholtzSides | None = None,
    ratio_sigma: np.ndarray | None = None,
    say=None,
) -> tuple[np.ndarray, np.ndarray, dict]:
    """Minimise E (module docstring) over a B-spline surface, from depths ``z0``.

    ``opts.iterations`` Levenberg-Marquardt steps on a spline ``COARSE`` times
    coarser, then as many on the final one, bring each surface's shape into
    agreement with the HS normals at its starting depth; :func:`.valley.depth_search`
    then finds each surface's depth (with ``opts.search``); ``opts.iterations``
    more steps polish shape and depth together; up to ``opts.restarts``
    rounds of :func:`restart_round` then restart surfaces at their
    neighbours' depths.

    Parameters
    ----------
    z0 : (H*W,) initial depths (metres; the discrete solution, refined).
    mask : (H*W,) pixels of the surface.
    grid : the reference camera's rays (H*W of them) and their origin.
    sides : from :func:`colourhs.reconstruct.sides.helmholtz_sides`.
    footprint : (H*W,) lateral size of a pixel at its depth, metres
        (z / focal length): the unit of depth edges and of the prior.
    opts : the fit's settings (:class:`RefineOptions`).
    fill : (H*W,) pixels that may be filled (the object's silhouette or the
        lit foreground): the holes of each surface inside it (black markers,
        dark spots, pixels whose rows were unusable) are filled by
        :func:`fill_holes` (their weight, and so their confidence, is 0).
    clear_sides : the sides with only the samples clear of every edge usable
        (:data:`colourhs.reconstruct.sides.RIM_SUPPORT`): the rim rows' pull on
        each surface's depth (:func:`.uncertainty.rim_valley_pull`) joins the depths' sigma.
    ratio_sigma : (P,) 1-sigma of each pair's log ratio mu_a / mu_b (the
        photometric calibration's); its move of each surface's depth
        (:func:`.uncertainty.ratio_sensitivity`) joins the depths' sigma.
    say : called with a line of text at each step (progress), if given.

    Returns
    -------
    z : (H*W,) refined depths (NaN outside the mask).
    normals : (H*W, 3) unit normals of the refined surface (NaN outside).
    info : ``valid`` (H*W,) pixels of the result (without the surfaces
        that :func:`explained_surfaces` leaves out), ``weights`` (H*W,) final
        robust weights (0 where the rows were unusable), ``sigma`` (H*W,) each
        depth's 1-sigma uncertainty (:func:`.uncertainty.surface_depth_sigma`:
        :func:`depth_sigma`, the depth search's :func:`.uncertainty.valley_sigma`
        with its pulls, and at least the move of
        :func:`.uncertainty.robust_scale_pull` and the spread of
        :func:`.uncertainty.pair_jackknife`, metres; infinite on a surface
        whose depth mode has no error bar; :func:`filled_sigma` where the rows
        were unusable, in filled holes and on a surface within one block, there
        at least its depth's distance from the nearest measured one), ``filled`` (H*W,)
        filled holes, ``energy`` after each step, ``depth_factors`` (the
        search's scale per surface), ``robust_pull_m`` (per surface, the median
        of :func:`.uncertainty.robust_scale_pull`'s move, metres; None without a
        sigma), ``pair_jackknife_m`` (the same for :func:`.uncertainty.pair_jackknife`'s
        spread), ``converged`` (False where the final stage did not settle: every
        sigma is then infinite, and none of its parts is computed), ``surfaces``,
        ``restarted`` (surfaces whose depth came from a neighbour's,
        :func:`restart_round`) and ``control_points``.
    """
    rays, c_ref, shape = grid.rays, grid.centre, grid.shape
    H, W = shape
    iterations, robust = opts.iterations, opts.robust
    say = say or (lambda text: None)
    spacing = float(opts.spacing_px or default_spacing(W))
    graph = SurfaceGraph(mask, shape, z0, footprint, opts.edge_footprints)
    R = rays[graph.pix]
    fp = float(np.median(footprint[graph.pix]))
    coarse = _problem(graph, R, sides, c_ref, spacing * COARSE, fp, robust)
    say(f"refinement: {graph.n_surfaces} surfaces, {iterations} LM steps on a coarse spline")
    c, energies, _, _ = coarse.lm(coarse.fit(z0[graph.pix]), iterations, say=say, settle=True)
    problem = _problem(graph, R, sides, c_ref, spacing, fp, robust)
    B = problem.B
    say(f"refinement: {iterations} LM steps on {B.shape[1]} control points")
    c, more, _, _ = problem.lm(problem.fit(coarse.B @ c), iterations, say=say)
    energies += more
    factors = np.ones(graph.n_surfaces)
    valley = np.zeros(graph.n_surfaces)
    search_kw = {"clear_sides": clear_sides, "ratio_sigma": ratio_sigma}
    if opts.search:
        stride = search_stride(spacing)
        say(f"refinement: depth search along E's valley (pixel stride {stride})")
        c, factors, valley = depth_search(problem.subsampled(stride), c, say=say, **search_kw)
    say(f"refinement: {iterations} final LM steps")
    c, more, _, converged = problem.lm(c, iterations, say=say, settle=True)
    restarted = np.zeros(graph.n_surfaces, bool)
    ambiguity = np.zeros(graph.n_surfaces)  # relative: half the gap to a depth E cannot rule out
    if opts.search and graph.n_surfaces > 0:
        focal = float(np.median(np.abs(z0[graph.pix]) / footprint[graph.pix]))
        for k in range(opts.restarts):
            c, factors, valley, taken, settled, spread = restart_round(
                problem, c, factors, valley, focal, iterations, search_kw, say, scan=k == 0
            )
            converged &= settled
            restarted |= taken
            ambiguity = np.maximum(ambiguity, spread)
            if not taken.any():
                break
        valley = np.hypot(valley, ambiguity)
    z = B @ c
    _, _, info = hs_residuals(z, graph, R, sides, c_ref, robust, jacobian=False)
    out_z = np.full(H * W, np.nan)
    out_z[graph.pix] = z
    # Every pixel of the surface keeps the spline's depth; those whose rows
    # were unusable at it (a saturated or dark sample, a silhouette edge in
    # another view) have weight, and so confidence, 0.
    valid = np.zeros(H * W, bool)
    explained = explained_surfaces(info["chi2"], info["valid"], graph.surface, info["scale"])
    valid[graph.pix] = explained[graph.surface]
    out_z[graph.pix[~explained[graph.surface]]] = np.nan
    weights = np.zeros(H * W)
    weights[graph.pix] = info["weights"] * info["valid"]
    del info  # its sides (info["samples"]) need not stay through the error bar's refits
    sigma = np.full(H * W, np.nan)
    pull_median, jack_median = [None] * graph.n_surfaces, [None] * graph.n_surfaces
    if opts.sigma_samples > 0 and converged:  # unconverged: every sigma is infinite below
        say("refinement: each depth's uncertainty")
        local = depth_sigma(problem, c, opts.sigma_samples)
        say("refinement: the surface's move under a tighter robust scale")
        pull = np.abs(robust_scale_pull(problem, c))
        say("refinement: the surface refitted with each reciprocal pair left out")
        jack = pair_jackknife(problem, c)
        floor = np.maximum(pull, jack)
        sigma[graph.pix] = surface_depth_sigma(local, z, valley, graph.surface, floor)
        on, n_s = np.isfinite(local), graph.n_surfaces
        pull_median, jack_median = (
            [None if np.isnan(m) else float(m) for m in surface_median(v, on, graph.surface, n_s)]
            for v in (pull, jack)
        )
    filled = np.zeros(H * W, bool)
    if fill is not None:
        zh = fill_holes(z, graph, fill, rays, surfaces=explained)
        filled = np.isfinite(zh) & (zh > 0)
        out_z[filled] = zh[filled]
        valid |= filled
    # Fragments too small to measure their depth mode, then filled holes and pixels
    # whose rows were unusable: from the nearest measured depth. An infinite sigma
    # (a surface without an error bar) is a measured one, and spreads.
    sigma[~valid] = np.nan  # no depth: no evidence for a neighbour's
    fragment = np.zeros(H * W, bool)
    fragment[graph.pix] = np.isnan(valley[graph.surface])
    fragment &= valid & np.isnan(sigma)
    sigma[fragment] = filled_sigma(sigma, fragment, shape, out_z)
    guessed = valid & np.isnan(sigma)
    sigma[guessed] = filled_sigma(sigma, guessed, shape)
    if not converged:  # E's minimum was not reached: no depth of it is known
        sigma[valid] = np.inf
    out_n = np.full((H * W, 3), np.nan)
    if valid.any():  # the output's normals: E's, over the output's own links
        # Filled holes had no footprint: it is z / focal length, so scale it from out_z.
        per_m = float(np.median(footprint[graph.pix] / np.abs(z0[graph.pix])))
        final = SurfaceGraph(valid, shape, out_z, np.abs(out_z) * per_m, opts.edge_footprints)
        out_n[final.pix] = surface_normals(final, out_z[final.pix], rays, c_ref)
        valid[final.pix] = np.all(np.isfinite(out_n[final.pix]), axis=1)
    return (
        out_z,
        out_n,
        {
            "valid": valid,
            "weights": weights,
            "sigma": sigma,
            "energy": energies + more,
            "filled": filled,
            "depth_factors": factors.tolist(),
            "depth_factor_sigma": valley.tolist(),
            "robust_pull_m": pull_median,
            "pair_jackknife_m": jack_median,
            "surfaces": int(graph.n_surfaces),
            "restarted": int(restarted.sum()),
            "control_points": int(B.shape[1]),
            "converged": bool(converged),
        },
    )
