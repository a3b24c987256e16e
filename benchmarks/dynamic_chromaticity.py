"""Moving coloured objects: what a chromaticity map calibrated in one pose costs.

Run: ``.venv/bin/python benchmarks/dynamic_chromaticity.py [--preset random-dynamic-tiny]
[--seeds 0-3] [--frames 0-11/2] [--evaluate 0,5,11] [--raw-truth] [--tracked] [--oracle]
[--keep DIR] [--tag SUFFIX]``.

Why: the paper calibrates the surface chromaticity p (eq. 4, Section III-D) per
camera pixel from chromatic captures of the object in one pose, and the
pipeline uses that map unchanged on every frame. Once a coloured object moves
or deforms, its colours no longer lie on those pixels. This benchmark measures
what that costs on the dynamic presets' sequences (``moving-toy``: rigid,
``cloth``: deforming, ``turning-metal``: turning, its chromatic captures in a
middle frame; :mod:`colourhs.synth.dynamicscenes`), and what the frame's true
chromaticity would give instead: the bound any tracking of p can reach.

How: for every seed it renders ``colourhs synth --preset PRESET --seed N``
without the ``geometric/`` captures (the rig is the true one), runs the
workflow's calibration stages (``generalisation.calibrate``: marker poses,
cross-talk, noise, photometric maps, the chromaticity map of every sequence
from its chromatic captures), then reconstructs every frame of every
dynamic sequence (``--frames``: only those, and always each sequence's
chromatic frame) with each variant of :data:`VARIANTS` and compares the depth
map with the frame's ground-truth mesh (``generalisation.evaluate_variant``,
one frame at a time):

- ``bayes_ph``: Bayesian HS with the photometric and cross-talk calibration,
  no chromaticity (p = 1);
- ``bayes_full_static``: ``bayes_full`` with the chromaticity map calibrated
  from the chromatic captures (the paper's method) on every frame: what the
  workflow does today;
- ``bayes_full_true``: ``bayes_full`` with the frame's true chromaticity
  (``scenes/<scene>/gt/chromaticity/<frame>.h5``: one float32 (H, W, 3) map
  per camera, the layout of the calibrated maps, relative to white, NaN where
  a pixel is not fully covered by the object), each triplet scaled to sum 3
  as the calibrated maps' are (their ``normalisation``: the calibration
  measures only the colour's direction). The scale matters: the
  reconstruction divides each intensity by p, and the truth's own scale (the
  albedo's brightness) would take every brightness texture out of the images,
  leaving the depth search nothing to anchor the surface's depth to (right
  normals, a depth offset). ``--raw-truth`` adds ``bayes_full_true_raw``, the
  truth as the dataset holds it, to show that.

A variant is a reconstruction method (``bayes_ph`` or ``bayes_full``, the
calibration files ``generalisation.variant_files`` picks) and a map source, a
function ``(data, scene, files) -> {frame: chromaticity h5}`` (None: no map).
A tracked chromaticity is one more source: ``tracked_variant(track)`` with
``track(data, scene, files) -> {frame: h5 path}`` gives the variant
``bayes_dyn``; ``--tracked`` adds the workflow's (:func:`tracked_source`).
``--oracle`` adds it and three oracles that split its gap to ``bayes_full_true``:
the tracked map with the true p in its holes (``bayes_dyn_truth_in_holes``) and
with the true p where it has one, its holes kept (``bayes_dyn_truth_where_known``)
(:func:`with_truth`), and the calibrated map at each point's true position
(``bayes_dyn_true_positions``, :func:`with_true_positions`): a perfect tracking of
the calibration, which leaves its own error.

Figures per seed x scene x frame x variant (``benchmarks/results/
dynamic_chromaticity_seeds<TAG>.csv``, written after every seed): the
depth median of the absolute errors and the signed median (reconstructed
minus true z-depth, mm), RMS and p95 (mm), normal median (deg), coverage
(compared / ground-truth-visible pixels of the reference camera), the error
bar's calibration (``depth_sigma_median_mm``, ``sigma_within_1/2/3``: the share
of the compared pixels within k depth_sigma of the truth, as
``generalisation.py`` gives them), the shares of those pixels dropped per
reason (``dropped_no_chromaticity``: no p at the pixel, e.g. where the object
now is but was not in the chromatic pose), and
the chromaticity error of the map used against the frame's truth
(a reconstruction that raises is a frame with nothing reconstructed: coverage
0, the exception in ``error``):

- ``chroma_rms_log``: over the object's pixels (the truth finite and > 0 in
  every band) where the map is finite and > 0 in every band, pooled over the
  three cameras, the RMS over pixels and bands R, G, B of the difference of
  the centred log ratios, ``clr(p)_c = log p_c - (log p_R + log p_G + log p_B)
  / 3``, of the map and the truth. It does not depend on either map's overall
  scale (nor on a per-pixel scale: only the colour's direction counts, which is
  what the reconstruction sees); 0.1 is about a 10 % error of a band ratio.
- ``chroma_sigma_median``, ``chroma_sigma_within_1/2/3``: for a map with a 1-sigma
  of log p (:func:`colourhs.calibration.chromaticity.map_log_sigma`: the
  calibration's, or a tracked map's with the calibration's at its position), its median
  and the shares of the pixels' and bands' centred log ratio differences above within
  1, 2 and 3 of it: the
  chromaticity's error bar against the truth, as ``sigma_within_k`` is the depth's.
- ``chroma_known``: the share of the object's pixels (as above) where the map
  has a p at all.
- ``track_position_px`` (median), ``track_position_p90_px``: for a tracked map,
  how far each pixel's tracked position in the chromatic frame is from its point's
  true one (:func:`colourhs.evaluation.tracking_errors.true_positions`, from the
  ground-truth meshes, which share one triangulation), pooled over the cameras'
  pixels with both, pixels; ``track_motion_px``: the median true motion since the
  chromatic frame, pixels, and ``track_position_known``: the share of the pixels
  with a true position that have a tracked one (with or without a p: a point the
  colour did not confirm keeps the flow's position). A p can be right with a wrong
  position (inside a uniform patch), so this is the tracking's own error.
- ``chroma_floor_rms_log`` (per frame, the same in every variant's row): the
  chromatic frame's truth carried to the frame by the true positions, against the
  frame's truth (:func:`chroma_floor`): what carrying any map on the pixel grid
  costs at patch edges with no tracking or calibration error, the floor of a tracked
  map's ``chroma_rms_log``.
- With ``--noise-free`` (:func:`noise_free_maps`): the chromatic captures are
  rendered again with the sensor noise alone off (same seed, rig, cross-talk,
  filters and everything else) and calibrated as the noisy ones are: the map
  eq. (12) gives without sensor noise. Carried to each frame by the true
  positions (:func:`noise_free_error`), it is what a map's error bar claims to
  cover, where the truth also holds eq. (12)'s own model error (a white specular
  lobe in the chromatic pose, which the albedo truth does not have):
  ``chroma_nf_rms_log`` (``chroma_rms_log`` against it) and
  ``chroma_nf_within_1/2/3`` (as ``chroma_sigma_within_k``) per map, and
  ``nf_model_rms_log`` per frame (:func:`carried_error`), the carried noise-free
  map against the frame's truth (eq. (12)'s definition plus carrying on the pixel
  grid: no tracking, no noise).

The summary (``dynamic_chromaticity_summary<TAG>.md`` / ``.json``) gives per
scene x variant and metric the median over seeds and the worst seed of the
per-frame figure on the chromatic frame and, per seed, the median over the
moved frames (every other frame) and their worst frame; and per frame the
median over seeds and the worst seed. With a tracked map, it counts the frames and
scenes that meet the bounds a tracked chromaticity is judged by
(:func:`tracking_targets`: the chroma drift to the last frame, the depth drift from
the chromatic frame, the gain over the static map), beside the true map's own drift
and gain over the static map (the bounds of any chromaticity, however it is found)
and the tracked map's depth against the true map's on the same frame, pooled and per
scene. Run times per seed (render, calibration, reconstruction) are in both.

A tiny preset (160x120) takes minutes per seed on 2 cores; ``random-dynamic``
(640x480) far longer: score fewer frames with ``--evaluate`` (``--frames`` renders
fewer, and a tracked map then crosses each gap in one step).
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE))

from generalisation import calibrate, evaluate_variant, figure, seeds_in_temp  # noqa: E402

#: A map source: (dataset, scene, calibration files by name) -> {frame: chromaticity h5};
#: its frames those of the scene that it has a map for.
MapSource = Callable[[Path, str, dict], dict[str, Path]]


@dataclass(frozen=True)
class Variant:
    """One reconstruction variant of this benchmark.

    Attributes
    ----------
    name : the rows' ``variant``.
    method : the calibration files' variant (``generalisation.variant_files``):
        ``bayes_ph`` (no chromaticity) or ``bayes_full``.
    source : where each frame's chromaticity map comes from (:data:`MapSource`);
        None without one.
    """

    name: str
    method: str
    source: MapSource | None = None


def _chromatic_object(data: Path, scene: str) -> str:
    from colourhs.capture import open_dataset

    obj = open_dataset(data, check_images=False).scenes[scene].chromatic
    if obj is None:
        raise ValueError(f"{scene}: not a chromatic scene")
    return obj


def static_source(data: Path, scene: str, files: dict) -> dict[str, Path]:
    """The map calibrated from the chromatic captures (``files['chroma/<object>']``) on
    every frame of the scene: the paper's method, what the workflow does."""
    from colourhs.capture import open_dataset

    sc = open_dataset(data, check_images=False).scenes[scene]
    path = files[f"chroma/{_chromatic_object(data, scene)}"]
    return dict.fromkeys(sc.frames, path)


def true_raw_source(data: Path, scene: str, files: dict) -> dict[str, Path]:
    """Each frame's true chromaticity as the dataset holds it,
    ``scenes/<scene>/gt/chromaticity/<frame>.h5`` (relative to white)."""
    folder = data / "scenes" / scene / "gt" / "chromaticity"
    return {p.stem: p for p in sorted(folder.glob("*.h5"))}


def true_source(data: Path, scene: str, files: dict) -> dict[str, Path]:
    """Each frame's true chromaticity normalised as the calibrated maps are (every
    triplet scaled to sum 3, :func:`colourhs.calibration.chromaticity.normalise`),
    written beside the calibration files (``true_chromaticity/<scene>/<frame>.h5``)."""
    import h5py

    from colourhs.calibration.chromaticity import NORMALISATION, normalise

    out = Path(files["photometric"]).parent / "true_chromaticity" / scene
    out.mkdir(parents=True, exist_ok=True)
    maps = {}
    for frame, src in true_raw_source(data, scene, files).items():
        maps[frame] = out / f"{frame}.h5"
        with h5py.File(src) as f, h5py.File(maps[frame], "w") as g:
            g.attrs["normalisation"] = NORMALISATION
            for cam in f:
                g.create_dataset(cam, data=normalise(f[cam][()]).astype(np.float32))
    return maps


def tracked_source(data: Path, scene: str, files: dict) -> dict[str, Path]:
    """The workflow's ``bayes_dyn`` maps: the calibrated map carried through the sequence
    (:func:`colourhs.calibration.chromaticity_tracking.track_sequence`), written beside
    the calibration files (``tracked_chromaticity/<scene>/<frame>.h5``)."""
    from colourhs.calibration.chromaticity_tracking import track_sequence

    out = Path(files["photometric"]).parent / "tracked_chromaticity" / scene
    return track_sequence(data, scene, files[f"chroma/{_chromatic_object(data, scene)}"], out)


def once_per_scene(source: MapSource) -> MapSource:
    """``source``, run once per dataset and scene: later calls return the first call's
    maps (the variants that build on one tracking share it)."""
    done: dict[tuple[str, str], dict[str, Path]] = {}

    def source_once(data: Path, scene: str, files: dict) -> dict[str, Path]:
        key = (str(data), scene)
        if key not in done:
            done[key] = source(data, scene, files)
        return done[key]

    return source_once


def put_truth(tracked_h5: Path, truth_h5: Path, out_h5: Path, part: str) -> Path:
    """A tracked map (:func:`tracked_source`) with the true p of its frame (as
    :func:`true_source` writes it) in one part of each camera's map: ``"holes"``, the
    pixels where the tracking left no p, or ``"known"``, those where it has one (in
    either, only where the truth has a p: the object covers the pixel). The rest,
    the tracking's sigma and the attributes (a moved frame stays one: the
    reconstruction's fill and borrowed p act as on the tracked map) are the tracked
    map's; written to ``out_h5``."""
    import h5py

    if part not in ("holes", "known"):
        raise ValueError(f"part {part!r}: 'holes' or 'known'")
    out_h5.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(tracked_h5, out_h5)
    with h5py.File(out_h5, "a") as f, h5py.File(truth_h5) as t:
        for cam in t:
            p, truth = f[cam][()], t[cam][()]
            hole = ~np.isfinite(p).all(axis=-1)
            where = (hole if part == "holes" else ~hole) & np.isfinite(truth).all(axis=-1)
            p[where] = truth[where]
            f[cam][...] = p
    return out_h5


def with_truth(track: MapSource, part: str) -> MapSource:
    """The maps of ``track`` with each frame's true p in one ``part`` of them
    (:func:`put_truth`), written beside the calibration files
    (``tracked_with_truth_<part>/<scene>/<frame>.h5``): an oracle that splits the
    gap between a tracked map and the true one (``bayes_full_true``) into what its
    holes cost and what its wrong p cost."""

    def source(data: Path, scene: str, files: dict) -> dict[str, Path]:
        truth = true_source(data, scene, files)
        out = Path(files["photometric"]).parent / f"tracked_with_truth_{part}" / scene
        return {
            frame: put_truth(h5, truth[frame], out / f"{frame}.h5", part)
            for frame, h5 in track(data, scene, files).items()
        }

    return source


def at_true_positions(tracked_h5: Path, calibrated_h5: Path, truth: dict, out_h5: Path) -> Path:
    """A tracked map (:func:`tracked_source`) whose points are where they truly are: per
    camera the position its true one (``truth``: camera -> (H, W, 2),
    :func:`true_position_maps`), p the calibrated map's there (as the tracking samples
    it, :func:`colourhs.calibration.chromaticity_tracking.sample_at`), the tracking's
    sigma 0 where that p is known (NaN elsewhere) and ``p_sigma`` the calibrated map's
    error bar there, with the nearest sampling's position error, where it has one
    (``tracked_log_sigma``); the attributes the
    tracked map's (a moved frame stays one); written to ``out_h5``. An oracle: the best
    any carry of the calibrated map can do, so what it misses against ``bayes_full_true``
    is the calibration's own error, carried to a pose where it no longer fits."""
    import h5py

    from colourhs.calibration.chromaticity_tracking import (
        TrackedMap,
        sample_at,
        tracked_log_sigma,
    )

    out_h5.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(tracked_h5, out_h5)
    with h5py.File(out_h5, "a") as f, h5py.File(calibrated_h5) as g:
        for cam, position in truth.items():
            p = sample_at(g[cam][()], position)
            zero = np.where(np.all(np.isfinite(p), axis=-1), 0.0, np.nan).astype(np.float32)
            m = TrackedMap(p, position.astype(np.float32), zero, zero)
            f[cam][...] = m.p
            for key in ("position", "position_sigma", "sigma"):
                f[f"{key}/{cam}"][...] = getattr(m, key)
            if f"p_sigma/{cam}" in f and f"sigma/{cam}" in g:
                f[f"p_sigma/{cam}"][...] = tracked_log_sigma(g[cam][()], g[f"sigma/{cam}"][()], m)
    return out_h5


def with_true_positions(track: MapSource) -> MapSource:
    """The maps of ``track`` with every point where it truly is on the moved frames
    (:func:`at_true_positions`; the chromatic frame's map unchanged), written beside the
    calibration files (``tracked_at_true_positions/<scene>/<frame>.h5``): splits the gap
    between the tracked map and the true one into the tracking's error and the
    calibration's.

    Raises
    ------
    ValueError
        A scene whose ground-truth meshes share no triangulation (no true position).
    """
    from colourhs.capture import open_dataset

    def source(data: Path, scene: str, files: dict) -> dict[str, Path]:
        ds = open_dataset(data, check_images=False)
        sc = ds.scenes[scene]
        calibrated = files[f"chroma/{sc.chromatic}"]
        out = Path(files["photometric"]).parent / "tracked_at_true_positions" / scene
        maps = {}
        for frame, h5 in track(data, scene, files).items():
            if frame == sc.chromatic_frame:
                maps[frame] = h5
                continue
            truth = true_position_maps(data, scene, frame, sc.chromatic_frame, ds.rig)
            if truth is None:
                raise ValueError(f"{scene}/{frame}: the meshes share no triangulation")
            maps[frame] = at_true_positions(h5, calibrated, truth, out / f"{frame}.h5")
        return maps

    return source


def tracked_variant(track: MapSource, name: str = "bayes_dyn") -> Variant:
    """The variant of a tracked chromaticity: ``track(data, scene, files) -> {frame: h5}``."""
    return Variant(name, "bayes_full", track)


#: The variants, in the tables' order.
VARIANTS = (
    Variant("bayes_ph", "bayes_ph"),
    Variant("bayes_full_static", "bayes_full", static_source),
    Variant("bayes_full_true", "bayes_full", true_source),
)
#: ``--raw-truth``: the true chromaticity as the dataset holds it, not normalised.
RAW_TRUTH = Variant("bayes_full_true_raw", "bayes_full", true_raw_source)


def oracle_variants(track: MapSource) -> tuple[Variant, ...]:
    """``--oracle``: ``bayes_dyn_truth_in_holes`` and ``bayes_dyn_truth_where_known``,
    the tracked map of ``track`` with the true p in its holes or where it has a p
    (:func:`with_truth`), and ``bayes_dyn_true_positions``, the calibrated map at each
    point's true position (:func:`with_true_positions`)."""
    return (
        Variant("bayes_dyn_truth_in_holes", "bayes_full", with_truth(track, "holes")),
        Variant("bayes_dyn_truth_where_known", "bayes_full", with_truth(track, "known")),
        Variant("bayes_dyn_true_positions", "bayes_full", with_true_positions(track)),
    )


#: The chromaticity map's own error bar against the truth (:func:`chroma_sigma_error`).
CHROMA_SIGMA_COLUMNS = (
    "chroma_sigma_median",
    "chroma_sigma_within_1",
    "chroma_sigma_within_2",
    "chroma_sigma_within_3",
)


def chroma_sigma_error(p: np.ndarray, truth: np.ndarray, sigma: np.ndarray) -> dict:
    """:data:`CHROMA_SIGMA_COLUMNS` of a map ``p`` (..., 3) whose 1-sigma of log p is
    ``sigma`` (..., 3) per band (or (...), the same in each), against ``truth`` (..., 3)
    (:func:`colourhs.calibration.chromaticity.log_sigma_coverage`); None where no pixel
    has all three."""
    from colourhs.calibration.chromaticity import log_sigma_coverage

    cover = log_sigma_coverage(p, truth, sigma)
    if cover is None:
        return dict.fromkeys(CHROMA_SIGMA_COLUMNS)
    median, within = cover
    return {
        "chroma_sigma_median": median,
        **{f"chroma_sigma_within_{k}": w for k, w in zip((1, 2, 3), within, strict=True)},
    }


def map_with_sigma(map_h5: Path, cameras) -> tuple[np.ndarray, np.ndarray | None]:
    """A map's p of ``cameras`` side by side (:func:`carried`, as it is) and its 1-sigma of
    log p the same way (:func:`colourhs.calibration.chromaticity.map_log_sigma`; None
    where a camera has none)."""
    import h5py

    from colourhs.calibration.chromaticity import map_log_sigma

    with h5py.File(map_h5) as f:
        sigmas = [map_log_sigma(f, cam) for cam in cameras]
    if any(s is None for s in sigmas):
        return carried(map_h5, None, cameras), None
    return carried(map_h5, None, cameras), np.concatenate([np.asarray(s, float) for s in sigmas])


def chroma_error(map_h5: Path, truth_h5: Path, cameras) -> dict:
    """``chroma_rms_log`` (:func:`colourhs.calibration.chromaticity.log_ratio_rms` of the
    cameras' maps side by side) and ``chroma_known`` of a map against a frame's truth
    (module docstring), pooled over ``cameras``; None where the object has no pixel.
    A map with a 1-sigma of log p (:func:`map_with_sigma`) also gets
    :func:`chroma_sigma_error`'s columns (None without)."""
    from colourhs.calibration.chromaticity import log_ratio_rms

    t = carried(truth_h5, None, cameras)
    p, sig = map_with_sigma(map_h5, cameras)
    on = np.all(np.isfinite(t) & (t > 0), axis=-1)
    known = on & np.all(np.isfinite(p) & (p > 0), axis=-1)
    out = {
        "chroma_rms_log": log_ratio_rms(p, t) if known.any() else None,
        "chroma_known": float(known.sum() / on.sum()) if on.any() else None,
    }
    if sig is None:
        return out | dict.fromkeys(CHROMA_SIGMA_COLUMNS)
    return out | chroma_sigma_error(p, t, sig)


#: The tracking's position columns (:func:`position_error`), None where not measured.
POSITION_COLUMNS = (
    "track_position_px",
    "track_position_p90_px",
    "track_motion_px",
    "track_position_known",
)


def true_position_maps(data: Path, scene: str, frame: str, chromatic: str, rig) -> dict | None:
    """Each camera's true positions of a frame's pixels in the chromatic frame (camera ->
    (H, W, 2), :func:`colourhs.evaluation.tracking_errors.true_positions`) from the
    scene's ground-truth meshes; None where the meshes share no triangulation."""
    from colourhs.common.ply import load_mesh
    from colourhs.evaluation.tracking_errors import same_triangulation, true_positions

    gt = data / "scenes" / scene / "gt"
    now, then = load_mesh(gt / f"{frame}.ply"), load_mesh(gt / f"{chromatic}.ply")
    if not same_triangulation(now, then):
        return None
    w, h = rig.image.width, rig.image.height
    return {c: true_positions(now, then, rig.camera(c), w, h) for c in rig.camera_names}


def position_error(map_h5: Path, truth: dict | None, cameras) -> dict:
    """:data:`POSITION_COLUMNS` of a tracked map (one with ``position/<camera>``) against
    the true positions (``truth``, :func:`true_position_maps`), pooled over ``cameras``;
    None where the map has no positions or there are no true ones (``truth`` None)."""
    import h5py

    from colourhs.evaluation.tracking_errors import position_summary

    with h5py.File(map_h5) as f:
        if "position" not in f or truth is None:
            return dict.fromkeys(POSITION_COLUMNS)
        pos = np.stack([f[f"position/{cam}"][()] for cam in cameras])
    s = position_summary(pos, np.stack([truth[c] for c in cameras]))
    return {
        "track_position_px": s["position_median_px"],
        "track_position_p90_px": s["position_p90_px"],
        "track_motion_px": s["motion_median_px"],
        "track_position_known": s["position_known"],
    }


def carried(map_h5: Path, positions: dict | None, cameras) -> np.ndarray:
    """A file's maps of ``cameras`` side by side (float), each carried by the true
    positions (``positions``, :func:`true_position_maps`) as a tracking samples the
    calibrated map (:func:`colourhs.calibration.chromaticity_tracking.sample_at`);
    ``positions`` None: as they are (the chromatic frame)."""
    import h5py

    from colourhs.calibration.chromaticity_tracking import sample_at

    with h5py.File(map_h5) as f:
        maps = [
            f[c][()] if positions is None else sample_at(f[c][()], positions[c]) for c in cameras
        ]
    return np.concatenate([np.asarray(m, float) for m in maps])


def carried_error(
    source_h5: Path, truth_h5: Path, positions: dict | None, home: bool, cameras
) -> float | None:
    """``chroma_rms_log`` of ``source_h5``'s maps carried to a frame (:func:`carried`; on
    the chromatic frame, ``home``, as they are) against the frame's truth, pooled over
    ``cameras``; None without true positions on a moved frame, or where no pixel has
    both."""
    import h5py

    from colourhs.calibration.chromaticity import log_ratio_rms

    if not home and positions is None:
        return None
    with h5py.File(truth_h5) as t:
        true = np.concatenate([t[c][()] for c in cameras])
    rms = log_ratio_rms(carried(source_h5, None if home else positions, cameras), true)
    return rms if np.isfinite(rms) else None


def chroma_floor(
    data: Path, scene: str, frame: str, chromatic: str, truth: dict | None, cameras
) -> float | None:
    """``chroma_floor_rms_log``: the chromatic frame's true chromaticity carried to the
    frame by the true positions (``truth``, :func:`carried_error`) against the frame's
    truth: what carrying a map on the pixel grid costs with neither a tracking nor a
    calibration error (a pixel whose point lies within half a pixel of a patch edge in
    the chromatic frame takes the other patch's p), the floor of any carried map's
    error. 0 on the chromatic frame; None without true positions (``truth`` None)."""
    if frame == chromatic:
        return 0.0
    folder = data / "scenes" / scene / "gt" / "chromaticity"
    return carried_error(folder / f"{chromatic}.h5", folder / f"{frame}.h5", truth, False, cameras)


#: A map against the noise-free map carried by the true motion (:func:`noise_free_error`).
NOISE_FREE_COLUMNS = (
    "chroma_nf_rms_log",
    "chroma_nf_within_1",
    "chroma_nf_within_2",
    "chroma_nf_within_3",
)


def noise_free_maps(data: Path, preset: str, seed: int, root: Path, objects) -> dict[str, Path]:
    """The chromaticity maps eq. (12) gives without sensor noise: the chromatic captures
    of ``objects`` (chromatic objects of ``data``, rendered from ``preset`` and ``seed``)
    rendered again with only the noise off
    (:func:`colourhs.synth.synthesise.noise_free_chromatic`, under ``root``) and
    calibrated as the noisy ones are (no noise model: nothing to propagate); object ->
    ``root / "calib" / "noise_free_<object>.h5"``."""
    from colourhs.calibration.chromaticity import chromaticity_maps
    from colourhs.capture import open_dataset
    from colourhs.synth.synthesise import noise_free_chromatic

    ds = open_dataset(data, check_images=False)
    scenes = tuple(n for n, sc in ds.scenes.items() if sc.chromatic in objects)
    noise_free = noise_free_chromatic(data, root / "noise_free", preset, seed, scenes)
    maps = {}
    for obj in objects:
        maps[obj] = root / "calib" / f"noise_free_{obj}.h5"
        chromaticity_maps(noise_free, obj, maps[obj])
    return maps


def noise_free_error(
    map_h5: Path, noise_free_h5: Path, positions: dict | None, home: bool, cameras
) -> dict:
    """:data:`NOISE_FREE_COLUMNS` of a map against the noise-free map
    (:func:`noise_free_maps`) carried to its frame by the true positions (``positions``,
    :func:`carried`; on the chromatic frame, ``home``, the noise-free map itself),
    pooled over ``cameras``: the error the map's own 1-sigma of log p
    (:func:`colourhs.calibration.chromaticity.map_log_sigma`) claims to cover, its
    calibration's sensor noise and its tracking's error, with eq. (12)'s model error
    taken out (``nf_model_rms_log``: :func:`carried_error` of the noise-free map). None
    where there is nothing to compare (a moved frame without true positions, a map
    without an error bar for the shares)."""
    from colourhs.calibration.chromaticity import log_ratio_rms

    if not home and positions is None:
        return dict.fromkeys(NOISE_FREE_COLUMNS)
    ref = carried(noise_free_h5, None if home else positions, cameras)
    p, sig = map_with_sigma(map_h5, cameras)
    rms = log_ratio_rms(p, ref)
    out = {"chroma_nf_rms_log": rms if np.isfinite(rms) else None}
    cover = None if sig is None else chroma_sigma_error(p, ref, sig)
    for k in (1, 2, 3):
        out[f"chroma_nf_within_{k}"] = None if cover is None else cover[f"chroma_sigma_within_{k}"]
    return out


def evaluate_frame(data, scene, frame, variant: Variant, files, chromatic, map_h5, work) -> dict:
    """One frame of one scene x variant (``generalisation.evaluate_variant`` on that frame,
    with ``map_h5`` as the object's chromaticity map where there is one)."""
    f = dict(files)
    if map_h5 is not None:
        f[f"chroma/{chromatic}"] = Path(map_h5)
    return evaluate_variant(data, scene, [frame], variant.method, f, chromatic, work / variant.name)


def failed_frame(exc: Exception, seconds: float) -> dict:
    """A frame whose reconstruction raised: nothing reconstructed (coverage 0, no depth
    figures), the exception in ``error``."""
    print(f"reconstruction failed: {exc!r}", flush=True)
    return {"coverage": 0.0, "seconds": seconds, "error": f"{type(exc).__name__}: {exc}"}


def _line(m: dict) -> str:
    """One scene x frame x variant's figures as a progress line (``-`` where none)."""

    def f(key, fmt):
        return figure(m, key, fmt)

    return (
        f"depth {f('depth_median_mm', '.3f')} mm (signed {f('depth_signed_median_mm', '+.3f')}) "
        f"normal {f('normal_median_deg', '.2f')} deg coverage {f('coverage', '.3f')} "
        f"chroma {f('chroma_rms_log', '.3f')} ({m['seconds']:.0f} s)"
    )


def select_frames(spec: str | None) -> tuple[int, ...] | None:
    """Frame indices from ``"0-11/2"`` (every 2nd of 0-11), ``"0,3,5-7"``; None: all."""
    if spec is None:
        return None
    out = set()
    for item in spec.split(","):
        span, _, step = item.strip().partition("/")
        first, sep, last = span.partition("-")
        if not first.isdigit() or (sep and not last.isdigit()) or (step and not step.isdigit()):
            raise argparse.ArgumentTypeError(f"frames {spec!r}: expected A-B/STEP, A-B or A")
        out.update(range(int(first), int(last if sep else first) + 1, int(step or 1)))
    return tuple(sorted(out))


def run_seed(
    seed: int,
    preset: str,
    root: Path,
    frames: tuple[int, ...] | None = None,
    variants=VARIANTS,
    keep: Path | None = None,
    evaluate: tuple[int, ...] | None = None,
    noise_free: bool = False,
) -> list[dict]:
    """One seed of ``preset``: render (no geometric captures; ``frames``: only those),
    calibrate, then every frame of every dynamic chromatic sequence (``evaluate``: only
    those indices and the chromatic frame; a tracked map still follows every rendered
    frame) with each variant; rows. ``noise_free``: also each map against the noise-free
    map (:func:`noise_free_maps`, :data:`NOISE_FREE_COLUMNS`, ``nf_model_rms_log``)."""
    from colourhs.capture import open_dataset
    from colourhs.synth.synthesise import RenderSelection, synthesise

    t0 = time.time()
    selection = RenderSelection(parts=("photometric", "chromatic", "scenes"), frames=frames)
    data = synthesise(root / "data", preset, seed=seed, selection=selection)
    t_render = time.time() - t0
    t0 = time.time()
    files = calibrate(data, root / "calib")
    t_calib = time.time() - t0
    ds = open_dataset(data, check_images=False)
    cameras = ds.rig.camera_names
    if noise_free:
        objects = sorted({sc.chromatic for sc in ds.scenes.values() if sc.dynamic and sc.chromatic})
        t0 = time.time()
        nf = noise_free_maps(data, preset, seed, root, objects)
        t_calib += time.time() - t0
    rows = []
    t0 = time.time()
    for scene, sc in ds.scenes.items():
        if not (sc.dynamic and sc.chromatic):
            continue
        maps = {v.name: v.source(data, scene, files) for v in variants if v.source is not None}
        chroma_index = sc.frames.index(sc.chromatic_frame)
        for i, frame in enumerate(sc.frames):
            if evaluate is not None and int(frame) not in evaluate and i != chroma_index:
                continue
            truth = data / "scenes" / scene / "gt" / "chromaticity" / f"{frame}.h5"
            # the true positions once per frame, for the floor and every map's position error
            positions = true_position_maps(data, scene, frame, sc.chromatic_frame, ds.rig)
            floor = chroma_floor(data, scene, frame, sc.chromatic_frame, positions, cameras)
            home = i == chroma_index
            nf_model = None
            if noise_free:
                nf_model = carried_error(nf[sc.chromatic], truth, positions, home, cameras)
            for v in variants:
                map_h5 = None if v.source is None else maps[v.name].get(frame)
                if v.source is not None and map_h5 is None:
                    raise ValueError(f"{v.name}: no chromaticity map of {scene} frame {frame}")
                t1 = time.time()
                try:
                    m = evaluate_frame(
                        data, scene, frame, v, files, sc.chromatic, map_h5, root / "w"
                    )
                except Exception as exc:  # a pipeline failure is a frame lost, not a lost seed
                    m = failed_frame(exc, time.time() - t1)
                err = {"chroma_rms_log": None, "chroma_known": None}
                err |= dict.fromkeys(CHROMA_SIGMA_COLUMNS)
                err |= dict.fromkeys(POSITION_COLUMNS)
                err |= dict.fromkeys(NOISE_FREE_COLUMNS) if noise_free else {}
                if map_h5 is not None:
                    err |= chroma_error(Path(map_h5), truth, cameras)
                    err |= position_error(Path(map_h5), positions, cameras)
                    if noise_free:
                        nf_h5 = nf[sc.chromatic]
                        err |= noise_free_error(Path(map_h5), nf_h5, positions, home, cameras)
                rows.append(
                    {
                        "preset": preset,
                        "seed": seed,
                        "scene": scene,
                        "frame": int(frame),
                        "chromatic_frame": int(sc.chromatic_frame),
                        "frames_from_chromatic": i - chroma_index,
                        "variant": v.name,
                        **m,
                        **err,
                        "chroma_floor_rms_log": floor,
                        **({"nf_model_rms_log": nf_model} if noise_free else {}),
                    }
                )
                print(f"seed {seed} {scene:13s} {frame} {v.name:18s} {_line(rows[-1])}", flush=True)
    t_rec = time.time() - t0
    for r in rows:
        r |= {"render_s": t_render, "calib_s": t_calib, "reconstruct_s": t_rec}
    print(
        f"seed {seed}: render {t_render:.0f} s, calibration {t_calib:.0f} s, "
        f"reconstruction and evaluation {t_rec:.0f} s",
        flush=True,
    )
    if keep is not None:
        shutil.copytree(root, keep / f"seed{seed}", dirs_exist_ok=True)
    return rows


#: Summarised metrics: (column, heading, format, how the worst is picked).
METRICS = (
    ("depth_median_mm", "depth median (mm)", ".3f", "max"),
    ("depth_signed_median_mm", "signed median (mm)", "+.3f", "abs"),
    ("normal_median_deg", "normal median (deg)", ".2f", "max"),
    ("coverage", "coverage", ".3f", "min"),
    ("depth_sigma_median_mm", "sigma median (mm)", ".3f", "max"),
    ("sigma_within_3", "within 3 sigma", ".2f", "min"),
    ("dropped_no_chromaticity", "dropped: no p", ".3f", "max"),
    ("chroma_rms_log", "chroma RMS log", ".3f", "max"),
    ("chroma_known", "chroma known", ".3f", "min"),
    ("chroma_floor_rms_log", "chroma floor RMS log", ".3f", "max"),
    ("chroma_sigma_within_3", "chroma within 3 sigma", ".2f", "min"),
    ("chroma_nf_rms_log", "chroma RMS log vs noise-free map", ".3f", "max"),
    ("chroma_nf_within_1", "within 1 sigma of noise-free map", ".2f", "min"),
    ("chroma_nf_within_3", "within 3 sigma of noise-free map", ".2f", "min"),
    ("nf_model_rms_log", "noise-free map's model RMS log", ".3f", "max"),
    ("track_position_px", "position error (px)", ".2f", "max"),
    ("track_motion_px", "motion (px)", ".1f", "max"),
)


def _worst(values: np.ndarray, how: str) -> float:
    if how == "min":
        return float(values.min())
    if how == "abs":
        return float(values[np.argmax(np.abs(values))])
    return float(values.max())


def _entry(values, how: str) -> dict | None:
    """Median and worst (``how``) of the finite values, and how many; None without."""
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    if not v.size:
        return None
    return {"median": float(np.median(v)), "worst": _worst(v, how), "seeds": int(v.size)}


def summarise(table: pd.DataFrame) -> dict:
    """Per scene x variant and metric: ``chromatic_frame`` (over seeds: the chromatic
    frame's figure), ``moved`` (over seeds: each seed's median over the other frames),
    ``moved_worst_frame`` (over seeds: each seed's worst other frame) and ``per_frame``
    (frame -> over seeds), ``empty_frames`` (``seed/frame`` with nothing reconstructed);
    ``seconds`` per seed; ``targets`` (:func:`tracking_targets` of ``bayes_dyn``) and
    ``oracle_targets`` (variant -> how many of the bounds but :data:`SHARED_BOUNDS` each
    ``bayes_dyn_*`` oracle meets as the tracked variant)."""
    out = {
        "presets": sorted(table["preset"].unique()),
        "seeds": sorted(int(s) for s in table["seed"].unique()),
        "variants": list(dict.fromkeys(table["variant"])),
        "scenes": {},
        "seconds": {},
    }
    for seed, g in table.groupby("seed"):
        out["seconds"][str(seed)] = {
            k: float(g[k].iloc[0]) for k in ("render_s", "calib_s", "reconstruct_s")
        }
    for (scene, variant), g in table.groupby(["scene", "variant"], sort=False):
        entry = {"chromatic_frame": {}, "moved": {}, "moved_worst_frame": {}, "per_frame": {}}
        home = g[g["frame"] == g["chromatic_frame"]]
        moved = g[g["frame"] != g["chromatic_frame"]]
        for col, _, _, how in METRICS:
            if col not in g or not g[col].notna().any():
                continue
            entry["chromatic_frame"][col] = _entry(home[col].astype(float), how)
            med, worst = [], []
            for _, s in moved.groupby("seed")[col]:
                v = s.astype(float).dropna().to_numpy()
                med.append(float(np.median(v)) if v.size else np.nan)
                worst.append(_worst(v, how) if v.size else np.nan)
            entry["moved"][col] = _entry(med, how)
            entry["moved_worst_frame"][col] = _entry(worst, how)
            for frame, f in g.groupby("frame"):
                entry["per_frame"].setdefault(str(frame), {})[col] = _entry(f[col], how)
        empty = g[~np.isfinite(g["depth_median_mm"].astype(float))]
        entry["empty_frames"] = [f"{int(r.seed)}/{int(r.frame):06d}" for r in empty.itertuples()]
        out["scenes"].setdefault(scene, {})[variant] = entry
    out["targets"] = tracking_targets(table)
    out["oracle_targets"] = {
        v: {k: n for k, n in tracking_targets(table, v)["met"].items() if k not in SHARED_BOUNDS}
        for v in out["variants"]
        if v.startswith("bayes_dyn_")
    }
    return out


#: The bounds a tracked chromaticity is judged by on a moving coloured sequence: its
#: chromaticity error in the last frame against the chromatic frame's, ``bayes_dyn``'s
#: depth on every moved frame against its chromatic frame's, and ``bayes_full`` with the
#: static map against ``bayes_dyn`` on the moved frames (a gain).
CHROMA_DRIFT_BOUND = 1.5
DEPTH_DRIFT_BOUND = 1.5
STATIC_GAIN_BOUND = 3.0
"""Why these bounds hold on any rig: each is a ratio of one figure to the same figure
of the same rig and scene (its chromatic frame, or another map on the same frame), so
the rig's own accuracy divides out; the values are the targets the tracking is set."""


#: The bounds that judge the scene, not the tracked map (:func:`tracking_targets`): the
#: carried truth's chroma drift and the true map's depth drift and gain over the static
#: map, left out of an oracle's counts (``oracle_targets``).
SHARED_BOUNDS = ("floor_drift", "true_depth_drift", "true_static_gain")


def _ratio(a, b) -> float | None:
    """``a / b`` as a float; None where either is missing or ``b`` is not positive."""
    a, b = float(a), float(b)
    return a / b if np.isfinite(a) and np.isfinite(b) and b > 0 else None


def _verdict(value: float | None, ok) -> bool | None:
    """``ok(value)``; None (no verdict) where the value is missing."""
    return None if value is None else bool(ok(value))


def _count(verdicts: list) -> dict:
    """How many verdicts are met (``met``) of those given (``of``; None is none)."""
    have = [v for v in verdicts if v is not None]
    return {"met": sum(have), "of": len(have)}


def _gains(static: float, depth: float) -> bool:
    """Whether the static map's depth median ``static`` is at least
    :data:`STATIC_GAIN_BOUND` times ``depth``."""
    return static >= STATIC_GAIN_BOUND * depth


def _against(dyn: float, other: float, ran: bool, ok, empty_meets: bool) -> bool | None:
    """Whether the tracked variant's depth median ``dyn`` meets ``ok(other, dyn)`` against
    another variant's ``other`` on one frame: no verdict where the other did not run (or
    reconstructed nothing, unless ``empty_meets``); a tracked variant that reconstructed
    nothing misses."""
    if not ran or (not np.isfinite(other) and not empty_meets):
        return None
    if not np.isfinite(dyn):
        return False
    return True if not np.isfinite(other) else bool(ok(other, dyn))


def tracking_targets(table: pd.DataFrame, tracked: str = "bayes_dyn") -> dict:
    """The bounds above, per preset x seed x scene with a ``tracked`` variant, and how
    many meet them.

    Per preset x seed x scene (``scenes``): ``chroma_drift``, the tracked map's
    ``chroma_rms_log`` in the scene's last scored frame over the chromatic frame's, and
    ``floor_drift``, that frame's ``chroma_floor_rms_log`` over the same (the bound of
    any carried map: the truth carried by the true motion, :func:`chroma_floor`). Per
    moved frame (``frames``): ``depth_drift``, the tracked variant's depth median over its
    chromatic frame's; ``static_gain``, ``bayes_full_static``'s over the tracked
    variant's; for the true chromaticity (``bayes_full_true``), the bounds of any
    tracking, ``true_depth_drift`` (its own drift) and ``true_static_gain``
    (``bayes_full_static``'s over the true map's: the most any chromaticity gains), and
    ``tracked_over_true`` (the tracked variant's depth median over the true map's on the
    same frame); None where a figure is missing; ``static_empty`` and ``true_empty``
    where that map ran and reconstructed nothing. ``met``: per bound, how many meet it
    of how many are judged: a frame the tracked variant (or, for the true map's own
    bounds, the true map) reconstructs nothing of misses every depth bound, a static
    map that reconstructs nothing is a gain, and a frame without the other variant (or
    where the true map reconstructs nothing) is not judged against it. ``met_by_scene``:
    the same counts per scene. Empty where the table has no ``tracked`` rows.
    """
    out = {"scenes": [], "frames": [], "met": {}, "met_by_scene": {}}
    if "variant" not in table or not (table["variant"] == tracked).any():
        return out
    keys = ["preset", "seed", "scene", "frame", "variant"]
    depth = {
        tuple(k): float(v)
        for k, v in zip(table[keys].to_numpy(), table["depth_median_mm"], strict=True)
    }

    def at(key, frame, variant) -> float:
        return depth.get((*key, frame, variant), float("nan"))

    names = (
        "chroma_drift",
        "floor_drift",
        "depth_drift",
        "static_gain",
        "true_depth_drift",
        "true_static_gain",
        "tracked_within_true",
    )
    verdicts = {k: [] for k in names}
    by_scene: dict[str, dict[str, list]] = {}

    def judge(scene: str, name: str, verdict: bool | None) -> None:
        verdicts[name].append(verdict)
        by_scene.setdefault(scene, {k: [] for k in names})[name].append(verdict)

    rows = table[table["variant"] == tracked]
    for key, g in rows.groupby(["preset", "seed", "scene"]):
        home = int(g["chromatic_frame"].iloc[0])
        by_frame = g.set_index("frame")
        if home not in by_frame.index:
            continue
        preset, seed, scene = key
        last = int(by_frame.index.max())
        chroma = floor = None
        if "chroma_rms_log" in g:
            at_home = by_frame.at[home, "chroma_rms_log"]
            chroma = _ratio(by_frame.at[last, "chroma_rms_log"], at_home)
            if "chroma_floor_rms_log" in g:
                floor = _ratio(by_frame.at[last, "chroma_floor_rms_log"], at_home)
        head = {"preset": preset, "seed": int(seed), "scene": scene}
        out["scenes"].append(
            head | {"last_frame": last, "chroma_drift": chroma, "floor_drift": floor}
        )
        judge(scene, "chroma_drift", _verdict(chroma, lambda v: v <= CHROMA_DRIFT_BOUND))
        judge(scene, "floor_drift", _verdict(floor, lambda v: v <= CHROMA_DRIFT_BOUND))
        for frame in sorted(int(f) for f in by_frame.index if int(f) != home):
            dyn = at(key, frame, tracked)
            static, true = at(key, frame, "bayes_full_static"), at(key, frame, "bayes_full_true")
            ran_static = (*key, frame, "bayes_full_static") in depth
            ran_true = (*key, frame, "bayes_full_true") in depth
            r = head | {
                "frame": frame,
                "depth_drift": _ratio(dyn, at(key, home, tracked)),
                "static_gain": _ratio(static, dyn),
                "true_depth_drift": _ratio(true, at(key, home, "bayes_full_true")),
                "true_static_gain": _ratio(static, true),
                "tracked_over_true": _ratio(dyn, true),
                "static_empty": ran_static and not np.isfinite(static),
                "true_empty": ran_true and not np.isfinite(true),
            }
            out["frames"].append(r)
            drift = r["depth_drift"]
            judge(scene, "depth_drift", drift is not None and drift <= DEPTH_DRIFT_BOUND)
            judge(scene, "static_gain", _against(dyn, static, ran_static, _gains, True))
            judge(
                scene,
                "true_depth_drift",
                _verdict(r["true_depth_drift"], lambda v: v <= DEPTH_DRIFT_BOUND),
            )
            judge(
                scene,
                "true_static_gain",
                _against(true, static, ran_static, _gains, True) if ran_true else None,
            )
            judge(
                scene,
                "tracked_within_true",
                _against(dyn, true, ran_true, lambda o, d: d <= DEPTH_DRIFT_BOUND * o, False),
            )
    out["met"] = {k: _count(v) for k, v in verdicts.items()}
    out["met_by_scene"] = {
        scene: {k: _count(v) for k, v in vs.items()} for scene, vs in by_scene.items()
    }
    return out


def targets_markdown(targets: dict, others: dict | None = None) -> list[str]:
    """:func:`tracking_targets` as markdown lines: how many meet each bound, then the
    ratios per seed x scene and per moved frame; none without targets. ``others``
    (variant -> :func:`tracking_targets`' ``met`` for that variant as the tracked one:
    the oracles) adds a column each to the first table."""
    if not targets["scenes"]:
        return []
    mets = [targets["met"], *(others or {}).values()]

    def cell(key, unit):
        return " | ".join(
            f"{m[key]['met']} of {m[key]['of']} {unit}" if key in m else "-" for m in mets
        )

    def num(v):
        return "-" if v is None else f"{v:.2f}"

    lines = [
        "",
        "## Targets of the tracked chromaticity",
        "",
        "| bound | " + " | ".join(["met", *(others or {})]) + " |",
        "|---|" + "---|" * len(mets),
        f"| chroma RMS, last frame <= {CHROMA_DRIFT_BOUND}x the chromatic frame's "
        f"| {cell('chroma_drift', 'scenes')} |",
        f"| the truth carried by the true motion, last frame <= {CHROMA_DRIFT_BOUND}x the "
        f"chromatic frame's (any carry's bound) | {cell('floor_drift', 'scenes')} |",
        f"| depth median, each moved frame <= {DEPTH_DRIFT_BOUND}x the chromatic frame's "
        f"| {cell('depth_drift', 'frames')} |",
        f"| static map's depth median >= {STATIC_GAIN_BOUND}x the tracked one's "
        f"| {cell('static_gain', 'frames')} |",
        f"| the true map's own depth drift <= {DEPTH_DRIFT_BOUND}x (any tracking's bound) "
        f"| {cell('true_depth_drift', 'frames')} |",
        f"| static map's depth median >= {STATIC_GAIN_BOUND}x the true map's (any "
        f"chromaticity's bound) | {cell('true_static_gain', 'frames')} |",
        f"| tracked depth median <= {DEPTH_DRIFT_BOUND}x the true map's on the same frame "
        f"| {cell('tracked_within_true', 'frames')} |",
    ]
    lines += _by_scene_lines(targets.get("met_by_scene") or {})
    lines += [
        "",
        "| preset | seed | scene | last frame | chroma drift | carried truth's drift |",
        "|---|---|---|---|---|---|",
    ]
    lines += [
        f"| {r['preset']} | {r['seed']} | {r['scene']} | {r['last_frame']:06d} "
        f"| {num(r['chroma_drift'])} | {num(r.get('floor_drift'))} |"
        for r in targets["scenes"]
    ]
    lines += [
        "",
        "| preset | seed | scene | frame | depth drift | static / tracked | true map's drift "
        "| static / true | tracked / true |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    lines += [
        f"| {r['preset']} | {r['seed']} | {r['scene']} | {r['frame']:06d} "
        f"| {num(r['depth_drift'])} "
        f"| {'static: nothing' if r['static_empty'] else num(r['static_gain'])} "
        f"| {num(r['true_depth_drift'])} "
        f"| {'true: nothing' if r['true_empty'] else num(r.get('true_static_gain'))} "
        f"| {'true: nothing' if r['true_empty'] else num(r['tracked_over_true'])} |"
        for r in targets["frames"]
    ]
    return lines


#: Each bound's short name in the per-scene table (:func:`targets_markdown`).
BOUND_NAMES = {
    "chroma_drift": "chroma drift",
    "floor_drift": "carried truth's chroma drift",
    "depth_drift": "depth drift",
    "static_gain": "gain over the static map",
    "true_depth_drift": "true map's depth drift",
    "true_static_gain": "true map's gain over the static map",
    "tracked_within_true": "within the true map",
}


def _by_scene_lines(by_scene: dict) -> list[str]:
    """The tracked variant's counts per bound (rows) and scene (columns), as markdown
    lines; none without scenes: a scene that no map of any chromaticity can meet a bound
    on shows it beside one where the tracking misses it."""
    if not by_scene:
        return []
    scenes = list(by_scene)
    lines = ["", "| bound | " + " | ".join(scenes) + " |", "|---|" + "---|" * len(scenes)]
    for key, name in BOUND_NAMES.items():
        counts = [by_scene[s].get(key, {"met": 0, "of": 0}) for s in scenes]
        if not any(c["of"] for c in counts):
            continue
        lines.append(f"| {name} | " + " | ".join(f"{c['met']} of {c['of']}" for c in counts) + " |")
    return lines


def _pair(e: dict | None, fmt: str) -> str:
    return "-" if not e else f"{e['median']:{fmt}} / {e['worst']:{fmt}}"


def _home_moved(home: dict, moved: dict, col: str, fmt: str) -> str:
    """One cell of a metric on the chromatic frame and on the moved frames (each
    :func:`_pair`); "-" where neither has it."""
    if not (home.get(col) or moved.get(col)):
        return "-"
    return f"{_pair(home.get(col), fmt)}; {_pair(moved.get(col), fmt)}"


def _nf_cell(home: dict, moved: dict) -> str:
    """The noise-free map's cell: within 1 sigma, then 3, each chromatic; moved."""
    one = _home_moved(home, moved, "chroma_nf_within_1", ".2f")
    three = _home_moved(home, moved, "chroma_nf_within_3", ".2f")
    return "-" if one == three == "-" else f"{one} // {three}"


def summarise_markdown(summary: dict) -> str:
    """:func:`summarise` as markdown: the chromatic frame against the moved frames per
    scene x variant, then per scene a table per frame (median over seeds / worst seed)."""
    seeds = ", ".join(map(str, summary["seeds"]))
    lines = [
        "# Moving coloured objects: static against true chromaticity",
        "",
        f"Preset {', '.join(summary['presets'])}, seeds {seeds}. Every cell: median over "
        "seeds / worst seed. `moved`: each seed's median over the frames other than the "
        "chromatic frame; `worst moved`: each seed's worst such frame. Chroma RMS log: RMS "
        "of the centred log ratios' difference to the truth over the object's pixels where "
        "the map has a p (`known`: their share); chroma within 3 sigma: the share of those "
        "pixels' and bands' differences within 3 of the map's own sigma of log p, "
        "against the truth; against the noise-free map (`--noise-free`, carried by the "
        "true motion: what the error bar claims to cover) within 1 and 3 (0.68, 0.997 "
        "for an honest Gaussian bar). "
        "Position error: a tracked map's median "
        "distance from each pixel's tracked position in the chromatic frame to its point's "
        "true one (pixels; motion: the true one's median distance from the pixel). Within "
        "3 sigma: the share of the compared pixels whose depth error is within 3 of their "
        "depth_sigma (0.997 for an honest Gaussian error bar). `empty`: seed x frame rows "
        "with nothing reconstructed (no depth figure; left out of the depth columns, coverage 0).",
        "",
    ]
    head = [
        "scene",
        "variant",
        "depth, chromatic frame",
        "depth, moved",
        "depth, worst moved",
        "within 3 sigma, chromatic / moved",
        "normal, moved",
        "coverage, chromatic frame",
        "coverage, moved",
        "chroma RMS log, chromatic / moved",
        "chroma known, chromatic / moved",
        "chroma within 3 sigma, chromatic / moved",
        "chroma within 1 / 3 sigma of the noise-free map, chromatic / moved",
        "position error (px), chromatic / moved",
        "empty",
    ]
    lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for scene, variants in summary["scenes"].items():
        for variant, e in variants.items():
            h, m, w = e["chromatic_frame"], e["moved"], e["moved_worst_frame"]
            cells = [
                _pair(h.get("depth_median_mm"), ".3f"),
                _pair(m.get("depth_median_mm"), ".3f"),
                _pair(w.get("depth_median_mm"), ".3f"),
                _home_moved(h, m, "sigma_within_3", ".2f"),
                _pair(m.get("normal_median_deg"), ".2f"),
                _pair(h.get("coverage"), ".3f"),
                _pair(m.get("coverage"), ".3f"),
                _home_moved(h, m, "chroma_rms_log", ".3f"),
                _home_moved(h, m, "chroma_known", ".3f"),
                _home_moved(h, m, "chroma_sigma_within_3", ".2f"),
                _nf_cell(h, m),
                _home_moved(h, m, "track_position_px", ".2f"),
                str(len(e["empty_frames"])),
            ]
            lines.append("| " + " | ".join([scene, variant, *cells]) + " |")
    for scene, variants in summary["scenes"].items():
        lines += ["", f"## {scene}, per frame", ""]
        head = ["frame", "variant", *(h for _, h, _, _ in METRICS)]
        lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        frames = sorted({int(f) for e in variants.values() for f in e["per_frame"]})
        for frame in frames:
            for variant, e in variants.items():
                pf = e["per_frame"].get(str(frame), {})
                cells = [_pair(pf.get(col), fmt) for col, _, fmt, _ in METRICS]
                lines.append("| " + " | ".join([f"{frame:06d}", variant, *cells]) + " |")
    lines += targets_markdown(summary["targets"], summary.get("oracle_targets"))
    lines += ["", "## Seconds per seed", "", "| seed | render | calibration | reconstruction |"]
    lines.append("|---|---|---|---|")
    for seed, s in summary["seconds"].items():
        lines.append(
            f"| {seed} | {s['render_s']:.0f} | {s['calib_s']:.0f} | {s['reconstruct_s']:.0f} |"
        )
    lines.append("")
    return "\n".join(lines)


def main(argv=None) -> dict:
    from colourhs.cli.commands import frame_indices
    from colourhs.common.progress import show_progress

    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument(
        "--preset",
        default="random-dynamic-tiny",
        help="a dynamic preset: dynamic-tiny, dynamic, random-dynamic, random-dynamic-tiny "
        "(default), corner-dynamic, corner-dynamic-tiny",
    )
    p.add_argument("--seeds", default="0-3", help="seeds, e.g. 0-3 or 1,3 (default 0-3)")
    p.add_argument(
        "--frames",
        default=None,
        help="frames of every sequence, e.g. 0-11/2 (every 2nd) or 0,4,8; each sequence's "
        "chromatic frame always (default all)",
    )
    p.add_argument(
        "--evaluate",
        default=None,
        help="reconstruct and score only these frames (as --frames) and each sequence's "
        "chromatic frame, rendering all that --frames selects (a tracked map follows "
        "every rendered frame; default all)",
    )
    p.add_argument(
        "--raw-truth",
        action="store_true",
        help="also bayes_full_true_raw: the true chromaticity not normalised to sum 3",
    )
    p.add_argument(
        "--tracked",
        action="store_true",
        help="also bayes_dyn: the calibrated map carried through the sequence (the workflow's)",
    )
    p.add_argument(
        "--oracle",
        action="store_true",
        help="also bayes_dyn and the tracked map with the true p in its holes "
        "(bayes_dyn_truth_in_holes) or where it has a p (bayes_dyn_truth_where_known), "
        "and the calibrated map at the true positions (bayes_dyn_true_positions)",
    )
    p.add_argument(
        "--noise-free",
        action="store_true",
        help="also render the chromatic captures without sensor noise and score every "
        "map against the noise-free map carried by the true motion (its error bar's claim)",
    )
    p.add_argument("--keep", type=Path, default=None, help="keep datasets and results here")
    p.add_argument("--tag", default="", help="suffix of the output files")
    p.add_argument(
        "--summarise", type=Path, nargs="+", default=None, help="only summarise these CSVs"
    )
    args = p.parse_args(argv)
    out = HERE / "results"
    out.mkdir(exist_ok=True)
    csv = out / f"dynamic_chromaticity_seeds{args.tag}.csv"
    if args.summarise is not None:
        table = pd.concat([pd.read_csv(c) for c in args.summarise], ignore_index=True)
    else:
        from colourhs.synth.synthesise import PRESETS

        if args.preset not in PRESETS or PRESETS[args.preset].scene_set != "dynamic":
            dynamic = ", ".join(k for k, v in PRESETS.items() if v.scene_set == "dynamic")
            p.error(f"--preset {args.preset}: not a dynamic preset ({dynamic})")
        show_progress()
        frames, evaluate = select_frames(args.frames), select_frames(args.evaluate)
        variants = VARIANTS + ((RAW_TRUTH,) if args.raw_truth else ())
        track = once_per_scene(tracked_source)
        variants += (tracked_variant(track),) if args.tracked or args.oracle else ()
        variants += oracle_variants(track) if args.oracle else ()
        rows = seeds_in_temp(
            frame_indices(args.seeds),
            "colourhs-dynchroma",
            lambda seed, root: run_seed(
                seed, args.preset, root, frames, variants, args.keep, evaluate, args.noise_free
            ),
            csv,
        )
        table = pd.DataFrame(rows)
    summary = summarise(table)
    (out / f"dynamic_chromaticity_summary{args.tag}.json").write_text(json.dumps(summary, indent=2))
    (out / f"dynamic_chromaticity_summary{args.tag}.md").write_text(summarise_markdown(summary))
    print(summarise_markdown(summary))
    return summary


if __name__ == "__main__":
    main()
