"""Semismooth Newton on the KKT system of a GNE problem [semi_newton], step by step.

Phi(z) = [L(z); phi(-g(a), lambda); h(a)] [system_equations] (:mod:`gnerun.solvers.kkt`: the min function or
Fischer-Burmeister, and the Jacobian element taken at ties). One step solves Phi(z^k) + JPhi(z^k)(z - z^k) = r^k
with JPhi(z^k) an element of the limiting Jacobian [eq:inexact_seminewton]. For the min map without noise on JPhi
the step is solved on the reduced system (:mod:`gnerun.solvers.reduced`; for LQ games from what is kept per active
set: :mod:`gnerun.solvers.lq_path`).

Perturbations (paper Study 1b and eq. inexact_seminewton), seeded: ``jacobian_noise`` adds i.i.d.
noise of the given scale to every element of JPhi(z^k); ``residual`` uses a right-hand side r^k of
norm ``scale`` in a random direction.

This class is the paper's local method (``solver.globalization: none``); the globalizations of
:mod:`gnerun.solvers.globalization` wrap it: Armijo backtracking along its direction (``line_search``), and the
default, globalized method (:mod:`gnerun.solvers.hybrid`), which takes these steps where they work and an
interior-point phase elsewhere.

Shape (see STYLE.md; the loop is :func:`gnerun.solvers.driver.iterate`): ``init(z0, x) -> state``,
``step(state) -> state`` (exactly one iteration, nothing else; at a solution the state as it is),
``terminate(state) -> (done, status)``. Failure is a status, never an exception: a singular or ill-conditioned JPhi
(the step is not taken), a non-finite Phi, divergence.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace

import numpy as np
from scipy.linalg import lapack

from ..game.compile import CompiledGame, KKTParts
from ..language.config import DisturbanceConfig, SolverConfig
from .kkt import KKTSystem, describe_row
from .linalg import factor, levenberg_marquardt, noise, norm
from .lq_path import LQPath
from .reduced import DenseReduced, SparseReduced, active_rows
from .status import FAILURES, SSNState, Status

__all__ = ["FAILURES", "SSNState", "SemismoothNewton", "Status", "describe_row", "levenberg_marquardt"]


class SemismoothNewton(KKTSystem):
    """The semismooth Newton method for a compiled game (see the module docstring); Phi, JPhi and the iterate states
    are :class:`~gnerun.solvers.kkt.KKTSystem`'s."""

    def __init__(self, game: CompiledGame, solver: SolverConfig, disturbance: DisturbanceConfig | None = None):
        super().__init__(game, solver, disturbance)
        d = self.disturbance
        # The min map's multiplier rows say lambda_j^+ = 0: solve only for a and the g-branch multipliers
        # (same step, smaller system). Noise on all of JPhi or on the right-hand side needs the full system.
        self.reduced = not self._fb and not (d.kind in ("jacobian_noise", "residual") and d.scale > 0)
        # LQ games: a step from what is kept per active set (gnerun.solvers.lq_path)
        self._lq = self.condensed and self.reduced and game.affine
        self._lq_inline = self._lq and not self._eq_rows.size and not self._fixed_rows.size
        self.lq = LQPath(game, self._eq, solver.min_rcond) if self._lq else None
        self.reduced_system: DenseReduced | SparseReduced = DenseReduced(game.n, solver.min_rcond)


    def forget(self) -> None:
        """Drop the factorisations kept per active set, so that the next solve computes exactly what a new solver's
        would (a kept factor reproduces a step to rounding, not bit for bit)."""
        if self.lq is not None:
            self.lq.forget()
        forget = getattr(self.reduced_system, "forget", None)
        if forget is not None:
            forget()
    def step(self, state: SSNState) -> SSNState:
        """Exactly one (perturbed) semismooth Newton iteration; a failed or converged state is returned unchanged
        (a step at a solution keeps it: :meth:`iteration` steps on from there, as polishing does)."""
        if state.status in FAILURES or self.at_solution(state):
            return state
        return self.iteration(state)

    def iteration(self, state: SSNState, taken: Callable[[SSNState, SSNState], bool] | None = None) -> SSNState:
        """One semismooth Newton iteration from ``state``, also at a solution (a failed state is returned
        unchanged). With ``taken``, the condition estimate of a nonlinear game's sparse matrix (about as costly as
        its banded factorisation) is made only where ``taken(state, new)`` is false for the iterate ``new`` the
        step makes: a step so judged on its result is kept whatever the estimate would have said (``new.rcond`` is
        then NaN), as the interior phase keeps its steps."""
        if state.status in FAILURES:
            return state
        if self._lq_inline:
            return self._lq_step(state)
        z_new, rcond = self.newton_point(state, estimate=taken is None)
        if z_new is None:
            return self.singular(state, rcond)
        new = self.advance(state, z_new, rcond=rcond)
        if taken is None or not math.isnan(rcond) or taken(state, new):
            return new
        rcond = self.reduced_system.last_rcond()
        if not rcond >= self.options.min_rcond:
            return self.singular(state, rcond)
        new.rcond = rcond
        return new

    def newton_point(self, state: SSNState, estimate: bool = True) -> tuple[np.ndarray | None, float]:
        """The end point z^k + dz of the (perturbed) Newton step from ``state``, and the reciprocal condition
        number of the matrix factorised; ``None`` for the point when that matrix is singular or ill-conditioned.
        Without ``estimate``, the sparse reduced system of a nonlinear game leaves its estimate out (NaN; then
        ``reduced_system.last_rcond()``)."""
        if self.reduced:
            return self._reduced_point(state, estimate)
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
        parts, z = state.parts, state.z
        if self._lq and self.lq.dual is not None:
            return self.lq.regularized(state.active, z, state.x, mu)
        if self.reduced:
            return self.reduced_system.regularized(state, self.active_rows(state.active), mu)
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

    def _reduced_point(self, state: SSNState, estimate: bool = True) -> tuple[np.ndarray | None, float]:
        """The min-map Newton step through the reduced system (:mod:`gnerun.solvers.reduced`), for LQ games from
        what is kept per active set."""
        if self._lq:
            return self.lq.point(state.active, state.x)
        return self.reduced_system.point(state, self.active_rows(state.active), estimate)

    def _lq_step(self, state: SSNState) -> SSNState:
        """:meth:`_reduced_point` then :meth:`advance` for an LQ game without equalities or line search, in one
        function: the same operations (z^+ from the kept factors of the active set, then
        Phi(z^+) = [L; min(-c, lambda)] with [L; c] = W z^+ + w0), without the calls between them."""
        x = state.x
        z, rcond = self.lq.point(state.active, x)
        if z is None:
            return self.singular(state, rcond)
        w0 = self.game.lq.offsets(x)
        n = self.game.n
        v = self.lq.W.dot(z)  # (ndarray.dot: the same BLAS call as @ with less of numpy's dispatch)
        v += w0
        phi = v.copy()
        a = np.negative(v[n:], out=phi[n:])
        lam = z[n:]
        active = a < lam - self._tie_tol
        np.minimum(a, lam, out=a)
        new = SSNState(z=z, x=x, k=state.k + 1, phi=phi, residual_norm=math.sqrt(phi.dot(phi)),
                       parts=KKTParts(v[:n], v[n:], self.lq.dL, self.lq.dc), active=active, z_prev=state.z,
                       active_prev=state.active, status=Status.RUNNING, message="", rng=state.rng, rcond=rcond)
        limit = self.options.divergence_limit
        if not math.isfinite(new.residual_norm) or z.dot(z) > limit * limit:  # rare: the general checks decide
            return self.checked(new)
        return new

    def active_rows(self, active: np.ndarray) -> np.ndarray:
        """The rows A of the reduced system at a state whose g-branch rows are ``active`` (and the equalities)."""
        return active_rows(active, self._eq, bool(self._eq_rows.size))
