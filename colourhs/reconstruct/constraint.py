"""One reciprocal pair's row of the colour HS constraint, eq. (5), for compiled kernels.

A reciprocal pair of Helmholtz cameras (a, b) at a surface point gives the row

    w = s_a v_a - s_b v_b,    w . n = 0 on the surface with normal n,

with ``s`` a side's intensity scaled by mu (eq. 2), the chromaticity p and the
light's fall-off, and ``v`` the direction from the point towards the side's
Helmholtz camera (the data term folds the distance into ``s`` and passes the
unnormalised offset). Beyond the paper: under sensor noise of variance
``var_a`` and ``var_b`` on ``s_a`` and ``s_b``, the residual ``w . n`` has the
variance ``var_a (v_a . n)^2 + var_b (v_b . n)^2`` (:func:`row_variance`), the
Sampson normaliser that puts every row in noise units.

Each function is inlined where it is called (numba, ``inline="always"``), so
the kernels (the data term, the ML cost, the Bayesian surface's residuals)
share the arithmetic at no cost. The plain-NumPy oracle the tests check them
against is ``tests/hs_constraint.py``.
"""

from __future__ import annotations

import numba as nb

__all__ = ["hs_row", "row_variance"]


@nb.njit(cache=True, inline="always")
def hs_row(sa, sb, vax, vay, vaz, vbx, vby, vbz):
    """The row ``w = s_a v_a - s_b v_b`` (3 floats) of eq. (5).

    ``sa``, ``sb``: the two sides' scaled intensities; ``va``, ``vb``: their
    directions towards the Helmholtz cameras (any common scale folded into
    ``sa`` and ``sb``).
    """
    return sa * vax - sb * vbx, sa * vay - sb * vby, sa * vaz - sb * vbz


@nb.njit(cache=True, inline="always")
def row_variance(var_a, var_b, vax, vay, vaz, vbx, vby, vbz, nx, ny, nz):
    """Predicted noise variance of ``w . n`` (beyond the paper: the Sampson normaliser).

    ``var_a (v_a . n)^2 + var_b (v_b . n)^2`` for sides of noise variance
    ``var_a`` and ``var_b`` (the units of ``sa`` and ``sb`` squared) and the
    normal ``n``. Returns the variance, ``v_a . n`` and ``v_b . n``.
    """
    ca = vax * nx + vay * ny + vaz * nz
    cb = vbx * nx + vby * ny + vbz * nz
    return var_a * ca * ca + var_b * cb * cb, ca, cb
