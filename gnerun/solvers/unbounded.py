"""Players without a best response: a cost that keeps decreasing along a feasible ray.

A player whose cost is unbounded below on its feasible set (x^3/3 - x + ..., a concave or a linear cost of an
unbounded decision, x^2 - 1e-6 x^4), or that decreases towards an infimum it never attains (exp(-x)), has no best
response, and a game in which that happens at a point has no equilibrium there, whatever the KKT residual says: a
KKT point may well be such a player's local minimum or maximum. From the point, rays y + t d are followed over
``STEPS`` decades of t (t = s/100, s/10, ..., 1e8 s with s the size of the point); a ray shows the player unbounded
when every point on it satisfies the player's constraints and the cost falls below the point's own over ``TAIL``
descending steps to a lowest value that it never leaves again (at the end of the ray, or a floor it approaches).
The directions: the coordinates the player's bounds leave free, the negative gradient there, a few seeded random
directions in the same cone, and any given ones (where a best-response solve ran away). A cost whose minimum lies
beyond 1e8 s along the ray is reported as unbounded as well; the values seen are in the report.

Two more directions find what coordinates and random draws miss: the eigenvectors of the player's own Hessian whose
eigenvalues are (nearly) zero or negative (a flat valley, along which a cost can decay forever while rising on both
sides), and the steepest descent direction of the recession cone of the player's linearised rows (min grad J . d
s.t. grad c_j . d <= 0 for every inequality row, = 0 for every equality, |d| <= 1: a linear program), which is the
way out of a polyhedral set along which a linear cost falls.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

STEPS = 11  # t = s * 10^k, k = -2..8
TAIL = 3  # strict decreases at the end of the ray
COORDINATE_RAYS_UP_TO = 8  # players with at most this many free coordinates get one ray per coordinate and sign
RANDOM_RAYS = 6


@dataclass(frozen=True)
class Ray:
    """A feasible ray along which the player's cost keeps decreasing."""

    direction: np.ndarray  # unit vector in the player's decisions
    steps: np.ndarray  # t of the points looked at
    costs: np.ndarray  # the cost at each
    start_cost: float  # the cost at the point the ray starts from
    unbounded_below: bool  # the cost fell by more than UNBOUNDED_DROP x max(1, |start cost|); else: not attained
    pole: np.ndarray | None = None  # a pole (:func:`pole_approach`): the point approached; steps are distances to it

    def describe(self, names: list[str]) -> str:
        if self.pole is not None:
            at = ", ".join(f"{names[k]} = {v:.6g}" for k, v in enumerate(self.pole[:4]))
            seen = ", ".join(f"{c:.3g} at distance {t:.0e}" for t, c in zip(self.steps[-3:], self.costs[-3:],
                                                                          strict=True))
            what = "decreases without bound" if self.unbounded_below else "keeps decreasing (like a logarithm)"
            return (f"its cost {what} approaching ({at}{', ...' if self.pole.size > 4 else ''}), where it is not "
                    f"finite or jumps, from {self.start_cost:.6g}: {seen}")
        d = self.direction
        big = np.flatnonzero(np.abs(d) >= 0.05 * np.max(np.abs(d)))[:4]
        along = " ".join(f"{'+' if d[k] > 0 else '-'}{abs(d[k]):.2g} {names[k]}" for k in big)
        pairs = list(zip(self.steps, self.costs, strict=True))
        distinct = [p for k, p in enumerate(pairs) if k == 0 or p[1] != pairs[k - 1][1]]  # underflow repeats zeros
        seen = ", ".join(f"{c:.3g} at t = {t:.0e}" for t, c in distinct[-3:])
        what = ("decreases without bound" if self.unbounded_below else
                "keeps decreasing towards a value it does not attain")
        return f"its cost {what} along ({along}) from {self.start_cost:.6g}: {seen}"


UNBOUNDED_DROP = 1e6
NEAR = 6  # the first part of a ray: t up to 1e3 s
FLOOR = 1e-9  # after its lowest point a ray's cost may wobble this much (relative) at the arithmetic's resolution


def free_directions(lower: np.ndarray, upper: np.ndarray, gradient: np.ndarray | None, seed,
                    extra: list[np.ndarray] = ()) -> list[np.ndarray]:
    """The directions a ray can take from a point of the box [lower, upper] without leaving it for good: + along a
    coordinate without an upper bound, - along one without a lower bound (and combinations of those)."""
    up = ~np.isfinite(upper)
    down = ~np.isfinite(lower)
    free = up | down
    dirs: list[np.ndarray] = []
    n = lower.size
    # the given directions, without the components that would leave the box for good
    extra = [np.where(((d > 0) & ~up) | ((d < 0) & ~down), 0.0, d) for d in extra if np.all(np.isfinite(d))]
    if not free.any():
        return []
    idx = np.flatnonzero(free)
    if idx.size <= COORDINATE_RAYS_UP_TO:
        for k in idx:
            for sign in (1.0, -1.0):
                if (sign > 0 and up[k]) or (sign < 0 and down[k]):
                    e = np.zeros(n)
                    e[k] = sign
                    dirs.append(e)
    if gradient is not None and np.all(np.isfinite(gradient)):
        g = -np.where(free, gradient, 0.0)
        g = np.where((g > 0) & ~up, 0.0, np.where((g < 0) & ~down, 0.0, g))
        if np.any(g):
            dirs.append(g)
    rng = np.random.default_rng(seed)
    for _ in range(RANDOM_RAYS if idx.size > 1 else 0):
        r = np.zeros(n)
        r[idx] = rng.standard_normal(idx.size)
        r = np.where((r > 0) & ~up, -r, np.where((r < 0) & ~down, -r, r))
        dirs.append(r)
    dirs += [d for d in extra if _admissible(d, up, down)]
    out = []
    for d in dirs:
        norm = float(np.linalg.norm(d))
        if norm > 0 and math.isfinite(norm):
            out.append(d / norm)
    return out


def flat_directions(hessian: np.ndarray) -> list[np.ndarray]:
    """Both signs of every eigenvector of the symmetric part of ``hessian`` whose eigenvalue is at most 1e-6 of the
    largest in size (flat or concave directions)."""
    H = 0.5 * (hessian + hessian.T)
    if not np.all(np.isfinite(H)) or not H.size:
        return []
    w, V = np.linalg.eigh(H)
    cut = 1e-6 * max(1.0, float(np.max(np.abs(w))))
    return [s * V[:, k] for k in np.flatnonzero(w <= cut) for s in (1.0, -1.0)]


def recession_direction(gradient: np.ndarray, rows_jacobian: np.ndarray, equality: np.ndarray,
                        multipliers: np.ndarray | None = None) -> np.ndarray | None:
    """The steepest descent direction of the recession cone of the linearised rows (None when no direction of that
    cone descends): min g . d s.t. C_j d <= 0 (inequalities), C_j d = 0 (equalities), -1 <= d <= 1.

    With ``multipliers`` (the candidate's, one per row), the linear program is not solved where they prove that it
    would return None (:func:`no_descent`)."""
    n = gradient.size
    if not np.all(np.isfinite(gradient)) or not np.all(np.isfinite(rows_jacobian)):
        return None
    C = rows_jacobian.reshape(-1, n)
    floor = 1e-12 * max(1.0, float(np.max(np.abs(gradient), initial=0.0)))
    if multipliers is not None and no_descent(gradient, C, equality, multipliers, floor):
        return None
    from scipy.optimize import linprog  # (loaded where a ray is sought: 0.2-0.4 s of import)

    res = linprog(gradient, A_ub=C[~equality] if (~equality).any() else None,
                  b_ub=np.zeros(int((~equality).sum())) if (~equality).any() else None,
                  A_eq=C[equality] if equality.any() else None,
                  b_eq=np.zeros(int(equality.sum())) if equality.any() else None,
                  bounds=[(-1.0, 1.0)] * n, method="highs")
    if res.status != 0 or not res.fun < -floor:
        return None
    return np.asarray(res.x, dtype=float)


def no_descent(gradient: np.ndarray, C: np.ndarray, equality: np.ndarray, multipliers: np.ndarray,
               floor: float) -> bool:
    """Whether multipliers prove that no d with C_I d <= 0, C_E d = 0 and |d|_inf <= 1 has g . d < -floor (Farkas):
    for -g = C_I' mu + C_E' nu + r with mu >= 0, every such d has g . d = -mu' C_I d - nu' C_E d + r . d >= -|r|_1.

    Tried with the given multipliers (those of inequalities clipped at 0), then refitted by least squares on the rows
    they use and clipped again, then by nonnegative least squares on every row (:func:`nonnegative_least_squares`; at
    a KKT point solved to 1e-10 the given ones leave |r|_1 ~ 1e-11, above a floor of ~1e-12, and the part of g that
    the rows in use do not span, ~1e-12, is balanced by the others). Whatever the fit, the residual it leaves is what
    is checked: a poor fit sends the question to the linear program, never to a wrong answer."""
    if C.size == 0 or not np.all(np.isfinite(multipliers)) or not np.all(np.isfinite(C)):
        return False
    lam = np.where(equality, multipliers, np.maximum(multipliers, 0.0))
    if float(np.sum(np.abs(gradient + C.T @ lam))) <= floor:
        return True
    used = equality | (lam > 0.0)
    if used.any():
        mu = np.linalg.lstsq(C[used].T, -gradient, rcond=None)[0]
        mu = np.where(equality[used], mu, np.maximum(mu, 0.0))  # any mu >= 0 proves it: the residual is checked
        if float(np.sum(np.abs(gradient + C[used].T @ mu))) <= floor:
            return True
    # every row: the equalities' multipliers free, as the difference of two nonnegative ones
    A = np.vstack([C[~equality], C[equality], -C[equality]]).T
    mu = nonnegative_least_squares(A, -gradient)
    return float(np.sum(np.abs(gradient + A @ mu))) <= floor


def nonnegative_least_squares(A: np.ndarray, b: np.ndarray, max_iter: int | None = None) -> np.ndarray:
    """x >= 0 minimising ||A x - b||_2: the active-set method of Lawson and Hanson (Solving Least Squares Problems,
    1974, ch. 23), as scipy.optimize.nnls does it (which a certificate would otherwise import for this alone, 0.1-0.2 s
    of a fresh process). Each outer step frees the variable whose gradient says it lowers the residual most; an inner
    loop steps back along the segment to the unconstrained least-squares point of the free ones until they are all
    positive."""
    m, n = A.shape
    x = np.zeros(n)
    free = np.zeros(n, dtype=bool)
    tol = 10.0 * np.finfo(float).eps * max(m, n) * max(1.0, float(np.abs(A).sum(axis=0).max(initial=0.0)))
    budget = 3 * n if max_iter is None else max_iter
    for _ in range(budget):
        w = A.T @ (b - A @ x)
        w[free] = -np.inf
        j = int(np.argmax(w))
        if not w[j] > tol:
            break
        free[j] = True
        while True:
            s = np.zeros(n)
            s[free] = np.linalg.lstsq(A[:, free], b, rcond=None)[0]
            if np.all(s[free] > 0.0):
                x = s
                break
            blocked = free & (s <= 0.0)
            alpha = float(np.min(x[blocked] / (x[blocked] - s[blocked])))
            x = x + alpha * (s - x)
            free &= x > tol
            x[~free] = 0.0
            if not free.any():
                break
    return x


def _admissible(d: np.ndarray, up: np.ndarray, down: np.ndarray) -> bool:
    return bool(np.all(np.isfinite(d)) and not np.any((d > 0) & ~up) and not np.any((d < 0) & ~down) and np.any(d))


def ray_points(y: np.ndarray, directions: list[np.ndarray], scale: float) -> tuple[np.ndarray, np.ndarray]:
    """The points y + t d of every ray, (len(directions) * STEPS, n), and the steps t."""
    t = scale * 10.0 ** np.arange(-2, STEPS - 2)
    D = np.asarray(directions).reshape(len(directions), 1, y.size)
    return (y + t.reshape(1, -1, 1) * D).reshape(-1, y.size), t


def _descends(seq: np.ndarray, slopes: np.ndarray, floor: float) -> bool:
    """seq (the start's cost, then the ray's) reaches its lowest value below the start by TAIL descending steps and
    does not rise from it by more than ``floor``."""
    low = int(np.argmin(seq))
    if not seq[low] < seq[0] or np.any(seq[low:] > seq[low] + floor):
        return False
    tail, k = 0, low
    while k > 0 and tail < TAIL:
        prev, cur = seq[k - 1], seq[k]
        if not (cur < prev - 1e-12 * abs(prev) or (cur <= prev and slopes[k - 1] < 0)):
            break
        tail += 1
        k -= 1
    return tail >= TAIL


def descending_ray(directions: list[np.ndarray], t: np.ndarray, costs: np.ndarray, feasible: np.ndarray,
                   start_cost: float, slopes: np.ndarray | None = None) -> Ray | None:
    """The first ray (costs, feasible, slopes: (len(directions) * STEPS,) in ray_points' order) that shows the cost
    decreasing without end, or None.

    Along the ray the cost must reach its lowest value below the start's by ``TAIL`` descending steps in a row (a
    step descends where the cost falls, or where it stays level at rounding while its exact directional derivative
    ``slopes`` there is negative: a cost of 1e-19 added to 1), and never rise again by more than ``FLOOR`` max(1,
    |start cost|) (a floor it approaches: an infimum at infinity, at the resolution of the arithmetic)."""
    costs = costs.reshape(len(directions), t.size)
    feasible = feasible.reshape(len(directions), t.size)
    slopes = np.full(costs.shape, np.nan) if slopes is None else slopes.reshape(len(directions), t.size)
    floor = FLOOR * max(1.0, abs(start_cost))
    best: Ray | None = None
    for d, c, ok, dc in zip(directions, costs, feasible, slopes, strict=True):
        if not ok.all() or np.any(np.isnan(c)):
            continue
        # the whole ray, or its first part (a valley followed along a direction known only to rounding leaves it
        # far out, rising like (t x rounding)^2: the floor is seen before that)
        if not any(_descends(np.concatenate([[start_cost], c[:end]]), dc[:end], floor) for end in (t.size, NEAR)):
            continue
        ray = Ray(d, t, c, start_cost, bool(c[-1] < start_cost - UNBOUNDED_DROP * max(1.0, abs(start_cost))))
        if best is None or ray.costs[-1] < best.costs[-1]:
            best = ray
    return best


# poles: a cost that falls without bound near a point of a bounded set (log(x) at x = 0, -tan(x) below pi/2, -1/x^2)
POLE_SCAN = 64  # points evenly spaced on the segment searched, and ...
POLE_NEAR_END = 14  # ... as many approaching its far end geometrically (1e-2 ... 1e-15 of its length from it)
POLE_HALVINGS = 60  # bisection steps towards the pole (a bracket of length L ends at L 2^-60)
POLE_DECADES = 8.0  # a fall that keeps its pace per decade of the distance over this many: log-like, ...
POLE_WINDOW, POLE_PACE = 4.0, 0.85  # ... its last 4 decades falling at least 0.85 times as fast as 4 early ones
POLE_OUTLIER = 100.0  # a lowest scanned cost this many times (1 + |median|) below the scan's median
POLE_TRIES = 4  # places narrowed (the lowest first, over all segments): each up to POLE_HALVINGS evaluations


def pole_segment(start: np.ndarray, target: np.ndarray, lower: np.ndarray, upper: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, float] | None:
    """The segment from ``start`` through ``target`` to the box's edge: (start, its direction, its length), or None
    where they coincide or the box has no edge that way."""
    d = target - start
    norm = float(np.linalg.norm(d))
    if not norm > 0 or not math.isfinite(norm):
        return None
    d = d / norm
    with np.errstate(divide="ignore", invalid="ignore"):
        to_edge = np.where(d > 0, (upper - start) / d, np.where(d < 0, (lower - start) / d, np.inf))
    t_max = float(np.min(to_edge))
    if not (math.isfinite(t_max) and t_max >= norm):
        return None
    return start, d, t_max


def coordinate_segments(point: np.ndarray, lower: np.ndarray, upper: np.ndarray
                        ) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """The segments from ``point`` to the box's edge along each coordinate, both ways."""
    out = []
    for k in range(point.size):
        for sign, length in ((1.0, upper[k] - point[k]), (-1.0, point[k] - lower[k])):
            if length > 0 and math.isfinite(length):
                d = np.zeros(point.size)
                d[k] = sign
                out.append((point, d, float(length)))
    return out


def approach_point(values, point: np.ndarray, directions: list[np.ndarray], length: float) -> Ray | None:
    """A pole at ``point`` itself (a best response found within rounding of one, as a local solve finds log|x - p|'s;
    the end of a bisection or golden-section search): the cost at point + 10^-k length d, k = 1..16, for each
    direction d (one call), read by :func:`_approach` over the longest run of admissible points nearing the point
    along which the cost keeps falling. The Ray's direction is that of the approach, -d; its steps are the distances
    to the point."""
    k = np.arange(1.0, 17.0)
    points = [point + 10.0 ** -j * length * d for d in directions for j in k]
    if not points:
        return None
    costs, ok = values(points)
    rays = []
    for d, c, good in zip(directions, np.split(costs, len(directions)), np.split(ok, len(directions)), strict=True):
        good = good & np.isfinite(c)
        best = (0, 0)  # the longest run [i, j) of admissible points with falling costs
        i = 0
        while i < c.size:
            j = i + 1
            while good[i] and j < c.size and good[j] and c[j] < c[j - 1]:
                j += 1
            if good[i] and j - i > best[1] - best[0]:
                best = (i, j)
            i = j
        i, j = best
        if j - i >= 3:
            rays.append(_approach(list(10.0 ** -k[i:j] * length), list(c[i:j]), -d, float(c[i]), point))
    rays = [r for r in rays if r is not None]
    return min(rays, key=lambda r: r.costs[-1]) if rays else None


def pole_approach(values, segments: list[tuple[np.ndarray, np.ndarray, float]]) -> Ray | None:
    """A pole of the cost on the segments (start, d, t_max): start + t d, 0 <= t <= t_max. ``values(points)`` gives
    each point's cost and whether it is admissible (feasible; a NaN or infinite cost is never a value). Every segment
    is scanned (all in one call). Where an admissible point borders one whose cost is not finite (log(0), the edge of
    a domain), the border is bisected (in the points themselves, to their own resolution: x -> 0 goes on to 1e-300),
    each step kept on the side of the lower cost; where a segment's lowest point lies between two finite ones and one
    of them jumps up by more than its size plus one (past a pole of tan or 1/x), or it lies far below the scan's
    median (a pole of -1/x^2 between two points), golden sections narrow it; the POLE_TRIES places of the lowest
    costs, over all segments. What shows a pole: :func:`_approach`. Returns the lowest approach as a Ray (``pole``:
    the point approached, ``steps``: distances to it), or None."""
    scans = []
    for start, d, t_max in segments:
        end = start + t_max * d
        points = [start + s * d for s in np.linspace(0.0, t_max, POLE_SCAN + 1)[:-1]]
        points += [end - t_max * 10.0 ** -j * d for j in np.arange(2.0, 2.0 + POLE_NEAR_END)] + [end]
        scans.append(points)
    if not scans:
        return None
    costs, ok = values([p for points in scans for p in points])
    tasks = []  # (the cost where the narrowing starts, narrowing, its arguments)
    for (_, d, _), points, c, k in zip(segments, scans, np.split(costs, len(scans)), np.split(ok, len(scans)),
                                       strict=True):
        if k[0] and math.isfinite(c[0]):  # the cost at the segment's start: what a fall is measured from
            tasks += _suspects(points, c, k, d, float(c[0]))
    rays = [narrow(values, *args) for _, narrow, args in sorted(tasks, key=lambda task: task[0])[:POLE_TRIES]]
    rays = [r for r in rays if r is not None]
    return min(rays, key=lambda r: r.costs[-1]) if rays else None


def _suspects(points: list[np.ndarray], costs: np.ndarray, ok: np.ndarray, d: np.ndarray, start_cost: float
              ) -> list[tuple]:
    """:func:`pole_approach`'s places to narrow on one scanned segment."""
    good = ok & np.isfinite(costs)
    low = int(np.flatnonzero(good)[np.argmin(costs[good])])
    typical = float(np.median(costs[good]))
    outlier = costs[low] < typical - POLE_OUTLIER * (abs(typical) + 1.0)  # far below the rest: near a pole
    tasks = []
    # every edge of the cost's domain (an admissible point beside one whose cost is not finite; an infeasible one is a
    # row's edge, no pole): log(x + 1.5) at -1.5 may fall below the rest only 1e-5 from its edge
    edge = good[:-1] & ~good[1:] & ~(~ok[1:] & np.isfinite(costs[1:]))  # (i, i + 1)
    back = good[1:] & ~good[:-1] & ~(~ok[:-1] & np.isfinite(costs[:-1]))  # (i + 1, i)
    length = float(np.linalg.norm(points[-1] - points[0]))
    for i, j in [(i, i + 1) for i in np.flatnonzero(edge)] + [(i + 1, i) for i in np.flatnonzero(back)]:
        tasks.append((float(costs[i]), _bisect, (points[i], points[j], float(costs[i]), d, start_cost, length)))
    if 0 < low < len(points) - 1 and good[low - 1] and good[low + 1] and (outlier or max(
            costs[low - 1], costs[low + 1]) > costs[low] + abs(costs[low]) + 1.0):
        tasks.append((float(costs[low]), _narrow,
                      (points[low - 1], points[low], points[low + 1], float(costs[low]), d, length)))
    return tasks


def _bisect(values, lo: np.ndarray, hi: np.ndarray, c_lo: float, d: np.ndarray, start_cost: float,
            length: float) -> Ray | None:
    """:func:`pole_approach`'s bisection of the segment [lo, hi] (the lowest point at lo, hi's cost not finite) to
    the edge of the domain, approached from there (:func:`approach_point`); or an overflow: the cost at the edge
    -inf after falling by more than UNBOUNDED_DROP max(1, |start cost|) (exp growing without bound)."""
    moved, seen = [], []
    for _ in range(POLE_HALVINGS):
        mid = 0.5 * (lo + hi)
        if np.array_equal(mid, lo) or np.array_equal(mid, hi):
            break
        cost, ok = values([mid])
        if ok[0] and math.isfinite(cost[0]) and cost[0] < c_lo:
            lo, c_lo = mid, float(cost[0])
            moved.append(mid)
            seen.append(c_lo)
        else:
            hi = mid
    if len(seen) >= 3 and seen[-1] < start_cost - UNBOUNDED_DROP * max(1.0, abs(start_cost)):
        return Ray(d, np.asarray([float(np.linalg.norm(q - hi)) for q in moved]), np.asarray(seen), start_cost, True,
                   pole=hi.copy())
    inward = lo - hi
    norm = float(np.linalg.norm(inward))
    return approach_point(values, hi, [inward / norm], length) if norm > 0 else None


def _narrow(values, a: np.ndarray, b: np.ndarray, c: np.ndarray, fb: float, d: np.ndarray,
            length: float) -> Ray | None:
    """:func:`pole_approach`'s golden-section search in the bracket a, b, c (the lowest point b between two higher
    ones), towards a minimum or a pole, approached from both sides where it ends (:func:`approach_point`)."""
    for _ in range(2 * POLE_HALVINGS):
        right = np.linalg.norm(c - b) > np.linalg.norm(b - a)
        m = b + GOLDEN * (c - b) if right else b - GOLDEN * (b - a)
        if np.array_equal(m, b) or np.array_equal(m, a) or np.array_equal(m, c):
            break
        cost, ok = values([m])
        if ok[0] and math.isfinite(cost[0]) and cost[0] < fb:
            a, c = (b, c) if right else (a, b)
            b, fb = m, float(cost[0])
        elif right:
            c = m
        else:
            a = m
    return approach_point(values, b, [d, -d], length)


GOLDEN = 0.5 * (3.0 - math.sqrt(5.0))


def _approach(distances: list[float], seen: list[float], d: np.ndarray, start_cost: float,
              point: np.ndarray) -> Ray | None:
    """The approach of a point by ever lower costs ``seen`` at ``distances`` from it, as a Ray where it shows a pole:
    a fall that keeps its pace per decade of the distance over at least POLE_DECADES decades (its last POLE_WINDOW
    decades fall per decade at least POLE_PACE times as fast as POLE_WINDOW decades early on: log(x), 1/x; a finite
    limit's fall fades with the distance: x log(x), sqrt(x), |x|^p for p >= 0.02, a minimum however deep). Distances
    within 100 units in the last place of the point are left out (rounding, not the cost, decides there)."""
    if len(seen) < 3:
        return None
    cost = np.asarray(seen)
    unbounded_below = bool(cost[-1] < start_cost - UNBOUNDED_DROP * max(1.0, abs(start_cost)))
    keep = np.asarray(distances) >= 100.0 * np.spacing(float(np.max(np.abs(point), initial=0.0)))
    with np.errstate(divide="ignore"):
        u, fell = np.log10(np.asarray(distances)[keep]), cost[keep]
    if u.size < 6 or not np.all(np.isfinite(u)) or u[0] - u[-1] < POLE_DECADES:
        return None

    def pace(top: float, bottom: float) -> float:  # the fall per decade over [bottom, top], by least squares
        inside = (u <= top) & (u >= bottom)
        return float(np.polyfit(u[inside], fell[inside], 1)[0]) if np.count_nonzero(inside) >= 3 else 0.0

    # POLE_WINDOW decades after the first two (where the smooth part of the cost still counts), and the last ones
    first, last = pace(u[0] - 2.0, u[0] - 2.0 - POLE_WINDOW), pace(u[-1] + POLE_WINDOW, u[-1])
    if not (first > 0 and last >= POLE_PACE * first and last > 1e-9 * max(1.0, abs(fell[-1]))):
        return None
    return Ray(d, np.asarray(distances), cost, start_cost, unbounded_below, pole=point.copy())
