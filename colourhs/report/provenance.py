"""What the evaluation report says beside its tables: provenance, the rig, files, figures.

Small functions that :func:`colourhs.report.page.build_report` calls and the tests
call directly: :func:`git_provenance` (commit and dirty flag of the project
checkout), :func:`run_command` (the command that made the report),
:func:`resolve_config` (the run's configuration with the package's defaults
filled in), :func:`rig_summary` and :func:`scene_descriptions` (from a
:class:`colourhs.capture.Dataset`), :func:`result_files` (a scene's meshes,
error-coloured meshes and depth files, results contract layout),
:func:`arrange_figures` (which figures are shown full width, which as
thumbnails) and :func:`frame_error_svg` (a metric over a sequence's frames,
per variant, as inline SVG).
"""

from __future__ import annotations

import io
import os
import re
import shlex
import subprocess
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from colourhs.workflow.variants import VARIANT_ORDER

__all__ = [
    "COMMAND_ENV",
    "WIDE_FIGURES",
    "arrange_figures",
    "frame_error_svg",
    "git_provenance",
    "resolve_config",
    "result_files",
    "rig_summary",
    "run_command",
    "scene_descriptions",
]

#: Environment variable in which ``colourhs run`` records its own command line,
#: so that the report (a job of the workflow it starts) can name it.
COMMAND_ENV = "COLOURHS_RUN_COMMAND"

#: Figures shown full width, in this order (file stems; the depth sigma map right
#: after the depth-error map it reads beside); every other figure is a thumbnail,
#: except per-variant error maps (``<variant>_*_error``), shown as larger tiles.
WIDE_FIGURES = ("figure7", "depth_error", "depth_sigma", "normal_error", "hausdorff")


def git_provenance(project_dir: str | Path) -> dict[str, str]:
    """The git commit of ``project_dir`` and whether its work tree has changes.

    Returns ``{"git commit": <40 hex digits>, "git work tree": "clean" or
    "modified (N files)"}``, or ``{"git commit": "not a git checkout"}`` when
    ``project_dir`` is not in one (or git is not installed).
    """

    def git(*args: str) -> str:
        return subprocess.run(
            ["git", "-C", str(project_dir), *args],
            capture_output=True,
            text=True,
            check=True,
            timeout=30,
        ).stdout

    try:
        commit = git("rev-parse", "HEAD").strip()
        changed = [line for line in git("status", "--porcelain").splitlines() if line.strip()]
    except (OSError, subprocess.SubprocessError):
        return {"git commit": "not a git checkout"}
    state = f"modified ({len(changed)} files)" if changed else "clean"
    return {"git commit": commit, "git work tree": state}


def run_command(argv: Sequence[str] | None = None) -> dict[str, str]:
    """The commands that made the report: ``colourhs run`` (when it started the
    workflow, from :data:`COMMAND_ENV`) and this process's own command line."""
    argv = list(sys.argv if argv is None else argv)
    if argv and argv[0].endswith("__main__.py"):
        argv[0] = "colourhs"
    out = {}
    if os.environ.get(COMMAND_ENV):
        out["workflow command"] = os.environ[COMMAND_ENV]
    out["report command"] = shlex.join(argv)
    return out


def resolve_config(
    config: Mapping,
    reconstruct_defaults: Mapping | None = None,
    photometric_defaults: Mapping | None = None,
) -> dict:
    """``config`` with the package's defaults in place of empty settings.

    ``reconstruction.params`` becomes ``reconstruct_defaults`` updated by the
    configured values, and ``calibration.photometric`` ``photometric_defaults``
    updated by its non-null values; a dataset's own
    ``datasets.<name>.calibration.photometric`` becomes that result updated by
    its non-null values. Everything else is copied as it is (``config`` is not
    changed).
    """
    out = {k: v for k, v in config.items()}

    def merged(defaults, given):
        given = dict(given or {})
        return {**dict(defaults), **{k: v for k, v in given.items() if v is not None}}

    if reconstruct_defaults is not None:
        rec = dict(out.get("reconstruction") or {})
        rec["params"] = merged(reconstruct_defaults, rec.get("params"))
        out["reconstruction"] = rec
    if photometric_defaults is not None:
        cal = dict(out.get("calibration") or {})
        cal["photometric"] = merged(photometric_defaults, cal.get("photometric"))
        out["calibration"] = cal
        datasets = {}
        for name, entry in (out.get("datasets") or {}).items():
            own = (entry or {}).get("calibration") or {}
            if "photometric" in own:
                own = {**own, "photometric": merged(cal["photometric"], own["photometric"])}
                entry = {**entry, "calibration": own}
            datasets[name] = entry
        if datasets:
            out["datasets"] = datasets
    return out


def rig_summary(dataset) -> dict[str, str]:
    """One-line facts of a dataset's rig (a :class:`colourhs.capture.Dataset`).

    Keys: ``dataset folder``, ``cameras`` (name and light colour each),
    ``image`` (width x height, bit depth), ``calibration poses``,
    ``chromatic objects``, ``frames per scene``, ``lights`` (collocated, or how
    far beside the lenses and the reciprocity defect that costs,
    :func:`colourhs.capture.rig.light_offset_warning`).
    """
    rig = dataset.rig
    cams = ", ".join(f"{c.name} ({c.light_colour} light)" for c in rig.cameras)
    im = rig.image
    frames = ", ".join(f"{n}: {len(s.frames)}" for n, s in dataset.scenes.items())
    return {
        "dataset folder": str(dataset.root),
        "cameras": f"{len(rig.cameras)}: {cams}",
        "image": f"{im.width} x {im.height} px, {im.bit_depth} bit",
        "calibration poses": str(len(dataset.poses)),
        "chromatic objects": ", ".join(dataset.chromatic_objects) or "none",
        "frames per scene": frames,
        "lights": _lights_line(rig),
    }


def _lights_line(rig) -> str:
    """Where the rig's lights are, and what a light beside its lens costs."""
    from colourhs.capture.rig import light_offset_warning, reciprocity_defect_deg

    offset = max(float(np.linalg.norm(c.light_offset)) for c in rig.cameras)
    if offset == 0:
        return "at the lens centres (collocated, as Helmholtz reciprocity assumes)"
    defect = reciprocity_defect_deg(rig)
    text = f"up to {offset * 1e3:.0f} mm beside the lenses"
    if defect is not None:
        text += f"; the reciprocal pairs' half-vectors up to {defect:.2f} deg apart"
    if light_offset_warning(rig):
        text += " (over the tolerance: a glossy surface's depth can be off by more than its sigma)"
    return text


def scene_descriptions(dataset) -> dict[str, str]:
    """Scene -> one line from its ``scene.json`` (description, static or dynamic, the
    chromatic object, ground truth)."""
    out = {}
    for name, s in dataset.scenes.items():
        kind = f"dynamic, {len(s.frames)} frames" if s.dynamic else "static"
        facts = [
            kind,
            f"chromatic object {s.chromatic}" if s.chromatic else "white surface",
            "ground truth" if s.has_gt else "no ground truth",
        ]
        text = s.description.strip()
        out[name] = (f"{text} ({'; '.join(facts)})" if text else "; ".join(facts)).strip()
    return out


def result_files(results_dir: str | Path, scene: str) -> dict[str, dict[str, list[Path]]]:
    """A scene's result files by variant: ``{variant: {"mesh": [...], "error-coloured
    mesh": [...], "depth": [...]}}`` (results contract: ``<variant>/mesh/<frame>.ply``,
    ``<variant>/eval/<frame>.ply``, ``<variant>/depth/<frame>.h5``), sorted by frame;
    variants in the paper's order, then others by name. Empty when the folder is missing.
    """
    root = Path(results_dir) / scene
    if not root.is_dir():
        return {}
    kinds = {
        "mesh": ("mesh", ".ply"),
        "error-coloured mesh": ("eval", ".ply"),
        "depth": ("depth", ".h5"),
    }
    names = sorted(p.name for p in root.iterdir() if p.is_dir())
    order = [v for v in VARIANT_ORDER if v in names] + [v for v in names if v not in VARIANT_ORDER]
    out = {}
    for v in order:
        files = {k: sorted((root / v / sub).glob(f"*{ext}")) for k, (sub, ext) in kinds.items()}
        if any(files.values()):
            out[v] = files
    return out


def _variant_rank(stem: str) -> tuple[int, str]:
    for i, v in enumerate(VARIANT_ORDER):
        if stem.startswith(v + "_"):
            return i, stem[len(v) + 1 :]
    return len(VARIANT_ORDER), stem


def arrange_figures(paths: Sequence[Path]) -> dict[str, list[Path]]:
    """Split a scene's figures into ``wide`` (:data:`WIDE_FIGURES`, in that order),
    ``errors`` (per-variant ``*_error`` maps) and ``thumbs`` (the rest); the latter
    two grouped by kind (the name after the variant), variants in the paper's order."""
    wide = sorted(
        (p for p in paths if p.stem in WIDE_FIGURES), key=lambda p: WIDE_FIGURES.index(p.stem)
    )
    rest = [p for p in paths if p.stem not in WIDE_FIGURES]

    def key(p):
        rank, kind = _variant_rank(p.stem)
        return kind, rank, p.name

    errors = sorted((p for p in rest if re.search(r"_error$", p.stem)), key=key)
    thumbs = sorted((p for p in rest if p not in errors), key=key)
    return {"wide": wide, "errors": errors, "thumbs": thumbs}


def frame_error_svg(metrics: pd.DataFrame, scene: str, column: str = "depth_median_mm") -> str:
    """Inline SVG: ``column`` over the frames of ``scene``, one line per variant; "" when
    the scene has one frame or no finite value of ``column``."""
    rows = metrics[metrics["scene"].astype(str) == scene]
    if column not in rows.columns or rows["frame"].nunique() < 2:
        return ""
    values = pd.to_numeric(rows[column], errors="coerce")
    if not np.isfinite(values).any():
        return ""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    table = rows.assign(v=values).pivot_table(index="frame", columns="variant", values="v")
    variants = [v for v in VARIANT_ORDER if v in table.columns]
    variants += [v for v in table.columns if v not in variants]
    x = np.array([int(f) if str(f).isdigit() else i for i, f in enumerate(table.index)])
    fig, ax = plt.subplots(figsize=(10.0, 2.6), layout="constrained")
    for v in variants:
        ax.plot(x, table[v].to_numpy(float), marker=".", label=v)
    ax.set_xlabel("frame")
    ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(integer=True))
    ax.set_ylabel(column.replace("_mm", " (mm)").replace("_", " "))
    ax.grid(alpha=0.3)
    fig.legend(fontsize="small", loc="outside right upper")  # beside the lines, not on them
    buf = io.StringIO()
    fig.savefig(buf, format="svg")
    plt.close(fig)
    svg = buf.getvalue()
    return svg[svg.index("<svg") :]
