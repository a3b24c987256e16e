"""The evaluation report ``reports/NAME/index.html``: one self-contained HTML page.

:func:`build_report` gathers what earlier stages wrote (the metrics table of the
results contract, the calibration and per-scene figures, Snakemake benchmark
files, the run's configuration) into one page that needs no network and no
files beside it: images (PNG, GIF, JPEG, SVG) are embedded as base64 data URIs,
styles are inline. The page is built in memory and written atomically, so a
failure leaves no partial HTML behind.

The tables are computed by the small functions :func:`summarise_metrics`,
:func:`read_benchmarks` and :func:`summarise_benchmarks`, which the tests call
directly; they live in :mod:`colourhs.reporttables` (reading and summarising
``metrics.csv`` and the benchmark files) and are re-exported here. This module
holds the page itself: the paper's reference numbers, the software versions
and the HTML.
"""

from __future__ import annotations

import base64
import html
import importlib.metadata
import importlib.util
import os
import platform
import sys
from collections.abc import Iterable, Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from colourhs.io import atomic_output
from colourhs.reporttables import (
    AGGREGATION,
    BENCHMARK_COLUMNS,
    METRIC_COLUMNS,
    REQUIRED_COLUMNS,
    _aggregation_of,
    find_benchmarks,
    format_number,
    read_benchmarks,
    read_metrics,
    summarise_benchmarks,
    summarise_metrics,
)
from colourhs.variants import VARIANT_LABELS, VARIANT_ORDER

__all__ = [
    "AGGREGATION",
    "BENCHMARK_COLUMNS",
    "METRIC_COLUMNS",
    "PAPER_REFERENCE",
    "PAPER_REFERENCE_SOURCE",
    "REQUIRED_COLUMNS",
    "VARIANT_LABELS",
    "VARIANT_ORDER",
    "build_report",
    "find_benchmarks",
    "format_number",
    "read_benchmarks",
    "read_metrics",
    "software_versions",
    "summarise_benchmarks",
    "summarise_metrics",
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
    "pymeshlab": ("pymeshlab", ("pymeshlab",)),
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

_CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", Helvetica, Arial, sans-serif;
       margin: 2em auto; max-width: 72em; padding: 0 1em; color: #222; line-height: 1.4; }
h1 { margin-bottom: 0.2em; }
h2 { border-bottom: 2px solid #ddd; padding-bottom: 0.2em; margin-top: 2em; }
code, pre { font-family: ui-monospace, Menlo, Consolas, monospace; font-size: 0.9em; }
pre { background: #f6f8fa; padding: 0.8em; overflow-x: auto; border-radius: 4px; }
table.metrics, table.bench, table.kv { border-collapse: collapse; margin: 0.8em 0;
       font-size: 0.9em; }
table.metrics th, table.metrics td, table.bench th, table.bench td, table.kv th, table.kv td {
       border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: right; }
table.metrics th, table.bench th, table.kv th { background: #f0f0f0; }
table.metrics td:first-child, table.metrics td:nth-child(2), table.bench td:first-child,
table.kv td, table.kv th { text-align: left; }
span.paper { background: #fff7e0; }
.meta { color: #555; }
.note { color: #555; font-size: 0.9em; }
.figures { display: flex; flex-wrap: wrap; gap: 1em; }
figure { margin: 0; max-width: 100%; }
figure img { max-width: 100%; height: auto; border: 1px solid #eee; }
figcaption { font-size: 0.85em; color: #444; text-align: center; }
"""


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


# --------------------------------------------------------------------------- html pieces


def _e(s) -> str:
    return html.escape(str(s), quote=True)


def _image_src(path: Path, out_dir: Path, embed: bool) -> str:
    if not embed:
        return Path(os.path.relpath(path.resolve(), out_dir.resolve())).as_posix()
    mime = _MIME.get(path.suffix.lower(), "application/octet-stream")
    return f"data:{mime};base64," + base64.b64encode(path.read_bytes()).decode("ascii")


def _caption(path: Path) -> str:
    return path.stem.replace("_", " ")


def _figure(path: Path, out_dir: Path, embed: bool, caption: str | None = None) -> str:
    cap = caption if caption is not None else _caption(path)
    return (
        f'<figure><img src="{_e(_image_src(path, out_dir, embed))}" alt="{_e(cap)}">'
        f"<figcaption>{_e(cap)}<br><code>{_e(path.name)}</code></figcaption></figure>"
    )


def _figures(paths: Sequence[Path], out_dir: Path, embed: bool) -> str:
    if not paths:
        return '<p class="note">No figures.</p>'
    return '<div class="figures">' + "".join(_figure(p, out_dir, embed) for p in paths) + "</div>"


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


def _table(df: pd.DataFrame, css_class: str) -> str:
    """``DataFrame.to_html`` with escaping, empty NaN cells and :func:`format_number`."""
    return df.to_html(
        classes=css_class,
        index=False,
        na_rep="",
        float_format=format_number,
        escape=True,
        border=0,
    )


def _kv_table(items: Mapping) -> str:
    rows = "".join(f"<tr><th>{_e(k)}</th><td>{_e(v)}</td></tr>" for k, v in items.items())
    return f'<table class="kv">{rows}</table>'


def _scene_table(summary: pd.DataFrame, scene: str) -> tuple[str, bool]:
    """The HTML table of one scene's variants, with the paper's numbers beside ours."""
    t = summary[summary["scene"] == scene].drop(columns="scene").copy()
    t.insert(1, "paper name", t["variant"].map(VARIANT_LABELS).fillna(""))
    ref = PAPER_REFERENCE.get(scene, {})
    ref_cols = sorted({c for per_variant in ref.values() for c in per_variant})
    for c in ref_cols:
        col = f"paper {c}"
        t[col] = t["variant"].map(lambda v, c=c: ref.get(v, {}).get(c, np.nan)).astype(float)
        # put the paper's column right after ours
        if c in t.columns:
            cols = list(t.columns)
            cols.remove(col)
            cols.insert(cols.index(c) + 1, col)
            t = t[cols]
    return _table(t, "metrics"), bool(ref_cols)


def _aggregation_legend(summary: pd.DataFrame) -> str:
    words = {
        "mean": "mean over frames",
        "max": "max over frames",
        "median": "median over frames",
        "rms": "RMS over frames, sqrt(mean(x²))",
        "sum": "sum over frames",
    }
    cols = [c for c in summary.columns if c not in ("scene", "variant", "frames")]
    items = "; ".join(f"<code>{_e(c)}</code>: {_e(words[_aggregation_of(c)])}" for c in cols)
    return (
        f'<p class="note">Aggregation over a scene\'s frames: {items}. '
        "Empty cells: no value (e.g. a scene without ground truth).</p>"
    )


# --------------------------------------------------------------------------- the report


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
    return (
        f'<p class="note">{text} on this scene: it has no chromatic object, so the '
        "chromaticity calibration has nothing to change; computed once and copied.</p>"
    )


def build_report(
    out_html: str | Path,
    dataset_name: str,
    metrics_csv: str | Path,
    calibration_pngs: Sequence[str | Path],
    scene_figures: Mapping[str, Sequence[str | Path]],
    benchmark_tsvs: Sequence[str | Path],
    config: Mapping | str | Path,
    extra: Mapping | None = None,
    *,
    embed_images: bool = True,
) -> Path:
    """Write the evaluation report ``reports/NAME/index.html`` and return its path.

    Parameters
    ----------
    out_html
        Where to write the page (atomically: a temporary sibling renamed into place).
    dataset_name
        The dataset's NAME (``results/NAME``).
    metrics_csv
        ``reports/NAME/metrics.csv`` of the results contract; aggregated by
        :func:`summarise_metrics`, one table per scene.
    calibration_pngs
        Calibration figures (mu maps, chromaticity maps), shown with their file
        names as captions. A folder stands for its images (PNG, GIF, JPEG, SVG,
        WebP), sorted by name.
    scene_figures
        ``{scene: [figure paths]}`` (or ``{scene: folder}``): grid renders, error
        maps, animation GIFs. Scenes here without metrics still get a section.
    benchmark_tsvs
        Snakemake benchmark files ``benchmarks/snakemake/<rule>/...``; summarised
        per rule by :func:`summarise_benchmarks` (see :func:`find_benchmarks`).
    config
        The run's configuration (a mapping, or a YAML file's path), shown as YAML.
    extra
        Further ``{label: value}`` lines for the page's header table (e.g. the
        dataset folder, a git commit).
    embed_images
        Embed images as base64 data URIs (default: the page stands alone); if
        false, link them by paths relative to the page.

    Raises
    ------
    ValueError
        When ``metrics_csv`` is missing or lacks contract columns (naming the file
        and the columns), or a figure or benchmark file is missing. Nothing is
        written then.
    """
    out = Path(out_html)
    out_dir = out.parent
    # read and check every input before anything is written
    metrics = read_metrics(metrics_csv)
    summary = summarise_metrics(metrics)
    calib = _check_figures(calibration_pngs, "calibration")
    figs = {str(s): _check_figures(ps, f"scene {s!r}") for s, ps in scene_figures.items()}
    bench = summarise_benchmarks(read_benchmarks(benchmark_tsvs))
    if isinstance(config, str | Path):
        config = yaml.safe_load(Path(config).read_text()) or {}
    config_yaml = yaml.safe_dump(_plain(config), sort_keys=False, allow_unicode=True)
    versions = software_versions()
    generated = datetime.now(UTC).strftime("%Y-%m-%d %H:%M:%S UTC")

    scenes = list(dict.fromkeys([*sorted(summary["scene"].unique()), *figs]))
    name = _e(dataset_name)
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>Colour HS evaluation: {name}</title>",
        f"<style>{_CSS}</style></head><body>",
        f"<h1>Colour Helmholtz Stereopsis: evaluation of <code>{name}</code></h1>",
    ]
    header = {"dataset": dataset_name, "generated": generated}
    header.update({str(k): v for k, v in (extra or {}).items()})
    parts.append(_kv_table(header))
    parts.append(
        '<p class="meta">Reproduce with <code>colourhs run DATASET_DIR --name '
        f"{name}</code> (writes <code>results/{name}/</code> and "
        f"<code>reports/{name}/</code>).</p>"
    )

    # contents
    toc = ['<li><a href="#calibration">Calibration</a></li>']
    toc += [f'<li><a href="#scene-{_e(s)}">Scene {_e(s)}</a></li>' for s in scenes]
    toc += ['<li><a href="#timing">Timing</a></li>', '<li><a href="#env">Configuration</a></li>']
    parts.append("<nav><ul>" + "".join(toc) + "</ul></nav>")

    # 1. calibration
    parts.append('<h2 id="calibration">Calibration</h2>')
    parts.append(
        '<p class="note">Photometric calibration: mu maps per camera and light colour '
        "(eq. 8); surface chromaticity per camera (eq. 12).</p>"
    )
    parts.append(_figures(calib, out_dir, embed_images))

    # 2. scenes
    for scene in scenes:
        parts.append(f'<h2 id="scene-{_e(scene)}">Scene <code>{_e(scene)}</code></h2>')
        if (summary["scene"] == scene).any():
            table, has_ref = _scene_table(summary, scene)
            parts.append(table)
            parts.append(_same_as_note(metrics, scene))
            parts.append(_aggregation_legend(summary))
            if has_ref:
                parts.append(
                    '<p class="note"><span class="paper">Columns "paper …"</span>: the '
                    f"paper's numbers for a real capture of this scene, not this dataset "
                    f"({_e(PAPER_REFERENCE_SOURCE)})</p>"
                )
        else:
            parts.append('<p class="note">No metrics for this scene.</p>')
        parts.append(_figures(figs.get(scene, []), out_dir, embed_images))

    # 3. timing
    parts.append('<h2 id="timing">Timing per stage</h2>')
    if bench.empty:
        parts.append('<p class="note">No benchmark files.</p>')
    else:
        parts.append(_table(bench, "bench"))
        parts.append(
            '<p class="note">From Snakemake <code>benchmark:</code> files: wall-clock '
            "seconds (<code>s</code>), CPU seconds, peak resident memory "
            "(<code>max_rss</code>, MB); row <code>all</code> totals every rule.</p>"
        )

    # 4. configuration and software
    parts.append('<h2 id="env">Configuration and software</h2>')
    parts.append(f"<pre>{_e(config_yaml)}</pre>")
    env = dict(versions)
    env["platform"] = platform.platform()
    env["python executable"] = sys.executable
    env["CPU count"] = os.cpu_count() or "unknown"
    parts.append(_kv_table(env))
    parts.append("</body></html>")

    with atomic_output(out) as tmp:
        tmp.write_text("\n".join(parts) + "\n", encoding="utf-8")
    return out
