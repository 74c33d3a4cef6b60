"""Semismooth Newton through the sparse formulation of a dynamic game (:mod:`gnerun.game.sparse`)."""

from __future__ import annotations

import numpy as np

from ..game.compile import CompiledGame
from ..game.sparse import DeferredParts, SparseKKT, SparseParts
from ..language.config import DisturbanceConfig, SolverConfig
from .linalg import norm
from .reduced import SparseReduced
from .ssn import SemismoothNewton


class SparseSemismoothNewton(SemismoothNewton):
    """Semismooth Newton (min map, reduced step) through the sparse formulation: the same iterates as
    :class:`~gnerun.ssn.SemismoothNewton` on the condensed system, at a cost linear in the horizon.

    Its Phi and parts are the sparse system's; its steps solve :class:`~gnerun.solvers.reduced.SparseReduced`.
    """

    condensed = False

    def __init__(self, game: CompiledGame, solver: SolverConfig, disturbance: DisturbanceConfig | None,
                 system: SparseKKT):
        super().__init__(game, solver, disturbance)
        if not self.reduced:
            raise ValueError("the sparse formulation takes min-map steps without noise on JPhi or the residual")
        self.system = system
        self.reduced_system = SparseReduced(game, system, solver.min_rcond)
        self._defer_below = solver.tol ** 0.5

    def evaluate(self, z: np.ndarray, x: np.ndarray) -> tuple[SparseParts, np.ndarray, np.ndarray]:
        parts = self.system.evaluate(z, x)
        return parts, *self.residual(parts, z)

    def evaluate_next(self, state, z: np.ndarray) -> tuple[SparseParts | DeferredParts, np.ndarray, np.ndarray]:
        """The iterate after ``state``: where ``state``'s ||Phi|| is at most sqrt(tol) (a Newton step from there,
        converging quadratically, is expected to meet tol), its residual first, and the whole system only if it
        does not meet tol (:class:`~gnerun.game.sparse.DeferredParts`: the same numbers, the Jacobian of a converged
        iterate not evaluated). On the MPC merge: a sampling time's second Newton step, from ||Phi|| ~ 1e-6."""
        if not state.residual_norm <= self._defer_below:
            return self.evaluate(z, state.x)
        parts = self.system.deferred(z, state.x)
        phi, active = self.residual(parts, z)
        if not norm(phi) <= self.options.tol:
            parts._full()  # not converged: the next step needs the whole system
        return parts, phi, active

    def kkt_residual(self, z: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.system.residual(z, x)

    def constraint_values(self, z: np.ndarray, x: np.ndarray) -> np.ndarray:
        return self.system.constraints(z, x)  # the same c as the residual's, without L
