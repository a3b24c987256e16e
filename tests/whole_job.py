"""The whole job, run once per test session and shared (conftest's ``whole_job``).

`colourhs run` on a copy of the tiny dataset: every stage, variants vh, bayes_ph and
bayes_full, all four scenes, 68 jobs (measured on 2 cores shared with another job,
fixture setup with the tiny dataset: 134 s with numba's cache empty, 103-109 s with
it filled, up to 206 s under load; most of a tiny job is its imports).
workflow/test_workflow.py checks what it made and what changes would rerun: one run
instead of two (test_workflow's own run of 36 jobs took 64-74 s, 125 s under load; the two
files went from 240 s to 173 s with numba's cache empty, 199 s to 145 s filled).
The dataset copy and the run's folder have spaces in their paths ("my capture",
"my run"): every rule's shell command must quote them. Every job records the
files it reads (tests/read_audit.py).

A test that changes the dataset or the run's files puts them back (bytes and
times), or works on its own copy (:func:`copy_run`): the tests share the run in
any order.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

from read_audit import ENV, audit

from colourhs.cli.parser import PROJECT_ROOT

NAME = "t"
#: Without ml_full and bayes_nocalib, for the suite's 15-minute budget: each variant's
#: six frames, meshes and evaluations cost 40-50 s of the run.
VARIANTS = ("vh", "bayes_ph", "bayes_full")


def snapshot(workdir: Path) -> dict[str, int]:
    """Relative path -> mtime (ns) of every file under results/ and reports/ but
    results/NAME/run-config.yaml (the run's own config, which `colourhs run` writes
    each time it is called, no job's output)."""
    return {
        str(p.relative_to(workdir)): p.stat().st_mtime_ns
        for top in ("results", "reports")
        for p in (workdir / top).rglob("*")
        if p.is_file() and p.name != "run-config.yaml"
    }


@dataclass
class WholeJob:
    """The shared run: `colourhs run DATA --directory WORKDIR`, as it finished."""

    data: Path  # the dataset copy, "my capture"
    workdir: Path  # the run's folder, "my run"
    cmd: list[str]  # the `colourhs run` command line
    done: subprocess.CompletedProcess  # its exit status and output
    reads: Path  # what each job read (colourhs.common.files.record_reads)
    first: dict[str, int] = field(default_factory=dict)  # snapshot() after the run

    @property
    def configfiles(self) -> list[Path]:
        """As `colourhs run` passes them: the project's config.yaml, then the run's."""
        return [PROJECT_ROOT / "config.yaml", self.workdir / "results" / NAME / "run-config.yaml"]

    @cached_property
    def audit(self) -> tuple[int, list[str]]:
        """read_audit.audit of the run: (the number of jobs, the problems found)."""
        return audit(self.reads, self.workdir, self.data, self.configfiles)


def run_whole_job(dataset: Path, root: Path) -> WholeJob:
    """Copy ``dataset`` to ROOT/my capture and run the whole job into ROOT/my run."""
    data = root / "my capture"
    shutil.copytree(dataset, data)
    workdir = root / "my run"
    workdir.mkdir()
    reads = root / "reads"
    reads.mkdir()
    cmd = [sys.executable, "-m", "colourhs", "run", str(data), "--name", NAME]
    cmd += ["--cores", "2", "--directory", str(workdir), "--variants", ",".join(VARIANTS)]
    done = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, ENV: str(reads)})
    job = WholeJob(data, workdir, cmd, done, reads)
    if done.returncode == 0:
        job.first = snapshot(workdir)
    return job


def copy_run(job: WholeJob, to: Path) -> Path:
    """A copy of the run's folder (outputs, logs, Snakemake's records; times kept),
    reading the same dataset: up to date, for a test that writes outputs."""
    shutil.copytree(job.workdir, to, symlinks=True)
    return to
