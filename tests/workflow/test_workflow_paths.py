"""colourhs.workflow.paths: the results layout, the one source of the workflow's paths.

Its templates against the contract of docs/results-layout.md; :func:`fill`; that the
rules and the rest of ``colourhs/workflow/`` write no path of their own (no string
literal under the folders the workflow writes); and that every job of a dry run (on
the capture tests' small dataset, tests/capture_helpers.py, beside the project's
synthetic one, not rendered) writes, logs and times to the templates filled with
its wildcards and reads and passes on results only at the templates.
"""

from __future__ import annotations

import ast
import json
import re
import subprocess
import sys
import tokenize
from pathlib import Path

import pytest
import yaml
from capture_helpers import add_geometric, make_dataset

from colourhs.cli.parser import PROJECT_ROOT, SNAKEFILE
from colourhs.workflow import paths
from colourhs.workflow.paths import (
    CHROMATICITY,
    DEPTH,
    HULL,
    MARKER_POSES,
    MESH,
    METRICS,
    PHOTOMETRIC,
    REPORT,
    VH_DEPTH,
    fill,
    wildcards,
)

#: Every template of the module.
TEMPLATES = sorted(
    {v for k, v in vars(paths).items() if k.isupper() and isinstance(v, str)}
    | set(paths.LOGS.values())
    | set(paths.BENCHMARKS.values())
    | set(paths.FRAME_RESULTS.values())
)
#: The folders the workflow writes, as a path literal would start (not inside a
#: longer name: ``../report/`` and ``--results`` are none).
PATH_LITERAL = re.compile(
    r"(?<![\w./-])(results|reports|logs|benchmarks|data/synthetic)(?=/|[\"']|$)"
)
#: The rules' source files.
RULE_FILES = [PROJECT_ROOT / "Snakefile", *sorted((PROJECT_ROOT / "workflow/rules").glob("*.smk"))]


def as_documented(template: str) -> str:
    """A template as docs/results-layout.md writes it: NAME, <scene>, <frame>, ..."""
    return re.sub(r"\{(\w+)\}", lambda m: "NAME" if m[1] == "name" else f"<{m[1]}>", template)


def matches_a_template(path: str) -> bool:
    """Whether a concrete path is one of the templates with some values filled in."""
    for template in TEMPLATES:
        parts = re.split(r"(\{\w+\})", template)
        regex = "".join("[^/]+" if re.fullmatch(r"\{\w+\}", p) else re.escape(p) for p in parts)
        if re.fullmatch(regex, path):
            return True
    return False


# --------------------------------------------------------------------------- the module


def test_templates_are_the_documented_layout():
    """The contract files in the order the document lists them, and every job's log
    in the tree of what the workflow writes (its ``{a,b}`` groups expanded)."""
    doc = (PROJECT_ROOT / "docs/results-layout.md").read_text()
    contract = doc.split("## Contract files")[1].split("Details of these files")[0]
    listed = re.findall(r"^    (\S+)", contract, flags=re.MULTILINE)
    ordered = (MARKER_POSES, PHOTOMETRIC, CHROMATICITY, DEPTH, MESH, METRICS, REPORT)
    assert listed == [as_documented(t) for t in ordered]
    tree = doc.split("## Everything the workflow writes")[1]
    logs = re.sub(
        r"(\S*)\{([\w,]+)\}(\S*)",
        lambda m: ", ".join(m[1] + x + m[3] for x in m[2].split(",")),
        tree.split("logs/")[1].split("benchmarks/")[0],
    )
    for rule, template in paths.LOGS.items():
        assert as_documented(template).removeprefix("logs/") in logs, rule
    assert f"{paths.BENCHMARK_ROOT}/<rule>/...tsv" in tree
    # Every template lies under a folder the workflow writes (none has a root of its own).
    assert all(PATH_LITERAL.match(t) for t in TEMPLATES)


def test_benchmarks_sit_in_one_folder_per_rule():
    """A rule's timings under benchmarks/snakemake/<its folder>/ named by its
    wildcards, which tell its jobs apart (the report's table groups them by folder)."""
    for rule, template in paths.BENCHMARKS.items():
        folder, job = template.removeprefix(paths.BENCHMARK_ROOT + "/").split("/", 1)
        assert folder == ("synth" if rule == "synth_dataset" else rule)
        assert wildcards(job.removesuffix(".tsv")) == wildcards(paths.LOGS[rule]), rule
    assert set(paths.LOGS) - set(paths.BENCHMARKS) == {"effective_config", "report"}


def test_fill_needs_every_wildcard_and_no_other():
    """A forgotten or misspelt wildcard fails at once (a path no rule makes would
    only fail when Snakemake looks for the rule)."""
    assert fill(DEPTH, name="d", scene="toy", variant="vh", frame="000000") == (
        "results/d/toy/vh/depth/000000.h5"
    )
    assert fill(paths.BENCHMARK_ROOT) == "benchmarks/snakemake"
    assert VH_DEPTH == "results/{name}/{scene}/vh/depth/{frame}.h5"
    with pytest.raises(ValueError, match=r"missing wildcards \['frame'\], unknown \[\]"):
        fill(HULL, name="d", scene="toy")
    with pytest.raises(ValueError, match=r"missing wildcards \[\], unknown \['variant'\]"):
        fill(HULL, name="d", scene="toy", frame="000000", variant="vh")


# --------------------------------------------------------------------------- no path of their own


def _string_tokens(path: Path) -> list[str]:
    """The string literals of a Snakefile (Python's tokens; comments are none) but its
    docstrings: the file's first statement and a rule's first line (a rule's
    ``shell:`` or ``benchmark:`` string on a line of its own is no docstring)."""
    kinds = {tokenize.STRING, getattr(tokenize, "FSTRING_MIDDLE", tokenize.STRING)}
    skip = {tokenize.NL, tokenize.COMMENT}
    with path.open() as f:
        tokens = [t for t in tokenize.generate_tokens(f.readline) if t.type not in skip]

    def docstring(i: int) -> bool:
        header = [t.string for t in tokens[max(i - 5, 0) : i]]
        return i == 0 or (
            len(header) == 5 and header[0] in ("rule", "checkpoint") and header[2] == ":"
        )

    return [t.string for i, t in enumerate(tokens) if t.type in kinds and not docstring(i)]


def _code_strings(path: Path) -> list[str]:
    """A module's string constants but its docstrings (f-strings' parts included)."""
    tree = ast.parse(path.read_text())
    docstrings = {
        id(node.body[0].value)
        for node in ast.walk(tree)
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef)
        and node.body
        and isinstance(node.body[0], ast.Expr)
        and isinstance(node.body[0].value, ast.Constant)
    }
    return [
        node.value
        for node in ast.walk(tree)
        if isinstance(node, ast.Constant)
        and isinstance(node.value, str)
        and id(node) not in docstrings
    ]


def test_the_rules_and_the_plan_write_no_path_of_their_own():
    """Every path under results/, reports/, logs/, benchmarks/ and data/synthetic/ in
    the rules and in ``colourhs/workflow/`` comes from :mod:`colourhs.workflow.paths`."""
    assert PATH_LITERAL.search('"results/{name}"') and PATH_LITERAL.search("x=results/d")
    assert not PATH_LITERAL.search('"../report/index.rst"') and not PATH_LITERAL.search("--logs")
    found = [
        (path.name, s)
        for path in RULE_FILES
        for s in _string_tokens(path)
        if PATH_LITERAL.search(s)
    ]
    modules = sorted((PROJECT_ROOT / "colourhs/workflow").glob("*.py"))
    assert len(modules) >= 4
    found += [
        (path.name, s)
        for path in modules
        if path.name != "paths.py"
        for s in _code_strings(path)
        if PATH_LITERAL.search(s)
    ]
    assert found == []
    assert len(RULE_FILES) >= 8  # the Snakefile and the rule files were read


# --------------------------------------------------------------------------- a dry run


def _jobs(text: str) -> list[dict]:
    """A dry run's jobs (``snakemake -n -p``): rule, each ``key: value`` line, shell."""
    jobs, job = [], None
    for line in text.splitlines():
        if m := re.fullmatch(r"(?:local)?(?:rule|checkpoint) (\w+):", line):
            job = {"rule": m[1]}
            jobs.append(job)
        elif job is not None and (m := re.fullmatch(r"    (\w+): (.*)", line)):
            job[m[1]] = m[2]
        elif job is not None and line.startswith("Shell command: "):
            job["shell"], job = line.removeprefix("Shell command: "), None
    return jobs


@pytest.fixture(scope="module")
def dry_run(tmp_path_factory) -> list[dict]:
    """Every job of a dataset given by path (its rig calibrated from its geometric/
    captures, a coloured sequence's chromaticity tracked, meshes and depth ranges from
    the visual hull) and the rendering of a synthetic one (asked for by its folder: the
    default target waits for it before it plans the others' reconstructions)."""
    root = tmp_path_factory.mktemp("paths")
    data = add_geometric(make_dataset(root / "my data"))
    # A moving coloured sequence: its chromaticity tracked frame to frame (bayes_dyn).
    wave = {"dynamic": True, "chromatic": "slinky", "chromatic_frame": "000001"}
    (data / "scenes/wave/scene.json").write_text(json.dumps(wave))
    config = root / "config.yaml"
    # The rig calibrated from geometric/ (rule calibrate_rig; every stage reads it).
    calibrated = {"path": str(data), "calibration": {"calibrate_rig": True}}
    config.write_text(
        yaml.safe_dump(
            {
                "datasets": {"d": calibrated, "s": {"synth": {"preset": "tiny"}}},
                "only": ["d"],
                "reconstruction": {"depth_from_hull": True},
                "surfaces": {"mesh_with_hull": True},
            }
        )
    )
    cmd = [sys.executable, "-m", "snakemake", "--snakefile", str(SNAKEFILE)]
    cmd += ["--directory", str(root), "--cores", "1", "-n", "-p"]
    cmd += ["all", fill(paths.SYNTH_DATASET, name="s")]
    cmd += ["--configfile", str(PROJECT_ROOT / "config.yaml"), str(config)]
    done = subprocess.run(cmd, cwd=root, capture_output=True, text=True)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    return _jobs(done.stdout + done.stderr)


def _wildcards(job: dict) -> dict:
    return (
        dict(kv.split("=", 1) for kv in job["wildcards"].split(", ")) if "wildcards" in job else {}
    )


def test_every_job_writes_logs_and_times_at_the_templates(dry_run):
    """Each job's outputs are templates filled with its wildcards, its log and
    benchmark its rule's (:data:`~colourhs.workflow.paths.LOGS`, ``BENCHMARKS``)."""
    assert {job["rule"] for job in dry_run} == {*paths.LOGS, "all"}  # every rule planned
    for job in dry_run:
        rule, values = job["rule"], _wildcards(job)
        if rule == "all":
            continue
        filled = {
            fill(t, **{k: values[k] for k in wildcards(t)})
            for t in TEMPLATES
            if set(wildcards(t)) <= set(values)
        }
        assert set(job["output"].split(", ")) <= filled, job
        assert job["log"] == fill(paths.LOGS[rule], **values)
        benchmark = paths.BENCHMARKS.get(rule)
        assert job.get("benchmark") == (benchmark and fill(benchmark, **values)), job


def test_every_result_a_job_reads_or_passes_on_is_a_template(dry_run):
    """The inputs under the workflow's folders, and the paths the commands name there
    (options, redirections), are templates filled in."""
    named = []
    for job in dry_run:
        named += [p for p in job.get("input", "").split(", ") if PATH_LITERAL.match(p)]
        words = re.findall(r"[^\s'\"=]+", job.get("shell") or "")
        named += [w for w in words if PATH_LITERAL.match(w)]
    assert len(named) > 300
    assert [p for p in named if not matches_a_template(p)] == []
    assert {"results/d", "results/d/calib", "benchmarks/snakemake"} <= set(named)
