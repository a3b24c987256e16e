"""Shared fixtures (synthetic datasets rendered once per test session) and the
opt-in markers.

Markers (``pyproject.toml``): ``slow`` marks the tests that take the suite's
time, so ``pytest -m "not slow"`` is the quick check while developing; the
whole suite is what CI runs. ``slurm``, ``bench`` and ``mitsuba`` mark tests
that need what a plain run lacks: they run only when ``-m`` names them
(``pytest -m slurm``) and are skipped, with the reason, otherwise.

The suite runs in two pytest-xdist workers (``addopts`` in ``pyproject.toml``),
each with its share of the cores for numba's and OpenBLAS's threads: the session
fixtures that render a dataset (:func:`built_once`) are rendered once for the whole
run, by the first worker that asks; a file's tests run on one worker
(``--dist loadfile``, the files with the most slow tests first), so its module
fixtures are built once, and the tests of
``whole_job`` are all in ``workflow/test_workflow.py``; ``pytest -n 0`` runs the
tests in one process.
"""

from __future__ import annotations

import fcntl
import os
import re
import shutil
from collections.abc import Callable
from pathlib import Path


def _share_the_cores() -> None:
    """Under pytest-xdist, give each worker its share of the machine's cores for numba's
    and OpenBLAS's threads (unless the environment already sets them): every worker
    otherwise starts one thread per core, and the workers' threads contend for the
    same cores. Set before numpy and numba are imported, which read them once."""
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    if workers > 1:
        share = str(max(1, (os.cpu_count() or 1) // workers))
        for var in ("NUMBA_NUM_THREADS", "OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"):
            os.environ.setdefault(var, share)


_share_the_cores()

import pytest  # noqa: E402
from logging_helpers import kept_logging  # noqa: E402

from colourhs.synth.simulated_rig import Nuisances  # noqa: E402
from colourhs.synth.synthesise import PARTS, Preset, RenderSelection, synthesise  # noqa: E402

#: Markers whose tests run only when ``-m`` names them, and why they are opt-in.
OPT_IN = {
    "slurm": "starts a local SLURM (needs root and Debian's packages; about 4 minutes)",
    "bench": "runs the paper benchmark at the tiny preset (about 70 s)",
    "mitsuba": "renders with Mitsuba 3 (needs pip install mitsuba; about 1.5 min)",
}


#: Fixtures that render a dataset or run the workflow for tens of seconds: a test
#: that uses one is ``slow``.
SLOW_FIXTURES = {
    "whole_job",
    "plane_calibrated",
    "clean_dataset",
    "exact_rigs",
    "sweep",
    "random_tiny",
    "clean_random_tiny",
    "offset_random_tiny",
    "fixed_tiny",
    "full_datasets",
    "white_specular_cloth",
}


@pytest.hookimpl(tryfirst=True)  # before -m selects on the markers added here
def pytest_collection_modifyitems(config, items):
    """Mark ``slow`` the tests that use a :data:`SLOW_FIXTURES` fixture; skip the tests
    of an opt-in marker unless ``-m`` asks for it (not negated); and put the files
    with the most slow tests first (:func:`_slowest_files_first`)."""
    expr = config.getoption("markexpr") or ""
    wanted = {m for m in OPT_IN if re.search(rf"(?<!not )\b{m}\b", expr)}
    for item in items:
        if SLOW_FIXTURES & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.slow)
        for marker, why in OPT_IN.items():
            if marker not in wanted and item.get_closest_marker(marker):
                item.add_marker(pytest.mark.skip(reason=f"opt-in: pytest -m {marker} ({why})"))
    items[:] = _slowest_files_first(items)


def _slowest_files_first(items: list) -> list:
    """The tests file by file, the files with the most ``slow`` tests first, each file's
    tests in their own order. pytest-xdist hands a worker the next file in this order
    whenever it is free (``--dist loadfile``, ``--no-loadscope-reorder``), so the long
    files start early and the short ones fill in at the end, and the two workers
    finish together (longest first); its own order, by the count of all tests, would
    start the whole-job file, a few long tests, last."""
    files: dict[str, list] = {}
    for item in items:
        files.setdefault(item.nodeid.split("::")[0], []).append(item)

    def slow(tests):
        return sum(t.get_closest_marker("slow") is not None for t in tests)

    ordered = sorted(files.values(), key=slow, reverse=True)  # stable: ties keep their order
    return [t for tests in ordered for t in tests]


@pytest.fixture(autouse=True)
def _logging_kept():
    """Every test leaves the ``colourhs`` loggers as it found them: ``main()`` shows
    progress for the rest of the process, and other tests assert silence."""
    with kept_logging():
        yield


def built_once(tmp_path_factory, name: str, build: Callable[[Path], object]) -> Path:
    """A session fixture's folder ``name``, filled by ``build(folder)`` once for the whole
    run: under pytest-xdist the first worker that asks builds it in the run's shared
    temporary folder while the others wait, then reuse it (a session fixture is
    otherwise built once per worker). A build that raises leaves it for the next to
    retry. Its users read it and write nothing into it, as with any session fixture."""
    base = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):  # each worker's basetemp is under the run's
        base = base.parent
    folder, done = base / name, base / f"{name}.built"
    with open(base / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not done.exists():
            shutil.rmtree(folder, ignore_errors=True)
            folder.mkdir()
            build(folder)
            done.touch()
    return folder


# 640x480 like the demo preset, with fewer board poses and sheet frames.
CHECK_PRESET = Preset("check", 640, 480, 1250.0, 2, n_poses=3, sheet_frames=1)


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory):
    """The tiny preset with every nuisance on (seed 0)."""
    root = built_once(tmp_path_factory, "tiny", lambda folder: synthesise(folder / "tiny", "tiny"))
    return root / "tiny"


@pytest.fixture(scope="session")
def whole_job(tiny_dataset, tmp_path_factory):
    """`colourhs run` of every stage on a copy of the tiny dataset (tests/whole_job.py),
    for workflow/test_workflow.py."""
    from whole_job import run_whole_job

    return run_whole_job(tiny_dataset, tmp_path_factory.mktemp("workflow"))


# The 640 x 480 fixtures skip the geometric captures: no test of theirs reads them.
NOT_GEOMETRIC = tuple(p for p in PARTS if p != "geometric")


@pytest.fixture(scope="session")
def clean_dataset(tmp_path_factory):
    """Demo resolution, noise and cross-talk off: equation (4) with mu and p only."""

    def build(folder):
        synthesise(
            folder / "clean",
            CHECK_PRESET,
            nuisances=Nuisances().without("noise", "crosstalk"),
            selection=RenderSelection(parts=NOT_GEOMETRIC),
        )

    return built_once(tmp_path_factory, "clean", build) / "clean"


# The demo preset's rig, board poses and seed, rendering only the board captures,
# the white reference and the plane: the plane frame is the demo dataset's own.
PLANE_PRESET = Preset("demo", 640, 480, 1250.0, 2, sheet_frames=1)


@pytest.fixture(scope="session")
def plane_calibrated(tmp_path_factory):
    """The demo plane with every nuisance on, and the pipeline's own calibration.

    Returns the dataset path and the calibration files (cross-talk JSON,
    photometric HDF5) made by the marker, cross-talk and photometric stages.
    """
    from colourhs.calibration.crosstalk import calibrate_crosstalk
    from colourhs.calibration.markers import marker_poses
    from colourhs.calibration.photometric import photometric_maps

    def build(root):
        plane = RenderSelection(parts=NOT_GEOMETRIC, scenes=("plane",))
        data = synthesise(root / "data", PLANE_PRESET, selection=plane)
        marker_poses(data, root / "marker_poses.csv")
        calibrate_crosstalk(data, root / "crosstalk.json")
        photometric_maps(
            data, root / "marker_poses.csv", root / "photometric.h5", root / "crosstalk.json"
        )

    root = built_once(tmp_path_factory, "plane", build)
    return root / "data", {
        "crosstalk_json": root / "crosstalk.json",
        "photometric_h5": root / "photometric.h5",
    }


# Capture-format tests (tests/capture/test_capture*.py, builders in tests/capture_helpers.py).


@pytest.fixture(scope="module")
def template(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from capture_helpers import make_dataset

    return make_dataset(tmp_path_factory.mktemp("template") / "dataset")


@pytest.fixture
def root(template: Path, tmp_path: Path) -> Path:
    """A fresh copy of the valid dataset, free to mutate."""
    return Path(shutil.copytree(template, tmp_path / "dataset"))
