"""One agent's functions of a compiled game: what a certificate's best-response check reads (``game.agents``).

Agent i's cost J_i and the rows c_i of its own problem (its own rows and the shared rows it carries), the Hessian of
J_i in its own decisions, the distances from their kinks of the piecewise functions in them, the domain of its cost,
and every cost and constraint value at many points at once. Each function is built once, on first use, and kept in
``game.derived``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import casadi as ca
import numpy as np

from .building import stoppable
from .evaluator import DenseOutputs, Evaluator
from .tape import Tape, UnsupportedTape, kink_function

if TYPE_CHECKING:
    from .compile import CompiledGame

BATCHES = (8, 64, 512)  # block sizes of evaluate_many's mapped functions
KINK_TAPE_USES = 8  # an agent's kinks are read off its instruction tape this many times before its function is built


def batch_size(left: int) -> int:
    """The block that evaluate_many evaluates next with ``left`` points to go: the smallest that holds them where at
    most half of it is padding, else the largest that they fill (a mapped call evaluates every column of its block:
    the 77 points of a certificate's rays in one block of 512 were 85% of its evaluations' time)."""
    size = next((s for s in BATCHES if s >= left), None)
    if size is not None and size <= 2 * left:
        return size
    return max((s for s in BATCHES if s <= left), default=BATCHES[0])


class AgentFunctions:
    """The per-agent functions of one compiled game (``game.agents``)."""

    def __init__(self, game: CompiledGame, rows: list[np.ndarray], domain: tuple | None):
        self.game = game
        self._rows = rows  # per agent: row indices of c that constrain its own problem
        self._domain = domain  # where each cost's log, sqrt... are defined

    def constraint_rows(self, agent: int) -> np.ndarray:
        """Indices of c that make up agent ``agent``'s own feasible set (for its best response)."""
        return self._rows[agent]

    def box_rows(self, agent: int) -> np.ndarray:
        """The rows of agent ``agent``'s own problem other than the bounds of its decisions."""
        rows = self.constraint_rows(agent)
        return rows[[not self.game.constraints[r].bound for r in rows]] if rows.size else rows

    def functions(self, agent: int) -> tuple[ca.Function, ca.Function, ca.Function]:
        """Agent ``agent``'s cost J_i(a; x), its gradient in the agent's own decisions, and the rows of its own
        problem c_i(a; x) (``constraint_rows``), as SX Functions of (a, x): what a best response's box search reads
        as instruction tapes (gnerun.game.tape). The rows of the agent's own bounds are left out (a search box lies
        inside them); ``box_rows`` are the rows kept, in the order of ``c``."""
        sym = self.game._symbolic
        sl = self.game.agent_slices[agent]
        Ji = sym.J[agent]
        rows = self.box_rows(agent).tolist()
        ci = sym.c[rows] if rows else ca.SX(0, 1)
        return (ca.Function("J", [sym.a, sym.x], [Ji]),
                ca.Function("dJ", [sym.a, sym.x], [ca.densify(ca.gradient(Ji, sym.a[sl]))]),
                ca.Function("c", [sym.a, sym.x], [ca.densify(ci)]))

    def kinks(self, agent: int) -> tuple[ca.Function, list[str]] | None:
        """The distances from their kinks of the piecewise functions of the decisions in agent ``agent``'s cost and
        rows, as one Function of (a, x), and the functions' names (gnerun.game.tape.kink_function); None if none.
        Built once per agent, from the parts that pass through such a function (``piecewise_parts``): they hold
        every one of them, and the rest of the graph is not walked (a merge car's cost: 50-60 -> 17-23 ms)."""
        cache = self.game.derived.setdefault("kinks", {})
        if agent not in cache:
            parts = self._piecewise_parts(agent)
            cache[agent] = None if parts is None else kink_function(parts)
        return cache[agent]

    def _piecewise_parts(self, agent: int) -> ca.Function | None:
        """Agent ``agent``'s cost (where it passes through a piecewise function) and those of its rows that do, as
        one Function of (a, x); None if none does."""
        sym = self.game._symbolic
        costs, pieces = self.game.lq.piecewise_parts
        rows = [r for r in self.constraint_rows(agent).tolist() if pieces[r]]
        parts = ([sym.J[agent]] if costs[agent] else []) + ([sym.c[rows]] if rows else [])
        return ca.Function("parts", [sym.a, sym.x], [ca.vertcat(*parts)]) if parts else None

    def kinks_at(self, agent: int, a: np.ndarray, x: np.ndarray, tol: float) -> list[str]:
        """The piecewise functions of the decisions in agent ``agent``'s cost and rows that are within ``tol``
        (relative) of their kink at a (x: the state with the runtime values), each name once. For its first
        ``KINK_TAPE_USES`` points, read off the parts' instruction tape (5-10 ms to build and read for a car of the
        intersection, whose compiled kink function, :meth:`kinks`, takes 40-80 ms to build); from then on (a closed
        loop's or a sweep's many certificates) by the compiled function."""
        cache = self.game.derived.setdefault("kink_tapes", {})
        if agent not in self.game.derived.get("kinks", {}):
            tape, uses = cache.get(agent, (None, 0))
            if uses < KINK_TAPE_USES:
                if tape is None:
                    parts = self._piecewise_parts(agent)
                    if parts is None:
                        return []
                    try:
                        tape = Tape(parts)
                    except UnsupportedTape:  # an instruction the tape does not read: the compiled function
                        uses = KINK_TAPE_USES
                if tape is not None:
                    cache[agent] = (tape, uses + 1)
                    return tape.kinks_within([a, x], tol)
        found = self.kinks(agent)
        if found is None:
            return []
        f, names = found
        d = np.asarray(f(a, x), dtype=float).reshape(-1)
        return list(dict.fromkeys(name for name, v in zip(names, d, strict=True) if v <= tol))

    def own_problem(self, agent: int, a: np.ndarray,
                    x: np.ndarray | None = None) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
        """Agent ``agent``'s own problem at a, in one evaluation: J_i, its gradient in the agent's own decisions, the
        rows of its feasible set (``constraint_rows``, bounds included) and their Jacobian in its own decisions (what
        a local solve of its best response asks for at every point; the game's functions compute every agent's
        costs and every row's derivatives in all decisions, N times the work with N players). Built once per
        agent."""
        cache = self.game.derived.setdefault("own_problems", {})
        if agent not in cache:
            cache[agent] = self._own_problem(agent)
        J, dJ, c, dc = cache[agent](a, self.game._x(x))
        return float(J[0, 0]), dJ.reshape(-1), c.reshape(-1), dc

    @stoppable
    def _own_problem(self, agent: int) -> DenseOutputs:
        sym = self.game._symbolic
        ai = sym.a[self.game.agent_slices[agent]]
        rows = self.constraint_rows(agent).tolist()
        ci = sym.c[rows] if rows else ca.SX(0, 1)
        return DenseOutputs(ca.Function("own_problem", [sym.a, sym.x],
                                        [sym.J[agent], ca.gradient(sym.J[agent], ai), ci, ca.jacobian(ci, ai)]))

    def hessian(self, agent: int, a: np.ndarray, x: np.ndarray | None = None) -> np.ndarray:
        """The Hessian of J_i in the agent's own decisions at a (its block of the game Hessian H; the function is
        built once per agent)."""
        cache = self.game.derived.setdefault("hessians", {})
        if agent not in cache:
            cache[agent] = self._hessian(agent)
        return cache[agent](a, self.game._x(x))[0]

    @stoppable
    def _hessian(self, agent: int) -> Evaluator:
        sym = self.game._symbolic
        ai = sym.a[self.game.agent_slices[agent]]
        return Evaluator(ca.Function("H_ii", [sym.a, sym.x], [ca.densify(ca.hessian(sym.J[agent], ai)[0])]))

    def outside_domain(self, a: np.ndarray, x: np.ndarray | None = None) -> np.ndarray:
        """Per agent: some log, sqrt, asin or acos of its cost is evaluated outside its domain at a, so the cost is
        not a number there, even where the compiled expression simplified the term away (0 * log(v) is 0 to
        CasADi)."""
        out = np.zeros(len(self.game.agent_names), dtype=bool)
        if self._domain is not None:
            f, strict, owner = self._domain
            v = f(a, self.game._x(x))[0].reshape(-1)
            bad = np.isnan(v) | np.where(strict, v <= 0, v < 0)
            out[owner[bad]] = True
        return out

    def evaluate_many(self, A: np.ndarray, x: np.ndarray | None = None,
                      V: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
        """Every cost and constraint value at many points at once: ``A`` is (k, n), one point a per row; returns
        J (k, N) and c (k, m), and with ``V`` (k, n) also each cost's directional derivative along the row of V at
        its point, dJ (k, N) (forward-mode AD). One mapped CasADi call per block of points (what a certificate's
        start points, rays and probes need: hundreds of points, each as cheap as one evaluation)."""
        game = self.game
        A = np.atleast_2d(np.asarray(A, dtype=float))
        k = A.shape[0]
        N, m = len(game.agent_names), game.m
        J, C = np.empty((k, N)), np.empty((k, m))
        dJ = np.empty((k, N)) if V is not None else None
        xv = game._x(x)
        done = 0
        while done < k:
            size = batch_size(k - done)
            f = self._batch(size, V is not None)
            rows = min(size, k - done)
            cols = np.zeros((game.n, size))
            cols[:, :rows] = A[done:done + rows].T
            args = [cols.ravel(order="F"), xv]  # CasADi stores matrices column by column
            if V is not None:
                dirs = np.zeros((game.n, size))
                dirs[:, :rows] = np.asarray(V, dtype=float)[done:done + rows].T
                args.append(dirs.ravel(order="F"))
            out = f(*args)
            J[done:done + rows] = out[0].T[:rows]
            if m:
                C[done:done + rows] = out[1].T[:rows]
            if dJ is not None:
                dJ[done:done + rows] = out[2].T[:rows]
            done += rows
        return (J, C) if dJ is None else (J, C, dJ)

    def _batch(self, size: int, directional: bool = False) -> Evaluator:
        cache = self.game.derived.setdefault("batches", {})
        if (size, directional) not in cache:
            sym = self.game._symbolic
            c = ca.densify(sym.c) if self.game.m else ca.densify(ca.SX(1, 1))
            if directional:
                v = ca.SX.sym("v", self.game.n)
                one = ca.Function("values", [sym.a, sym.x, v],
                                  [ca.densify(sym.J), c, ca.densify(ca.jtimes(sym.J, sym.a, v))])
            else:
                one = ca.Function("values", [sym.a, sym.x], [ca.densify(sym.J), c])
            cache[(size, directional)] = Evaluator(one.map(f"values_{size}", "serial", size, [1], []))
        return cache[(size, directional)]


class OwnProblem:
    """Agent ``agent``'s own problem with the others fixed at ``a`` (and the state x), for a local solver that asks
    for the cost and for the rows at the same point separately (SciPy's SLSQP): one evaluation of
    :meth:`AgentFunctions.own_problem` per point, kept for the next call. The rows are the agent's
    ``constraint_rows``, in that order; ``eq`` marks its equalities."""

    def __init__(self, game: CompiledGame, agent: int, a: np.ndarray, x: np.ndarray | None) -> None:
        self.game, self.agent, self.x = game, agent, x
        self.a = np.asarray(a, dtype=float)
        self.sl = game.agent_slices[agent]
        self.rows = game.agents.constraint_rows(agent)
        self.eq = game.equality_mask[self.rows]
        self._key: bytes | None = None
        self._values: tuple = ()

    def full(self, ai: np.ndarray) -> np.ndarray:
        """The decisions of every agent with this agent's replaced by ``ai``."""
        b = self.a.copy()
        b[self.sl] = ai
        return b

    def at(self, ai: np.ndarray) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
        """(J_i, its gradient, the rows, their Jacobian) at ``ai``."""
        key = np.asarray(ai, dtype=float).tobytes()
        if key != self._key:
            self._values = self.game.agents.own_problem(self.agent, self.full(ai), self.x)
            self._key = key
        return self._values

    def objective(self, ai: np.ndarray) -> tuple[float, np.ndarray]:
        J, dJ, _, _ = self.at(ai)
        return J, dJ

    def constraints(self) -> list[dict]:
        """SLSQP's constraints: c_i <= 0 as -c_i >= 0, and the equalities."""
        ineq, eq = ~self.eq, self.eq
        out = []
        if ineq.any():
            out.append({"type": "ineq", "fun": lambda ai: -self.at(ai)[2][ineq],
                        "jac": lambda ai: -self.at(ai)[3][ineq]})
        if eq.any():
            out.append({"type": "eq", "fun": lambda ai: self.at(ai)[2][eq], "jac": lambda ai: self.at(ai)[3][eq]})
        return out

    def violation(self, ai: np.ndarray) -> float:
        """The largest violation of the rows at ``ai`` (0 where every row holds)."""
        c = self.at(ai)[2]
        return max(float(np.max(c[~self.eq], initial=0.0)), float(np.max(np.abs(c[self.eq]), initial=0.0)))
