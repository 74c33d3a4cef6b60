"""Phase 1: can every constraint of the game hold at once?

A generalized Nash equilibrium satisfies every agent's constraints and every shared one at the same point, so a game
whose rows cannot hold together has none, and a solver can only fail on it. After a failed solve this is checked
directly: the smallest t such that every row holds within t,

    min_{a, t} t   s.t.  g_j(a; x) <= t,  -t <= h_j(a; x) <= t   (every row j, bounds included),

at the given plant state x. Where every row is affine in a (bounds, budgets, the rows of LQ dynamic games) this is a
linear program, solved by HiGHS (scipy.optimize.linprog): its optimum t* > 0 proves that no point satisfies every row
within less than t*, and the rows binding at the optimum realise it. Otherwise it is a smooth nonlinear program
solved locally by SLSQP from several starts: a positive t* is then what the searches found, not a proof.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from ..game.compile import CompiledGame

TOL = 1e-7  # a smallest violation above this (relative to the rows' size) is infeasibility


@dataclass(frozen=True)
class PhaseOne:
    """The outcome of :func:`phase_one`."""

    violation: float  # the smallest largest-violation found: 0 when a point satisfies every row
    rows: list[str]  # labels of the rows that realise it (linear: nonzero duals, weightiest first; else: binding)
    point: np.ndarray | None  # the point found
    proven: bool  # the rows are affine and the linear program's optimum is the smallest violation
    method: str

    @property
    def infeasible(self) -> bool:
        return self.violation > TOL

    def describe(self) -> str:
        shown = "; ".join(self.rows[:4]) + (f"; and {len(self.rows) - 4} more" if len(self.rows) > 4 else "")
        how = ("proven by linear programming: no point satisfies every row within less than this" if self.proven else
               f"{self.method}; the rows are nonlinear, so this is what the searches found, not a proof")
        return f"the constraints cannot all hold: the smallest largest violation is {self.violation:.3g} ({how}), " \
               f"at {shown}"


def phase_one(game: CompiledGame, x: np.ndarray | None = None, starts: list[np.ndarray] = ()) -> PhaseOne | None:
    """Minimise the largest violation of the game's rows (None: a game without rows)."""
    m = game.m
    if m == 0:
        return None
    # rows no decision reaches: conditions on the plant state, reported elsewhere
    fixed = game.pattern.zero_gradient_rows
    rows = np.flatnonzero(~fixed)
    if rows.size == 0:
        return None
    if game.lq.linear_rows[rows].all():
        return _linear(game, x, rows)
    return _nonlinear(game, x, rows, list(starts) + [game.a_start])


def _linear(game: CompiledGame, x: np.ndarray | None, rows: np.ndarray) -> PhaseOne:
    n = game.n
    c0, dc = game.constraint_values(np.zeros(n), x)
    c0, dc = c0[rows], dc[rows]
    eq = game.equality_mask[rows]
    # variables (a, t): dc a + c0 <= t, and for equalities -(dc a + c0) <= t
    A = np.vstack([np.hstack([dc, -np.ones((rows.size, 1))]), np.hstack([-dc[eq], -np.ones((int(eq.sum()), 1))])])
    b = np.concatenate([-c0, c0[eq]])
    cost = np.zeros(n + 1)
    cost[-1] = 1.0
    from scipy.optimize import linprog  # (loaded where a failed solve is diagnosed: 0.2-0.4 s of import)

    res = linprog(cost, A_ub=A, b_ub=b, bounds=[(None, None)] * n + [(0, None)], method="highs")
    if res.status != 0 or not np.all(np.isfinite(res.x)):
        return PhaseOne(math.nan, [], None, False, f"linear programming: {res.message}")
    a = res.x[:n]
    t = float(res.x[-1])
    # the rows that realise the optimum: those with a nonzero dual (a Farkas combination of them proves that no point
    # does better), the weightiest first
    dual = -np.asarray(res.ineqlin.marginals, dtype=float)
    weight = dual[: rows.size].copy()
    weight[np.flatnonzero(eq)] += dual[rows.size:]
    order = [k for k in np.argsort(-weight, kind="stable") if weight[k] > 1e-12] if t > TOL else []
    labels = list(dict.fromkeys(game.constraints[int(rows[k])].label for k in order))  # a shared row's copies once
    return PhaseOne(t, labels, a, True, "linear programming (HiGHS)")


def _binding(game: CompiledGame, rows: np.ndarray, c: np.ndarray, eq: np.ndarray, t: float) -> list[str]:
    over = np.where(eq, np.abs(c), c)
    near = np.flatnonzero(over >= t - 1e-7 * max(1.0, abs(t))) if t > 0 else np.zeros(0, dtype=int)
    return list(dict.fromkeys(game.constraints[int(rows[k])].label for k in near))  # a shared row's copies once


def _nonlinear(game: CompiledGame, x: np.ndarray | None, rows: np.ndarray, starts: list[np.ndarray]) -> PhaseOne:
    from scipy.optimize import minimize  # (loaded where a failed solve is diagnosed)

    n = game.n
    eq = game.equality_mask[rows]

    def values(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        c, dc = game.constraint_values(v[:n], x)
        return c[rows], dc[rows]

    def ineq(v: np.ndarray) -> np.ndarray:
        c, _ = values(v)
        return np.concatenate([v[-1] - c, v[-1] + c[eq]])

    def ineq_jac(v: np.ndarray) -> np.ndarray:
        _, dc = values(v)
        top = np.hstack([-dc, np.ones((rows.size, 1))])
        bottom = np.hstack([dc[eq], np.ones((int(eq.sum()), 1))])
        return np.vstack([top, bottom])

    best: tuple[float, np.ndarray] | None = None
    tried = 0
    for s in starts:
        s = np.asarray(s, dtype=float)
        if s.size != n or not np.all(np.isfinite(s)):
            continue
        tried += 1
        c, _ = values(np.append(s, 0.0))
        t0 = float(max(np.max(np.where(eq, np.abs(c), c)), 0.0)) if np.all(np.isfinite(c)) else 1.0
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = minimize(lambda v: v[-1], np.append(s, t0), jac=lambda v: np.eye(n + 1)[-1], method="SLSQP",
                           constraints=[{"type": "ineq", "fun": ineq, "jac": ineq_jac}],
                           options={"maxiter": 500, "ftol": 1e-14})
        v = np.asarray(res.x, dtype=float)
        if not np.all(np.isfinite(v)):
            continue
        c, _ = values(v)
        if not np.all(np.isfinite(c)):
            continue
        t = float(max(np.max(np.where(eq, np.abs(c), c)), 0.0))  # the violation actually reached
        if best is None or t < best[0]:
            best = (t, v[:n])
        if t <= TOL:
            break
    if best is None:
        return PhaseOne(math.nan, [], None, False, "local searches (SLSQP) ended nowhere finite")
    t, a = best
    c, _ = values(np.append(a, 0.0))
    return PhaseOne(t, _binding(game, rows, c, eq, t), a, False, f"local searches (SLSQP) from {tried} starts")
