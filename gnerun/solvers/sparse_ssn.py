"""Semismooth Newton through the sparse formulation of a dynamic game (:mod:`gnerun.game.sparse`)."""

from __future__ import annotations

import numpy as np

from ..game.compile import CompiledGame
from ..game.sparse import SparseKKT, SparseParts
from ..language.config import DisturbanceConfig, SolverConfig
from .reduced import FactorCache, assemble
from .ssn import SemismoothNewton
from .status import SSNState


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
        self._lus = FactorCache(64)  # LQ games: (SuperLU factors or None, rcond) per active set

    def evaluate(self, z: np.ndarray, x: np.ndarray) -> tuple[SparseParts, np.ndarray, np.ndarray]:
        parts = self.system.evaluate(z, x)
        return parts, *self.residual(parts, z)

    def kkt_residual(self, z: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self.system.residual(z, x)

    def _reduced_point(self, state: SSNState) -> tuple[np.ndarray | None, float]:
        system, parts, z = self.system, state.parts, state.z
        A = self.active_rows(state.active)
        keep = system.kept(A)
        if self._J is not None:  # LQ: a constant matrix, one factorisation per active set
            J = self._J
            key = A.tobytes()
            entry = self._lus.get(key)
            if entry is None:
                entry = self._lus.keep(key, system.orderings["newton"].factor(J[keep][:, keep].tocsc()))
        else:
            J = system.matrix(parts.J)
            entry = system.orderings["newton"].factor(J[keep][:, keep].tocsc())
        lu, rcond = entry
        if lu is None or not rcond >= self.options.min_rcond:
            return None, rcond
        sol = lu.solve(system.rhs(parts)[keep])
        return system.new_iterate(z, sol, A), rcond

    def regularized_point(self, state: SSNState, mu: float) -> np.ndarray | None:
        """The condensed method's Levenberg-Marquardt step, in the full space: y = (da, dxi, p^+, dlambda_A)
        minimises ||M_1 y - r_1||^2 + mu ||(da, dlambda_A)||^2 subject to M_2 y = r_2, where rows 1 are the
        stationarity in a and the active constraints, and rows 2 (the costate equations and the dynamics) are the
        ones the condensed system eliminates. Their solution is the condensed step (the states and costates
        follow from (da, dlambda_A) through rows 2), found from one sparse symmetric system without the normal
        equations' product:

            [ mu E^T E   M_1^T   M_2^T ] [y  ]   [0  ]
            [ M_1        -I      0     ] [nu1] = [r_1]
            [ M_2        0       0     ] [nu2]   [r_2]

        (nu1 = M_1 y - r_1 is the residual, E picks (da, dlambda_A))."""
        import scipy.sparse as sp

        system, parts, z = self.system, state.parts, state.z
        n, m = self.game.n, self.game.m
        A = self.active_rows(state.active)
        keep = system.kept(A)
        J = system.matrix(parts.J)
        lam = z[n:]
        inactive = np.setdiff1d(np.arange(m), A)
        lam0 = system.size - m
        r = -(parts.F - J[:, lam0 + inactive] @ lam[inactive])  # F with the inactive multipliers at zero
        M = J[keep][:, keep].tocsc()
        size = keep.size
        first = np.zeros(size, dtype=bool)  # rows 1 (and the columns E picks): a and the active multipliers
        first[:n] = True
        first[lam0:] = True
        K = sp.bmat([[sp.diags(mu * first.astype(float)), M.T], [M, sp.diags(-first.astype(float))]], format="csc")
        lu, _ = system.orderings["regularized"].factor(K)
        if lu is None:
            return None
        dy = lu.solve(np.concatenate([np.zeros(size), r[keep]]))[:size]
        if not np.all(np.isfinite(dy)):
            return None
        return assemble(z.size, z[:n] + dy[:n], A, lam[A] + dy[size - A.size:])
