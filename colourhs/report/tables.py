"""The report's tables: ``metrics.csv`` and Snakemake benchmark files, read and summarised.

:func:`read_metrics` reads the results contract's per-frame metrics table
(``reports/NAME/metrics.csv``, columns :data:`REQUIRED_COLUMNS`, defined in
:mod:`colourhs.common.metrics_csv`) and
:func:`summarise_metrics` aggregates it over frames, one row per (scene,
variant), as :data:`AGGREGATION` says. :func:`find_benchmarks`,
:func:`read_benchmarks` and :func:`summarise_benchmarks` do the same for the
Snakemake ``benchmark:`` files (timing and memory per rule).
:func:`format_number` is how the report prints every number and
:func:`html_table` every table; :func:`best_rows` picks each scene's best
variant and :func:`by_variant` turns a scene's table to one column per variant.

The HTML page that shows these tables is :mod:`colourhs.report.page`, which
re-exports them.
"""

from __future__ import annotations

import html
import math
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from colourhs.common.metrics_csv import (
    DROP_COLUMNS,
    DROP_REASONS,
    EXTRA_COLUMNS,
    GAUSSIAN_WITHIN,
    KEY_COLUMNS,
    METRIC_COLUMNS,
    REQUIRED_COLUMNS,
    SIGMA_MULTIPLES,
)
from colourhs.workflow.variants import VARIANT_ORDER

__all__ = [
    "AGGREGATION",
    "BENCHMARK_COLUMNS",
    "EXPECTED_ERROR_COLUMNS",
    "EXTRA_COLUMNS",
    "KEY_COLUMNS",
    "METRIC_COLUMNS",
    "REQUIRED_COLUMNS",
    "best_rows",
    "breakable",
    "by_variant",
    "drop_table",
    "expected_error_table",
    "find_benchmarks",
    "format_number",
    "html_table",
    "read_benchmarks",
    "read_metrics",
    "sigma_calibration_table",
    "summarise_benchmarks",
    "summarise_metrics",
]

#: How a contract metric is aggregated over the frames of one (scene, variant):
#: "mean", "max", "median", "rms" (``sqrt(mean(x**2))``) or "sum". Other numeric
#: columns are aggregated by :func:`_aggregation_of` (by their name's pattern),
#: except those named here too.
AGGREGATION = {
    "hausdorff_rms_mm": "mean",
    "hausdorff_mean_mm": "mean",
    "hausdorff_max_mm": "max",
    "depth_median_mm": "median",
    "depth_rms_mm": "rms",
    "normal_median_deg": "median",
    # a median sigma per frame, as depth_sigma_median_mm (which its name's pattern gives)
    "expected_depth_error_mm": "median",
    # a median over each frame's points; the frames' median likewise
    "reciprocity_defect_deg": "median",
}

#: The expected-error table's metric columns (:func:`expected_error_table`): the
#: reconstruction's own median sigma and flagged share, and the lights' reciprocity
#: defect (which the sigma does not cover), which need no ground truth, then the
#: measured errors beside them where there is ground truth.
EXPECTED_ERROR_COLUMNS = (
    "expected_depth_error_mm",
    "uncertain_share",
    "reciprocity_defect_deg",
    "depth_sigma_median_mm",
    "depth_median_mm",
    "depth_signed_median_mm",
)

#: Columns of a Snakemake benchmark TSV file.
BENCHMARK_COLUMNS = (
    "s",
    "h:m:s",
    "max_rss",
    "max_vms",
    "max_uss",
    "max_pss",
    "io_in",
    "io_out",
    "mean_load",
    "cpu_time",
)


# --------------------------------------------------------------------------- numbers


def format_number(x) -> str:
    """Three significant digits, no exponent from 1e-3 to 1e6; empty for missing values.

    ``2.5 -> "2.50"``, ``2 -> "2.00"``, ``0.01234 -> "0.0123"``, ``1234.5 -> "1234"``
    (numbers of four or more integer digits are rounded to integers).
    """
    if x is None:
        return ""
    try:
        v = float(x)
    except (TypeError, ValueError):
        return html.escape(str(x))
    if not math.isfinite(v):
        return ""
    if v == 0:
        return "0"
    a = abs(v)
    if a >= 1000:
        return f"{v:.0f}" if a < 1e6 else f"{v:.3g}"
    s = f"{v:#.3g}"
    return s[:-1] if s.endswith(".") else s


def breakable(text) -> str:
    """``text`` escaped for HTML, with a line-break opportunity (``<wbr>``) after each
    underscore: a header such as ``depth_median_mm`` then wraps between its words
    instead of widening its column or breaking inside a word."""
    return html.escape(str(text), quote=True).replace("_", "_<wbr>")


def _cell_text(value) -> str:
    """A table cell's HTML: integers as they are, other numbers by
    :func:`format_number`, text escaped, missing values empty."""
    if value is None or (
        not isinstance(value, str) and pd.api.types.is_scalar(value) and pd.isna(value)
    ):
        return ""
    if isinstance(value, bool | np.bool_):
        return str(bool(value))
    if isinstance(value, int | np.integer):
        return str(int(value))
    if isinstance(value, float | np.floating):
        return format_number(value)
    return html.escape(str(value), quote=True)


def _class_attr(name: str) -> str:
    return f' class="{html.escape(name, quote=True)}"' if name else ""


def html_table(
    table: pd.DataFrame,
    css_class: str,
    *,
    row_class: Sequence[str] | None = None,
    cell_class: pd.DataFrame | None = None,
) -> str:
    """``table`` as an HTML ``<table>``: a header row of its column names, one row
    per row of ``table`` (no index).

    Headers wrap only at spaces and underscores (:func:`breakable`), so a narrow
    window wraps them between words; cells are printed by :func:`_cell_text`
    (numbers by :func:`format_number`, missing values empty, text escaped).

    Parameters
    ----------
    table
        The rows to show.
    css_class
        The table's ``class`` attribute.
    row_class
        A class per row of ``table`` ("" for none), or None.
    cell_class
        A class per cell ("" for none): a frame of ``table``'s shape, in its order,
        or None.
    """
    head = "".join(f"<th>{breakable(c)}</th>" for c in table.columns)
    classes = None if cell_class is None else cell_class.to_numpy(object)
    rows = []
    for i, values in enumerate(table.itertuples(index=False, name=None)):
        cells = "".join(
            f"<td{_class_attr(classes[i, j] if classes is not None else '')}>{_cell_text(v)}</td>"
            for j, v in enumerate(values)
        )
        rows.append(f"<tr{_class_attr(row_class[i] if row_class is not None else '')}>{cells}</tr>")
    return (
        f"<table{_class_attr(css_class)}><thead><tr>{head}</tr></thead>"
        f"<tbody>{''.join(rows)}</tbody></table>"
    )


def _rms(x: pd.Series) -> float:
    """``sqrt(mean(x**2))`` over the finite values; NaN when there are none."""
    v = pd.to_numeric(x, errors="coerce").to_numpy(float)
    v = v[np.isfinite(v)]
    return float(np.sqrt(np.mean(v**2))) if v.size else float("nan")


def _aggregation_of(column: str) -> str:
    """The aggregation over frames of a metric column (see :data:`AGGREGATION`).

    Other columns, by their name: ``*_max_*`` -> max, ``*_median_*`` or ``*_p<NN>_*``
    -> median, ``*_samples`` -> sum, anything else (``completeness_rms_mm``,
    ``coverage``, ...) -> mean.
    """
    if column in AGGREGATION:
        return AGGREGATION[column]
    parts = column.split("_")
    if "max" in parts:
        return "max"
    if "median" in parts or any(p[:1] == "p" and p[1:].isdigit() for p in parts):
        return "median"
    if parts[-1] == "samples":
        return "sum"
    return "mean"


# --------------------------------------------------------------------------- metrics


def read_metrics(metrics_csv: str | Path) -> pd.DataFrame:
    """Read ``reports/NAME/metrics.csv``, checking the contract's columns.

    ``scene``, ``frame`` and ``variant`` are read as strings (frame ids keep their
    leading zeros); empty cells are NaN.

    Raises
    ------
    ValueError
        When the file is missing, empty, or lacks any of :data:`REQUIRED_COLUMNS`
        (the message names the file and the missing columns).
    """
    path = Path(metrics_csv)
    if not path.is_file():
        raise ValueError(f"{path}: metrics CSV not found")
    try:
        df = pd.read_csv(path, dtype={k: str for k in KEY_COLUMNS}, keep_default_na=True)
    except pd.errors.EmptyDataError:
        df = pd.DataFrame()
    missing = [c for c in REQUIRED_COLUMNS if c not in df.columns]
    if missing:
        raise ValueError(f"{path}: metrics CSV lacks the contract columns {missing}")
    return df


def _variant_sort_key(variants: Iterable[str]) -> list[str]:
    """The paper's variants in its order, then any others alphabetically."""
    variants = list(dict.fromkeys(variants))
    known = [v for v in VARIANT_ORDER if v in variants]
    return known + sorted(v for v in variants if v not in VARIANT_ORDER)


def summarise_metrics(df: pd.DataFrame) -> pd.DataFrame:
    """Aggregate a per-frame metrics table over frames, one row per (scene, variant).

    Parameters
    ----------
    df
        The contents of ``metrics.csv``: columns at least ``scene``, ``variant``
        and the numeric metric columns; one row per (scene, frame, variant).

    Returns
    -------
    DataFrame with columns ``scene``, ``variant``, ``frames`` (row count), then
    every numeric metric column of ``df`` in its order, aggregated as
    :data:`AGGREGATION` says for the contract's columns (mean of
    ``hausdorff_rms_mm`` and ``hausdorff_mean_mm``, max of ``hausdorff_max_mm``,
    median of ``depth_median_mm`` and ``normal_median_deg``, RMS of
    ``depth_rms_mm``) and by :func:`_aggregation_of` for others. Missing values
    are skipped; a value missing in every frame stays NaN. Rows are sorted by
    scene, then variant in the paper's order (:data:`VARIANT_ORDER`) with other
    variants after it. Non-numeric columns other than the keys are dropped.
    """
    for key in ("scene", "variant"):
        if key not in df.columns:
            raise ValueError(f"metrics table lacks the column {key!r}")
    df = df.copy()
    df["scene"] = df["scene"].astype(str)
    df["variant"] = df["variant"].astype(str)
    metric_cols = []
    for c in df.columns:
        if c in KEY_COLUMNS or c in ("method", "same_as"):  # labels, not metrics
            continue
        if c in METRIC_COLUMNS or pd.api.types.is_numeric_dtype(df[c]):
            df[c] = pd.to_numeric(df[c], errors="coerce")
            metric_cols.append(c)
    # the contract's metrics first, in its order, then the others as they come
    metric_cols = [c for c in METRIC_COLUMNS if c in metric_cols] + [
        c for c in metric_cols if c not in METRIC_COLUMNS
    ]

    rows = []
    for (scene, variant), g in df.groupby(["scene", "variant"], sort=False):
        row = {"scene": scene, "variant": variant, "frames": len(g)}
        for c in metric_cols:
            how = _aggregation_of(c)
            s = g[c]
            if how == "rms":
                row[c] = _rms(s)
            elif s.notna().any():
                row[c] = float(getattr(s, how)(skipna=True))
            else:
                row[c] = float("nan")
        rows.append(row)
    out = pd.DataFrame(rows, columns=["scene", "variant", "frames", *metric_cols])
    if out.empty:
        return out
    order = {v: i for i, v in enumerate(_variant_sort_key(out["variant"]))}
    out["_o"] = out["variant"].map(order)
    out = out.sort_values(["scene", "_o"], kind="stable").drop(columns="_o")
    out["frames"] = out["frames"].astype(int)
    return out.reset_index(drop=True)


def best_rows(summary: pd.DataFrame, metric: str) -> pd.Series:
    """Which rows of :func:`summarise_metrics`' table hold their scene's best ``metric``.

    Parameters
    ----------
    summary
        Columns ``scene`` and ``metric`` (an error: lower is better), one row per
        (scene, variant).
    metric
        The column to compare.

    Returns
    -------
    Series of bool, on ``summary``'s index: True where the row's ``metric`` is the
    lowest of its scene, for every row that ties for it; False where it is missing
    (NaN), so a scene without any value of ``metric`` (no ground truth) has none.
    """
    if metric not in summary.columns:
        return pd.Series(False, index=summary.index)
    values = pd.to_numeric(summary[metric], errors="coerce")
    lowest = values.groupby(summary["scene"].astype(str)).transform("min")
    return values.notna() & (values == lowest)


def by_variant(table: pd.DataFrame) -> pd.DataFrame:
    """A scene's table turned: one row per column of ``table`` but ``variant`` (column
    ``metric``, the column's name), one column per variant, in ``table``'s order.

    A table of many metrics and a few variants reads down the page this way
    instead of growing wider than a narrow window; each value keeps its type
    (frame counts stay integers).
    """
    names = [c for c in table.columns if c != "variant"]
    out = pd.DataFrame({"metric": names})
    for i, variant in enumerate(table["variant"].astype(str)):
        out[variant] = pd.Series([table[c].iloc[i] for c in names], dtype=object)
    return out


def _has_values(table: pd.DataFrame, columns) -> pd.Series:
    """Rows of ``table`` with a finite value in any of ``columns`` (those present)."""
    cols = [c for c in columns if c in table.columns]
    if not cols:
        return pd.Series(False, index=table.index)
    values = table[cols].apply(pd.to_numeric, errors="coerce").to_numpy(float)
    return pd.Series(np.isfinite(values).any(axis=1), index=table.index)


def expected_error_table(summary: pd.DataFrame) -> pd.DataFrame:
    """Each variant's expected depth error, from :func:`summarise_metrics`' rows of a scene.

    Parameters
    ----------
    summary : DataFrame
        Rows of one scene (columns ``variant`` and metric columns).

    Returns
    -------
    DataFrame
        Columns ``variant`` and those of :data:`EXPECTED_ERROR_COLUMNS` present in
        ``summary`` (``expected_depth_error_mm``: median sigma, mm, with or without
        ground truth; the measured errors are NaN without it); one row per variant
        with an expected error or a flagged share. Empty when no variant has
        either (depth files without ``depth_sigma``).
    """
    cols = [c for c in EXPECTED_ERROR_COLUMNS if c in summary.columns]
    rows = summary[_has_values(summary, ("expected_depth_error_mm", "uncertain_share"))]
    return rows[["variant", *cols]].reset_index(drop=True)


def sigma_calibration_table(summary: pd.DataFrame) -> pd.DataFrame:
    """Shares of pixels within 1, 2, 3 sigma per variant, beside a calibrated sigma's.

    Parameters
    ----------
    summary : DataFrame
        :func:`summarise_metrics`' rows of one scene (columns ``variant`` and
        ``sigma_within_<k>``, k in :data:`colourhs.common.metrics_csv.SIGMA_MULTIPLES`).

    Returns
    -------
    DataFrame
        Columns ``variant`` and ``within 1 sigma``, ``within 2 sigma``, ``within 3
        sigma``: one row per variant with a share (measured against ground truth),
        then the row ``calibrated (Gaussian)`` with
        :data:`colourhs.common.metrics_csv.GAUSSIAN_WITHIN` (0.683, 0.954, 0.997). Empty
        when no variant has a share.
    """
    share = [f"sigma_within_{k}" for k in SIGMA_MULTIPLES]
    label = {c: f"within {k} sigma" for c, k in zip(share, SIGMA_MULTIPLES, strict=True)}
    columns = ["variant", *label.values()]
    rows = summary[_has_values(summary, share)]
    if rows.empty:
        return pd.DataFrame(columns=columns)
    table = rows.reindex(columns=["variant", *share]).rename(columns=label)
    ideal = {"variant": "calibrated (Gaussian)"} | {
        label[c]: GAUSSIAN_WITHIN[k] for c, k in zip(share, SIGMA_MULTIPLES, strict=True)
    }
    return pd.concat([table, pd.DataFrame([ideal])], ignore_index=True)[columns]


def _percent(x) -> str:
    """A share (0 to 1) as a percentage with one decimal, ``0.1234 -> "12.3"``; empty
    for missing values."""
    v = float(x)
    return f"{100.0 * v:.1f}" if math.isfinite(v) else ""


def drop_table(frames: pd.DataFrame) -> pd.DataFrame:
    """Where the missing depth goes: per variant, the ground truth's pixels reconstructed
    and lost to each reason, percent, from the per-frame metrics rows of one scene.

    Parameters
    ----------
    frames : DataFrame
        :func:`read_metrics`' rows of one scene (columns ``variant``, ``coverage``
        and :data:`colourhs.common.metrics_csv.DROP_COLUMNS`; one row per frame and variant).

    Returns
    -------
    DataFrame
        Columns ``variant``, ``frames`` (the frames with the shares), ``reconstructed``
        (``coverage``), one per reason of :data:`colourhs.common.metrics_csv.DROP_REASONS` and
        ``other`` (lost without a reason): percent of the ground truth's pixels with
        one decimal (text), the mean over the variant's frames that have the shares,
        so that a row adds to 100 up to rounding. One row per variant with a share,
        in the paper's order (:data:`VARIANT_ORDER`); empty when none has one (depth
        files without ``dropped``, scenes without ground truth).
    """
    shares = ["coverage", *DROP_COLUMNS]
    columns = ["variant", "frames", "reconstructed", *DROP_REASONS, "other"]
    rows = frames[_has_values(frames, DROP_COLUMNS)]
    if rows.empty:
        return pd.DataFrame(columns=columns)
    values = rows.reindex(columns=shares).apply(pd.to_numeric, errors="coerce")
    values["variant"] = rows["variant"].astype(str)
    out = []
    for variant in _variant_sort_key(values["variant"]):
        mean = values[values["variant"] == variant][shares].mean()
        n = int((values["variant"] == variant).sum())
        out.append([variant, n, *(_percent(mean[c]) for c in shares)])
    return pd.DataFrame(out, columns=columns)


# --------------------------------------------------------------------------- benchmarks


def _rule_of(path: Path) -> str:
    """The rule name of a benchmark file ``.../benchmarks/snakemake/<rule>/...``.

    Falls back to the part after ``benchmarks``, then to the file's folder name.
    """
    parts = path.parts
    for anchor in ("snakemake", "benchmarks"):
        if anchor in parts[:-1]:
            i = len(parts) - 1 - parts[::-1].index(anchor)
            if i + 1 < len(parts) - 1:
                return parts[i + 1]
            if i + 1 == len(parts) - 1:  # benchmarks/snakemake/<rule>.tsv
                return path.stem
    return path.parent.name or path.stem


def find_benchmarks(root: str | Path, name: str | None = None) -> list[Path]:
    """The Snakemake benchmark files under ``root`` (e.g. ``benchmarks/snakemake``), sorted.

    With ``name``, only those of that dataset: files named ``<name>.tsv`` or lying
    in a folder ``<name>`` below the rule's folder (``<rule>/<name>/...``).
    """
    root = Path(root)
    if not root.is_dir():
        return []
    out = []
    for f in sorted(root.rglob("*.tsv")):
        rel = f.relative_to(root).parts
        if name is None or f.stem == name or name in rel[1:-1]:
            out.append(f)
    return out


def read_benchmarks(tsv_paths: Iterable[str | Path]) -> pd.DataFrame:
    """Read Snakemake benchmark TSV files into one table, one row per measured run.

    Each file (written by a rule's ``benchmark:`` directive) has the header
    :data:`BENCHMARK_COLUMNS` and one row per repeat. The rule name comes from
    the path ``benchmarks/snakemake/<rule>/...``.

    Returns
    -------
    DataFrame with columns ``rule``, ``job`` (the file's path), then the file's
    columns (numeric ones as float, ``NA`` as NaN; ``s`` in seconds, ``max_rss``
    and the other memory columns in MB).

    Raises
    ------
    ValueError
        For a missing file or one without the ``s`` column.
    """
    frames = []
    for p in tsv_paths:
        path = Path(p)
        if not path.is_file():
            raise ValueError(f"{path}: benchmark file not found")
        try:
            t = pd.read_csv(path, sep="\t", na_values=["NA", "-", ""])
        except pd.errors.EmptyDataError:
            t = pd.DataFrame()
        if "s" not in t.columns:
            raise ValueError(f"{path}: not a Snakemake benchmark file (no 's' column)")
        for c in t.columns:
            if c != "h:m:s":
                t[c] = pd.to_numeric(t[c], errors="coerce")
        t.insert(0, "job", str(path))
        t.insert(0, "rule", _rule_of(path))
        frames.append(t)
    if not frames:
        return pd.DataFrame(columns=["rule", "job", *BENCHMARK_COLUMNS])
    return pd.concat(frames, ignore_index=True)


def summarise_benchmarks(bench: pd.DataFrame) -> pd.DataFrame:
    """Per-rule timing from :func:`read_benchmarks`' table, plus a ``sum of jobs`` row.

    Columns ``rule``, ``jobs`` (benchmark files), ``runs`` (rows; more than jobs
    when a rule was benchmarked with repeats), ``total_s`` (sum of ``s``),
    ``mean_s`` (mean of ``s`` per run), ``max_s``, ``cpu_time_s`` (sum) and
    ``max_rss_mb`` (max of ``max_rss``). Rules in order of decreasing total time; the
    last row, ``sum of jobs``, totals every job (more than the run's elapsed time when
    jobs ran in parallel).
    """
    cols = ["rule", "jobs", "runs", "total_s", "mean_s", "max_s", "cpu_time_s", "max_rss_mb"]
    if bench.empty:
        return pd.DataFrame(columns=cols)
    b = bench.copy()
    for c in ("cpu_time", "max_rss"):
        if c not in b.columns:
            b[c] = np.nan

    def one(rule: str, g: pd.DataFrame) -> dict:
        return {
            "rule": rule,
            "jobs": int(g["job"].nunique()),
            "runs": len(g),
            "total_s": float(g["s"].sum(min_count=1)),
            "mean_s": float(g["s"].mean()),
            "max_s": float(g["s"].max()),
            "cpu_time_s": float(g["cpu_time"].sum(min_count=1)),
            "max_rss_mb": float(g["max_rss"].max()),
        }

    rows = [one(rule, g) for rule, g in b.groupby("rule", sort=True)]
    rows.sort(key=lambda r: -(r["total_s"] if math.isfinite(r["total_s"]) else -1))
    rows.append(one("sum of jobs", b))  # jobs overlap: more than the run's elapsed time
    return pd.DataFrame(rows, columns=cols)
