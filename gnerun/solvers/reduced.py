"""The reduced system of the min-map Newton step, in the two formulations: :class:`DenseReduced` (the condensed KKT
system) and :class:`SparseReduced` (the sparse one of a dynamic game, :mod:`gnerun.game.sparse`), each with the
factorisations it keeps; and the pieces both share: which rows are in it, its dense matrix, and the iterate
z = (a, lambda) assembled from its solution (the inactive multipliers zero).

With A the g-branch rows (and the equalities), the multiplier rows of the min map give lambda_I^+ = 0 and the rest is

    [ dL/da     dL/dlambda_A ] [ da          ]   [ -L(z) + dL/dlambda lambda ]
    [ dc_A/da   0            ] [ lambda_A^+  ] = [ -c_A(a)                   ]

(a row -dc_j/da da = c_j of JPhi, negated): the same step as the full Newton system, a smaller matrix. Its
reciprocal condition number is the one checked.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import lapack

from .linalg import factor, levenberg_marquardt

# a nonlinear game's sparse Newton point in one compiled call where its matrix is banded
# (gnerun.game.banded.ReducedPoint: the same values to the bit; False: the numpy code always)
FUSED = True


def active_rows(active: np.ndarray, eq: np.ndarray, has_equalities: bool) -> np.ndarray:
    """The rows A of the reduced system: the g-branch rows, and the equality rows."""
    return np.flatnonzero(active | eq) if has_equalities else np.flatnonzero(active)


def reduced_matrix(dL_dz: np.ndarray, dc_da: np.ndarray, A: np.ndarray) -> np.ndarray:
    """[[dL/da, dL/dlambda_A], [dc_A/da, 0]]: the reduced system of the min-map Newton step for the rows A."""
    n, k = dL_dz.shape[0], A.size
    M = np.zeros((n + k, n + k))
    M[:n, :n] = dL_dz[:, :n]
    M[:n, n:] = dL_dz[:, n + A]
    M[n:, :n] = dc_da[A]
    return M


def assemble(size: int, a: np.ndarray, A: np.ndarray, lam_A: np.ndarray) -> np.ndarray:
    """z = (a, lambda) with lambda_A = ``lam_A`` and the other multipliers zero (columnwise for 2-D arguments)."""
    n = a.shape[0]
    z = np.zeros((size,) + lam_A.shape[1:])
    z[:n] = a
    z[n + A] = lam_A
    return z


class FactorCache(dict):
    """Factorisations kept by key (an active set), at most ``capacity`` of them: full, it is emptied at once (an
    active set that comes back is factorised again)."""

    def __init__(self, capacity: int) -> None:
        super().__init__()
        self.capacity = capacity

    def keep(self, key: bytes, value):
        """Store ``value`` under ``key`` (emptying the cache first when it is full) and return it."""
        if len(self) >= self.capacity:
            self.clear()
        self[key] = value
        return value


class DenseReduced:
    """The condensed reduced system, factorised once per step (LQ games keep theirs: :mod:`gnerun.solvers.lq_path`)."""

    def __init__(self, n: int, min_rcond: float) -> None:
        self.n = n
        self.min_rcond = min_rcond

    def point(self, state, A: np.ndarray, estimate: bool = True) -> tuple[np.ndarray | None, float]:
        """The min-map Newton step for the rows A, and the reciprocal condition number of the matrix factorised
        (``None`` for the point when it is singular or ill-conditioned). Made whatever ``estimate`` says: next to a
        dense factorisation it is cheap."""
        n, parts, z = self.n, state.parts, state.z
        lu, piv, info, rcond = factor(reduced_matrix(parts.dL_dz, parts.dc_da, A))
        if info != 0 or not rcond >= self.min_rcond:
            return None, rcond
        lam = z[n:]
        rhs = np.concatenate([parts.dL_dz[:, n:] @ lam - parts.L, -parts.c[A]])
        sol, _ = lapack.dgetrs(lu, piv, rhs)
        return assemble(z.size, z[:n] + sol[:n], A, sol[n:]), float(rcond)

    def regularized(self, state, A: np.ndarray, mu: float) -> np.ndarray | None:
        """The Levenberg-Marquardt step on the reduced system (the inactive multipliers still go to zero)."""
        n, parts, z = self.n, state.parts, state.z
        M = reduced_matrix(parts.dL_dz, parts.dc_da, A)
        lam = z[n:]
        rhs = np.concatenate([parts.dL_dz[:, n:] @ lam - parts.L, -parts.c[A]])
        y0 = np.concatenate([np.zeros(n), lam[A]])
        r = rhs - M @ y0
        dy = levenberg_marquardt(M, r, mu)
        if dy is None:
            return None
        return assemble(z.size, z[:n] + dy[:n], A, lam[A] + dy[n:])


class SparseReduced:
    """The reduced system in the sparse formulation's full space, factorised by banded LU on the stage order or by
    SuperLU (:meth:`~gnerun.game.sparse.SparseKKT.factor_kept`), with its reciprocal 1-norm condition estimate. For
    LQ games the matrix depends on the active set only, and its factorisation is kept (at most 64)."""

    def __init__(self, game, system, min_rcond: float) -> None:
        self.game = game
        self.system = system
        self.min_rcond = min_rcond
        self._J = system.evaluate(game.z_start(), game.x0).J if system.affine else None
        self._lus = FactorCache(64)  # LQ games: (factors or None, rcond) per active set
        self._unestimated: tuple | None = None  # the last factors made without their estimate (last_rcond)

    def forget(self) -> None:
        """Drop the factorisations kept per active set."""
        self._lus.clear()

    def point(self, state, A: np.ndarray, estimate: bool = True) -> tuple[np.ndarray | None, float]:
        """The min-map Newton step for the rows A, and the reciprocal condition estimate; without ``estimate``, NaN
        for a nonlinear game's matrix (its estimate costs about as much as its banded factorisation), whose estimate
        :meth:`last_rcond` then makes from the same factors."""
        system, parts, z = self.system, state.parts, state.z
        keep = system.kept(A)
        found = None
        if self._J is not None:  # LQ: a constant matrix, one factorisation per active set
            key = A.tobytes()
            entry = self._lus.get(key)
            if entry is None:
                entry = self._lus.keep(key, system.factor_kept("newton", self._J, keep))
        else:
            # factors, estimate and point in one compiled call where it can (the same values), else step by step
            found = system.point_kept(parts, z, keep, estimate) if FUSED else None
            if found is not None:
                lu, z_new, rcond = found
                entry = (lu, rcond)
            else:
                entry = system.factor_kept("newton", parts.J, keep, estimate=estimate)
            self._unestimated = None if estimate else (entry[0], parts.J, keep)
        lu, rcond = entry
        if lu is None or not (rcond >= self.min_rcond or math.isnan(rcond) and not estimate):
            return None, rcond
        if found is not None:
            return z_new, rcond
        sol = lu.solve(system.rhs(parts)[keep])
        return system.new_iterate(z, sol, A), rcond

    def last_rcond(self) -> float:
        """The condition estimate of the last matrix :meth:`point` factorised without it (the same number it would
        have returned)."""
        lu, J, keep = self._unestimated
        return self.system.rcond_kept(lu, J, keep)

    def regularized(self, state, A: np.ndarray, mu: float) -> np.ndarray | None:
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
        lu, _ = system.orderings["regularized"].factor(K, estimate=False)  # the step needs the factors only
        if lu is None:
            return None
        dy = lu.solve(np.concatenate([np.zeros(size), r[keep]]))[:size]
        if not np.all(np.isfinite(dy)):
            return None
        return assemble(z.size, z[:n] + dy[:n], A, lam[A] + dy[size - A.size:])
