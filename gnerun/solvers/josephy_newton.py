"""The Josephy-Newton method for Nash equilibrium problems [eq:JN], and its perturbed version [eq:JN_pertu].

An NE problem has independent constraint sets: every agent's constraints involve only its own
decisions. Its equilibria solve VI(A, F) with the pseudogradient F (Theorem "Equivalence_VI"); one
Josephy-Newton step solves the affine VI

    F(a^k) + H(a^k)(a - a^k) + N_A(a) ∋ 0

exactly, H the game Hessian. For polyhedral A = {a : G a <= h, E a = e} this is a mixed linear
complementarity problem, solved here by Lemke's method (:mod:`gnerun.lcp`). With
``equilibrium: variational`` and shared constraints, A is the joint feasible set and the step computes
the variational GNE (one common multiplier per shared constraint, paper §III-A).

The multipliers of the affine VI are kept, so an iterate is z = (a, lambda) as for semismooth
Newton, and convergence is measured by the same ||Phi(z)||. ``disturbance.kind: pseudogradient``
adds seeded i.i.d. noise of the given scale to every element of F(a^k) and H(a^k) [eq:JN_pertu].
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..errors import InputError
from ..game.compile import CompiledGame
from ..language.config import DisturbanceConfig, SolverConfig
from .kkt import KKTSystem
from .lcp import lemke
from .linalg import noise
from .status import FAILURES, SSNState, Status


def check_nash_problem(game: CompiledGame) -> None:
    """Refuse games that Josephy-Newton cannot solve, with the reason."""
    if game.shares_constraints_generalized:
        raise InputError("solver.kind 'jn' needs independent constraint sets; this game's shared constraints are "
                         "carried by each agent with its own multiplier (a GNE): use solver.kind 'ssn', or "
                         "equilibrium: variational for the variational equilibrium")
    coupled = game.pattern.coupled_rows()
    if coupled:
        labels = ", ".join(f"{game.agent_names[game.constraints[r].owner]}: {game.constraints[r].label}"
                           for r in coupled[:3])
        raise InputError(f"solver.kind 'jn' needs independent constraint sets, but {len(coupled)} constraint(s) "
                         f"involve other agents' decisions ({labels}{', ...' if len(coupled) > 3 else ''}): this is "
                         "a generalized Nash problem, use solver.kind 'ssn'")
    if not game.lq.linear_rows.all():
        bad = [game.constraints[r].label for r in np.flatnonzero(~game.lq.linear_rows)[:3]]
        raise InputError(f"solver.kind 'jn' solves each step as a linear complementarity problem and needs "
                         f"polyhedral (affine) constraints; nonlinear: {', '.join(bad)}: use solver.kind 'ssn'")


def solve_affine_vi(M: np.ndarray, q: np.ndarray, G: np.ndarray, h: np.ndarray, equality: np.ndarray,
                    tol: float = 1e-12, B: np.ndarray | None = None, d: np.ndarray | None = None):
    """Solve the affine VI: M a + q + G^T lam = 0, 0 <= lam_j ⊥ h_j - G_j a >= 0 (lam_j free, G_j a = h_j
    for equality rows), as one LCP. With ``B``, the stationarity is M a + q + B lam = 0 instead: the affine
    KKT system of a generalized Nash game, where the multiplier of an agent's row enters that agent's
    stationarity only (B is dL/dlambda).

    Variables with a lower bound (a row with a single negative coefficient, whose multiplier enters the
    stationarity as G_j^T) are shifted, a = l + y with y >= 0, and that row's multiplier is read off the
    stationarity slack; the other variables are split, a = p - m. Equality rows become two inequalities.
    ``d`` is Lemke's covering vector (repeated to the LCP's size; None: all ones). Returns (a, lam, LCPResult).
    """
    n = q.size
    m = h.size
    B = G.T if B is None else B
    lower = np.full(n, -np.inf)
    lower_row = np.full(n, -1)
    for j in np.flatnonzero(~equality):
        nz = np.flatnonzero(G[j])
        if nz.size == 1 and G[j, nz[0]] < 0 and np.array_equal(B[:, j], G[j]):
            i = nz[0]
            bound = h[j] / G[j, i]
            if bound > lower[i]:
                lower[i], lower_row[i] = bound, j
    shifted = np.isfinite(lower)
    free = ~shifted
    a0 = np.where(shifted, lower, 0.0)
    # a = a0 + D u with u = (y, p, m) >= 0
    S, F = np.flatnonzero(shifted), np.flatnonzero(free)
    D = np.zeros((n, S.size + 2 * F.size))
    D[S, np.arange(S.size)] = 1.0
    D[F, S.size + np.arange(F.size)] = 1.0
    D[F, S.size + F.size + np.arange(F.size)] = -1.0
    used = set(lower_row[shifted].tolist())
    general = [j for j in range(m) if j not in used and not equality[j]]
    eq_rows = np.flatnonzero(equality)
    Gr = np.vstack([G[general], G[eq_rows], -G[eq_rows]]) if m else np.zeros((0, n))
    Br = np.hstack([B[:, general], B[:, eq_rows], -B[:, eq_rows]]) if m else np.zeros((n, 0))
    hr = np.concatenate([h[general], h[eq_rows], -h[eq_rows]]) if m else np.zeros(0)
    nu, nr = D.shape[1], Gr.shape[0]
    lcp_M = np.zeros((nu + nr, nu + nr))
    lcp_M[:nu, :nu] = D.T @ M @ D
    lcp_M[:nu, nu:] = D.T @ Br
    lcp_M[nu:, :nu] = -Gr @ D
    lcp_q = np.concatenate([D.T @ (M @ a0 + q), hr - Gr @ a0])
    result = lemke(lcp_M, lcp_q, None if d is None else np.resize(d, lcp_q.size), tol=tol)
    u, mu = result.z[:nu], result.z[nu:]
    a = a0 + D @ u
    lam = np.zeros(m)
    ng, ne = len(general), eq_rows.size
    lam[general] = mu[:ng]
    lam[eq_rows] = mu[ng : ng + ne] - mu[ng + ne :]
    r = M @ a + q + Br @ mu
    for i in S:
        j = lower_row[i]
        lam[j] = max(r[i], 0.0) / -G[j, i]
    return a, lam, result


def kkt_lcp_point(parts, z: np.ndarray, equality: np.ndarray, d: np.ndarray | None = None,
                  tol: float = 1e-12) -> np.ndarray | None:
    """The solution of the KKT system linearised at z, L + dL/da (a' - a) + dL/dlambda (lambda' - lambda) = 0,
    0 <= lambda'_j ⊥ -(c_j + dc_j/da (a' - a)) >= 0 (equality rows: = 0), by Lemke's method with covering
    vector ``d`` (None: all ones); None when Lemke's method ends on a ray. For an LQ game this is the KKT system
    itself, so the point solves the game: a pivoting method, which finds a point of a continuum of generalized
    equilibria that the central path of an interior-point method does not lead to."""
    n = z.size - parts.c.size
    A, B, C = parts.dL_dz[:, :n], parts.dL_dz[:, n:], parts.dc_da
    a, lam = z[:n], z[n:]
    q = parts.L - A @ a - B @ lam
    h = C @ a - parts.c
    a_new, lam_new, result = solve_affine_vi(A, q, C, h, equality, tol=tol, B=B, d=d)
    if not result.solved:
        return None
    return np.concatenate([a_new, lam_new])


class JosephyNewton:
    """Josephy-Newton steps [eq:JN]. Phi, the iterate states and their end (``init``, ``terminate``, ``finish``) are a
    :class:`~gnerun.solvers.kkt.KKTSystem`'s, so iterates are measured by the same ||Phi|| as SSN's."""

    def __init__(self, game: CompiledGame, solver: SolverConfig, disturbance: DisturbanceConfig | None = None):
        check_nash_problem(game)
        self.kkt = KKTSystem(game, solver, disturbance)
        self.game = game
        self.options = solver
        self.disturbance = self.kkt.disturbance

    def init(self, z0: np.ndarray | None = None, x: np.ndarray | None = None,
             rng: np.random.Generator | None = None, warm: bool = False) -> SSNState:
        if rng is None and self.disturbance.kind == "pseudogradient":
            rng = np.random.default_rng(self.disturbance.seed)
        return self.kkt.init(z0, x, rng)

    def terminate(self, state: SSNState) -> tuple[bool, Status]:
        return self.kkt.terminate(state)

    def finish(self, state: SSNState) -> SSNState:
        return self.kkt.finish(state)

    def at_solution(self, state: SSNState) -> bool:
        return self.kkt.at_solution(state)

    def step(self, state: SSNState) -> SSNState:
        """One (perturbed) Josephy-Newton step: the affine VI at a^k, solved exactly by Lemke's method; a failed or
        converged state is returned unchanged (:meth:`iteration` steps on from a solution)."""
        if state.status in FAILURES or self.kkt.at_solution(state):
            return state
        return self.iteration(state)

    def iteration(self, state: SSNState) -> SSNState:
        """One Josephy-Newton step from ``state``, also at a solution."""
        if state.status in FAILURES:
            return state
        game = self.game
        n = game.n
        a = state.z[:n]
        F, H = game.pseudogradient(a, state.x)
        d = self.disturbance
        if d.kind == "pseudogradient" and d.scale > 0:
            F = F + d.scale * noise(state.rng, F.shape, d.distribution)
            H = H + d.scale * noise(state.rng, H.shape, d.distribution)
        if not (np.all(np.isfinite(F)) and np.all(np.isfinite(H))):
            return replace(state, status=Status.NAN, message=f"F or H is not finite at a^{state.k}")
        G = state.parts.dc_da
        h = G @ a - state.parts.c  # c is affine: c(a') = c(a) + G (a' - a)
        # the affine VI in the variable a: H a + (F - H a^k) + G^T lam = 0, complementarity with h - G a
        a_new, lam_new, sub = solve_affine_vi(H, F - H @ a, G, h, game.equality_mask, tol=1e-12)
        if not sub.solved:
            return replace(state, status=Status.SUBPROBLEM_FAILED,
                           message=f"the Josephy-Newton subproblem at a^{state.k} has no solution found by Lemke's "
                                   f"method: {sub.message}; the step was not taken")
        return self.kkt.advance(state, np.concatenate([a_new, lam_new]))
