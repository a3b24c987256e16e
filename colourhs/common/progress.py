"""Progress on stderr for the stages that run long at paper scale.

Every Snakemake rule sends a job's stdout and stderr to its log, so progress
must read well in a file as well as at a terminal: one line per stage
(:func:`stage`, a :mod:`logging` record, with the seconds since the job's start)
where there is no loop, and a tqdm bar (:func:`bar`) redrawn at most every
:data:`MIN_INTERVAL_S` over the loops that take long.

Who shows them is the caller's choice, not a parameter of every function: the
stage lines go to each module's logger under ``colourhs``, which by default
inherits the root logger's WARNING level (a library call prints nothing), and
the bars show only when the :data:`BARS` logger is enabled for INFO (its own
switch, below ``colourhs``). The command line calls :func:`show_progress`; a
library caller may too, or configure :mod:`logging` itself.
"""

from __future__ import annotations

import logging
import sys
from time import perf_counter

from tqdm import tqdm

__all__ = [
    "BARS",
    "LOGGER",
    "MIN_INTERVAL_S",
    "bar",
    "bars_enabled",
    "line_buffered",
    "show_progress",
    "stage",
]

MIN_INTERVAL_S = 2.0
"""Shortest time between two redraws of a bar, seconds (a log gets a line per redraw)."""

LOGGER = "colourhs"
"""The package's logger: every module's logger is below it."""

BARS = "colourhs.bars"
"""The bars' switch: a bar is shown when this logger is enabled for INFO."""


def stage(log: logging.Logger, text: str, start: float | None = None) -> None:
    """Log one progress line at INFO: ``text``, then the seconds since ``start``.

    Parameters
    ----------
    log : logging.Logger
        The calling module's logger (``logging.getLogger(__name__)``).
    text : str
        What starts now, e.g. ``"visual hull: carving 696 x 577 x 1128 voxels"``.
    start : float, optional
        A :func:`time.perf_counter` reading (the job's start); adds ``" [12.3 s]"``.
    """
    elapsed = "" if start is None else f" [{perf_counter() - start:.1f} s]"
    log.info(f"{text}{elapsed}")


def bars_enabled() -> bool:
    """Whether :func:`bar` shows its bars: the :data:`BARS` logger is enabled for INFO
    (it inherits ``colourhs``'s level unless set itself)."""
    return logging.getLogger(BARS).isEnabledFor(logging.INFO)


def bar(iterable=None, desc: str = "", total: int | None = None, disable: bool = False, **kw):
    """A tqdm progress bar on stderr, redrawn at most every :data:`MIN_INTERVAL_S`.

    Shown when :func:`bars_enabled`, in a log file too (unlike tqdm's
    ``disable=None``), without a line per item; otherwise a silent bar that
    iterates and prints nothing. Keyword arguments go to :class:`tqdm.tqdm`
    (``unit``, ...).

    Parameters
    ----------
    iterable : iterable, optional
    desc : str
        The bar's label.
    total : int, optional
        Number of items (default ``len(iterable)``).
    disable : bool
        Hide this bar whatever the switch (a loop with nothing to show this time).
    """
    return tqdm(
        iterable,
        desc=desc,
        total=total,
        disable=disable or not bars_enabled(),
        mininterval=MIN_INTERVAL_S,
        # Every update may redraw (once MIN_INTERVAL_S has passed): tqdm's default
        # adapts a minimum of items between redraws to the first items' rate, so a
        # loop whose items slow down would go silent.
        miniters=1,
        file=sys.stderr,
        dynamic_ncols=False,
        **kw,
    )


class _StderrHandler(logging.StreamHandler):
    """A handler that writes to whatever ``sys.stderr`` is when a record is emitted
    (a redirected stderr, a test's capture), not the stream it was created with."""

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, value) -> None:  # StreamHandler's __init__ and setStream set it
        pass


def show_progress(bars: bool = True, level: int = logging.INFO) -> None:
    """Show the stage lines (``"%(message)s"``) and the bars on stderr: the command line's
    setting.

    Adds one handler to the ``colourhs`` logger (a second call adds none), sets that
    logger's level and stops its records reaching the root logger's handlers (which
    would print each line twice where the root is configured too).

    Parameters
    ----------
    bars : bool
        Show the tqdm bars with the stage lines (the :data:`BARS` logger follows
        ``colourhs``'s level); False hides them (that logger at WARNING).
    level : int
        The ``colourhs`` logger's level: ``logging.INFO`` shows the stage lines,
        ``logging.WARNING`` hides them, and the bars with them.
    """
    log = logging.getLogger(LOGGER)
    if not any(isinstance(h, _StderrHandler) for h in log.handlers):
        handler = _StderrHandler()
        handler.setFormatter(logging.Formatter("%(message)s"))
        log.addHandler(handler)
    log.setLevel(level)
    log.propagate = False
    # NOTSET: the bars follow the stage lines (hidden with them at WARNING).
    logging.getLogger(BARS).setLevel(logging.NOTSET if bars else logging.WARNING)


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
