"""Dense linear algebra of the Newton-type steps: LU factors with their condition number, the Levenberg-Marquardt
step, the 2-norm and seeded noise (the perturbations of [eq:inexact_seminewton] and [eq:JN_pertu])."""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import lapack


def factor(M: np.ndarray) -> tuple[np.ndarray, np.ndarray, int, float]:
    """LU factors of M, LAPACK's info, and the reciprocal 1-norm condition number (0 when singular)."""
    if not M.size:
        return M, np.zeros(0, dtype=np.int32), 0, 1.0
    lu, piv, info = lapack.dgetrf(M)
    rcond = 0.0
    if info == 0:
        rcond, _ = lapack.dgecon(lu, float(np.abs(M).sum(axis=0).max()), norm="1")
    return lu, piv, info, float(rcond)


def levenberg_marquardt(M: np.ndarray, r: np.ndarray, mu: float) -> np.ndarray | None:
    """d with (M'M + mu I) d = M'r (the minimiser of ||M d - r||^2 + mu ||d||^2), or None."""
    if not M.shape[1]:
        return np.zeros(0)
    N = M.T @ M
    N.flat[:: N.shape[0] + 1] += mu
    chol, info = lapack.dpotrf(N, lower=0, clean=0, overwrite_a=1)
    if info != 0:
        return None
    d, info = lapack.dpotrs(chol, M.T @ r, lower=0)
    return d if info == 0 and np.all(np.isfinite(d)) else None


def norm(v: np.ndarray) -> float:
    # nan if v has a nan, inf if it overflows; 0 for an empty v (ndarray.dot: the BLAS call of @ with less of numpy's
    # dispatch, 0.3 instead of 0.5 us on a short vector)
    return math.sqrt(v.dot(v))


def largest(v: np.ndarray) -> float:
    """max |v_i| (0 for an empty v; NaN where v has one): ``np.max(np.abs(v), initial=0.0)``, by the array's own
    methods (a third of the time on the short vectors of a step)."""
    return float(np.abs(v).max()) if v.size else 0.0


def noise(rng: np.random.Generator, shape: tuple[int, ...], distribution: str) -> np.ndarray:
    if distribution == "uniform":
        return rng.uniform(-1.0, 1.0, size=shape)
    return rng.standard_normal(size=shape)
