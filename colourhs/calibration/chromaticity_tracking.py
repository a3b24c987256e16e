"""Chromaticity that follows the surface through a sequence (beyond the paper).

The paper calibrates the surface chromaticity p (eqs. 9-12) per camera pixel from
chromatic captures of an object in one pose, and names dense surface point tracking,
carrying that calibration to each point's new position, as the way to reconstruct
moving multi-coloured objects (its conclusion). Here each camera's map is carried
from the chromatic frame c (scene.json's ``chromatic_frame``) through the sequence,
one frame at a time in each direction, so that frame f's map depends on its
neighbour towards c only:

1. Prediction: each pixel keeps its point's pixel in frame c (``position``); a dense
   optical flow from frame f's image to its neighbour's carries the neighbour's
   positions to frame f; where it leaves what the neighbour tracked, the pixel takes
   the neighbour's position at itself (no motion), or else its own pixel
   (:func:`predict_positions`). The flow is chosen per pixel among candidates
   (:func:`prediction_flow`): OpenCV's DIS on the brightness (:func:`flow_image`),
   which follows texture to a fraction of a pixel but also follows highlights as they
   slide over a glossy surface; DIS at a coarse scale on the image's colour
   (:func:`colour_flow`), which sees the surface's colour edges and not its shading;
   and no motion. Each pixel takes the candidate whose colour, compared over a
   window, best matches the neighbour's there (:func:`select_flow`). The same flow
   from frame f straight to frame c gives a second prediction, which does not add up
   the small errors of each step; each pixel takes the one whose colour in frame c,
   compared over the same window, best matches its own, the direct one where they
   match equally (:func:`predict_from_both`).
2. Shading: the image colour (:func:`image_colour`: the channels over their sum, all
   lights on) is p times each band's shading, and the shading of each band changes as
   the surface turns under its light. A smooth gain per band (:func:`shading_gain`,
   log colour of frame f over that of frame c at the prediction, averaged over
   :data:`GAIN_SIGMA_PX` without the pixels that disagree by more than
   :data:`GAIN_OUTLIER`) is divided out of frame f's colour before it is compared with
   frame c's: a colour edge moves by pixels, a shading change spreads over many.
3. Colour: the prediction is then moved, within :data:`SEARCH_PX`, to the pixel of
   frame c whose colour best matches the pixel's own (shading divided out) in frame
   f, with a small preference for the prediction (:data:`PROXIMITY`). Flow fails
   where the surface has no texture (a uniform patch, a metal under moving
   highlights) but the colour does not: within a uniform patch any match has the
   right p, and at a patch edge the colour picks the side. Every frame is matched to
   frame c itself, so the drift of the chained flow is re-anchored at every step,
   not only where the object shows the chromatic pose again.
4. A pixel whose best match still differs by more than :data:`COLOUR_TOL` is left
   unknown (NaN, as the calibration leaves a pixel it cannot measure): a surface that
   frame c did not show, a highlight, or a wrong prediction. Its point keeps the
   prediction as its position, so that the next frame's flow carries it on and the
   colour can confirm it again once the highlight has passed (a lost point's position
   would otherwise fall back to no motion and stay behind the surface).
5. p is sampled once from the calibrated map at the position (:func:`sample_at`,
   nearest: no colour is mixed across a patch edge, and no blur accumulates). The
   match's relative colour residual, ``|q_f - q_c| / |q_c|``, is the tracking's 1-sigma
   of log p (``sigma``: the reconstruction weighs the channels by it). Where the
   calibrated map carries its own error bar
   (:func:`colourhs.calibration.chromaticity.log_sigma`, the chromatic captures'
   sensor noise), the tracked map's 1-sigma of log p per band (``p_sigma``,
   :func:`tracked_log_sigma`) is that error bar at the position and the position's
   error times the colour edge there, in quadrature: the p sampled there carries the
   calibration's error, and at a patch edge a point placed off its true position
   takes the other patch's p, which the colours, blurred alike on both sides of the
   match, do not show. The position's error is the nearest sampling's
   (:data:`POSITION_SIGMA_PX`) and the prediction's, the distance between step 1's
   two predictions (``spread``: where the chained and the direct flow disagree, one
   of them is wrong), in quadrature; the edge is the largest change of log p from the
   sampled pixel to a neighbour beyond the calibration's noise (:func:`log_p_jump`;
   0 inside a patch of one colour). The match's residual is not in ``p_sigma``:
   inside a patch it is the shading's change and the images' noise, not an error of
   p. The reconstruction is not weighed by the edge term: widening the intensity
   variance at every colour edge moved the depth of tracked cloths away from the
   truth.

The map keeps the tracking's own holes. Where the reconstruction reads it for a
moved frame, a pixel of its reference camera without p that shows the colour of a
pixel near it with one (in that frame's image, :func:`colour_match` within
:data:`COLOUR_TOL`) takes that pixel's p, :data:`FILL_ROUNDS` times, each reaching on
from the last (:func:`fill_from_colour`,
:func:`colourhs.reconstruct.inputs.fill_reference_holes`; beyond the paper): within a
patch of one colour, the same p, where a lost point (a highlight passed, a surface
turned into view) or a point the calibration could not measure would drop the pixel.

A static scene, or the chromatic frame itself, keeps the calibrated map unchanged
(position the pixel itself, sigma 0, ``p_sigma`` the calibrated map's):
``bayes_dyn`` there equals ``bayes_full``.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import h5py
import numpy as np

from colourhs.capture import Dataset, dataset_of, read_image
from colourhs.common.files import atomic_output, note_read
from colourhs.common.progress import bar, stage

log = logging.getLogger(__name__)

__all__ = [
    "COLOUR_FLOW_WIDTH_PX",
    "COLOUR_TOL",
    "FILL_ROUNDS",
    "GAIN_OUTLIER",
    "GAIN_SIGMA_PX",
    "GAIN_SUPPORT",
    "JUMP_NOISE_SIGMAS",
    "POSITION_SIGMA_PX",
    "PROXIMITY",
    "SEARCH_PX",
    "SELECT_WINDOW_PX",
    "TrackedMap",
    "calibrated_as_tracked",
    "colour_match",
    "dense_flow",
    "colour_flow",
    "fill_from_colour",
    "flow_image",
    "image_colour",
    "log_p_jump",
    "predict_from_both",
    "predict_positions",
    "prediction_flow",
    "read_tracked",
    "sample_at",
    "select_flow",
    "shading_gain",
    "track_camera",
    "track_chromaticity",
    "track_sequence",
    "tracked_log_sigma",
    "tracking_neighbour",
]

SEARCH_PX = 3
"""Radius of the colour search around the flow's prediction, pixels: the flow errs by
less than a pixel on a textured surface, and where it fails (no texture) the search
needs only reach a patch's other side; three pixels, at any image size."""

COLOUR_TOL = 0.05
"""Largest distance between a pixel's colour and its match's in the chromatic frame
(:func:`image_colour`: the channels over their sum) that keeps its p: the same surface
seen again under the same lights differs by a few hundredths as its shading changes,
two patches of the calibrated colours by tenths."""

PROXIMITY = 5e-4
"""Preference for the flow's prediction: the squared colour distance one pixel of
displacement costs, so that among equally good colours (a uniform patch) the match
stays where the flow put it; at :data:`SEARCH_PX` it costs less than a fifth of
:data:`COLOUR_TOL` squared."""

GAIN_SIGMA_PX = 5 * SEARCH_PX
"""Scale of the shading gain (:func:`shading_gain`), pixels (a Gaussian's sigma): five
search radii, so that the gain cannot mimic a colour edge displaced by up to
:data:`SEARCH_PX` (which the colour match must see), at any image size."""

GAIN_OUTLIER = 0.2
"""Largest difference of log colour (:func:`shading_gain`) a pixel may have from the gain
and still inform it: shading changes a band by a few tens of per cent from frame to
frame, a wrong colour (another patch, a highlight) by far more."""

GAIN_SUPPORT = 0.25
"""Least share of the gain's Gaussian weight that the pixels informing it must hold for
a gain to be set (else 0): a quarter of the neighbourhood agrees on the shading; a
few pixels of mixed colour at patch edges do not."""

SELECT_WINDOW_PX = 9
"""Side of the window over which :func:`select_flow` compares the candidates' colours,
pixels: a few pixels either side of a colour edge, so a window that straddles one
tells a right displacement from a wrong one, at any image size."""

COLOUR_FLOW_WIDTH_PX = 80
"""Width of the finest pyramid level of :func:`colour_flow`'s DIS, pixels (an eighth of a
640-pixel image, its patches of 16 pixels a fifth of that): the colour's edges, not its
shading or highlights, at any image size; the brightness flow gives the fine detail
where it is right."""


JUMP_NOISE_SIGMAS = 3.0
"""How many 1-sigmas of two neighbouring pixels' noise difference a change of log p
must exceed to count as a colour edge (:func:`log_p_jump`): beyond 3 sigma a Gaussian
difference is noise once in 370; a property of the noise's distribution, not of the
rig."""


POSITION_SIGMA_PX = 12**-0.5
"""1-sigma of the position at which :func:`sample_at` takes p, pixels: the nearest
pixel's centre stands for a point anywhere within that pixel, uniformly, whose standard
deviation is one over the square root of 12 of the pixel's side; a property of the
pixel lattice, so it holds at any image size and on any rig."""


FILL_ROUNDS = 4
"""Rounds of the hole fill (:func:`fill_from_colour`), each reaching on two pixels
where the colours are equal (:func:`colour_match`'s cost of a displacement,
:data:`PROXIMITY`, stays within :data:`COLOUR_TOL`): a hole up to 16 pixels across is
filled from both sides. In pixels, as the search: the fill follows a patch of one
colour pixel by pixel, and its reach bounds how far a p is carried from where the
colour match confirmed it, at any image size."""


@dataclass(frozen=True)
class TrackedMap:
    """One camera's chromaticity in one frame.

    Attributes
    ----------
    p : (H, W, 3) float32, (p_R, p_G, p_B) summing to 3, NaN where unknown.
    position : (H, W, 2) float32, each pixel's point as a pixel (x, y) of the chromatic
        frame: the colour match's where p is known, the prediction where the colour
        did not confirm it; NaN where the pixel is dark (nothing seen to track) or,
        in the chromatic frame, where the calibration has no p.
    position_sigma : (H, W) float32, how far the colour match moved the flow's
        prediction, pixels (0 in the chromatic frame).
    sigma : (H, W) float32, the tracking's 1-sigma of log p: the match's relative
        colour residual.
    p_sigma : (H, W, 3) float32 or None, each band's 1-sigma of log p of the map
        (:func:`tracked_log_sigma`); None where the calibrated map has no error bar.
    spread : (H, W) float32 or None, how far apart step 1's two predictions (the
        chained and the direct one, :func:`predict_from_both`) put each pixel's point,
        pixels: the flows' own disagreement, a measure of the prediction's position
        error (0 in the chromatic frame); None where not measured (a file written
        without it).
    """

    p: np.ndarray
    position: np.ndarray
    position_sigma: np.ndarray
    sigma: np.ndarray
    p_sigma: np.ndarray | None = None
    spread: np.ndarray | None = None


def flow_image(rgb: np.ndarray) -> np.ndarray:
    """An image (H, W, 3), linear, as the 8-bit single channel the flow reads: the
    square root of the channels' mean (shot noise even, highlights compressed),
    scaled so that its 99.9th percentile is 255 (the exposure of any rig)."""
    g = np.sqrt(np.clip(np.asarray(rgb, np.float32).mean(axis=-1), 0.0, None))
    top = float(np.percentile(g, 99.9)) or 1.0
    return np.clip(np.round(g * (255.0 / top)), 0, 255).astype(np.uint8)


def dense_flow(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dense optical flow (H, W, 2) from 8-bit image ``a`` to ``b``: ``a(x) ~ b(x + flow(x))``
    (OpenCV's DIS, its medium preset), pixels."""
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    return dis.calc(a, b, None)


def colour_flow(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dense flow (H, W, 2) from linear image ``a`` (H, W, 3) to ``b`` on their colour
    (:func:`image_colour`): OpenCV's DIS, its finest level about
    :data:`COLOUR_FLOW_WIDTH_PX` wide, on each band of the colour (as 8 bits), their
    median per pixel. Shading and white light change the brightness; the colour
    changes where the surface's colour does."""
    qa, qb = image_colour(a), image_colour(b)
    scale = max(0, round(np.log2(a.shape[1] / COLOUR_FLOW_WIDTH_PX)))
    flows = []
    for k in range(3):
        dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
        dis.setFinestScale(scale)
        dis.setPatchSize(16)
        dis.setPatchStride(4)
        ia, ib = (np.clip(np.round(np.nan_to_num(q[..., k]) * 255), 0, 255) for q in (qa, qb))
        flows.append(dis.calc(ia.astype(np.uint8), ib.astype(np.uint8), None))
    return np.median(flows, axis=0).astype(np.float32)


def select_flow(
    candidates: list[np.ndarray], colour: np.ndarray, neighbour_colour: np.ndarray
) -> np.ndarray:
    """Per pixel, the candidate flow (each (H, W, 2), from this frame to its neighbour)
    whose displaced neighbour colour best matches this frame's ``colour`` (each (H, W, 3),
    :func:`image_colour`), the squared distance summed over a window of
    :data:`SELECT_WINDOW_PX` (an unknown colour counts as the largest distance, 1); the
    first candidate wins a tie."""
    gx, gy = _grid(colour.shape)
    win = (SELECT_WINDOW_PX, SELECT_WINDOW_PX)
    costs = []
    for flow in candidates:
        seen = _remap(neighbour_colour, gx + flow[..., 0], gy + flow[..., 1])
        cost = np.nan_to_num(np.sum((colour - seen) ** 2, axis=-1), nan=1.0)
        costs.append(cv2.boxFilter(cost.astype(np.float32), -1, win))
    best = np.argmin(np.stack(costs), axis=0)
    return np.take_along_axis(np.stack(candidates), best[None, ..., None], axis=0)[0]


def prediction_flow(frame_rgb: np.ndarray, neighbour_rgb: np.ndarray) -> np.ndarray:
    """Step 1's flow (H, W, 2) from a frame's image to its neighbour's (linear, (H, W, 3)):
    :func:`select_flow` among the colour flow (:func:`colour_flow`: first, so that it
    wins where no colour tells them apart), the brightness flow (:func:`dense_flow` of
    :func:`flow_image`) and no motion."""
    candidates = [
        colour_flow(frame_rgb, neighbour_rgb),
        dense_flow(flow_image(frame_rgb), flow_image(neighbour_rgb)),
        np.zeros(frame_rgb.shape[:2] + (2,), np.float32),
    ]
    return select_flow(candidates, image_colour(frame_rgb), image_colour(neighbour_rgb))


def _masked_blur(values: np.ndarray, weight: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian average (H, W, C) of ``values`` over the pixels where ``weight``; NaN
    where they are less than :data:`GAIN_SUPPORT` of the Gaussian's weight (no value is
    carried far from the pixels that give it)."""
    num = cv2.GaussianBlur(np.where(weight[..., None], values, 0).astype(np.float32), (0, 0), sigma)
    den = cv2.GaussianBlur(weight.astype(np.float32), (0, 0), sigma)[..., None]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den >= GAIN_SUPPORT, num / den, np.nan)


def shading_gain(
    colour: np.ndarray, anchor_colour: np.ndarray, predicted: np.ndarray, iterations: int = 3
) -> np.ndarray:
    """Step 2 of the module: the smooth per-band gain (H, W, 3), log, of a frame's colour
    over the chromatic frame's at the predicted positions (0 where nothing informs it).

    The log ratio of the colours is averaged over :data:`GAIN_SIGMA_PX`, then again
    without the pixels farther than :data:`GAIN_OUTLIER` from that average (another
    patch, a highlight), ``iterations`` times in all.
    """
    seen = sample_at(anchor_colour, predicted)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.log(colour) - np.log(seen)
    known = np.all(np.isfinite(ratio), axis=-1)
    ratio = np.where(known[..., None], ratio, 0.0)
    gain = np.zeros_like(ratio)
    for _ in range(iterations):
        near = known & (np.linalg.norm(ratio - gain, axis=-1) < GAIN_OUTLIER)
        gain = np.nan_to_num(_masked_blur(ratio, near, GAIN_SIGMA_PX))
    return gain.astype(np.float32)


def _grid(shape) -> tuple[np.ndarray, np.ndarray]:
    h, w = shape[:2]
    return np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))


def _remap(values: np.ndarray, x: np.ndarray, y: np.ndarray, nearest=False) -> np.ndarray:
    """``values`` (H, W) or (H, W, C) sampled at (x, y), NaN outside; bilinear where the four
    neighbours are known, else the nearest (an edge of the known region keeps its value)."""
    v = np.asarray(values, np.float32)
    v = v[..., None] if v.ndim == 2 else v
    x = np.nan_to_num(x, nan=-1e6).astype(np.float32)
    y = np.nan_to_num(y, nan=-1e6).astype(np.float32)
    out = []
    for k in range(v.shape[-1]):
        near = cv2.remap(v[..., k], x, y, cv2.INTER_NEAREST, borderValue=np.nan)
        if nearest:
            out.append(near)
            continue
        lin = cv2.remap(v[..., k], x, y, cv2.INTER_LINEAR, borderValue=np.nan)
        out.append(np.where(np.isfinite(lin), lin, near))
    out = np.stack(out, axis=-1)
    return out[..., 0] if np.ndim(values) == 2 else out


def sample_at(values: np.ndarray, position: np.ndarray) -> np.ndarray:
    """Step 5's sampling: ``values`` (H, W) or (H, W, C) of the chromatic frame at each
    pixel's ``position`` there ((H', W', 2), x and y), the nearest pixel's (no colour is
    mixed across a patch edge, and no blur accumulates); NaN outside the image or where
    the position is NaN."""
    return _remap(values, position[..., 0], position[..., 1], nearest=True)


def log_p_jump(calibrated: np.ndarray, calibrated_sigma: np.ndarray | None = None) -> np.ndarray:
    """The largest change of log p (H, W) from a pixel of the calibrated map
    (``calibrated`` (H, W, 3)) to one of its 4-neighbours with a p, over the three
    bands: 0 inside a patch of one colour, the patches' log ratio at its edge; 0 where
    the pixel or all its neighbours have none (beyond the paper).

    With the map's error bar (``calibrated_sigma`` (H, W, 3), 1-sigma of log p), each
    band's change less :data:`JUMP_NOISE_SIGMAS` of the two pixels' noise, in
    quadrature (0 where no larger): the colour edge alone, since a change that noise
    explains is not one a displaced sample would make (the noise is the calibration's
    own term of :func:`tracked_log_sigma`)."""
    log_p = np.log(np.where(calibrated > 0, calibrated, np.nan))
    jump = np.zeros(log_p.shape[:2])
    with np.errstate(invalid="ignore"):
        for axis in (0, 1):
            d = np.abs(np.diff(log_p, axis=axis))
            if calibrated_sigma is not None:
                s = np.asarray(calibrated_sigma, float)
                lo_s = s[:-1] if axis == 0 else s[:, :-1]
                hi_s = s[1:] if axis == 0 else s[:, 1:]
                noise = JUMP_NOISE_SIGMAS**2 * (np.nan_to_num(lo_s) ** 2 + np.nan_to_num(hi_s) ** 2)
                d = np.sqrt(np.maximum(d * d - noise, 0.0))
            d = np.nan_to_num(d.max(axis=-1))
            lo = [slice(None)] * 2
            hi = [slice(None)] * 2
            lo[axis], hi[axis] = slice(None, -1), slice(1, None)
            jump[tuple(lo)] = np.maximum(jump[tuple(lo)], d)
            jump[tuple(hi)] = np.maximum(jump[tuple(hi)], d)
    return jump.astype(np.float32)


def image_colour(rgb: np.ndarray) -> np.ndarray:
    """An image's colour (H, W, 3): each pixel's channels over their sum (NaN where it
    is dark), smoothed by a Gaussian of 1 pixel against the noise."""
    rgb = np.clip(np.asarray(rgb, np.float32), 0.0, None)
    total = rgb.sum(axis=-1, keepdims=True)
    lit = total > 1e-3 * float(np.percentile(total, 99.9) or 1.0)
    q = np.where(lit, rgb / np.where(lit, total, 1.0), 0.0).astype(np.float32)
    q = cv2.GaussianBlur(q, (0, 0), 1.0)
    q[~lit[..., 0]] = np.nan
    return q


def predict_positions(neighbour: TrackedMap, forward: np.ndarray) -> np.ndarray:
    """Positions in the chromatic frame (H, W, 2) predicted for a frame whose flow to its
    neighbour frame is ``forward``: the neighbour's where the flow sends each pixel; where
    that is unknown the neighbour's at the pixel itself (no motion), and where that is
    unknown too the pixel itself (a surface the neighbour lost may be found again)."""
    gx, gy = _grid(forward.shape)
    moved = _remap(neighbour.position, gx + forward[..., 0], gy + forward[..., 1])
    moved = np.where(np.isfinite(moved), moved, neighbour.position)
    return np.where(np.isfinite(moved), moved, np.stack([gx, gy], axis=-1)).astype(np.float32)


def predict_from_both(
    chained: np.ndarray, direct: np.ndarray, colour: np.ndarray, anchor_colour: np.ndarray
) -> np.ndarray:
    """Step 1's prediction (H, W, 2), positions in the chromatic frame: per pixel, the
    ``chained`` one (:func:`predict_positions`, carried from the neighbour frame) or the
    pixel moved by ``direct``, the flow (H, W, 2) straight to the chromatic frame
    (:func:`prediction_flow`), whichever :func:`select_flow` finds the frame's
    ``colour`` agrees with in ``anchor_colour`` (:func:`image_colour` of each); the
    direct one wins a tie (inside a patch of one colour, where the colours cannot tell
    them apart), since it has no earlier step's error to carry (beyond the paper)."""
    grid = np.stack(_grid(colour.shape), axis=-1)
    return grid + select_flow([direct, chained - grid], colour, anchor_colour)


def colour_match(
    predicted: np.ndarray, colour: np.ndarray, anchor_colour: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Step 3 of the module: per pixel, the position within :data:`SEARCH_PX` of
    ``predicted`` whose colour in the chromatic frame (``anchor_colour``) best matches
    the pixel's ``colour``, and the match's colour distance (NaN where none)."""
    best = np.full(colour.shape[:2], np.inf, np.float32)
    out = np.full_like(predicted, np.nan)
    r = int(SEARCH_PX)
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            cand = predicted + np.array([dx, dy], np.float32)
            seen = sample_at(anchor_colour, cand)
            cost = np.sum((colour - seen) ** 2, axis=-1) + PROXIMITY * (dx * dx + dy * dy)
            better = cost < best  # False where NaN
            best[better] = cost[better]
            out[better] = cand[better]
    found = np.isfinite(best)
    distance = np.where(found, np.sqrt(np.where(found, best, 0.0)), np.nan)
    return out, distance.astype(np.float32)


def calibrated_as_tracked(calibrated: np.ndarray) -> TrackedMap:
    """The chromatic frame's map: the calibrated one, each pixel at itself, sigma 0."""
    gx, gy = _grid(calibrated.shape)
    known = np.all(np.isfinite(calibrated), axis=-1)
    position = np.where(known[..., None], np.stack([gx, gy], axis=-1), np.nan)
    zero = np.where(known, 0.0, np.nan).astype(np.float32)
    return TrackedMap(
        calibrated.astype(np.float32), position.astype(np.float32), zero, zero, spread=zero
    )


def track_camera(
    calibrated: np.ndarray,
    neighbour: TrackedMap,
    frame_rgb: np.ndarray,
    neighbour_rgb: np.ndarray,
    anchor_rgb: np.ndarray,
) -> TrackedMap:
    """One camera's map in a frame from its neighbour's (steps 1-5 of the module).

    Parameters
    ----------
    calibrated : (H, W, 3) the calibrated map of the chromatic frame.
    neighbour : the neighbour frame's map (towards the chromatic frame).
    frame_rgb, neighbour_rgb, anchor_rgb : (H, W, 3) linear images (all lights on) of
        the frame, of its neighbour and of the chromatic frame.
    """
    colour, anchor = image_colour(frame_rgb), image_colour(anchor_rgb)
    chained = predict_positions(neighbour, prediction_flow(frame_rgb, neighbour_rgb))
    direct = prediction_flow(frame_rgb, anchor_rgb)
    predicted = predict_from_both(chained, direct, colour, anchor)
    spread = np.linalg.norm(chained - np.stack(_grid(colour.shape), axis=-1) - direct, axis=-1)
    colour = colour * np.exp(-shading_gain(colour, anchor, predicted))
    colour /= colour.sum(axis=-1, keepdims=True)
    position, distance = colour_match(predicted, colour, anchor)
    seen = sample_at(anchor, position)
    with np.errstate(invalid="ignore", divide="ignore"):
        sigma = np.linalg.norm(colour - seen, axis=-1) / np.linalg.norm(seen, axis=-1)
    p = sample_at(calibrated, position)
    lost = ~(distance <= COLOUR_TOL) | ~np.all(np.isfinite(p), axis=-1) | ~np.isfinite(sigma)
    p[lost] = np.nan
    moved = np.linalg.norm(position - predicted, axis=-1)
    seen_here = np.all(np.isfinite(colour), axis=-1)
    position[lost] = np.where(seen_here[lost, None], predicted[lost], np.nan)
    moved[lost] = np.nan
    sigma[lost] = np.nan
    return TrackedMap(
        p.astype(np.float32),
        position,
        moved.astype(np.float32),
        sigma.astype(np.float32),
        spread=spread.astype(np.float32),
    )


def fill_from_colour(
    p: np.ndarray, sigma: np.ndarray, colour: np.ndarray, rounds: int = FILL_ROUNDS
) -> tuple[np.ndarray, np.ndarray]:
    """A map's unknown pixels (``p`` (H, W, 3) NaN) given the p of
    the pixel within :data:`SEARCH_PX` whose ``colour`` (H, W, 3, :func:`image_colour`
    of the same image) best matches theirs, where it is within :data:`COLOUR_TOL`;
    ``rounds`` times, so a filled pixel may pass its p on. ``sigma`` (H, W), the
    tracking's 1-sigma of log p: the source's and the relative colour difference
    ``|q - q_source| / |q_source|`` in quadrature. Returns new ``p`` and ``sigma``."""
    p, sigma = p.copy(), sigma.copy()
    grid = np.stack(_grid(colour.shape), axis=-1)
    seen = np.all(np.isfinite(colour), axis=-1)
    for _ in range(rounds):
        known = np.all(np.isfinite(p), axis=-1)
        source, distance = colour_match(grid, colour, np.where(known[..., None], colour, np.nan))
        new = ~known & seen & (distance <= COLOUR_TOL)
        if not new.any():
            break
        x, y = source[new, 0], source[new, 1]
        xi, yi = np.round(x).astype(np.int64), np.round(y).astype(np.int64)
        q = colour[yi, xi]
        residual = np.linalg.norm(colour[new] - q, axis=-1) / np.linalg.norm(q, axis=-1)
        p[new] = p[yi, xi]
        sigma[new] = np.hypot(sigma[yi, xi], residual)
    return p, sigma


def tracked_log_sigma(
    calibrated: np.ndarray, calibrated_sigma: np.ndarray, tracked: TrackedMap
) -> np.ndarray:
    """Step 5's error bar of a tracked map: each band's 1-sigma of log p (H, W, 3), in
    quadrature the calibrated map's (``calibrated_sigma``, (H, W, 3),
    :func:`colourhs.calibration.chromaticity.log_sigma`) at the tracked position
    (nearest, as p is sampled) and the position's error times the colour edge of
    ``calibrated`` (H, W, 3) there (:func:`log_p_jump`, its noise taken out), where
    the point was carried (its position is not the pixel itself: the chromatic
    frame's map is the calibrated one, measured where it is). The position's error
    is the nearest sampling's, :data:`POSITION_SIGMA_PX`, and the prediction's
    (``tracked.spread``, the two flows' disagreement), in quadrature. NaN where the
    calibration's is unknown or the tracking lost the point (beyond the paper).

    The match's colour residual (``tracked.sigma``) is not in it: inside a patch it is
    the shading's change and the images' noise, not an error of p, and where the colour
    shows another patch the match is refused (:data:`COLOUR_TOL`)."""
    at = tracked.position
    calibration = sample_at(calibrated_sigma, at)
    carried = np.any(at != np.stack(_grid(at.shape), axis=-1), axis=-1)
    spread = 0.0 if tracked.spread is None else np.nan_to_num(tracked.spread)
    position = np.where(carried, np.hypot(POSITION_SIGMA_PX, spread), 0.0)
    jump = np.nan_to_num(sample_at(log_p_jump(calibrated, calibrated_sigma), at))
    lost = ~np.isfinite(tracked.sigma)
    out = np.hypot(calibration, (position * jump)[..., None])
    out[lost] = np.nan
    return out.astype(np.float32)


def tracking_neighbour(frames: tuple[str, ...], chromatic_frame: str, frame: str) -> str | None:
    """The frame whose map ``frame``'s is carried from: the next one towards the chromatic
    frame; None for the chromatic frame itself."""
    i, c = frames.index(frame), frames.index(chromatic_frame)
    return None if i == c else frames[i - 1 if i > c else i + 1]


def read_tracked(path: str | Path, camera: str) -> TrackedMap:
    """One camera's :class:`TrackedMap` from a file of :func:`track_chromaticity`."""
    note_read(path)
    with h5py.File(path) as f:
        return TrackedMap(
            f[camera][()],
            f[f"position/{camera}"][()],
            f[f"position_sigma/{camera}"][()],
            f[f"sigma/{camera}"][()],
            f[f"p_sigma/{camera}"][()] if f"p_sigma/{camera}" in f else None,
            f[f"spread/{camera}"][()] if f"spread/{camera}" in f else None,
        )


def track_chromaticity(
    dataset: str | Path | Dataset,
    scene: str,
    frame: str,
    calibrated_h5: str | Path,
    out_h5: str | Path,
    neighbour_h5: str | Path | None = None,
) -> dict:
    """Write a frame's chromaticity maps, carried from the chromatic frame (module docstring).

    Parameters
    ----------
    dataset : the dataset folder, or a Dataset (:func:`colourhs.capture.dataset_of`).
    scene, frame : the scene (with a chromatic object) and the frame.
    calibrated_h5 : the object's calibrated maps (``colourhs chromaticity``).
    out_h5 : the file to write: per camera ``<camera>`` (H, W, 3) p as the calibrated
        maps (so ``colourhs reconstruct --chromaticity`` reads it), ``position/<camera>``,
        ``position_sigma/<camera>``, ``sigma/<camera>`` and, where ``calibrated_h5`` has
        an error bar (``sigma/<camera>``), ``p_sigma/<camera>`` (:class:`TrackedMap`); attributes
        ``scene``, ``frame``, ``chromatic_frame``, ``neighbour`` and ``tracked`` (JSON:
        camera -> the frame's pixels with a p over the calibrated map's).
    neighbour_h5 : the neighbour frame's file (:func:`tracking_neighbour`); required but
        for the chromatic frame.

    Returns
    -------
    dict : the file's attributes.

    Raises
    ------
    ValueError
        A scene without a chromatic object, or a neighbour file missing or given where
        there is none.
    """
    ds = dataset_of(dataset, scenes=[scene])
    sc = ds.scene(scene)
    if not sc.chromatic:
        raise ValueError(f"scene {scene!r} has no chromatic object: nothing to track")
    c = sc.chromatic_frame
    neighbour = tracking_neighbour(sc.frames, c, frame)
    if (neighbour is None) != (neighbour_h5 is None):
        need = f"the map of frame {neighbour} (neighbour_h5)" if neighbour else "no neighbour"
        raise ValueError(f"{scene}/{frame}: tracking from chromatic frame {c} needs {need}")
    note_read(calibrated_h5)
    maps, tracked = {}, {}

    def image(f: str, cam: str) -> np.ndarray:
        return read_image(ds.frame_image(scene, f, cam), ds.rig.image)[0]

    with h5py.File(calibrated_h5) as h:
        calibrated = {cam: h[cam][()] for cam in ds.rig.camera_names}
        error_bar = {cam: h[f"sigma/{cam}"][()] for cam in calibrated if f"sigma/{cam}" in h}
    for cam in bar(ds.rig.camera_names, f"chromaticity {scene}/{frame}", unit="camera"):
        if neighbour is None:
            maps[cam] = calibrated_as_tracked(calibrated[cam])
        else:
            maps[cam] = track_camera(
                calibrated[cam],
                read_tracked(neighbour_h5, cam),
                image(frame, cam),
                image(neighbour, cam),
                image(c, cam),
            )
        if cam in error_bar:
            p_sigma = tracked_log_sigma(calibrated[cam], error_bar[cam], maps[cam])
            maps[cam] = replace(maps[cam], p_sigma=p_sigma)
        known = np.all(np.isfinite(calibrated[cam]), axis=-1).sum()
        tracked[cam] = float(np.all(np.isfinite(maps[cam].p), axis=-1).sum() / max(known, 1))
    attrs = {
        "scene": scene,
        "frame": frame,
        "chromatic_frame": c,
        "neighbour": neighbour or "",
        "tracked": json.dumps(tracked),
    }
    stage(log, f"chromaticity {scene}/{frame}: writing {Path(out_h5).name}")
    with atomic_output(out_h5) as tmp, h5py.File(tmp, "w") as f:
        for cam, m in maps.items():
            f[cam] = m.p
            f[f"position/{cam}"] = m.position
            f[f"position_sigma/{cam}"] = m.position_sigma
            f[f"sigma/{cam}"] = m.sigma
            if m.spread is not None:
                f[f"spread/{cam}"] = m.spread
            if m.p_sigma is not None:
                f[f"p_sigma/{cam}"] = m.p_sigma
        f.attrs.update(attrs)
    return attrs


def tracking_order(frames: tuple[str, ...], chromatic_frame: str) -> list[str]:
    """The frames in an order where each follows its neighbour (:func:`tracking_neighbour`):
    the chromatic frame, the later frames, then the earlier ones backwards."""
    c = frames.index(chromatic_frame)
    return [frames[c], *frames[c + 1 :], *frames[:c][::-1]]


def track_sequence(
    dataset: str | Path | Dataset, scene: str, calibrated_h5: str | Path, out_dir: str | Path
) -> dict[str, Path]:
    """Every frame's maps of a scene (:func:`track_chromaticity` in :func:`tracking_order`),
    written as ``out_dir/<frame>.h5`` (the workflow runs one frame per job instead).

    Returns
    -------
    dict : frame -> file, in the scene's frame order.
    """
    ds = dataset_of(dataset, scenes=[scene])
    sc = ds.scene(scene)
    out = {f: Path(out_dir) / f"{f}.h5" for f in sc.frames}
    for f in tracking_order(sc.frames, sc.chromatic_frame):
        neighbour = tracking_neighbour(sc.frames, sc.chromatic_frame, f)
        track_chromaticity(ds, scene, f, calibrated_h5, out[f], neighbour and out[neighbour])
    return out
