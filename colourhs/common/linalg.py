"""Sparse symmetric positive definite solves: the normal equations of the least squares.

Beyond the paper (numerics only). The refinement's Gauss-Newton and
Levenberg-Marquardt steps, the normal integration and the spline fits
all solve ``A x = b`` with ``A = J^T J + D`` symmetric positive definite.
SuperLU in its symmetric mode (a minimum-degree ordering of ``A + A^T``,
pivots kept on the diagonal) factors them without the unsymmetric
column ordering and pivot search that :func:`scipy.sparse.linalg.spsolve`
uses by default, to the same solution within rounding.

:class:`NearbySolver` solves a sequence of such systems that differ a
little (the normal integration's reweighted anchors and passes) by
conjugate gradients preconditioned with the first one's factors.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import LinearOperator, cg, splu


def solve_spd(A: sp.spmatrix, b: np.ndarray) -> np.ndarray:
    """Solve ``A x = b`` for a sparse symmetric positive definite ``A``.

    The solution equals :func:`scipy.sparse.linalg.spsolve`'s within
    rounding, which grows with ``A``'s condition number (large for the
    refinement's lightly damped systems).

    Parameters
    ----------
    A : (n, n) sparse, symmetric positive definite (not checked).
    b : (n,) right-hand side.

    Returns
    -------
    (n,) solution.
    """
    return _factor(A).solve(np.asarray(b, float))


def _factor(A):
    return splu(
        sp.csc_matrix(A),
        permc_spec="MMD_AT_PLUS_A",
        diag_pivot_thresh=0.0,
        options={"SymmetricMode": True},
    )


class _OffTrack(Exception):
    """CG's residual will not reach the tolerance within the iterations allowed."""


class NearbySolver:
    """Solves a sequence of nearby sparse SPD systems ``A_i x = b_i``.

    The first is factored as :func:`solve_spd` does; each next one is solved
    by conjugate gradients preconditioned with the last factors, from
    ``x0``, to a residual ``rtol`` times ``|b|``; where that takes more than
    ``max_iter`` iterations (or the size changed) it is factored anew.

    ``rtol`` 1e-12 is the direct solve's own accuracy, so CG's answer is as
    good as a fresh factorisation's, in a few iterations where the
    preconditioner still fits.

    Beyond a plain CG: the residual is checked at iterations
    ``check_at // 2`` and ``check_at``; where the rate between them (decades
    per iteration) would need more than ``slack * max_iter`` iterations in
    all to reach ``rtol``, CG stops there and the system is factored anew,
    as it would be after ``max_iter`` iterations. The same answer, without
    the iterations that could not converge: when the normal integration's
    links change between passes the old factors are a poor preconditioner,
    and CG would spend all ``max_iter`` iterations without reaching
    ``rtol``. ``slack`` allows for CG's rate improving as it goes
    (superlinear convergence once the few outlying eigenvalues are
    resolved), so it separates the solves that go on to converge from those
    that do not. CG is stopped only while its residual is still above
    ``stop_above`` of ``|b|``: there the old factors have not yet captured
    the system. Below it a flat stretch is CG's plateau before the outlying
    eigenvalues resolve, and stopping it would change the depths through
    the refinement's discrete choices, where CG and the direct solve agree
    to ``rtol``.
    """

    def __init__(
        self,
        rtol: float = 1e-12,
        max_iter: int = 40,
        check_at: int = 6,
        slack: float = 1.4,
        stop_above: float = 1e-2,
    ):
        self.rtol, self.max_iter, self.check_at, self.slack = rtol, max_iter, check_at, slack
        self.stop_above = stop_above
        self.lu = None
        self.factored = 0  # how many systems were factored (for tests and logs)
        self.abandoned = 0  # CG solves stopped at the check (for tests and logs)

    def solve(self, A: sp.spmatrix, b: np.ndarray, x0: np.ndarray | None = None) -> np.ndarray:
        """The solution (n,) of ``A x = b``; ``x0`` a starting guess for CG."""
        b = np.asarray(b, float)
        if self.lu is not None and self.lu.shape == A.shape:
            A = sp.csr_matrix(A)
            M = LinearOperator(A.shape, self.lu.solve)
            try:
                x, info = cg(
                    A,
                    b,
                    x0=x0,
                    rtol=self.rtol,
                    atol=0.0,
                    maxiter=self.max_iter,
                    M=M,
                    callback=self._watch(A, b),
                )
            except _OffTrack:
                self.abandoned += 1
                info = -1
            if info == 0:
                return x
        self.lu = _factor(A)
        self.factored += 1
        return self.lu.solve(b)

    def _watch(self, A, b):
        """CG's callback: raises :class:`_OffTrack` at iteration ``check_at`` where the
        residual is above ``stop_above |b|`` and its rate since iteration
        ``check_at // 2`` would need more than ``slack * max_iter`` iterations in
        all to reach ``rtol |b|``."""
        bnorm = np.linalg.norm(b)
        target, high = self.rtol * bnorm, self.stop_above * bnorm
        half = self.check_at // 2
        count, r_half = 0, None

        def callback(xk):
            nonlocal count, r_half
            count += 1
            if count not in (half, self.check_at):
                return
            r = np.linalg.norm(b - A @ xk)
            if count == half:
                r_half = r
            elif r > high:
                if r >= r_half:
                    raise _OffTrack
                rate = np.log(r_half / r) / (self.check_at - half)
                if count + np.log(r / target) / rate > self.slack * self.max_iter:
                    raise _OffTrack

        return callback
