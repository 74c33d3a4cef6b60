"""The bounded LQ dynamic-game family: the paper's Study 1 game with input bounds and one shared state constraint.

Three agents, x(t + 1) = diag(0.5, 0.3, 0.2) x(t) + u(t), x(0) = (1, 3, 5), horizon T (inputs u_i(0..T)), the
stage costs of configs/paper_study1.yaml with the targets moved to 2 (below), charged on the state each input
produces, without the agents' own (coupled) constraints of Study 1; instead -1/2 <= u_i <= 1/2 for every agent and one
constraint shared by all three, x1 + x2 + x3 <= 3 at every stage tau = 0..T (on x(tau + 1)). Horizons 5, 20, 40;
equilibrium ``variational`` (one common multiplier per stage) or ``generalized`` (each agent carries the shared
constraint with its own multiplier). The configs leave out ``solver:``: the suite tests gnerun's defaults.

Independent of gnerun, the game is condensed here by hand: X_i = (x_i(1), ..., x_i(T + 1)) = M_i z + d_i with
z = (u1(0..T), u2(0..T), u3(0..T)) (gnerun's order of the inputs), so J_i(z) = 0.5 z'Q_i z + c_i'z + k_i, the
shared constraint is A z <= b and the bounds lb <= z <= ub. The variational equilibrium solves the VI
F(z) = P z + q (row block i of P and q: agent i's rows of Q_i and c_i) on that polyhedron; the references below
come from two independent solves of it (:func:`compute_references`): nashopt's ``GNEP_LQ(..., variational=True,
solver="dr_daqp")`` (Douglas-Rachford with DAQP active-set acceleration) and an extragradient method whose
Euclidean projections onto the polyhedron are QPs solved by DAQP, finished by solving the KKT system of the
active set it identifies. Both must agree to 1e-8.

The state targets are 2 (l1 = (x1 - 2)^2 - x1 x2, l2 = (x2 - 2)^2 + x1 x2, l3 = (x3 - 2)^2) and the bounds |u_i| <= 1/2,
so that the bounds and the shared constraint bind at the equilibrium: from z = 0 the local semismooth Newton method
meets a singular JPhi at its second step (four active rows on three stage-0 inputs), and the generalized version
has a continuum of equilibria (each agent carries the binding shared row with its own multiplier).

``python -m benchmarks.problems.lq`` recomputes the references and compares them with the stored ones.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from functools import cached_property, partial

import numpy as np

from benchmarks.problems import Problem

A_DIAG = np.array([0.5, 0.3, 0.2])  # x(t + 1) = diag(A_DIAG) x(t) + u(t)
X0 = np.array([1.0, 3.0, 5.0])
TARGET = 2.0  # every agent's state target: (x_i - TARGET)^2
BOUND = 0.5  # -BOUND <= u_i <= BOUND
SHARED_RHS = 3.0  # x1 + x2 + x3 <= SHARED_RHS at every stage
HORIZONS = (5, 20, 40)
EQUILIBRIA = ("variational", "generalized")
AGENTS = ("agent1", "agent2", "agent3")
FEAS_TOL = 1e-9  # a point violating an agent's constraints by more than this has an infinite best-response gap
POLISH_FROM = 1e-9  # extragradient steps below this start the exact active-set finish
REFERENCE_AGREEMENT = 1e-8  # the two independent solves must agree to this (infinity norm)


def lq_yaml(T: int, equilibrium: str) -> str:
    """The gnerun config of the family's game at horizon ``T`` (no ``solver:`` block: gnerun's defaults)."""
    if equilibrium not in EQUILIBRIA:
        raise ValueError(f"equilibrium must be one of {EQUILIBRIA}, not {equilibrium!r}")
    a = [[float(A_DIAG[i]) if i == j else 0.0 for j in range(3)] for i in range(3)]
    b = [[1.0 if i == j else 0.0 for j in range(3)] for i in range(3)]
    costs = (f"(x1 - {TARGET})**2 - x1*x2", f"(x2 - {TARGET})**2 + x1*x2", f"(x3 - {TARGET})**2")
    lines = [
        f"# Bounded LQ family: Study 1's dynamics and costs, |u_i| <= {BOUND}, shared x1 + x2 + x3 <= {SHARED_RHS}.",
        f"name: lq-{equilibrium}-T{T}",
        "game:",
        "  kind: dynamic",
        f"  horizon: {T}",
        "  states: [x1, x2, x3]",
        "  dynamics:",
        f"    A: {a}",
        f"    B: {b}",
        f"  x0: {X0.tolist()}",
        "  agents:",
    ]
    for i, (name, cost) in enumerate(zip(AGENTS, costs, strict=True)):
        lines += [
            f"    - name: {name}",
            f"      inputs: {{u{i + 1}: {{lower: {-BOUND}, upper: {BOUND}}}}}",
            f'      stage_cost: "{cost}"',
        ]
    lines += [f'  shared_constraints: ["x1 + x2 + x3 <= {SHARED_RHS}"]', f"  equilibrium: {equilibrium}"]
    return "\n".join(lines) + "\n"


@dataclass(frozen=True)
class CondensedLQ:
    """The game condensed over the horizon: agent i minimises J_i(z) = 0.5 z'Q[i] z + c[i]'z + k[i] over its
    block of z, subject to lb <= z <= ub and A z <= b (shared)."""

    T: int
    M: list[np.ndarray]  # X_i = M[i] z + d[i], X_i = (x_i(1), ..., x_i(T + 1))
    d: list[np.ndarray]
    Q: list[np.ndarray]
    c: list[np.ndarray]
    k: list[float]
    lb: np.ndarray
    ub: np.ndarray
    A: np.ndarray
    b: np.ndarray

    @property
    def H(self) -> int:
        """Stages per agent, T + 1."""
        return self.T + 1

    @property
    def n(self) -> int:
        """Decision variables, 3 (T + 1)."""
        return 3 * self.H

    def block(self, i: int) -> slice:
        """Agent i's inputs in z."""
        return slice(i * self.H, (i + 1) * self.H)

    @cached_property
    def P(self) -> np.ndarray:
        """The VI matrix: F(z) = P z + q, row block i = agent i's rows of Q[i]."""
        return np.vstack([self.Q[i][self.block(i)] for i in range(3)])

    @cached_property
    def q(self) -> np.ndarray:
        """The VI vector: row block i = agent i's rows of c[i]."""
        return np.concatenate([self.c[i][self.block(i)] for i in range(3)])

    def costs(self, z: np.ndarray) -> np.ndarray:
        """(J_1(z), J_2(z), J_3(z)), constants included."""
        return np.array([0.5 * z @ self.Q[i] @ z + self.c[i] @ z + self.k[i] for i in range(3)])

    def states(self, z: np.ndarray) -> np.ndarray:
        """X_i(z) by agent (rows) and stage tau + 1 (columns)."""
        return np.array([self.M[i] @ z + self.d[i] for i in range(3)])

    @cached_property
    def G(self) -> np.ndarray:
        """All inequality rows, G z <= h: upper bounds, lower bounds, the shared rows."""
        return np.vstack([np.eye(self.n), -np.eye(self.n), self.A])

    @cached_property
    def h(self) -> np.ndarray:
        """Right-hand sides of :attr:`G`."""
        return np.concatenate([self.ub, -self.lb, self.b])


def condense(T: int) -> CondensedLQ:
    """Condense the family's game at horizon T (states affine in the inputs, quadratic costs)."""
    H = T + 1
    n = 3 * H
    k = np.arange(H)
    lag = np.subtract.outer(k, k)  # row tau (state x(tau + 1)), column s (input u(s)): a^(tau - s) for s <= tau
    M: list[np.ndarray] = []
    d: list[np.ndarray] = []
    for i in range(3):
        Ei = np.zeros((H, n))
        Ei[:, i * H : (i + 1) * H] = np.eye(H)
        Gi = np.where(lag >= 0, A_DIAG[i] ** np.clip(lag, 0, None), 0.0)
        M.append(Gi @ Ei)
        d.append(A_DIAG[i] ** (k + 1) * X0[i])
    r = np.full(H, TARGET)
    cross = M[0].T @ M[1] + M[1].T @ M[0]  # Hessian of X1.X2
    cross_lin = M[0].T @ d[1] + M[1].T @ d[0]  # its gradient at z = 0
    cross_const = float(d[0] @ d[1])
    own = [(2 * M[i].T @ M[i], 2 * M[i].T @ (d[i] - r), float((d[i] - r) @ (d[i] - r))) for i in range(3)]
    Q = [own[0][0] - cross, own[1][0] + cross, own[2][0]]
    c = [own[0][1] - cross_lin, own[1][1] + cross_lin, own[2][1]]
    consts = [own[0][2] - cross_const, own[1][2] + cross_const, own[2][2]]
    return CondensedLQ(
        T=T,
        M=M,
        d=d,
        Q=Q,
        c=c,
        k=consts,
        lb=np.full(n, -BOUND),
        ub=np.full(n, BOUND),
        A=M[0] + M[1] + M[2],
        b=SHARED_RHS - (d[0] + d[1] + d[2]),
    )


def _qp(H: np.ndarray, f: np.ndarray, lb: np.ndarray, ub: np.ndarray, A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """argmin 0.5 x'H x + f'x subject to lb <= x <= ub, A x <= b, by DAQP (H positive definite)."""
    from ctypes import c_int

    import daqp

    m = A.shape[0]
    bupper = np.concatenate([ub, b])
    blower = np.concatenate([lb, np.full(m, -1e30)])
    x, _, exitflag, _ = daqp.solve(np.ascontiguousarray(H, dtype=float), np.ascontiguousarray(f, dtype=float),
                                   np.ascontiguousarray(A, dtype=float), bupper, blower,
                                   np.zeros(lb.size + m, dtype=c_int), primal_tol=1e-12)
    if exitflag <= 0:
        raise RuntimeError(f"DAQP found no solution of a strictly convex QP (exit flag {exitflag})")
    return np.asarray(x, dtype=float)


def _violation(game: CondensedLQ, z: np.ndarray) -> float:
    """Largest violation of the bounds and the shared constraint (0 when all hold)."""
    return float(max(0.0, np.max(game.G @ z - game.h)))


def best_response_gaps(game: CondensedLQ, a: np.ndarray) -> dict[str, float]:
    """Per agent, J_i(a) - min over its own inputs (the others fixed at a_-i) subject to its bounds and the shared
    constraint: a convex QP, solved by DAQP. An agent whose inputs violate those constraints by more than
    ``FEAS_TOL`` has gap ``inf`` (an infeasible point is no equilibrium)."""
    a = np.asarray(a, dtype=float)
    if a.shape != (game.n,):
        raise ValueError(f"expected {game.n} inputs, got shape {a.shape}")
    gaps: dict[str, float] = {}
    for i, name in enumerate(AGENTS):
        s = game.block(i)
        others = np.ones(game.n, dtype=bool)
        others[s] = False
        Qii = game.Q[i][s, s]
        lin = game.c[i][s] + game.Q[i][s][:, others] @ a[others]
        rhs = game.b - game.A[:, others] @ a[others]
        ai = a[s]
        viol = max(0.0, float(np.max(game.lb[s] - ai)), float(np.max(ai - game.ub[s])),
                   float(np.max(game.A[:, s] @ ai - rhs)))
        if viol > FEAS_TOL:
            gaps[name] = math.inf
            continue
        best = _qp(Qii, lin, game.lb[s], game.ub[s], game.A[:, s], rhs)
        step = ai - best  # J_i(a) - J_i(best) written without cancellation of the two cost values
        gaps[name] = float((Qii @ best + lin) @ step + 0.5 * step @ Qii @ step)
    return gaps


def vi_kkt_residual(game: CondensedLQ, a: np.ndarray, active_tol: float = 1e-9) -> float:
    """Residual of the variational KKT system at ``a``: P a + q + G'lam = 0, lam >= 0, G a <= h, lam'(h - G a) = 0.
    The multipliers of the rows within ``active_tol`` of active are fitted by least squares; the result is the
    largest of the stationarity residual, the infeasibility, the negative part of the multipliers and the
    complementarity products (infinity norms)."""
    a = np.asarray(a, dtype=float)
    slack = game.h - game.G @ a
    active = slack <= active_tol
    grad = game.P @ a + game.q
    if active.any():
        Ga = game.G[active]
        lam = np.linalg.lstsq(Ga.T, -grad, rcond=None)[0]
        stat = grad + Ga.T @ lam
        sign = float(max(0.0, -lam.min()))
        comp = float(np.max(np.abs(lam * slack[active])))
    else:
        stat, sign, comp = grad, 0.0, 0.0
    return max(float(np.max(np.abs(stat))), max(0.0, float(-slack.min())), sign, comp)


def _active_set_solve(game: CondensedLQ, active: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(z, lam) solving P z + q + G_A'lam = 0, G_A z = h_A for the rows ``active``."""
    Ga = game.G[active]
    m = Ga.shape[0]
    K = np.block([[game.P, Ga.T], [Ga, np.zeros((m, m))]])
    sol = np.linalg.lstsq(K, np.concatenate([-game.q, game.h[active]]), rcond=None)[0]
    return sol[: game.n], sol[game.n :]


def solve_vi_extragradient(game: CondensedLQ, tol: float = 1e-12, max_iter: int = 20000) -> tuple[np.ndarray, int]:
    """The variational equilibrium by Korpelevich's extragradient method, z+ = Proj(z - g F(Proj(z - g F(z)))) with
    g = 0.9 / ||P||_2 and the Euclidean projections onto {lb <= z <= ub, A z <= b} solved as QPs by DAQP. Once the
    iterates move by at most ``POLISH_FROM`` per step, the active set of the iterate is tried: the KKT system of that
    active set is solved exactly and its point accepted when it lies within 1e3 ``POLISH_FROM`` of the iterate and
    satisfies the VI's KKT conditions to ``tol``. Returns (z, iterations)."""
    eye = np.eye(game.n)

    def project(v: np.ndarray) -> np.ndarray:
        return _qp(eye, -v, game.lb, game.ub, game.A, game.b)

    step = 0.9 / np.linalg.norm(game.P, 2)
    z = project(np.zeros(game.n))
    for it in range(1, max_iter + 1):
        y = project(z - step * (game.P @ z + game.q))
        z_new = project(z - step * (game.P @ y + game.q))
        moved = float(np.max(np.abs(z_new - z)))
        z = z_new
        if moved <= POLISH_FROM:
            active = game.h - game.G @ z <= max(1e3 * moved, 1e-10)
            candidate = _active_set_solve(game, active)[0] if active.any() else np.linalg.solve(game.P, -game.q)
            close = float(np.max(np.abs(candidate - z))) <= 1e3 * POLISH_FROM
            if close and vi_kkt_residual(game, candidate) <= tol:
                return candidate, it
    raise RuntimeError(f"extragradient: no solution to {tol:g} in {max_iter} iterations")


def solve_vi_nashopt(game: CondensedLQ) -> np.ndarray:
    """The variational equilibrium by nashopt's ``GNEP_LQ(..., variational=True, solver="dr_daqp")`` (raises
    ImportError without nashopt)."""
    from nashopt import GNEP_LQ

    lq = GNEP_LQ([game.H] * 3, game.Q, game.c, lb=game.lb.copy(), ub=game.ub.copy(), A=game.A, b=game.b,
                 variational=True, solver="dr_daqp")
    return np.asarray(lq.solve().x, dtype=float)


def compute_references(horizons: tuple[int, ...] = HORIZONS, require_nashopt: bool = False) -> dict[int, np.ndarray]:
    """Recompute the variational references: the extragradient solve, checked against nashopt's dr_daqp (when
    importable, or always with ``require_nashopt``) to ``REFERENCE_AGREEMENT``, and both against the KKT conditions
    and the best-response gaps. Raises RuntimeError when a check fails."""
    try:
        import nashopt  # noqa: F401

        have_nashopt = True
    except ImportError:
        if require_nashopt:
            raise
        have_nashopt = False
    refs: dict[int, np.ndarray] = {}
    for T in horizons:
        game = condense(T)
        z, _ = solve_vi_extragradient(game)
        candidates = [("extragradient", z)]
        if have_nashopt:
            z_dr = solve_vi_nashopt(game)
            diff = float(np.max(np.abs(z_dr - z)))
            if not diff <= REFERENCE_AGREEMENT:
                raise RuntimeError(f"T = {T}: nashopt dr_daqp and extragradient differ by {diff:.2e}")
            candidates.append(("nashopt dr_daqp", z_dr))
        for label, cand in candidates:
            kkt = vi_kkt_residual(game, cand)
            gap = max(best_response_gaps(game, cand).values())
            if not (kkt <= REFERENCE_AGREEMENT and gap <= REFERENCE_AGREEMENT):
                raise RuntimeError(f"T = {T}: {label} solution has KKT residual {kkt:.2e}, largest gap {gap:.2e}")
        refs[T] = z
    return refs


# The variational equilibria, inputs in gnerun's order (u1(0..T), u2(0..T), u3(0..T)), from compute_references().
REFERENCES: dict[int, list[float]] = {
    5: [
        0.4999999999999995, 0.5000000000000027, 0.49999999999999545, 0.49999999999999767,
        0.5000000000000028, 0.4999999999999949, -0.14309251702922415, 0.49999999999999895,
        0.4999999999999971, 0.4999999999999979, 0.500000000000006, 0.49999999999999634, 0.24309251702922688,
        0.49999999999999917, 0.49999999999999734, 0.499999999999994, 0.5000000000000023, 0.49999999999999384
    ],
    20: [
        0.5000000000000024, 0.49999999999999556, 0.4999999999999992, 0.4999999999999969, 0.5000000000000004,
        0.5000000000000053, 0.49999999999999956, 0.4999999999999927, 0.5000000000000023,
        0.49999999999999367, 0.4999999999999977, 0.4999999999999971, 0.4999999999999995, 0.499999999999998,
        0.5000000000000082, 0.49999999999999156, 0.49999999999999545, 0.499999999999992, 0.5000000000000092,
        0.5000000000000003, 0.5000000000000048, -0.14276165012007702, 0.5000000000000027,
        0.5000000000000058, 0.5000000000000044, 0.4999999999999978, 0.5000000000000007, 0.5,
        0.5000000000000013, 0.499999999999992, 0.4999999999999977, 0.5000000000000036, 0.500000000000004,
        0.500000000000004, 0.49999999999999045, 0.5000000000000027, 0.4999999999999987, 0.5000000000000021,
        0.4999999999999999, 0.5000000000000029, 0.49999999999999456, 0.4999999999999958,
        0.24276165012007678, 0.4999999999999995, 0.5000000000000044, 0.5000000000000021, 0.5000000000000051,
        0.5000000000000037, 0.5000000000000029, 0.5000000000000073, 0.5000000000000072, 0.4999999999999986,
        0.4999999999999951, 0.49999999999999645, 0.5000000000000057, 0.5000000000000004, 0.5000000000000064,
        0.5000000000000049, 0.49999999999999756, 0.49999999999999933, 0.4999999999999994,
        0.4999999999999957, 0.49999999999999944
    ],
    40: [
        0.5000000000000141, 0.49999999999999645, 0.5000000000000058, 0.5000000000000129, 0.4999999999999942,
        0.5000000000000018, 0.499999999999994, 0.5000000000000009, 0.5, 0.5000000000000049,
        0.5000000000000022, 0.5000000000000033, 0.5000000000000032, 0.5000000000000023, 0.5000000000000051,
        0.4999999999999992, 0.5000000000000022, 0.5000000000000053, 0.5000000000000034, 0.5000000000000022,
        0.5000000000000009, 0.4999999999999942, 0.4999999999999969, 0.5000000000000051, 0.500000000000006,
        0.5000000000000043, 0.5000000000000018, 0.500000000000009, 0.4999999999999978, 0.4999999999999986,
        0.4999999999999982, 0.5000000000000018, 0.5000000000000044, 0.4999999999999961, 0.5000000000000007,
        0.5000000000000012, 0.4999999999999978, 0.4999999999999918, 0.4999999999999959, 0.49999999999999434,
        0.5000000000000022, -0.14276165011460584, 0.5000000000000049, 0.49999999999999506,
        0.5000000000000029, 0.49999999999999967, 0.49999999999999634, 0.4999999999999999,
        0.49999999999999734, 0.49999999999999434, 0.49999999999999767, 0.49999999999999795,
        0.500000000000003, 0.49999999999999367, 0.5000000000000036, 0.4999999999999993, 0.49999999999999784,
        0.4999999999999985, 0.49999999999999467, 0.4999999999999964, 0.500000000000002, 0.49999999999999967,
        0.4999999999999911, 0.5000000000000022, 0.49999999999999023, 0.49999999999999734,
        0.5000000000000008, 0.5000000000000011, 0.4999999999999968, 0.4999999999999989, 0.5000000000000047,
        0.49999999999999695, 0.5000000000000029, 0.5000000000000001, 0.4999999999999938,
        0.49999999999999867, 0.4999999999999965, 0.49999999999999684, 0.5000000000000002,
        0.5000000000000004, 0.5000000000000037, 0.5000000000000043, 0.24276165011458636, 0.5000000000000042,
        0.49999999999999245, 0.5000000000000008, 0.500000000000001, 0.5000000000000028, 0.5000000000000022,
        0.49999999999999906, 0.4999999999999989, 0.5000000000000053, 0.4999999999999983, 0.5000000000000049,
        0.49999999999999767, 0.5000000000000017, 0.4999999999999975, 0.49999999999999956,
        0.5000000000000042, 0.5000000000000008, 0.5000000000000003, 0.4999999999999935, 0.4999999999999981,
        0.4999999999999953, 0.500000000000001, 0.4999999999999991, 0.5000000000000006, 0.5000000000000002,
        0.5000000000000001, 0.49999999999999306, 0.5000000000000036, 0.4999999999999939, 0.500000000000004,
        0.5000000000000018, 0.49999999999999406, 0.5000000000000017, 0.4999999999999948, 0.4999999999999981,
        0.500000000000003, 0.5000000000000047, 0.4999999999999967, 0.5000000000000032, 0.499999999999999
    ],
}

REFERENCE_SOURCE = (
    "hand-condensed LQ game (benchmarks/problems/lq.py); variational equilibrium by an extragradient method with "
    "DAQP projections and an exact active-set finish, agreeing to 1e-8 with nashopt 1.3.9 GNEP_LQ(variational=True, "
    "solver='dr_daqp'); KKT residual and best-response gaps <= 1e-8 (compute_references()); equal to the closed form "
    "of the unconstrained equilibrium to 1e-12"
)


def lq_problems() -> list[Problem]:
    """The family: horizons 5, 20, 40, variational and generalized (6 problems), from u = 0, lambda = 0."""
    problems = []
    for T in HORIZONS:
        game = condense(T)
        gaps = partial(best_response_gaps, game)
        ref = np.array(REFERENCES[T])
        binding = int(np.sum(game.b - game.A @ ref <= FEAS_TOL))
        active = f"{int(np.sum(game.h - game.G @ ref <= FEAS_TOL))} of {game.G.shape[0]} constraint rows active"
        for eq in EQUILIBRIA:
            variational = eq == "variational"
            if variational:
                notes = f"unique variational equilibrium (strongly monotone pseudo-gradient); {active}"
            elif binding:
                notes = (f"each agent carries x1 + x2 + x3 <= {SHARED_RHS:g} with its own multiplier; it binds at "
                         f"{binding} stages of the variational equilibrium: a continuum of equilibria, no reference")
            else:
                notes = (f"each agent carries x1 + x2 + x3 <= {SHARED_RHS:g} with its own multiplier; it binds at no "
                         "stage of the variational equilibrium, which is then also the generalized one (isolated); "
                         "checked by best-response gaps only")
            problems.append(
                Problem(
                    family="lq",
                    name=f"LQ T={T} {eq}",
                    start="u = 0, lambda = 0",
                    config_yaml=lq_yaml(T, eq),
                    reference=ref if variational else None,
                    reference_tol=1e-6,
                    reference_source=REFERENCE_SOURCE if variational else "",
                    best_response_gaps=gaps,
                    notes=notes,
                )
            )
    return problems


def references_literal(refs: dict[int, np.ndarray]) -> str:
    """``refs`` as the Python literal of :data:`REFERENCES` (shortest round-trip floats, lines within 120)."""
    import textwrap

    lines = ["REFERENCES: dict[int, list[float]] = {"]
    for T, z in refs.items():
        body = ", ".join(repr(float(v)) for v in z)
        lines += [f"    {T}: ["] + textwrap.wrap(body, 108, initial_indent=" " * 8, subsequent_indent=" " * 8)
        lines.append("    ],")
    return "\n".join([*lines, "}"])


def _main() -> int:
    """Recompute the references, print them as a literal and their distance to the stored ones."""
    refs = compute_references()
    print(references_literal(refs))
    for T, z in refs.items():
        stored = REFERENCES.get(T)
        diff = float(np.max(np.abs(np.array(stored) - z))) if stored is not None else math.inf
        print(f"T = {T}: max |recomputed - stored| = {diff:.2e}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(_main())
