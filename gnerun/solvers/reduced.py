"""The min-map reduced system's pieces that every formulation shares: which rows are in it, its dense matrix, and
the iterate z = (a, lambda) assembled from its solution (the inactive multipliers zero)."""

from __future__ import annotations

import numpy as np


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
