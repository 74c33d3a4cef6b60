"""Equilibrium certificates: is z = (a, lambda) really a (generalized) Nash equilibrium?

Two independent checks. The KKT residuals are read off the compiled KKT parts. The best-response
gaps do not use the Newton machinery at all: each agent's own problem

    min_{a_i} J_i(a_i, a_-i)  s.t. its own constraints g_i(a_i, a_-i) <= 0 (and h_i = 0)

is solved by scipy's SLSQP with the other agents fixed at a_-i, from the candidate, from the config's
start values, where the agent's decisions are bounded from the corners of their box (the lower and the upper
bounds; a nonconvex player's better choices often lie there), and from a seeded perturbation of the candidate
(another basin), and gap_i = J_i(a) - (best value found)
is reported. A gap near zero (or slightly negative, at the level of SLSQP's tolerance) says that no agent can
improve unilaterally from these starts; for nonconvex agent problems it is a local statement.
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
    parts = game.kkt_parts(z, x)
    lam = z[n:]
    eq = game.equality_mask
    ineq = ~eq
    c = parts.c
    stationarity = float(np.max(np.abs(parts.L), initial=0.0))
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
    if starts is None:
        lo, hi = game.a_lower[sl], game.a_upper[sl]
        starts = [a[sl], game.a_start[sl]]
        if np.all(np.isfinite(lo)):
            starts.append(lo.copy())
        if np.all(np.isfinite(hi)):
            starts.append(hi.copy())
        # and seeded perturbations of the candidate, inside the bounds: other basins for a nonconvex player
        rng = np.random.default_rng(agent)
        for scale in PERTURBATIONS:
            shaken = a[sl] + scale * np.maximum(1.0, np.abs(a[sl])) * rng.standard_normal(sl.stop - sl.start)
            starts.append(np.clip(shaken, lo, hi))
    candidates = starts
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
                best: dict[str, np.ndarray] | None = None) -> dict:
    """KKT residuals and every agent's best-response gap at z (SPEC §4 ``certificate``); ``best``, if given,
    receives each agent's best response found."""
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
        value, decision, note = best_response(game, i, a, x, prices=z[n + game.constraint_rows(i)])
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
