"""A primal-dual interior-point method on the KKT system of a GNE problem (the globalized method's robust phase).

With slacks w for the inequality rows, the concatenated KKT system [KKT_concatenated] is the constrained equation

    H(a, lambda, w) = ( L(a, lambda),  c_I(a) + w,  c_E(a),  lambda_I o w ) = 0,   lambda_I >= 0, w >= 0,

as in Dreves, Facchinei, Kanzow and Sagratella (SIAM J. Optim. 21, 2011). Every iterate stays strictly inside
(lambda_I, w > 0) and takes a Newton step towards H_eps = (L, c_I + w, c_E, lambda_I o w - eps) = 0, a point of
the central path; eps shrinks (by ``SHRINK``) once the residual of H_eps is below ``KAPPA`` eps, as in the
interior-point solver of MixedComplementarityProblems.jl (Nocedal and Wright, ch. 19). The Newton system is

    [ dL/da     dL/dlambda ] [ da      ]   [ -L                     ]
    [ dc/da     -D         ] [ dlambda ] = [ -(c_I + eps/lambda_I)  ]   (equality rows: -c_E, and D = 0)

with D = diag(w / lambda_I) and dw = eps/lambda_I - w - D dlambda_I. It stays nonsingular where the semismooth
Newton matrix is not (zero multipliers meeting active bounds, costs linear in a player's own variables, dependent
constraint gradients), because lambda_I and w are positive.

What makes it work on the field's games (``python -m benchmarks robustness``; the measurements behind each choice:
benchmarks/results/solver-design.md):

- **Each player's own block is made positive definite** (in its symmetric part), by the smallest multiple of the
  identity that does, like the inertia correction of interior-point methods for one nonconvex program (IPOPT):
  the direction is then a descent direction of every player's own barrier problem. Without it, trajectory games
  with nonlinear dynamics send the inputs far away.
- **Primal and dual variables take their own step lengths** to the boundary (``BOUNDARY`` of the way), so that a
  multiplier heading for zero does not hold up the decisions.
- **Multipliers start small**, at mu / max(w, 1) with mu = 1e-3 (``STARTS``): a multiplier of 1 on a constraint of
  a game whose costs are of order 1e-2 starts the method far from the central path. Where that stalls, the
  globalized method restarts with mu = 1e-4, then with mu scaled by the size of the pseudogradient (which says how
  large the multipliers must become: decisions starting at their bounds with gradients of 1e4, FK A.6 from 10).
- **Slacks start close**: at -c, or ``START_FLOOR`` = 0.1 where a row is violated or nearly active (not 1, which is
  ten times the size of a trajectory game's constraint values: collision distances and road margins of order 0.1),
  and the barrier target eps shrinks once every residual of H_eps is below ``KAPPA`` = 100 eps (the
  measurements that chose both: benchmarks/results/solver-design.md); below ``KAPPA_PLANS`` = 1000 eps in the
  decoupled game's solve and from its plans (:mod:`gnerun.solvers.hybrid`), near an equilibrium but for the rows
  that couple the players, and in the first start from a trajectory game's start near stationary.
- **No merit function**: every step is taken at its full length to the boundary (a potential-reduction line search
  and residual-based backtracking lost robustness on nonconvex games); instead, the globalized method
  (:mod:`gnerun.solvers.hybrid`) watches for stalls and restarts.
- **Mehrotra's predictor-corrector step where the last step went (nearly) all the way**, in the first start from
  z^0 (restarts and warm starts keep the monotone target: they are the safety net where it fails, as in FK A.4 from
  10 with the interior phase alone): at the start and after a step of at least ``PREDICT_AFTER`` = 0.9 of the
  Newton step, the affine-scaling direction (eps = 0) is solved first and the step aims at sigma mu - dlambda_aff o
  dw_aff, sigma = (mu_aff / mu)^3 at least ``CENTERING`` = 0.1 (Nocedal and Wright, alg. 14.3), unless the
  predictor goes less than ``PREDICTED`` = 5% of the way (then eps). After short steps, cut by the boundary one row
  at a time, the monotone target eps is kept: Mehrotra's target there lets the products lambda_i w_i spread and the
  primal step overshoot on nonconvex constraints (measured on ALGAMES's merges: benchmarks/results/solver-design.md).

- **Slack reset** (by the globalized method, far from a solution: :meth:`InteriorPoint.reset_slacks`): after a
  step, a row guessed inactive (lambda_j <= w_j) whose constraint lies further inside than its slack (-c_j > w_j:
  the linearisation of a concave constraint, such as a collision distance, underestimates how far inside a step
  goes) gets w_j = -c_j, its multiplier scaled to keep lambda_j w_j. Otherwise such a slack is driven towards zero
  by the linearisation and cuts the next steps at the boundary, one row at a time (ALGAMES's merges).

The linear algebra has the two forms of the semismooth Newton step: condensed (the inequality multipliers
eliminated, one dense factorisation of n unknowns and the equality multipliers; constraint rows with a single
nonzero, such as bounds, add to the diagonal) and sparse (the full-space system of a dynamic game with -D on its
multiplier block, factorised once per step by banded LU on the stage order, its inequality multipliers eliminated
first: a narrower band; the players' blocks of its Schur complement made positive definite in the same way, so that
both forms take the same direction).

Rows that no decision variable reaches (a condition on the plant state alone) take no part: their multipliers stay zero.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import lapack

from ..game import banded
from .linalg import factor, largest

BOUNDARY = 0.995  # a step goes at most this fraction of the way to the boundary lambda_I = 0 or w = 0
SHRINK = 0.2  # eps shrinks by this factor ...
KAPPA = 100.0  # ... once every residual of H_eps is below KAPPA eps
# ... or KAPPA_PLANS eps in the decoupled game's solve and from its plans (gnerun.solvers.hybrid): near the
# equilibrium but for the coupling rows, where the faster barrier saves a quarter of the steps (ALGAMES's merges);
# and in the first start from a trajectory game's start near stationary (the intersections: a third), given up
# after a few stalled steps: elsewhere it lets the overtaking game's steps cycle (benchmarks/results/solver-design.md)
KAPPA_PLANS = 1000.0
# lambda_i w_i starts at mu, times the size of the pseudogradient when scaled (it says how large the multipliers
# must become); one start after another: the globalized method restarts with the next when the phase stalls
STARTS = ((1e-3, False), (1e-4, False), (1e-2, True))
WARM = 1e-5  # lambda_i w_i at a warm start: a point near an equilibrium (see HybridNewton.restart)
START_FLOOR = 0.1  # slacks start at least this far inside
BOUND_PUSH = 1e-2  # decisions start at least this far (relative) inside their bounds
REGULARIZATION = 1e-10  # the first multiple of the identity tried where the Newton matrix is singular
PREDICT_AFTER = 0.9  # the first start, or a step of it that went at least this far, is followed by Mehrotra's
PREDICTED = 0.05  # predictor-corrector step where the predictor goes at least this fraction of the way, and
CENTERING = 0.1  # its centering parameter sigma is at least this
# the sparse form factorises K with its inequality multipliers eliminated (a narrower band; False: K as it is)
ELIMINATE = True
# the sparse form's step in one compiled call where its common case holds (gnerun.game.banded.InteriorStep: the same
# step to the bit; False: the numpy code always)
FUSED = True


@dataclass(slots=True)
class InteriorIterate:
    """(a, lambda, w) with lambda_I, w > 0, the target eps and how far the last step went."""

    z: np.ndarray  # (a, lambda) in the layout of the semismooth Newton iterate
    w: np.ndarray  # slacks of the inequality rows
    L: np.ndarray  # L(z)
    c: np.ndarray  # c(a)
    eps: float  # the target of lambda_i w_i
    t: float = 1.0  # the step length that led here (fraction of the Newton step)
    predict: bool = False  # whether this start takes Mehrotra's steps (its first start from z^0: InteriorPoint.step)
    kappa: float = KAPPA  # eps shrinks once H_eps is solved to kappa eps


class InteriorPoint:
    """Interior-point steps for the game of ``newton`` (a :class:`~gnerun.solvers.ssn.SemismoothNewton`, whose
    evaluations, condensed or sparse, it uses)."""

    def __init__(self, newton) -> None:
        self.newton = newton
        game = newton.game
        self.n = game.n
        fixed = newton._fixed  # rows no decision reaches (and rows a method leaves out: KKTSystem.without_rows)
        eq = game.equality_mask
        self.I = np.flatnonzero(~eq & ~fixed)
        self.E = np.flatnonzero(eq & ~fixed)
        self.fixed = np.flatnonzero(fixed)
        self.linear = DenseBarrier(self) if newton.condensed else SparseBarrier(newton.system, self)
        self._barrier = None  # the compiled bookkeeping (see _compiled)

    def start(self, z: np.ndarray, x: np.ndarray, attempt: int = 0,
              warm: bool = False) -> tuple[np.ndarray, np.ndarray, float]:
        """An interior start (z, w, eps) from z: decisions moved inside their bounds, slacks at least
        ``START_FLOOR``, multipliers at least mu / max(w, 1) (``STARTS[attempt]``, or ``WARM`` for a warm start), the
        rows no decision reaches at zero."""
        z = z.copy()
        n, I = self.n, self.I
        lo, hi = self.newton.game.a_lower, self.newton.game.a_upper
        push = np.minimum(BOUND_PUSH * np.maximum(1.0, np.abs(z[:n])), 0.5 * (hi - lo))
        z[:n] = np.clip(z[:n], lo + push, hi - push)
        bare = z.copy()
        bare[n:] = 0.0
        F, c = self.newton.kkt_residual(bare, x)  # the pseudogradient: how large the multipliers must become
        w = np.maximum(-c[I], START_FLOOR)
        w[~np.isfinite(w)] = START_FLOOR
        mu, scaled = (WARM, False) if warm else STARTS[attempt % len(STARTS)]
        if scaled:
            size = float(np.max(np.abs(F), initial=0.0))
            mu *= max(1.0, size) if math.isfinite(size) else 1.0
        lam = z[n + I]
        floor = mu / np.maximum(w, 1.0)
        z[n + I] = np.where(lam >= floor, lam, floor)  # NaN too
        z[n + self.fixed] = 0.0
        return z, w, mu

    def measure(self, z: np.ndarray, w: np.ndarray, L: np.ndarray, c: np.ndarray, eps: float,
                t: float = 1.0, predict: bool = False, kappa: float = KAPPA) -> InteriorIterate:
        """The iterate at (z, w) given L and c there; eps shrinks if H_eps is solved to ``kappa`` eps. ``predict``:
        Mehrotra's steps are taken from it (see :meth:`step`)."""
        compiled = self._compiled()
        if compiled:
            err = compiled.error(L, c, z, w, eps)
        else:
            I, E = self.I, self.E
            lw = z[self.n + I] * w
            err = max(largest(L), largest(c[I] + w), largest(c[E]), largest(lw - eps))
        return InteriorIterate(z, w, L, c, eps * SHRINK if err <= kappa * eps else eps, t, predict, kappa)

    def _compiled(self):
        """:meth:`measure`'s and :meth:`reset_slacks`' arithmetic compiled (:class:`gnerun.game.banded.Barrier`: the
        same numbers; made once), or False where nothing is compiled or ``FUSED`` is off."""
        if self._barrier is None:
            self._barrier = banded.barrier(self.n, self.I, self.E, self.n + self.newton.game.m) or False
        return self._barrier if FUSED else False

    def convex_at(self, it: InteriorIterate, parts) -> bool:
        """Whether every player's block of the barrier Newton matrix at ``it`` (``parts``: the derivatives there) is
        positive definite as it is, with no convexifying shift: near a KKT point with strictly complementary
        multipliers, second-order sufficiency for each player's own problem (the barrier terms hold the directions
        off the active rows' tangent space). The matrix is kept for the step from ``it``."""
        I = self.I
        return self.linear._factored(parts, it.w / it.z[self.n + I]).convex

    def reset_slacks(self, z: np.ndarray, w: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The slack reset after a step to (z, w) with c = c(a) there: a row guessed inactive (lambda_j <= w_j) whose
        constraint is further inside than its slack says (-c_j > w_j, as the linearisation of a concave constraint,
        a collision distance, underestimates) gets w_j = -c_j, and its multiplier is scaled by the old slack over
        the new, so that lambda_j w_j, the row's place on the central path, is kept. Returns (z, w), copies where
        changed."""
        compiled = self._compiled()
        if compiled:
            return compiled.reset(c, z, w)
        lam = z[self.n + self.I]
        inside = -c[self.I]
        reset = (inside > w) & (lam <= w) & np.isfinite(inside)
        if not reset.any():
            return z, w
        z, w = z.copy(), w.copy()
        rows = self.n + self.I[reset]
        z[rows] *= w[reset] / inside[reset]
        w[reset] = inside[reset]
        return z, w

    def step(self, it: InteriorIterate, parts) -> tuple[np.ndarray, np.ndarray, float, float] | tuple[None, str]:
        """The next point (z, w), the step length taken and the reciprocal condition number of the matrix
        factorised, from ``it`` (``parts``: the derivatives at it.z); or (None, why not). In an iterate that
        predicts (the first start from z^0), at the start and after a step that went at least ``PREDICT_AFTER`` of
        the way, the target of lambda_I o w is Mehrotra's (:meth:`_target`) where its predictor is not blocked."""
        n, I, E = self.n, self.I, self.E
        z, w = it.z, it.w
        lam = z[n + I]
        D = w / lam
        predict = bool(I.size and it.predict and it.t >= PREDICT_AFTER)
        fused = self.linear.fused(parts, it, lam, D, predict) if FUSED else None
        if fused is not None:
            return fused
        comp = it.eps  # the target of lambda_I o w, less a second-order correction
        if predict:
            target = self._target(parts, it, D)
            if isinstance(target, str):
                return None, target
            if target is not None:
                comp = target
        solved = self._direction(parts, it, D, -(it.c[I] + comp / lam))
        if isinstance(solved, str):
            return None, solved
        da, dlam, rcond = solved
        dw = comp / lam - w - D * dlam[I]
        t_p = _to_boundary(w, dw)
        t_d = _to_boundary(lam, dlam[I])
        z_new = z.copy()
        z_new[:n] += t_p * da
        z_new[n + I] += t_d * dlam[I]
        z_new[n + E] += t_d * dlam[E]
        return z_new, w + t_p * dw, min(t_p, t_d), rcond

    def _target(self, parts, it: InteriorIterate, D: np.ndarray) -> np.ndarray | str | None:
        """Mehrotra's predictor-corrector target (Nocedal and Wright, alg. 14.3): the affine-scaling direction
        (eps = 0) predicts how far complementarity can fall, mu_aff after the longest steps to the boundary; the
        step then aims at sigma mu - dlambda_aff o dw_aff with sigma = (mu_aff / mu)^3, at least ``CENTERING``.
        Returns the target per row; None where the predictor goes less than ``PREDICTED`` of the way (it says
        nothing there: the barrier's own target eps is kept); or why the prediction failed."""
        I = self.I
        w, lam = it.w, it.z[self.n + I]
        solved = self._direction(parts, it, D, -it.c[I])
        if isinstance(solved, str):
            return solved
        dlam = solved[1][I]
        dw = -w - D * dlam
        t_p, t_d = _to_boundary(w, dw, 1.0), _to_boundary(lam, dlam, 1.0)
        if min(t_p, t_d) < PREDICTED:
            return None
        mu = float(np.mean(lam * w))
        mu_aff = float(np.mean((w + t_p * dw) * (lam + t_d * dlam)))
        sigma = min(1.0, max(CENTERING, (mu_aff / mu) ** 3))
        return sigma * mu - dlam * dw

    def _direction(self, parts, it: InteriorIterate, D: np.ndarray,
                   rhs_I: np.ndarray) -> tuple[np.ndarray, np.ndarray, float] | str:
        """(da, dlambda, rcond) of the Newton system with right-hand side ``rhs_I`` on the inequality rows, the
        matrix regularised by a multiple of the identity where it is singular; or why there is none."""
        solve = self.linear.direction(parts, it, D, rhs_I)
        delta = 0.0
        while True:
            solved = solve(delta)
            if solved is not None:
                da, dlam, rcond = solved
                if np.isfinite(da).all() and np.isfinite(dlam).all():
                    return da, dlam, rcond
            delta = REGULARIZATION * self.linear.scale if delta == 0.0 else 100.0 * delta
            if not math.isfinite(delta):  # a matrix with an infinite entry: no shift helps
                return "the interior-point Newton matrix is not finite (an expression overflows here)"
            if delta > 1e10 * self.linear.scale:
                return "the interior-point Newton matrix is singular even when regularised"


def _to_boundary(v: np.ndarray, dv: np.ndarray, fraction: float = BOUNDARY) -> float:
    """``fraction`` times the largest t <= 1 with v + t dv >= 0 (v > 0), or 1."""
    neg = dv < 0
    if not neg.any():
        return 1.0
    return min(1.0, fraction * float((-v[neg] / dv[neg]).min()))


class DenseBarrier:
    """The interior-point Newton system of the condensed KKT system, with the inequality multipliers eliminated:

        (dL/da + dL/dlambda_I D^-1 dc_I/da) da + dL/dlambda_E dlambda_E = -L + dL/dlambda_I D^-1 rhs_I
        dc_E/da da = -c_E,      dlambda_I = D^-1 (dc_I/da da - rhs_I),

    each player's own block of the first matrix made positive definite (:func:`convexify`). Rows of dc/da with one
    nonzero (bounds, and any constraint on a single decision) add to the diagonal instead of a dense product.
    """

    def __init__(self, ip: InteriorPoint) -> None:
        self.ip = ip
        self.scale = 1.0
        self._pattern: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._by_column: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._key: tuple[np.ndarray, np.ndarray] | None = None  # the derivative arrays _cached was sliced from
        self._cached: tuple[np.ndarray, ...] = ()
        self._held: _Factored | None = None  # the last matrix factorised (see _factored)

    def _split(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Inequality rows whose gradient has a single structural nonzero (their positions in I, and their
        columns), and the others."""
        if self._pattern is None:
            game, I = self.ip.newton.game, self.ip.I
            rows, cols = game.pattern.constraint_nonzeros()
            count = np.bincount(rows, minlength=game.m)
            column = np.zeros(game.m, dtype=int)
            column[rows] = cols
            single = count[I] == 1
            self._pattern = (np.flatnonzero(single), column[I[single]], np.flatnonzero(~single))
        return self._pattern

    def _columns(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The single-nonzero rows ordered by their column, where each column's run starts, and the columns: the
        column update as one sum per column (a lower and an upper bound share theirs)."""
        if self._by_column is None:
            _, columns, _ = self._split()
            order = np.argsort(columns, kind="stable")
            targets, starts = np.unique(columns[order], return_index=True)
            self._by_column = (order, starts, targets)
        return self._by_column

    def _blocks(self, parts) -> tuple[np.ndarray, ...]:
        """The pieces of the derivatives the matrix is built from, sliced once per pair of derivative arrays (an
        LQ game's are the same arrays at every iterate): dL/da, dL/dlambda_I, its columns of the general rows
        and dc/da's rows there, its columns of the single-nonzero rows (ordered by column) and their nonzeros,
        dL/dlambda_E, dc_E/da and dc_I/da. Where each single-nonzero row enters its own column's Lagrangian only,
        the fifth is None and the sixth holds the diagonal entries B_jj g_j."""
        dL, dc = parts.dL_dz, parts.dc_da
        if self._key is not None and self._key[0] is dL and self._key[1] is dc:
            return self._cached
        ip = self.ip
        n, I, E = ip.n, ip.I, ip.E
        single, columns, general = self._split()
        order, _, _ = self._columns()
        B = dL[:, n:]
        rows_s = I[single[order]]
        cols_s = columns[order]
        B_single = B[:, rows_s]
        on_column = B_single[cols_s, np.arange(cols_s.size)]
        if np.count_nonzero(B_single) == np.count_nonzero(on_column):
            # each such row enters its own column's Lagrangian only (a bound, a player's constraint on its own
            # decision): the update is diagonal, its entries B_jj g_j / D_j summed per column
            B_single = None
        g = dc[rows_s, cols_s]
        self._cached = (dL[:, :n], B[:, I], B[:, I[general]], dc[I[general]], B_single,
                        g if B_single is not None else on_column * g, B[:, E], dc[E], dc[I])
        self._key = (dL, dc)
        return self._cached

    def _factored(self, parts, D: np.ndarray) -> _Factored:
        """The matrix at ``parts`` and ``D`` (its diagonal of S and its scale) with its factorisations per
        regularisation: kept for the next direction with the same matrix (Mehrotra's predictor and corrector)."""
        held = self._held
        if held is not None and held.holds(parts, parts.dL_dz, D):
            return held
        ip = self.ip
        n, E = ip.n, ip.E
        A, _, B_general, C_general, B_single, c_single, BE, CE, _ = self._blocks(parts)
        single, _, general = self._split()
        S = A.copy()
        if general.size:
            S += (B_general / D[general]) @ C_general
        if single.size:  # B_j D_j^-1 C_j with C_j = g_j e_col: a column update (one nonzero per row of C)
            order, starts, targets = self._columns()
            if B_single is None:  # c_single holds B_jj g_j
                S[targets, targets] += np.add.reduceat(c_single / D[single[order]], starts)
            else:
                S[:, targets] += np.add.reduceat(B_single * (c_single / D[single[order]]), starts, axis=1)
        convex = convexify(S, ip.newton.game.agent_slices)
        k = E.size
        M = np.empty((n + k, n + k))
        M[:n, :n] = S
        if k:
            M[:n, n:] = BE
            M[n:, :n] = CE
            M[n:, n:] = 0.0
        diag = np.diag(S).copy()
        scale = max(1.0, float(np.abs(diag).max(initial=0.0)))
        self._held = _Factored(parts, parts.dL_dz, D.copy(), diag, scale, {}, convex, M)
        return self._held

    def fused(self, parts, it: InteriorIterate, lam: np.ndarray, D: np.ndarray, predict: bool) -> None:
        """The condensed form has no compiled step (see :meth:`SparseBarrier.fused`)."""
        return None

    def direction(self, parts, it: InteriorIterate, D: np.ndarray, rhs_I: np.ndarray):
        ip = self.ip
        n, I, E = ip.n, ip.I, ip.E
        blocks = self._blocks(parts)
        BI, CI = blocks[1], blocks[8]
        held = self._factored(parts, D)
        M, diag = held.matrix, held.diagonal
        rhs_a = BI @ (rhs_I / D)
        rhs_a -= it.L
        rhs = np.concatenate([rhs_a, -it.c[E]]) if E.size else rhs_a
        self.scale = held.scale
        idx = np.arange(n)

        def solve(delta: float):
            if held.delta != delta:
                M[idx, idx] = diag + delta if delta else diag
                held.delta = delta
            entry = held.factors.get(delta)
            if entry is None:
                entry = held.factors[delta] = factor(M)
            lu, piv, info, rcond = entry
            if info != 0 or not rcond > 0.0:
                return None
            sol, _ = lapack.dgetrs(lu, piv, rhs)
            if rcond < 1e-8:  # one step of iterative refinement where the matrix is ill-conditioned
                fix, _ = lapack.dgetrs(lu, piv, rhs - M @ sol)
                sol += fix
            da = sol[:n]
            dlam = np.zeros(ip.newton.game.m)
            dlam[I] = (CI @ da - rhs_I) / D
            dlam[E] = sol[n:]
            return da, dlam, rcond

        return solve


class SparseBarrier:
    """The interior-point Newton system in the sparse formulation of a dynamic game: the full-space matrix K of
    (a, xi, p, lambda) with -D on the inequality multipliers' diagonal, factorised once per step (banded LU on the
    stage order, or SuperLU: :meth:`~gnerun.game.sparse.SparseKKT.factor_kept`), where ``ELIMINATE`` with the
    inequality multipliers eliminated first (:class:`~gnerun.game.sparse.Elimination`: K_rest + K_r,lam D^-1 K_lam,r;
    on ALGAMES's merge 600 unknowns and a band of (18, 18) instead of 780 and (18, 27)). Its Schur complement on
    (a, lambda_E) is the condensed matrix, as for the semismooth Newton step; each player's own block of that
    complement is made positive definite as in the condensed form (:func:`convexify`), by a shift of the player's
    diagonal in K (which shifts the complement's block by the same), so both forms take the same direction.

    Player i's block S_ii = K_ii + K_iR y, where K_RR y = -K_Ri over what the complement eliminates
    (R: states, costates, inequality multipliers), is found stage-structured, without factorising K_RR: the
    dynamics' rows give the states' response to a_i (a banded triangular solve: -I on the diagonal, the dynamics'
    Jacobian below it), the inequality rows the multipliers' (a division by D), and agent i's costate rows its
    costates' response (the transposed solve); K_iR touches no other agent's costates. The sub-blocks of K are
    gathered from its nonzeros into arrays and sparse matrices built once (the pattern is fixed)."""

    def __init__(self, system, ip: InteriorPoint) -> None:
        self.system = system
        self.ip = ip
        size, m, n = system.size, system.m, ip.n
        self.lam0 = size - m
        keep = np.ones(size, dtype=bool)
        keep[self.lam0 + ip.fixed] = False
        self.keep = np.flatnonzero(keep)
        # the diagonal entries added to K (in keep): the decisions' shifts, then -D on the inequality multipliers
        self.at = np.concatenate([np.arange(n), np.searchsorted(self.keep, self.lam0 + ip.I)])
        self.multipliers = self.at[n:]  # the inequality multipliers (eliminated first where ELIMINATE)
        self._templates: _AgentBlocks | None = None
        self._diagonal: np.ndarray | None = None
        self._held: _Factored | None = None  # the last matrix factorised (see _factored)
        self._layouts: dict[bool, object] = {}  # per ELIMINATE, the matrix's layout (see _layout)
        self._steps: dict[bool, object] = {}  # per ELIMINATE, the compiled step (see _step; False: none)
        self._undecided: tuple | None = None  # (J's nonzeros, D) where the compiled step's recursion said "not all"

    def _layout(self):
        """The layout of the matrix factorised (:meth:`~gnerun.game.sparse.SparseKKT.layout`), held: its rows,
        columns and diagonal additions are the same at every step."""
        layout = self._layouts.get(ELIMINATE)
        if layout is None:
            layout = self._layouts[ELIMINATE] = self.system.layout(self.keep, self.at,
                                                                   self.multipliers if ELIMINATE else None)
        return layout

    @property
    def scale(self) -> float:
        """The condensed form's scale of the last matrix factorised, the one of the last direction (what its
        regularisation is a multiple of): the largest diagonal entry of its shifted Schur complement, at least 1;
        made from the dense players' blocks when first asked for where the stage recursion found every block positive
        definite (:class:`_StageRecursion`)."""
        held = self._held
        if held is None:
            return 1.0
        if held.scale is None:
            found = self._blocks().shifts(held.data, held.D, recursion=False)
            held.scale = 1.0 if found is None else found[1]
        return held.scale

    def _blocks(self) -> _AgentBlocks:
        """The sub-blocks of K that the players' blocks of the complement are built from: sliced once per system and
        inequality rows, and kept with the system (10-14 ms on ALGAMES's merge: half a solve's time when every draw
        of a Monte Carlo, every point of a sweep or every certificate's restart built them anew)."""
        if self._templates is None:
            kept, key = self.system.agent_blocks, self.ip.I.tobytes()
            if key not in kept:
                kept[key] = self._build_blocks()
            self._templates, self._diagonal = kept[key]
        return self._templates

    def _build_blocks(self) -> tuple[_AgentBlocks, np.ndarray]:
        """The players' block templates, and where K's diagonal entries of the decisions are among its nonzeros."""
        import scipy.sparse as sp  # loaded by the sparse formulation only

        ip, system = self.ip, self.system
        n, S, lam0 = ip.n, system.S, self.lam0
        P = lam0 - n - S
        lam_I = lam0 + ip.I
        pattern = system.pattern
        # the pattern with its nonzeros numbered from 1 (a slice of it says which nonzeros it holds)
        numbered = sp.csc_matrix((np.arange(1, pattern.nnz + 1, dtype=float), pattern.indices, pattern.indptr),
                                 shape=pattern.shape)
        agents = []
        for ai, pi, own in zip(ip.newton.game.agent_slices, system.costates, system.states, strict=True):
            a_cols = np.arange(ai.start, ai.stop)
            g_rows, p_cols = np.arange(n + pi.start, n + pi.stop), np.arange(n + S + pi.start, n + S + pi.stop)
            agents.append((n + P + own, n + own, a_cols, g_rows, p_cols))
        row_stage, _, col_stage, _ = system.stage_order.stages
        templates = _AgentBlocks(numbered, agents, lam_I, (row_stage, col_stage))
        # where K's diagonal entries of the decisions are among its nonzeros (-1: not in the pattern)
        diagonal = numbered.diagonal()[:n].astype(np.int64) - 1
        return templates, diagonal

    def _shifts(self, data: np.ndarray, D: np.ndarray) -> tuple[np.ndarray, float] | None:
        """Per decision, the shift that makes its player's block of the Schur complement positive definite, and
        the largest diagonal entry of the shifted complement (the condensed form's scale); ``None`` if a
        dynamics block is singular (then no shift). ``data``: K's nonzeros without -D."""
        ip = self.ip
        undecided = self._undecided
        self._undecided = None
        # (where the compiled step's recursion has just said "not every block", the dense blocks at once)
        found = self._blocks().shifts(data, D, recursion=not (undecided is not None and undecided[0] is data
                                                               and undecided[1] is D))
        if found is None:
            return None
        deltas, scale = found
        shift = np.zeros(ip.n)
        for ai, delta in zip(ip.newton.game.agent_slices, deltas, strict=True):
            shift[ai] = delta
        return shift, scale

    def _factored(self, parts, D: np.ndarray) -> _Factored:
        """The shifts and the factorisations (per regularisation) of the matrix at ``parts`` and ``D``: kept for
        the next direction with the same matrix (Mehrotra's predictor and corrector solve with one matrix)."""
        held = self._held
        if held is not None and held.holds(parts, parts.J, D):
            return held
        found = self._shifts(parts.J, D)
        shifts = np.zeros(self.ip.n)
        if found is None:  # a singular dynamics block: no shifts, and no statement on the players' curvature
            at = self._diagonal
            diagonal = np.where(at >= 0, parts.J[at], 0.0)
            scale = max(1.0, float(np.max(np.abs(diagonal), initial=0.0)))
        else:
            shifts, scale = found
        convex = found is not None and not shifts.any()
        self._held = _Factored(parts, parts.J, D.copy(), shifts, scale, {}, convex)
        return self._held

    def fused(self, parts, it: InteriorIterate, lam: np.ndarray, D: np.ndarray,
              predict: bool) -> tuple[np.ndarray, np.ndarray, float, float] | None:
        """:meth:`InteriorPoint.step`'s result (z, w, t, rcond: NaN, as the step's factorisation makes no estimate) by
        one compiled call (:class:`gnerun.game.banded.InteriorStep`), the same to the bit; None where its common case
        does not hold or nothing is compiled (the numpy code takes the step). The matrix it factorised is held as
        :meth:`_factored` holds it (no shifts), its factors not kept: a later direction with it factorises again,
        to the same values."""
        step = self._step()
        held = self._held
        if step is None or (held is not None and held.holds(parts, parts.J, D)):
            return None
        found = step(parts.J, parts.F, it.c, it.z, it.w, lam, D, it.eps, predict)
        if isinstance(found, int):
            # the recursion did not find every block positive definite: the numpy code's blocks decide at once
            self._undecided = (parts.J, D) if found == 1 else None
            return None
        self._held = _Factored(parts, parts.J, D.copy(), np.zeros(self.ip.n), None, {}, True)
        z, w, t = found
        return z, w, t, math.nan

    def _step(self):
        """The compiled step for this barrier's layout (built once; None where there is none: no compiler, no stage
        recursion, SuperLU's layout, no inequality rows, or K factorised as it is)."""
        step = self._steps.get(ELIMINATE)
        if step is None:
            step = self._steps[ELIMINATE] = self._build_step() or False
        return step or None

    def _build_step(self):
        """The compiled step's positions and sizes (:func:`gnerun.game.banded.interior_step`), or None."""
        ip, system = self.ip, self.system
        if not ELIMINATE or not ip.I.size:
            return None
        definite = self._blocks()._definite
        layout = self._layout()
        e = layout.elimination
        if definite is None or not layout.banded or e is None or not layout.size or (
                layout.lower >= 32 and layout.upper > 64):
            return None
        ix = [self.keep, ip.I, ip.E, layout.nonzeros, layout.flat, layout.flat_at, layout.flat_fill, e.add_kept,
              e.diagonal_at, e.pair_re, e.pair_er, e.pair_out, e.pair_entry, e.re[0], e.er[0], e.rest, e.out,
              e.re[1], e.re[2], e.er[1], e.er[2], layout.row_order, layout.col_order]
        dims = [ip.n, system.size, self.lam0, self.keep.size, ip.I.size, ip.E.size, layout.nonzeros.size,
                layout.flat_at.size, e.fill_r.size, e.pair_entry.size, e.out.size, e.re[0].size, e.er[0].size,
                e.rest.size, layout.lower, layout.upper, layout.ld, definite._agents, definite._work, 0,
                ip.n + ip.I.size, system.m]
        return banded.interior_step(dims, ix, definite, (BOUNDARY, PREDICTED, CENTERING, e.refine_from))

    def direction(self, parts, it: InteriorIterate, D: np.ndarray, rhs_I: np.ndarray):
        ip, system = self.ip, self.system
        n, I, E, lam0, keep = ip.n, ip.I, ip.E, self.lam0, self.keep
        rhs = -parts.F.copy()
        rhs[lam0 + I] = rhs_I
        rhs[lam0 + E] = -it.c[E]
        rhs = rhs[keep]
        held = self._factored(parts, D)

        def solve(delta: float):
            entry = held.factors.get(delta)
            if entry is None:
                add = np.concatenate([held.diagonal + delta if delta else held.diagonal, -held.D])
                # no condition estimate (it was 18% of a merge iteration): the step needs the factors only; a
                # singular matrix has no factors, and a solution that overflows is refused like one
                entry = held.factors[delta] = system.factor_layout("interior", self._layout(), parts.J, add,
                                                                   estimate=False)
            lu, rcond = entry
            if lu is None:
                return None
            sol = np.zeros(system.size)
            sol[keep] = lu.solve(rhs)
            if not np.isfinite(sol).all():
                return None
            dlam = np.zeros(system.m)
            dlam[I] = sol[lam0 + I]
            dlam[E] = sol[lam0 + E]
            return sol[:n], dlam, rcond

        return solve


@dataclass(slots=True)
class _Factored:
    """A barrier matrix by the derivatives and D it was built from (``parts`` and its array ``data``: identity,
    D: values), with what its factorisations are built from (the sparse form: the players' shifts; the dense form:
    the diagonal of S and the matrix, whose diagonal holds ``delta`` more), its scale and its factorisations per
    regularisation delta."""

    parts: object
    data: np.ndarray
    D: np.ndarray
    diagonal: np.ndarray
    scale: float | None  # None: not made yet (SparseBarrier.scale makes it when asked for)
    factors: dict
    convex: bool  # every player's block was positive definite as it was (no shift)
    matrix: np.ndarray | None = None
    delta: float = 0.0

    def holds(self, parts, data: np.ndarray, D: np.ndarray) -> bool:
        """Whether this is the matrix of ``parts`` (the same object and array) and ``D`` (the same values)."""
        return self.parts is parts and self.data is data and np.array_equal(self.D, D)


class _AgentBlocks:
    """The agents' sub-blocks of K, by each agent's dynamics rows (d), states (x), decisions (a), costate rows (g),
    costates (p) and the inequality multipliers (l) of the rows it touches: D_x (banded lower triangular), D_a, then
    [C; G; A] x (x, a) and [G; A] x l stacked, and A x p, each gathered from K's nonzeros (``numbered``: the pattern
    with its nonzeros numbered 1, 2, ...; ``agents``: per agent (d, x, a, g, p) as indices into K).

    All agents are stacked block-diagonally (agent after agent in every kind of row and column; the decisions'
    columns of each agent from the first, as many as the agent with the most has), so that one triangular solve and
    one product serve every agent: the per-agent calls cost more than their arithmetic. The blocks are zero between
    agents, so each agent's entries are computed by the same operations as on its own."""

    def __init__(self, numbered, agents: list[tuple[np.ndarray, ...]], lam_I: np.ndarray,
                 stages: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        # the stage recursion (None where K has not the structure, or nothing is compiled)
        self._definite = None if stages is None else _StageRecursion.build(numbered, agents, lam_I, *stages)
        self.states = np.array([x.size for _, x, _, _, _ in agents])
        self.decisions = np.array([a.size for _, _, a, _, _ in agents])
        width = dmax = 0
        touched_all, lams, bands = [], [], []
        for d_rows, x_cols, a_cols, g_rows, p_cols in agents:
            if not g_rows.size == p_cols.size == x_cols.size:  # an agent's costates are those of its states
                raise AssertionError("an agent's costates do not match its states in the sparse system")
            # the inequality rows that involve the agent's states or decisions, or whose multipliers enter its rows:
            # the others' multipliers do not respond to its decisions
            touched = numbered[lam_I][:, np.concatenate([x_cols, a_cols])].getnnz(axis=1) > 0
            touched |= numbered[np.concatenate([g_rows, a_cols])][:, lam_I].getnnz(axis=0) > 0
            touched_all.append(np.flatnonzero(touched))
            lams.append(lam_I[touched])
            Dx = numbered[d_rows][:, x_cols].tocoo()
            below = Dx.row - Dx.col
            diagonal = np.zeros(x_cols.size, dtype=bool)
            diagonal[Dx.row[below == 0]] = True
            # the defects f(xi(tau), u) - xi(tau + 1), stage-major: -I on the diagonal, the dynamics' Jacobian below
            if not (np.all(below >= 0) and diagonal.all()):
                raise AssertionError("the dynamics' block of the sparse system is not lower triangular")
            bands.append((Dx.col, below, Dx.data))
            width = max(width, int(below.max(initial=0)))
            dmax = max(dmax, a_cols.size)
        self.width, self.columns = width, dmax
        self.touched = np.concatenate(touched_all)
        self.counts = (self.touched.size, int(self.states.sum()))  # the rows of C and of G stacked
        # the band of D_x for the triangular solves: row i holds column i of D_x from its diagonal down
        start = np.cumsum(self.states) - self.states
        self._band = (np.concatenate([(col + at) * (width + 1) + below
                                      for (col, below, _), at in zip(bands, start, strict=True)]),
                      np.concatenate([data for _, _, data in bands]).astype(np.int64) - 1)
        d, x, a, g, p = ([agent[k] for agent in agents] for k in range(5))
        x_at = np.concatenate([[0], np.cumsum(self.states)])  # each agent's columns of states (and costates)
        l_at = np.concatenate([[0], np.cumsum([lam.size for lam in lams])])  # and of multipliers
        stacked = [*lams, *g, *a]
        agent = [*range(len(agents))] * 3
        self._Da = _Gather(numbered, [(d[i], a[i], 0) for i in range(len(agents))])
        self._Ka = _Gather(numbered, [(r, a[i], 0) for r, i in zip(stacked, agent, strict=True)])
        self._Kx = _Product(numbered, [(r, x[i], x_at[i]) for r, i in zip(stacked, agent, strict=True)])
        self._Kl = _Product(numbered, [(r, lams[i], l_at[i]) for r, i in zip([*g, *a], agent[:2 * len(agents)],
                                                                                strict=True)])
        self._Ap = _Product(numbered, [(a[i], p[i], x_at[i]) for i in range(len(agents))])
        self._rows = np.concatenate([[0], np.cumsum(self.decisions)])  # each agent's rows of the result
        self._compiled = None  # gnerun.game.banded.PlayersComplement, False where it is not used (see _stacked)
        self.compiled = False  # whether the last call was computed by it
        self._compiled_shifts: bool | None = None  # whether the compiled shifts agree with numpy's (None: not asked)

    def complement(self, data: np.ndarray, D: np.ndarray) -> list[np.ndarray] | None:
        """Each agent's block of the Schur complement, or None if some D_x is singular. The triangular solves are
        :mod:`gnerun.game.banded`'s, LAPACK's arithmetic on all right-hand sides at once: the same bits (a loop
        that rounds otherwise, without LAPACK's fused multiply-adds, changed a best response the certificate finds
        on one of ten ALGAMES merges)."""
        K = self._stacked(data, D)
        return None if K is None else self._split(K)

    def _split(self, K: np.ndarray) -> list[np.ndarray]:
        """Each agent's block of the stacked result K (views: K is new at every call)."""
        S, rows = K[self.counts[0] + self.counts[1]:], self._rows
        return [S[rows[i]:rows[i + 1], :k] for i, k in enumerate(self.decisions)]

    def shifts(self, data: np.ndarray, D: np.ndarray,
               recursion: bool = True) -> tuple[list[float], float | None] | None:
        """Each agent's :func:`convexifying_shift` of its block, and the largest |diagonal entry + shift| over all
        blocks, at least 1; None if some D_x is singular. Compiled with the complement (the same dpotrf), once its
        first result equals numpy's, else numpy's. Where the stage recursion (``recursion``) finds every block
        positive definite, no block is formed: the shifts are zero, and the scale None (made when asked for)."""
        if recursion and self._definite is not None and self._definite(data, D) == 1:
            return [0.0] * self.decisions.size, None
        K = self._stacked(data, D)
        if K is None:
            return None
        if self._compiled and self._compiled_shifts is not False:
            found = self._compiled.shifts(K)
            if found is not None and self._compiled_shifts is None:  # the first: compared with numpy's
                self._compiled_shifts = found == self._numpy_shifts(K)
            if found is not None and self._compiled_shifts:
                return found
            self._compiled_shifts = False
        return self._numpy_shifts(K)

    def _numpy_shifts(self, K: np.ndarray) -> tuple[list[float], float]:
        blocks = self._split(K)
        deltas = [convexifying_shift(block) for block in blocks]
        diagonal = np.concatenate([np.diagonal(block) for block in blocks]) + np.repeat(deltas, self.decisions)
        return deltas, max(1.0, float(np.max(np.abs(diagonal), initial=0.0)))

    def _stacked(self, data: np.ndarray, D: np.ndarray) -> np.ndarray | None:
        """[Y_lambda; Y_p; S] (S: the agents' blocks stacked), or None if some D_x is singular: by
        :class:`gnerun.game.banded.PlayersComplement` (the same operations in C, less those that add a zero, 2-3x
        faster on the merges), once its first result equals :meth:`_numpy`'s values bit for bit (a zero's sign aside),
        else by :meth:`_numpy`."""
        compiled = self._compiled
        if compiled is None:
            nI, ng = self.counts
            dims = (ng, self.columns, self.width, nI, int(self.decisions.sum()))
            parts = [self._Da.flat, self._Da.positions, *self._band,
                     *(getattr(self._Kx.matrix, k) for k in ("indptr", "indices")), self._Kx.positions,
                     self._Ka.flat, self._Ka.positions, self.touched,
                     *(getattr(self._Kl.matrix, k) for k in ("indptr", "indices")), self._Kl.positions,
                     *(getattr(self._Ap.matrix, k) for k in ("indptr", "indices")), self._Ap.positions]
            compiled = banded.players_complement(dims, parts, self._rows[:-1], self.decisions)
            if compiled is not None:
                ours, reference = compiled(data, D), self._numpy(data, D)
                if (ours is None and reference is None) or ours is False:  # nothing to compare: the next call compares
                    self.compiled = False
                    return reference
                if ours is None or reference is None or not np.array_equal(ours, reference):  # a zero's sign aside
                    compiled = None
            self._compiled = compiled if compiled is not None else False
        self.compiled = bool(compiled)
        if compiled:
            K = compiled(data, D)
            if K is not False:
                return K
            self.compiled = False  # a value that is not finite where the compiled code skips zeros
        return self._numpy(data, D)

    def _numpy(self, data: np.ndarray, D: np.ndarray) -> np.ndarray | None:
        """:meth:`_stacked` by numpy and scipy.sparse. (In place where it can: the arrays are of the size of all
        agents' states times decisions, and allocating and adding them costs more than the products; every entry
        is the same sum, in the same order, as without.)"""
        nI, ng = self.counts
        Yx = self._Da.dense(data, -1.0)
        if ng:
            band = np.zeros((ng, self.width + 1))
            flat, positions = self._band
            band.reshape(-1)[flat] = data[positions]
            if banded.solve(band, Yx) != 0:  # a zero on the diagonal
                return None
        K = self._Kx(data) @ Yx  # [C; G; A] Y_x, then plus [C; G; A]_a
        self._Ka.add_to(K, data)
        Ylam = K[:nI]
        Ylam /= D[self.touched, None]
        LY = self._Kl(data) @ Ylam
        G = K[nI:nI + ng]
        G += LY[:ng]
        np.negative(G, out=G)  # the right-hand side of the costates' equations
        if ng:
            banded.solve(band, G, transpose=True)  # in place: G becomes Y_p
        S = K[nI + ng:]
        S += self._Ap(data) @ G
        S += LY[ng:]
        return K


class _StageRecursion:
    """Whether every player's block of the Schur complement is positive definite, by a recursion over each player's
    stages instead of the dense blocks (:func:`gnerun.game.banded.players_definite`, in C): the block is the reduced
    Hessian of the player's barrier Lagrangian on its dynamics. Its unknowns grouped by stage as (u(t), x(t), x(t+1))
    (the sparse system's stage order; x(0) is the plant state), with the group's Hessian (the symmetric part of K's
    entries between the group's rows, u(t) and the states' costate rows, and its columns, plus C' D^-1 C over the
    multipliers the player carries) and the dynamics' rows (-I on x(t+1), A_t on x(t), B_t on u(t)), a Riccati
    recursion from the last stage tests one u(t)-block each: on ALGAMES's merges and intersections and the overtaking
    game it decides as the dense blocks' Cholesky factorisations do, in a fifth to a half of their time
    (benchmarks/results/solver-design.md). Built only where every player's K has that structure (each Hessian entry
    and each carried multiplier's row within one stage's group, the dynamics' rows as above); None otherwise. Its
    answer is used where it is "every block positive definite": then no player is shifted, as the dense test would
    find; elsewhere the dense blocks decide."""

    @classmethod
    def build(cls, numbered, agents: list[tuple[np.ndarray, ...]], lam_I: np.ndarray, row_stage: np.ndarray,
              col_stage: np.ndarray):
        parts = []
        for d_rows, x_cols, a_cols, g_rows, _ in agents:
            part = cls._player(numbered, d_rows, x_cols, a_cols, g_rows, lam_I, row_stage, col_stage)
            if part is None:
                return None
            parts.append(part)
        # each part: T, nu, nx, then the position arrays in players_definite's order (H's entries per stage, their
        # places, their positions, B, A, the dynamics' diagonal, the terms' stages, multipliers, columns and rows)
        dims = np.array([[part[0], part[1], part[2], part[9].size] for part in parts], dtype=np.int64)
        ix = [np.concatenate([part[k].reshape(-1) for part in parts]) for k in range(3, 13)]
        m, nu, nx = int((dims[:, 1] + 2 * dims[:, 2]).max()), int(dims[:, 1].max()), int(dims[:, 2].max())
        work = 4 * nx * nx + m * m + nu * nu + 4 * nu * nx + 1
        return banded.players_definite(dims.reshape(-1), ix, work)

    @staticmethod
    def _player(numbered, d_rows, x_cols, a_cols, g_rows, lam_I, row_stage, col_stage):
        """(T, nu, nx, and the position arrays of ``players_definite`` for one player), or None where its K does not
        have the stage structure. Stage t's local unknowns are (u(t), x(t), x(t+1)) (x(0) is the plant state, not an
        unknown): every Hessian entry and every carried row lies in one such group, or there is no recursion."""
        T = int(col_stage[a_cols].max(initial=-1)) + 1
        if T <= 0 or a_cols.size % T or x_cols.size % T or d_rows.size != x_cols.size or g_rows.size != x_cols.size:
            return None
        nu, nx = a_cols.size // T, x_cols.size // T
        stage_u, stage_x = np.repeat(np.arange(T), nu), np.repeat(np.arange(T), nx)
        if not (np.array_equal(col_stage[a_cols], stage_u) and np.array_equal(col_stage[x_cols], stage_x)
                and np.array_equal(row_stage[d_rows], stage_x) and np.array_equal(row_stage[g_rows], stage_x)):
            return None
        mz = nu + 2 * nx
        # the player's unknowns (its decisions' rows and columns, then its states' costate rows and columns): kind
        # (0: u(t), 1: x(s), s = t + 1 for the states of stage t), time and component
        kind = np.concatenate([np.zeros(a_cols.size, dtype=np.int64), np.ones(x_cols.size, dtype=np.int64)])
        time = np.concatenate([stage_u, stage_x + 1])
        comp = np.concatenate([np.tile(np.arange(nu), T), np.tile(np.arange(nx), T)])

        def place(k, tau, c, t):
            """Where unknowns sit in stage t's group (u(t), x(t), x(t+1)); -1 where outside it."""
            return np.where(k == 0, np.where(tau == t, c, -1),
                            np.where(tau == t, nu + c, np.where(tau == t + 1, nu + nx + c, -1)))

        def group(u, tau_u, tau_last):
            """The group of a set of unknowns: the stage of its decisions (``u``: it has some, at ``tau_u``), of
            states alone the group where the latest (``tau_last``) is x(t+1)."""
            return np.where(u, tau_u, tau_last - 1)

        rows, cols = np.concatenate([a_cols, g_rows]), np.concatenate([a_cols, x_cols])
        hh = numbered[rows][:, cols].tocoo()
        r, c, number = hh.row, hh.col, hh.data.astype(np.int64) - 1
        t = group((kind[r] == 0) | (kind[c] == 0), np.where(kind[r] == 0, time[r], time[c]), np.maximum(time[r],
                                                                                                     time[c]))
        i, j = place(kind[r], time[r], comp[r], t), place(kind[c], time[c], comp[c], t)
        if not np.all((t >= 0) & (t < T) & (i >= 0) & (j >= 0)):  # a Hessian entry between two stages' groups
            return None
        H = np.full((T, mz, mz), -1, dtype=np.int64)
        H[t, i, j] = number
        # the dynamics f(x(t), u(t)) - x(t+1): B on u(t), A on x(t), -I on x(t+1), nothing else of the player's
        dd = numbered[d_rows][:, cols].tocoo()
        r, c, number = dd.row, dd.col, dd.data.astype(np.int64) - 1
        t, i = stage_x[r], comp[a_cols.size + r]
        on_u = (kind[c] == 0) & (time[c] == t)
        on_x = (kind[c] == 1) & (time[c] == t) & (t > 0)
        on_y = (kind[c] == 1) & (time[c] == t + 1) & (comp[c] == i)
        if not np.all(on_u | on_x | on_y):
            return None
        B = np.full((T, nx, nu), -1, dtype=np.int64)
        A = np.full((T, nx, nx), -1, dtype=np.int64)
        diag = np.full((T, nx), -1, dtype=np.int64)
        B[t[on_u], i[on_u], comp[c[on_u]]] = number[on_u]
        A[t[on_x], i[on_x], comp[c[on_x]]] = number[on_x]
        diag[t[on_y], i[on_y]] = number[on_y]
        # the multipliers the player carries (its rows have their columns), each within one stage's group: its column
        # over the player's rows and its row over the player's columns, placed in the group's order
        carried = np.flatnonzero(numbered[rows][:, lam_I].getnnz(axis=0) > 0)
        col = numbered[rows][:, lam_I[carried]].toarray().astype(np.int64).T - 1
        row = numbered[lam_I[carried]][:, cols].toarray().astype(np.int64) - 1
        support = (col >= 0) | (row >= 0)
        u = support & (kind == 0)
        t = group(u.any(axis=1), np.where(u, time, -1).max(axis=1, initial=-1),
                  np.where(support, time, -1).max(axis=1, initial=-1))
        at = place(kind, time, comp, t[:, None])
        if not (np.all((t >= 0) & (t < T)) and np.all(~support | (at >= 0))):
            return None
        tc, tr = np.full((carried.size, mz), -1, dtype=np.int64), np.full((carried.size, mz), -1, dtype=np.int64)
        k, e = np.nonzero(col >= 0)
        tc[k, at[k, e]] = col[k, e]
        k, e = np.nonzero(row >= 0)
        tr[k, at[k, e]] = row[k, e]
        order = np.argsort(t, kind="stable")  # by stage
        tg, td, tc, tr = t[order].astype(np.int64), carried[order].astype(np.int64), tc[order], tr[order]
        # H's entries there are, stage by stage: how many, where in the group's matrix, where in K's nonzeros
        flat = H.reshape(T, -1)
        there = flat >= 0
        return (T, nu, nx, there.sum(axis=1), np.nonzero(there)[1], flat[there], B, A, diag, tg, td, tc, tr)


def _placed(numbered, blocks: list[tuple[np.ndarray, np.ndarray, int]]):
    """Sub-blocks (rows, cols) of a fixed sparsity pattern (``numbered``: the pattern with its nonzeros numbered 1,
    2, ...), one below the other, each from its column ``offset`` on: their nonzeros' (rows, cols, positions in the
    pattern's data), and the shape of the whole."""
    rows, cols, numbers = [], [], []
    top = width = 0
    for r, c, offset in blocks:
        sub = numbered[r][:, c].tocoo()
        rows.append(sub.row + top)
        cols.append(sub.col + offset)
        numbers.append(sub.data)
        top += r.size
        width = max(width, offset + c.size)
    return (np.concatenate(rows).astype(np.int64), np.concatenate(cols).astype(np.int64),
            np.concatenate(numbers).astype(np.int64) - 1), (top, width)


class _Product:
    """Sub-blocks of a fixed sparsity pattern placed as :func:`_placed` says, as a sparse matrix built once, its
    values refreshed from the pattern's nonzeros at every call (building a sparse matrix costs more than the product
    it serves)."""

    def __init__(self, numbered, blocks: list[tuple[np.ndarray, np.ndarray, int]]) -> None:
        import scipy.sparse as sp  # loaded by the sparse formulation only

        (rows, cols, positions), shape = _placed(numbered, blocks)
        self.matrix = sp.csr_matrix((positions + 1.0, (rows, cols)), shape=shape)
        self.matrix.sort_indices()
        self.positions = self.matrix.data.astype(np.int64) - 1

    def __call__(self, data: np.ndarray):
        self.matrix.data[:] = data[self.positions]
        return self.matrix


class _Gather:
    """Sub-blocks of a fixed sparsity pattern placed as :func:`_placed` says, as a dense array rebuilt from the
    pattern's nonzeros by a gather (sparse slicing at every call costs more than the arithmetic it serves)."""

    def __init__(self, numbered, blocks: list[tuple[np.ndarray, np.ndarray, int]]) -> None:
        (rows, cols, self.positions), self.shape = _placed(numbered, blocks)
        self.flat = rows * self.shape[1] + cols  # where in the C-ordered array (one index: half the cost of two)

    def dense(self, data: np.ndarray, sign: float = 1.0) -> np.ndarray:
        """The blocks (times ``sign``)."""
        out = np.zeros(self.shape)
        out.reshape(-1)[self.flat] = data[self.positions] if sign == 1.0 else sign * data[self.positions]
        return out

    def add_to(self, out: np.ndarray, data: np.ndarray) -> None:
        """``out`` (C-ordered) += the blocks, in place (each entry once: the positions are distinct)."""
        np.reshape(out, -1, copy=False)[self.flat] += data[self.positions]


def convexify(S: np.ndarray, blocks: list[slice]) -> bool:
    """Make each player's own block of the barrier Newton matrix positive definite (in its symmetric part), in
    place, by adding the smallest multiple of the identity (from 1e-8 of the block's scale, times 10) that does:
    the direction is then a descent direction of every player's own barrier problem. Convex players' blocks are
    left as they are. Returns whether every block was left as it was."""
    convex = True
    for sl in blocks:
        delta = convexifying_shift(S[sl, sl])
        if delta:
            idx = np.arange(sl.start, sl.stop)
            S[idx, idx] += delta
            convex = False
    return convex


def convexifying_shift(block: np.ndarray) -> float:
    """The multiple of the identity :func:`convexify` adds to one player's block (0 for a convex player)."""
    sym = 0.5 * (block + block.T)
    if _positive_definite(sym):
        return 0.0
    scale = max(1.0, float(np.max(np.abs(np.diag(sym)), initial=0.0)))
    delta = 1e-8 * scale
    eye = np.eye(sym.shape[0])
    while delta < 1e12 * scale and not _positive_definite(sym + delta * eye):
        delta *= 10.0
    return delta


def _positive_definite(sym: np.ndarray) -> bool:
    """Whether the Cholesky factorisation of the symmetric ``sym`` succeeds (LAPACK's, which reports failure
    without the cost of an exception)."""
    _, info = lapack.dpotrf(sym, lower=1, clean=0, overwrite_a=0)
    return info == 0
