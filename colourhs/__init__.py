"""colourhs: Colour Helmholtz Stereopsis, from raw captures to evaluated meshes."""

import os

__version__ = "0.1.0"

# Beyond the paper (speed): NumPy advises the kernel to back every large
# array with transparent huge pages (madvise). Where the kernel's THP defrag
# setting is "madvise" (the upstream default), the first write to each such
# page may then stall in direct memory compaction, and the pipeline's jobs
# each fill fresh volumes of hundreds of MB once. NumPy reads the setting
# when it is first imported, so this takes effect in the command line and
# the workflow's jobs (which import colourhs first), and not where NumPy is
# already imported; set NUMPY_MADVISE_HUGEPAGE=1 to keep NumPy's default.
os.environ.setdefault("NUMPY_MADVISE_HUGEPAGE", "0")

# Beyond the paper (speed): open3d's plotly viewer (dash) is imported on its
# first use, not with open3d, so a job that imports open3d but never plots
# does not pay for dash's import (colourhs.common.lazy_open3d).
from colourhs.common.lazy_open3d import defer_open3d_plotly  # noqa: E402

defer_open3d_plotly()
