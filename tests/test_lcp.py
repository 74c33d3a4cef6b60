"""Lemke's method against brute-force enumeration of complementary bases."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from gnerun.solvers.josephy_newton import solve_affine_vi
from gnerun.solvers.lcp import LCPStatus, lemke


def enumerate_solutions(M: np.ndarray, q: np.ndarray, tol: float = 1e-9) -> list[np.ndarray]:
    """Every solution of LCP(M, q) that is a complementary basic solution (2^n linear solves)."""
    n = q.size
    out = []
    for pattern in itertools.product([False, True], repeat=n):
        S = np.array(pattern, dtype=bool)
        z = np.zeros(n)
        if S.any():
            B = M[np.ix_(S, S)]
            if abs(np.linalg.det(B)) < 1e-12:
                continue
            z[S] = np.linalg.solve(B, -q[S])
        w = M @ z + q
        if np.all(z >= -tol) and np.all(w >= -tol):
            out.append(z)
    return out


def _is_solution(M, q, z, tol=1e-8) -> bool:
    w = M @ z + q
    return bool(np.all(z >= -tol) and np.all(w >= -tol) and abs(z @ w) <= tol * max(1.0, np.abs(q).max()))


def _p_matrix(rng, n):
    # positive definite symmetric part: a P-matrix (every principal minor positive)
    A = rng.standard_normal((n, n))
    S = rng.standard_normal((n, n))
    return A @ A.T + 0.1 * np.eye(n) + (S - S.T)


@pytest.mark.parametrize("seed", range(5))
def test_p_matrix_lcps_match_the_unique_enumerated_solution(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for _ in range(40):
        n = int(rng.integers(1, 7))
        M = _p_matrix(rng, n)
        q = 3 * rng.standard_normal(n)
        [expected] = enumerate_solutions(M, q)
        result = lemke(M, q)
        assert result.status == LCPStatus.SOLVED
        np.testing.assert_allclose(result.z, expected, atol=1e-9)
        np.testing.assert_allclose(result.w, M @ result.z + q, atol=1e-12)


@pytest.mark.parametrize("seed", range(5))
def test_copositive_plus_lcps_are_solved_or_proven_infeasible(seed: int) -> None:
    # M = PSD + skew-symmetric (copositive-plus). Lemke solves every feasible LCP of this class and ends
    # on a ray only when the LCP has no solution.
    rng = np.random.default_rng(100 + seed)
    solved = rays = 0
    for _ in range(40):
        n = int(rng.integers(2, 7))
        A = rng.standard_normal((n, max(1, n - 2)))  # rank deficient: PSD, not PD
        S = rng.standard_normal((n, n))
        M = A @ A.T + (S - S.T) * rng.integers(0, 2)
        q = 2 * rng.standard_normal(n)
        result = lemke(M, q)
        found = enumerate_solutions(M, q)
        if result.status == LCPStatus.SOLVED:
            assert _is_solution(M, q, result.z)
            solved += 1
        else:
            assert result.status == LCPStatus.RAY_TERMINATION
            assert found == [], "Lemke ended on a ray although the LCP has a solution"
            rays += 1
    assert solved > 10


def test_nonnegative_matrices_with_degenerate_data_terminate() -> None:
    # integer data with many ties exercise the lexicographic rule; nonnegative M is copositive-plus
    rng = np.random.default_rng(7)
    for _ in range(200):
        n = int(rng.integers(2, 6))
        M = rng.integers(0, 3, size=(n, n)).astype(float) + np.eye(n)
        q = rng.integers(-2, 2, size=n).astype(float)
        result = lemke(M, q)
        assert result.status == LCPStatus.SOLVED  # strictly copositive: always solvable
        assert _is_solution(M, q, result.z)


def test_ray_termination_is_reported() -> None:
    # w2 = -2 z2 - 2 >= 0 is impossible for z2 >= 0: no solution
    result = lemke(np.array([[2.0, -1.0], [0.0, -2.0]]), np.array([-1.0, -2.0]))
    assert result.status == LCPStatus.RAY_TERMINATION
    assert "ray termination" in result.message


def test_trivial_and_shape_errors() -> None:
    r = lemke(np.eye(3), np.array([1.0, 0.0, 2.0]))
    assert r.solved and r.pivots == 0 and np.all(r.z == 0)
    with pytest.raises(ValueError):
        lemke(np.eye(2), np.ones(3))


def test_affine_vi_with_bounds_free_variables_and_equalities() -> None:
    # min over a box and a hyperplane of a strongly monotone affine map; check the KKT conditions
    rng = np.random.default_rng(3)
    for _ in range(30):
        n = 4
        M = _p_matrix(rng, n)
        q = 5 * rng.standard_normal(n)
        # rows: a_0 >= -1 (bound), a_1 <= 2 (bound), a_2 + a_3 <= 1, a_0 - a_1 + a_2 == 0.5; a_3 free
        G = np.array([[-1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, 1.0], [1.0, -1.0, 1.0, 0]])
        h = np.array([1.0, 2.0, 1.0, 0.5])
        eq = np.array([False, False, False, True])
        a, lam, result = solve_affine_vi(M, q, G, h, eq)
        assert result.solved
        np.testing.assert_allclose(M @ a + q + G.T @ lam, 0.0, atol=1e-9)
        slack = h - G @ a
        assert np.all(slack[~eq] >= -1e-9) and abs(slack[3]) <= 1e-9
        assert np.all(lam[~eq] >= -1e-12)
        np.testing.assert_allclose(lam[~eq] * slack[~eq], 0.0, atol=1e-8)
