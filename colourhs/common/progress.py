"""Progress on stderr for the stages that run long at paper scale.

Every Snakemake rule sends a job's stdout and stderr to its log, so progress
must read well in a file as well as at a terminal: one line per stage
(:func:`stage`, with the seconds since the job's start) where there is no
loop, and a tqdm bar (:func:`bar`) redrawn at most every
:data:`MIN_INTERVAL_S` over the loops that take long. Both stay silent with
``enabled=False`` (library callers and tests that want no output).
"""

from __future__ import annotations

import sys
from time import perf_counter

from tqdm import tqdm

__all__ = ["MIN_INTERVAL_S", "bar", "line_buffered", "stage"]

MIN_INTERVAL_S = 2.0
"""Shortest time between two redraws of a bar, seconds (a log gets a line per redraw)."""


def stage(text: str, start: float | None = None, enabled: bool = True) -> None:
    """Print one progress line on stderr: ``text``, then the seconds since ``start``.

    Parameters
    ----------
    text : str
        What starts now, e.g. ``"visual hull: carving 696 x 577 x 1128 voxels"``.
    start : float, optional
        A :func:`time.perf_counter` reading (the job's start); adds ``" [12.3 s]"``.
    enabled : bool
        False prints nothing.
    """
    if not enabled:
        return
    elapsed = "" if start is None else f" [{perf_counter() - start:.1f} s]"
    print(f"{text}{elapsed}", file=sys.stderr, flush=True)


def bar(iterable=None, desc: str = "", total: int | None = None, enabled: bool = True, **kw):
    """A tqdm progress bar on stderr, redrawn at most every :data:`MIN_INTERVAL_S`.

    Shown in a log file too (unlike tqdm's ``disable=None``), without a line
    per item. Keyword arguments go to :class:`tqdm.tqdm` (``unit``, ...).

    Parameters
    ----------
    iterable : iterable, optional
    desc : str
        The bar's label.
    total : int, optional
        Number of items (default ``len(iterable)``).
    enabled : bool
        False: a silent bar (iterates, prints nothing).
    """
    return tqdm(
        iterable,
        desc=desc,
        total=total,
        disable=not enabled,
        mininterval=MIN_INTERVAL_S,
        # Every update may redraw (once MIN_INTERVAL_S has passed): tqdm's default
        # adapts a minimum of items between redraws to the first items' rate, so a
        # loop whose items slow down would go silent.
        miniters=1,
        file=sys.stderr,
        dynamic_ncols=False,
        **kw,
    )


def line_buffered(stream=None) -> None:
    """Make a text stream (default ``sys.stdout``) write each line as it is printed.

    A job's stdout goes to its log file, where Python buffers it in blocks: its
    lines (``wrote ...``, per-camera summaries) would reach the log only when the
    job ended.
    A stream that cannot be reconfigured (a test's capture) is left as it is.
    """
    stream = sys.stdout if stream is None else stream
    reconfigure = getattr(stream, "reconfigure", None)
    if reconfigure is not None:
        reconfigure(line_buffering=True)
