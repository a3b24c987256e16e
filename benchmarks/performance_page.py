"""The measured figures, gathered: ``docs/performance.md`` and the README's table.

Run: ``.venv/bin/python benchmarks/performance_page.py`` after the benchmarks it
reads; it renders nothing and measures nothing itself. Sources, each read when
present in ``benchmarks/results/`` (a missing one leaves its section out):

- ``pipeline_demo*.json`` (:mod:`bench_pipeline`): the README's main job, wall
  time on the machine's cores, every run found (their spread), and the rules
  that take the time;
- ``generalisation_summary.json`` (:mod:`generalisation`), or the summaries
  named with ``--generalisation``: accuracy on randomised and corner rigs (a
  set named twice: the later file), each scene with the variant a rig owner
  runs (:data:`generalisation.TARGETS`), median over the rigs / worst rig, and
  the depth error bar's calibration.

The README's table sits between the markers ``<!-- performance -->`` and
``<!-- /performance -->``; ``--check`` exits 1 when either file is not what
this script would write.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
START, END = "<!-- performance -->", "<!-- /performance -->"


def own_variants() -> dict[str, str]:
    """Scene -> the variant its accuracy targets are set on (generalisation.TARGETS)."""
    sys.path.insert(0, str(HERE))
    from generalisation import TARGETS

    return {scene: variant for scene, variant, _ in TARGETS}


def pipeline_runs(results: Path) -> list[dict]:
    """Every ``pipeline_demo*.json`` run, oldest file first."""
    files = sorted(results.glob("pipeline_demo*.json"), key=lambda p: p.stat().st_mtime)
    return [json.loads(p.read_text()) | {"file": p.name} for p in files]


def generalisation_sets(files: list[Path]) -> dict[str, dict]:
    """Set name -> its summary (with ``file``), from the last of ``files`` holding the set."""
    out: dict[str, dict] = {}
    for path in (f for f in files if f.exists()):
        for name, summary in json.loads(path.read_text()).get("sets", {}).items():
            out[name] = summary | {"file": path.name}
    return out


def _pair(entry: dict | None, fmt: str) -> str:
    if not entry or entry.get("median") is None:
        return "-"
    worst = entry.get("worst")
    return f"{entry['median']:{fmt}} / {worst:{fmt}}" if worst is not None else "-"


def _minutes(walls: list[float]) -> str:
    """ "14.3 min (1 run)" or "14.3-19.4 min (2 runs)": the runs' spread."""
    span = f"{min(walls):.1f}" if len(walls) == 1 else f"{min(walls):.1f}-{max(walls):.1f}"
    return f"{span} min ({len(walls)} run{'s' if len(walls) > 1 else ''})"


def pipeline_lines(runs: list[dict]) -> list[str]:
    walls = [r["wall_s"] / 60 for r in runs if r.get("rendered")]
    if not walls:
        return []
    last = [r for r in runs if r.get("rendered")][-1]
    rules = sorted(last["rules"], key=lambda r: -float(r.get("total_s") or r.get("seconds") or 0))
    lines = [
        "## The main job",
        "",
        f"`snakemake --cores 2` from nothing (the synthetic demo rendered, then every job) "
        f"on {last.get('cpu_count')} cores: {_minutes(walls)} (`{last['file']}`"
        + (f", commit {last['commit']}" if last.get("commit") else "")
        + ").",
        "",
    ]
    if rules:
        keys = [k for k in rules[0] if k != "rule"]
        lines += ["| rule | " + " | ".join(keys) + " |", "|---" * (len(keys) + 1) + "|"]
        for r in rules[:8]:
            lines.append(f"| {r.get('rule')} | " + " | ".join(str(r[k]) for k in keys) + " |")
        lines.append("")
    return lines


def accuracy_lines(sets: dict[str, dict], own: dict[str, str]) -> list[str]:
    if not sets:
        return []
    lines = [
        "## Accuracy on randomised and corner rigs",
        "",
        "Every nuisance on, every calibration from the pipeline; median over the set's "
        "rigs / worst rig. Signed: reconstructed minus true depth (a bias).",
        "",
    ]
    for name, s in sets.items():
        lines += [
            f"### `{name}` (seeds {', '.join(map(str, s.get('seeds', [])))}; `{s['file']}`)",
            "",
            "| scene | variant | depth median (mm) | signed median (mm) | RMS (mm) "
            "| normal median (deg) | coverage |",
            "|---|---|---|---|---|---|---|",
        ]
        for scene, variant in own.items():
            m = s.get("scenes", {}).get(scene, {}).get(variant)
            if m is None:
                continue
            lines.append(
                f"| {scene} | {variant} | {_pair(m.get('depth_median_mm'), '.3f')} "
                f"| {_pair(m.get('depth_signed_median_mm'), '+.3f')} "
                f"| {_pair(m.get('depth_rms_mm'), '.3f')} "
                f"| {_pair(m.get('normal_median_deg'), '.2f')} "
                f"| {_pair(m.get('coverage'), '.3f')} |"
            )
        calib = s.get("sigma_calibration", {})
        rows = [
            f"| {v} | "
            + " | ".join(f"{c[f'sigma_within_{k}']['mean']:.3f}" for k in (1, 2, 3))
            + " |"
            for v, c in calib.items()
            if all(f"sigma_within_{k}" in c for k in (1, 2, 3))
        ]
        if rows:
            lines += [
                "",
                "Depth error bar: share of pixels within 1 / 2 / 3 sigma (Gaussian: "
                "0.683 / 0.954 / 0.997).",
                "",
                "| variant | 1 sigma | 2 sigma | 3 sigma |",
                "|---|---|---|---|",
                *rows,
            ]
        lines.append("")
    return lines


def readme_table(runs: list[dict], sets: dict[str, dict], own: dict[str, str]) -> list[str]:
    """The README's few lines: main-job time and depth accuracy on the random set."""
    lines = ["| figure | measured |", "|---|---|"]
    walls = [r["wall_s"] / 60 for r in runs if r.get("rendered")]
    if walls:
        lines.append(f"| main job from nothing, 2 cores | {_minutes(walls)} |")
    random = sets.get("random")
    for scene, variant in own.items():
        m = (random or {}).get("scenes", {}).get(scene, {}).get(variant)
        if m:
            lines.append(
                f"| {scene} depth error, random rigs ({variant}) | "
                f"{_pair(m.get('depth_median_mm'), '.2f')} mm, signed "
                f"{_pair(m.get('depth_signed_median_mm'), '+.2f')} mm (median / worst rig) |"
            )
    lines.append("")
    lines.append("More, and how each was measured: [docs/performance.md](docs/performance.md).")
    return lines


def page(runs, sets, own) -> str:
    lines = [
        "# Performance",
        "",
        "Generated by `benchmarks/performance_page.py` from the benchmarks' outputs in "
        "`benchmarks/results/`; do not edit by hand. Each benchmark's docstring says "
        "how to run it.",
        "",
        *pipeline_lines(runs),
        *accuracy_lines(sets, own),
    ]
    return "\n".join(lines).rstrip("\n") + "\n"


def with_readme_table(readme: str, table: list[str]) -> str:
    """``readme`` with the text between the markers replaced by ``table``."""
    if START not in readme or END not in readme:
        raise ValueError(f"README.md: the markers {START} and {END} are missing")
    head, rest = readme.split(START, 1)
    _, tail = rest.split(END, 1)
    return head + START + "\n" + "\n".join(table) + "\n" + END + tail


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--results", type=Path, default=HERE / "results")
    p.add_argument(
        "--generalisation",
        type=Path,
        nargs="+",
        default=None,
        help="generalisation summaries (default RESULTS/generalisation_summary.json)",
    )
    p.add_argument("--check", action="store_true", help="exit 1 if a file would change")
    args = p.parse_args(argv)
    summaries = args.generalisation or [args.results / "generalisation_summary.json"]
    runs, sets, own = pipeline_runs(args.results), generalisation_sets(summaries), own_variants()
    targets = {
        ROOT / "docs" / "performance.md": page(runs, sets, own),
        ROOT / "README.md": with_readme_table(
            (ROOT / "README.md").read_text(), readme_table(runs, sets, own)
        ),
    }
    stale = [p for p, text in targets.items() if not p.exists() or p.read_text() != text]
    if args.check:
        for path in stale:
            print(f"{path.relative_to(ROOT)}: not what benchmarks/performance_page.py writes")
        return 1 if stale else 0
    for path, text in targets.items():
        path.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
