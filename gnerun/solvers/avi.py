"""LQ games whose KKT system is an affine variational inequality: one exact step by DAQP's AVI solver.

An LQ game has L(z) = P a + E lambda + l0(x) and c(a) = C a + c0(x) with constant P, E, C. Where every constraint
row's multiplier enters the Lagrangian through that row's own gradient (E = C^T: a Nash problem, or a variational
GNE), the KKT system is that of the affine VI

    P a + l0 + N_K(a) ∋ 0,    K = {a : C a + c0 <= 0 (equality rows: = 0)},

and its Josephy-Newton step [eq:JN] is its solution. A plain GNE whose shared rows each carrier holds a copy of
(same row, a multiplier of its own in its own stationarity) has the same form once the copies are merged: where the
carriers' parts of a merged row make up its whole gradient, the VI's solution, with every copy's multiplier equal
to the VI's, is one of the game's equilibria (a solution of the VI on the joint set is a GNE: Harker 1991;
Facchinei and Kanzow, 4OR 2007, section 3). A game with rows that couple agents without being shared this way (the
paper's Study 1: agent 3 alone carries u3 >= u1 + u2) is no VI, and :meth:`AffineVI.of` returns None.

The AVI is solved by DAQP (Arnström, Bemporad and Axehill, IEEE TAC 2022), a dual active-set solver in C, in its
AVI mode for an asymmetric P (``is_avi``: Arnström, Benenati and Belgioioso, "DR-DAQP: a hybrid operator splitting
and active-set solver for affine variational inequalities", arXiv:2604.02531, 2026). Bounds (rows with one
nonzero) are passed as DAQP's simple bounds, which it treats without rows. DAQP adds the active rows one at a time,
each at the cost of a factor update, so it is left to the Newton iterations from ``UP_TO`` decisions (the break-even
measured on the bounded LQ family: benchmarks/results/solver-design.md). Its solution is exact on the active set it
ends with (to rounding); where it is not within the solver's tolerance, the Newton steps that follow finish from there.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..game.compile import CompiledGame

UP_TO = 64  # decisions: larger LQ games are left to the Newton iterations (benchmarks/results/solver-design.md)
ROWS_UP_TO = 256  # ... and so are those with more (merged) constraint rows
ITER_LIMIT = 20  # DAQP's iteration limit: this many times the number of rows, plus the number of decisions
_INF = 1e30  # DAQP's infinity


@dataclass(slots=True, frozen=True)
class AffineVI:
    """The AVI of an LQ game (module docstring), built once per game. Copies of a row are merged; of the merged
    rows, a variable's first upper and first lower bound (a row with one nonzero) are DAQP's simple bounds on it,
    and the others are its general rows (C-ordered, as DAQP reads them). DAQP's bounds are gathered from c0 in one
    product each: ``upper0 + coef * c0[rows]`` at positions ``at``."""

    P: np.ndarray
    G: np.ndarray  # the general rows' gradients
    sense: np.ndarray  # DAQP's constraint types (0 inequality, 5 equality): the simple bounds, then the general rows
    upper0: np.ndarray  # DAQP's upper bounds where no row sets one (+inf) ...
    upper_at: np.ndarray  # ... the positions that rows set ...
    upper_rows: np.ndarray  # ... from these rows of c ...
    upper_coef: np.ndarray  # ... times these factors (-1 / the row's coefficient)
    lower0: np.ndarray  # the same for DAQP's lower bounds (equality rows set both)
    lower_at: np.ndarray
    lower_rows: np.ndarray
    lower_coef: np.ndarray
    rows: np.ndarray  # the rows of c that a decision reaches (the others' multipliers stay zero) ...
    source: np.ndarray  # ... the entry of [max(mu, 0), min(mu, 0), mu] (mu: DAQP's multipliers) each one reads ...
    scale: np.ndarray  # ... times this (1 / the coefficient for a simple bound, 1 for a general row)
    n: int

    @staticmethod
    def of(game: CompiledGame) -> AffineVI | None:
        """The AVI of ``game``, or None when it has none: the game is not LQ, its KKT system is not a VI's (rows
        that couple agents without being shared by them all), or it is larger than ``UP_TO`` / ``ROWS_UP_TO``
        (kept on the game: found once)."""
        if not game.affine or game.n > UP_TO:
            return None
        cache = game.lq.cache
        if "avi" not in cache:
            cache["avi"] = _build(game)
        return cache["avi"]

    def point(self, offsets: np.ndarray, size: int) -> np.ndarray | None:
        """z = (a, lambda) solving the KKT system for the offsets [l0; c0] = [L(0; x); c(0; x)], or None when DAQP
        finds no solution (an empty K, an unbounded or non-monotone VI it cannot solve, its iteration limit)."""
        import daqp

        n = self.n
        c0 = offsets[n:]
        upper = self.upper0.copy()
        upper[self.upper_at] = self.upper_coef * c0[self.upper_rows]
        lower = self.lower0.copy()
        lower[self.lower_at] = self.lower_coef * c0[self.lower_rows]
        a, _, flag, info = daqp.solve(self.P, offsets[:n].copy(), self.G, upper, lower, self.sense, is_avi=True,
                                      iter_limit=ITER_LIMIT * upper.size + n)
        if flag < 1:
            return None
        mu = info["lam"]
        z = np.zeros(size)
        z[:n] = a
        z[n + self.rows] = np.concatenate([np.maximum(mu, 0.0), np.minimum(mu, 0.0), mu])[self.source] * self.scale
        return z if np.isfinite(z @ z) else None


def _build(game: CompiledGame) -> AffineVI | None:
    n, m = game.n, game.m
    cache = game.lq.cache
    dL, C = cache["dL"], cache["dc"]
    P, E = dL[:, :n], dL[:, n:]
    equality = game.equality_mask
    reached = ~game.pattern.zero_gradient_rows
    # rows with the same gradient and kind are copies of one constraint when their offsets agree too; the offsets
    # depend on x, so rows are merged only where they agree at the start state and in their (affine) dependence on x
    offset_map = game.lq.offset_map
    keys: dict[bytes, int] = {}
    first: list[int] = []
    group = np.full(m, -1)
    w0 = game.lq.offsets(game._x(None))[n:]
    for j in np.flatnonzero(reached):
        parts = [C[j].tobytes(), bytes([bool(equality[j])]), np.float64(w0[j]).tobytes()]
        if offset_map is not None:
            parts.append(offset_map[0][n + j].tobytes())
        key = b"".join(parts)
        if key not in keys:
            keys[key] = len(first)
            first.append(int(j))
        group[j] = keys[key]
    if not first or len(first) > ROWS_UP_TO:
        return None
    if offset_map is None and (np.bincount(group[reached]) > 1).any():  # offsets nonlinear in x: copies may part
        return None
    first_rows = np.asarray(first)
    # the merged row's multiplier must enter the stationarity as its gradient: the copies' columns of E add up to
    # C_j^T (each carrier holds its own part; no part missing, none counted twice)
    merged_E = np.zeros((first_rows.size, n))
    np.add.at(merged_E, group[reached], E.T[reached])
    if not np.allclose(merged_E, C[first_rows], rtol=0.0, atol=1e-12 * max(1.0, float(np.abs(C).max()))):
        return None
    # DAQP's simple bounds: a variable's first upper and first lower row among the merged inequality rows with one
    # nonzero; every other merged row is a general row. pos[j]: row j's entry of DAQP's constraints, coef[j]: the
    # factor of its multiplier, side[j]: 0 an upper bound or an inequality row (mu >= 0), 1 a lower bound (mu <= 0),
    # 2 an equality row (mu free)
    has_upper, has_lower = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
    pos, coef, side = np.zeros(m, dtype=int), np.ones(m), np.full(m, 2)
    general: list[int] = []
    for j in first_rows:
        nz = np.flatnonzero(C[j])
        if not equality[j] and nz.size == 1:
            k, c = int(nz[0]), float(C[j, nz[0]])
            taken = has_upper if c > 0 else has_lower
            if not taken[k]:
                taken[k] = True
                pos[j], coef[j], side[j] = k, 1.0 / c, 0 if c > 0 else 1
                continue
        pos[j], side[j] = n + len(general), 2 if equality[j] else 0
        general.append(int(j))
    G = np.array(C[np.asarray(general, dtype=int)].reshape(-1, n), order="C")
    size = n + G.shape[0]
    is_eq = side[first_rows] == 2
    up = first_rows[side[first_rows] != 1]
    lo = first_rows[side[first_rows] >= 1]
    sense = np.zeros(size, dtype=np.int32)
    sense[pos[first_rows[is_eq]]] = 5
    rows = np.flatnonzero(reached)
    lead = first_rows[group[rows]]  # copies read their merged row's multiplier
    return AffineVI(np.array(P, order="C"), G, sense,
                    np.full(size, np.inf), pos[up], up, -coef[up], np.full(size, -np.inf), pos[lo], lo, -coef[lo],
                    rows, side[lead] * size + pos[lead], coef[lead], n)
