"""The results contract's ``metrics.csv`` (results-contract.md): its columns, in
order, and :func:`metrics_table`, which writes it from the per-frame metrics JSON.

Light on purpose (the standard library; pandas only inside
:func:`metrics_table`), so that the evaluation job that writes a row
(:mod:`colourhs.evaluation.accuracy`, which imports open3d), the ``colourhs metrics`` job
that gathers the rows and the report that reads the table
(:mod:`colourhs.report.tables`) share one definition without importing each
other's libraries."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import TYPE_CHECKING

from colourhs.common.files import atomic_output

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "DROP_COLUMNS",
    "DROP_REASONS",
    "EXTRA_COLUMNS",
    "GAUSSIAN_WITHIN",
    "KEY_COLUMNS",
    "METRIC_COLUMNS",
    "REQUIRED_COLUMNS",
    "SIGMA_MULTIPLES",
    "metrics_table",
]

#: The contract's key columns of ``metrics.csv``.
KEY_COLUMNS = ("scene", "frame", "variant")
#: The contract's metric columns of ``metrics.csv``, in order.
METRIC_COLUMNS = (
    "hausdorff_rms_mm",
    "hausdorff_mean_mm",
    "hausdorff_max_mm",
    "depth_median_mm",
    "depth_rms_mm",
    "normal_median_deg",
)
#: Multiples k of the depth's sigma whose share ``sigma_within_<k>`` is reported: the
#: 68-95-99.7 rule's, so that each share reads against a well-known Gaussian value.
SIGMA_MULTIPLES = (1, 2, 3)
#: The share of a Gaussian error within k sigma, ``erf(k / sqrt(2))``: what a calibrated
#: sigma gives (0.683, 0.954, 0.997).
GAUSSIAN_WITHIN = {k: math.erf(k / math.sqrt(2.0)) for k in SIGMA_MULTIPLES}
#: Why a pixel of the reference camera has no depth: code ``k + 1`` of a depth file's
#: ``dropped`` dataset is ``DROP_REASONS[k]``; code 0 is a pixel with a depth (or, where
#: the file has no ``dropped``, unknown). New reasons go at the end (the codes stay).
#: :mod:`colourhs.common.depthfile` re-exports it; defined here so that the metrics' columns
#: (:data:`DROP_COLUMNS`) need neither h5py nor numpy.
DROP_REASONS = (
    # not in the object's silhouette or lit region
    "outside",
    # too dark in the reference camera's reciprocal channels
    "dark",
    # saturated in the reference camera
    "saturated",
    # no chromaticity p at the pixel
    "no_chromaticity",
    # every depth hypothesis failed (unusable samples in another view, the facing
    # test) or its cost was over the limit
    "data_term",
    # left out of the initial surface (depth edges, small components)
    "surface",
    # on a surface the refinement did not explain, and no hole filling filled it
    "refinement",
    # its depth's sigma exceeded the tolerance (flagged ``uncertain``)
    "uncertain",
    # eroded at the rim of what was reconstructed
    "rims",
)
#: Share of the ground truth's pixels lost to each reason (``dropped_<reason>``, in
#: :data:`DROP_REASONS`' order), then ``dropped_other``: lost without a reason (code 0).
#: With ``coverage`` they add to 1 (:func:`colourhs.evaluation.depth_errors.drop_summary`).
DROP_COLUMNS = (*(f"dropped_{reason}" for reason in DROP_REASONS), "dropped_other")
#: Every column ``metrics.csv`` must have (results contract, version 1).
REQUIRED_COLUMNS = KEY_COLUMNS + METRIC_COLUMNS
#: Extra metric columns that the evaluation writes after the contract's
#: (:func:`colourhs.evaluation.accuracy.evaluate_frame`).
EXTRA_COLUMNS = (
    "hausdorff_median_mm",
    "completeness_rms_mm",
    "completeness_mean_mm",
    "completeness_max_mm",
    "depth_p95_mm",
    "coverage",
    "hausdorff_samples",
    "completeness_samples",
    "outside_share",
    # The depth's own 1-sigma uncertainty (``depth_sigma`` of the depth file), against
    # the ground truth on the depth errors' pixels and, without it, as it stands.
    "depth_signed_median_mm",
    "depth_sigma_median_mm",
    *(f"sigma_within_{k}" for k in SIGMA_MULTIPLES),
    "expected_depth_error_mm",
    "uncertain_share",
    # Lights beside the lenses: the half-vector angle between a reciprocal pair's two
    # readings, median over the reconstructed points (degrees; 0 when collocated).
    "reciprocity_defect_deg",
    # Where the ground truth's pixels without a depth went (``dropped`` of the depth file).
    *DROP_COLUMNS,
)


def metrics_table(json_paths, out_csv: str | Path) -> pd.DataFrame:
    """Gather per-frame metrics JSON files into the tidy ``reports/NAME/metrics.csv``.

    One row per (scene, frame, variant), sorted by them; columns
    :data:`REQUIRED_COLUMNS`, then :data:`EXTRA_COLUMNS`, then ``method`` and
    ``same_as`` (the variant whose result a row copies: :func:`colourhs.workflow.variants.same_as`);
    empty cells where a metric is unknown (no ground truth). Written atomically.

    Raises
    ------
    ValueError
        On a repeated (scene, frame, variant) or a file missing those keys.
    """
    import pandas as pd

    keys = list(KEY_COLUMNS)
    rows = []
    for p in json_paths:
        rec = json.loads(Path(p).read_text())
        missing = [k for k in keys if k not in rec]
        if missing:
            raise ValueError(f"{p}: metrics lack {missing}")
        rows.append(rec)
    columns = list(REQUIRED_COLUMNS) + list(EXTRA_COLUMNS) + ["method", "same_as"]
    table = pd.DataFrame(rows, columns=columns)
    for key in keys:
        table[key] = table[key].astype(str)
    dup = table.duplicated(keys)
    if dup.any():
        raise ValueError(f"metrics: repeated rows {table.loc[dup, keys]}")
    table = table.sort_values(keys).reset_index(drop=True)
    with atomic_output(out_csv) as tmp:
        table.to_csv(tmp, index=False)
    return table
