"""Equilibrium certificates: is z = (a, lambda) really a (generalized) Nash equilibrium?

Two checks. The KKT residuals are read off the compiled KKT parts. The best-response gaps solve each agent's own
problem

    min_{a_i} J_i(a_i, a_-i)  s.t. its own constraints g_i(a_i, a_-i) <= 0 (and h_i = 0)

with the other agents fixed at a_-i, from the candidate (warm: with its multipliers), from the config's start
values, where the agent's decisions are bounded from the corners of their box (the lower and the upper bounds; a
nonconvex player's better choices often lie there), and from seeded perturbations of the candidate (other basins),
and gap_i = J_i(a) - (best value found) is reported. A gap near zero (or slightly negative, at the level of the
solver's tolerance) says that no agent can improve unilaterally from these starts; for nonconvex agent problems it
is a local statement.

The agent's problem is solved by Newton steps on its own compiled problem (:class:`NewtonResponses`: the
interior-point method, gnerun.game.compile_agent_problem with tau = 0: its own cost and constraints, the others as
parameters), where a start's solve converges to a feasible point; by scipy's SLSQP, which shares nothing with
the Newton machinery, from the same starts otherwise (or for every start, without ``responses``). Measured on
ALGAMES's 3-car merge (40 decisions and 100 constraint rows per car): 16 s for the three agents by SLSQP, 0.7 s
by Newton, most of it the compilation of the agents' problems.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
from scipy.optimize import minimize

from ..game.compile import CompiledGame

FEASIBILITY_TOL = 1e-9
PERTURBATIONS = (0.1, 1.0)  # relative sizes of the perturbed starts of a best response
GAP_TOL = 1e-6  # a best-response gap above this (relative to max(1, |J_i|)) means the agent can improve alone


def kkt_residuals(game: CompiledGame, z: np.ndarray, x: np.ndarray | None = None) -> dict[str, float]:
    """Natural KKT residual (infinity norm of [L; min(-g, lambda); h]) and its parts."""
    n = game.n
    L, c = game.kkt_residual(z, x)
    lam = z[n:]
    eq = game.equality_mask
    ineq = ~eq
    stationarity = float(np.max(np.abs(L), initial=0.0))
    primal = float(max(np.max(c[ineq], initial=0.0), np.max(np.abs(c[eq]), initial=0.0), 0.0))
    dual = float(max(np.max(-lam[ineq], initial=0.0), 0.0)) + 0.0  # no -0.0
    comp = float(np.max(np.abs(lam[ineq] * c[ineq]), initial=0.0))
    natural = float(max(stationarity, np.max(np.abs(np.minimum(-c[ineq], lam[ineq])), initial=0.0),
                        np.max(np.abs(c[eq]), initial=0.0)))
    return {
        "kkt_residual": natural,
        "stationarity": stationarity,
        "primal_infeasibility": primal,
        "dual_infeasibility": dual,
        "complementarity": comp,
    }


def response_starts(game: CompiledGame, agent: int, a: np.ndarray) -> list[np.ndarray]:
    """Where a best response is sought from: the candidate, the start values, the box's corners (when bounded) and
    seeded perturbations of the candidate inside the box."""
    sl = game.agent_slices[agent]
    lo, hi = game.a_lower[sl], game.a_upper[sl]
    starts = [a[sl], game.a_start[sl]]
    if np.all(np.isfinite(lo)):
        starts.append(lo.copy())
    if np.all(np.isfinite(hi)):
        starts.append(hi.copy())
    rng = np.random.default_rng(agent)
    for scale in PERTURBATIONS:
        shaken = a[sl] + scale * np.maximum(1.0, np.abs(a[sl])) * rng.standard_normal(sl.stop - sl.start)
        starts.append(np.clip(shaken, lo, hi))
    return starts


class NewtonResponses:
    """Best responses by Newton steps on each agent's own problem (built on first use: gnerun.game.compile_agent_problem
    with tau = 0, whose parameters are the plant state and the others' decisions): the interior-point method of the
    globalized solver (``globalization: interior_point``), whose direction makes the player's own block positive
    definite, so that it descends to a minimum of the player's problem; the plain semismooth Newton step would
    stop at any stationary point, a concave player's maximum included. A start counts when its solve converges to a
    point that satisfies the agent's constraints within ``FEASIBILITY_TOL``."""

    MAX_ITER = 200

    def __init__(self, cfg, game: CompiledGame):
        self.cfg = cfg
        self.game = game
        self._solvers: dict[int, tuple[CompiledGame, object, np.ndarray]] = {}

    def _solver(self, agent: int):
        if agent not in self._solvers:
            from ..game.compile import compile_agent_problem
            from ..language.config import SolverConfig
            from .hybrid import globalized
            from .ssn import SemismoothNewton

            problem = compile_agent_problem(self.cfg, agent, 0.0)
            opts = SolverConfig(**{**self.cfg.solver.model_dump(), "kind": "ssn", "globalization": "interior_point",
                                   "formulation": "condensed", "max_iter": self.MAX_ITER,
                                   "tol": min(self.cfg.solver.tol, 1e-10)})
            # the candidate's multipliers in the agent problem's row order (matched by label: the game lists an
            # agent's own rows, then the common shared rows; the agent's problem, stage by stage)
            rows = self.game.constraint_rows(agent)
            free: dict[str, list[int]] = {}
            for k, r in enumerate(rows):
                free.setdefault(self.game.constraints[r].label, []).append(k)
            order = np.array([free[c.label].pop(0) if free.get(c.label) else -1 for c in problem.constraints],
                             dtype=int)
            self._solvers[agent] = (problem, globalized(SemismoothNewton(problem, opts)), order)
        return self._solvers[agent]

    def best_response(self, agent: int, a: np.ndarray, x: np.ndarray | None, starts: list[np.ndarray],
                      multipliers: np.ndarray | None = None) -> tuple[float | None, np.ndarray | None, int]:
        """(best value, its decision, how many starts ended feasible and converged); the first start is warm with
        ``multipliers`` (the candidate's, in the agent's row order)."""
        from .ssn import FAILURES, Status

        problem, solver, order = self._solver(agent)
        game = self.game
        sl = game.agent_slices[agent]
        xv = game.x0 if x is None else np.asarray(x, dtype=float)
        p = np.concatenate([xv, a[: sl.start], a[sl.stop:], a[sl]])
        best_val, best_x, counted = None, None, 0
        own = float(game.costs(a, x)[agent])  # the candidate's cost: a start that did not converge must beat it
        for k, s in enumerate(starts):
            lam = np.zeros(problem.m)
            if k == 0 and multipliers is not None and (order >= 0).all():
                lam = multipliers[order]
            state = solver.init(np.concatenate([np.asarray(s, dtype=float), lam]), p)
            while not solver.terminate(state)[0]:
                state = solver.step(state)
            converged = solver.terminate(state)[1] == Status.CONVERGED and state.status not in FAILURES
            ai = state.z[: problem.n]
            if not np.all(np.isfinite(ai)):
                continue
            c = problem.constraint(ai, p)
            eq = problem.equality_mask
            viol = max(float(np.max(c[~eq], initial=0.0)), float(np.max(np.abs(c[eq]), initial=0.0)))
            if not viol <= FEASIBILITY_TOL * max(1.0, float(np.max(np.abs(ai), initial=0.0))):
                continue
            b = a.copy()
            b[sl] = ai
            val = float(game.costs(b, x)[agent])
            counted += converged
            # a start that did not converge still counts where it ended feasible and better: a feasible point of
            # lower cost proves that the agent can improve (a player whose cost is unbounded below diverges)
            if math.isfinite(val) and (converged or val < own) and (
                    best_val is None or val < best_val):
                best_val, best_x = val, ai
        return best_val, best_x, counted


def best_response(game: CompiledGame, agent: int, a: np.ndarray, x: np.ndarray | None = None,
                  starts: list[np.ndarray] | None = None,
                  prices: np.ndarray | None = None) -> tuple[float | None, np.ndarray | None, str]:
    """Agent ``agent``'s best response to a_-i: (value, its decision, a note).

    SLSQP's answers may violate the constraints within ``FEASIBILITY_TOL``; with ``prices`` (the candidate's
    multipliers of the agent's rows, in ``constraint_rows`` order) such a point is charged for its violations at
    those prices, so that violating a constraint by 1e-9 at a multiplier of 100 does not count as a gain of 1e-7."""
    a = np.asarray(a, dtype=float)
    sl = game.agent_slices[agent]
    rows = game.constraint_rows(agent)
    eq_rows = rows[game.equality_mask[rows]]
    in_rows = rows[~game.equality_mask[rows]]
    last: dict = {}

    def full(ai: np.ndarray) -> np.ndarray:
        b = a.copy()
        b[sl] = ai
        return b

    def values(ai: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The constraint values and their Jacobian at a_i (kept for the next call at the same point: SLSQP asks
        for the function and the Jacobian separately)."""
        key = ai.tobytes()
        if last.get("key") != key:
            c, dc = game.constraint_values(full(ai), x)
            last.update(key=key, c=c, dc=dc[:, sl])
        return last["c"], last["dc"]

    def objective(ai: np.ndarray) -> tuple[float, np.ndarray]:
        b = full(ai)
        return float(game.costs(b, x)[agent]), game.cost_gradients(b, x)[agent, sl]

    constraints = []
    if in_rows.size:
        constraints.append({"type": "ineq", "fun": lambda ai: -values(ai)[0][in_rows],
                            "jac": lambda ai: -values(ai)[1][in_rows]})
    if eq_rows.size:
        constraints.append({"type": "eq", "fun": lambda ai: values(ai)[0][eq_rows],
                            "jac": lambda ai: values(ai)[1][eq_rows]})
    candidates = response_starts(game, agent, a) if starts is None else starts
    best_val, best_x, notes = None, None, []
    for s in candidates:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = minimize(objective, np.array(s, dtype=float), jac=True, method="SLSQP", constraints=constraints,
                           options={"ftol": 1e-15, "maxiter": 300})
        ai = np.asarray(res.x, dtype=float)
        c = values(ai)[0]
        viol = max(float(np.max(c[in_rows], initial=0.0)), float(np.max(np.abs(c[eq_rows]), initial=0.0)))
        val = objective(ai)[0]
        if prices is not None:
            over = np.where(game.equality_mask[rows], np.abs(c[rows]), np.maximum(c[rows], 0.0))
            val += float(np.abs(prices) @ over)
        if not math.isfinite(val) or viol > FEASIBILITY_TOL * max(1.0, float(np.max(np.abs(ai), initial=0.0))):
            notes.append(f"SLSQP from a start ended infeasible ({res.message})")
            continue
        if best_val is None or val < best_val:
            best_val, best_x = val, ai
    note = "; ".join(notes) if best_val is None else "ok"
    return best_val, best_x, note


def certificate(game: CompiledGame, z: np.ndarray, x: np.ndarray | None = None,
                best: dict[str, np.ndarray] | None = None, responses: NewtonResponses | None = None) -> dict:
    """KKT residuals and every agent's best-response gap at z (``certificate`` in summary.json); ``best``, if
    given, receives each agent's best response found. With ``responses``, the best responses are Newton solves of
    the agents' own problems, and SLSQP's where none of those ends feasible; without, SLSQP's."""
    n = game.n
    a = np.asarray(z[:n], dtype=float)
    out: dict = kkt_residuals(game, z, x)
    if not np.all(np.isfinite(z)):
        out["best_response_gap"] = {name: None for name in game.agent_names}
        out["best_response_note"] = {name: "the candidate is not finite" for name in game.agent_names}
        return out
    values = game.costs(a, x)
    gaps: dict[str, float | None] = {}
    notes: dict[str, str] = {}
    for i, name in enumerate(game.agent_names):
        prices = z[n + game.constraint_rows(i)]
        value = None
        if responses is not None:
            starts = response_starts(game, i, a)
            value, decision, counted = responses.best_response(i, a, x, starts, prices)
            note = f"ok (Newton, {counted} of {len(starts)} starts)"
        if value is None:
            value, decision, note = best_response(game, i, a, x, prices=prices)
            if responses is not None:
                note = f"{note} (SLSQP: no Newton start ended feasible)"
        gaps[name] = None if value is None else float(values[i] - value)
        notes[name] = note
        if best is not None and decision is not None:
            best[name] = decision
    out["best_response_gap"] = gaps
    out["best_response_note"] = notes
    return out


def improving_agents(game: CompiledGame, cert: dict, a: np.ndarray, x: np.ndarray | None = None) -> dict[str, float]:
    """The agents whose best-response gap in ``cert`` exceeds GAP_TOL max(1, |J_i(a)|): at a KKT point of a game
    with nonconvex players, each of them can improve on its own, so the point is not an equilibrium."""
    gaps = cert.get("best_response_gap") or {}
    values = game.costs(np.asarray(a, dtype=float), x)
    return {name: gap for (name, gap), value in zip(gaps.items(), values, strict=True)
            if gap is not None and gap > GAP_TOL * max(1.0, abs(float(value)))}
