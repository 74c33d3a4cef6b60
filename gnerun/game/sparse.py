"""The sparse (non-condensed) formulation of a dynamic game's semismooth Newton step.

The condensed KKT system of a dynamic game (gnerun.game) eliminates the states: its Jacobian is dense
and a step costs O(T^2) to O(T^3) in the horizon T. Here the states xi(1..T+1) stay unknowns, with the
dynamics as equality constraints f(xi(tau), u(tau)) - xi(tau+1) = 0 and one costate sequence p_i per
agent (agent i's multipliers of the dynamics in its own problem). Agent i's Lagrangian is

    L_i = J_i(xi, a) + lambda_i^T g_i(xi, a) [+ lambda_s^T g_s] + p_i^T d_i(xi, a; x),

where d_i are the defects of the states that agent i's inputs can reach through the dynamics (all of them when
the dynamics couple the agents; a car's own four when the cars move independently). The other states do not
depend on agent i's decisions: they are data of its problem, and their costates would solve equations of their
own that feed back into nothing. Leaving them out makes an N-car game's costates O(N) instead of O(N^2).

and the whole system F(w) = [(grad_{a_i} L_i)_i; (grad_xi L_i)_i; d; c] in w = (a, xi, p, lambda) has a
block-banded Jacobian: every row and column belongs to one stage and touches only its neighbours. One
LU factorisation of it costs O(T): LAPACK's banded LU on the rows and columns ordered stage by stage
(:class:`StageOrder`), or SuperLU where the band would be wide (:func:`banded_wins`).

The iterate stays z = (a, lambda), and the step is the condensed method's step. Before every
evaluation the states are rolled out from (x, a) and the costates solved backwards from
grad_xi L_i = 0; at such a point the full Newton system, with xi and p eliminated, is the condensed
one (the reduced Hessian of L_i is the condensed Hessian, and grad_{a_i} L_i is the condensed
stationarity L(z)). So both formulations produce the same iterates up to rounding, and the same
closed loop; only the cost of a step differs.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from functools import cached_property
from typing import NamedTuple

import casadi as ca
import numpy as np
import scipy.sparse as sp
from scipy.linalg import lapack
from scipy.sparse import linalg as spla

from ..errors import one_line
from ..language.config import Config, DynamicGame
from . import banded
from .building import stoppable
from .compile import CompiledGame, Evaluator, _expressions, _layout, compile_key, shared_rows_carried
from .kernels import (
    KernelReport,
    Stages,
    build_library,
    compiler,
    entry_key,
    load_entry,
    pattern_positions,
    save_entry,
    scatter,
)


class SparseParts(NamedTuple):
    """L and c of the condensed system at z (so Phi is the same), and the full system at the projected point."""

    L: np.ndarray
    c: np.ndarray
    dL_dz: None
    dc_da: None
    F: np.ndarray  # the full residual (its G_xi and d rows vanish up to rounding)
    J: np.ndarray  # nonzeros of dF/dw in the pattern of SparseKKT.pattern
    F0: np.ndarray  # F with the costates and multipliers set to zero (F is linear in them)


class DeferredParts:
    """:class:`SparseParts` whose full system (F, its Jacobian's nonzeros J, F0) is evaluated when first asked for:
    L and c, all that Phi needs, come from the system's residual alone (the same expressions, so the same numbers as
    the full evaluation's). A converged iterate is a step's last point, whose Jacobian no step uses: on the MPC
    merge the residual costs 27 us and the whole system 63."""

    __slots__ = ("L", "c", "_evaluate", "_parts")
    dL_dz = None
    dc_da = None

    def __init__(self, L: np.ndarray, c: np.ndarray, evaluate: Callable[[], SparseParts]):
        self.L, self.c = L, c
        self._evaluate = evaluate
        self._parts: SparseParts | None = None

    def _full(self) -> SparseParts:
        if self._parts is None:
            self._parts = self._evaluate()
        return self._parts

    @property
    def F(self) -> np.ndarray:
        return self._full().F

    @property
    def J(self) -> np.ndarray:
        return self._full().J

    @property
    def F0(self) -> np.ndarray:
        return self._full().F0

    def __reduce__(self):  # pickled and deep-copied whole (the evaluation it defers is a closure)
        return SparseParts, tuple(self._full())


class SparseKKT:
    """The full-space KKT system of a dynamic game, evaluated at rolled-out states and solved costates.

    Unknowns w = (a [n], xi [S], p_1..p_N [S_1 + ... + S_N], lambda [m]) with S = nx (T + 1) and S_i = S's share
    that agent i reaches; rows F = (G_a [n], G_xi [sum S_i], d [S], c [m]). Build with :func:`compile_sparse`.
    """

    def __init__(self, game: CompiledGame, function: ca.Function, residual: ca.Function, constraints: ca.Function,
                 pattern: ca.Sparsity, affine: bool, S: int, costates: list[slice], states: list[np.ndarray]):
        self.game = game
        self._residual = Evaluator(residual)
        self._constraints = Evaluator(constraints)
        self.n, self.m, self.S = game.n, game.m, S
        self.N = len(game.agent_names)
        self.costates = costates  # agent i's costates p_i: these positions of p (and rows of G_xi)
        self.states = states  # the positions in xi of the states agent i reaches (stage-major)
        self.size = self.n + S + (costates[-1].stop if costates else 0) + self.m
        self.stages = (game.horizon or 0) + 1  # the stages tau = 0..T of the states and the decisions
        self._eval = Evaluator(function, dense=False)
        colind, row = pattern.colind(), pattern.row()
        self.pattern = sp.csc_matrix((np.zeros(len(row)), np.asarray(row), np.asarray(colind)),
                                     shape=(self.size, self.size))
        self.affine = affine  # dF/dw constant: LQ games
        self._lam0 = self.size - self.m  # first multiplier column (and first c row)
        self._not_multipliers = np.arange(self._lam0)
        # SuperLU orderings per kind of matrix: the reduced Newton system, the regularised one, the interior one
        self.orderings = {"newton": Ordering(), "regularized": Ordering(), "interior": Ordering()}
        self.kernels = KernelReport("interpreted")  # how the function is evaluated (set by compile_sparse)
        self.agent_blocks: dict = {}  # the interior step's players' block templates per inequality rows (SparseBarrier)

    def residual(self, z: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The condensed L(z) and c(a) alone (states rolled out, costates solved; no Jacobian)."""
        L, c = self._residual(z[: self.n], z[self.n :], self.game._x(x))
        return L.reshape(-1), c.reshape(-1)

    def constraints(self, z: np.ndarray, x: np.ndarray) -> np.ndarray:
        """c(a) alone (states rolled out): the residual's c, with nothing else evaluated."""
        return self._constraints(z[: self.n], self.game._x(x))[0].reshape(-1)

    def evaluate(self, z: np.ndarray, x: np.ndarray) -> SparseParts:
        n = self.n
        F, J, F0 = self._eval(z[:n], z[n:], self.game._x(x))
        return SparseParts(F[:n], F[self._lam0:], None, None, F, J, F0)

    def deferred(self, z: np.ndarray, x: np.ndarray) -> DeferredParts:
        """The parts at z with L and c evaluated and the rest (:meth:`evaluate`) when first asked for."""
        L, c = self.residual(z, x)
        return DeferredParts(L, c, lambda: self.evaluate(z, x))

    def matrix(self, J: np.ndarray) -> sp.csc_matrix:
        """dF/dw as a sparse matrix, from the nonzeros of an evaluation."""
        M = self.pattern.copy()
        M.data = J
        return M

    def kept(self, A: np.ndarray) -> np.ndarray:
        """Rows and columns of the reduced system for the g-branch rows A (and equalities): all but the
        inactive multipliers (zero after the step) and their rows."""
        return np.concatenate([self._not_multipliers, self._lam0 + A])

    @cached_property
    def stage_order(self) -> StageOrder:
        """The rows and columns ordered stage by stage (computed from the pattern once per game)."""
        return StageOrder(self)

    def layout(self, keep: np.ndarray, at: np.ndarray | None = None, eliminate: np.ndarray | None = None) -> KeptLayout:
        """Where the nonzeros of the matrix with rows and columns ``keep`` (and entries added to its diagonal at
        ``at``, positions in ``keep``; ``eliminate``: the positions eliminated before the factorisation,
        :class:`Elimination`) go in its factorisation's storage; the 64 used last are kept."""
        key = tuple(None if v is None else v.tobytes() for v in (keep, at, eliminate))
        layouts = self.stage_order.layouts
        layout = layouts.pop(key, None)
        if layout is None:
            if len(layouts) >= 64:  # the least recently used without an elimination goes (an elimination's ordering
                # costs ~10 ms; the interior matrix's stays among the active sets' of a long Newton phase)
                del layouts[next((k for k, v in layouts.items() if v.elimination is None), next(iter(layouts)))]
            layout = KeptLayout(self.stage_order, keep, at, self.stage_order.banded, eliminate)
        layouts[key] = layout  # the most recently used last
        return layout

    def factor_kept(self, kind: str, data: np.ndarray, keep: np.ndarray, at: np.ndarray | None = None,
                    add: np.ndarray | None = None, estimate: bool = True, eliminate: np.ndarray | None = None,
                    ) -> tuple[BandLU | EliminatedLU | spla.SuperLU | None, float]:
        """Factors of dF/dw (nonzeros ``data``) restricted to the rows and columns ``keep``, with ``add`` added to
        its diagonal at the positions ``at`` (in ``keep``), and an estimate of the reciprocal 1-norm condition
        number (0 when singular; NaN without ``estimate``): banded LU on the stage order where the band is narrow
        (:class:`KeptLayout`), SuperLU otherwise (``kind``: which of ``orderings``). Either has ``solve(b)`` for a
        right-hand side over ``keep``. ``eliminate``: positions in ``keep`` with a diagonal block (entries in ``add``
        only) eliminated first (:class:`Elimination`; the estimate is then the factorised complement's)."""
        return self.factor_layout(kind, self.layout(keep, at, eliminate), data, add, estimate)

    def factor_layout(self, kind: str, layout: KeptLayout, data: np.ndarray, add: np.ndarray | None = None,
                      estimate: bool = True) -> tuple[BandLU | EliminatedLU | spla.SuperLU | None, float]:
        """:meth:`factor_kept` with the layout (:meth:`layout`'s) held by the caller: a matrix whose rows, columns
        and diagonal additions are the same at every step (the interior step's) is not looked up again."""
        if layout.banded:
            return layout.factor(data, add, estimate)
        lu, rcond = self.orderings[kind].factor(layout.csc(data, add), estimate)
        return layout.eliminated(lu, data, add), rcond

    def point_kept(self, parts: SparseParts, z: np.ndarray, keep: np.ndarray,
                   estimate: bool) -> tuple[BandLU, np.ndarray, float] | None:
        """The min-map Newton point for the rows and columns ``keep`` (:meth:`kept`) in one compiled call where its
        matrix is banded (:class:`gnerun.game.banded.ReducedPoint`): the factors :meth:`factor_kept` makes, the point
        :meth:`new_iterate` makes from their solution of :meth:`rhs`, and the estimate (NaN without ``estimate``), the
        same values to the bit; None where it does not apply or nothing is compiled (the numpy code makes them)."""
        layout = self.layout(keep)
        compiled = layout.compiled_point
        if compiled is None:
            compiled = layout.compiled_point = banded.reduced_point(layout, keep, self.n, self.n + self.m,
                                                                    self._lam0) or False
        if not compiled:
            return None
        found = compiled(parts.J, parts.F0, z, estimate)
        if found is None:
            return None
        z_new, lu, piv, rcond = found
        return BandLU(layout, lu, piv), z_new, rcond

    def rcond_kept(self, factors, data: np.ndarray, keep: np.ndarray, at: np.ndarray | None = None,
                   add: np.ndarray | None = None, eliminate: np.ndarray | None = None) -> float:
        """The condition estimate :meth:`factor_kept` returns with ``estimate``, from the factors it made without."""
        layout = self.layout(keep, at, eliminate)
        if layout.banded:
            return layout.rcond(factors, data, add)
        return _rcond(layout.csc(data, add), getattr(factors, "factors", factors))

    @staticmethod
    def rhs(parts: SparseParts) -> np.ndarray:
        """The right-hand side -F(a, xi, 0, 0): F is linear in (p, lambda), so with their current values
        moved over, the unknowns of the step are their new values, (da, dxi, p^+, lambda_A^+)."""
        return -parts.F0

    def new_iterate(self, z: np.ndarray, sol: np.ndarray, A: np.ndarray) -> np.ndarray:
        """z^+ = (a + da, lambda^+) from the solution of the reduced system."""
        n = self.n
        z_new = np.zeros_like(z)
        z_new[:n] = z[:n] + sol[:n]
        z_new[n + A] = sol[self._lam0:]
        return z_new


class AgentSparseKKT(SparseKKT):
    """One agent's best response to the others' decisions (their inputs fixed) as a principal part of the game's
    sparse system: its rows G_a(i), G_xi(i), the defects d and its constraint rows c_i, in its unknowns a_i, xi, p_i
    and its multipliers. At a point whose other multipliers are zero these rows are the agent's own problem's KKT
    system (its costates solve grad_xi L_i = 0, the states roll out from all inputs), so it is evaluated by the
    game's own (compiled) system and nothing is built per agent.

    ``problem`` is the agent's problem as compiled by :func:`gnerun.game.compile.compile_agent_problem` (proximal
    weight 0), whose parameter vector is (x with the runtime values, the others' decisions, a centre unused);
    ``rows[k]`` the game's row of c of its constraint k.
    """

    def __init__(self, full: SparseKKT, problem: CompiledGame, agent: int, rows: np.ndarray):
        game = full.game
        sl = game.agent_slices[agent]
        n, S, m, P = game.n, full.S, game.m, full.costates[-1].stop
        own_p = full.costates[agent]
        self._rows, self._slice, self._full = np.asarray(rows, dtype=int), sl, full
        self._nx = game._x(None).size  # the plant state and the runtime values at the front of the parameters
        self._lam = np.zeros(m)
        F_rows = np.concatenate([np.arange(sl.start, sl.stop), n + np.arange(own_p.start, own_p.stop),
                                 n + P + np.arange(S), n + P + S + self._rows])
        w_cols = np.concatenate([np.arange(sl.start, sl.stop), n + np.arange(S),
                                 n + S + np.arange(own_p.start, own_p.stop), n + S + P + self._rows])
        index = full.pattern.copy()
        index.data = np.arange(index.nnz, dtype=float)
        sub = index[F_rows][:, w_cols].tocsc()
        sub.sort_indices()
        self._F_rows, self._nonzeros = F_rows, sub.data.astype(int)
        pattern = ca.Sparsity(sub.shape[0], sub.shape[1], sub.indptr.tolist(), sub.indices.tolist())
        super().__init__(problem, full._eval.function, full._residual.function, full._constraints.function, pattern,
                         False, S, [slice(0, own_p.stop - own_p.start)], [full.states[agent]])
        self.kernels = full.kernels
        # the game's stages (the agent's problem is compiled as a static one): its matrix is banded in their order
        # (the merge's car: 440 unknowns, band (18, 20); one stage, (52, 401), left SuperLU a third of a certificate)
        self.stages = full.stages

    def _point(self, z: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The game's (a, lambda, x) of the agent problem's (z, parameters)."""
        sl, ni = self._slice, self._slice.stop - self._slice.start
        p = self.game._x(x)
        xv, others = p[:self._nx], p[self._nx:self._nx + self._full.n - ni]
        a = np.concatenate([others[:sl.start], z[:ni], others[sl.start:]])
        lam = self._lam.copy()
        lam[self._rows] = z[ni:]
        return a, lam, xv

    def residual(self, z: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        a, lam, xv = self._point(z, x)
        L, c = self._full._residual(a, lam, xv)
        return L.reshape(-1)[self._slice], c.reshape(-1)[self._rows]

    def constraints(self, z: np.ndarray, x: np.ndarray) -> np.ndarray:
        a, _, xv = self._point(z, x)
        return self._full._constraints(a, xv)[0].reshape(-1)[self._rows]

    def evaluate(self, z: np.ndarray, x: np.ndarray) -> SparseParts:
        F, J, F0 = self._full._eval(*self._point(z, x))
        F, F0 = F[self._F_rows], F0[self._F_rows]
        return SparseParts(F[:self.n], F[self._lam0:], None, None, F, J[self._nonzeros], F0)

    def rows_jacobian(self, a_i: np.ndarray, x: np.ndarray) -> np.ndarray:
        """The Jacobian of the agent's rows (in this system's row order) in its own decisions at a_i, the states
        responding through the dynamics: dc/da_i = C_a + C_xi dxi/da_i with D_xi dxi/da_i = -D_a (the linearised
        defects; D_xi is lower block-triangular with the identity's blocks on its diagonal). What the condensed
        problem's dc/da is, to rounding, without building its dense derivatives."""
        import scipy.sparse.linalg as spla

        n, S, lam0 = self.n, self.S, self._lam0
        M = self.matrix(self.evaluate(np.concatenate([a_i, np.zeros(self.m)]), x).J).tocsr()
        defects = slice(lam0 - S, lam0)  # the rows d: after G_a and the agent's costate rows
        D_a, D_x = M[defects][:, :n], M[defects][:, n:n + S]
        C_a, C_x = M[lam0:][:, :n], M[lam0:][:, n:n + S]
        response = -spla.spsolve(D_x.tocsc(), D_a.toarray())
        return C_a.toarray() + C_x @ response.reshape(S, n)


def sparse_system(cfg: Config, game: CompiledGame) -> SparseKKT:
    """The game's sparse system, compiled once per game (kept in ``game.derived``): ``gnerun solve`` and ``gnerun
    simulate`` build it with the game, before a run begins, wherever the solver takes the sparse formulation."""
    system = game.derived.get("sparse")
    if system is None:
        system = game.derived["sparse"] = compile_sparse(cfg, game)
    return system


@stoppable
def compile_sparse(cfg: Config, game: CompiledGame, *, build_c: bool = True) -> SparseKKT:
    """The full-space system of the dynamic game of ``cfg`` (``game`` is its condensed compilation, whose
    constraint order and multiplier blocks it shares), evaluated by compiled stage kernels where
    ``cfg.solver.compile`` asks for them (gnerun.game.kernels). ``build_c=False``: the stage kernels' graph
    evaluated by CasADi's interpreter instead of compiled (to check it without a compiler)."""
    g = cfg.game
    if not isinstance(g, DynamicGame):
        raise ValueError("the sparse formulation is for dynamic games")
    lay = _layout(g, game.runtime)
    N, n, nx, T = len(g.agents), lay.n, lay.nx, lay.horizon
    key = None
    if build_c and cfg.solver.compile != "interpreted" and compiler() is not None:
        key = entry_key(compile_key(cfg))
        cached = _from_cache(game, key, T + 1, cfg.solver.compile)
        if cached is not None:
            return cached
    S = nx * (T + 1)
    a = ca.SX.sym("a", n)
    x = ca.SX.sym("x", nx + lay.np)  # the plant state, then the runtime values
    X = ca.SX.sym("xi", S)
    ex = _expressions(g, lay, a, x, list(range(N)), states=X)
    rows = [r for i in range(N) for r in ex.own_rows[i]] + ex.shared_common
    if [r.info.label for r in rows] != [c.label for c in game.constraints]:
        raise AssertionError("sparse and condensed constraint orders differ")
    m = len(rows)
    lam = ca.SX.sym("lam", m)
    inputs = [(i, j) for i, names in enumerate(lay.variable_names) for j in range(len(names))]
    reach = reachable_states(ex.dynamics, [[k for k, (i, _) in enumerate(inputs) if i == agent] for agent in range(N)])
    # agent i's states in xi, stage-major, and the offsets of its costates in p
    own = [np.array([tau * nx + k for tau in range(T + 1) for k in np.flatnonzero(r)], dtype=int) for r in reach]
    offsets = np.cumsum([0, *[idx.size for idx in own]])
    P = ca.SX.sym("p", int(offsets[-1]))
    c = ca.vertcat(*[r.expr for r in rows]) if rows else ca.SX(0, 1)
    d = ca.vertcat(*ex.defects)
    shared = game.shared_slice
    common_grads: dict[tuple[int, ...], ca.SX] = {}  # the shared rows' lambda^T c, differentiated once per set
    Ga, Gx, gx_only = [], [], []
    for i in range(N):
        ms = game.multiplier_slices[i]
        Li = ex.costs[i]
        if ms.stop > ms.start:
            Li = Li + ca.dot(lam[ms], c[ms])
        Xi = X[own[i].tolist()]
        ai = a[lay.agent_slices[i]]
        common = tuple(shared_rows_carried(rows[shared], shared.start, i).tolist())
        if common and common not in common_grads:
            common_grads[common] = ca.gradient(ca.dot(lam[list(common)], c[list(common)]), ca.vertcat(a, X))
        g_a = ca.gradient(Li, ai)
        g_x = ca.gradient(Li, Xi)  # grad_xi of J_i + lambda^T c (no costates)
        if common:
            g_a = g_a + common_grads[common][lay.agent_slices[i]]
            g_x = g_x + common_grads[common][(n + own[i]).tolist()]
        gx_only.append(g_x)
        Pi = P[int(offsets[i]):int(offsets[i + 1])]
        dP = ca.dot(Pi, d[own[i].tolist()])
        Ga.append(g_a + ca.gradient(dP, ai))
        Gx.append(g_x + ca.gradient(dP, Xi))
    F = ca.vertcat(*Ga, *Gx, d, c)
    w = ca.vertcat(a, X, P, lam)
    J = ca.jacobian(F, w)
    full = ca.Function("full", [a, X, P, lam, x], [F, J])

    # projection: xi rolled out from (x, a); p_i from grad_xi L_i = 0, backwards over agent i's states R_i:
    # p_i(tau) = grad_{xi_R(tau+1)} (J_i + lambda^T c) + f_xi[R, R](xi(tau+1), u(tau+1))^T p_i(tau+1), p_i(T+1) = 0
    # (f_xi[not R, R] = 0: a state that depends on one agent i reaches is one it reaches)

    def u_at(tau: int) -> ca.SX:
        return ca.vertcat(*[a[lay.agent_slices[i].start + tau * len(lay.variable_names[i]) + j] for i, j in inputs])

    f = ex.dynamics
    xs = [x[:nx]]
    for tau in range(T + 1):
        xs.append(f(xs[-1], u_at(tau)))
    X_roll = ca.vertcat(*xs[1:])
    costates = _costates(f, len(inputs), gx_only, reach, X, u_at, T)
    adjoint = ca.Function("adjoint", [a, X, lam, x], [ca.vertcat(*costates)])
    P_proj = adjoint(a, X_roll, lam, x)
    F_proj, J_proj = full(a, X_roll, P_proj, lam, x)
    F0, _ = full(a, X_roll, ca.SX.zeros(P.numel()), ca.SX.zeros(m), x)
    function = ca.Function("sparse_kkt", [a, lam, x], [F_proj, J_proj, F0], ["a", "lam", "x"], ["F", "J", "F0"])
    residual = ca.Function("sparse_residual", [a, lam, x], [ca.densify(F_proj[:n]), ca.densify(F_proj[F.numel() - m:])],
                           ["a", "lam", "x"], ["L", "c"])
    constraints = ca.Function("sparse_constraints", [a, x], [ca.densify(F_proj[F.numel() - m:])], ["a", "x"], ["c"])
    affine = not ca.depends_on(J, ca.vertcat(a, X, P, lam, x)) and not game.lq.piecewise
    pattern = function.sparsity_out(1)
    report = KernelReport("interpreted", horizon=T + 1)
    function_ops = function.n_instructions()
    why_not = _why_interpreted(cfg.solver.compile, affine, function_ops, build_c)
    if why_not:
        report = KernelReport("interpreted", reason=why_not, horizon=T + 1)
    else:
        try:
            timed = lay.runtime is not None and lay.runtime.time
            if timed:  # every stage built as the first, taking its own time t + tau dt: one Function for many
                ex = _expressions(g, lay, a, x, list(range(N)), states=X, local_time=True)
                rows = [r for i in range(N) for r in ex.own_rows[i]] + ex.shared_common
            staged = _staged(ex, rows, lay, game, reach, offsets, inputs, a, X, x, lam, pattern, F.numel(),
                             lay.runtime.dt if timed else None)
            if build_c:
                lib, hit, seconds = build_library(staged[:3], f"sparse_kkt_{T + 1}")
                function, residual, constraints = _externals(lib)
                report = KernelReport("compiled", path=str(lib), cache_hit=hit, compile_s=seconds,
                                      stages=staged[3], horizon=T + 1)
                if key is not None:
                    save_entry(key, lib, {"size": np.array(F.numel()), "colind": np.asarray(pattern.colind()),
                                          "row": np.asarray(pattern.row()), "S": np.array(S), "offsets": offsets,
                                          "own": np.concatenate(own), "own_len": np.array([o.size for o in own]),
                                          "stages": np.array(staged[3]),
                                          "operations": np.array(function_ops)})
            else:
                function, residual, constraints = staged[:3]
                report = KernelReport("interpreted", reason="stage kernels not compiled", stages=staged[3],
                                      horizon=T + 1)
        except (RuntimeError, ValueError) as why:  # a compiler's or CasADi's failure: the interpreted path stays
            report = KernelReport("interpreted", reason=one_line(str(why)), horizon=T + 1)
    system = SparseKKT(game, function, residual, constraints, pattern, affine, S,
                       [slice(int(offsets[i]), int(offsets[i + 1])) for i in range(N)], own)
    system.kernels = report
    return system


def _externals(library) -> tuple[ca.Function, ca.Function, ca.Function]:
    """The sparse system's function, its residual function and its constraint function from a compiled library
    (:func:`_staged`'s names)."""
    return tuple(ca.external(name, str(library)) for name in ("sparse_kkt", "sparse_residual", "sparse_constraints"))


def _from_cache(game: CompiledGame, key: str, horizon: int, mode: str) -> SparseKKT | None:
    """The game's compiled sparse system from the cache (gnerun.game.kernels), if it is there (and for ``auto``, the
    game is one it compiles): nothing is built."""
    entry = load_entry(key)
    if entry is None:
        return None
    library, arr = entry
    if mode == "auto" and int(arr["operations"]) < AUTO_FROM:
        return None
    try:
        function, residual, constraints = _externals(library)
    except RuntimeError:  # a library that does not load (or one without a function named here): built again
        return None
    size = int(arr["size"])
    pattern = ca.Sparsity(size, size, arr["colind"].tolist(), arr["row"].tolist())
    own = np.split(arr["own"].astype(int), np.cumsum(arr["own_len"])[:-1])
    offsets = arr["offsets"]
    system = SparseKKT(game, function, residual, constraints, pattern, False, int(arr["S"]),
                       [slice(int(offsets[i]), int(offsets[i + 1])) for i in range(len(own))], own)
    system.kernels = KernelReport("compiled", path=str(library), cache_hit=True, stages=int(arr["stages"]),
                                  horizon=horizon)
    return system


# solver.compile: auto compiles the stage kernels from this many operations of the interpreted function: where one
# evaluation takes ~70-100 us interpreted (measured: the 20-knot merge 42,000 operations 142 us, the intersection
# 119,000 490 us; the 6-robot ring 11,000 48 us), against 0.5-2 s of the compiler once per game (then cached)
AUTO_FROM = 20_000


def _why_interpreted(mode: str, affine: bool, operations: int, build_c: bool = True) -> str:
    """Why the sparse system stays interpreted ('': its stage kernels are built)."""
    if affine:
        return "constant derivatives, evaluated once"
    if mode == "interpreted":
        return "solver.compile: interpreted"
    if mode == "auto" and operations < AUTO_FROM:
        return f"auto: {operations:,} operations, below {AUTO_FROM:,}"
    if build_c and compiler() is None:
        return "no C compiler found (gcc, cc or $CC)"
    return ""


# long: the stage walk needs the layout, the rows and the costate sets together; split, each part would take them all
def _staged(ex, rows: list, lay, game: CompiledGame, reach: list[np.ndarray], offsets: np.ndarray, inputs: list,
            a: ca.SX, X: ca.SX, x: ca.SX, lam: ca.SX, pattern: ca.Sparsity, size: int, dt: float | None
            ) -> tuple[ca.Function, ca.Function, ca.Function, int]:
    """The sparse system's function (a, lam, x) -> (F, nonzeros of dF/dw in ``pattern``, F0), its residual
    function (a, lam, x) -> (L, c) and its constraint function (a, x) -> c, built from per-stage Functions
    (gnerun.game.kernels) as MX graphs of their calls. Returns them and the number of distinct stage Functions.
    ``dt``: the expressions' stages take their own time in the first runtime value (built with ``local_time``),
    which is t + tau dt at stage tau."""
    N, n, nx, T = len(lay.variable_names), lay.n, lay.nx, lay.horizon
    S, Ptot, m = nx * (T + 1), int(offsets[-1]), len(rows)
    stage_rows: list[list[int]] = [[] for _ in range(T + 1)]
    for r, row in enumerate(rows):
        if row.info.stage is None or not 0 <= row.info.stage <= T:
            raise ValueError(f"constraint '{row.info.label}' belongs to no stage")
        stage_rows[row.info.stage].append(r)
    shared = game.shared_slice
    carried = [set(shared_rows_carried(rows[shared], shared.start, i).tolist()) for i in range(N)]
    R = [np.flatnonzero(r) for r in reach]
    k = [r.size for r in R]
    mine = [[q for q, (i, _) in enumerate(inputs) if i == agent] for agent in range(N)]
    nu = [len(names) for names in lay.variable_names]

    def u_index(tau: int) -> list[int]:
        return [lay.agent_slices[i].start + tau * nu[i] + j for i, j in inputs]

    stages = Stages()
    prm = x[nx:]
    for tau in range(T + 1):
        xp = x[:nx] if tau == 0 else X[(tau - 1) * nx:tau * nx]
        xn = X[tau * nx:(tau + 1) * nx]
        u = ca.vertcat(*[a[q] for q in u_index(tau)])
        sr = stage_rows[tau]
        lam_t = ca.vertcat(*[lam[r] for r in sr]) if sr else ca.SX(0, 1)
        c_t = ca.vertcat(*[rows[r].expr for r in sr]) if sr else ca.SX(0, 1)
        p_t = ca.SX.sym("p", sum(k))
        d_t = ex.defects[tau]
        ga, gxn, gxp = [], [], []
        for i in range(N):
            cost = ex.stage_costs[i][tau] + (ex.stage_costs[i][T + 1] if tau == T else 0)
            ms = game.multiplier_slices[i]
            q_i = [q for q, r in enumerate(sr) if ms.start <= r < ms.stop or r in carried[i]]
            pi = p_t[sum(k[:i]):sum(k[:i + 1])]
            ell = cost + ca.dot(lam_t[q_i], c_t[q_i]) + ca.dot(pi, d_t[R[i].tolist()])
            ga.append(ca.gradient(ell, u[mine[i]]))
            gxn.append(ca.gradient(ell, xn[R[i].tolist()]))
            gxp.append(ca.gradient(ell, xp[R[i].tolist()]))
        local = ca.vertcat(*ga, *gxn, *gxp, d_t, c_t)
        row_map = np.concatenate([
            *[np.array([lay.agent_slices[i].start + tau * nu[i] + j for j in range(nu[i])], dtype=int)
              for i in range(N)],
            *[n + offsets[i] + tau * k[i] + np.arange(k[i]) for i in range(N)],
            *[n + offsets[i] + (tau - 1) * k[i] + np.arange(k[i]) if tau else np.full(k[i], -1) for i in range(N)],
            n + Ptot + tau * nx + np.arange(nx), n + Ptot + S + np.asarray(sr, dtype=int)]).astype(int)
        col_map = np.concatenate([
            n + (tau - 1) * nx + np.arange(nx) if tau else np.full(nx, -1), np.asarray(u_index(tau), dtype=int),
            n + tau * nx + np.arange(nx), n + S + Ptot + np.asarray(sr, dtype=int),
            *[n + S + offsets[i] + tau * k[i] + np.arange(k[i]) for i in range(N)]]).astype(int)
        first = sum(nu)
        gxn_slices = [slice(first + sum(k[:i]), first + sum(k[:i + 1])) for i in range(N)]
        stages.add([xp, u, xn, lam_t, p_t, prm], local, ca.vertcat(xp, u, xn, lam_t, p_t), row_map, col_map,
                   gxn_slices, len(sr))

    aM, lamM, xM = ca.MX.sym("a", n), ca.MX.sym("lam", m), ca.MX.sym("x", x.numel())
    U = ca.reshape(aM[[q for tau in range(T + 1) for q in u_index(tau)]], len(inputs), T + 1)
    XR = ex.dynamics.mapaccum("roll", T + 1)(xM[:nx], U)  # xi(1..T+1)
    XP = ca.horzcat(xM[:nx], XR[:, :T])  # xi(0..T)
    pM, K = xM[nx:], sum(k)
    # runs of consecutive stages with one Function: each is one mapped call
    runs: list[tuple[int, int]] = []
    for tau in range(T + 1):
        if runs and stages.calls[tau] is stages.calls[runs[-1][0]]:
            runs[-1] = (runs[-1][0], tau + 1)
        else:
            runs.append((tau, tau + 1))

    def mapped(which: int, lo: int, hi: int, lam_on: bool, P) -> list:
        f = stages.calls[lo][which].map(hi - lo)
        nl = len(stage_rows[lo])
        lam_run = (ca.reshape(lamM[[r for tau in range(lo, hi) for r in stage_rows[tau]]], nl, hi - lo)
                   if lam_on and nl else ca.MX.zeros(nl, hi - lo))
        prm = pM
        if dt is not None:
            prm = ca.vertcat(pM[0] + dt * ca.DM(list(range(lo, hi))).T, ca.repmat(pM[1:], 1, hi - lo))
        out = f(XP[:, lo:hi], U[:, lo:hi], XR[:, lo:hi], lam_run, P[:, lo:hi], prm)
        return out if isinstance(out, (list, tuple)) else [out]

    first = sum(nu)
    zeros_P = ca.MX.zeros(K, T + 1)
    GX = ca.horzcat(*[mapped(0, lo, hi, True, zeros_P)[0][first:first + K, :] for lo, hi in runs])
    # costates backwards: p(T) = g(T), p(tau) = g(tau) + blockdiag_i f_xi[R_i, R_i](xi(tau+1), u(tau+1))^T p(tau+1)
    pn, xs, us, gs = ca.SX.sym("pn", K), ca.SX.sym("xs", nx), ca.SX.sym("us", len(inputs)), ca.SX.sym("g", K)
    A = ca.jacobian(ex.dynamics(xs, us), xs)
    back = [gs[sum(k[:i]):sum(k[:i + 1])] + ca.mtimes(A[R[i].tolist(), R[i].tolist()].T, pn[sum(k[:i]):sum(k[:i + 1])])
            for i in range(N)]
    step = ca.Function("costate_step", [pn, xs, us, gs], [ca.vertcat(*back)])
    if T:
        rev = list(range(T - 1, -1, -1))
        Pback = step.mapaccum("costates", T)(GX[:, T], XR[:, rev], U[:, [t + 1 for t in rev]], GX[:, rev])
        P = ca.horzcat(Pback[:, list(range(T - 1, -1, -1))], GX[:, T])
    else:
        P = GX
    fj = [mapped(1, lo, hi, True, P) for lo, hi in runs]
    f0 = [mapped(0, lo, hi, False, zeros_P)[0] for lo, hi in runs]
    f_only = [mapped(0, lo, hi, True, P)[0] for lo, hi in runs]
    M_F = scatter(size, stages.row_maps)
    targets = [pattern_positions(pattern, rm[r], cm[c])
               for rm, cm, (r, c) in zip(stages.row_maps, stages.col_maps, stages.jac_entries, strict=True)]
    M_J = scatter(pattern.nnz(), targets)

    def summed(M: ca.DM, parts: list) -> ca.MX:
        return ca.densify(ca.mtimes(M, ca.vertcat(*[ca.vec(v) for v in parts])))

    F, F0 = summed(M_F, [out[0] for out in fj]), summed(M_F, f0)
    Jnz = summed(M_J, [out[1] for out in fj])
    kkt = ca.Function("sparse_kkt", [aM, lamM, xM], [F, Jnz, F0], ["a", "lam", "x"], ["F", "J", "F0"])
    F_res = summed(M_F, f_only)
    residual = ca.Function("sparse_residual", [aM, lamM, xM], [F_res[:n], F_res[size - m:]], ["a", "lam", "x"],
                           ["L", "c"])
    # c alone (the states rolled out, each stage's rows of c): what the interior phase's slack reset reads
    with_rows = [(lo, hi) for lo, hi in runs if stage_rows[lo]]
    M_C = scatter(m, [np.asarray(stage_rows[tau], dtype=int) for lo, hi in with_rows for tau in range(lo, hi)])
    c_only = summed(M_C, [mapped(2, lo, hi, False, zeros_P)[0] for lo, hi in with_rows]) if with_rows else ca.MX(m, 1)
    constraints = ca.Function("sparse_constraints", [aM, xM], [c_only], ["a", "x"], ["c"])
    return kkt, residual, constraints, len(stages.groups)


def _costates(f: ca.Function, n_inputs: int, gx_only: list[ca.SX], reach: list[np.ndarray], X: ca.SX,
              u_at: Callable[[int], ca.SX], T: int) -> list[ca.SX]:
    """Each agent's costates p_i over its reachable states R_i, stage-major, by the backward recursion
    p_i(tau) = g_i(tau) + f_xi[R, R](xi(tau+1), u(tau+1))^T p_i(tau+1), p_i(T+1) = 0, with g_i = grad_xi of
    J_i + lambda^T c (``gx_only``)."""
    nx = f.nnz_in(0)
    xsym, usym = ca.SX.sym("xs", nx), ca.SX.sym("us", n_inputs)
    f_xi = ca.Function("f_xi", [xsym, usym], [ca.jacobian(f(xsym, usym), xsym)])
    costates = []
    for i, gi in enumerate(gx_only):
        R = np.flatnonzero(reach[i]).tolist()
        k = len(R)
        p_next = ca.SX.zeros(k)
        stages = [None] * (T + 1)
        for tau in range(T, -1, -1):
            p = gi[tau * k:(tau + 1) * k]
            if tau < T:
                p = p + ca.mtimes(f_xi(X[tau * nx:(tau + 1) * nx], u_at(tau + 1))[R, R].T, p_next)
            stages[tau] = p
            p_next = p
        costates.append(ca.vertcat(*stages))
    return costates


def reachable_states(dynamics: ca.Function, agent_inputs: list[list[int]]) -> list[np.ndarray]:
    """Per agent, the states its inputs can move (structurally): those the dynamics f(xi, u) make depend on its
    inputs, then every state whose derivative depends on one of them, to a fixed point."""
    Bx = _pattern(dynamics.jac_sparsity(0, 0))
    Bu = _pattern(dynamics.jac_sparsity(0, 1))
    out = []
    for cols in agent_inputs:
        r = Bu[:, cols].any(axis=1)
        while True:
            grown = r | Bx[:, r].any(axis=1)
            if (grown == r).all():
                break
            r = grown
        out.append(r)
    return out


def _pattern(sparsity: ca.Sparsity) -> np.ndarray:
    rows, cols = sparsity.get_triplet()
    B = np.zeros(sparsity.shape, dtype=bool)
    B[np.asarray(rows, dtype=int), np.asarray(cols, dtype=int)] = True
    return B


ORDERINGS = ("MMD_ATA", "COLAMD")


class Ordering:
    """SuperLU's column ordering for one kind of matrix of one game, chosen at its first factorisation: the one of
    ``ORDERINGS`` with the least fill (nonzeros of L and U; deterministic, unlike a timing). Minimum degree on M^T M
    keeps the fill linear in T for long horizons with few agents; COLAMD fills less with many agents
    (docs/performance.md). The choice is a property of the sparsity pattern, kept with the game's sparse system like the
    pattern itself."""

    def __init__(self) -> None:
        self.spec: str | None = None

    def factor(self, M: sp.csc_matrix, estimate: bool = True) -> tuple[spla.SuperLU | None, float]:
        if self.spec is not None:
            return factor(M, self.spec, estimate)
        best: tuple[int, str, spla.SuperLU] | None = None
        for spec in ORDERINGS:
            lu = _splu(M, spec)
            if lu is not None and (best is None or lu.L.nnz + lu.U.nnz < best[0]):
                best = (lu.L.nnz + lu.U.nnz, spec, lu)
        if best is None:
            return None, 0.0
        self.spec = best[1]
        return best[2], _rcond(M, best[2]) if estimate else math.nan


def _splu(M: sp.csc_matrix, spec: str) -> spla.SuperLU | None:
    try:
        return spla.splu(M, permc_spec=spec)
    except RuntimeError:  # "Factor is exactly singular"
        return None


def factor(M: sp.csc_matrix, permc_spec: str = "MMD_ATA", estimate: bool = True) -> tuple[spla.SuperLU | None, float]:
    """SuperLU factors of M and an estimate of its reciprocal 1-norm condition number (0 when singular; NaN
    without ``estimate``)."""
    lu = _splu(M, permc_spec)
    if lu is None:
        return None, 0.0
    return lu, _rcond(M, lu) if estimate else math.nan


def _rcond(M: sp.csc_matrix, lu: spla.SuperLU) -> float:
    """An estimate of M's reciprocal 1-norm condition number from its factors."""
    if M.shape[0] == 0:
        return 1.0
    inverse = spla.LinearOperator(M.shape, matvec=lu.solve, rmatvec=lambda b: lu.solve(b, trans="T"),
                                  dtype=float)
    with np.errstate(all="ignore"):
        inv_norm = spla.onenormest(inverse, t=1)
    norm = abs(M).sum(axis=0).max()
    rcond = 1.0 / (norm * inv_norm) if np.isfinite(inv_norm) and inv_norm > 0 else 0.0
    return float(rcond)


# the kinds of rows (and of columns) within a stage: stationarity in a (a), in xi (costates p), the defects d (states
# xi), the constraints c (multipliers lambda)
KINDS = 4


def _stages(system: SparseKKT) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The stage and kind of every row and every column of the full system. a_i(tau), xi(tau + 1), agent i's costates
    of xi(tau + 1) and the rows G_a, G_xi and d of the same variables belong to stage tau; a constraint row and its
    multiplier to the last stage of the variables it involves (from the pattern)."""
    game = system.game
    n, S, m, size = system.n, system.S, system.m, system.size
    P = size - n - S - m
    stages = system.stages
    nx = S // stages
    row_stage, col_stage = np.zeros(size, dtype=int), np.zeros(size, dtype=int)
    row_kind, col_kind = np.zeros(size, dtype=int), np.zeros(size, dtype=int)
    for sl in game.agent_slices:
        count = sl.stop - sl.start
        row_stage[sl] = col_stage[sl] = np.arange(count) // max(1, count // stages)
    col_stage[n:n + S] = row_stage[n + P:n + P + S] = np.arange(S) // nx
    for p, own in zip(system.costates, system.states, strict=True):
        col_stage[n + S + p.start:n + S + p.stop] = row_stage[n + p.start:n + p.stop] = own // nx
    row_kind[n:n + P], col_kind[n:n + S] = 1, 2
    row_kind[n + P:n + P + S], col_kind[n + S:n + S + P] = 2, 1
    lam0 = size - m
    row_kind[lam0:] = col_kind[lam0:] = 3
    c = system.pattern.tocoo()
    on = (c.row >= lam0) & (c.col < lam0)
    last = np.zeros(m, dtype=int)
    np.maximum.at(last, c.row[on] - lam0, col_stage[c.col[on]])
    row_stage[lam0:] = col_stage[lam0:] = last
    return row_stage, row_kind, col_stage, col_kind


def _inverse(order: np.ndarray) -> np.ndarray:
    where = np.empty_like(order)
    where[order] = np.arange(order.size)
    return where


class StageOrder:
    """The full system's rows and columns ordered stage by stage (every row and column belongs to one stage: the
    stage of the variables it is about, :func:`_stages`), and within a stage by kind, in the order of kinds (for rows
    and for columns: 24 x 24 pairs) that makes the band of the pattern and the diagonal narrowest (least
    kl (kl + ku), the flops of banded LU; with the diagonal of the decisions' and the multipliers' blocks, where the
    solvers add to it). Rows and columns touch their own and the neighbouring stages only, so the
    matrix is banded with a bandwidth of about half a stage's unknowns (merge: kl = 18, ku = 27 for 39 unknowns per
    stage)."""

    def __init__(self, system: SparseKKT) -> None:
        self.stages = _stages(system)  # (row stage, row kind, column stage, column kind)
        c = system.pattern.tocoo()
        self.rows, self.cols = c.row.astype(np.int64), c.col.astype(np.int64)  # the nonzeros, in data order
        # the solvers add to the diagonal of the decisions' and the multipliers' blocks (same stage and kind)
        diagonal = np.r_[0:system.n, system.size - system.m:system.size]
        rows, cols = np.concatenate([self.rows, diagonal]), np.concatenate([self.cols, diagonal])
        self.row_key, self.col_key, self.lower, self.upper = _narrowest(*self.stages, rows, cols)
        self.size = system.size
        self.layouts: dict = {}
        self.banded: bool | None = None  # None: banded LU where banded_wins; True or False: always that (benchmarks)
        self.compiled_layouts = None  # the compiled layout arithmetic (KeptLayout._compiled; False: none)


def _narrowest(row_stage: np.ndarray, row_kind: np.ndarray, col_stage: np.ndarray, col_kind: np.ndarray,
               rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray, int, int]:
    """The keys that order rows and columns stage by stage, and within a stage by kind, in the order of kinds (for
    rows and for columns: 24 x 24 pairs) that gives the entries (``rows``, ``cols``) the narrowest band (least
    kl (kl + ku), the flops of banded LU); and that band (kl, ku)."""
    perms = [np.array(p) for p in itertools.permutations(range(KINDS))]
    row_keys = [row_stage * KINDS + p[row_kind] for p in perms]
    col_keys = [col_stage * KINDS + p[col_kind] for p in perms]
    row_at = [_inverse(np.argsort(k, kind="stable"))[rows] for k in row_keys]
    col_at = [_inverse(np.argsort(k, kind="stable"))[cols] for k in col_keys]
    best = None
    for i, ri in enumerate(row_at):
        for j, cj in enumerate(col_at):
            d = ri - cj
            kl, ku = max(int(d.max(initial=0)), 0), max(-int(d.min(initial=0)), 0)
            if best is None or (kl * (kl + ku), kl, ku) < best[0]:
                best = ((kl * (kl + ku), kl, ku), i, j)
    (_, lower, upper), i, j = best
    return row_keys[i], col_keys[j], lower, upper  # sort the kept rows (columns) by the keys, stably


class KeptLayout:
    """Where the pattern's nonzeros (and additions to the diagonal at ``at``) of the matrix restricted to the rows and
    columns ``keep`` go: in LAPACK's band storage of the stage-ordered matrix (rows and columns permuted by the
    stage order), or in a CSC matrix for SuperLU, whichever factorises faster (``banded``). With ``eliminate``
    (positions in ``keep`` whose block is diagonal, :class:`Elimination`), the matrix stored is the one those unknowns
    are eliminated from, in its own stage order (the kinds ordered anew for its pattern)."""

    def __init__(self, order: StageOrder, keep: np.ndarray, at: np.ndarray | None, banded: bool | None = None,
                 eliminate: np.ndarray | None = None) -> None:
        self.compiled_point = None  # the compiled Newton point (SparseKKT.point_kept; False: none)
        if eliminate is None and self._compiled(order, keep, at, banded):
            return
        where = np.full(order.size, -1)
        where[keep] = np.arange(keep.size)
        r, c = where[order.rows], where[order.cols]
        inside = (r >= 0) & (c >= 0)
        nonzeros = np.flatnonzero(inside)  # which of the data are in the kept matrix
        r, c = r[nonzeros], c[nonzeros]  # their rows and columns in the kept matrix
        at = np.zeros(0, dtype=np.int64) if at is None else at.astype(np.int64)
        row_key, col_key = order.row_key[keep], order.col_key[keep]
        self.elimination: Elimination | None = None
        fill_r = fill_c = np.zeros(0, dtype=np.int64)  # the entries the elimination adds
        if eliminate is not None:
            e = self.elimination = Elimination(keep.size, nonzeros, r, c, at, eliminate)
            nonzeros, r, c, at, fill_r, fill_c = e.nonzeros, e.r, e.c, e.at, e.fill_r, e.fill_c
            rest = keep[e.rest]
            row_key, col_key, _, _ = _narrowest(*(stage[rest] for stage in order.stages),
                                                np.concatenate([r, at, fill_r]), np.concatenate([c, at, fill_c]))
        self.nonzeros, self.at = nonzeros, at
        self.size = size = row_key.size
        self.row_order = np.argsort(row_key, kind="stable")  # band row i is kept row row_order[i]
        self.col_order = np.argsort(col_key, kind="stable")
        ir, ic = _inverse(self.row_order), _inverse(self.col_order)
        rows, cols = np.concatenate([r, at, fill_r]), np.concatenate([c, at, fill_c])
        i, j = ir[rows], ic[cols]
        d = i - j
        self.lower, self.upper = max(int(d.max(initial=0)), 0), max(-int(d.min(initial=0)), 0)
        self.banded = banded_wins(size, self.lower, self.upper) if banded is None else banded
        if self.banded:
            kl, ku = self.lower, self.upper
            self.ld = 2 * kl + ku + 1
            # entry (i, j) of the permuted matrix is ab[kl + ku + i - j, j]; ab is Fortran-ordered (ld, size), held
            # as its C-ordered transpose
            positions = j * self.ld + kl + ku + d
        else:
            keys = cols * size + rows
            unique = np.unique(keys)
            self.indices = (unique % size).astype(np.int32)
            self.indptr = np.searchsorted(unique // size, np.arange(size + 1)).astype(np.int32)
            positions = np.searchsorted(unique, keys)
            self.nnz = unique.size
        self.flat, self.flat_at, self.flat_fill = (positions[:r.size], positions[r.size:r.size + at.size],
                                                   positions[r.size + at.size:])

    def _compiled(self, order: StageOrder, keep: np.ndarray, at: np.ndarray | None, banded: bool | None) -> bool:
        """The banded layout without an elimination from the compiled index arithmetic
        (:class:`gnerun.game.banded.KeptLayouts`: the same integers as the numpy code below, in a third to a half of
        its time); False where nothing is compiled or the matrix goes to SuperLU (the numpy code then makes it)."""
        compiled = order.compiled_layouts
        if compiled is None:
            compiled = order.compiled_layouts = banded_code.kept_layouts(
                order.size, order.rows, order.cols, order.row_key, order.col_key, BAND_FRACTION) or False
        if not compiled:
            return False
        at = np.zeros(0, dtype=np.int64) if at is None else at.astype(np.int64)
        found = compiled(keep, at, banded)
        if found is None or not found[6]:
            return False
        nonzeros, positions, row_order, col_order, kl, ku, _ = found
        self.elimination = None
        self.nonzeros, self.at, self.size = nonzeros, at, keep.size
        self.row_order, self.col_order, self.lower, self.upper = row_order, col_order, kl, ku
        self.banded, self.ld = True, 2 * kl + ku + 1
        self.flat, self.flat_at, self.flat_fill = positions[:nonzeros.size], positions[nonzeros.size:], positions[:0]
        return True

    def _fill(self, out: np.ndarray, data: np.ndarray, add: np.ndarray | None) -> None:
        """The matrix's entries into the flat storage ``out`` (zeros)."""
        out[self.flat] = data[self.nonzeros]
        e = self.elimination
        if e is not None:
            out[self.flat_fill] += e.fill(data, add)
            add = add[e.add_kept]
        if add is not None:
            out[self.flat_at] += add

    def csc(self, data: np.ndarray, add: np.ndarray | None) -> sp.csc_matrix:
        values = np.zeros(self.nnz)
        self._fill(values, data, add)
        return sp.csc_matrix((values, self.indices, self.indptr), shape=(self.size, self.size))

    def band(self, data: np.ndarray, add: np.ndarray | None) -> np.ndarray:
        """The stage-ordered matrix in LAPACK's band storage with room for the fill of partial pivoting."""
        ab = np.zeros((self.size, self.ld))  # the transpose of the Fortran-ordered band
        self._fill(ab.reshape(-1), data, add)
        return ab.T

    def factor(self, data: np.ndarray, add: np.ndarray | None,
               estimate: bool = True) -> tuple[BandLU | EliminatedLU | None, float]:
        """Banded LU with partial pivoting (LAPACK dgbtrf) and its reciprocal 1-norm condition estimate (dgbcon's;
        NaN without ``estimate``; with an elimination, of the matrix factorised). The factorisation, the norm and the
        estimate are compiled (:mod:`gnerun.game.banded`: the same bits as LAPACK's and numpy's), or LAPACK's and
        numpy's where the compiled code is not used."""
        if not self.size:
            factors = BandLU(self, np.zeros((self.ld, 0), order="F"), np.zeros(0, dtype=np.int32))
            return self.eliminated(factors, data, add), 1.0
        ab = self.band(data, add)
        norm = math.nan
        if estimate:  # before dgbtrf overwrites ab
            norm = banded.one_norm(ab)
            if norm is None:
                norm = float(np.abs(ab).sum(axis=0).max())
        factored = banded.lu_factor(ab, self.lower, self.upper)  # dgbtrf's bits, compiled where it can
        if factored is None:  # the compiled factorisation met a value that is not finite: LAPACK's, on a new band
            factored = lapack.dgbtrf(self.band(data, add), self.lower, self.upper, overwrite_ab=1)
        lu, piv, info = factored
        if info != 0:  # an exactly zero pivot
            return None, 0.0
        factors = BandLU(self, lu, piv)
        if not estimate:
            return self.eliminated(factors, data, add), math.nan
        return self.eliminated(factors, data, add), self._rcond(factors, norm)

    def rcond(self, factors: BandLU | EliminatedLU, data: np.ndarray, add: np.ndarray | None) -> float:
        """The estimate :meth:`factor` returns with ``estimate``, from the factors it made without (the band filled
        again for its norm: the same number)."""
        if not self.size:
            return 1.0
        ab = self.band(data, add)
        norm = banded.one_norm(ab)
        if norm is None:
            norm = float(np.abs(ab).sum(axis=0).max())
        return self._rcond(getattr(factors, "factors", factors), norm)

    def _rcond(self, factors: BandLU, norm: float) -> float:
        """1 / (||M||_1 times the estimate of ||M^-1||_1 from the factors), 0 where that estimate is not positive."""
        lu, piv = factors.lu, factors.piv
        inverse = banded.lu_inverse_norm(lu, self.lower, self.upper, piv)  # the same estimate, all in C
        if inverse is None:
            inverse = inverse_norm(factors.solve_band, lambda b: factors.solve_band(b, 1), self.size)
        return 1.0 / (norm * inverse) if np.isfinite(inverse) and inverse > 0 else 0.0

    def eliminated(self, factors, data: np.ndarray, add: np.ndarray | None):
        """``factors`` of the matrix stored, as factors of the kept matrix (the same without an elimination)."""
        if self.elimination is None or factors is None:
            return factors
        return EliminatedLU(self.elimination, factors, data, add)


class Elimination:
    """Unknowns eliminated from a kept matrix before its factorisation: ``eliminate`` (positions in the kept matrix)
    whose block is diagonal, its entries added at ``at`` (none in the pattern). With K = [K_rr K_re; K_er E] (r: the
    rest), E diagonal, the matrix factorised is the Schur complement K_rr - K_re E^-1 K_er, and x_e = E^-1 (b_e - K_er
    x_r): the interior-point matrix with its inequality multipliers eliminated, 600 unknowns instead of 780 and a band
    of (18, 18) instead of (18, 27) on ALGAMES's merge. The pattern is fixed: every product K_ie E_ee^-1 K_ej is a
    pair of the pattern's nonzeros, listed once, summed per entry (i, j) of the complement.

    ``nonzeros``, ``r``, ``c``: which of the pattern's data are in the kept matrix, and their rows and columns there.
    Afterwards the same, and ``at``, are over the rest (numbered 0, 1, ... in the order of ``rest``), and ``fill_r``,
    ``fill_c`` are the entries the products add (``fill``: their values)."""

    def __init__(self, size: int, nonzeros: np.ndarray, r: np.ndarray, c: np.ndarray, at: np.ndarray,
                 eliminate: np.ndarray) -> None:
        out = np.zeros(size, dtype=bool)
        out[eliminate] = True
        self.rest, self.out = np.flatnonzero(~out), np.sort(eliminate)
        number = np.full(size, -1)
        number[self.rest] = np.arange(self.rest.size)
        number[self.out] = np.arange(self.out.size)
        where_at = np.full(size, -1)
        where_at[at] = np.arange(at.size)
        self.diagonal_at = where_at[self.out]  # the eliminated block's diagonal: these entries of add
        if np.any(self.diagonal_at < 0) or np.any(out[r] & out[c]):
            raise ValueError("the unknowns eliminated must have a diagonal block, added at `at`")
        self.add_kept = np.flatnonzero(~out[at])
        self.whole = (nonzeros, r, c, at)  # the kept matrix, for the residual of a refinement
        kept = ~out[r] & ~out[c]
        self.nonzeros, self.r, self.c = nonzeros[kept], number[r[kept]], number[c[kept]]
        self.at = number[at[self.add_kept]]
        # K_re (rows of the rest, columns eliminated) and K_er, by eliminated unknown
        re, er = ~out[r] & out[c], out[r] & ~out[c]
        re_order = np.argsort(number[c[re]], kind="stable")
        er_order = np.argsort(number[r[er]], kind="stable")
        self.re = (nonzeros[re][re_order], number[r[re]][re_order], number[c[re]][re_order])  # (data, row, column)
        self.er = (nonzeros[er][er_order], number[r[er]][er_order], number[c[er]][er_order])
        k = self.out.size
        re_count, er_count = np.bincount(self.re[2], minlength=k), np.bincount(self.er[1], minlength=k)
        re_start, er_start = np.cumsum(re_count) - re_count, np.cumsum(er_count) - er_count
        # every pair (i, e), (e, j): its entry of K_re, of K_er, and e
        first = np.concatenate([np.repeat(np.arange(re_start[e], re_start[e] + re_count[e]), er_count[e])
                                for e in range(k)] or [np.zeros(0, dtype=np.int64)]).astype(np.int64)
        second = np.concatenate([np.tile(np.arange(er_start[e], er_start[e] + er_count[e]), re_count[e])
                                 for e in range(k)] or [np.zeros(0, dtype=np.int64)]).astype(np.int64)
        self.pair_re, self.pair_er = self.re[0][first], self.er[0][second]
        self.pair_out = self.re[2][first]
        rows, cols = self.re[1][first], self.er[2][second]
        keys, self.pair_entry = np.unique(rows * size + cols, return_inverse=True)
        self.fill_r, self.fill_c = keys // size, keys % size
        self.pair_entry = self.pair_entry.reshape(-1)
        self._compiled = None  # the compiled solve (see compiled)

    @property
    def refine_from(self) -> float:
        """``REFINE_FROM``: a solve is refined where an eliminated diagonal entry is at most its reciprocal."""
        return REFINE_FROM

    def compiled(self, layout: KeptLayout):
        """The compiled solve (:class:`gnerun.game.banded.EliminatedSolve`) with the band ``layout`` of the complement
        (built once; False where nothing is compiled)."""
        if self._compiled is None:
            found = banded.eliminated_solve([self.rest, self.out, self.re[1], self.re[2], self.er[1], self.er[2],
                                             layout.row_order, layout.col_order], layout.lower, layout.upper)
            self._compiled = found if found is not None else False
        return self._compiled

    def fill(self, data: np.ndarray, add: np.ndarray) -> np.ndarray:
        """The entries of -K_re E^-1 K_er (at ``fill_r``, ``fill_c``) for the pattern's nonzeros ``data`` and the
        diagonal additions ``add``."""
        inverse = -1.0 / add[self.diagonal_at]
        products = data[self.pair_re] * data[self.pair_er] * inverse[self.pair_out]
        return np.bincount(self.pair_entry, products, minlength=self.fill_r.size)


# one step of iterative refinement on the kept system where an eliminated diagonal entry is this small (|E_ee| <=
# 1/REFINE_FROM): the complement's entries grow as 1/E, and with them the kept system's residual (measured on the
# interior matrices of 10 merges: ||r|| / ||b|| up to 1e-8 at 1/D = 1e12, 1e-11 with the unreduced LU or refined)
REFINE_FROM = 1e6


class EliminatedLU:
    """Factors of a kept matrix with unknowns eliminated (:class:`Elimination`): those of the Schur complement
    (``factors``), and what the solve needs of K_re, K_er and E (``data``, ``add``)."""

    def __init__(self, elimination: Elimination, factors, data: np.ndarray, add: np.ndarray) -> None:
        e = self.elimination = elimination
        self.factors, self.data, self.add = factors, data, add
        self.diagonal = add[e.diagonal_at]
        self.re, self.er = data[e.re[0]], data[e.er[0]]
        self.refine = bool(np.any(np.abs(self.diagonal) * REFINE_FROM <= 1.0))

    def solve(self, b: np.ndarray) -> np.ndarray:
        """The solution of the kept system (refined once where ``refine``)."""
        x = self._solve(b)
        if self.refine:
            nonzeros, r, c, at = self.elimination.whole
            residual = b - np.bincount(r, self.data[nonzeros] * x[c], minlength=b.size)
            residual[at] -= self.add * x[at]
            x += self._solve(residual)
        return x

    def _solve(self, b: np.ndarray) -> np.ndarray:
        """x_r from the complement's factors, then x_e = E^-1 (b_e - K_er x_r): compiled where the factors are banded
        (:class:`gnerun.game.banded.EliminatedSolve`, the same operations), else by numpy."""
        e, factors = self.elimination, self.factors
        if isinstance(factors, BandLU):
            compiled = e.compiled(factors.layout)
            if compiled:
                return compiled(factors.lu, factors.piv, self.diagonal, self.re, self.er, b)
        x = np.empty_like(b)
        b_out = b[e.out] / self.diagonal
        x_rest = self.factors.solve(b[e.rest] - np.bincount(e.re[1], self.re * b_out[e.re[2]],
                                                             minlength=e.rest.size))
        x[e.rest] = x_rest
        x[e.out] = b_out - np.bincount(e.er[1], self.er * x_rest[e.er[2]], minlength=e.out.size) / self.diagonal
        return x


class BandLU:
    """The LU factors of a stage-ordered kept matrix (:class:`KeptLayout`), solving in the original order."""

    def __init__(self, layout: KeptLayout, lu: np.ndarray, piv: np.ndarray) -> None:
        self.layout, self.lu, self.piv = layout, lu, piv

    def solve(self, b: np.ndarray) -> np.ndarray:
        layout = self.layout
        if not layout.size:
            return np.zeros(0)
        x = np.empty_like(b)
        x[layout.col_order] = self.solve_band(b[layout.row_order])
        return x

    def solve_band(self, b: np.ndarray, trans: int = 0) -> np.ndarray:
        """The solution of the stage-ordered system (``trans`` = 1: of its transpose), dgbtrs's (compiled, the same
        bits: :func:`gnerun.game.banded.lu_solve`)."""
        return banded.lu_solve(self.lu, self.layout.lower, self.layout.upper, self.piv, b, trans)  # dgbtrs's bits


def inverse_norm(solve: Callable[[np.ndarray], np.ndarray], solve_T: Callable[[np.ndarray], np.ndarray],
                 n: int) -> float:
    """An estimate of ||A^-1||_1 from solves with A and A^T: Hager's method as Higham refined it, the algorithm of
    LAPACK's condition estimators (dlacn2, at most 5 iterations); dgbcon's estimate, with dgbtrs's solves in place
    of its scaled triangular ones (three times slower on these bands). :func:`gnerun.game.banded.lu_inverse_norm` makes
    the same operations in C, with the same result."""
    x = solve(np.full(n, 1.0 / n))
    if n == 1:
        return float(abs(x[0]))
    est = float(np.abs(x).sum())
    if not np.isfinite(est):
        return est
    signs = np.where(x >= 0, 1.0, -1.0)
    x = solve_T(signs)
    j = int(np.argmax(np.abs(x)))
    for iteration in range(2, 6):
        e = np.zeros(n)
        e[j] = 1.0
        x = solve(e)
        previous, est = est, float(np.abs(x).sum())
        new_signs = np.where(x >= 0, 1.0, -1.0)
        if np.array_equal(new_signs, signs) or est <= previous:
            break
        signs = new_signs
        x = solve_T(signs)
        last, j = j, int(np.argmax(np.abs(x)))
        if x[last] == abs(x[j]) or iteration == 5:
            break
    alternating = np.where(np.arange(n) % 2 == 0, 1.0, -1.0) * (1.0 + np.arange(n) / (n - 1))
    return max(est, 2.0 * float(np.abs(solve(alternating)).sum()) / (3.0 * n))


BAND_FRACTION = 0.25  # banded LU where the band (kl + ku + 1) is at most this fraction of the matrix's size


banded_code = banded  # (KeptLayout's own argument ``banded`` hides the module)


def banded_wins(size: int, lower: int, upper: int) -> bool:
    """Whether banded LU factorises the stage-ordered matrix faster than SuperLU: where its band is narrow, at most
    ``BAND_FRACTION`` of its size. Measured on the matrices the solvers factorise (``python -m benchmarks stages``:
    assembly, LU and condition estimate, same matrices, same process, three runs on a loaded machine), banded LU is
    1.4-5 times faster than SuperLU with ``onenormest`` on every game measured, whose bands cover 1.3-9% of the size:
    the ALGAMES merge of 3, 5, 8 and 12 cars (kl = 18..72), the 41-knot merge and intersection, the 6-robot formation
    ring and the bounded LQ family at T = 40 and 80. A pattern whose rows reach across the horizon (a constraint on
    all stages) has a band as wide as the matrix, where SuperLU's fill-reducing orderings keep the work linear in the
    horizon and the band's is cubic."""
    return lower + upper + 1 <= BAND_FRACTION * size
