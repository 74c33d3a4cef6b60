"""A player's best response searched globally on a box, with a guarantee: branch and bound over intervals.

For a player with few decisions (``MAX_DIM``), the question a certificate asks, "is there a point y of the box,
feasible for the player's own constraints with the others fixed, whose cost is below J_i(a) - tol?", has an answer
that does not depend on where local solves start. The box is split in halves along its widest side; on each piece
the cost is bounded below by interval arithmetic over the cost's instruction tape (gnerun.game.tape: every result
rounded outwards), in two forms, the natural extension and the mean-value form J(m) + [grad J](box) (y - m) (tight
near a minimum, where the gradient's enclosure straddles zero; not for a cost that may jump, such as atan2 across its
cut, whose derivative's tape knows nothing of the jump), and the constraint rows are bounded too. A piece
is discarded when its cost cannot go below the threshold or a constraint row cannot hold anywhere on it. A piece
whose centre is provably feasible (every row's enclosure at the centre <= 0) and provably below the threshold is a
witness: the player improves alone. When no piece remains, no point of the box improves by more than tol: a
global statement on the box, up to the tape's outward rounding. When the work budget runs out first, the
smallest lower bound of the remaining pieces bounds the player's best value on the box from below, and the
statement stays local.

This is the classical interval branch and bound of global optimisation (Moore; Hansen and Walster, *Global
Optimization Using Interval Analysis*, 2004), without its refinements (interval Newton contraction, monotonicity
tests): the boxes here have one to three sides.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..game.tape import Tape

MAX_DIM = 3  # players with at most this many decisions get the box search
MAX_PIECES = 60_000  # pieces bounded per search (the work budget)
MAX_ACTIVE = 8_192  # pieces kept at once; past this the search stops, its statement local


@dataclass(frozen=True)
class BoxSearch:
    """The outcome of :func:`box_search`."""

    complete: bool  # every piece was discarded: no feasible point of the box is below the threshold (with tol: below
    # the witness's value minus tol)
    witness: np.ndarray | None  # a point of the box, provably feasible, whose cost is provably below the threshold
    witness_value: float | None
    lower_bound: float  # the player's cost is >= this at every feasible point of the box (-inf: nothing known)
    pieces: int


def box_search(cost: Tape, gradient: Tape | None, rows: Tape | None, equality: np.ndarray, lower: np.ndarray,
               upper: np.ndarray, embed, threshold: float, *, tol: float | None = None,
               max_pieces: int = MAX_PIECES, candidate: np.ndarray | None = None) -> BoxSearch:
    """Search the box [lower, upper] of the player's own decisions for a feasible point below ``threshold``.

    ``cost``, ``gradient`` and ``rows`` are tapes of functions of (a, x) (J_i, grad_{a_i} J_i, the player's rows);
    ``embed(lo, hi)`` turns bounds of the player's decisions, shaped (d, B), into the inputs' bounds of those tapes
    (lists for :meth:`Tape.bounds`: the others' decisions and the state as degenerate intervals). With ``tol``, a
    witness does not end the search: the threshold drops to the witness's value minus ``tol`` and the search goes on,
    so that a complete search returns a witness within ``tol`` of the cheapest feasible point of the box (a best
    response, not just a better point).

    ``candidate`` (the point being certified, in the player's decisions): a row counts as holding where it is no
    worse than there. A point accepted as a solution may break a row by rounding (a row of the others' decisions
    alone, a constant for this player, at +2e-13); held to exactly zero, that row would discard every piece, and
    the search would end complete with nothing found, whatever the player could gain."""
    d = lower.size
    lo = lower.reshape(d, 1).astype(float)
    hi = upper.reshape(d, 1).astype(float)
    width0 = np.maximum(upper - lower, 1e-300).reshape(d, 1)
    pieces = 0
    witness, witness_value = None, None
    slack = np.zeros((equality.size, 1))  # what each row may be, as the candidate has it (0: none beyond exact)
    if rows is not None and equality.size and candidate is not None:
        y = np.asarray(candidate, dtype=float).reshape(d, 1)
        (yl,), (yh,) = rows.bounds(*embed(y, y))
        worst = np.where(equality.reshape(-1, 1), np.maximum(np.abs(yl), np.abs(yh)), yh)
        slack = np.where(np.isfinite(worst), np.maximum(worst, 0.0), 0.0)
    while lo.shape[1]:
        pieces += lo.shape[1]
        mid = 0.5 * (lo + hi)
        # cost: natural enclosure, and the mean-value form around the centre
        (jl,), _ = cost.bounds(*embed(lo, hi))
        bound = jl[0]
        (ml,), (mh,) = cost.bounds(*embed(mid, mid))
        if gradient is not None and not cost.jumps:  # (a cost that may jump has no mean-value bound)
            (gl,), (gh,) = gradient.bounds(*embed(lo, hi))
            with np.errstate(all="ignore"):
                dl, dh = lo - mid, hi - mid
                terms = np.minimum.reduce([gl * dl, gl * dh, gh * dl, gh * dh])
                terms = np.where(np.isnan(terms), -math.inf, terms)
                mv = ml[0] + np.sum(terms, axis=0)
            mv = np.nextafter(np.nextafter(mv, -math.inf), -math.inf)
            bound = np.maximum(bound, np.where(np.isnan(mv), -math.inf, mv))
        keep = np.ones(lo.shape[1], dtype=bool)
        centre_ok = np.ones(lo.shape[1], dtype=bool)
        if rows is not None and equality.size:
            (cl,), (ch,) = rows.bounds(*embed(lo, hi))
            ineq = ~equality
            impossible = ((cl[ineq] > slack[ineq]).any(axis=0) | (cl[equality] > slack[equality]).any(axis=0)
                          | (ch[equality] < -slack[equality]).any(axis=0))
            keep &= ~impossible
            (pl,), (ph,) = rows.bounds(*embed(mid, mid))
            # a centre counts only where every row provably holds there (equality rows cannot: they need a solve)
            centre_ok &= (ph[ineq] <= slack[ineq]).all(axis=0) & ~equality.any()
        # a centre provably feasible and provably below the threshold is a witness; with tol, the best one so far
        hit = np.flatnonzero(keep & centre_ok & (mh[0] < threshold))
        if hit.size:
            j = hit[np.argmin(mh[0][hit])]
            witness, witness_value = mid[:, j].copy(), float(mh[0][j])
            if tol is None:
                return BoxSearch(False, witness, witness_value, -math.inf, pieces)
            threshold = witness_value - tol
        keep &= ~(bound >= threshold)
        lo, hi, bound = lo[:, keep], hi[:, keep], bound[keep]
        if not lo.shape[1]:
            break
        stop = pieces >= max_pieces or 2 * lo.shape[1] > MAX_ACTIVE
        # split each piece in halves along its widest side (relative to the box)
        side = np.argmax((hi - lo) / width0, axis=0)
        cols = np.arange(lo.shape[1])
        cut = 0.5 * (lo[side, cols] + hi[side, cols])
        stop = stop or not np.all((cut > lo[side, cols]) & (cut < hi[side, cols]))  # down to rounding
        if stop:
            return BoxSearch(False, witness, witness_value, min(float(np.min(bound)), threshold), pieces)
        lo2, hi2 = lo.copy(), hi.copy()
        hi[side, cols] = cut
        lo2[side, cols] = cut
        lo, hi = np.hstack([lo, lo2]), np.hstack([hi, hi2])
    return BoxSearch(True, witness, witness_value, threshold, pieces)
