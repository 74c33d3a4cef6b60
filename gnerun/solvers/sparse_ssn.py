"""Semismooth Newton through the sparse formulation of a dynamic game (:mod:`gnerun.game.sparse`)."""

from __future__ import annotations

import numpy as np

from ..game.compile import CompiledGame
from ..game.sparse import SparseKKT, SparseParts
from ..language.config import DisturbanceConfig, SolverConfig
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

    def evaluate(self, z: np.ndarray, x: np.ndarray) -> tuple[SparseParts, np.ndarray, np.ndarray]:
        parts = self.system.evaluate(z, x)
        return parts, *self.residual(parts, z)

    def kkt_residual(self, z: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.system.residual(z, x)
