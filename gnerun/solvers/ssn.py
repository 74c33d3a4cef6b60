"""Semismooth Newton on the KKT system of a GNE problem [semi_newton], step by step.

Phi(z) = [L(z); phi(-g(a), lambda); h(a)] [system_equations] with the complementarity function
phi either the min function (the paper's choice, default) or Fischer-Burmeister
phi(a, b) = a + b - sqrt(a^2 + b^2). One step solves Phi(z^k) + JPhi(z^k)(z - z^k) = r^k with
JPhi(z^k) an element of the limiting Jacobian [eq:inexact_seminewton].

Jacobian element at ties (documented choice). A min-map row min(-g_j, lambda_j) is differentiable
unless -g_j == lambda_j. We treat |-g_j - lambda_j| <= ``tie_tol`` as a tie and take the
*multiplier row* e_{lambda_j} (the constraint is treated as inactive for this step). At the
degenerate pair -g_j = lambda_j = 0 both rows belong to the limiting Jacobian; the g-row can be
nearly singular there (condition ~1e17 on the paper's own Study 1 after one step) while the
multiplier row is well conditioned, and an exact comparison would pick either one depending on
rounding. For Fischer-Burmeister the only nondifferentiable point is (0, 0), where we take the
element (1 - 1/sqrt 2, 1 - 1/sqrt 2).

Perturbations (paper Study 1b and eq. inexact_seminewton), seeded: ``jacobian_noise`` adds i.i.d.
noise of the given scale to every element of JPhi(z^k); ``residual`` uses a right-hand side r^k of
norm ``scale`` in a random direction.

Constraint rows that depend on no decision variable (a condition on the plant state alone, e.g. a
position one step after an input that drives its acceleration) are not Newton rows: their multipliers are
held at zero, and a violated one ends the solve as ``infeasible_stage_constraint``.

This class is the paper's local method (``solver.globalization: none``); the globalizations of
:mod:`gnerun.solvers.globalization` wrap it: Armijo backtracking along its direction (``line_search``), and the
default, globalized method (:mod:`gnerun.solvers.hybrid`), which takes these steps where they work and an
interior-point phase elsewhere.

Shape (see STYLE.md): ``init(z0, x) -> state``, ``step(state) -> state`` (exactly one iteration,
nothing else), ``terminate(state) -> (done, status)``. Failure is a status, never an exception:
a singular or ill-conditioned JPhi (the step is not taken), a non-finite Phi, divergence.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy.linalg import lapack

from ..game.compile import CompiledGame, KKTParts
from ..language.config import DisturbanceConfig, SolverConfig
from .linalg import factor, levenberg_marquardt, noise, norm
from .lq_path import LQPath
from .reduced import active_rows, assemble, reduced_matrix
from .status import FAILURES, SSNState, Status

__all__ = ["FAILURES", "SSNState", "SemismoothNewton", "Status", "describe_row", "levenberg_marquardt"]

_FB_TIE = 1.0 - 1.0 / math.sqrt(2.0)
class SemismoothNewton:
    """The semismooth Newton method for a compiled game (see the module docstring)."""

    condensed = True  # steps through the condensed KKT system (see gnerun.game.sparse for the other formulation)

    def __init__(self, game: CompiledGame, solver: SolverConfig, disturbance: DisturbanceConfig | None = None):
        self.game = game
        self.options = solver
        self.disturbance = disturbance or DisturbanceConfig()
        self._eq = game.equality_mask
        self._ineq = ~self._eq
        self._fb = solver.complementarity == "fischer_burmeister"
        d = self.disturbance
        # The min map's multiplier rows say lambda_j^+ = 0: solve only for a and the g-branch multipliers
        # (same step, smaller system). Noise on all of JPhi or on the right-hand side needs the full system.
        self.reduced = not self._fb and not (d.kind in ("jacobian_noise", "residual") and d.scale > 0)
        self._eq_rows = np.flatnonzero(self._eq)
        # rows no decision reaches: multipliers held at zero, never g-branch rows (checked at init)
        self._fixed = game.zero_gradient_rows
        self._fixed_rows = np.flatnonzero(self._fixed)
        self._z_start = game.z_start()
        self._noisy = self.disturbance.kind in ("jacobian_noise", "residual")
        # LQ games: a step from what is kept per active set (gnerun.solvers.lq_path)
        self._lq = self.condensed and self.reduced and game.affine
        self._lq_inline = self._lq and not self._eq_rows.size and not self._fixed_rows.size
        self._tie_tol = solver.tie_tol
        self.lq = LQPath(game, self._eq, solver.min_rcond) if self._lq else None

    # ------------------------------------------------------------------------------------
    def residual(self, parts: KKTParts, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Phi(z) [system_equations] and the g-branch rows (for the Jacobian element)."""
        return self.phi(parts.L, parts.c, z)

    def phi(self, L: np.ndarray, c: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Phi(z) from L(z) and c(a), and the g-branch rows."""
        n = self.game.n
        lam = z[n:]
        a = -c
        tol = self.options.tie_tol
        phi = np.empty(n + a.size)
        phi[:n] = L
        if self._fb:
            r = np.hypot(a, lam)
            phi[n:] = a + lam - r
            active = a < lam
        else:
            np.minimum(a, lam, out=phi[n:])
            active = a < lam - tol
        if self._eq_rows.size:
            phi[n + self._eq_rows] = c[self._eq_rows]
            active &= self._ineq
        if self._fixed_rows.size:  # held at lambda = 0 and checked at init: not part of Phi
            phi[n + self._fixed_rows] = 0.0
            active &= ~self._fixed
        return phi, active

    def evaluate(self, z: np.ndarray, x: np.ndarray) -> tuple[KKTParts, np.ndarray, np.ndarray]:
        """The parts, Phi and the g-branch rows at z; for LQ games with the min map, in a few products."""
        if not (self._lq and self._eq_rows.size == 0 and self._fixed_rows.size == 0):
            parts = self.game.kkt_parts(z, x)
            return parts, *self.residual(parts, z)
        n = self.game.n
        v = self.lq.W @ z
        v += self.game.offsets(x)
        phi = v.copy()
        a = np.negative(v[n:], out=phi[n:])  # -c, in place in Phi's buffer
        lam = z[n:]
        active = a < lam - self._tie_tol
        np.minimum(a, lam, out=a)
        return KKTParts(v[:n], v[n:], self.lq.dL, self.lq.dc), phi, active

    def kkt_residual(self, z: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """L(z) and c(a) alone, without derivatives (what a line search evaluates)."""
        return self.game.kkt_residual(z, x)

    def jacobian(self, parts: KKTParts, z: np.ndarray, active: np.ndarray) -> np.ndarray:
        """An element JPhi(z) of the limiting Jacobian of Phi (tie rule in the module docstring)."""
        n, m = self.game.n, self.game.m
        J = np.zeros((n + m, n + m))
        J[:n] = parts.dL_dz
        if m == 0:
            return J
        rows = np.arange(m)
        if self._fb:
            a = -parts.c
            lam = z[n:]
            r = np.hypot(a, lam)
            smooth = r > self.options.tie_tol
            with np.errstate(invalid="ignore", divide="ignore"):
                da = np.where(smooth, 1.0 - a / np.where(smooth, r, 1.0), _FB_TIE)
                db = np.where(smooth, 1.0 - lam / np.where(smooth, r, 1.0), _FB_TIE)
            ineq = self._ineq & ~self._fixed
            J[n:][ineq, :n] = -da[ineq, None] * parts.dc_da[ineq]
            J[n + rows[ineq], n + rows[ineq]] = db[ineq]
        else:
            J[n:][active, :n] = -parts.dc_da[active]
            mult = self._ineq & ~active
            J[n + rows[mult], n + rows[mult]] = 1.0
        J[n:][self._eq, :n] = parts.dc_da[self._eq]
        if self._fixed_rows.size:  # lambda_j = 0 for rows no decision reaches
            J[n + self._fixed_rows] = 0.0
            J[n + self._fixed_rows, n + self._fixed_rows] = 1.0
        return J

    # ------------------------------------------------------------------------------------
    def init(self, z0: np.ndarray | None = None, x: np.ndarray | None = None,
             rng: np.random.Generator | None = None) -> SSNState:
        """State at z0 (default: the config's start values, multipliers zero) and plant state x."""
        game = self.game
        if z0 is None:
            z = self._z_start.copy()
        elif type(z0) is np.ndarray and z0.dtype == np.float64 and z0.ndim == 1:
            z = z0.copy()
        else:
            z = np.array(z0, dtype=float).reshape(-1)
        if z.size != game.size:
            raise ValueError(f"z0 has {z.size} entries; the KKT system has {game.size} unknowns")
        xv = game.x0 if x is None else game._x(x)
        if rng is None and self._noisy:
            rng = np.random.default_rng(self.disturbance.seed)
        if self._fixed_rows.size:
            z[game.n + self._fixed_rows] = 0.0
        parts, phi, active = self.evaluate(z, xv)
        state = SSNState(z=z, x=xv, k=0, phi=phi, residual_norm=norm(phi), parts=parts, active=active, z_prev=None,
                         active_prev=None, status=Status.RUNNING, message="", rng=rng)
        return self._check_stage_rows(self._check_finite(state))

    def _check_stage_rows(self, state: SSNState) -> SSNState:
        """A row that no decision reaches must hold at the plant state as it is; otherwise nothing can be done."""
        if not self._fixed_rows.size or state.status != Status.RUNNING:
            return state
        c = state.parts.c[self._fixed_rows]
        tol = max(self.options.tol, 1e-9)
        bad = np.where(self._eq[self._fixed_rows], np.abs(c) > tol, c > tol)
        if not bad.any():
            return state
        rows = self._fixed_rows[bad]
        labels = "; ".join(f"{describe_row(self.game, self.game.n + r)} (violated by {c[bad][i]:.3g})"
                           for i, r in enumerate(rows[:3]))
        more = f" and {rows.size - 3} more" if rows.size > 3 else ""
        return replace(state, status=Status.INFEASIBLE_STAGE_CONSTRAINT,
                       message=f"{rows.size} constraint row(s) that no decision variable can change are violated at "
                               f"this state: {labels}{more}")

    def step(self, state: SSNState) -> SSNState:
        """Exactly one (perturbed) semismooth Newton iteration; a failed or converged state is returned unchanged
        (a step at a solution keeps it: :meth:`iteration` steps on from there, as polishing does)."""
        if state.status in FAILURES or self.at_solution(state):
            return state
        return self.iteration(state)

    def at_solution(self, state: SSNState) -> bool:
        """||Phi(z^k)|| <= tol: where ``step`` stops (the test of :meth:`terminate`)."""
        return state.residual_norm <= self.options.tol

    def iteration(self, state: SSNState) -> SSNState:
        """One semismooth Newton iteration from ``state``, also at a solution (a failed state is returned
        unchanged)."""
        if state.status in FAILURES:
            return state
        if self._lq_inline:
            return self._lq_step(state)
        z_new, rcond = self.newton_point(state)
        if z_new is None:
            return self.singular(state, rcond)
        return self.advance(state, z_new, rcond=rcond)

    def newton_point(self, state: SSNState) -> tuple[np.ndarray | None, float]:
        """The end point z^k + dz of the (perturbed) Newton step from ``state``, and the reciprocal condition
        number of the matrix factorised; ``None`` for the point when that matrix is singular or ill-conditioned."""
        if self.reduced:
            return self._reduced_point(state)
        J = self.jacobian(state.parts, state.z, state.active)
        rhs = -state.phi
        d = self.disturbance
        if d.kind == "jacobian_noise" and d.scale > 0:
            J = J + d.scale * noise(state.rng, J.shape, d.distribution)
        elif d.kind == "residual" and d.scale > 0:
            w = noise(state.rng, rhs.shape, d.distribution)
            rhs = rhs + d.scale * w / max(norm(w), 1e-300)
        lu, piv, info, rcond = factor(J)
        if info != 0 or not rcond >= self.options.min_rcond:
            return None, rcond
        dz, info = lapack.dgetrs(lu, piv, rhs)
        return state.z + dz, float(rcond)

    def regularized_point(self, state: SSNState, mu: float) -> np.ndarray | None:
        """The end point of a Levenberg-Marquardt step: dz minimises ||JPhi dz + Phi||^2 + mu ||dz||^2, on the
        reduced system for the min map (the inactive multipliers still go to zero). Where JPhi is singular, as on
        a continuum of solutions, this step exists and, with mu ~ ||Phi||, converges to a point of the set (under
        an error bound). Unperturbed; ``None`` if even the regularised system cannot be solved."""
        game, parts, z = self.game, state.parts, state.z
        n = game.n
        if self._lq and self.lq.dual is not None:
            return self.lq.regularized(state.active, z, state.x, mu)
        if self.reduced:
            A = self.active_rows(state.active)
            M = reduced_matrix(parts.dL_dz, parts.dc_da, A)
            lam = z[n:]
            rhs = np.concatenate([parts.dL_dz[:, n:] @ lam - parts.L, -parts.c[A]])
            y0 = np.concatenate([np.zeros(n), lam[A]])
            r = rhs - M @ y0
            dy = levenberg_marquardt(M, r, mu)
            if dy is None:
                return None
            return assemble(z.size, z[:n] + dy[:n], A, lam[A] + dy[n:])
        dz = levenberg_marquardt(self.jacobian(parts, z, state.active), -state.phi, mu)
        return None if dz is None else z + dz

    def singular(self, state: SSNState, rcond: float) -> SSNState:
        """``state`` ended as singular_jacobian (the step was not taken), with the reason."""
        opts = self.options
        msg = (f"JPhi(z^{state.k}) is singular or ill-conditioned (reciprocal condition number "
               f"{rcond:.1e} < min_rcond {opts.min_rcond:.0e}); the step was not taken")
        if self.game.shares_constraints_generalized:
            msg += ("; this plain GNE has constraints shared by several agents, each with its own "
                    "multiplier: such games have a continuum of equilibria with a singular JPhi there "
                    "(the default solver.globalization: hybrid returns one of them)")
        else:
            msg += ("; the local method may have left its region of convergence (the default "
                    "solver.globalization: hybrid continues from such points)")
        return replace(state, status=Status.SINGULAR_JACOBIAN, message=msg, rcond=float(rcond))

    def _reduced_point(self, state: SSNState) -> tuple[np.ndarray | None, float]:
        """The min-map Newton step through the reduced system. With A the g-branch rows (and equalities),
        the multiplier rows give lambda_I^+ = 0 and the rest is

            [ dL/da     dL/dlambda_A ] [ da          ]   [ -L(z) + dL/dlambda lambda ]
            [ dc_A/da   0            ] [ lambda_A^+  ] = [ -c_A(a)                   ]

        (a row -dc_j/da da = c_j of JPhi, negated). Its reciprocal condition number is the one checked.
        """
        game, opts = self.game, self.options
        n = game.n
        parts, z = state.parts, state.z
        if self._lq:
            return self.lq.point(state.active, state.x)
        A = self.active_rows(state.active)
        lu, piv, info, rcond = factor(reduced_matrix(parts.dL_dz, parts.dc_da, A))
        if info != 0 or not rcond >= opts.min_rcond:
            return None, rcond
        lam = z[n:]
        rhs = np.concatenate([parts.dL_dz[:, n:] @ lam - parts.L, -parts.c[A]])
        sol, _ = lapack.dgetrs(lu, piv, rhs)
        return assemble(z.size, z[:n] + sol[:n], A, sol[n:]), float(rcond)

    def _lq_step(self, state: SSNState) -> SSNState:
        """:meth:`_reduced_point` then :meth:`advance` for an LQ game without equalities or line search, in one
        function: the same operations (z^+ from the kept factors of the active set, then
        Phi(z^+) = [L; min(-c, lambda)] with [L; c] = W z^+ + w0), without the calls between them."""
        x = state.x
        z, rcond = self.lq.point(state.active, x)
        if z is None:
            return self.singular(state, rcond)
        w0 = self.game.offsets(x)
        n = self.game.n
        v = self.lq.W @ z
        v += w0
        phi = v.copy()
        a = np.negative(v[n:], out=phi[n:])
        lam = z[n:]
        active = a < lam - self._tie_tol
        np.minimum(a, lam, out=a)
        new = SSNState(z=z, x=x, k=state.k + 1, phi=phi, residual_norm=math.sqrt(phi @ phi),
                       parts=KKTParts(v[:n], v[n:], self.lq.dL, self.lq.dc), active=active, z_prev=state.z,
                       active_prev=state.active, status=Status.RUNNING, message="", rng=state.rng, rcond=rcond)
        limit = self.options.divergence_limit
        if not math.isfinite(new.residual_norm) or z @ z > limit * limit:  # rare: the general checks decide
            return self.checked(new)
        return new

    def active_rows(self, active: np.ndarray) -> np.ndarray:
        """The rows A of the reduced system at a state whose g-branch rows are ``active`` (and the equalities)."""
        return active_rows(active, self._eq, bool(self._eq_rows.size))

    def advance(self, state: SSNState, z: np.ndarray, *, rcond: float = math.nan) -> SSNState:
        """The iterate after ``state``: z evaluated once (Phi, the parts for the next step), checked for
        NaN and divergence. Every method's step ends here."""
        parts, phi, active = self.evaluate(z, state.x)
        new = SSNState(z=z, x=state.x, k=state.k + 1, phi=phi, residual_norm=norm(phi), parts=parts, active=active,
                       z_prev=state.z, active_prev=state.active, status=Status.RUNNING, message="", rng=state.rng,
                       rcond=rcond)
        return self.checked(new)

    def checked(self, new: SSNState) -> SSNState:
        """``new`` with the NaN and divergence checks applied."""
        z = new.z
        new = self._check_finite(new)
        limit = self.options.divergence_limit
        if new.status == Status.RUNNING and z @ z > limit * limit and np.abs(z).max() > limit:
            new = replace(new, status=Status.DIVERGED,
                          message=f"diverged at iteration {new.k}: ||z||_inf = {np.max(np.abs(z)):.2e} exceeds "
                                  f"divergence_limit {limit:.0e}")
        return new

    def terminate(self, state: SSNState) -> tuple[bool, Status]:
        if state.status in FAILURES:
            return True, state.status
        if state.residual_norm <= self.options.tol:
            return True, Status.CONVERGED
        if state.k >= self.options.max_iter:
            return True, Status.MAX_ITER
        return False, Status.RUNNING

    def finish(self, state: SSNState) -> SSNState:
        """The state with its final status and a human message (call when terminate says done)."""
        done, status = self.terminate(state)
        if not done:
            return state
        if status == Status.CONVERGED:
            msg = (f"converged in {state.k} iteration{'s' if state.k != 1 else ''}: ||Phi|| = "
                   f"{state.residual_norm:.2e} <= tol {self.options.tol:.0e}")
        elif status == Status.MAX_ITER:
            n = self.options.max_iter
            msg = (f"stopped after max_iter = {n} iteration{'s' if n != 1 else ''} without convergence: "
                   f"||Phi|| = {state.residual_norm:.2e} > tol {self.options.tol:.0e}")
        else:
            msg = state.message
        return replace(state, status=status, message=msg)

    # ------------------------------------------------------------------------------------
    def _check_finite(self, state: SSNState) -> SSNState:
        if math.isfinite(state.residual_norm):  # a NaN or an infinity anywhere shows in the norm
            return state
        bad = ~np.isfinite(state.phi)
        if not bad.any():
            return state
        row = int(np.flatnonzero(bad)[0])
        return replace(state, status=Status.NAN,
                       message=f"Phi(z^{state.k}) is not finite (first at {describe_row(self.game, row)}): an "
                               "expression is undefined or overflows there (e.g. log or sqrt of a negative number)")


def describe_row(game: CompiledGame, row: int) -> str:
    """Human name of row ``row`` of Phi."""
    n = game.n
    if row < n:
        for name, sl, vars_ in zip(game.agent_names, game.agent_slices, game.variable_names, strict=True):
            if sl.start <= row < sl.stop:
                j = row - sl.start
                var = vars_[j % len(vars_)]
                stage = "" if game.kind == "static" else f" [tau={j // len(vars_)}]"
                return f"the stationarity of {name} in {var}{stage}"
    info = game.constraints[row - n]
    owner = "shared" if info.owner is None else game.agent_names[info.owner]
    return f"the constraint of {owner}: {info.label}"


_factor, _norm, _noise = factor, norm, noise  # the names of earlier versions
