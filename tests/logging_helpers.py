"""The ``colourhs`` loggers' configuration kept around a test or fixture.

``colourhs`` (the command line's :func:`colourhs.common.progress.show_progress`)
configures the package's loggers for the whole process; a test that runs it, or a
fixture that shows progress, must leave them as it found them, since other tests
assert that a library call prints nothing.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from contextlib import contextmanager

from colourhs.common.progress import BARS, LOGGER


@contextmanager
def kept_logging() -> Iterator[None]:
    """Restore the handlers, level and propagation of the ``colourhs`` and
    ``colourhs.bars`` loggers on leaving, whatever was configured inside."""
    loggers = [logging.getLogger(name) for name in (LOGGER, BARS)]
    saved = [(list(log.handlers), log.level, log.propagate) for log in loggers]
    try:
        yield
    finally:
        for log, (handlers, level, propagate) in zip(loggers, saved, strict=True):
            log.handlers[:] = handlers
            log.setLevel(level)
            log.propagate = propagate
