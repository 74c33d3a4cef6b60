"""Phase 1: can every constraint of the game hold at once?

A generalized Nash equilibrium satisfies every agent's constraints and every shared one at the same point, so a game
whose rows cannot hold together has none, and a solver can only fail on it. After a failed solve this is checked
directly: the smallest t such that every row holds within t,

    min_{a, t} t   s.t.  g_j(a; x) <= t,  -t <= h_j(a; x) <= t   (every row j, bounds included),

at the given plant state x. Where every row is affine in a (bounds, budgets, the rows of LQ dynamic games) this is a
linear program, solved by HiGHS (scipy.optimize.linprog): its optimum t* > 0 proves that no point satisfies every row
within less than t*, and the rows binding at the optimum realise it. Otherwise it is a smooth nonlinear program:
``DESIGN`` points of a low-discrepancy design over the decisions' box are screened first (any of them, or a start,
that satisfies every row ends the question), then SLSQP searches from the starts and from the ``SEARCHES`` least
violated design points; a positive t* is then what the searches found, not a proof. (With two local searches from
the solver's last iterate and the start values, 35 of about 700 random feasible games were called infeasible, one
of them satisfied by its zero inputs.)
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from ..game.compile import CompiledGame
from .design import kronecker

TOL = 1e-7  # a smallest violation above this (relative to the rows' size) is infeasibility
DESIGN = 512  # nonlinear rows: design points screened for a feasible point before the local searches
SEARCHES = 6  # ... and the least violated of them that the local searches start from (after the given starts)
SPREAD = 10.0  # an unbounded decision's range in the design: this times max(1, |start|) on each open side


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
    starts = [np.asarray(s, dtype=float) for s in [*starts, game.a_start]]
    starts = [s for s in starts if s.size == game.n and np.all(np.isfinite(s))]
    found, design = _screened(game, x, rows, starts)
    if found is not None:
        return found
    return _nonlinear(game, x, rows, starts + design)


def _screened(game: CompiledGame, x: np.ndarray | None, rows: np.ndarray,
              starts: list[np.ndarray]) -> tuple[PhaseOne | None, list[np.ndarray]]:
    """The starts and ``DESIGN`` design points over the decisions' box (an open side ``SPREAD`` times the start's
    size), evaluated at once: a point that satisfies every row (then the game is feasible), or the ``SEARCHES``
    least violated design points."""
    lo, hi, s = game.a_lower, game.a_upper, game.a_start
    r = SPREAD * np.maximum(1.0, np.abs(s))
    low = np.where(np.isfinite(lo), lo, np.where(np.isfinite(hi), np.minimum(hi, s) - r, s - r))
    high = np.where(np.isfinite(hi), hi, np.where(np.isfinite(lo), np.maximum(lo, s) + r, s + r))
    design = low + kronecker(game.n, DESIGN, np.random.default_rng(0)) * (high - low)
    points = np.vstack([*starts, np.clip(np.zeros(game.n), lo, hi), design])
    _, C = game.agents.evaluate_many(points, x)
    c = C[:, rows]
    eq = game.equality_mask[rows]
    with np.errstate(invalid="ignore"):
        viol = np.max(np.where(eq, np.abs(c), np.maximum(c, 0.0)), axis=1, initial=0.0)
    viol = np.where(np.isfinite(viol), viol, np.inf)
    k = int(np.argmin(viol))
    if viol[k] <= TOL:
        return PhaseOne(float(viol[k]), [], points[k], False, "a point of a design over the box"), []
    order = np.argsort(viol[len(points) - DESIGN:], kind="stable")[:SEARCHES]
    return None, [design[j] for j in order if np.isfinite(viol[len(points) - DESIGN + j])]


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
