"""Per-frame colour HS reconstruction: ML and Bayesian HS to depth/normal HDF5.

- ML HS (Zickler et al.; paper section III-A): per pixel a root of the eq. (5)
  data cost along the ray (:mod:`colourhs.reconstruct.ml`: the candidate
  roots decided by a tangent-plane window, then the root's continuous
  minimum; beyond the paper).
- Bayesian HS (Roubtsova and Guillemaut; paper section III-E): the MAP
  labelling of alpha * E_data + (1 - alpha) * E_prior with the depth-normal
  consistency prior, optimised by semi-global aggregation along 8 directions
  (:mod:`colourhs.reconstruct.bayes.mrf`); then, beyond the paper, a smooth initial
  surface that integrates the HS normals (:mod:`colourhs.reconstruct.bayes.integrate`), and the
  continuous surface that minimises the depth-normal consistency energy in
  noise units (:mod:`colourhs.reconstruct.bayes.surface`): its shape from the
  agreement of its normals with eq. (5), its depth from a search along that
  energy's valley, never from the discrete labels.
"""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass
from functools import partial
from time import perf_counter

import numpy as np

from colourhs.capture import (
    LIT_THRESHOLD,
    Camera,
    Rig,
)
from colourhs.common.depthfile import DepthResult, write_depth
from colourhs.common.files import sha256_files
from colourhs.common.geometry import (
    normalised_coordinates,
    pixel_grid,
    ray_directions,
)
from colourhs.common.progress import bar, stage
from colourhs.reconstruct.bayes.integrate import IntegrationOptions, initial_surface
from colourhs.reconstruct.dataterm import INVALID_COST, data_term, pair_arrays, prepare_images
from colourhs.reconstruct.drops import drop_codes, reference_unusable
from colourhs.reconstruct.inputs import (
    CalibrationFiles,
    Frame,
    RayGrid,
    fill_reference_holes,
    load_frame,
)
from colourhs.reconstruct.options import (
    MAX_SIGMA,
    WORKING_RADIUS,
    ReconstructOptions,
    min_component_px,
)

log = logging.getLogger(__name__)

METHODS = ("ml", "bayes")
CHUNK = 16384  # pixels per data-term call (bounds the float32 normals buffer)


@dataclass(frozen=True)
class _Search:
    """What both methods search over: the reference camera and its ray grid, the
    foreground pixels to reconstruct (flat indices into the grid), the depth
    hypotheses (metres) and the reciprocal pairs (:func:`.dataterm.pair_arrays`)."""

    ref: Camera
    grid: RayGrid
    pix: np.ndarray
    depths: np.ndarray
    pairs: tuple


def reference_rays(camera: Camera, width: int, height: int) -> np.ndarray:
    """World rays (H*W, 3) of a camera's pixel centres, scaled to unit z-depth."""
    xy = normalised_coordinates(pixel_grid(width, height).reshape(-1, 2), camera.K, camera.dist)
    return ray_directions(xy, camera.R, unit_length=False)


def working_depth(rig: Rig, ref: Camera) -> float:
    """z-depth in ``ref`` of the fixation point (:meth:`colourhs.capture.Rig.fixation_point`)."""
    x = rig.fixation_point()
    return float((np.asarray(ref.R, float) @ x + np.asarray(ref.t, float))[2])


def object_mask(frame: Frame, ref: int, threshold: float = LIT_THRESHOLD) -> np.ndarray:
    """The object in the reference camera (H, W): its silhouette, or the lit pixels.

    Without masks, pixels brighter than ``threshold`` (fraction of full
    scale) in some channel: the rig has no ambient light.
    """
    if frame.silhouettes is not None:
        return frame.silhouettes[ref].astype(bool)
    return frame.images[ref].max(axis=0) > threshold


def foreground(frame: Frame, ref: int, threshold: float = LIT_THRESHOLD) -> np.ndarray:
    """Pixels (H, W) of the reference camera to reconstruct.

    The silhouette when the dataset has masks, otherwise pixels brighter than
    ``threshold`` (fraction of full scale) in some channel, since the rig has
    no ambient light; in both cases without the pixels too dark to measure in
    either reciprocal channel of the reference camera (at most ``threshold``:
    black markers, shadows), dilated by one pixel, since their rows carry no
    signal.

    ``threshold`` is a fraction of the sensor's range, not of its noise: a
    threshold of a few noise sigmas would take in the weak readings of
    saturated plastics in the other lights' channels, which add coverage but
    spoil the depth, and on nearly exact data the black markers, whose mixed
    footprints move a board's depth.
    """
    from scipy.ndimage import binary_dilation

    img = frame.images[ref]
    own = frame.rig.cameras[ref].light_channel
    recip = [c for c in range(3) if c != own]
    fg = object_mask(frame, ref, threshold)
    dark = np.min(img[recip], axis=0) <= threshold
    # One pixel of dilation (4-neighbours; no wrap-around at the border).
    return fg & ~binary_dilation(dark)


def _parabola(c_m, c_0, c_p):
    """Offset in (-0.5, 0.5) of the vertex of the parabola through (-1, c_m), (0, c_0), (1, c_p)."""
    den = c_m - 2 * c_0 + c_p
    with np.errstate(invalid="ignore", divide="ignore"):
        off = np.where(den > 0, 0.5 * (c_m - c_p) / den, 0.0)
    return np.clip(np.nan_to_num(off), -0.5, 0.5)


def _subpixel(volume: np.ndarray, rows: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """Sub-label positions (N,) of ``labels`` in rows ``rows`` of ``volume`` (M, L):
    the vertex of the parabola through the label and its two neighbours."""
    K = volume.shape[1]
    lm = np.clip(labels - 1, 0, K - 1)
    lp = np.clip(labels + 1, 0, K - 1)
    off = _parabola(volume[rows, lm], volume[rows, labels], volume[rows, lp])
    inside = (labels > 0) & (labels < K - 1)
    return labels + np.where(inside, off, 0.0)


def _depth_at(depths: np.ndarray, fractional: np.ndarray) -> np.ndarray:
    return depths[0] + fractional * (depths[1] - depths[0])


def reconstruct(
    frame: Frame,
    method: str = "bayes",
    reference: str | None = None,
    depth_range: tuple[float, float] | None = None,
    **options,
) -> DepthResult:
    """Reconstruct one frame with ML or Bayesian colour HS.

    Parameters
    ----------
    frame : inputs from :func:`load_frame`.
    method : ``"ml"`` or ``"bayes"``.
    reference : reference camera name (default: the first camera).
    depth_range : (near, far) z-depth range in metres; default the working
        depth zc (where the optical axes meet) +- ``working_radius`` zc.
    **options : the tuning options, :class:`ReconstructOptions` (a TypeError
        names any other keyword).

    Notes
    -----
    Logs one line per step at INFO, with the seconds since the start, and shows
    a bar over the data term's chunks of pixels (:mod:`colourhs.common.progress`).

    ML: the best hypothesis per pixel, then :func:`refine_ml` (continuous),
    :func:`_ml_reconstruction`. Bayesian: the MAP labelling of the MRF, a smooth
    initial surface from the HS normals
    (:func:`colourhs.reconstruct.bayes.integrate.refine_depth`; its depth is still the
    labelling's), then the depth from the agreement of the geometry with eq. (5)
    (:func:`colourhs.reconstruct.bayes.refine.refine_surface`), :func:`_bayes_reconstruction`.
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    opts = ReconstructOptions(**options)
    say = partial(stage, log, start=perf_counter())
    rig = frame.rig
    names = list(rig.camera_names)
    ref_i = names.index(rig.camera(reference).name) if reference else 0
    ref = rig.cameras[ref_i]
    frame = fill_reference_holes(frame, ref_i)  # a tracked map's: beyond the paper
    H, W = rig.image.height, rig.image.width
    depths = depth_hypotheses(
        rig, ref, opts.n_labels, depth_range, opts.working_radius, opts.working_radius_m
    )
    rays = reference_rays(ref, W, H)
    pix = np.flatnonzero(foreground(frame, ref_i).ravel())
    if len(pix) == 0:
        raise ValueError("no foreground pixels in the reference camera: nothing to reconstruct")
    pairs = pair_arrays(rig)
    say(f"{method}: data term of {len(pix)} pixels x {opts.n_labels} depths")
    evaluate = data_term_evaluator(frame, ref, pairs)
    info = {
        "method": method,
        "reference": ref.name,
        "n_labels": opts.n_labels,
        "depth_range_m": [float(depths[0]), float(depths[-1])],
        "alpha": opts.alpha,
        "tau": opts.tau,
        "pixels": int(len(pix)),
    }
    search = _Search(ref, RayGrid(rays, ref.centre, (H, W)), pix, depths, pairs)
    solve = _ml_reconstruction if method == "ml" else _bayes_reconstruction
    z, nrm, ok, conf, sigma, stages = solve(frame, evaluate, search, opts, info, say)
    limit = MAX_SIGMA * np.abs(z) if opts.max_sigma_mm is None else opts.max_sigma_mm * 1e-3
    # Where the refinement ran, a kept depth whose error bar did not compute (NaN: a
    # surface whose uncertainty failed) has none: infinite, as docs/results-layout.md
    # states, so it is flagged like one beyond the limit rather than kept silently.
    # Without the refinement (ML, or too few pixels) no depth has one, and NaN flags
    # nothing.
    if "surface" in info:
        sigma = np.where(ok & np.isnan(sigma), np.inf, sigma)
    with np.errstate(invalid="ignore"):
        uncertain = ok & (sigma > limit)
    ok = ok & ~uncertain  # a new array: the last of ``stages`` may be ``ok`` itself
    z[~ok] = np.nan
    nrm[~ok] = np.nan
    conf[~ok] = 0.0
    sigma = np.where(ok | uncertain, sigma, np.nan)
    info |= {"max_sigma_mm": opts.max_sigma_mm, "uncertain_pixels": int(uncertain.sum())}
    # Lights beside the lenses: how far apart each point's pair readings' half-vectors are.
    defect = rig.reciprocity_defect(ref.centre + rays[ok] * z[ok, None]).max(axis=0, initial=0)
    info["reciprocity_defect_deg"] = float(np.degrees(np.median(defect))) if ok.any() else None
    in_fg = np.zeros(H * W, bool)
    in_fg[pix] = True
    dropped = drop_codes(
        object_mask(frame, ref_i).ravel(),
        in_fg,
        reference_unusable(frame, ref_i),
        [*stages, ("uncertain", ~uncertain)],
        ok,
    )
    return DepthResult(
        z.reshape(H, W).astype(np.float32),
        nrm.reshape(H, W, 3).astype(np.float32),
        conf.reshape(H, W),
        ok.reshape(H, W),
        info | {"valid_pixels": int(ok.sum())},
        depth_sigma=sigma.reshape(H, W).astype(np.float32),
        uncertain=uncertain.reshape(H, W),
        dropped=dropped.reshape(H, W),
    )


def _ml_reconstruction(frame, evaluate, search: _Search, opts, info, say):
    """ML HS of the foreground ``search.pix``: the cost volume (no normals: ML HS
    takes its normals from its own minima), then :func:`_ml_solution`. Returns
    (H*W,) depth, (H*W, 3) normal, validity, confidence, uncertainty and the
    stages that removed pixels (:func:`.drops.drop_codes`); ``info`` is not changed."""
    pix, depths = search.pix, search.depths
    cost = np.empty((len(pix), len(depths)), np.float32)
    evaluate(search.grid.rays[pix], depths, show=True, out=(cost, None, np.arange(len(pix))))
    z, nrm, ok, conf, sigma = _ml_solution(frame, cost, search, opts.max_cost, opts.blur_px, say)
    return z, nrm, ok, conf, sigma, [("data_term", ok)]


def _bayes_reconstruction(frame, evaluate, search: _Search, opts, info, say):
    """Bayesian HS of the foreground ``search.pix`` (paper section III-E, then beyond it):
    the data term written into the MRF box's volumes, the MAP labelling
    (:func:`_bayes_labelling`), the initial surface
    (:func:`colourhs.reconstruct.bayes.integrate.initial_surface`) and the consistent
    surface (:func:`_consistent_surface`), the rims eroded. Returns (H*W,) depth,
    (H*W, 3) normal, validity, confidence, each depth's 1-sigma uncertainty
    (metres, :mod:`colourhs.reconstruct.bayes.uncertainty`; NaN without the
    refinement) and the stages that removed pixels (:func:`.drops.drop_codes`); adds
    the MRF's and the surface's figures to ``info``."""
    rays, pix, depths, shape = search.grid.rays, search.pix, search.depths, search.grid.shape
    H, W = shape
    box, local = _mrf_box(pix, shape)
    h, w = box[1] - box[0], box[3] - box[2]
    # The volumes over the MRF's box, the data term written into them directly.
    cost = np.full((h * w, len(depths)), INVALID_COST, np.float32)
    normals = np.zeros((h * w, len(depths), 3), np.float16)
    evaluate(rays[pix], depths, np.float16, show=True, out=(cost, normals, local))
    say(f"bayes: MRF labelling over {h} x {w} pixels")
    labels, frac = _bayes_labelling(cost, normals, local, box, rays, depths, shape, opts, info, say)
    z, nrm, ok, conf = _labelled_surface(
        cost[local, labels], normals[local, labels], frac, depths, pix, shape, opts.max_cost
    )
    del cost, normals
    stages = [("data_term", ok.copy())]
    sigma = np.full(H * W, np.nan)
    if opts.refine and ok.sum() > 10:
        # Wrong labels (a few labels off or worse) must not move the surface.
        anchor = 2.0 * float(depths[1] - depths[0]) / float(np.median(depths))
        say(f"bayes: initial surface ({opts.refine_passes} passes of normal integration)")
        integration = IntegrationOptions(
            opts.refine_passes,
            opts.data_weight,
            opts.edge_m,
            anchor,
            opts.link_m,
            min_component_px(opts.min_component, shape),
        )
        z, nrm, ok = initial_surface(z, nrm, ok, rays, pix, shape, evaluate, integration, say)
        stages.append(("surface", ok.copy()))
        z, nrm, ok, weights, sigma, info["surface"] = _consistent_surface(
            frame, z, ok, search, opts.surface_iterations, opts.spline_px, opts.blur_px, say
        )
        conf = np.where(ok, weights, 0.0).astype(np.float32)
        stages.append(("refinement", ok.copy()))
    erode_px = max(1, round(W / 320)) if opts.erode_px is None else opts.erode_px
    ok = _without_rims(ok, shape, erode_px)
    return z, nrm, ok, conf, sigma, [*stages, ("rims", ok)]


def depth_hypotheses(
    rig: Rig,
    ref: Camera,
    n_labels: int,
    depth_range: tuple[float, float] | None = None,
    working_radius: float = WORKING_RADIUS,
    working_radius_m: float | None = None,
) -> np.ndarray:
    """The ``n_labels`` z-depths (metres, evenly spaced) hypothesised along every ray.

    ``depth_range`` (near, far) when given, else the working depth zc of
    ``ref`` (:func:`working_depth`) +- ``working_radius`` zc (or
    +- ``working_radius_m`` metres).
    """
    if depth_range is None:
        zc = working_depth(rig, ref)
        radius = working_radius * zc if working_radius_m is None else working_radius_m
        depth_range = (zc - radius, zc + radius)
    return np.linspace(depth_range[0], depth_range[1], n_labels)


def data_term_evaluator(frame: Frame, ref: Camera, pairs):
    """``evaluate(rays, depths, normal_dtype=np.float32, show=False, out=None)``:
    the eq. (5) data term (:func:`colourhs.reconstruct.dataterm.data_term`)
    of rays from ``ref``'s centre at each hypothesised depth, in chunks of
    ``CHUNK`` pixels (bounds the float32 normals buffer; ``show``: a progress
    bar over them, for the whole frame's call rather than the initial surface's
    one-depth calls); returns the (N, L) cost and (N, L, 3) normals, or with
    ``out = (cost, normals, rows)`` writes ray i's into row ``rows[i]`` of
    those arrays (``normals`` None: not kept) and returns them."""
    prepared = prepare_images(
        frame.images,
        frame.saturated,
        pairs,
        frame.mu,
        frame.chroma,
        frame.silhouettes,
        borrow_p=frame.chroma_tracked,
    )
    cameras = frame.rig.cameras

    def evaluate(pixel_rays, hypotheses, normal_dtype=np.float32, show=False, out=None):
        if out is None:
            cost = np.empty((len(pixel_rays), len(hypotheses)), np.float32)
            normals = np.empty((len(pixel_rays), len(hypotheses), 3), normal_dtype)
            rows = np.arange(len(pixel_rays))
        else:
            cost, normals, rows = out
        chunks = range(0, len(pixel_rays), CHUNK)
        for s in bar(chunks, "data term", disable=not show, unit="chunk"):
            c, n = data_term(
                pixel_rays[s : s + CHUNK], ref.centre, hypotheses, cameras, prepared, pairs
            )
            cost[rows[s : s + len(c)]] = c
            if normals is not None:
                normals[rows[s : s + len(c)]] = n
        return cost, normals

    return evaluate


def _frame_sides(frame, ref, pairs, blur_px, min_support=None):
    """The frame's :func:`~colourhs.reconstruct.sides.helmholtz_sides` for rays from
    camera ``ref``; with a tracked chromaticity map, a side without p takes the
    reference pixel's (as the data term, :mod:`colourhs.reconstruct.dataterm`)."""
    from colourhs.reconstruct.sides import BLUR_SUPPORT, helmholtz_sides

    at = frame.rig.camera_names.index(ref.name) if frame.chroma_tracked else None
    support = BLUR_SUPPORT if min_support is None else min_support
    return helmholtz_sides(
        frame, frame.variance, pairs, blur_px=blur_px, min_support=support, reference=at
    )


def _ml_solution(frame, cost, search: _Search, max_cost, blur_px=None, say=None):
    """ML HS (:func:`colourhs.reconstruct.ml.ml_depth`) as (H*W,) depth, (H*W, 3)
    normal, validity, confidence (1 - the best hypothesis' cost) and each
    depth's 1-sigma uncertainty (:func:`ml_sigma`, metres)."""
    from colourhs.reconstruct.ml import ml_depth

    rays, pix, depths, ref, pairs = (
        search.grid.rays,
        search.pix,
        search.depths,
        search.ref,
        search.pairs,
    )
    shape = search.grid.shape
    H, W = shape
    sides = _frame_sides(frame, ref, pairs, blur_px)
    z_ml, n_ml, good = ml_depth(cost, depths, pix, rays, ref.centre, sides, shape, max_cost, say)
    z = np.full(H * W, np.nan)
    z[pix] = np.where(good, z_ml, np.nan)
    nrm = np.zeros((H * W, 3))
    nrm[pix] = np.where(good[:, None], n_ml, np.nan)
    ok = np.zeros(H * W, bool)
    ok[pix] = good
    conf = np.zeros(H * W, np.float32)
    conf[pix] = np.clip(1.0 - cost.min(axis=1), 0, 1) * good
    sigma = np.full(H * W, np.nan)
    if good.any():
        from colourhs.reconstruct.bayes.uncertainty import ml_sigma

        if say is not None:
            say("ml: each depth's uncertainty")
        sel = pix[good]
        sigma[sel] = ml_sigma(sides, rays[sel], z[sel], ref.centre)
    return z, nrm, ok, conf, sigma


def _labelled_surface(chosen, n_sel, frac, depths, pix, shape, max_cost):
    """The labelling as (H*W,) depth, (H*W, 3) normal, validity (the chosen
    hypothesis' cost ``chosen`` is under ``max_cost``) and confidence (1 - that cost);
    ``n_sel`` (N, 3) are the chosen hypotheses' normals."""
    H, W = shape
    valid = chosen < max_cost
    n_sel = n_sel.astype(float)
    n_sel /= np.maximum(np.linalg.norm(n_sel, axis=1, keepdims=True), 1e-12)
    z = np.full(H * W, np.nan)
    z[pix] = _depth_at(depths, frac)
    nrm = np.zeros((H * W, 3))
    nrm[pix] = n_sel
    ok = np.zeros(H * W, bool)
    ok[pix] = valid
    conf = np.zeros(H * W, np.float32)
    conf[pix] = np.clip(1.0 - chosen, 0, 1) * valid
    return z, nrm, ok, conf


def _without_rims(ok, shape, erode_px):
    """``ok`` (H*W,) eroded by ``erode_px`` pixels: pixels next to where nothing
    was reconstructed (board edges, marker rims, silhouettes) mix surfaces
    within their footprint, so they are left out."""
    from scipy.ndimage import binary_erosion

    if erode_px <= 0:
        return ok
    return ok & binary_erosion(ok.reshape(shape), iterations=erode_px).ravel()


def _mrf_box(pix, shape):
    """The MRF's box: the foreground's bounding box plus a margin of 2 pixels
    (the background carries no data, only path length), as ``(r0, r1, c0, c1)``,
    and the foreground pixels' indices (N,) in it, row-major."""
    H, W = shape
    rows, cols = np.divmod(pix, W)
    r0, r1 = max(rows.min() - 2, 0), min(rows.max() + 3, H)
    c0, c1 = max(cols.min() - 2, 0), min(cols.max() + 3, W)
    return (int(r0), int(r1), int(c0), int(c1)), (rows - r0) * (c1 - c0) + (cols - c0)


def _bayes_labelling(cost, normals, local, box, rays, depths, shape, opts, info, say=None):
    """MAP labels of the MRF (SGM with the depth-normal prior) over the box of :func:`_mrf_box`.

    ``cost`` (h*w, L) and ``normals`` (h*w, L, 3) are the data term over the
    box, the foreground at rows ``local`` (N,); the MRF's data cost is
    ``cost / opts.cost_scale``, ``INVALID_COST / opts.cost_scale`` on the box's
    background (``opts.alpha``, ``opts.tau``: the MRF's weights). Returns the
    foreground's labels (N,) and their sub-label positions (a parabola through
    the aggregated cost). ``say(text)``, if given, reports the SGM sweeps.
    """
    from colourhs.reconstruct.bayes.mrf import labelling_energy, sgm_depth_normal

    H, W = shape
    n_labels = len(depths)
    r0, r1, c0, c1 = box
    h, w = r1 - r0, c1 - c0
    scaled = cost / opts.cost_scale
    background = np.ones(h * w, bool)
    background[local] = False
    scaled[background] = INVALID_COST / opts.cost_scale
    volumes = (scaled.reshape(h, w, n_labels), normals.reshape(h, w, n_labels, 3))
    box_rays = rays.reshape(H, W, 3)[r0:r1, c0:c1]
    lab, S = sgm_depth_normal(
        *volumes,
        box_rays.astype(np.float32),
        depths.astype(np.float32),
        opts.alpha,
        opts.tau,
        say=say,
    )
    info["energy"] = float(labelling_energy(lab, *volumes, box_rays, depths, opts.alpha, opts.tau))
    info["mrf_box"] = [r0, r1, c0, c1]
    labels = lab.ravel()[local]
    return labels, _subpixel(S.reshape(h * w, n_labels), local, labels)


def _consistent_surface(
    frame, z, ok, search: _Search, iterations, spline_px, blur_px=None, say=None
):
    """The depth from the agreement of geometry and eq. (5) (see :mod:`.surface`);
    ``say(text)`` reports its steps."""
    from colourhs.reconstruct.bayes.refine import RefineOptions, refine_surface
    from colourhs.reconstruct.sides import RIM_SUPPORT

    ref, pairs = search.ref, search.pairs
    if say is not None:
        say("refinement: each reciprocal pair's images and noise, resampled for E")
    sides = _frame_sides(frame, ref, pairs, blur_px)
    # The rows at the edges of unusable regions: their pull joins the sigma (rim_valley_pull).
    clear = _frame_sides(frame, ref, pairs, blur_px, RIM_SUPPORT)
    footprint = np.abs(z) / float(ref.K[0, 0])
    fill = object_mask(frame, frame.rig.camera_names.index(ref.name)).ravel()
    zr, nr, sinfo = refine_surface(
        z,
        ok,
        search.grid,
        sides,
        footprint,
        RefineOptions(spacing_px=spline_px, iterations=iterations),
        fill=fill,
        clear_sides=clear,
        ratio_sigma=frame.mu_ratio_sigma,
        say=say,
    )
    ok = (ok | sinfo["filled"]) & np.isfinite(zr) & sinfo["valid"]
    z = np.where(ok, zr, np.nan)
    sigma = np.where(ok, sinfo["sigma"], np.nan)
    nrm = np.where(ok[:, None], nr, np.nan)
    info = {
        "iterations": iterations,
        "energy": sinfo["energy"],
        "surfaces": sinfo["surfaces"],
        "restarted": sinfo["restarted"],
        "control_points": sinfo["control_points"],
        "filled": int(sinfo["filled"].sum()),
        "depth_factors": sinfo["depth_factors"],
        "depth_factor_sigma": sinfo["depth_factor_sigma"],
        "robust_pull_m": sinfo["robust_pull_m"],
        "pair_jackknife_m": sinfo["pair_jackknife_m"],
        "converged": sinfo["converged"],
    }
    return z, nrm, ok, sinfo["weights"], sigma, info


def reconstruct_frame(
    dataset_dir,
    scene,
    frame,
    out_h5,
    method="bayes",
    calibration: CalibrationFiles | None = None,
    hull_ply=None,
    **params,
) -> DepthResult:
    """Load, reconstruct and write one frame (the Snakemake rule's function).

    ``calibration``: the files :func:`load_frame` applies (none by default);
    their paths and SHA-256 go into the depth file's attributes.

    With ``hull_ply`` (the frame's visual hull, ``colourhs hull``) the depth
    hypotheses span the hull's depth range in the reference camera
    (:func:`colourhs.surfaces.hull.hull_depth_range`) instead of the working range.
    """
    calibration = calibration or CalibrationFiles()
    fr = load_frame(dataset_dir, scene, frame, **asdict(calibration))
    if hull_ply is not None:
        from colourhs.common.ply import load_mesh
        from colourhs.surfaces.hull import hull_depth_range

        vertices, triangles, _ = load_mesh(hull_ply)
        ref = fr.rig.camera(params.get("reference") or fr.rig.camera_names[0])
        try:
            span = hull_depth_range(
                vertices, triangles, ref, fr.rig.image.width, fr.rig.image.height
            )
        except ValueError as err:
            raise ValueError(f"{hull_ply}: {err}") from None
        params = {**params, "depth_range": span}
    result = reconstruct(fr, method, **params)
    ref = fr.rig.camera(result.info["reference"])
    calib = calibration.provenance()
    attrs = {
        "method": method,
        "params": result.info,
        "calibration": {k: str(v) if v else None for k, v in calib.items()},
        "calibration_sha256": {k: sha256_files([v]) for k, v in calib.items() if v},
        "inputs_sha256": sha256_files(fr.inputs),
    }
    if hull_ply is not None:
        attrs.update(hull=str(hull_ply), hull_sha256=sha256_files([hull_ply]))
    write_depth(out_h5, result, ref, attrs)
    return result
