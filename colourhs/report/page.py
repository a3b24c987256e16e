"""The evaluation report ``reports/NAME/index.html``: one HTML page that reads at a glance.

:func:`build_report` gathers what earlier stages wrote (the metrics table of the
results contract, the calibration and per-scene figures, Snakemake benchmark
files, the run's configuration, the dataset's rig and scene descriptions, the
result files) into one page rendered from the jinja2 template
``colourhs/report/templates/report.html`` (package data). The report folder
stands alone: images are linked by paths relative to the page, those from
outside the folder (``results/NAME/calib``) from copies in its ``assets/``
(:mod:`colourhs.report.assets`), or embedded as base64 data URIs with
``embed_images``; the result files of ``results/NAME`` are named, not linked
(``link_outside`` links every file where it is instead). Styles are inline. The
page is built in memory and written atomically, after the copies, so a failure
leaves no partial HTML nor partial copy behind.

The tables are computed by the small functions :func:`summarise_metrics`,
:func:`read_benchmarks` and :func:`summarise_benchmarks` in
:mod:`colourhs.report.tables` (re-exported here) and printed by its
:func:`~colourhs.report.tables.html_table`; the summary marks each scene's best
variant by :data:`BEST_METRIC`; provenance, rig summary, file
links and the figures' arrangement by :mod:`colourhs.report.provenance`. This module
holds the paper's reference numbers, the software versions and the page.
"""

from __future__ import annotations

import base64
import html
import importlib.metadata
import importlib.util
import logging
import os
import platform
import sys
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from colourhs.common.files import atomic_output
from colourhs.common.progress import stage
from colourhs.report.assets import link_files, place_files, write_assets
from colourhs.report.calibration import calibration_diagnostics
from colourhs.report.provenance import (
    arrange_figures,
    frame_error_svg,
    git_provenance,
    result_files,
    rig_summary,
    run_command,
    scene_descriptions,
)
from colourhs.report.tables import (
    AGGREGATION,
    BENCHMARK_COLUMNS,
    METRIC_COLUMNS,
    REQUIRED_COLUMNS,
    _aggregation_of,
    best_rows,
    by_variant,
    drop_table,
    expected_error_table,
    find_benchmarks,
    format_number,
    html_table,
    read_benchmarks,
    read_metrics,
    sigma_calibration_table,
    summarise_benchmarks,
    summarise_metrics,
)
from colourhs.report.view3d import scene_views
from colourhs.workflow.variants import VARIANT_LABELS, VARIANT_ORDER, VARIANTS

log = logging.getLogger(__name__)

__all__ = [
    "AGGREGATION",
    "BENCHMARK_COLUMNS",
    "BEST_METRIC",
    "METRIC_COLUMNS",
    "PAPER_REFERENCE",
    "PAPER_REFERENCE_SOURCE",
    "REQUIRED_COLUMNS",
    "VARIANT_LABELS",
    "VARIANT_ORDER",
    "PageOptions",
    "ReportInputs",
    "build_report",
    "find_benchmarks",
    "format_number",
    "read_benchmarks",
    "read_metrics",
    "software_versions",
    "summarise_benchmarks",
    "summarise_metrics",
    "summary_table",
]

#: Numbers the paper states, as ``{scene: {variant: {column: value}}}``. The paper
#: gives only these two: the RMS Hausdorff distance (mm) of the ``plane`` scene
#: (a held-out calibration board pose, real capture; no chromaticity calibration
#: was needed for it, so BayesianHS_wPhCalib is our ``bayes_ph``). No other scene
#: has a quantitative figure in the paper (Monster, Slinky and the dynamic
#: scenes are evaluated qualitatively only, for lack of ground truth).
PAPER_REFERENCE: dict[str, dict[str, dict[str, float]]] = {
    "plane": {
        "bayes_nocalib": {"hausdorff_rms_mm": 2.5},
        "bayes_ph": {"hausdorff_rms_mm": 2.0},
    },
}
#: Where :data:`PAPER_REFERENCE` comes from.
PAPER_REFERENCE_SOURCE = (
    "Colour Helmholtz Stereopsis, Section IV-A.1 'Quantitative evaluation' (with Figure 5): "
    "RMS Hausdorff distance of 2.5 mm for BayesianHS_w/oPhCalib and 2 mm for "
    "BayesianHS_wPhCalib on the real test plane; Section V repeats the 2 mm."
)

#: Packages whose versions the report lists: label -> (import name, distribution names).
SOFTWARE = {
    "numpy": ("numpy", ("numpy",)),
    "scipy": ("scipy", ("scipy",)),
    "pandas": ("pandas", ("pandas",)),
    "matplotlib": ("matplotlib", ("matplotlib",)),
    "open3d": ("open3d", ("open3d", "open3d-cpu")),
    "opencv": (
        "cv2",
        (
            "opencv-python-headless",
            "opencv-python",
            "opencv-contrib-python-headless",
            "opencv-contrib-python",
        ),
    ),
    "h5py": ("h5py", ("h5py",)),
    "snakemake": ("snakemake", ("snakemake",)),
    "numba": ("numba", ("numba",)),
    "pyyaml": ("yaml", ("PyYAML", "pyyaml")),
}

_MIME = {
    ".png": "image/png",
    ".gif": "image/gif",
    ".jpg": "image/jpeg",
    ".jpeg": "image/jpeg",
    ".svg": "image/svg+xml",
    ".webp": "image/webp",
}


# --------------------------------------------------------------------------- environment


def _version(import_name: str, dists: Sequence[str]) -> str:
    if importlib.util.find_spec(import_name) is None:
        return "not installed"
    for d in dists:
        try:
            return importlib.metadata.version(d)
        except importlib.metadata.PackageNotFoundError:
            continue
    try:  # importable but without distribution metadata: ask the module itself
        return str(getattr(importlib.import_module(import_name), "__version__", "unknown"))
    except Exception:  # noqa: BLE001 - a broken install is still worth a line
        return "not importable"


def software_versions() -> dict[str, str]:
    """Versions of Python, colourhs (``"dev"`` when not installed) and the key packages.

    Versions come from the installed distributions' metadata (no heavy imports);
    a package that cannot be found reads ``"not installed"``.
    """
    try:
        ours = importlib.metadata.version("colourhs")
    except importlib.metadata.PackageNotFoundError:
        ours = "dev"
    out = {"python": platform.python_version(), "colourhs": ours}
    for label, (mod, dists) in SOFTWARE.items():
        out[label] = _version(mod, dists)
    return out


def _plain(obj):
    """``obj`` with only YAML-safe types (paths, tuples, numpy values converted)."""
    if isinstance(obj, Mapping):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple | set | frozenset):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _plain(obj.tolist())
    if isinstance(obj, np.generic):
        return obj.item()
    if obj is None or isinstance(obj, bool | int | float | str):
        return obj
    return str(obj)


# --------------------------------------------------------------------------- page pieces

#: What each metric column means (units in the names), for the summary's legend.
COLUMN_LEGEND = {
    "frames": "frames of the scene evaluated",
    "hausdorff_rms_mm": "accuracy: RMS distance from the reconstructed mesh to the seen "
    "ground-truth surface (the paper's 'RMS Hausdorff distance'), mean over frames",
    "hausdorff_mean_mm": "accuracy: mean of that distance, mean over frames",
    "hausdorff_max_mm": "accuracy: largest such distance, max over frames",
    "depth_median_mm": "median |depth error| per pixel against the ground truth rendered "
    "into the reference camera, median over frames",
    "depth_rms_mm": "RMS depth error per pixel, RMS over frames",
    "normal_median_deg": "median angle between reconstructed and true normals, median over frames",
    "coverage": "share of the ground truth's pixels that have a depth, mean over frames",
}
#: The accuracy by which the summary marks each scene's best variant (lower is
#: better): the summary's first metric, the paper's RMS Hausdorff distance.
BEST_METRIC = "hausdorff_rms_mm"
#: The summary table's metric columns (those present are shown), led by :data:`BEST_METRIC`.
SUMMARY_COLUMNS = (
    "frames",
    BEST_METRIC,
    "depth_median_mm",
    "depth_rms_mm",
    "normal_median_deg",
    "coverage",
)


#: Columns a scene's metrics table shows right after another (column -> the one it
#: follows): the signed median depth error (the bias) beside the absolute one.
BESIDE = {"depth_signed_median_mm": "depth_median_mm"}


def beside(table: pd.DataFrame, pairs: Mapping[str, str] = BESIDE) -> pd.DataFrame:
    """``table`` with each column of ``pairs`` moved right after the column it names
    (where both are present; the others keep their order)."""
    cols = list(table.columns)
    for col, anchor in pairs.items():
        if col in cols and anchor in cols:
            cols.remove(col)
            cols.insert(cols.index(anchor) + 1, col)
    return table[cols]


def _data_uri(path: Path) -> str:
    mime = _MIME.get(path.suffix.lower(), "application/octet-stream")
    return f"data:{mime};base64," + base64.b64encode(path.read_bytes()).decode("ascii")


def _figure(path: Path, where: Mapping[Path, str] | None, cls: str = "") -> dict:
    """A figure for the template: src, a link to the file (when linked), caption.

    ``where`` maps each resolved image path to its path relative to the page
    (:func:`colourhs.report.assets.place_files`); None embeds the image instead.
    """
    if where is None:
        src, href = _data_uri(path), None
    else:
        src = href = where[path.resolve()]
    return {"src": src, "href": href, "caption": path.stem.replace("_", " "), "cls": cls}


def _check_figures(paths: Iterable[str | Path] | str | Path, what: str) -> list[Path]:
    """The figure files ``paths`` names; a folder stands for its images, sorted by name."""
    if isinstance(paths, str | Path):
        paths = [paths]
    out = []
    for p in paths:
        path = Path(p)
        if path.is_dir():
            out += sorted(f for f in path.iterdir() if f.suffix.lower() in _MIME and f.is_file())
            continue
        if not path.is_file():
            raise ValueError(f"{path}: {what} figure not found")
        out.append(path)
    return out


#: The summary's caption: what marks a scene's best variant.
BEST_CAPTION = (
    f"Bold and \u2605: the scene's best variant, the lowest {BEST_METRIC} "
    "(every one that ties; none where the scene has no value)."
)


def summary_table(summary: pd.DataFrame) -> str:
    """The summary as HTML: :func:`~colourhs.report.tables.html_table` of ``summary``
    (columns ``scene``, ``variant``, metrics) with each scene's best variant by
    :data:`BEST_METRIC` marked (:func:`~colourhs.report.tables.best_rows`): its row
    of class ``best`` (bold), its :data:`BEST_METRIC` cell of class ``best`` (a star),
    which :data:`BEST_CAPTION` (under the table) explains. The first row of each
    scene but the first is of class ``scene-start`` (a rule above it)."""
    best = best_rows(summary, BEST_METRIC).to_numpy()
    scenes = summary["scene"].astype(str)
    start = (scenes != scenes.shift()).to_numpy(copy=True)
    start[:1] = False
    rows = [
        " ".join(name for name, on in (("scene-start", s), ("best", b)) if on)
        for s, b in zip(start, best, strict=True)
    ]
    cells = pd.DataFrame("", index=summary.index, columns=summary.columns)
    if BEST_METRIC in cells.columns:
        cells.loc[best, BEST_METRIC] = "best"
    return html_table(summary, "summary", row_class=rows, cell_class=cells)


def variant_names(variants: Iterable[str]) -> str:
    """The paper's name of each of ``variants`` that has one (:data:`VARIANT_LABELS`),
    as one line for the summary's legend: ``"vh: VH; bayes_ph: BayesianHS_wPhCalib"``."""
    return "; ".join(f"{v}: {VARIANT_LABELS[v]}" for v in variants if v in VARIANT_LABELS)


def with_paper_columns(table: pd.DataFrame) -> tuple[pd.DataFrame, bool]:
    """``table`` (columns ``scene``, ``variant``, metrics) with, right after each metric
    the paper states, a column ``paper <metric>`` (:data:`PAPER_REFERENCE`; empty
    where the paper gives no number). Also returns whether any such column was added."""
    t = table.copy()
    scenes = set(t["scene"]) if "scene" in t.columns else set()
    refs = {s: PAPER_REFERENCE[s] for s in scenes if s in PAPER_REFERENCE}
    ref_cols = sorted({c for r in refs.values() for per in r.values() for c in per})
    for c in ref_cols:
        col = f"paper {c}"
        t[col] = [
            refs.get(s, {}).get(v, {}).get(c, np.nan)
            for s, v in zip(t["scene"], t["variant"], strict=True)
        ]
        t[col] = t[col].astype(float)
        if c in t.columns:  # right after our column
            cols = list(t.columns)
            cols.remove(col)
            cols.insert(cols.index(c) + 1, col)
            t = t[cols]
    return t, bool(ref_cols)


def _legend(summary: pd.DataFrame, columns: Sequence[str], has_paper: bool) -> dict[str, str]:
    """The summary's legend: the paper's names of its variants, what each of its
    metric ``columns`` means, and the paper's columns when it has them."""
    names = variant_names(dict.fromkeys(summary["variant"].astype(str)))
    return (
        ({"variant": f"the paper's names: {names}"} if names else {})
        | {c: COLUMN_LEGEND[c] for c in columns if c in COLUMN_LEGEND}
        | ({"paper …": "the paper's number (see below)"} if has_paper else {})
    )


def _aggregation_text(summary: pd.DataFrame) -> str:
    words = {"mean": "mean", "max": "max", "median": "median", "rms": "RMS", "sum": "sum"}
    cols = [c for c in summary.columns if c not in ("scene", "variant", "frames")]
    items = "; ".join(f"{c}: {words[_aggregation_of(c)]}" for c in cols)
    return f"Aggregation over a scene's frames: {items}."


def _same_as_note(metrics: pd.DataFrame, scene: str) -> str:
    """A note naming the variants whose rows copy another's on ``scene`` (or "")."""
    if "same_as" not in metrics.columns:
        return ""
    rows = metrics[(metrics["scene"] == scene) & metrics["same_as"].notna()]
    rows = rows[rows["same_as"].astype(str) != ""]
    pairs = sorted(
        {(str(v), str(o)) for v, o in zip(rows["variant"], rows["same_as"], strict=True)}
    )
    if not pairs:
        return ""
    text = "; ".join(f"<code>{_e(v)}</code> is <code>{_e(o)}</code>" for v, o in pairs)
    untracked = all(VARIANTS.get(o, {}).get("chromaticity") for _, o in pairs)
    why = (
        "its chromaticity does not move (no sequence of a chromatic object), so carrying "
        "it from frame to frame has nothing to change"
        if untracked
        else "it has no chromatic object, so the chromaticity calibration has nothing to change"
    )
    return f'<p class="note">{text} on this scene: {why}; computed once and copied.</p>'


def _e(s) -> str:
    return html.escape(str(s), quote=True)


def _frames_note(metrics: pd.DataFrame, scene: str, figures: Sequence[Path]) -> str:
    """Which frame the maps show, for a scene of several frames (or "")."""
    frames = sorted(metrics.loc[metrics["scene"] == scene, "frame"].astype(str).unique())
    if len(frames) < 2:
        return ""
    anim = " The animation shows every frame." if any(p.suffix == ".gif" for p in figures) else ""
    return (
        f"Sequence of {len(frames)} frames ({frames[0]} to {frames[-1]}): the tables "
        f"aggregate every frame; the maps and renders show frame {frames[0]}.{anim}"
    )


def _file_links(results_dir, scene: str, out_dir: Path, link: bool) -> dict:
    """A scene's result files for the template, by variant and kind: each one's
    label, its path in the variant's folder and, with ``link``, its path relative
    to the page (else None: named, not linked, so the report folder stands alone)."""
    files = result_files(results_dir, scene)
    every = [p for kinds in files.values() for ps in kinds.values() for p in ps]
    hrefs = link_files(every, out_dir) if link else {}
    return {
        v: {
            k: [
                {
                    "href": hrefs.get(p.resolve()),
                    "label": p.stem,
                    "path": p.relative_to(Path(results_dir, scene, v)).as_posix(),
                }
                for p in ps
            ]
            for k, ps in kinds.items()
            if ps
        }
        for v, kinds in files.items()
    }


def _template():
    import jinja2

    env = jinja2.Environment(
        loader=jinja2.PackageLoader("colourhs.report", "templates"),
        autoescape=True,
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
    )
    return env.get_template("report.html")


# --------------------------------------------------------------------------- the report


@dataclass(frozen=True)
class ReportInputs:
    """What the report shows.

    Attributes
    ----------
    metrics_csv : ``reports/NAME/metrics.csv`` of the results contract; aggregated by
        :func:`summarise_metrics`.
    calibration_pngs : calibration figures (mu maps, chromaticity maps). A folder
        stands for its images (PNG, GIF, JPEG, SVG, WebP), sorted by name.
    scene_figures : ``{scene: [figure paths]}`` (or ``{scene: folder}``), arranged by
        :func:`colourhs.report.provenance.arrange_figures`. Scenes here without
        metrics still get a section.
    benchmark_tsvs : Snakemake benchmark files; summarised per rule by
        :func:`summarise_benchmarks`.
    config : the run's configuration (a mapping, or a YAML file's path), shown as YAML.
    """

    metrics_csv: str | Path
    calibration_pngs: Sequence[str | Path] = ()
    scene_figures: Mapping[str, Sequence[str | Path]] = field(default_factory=dict)
    benchmark_tsvs: Sequence[str | Path] = ()
    config: Mapping | str | Path = field(default_factory=dict)


@dataclass(frozen=True)
class PageOptions:
    """How the report's page is made.

    Attributes
    ----------
    embed_images : embed images as base64 data URIs (one file holds the whole
        page); by default they are linked by paths relative to the page.
    link_outside : link the images and result files outside the report folder
        where they are (``../../results/...``) instead of copying the images into
        ``assets/`` and naming the result files: the page then works only beside
        ``results/``, and ``assets/`` is left as it is.
    views : embed each scene's first-frame error-coloured meshes (``results_dir``),
        simplified, in an offline 3D viewer (:func:`colourhs.report.view3d.scene_views`),
        seen first from the dataset's first camera.
    config_resolved : whether the configuration has the package's defaults filled
        in (said on the page).
    """

    embed_images: bool = False
    link_outside: bool = False
    views: bool = False
    config_resolved: bool = False


def build_report(
    out_html: str | Path,
    dataset_name: str,
    inputs: ReportInputs,
    options: PageOptions | None = None,
    *,
    extra: Mapping | None = None,
    dataset=None,
    results_dir: str | Path | None = None,
    provenance: Mapping | None = None,
    calibration_dir: str | Path | None = None,
) -> Path:
    """Write the evaluation report ``reports/NAME/index.html`` and return its path.

    The page (template ``colourhs/report/templates/report.html``) opens with a summary
    table (scene x variant, key metrics beside the paper's numbers, each scene's
    best variant marked, :func:`summary_table`, a legend);
    per scene: its description, every metric (one column per variant), its
    expected depth error (the median ``depth_sigma``, with or without ground
    truth: :func:`colourhs.report.tables.expected_error_table`) and, with ground
    truth, how well sigma predicts the error
    (:func:`colourhs.report.tables.sigma_calibration_table`) and where the
    ground truth's pixels without a depth went
    (:func:`colourhs.report.tables.drop_table`), the Figure 7 renders, error
    and sigma maps full width, the other figures as thumbnails, a per-frame
    plot for sequences and links to the result files;
    then timing, provenance, configuration and software versions.

    The report folder (``out_html``'s) stands alone: every ``src`` and ``href`` of
    the page resolves inside it. Images outside it are copied into its ``assets/``
    (:func:`colourhs.report.assets.place_files`, :func:`~colourhs.report.assets.write_assets`)
    and the result files of ``results_dir`` are named, not linked;
    ``options.link_outside`` links both where they are instead.

    Logs a line at INFO before the calibration's diagnostics and shows a bar over
    each scene's 3D views (:mod:`colourhs.common.progress`).

    Parameters
    ----------
    out_html
        Where to write the page (atomically: a temporary sibling renamed into place).
    dataset_name
        The dataset's NAME (``results/NAME``).
    inputs
        What the page shows (:class:`ReportInputs`): the metrics, the figures,
        the jobs' timings and the run's configuration.
    options
        How the page is made (:class:`PageOptions`; default: images linked,
        the folder standing alone, no 3D views).
    extra
        Further ``{label: value}`` lines for the page's header table.
    dataset
        The :class:`colourhs.capture.Dataset` (or None): its rig summary and
        the scenes' descriptions are shown.
    results_dir
        ``results/NAME`` (or None): each scene's meshes, error-coloured meshes
        and depth files are listed (linked with ``options.link_outside``).
    provenance
        ``{label: value}`` for the provenance table (default: the git commit of
        the colourhs code and this process's command line, see
        :func:`colourhs.report.provenance.git_provenance` and
        :func:`~colourhs.report.provenance.run_command`).
    calibration_dir
        ``results/NAME/calib`` (or None): the calibration's diagnostics tables
        (:func:`colourhs.report.calibration.calibration_diagnostics`: marker reprojection
        RMS, cross-talk matrices, photometric residual, mu error against the
        dataset's ``gt/photometric.h5`` when it has one).

    Raises
    ------
    ValueError
        When ``metrics_csv`` is missing or lacks contract columns (naming the file
        and the columns), or a figure or benchmark file is missing. Nothing is
        written then.
    OSError
        When an image cannot be copied or the page cannot be written; the
        report folder is left as it was then.
    """
    out = Path(out_html)
    out_dir = out.parent
    options = options or PageOptions()
    embed_images, link_outside, views = options.embed_images, options.link_outside, options.views
    metrics_csv, calibration_pngs, scene_figures, benchmark_tsvs, config = (
        inputs.metrics_csv,
        inputs.calibration_pngs,
        inputs.scene_figures,
        inputs.benchmark_tsvs,
        inputs.config,
    )
    # read and check every input before anything is written
    if views and results_dir is None:
        raise ValueError("the 3D views need results_dir (colourhs report --results): the meshes")
    metrics = read_metrics(metrics_csv)
    summary = summarise_metrics(metrics)
    calib = _check_figures(calibration_pngs, "calibration")
    figs = {str(s): _check_figures(ps, f"scene {s!r}") for s, ps in scene_figures.items()}
    bench = summarise_benchmarks(read_benchmarks(benchmark_tsvs))
    if isinstance(config, str | Path):
        config = yaml.safe_load(Path(config).read_text()) or {}
    if provenance is None:
        provenance = {**git_provenance(Path(__file__).parent), **run_command()}
    descriptions = scene_descriptions(dataset) if dataset is not None else {}
    if calibration_dir:
        stage(log, f"report: calibration diagnostics of {calibration_dir}")
    diagnostics = calibration_diagnostics(calibration_dir, dataset) if calibration_dir else []

    scenes = list(dict.fromkeys([*sorted(summary["scene"].unique()), *figs]))
    turn = dataset.rig.cameras[0].R if views and dataset is not None else None
    key = [c for c in SUMMARY_COLUMNS if c in summary.columns]
    top, has_paper = with_paper_columns(summary[["scene", "variant", *key]])
    images = [*calib, *(p for ps in figs.values() for p in ps)]
    if embed_images:
        where = None
    elif link_outside:
        where = link_files(images, out_dir)
    else:
        where = place_files(images, out_dir)
    sections = []
    for scene in scenes:
        arranged = arrange_figures(figs.get(scene, []))
        s = {
            "name": scene,
            "description": descriptions.get(scene, ""),
            "table": "",
            "frames_note": _frames_note(metrics, scene, figs.get(scene, [])),
            "plot": frame_error_svg(metrics, scene),
            "plot_caption": "Median depth error per frame and variant (depth_median_mm, mm).",
            **{
                k: [_figure(p, where, "wide" if k == "wide" else "") for p in ps]
                for k, ps in arranged.items()
            },
        }
        rows = summary[summary["scene"] == scene]
        expected, calibration = expected_error_table(rows), sigma_calibration_table(rows)
        s["expected"] = html_table(expected, "metrics") if len(expected) else ""
        s["sigma_calibration"] = html_table(calibration, "metrics") if len(calibration) else ""
        dropped = drop_table(metrics[metrics["scene"].astype(str) == scene])
        s["dropped"] = html_table(dropped, "metrics turned-heads") if len(dropped) else ""
        if len(rows):
            t, _ = with_paper_columns(beside(rows))
            turned = by_variant(t.drop(columns="scene"))
            s["table"] = html_table(turned, "metrics")
            s["n_metrics"] = len(turned)
            s["aggregation"] = _aggregation_text(summary)
            s["same_as"] = _same_as_note(metrics, scene)
        s["files"] = _file_links(results_dir, scene, out_dir, link_outside) if results_dir else {}
        s["files_root"] = Path(results_dir, scene).as_posix() if results_dir else ""
        s["files_linked"] = link_outside
        s["views"] = scene_views(results_dir, scene, rotation=turn) if views else {}
        s["n_files"] = sum(len(ls) for k in s["files"].values() for ls in k.values())
        sections.append(s)

    env = dict(software_versions())
    env["platform"] = platform.platform()
    env["python executable"] = sys.executable
    env["CPU count"] = os.cpu_count() or "unknown"
    header = {
        "dataset": dataset_name,
        "generated": datetime.now(UTC).strftime("%Y-%m-%d %H:%M:%S UTC"),
    }
    header.update({str(k): v for k, v in (extra or {}).items()})
    page = _template().render(
        name=dataset_name,
        header=header,
        reproduce=provenance.get("workflow command")
        or f"colourhs run DATASET_DIR --name {dataset_name}",
        summary_table=summary_table(top) if len(top) else "",
        best_caption=BEST_CAPTION,
        has_paper=has_paper,
        legend=_legend(top, key, has_paper),
        paper_source=PAPER_REFERENCE_SOURCE,
        calibration=[_figure(p, where) for p in calib],
        diagnostics=[{**d, "table": html_table(d["table"], "bench")} for d in diagnostics],
        scenes=sections,
        timing_table=html_table(bench, "bench") if not bench.empty else "",
        provenance=provenance,
        rig=rig_summary(dataset) if dataset is not None else {},
        env=env,
        config_resolved=options.config_resolved,
        config_yaml=yaml.safe_dump(_plain(config), sort_keys=False, allow_unicode=True),
    )
    if where is not None and not link_outside:  # embedded images need no copies
        write_assets(where, out_dir)
    with atomic_output(out) as tmp:
        tmp.write_text(page, encoding="utf-8")
    return out
