"""Every job reads only its declared inputs (helpers of the workflow tests).

A run with ``COLOURHS_AUDIT_READS=FOLDER`` set has every job's ``colourhs`` process
record the files it opened to read (:func:`colourhs.common.files.record_reads`: Python's
``open`` audit events, and the HDF5 and PLY files read in C through
:func:`colourhs.common.files.note_read`). :func:`undeclared_reads` compares them with what
Snakemake recorded for each job: a file a job reads but its rule does not declare
would not rerun the job when it changes (a silent stale result). Folders the jobs
list are not checked: the rules' input functions glob the same folders, so an
added or removed file changes a job's set of inputs.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import shlex
from dataclasses import dataclass
from pathlib import Path

from snakemake.api import SnakemakeApi
from snakemake.settings.enums import Quietness
from snakemake.settings.types import ConfigSettings, DAGSettings, OutputSettings, ResourceSettings

from colourhs.cli.parser import SNAKEFILE

ENV = "COLOURHS_AUDIT_READS"

# Files a job may read beyond its inputs: the report's table of run times reads the
# benchmark files of the jobs before it (they are rewritten only when their job
# reruns, and then so is one of the report's inputs).
UNDECLARED = {"report": ("benchmarks/snakemake",)}


@contextlib.contextmanager
def quiet_workflow(workdir: Path, configfiles):
    """The project's workflow through Snakemake's public API (a ``WorkflowApi``) with
    what it prints captured: yields (the workflow, the StringIO of its stdout)."""
    text = io.StringIO()
    with (
        contextlib.redirect_stdout(text),
        SnakemakeApi(OutputSettings(quiet={Quietness.ALL})) as api,
    ):
        yield (
            api.workflow(
                resource_settings=ResourceSettings(cores=2),
                config_settings=ConfigSettings(configfiles=[Path(p) for p in configfiles]),
                snakefile=SNAKEFILE,
                workdir=workdir,
            ),
            text,
        )


def summary(workdir: Path, configfiles, detailed: bool = False) -> list[list[str]]:
    """Snakemake's public summary (``DAGApi.summary``, the `--summary` table), one row
    per output file: output_file, date, rule, log-file(s), [input-file(s), shellcmd,]
    status, plan; detailed, the inputs and command its job last ran with (Snakemake's
    records under .snakemake/metadata)."""
    with quiet_workflow(workdir, configfiles) as (workflow, text):
        workflow.dag(DAGSettings()).summary(detailed=detailed)
    lines = text.getvalue().splitlines()
    header = lines.index(next(x for x in lines if x.startswith("output_file\t")))
    columns = 8 if detailed else 6
    return [r for r in (x.split("\t") for x in lines[header + 1 :]) if len(r) == columns]


@dataclass
class Job:
    """A job of the last run as Snakemake recorded it; absolute paths."""

    rule: str
    inputs: set[str]
    outputs: set[str]
    log: str


def _abs(workdir: Path, path: str) -> str:
    return os.path.normpath(os.path.join(workdir, path))


def declared_jobs(workdir: Path, configfiles) -> dict[tuple[str, ...], Job]:
    """Every job of the last run by its `colourhs` arguments (from the shell command
    Snakemake recorded), with the inputs, outputs and log file it ran with (the
    detailed summary; its input lists are comma-separated: no "," in our paths)."""
    jobs: dict[str, tuple[tuple[str, ...], Job]] = {}
    for out, _, rule, log, inputs, cmd, _, _ in summary(workdir, configfiles, detailed=True):
        if rule == "all":
            continue
        words = shlex.split(cmd)
        argv = tuple(words[words.index("colourhs") + 1 : words.index(">")])
        _, job = jobs.setdefault(log, (argv, Job(rule, set(), set(), _abs(workdir, log))))
        job.inputs |= {_abs(workdir, p) for p in inputs.split(",") if p not in ("", "-")}
        job.outputs.add(_abs(workdir, out))
    return dict(jobs.values())


def undeclared_reads(job: Job, reads: list[str], roots: tuple[str, ...], workdir: Path):
    """The files under ``roots`` a job read beyond its inputs, outputs and log (and the
    files inside those that are folders). A path that is no file is no read (an open
    that failed: numba opens the editable install's path-hook entry of sys.path, a
    name relative to the working folder)."""
    own = job.inputs | job.outputs | {job.log}
    own |= {_abs(workdir, p) for p in UNDECLARED.get(job.rule, ())}
    return [
        p
        for p in reads
        if any(p.startswith(r + os.sep) for r in roots)
        and p not in own
        and not any(p.startswith(o + os.sep) for o in own)
        and os.path.exists(p)
    ]


def audit(reads: Path, workdir: Path, data: Path, configfiles) -> tuple[int, list[str]]:
    """Check a run's records (folder ``reads``) against its jobs: (the number of
    jobs, the problems found: a job without one record, a job with inputs that read
    none of them (the records are incomplete), an undeclared read under the dataset
    ``data`` or the run's folder ``workdir``)."""
    jobs = declared_jobs(workdir, configfiles)
    records = [json.loads(p.read_text()) for p in sorted(reads.glob("*.json"))]
    records = [r for r in records if r["argv"][1:2] != ["run"]]  # `colourhs run` drives
    problems, seen = [], []
    for record in records:
        job = jobs.get(tuple(record["argv"][1:]))
        if job is None:
            problems.append(f"a process of no job: {record['argv']}")
            continue
        seen.append(job.log)
        if job.inputs and not job.inputs & set(record["reads"]):
            problems.append(f"{job.rule} ({job.log}) read none of its inputs")
        for path in undeclared_reads(job, record["reads"], (str(data), str(workdir)), workdir):
            problems.append(f"{job.rule} ({job.log}) read {path}")
    for job in jobs.values():
        if seen.count(job.log) != 1:
            problems.append(f"{job.rule} ({job.log}): {seen.count(job.log)} records")
    return len(jobs), problems
