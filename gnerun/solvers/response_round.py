"""A round of best responses: a new start for the globalized method where its interior phase stalls from z^0.

A trajectory game started cold (zero inputs) can begin far from every equilibrium and infeasible: in the two-car
overtaking of the robustness suite the faster car drives through the slower one, and at the knot where they coincide
the collision row's gradient vanishes. The interior phase of :mod:`gnerun.solvers.hybrid` then stalls from each of its
starting points. A start from which it does converge is one round of best responses (a Jacobi round, as in iterated
best-response schemes for games): each player's own problem,

    min_{a_i} J_i(a_i, a^0_-i)  s.t.  its own constraints and the shared ones, the others fixed at their start,

solved by SciPy's SLSQP with the game's exact derivatives from the player's start and from seeded perturbations of
it (``PERTURBATIONS`` of its size: a start at a point where a constraint's gradient vanishes goes nowhere), the
lowest feasible cost kept. Every player answers the same plans, so the round does not depend on the players' order.
The players' answers together are the new start: each car has planned around the others, and the coupling rows
are close to where an equilibrium puts them. The joint problem is then solved from there.

Chosen among other new starts (the nearest feasible point, homotopies on the violated rows or the collision radius,
another interior start) on a family of overtaking games: benchmarks/results/solver-design.md.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from ..game.agents import OwnProblem
from ..game.compile import CompiledGame

PERTURBATIONS = (0.1, 1.0)  # relative sizes of the seeded perturbed starts of a player's answer
FEASIBILITY_TOL = 1e-6  # an answer violating its rows by more than this (relative to max(1, |a_i|)) is dropped
MAX_ITER = 100  # SLSQP iterations per start (a start that ends feasible without converging still counts)


def best_answer(game: CompiledGame, agent: int, a: np.ndarray, x: np.ndarray | None,
                starts: list[np.ndarray]) -> tuple[float, np.ndarray] | None:
    """Player ``agent``'s lowest cost, and its decisions, over the feasible end points of SLSQP on its own problem
    (its cost, its own rows and the shared ones; the others fixed at ``a``) from ``starts``; None if none is
    feasible."""
    problem = OwnProblem(game, agent, a, x)
    objective, constraints = problem.objective, problem.constraints()
    from scipy.optimize import minimize  # (loaded when a round of best responses runs: a fallback, 0.2 s of import)

    best: tuple[float, np.ndarray] | None = None
    for s in starts:
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")
            try:  # a start where an expression is undefined is no answer, not a failure of the solve
                res = minimize(objective, np.array(s, dtype=float), jac=True, method="SLSQP", constraints=constraints,
                               options={"maxiter": MAX_ITER})
            except (ValueError, ArithmeticError, np.linalg.LinAlgError):
                continue
        ai = np.asarray(res.x, dtype=float)
        if not np.all(np.isfinite(ai)):
            continue
        viol = problem.violation(ai)
        value = objective(ai)[0]
        if not (math.isfinite(value) and viol <= FEASIBILITY_TOL * max(1.0, float(np.max(np.abs(ai), initial=0.0)))):
            continue
        if best is None or value < best[0]:
            best = (value, ai)
    return best


def answer_starts(game: CompiledGame, agent: int, a: np.ndarray) -> list[np.ndarray]:
    """Player ``agent``'s own plan in ``a`` and seeded perturbations of it (of ``PERTURBATIONS`` times its size), kept
    inside its bounds."""
    sl = game.agent_slices[agent]
    lo, hi = game.a_lower[sl], game.a_upper[sl]
    own = a[sl]
    rng = np.random.default_rng(agent)
    starts = [own.copy()]
    for scale in PERTURBATIONS:
        shaken = own + scale * np.maximum(1.0, np.abs(own)) * rng.standard_normal(own.size)
        starts.append(np.clip(shaken, lo, hi))
    return starts


def response_round(game: CompiledGame, a: np.ndarray, x: np.ndarray | None) -> np.ndarray | None:
    """One Jacobi round of best responses from the decisions ``a``: every player's best answer (:func:`best_answer`)
    to the others' plans in ``a``; a player without a feasible answer keeps its plan. None if no player has one."""
    a = np.asarray(a, dtype=float)
    out = a.copy()
    moved = False
    for i, sl in enumerate(game.agent_slices):
        found = best_answer(game, i, a, x, answer_starts(game, i, a))
        if found is not None:
            out[sl] = found[1]
            moved = True
    return out if moved else None
