"""LQ games: the semismooth Newton step from what is kept per active set (the fast path of
:class:`~gnerun.solvers.ssn.SemismoothNewton` for the min map without perturbations).

An LQ game has L = P a + E lambda + l0(x) and c = C a + c0(x) with constant P, E, C, so the reduced matrix of a
min-map step depends on the active set A only, and the step lands on the same point from any z with that active
set: its LU factors (or the reason there are none) are kept per active set, and a step is one triangular solve;
from an active set's ``MAP_AFTER``-th use on, the map G_A with z^+ = G_A w0 for every state x. Where P is
invertible and the game is large (``DUAL_FROM`` decisions), the system solved is the reduced matrix's Schur
complement (:class:`_Dual`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import lapack

from ..game.compile import CompiledGame
from .linalg import factor, levenberg_marquardt
from .reduced import FactorCache, assemble, reduced_matrix

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


class LQPath:
    """What an LQ game's min-map steps keep: per active set (at most ``CAPACITY``), the reduced matrix's factors and
    map; per solver, the Schur complement's data. ``eq``: the equality rows (always in A)."""

    CAPACITY = 256

    def __init__(self, game: CompiledGame, eq: np.ndarray, min_rcond: float) -> None:
        self.game = game
        self._eq = eq
        self.min_rcond = min_rcond
        cache = game.lq.cache
        self.W, self.dL, self.dc = cache["W"], cache["dL"], cache["dc"]
        self._maps = FactorCache(self.CAPACITY)  # an _ActiveSet (the reduced matrix's LU factors) per active set
        self._dual_cache: _Dual | None | bool = False  # the Schur complement's data (False: not yet built)

    def forget(self) -> None:
        """Drop the factors kept per active set (the Schur complement's data, the game's constants, stays)."""
        self._maps.clear()

    @property
    def dual(self) -> _Dual | None:
        """P's LU factors and P^{-1} E for an LQ game (built on first use), or None when P is singular or
        ill-conditioned, or the game has fewer than ``DUAL_FROM`` decisions (then the reduced system itself is
        factorised; ``DUAL_FROM``: measured, benchmarks/results/solver-design.md)."""
        if self._dual_cache is False:
            self._dual_cache = self._build_dual()
        return self._dual_cache

    def _build_dual(self) -> _Dual | None:
        n = self.game.n
        if n < DUAL_FROM:
            return None
        P = np.array(self.dL[:, :n], order="F")
        lu, piv, info, rcond = factor(P)
        if info != 0 or not rcond >= DUAL_MIN_RCOND:
            return None
        # P^{-1} E from P^{-1}: a column of E with one nonzero (a bound, a constraint on one decision) is a
        # scaled column of P^{-1}; only the others cost a product
        Pinv, _ = lapack.dgetri(lu, piv)
        E = self.dL[:, n:]
        cache = self.game.lq.cache
        if "single" not in cache:  # the structure of the game's constant matrices: found once per game
            C = np.ascontiguousarray(self.dc)
            cache["single"] = (_single_nonzeros(E.T), C, _single_nonzeros(C))
        (single, where, coef), C, rows = cache["single"]
        PinvE = np.empty(E.shape)
        PinvE[:, single] = Pinv[:, where[single]] * coef[single]
        general = ~single
        PinvE[:, general] = Pinv @ E[:, general]
        return _Dual(lu, piv, PinvE, C, *rows)

    def active_set(self, active: np.ndarray) -> _ActiveSet:
        """What is kept for the active set ``active`` (built on its first use)."""
        key = active.tobytes()
        entry = self._maps.get(key)
        if entry is not None:
            return entry
        A = np.flatnonzero(active | self._eq)
        dual = self.dual
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
            lu, piv, info, rcond = factor(reduced_matrix(self.dL, self.dc, A))
        ok = info == 0 and rcond >= self.min_rcond
        return self._maps.keep(key, _ActiveSet(lu if ok else None, piv, A, float(rcond), S=S))

    def dual_rhs(self, A: np.ndarray, w0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """y = P^{-1} l0 and the Schur system's right-hand side c0_A - C_A y for the offsets w0 = [l0; c0] (a
        vector, or one per column)."""
        dual, n = self.dual, self.game.n
        y, _ = lapack.dgetrs(dual.lu, dual.piv, w0[:n])
        return y, w0[n + A] - dual.C[A] @ y

    def dual_point(self, A: np.ndarray, lam_A: np.ndarray, y: np.ndarray) -> np.ndarray:
        """z = (a, lambda) with lambda_A = ``lam_A``, the other multipliers zero and a = -y - P^{-1} E_A lambda_A
        (y = P^{-1} l0); columnwise for 2-D arguments."""
        n = self.game.n
        z = np.zeros((self.game.size,) + lam_A.shape[1:])
        a = z[:n]
        np.negative(y, out=a)
        a -= self.dual.PinvE[:, A] @ lam_A
        z[n + A] = lam_A
        return z

    def point(self, active: np.ndarray, x: np.ndarray) -> tuple[np.ndarray | None, float]:
        """z^+ for an LQ game from any z with active set ``active`` (g-branch rows and equalities): the reduced
        system M [a; lambda_A] = -[L(0); c_A(0)], whose factors are kept per active set (M depends on the active
        set only), solved for w0(x); from the set's ``MAP_AFTER``-th use on, the map G_A with z^+ = G_A w0 for every
        x (built once from the factors). Where P is invertible, the system solved is M's Schur complement
        (:class:`_Dual`). ``None`` when M is singular."""
        entry = self.active_set(active)
        if entry.lu is None:
            return None, entry.rcond
        w0 = self.game.lq.offsets(x)
        if entry.G is not None:
            return entry.G.dot(w0), entry.rcond
        entry.uses += 1
        if entry.uses >= MAP_AFTER:
            # an active set that comes back (a closed loop, repeated solves): the map z^+ = G_A w0, one product per step
            entry.G = self.solve(entry, np.eye(self.game.size))
            return entry.G @ w0, entry.rcond
        return self.solve(entry, w0), entry.rcond

    def solve(self, entry: _ActiveSet, w0: np.ndarray) -> np.ndarray:
        """z^+ for the offsets w0 = [l0; c0] (a vector, or one per column) by the kept factors of ``entry``."""
        n, A = self.game.n, entry.A
        if self.dual is not None:
            y, rhs = self.dual_rhs(A, w0)
            lam_A = lapack.dgetrs(entry.lu, entry.piv, rhs)[0] if A.size else rhs
            return self.dual_point(A, lam_A, y)
        rhs = np.concatenate([-w0[:n], -w0[n + A]])
        sol, _ = lapack.dgetrs(entry.lu, entry.piv, rhs)
        return assemble(self.game.size, sol[:n], A, sol[n:])

    def regularized(self, active: np.ndarray, z: np.ndarray, x: np.ndarray, mu: float) -> np.ndarray | None:
        """The Levenberg-Marquardt step in the multipliers alone (a = a(lambda) keeps L = 0, where P is invertible):
        min ||c_A(lambda)||^2 + mu ||lambda_A - lambda_A^k||^2; None if it cannot be solved."""
        entry = self.active_set(active)
        A = entry.A
        y, rhs = self.dual_rhs(A, self.game.lq.offsets(x))
        lam_A = z[self.game.n + A]
        d = levenberg_marquardt(entry.S, rhs - entry.S @ lam_A, mu)
        return None if d is None else self.dual_point(A, lam_A + d, y)
