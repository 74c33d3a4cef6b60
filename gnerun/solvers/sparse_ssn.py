"""Semismooth Newton through the sparse formulation of a dynamic game (:mod:`gnerun.game.sparse`)."""

from __future__ import annotations

import numpy as np
from scipy.sparse import linalg as spla

from ..game.compile import CompiledGame
from ..game.sparse import SparseKKT, SparseParts, factor
from ..language.config import DisturbanceConfig, SolverConfig
from .ssn import SemismoothNewton, SSNState


class SparseSemismoothNewton(SemismoothNewton):
    """Semismooth Newton (min map, reduced step) through the sparse formulation: the same iterates as
    :class:`~gnerun.ssn.SemismoothNewton` on the condensed system, at a cost linear in the horizon.

    The reciprocal condition number checked is SuperLU's 1-norm estimate for the reduced full-space
    matrix. For LQ games that matrix depends on the active set only, and its factorisation is kept.
    """

    condensed = False

    def __init__(self, game: CompiledGame, solver: SolverConfig, disturbance: DisturbanceConfig | None,
                 system: SparseKKT):
        super().__init__(game, solver, disturbance)
        if not self.reduced:
            raise ValueError("the sparse formulation takes min-map steps without noise on JPhi or the residual")
        self.system = system
        self._J = system.matrix(system.evaluate(game.z_start(), game.x0).J) if system.affine else None
        self._lus: dict[bytes, tuple[spla.SuperLU | None, float]] = {}

    def _evaluate(self, z: np.ndarray, x: np.ndarray) -> tuple[SparseParts, np.ndarray, np.ndarray]:
        parts = self.system.evaluate(z, x)
        return parts, *self.residual(parts, z)

    def _reduced_step(self, state: SSNState) -> SSNState:
        system, parts, z = self.system, state.parts, state.z
        A = np.flatnonzero(state.active | self._eq) if self._eq_rows.size else np.flatnonzero(state.active)
        keep = system.kept(A)
        if self._J is not None:  # LQ: a constant matrix, one factorisation per active set
            J = self._J
            key = A.tobytes()
            entry = self._lus.get(key)
            if entry is None:
                if len(self._lus) >= 64:
                    self._lus.clear()
                entry = self._lus[key] = factor(J[keep][:, keep].tocsc())
        else:
            J = system.matrix(parts.J)
            entry = factor(J[keep][:, keep].tocsc())
        lu, rcond = entry
        if lu is None or not rcond >= self.options.min_rcond:
            return self._singular(state, rcond)
        sol = lu.solve(system.rhs(parts)[keep])
        z_new = system.new_iterate(z, sol, A)
        if self.options.line_search:
            dz = z_new - z
            t = self._armijo(state, dz)
            if t != 1.0:
                z_new = z + t * dz
        return self.advance(state, z_new, rcond=rcond)
