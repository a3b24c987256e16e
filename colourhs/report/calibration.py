"""Calibration diagnostics for the evaluation report, from the calibration's own files.

What the calibration stages measured of their own fit, read back from what they
wrote (``results/NAME/calib/``, docs/results-layout.md): the board poses'
marker reprojection RMS (``marker_poses.csv``), each camera's channel
cross-talk matrix (``crosstalk.json``), the photometric fit's residual and
coverage (``photometric.h5``) and, where the dataset carries the true mu maps
(``gt/photometric.h5``, synthetic data), the mu maps' error against them.

Each ``*_table`` function reads one file and returns a small table;
:func:`calibration_diagnostics` gathers those whose files exist, with a title
and a note on units, for :func:`colourhs.report.page.build_report`.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

__all__ = [
    "calibration_diagnostics",
    "crosstalk_table",
    "marker_table",
    "mu_error_table",
    "photometric_table",
]

_CHANNELS = ("R", "G", "B")
_LIGHTS = ("red", "green", "blue")


def marker_table(marker_poses_csv: str | Path) -> pd.DataFrame:
    """One row per usable board pose: ``pose``, ``n_markers`` (markers seen by two or
    more cameras) and ``rms_px`` (the pose fit's marker-corner reprojection RMS,
    pixels), from the markers stage's ``marker_poses.csv``."""
    df = pd.read_csv(marker_poses_csv, dtype={"pose": str})
    return df[["pose", "n_markers", "rms_px"]].reset_index(drop=True)


def crosstalk_table(crosstalk_json: str | Path) -> pd.DataFrame:
    """Each camera's median channel mixing matrix M from ``crosstalk.json``.

    ``M[c, b]`` is camera channel c's response to light colour b relative to
    channel b's own (unit diagonal; the median over the image of the mixing
    field): rows ``camera``, ``channel`` (R, G, B), then one column per light
    colour (``red``, ``green``, ``blue``), dimensionless.
    """
    cameras = json.loads(Path(crosstalk_json).read_text())["cameras"]
    rows = [
        {"camera": cam, "channel": ch, **dict(zip(_LIGHTS, row, strict=True))}
        for cam, entry in cameras.items()
        for ch, row in zip(_CHANNELS, entry["M"], strict=True)
    ]
    return pd.DataFrame(rows, columns=["camera", "channel", *_LIGHTS])


def photometric_table(photometric_h5: str | Path) -> pd.DataFrame:
    """Per Helmholtz camera (map ``<camera>/<colour>``) of ``photometric.h5``:
    ``constraints`` (eq. 7 rows that constrain it), ``residual_rms_log`` (the fit's
    residual RMS, natural log of mu), ``noise_rms_log`` (the part of it the
    readings' noise explains; NaN in files written before it), ``residual_over_noise``
    (about 1 where the board poses follow eq. 6) and ``calibrated_share`` (share
    of the image where the data determine mu)."""
    import h5py

    with h5py.File(photometric_h5, "r") as f:
        counts = json.loads(f.attrs["constraints"])
        residual = json.loads(f.attrs["residual_rms_log"])
        noise = json.loads(f.attrs.get("noise_rms_log", "{}"))
        share = {k: float(np.mean(f["calibrated"][k][()])) for k in counts if k in f["calibrated"]}
    return pd.DataFrame(
        [
            {
                "map": k,
                "constraints": int(counts[k]),
                "residual_rms_log": float(residual[k]),
                "noise_rms_log": float(noise.get(k, np.nan)),
                "residual_over_noise": float(residual[k]) / float(noise.get(k, np.nan)),
                "calibrated_share": share.get(k, np.nan),
            }
            for k in counts
        ]
    )


def mu_error_table(photometric_h5: str | Path, truth_h5: str | Path, rig) -> pd.DataFrame:
    """Each calibrated mu map against the true one (``gt/photometric.h5``): RMS of
    the natural-log error over the calibrated region, one scale per reciprocal pair
    removed (:func:`colourhs.evaluation.photometric_errors.mu_map_errors`), beside the same
    for mu = 1 (no calibration). Columns ``map``, ``rms_log_error``,
    ``rms_log_error_mu1``, ``calibrated_share``; ``rig``: the dataset's
    :class:`colourhs.capture.Rig`. Raises KeyError when a map is missing."""
    import h5py

    from colourhs.calibration.photometric import read_mu_maps
    from colourhs.evaluation.photometric_errors import mu_map_errors

    maps = read_mu_maps(photometric_h5)
    with h5py.File(photometric_h5, "r") as f:
        calibrated = {k: f["calibrated"][k][()].astype(bool) for k in maps}
    errors = mu_map_errors({"maps": maps, "calibrated": calibrated}, read_mu_maps(truth_h5), rig)
    table = errors.pivot(index="map", columns="method", values="rms_log_error")
    share = errors.drop_duplicates("map").set_index("map")["calibrated_fraction"]
    return pd.DataFrame(
        {
            "map": table.index,
            "rms_log_error": table["calibrated"].to_numpy(),
            "rms_log_error_mu1": table["no calibration"].to_numpy(),
            "calibrated_share": share.loc[table.index].to_numpy(),
        }
    )


def calibration_diagnostics(calib_dir: str | Path, dataset=None) -> list[dict]:
    """The diagnostics tables whose files exist under ``calib_dir`` (results/NAME/calib).

    Returns ``[{"title", "note", "table": DataFrame}]``: board poses, cross-talk,
    photometric fit, and the mu error when ``dataset`` (a
    :class:`colourhs.capture.Dataset`) has ``gt/photometric.h5`` with this rig's
    maps. Missing files are left out (a rig without cross-talk calibration).
    """
    calib = Path(calib_dir)
    out = []
    if (calib / "marker_poses.csv").is_file():
        out.append(
            {
                "title": "Board poses",
                "note": "marker_poses.csv: markers seen by two or more cameras and the pose "
                "fit's reprojection RMS of their corners (pixels).",
                "table": marker_table(calib / "marker_poses.csv"),
            }
        )
    if (calib / "crosstalk.json").is_file():
        out.append(
            {
                "title": "Channel cross-talk",
                "note": "crosstalk.json: M[channel, light], a channel's response to a light "
                "colour relative to that colour's own channel (median over the image; 1 on "
                "the diagonal, 0 = no cross-talk).",
                "table": crosstalk_table(calib / "crosstalk.json"),
            }
        )
    photometric = calib / "photometric.h5"
    if photometric.is_file():
        out.append(
            {
                "title": "Photometric fit",
                "note": "photometric.h5: eq. (7) constraints per Helmholtz camera, the fit's "
                "residual RMS (natural log of mu; 0.01 is about 1 %), the part of it the "
                "readings' noise explains and their ratio (about 1 where the board poses "
                "follow eq. (6); above 1.3 the calibration warns: interreflections, room "
                "light, or a glossy board with lights beside the lenses) and the share of "
                "the image where the board determined mu.",
                "table": photometric_table(photometric),
            }
        )
    truth = Path(dataset.root) / "gt" / "photometric.h5" if dataset is not None else None
    if photometric.is_file() and truth is not None and truth.is_file():
        try:
            table = mu_error_table(photometric, truth, dataset.rig)
        except KeyError as e:  # maps of other camera names: said, not fatal
            table = pd.DataFrame({"note": [f"no map {e} in the calibration or the truth"]})
        out.append(
            {
                "title": "mu against the ground truth",
                "note": "gt/photometric.h5: RMS of the natural-log error of each mu map over "
                "its calibrated region, one scale per reciprocal pair removed, beside "
                "the same for mu = 1 (no photometric calibration).",
                "table": table,
            }
        )
    return out
