"""The KKT system of a GNE problem as the semismooth reformulation Phi(z) = 0, and its iterates [system_equations].

Phi(z) = [L(z); phi(-g(a), lambda); h(a)] with the complementarity function phi either the min function (the
paper's choice, default) or Fischer-Burmeister phi(a, b) = a + b - sqrt(a^2 + b^2). :class:`KKTSystem` evaluates Phi
and an element JPhi of its limiting Jacobian, makes the iterate states (``init``, ``advance``: z evaluated once,
checked for NaN and divergence) and ends them (``terminate``, ``finish``): what every Newton-type method of
:mod:`gnerun.solvers` shares, whatever its step (semismooth Newton, Josephy-Newton, proximal responses).

Jacobian element at ties (documented choice). A min-map row min(-g_j, lambda_j) is differentiable
unless -g_j == lambda_j. We treat |-g_j - lambda_j| <= ``tie_tol`` as a tie and take the
*multiplier row* e_{lambda_j} (the constraint is treated as inactive for this step). At the
degenerate pair -g_j = lambda_j = 0 both rows belong to the limiting Jacobian; the g-row can be
nearly singular there (condition ~1e17 on the paper's own Study 1 after one step) while the
multiplier row is well conditioned, and an exact comparison would pick either one depending on
rounding. For Fischer-Burmeister the only nondifferentiable point is (0, 0), where we take the
element (1 - 1/sqrt 2, 1 - 1/sqrt 2).

Constraint rows that depend on no decision variable (a condition on the plant state alone, e.g. a
position one step after an input that drives its acceleration) are not Newton rows: their multipliers are
held at zero, and a violated one ends the solve as ``infeasible_stage_constraint``.
"""

from __future__ import annotations

import copy
import math
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from ..game.compile import CompiledGame, KKTParts
from ..language.config import DisturbanceConfig, SolverConfig
from .linalg import norm
from .status import FAILURES, SSNState, Status

if TYPE_CHECKING:
    from .hybrid import Memory

_FB_TIE = 1.0 - 1.0 / math.sqrt(2.0)


class KKTSystem:
    """Phi, JPhi and the iterate states of a compiled game (see the module docstring)."""

    condensed = True  # the condensed KKT system (gnerun.solvers.sparse_ssn evaluates the sparse one)

    def __init__(self, game: CompiledGame, solver: SolverConfig, disturbance: DisturbanceConfig | None = None):
        self.game = game
        self.options = solver
        self.disturbance = disturbance or DisturbanceConfig()
        self._eq = game.equality_mask
        self._ineq = ~self._eq
        self._fb = solver.complementarity == "fischer_burmeister"
        self._eq_rows = np.flatnonzero(self._eq)
        # rows no decision reaches: multipliers held at zero, never g-branch rows (checked at init)
        self._fixed = game.pattern.zero_gradient_rows
        self._fixed_rows = np.flatnonzero(self._fixed)
        self._stage_rows = self._fixed_rows  # of those, the rows that must hold at the plant state (all of them)
        self._z_start = game.z_start()
        d = self.disturbance
        self._noisy = d.kind in ("jacobian_noise", "residual")
        self._tie_tol = solver.tie_tol
        # LQ games with the min map (no noise on JPhi or the right-hand side), no equality and no fixed rows:
        # [L; c] = W z + w0(x) in one product, Phi from it in place
        self._affine = (self.condensed and not self._fb and not (self._noisy and d.scale > 0) and game.affine
                        and not self._eq_rows.size and not self._fixed_rows.size)
        if self._affine:
            cache = game.lq.cache
            self._W, self._dL, self._dc = cache["W"], cache["dL"], cache["dc"]

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
        if not self._affine:
            parts = self.game.kkt_parts(z, x)
            return parts, *self.residual(parts, z)
        n = self.game.n
        v = self._W.dot(z)
        v += self.game.lq.offsets(x)
        phi = v.copy()
        a = np.negative(v[n:], out=phi[n:])  # -c, in place in Phi's buffer
        lam = z[n:]
        active = a < lam - self._tie_tol
        np.minimum(a, lam, out=a)
        return KKTParts(v[:n], v[n:], self._dL, self._dc), phi, active

    def evaluate_next(self, state: SSNState, z: np.ndarray) -> tuple[KKTParts, np.ndarray, np.ndarray]:
        """:meth:`evaluate` at the iterate after ``state`` (:meth:`advance`'s evaluation)."""
        return self.evaluate(z, state.x)

    def kkt_residual(self, z: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """L(z) and c(a) alone, without derivatives (what a line search evaluates)."""
        return self.game.kkt_residual(z, x)

    def constraint_values(self, z: np.ndarray, x: np.ndarray) -> np.ndarray:
        """c(a) alone (what the interior phase's slack reset reads): :meth:`kkt_residual`'s c."""
        return self.kkt_residual(z, x)[1]

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
             rng: np.random.Generator | None = None, warm: bool = False) -> SSNState:
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
        xv = game._x(x)
        if rng is None and self._noisy:
            rng = np.random.default_rng(self.disturbance.seed)
        if self._fixed_rows.size:
            z[game.n + self._fixed_rows] = 0.0
        parts, phi, active = self.evaluate(z, xv)
        state = SSNState(z=z, x=xv, k=0, phi=phi, residual_norm=norm(phi), parts=parts, active=active, z_prev=None,
                         active_prev=None, status=Status.RUNNING, message="", rng=rng)
        return self._check_stage_rows(self._check_finite(state))

    def without_rows(self, rows: np.ndarray) -> KKTSystem:
        """This method on the game with the constraint rows ``rows`` (a mask) left out: their multipliers held at zero
        and their complementarity not part of Phi, as the rows no decision reaches are (but not checked at init). A
        shallow copy: what it keeps per game (the sparse system, its layouts per set of rows) is shared."""
        other = copy.copy(self)
        other._fixed = self._fixed | rows
        other._fixed_rows = np.flatnonzero(other._fixed)
        other._affine = False
        for name in ("_lq", "_lq_inline"):  # the LQ paths keep what they factorise per active set of every row
            if hasattr(other, name):
                setattr(other, name, False)
        return other

    def _check_stage_rows(self, state: SSNState) -> SSNState:
        """A row that no decision reaches must hold at the plant state as it is; otherwise nothing can be done."""
        stage = self._stage_rows
        if not stage.size or state.status != Status.RUNNING:
            return state
        c = state.parts.c[stage]
        tol = max(self.options.tol, 1e-9)
        bad = np.where(self._eq[stage], np.abs(c) > tol, c > tol)
        if not bad.any():
            return state
        rows = stage[bad]
        labels = "; ".join(f"{describe_row(self.game, self.game.n + r)} (violated by {c[bad][i]:.3g})"
                           for i, r in enumerate(rows[:3]))
        more = f" and {rows.size - 3} more" if rows.size > 3 else ""
        return replace(state, status=Status.INFEASIBLE_STAGE_CONSTRAINT,
                       message=f"{rows.size} constraint row(s) that no decision variable can change are violated at "
                               f"this state: {labels}{more}")


    def at_solution(self, state: SSNState) -> bool:
        """||Phi(z^k)|| <= tol: where ``step`` stops (the test of :meth:`terminate`)."""
        return state.residual_norm <= self.options.tol

    def advance(self, state: SSNState, z: np.ndarray, *, rcond: float = math.nan, search: Memory | None = None,
                k: int | None = None, parts: KKTParts | None = None) -> SSNState:
        """The iterate after ``state``: z evaluated once (Phi, the parts for the next step), checked for NaN and
        divergence, carrying the globalization's ``search`` memory. With ``k``, z takes ``state``'s place as iterate
        k instead (a new start of the globalized method: the iterate before it stays ``state``'s). ``parts``: the
        condensed parts at z already evaluated by another method on this game (``game.kkt_parts``), taken as they
        are where this method would evaluate the same. Every method's step ends here."""
        if parts is not None and self.condensed and not self._affine:
            phi, active = self.residual(parts, z)
        else:
            parts, phi, active = self.evaluate_next(state, z)
        moved = k is not None
        new = SSNState(z=z, x=state.x, k=k if moved else state.k + 1, phi=phi, residual_norm=norm(phi), parts=parts,
                       active=active, z_prev=state.z_prev if moved else state.z,
                       active_prev=state.active_prev if moved else state.active, status=Status.RUNNING, message="",
                       rng=state.rng, rcond=rcond, search=search)
        return self.checked(new)

    def checked(self, new: SSNState) -> SSNState:
        """``new`` with the NaN and divergence checks applied."""
        z = new.z
        new = self._check_finite(new)
        limit = self.options.divergence_limit
        if new.status == Status.RUNNING and z.dot(z) > limit * limit and np.abs(z).max() > limit:
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
        return state.ended(status, msg)

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
