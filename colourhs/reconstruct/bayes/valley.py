"""Each surface's depth along E's valley: the depth search (beyond the paper).

Under noise the energy E of :mod:`colourhs.reconstruct.bayes.surface` has a long,
nearly flat valley along each surface's depth (a scale of the surface about
the camera centre); :func:`depth_search` walks it and takes E's minimum
there, and gives the depth mode's uncertainty from its own trials
(:mod:`colourhs.reconstruct.bayes.uncertainty`). :func:`search_stride` subsamples
the pixels it uses at high resolution. Called by
:func:`colourhs.reconstruct.bayes.refine.refine_surface`.
"""

from __future__ import annotations

import copy
from functools import partial

import numpy as np

from colourhs.reconstruct.bayes.restart import RESTART_TEST
from colourhs.reconstruct.bayes.uncertainty import (
    energy_rise,
    flat_valley_sigma,
    measured_valley_sigma,
    pair_disagreement,
    ratio_sensitivity,
    rim_valley_pull,
    valley_blocks,
)

SEARCH_STEP = 0.005  # depth search step, relative (0.5 % of the depth)
SEARCH_STEPS = 12  # at most 6 % of the depth either way
SEARCH_FITS = 3  # LM steps that re-fit the shape at each depth of the search
SEARCH_PARABOLAS = (1.0, 0.25, 0.05)  # half-widths of the parabolas through E, in steps
SEARCH_CELL_PX = 5.0  # the depth search keeps at least this many pixels across a control cell
"""Why these values hold on any rig:

- ``SEARCH_STEP``: a relative depth, so the same at any working distance;
  the labelling's error on smooth surfaces is a few labels to a few per cent
  of the depth, so ``SEARCH_STEPS`` steps of 0.5 % (6 %) cover it.
- ``SEARCH_FITS``: with fewer re-fitting steps per depth the shape has not
  converged, and the valley's energy is then noisy enough to move a surface's
  depth, most of all on exact data, where E's minimum is sharp.
- ``SEARCH_PARABOLAS``: half-widths (in steps) of the parabolas fitted
  through E around the best depth, each through the previous vertex. On
  exact data E is sharp and, beyond a few tenths of a millimetre, flattened
  by the robust function, so a parabola a quarter step (1 mm at 0.8 m) wide
  can put its vertex off the minimum (a uniform offset; E at the result
  above E at the truth); the third, a twentieth of a step wide, is within
  the parabola's own range.
- ``SEARCH_CELL_PX``: in pixels of the spline's own spacing, which is a
  fixed fraction of the image width, so the subsampling
  (:func:`search_stride`) is the same on any rig at a given resolution:
  none below 1200 pixels wide (spacing < 10 px: the demo and random presets),
  every 2nd pixel in rows and columns from 1200 to 1799 (the paper preset's
  1280: a quarter of each cell's pixels kept).
"""


def search_stride(spacing: float) -> int:
    """Pixel stride of the depth search: ``floor(spacing / SEARCH_CELL_PX)``, at least 1.

    Beyond the paper (speed). The search fits each trial depth's shape and
    compares E along the valley; both rest on many pixels per control cell
    (``spacing^2``), so at high resolution a subsample decides them as well
    and each trial costs a ``stride^2``-th of the pixels' work; the final
    Levenberg-Marquardt steps use every pixel.
    """
    return max(1, int(spacing // SEARCH_CELL_PX))


def walk_out(tried, best, blocks, flat, step, max_steps, run) -> None:
    """Trial depths beyond E's flat minimum, until E rises beyond its noise (beyond the paper).

    For each surface ``flat`` (n,) bool (E does not curve upwards about its
    ``best`` (n,) depth factor), on each side in turn, ``run(deltas, record)``
    tries a step ``step`` beyond its farthest trial depth on that side (``deltas``
    (n,), ``best`` for the others; ``record`` (n,) the surfaces it adds to
    ``tried``, surface -> delta -> (per-pixel rho, prior energy, ...)), until E
    there is above E at ``best`` by ``RESTART_TEST`` standard errors
    (:func:`energy_rise` over the surface's pixels' ``blocks``), at most
    ``max_steps`` steps: :func:`flat_valley_sigma` then measures the depths E's
    noise cannot rule out instead of the few the search tried.
    """
    n = len(best)
    for side in (-1.0, 1.0):
        walking = np.asarray(flat, bool).copy()
        for _ in range(max_steps):
            far = np.array([side * max(side * d for d in tried[k]) for k in range(n)])
            for k in np.flatnonzero(walking):
                rise, se = energy_rise(tried[k], best[k], far[k], blocks[k])
                walking[k] = not rise > RESTART_TEST * se
            if not walking.any():
                break
            run(np.where(walking, far + side * step, best), walking)


def depth_search(
    problem,
    c,
    step=SEARCH_STEP,
    max_steps=SEARCH_STEPS,
    clear_sides=None,
    ratio_sigma=None,
    say=None,
    scale=None,
):
    """Each surface's depth from the minimum of E along its family of shapes.

    Beyond the paper. Under noise E has a long, nearly flat valley: at each
    depth (a scale of the surface about the camera centre) some shape agrees
    with the HS normals evaluated there, and Gauss-Newton creeps along that
    valley (each iteration moves the depth a small part of its error). Along the
    valley E still has a clear minimum, at the true depth (there alone the
    rows are rank 2 and the normals integrable). So every surface walks its
    own scale factor in relative steps of ``step`` (re-fitting its shape at
    each depth with ``SEARCH_FITS`` LM steps, the robust scale fixed so that
    energies compare), downhill until E rises, at most ``max_steps`` steps;
    parabolas through the best depth and its neighbours ``SEARCH_PARABOLAS``
    steps either side (a step, then narrower ones, each about the previous
    vertex) give the minimum.

    Returns the control points at each surface's best depth (shape re-fitted),
    the factors (n_surfaces,) applied and the relative 1-sigma uncertainty
    of each factor (:func:`measured_valley_sigma`, from the trial depths' energies, or,
    where E does not curve upwards about its minimum or so little that that sigma
    is beyond every depth the search tries, :func:`flat_valley_sigma`
    after a walk out on each side, a step at a time, until E rises beyond its
    noise, at most ``max_steps`` steps;
    with ``clear_sides``, the sides with only the samples clear of every
    edge usable, the rim rows' bias :func:`rim_valley_pull` added in
    variance; each pair's log-ratio uncertainty, ``ratio_sigma`` (P,) from the
    photometric calibration and the pair's uniform disagreement beyond the
    noise at the best depth (:func:`pair_disagreement`) in quadrature, moves
    the depth mode by :func:`ratio_sensitivity` times it, added in variance,
    where the valley is not flat).
    ``problem`` is E over the spline (``refine._Problem``, subsampled with
    :func:`search_stride`). ``say(text)``, if given, reports each trial depth (each is
    ``SEARCH_FITS`` LM steps). ``scale``: the robust scale at which energies
    compare (default that of the residuals at ``c``).
    """
    n = problem.n
    if n == 0:  # nothing left to refine (every pixel dropped before): nothing to search
        return c, np.ones(0), np.zeros(0)
    sc = problem.scale(c) if scale is None else scale
    mine = [problem.ctrl_surface == k for k in range(n)]
    pixels = [problem.graph.surface == k for k in range(n)]
    tried = [{} for _ in range(n)]  # surface -> offset -> (rho, prior, control points)
    trials = [0]  # how many trial depths so far (progress)

    def key(delta) -> float:
        return round(float(delta), 9)

    def energies(k, deltas) -> np.ndarray:
        """Surface k's energies at ``deltas`` (inf where not tried), compared."""
        have = [key(d) in tried[k] for d in deltas]
        out = np.full(len(deltas), np.inf)
        if any(have):
            states = [tried[k][key(d)][:2] for d, h in zip(deltas, have, strict=True) if h]
            common = np.all([np.isfinite(rho) for rho, _ in states], axis=0)
            out[np.flatnonzero(have)] = [np.sum(rho[common]) + pr for rho, pr in states]
        return out

    def at(deltas) -> np.ndarray:
        return np.concatenate([tried[k][key(deltas[k])][2] for k in range(n)])

    def trial(base, base_delta, new_delta, record) -> None:
        trials[0] += 1
        if say is not None:
            shown = ", ".join(f"{100 * d:+.2f}" for d in new_delta[record][:4])
            say(f"refinement: depth search, trial {trials[0]} at {shown} % (first surfaces)")
        cc = problem.scaled(base, (1.0 + new_delta) / (1.0 + base_delta))
        cc, _, (rho, prior), _ = problem.lm(cc, SEARCH_FITS, scale=sc)
        for k in np.flatnonzero(record):
            tried[k][key(new_delta[k])] = (rho[pixels[k]], prior[k], cc[mine[k]])

    def pick(candidates) -> np.ndarray:
        """Per surface, the candidate offset of least energy."""
        out = np.empty(n)
        for k in range(n):
            cand = np.unique([key(d) for d in candidates[k] if key(d) in tried[k]])
            out[k] = cand[np.argmin(energies(k, cand))]
        return out

    zero, everyone = np.zeros(n), np.ones(n, bool)
    trial(c, zero, zero, everyone)
    for d in (step, -step):
        trial(at(zero), zero, zero + d, everyone)
    best = pick([(0.0, step, -step)] * n)
    direction = np.sign(best)
    active = best != 0.0
    for _ in range(max_steps - 1):
        if not active.any():
            break
        nxt = best + direction * step * active
        trial(at(best), best, nxt, active)
        improved = active & (pick(list(zip(best, nxt, strict=True))) == nxt)
        best = np.where(improved, nxt, best)
        active = improved
    for h in step * np.asarray(SEARCH_PARABOLAS):
        for side in (-1.0, 1.0):
            need = np.array([key(best[k] + side * h) not in tried[k] for k in range(n)])
            if need.any():
                trial(at(best), best, best + side * h * need, need)
        vertex = best.copy()
        for k in range(n):
            em, e0, ep = energies(k, best[k] + np.array([-h, 0.0, h]))
            den = em - 2.0 * e0 + ep
            if np.isfinite(den) and den > 0:
                vertex[k] += h * float(np.clip(0.5 * (em - ep) / den, -1.0, 1.0))
        trial(at(best), best, vertex, everyone)
        best = pick(list(zip(best, vertex, strict=True)))
    g = problem.graph
    groups = valley_blocks(g.rows, g.cols, g.shape[1], problem.spline.spacing)
    blocks = [groups[pixels[k]] for k in range(n)]
    reach = max_steps * step
    sigma = np.array(
        [measured_valley_sigma(tried[k], best[k], blocks[k], step, reach) for k in range(n)]
    )
    flat = np.isinf(sigma)  # E flat within its noise at this step: walk out until it rises
    walk_out(tried, best, blocks, flat, step, max_steps, partial(trial, at(best), best))
    for k in np.flatnonzero(flat):
        sigma[k] = flat_valley_sigma(tried[k], best[k], blocks[k])
    if clear_sides is not None:  # the rim rows' pull on each surface's depth mode
        alt = copy.copy(problem)
        alt.sides = clear_sides
        clear = np.isfinite(alt.state(at(best), sc)[0])
        pull = [
            rim_valley_pull(tried[k], best[k], step, clear[pixels[k]], blocks[k]) for k in range(n)
        ]
        # NaN where E over every pixel does not curve upwards: the flat valley's sigma.
        sigma = np.hypot(sigma, np.nan_to_num(np.asarray(pull), nan=0.0))
    # The pair ratios' uncertainty, calibrated and as each pair's uniform disagreement
    # beyond the noise at the best depths, through each depth mode's gain.
    ratios = pair_disagreement(problem, at(best), sc)
    if ratio_sigma is not None:
        known = np.nan_to_num(np.asarray(ratio_sigma, float), nan=0.0)  # NaN: unknown
        ratios = np.sqrt(ratios**2 + known[None, :] ** 2)
    if np.any(np.nan_to_num(ratios) > 0):
        gain = ratio_sensitivity(problem, tried, best, step, pixels, at, sc)
        gain[flat] = np.nan  # no quadratic holds there: the walk's width stands for it
        moved = np.sqrt(np.nansum((gain * ratios) ** 2, axis=1))
        sigma = np.hypot(sigma, np.where(np.all(np.isnan(gain), axis=1), 0.0, moved))
    return at(best), 1.0 + best, sigma
