"""Names of the results contract's ``metrics.csv`` (results-contract.md): its
columns, in order, with no dependencies, so that the evaluation job that
writes a row and the report that reads the table share one definition
(:mod:`colourhs.evaluate`, :mod:`colourhs.reporttables`)."""

from __future__ import annotations

__all__ = ["EXTRA_COLUMNS", "KEY_COLUMNS", "METRIC_COLUMNS", "REQUIRED_COLUMNS"]

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
#: Every column ``metrics.csv`` must have (results contract, version 1).
REQUIRED_COLUMNS = KEY_COLUMNS + METRIC_COLUMNS
#: Extra metric columns that the evaluation writes after the contract's
#: (:func:`colourhs.evaluate.evaluate_frame`).
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
)
