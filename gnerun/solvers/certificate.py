"""Equilibrium certificates: is z = (a, lambda) really a (generalized) Nash equilibrium?

Two checks. The KKT residuals are read off the compiled KKT parts. The best-response gaps solve each agent's own
problem

    min_{a_i} J_i(a_i, a_-i)  s.t. its own constraints g_i(a_i, a_-i) <= 0 (and h_i = 0)

with the other agents fixed at a_-i, and gap_i = J_i(a) - (best value found) is reported, with the kind of
statement it is (``best_response_kind``):

- **global on the box**: for a player with at most three decisions, an interval branch and bound over its box
  (its bounds) proves that no feasible point of the box has a cost below J_i(a) - tol, or finds one that has
  (:mod:`gnerun.solvers.global_response`); **global on the search box** where a decision is unbounded: the box is
  then of radius ``BOX_RADIUS`` times the point's size around the candidate in that decision, and a cheaper point
  farther away is not excluded (the rays below look along lines only);
- **global (convex)**: in an LQ game, a player whose own Hessian block is positive semidefinite has a
  convex problem (its rows are affine), whose KKT points are its minima: the candidate, a KKT point, is its best
  response, and the local solves confirm the gap;
- **global (QP faces)**: in an LQ game, a small player whose block is not positive semidefinite, every decision
  bounded: the stationary points of its cost on every face of its polytope (:func:`_qp_faces`) hold its minimum;
- **over N starts**: otherwise, the best of local solves from the starts below, a statement about those starts.

Every start is first compared as it is, before any local solve (a start better than the candidate is a proof
already, wherever a local solve from it goes). The starts cover the player's feasible set: the candidate (warm,
with its multipliers), the config's start values, the corners of bounded decisions, the other players' decisions
and start values where they have as many decisions (symmetric games), seeded perturbations of the candidate
scaled per decision to its box (or to its size, where unbounded), and a low-discrepancy design in the box (a
randomly shifted Kronecker sequence, :func:`kronecker`), seeded by the agent and the candidate. Local solves run
from the candidate, the start values, the two extreme corners, the perturbations, the best design points and any
start already better than the candidate: Newton steps on the agent's own compiled problem (:class:`NewtonResponses`,
the interior-point method, whose direction makes the player's block positive definite so that it descends to a
minimum, never to a maximum), and scipy's SLSQP, which shares nothing with the Newton machinery, where no Newton
start ends feasible (or for every start, without ``responses``).

Three more things make a point fail the certificate, whatever the gaps:

- **a player without a best response** (:mod:`gnerun.solvers.unbounded`): along a ray from the candidate, feasible
  for the player's rows, its cost keeps decreasing over eight decades of the step (unbounded below, or towards an
  infimum it never attains). ``unbounded`` records the direction and the costs seen;
- **a cost that is not finite** at the candidate (nan, inf, or a non-finite gradient): ``not_finite``;
- **a kink**: where a piecewise function of the decisions (abs, min, max) is at its kink in a player's cost or
  rows, the KKT conditions used one branch's derivative. The branches are then compared directly: points a small
  step away along every coordinate (both signs) and along seeded random directions join the compared starts;
  ``kinks`` names the functions.
"""

from __future__ import annotations

import itertools
import math
import warnings
import zlib
from dataclasses import dataclass, field

import numpy as np

from ..game.agents import OwnProblem
from ..game.compile import CompiledGame
from ..game.tape import Tape, UnsupportedTape
from . import global_response, unbounded
from .design import kronecker
from .unbounded import Ray

FEASIBILITY_TOL = 1e-9
# a local solve's interior-point iterates are polished by Newton steps once ||Phi|| <= POLISH (each step kept only where
# it reduces ||Phi||): on 100 ALGAMES merges the certificate's median 134 -> 98 ms, no certificate changed
POLISH = 1e-4
PERTURBATIONS = (0.1, 1.0)  # relative sizes of the perturbed starts of a best response (of the box, or of |a_i|)
GAP_TOL = 1e-6  # a best-response gap above this (relative to max(1, |J_i|)) means the agent can improve alone
KINK_TOL = 1e-6  # a piecewise function this close to its kink (relative) is at its kink
KINK_STEPS = (1e-6, 1e-4, 1e-2)  # the probes' steps away from a kink, times max(1, |a_i|)
BOX_RADIUS = 100.0  # the box search's half-width on unbounded decisions, times max(1, |a_i|, |start|)
DESIGN_SMALL, DESIGN_LARGE = 256, 32  # design points compared as they are (players of <= MAX_DIM decisions; others)
LOCAL_FROM_DESIGN = 4  # players of <= MAX_DIM decisions: local solves start from the best compared points too
# ... and larger players from their best two: a 6-robot formation's KKT point (draw 7 of seed 1) at which robot 4 gains
# 2e-3 alone was certified "over 54 starts" without them (SLSQP from random plans finds the gain)
LOCAL_FROM_DESIGN_LARGE = 2


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
    if not all(math.isfinite(v) for v in (stationarity, primal, comp)) or not np.all(np.isfinite(L)):
        natural = math.nan
    return {
        "kkt_residual": natural,
        "stationarity": stationarity,
        "primal_infeasibility": primal,
        "dual_infeasibility": dual,
        "complementarity": comp,
    }


def _seed(agent: int, a: np.ndarray) -> list[int]:
    """A seed for an agent's random starts at candidate a: reproducible, and different at every candidate."""
    return [agent, zlib.crc32(np.ascontiguousarray(a, dtype=float).tobytes())]


def _scales(game: CompiledGame, agent: int, a: np.ndarray) -> np.ndarray:
    """Per decision of the agent, the size its starts are spread over: its box where bounded on both sides, else the
    size of the candidate, its start value and its finite bound's distance (at least 1)."""
    sl = game.agent_slices[agent]
    lo, hi, y, s = game.a_lower[sl], game.a_upper[sl], a[sl], game.a_start[sl]
    size = np.maximum.reduce([np.ones_like(y), np.abs(y), np.abs(s),
                              np.where(np.isfinite(lo), np.abs(y - lo), 0.0),
                              np.where(np.isfinite(hi), np.abs(hi - y), 0.0)])
    return np.where(np.isfinite(lo) & np.isfinite(hi), hi - lo, size)


def search_box(game: CompiledGame, agent: int, a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The box a player's design points and box search cover: its bounds, and ``BOX_RADIUS`` times its size around
    the candidate where a decision is unbounded."""
    sl = game.agent_slices[agent]
    lo, hi, y = game.a_lower[sl], game.a_upper[sl], a[sl]
    r = BOX_RADIUS * max(1.0, float(np.max(np.abs(y), initial=0.0)),
                         float(np.max(np.abs(game.a_start[sl]), initial=0.0)))
    return np.where(np.isfinite(lo), lo, y - r), np.where(np.isfinite(hi), hi, y + r)


@dataclass
class Starts:
    """Where an agent's best response is sought from: ``compare`` is every point compared as it is; ``local`` the
    subset local solves start from (``local[0]`` is the candidate)."""

    compare: list[np.ndarray]
    local: list[np.ndarray]
    kinks: list[str] = field(default_factory=list)


def response_starts(game: CompiledGame, agent: int, a: np.ndarray, x: np.ndarray | None = None) -> Starts:
    """The candidate, the start values, the box's corners, the others' decisions and starts of the same size, scaled
    perturbations, a Kronecker design in the search box, and (at a kink) probes around the candidate."""
    sl = game.agent_slices[agent]
    ni = sl.stop - sl.start
    lo, hi = game.a_lower[sl], game.a_upper[sl]
    y = a[sl].astype(float)
    rng = np.random.default_rng(_seed(agent, a))
    scale = _scales(game, agent, a)
    local = [y.copy(), np.clip(game.a_start[sl], lo, hi)]
    corners: list[np.ndarray] = []
    if np.all(np.isfinite(lo)):
        local.append(lo.copy())
    if np.all(np.isfinite(hi)):
        local.append(hi.copy())
    if ni <= global_response.MAX_DIM and np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)):
        corners = [np.where(np.array([(k >> j) & 1 for j in range(ni)], dtype=bool), hi, lo) for k in range(2**ni)]
    for frac in PERTURBATIONS:
        local.append(np.clip(y + frac * scale * rng.standard_normal(ni), lo, hi))
    others = []
    for j, sj in enumerate(game.agent_slices):
        if j != agent and sj.stop - sj.start == ni:
            others += [np.clip(a[sj], lo, hi), np.clip(game.a_start[sj], lo, hi)]
    # a randomly shifted Kronecker design over the search box
    blo, bhi = search_box(game, agent, a)
    count = DESIGN_SMALL if ni <= global_response.MAX_DIM else DESIGN_LARGE
    # blo + (bhi - blo) * u: a fixed decision (lower = upper) has an empty box there
    design = blo + (bhi - blo) * kronecker(ni, count, rng) if ni else np.zeros((0, 0))
    compare = local + corners + others + list(design)
    kinks = _kinks(game, agent, a, x)
    if kinks:
        for step in KINK_STEPS:
            h = step * max(1.0, float(np.max(np.abs(y), initial=0.0)))
            for k in range(ni):
                for sign in (1.0, -1.0):
                    e = y.copy()
                    e[k] += sign * h
                    compare.append(np.clip(e, lo, hi))
            for _ in range(4 * ni):
                r = rng.standard_normal(ni)
                compare.append(np.clip(y + h * r / np.linalg.norm(r), lo, hi))
    small = ni <= global_response.MAX_DIM
    return Starts(compare, _unique(local + (others if small else [])), kinks)


def _unique(points: list[np.ndarray]) -> list[np.ndarray]:
    out: list[np.ndarray] = []
    for p in points:
        if not any(np.array_equal(p, q) for q in out):
            out.append(p)
    return out


def _kinks(game: CompiledGame, agent: int, a: np.ndarray, x: np.ndarray | None) -> list[str]:
    """The piecewise functions (abs, min, max...) at their kink in the agent's cost or rows at a."""
    costs, rows = game.lq.piecewise_parts
    if not costs[agent] and not rows[game.agents.constraint_rows(agent)].any():
        return []
    return game.agents.kinks_at(agent, a, game._x(x), KINK_TOL)


def _agent_tape(game: CompiledGame, agent: int, f) -> Tape:
    cache = game.derived.setdefault("tapes", {})
    key = (agent, f.name())
    if key not in cache:
        cache[key] = Tape(f)
    return cache[key]


class NewtonResponses:
    """Best responses by Newton steps on each agent's own problem (built on first use from the game's expressions:
    gnerun.game.compile.agent_problem with tau = 0, whose parameters are the plant state and the others' decisions):
    the interior-point method of the globalized solver (``globalization: interior_point``), whose direction makes
    the player's own block positive definite, so that it descends to a minimum of the player's problem; the plain
    semismooth Newton step would stop at any stationary point, a concave player's maximum included. Once ||Phi|| is
    below ``POLISH`` the semismooth Newton steps polish the point the interior phase has come to, each kept only
    where it reduces ||Phi|| (else the interior phase goes on), instead of the barrier's last decades at a fifth per
    step. A start counts when its solve converges to a point that satisfies the agent's constraints within
    ``FEASIBILITY_TOL``."""

    MAX_ITER = 200

    def __init__(self, cfg, game: CompiledGame, check=None):
        self.cfg = cfg
        self.game = game
        self.check = check  # called before every step (a stop request raises there)
        self._solvers: dict[int, tuple[CompiledGame, object, np.ndarray]] = {}

    def _solver(self, agent: int):
        if agent not in self._solvers:
            from ..language.config import SolverConfig

            opts = SolverConfig(**{**self.cfg.solver.model_dump(), "kind": "ssn", "globalization": "interior_point",
                                   "formulation": "condensed", "max_iter": self.MAX_ITER,
                                   "tol": min(self.cfg.solver.tol, 1e-10)})
            # once per game and options: the solves of a sweep's points, a Monte Carlo's draws and a closed loop's
            # sampling times share the agent's problem, its system and what the solver keeps (its stage order and
            # factorisation layouts, ~10 ms per agent to build)
            solvers = self.game.derived.setdefault("response_solvers", {})
            full = self.game.derived.get("sparse")
            key = (agent, opts.model_dump_json(), None if full is None else id(full))  # (held by the entry)
            if key not in solvers:
                solvers[key] = self._build(agent, opts, full)
            self._solvers[agent] = solvers[key]
        return self._solvers[agent]

    def _build(self, agent: int, opts, full):
        """(the agent's problem, its solver: the interior phase alone, polished once ||Phi|| <= ``POLISH``, the game's
        rows in the problem's order); ``full``: the game's
        sparse system, where the game was solved in the sparse formulation."""
        from ..game.compile import agent_problem
        from .hybrid import HybridNewton
        from .ssn import SemismoothNewton

        built = self.game.derived.setdefault("agent_problems", {})  # once per game (a sweep's points share it)
        if agent not in built:
            built[agent] = agent_problem(self.game, agent, 0.0, self.cfg)  # from the game's own expressions
        problem = built[agent]
        # the candidate's multipliers in the agent problem's row order (matched by label: the game lists an
        # agent's own rows, then the common shared rows; the agent's problem, stage by stage)
        rows = self.game.agents.constraint_rows(agent)
        free: dict[str, list[int]] = {}
        for k, r in enumerate(rows):
            free.setdefault(self.game.constraints[r].label, []).append(k)
        order = np.array([free[c.label].pop(0) if free.get(c.label) else -1 for c in problem.constraints],
                         dtype=int)
        if full is not None and (order >= 0).all():
            # the agent's problem as a part of the game's sparse system: no dense derivatives of its own
            from ..game.sparse import AgentSparseKKT
            from .sparse_ssn import SparseSemismoothNewton

            system = AgentSparseKKT(full, problem, agent, rows[order])
            newton = SparseSemismoothNewton(problem, opts.model_copy(update={"formulation": "sparse"}), None,
                                            system)
        else:
            from ..game.compile import derivatives_from_game

            derivatives_from_game(problem, self.game, agent)  # blocks of the game's, where the game has them
            newton = SemismoothNewton(problem, opts)
        return problem, HybridNewton(newton, handover=False, polish=POLISH), order

    def rows_jacobian(self, agent: int, a: np.ndarray, x: np.ndarray | None) -> np.ndarray | None:
        """The Jacobian of the agent's rows (``constraint_rows`` order) in its own decisions at a, from its own
        problem's dense derivatives where its local solves built them (the game's row expressions differentiated in
        the agent's decisions alone: the game's values to rounding, its last bit where the derivative's operations
        come in another order); in a game solved in the sparse formulation, from the agent's part of its sparse
        system (:meth:`~gnerun.game.sparse.AgentSparseKKT.rows_jacobian`); None otherwise. The game's own dense row
        Jacobian is then never built (on the 6-robot formation 50 ms, on the intersection 0.3 s)."""
        from ..game.sparse import AgentSparseKKT

        problem, solver, order = self._solver(agent)
        rows = self.game.agents.constraint_rows(agent)
        if order.size != rows.size or (order < 0).any():
            return None
        sl = self.game.agent_slices[agent]
        p = np.concatenate([self.game._x(x), a[: sl.start], a[sl.stop:], a[sl]])
        system = getattr(getattr(solver, "newton", None), "system", None)
        if isinstance(system, AgentSparseKKT):  # a part of the game's sparse system: the states' response solved
            dc = system.rows_jacobian(a[sl], p)
        elif "_derivatives" in problem.__dict__:
            dc = problem.kkt_parts(np.concatenate([a[sl], np.zeros(problem.m)]), p).dc_da
        else:
            return None
        out = np.empty((rows.size, sl.stop - sl.start))
        out[order] = dc  # the problem's row j is the agent's row order[j]
        return out

    def solve_from(self, agent: int, a: np.ndarray, x: np.ndarray | None, starts: list[np.ndarray],
                   multipliers: np.ndarray | None = None) -> list[tuple[np.ndarray, bool]]:
        """Each start's end point and whether its solve converged; the first start is warm with ``multipliers``
        (the candidate's, in the agent's row order)."""
        from .driver import iterate
        from .status import Status

        problem, solver, order = self._solver(agent)
        game = self.game
        sl = game.agent_slices[agent]
        xv = game._x(x)
        p = np.concatenate([xv, a[: sl.start], a[sl.stop:], a[sl]])
        ends = []
        check = self.check  # a stop request raises there, before every step
        stop = None if check is None else (lambda state: bool(check()))
        for k, s in enumerate(starts):
            lam = np.zeros(problem.m)
            if k == 0 and multipliers is not None and (order >= 0).all():
                lam = multipliers[order]
            state = iterate(solver, solver.init(np.concatenate([np.asarray(s, dtype=float), lam]), p), stop=stop)
            converged = state.status == Status.CONVERGED
            ends.append((state.z[: problem.n].copy(), converged))
        return ends

    def best_response(self, agent: int, a: np.ndarray, x: np.ndarray | None, starts: list[np.ndarray],
                      multipliers: np.ndarray | None = None) -> tuple[float | None, np.ndarray | None, int]:
        """(best value, its decision, how many starts ended feasible and converged): a start that did not converge
        counts where it ended feasible and below the candidate's cost (a feasible point of lower cost proves that the
        agent can improve)."""
        game = self.game
        sl = game.agent_slices[agent]
        own = float(game.costs(a, x)[agent])
        ends = self.solve_from(agent, a, x, starts, multipliers)
        values, feasible = _values(game, agent, a, x, [e for e, _ in ends])
        best_val, best_x, counted = None, None, 0
        for (ai, converged), val, ok in zip(ends, values, feasible, strict=True):
            if not ok or not math.isfinite(val):
                continue
            counted += converged
            if (converged or val < own) and (best_val is None or val < best_val):
                best_val, best_x = float(val), ai
        del sl
        return best_val, best_x, counted


def _values(game: CompiledGame, agent: int, a: np.ndarray, x: np.ndarray | None, points: list[np.ndarray],
            prices: np.ndarray | None = None, strict: bool = False, directions: np.ndarray | None = None):
    """The agent's cost at each of its decisions ``points`` (the others at a) and whether each satisfies the agent's
    rows within ``FEASIBILITY_TOL`` (``strict``: exactly); with ``prices``, each violation is charged at its price;
    with ``directions`` (one per point, in the agent's decisions), also the cost's derivative along each."""
    sl = game.agent_slices[agent]
    if not points:
        empty = (np.zeros(0), np.zeros(0, dtype=bool))
        return empty if directions is None else (*empty, np.zeros(0))
    Y = np.asarray(points, dtype=float).reshape(len(points), sl.stop - sl.start)
    A = np.repeat(a.reshape(1, -1).astype(float), len(points), axis=0)
    A[:, sl] = Y
    finite = np.all(np.isfinite(A), axis=1)
    A[~finite] = 0.0
    V = None
    if directions is not None:
        V = np.zeros_like(A)
        V[:, sl] = directions
    J, C, *rest = game.agents.evaluate_many(A, x, V)
    rows = game.agents.constraint_rows(agent)
    c = C[:, rows]
    eq = game.equality_mask[rows]
    over = np.where(eq, np.abs(c), np.maximum(c, 0.0))
    viol = np.max(over, axis=1, initial=0.0)
    size = np.maximum(1.0, np.max(np.abs(Y), axis=1, initial=0.0))
    feasible = finite & ((viol <= 0.0) if strict else (viol <= FEASIBILITY_TOL * size))
    value = J[:, agent].copy()
    if prices is not None and rows.size:
        with np.errstate(all="ignore"):
            value += over @ np.abs(prices)
    value[~finite] = math.nan
    if directions is None:
        return value, feasible
    return value, feasible, rest[0][:, agent]


def best_response(game: CompiledGame, agent: int, a: np.ndarray, x: np.ndarray | None = None,
                  starts: list[np.ndarray] | None = None,
                  prices: np.ndarray | None = None) -> tuple[float | None, np.ndarray | None, str]:
    """Agent ``agent``'s best response to a_-i by SLSQP from ``starts`` (default: the local starts of
    :func:`response_starts`): (value, its decision, a note).

    SLSQP's answers may violate the constraints within ``FEASIBILITY_TOL``; with ``prices`` (the candidate's
    multipliers of the agent's rows, in ``constraint_rows`` order) such a point is charged for its violations at
    those prices, so that violating a constraint by 1e-9 at a multiplier of 100 does not count as a gain of 1e-7."""
    from scipy.optimize import minimize  # (loaded where SLSQP runs: a fallback, 0.2-0.4 s of import)

    a = np.asarray(a, dtype=float)
    problem = OwnProblem(game, agent, a, x)
    objective, constraints = problem.objective, problem.constraints()
    candidates = response_starts(game, agent, a, x).local if starts is None else starts
    best_val, best_x, notes = None, None, []
    for s in candidates:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = minimize(objective, np.array(s, dtype=float), jac=True, method="SLSQP", constraints=constraints,
                           options={"ftol": 1e-15, "maxiter": 300})
        ai = np.asarray(res.x, dtype=float)
        if not np.all(np.isfinite(ai)):
            notes.append("SLSQP from a start ended at a non-finite point")
            continue
        viol = problem.violation(ai)
        val = objective(ai)[0]
        if prices is not None:
            c = problem.at(ai)[2]
            over = np.where(problem.eq, np.abs(c), np.maximum(c, 0.0))
            val += float(np.abs(prices) @ over)
        if not math.isfinite(val) or viol > FEASIBILITY_TOL * max(1.0, float(np.max(np.abs(ai), initial=0.0))):
            notes.append(f"SLSQP from a start ended infeasible ({res.message})")
            continue
        if best_val is None or val < best_val:
            best_val, best_x = val, ai
    note = "; ".join(notes) if best_val is None else "ok"
    return best_val, best_x, note


@dataclass
class PlayerCheck:
    """One agent's part of a certificate."""

    gap: float | None  # J_i(a) - the best value found (None: nothing feasible was found, or the cost is not finite)
    decision: np.ndarray | None  # the best response found
    kind: str  # "global on the box" | "global on the search box" | "global (convex)" | "global (QP faces)" |
    # "over N starts" | "not checked"
    note: str
    box: tuple[list[float], list[float]] | None = None  # the box of a global statement
    bound: float | None = None  # a proven upper bound on the gap (global on the box)
    ray: Ray | None = None  # a feasible ray along which the cost keeps decreasing (no best response)
    finite: bool = True
    kinks: list[str] = field(default_factory=list)


def check_player(game: CompiledGame, agent: int, z: np.ndarray, x: np.ndarray | None = None,
                 responses: NewtonResponses | None = None, gradients: np.ndarray | None = None) -> PlayerCheck:
    """Agent ``agent``'s best response to the others at z, as the module docstring describes. ``gradients``: the
    game's ``own_gradients`` at z, where the caller has them (one evaluation for every player's check).

    One function of about 100 lines (the reason): its stages (design points, the box search, local solves, rays)
    share the best value and decision found so far, and each stage's starts depend on what the earlier ones found.
    """
    n = game.n
    a = np.asarray(z[:n], dtype=float)
    sl = game.agent_slices[agent]
    ni = sl.stop - sl.start
    y = a[sl]
    rows = game.agents.constraint_rows(agent)
    prices = z[n + rows]
    J0 = float(game.costs(a, x)[agent])
    grad = (game.own_gradients(a, x) if gradients is None else gradients)[sl]
    undefined = bool(game.agents.outside_domain(a, x)[agent])
    if not math.isfinite(J0) or not np.all(np.isfinite(grad)) or undefined:
        what = (f"J = {J0}" if not math.isfinite(J0) else "its gradient is not finite" if not undefined else
                "a log, sqrt, asin or acos in it is evaluated outside its domain")
        note = f"the cost is not finite at the point ({what})"
        # a point outside the cost's domain (a solve that stalled there) says nothing of a pole: it is sought from
        # the lowest point of a small design where the cost is defined
        target = _lowest_defined(game, agent, a, x, prices)
        ray = None if target is None else _pole(game, agent, a, x, prices, target)
        if ray is not None:
            note += "; " + ray.describe(_decision_names(game, agent))
        return PlayerCheck(None, None, "not checked", note, ray=ray, finite=False)
    tol = GAP_TOL * max(1.0, abs(J0))
    H = _lq_hessian(game, agent, a, x)  # an LQ player's own Hessian block (None: the game is not LQ)
    convex = H is not None and _positive_semidefinite(H)  # then a local solve is global already: no box search
    if convex:  # one solve of its convex QP: a KKT point of a convex problem is its global minimum
        answer = _convex_response(game, agent, a, x, H, grad, prices)
        if answer is not None:
            val, ok = _values(game, agent, a, x, [answer], prices)
            if ok[0] and math.isfinite(val[0]):
                gap = J0 - float(val[0])
                return PlayerCheck(gap, answer, "global (convex)",  # the exact gap, whatever its size
                                   "ok (convex: one QP solve on the candidate's active set)")
    faces = _qp_faces(game, agent, a, x, H, grad) if H is not None and not convex else None  # small, nonconvex
    if faces is not None and np.all(np.isfinite(game.a_lower[sl])) and np.all(np.isfinite(game.a_upper[sl])):
        points = [y, *faces]
        vals, ok = _values(game, agent, a, x, points, prices)  # bounded: the cheapest is its best response
        vals = np.where(ok & np.isfinite(vals), vals, np.inf)
        k = int(np.argmin(vals))
        if math.isfinite(vals[k]):
            return PlayerCheck(J0 - float(vals[k]), points[k], "global (QP faces)",
                               f"ok (nonconvex QP: the stationary points of its faces, {len(faces)} of them)")
    starts = response_starts(game, agent, a, x)
    if faces:  # an unbounded decision: its faces' stationary points are starts (it may be unbounded below)
        starts = Starts(starts.compare + faces, starts.local, starts.kinks)
    best_val, best_x = math.inf, None

    def consider(points: list[np.ndarray], strict: bool) -> None:
        nonlocal best_val, best_x
        vals, ok = _values(game, agent, a, x, points, prices, strict)
        for p, v, good in zip(points, vals, ok, strict=True):
            if good and math.isfinite(v) and v < best_val:
                best_val, best_x = float(v), np.asarray(p, dtype=float).copy()

    consider(starts.compare, strict=False)
    local = list(starts.local)
    # the best design points and any point already better than the candidate start local solves too
    vals, ok = _values(game, agent, a, x, starts.compare, prices)
    order = [k for k in np.argsort(np.where(ok, vals, np.inf)) if ok[k] and math.isfinite(vals[k])]
    # (any point already better than the candidate is among them)
    count = LOCAL_FROM_DESIGN + 1 if ni <= global_response.MAX_DIM else LOCAL_FROM_DESIGN_LARGE
    local = _unique(local + [starts.compare[k] for k in order[:count]])

    # the box search (small players): a global statement, or a witness
    box_result, box = None, None
    if 0 < ni <= global_response.MAX_DIM and not convex:
        box_result, box = _box_search(game, agent, a, x, J0 - tol, tol)
        if box_result is not None and box_result.witness is not None:
            consider([box_result.witness], strict=False)
            local = _unique(local + [box_result.witness])

    # local solves
    kind_note = ""
    ends: list[tuple[np.ndarray, bool]] = []
    counted = 0
    if responses is not None:
        ends = responses.solve_from(agent, a, x, local, prices if rows.size else None)
        vals, ok = _values(game, agent, a, x, [e for e, _ in ends], prices)
        counted = sum(1 for (_, conv), good in zip(ends, ok, strict=True) if conv and good)
        for (e, conv), v, good in zip(ends, vals, ok, strict=True):
            if good and math.isfinite(v) and (conv or v < J0) and v < best_val:
                best_val, best_x = float(v), e
        kind_note = f"Newton, {counted} of {len(local)} starts"
    if responses is None or counted == 0:
        val, dec, note = best_response(game, agent, a, x, local, prices)
        if val is not None and val < best_val:
            best_val, best_x = val, dec
        kind_note = "SLSQP" + (": no Newton start ended feasible" if responses is not None else "")
        if val is None:
            kind_note += f" ({note})"

    # rays: a player whose cost keeps decreasing has no best response
    runaway = [e - y for e, conv in ends if np.all(np.isfinite(e)) and
               np.linalg.norm(e - y) > 1e3 * max(1.0, float(np.linalg.norm(y)))]
    ray = None
    extra = list(runaway)
    if ni <= unbounded.COORDINATE_RAYS_UP_TO:  # flat and concave directions of the player's own cost
        extra += unbounded.flat_directions(game.agents.hessian(agent, a, x))
    if rows.size:  # the way out of its linearised rows along which the cost falls
        dc_own = None if responses is None else responses.rows_jacobian(agent, a, x)
        if dc_own is None:  # the game's (its dense row Jacobian is built on first use)
            dc_own = game.constraint_values(a, x)[1][rows][:, sl]
        d = unbounded.recession_direction(grad, dc_own, game.equality_mask[rows], prices)
        if d is not None:
            extra.append(d)
    directions = unbounded.free_directions(game.a_lower[sl], game.a_upper[sl], grad, _seed(agent, a), extra)
    if directions:
        scale = max(1.0, float(np.max(np.abs(y), initial=0.0)))
        points, t = unbounded.ray_points(y, directions, scale)
        along = np.repeat(np.asarray(directions), t.size, axis=0)
        vals, ok, slopes = _values(game, agent, a, x, list(points), prices, directions=along)
        ray = unbounded.descending_ray(directions, t, np.where(np.isfinite(vals), vals, np.nan), ok, J0, slopes)
        consider(list(points), strict=False)

    if ray is None and not (box_result is not None and box_result.complete):
        # a pole: a cost that falls without bound near a point of the player's set (log(x) at 0; a complete box
        # search has bounded the cost below on the whole box, so it has none)
        ray = _pole(game, agent, a, x, prices, y if best_x is None or best_val >= J0 else best_x)

    gap = None if best_x is None else J0 - best_val
    if box_result is not None and box_result.complete and gap is not None:
        # no feasible point of the box is cheaper than the best one found by more than tol; where a decision has no
        # bound, the box is a radius around the point (search_box), not the player's own range
        bounded = bool(np.all(np.isfinite(game.a_lower[sl])) and np.all(np.isfinite(game.a_upper[sl])))
        kind = "global on the box" if bounded else "global on the search box"
        bound = gap + tol
    elif gap is not None and gap <= tol and convex:
        kind = "global (convex)"  # the candidate is a KKT point of the player's own convex problem
        bound = None
    else:
        kind = f"over {len(starts.compare) + len(local)} starts"
        bound = None
        if box_result is not None and math.isfinite(box_result.lower_bound):
            bound = J0 - box_result.lower_bound  # the search's budget ran out: what it proved
    note = "ok (" + kind_note + ")" if gap is not None else "no start ended feasible (" + kind_note + ")"
    if starts.kinks:
        note += f"; at a kink of {', '.join(starts.kinks)}: the branches compared by probes around the point"
    if ray is not None:
        note += "; " + ray.describe(_decision_names(game, agent))
    return PlayerCheck(gap, best_x, kind, note, box, bound, ray, True, starts.kinks)


def _origins(game: CompiledGame, agent: int, a: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """The agent's search box and where a pole search may begin in it: its start values, then the box's centre."""
    lower, upper = search_box(game, agent, a)
    return lower, upper, [np.clip(game.a_start[game.agent_slices[agent]], lower, upper), 0.5 * (lower + upper)]


def _lowest_defined(game: CompiledGame, agent: int, a: np.ndarray, x: np.ndarray | None,
                    prices: np.ndarray) -> np.ndarray | None:
    """The agent's lowest feasible point with a finite cost among its start values, its search box's centre and a
    Kronecker design of DESIGN_LARGE points in the box (None: none)."""
    lower, upper, points = _origins(game, agent, a)
    rng = np.random.default_rng(_seed(agent, a))
    points += list(lower + (upper - lower) * kronecker(lower.size, DESIGN_LARGE, rng))
    with np.errstate(all="ignore"):
        vals, ok = _values(game, agent, a, x, points, prices)
    vals = np.where(ok & np.isfinite(vals), vals, np.inf)
    k = int(np.argmin(vals))
    return points[k] if math.isfinite(vals[k]) else None


def _decision_names(game: CompiledGame, agent: int) -> list[str]:
    """The agent's decisions as a ray's description names them: its variables, or a[k] (dynamic games)."""
    sl = game.agent_slices[agent]
    return game.variable_names[agent] if game.kind == "static" else [f"a[{k}]" for k in range(sl.stop - sl.start)]


def _pole(game: CompiledGame, agent: int, a: np.ndarray, x: np.ndarray | None, prices: np.ndarray,
          target: np.ndarray) -> Ray | None:
    """A pole of the agent's cost (:func:`gnerun.solvers.unbounded.pole_approach`) on the segment from its start
    values (or its search box's centre, where they are ``target``) through ``target``, the lowest point found (the
    candidate, or the best response found), to the edge of its search box, and (a player with at most
    COORDINATE_RAYS_UP_TO decisions) on the segments from ``target`` to the box's edge along each coordinate; and at
    ``target`` itself, approached along those directions (:func:`gnerun.solvers.unbounded.approach_point`)."""
    lower, upper, starts = _origins(game, agent, a)
    segments = next(([s] for s in (unbounded.pole_segment(o, target, lower, upper) for o in starts) if s), [])
    coordinates = unbounded.coordinate_segments(target, lower, upper) if target.size <= \
        unbounded.COORDINATE_RAYS_UP_TO else []

    def values(points: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        with np.errstate(all="ignore"):
            return _values(game, agent, a, x, points, prices)

    # the target itself within rounding of a pole (a local solve's end next to log|x - p|'s), then the segments
    directions = [s * d for _, d, _ in segments for s in (1.0, -1.0)] + [d for _, d, _ in coordinates]
    length = float(np.max(upper - lower, initial=1.0))
    rays = [unbounded.approach_point(values, target, directions, length),
            unbounded.pole_approach(values, segments + coordinates)]
    rays = [r for r in rays if r is not None]
    return min(rays, key=lambda r: r.costs[-1]) if rays else None


HESSIAN_BUILT_UP_TO = 100  # an LQ player with more decisions reads its Hessian from gradients
QP_FACES_UP_TO = 8  # a nonconvex LQ player with at most this many decisions, all bounded, ...
QP_FACES = 4096  # ... and at most this many faces (sets of active rows) has them all enumerated
PSD_ROUNDING = 8.0  # a player's Hessian is positive semidefinite where its least eigenvalue >= -this n eps ||H||


def _positive_semidefinite(H: np.ndarray) -> bool:
    """Whether an LQ player's Hessian block H is positive semidefinite, so that its problem is convex for certain (its
    KKT points are its minima): as far as its eigenvalues can tell, which eigvalsh gives exactly for H + E with ||E||
    of about n eps ||H||; a negative eigenvalue beyond that is negative curvature however small beside the largest
    (1e6 x^2 - 1e-5 y^2 falls by 10 at y = 1000)."""
    w = np.linalg.eigvalsh(H)
    rounding = PSD_ROUNDING * w.size * np.finfo(float).eps * float(np.max(np.abs(w), initial=0.0))
    return bool(w.size == 0 or w[0] >= -rounding)


def _lq_hessian(game: CompiledGame, agent: int, a: np.ndarray, x: np.ndarray | None) -> np.ndarray | None:
    """The agent's own Hessian block (symmetric) where the game is LQ (constant derivatives, affine rows); None
    otherwise."""
    # whether the game is LQ, where that is known without building its condensed derivatives (a game solved in the
    # sparse formulation has not built them, and at long horizons they cost more than the solve)
    if "_derivatives" in game.__dict__ or game.kind == "static":
        affine = game.affine
    else:
        sparse = game.derived.get("sparse")
        affine = bool(sparse is not None and sparse.affine)
    if not affine:
        return None
    sl = game.agent_slices[agent]
    if sl.stop - sl.start <= HESSIAN_BUILT_UP_TO:
        H = game.agents.hessian(agent, a, x)
    else:
        # J_i is quadratic: its gradient's differences are the Hessian's columns (building the Hessian's own
        # function grows like T^3.7 at horizon T in a condensed dynamic game: 6 s at T = 400)
        H = _hessian_from_gradients(game, agent, a, x)
    return 0.5 * (H + H.T)


def _qp_faces(game: CompiledGame, agent: int, a: np.ndarray, x: np.ndarray | None, H: np.ndarray,
              grad: np.ndarray) -> list[np.ndarray] | None:
    """The stationary points of the faces of a small LQ player's problem (a quadratic cost, affine rows) that is not
    convex: for every set W of at most n_i inequality rows (with the equalities), the KKT system [H A_W'; A_W 0] of
    that face, solved where it is nonsingular. A quadratic bounded below on a polyhedron attains its minimum (Frank and
    Wolfe), at a stationary point of its restriction to the relative interior of some face (a vertex included; a face
    whose system is singular, or whose cost is not convex on it, has its minimum on a smaller face, which is
    enumerated too): the cheapest feasible one of these points is the player's best response wherever its problem is
    bounded below, which every bounded decision guarantees. ``H``: its Hessian block (:func:`_lq_hessian`). None past
    ``QP_FACES_UP_TO`` decisions or ``QP_FACES`` faces."""
    sl = game.agent_slices[agent]
    ni = sl.stop - sl.start
    if ni > QP_FACES_UP_TO:
        return None
    rows = game.agents.constraint_rows(agent)
    c_all, dc = game.constraint_values(a, x)
    c0, C = c_all[rows], dc[rows][:, sl]
    eq = game.equality_mask[rows]
    E, I = np.flatnonzero(eq), np.flatnonzero(~eq)
    free = ni - E.size
    if free < 0 or sum(math.comb(I.size, k) for k in range(free + 1)) > QP_FACES:
        return None
    if E.size and np.linalg.matrix_rank(C[E]) < E.size:
        return None  # dependent equalities: every face's system is singular, and none would be enumerated
    y = a[sl]
    points = []
    for k in range(free + 1):
        for W in itertools.combinations(I, k):
            A = np.concatenate([E, np.asarray(W, dtype=int)])
            K = np.block([[H, C[A].T], [C[A], np.zeros((A.size, A.size))]])
            try:
                sol = np.linalg.solve(K, np.concatenate([-grad, -c0[A]]))
            except np.linalg.LinAlgError:  # singular: its minimum lies on a smaller face
                continue
            if np.all(np.isfinite(sol)):  # (an ill-conditioned face's point is still a point: it is only compared)
                points.append(y + sol[:ni])
    return points


def _convex_response(game: CompiledGame, agent: int, a: np.ndarray, x: np.ndarray | None, H: np.ndarray,
                     grad: np.ndarray, prices: np.ndarray) -> np.ndarray | None:
    """The best response of a player whose problem is a convex QP (:func:`_positive_semidefinite`), by one QP solve: an
    active-set method from the candidate's active set (its equalities, and the rows that hold with equality or carry a
    positive multiplier), each step the QP's KKT system on the working set (exact for a quadratic with affine rows),
    the most violated row added or the most negative multiplier dropped. Returned only where the answer satisfies the
    QP's KKT conditions (every row feasible, the inequalities' multipliers nonnegative): then it is the player's
    global minimum. None where the method does not get there (the general path then decides)."""
    sl = game.agent_slices[agent]
    ni = sl.stop - sl.start
    rows = game.agents.constraint_rows(agent)
    y = a[sl]
    size = max(1.0, float(np.max(np.abs(y), initial=0.0)))
    if rows.size:
        c_all, dc = game.constraint_values(a, x)
        c0, C = c_all[rows], dc[rows][:, sl]
    else:
        c0, C = np.zeros(0), np.zeros((0, ni))
    eq = game.equality_mask[rows]
    active = eq | (prices > 0) | (c0 >= -FEASIBILITY_TOL * size)
    for _ in range(2 * rows.size + 10):
        A = np.flatnonzero(active)
        K = np.block([[H, C[A].T], [C[A], np.zeros((A.size, A.size))]])
        rhs = np.concatenate([-grad, -c0[A]])
        try:
            sol = np.linalg.solve(K, rhs)
        except np.linalg.LinAlgError:
            sol = np.linalg.lstsq(K, rhs, rcond=None)[0]
        dy, mu = sol[:ni], sol[ni:]
        scale = max(1.0, float(np.max(np.abs(rhs), initial=0.0)))
        if not (np.all(np.isfinite(sol)) and np.max(np.abs(K @ sol - rhs), initial=0.0) <= 1e-10 * scale):
            return None  # no stationary point on this working set
        c_new = c0 + C @ dy
        over = np.where(eq, np.abs(c_new), c_new)
        tol = FEASIBILITY_TOL * max(size, 1.0 + float(np.max(np.abs(y + dy), initial=0.0)))
        violated = np.where(active, -np.inf, over)
        if violated.size and violated.max() > tol:
            active[int(np.argmax(violated))] = True
            continue
        inequality = ~eq[A]
        scale = max(1.0, float(np.max(np.abs(mu), initial=0.0)))  # (of the multipliers)
        if np.any(mu[inequality] < -1e-9 * scale):
            k = int(np.argmin(np.where(inequality, mu, np.inf)))
            active[A[k]] = False
            continue
        return y + dy  # the QP's KKT conditions hold
    return None


def _hessian_from_gradients(game: CompiledGame, agent: int, a: np.ndarray, x: np.ndarray | None) -> np.ndarray:
    """The Hessian of a quadratic J_i in the agent's own decisions, column by column from differences of its
    gradient (exact up to rounding for a quadratic: a unit step of the size of the point)."""
    sl = game.agent_slices[agent]
    a = np.asarray(a, dtype=float)
    h = max(1.0, float(np.max(np.abs(a[sl]), initial=0.0)))
    g0 = game.own_gradients(a, x)[sl]
    H = np.empty((sl.stop - sl.start,) * 2)
    for k in range(H.shape[1]):
        b = a.copy()
        b[sl.start + k] += h
        H[:, k] = (game.own_gradients(b, x)[sl] - g0) / h
    return H


def _box_search(game: CompiledGame, agent: int, a: np.ndarray, x: np.ndarray | None, threshold: float,
                tol: float):
    sl = game.agent_slices[agent]
    J, dJ, c = game.agents.functions(agent)
    try:
        tapes = [_agent_tape(game, agent, f) for f in (J, dJ, c)]
    except UnsupportedTape:
        return None, None
    lo, hi = search_box(game, agent, a)
    xv = game._x(x)
    rows = game.agents.box_rows(agent)  # the bounds' rows hold on the whole box: they are left out of the search
    eq = game.equality_mask[rows]

    def embed(blo: np.ndarray, bhi: np.ndarray):
        B = blo.shape[1]
        Al = np.repeat(a.reshape(-1, 1), B, axis=1)
        Ah = Al.copy()
        Al[sl], Ah[sl] = blo, bhi
        return [Al, xv], [Ah, xv]

    result = global_response.box_search(tapes[0], tapes[1], tapes[2] if rows.size else None, eq, lo, hi, embed,
                                        threshold, tol=tol, candidate=a[sl])
    return result, (lo.tolist(), hi.tolist())


def certificate(game: CompiledGame, z: np.ndarray, x: np.ndarray | None = None,
                best: dict[str, np.ndarray] | None = None, responses: NewtonResponses | None = None,
                check=None, checks: dict[str, PlayerCheck] | None = None,
                earlier: dict[str, PlayerCheck] | None = None) -> dict:
    """KKT residuals and every agent's best-response check at z (``certificate`` in summary.json); ``best``, if
    given, receives each agent's best response found. With ``responses``, the local best responses are Newton
    solves of the agents' own problems, and SLSQP's where none of those ends feasible; without, SLSQP's. ``check``
    is called before each agent (a stop request may raise there). ``checks``, if given, receives each agent's
    check; ``earlier``: checks of agents made at the same point (to rounding), taken as they are."""
    out: dict = kkt_residuals(game, z, x)
    names = game.agent_names
    if not np.all(np.isfinite(z)):
        out["best_response_gap"] = {name: None for name in names}
        out["best_response_note"] = {name: "the candidate is not finite" for name in names}
        out["best_response_kind"] = {name: "not checked" for name in names}
        out["not_finite"] = list(names)
        return out
    gaps: dict[str, float | None] = {}
    notes: dict[str, str] = {}
    kinds: dict[str, str] = {}
    bounds: dict[str, float | None] = {}
    boxes: dict[str, dict] = {}
    rays: dict[str, dict] = {}
    kinks: dict[str, list[str]] = {}
    not_finite: list[str] = []
    gradients = game.own_gradients(z[: game.n], x)  # every player's, evaluated once
    for i, name in enumerate(names):
        if check is not None:
            check()
        pc = earlier[name] if earlier and name in earlier else check_player(game, i, z, x, responses, gradients)
        if checks is not None:
            checks[name] = pc
        gaps[name] = pc.gap
        notes[name] = pc.note
        kinds[name] = pc.kind
        bounds[name] = pc.bound
        if pc.box is not None and pc.kind.startswith("global on the"):
            boxes[name] = {"lower": pc.box[0], "upper": pc.box[1]}
        if pc.ray is not None:
            rays[name] = {"direction": pc.ray.direction.tolist(), "steps": pc.ray.steps.tolist(),
                          "costs": pc.ray.costs.tolist(), "cost_at_point": pc.ray.start_cost,
                          "unbounded_below": pc.ray.unbounded_below}
            if pc.ray.pole is not None:  # steps: distances to this point
                rays[name]["pole"] = pc.ray.pole.tolist()
        if pc.kinks:
            kinks[name] = pc.kinks
        if not pc.finite:
            not_finite.append(name)
        if best is not None and pc.decision is not None:
            best[name] = pc.decision
    out["best_response_gap"] = gaps
    out["best_response_note"] = notes
    out["best_response_kind"] = kinds
    out["best_response_gap_bound"] = bounds
    if boxes:
        out["best_response_box"] = boxes
    if rays:
        out["unbounded"] = rays
    if kinks:
        out["kinks"] = kinks
    if not_finite:
        out["not_finite"] = not_finite
    return out


@dataclass(frozen=True)
class Verdict:
    """What a certificate says about a KKT point (:func:`assess`)."""

    improving: dict[str, float]  # agents that can improve alone, by their gaps
    unbounded: dict[str, str]  # agents without a best response: the ray seen
    not_finite: list[str]  # agents whose cost is not finite at the point
    unchecked: dict[str, str]  # agents whose best response could not be checked: why

    @property
    def certified(self) -> bool:
        return not (self.improving or self.unbounded or self.not_finite or self.unchecked)


def assess(game: CompiledGame, cert: dict, a: np.ndarray, x: np.ndarray | None = None) -> Verdict:
    """Read a certificate: which agents improve alone (gap above GAP_TOL max(1, |J_i(a)|)), have no best response,
    have a cost that is not finite, or could not be checked."""
    gaps = cert.get("best_response_gap") or {}
    notes = cert.get("best_response_note") or {}
    values = game.costs(np.asarray(a, dtype=float), x)
    not_finite = list(cert.get("not_finite", []))
    unbounded_agents = {}
    for name, ray in (cert.get("unbounded") or {}).items():
        unbounded_agents[name] = notes.get(name, "").split("; ")[-1]
        del ray
    improving, unchecked = {}, {}
    for (name, gap), value in zip(gaps.items(), values, strict=True):
        if name in not_finite or name in unbounded_agents:
            continue
        if gap is None or not math.isfinite(gap):
            unchecked[name] = notes.get(name, "no best response could be computed")
        elif gap > GAP_TOL * max(1.0, abs(float(value))):
            improving[name] = gap
    return Verdict(improving, unbounded_agents, not_finite, unchecked)


def improving_agents(game: CompiledGame, cert: dict, a: np.ndarray, x: np.ndarray | None = None) -> dict[str, float]:
    """The agents whose best-response gap in ``cert`` exceeds GAP_TOL max(1, |J_i(a)|): at a KKT point of a game
    with nonconvex players, each of them can improve on its own, so the point is not an equilibrium."""
    return assess(game, cert, a, x).improving
