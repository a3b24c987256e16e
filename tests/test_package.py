"""The package's shape: no import cycles, counting imports inside functions."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "colourhs"


def _modules() -> dict[str, Path]:
    out = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = path
    return out


def import_graph() -> dict[str, set[str]]:
    """Module -> the package modules it imports anywhere in its source."""
    modules = _modules()
    graph = {name: set() for name in modules}
    for name, path in modules.items():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                targets = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            else:
                continue
            graph[name] |= {t for t in targets if t in modules and t != name}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The import chains that lead back to where they started (depth-first search)."""
    found, state = [], {}

    def visit(node, stack):
        state[node] = "open"
        for nxt in sorted(graph[node]):
            if state.get(nxt) == "open":
                found.append(stack[stack.index(nxt) :] + [nxt])
            elif nxt not in state:
                visit(nxt, stack + [nxt])
        state[node] = "done"

    for node in sorted(graph):
        if node not in state:
            visit(node, [node])
    return found


def test_cycle_finder_finds_a_cycle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c", "a"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycles():
    """Cycles there were once: hull <-> reconstruct.frame (the depth file),
    evaluate <-> figures, photometric <-> crosstalk, synth.dataset <-> synth.randomrig."""
    graph = import_graph()
    assert len(graph) > 30 and "colourhs.common.depthfile" in graph["colourhs.surfaces.hull"]
    assert cycles(graph) == []


#: The package's folders, one per stage of the pipeline, and what each may import
#: from the rest of the package (docs/architecture.md draws the same).
LAYERS = {
    "common": {"capture"},
    "capture": {"common"},
    "calibration": {"capture", "common"},
    "surfaces": {"capture", "common"},
    "reconstruct": {"calibration", "capture", "common", "surfaces"},
    "evaluation": {"capture", "common"},
    "synth": {"capture", "common"},
    "report": {"calibration", "capture", "common", "evaluation", "workflow"},
    "workflow": {"calibration", "capture", "synth"},
    "cli": {
        "calibration",
        "capture",
        "common",
        "evaluation",
        "reconstruct",
        "report",
        "surfaces",
        "synth",
        "workflow",
    },
}


def _package_of(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def test_package_is_laid_out_as_the_pipeline():
    """One folder per stage and no loose modules beside them, every folder with a
    docstring that says what it holds; no two modules share a name (a reader
    searching for ``rig.py`` finds one)."""
    loose = sorted(p.name for p in PACKAGE.glob("*.py"))
    assert loose == ["__init__.py", "__main__.py"]
    folders = {p.parent.name for p in PACKAGE.glob("*/__init__.py")}
    assert folders == set(LAYERS)
    for init in PACKAGE.rglob("__init__.py"):
        assert ast.get_docstring(ast.parse(init.read_text())), init
    names = [p.name for p in PACKAGE.rglob("*.py") if p.name != "__init__.py"]
    assert sorted({n for n in names if names.count(n) > 1}) == []


def test_each_stage_imports_only_the_stages_below_it():
    """A stage's folder imports only those :data:`LAYERS` allows it, so the graph of
    folders has no cycle beyond the base (capture and common, which share the rig's
    types) and a newcomer knows where a new stage goes."""
    graph = import_graph()
    wrong = sorted(
        (a, b)
        for a, targets in graph.items()
        for b in targets
        if _package_of(a) in LAYERS
        and _package_of(b) != _package_of(a)
        and _package_of(b) not in LAYERS[_package_of(a)]
    )
    assert len(graph) > 70 and wrong == []


def test_one_variant_table():
    """The workflow, report, CLI and benchmarks read colourhs.workflow.variants; the config
    schema's enum (static YAML) must list the same ids in the same order."""
    import yaml

    from colourhs.workflow.variants import VARIANTS

    schema = yaml.safe_load((PACKAGE.parent / "workflow/schemas/config.schema.yaml").read_text())
    enum = schema["properties"]["reconstruction"]["properties"]["variants"]["items"]["enum"]
    assert enum == list(VARIANTS)
    # The workflow reads it through colourhs.workflow.plan (common.smk's plan).
    plan = (PACKAGE / "workflow" / "plan.py").read_text()
    assert "from colourhs.workflow.variants import" in plan and "VARIANTS = {" not in plan
    common = (PACKAGE.parent / "workflow/rules/common.smk").read_text()
    assert "from colourhs.workflow.plan import" in common and "VARIANTS" not in common
    # The reconstruction rule's variant wildcard is the table's HS variants, not a copy.
    from colourhs.workflow.variants import HS_VARIANT_PATTERN

    assert HS_VARIANT_PATTERN == "ml_full|bayes_nocalib|bayes_ph|bayes_full|bayes_dyn"
    rules = (PACKAGE.parent / "workflow/rules/reconstruct.smk").read_text()
    assert "variant=HS_VARIANT_PATTERN," in rules and "bayes_nocalib|" not in rules


def test_each_stage_imports_only_what_it_needs(tmp_path):
    """A job imports its own stage's libraries only. The command line
    (cli, commands) none of the heavy ones; an evaluation open3d for its ray
    casting but not pandas, scipy, matplotlib (only when it colours a mesh),
    numba or pymeshlab; ``evaluate --help`` not the reconstruction (numba).
    ``colourhs metrics`` (gathering metrics.csv) pandas only, not open3d
    (it imported colourhs.evaluation.accuracy); the command line not even numpy, cv2 or
    jsonschema (colourhs.capture loads its dataset reader on first use).
    Measured: about 2.4 s (one interpreter importing open3d)."""
    import json
    import subprocess
    import sys

    rows = [tmp_path / f"{v}.json" for v in ("vh", "ml_full")]
    for path in rows:
        path.write_text(json.dumps({"scene": "s", "frame": "000000", "variant": path.stem}))
    metrics = ["metrics", *map(str, rows), str(tmp_path / "metrics.csv")]
    heavy = ("open3d", "pandas", "scipy", "matplotlib", "numba", "pymeshlab", "skimage")
    heavy += ("numpy", "cv2", "jsonschema")
    code = (
        "import sys, contextlib, io\n"
        f"heavy = {heavy!r}\n"
        "def loaded(): return sorted(h for h in heavy if h in sys.modules)\n"
        "from colourhs.cli.parser import main\n"
        "print(loaded())\n"
        "with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):\n"
        "    main(['evaluate', '--help'])\n"
        "print(loaded())\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        f"    assert main({metrics!r}) == 0\n"
        "print(loaded())\n"
        "import colourhs.evaluation.accuracy\n"
        "print(loaded())\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=PACKAGE.parent
    ).stdout.split("\n")
    assert out[:4] == ["[]", "[]", "['numpy', 'pandas']", "['cv2', 'numpy', 'open3d', 'pandas']"]
    assert (tmp_path / "metrics.csv").read_text().count("\n") == 3  # header and two rows


def test_importing_colourhs_first_turns_numpy_huge_page_advice_off():
    """colourhs/__init__.py sets NUMPY_MADVISE_HUGEPAGE=0 unless the user set it: a
    process that imports colourhs before NumPy (the command line, every workflow job)
    gets NumPy without the huge-page advice, and a user's own setting wins."""
    import os
    import subprocess
    import sys

    probe = (
        "import colourhs, numpy\n"
        "from numpy._core.multiarray import _get_madvise_hugepage\n"
        "print(_get_madvise_hugepage())"
    )
    env = {k: v for k, v in os.environ.items() if k != "NUMPY_MADVISE_HUGEPAGE"}
    for setting, expected in ((None, "False"), ("1", "True")):
        run_env = env if setting is None else {**env, "NUMPY_MADVISE_HUGEPAGE": setting}
        out = subprocess.run(
            [sys.executable, "-c", probe], env=run_env, capture_output=True, text=True, check=True
        )
        assert out.stdout.strip() == expected, (setting, out.stdout, out.stderr)


def test_open3d_plotly_viewer_is_imported_on_first_use():
    """colourhs.common.lazy_open3d: importing colourhs, then open3d, does not import dash
    (open3d's plotly viewer; 0.25 s of a job's start), the viewer still works (it
    is imported on its first call), and COLOURHS_EAGER_OPEN3D=1 keeps open3d's
    own import."""
    import os
    import subprocess
    import sys

    probe = (
        "import sys, colourhs, open3d as o3d, numpy as np\n"
        "print('dash' in sys.modules)\n"
        "pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.eye(3)))\n"
        "fig = o3d.visualization.get_plotly_fig([pcd])\n"
        "print('dash' in sys.modules, type(fig).__name__)\n"
    )
    for eager, expected in ((None, ["False", "True Figure"]), ("1", ["True", "True Figure"])):
        env = {k: v for k, v in os.environ.items() if k != "COLOURHS_EAGER_OPEN3D"}
        env = env if eager is None else {**env, "COLOURHS_EAGER_OPEN3D": eager}
        out = subprocess.run(
            [sys.executable, "-c", probe], env=env, capture_output=True, text=True, check=True
        )
        assert out.stdout.split("\n")[:2] == expected, (eager, out.stdout, out.stderr)


MAX_PARAMETERS = 10
COMPILED = ("njit", "jit", "overload", "intrinsic", "vectorize", "guvectorize", "cfunc")


def _long_parameter_lists() -> list[str]:
    """Every function of the package (numba kernels aside) with more than
    MAX_PARAMETERS parameters, as ``path:line name (count)``."""
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                continue
            if any(c in ast.unparse(d) for d in node.decorator_list for c in COMPILED):
                continue
            a = node.args
            count = len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs)
            count += (a.vararg is not None) + (a.kwarg is not None)
            if count > MAX_PARAMETERS:
                found.append(f"{path.relative_to(PACKAGE)}:{node.lineno} {node.name} ({count})")
    return found


def test_long_parameter_lists_are_option_dataclasses():
    """No function takes more than 10 parameters: what belongs together travels
    as an option dataclass (numba kernels, whose arguments are arrays, aside)."""
    assert _long_parameter_lists() == []
