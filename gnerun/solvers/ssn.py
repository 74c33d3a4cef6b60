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
from dataclasses import dataclass, replace

import numpy as np
from scipy.linalg import lapack

from ..game.compile import CompiledGame, KKTParts
from ..language.config import DisturbanceConfig, SolverConfig
from .linalg import factor, levenberg_marquardt, noise, norm
from .status import FAILURES, SSNState, Status

__all__ = ["FAILURES", "SSNState", "SemismoothNewton", "Status", "describe_row", "levenberg_marquardt"]

_FB_TIE = 1.0 - 1.0 / math.sqrt(2.0)
DUAL_FROM = 32  # LQ games with at least this many decisions solve the Schur complement (below, its set-up costs more)
DUAL_MIN_RCOND = 1e-8  # LQ games: P = dL/da better conditioned than this is eliminated (the Schur complement)
MAP_AFTER = 3  # LQ games: an active set's map G_A is built on its third use (one triangular solve per use before)


@dataclass(slots=True)
class _ActiveSet:
    """LQ games: what is kept per active set A: the reduced matrix's LU factors (None when it is singular), the
    rows A, the reciprocal condition number, how often the set was used, and its map G_A once built."""

    lu: np.ndarray | None
    piv: np.ndarray
    A: np.ndarray
    rcond: float
    uses: int = 0
    G: np.ndarray | None = None
    S: np.ndarray | None = None  # the Schur complement S_AA (when P is invertible: see SemismoothNewton._dual)


@dataclass(slots=True, frozen=True)
class _Dual:
    """LQ games whose pseudo-gradient Jacobian P = dL/da is invertible: L = P a + E lambda + l0, c = C a + c0,
    so a = -P^{-1}(E lambda + l0) and the reduced system of an active set A is its Schur complement
    S_AA lambda_A = c0_A - C_A P^{-1} l0 with S_AA = C_A P^{-1} E_A, |A| x |A| instead of (n + |A|)^2: the same
    step, a smaller matrix. ``PinvE`` = P^{-1} E, computed once per solver."""

    lu: np.ndarray
    piv: np.ndarray
    PinvE: np.ndarray
    C: np.ndarray  # dc/da
    single: np.ndarray  # rows of C with one nonzero ...
    where: np.ndarray  # ... its column ...
    coef: np.ndarray  # ... and its value


def _single_nonzeros(M: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which rows of M have exactly one nonzero, where it is and its value (0 for the other rows)."""
    nonzero = M != 0.0
    single = np.count_nonzero(nonzero, axis=1) == 1
    where = nonzero.argmax(axis=1)
    coef = np.where(single, M[np.arange(M.shape[0]), where], 0.0)
    return single, where, coef


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
        # LQ games: the reduced matrix depends on the active set only, and the step lands on the same
        # point from any z with that active set: its LU factors (or the reason there are none) are kept per
        # active set, so a step is one triangular solve.
        self._lq = self.condensed and self.reduced and game.affine
        self._lq_inline = self._lq and not self._eq_rows.size and not self._fixed_rows.size
        self._tie_tol = solver.tie_tol
        self._maps: dict[bytes, _ActiveSet] = {}  # LQ games: the reduced matrix's LU factors per active set
        self._dual_cache: _Dual | None | bool = False  # LQ games: the Schur complement's data (False: not yet built)
        if self._lq:
            cache = game.affine_cache
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
        if not (self._lq and self._eq_rows.size == 0 and self._fixed_rows.size == 0):
            parts = self.game.kkt_parts(z, x)
            return parts, *self.residual(parts, z)
        n = self.game.n
        v = self._W @ z
        v += self.game.offsets(x)
        phi = v.copy()
        a = np.negative(v[n:], out=phi[n:])  # -c, in place in Phi's buffer
        lam = z[n:]
        active = a < lam - self._tie_tol
        np.minimum(a, lam, out=a)
        return KKTParts(v[:n], v[n:], self._dL, self._dc), phi, active

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
        if self._lq and self._dual is not None:
            # in the multipliers alone (a = a(lambda) keeps L = 0):
            # min ||c_A(lambda)||^2 + mu ||lambda_A - lambda_A^k||^2
            entry = self._active_set(state.active)
            A = entry.A
            y, rhs = self._dual_rhs(A, game.offsets(state.x))
            lam_A = z[n + A]
            d = levenberg_marquardt(entry.S, rhs - entry.S @ lam_A, mu)
            return None if d is None else self._dual_point(A, lam_A + d, y)
        if self.reduced:
            A = np.flatnonzero(state.active | self._eq) if self._eq_rows.size else np.flatnonzero(state.active)
            M = self._reduced_matrix(parts, A)
            lam = z[n:]
            rhs = np.concatenate([parts.dL_dz[:, n:] @ lam - parts.L, -parts.c[A]])
            y0 = np.concatenate([np.zeros(n), lam[A]])
            r = rhs - M @ y0
            dy = levenberg_marquardt(M, r, mu)
            if dy is None:
                return None
            z_new = np.zeros_like(z)
            z_new[:n] = z[:n] + dy[:n]
            z_new[n + A] = lam[A] + dy[n:]
            return z_new
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
            return self._lq_point(state.active, state.x)
        A = np.flatnonzero(state.active | self._eq) if self._eq_rows.size else np.flatnonzero(state.active)
        lu, piv, info, rcond = factor(self._reduced_matrix(parts, A))
        if info != 0 or not rcond >= opts.min_rcond:
            return None, rcond
        lam = z[n:]
        rhs = np.concatenate([parts.dL_dz[:, n:] @ lam - parts.L, -parts.c[A]])
        sol, _ = lapack.dgetrs(lu, piv, rhs)
        z_new = np.zeros_like(z)
        z_new[:n] = z[:n] + sol[:n]
        z_new[n + A] = sol[n:]
        return z_new, float(rcond)

    def _lq_step(self, state: SSNState) -> SSNState:
        """:meth:`_reduced_point` then :meth:`advance` for an LQ game without equalities or line search, in one
        function: the same operations (z^+ from the kept factors of the active set, then
        Phi(z^+) = [L; min(-c, lambda)] with [L; c] = W z^+ + w0), without the calls between them."""
        x = state.x
        z, rcond = self._lq_point(state.active, x)
        if z is None:
            return self.singular(state, rcond)
        w0 = self.game.offsets(x)
        n = self.game.n
        v = self._W @ z
        v += w0
        phi = v.copy()
        a = np.negative(v[n:], out=phi[n:])
        lam = z[n:]
        active = a < lam - self._tie_tol
        np.minimum(a, lam, out=a)
        new = SSNState(z=z, x=x, k=state.k + 1, phi=phi, residual_norm=math.sqrt(phi @ phi),
                       parts=KKTParts(v[:n], v[n:], self._dL, self._dc), active=active, z_prev=state.z,
                       active_prev=state.active, status=Status.RUNNING, message="", rng=state.rng, rcond=rcond)
        limit = self.options.divergence_limit
        if not math.isfinite(new.residual_norm) or z @ z > limit * limit:  # rare: the general checks decide
            return self.checked(new)
        return new

    def _reduced_matrix(self, parts: KKTParts, A: np.ndarray) -> np.ndarray:
        n, k = self.game.n, A.size
        M = np.zeros((n + k, n + k))
        M[:n, :n] = parts.dL_dz[:, :n]
        M[:n, n:] = parts.dL_dz[:, n + A]
        M[n:, :n] = parts.dc_da[A]
        return M

    @property
    def _dual(self) -> _Dual | None:
        """P's LU factors and P^{-1} E for an LQ game (built on first use), or None when P is singular or
        ill-conditioned, or the game has fewer than ``DUAL_FROM`` decisions (then the reduced system itself is
        factorised). Measured on fresh solves: 0.8-0.95 times as fast at n = 2-20 (FK library, the LQ family at
        T = 5), 1.1-1.4 times as fast from n = 33 (the LQ family at T = 10 and 20)."""
        if self._dual_cache is False:
            self._dual_cache = self._build_dual()
        return self._dual_cache

    def _build_dual(self) -> _Dual | None:
        n = self.game.n
        if n < DUAL_FROM:
            return None
        P = np.array(self._dL[:, :n], order="F")
        lu, piv, info, rcond = factor(P)
        if info != 0 or not rcond >= DUAL_MIN_RCOND:
            return None
        # P^{-1} E from P^{-1}: a column of E with one nonzero (a bound, a constraint on one decision) is a
        # scaled column of P^{-1}; only the others cost a product
        Pinv, _ = lapack.dgetri(lu, piv)
        E = self._dL[:, n:]
        cache = self.game.affine_cache
        if "single" not in cache:  # the structure of the game's constant matrices: found once per game
            C = np.ascontiguousarray(self._dc)
            cache["single"] = (_single_nonzeros(E.T), C, _single_nonzeros(C))
        (single, where, coef), C, rows = cache["single"]
        PinvE = np.empty(E.shape)
        PinvE[:, single] = Pinv[:, where[single]] * coef[single]
        general = ~single
        PinvE[:, general] = Pinv @ E[:, general]
        return _Dual(lu, piv, PinvE, C, *rows)

    def _active_set(self, active: np.ndarray) -> _ActiveSet:
        """What is kept for the active set ``active`` (built on its first use)."""
        key = active.tobytes()
        entry = self._maps.get(key)
        if entry is not None:
            return entry
        A = np.flatnonzero(active | self._eq)
        dual = self._dual
        S = None
        if dual is not None:
            # S_AA = C_A P^{-1} E_A; a row of C_A with one nonzero (a bound) picks a scaled row of P^{-1} E_A
            PA = dual.PinvE[:, A]
            single = dual.single[A]
            S = np.empty((A.size, A.size), order="F")  # LAPACK's order: factorised without a copy
            S[single] = PA[dual.where[A[single]]] * dual.coef[A[single], None]
            general = ~single
            if general.any():
                S[general] = dual.C[A[general]] @ PA
        if A.size > self.game.n:
            # more active rows than decisions: their gradients are dependent, the system singular (nothing to
            # factorise); the Schur complement is kept for the Levenberg-Marquardt step
            lu, piv, info, rcond = None, np.zeros(0, dtype=np.int32), 0, 0.0
        elif dual is not None:
            lu, piv, info, rcond = factor(S)
        else:
            lu, piv, info, rcond = factor(self._reduced_matrix(KKTParts(None, None, self._dL, self._dc), A))
        ok = info == 0 and rcond >= self.options.min_rcond
        if len(self._maps) >= 256:
            self._maps.clear()
        entry = self._maps[key] = _ActiveSet(lu if ok else None, piv, A, float(rcond), S=S)
        return entry

    def _dual_rhs(self, A: np.ndarray, w0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """y = P^{-1} l0 and the Schur system's right-hand side c0_A - C_A y for the offsets w0 = [l0; c0] (a
        vector, or one per column)."""
        dual, n = self._dual, self.game.n
        y, _ = lapack.dgetrs(dual.lu, dual.piv, w0[:n])
        return y, w0[n + A] - dual.C[A] @ y

    def _dual_point(self, A: np.ndarray, lam_A: np.ndarray, y: np.ndarray) -> np.ndarray:
        """z = (a, lambda) with lambda_A = ``lam_A``, the other multipliers zero and a = -y - P^{-1} E_A lambda_A
        (y = P^{-1} l0); columnwise for 2-D arguments."""
        n = self.game.n
        z = np.zeros((self.game.size,) + lam_A.shape[1:])
        a = z[:n]
        np.negative(y, out=a)
        a -= self._dual.PinvE[:, A] @ lam_A
        z[n + A] = lam_A
        return z

    def _lq_point(self, active: np.ndarray, x: np.ndarray) -> tuple[np.ndarray | None, float]:
        """z^+ for an LQ game from any z with active set ``active`` (g-branch rows and equalities): the reduced
        system M [a; lambda_A] = -[L(0); c_A(0)], whose factors are kept per active set (M depends on the active
        set only), solved for w0(x); from the set's ``MAP_AFTER``-th use on, the map G_A with z^+ = G_A w0 for every
        x (built once from the factors). Where P is invertible, the system solved is M's Schur complement
        (:class:`_Dual`). ``None`` when M is singular."""
        entry = self._active_set(active)
        if entry.lu is None:
            return None, entry.rcond
        w0 = self.game.offsets(x)
        if entry.G is not None:
            return entry.G @ w0, entry.rcond
        entry.uses += 1
        if entry.uses >= MAP_AFTER:
            # an active set that comes back (a closed loop, repeated solves): the map z^+ = G_A w0, one product per step
            entry.G = self._lq_solve(entry, np.eye(self.game.size))
            return entry.G @ w0, entry.rcond
        return self._lq_solve(entry, w0), entry.rcond

    def _lq_solve(self, entry: _ActiveSet, w0: np.ndarray) -> np.ndarray:
        """z^+ for the offsets w0 = [l0; c0] (a vector, or one per column) by the kept factors of ``entry``."""
        n, A = self.game.n, entry.A
        if self._dual is not None:
            y, rhs = self._dual_rhs(A, w0)
            lam_A = lapack.dgetrs(entry.lu, entry.piv, rhs)[0] if A.size else rhs
            return self._dual_point(A, lam_A, y)
        rhs = np.concatenate([-w0[:n], -w0[n + A]])
        sol, _ = lapack.dgetrs(entry.lu, entry.piv, rhs)
        z = np.zeros((self.game.size,) + w0.shape[1:])
        z[:n] = sol[:n]
        z[n + A] = sol[n:]
        return z

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
