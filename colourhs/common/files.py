"""Small file helpers shared by the stages: outputs appear whole or not at all, and
(opt-in, for tests) a record of the files a command reads."""

from __future__ import annotations

import json
import os
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


@contextmanager
def atomic_output(path: str | Path) -> Iterator[Path]:
    """Write to a temporary sibling of ``path`` and move it into place on success.

    Yields the temporary path (a hidden file in the same folder, so the
    final rename is atomic, with the same suffix, so writers that choose the
    format by extension, such as open3d's, work); on any error the temporary
    file is removed and ``path`` is left as it was.
    """
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.stem}.{os.getpid()}.tmp{out.suffix}")
    try:
        yield tmp
        os.replace(tmp, out)
    finally:
        tmp.unlink(missing_ok=True)


def write_json(path: str | Path, data) -> None:
    """Write ``data`` as indented JSON, atomically."""
    with atomic_output(path) as tmp:
        tmp.write_text(json.dumps(data, indent=2))


def sha256_files(paths) -> str:
    """Short (16 hex digit) SHA-256 of the concatenated contents of ``paths``, for provenance."""
    import hashlib

    h = hashlib.sha256()
    for p in paths:
        h.update(Path(p).read_bytes())
    return h.hexdigest()[:16]


def copy_output(src: str | Path, out: str | Path) -> Path:
    """Copy ``src`` to ``out`` atomically (a result another job computed)."""
    import shutil

    with atomic_output(out) as tmp:
        shutil.copyfile(src, tmp)
    return Path(out)


#: Audit event of a file read in C (h5py, open3d), where Python raises no ``open`` event.
READ_EVENT = "colourhs.read"


def note_read(path: str | Path) -> None:
    """Announce a read the C libraries do (HDF5, PLY) as audit event ``colourhs.read``.

    Costs a function call when no audit hook is installed (the default); with
    ``COLOURHS_AUDIT_READS`` set, :func:`record_reads` records it.
    """
    sys.audit(READ_EVENT, os.fspath(path))


def record_reads(folder: str | Path) -> None:
    """Record every file this process opens to read, into ``FOLDER/<pid>-<ns>.json`` at exit.

    Opt-in, for tests (``COLOURHS_AUDIT_READS=FOLDER``, read by ``colourhs.cli.parser.main``):
    a :func:`sys.addaudithook` hook collects the absolute paths of Python's ``open``
    events in a mode that reads what the file holds (not ``w``/``w+``/``x``) and of
    :func:`note_read`'s events; they are written with ``sys.argv``. Python's own
    imports are recorded too (the reader filters). The file name adds the exit
    time (ns) to the process id: process ids wrap around in a long run (32,768 on
    a default Linux), and one job's record must not overwrite another's.
    """
    reads = set()

    def hook(event, args):
        if event == "open":
            path, mode, flags = args
            if isinstance(mode, str):  # io.open
                reading = "r" in mode or ("a" in mode and "+" in mode)
            else:  # os.open: mode None, O_ flags
                reading = (flags & os.O_ACCMODE) != os.O_WRONLY and not flags & os.O_TRUNC
            if reading and isinstance(path, (str, bytes, os.PathLike)):
                reads.add(os.path.abspath(os.fsdecode(path)))
        elif event == READ_EVENT:
            reads.add(os.path.abspath(args[0]))

    def write():
        record = {"argv": sys.argv, "reads": sorted(reads)}
        name = f"{os.getpid()}-{time.time_ns()}.json"
        Path(folder, name).write_text(json.dumps(record))

    import atexit

    atexit.register(write)
    sys.addaudithook(hook)
