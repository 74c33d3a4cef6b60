"""Linear complementarity problems by Lemke's complementary pivoting method.

LCP(M, q): find z >= 0 with w = M z + q >= 0 and z^T w = 0.

Lemke's method (Cottle, Pang & Stone, *The Linear Complementarity Problem*, §4.4) adds an artificial
variable z0 with covering vector d > 0, w = M z + q + d z0, starts from the almost-complementary
basis where z0 enters at the most negative q_i/d_i, and pivots on the complement of each leaving
variable until z0 leaves (a solution) or the entering column has no positive entry (ray
termination: for copositive-plus M this proves the LCP infeasible). Degenerate pivots are resolved
by the lexicographic minimum-ratio rule, which prevents cycling. The tableau is dense: the
problems gnerun hands to it (Josephy-Newton subproblems) have tens to hundreds of rows.

No maintained Python library solves LCPs exactly by pivoting, hence this module.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import numpy as np


class LCPStatus(StrEnum):
    SOLVED = "solved"
    RAY_TERMINATION = "ray_termination"
    MAX_PIVOTS = "max_pivots"


@dataclass(frozen=True)
class LCPResult:
    z: np.ndarray
    w: np.ndarray
    status: LCPStatus
    pivots: int
    message: str

    @property
    def solved(self) -> bool:
        return self.status == LCPStatus.SOLVED


def _lexmin_row(T: np.ndarray, rows: np.ndarray, col: np.ndarray, n: int, tol: float) -> int:
    """Among ``rows`` (positive entries of the entering column), the lexicographic minimum of
    (rhs, B^{-1} row) / column entry. B^{-1} sits in the first n columns (the w columns)."""
    candidates = rows
    keys = [T[:, -1]] + [T[:, j] for j in range(n)]
    for key in keys:
        ratios = key[candidates] / col[candidates]
        best = ratios.min()
        candidates = candidates[ratios <= best + tol * max(1.0, abs(best))]
        if candidates.size == 1:
            break
    return int(candidates[0])


def lemke(M: np.ndarray, q: np.ndarray, d: np.ndarray | None = None, *, max_pivots: int | None = None,
          tol: float = 1e-12) -> LCPResult:
    """Solve LCP(M, q) by Lemke's method with the lexicographic anti-cycling rule."""
    M = np.asarray(M, dtype=float)
    q = np.asarray(q, dtype=float).reshape(-1)
    n = q.size
    if M.shape != (n, n):
        raise ValueError(f"M is {M.shape}, q has {n} entries")
    if n == 0 or np.all(q >= 0):
        z = np.zeros(n)
        return LCPResult(z, q.copy(), LCPStatus.SOLVED, 0, "q >= 0: z = 0 solves the LCP")
    d = np.ones(n) if d is None else np.asarray(d, dtype=float)
    if np.any(d <= 0):
        raise ValueError("the covering vector d must be positive")
    max_pivots = max_pivots if max_pivots is not None else 50 * (n + 1)
    scale = max(1.0, float(np.abs(M).max(initial=0.0)), float(np.abs(q).max()))
    ptol = tol * scale

    # tableau rows: B^{-1} [I | -M | -d | q]; variables: w_0..w_{n-1}, z_0..z_{n-1}, z0 (index 2n)
    T = np.hstack([np.eye(n), -M, -d[:, None], q[:, None]])
    basis = np.arange(n)
    artificial = 2 * n

    def pivot(r: int, c: int) -> None:
        T[r] /= T[r, c]
        others = np.arange(n) != r
        T[others] -= np.outer(T[others, c], T[r])
        basis[r] = c

    # first pivot: z0 enters where q_i / d_i is most negative. Among ties the last index leaves, which
    # keeps every row of (rhs, B^{-1}) lexicographically positive, as the anti-cycling rule requires.
    ratios = q / d
    r = int(np.flatnonzero(ratios <= ratios.min() + tol * max(1.0, abs(ratios.min())))[-1])
    leaving = int(basis[r])
    pivot(r, artificial)
    entering = leaving + n if leaving < n else leaving - n
    pivots = 1
    while pivots < max_pivots:
        col = T[:, entering]
        rows = np.flatnonzero(col > ptol)
        if rows.size == 0:
            z, w = _solution(T, basis, n)
            return LCPResult(z, w, LCPStatus.RAY_TERMINATION, pivots,
                             f"ray termination after {pivots} pivots: the entering column has no positive entry "
                             "(for a copositive-plus M the LCP has no solution)")
        # prefer z0 leaving among tied rows: it ends the path
        r = _lexmin_row(T, rows, col, n, tol)
        ratio = T[r, -1] / col[r]
        z0_row = np.flatnonzero(basis == artificial)
        if z0_row.size and z0_row[0] in rows and T[z0_row[0], -1] / col[z0_row[0]] <= ratio + ptol:
            r = int(z0_row[0])
        leaving = int(basis[r])
        pivot(r, entering)
        pivots += 1
        if leaving == artificial:
            z, w = _solution(T, basis, n)
            w = M @ z + q  # recompute from the data, not from the tableau
            return LCPResult(z, w, LCPStatus.SOLVED, pivots, f"solved in {pivots} pivots")
        entering = leaving + n if leaving < n else leaving - n
    z, w = _solution(T, basis, n)
    return LCPResult(z, w, LCPStatus.MAX_PIVOTS, pivots, f"no solution within {max_pivots} pivots")


def _solution(T: np.ndarray, basis: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    values = np.zeros(2 * n + 1)
    values[basis] = T[:, -1]
    w, z = values[:n], values[n : 2 * n]
    return np.maximum(z, 0.0), w
