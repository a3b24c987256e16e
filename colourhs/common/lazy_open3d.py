"""Start-up time: open3d's plotly viewer, loaded when it is first used, not at ``import open3d``.

Beyond the paper (speed). ``import open3d`` runs
``open3d.visualization.draw_plotly``, which imports dash and plotly for
open3d's browser viewer, a large share of open3d's own import time. colourhs
never uses that viewer, and every evaluation, mesh and hull job of the
workflow imports open3d once, so that cost is paid once per job.
:func:`defer_open3d_plotly` puts a stand-in for that one module in
``sys.modules`` before open3d is imported: every name open3d takes from it is
a function that imports the real module on its first call and calls the real
function, so ``open3d.visualization.draw_plotly(...)`` still works, a little
later. Nothing happens where open3d was already imported, where dash is not
installed, or where ``COLOURHS_EAGER_OPEN3D=1`` is set.
"""

from __future__ import annotations

import importlib.util
import os
import sys
import types

#: The module of open3d's plotly viewer (imports dash and plotly).
PLOTLY_MODULE = "open3d.visualization.draw_plotly"


def _load_real(name: str) -> types.ModuleType:
    """Import module ``name`` itself, replacing its stand-in in ``sys.modules``."""
    module = sys.modules.get(name)
    if isinstance(module, _Deferred):
        del sys.modules[name]
        module = importlib.import_module(name)
    return module


class _Deferred(types.ModuleType):
    """A stand-in module: any public name is a function that loads the real module
    (:func:`_load_real`) and calls the real function of that name."""

    def __getattr__(self, attr: str):
        if attr.startswith("__"):
            raise AttributeError(attr)
        name = self.__name__

        def deferred(*args, **kwargs):
            return getattr(_load_real(name), attr)(*args, **kwargs)

        deferred.__name__ = deferred.__qualname__ = attr
        deferred.__doc__ = (
            f"{name}.{attr}, imported on its first call (colourhs.common.lazy_open3d)."
        )
        return deferred


def defer_open3d_plotly() -> bool:
    """Install the stand-in for :data:`PLOTLY_MODULE`; True when it was installed."""
    if os.environ.get("COLOURHS_EAGER_OPEN3D") == "1":
        return False
    if "open3d" in sys.modules or PLOTLY_MODULE in sys.modules:
        return False
    if importlib.util.find_spec("dash") is None:
        return False
    sys.modules[PLOTLY_MODULE] = _Deferred(PLOTLY_MODULE)
    return True
