"""Small file helpers shared by the stages: outputs appear whole or not at all."""

from __future__ import annotations

import json
import os
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
