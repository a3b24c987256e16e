"""A moving coloured object's chromaticity over its sequence, for the report (beyond
the paper): the drift of the maps carried from the chromatic frame
(:mod:`colourhs.calibration.chromaticity_tracking`) over the frames, which
:mod:`colourhs.report.figures` animates and plots."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

import h5py
import numpy as np

from colourhs.calibration.chromaticity import log_ratio_rms, map_log_sigma
from colourhs.common.files import note_read

__all__ = ["chromaticity_drift", "tracked_maps"]


def tracked_maps(path: str | Path, camera: str | None) -> tuple[str, h5py.File]:
    """The camera shown (``camera``, else the file's first) and the open file."""
    note_read(path)
    f = h5py.File(path, "r")
    cams = [k for k, v in f.items() if isinstance(v, h5py.Dataset)]
    return (camera if camera in cams else cams[0]), f


def chromaticity_drift(
    tracked: Mapping[str, str | Path],
    truth: Mapping[str, str | Path] | None = None,
    calibrated: str | Path | None = None,
) -> dict[str, dict[str, float]]:
    """Per frame, over the cameras: the median 1-sigma of the tracked log p
    (``sigma``, :func:`colourhs.calibration.chromaticity.map_log_sigma`), the share of
    the calibrated pixels tracked (``tracked``) and, with ground truth (frame ->
    ``gt/chromaticity/<frame>.h5``), the RMS log-ratio error of the tracked maps
    (``error``, :func:`colourhs.calibration.chromaticity.log_ratio_rms`) and of the
    calibrated maps used unchanged (``static_error``, the paper's method)."""
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
            sigma = np.concatenate([np.ravel(map_log_sigma(f, c)) for c in cams])
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
