"""The depth's error bar: a 1-sigma uncertainty for every reconstructed depth.

Beyond the paper, which gives no error bar. Bayesian HS
(:func:`colourhs.reconstruct.bayes.refine.refine_surface`): the local part from
the Gauss-Newton covariance of the spline's control points
(:func:`depth_sigma`, with the sides' correlated noise,
:func:`correlated_gain`), the depth mode that E fixes weakly from the depth
search's own trial energies (:func:`valley_sigma`; where E does not curve
upwards about it, the depths E's noise cannot rule out,
:func:`flat_valley_sigma`) and the pull of the rows
at the edges of unusable regions on it, a model error
(:func:`rim_valley_pull`), and the move of that mode that the pair ratios'
uncertainty allows (:func:`ratio_sensitivity`: the calibrated ratios' sigma from
:func:`colourhs.calibration.photometric_solve.pair_ratio_sigma` and each pair's
uniform disagreement beyond the noise, :func:`pair_disagreement`), filled
holes and fragments too small for a valley sigma from their nearest measured
depth (:func:`filled_sigma`); the parts add in variance, and the sum is at least
the move of the surface when E's robust scale is tightened, a model error
that sensor noise lets into the fit (:func:`robust_scale_pull`), and the
spread of the depths refitted with one reciprocal pair left out at a time, a
model error of one pair (:func:`pair_jackknife`); and it is
infinite on a surface whose depth mode has no error bar
(:func:`surface_depth_sigma`). ML HS: the
curvature of its chi-square cost along the ray (:func:`ml_sigma`).
"""

from __future__ import annotations

import copy

import numpy as np
import scipy.sparse as sp

from colourhs.common.linalg import _factor
from colourhs.reconstruct.bayes.restart import RESTART_TEST, energy_difference
from colourhs.reconstruct.sides import (
    HelmholtzSides,
    noise_correlation,
    with_pairs,
    with_side_scaled,
)

VALLEY_BLOCK = 4  # blocks of the valley's uncertainty, in spline control spacings
"""Why ``VALLEY_BLOCK`` holds on any rig: in units of the spline's spacing
(a fixed fraction of the image width), so blocks hold the same share of a
surface at any resolution, wide enough that neighbouring blocks share few
control points and no noise (the sides' blur is a pixel)."""


def valley_blocks(rows: np.ndarray, cols: np.ndarray, width: int, spacing: float) -> np.ndarray:
    """Each pixel's block (n,) for the cluster-robust variances: squares of
    ``VALLEY_BLOCK`` spline spacings (``spacing``, pixels) over an image
    ``width`` pixels wide, at pixel coordinates ``rows``, ``cols`` (n,)."""
    block = VALLEY_BLOCK * spacing
    return (rows // block).astype(np.int64) * (int(width // block) + 1) + cols // block


def _near_trials(tried: dict, best: float, span: float):
    """The depth search's trial depths within ``span`` of ``best``: per-pixel rho
    (trials, n), prior energies (trials,), offsets ``x = d - best`` and the
    quadratic's design matrix [1, x, x^2]; None with fewer than three."""
    deltas = sorted(d for d in tried if abs(d - best) <= span * (1 + 1e-6))
    if len(deltas) < 3:
        return None
    rho = np.array([tried[d][0] for d in deltas])
    prior = np.array([tried[d][1] for d in deltas])
    x = np.asarray(deltas) - best
    return rho, prior, x, np.stack([np.ones_like(x), x, x * x], axis=1)


def valley_sigma(tried: dict, best: float, groups: np.ndarray, span: float) -> float:
    """Relative 1-sigma uncertainty of a surface's depth factor from the depth search.

    Beyond the paper. Along E's valley the depth of a smooth surface is
    decided by weak shading differences against the sensor noise sampled at
    positions that move with the depth, so the minimum's scatter can far
    exceed what E's curvature alone says (the noise also shapes E along the
    valley). This is the sandwich (cluster-robust) variance of the
    minimum: each block of pixels (``groups``, about independent) gets its
    own quadratic ``E_g(d) = a_g + b_g x + c_g x^2`` in ``x = d - best``
    through the trial depths within ``span`` of ``best`` (a search step: E's
    trial energies nearer each other differ by less than their fits' own
    noise; ``tried``: delta -> (per-pixel rho, prior energy, control
    points)), and the minimum's
    variance is ``G / (G - 1) sum_g (b_g - mean b)^2 / (2 sum_g c_g + 2
    c_prior)^2``. Returns inf where E does not curve upwards there (the
    depth is not determined) and NaN with fewer than three trial depths.
    """
    near = _near_trials(tried, best, span)
    if near is None:
        return float("nan")
    rho, prior, _, X = near
    common = np.all(np.isfinite(rho), axis=0)
    _, grp = np.unique(groups[common], return_inverse=True)
    G = int(grp.max()) + 1 if len(grp) else 0
    if G < 2:
        return float("nan")
    Eg = np.stack([np.bincount(grp, r[common], G) for r in rho])  # (trials, G)
    coef, *_ = np.linalg.lstsq(X, np.concatenate([Eg, prior[:, None]], axis=1), rcond=None)
    b, c = coef[1, :G], coef[2]
    curvature = 2.0 * c.sum()
    if not curvature > 0:
        return float("inf")
    return float(np.sqrt(G / (G - 1) * np.sum((b - b.mean()) ** 2)) / curvature)


def measured_valley_sigma(
    tried: dict, best: float, groups: np.ndarray, span: float, reach: float
) -> float:
    """:func:`valley_sigma` (its quadratics fitted within ``span`` of ``best``) where it is
    at most ``reach``, the farthest the depth search tries; inf beyond (E flat within
    its noise, as where it does not curve upwards, so :func:`flat_valley_sigma` after a
    walk out decides); NaN where :func:`valley_sigma` is (too few trial depths: a
    fragment, whose sigma comes from its neighbours). Beyond the paper: as E's
    curvature falls to 0 from above, the quadratic's sigma grows without bound (its
    curvature is the noise's), where a flat valley's walk stays finite; a scatter
    beyond every depth the search could try is one no trial measured."""
    sigma = valley_sigma(tried, best, groups, span)
    return float("inf") if sigma > reach else sigma  # NaN (too few trials) stays NaN


def flat_valley_sigma(tried: dict, best: float, groups: np.ndarray, test=RESTART_TEST) -> float:
    """Relative 1-sigma of a surface's depth factor where E does not curve upwards
    about its minimum (:func:`valley_sigma` inf): E's own noise decides.

    Beyond the paper. Where E along the valley is flat within its noise at the
    search's step, no quadratic measures the minimum's scatter, but E's difference
    between two depths has a standard error (cluster-robust over the blocks
    ``groups``, :func:`colourhs.reconstruct.bayes.restart.energy_difference`, over
    the pixels usable at both). A trial depth (``tried``: delta -> (per-pixel rho,
    prior energy, ...)) whose E is not above ``best``'s by ``test`` standard errors
    is not ruled out, and the set of such depths, a ``test``-standard-error
    interval, is about two sigmas either side of the minimum: the sigma is half its
    largest distance from ``best``. :func:`colourhs.reconstruct.bayes.valley.depth_search`
    walks out on both sides until E rises beyond its noise; where a side's walk
    ends first (its steps spent) this is a lower bound. Inf with fewer than two
    blocks of common pixels.
    """
    width = 0.0
    for d in tried:
        rise, se = energy_rise(tried, best, d, groups)
        if not np.isfinite(se):
            return float("inf")
        if not rise > test * se:
            width = max(width, abs(d - best))
    return 0.5 * width


def energy_rise(tried: dict, best: float, delta: float, groups: np.ndarray) -> tuple[float, float]:
    """E at the trial depth ``delta`` less E at ``best`` (``tried``: delta -> (per-pixel
    rho, prior energy, ...)), over the pixels usable at both, and its cluster-robust
    standard error over the blocks ``groups``
    (:func:`colourhs.reconstruct.bayes.restart.energy_difference`; inf with fewer
    than two blocks)."""
    (r0, p0, *_), (r1, p1, *_) = tried[best], tried[delta]
    one = np.zeros(len(groups), np.int64)
    rise, se = energy_difference(r0, r1, [p0], [p1], one, groups, 1)
    return float(rise[0]), float(se[0])


def rim_valley_pull(
    tried: dict, best: float, span: float, clear: np.ndarray, groups: np.ndarray
) -> float:
    """Relative bias of a surface's depth factor from its rim rows (E's valley).

    Beyond the paper. A sample whose blur kernel reaches an unusable region
    (a silhouette, a dark marker, a saturated patch) mixes the edge into the
    surface, differently in the two views of a pair: a model error that
    does not fall with the sensor noise, so the robust weights drop such
    rows only on nearly exact data, and under noise they move the depth
    mode (a bias, not scatter: it stays on exact images, where the rows
    clear of every edge alone give the true depth). E's Gauss-Newton model
    does not see that move (it does not follow the valley), so it is measured on the
    depth search's own energies: ``tried`` (delta -> per-pixel rho, prior
    energy, ...) at the trial depths, ``clear`` (the surface's pixels) those
    whose rows are clear of every edge. Quadratics through E over every
    usable pixel and over the clear ones alone, at the trial depths within
    ``span`` of ``best``, give two minima (each kept within those trial
    depths, where the quadratics hold) a distance d apart. Without a rim
    bias d is noise alone, with variance ``s_clear^2 - s_all^2`` (the clear
    pixels' minimum is the less precise of two nested estimates of one
    depth; each s from :func:`valley_sigma` with ``groups``), so the bias is
    ``sqrt(max(0, d^2 - (s_clear^2 - s_all^2)))`` (a Hausman-type
    difference): 0 where the clear pixels cannot tell it from their own
    noise, or where no pixel is a rim's. NaN with fewer than three trial
    depths or an energy over every pixel that does not curve upwards.
    """
    near = _near_trials(tried, best, span)
    if near is None:
        return float("nan")
    rho, prior, x, X = near
    usable = np.all(np.isfinite(rho), axis=0)
    inner = usable & clear
    if inner.sum() == usable.sum():
        return 0.0
    E = np.stack([rho[:, usable].sum(axis=1) + prior, rho[:, inner].sum(axis=1) + prior], axis=1)
    coef, *_ = np.linalg.lstsq(X, E, rcond=None)
    if not coef[2, 0] > 0:
        return float("nan")
    if not coef[2, 1] > 0:
        return 0.0  # the clear pixels alone do not fix the depth: no bias can be told
    vertex = np.clip(-coef[1] / (2.0 * coef[2]), x.min(), x.max())  # the fits hold there only
    s_all = valley_sigma(tried, best, groups, span)
    inner_only = {d: (np.where(inner, r[0], np.nan), *r[1:]) for d, r in tried.items()}
    s_clear = valley_sigma(inner_only, best, groups, span)
    noise = s_clear**2 - s_all**2 if np.isfinite(s_clear) and np.isfinite(s_all) else np.inf
    return float(np.sqrt(max(0.0, (vertex[1] - vertex[0]) ** 2 - max(noise, 0.0))))


RATIO_STEP = 1e-6
"""Log step of a pair's ratio in :func:`ratio_sensitivity`. Why it holds on any
rig: a share of the intensities, so the same on any sensor and scale, far below
any sensor's relative noise (a 16-bit sample's is above 1e-5), so that E's
change is its derivative even where the rows sit on the robust function's
knee, and far above the rounding of E's float64 terms."""


def ratio_sensitivity(problem, tried, best, span, pixels, at, scale, step=RATIO_STEP):
    """How far each surface's depth factor moves per unit log ratio of each pair.

    Beyond the paper. On a smooth surface the depth is the mode E fixes
    weakly (:func:`valley_sigma`), and a pair's ratio mu_a / mu_b (eq. 5's
    weights, from the photometric calibration) enters it as the distances'
    fall-off does: a small error of the ratio moves the valley's minimum far.
    Linearised on the depth search's own trials: with pair p's side a scaled by
    ``exp(step)``, E at each trial depth within ``span`` of ``best`` changes by
    ``step g(x)`` (the shape's re-fit is of second order there); with E's
    quadratic ``a + b x + c x^2`` the minimum moves by ``-step g'(x) / (2 c)``.

    ``problem`` (``refine._Problem``), ``tried`` (per surface: delta -> (per-pixel
    rho, prior, control points)), ``best`` (n,), ``pixels`` (per surface: its
    pixels' mask), ``at(deltas)`` (the control points at one delta per surface),
    ``scale`` (the robust scale the trials used). Returns (n, P) relative shifts
    per unit log ratio; NaN where a surface has fewer than three trials there or
    E does not curve upwards.
    """
    n, P = len(tried), problem.sides.pairs
    near = [_near_trials(tried[k], best[k], span) for k in range(n)]
    deltas = [
        np.asarray(best[k]) + near[k][2] if near[k] is not None else np.array([best[k]])
        for k in range(n)
    ]
    steps = max(len(d) for d in deltas)
    out = np.full((n, P), np.nan)
    for p in range(P):
        alt = copy.copy(problem)
        alt.sides = with_side_scaled(problem.sides, 2 * p, float(np.exp(step)))
        change = [np.full(len(d), np.nan) for d in deltas]
        for i in range(steps):
            rho, _ = alt.state(at([d[min(i, len(d) - 1)] for d in deltas]), scale)
            for k in range(n):
                if near[k] is None or i >= len(deltas[k]):
                    continue
                r0, r1 = near[k][0][i], rho[pixels[k]]
                both = np.isfinite(r0) & np.isfinite(r1)
                change[k][i] = np.sum(r1[both] - r0[both])
        for k in range(n):
            if near[k] is None:
                continue
            rho0, prior, x, X = near[k]
            common = np.all(np.isfinite(rho0), axis=0)
            E = rho0[:, common].sum(axis=1) + prior
            c = np.linalg.lstsq(X, E, rcond=None)[0][2]
            g = np.polyfit(x, change[k], 1)[0]
            if c > 0:
                out[k, p] = -g / (2.0 * c) / step
    return out


def pair_disagreement(problem, c, scale) -> np.ndarray:
    """Each surface's uniform disagreement of each reciprocal pair's two sides
    (n_surfaces, P), as a log ratio: 0 where the noise explains it.

    Beyond the paper. At the surface ``c`` (``problem``, ``refine._Problem``;
    its active pixels) eq. (5) holds for pair k where its two sides' terms
    along the normal agree, ``s_a (v_a . N) = s_b (v_b . N)``. Their log ratio
    ``m = log(s_a v_a . N) - log(s_b v_b . N)`` has the noise variance
    ``n2 = var_a / s_a^2 + var_b / s_b^2``. A wrong ratio mu_a / mu_b of the
    pair (a calibration or unmixing error, a chromaticity wrong in one
    camera) shifts m alike over the surface, and moves its depth mode by the
    gain :func:`ratio_sensitivity` gives. Its size is the mean of ``m`` over
    the surface's usable pixels, each weighted as E weighs it (its
    Geman-McClure weight at robust ``scale``: rows E drops do not count); it
    counts only beyond ``RESTART_TEST`` standard errors of that mean under the
    noise model (``n2`` per pixel, times the gain of the sides' correlated
    noise, :func:`correlated_gain`). Returns its magnitude.
    """
    from colourhs.reconstruct.bayes.surface import pixel_normals

    g = problem.graph
    act = np.ones(g.n, bool) if problem.active is None else problem.active
    X = problem.c_ref + problem.R * (problem.B @ c)[:, None]
    normals = pixel_normals(g, X, problem.R)[act]
    _, _, info = problem._residuals(c, jacobian=False, scale=scale)
    s, var, v = info["samples"]
    weight = (info["weights"] * info["valid"])[act]
    P = problem.sides.pairs
    with np.errstate(invalid="ignore", divide="ignore"):
        along = s * np.einsum("npjc,nc->npj", v, normals)
        m = np.log(along[..., 0] / along[..., 1])
        n2 = var[..., 0] / s[..., 0] ** 2 + var[..., 1] / s[..., 1] ** 2
    gain = correlated_gain(problem.sides)
    surface = g.surface[act]
    out = np.zeros((problem.n, P))
    for p in range(P):
        on = np.isfinite(m[:, p]) & np.isfinite(n2[:, p]) & (weight > 0)
        w, k = weight[on], surface[on]
        total = np.bincount(k, w, problem.n)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.bincount(k, w * m[on, p], problem.n) / total
            se = np.sqrt(gain * np.bincount(k, w * w * n2[on, p], problem.n)) / total
        out[:, p] = np.where((total > 0) & (np.abs(mean) > RESTART_TEST * se), np.abs(mean), 0.0)
    return out


SIGMA_SAMPLES = 64  # Monte Carlo draws of the control points' posterior (sigma to ~9 %)
"""Why ``SIGMA_SAMPLES`` holds on any rig: it is a count of draws, whose
relative error in a standard deviation is ``1 / sqrt(2 (n - 1))`` whatever
the rig (64: 9 %), enough to tell a 1-sigma share of 0.68 from 0.6 or 0.76."""


def correlated_gain(sides: HelmholtzSides) -> float:
    """Variance gain of a smooth average of the sides' blurred noise over independent
    rows: the sum of the noise's correlation over the 2D pixel lattice (1 unblurred)."""
    if not sides.blurred:
        return 1.0
    corr = noise_correlation(sides.blur_px, int(np.ceil(6 * sides.blur_px)) + 1)
    return float(corr[0] + 2.0 * corr[1:].sum()) ** 2


def depth_sigma(problem, c, samples: int = SIGMA_SAMPLES, seed: int = 0) -> np.ndarray:
    """1-sigma uncertainty (n,) of each pixel's depth on the spline ``c``, metres.

    ``problem`` is E over the spline (``refine._Problem``).

    Beyond the paper. Near E's minimum the control points' posterior is
    Gaussian with covariance ``level * A^-1``, where ``A = (J B)^T W (J B) +
    level D^T D`` is the Gauss-Newton matrix of E (the IRLS-weighted rows
    of every pixel in noise units, :func:`hs_residuals`, and the spline
    prior) and ``level`` the residuals' excess over the noise model (1 when
    the noise model explains them; larger where rendering, sampling or
    calibration leave more). A pixel's variance is ``b_p^T A^-1 b_p`` (its
    row of the basis B); it holds the depth mode that E determines weakly
    (the valley of :func:`depth_search`) as well as the local shape.

    Computed without inverting A: ``x = A^-1 (J_c^T g_1 + sqrt(level) D^T
    g_2)`` with standard normal g has covariance ``A^-1`` (``A`` is the
    Gram matrix of the stacked rows), so ``samples`` solves with one
    factorisation give each pixel's variance as the mean square of ``B x``.

    The Gauss-Newton covariance treats every row's noise as independent; the
    sides are blurred before sampling (:func:`colourhs.reconstruct.sides.side_maps`),
    so neighbouring rows share their noise, and a shape smoother than the
    blur (the spline's cells span several pixels) averages fewer independent
    samples than it has rows: the variance is scaled by the correlated noise's
    gain over the pixel lattice, ``(sum_k corr[|k|])^2`` (4 pi sigma^2 for a
    blur of sigma pixels; 1 without blur). Pixels whose rows are unusable get NaN.
    """
    J, r, info = problem._residuals(c, robust=problem.robust)  # its own robust scale
    sc = info["scale"]
    level = sc / (problem.robust**2 * problem.sides.pairs)
    A = (problem.gram.matrix(info["jacobian_values"]) + problem.DtD * level).tocsc()
    Jc = (J @ problem.B).tocsr()
    Dw = problem.prior(sc)
    rng = np.random.default_rng(seed)
    g1 = rng.standard_normal((Jc.shape[0], samples))
    g2 = rng.standard_normal((Dw.shape[0], samples))
    rhs = Jc.T @ g1 + Dw.T @ g2
    diag = A.diagonal()
    A = A + sp.diags(1e-12 * max(diag.mean(), 1e-300) * np.ones(A.shape[0]))
    x = _factor(A).solve(np.asarray(rhs, float))
    zs = problem.B @ x
    var = np.mean(zs * zs, axis=1) * level * correlated_gain(problem.sides)
    return np.where(info["valid"], np.sqrt(var), np.nan)


ROBUST_CHECK = 0.5  # the robust scale of the check fit, as a share of E's own
"""Why ``ROBUST_CHECK`` holds on any rig: it is a ratio of two robust scales,
each already in units of the rows' own noise level
(:func:`colourhs.reconstruct.bayes.surface.hs_residuals`), so the check fit
rejects the same share of rows at any noise, resolution or working distance.
Half keeps most rows that the noise alone explains (at a chi-square of ``P``,
the noise's mean over a pixel's ``P`` rows, its Geman-McClure weight falls from
0.81 to 0.48 when the scale of 3 noise units halves) and lets rows that the
model cannot explain lose most of theirs."""

ROBUST_CHECK_STEPS = 20  # Levenberg-Marquardt steps of the check fit
"""Why ``ROBUST_CHECK_STEPS`` holds on any rig: it counts reweightings of the
rows (each step recomputes the Geman-McClure weights), and the check fit's
move nears its limit by a share per step that depends on how far the rows
bend the surface, not on the image's size or the rig. E's settling test
(``refine.LM_SETTLED``) would stop this fit early: it drifts slowly and
steadily, each step lowering E by less than the test's share; half of E's
step limit (``refine.LM_MAX_STEPS``) lets it get most of the way."""


def robust_scale_pull(problem, c, steps: int = ROBUST_CHECK_STEPS) -> np.ndarray:
    """Each pixel's depth move (n,) when E's robust scale is tightened, metres.

    Beyond the paper. The Geman-McClure weights
    (:mod:`colourhs.reconstruct.bayes.surface`) keep the rows that the model
    explains and drop the others (a white highlight on a coloured surface, a
    mixed pixel), but their scale follows the residuals' own level: where
    sensor noise raises that level, rows that break the model keep part of
    their weight and bend the surface. That is a bias which grows with the
    noise while the noise-only covariance (:func:`depth_sigma`) stays small,
    since the surface fits those rows. The same E refitted from ``c`` with
    its scale times :data:`ROBUST_CHECK` (``steps`` Levenberg-Marquardt steps
    on ``problem``, ``refine._Problem``) moves the surface where such rows pull
    it; where every row follows the noise model the two fits differ by noise
    alone, which the error bar already holds. A depth's sigma is therefore at
    least the size of its move (beyond the paper; a model error the noise
    lets in, not a noise of its own, so it does not add in variance to what
    already covers the move).
    """
    tight = copy.copy(problem)
    tight.robust = problem.robust * ROBUST_CHECK
    checked, _, _, _ = tight.lm(c, steps)
    return problem.B @ (checked - c)


def pair_jackknife(problem, c) -> np.ndarray:
    """Each pixel's depth jackknife standard deviation (n,) over the reciprocal pairs,
    metres.

    Beyond the paper. Every pair's rows of eq. (5) measure the same surface,
    but what breaks the model breaks it pair by pair: the lights' reciprocity
    defect (a light beside its lens: a glossy lobe differs between a pair's two
    readings by a share no calibration removes, ``docs/capture-format.md``), a
    pair's calibrated ratio mu_a / mu_b, the cross-talk unmixing of its
    channels or a camera's chromaticity p. Such an error bends the surface
    where the noise-only covariance (:func:`depth_sigma`) sees a good fit, and
    it is correlated over whole regions, so no per-row or per-block variance of
    the residuals measures it (at E's minimum the residuals are orthogonal to
    the rows' gradients). Leaving one pair out removes that pair's share of it:
    E over the other pairs (``problem``, ``refine._Problem``, with
    :func:`colourhs.reconstruct.sides.with_pairs`) is refitted from ``c``
    (Levenberg-Marquardt steps until E settles, as every stage of the
    refinement), and the P leave-one-out depths ``z_k`` give the jackknife
    variance ``(P - 1) / P sum_k (z_k - mean z)^2``, the spread that the pairs'
    disagreement puts on the depth; where the pairs agree it is the noise's
    own, which the covariance already holds. So, like
    :func:`robust_scale_pull`, it is a floor of the error bar, not a term added
    in variance. Zero with fewer than three pairs (one pair left cannot fix a
    normal).
    """
    P = problem.sides.pairs
    if P < 3:
        return np.zeros(problem.graph.n)
    z = []
    for k in range(P):
        alone = problem.with_sides(with_pairs(problem.sides, [q for q in range(P) if q != k]))
        ck, _, _, _ = alone.lm(c, 1, settle=True)
        z.append(problem.B @ ck)
    z = np.asarray(z)
    return np.sqrt((P - 1) / P * np.sum((z - z.mean(axis=0)) ** 2, axis=0))


FILL_SIGMA = 2.0  # a filled hole's sigma, in units of its nearest measured depth's
"""Why ``FILL_SIGMA`` holds on any rig: a ratio of two sigmas. A hole's depth
is the quadric through a ring of measured depths around it (:func:`fill_holes`),
an extrapolation whose error is at least the ring's and grows inside it:
twice the nearest measured pixel's sigma bounds it without a figure of the rig."""


def surface_depth_sigma(
    local: np.ndarray, z: np.ndarray, valley: np.ndarray, surface: np.ndarray, pull: np.ndarray
) -> np.ndarray:
    """Each pixel's depth 1-sigma (n,), metres, from its parts: the ``local`` one
    (n,, :func:`depth_sigma`) and its surface's depth mode, ``z`` (n,) times the
    relative ``valley`` sigma (n_surfaces,, :func:`valley_sigma` with its pulls) of
    its ``surface`` (n,), in quadrature; at least ``pull`` (n,,
    :func:`robust_scale_pull`). NaN where ``local`` is (the pixel's rows were
    unusable: :func:`filled_sigma` extrapolates it).

    Beyond the paper: infinite on a surface whose valley sigma is infinite (not
    even E's noise could be told, :func:`flat_valley_sigma`: the depth has no
    error bar, and the reconstruction flags it); NaN on one whose valley sigma is
    NaN (it lies in one block, so that no scatter of the blocks' minima measures
    its mode: a fragment, whose error bar :func:`filled_sigma` takes from the
    nearest measured depth, with its depth's distance from it).
    """
    mode = np.asarray(valley, float)[surface]
    sigma = np.maximum(np.hypot(local, z * mode), pull)
    return np.where(np.isinf(mode), np.inf, sigma)


def filled_sigma(
    sigma: np.ndarray, filled: np.ndarray, shape, z: np.ndarray | None = None
) -> np.ndarray:
    """Sigmas (k,) of the ``filled`` pixels (H*W,): ``FILL_SIGMA`` times that of
    the nearest pixel with a measured ``sigma`` (H*W,; infinite where E does not fix
    the depth, which a pixel next to it inherits); NaN where there is none. With
    the depths ``z`` (H*W,), at least each pixel's depth's distance from that
    pixel's (beyond the paper: a fragment too small to measure its own depth mode
    has only its nearest measured neighbour as evidence, and a fragment at another
    depth than it has none)."""
    from scipy.ndimage import distance_transform_edt

    known = ~np.isnan(sigma).reshape(shape)
    if not known.any():
        return np.full(int(filled.sum()), np.nan)
    _, (ii, jj) = distance_transform_edt(~known, return_indices=True)
    nearest = (ii * shape[1] + jj).ravel()[filled]
    out = FILL_SIGMA * sigma[nearest]
    if z is not None:
        out = np.maximum(out, np.abs(z[filled] - z[nearest]))
    return out


ML_SIGMA_STEP = 1e-4  # the curvature's half-step, relative to the depth (0.08 mm at 0.8 m)
"""Why ``ML_SIGMA_STEP`` holds on any rig: it is relative to the depth, so it
stays a fixed fraction of a pixel's disparity step at any working distance,
far below the cost's width (a label is 0.26 % of the depth) and far above
rounding."""


def ml_sigma(sides, rays, z, centre, step: float = ML_SIGMA_STEP) -> np.ndarray:
    """1-sigma uncertainty (N,) of ML depths ``z`` along ``rays`` (N, 3), metres.

    Beyond the paper. The whitened ML cost (:func:`colourhs.reconstruct.sides.whitened_cost`)
    is a chi-square with one degree of freedom along the ray, so the depth's
    variance is ``2 / (d^2 chi2 / dz^2)``, its second derivative taken by
    central differences ``step * z`` either side. NaN where the cost does not
    curve upwards there or a sample is unusable.
    """
    from colourhs.reconstruct.sides import whitened_cost

    h = step * np.abs(z)
    chi = [whitened_cost(sides, centre + rays * (z + d)[:, None], rays)[0] for d in (-h, 0, h)]
    curv = (chi[0] - 2.0 * chi[1] + chi[2]) / (h * h)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(curv > 0, np.sqrt(2.0 / curv), np.nan)
