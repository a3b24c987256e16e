"""A moving coloured object's chromaticity over its sequence, for the report (beyond
the paper): the maps carried from the chromatic frame
(:mod:`colourhs.calibration.chromaticity_tracking`) as an animation beside the
depth animation, and their drift as a plot over the frames."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

import h5py
import numpy as np

from colourhs.calibration.chromaticity import log_ratio_rms
from colourhs.common.files import note_read
from colourhs.report.animation import write_animation

__all__ = ["chromaticity_animation", "chromaticity_drift", "chromaticity_drift_figure"]


def _maps(path: str | Path, camera: str | None) -> tuple[str, h5py.File]:
    """The camera shown (``camera``, else the file's first) and the open file."""
    note_read(path)
    f = h5py.File(path, "r")
    cams = [k for k, v in f.items() if isinstance(v, h5py.Dataset)]
    return (camera if camera in cams else cams[0]), f


def chromaticity_animation(
    tracked: Mapping[str, str | Path], path: str | Path, camera: str | None = None, fps=8
) -> Path:
    """``chromaticity.gif``: one camera's tracked chromaticity map per frame
    (:func:`colourhs.report.figures.chromaticity_rgb`, unknown black), each frame
    labelled with its name, its place in the sequence and the share of the
    calibrated pixels it still has a p for.

    Parameters
    ----------
    tracked : frame -> tracked chromaticity file (``colourhs track-chromaticity``), in
        frame order.
    path : the GIF to write.
    camera : the camera shown (default: each file's first).
    """
    from colourhs.report.figures import chromaticity_rgb

    images, labels, n = [], [], len(tracked)
    for i, (frame, h5) in enumerate(tracked.items()):
        cam, f = _maps(h5, camera)
        with f:
            p = f[cam][()]
            share = json.loads(f.attrs.get("tracked", "{}")).get(cam)
            anchor = f.attrs.get("chromatic_frame", "")
        rgb = np.round(255 * chromaticity_rgb(p)).astype(np.uint8)
        # Small maps are enlarged so that the label reads.
        scale = max(1, int(np.ceil(320 / rgb.shape[1])))
        images.append(np.repeat(np.repeat(rgb, scale, axis=0), scale, axis=1))
        kept = "" if share is None else f", {share:.0%} tracked"
        chromatic = " (chromatic)" if frame == anchor else ""
        labels.append(f"{cam} frame {frame}{chromatic} ({i + 1}/{n}){kept}")
    return write_animation(images, path, fps=fps, labels=labels)


def chromaticity_drift(
    tracked: Mapping[str, str | Path],
    truth: Mapping[str, str | Path] | None = None,
    calibrated: str | Path | None = None,
) -> dict[str, dict[str, float]]:
    """Per frame, over the cameras: the median 1-sigma of the tracked log p
    (``sigma``), the share of the calibrated pixels tracked (``tracked``) and, with
    ground truth (frame -> ``gt/chromaticity/<frame>.h5``), the RMS log-ratio error of
    the tracked maps (``error``, :func:`colourhs.calibration.chromaticity.log_ratio_rms`)
    and of the calibrated maps used unchanged (``static_error``, the paper's method)."""
    static = {}
    if calibrated is not None:
        note_read(calibrated)
        with h5py.File(calibrated) as f:
            static = {k: v[()] for k, v in f.items() if isinstance(v, h5py.Dataset)}
    out = {}
    for frame, h5 in tracked.items():
        note_read(h5)
        with h5py.File(h5) as f:
            cams = [k for k, v in f.items() if isinstance(v, h5py.Dataset)]
            maps = {c: f[c][()] for c in cams}
            sigma = np.concatenate([f[f"sigma/{c}"][()].ravel() for c in cams])
            shares = json.loads(f.attrs.get("tracked", "{}"))
        row = {
            "sigma": float(np.nanmedian(sigma)) if np.isfinite(sigma).any() else float("nan"),
            "tracked": float(np.mean(list(shares.values()))) if shares else float("nan"),
        }
        if truth and frame in truth:
            note_read(truth[frame])
            with h5py.File(truth[frame]) as g:
                gt = {c: g[c][()] for c in cams if c in g}
            row["error"] = float(np.nanmean([log_ratio_rms(maps[c], gt[c]) for c in gt]))
            if static:
                errs = [log_ratio_rms(static[c], gt[c]) for c in gt if c in static]
                row["static_error"] = float(np.nanmean(errs))
        out[frame] = row
    return out


def chromaticity_drift_figure(drift: Mapping[str, Mapping[str, float]], path: str | Path) -> Path:
    """``chromaticity_drift.png``: :func:`chromaticity_drift` over the frames: the
    errors against the truth (where known) and the tracked maps' median sigma (log p),
    with the share tracked on a second axis."""
    import matplotlib.pyplot as plt

    from colourhs.report.figures import _save_png

    frames = list(drift)
    x = np.arange(len(frames))
    fig, ax = plt.subplots(figsize=(6.4, 3.4))
    for key, label, style in (
        ("error", "tracked: RMS log-ratio error", "o-"),
        ("static_error", "calibrated map unchanged (paper)", "s--"),
        ("sigma", "tracked: median sigma of log p", "^:"),
    ):
        y = [drift[f].get(key, np.nan) for f in frames]
        if np.isfinite(y).any():
            ax.plot(x, y, style, label=label, markersize=4)
    ax.set_xlabel("frame")
    ax.set_ylabel("log p")
    ax.set_xticks(x, frames, rotation=60, fontsize=7)
    ax.set_ylim(bottom=0)
    share = ax.twinx()
    share.plot(x, [drift[f].get("tracked", np.nan) for f in frames], color="0.6", lw=1)
    share.set_ylabel("share tracked", color="0.4")
    share.set_ylim(0, 1.05)
    ax.legend(fontsize=7, loc="upper left")
    ax.set_title("chromaticity over the sequence")
    fig.tight_layout()
    return _save_png(fig, path)
