"""The files the report's page links, kept inside the report folder so that it stands alone.

The page ``reports/NAME/index.html`` refers to images by paths relative to
itself. :func:`place_files` says where the page finds each one when the folder
is to stand alone (zipped, mailed, moved): a file inside the report folder
(``figures/``) where it is, a file outside it (the calibration figures of
``results/NAME/calib``) in the folder's :data:`ASSETS` subfolder, at its path
relative to the common folder of the files outside, so that the copies keep
readable, distinct names. :func:`write_assets` makes those copies, all or none.
:func:`link_files` is the other way: every file linked where it is, which works
only while the page stays beside them.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterable, Mapping
from pathlib import Path

__all__ = ["ASSETS", "link_files", "place_files", "write_assets"]

#: The report folder's subfolder of copies of the files the page links from outside it.
ASSETS = "assets"


def _inside(path: Path, folder: Path) -> bool:
    """Whether the resolved ``path`` lies in ``folder`` but not in its :data:`ASSETS`
    subfolder (which each build replaces, so nothing is linked from there in place)."""
    return path.is_relative_to(folder) and not path.is_relative_to(folder / ASSETS)


def place_files(paths: Iterable[str | Path], out_dir: str | Path) -> dict[Path, str]:
    """Where a page in ``out_dir`` finds each file of ``paths`` when the folder stands alone.

    Returns
    -------
    dict
        Resolved path -> POSIX path relative to ``out_dir``: a file inside
        ``out_dir`` where it is; a file outside it under :data:`ASSETS`, at its
        path relative to the deepest folder that holds every such file (never
        ``..`` nor an absolute path). :func:`write_assets` copies the latter.
    """
    folder = Path(out_dir).resolve()
    files = list(dict.fromkeys(Path(p).resolve() for p in paths))
    outside = [p for p in files if not _inside(p, folder)]
    root = Path(os.path.commonpath([p.parent for p in outside])) if outside else folder
    return {
        p: f"{ASSETS}/{p.relative_to(root).as_posix()}"
        if p in outside
        else p.relative_to(folder).as_posix()
        for p in files
    }


def link_files(paths: Iterable[str | Path], out_dir: str | Path) -> dict[Path, str]:
    """Resolved path -> POSIX path relative to ``out_dir`` of each file of ``paths``,
    where it is (``../../results/...`` for a file outside the folder)."""
    folder = Path(out_dir).resolve()
    return {
        p: Path(os.path.relpath(p, folder)).as_posix()
        for p in dict.fromkeys(Path(q).resolve() for q in paths)
    }


def write_assets(placed: Mapping[Path, str], out_dir: str | Path) -> list[Path]:
    """Copy the files :func:`place_files` put under :data:`ASSETS` into ``out_dir``.

    The copies are made in a hidden temporary sibling folder, which then
    replaces ``OUT_DIR/assets`` as a whole: a failure leaves the folder as it
    was and no partial copy behind, and copies an earlier build made that this
    one does not link are removed. Without any file to copy the folder is
    empty: it exists after every build, so the workflow declares it as the
    report job's output.

    Returns
    -------
    list of Path
        The copies written.
    """
    out_dir = Path(out_dir)
    folder = out_dir / ASSETS
    prefix = f"{ASSETS}/"
    copies = {
        src: folder / rel[len(prefix) :] for src, rel in placed.items() if rel.startswith(prefix)
    }
    tmp = out_dir / f".{ASSETS}.{os.getpid()}.tmp"
    old = out_dir / f".{ASSETS}.{os.getpid()}.old"
    try:
        tmp.mkdir(parents=True, exist_ok=True)
        for src, dst in copies.items():
            staged = tmp / dst.relative_to(folder)
            staged.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(src, staged)
        if folder.exists():
            os.replace(folder, old)
        os.replace(tmp, folder)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        shutil.rmtree(old, ignore_errors=True)
    return list(copies.values())
