"""The workflow on a running SLURM: every job a SLURM job, results identical.

Starts a single-node SLURM with ``scripts/slurm-local.sh`` (munged, MariaDB,
slurmdbd, slurmctld, slurmd), runs the tiny preset's statue (variants vh and
bayes_ph: calibration, hull, reconstruction, mesh, evaluation, figures,
report) once through ``--profile profiles/slurm`` with
snakemake-executor-plugin-slurm and once locally, and compares the depth
files and metrics.csv. Measured on a 2-core machine: 17 SLURM jobs, 3 min
(the local run 37 s: each SLURM job starts a fresh Snakemake and Python),
depth files identical to the bit.

Opt-in (``pytest -m slurm``): it needs root and Debian's packages, and
minutes of a plain run's time; skipped with the reason otherwise.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import h5py
import numpy as np
import pandas as pd
import pytest
import yaml

from colourhs.cli.parser import PROJECT_ROOT
from colourhs.synth.synthesise import synthesise

SCRIPT = PROJECT_ROOT / "scripts" / "slurm-local.sh"


def _why_not() -> str | None:
    if os.geteuid() != 0:
        return "needs root to start the SLURM daemons"
    if not shutil.which("apt-get") and not shutil.which("slurmctld"):
        return "no SLURM and no apt-get to install it"
    return None


pytestmark = [
    pytest.mark.slurm,
    pytest.mark.skipif(_why_not() is not None, reason=_why_not() or ""),
]


def _snakemake(directory, run_yaml, *extra):
    cmd = [
        sys.executable,
        "-m",
        "snakemake",
        "--snakefile",
        str(PROJECT_ROOT / "Snakefile"),
        "--directory",
        str(directory),
        *extra,
        "--configfile",
        str(PROJECT_ROOT / "config.yaml"),
        str(run_yaml),
    ]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=1800)


def test_tiny_preset_through_slurm_equals_the_local_run(tmp_path):
    started = subprocess.run(["bash", str(SCRIPT), "start"], capture_output=True, text=True)
    if started.returncode != 0:
        pytest.skip(f"SLURM could not start here: {started.stderr.strip()[-300:]}")
    data = synthesise(tmp_path / "tiny", "tiny")
    run_yaml = tmp_path / "run.yaml"
    run_yaml.write_text(
        yaml.safe_dump(
            {
                "datasets": {"tiny": {"path": str(data)}},
                "only": ["tiny"],
                "reconstruction": {"variants": ["vh", "bayes_ph"], "scenes": ["statue"]},
            }
        )
    )
    on_slurm = _snakemake(
        tmp_path / "slurm",
        run_yaml,
        "--profile",
        str(PROJECT_ROOT / "profiles" / "slurm"),
        "--default-resources",
        "slurm_account=colourhs",
        "slurm_partition=local",
        "runtime=30",
        "mem_mb=4000",
        "--slurm-init-seconds-before-status-checks",
        "5",
    )
    assert on_slurm.returncode == 0, on_slurm.stderr[-3000:]
    local = _snakemake(tmp_path / "local", run_yaml, "--cores", "2")
    assert local.returncode == 0, local.stderr[-3000:]

    # Every job but the final `all` went to SLURM, and SLURM's accounting saw it complete.
    log = on_slurm.stdout + on_slurm.stderr
    ids = [
        line.split("SLURM jobid ")[1].split()[0]
        for line in log.splitlines()
        if "has been submitted with SLURM jobid" in line
    ]
    jobs = log.count("localrule ") + len(ids)
    assert len(ids) >= 15 and len(ids) == jobs - 1, log[-2000:]
    sacct = subprocess.run(
        ["sacct", "-X", "-n", "-P", "-o", "JobID,State", "-j", ",".join(ids)],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    states = dict(line.split("|") for line in sacct.split())
    assert set(states) == set(ids) and set(states.values()) == {"COMPLETED"}

    # Identical results.
    a, b = tmp_path / "local" / "results" / "tiny", tmp_path / "slurm" / "results" / "tiny"
    depth_files = sorted(a.rglob("depth/*.h5"))
    assert len(depth_files) == 2
    for f in depth_files:
        with h5py.File(f) as x, h5py.File(b / f.relative_to(a)) as y:
            for key in ("depth", "normal", "mask", "confidence"):
                assert np.array_equal(x[key][()], y[key][()], equal_nan=True), (f, key)
    ma = pd.read_csv(tmp_path / "local" / "reports" / "tiny" / "metrics.csv")
    mb = pd.read_csv(tmp_path / "slurm" / "reports" / "tiny" / "metrics.csv")
    pd.testing.assert_frame_equal(ma, mb)
