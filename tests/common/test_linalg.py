"""Sparse SPD solves (colourhs.common.linalg): equal to a dense solve, and the nearby
solver's CG."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from colourhs.common.linalg import NearbySolver, solve_spd


def _laplacian(n: int, anchor: np.ndarray) -> sp.csr_matrix:
    """A grid Laplacian of n x n pixels plus a small anchor: the normal integration's matrix."""
    d = sp.diags([-np.ones(n - 1), np.ones(n - 1)], [0, 1], shape=(n - 1, n))
    G = sp.vstack([sp.kron(sp.identity(n), d), sp.kron(d, sp.identity(n))])
    return (G.T @ G + sp.diags(anchor)).tocsr()


def test_solve_spd_equals_a_dense_solve():
    rng = np.random.default_rng(0)
    A = _laplacian(20, np.full(400, 1e-4))
    b = rng.standard_normal(400)
    x = solve_spd(A, b)
    ref = np.linalg.solve(A.toarray(), b)
    # measured 2.1e-12 relative (condition number 8e4)
    assert np.max(np.abs(x - ref)) <= 1e-10 * np.max(np.abs(ref))


def test_nearby_solver_reuses_the_factors_and_matches_a_direct_solve():
    rng = np.random.default_rng(1)
    solver = NearbySolver()
    b = rng.standard_normal(900)
    x = None
    for i in range(3):  # reweighted anchors, as refine_depth's three solves
        A = _laplacian(30, 1e-4 * rng.uniform(0.2, 1.0, 900))
        x = solver.solve(A, b, x0=x)
        ref = solve_spd(A, b)
        # measured 2.3e-13 of the solution's size
        assert np.max(np.abs(x - ref)) <= 1e-9 * np.max(np.abs(ref)), i
    assert (solver.factored, solver.abandoned) == (1, 0)
    # another size: factored anew
    A = _laplacian(10, np.full(100, 1e-4))
    x = solver.solve(A, b[:100])
    assert solver.factored == 2
    assert np.allclose(A @ x, b[:100], atol=1e-9)


def _cut_laplacian(n: int, anchor: np.ndarray, keep: np.ndarray) -> sp.csr_matrix:
    """:func:`_laplacian` with only the links ``keep`` (bool, one per link)."""
    d = sp.diags([-np.ones(n - 1), np.ones(n - 1)], [0, 1], shape=(n - 1, n))
    G = sp.vstack([sp.kron(sp.identity(n), d), sp.kron(d, sp.identity(n))]).tocsr()[keep]
    return (G.T @ G + sp.diags(anchor)).tocsr()


def test_nearby_solver_stops_cg_early_where_the_links_changed():
    # The normal integration's next pass: many links cut or restored, so the
    # old factors precondition poorly and CG is stopped at its check (6
    # iterations, not 40), then the system is factored anew: the same answer.
    rng = np.random.default_rng(2)
    n = 30
    links = 2 * n * (n - 1)
    anchor = np.full(n * n, 1e-4)
    b = rng.standard_normal(n * n)
    solver = NearbySolver()
    x = solver.solve(_cut_laplacian(n, anchor, rng.uniform(size=links) > 0.1), b)
    A = _cut_laplacian(n, anchor, rng.uniform(size=links) > 0.1)
    x = solver.solve(A, b, x0=x)
    assert (solver.factored, solver.abandoned) == (2, 1)
    ref = solve_spd(A, b)
    assert np.array_equal(x, ref)  # the direct solve itself
    # a reweighted anchor on the same links: CG converges, nothing abandoned
    A2 = _cut_laplacian(n, anchor * rng.uniform(0.5, 1.0, n * n), np.ones(links, bool))
    solver = NearbySolver()
    x = solver.solve(_cut_laplacian(n, anchor, np.ones(links, bool)), b)
    x = solver.solve(A2, b, x0=x)
    assert (solver.factored, solver.abandoned) == (1, 0)
    # measured 1e-13 of the solution's size
    assert np.max(np.abs(x - solve_spd(A2, b))) <= 1e-9 * np.max(np.abs(x))
