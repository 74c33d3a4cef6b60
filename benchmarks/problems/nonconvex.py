"""Small static games whose answer a Newton method cannot take for granted, each with what is known about it.

Six kinds, each written twice (as gnerun expressions in ``config_yaml`` and, independently, as numpy functions):

* ``nonconvex``: nonconvex players whose equilibrium is known (double wells, tilted wells, sums of Gaussians with a
  shallow near basin and a deep far one, sin/cos costs on boxes, concave players whose best response is a corner,
  coercive quartics on unbounded decisions), started next to a worse basin, at a local maximum or at a bound;
* ``nonsmooth``: ``abs``, ``max`` and ``min`` in costs, equilibria at a kink and away from one, L1 terms on bounded
  variables;
* ``unbounded``: no equilibrium, because a player's cost is unbounded below or has no minimiser for every choice of
  the others (cubics, concave players, a quartic that turns down far away, linear costs, exp and softplus, a
  direction of descent that only general constraints leave open);
* ``infeasible``: no equilibrium, because no point satisfies every player's constraints (contradictory shared rows,
  own rows, bounds against a shared row, a disk and a half-plane that miss, a nonconvex set that is empty);
* ``nan``: no equilibrium, because a cost is NaN or infinite on the whole feasible set;
* ``no pure NE``: continuous games in which every player has a best response but no point is a best response for
  all (a smooth matching-pennies cycle), each with its proof.

Each game comes with hard starts as separate :class:`Problem` s (name ``game @ start``).

The independent check (:func:`best_response_report`, behind ``Problem.best_response_gaps``) shares nothing with
gnerun: for every player, with the others fixed at the candidate, a dense grid over its own variables (its box, and
for an unbounded variable a wide box around 0 and around the candidate plus a fine box near the candidate), the
points that violate a row dropped, then SciPy polishes (L-BFGS-B, or SLSQP with rows) from the best grid points and
from the candidate. A minimum on the edge of the wide box of an unbounded variable is followed along the ray to
it, at doubling distances: a cost that keeps decreasing there is reported (gap ``inf`` when it passes below
-1e12). A candidate that violates a player's rows (by more than ``FEAS_TOL``) has gap ``inf`` for that player, a
candidate with a non-finite cost gap ``nan``: neither is an equilibrium.

Every reference was derived by hand (the comment at the game says how) and confirmed by an independent computation:
:func:`compute_references` iterates global best responses (the check's own search) from the derivation's
neighbourhood, and for two-player games scans the composite best-response map ``x1 -> BR1(BR2(x1))`` over a grid to
count its fixed points. ``python -m benchmarks.problems.nonconvex`` prints both for every game with an equilibrium.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import optimize

from . import Problem

INF = math.inf
FAMILY = "nonconvex"
KINDS = ("nonconvex", "nonsmooth", "unbounded", "infeasible", "nan", "no pure NE")

# --------------------------------------------------------------------------------------------------------------
# the game container
# --------------------------------------------------------------------------------------------------------------

Cost = Callable[[int, np.ndarray], np.ndarray]  # J_i(a), a of shape (n,) or (n, k) -> () or (k,)
Rows = Callable[[int, np.ndarray], list]  # player i's rows g(a) <= 0 beyond its bounds (own, then shared)


@dataclass(frozen=True)
class _Player:
    name: str
    variables: tuple[str, ...]
    cost: str  # gnerun expression
    lower: tuple[float, ...] = ()  # () = no bounds; otherwise one per variable (-inf allowed)
    upper: tuple[float, ...] = ()
    constraints: tuple[str, ...] = ()  # own rows, gnerun text

    def bounds(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        d = len(self.variables)
        return (self.lower or (-INF,) * d), (self.upper or (INF,) * d)


@dataclass(frozen=True)
class _Game:
    name: str
    kind: str
    players: tuple[_Player, ...]
    cost: Cost  # the numpy writing of every player's cost
    starts: tuple[tuple[str, tuple[float, ...]], ...]  # (label, a0 in gnerun's order)
    derivation: str  # what is known and how
    has_gne: bool = True
    reference: tuple[float, ...] | None = None  # the equilibrium, when unique
    rows: Rows | None = None  # the numpy writing of the rows (own and shared) of each player, g(a) <= 0
    eq_rows: Rows | None = None  # rows h(a) == 0
    shared: tuple[str, ...] = ()  # gnerun text of the shared rows

    @property
    def sizes(self) -> list[int]:
        return [len(p.variables) for p in self.players]

    @property
    def n(self) -> int:
        return sum(self.sizes)

    @property
    def slices(self) -> list[slice]:
        off = np.cumsum([0, *self.sizes])
        return [slice(int(off[i]), int(off[i + 1])) for i in range(len(self.players))]

    @property
    def lower(self) -> np.ndarray:
        return np.array([v for p in self.players for v in p.bounds()[0]], dtype=float)

    @property
    def upper(self) -> np.ndarray:
        return np.array([v for p in self.players for v in p.bounds()[1]], dtype=float)

    def costs(self, a: np.ndarray) -> np.ndarray:
        a = np.asarray(a, dtype=float)
        with np.errstate(all="ignore"):
            return np.array([float(self.cost(i, a)) for i in range(len(self.players))])

    def violation(self, i: int, a: np.ndarray) -> np.ndarray:
        """Player i's largest violation of its bounds and rows at a (shape a.shape[1:])."""
        sl = self.slices[i]
        lo, up = self.lower[sl], self.upper[sl]
        shape = a.shape[1:]
        lo = lo.reshape((-1,) + (1,) * len(shape))
        up = up.reshape((-1,) + (1,) * len(shape))
        v = np.max(np.maximum(np.maximum(lo - a[sl], a[sl] - up), 0.0), axis=0)
        with np.errstate(all="ignore"):
            for g in self.rows(i, a) if self.rows is not None else []:
                v = np.maximum(v, np.where(np.isnan(g), INF, np.maximum(g, 0.0)))
            for h in self.eq_rows(i, a) if self.eq_rows is not None else []:
                v = np.maximum(v, np.where(np.isnan(h), INF, np.abs(h)))
        return v

    def config_yaml(self, start: Sequence[float], name: str) -> str:
        lines = [f"name: {name}", "game:", "  kind: static", "  agents:"]
        k = 0
        for p in self.players:
            lines += [f"    - name: {p.name}", "      variables:"]
            lo, up = p.bounds()
            for v, low, high in zip(p.variables, lo, up, strict=True):
                fields = []
                if math.isfinite(low):
                    fields.append(f"lower: {_num(low)}")
                if math.isfinite(high):
                    fields.append(f"upper: {_num(high)}")
                fields.append(f"start: {_num(start[k])}")
                k += 1
                lines.append(f"        {v}: {{{', '.join(fields)}}}")
            lines.append(f'      cost: "{p.cost}"')
            if p.constraints:
                lines.append("      constraints:")
                lines += [f'        - "{c}"' for c in p.constraints]
        if self.shared:
            lines.append("  shared_constraints:")
            lines += [f'    - "{c}"' for c in self.shared]
            lines.append("  equilibrium: generalized")
        lines += ["run:", "  reference: none"]
        return "\n".join(lines) + "\n"


def _num(c: float) -> str:
    c = float(c)
    if c == int(c) and abs(c) < 1e15:
        return str(int(c))
    return repr(c)


# --------------------------------------------------------------------------------------------------------------
# the independent best-response check (numpy and scipy only)
# --------------------------------------------------------------------------------------------------------------

FEAS_TOL = 1e-6  # a candidate that violates a row of player i by more than this is not feasible for i
WIDE = 100.0  # an unbounded variable is searched over [-WIDE, WIDE] and within WIDE of the candidate ...
NEAR = 5.0  # ... and on a finer grid within NEAR of the candidate
GRID = {1: (200_001, 20_001), 2: (601, 401), 3: (101, 61)}  # points per axis (wide box, near box) by dimension
POLISH = 10  # local solves from the best grid points
UNBOUNDED = -1e12  # a cost that passes below this along the ray is unbounded below (gap inf)


@dataclass
class Response:
    """One player's global best response found by the check."""

    gap: float  # J_i(a) - min (inf: not feasible or unbounded below; nan: J_i(a) is not finite)
    value: float  # the minimum found
    point: np.ndarray | None  # where
    note: str = ""


def _grid(lo: np.ndarray, hi: np.ndarray, m: int) -> np.ndarray:
    axes = [np.linspace(lo[k], hi[k], m) if hi[k] > lo[k] else np.array([lo[k]]) for k in range(lo.size)]
    return np.stack([g.ravel() for g in np.meshgrid(*axes, indexing="ij")])


def best_response(game: _Game, i: int, a: np.ndarray) -> Response:
    """Player i's global best response to a_-i by the grid-and-polish search described in the module docstring."""
    a = np.asarray(a, dtype=float)
    sl = game.slices[i]
    d = sl.stop - sl.start
    with np.errstate(all="ignore"):
        here = float(game.cost(i, a))
    if not np.all(np.isfinite(a)) or not math.isfinite(here):
        return Response(math.nan, math.nan, None, "the candidate's cost is not finite")
    if float(game.violation(i, a)) > FEAS_TOL:
        return Response(INF, math.nan, None, f"the candidate violates a row by {float(game.violation(i, a)):.1e}")
    lo, up = game.lower[sl], game.upper[sl]
    own = a[sl]
    wide_lo = np.where(np.isfinite(lo), lo, np.minimum(-WIDE, own - WIDE))
    wide_hi = np.where(np.isfinite(up), up, np.maximum(WIDE, own + WIDE))
    near_lo = np.maximum(np.where(np.isfinite(lo), lo, -INF), own - NEAR)
    near_hi = np.minimum(np.where(np.isfinite(up), up, INF), own + NEAR)
    m_wide, m_near = GRID[d]

    def values(P: np.ndarray) -> np.ndarray:
        out = np.empty(P.shape[1])
        for s in range(0, P.shape[1], 200_000):
            chunk = P[:, s : s + 200_000]
            full = np.repeat(a[:, None], chunk.shape[1], axis=1)
            full[sl] = chunk
            with np.errstate(all="ignore"):
                J = np.asarray(game.cost(i, full), dtype=float) * np.ones(chunk.shape[1])
                ok = (game.violation(i, full) <= 1e-9) & np.isfinite(J)
            out[s : s + chunk.shape[1]] = np.where(ok, J, INF)
        return out

    P = np.concatenate([_grid(wide_lo, wide_hi, m_wide), _grid(near_lo, near_hi, m_near), own[:, None]], axis=1)
    J = values(P)
    order = np.argsort(J)
    best_val, best_pt = here, own.copy()
    starts = [own]
    for k in order[: 50 * POLISH]:
        if not math.isfinite(J[k]) or len(starts) > POLISH:
            break
        if all(np.max(np.abs(P[:, k] - s)) > 1e-3 * max(1.0, np.max(np.abs(s))) for s in starts):
            starts.append(P[:, k])
        if J[k] < best_val:
            best_val, best_pt = float(J[k]), P[:, k].copy()
    for s in starts:
        x, v = _polish(game, i, a, s, lo, up)
        if v < best_val:
            best_val, best_pt = v, x
    note = ""
    step_wide = (wide_hi - wide_lo) / max(m_wide - 1, 1)
    at_edge = (((~np.isfinite(lo)) & (best_pt <= wide_lo + step_wide))
               | ((~np.isfinite(up)) & (best_pt >= wide_hi - step_wide)))
    if np.any(at_edge):  # follow the ray from the candidate through the best point at doubling distances
        direction = best_pt - own
        direction /= max(np.linalg.norm(direction), 1e-300)
        seen = [best_val]
        t = float(np.linalg.norm(best_pt - own))
        for _ in range(60):
            t *= 2.0
            v = float(values((own + t * direction)[:, None])[0])
            if not v < seen[-1]:
                break
            seen.append(v)
            if v < UNBOUNDED:
                break
        if len(seen) > 1:
            best_val = seen[-1]
            best_pt = own + t * direction if math.isfinite(seen[-1]) else best_pt
            note = f"the cost keeps decreasing along a ray ({seen[0]:.3g} -> {seen[-1]:.3g} at distance {t:.3g})"
            if best_val < UNBOUNDED:
                return Response(INF, -INF, None, note + ": unbounded below")
    return Response(max(here - best_val, 0.0), best_val, best_pt, note)


def _polish(game: _Game, i: int, a: np.ndarray, x0: np.ndarray, lo: np.ndarray, up: np.ndarray
            ) -> tuple[np.ndarray, float]:
    sl = game.slices[i]

    def full(y: np.ndarray) -> np.ndarray:
        b = a.copy()
        b[sl] = y
        return b

    def f(y: np.ndarray) -> float:
        with np.errstate(all="ignore"):
            v = float(game.cost(i, full(y)))
        return v if math.isfinite(v) else 1e300

    bounds = [(None if not math.isfinite(lo_) else lo_, None if not math.isfinite(up_) else up_)
              for lo_, up_ in zip(lo, up, strict=True)]
    x0 = np.clip(x0, lo, up)
    try:
        if game.rows is None and game.eq_rows is None:
            res = optimize.minimize(f, x0, method="L-BFGS-B", bounds=bounds, options={"maxiter": 2000})
        else:
            cons = []
            if game.rows is not None:
                cons.append({"type": "ineq", "fun": lambda y: -np.atleast_1d(np.array(game.rows(i, full(y)), float))})
            if game.eq_rows is not None:
                cons.append({"type": "eq", "fun": lambda y: np.atleast_1d(np.array(game.eq_rows(i, full(y)), float))})
            res = optimize.minimize(f, x0, method="SLSQP", bounds=bounds, constraints=cons,
                                    options={"maxiter": 500, "ftol": 1e-14})
        x = np.asarray(res.x, dtype=float)
    except (ValueError, OverflowError, np.linalg.LinAlgError):
        return x0, INF
    if float(game.violation(i, full(x))) > 1e-9:
        return x, INF
    v = f(x)
    return x, v if v < 1e300 else INF


def best_response_report(game: _Game, a: np.ndarray) -> dict[str, Response]:
    """Every player's :func:`best_response` at a, by name."""
    return {p.name: best_response(game, i, a) for i, p in enumerate(game.players)}


def best_response_gaps(game: _Game, a: np.ndarray) -> dict[str, float]:
    return {name: r.gap for name, r in best_response_report(game, a).items()}


# --------------------------------------------------------------------------------------------------------------
# the games
# --------------------------------------------------------------------------------------------------------------


def _p(name: str, variables: str, cost: str, lower: Sequence[float] = (), upper: Sequence[float] = (),
       constraints: Sequence[str] = ()) -> _Player:
    return _Player(name, tuple(variables.split()), cost, tuple(float(v) for v in lower),
                   tuple(float(v) for v in upper), tuple(constraints))


def _games() -> list[_Game]:
    return [*_nonconvex(), *_nonsmooth(), *_unbounded(), *_infeasible(), *_nonfinite(), *_no_pure()]


def _nonconvex() -> list[_Game]:
    E = np.exp
    games = [
        # J1 = (x1^2 - 1)^2 + c x1 with tilt c = -0.3 + 0.2 x2 and BR2 = 1 - 0.25 x1. A tilted double well's global
        # minimum lies on the side opposite the tilt (f(-s|x|) < f(s|x|)). In the positive well (x1 ~ 1, x2 ~ 0.75)
        # c = -0.15 < 0: consistent; in the negative well (x1 ~ -1, x2 ~ 1.25) c = -0.05 < 0 still favours the
        # positive side: not an equilibrium. So the equilibrium is unique: 4 x1^3 - 4 x1 - 0.3 + 0.2 (1 - 0.25 x1)
        # = 0 on the positive branch (brentq). Start: in the negative well, whose KKT point is not an equilibrium.
        _Game("nc-tilted-well", "nonconvex",
              (_p("p1", "x1", "(x1**2 - 1)**2 - 0.3*x1 + 0.2*x1*x2"), _p("p2", "x2", "(x2 - 1)**2 + 0.5*x1*x2")),
              lambda i, a: ((a[0] ** 2 - 1) ** 2 - 0.3 * a[0] + 0.2 * a[0] * a[1]) if i == 0 else
              ((a[1] - 1) ** 2 + 0.5 * a[0] * a[1]),
              (("worse well", (-1.2, 1.3)),),
              "unique; the positive root of 4 x^3 - 4.05 x - 0.1 = 0 (brentq), x2 = 1 - x1/4",
              reference=(1.018356208167949, 0.7454109479580128)),
        # BR2 = 1 whatever x1; then J1 = (x1^2 - 2)^2 + 0.5 x1 is a double well tilted to the left: its global
        # minimum is the negative root of 4 x^3 - 8 x + 0.5 = 0. The start is the middle root (0.0627...), the local
        # maximum, with x2 = 1: the start is itself a KKT point of the game.
        _Game("nc-well-at-max", "nonconvex",
              (_p("p1", "x1", "(x1**2 - 2)**2 + 0.5*x1*x2"), _p("p2", "x2", "(x2 - 1)**2")),
              lambda i, a: ((a[0] ** 2 - 2) ** 2 + 0.5 * a[0] * a[1]) if i == 0 else (a[1] - 1) ** 2,
              (("local maximum", (0.06262279120668492, 1.0)),),
              "unique (x2 = 1 is dominant); x1 the negative root of 4 x^3 - 8 x + 0.5 = 0 (brentq)",
              reference=(-1.4444847004446535, 1.0)),
        # J1: a shallow Gaussian well at -2 (depth 1.5) and a deep wide one at 4 (depth 2.5), coupled weakly to x2;
        # BR2 = 0.4 x1 + 1. Near x1 = 4 (x2 ~ 2.6) the deep well wins (-2.46 against -1.08); near x1 = -2 (x2 ~ 0.2)
        # too (-2.21 against -1.40): the only fixed point of BR1 o BR2 is the deep one (the scan, fixed_points).
        _Game("nc-gauss", "nonconvex",
              (_p("p1", "x1", "-1.5*exp(-(x1 + 2)**2) - 2.5*exp(-(x1 - 4)**2/2) + 0.02*(x1 - x2)**2"),
               _p("p2", "x2", "(x2 - 0.4*x1 - 1)**2")),
              lambda i, a: (-1.5 * E(-(a[0] + 2) ** 2) - 2.5 * E(-(a[0] - 4) ** 2 / 2) + 0.02 * (a[0] - a[1]) ** 2)
              if i == 0 else (a[1] - 0.4 * a[0] - 1) ** 2,
              (("shallow basin", (-2.2, 0.1)), ("between the basins", (0.6, 1.2))),
              "unique (one fixed point in the scan); best-response iteration, then Newton on the stationarity",
              reference=(3.977807582956297, 2.591123033182519)),
        # A two-variable player with a shallow well at (1, 1) and a deep one at (-2, 3), pulled towards x3;
        # BR3 = (y1 + y2)/2.2. The deep well wins by > 1.5 for every x3 the game can produce: unique, by best-response
        # iteration from the deep well (contraction: the coupling 0.05 against the wells' curvature).
        _Game("nc-gauss-2d", "nonconvex",
              (_p("p1", "y1 y2", "-exp(-((y1 - 1)**2 + (y2 - 1)**2)) - 3*exp(-((y1 + 2)**2 + (y2 - 3)**2)/2)"
                  " + 0.05*(y1 - x3)**2"),
               _p("p2", "x3", "(x3 - 0.5*y1 - 0.5*y2)**2 + 0.1*x3**2")),
              lambda i, a: (-E(-((a[0] - 1) ** 2 + (a[1] - 1) ** 2)) - 3 * E(-((a[0] + 2) ** 2 + (a[1] - 3) ** 2) / 2)
                            + 0.05 * (a[0] - a[2]) ** 2) if i == 0 else
              ((a[2] - 0.5 * a[0] - 0.5 * a[1]) ** 2 + 0.1 * a[2] ** 2),
              (("shallow basin", (1.1, 0.9, 0.9)),),
              "unique (the deep well always wins); best-response iteration, then Newton on the stationarity",
              reference=(-1.9193790553633878, 2.99999512711831, 0.4911891235249645)),
        # sin(3 x1) on [0, 4] has interior minima near pi/2 and 7 pi/6 (1.571, 3.665) and a KKT point at the bound 0
        # (sin'(0) = 3 > 0); BR2 = 1.5 + 0.2 x1. At the far minimum x2 ~ 2.23 and the near minimum is lower (-0.93
        # against -0.69): the far basin holds no equilibrium, the near one does (the scan finds one fixed point).
        # Starts: the bound x1 = 0 and the far basin, both local minima of p1.
        _Game("nc-sin-box", "nonconvex",
              (_p("p1", "x1", "sin(3*x1) + 0.15*(x1 - x2)**2", [0], [4]), _p("p2", "x2", "(x2 - 1.5 - 0.2*x1)**2")),
              lambda i, a: (np.sin(3 * a[0]) + 0.15 * (a[0] - a[1]) ** 2) if i == 0 else (a[1] - 1.5 - 0.2 * a[0]) ** 2,
              (("at the bound", (0.0, 1.5)), ("far basin", (3.6, 2.2))),
              "unique (one fixed point in the scan); best-response iteration, then Newton on the stationarity",
              reference=(1.5786984418117693, 1.8157396883623538)),
        # J1 = cos(2 y1) + cos(y2) + 0.1 (y1 - x3)^2 + 0.1 y2 on [-3, 3]^2; cos(y2) + 0.1 y2 is least at the lower
        # bound y2 = -3 (-1.29 against -0.70 near the upper bound) whatever x3; then BR3 = 1 - 0.1 y2 = 1.3, and
        # cos(2 y1) + 0.1 (y1 - 1.3)^2 is least near +pi/2 (-0.993 against -0.18 near -pi/2): unique. Start: y1 in
        # the far well, y2 in the local minimum near the upper bound.
        _Game("nc-cos-box-2d", "nonconvex",
              (_p("p1", "y1 y2", "cos(2*y1) + cos(y2) + 0.1*(y1 - x3)**2 + 0.1*y2", [-3, -3], [3, 3]),
               _p("p2", "x3", "(x3 - 1)**2 + 0.2*x3*y2")),
              lambda i, a: (np.cos(2 * a[0]) + np.cos(a[1]) + 0.1 * (a[0] - a[2]) ** 2 + 0.1 * a[1]) if i == 0 else
              ((a[2] - 1) ** 2 + 0.2 * a[2] * a[1]),
              (("wrong wells", (-1.6, 2.9, 0.0)),),
              "unique (y2 = -3 dominant, then x3 = 1.3); y1 the root of -2 sin(2 y1) + 0.2 (y1 - 1.3) = 0 near pi/2",
              reference=(1.5578999018152087, -3.0, 1.3)),
        # Three double wells coupled linearly: J_i = (x_i^2 - 1)^2 + t_i x_i + 0.1 x_i (sum of the others), t = (0.6,
        # -0.5, 0.7). |0.1 (sum of the others)| <= 0.26 < min |t_i| for any point of the wells, so each player's
        # global minimum is on the side opposite t_i: signs (-, +, -). On those branches the best responses
        # contract (|dx/de| ~ 1/8, coupling 0.2): unique. Start: every player in its other well.
        _Game("nc-wells-3p", "nonconvex",
              tuple(_p(f"p{k + 1}", f"x{k + 1}", f"(x{k + 1}**2 - 1)**2 + {t}*x{k + 1} + 0.1*x{k + 1}*({o})")
                    for k, (t, o) in enumerate(((0.6, "x2 + x3"), (-0.5, "x1 + x3"), (0.7, "x1 + x2")))),
              lambda i, a: (a[i] ** 2 - 1) ** 2 + (0.6, -0.5, 0.7)[i] * a[i] + 0.1 * a[i] * (np.sum(a, axis=0) - a[i]),
              (("other wells", (1.0, -1.0, 1.0)),),
              "unique (signs fixed by the tilts); best-response iteration, then Newton on the stationarity",
              reference=(-1.0679369467673805, 1.07957647105533, -1.078226955881983)),
        # A concave player on a box: J1 = -(y1 - 0.3)^2 - (y2 + 0.2)^2 + 0.1 y1 y2 + 0.2 x3 y1 on [-1, 2]^2 (Hessian
        # [[-2, 0.1], [0.1, -2]]: its minimum is a vertex), BR3 = y1 - y2. At x3 = 0 the vertex values are -7.33 at
        # (2, 2), -6.73 at (-1, 2), -3.73 at (2, -1), -2.23 at (-1, -1): (2, 2) with x3 = 0 is an equilibrium. The
        # other vertices' x3 (-3, 3, 0) make (2, 2), (-1, 2), (2, 2) p1's best: none is its own best response, so
        # the equilibrium is unique. Start: the game's interior KKT point, a local maximum of p1.
        _Game("nc-concave-corner", "nonconvex",
              (_p("p1", "y1 y2", "-(y1 - 0.3)**2 - (y2 + 0.2)**2 + 0.1*y1*y2 + 0.2*x3*y1", [-1, -1], [2, 2]),
               _p("p2", "x3", "(x3 - y1 + y2)**2")),
              lambda i, a: (-(a[0] - 0.3) ** 2 - (a[1] + 0.2) ** 2 + 0.1 * a[0] * a[1] + 0.2 * a[2] * a[0]) if i == 0
              else (a[2] - a[0] + a[1]) ** 2,
              (("local maximum", (0.34349030470914127, -0.1828254847645429, 0.5263157894736842)),),
              "unique; the vertex (2, 2) with x3 = 0 (enumeration of the vertices)",
              reference=(2.0, 2.0, 0.0)),
        # Double wells in both of p1's variables, pushed beyond the box's upper corner: J1 = (y1^2 - 1)^2 + (y2^2 -
        # 1)^2 - 2 y1 - 1.5 y2 + 0.3 x3 y1 on [-1.5, 1.1]^2, BR3 = y1/3. At (1.1, 1.1), x3 = 11/30: the partial
        # derivatives -0.966 and -0.576 are < 0, so the corner is a KKT point; the negative wells cost > 3 more.
        # Start: both in the negative wells (a local minimum).
        _Game("nc-wells-corner", "nonconvex",
              (_p("p1", "y1 y2", "(y1**2 - 1)**2 + (y2**2 - 1)**2 - 2*y1 - 1.5*y2 + 0.3*x3*y1", [-1.5, -1.5],
                  [1.1, 1.1]),
               _p("p2", "x3", "(x3 - 0.5*y1)**2 + 0.5*x3**2")),
              lambda i, a: ((a[0] ** 2 - 1) ** 2 + (a[1] ** 2 - 1) ** 2 - 2 * a[0] - 1.5 * a[1] + 0.3 * a[2] * a[0])
              if i == 0 else ((a[2] - 0.5 * a[0]) ** 2 + 0.5 * a[2] ** 2),
              (("negative wells", (-1.0, -1.0, -0.3)),),
              "unique; the corner (1.1, 1.1), x3 = 1.1/3 (KKT signs by hand; scan)",
              reference=(1.1, 1.1, 1.1 / 3)),
        # A ring of minima y1^2 + y2^2 = 4 tilted by (0.5, -0.3 x3), BR3 = 1 - 0.05 y2, unbounded decisions: the
        # global minimum lies on the ring opposite the tilt (unique for a nonzero tilt); best-response iteration
        # contracts. Start: the origin, the top of the hat.
        _Game("nc-ring", "nonconvex",
              (_p("p1", "y1 y2", "(y1**2 + y2**2 - 4)**2 + 0.5*y1 - 0.3*y2*x3"),
               _p("p2", "x3", "(x3 - 1)**2 + 0.1*x3*y2")),
              lambda i, a: ((a[0] ** 2 + a[1] ** 2 - 4) ** 2 + 0.5 * a[0] - 0.3 * a[1] * a[2]) if i == 0 else
              ((a[2] - 1) ** 2 + 0.1 * a[2] * a[1]),
              (("hat top", (0.0, 0.0, 1.0)),),
              "unique (a tilted ring); best-response iteration, then Newton on the stationarity",
              reference=(-1.7529563239201171, 0.9992258178588715, 0.9500387091070565)),
        # J1 = x1^4/4 - 2 x1^2 + 0.6 x1 x2 (coercive, wells at +-2), BR2 = 1 - 0.3 x1. In the negative well x2 ~ 1.6
        # > 0 tilts towards the negative side: consistent; in the positive well x2 ~ 0.4 > 0 still tilts towards
        # the negative side: not an equilibrium. Unique: x1^3 - 4 x1 + 0.6 (1 - 0.3 x1) = 0, negative root.
        _Game("nc-quartic", "nonconvex",
              (_p("p1", "x1", "0.25*x1**4 - 2*x1**2 + 0.6*x1*x2"), _p("p2", "x2", "0.5*(x2 + 0.3*x1 - 1)**2")),
              lambda i, a: (0.25 * a[0] ** 4 - 2 * a[0] ** 2 + 0.6 * a[0] * a[1]) if i == 0 else
              0.5 * (a[1] + 0.3 * a[0] - 1) ** 2,
              (("positive well", (2.0, 0.4)),),
              "unique; the negative root of x^3 - 4.18 x + 0.6 = 0 (brentq), x2 = 1 - 0.3 x1",
              reference=(-2.112813646633258, 1.6338440939899774)),
    ]
    # Three players with three variables each, every variable a double well with its own tilt t and a weak
    # coupling 0.05 y_i . (sum of the others' vectors): |coupling| <= 0.05 * 2 * 1.2 < 0.3 <= |t|, so the sign of
    # each coordinate at any equilibrium is -sign(t); on those branches best responses contract: unique.
    T = ((0.5, -0.4, 0.6), (-0.3, 0.7, -0.5), (0.4, 0.3, -0.6))
    names = [[f"y{i + 1}{k + 1}" for k in range(3)] for i in range(3)]
    players = []
    for i in range(3):
        terms = [f"(y{i + 1}{k + 1}**2 - 1)**2 + {T[i][k]}*y{i + 1}{k + 1}" for k in range(3)]
        others = [j for j in range(3) if j != i]
        coupling = " + ".join(f"y{i + 1}{k + 1}*({' + '.join(names[j][k] for j in others)})" for k in range(3))
        players.append(_p(f"p{i + 1}", " ".join(names[i]), " + ".join(terms).replace("+ -", "- ")
                          + f" + 0.05*({coupling})"))

    def wells9(i: int, a: np.ndarray) -> np.ndarray:
        y = a.reshape((3, 3) + a.shape[1:])
        others = np.sum(y, axis=0) - y[i]
        t = np.array(T[i]).reshape((3,) + (1,) * (a.ndim - 1))
        return np.sum((y[i] ** 2 - 1) ** 2 + t * y[i] + 0.05 * y[i] * others, axis=0)

    games.append(_Game("nc-wells-3x3", "nonconvex", tuple(players), wells9,
                       (("other wells", tuple(float(np.sign(t)) for row in T for t in row)),),
                       "unique (signs fixed by the tilts); best-response iteration, then Newton on the stationarity",
                       reference=(-1.0574570851318184, 1.0580568188601853, -1.078740457735236, 1.047249059705464,
                                  -1.0782235027312117, 1.0575106112232942, -1.0466247245106668, -1.0354650050065985,
                                  1.0680325936620951)))
    return games


def _nonsmooth() -> list[_Game]:
    A = np.abs
    return [
        # J1 = 2|x1 - 0.5| + 0.3 (x1 - x2)^2 is strictly convex; at x1 = 0.5 its subdifferential 0.6 (0.5 - x2) +
        # [-2, 2] holds 0 for |x2 - 0.5| <= 10/3. BR2 = 0.2 x1 + 1 = 1.1: the kink, unique (both strictly convex,
        # and BR1 is constant near the solution).
        _Game("ns-abs-kink", "nonsmooth",
              (_p("p1", "x1", "2*abs(x1 - 0.5) + 0.3*(x1 - x2)**2"), _p("p2", "x2", "(x2 - 0.2*x1 - 1)**2")),
              lambda i, a: (2 * A(a[0] - 0.5) + 0.3 * (a[0] - a[1]) ** 2) if i == 0 else (a[1] - 0.2 * a[0] - 1) ** 2,
              (("far right", (4.0, 0.0)),),
              "unique; the kink x1 = 0.5 (subdifferential by hand), x2 = 1.1", reference=(0.5, 1.1)),
        # J1 = 0.3 |x1 + 1| + (x1 - x2)^2, on x1 > -1: x1 = x2 - 0.15; BR2 = 2 - 0.1 x1. Then 1.1 x1 = 1.85:
        # x1 = 37/22 > -1, away from the kink; unique (strictly convex players, contraction 0.1).
        _Game("ns-abs-smooth-side", "nonsmooth",
              (_p("p1", "x1", "0.3*abs(x1 + 1) + (x1 - x2)**2"), _p("p2", "x2", "(x2 - 2)**2 + 0.2*x2*x1")),
              lambda i, a: (0.3 * A(a[0] + 1) + (a[0] - a[1]) ** 2) if i == 0 else
              ((a[1] - 2) ** 2 + 0.2 * a[1] * a[0]),
              (("at the kink", (-1.0, 0.0)),),
              "unique; x1 = 37/22, x2 = 2 - 3.7/22 (by hand)", reference=(37 / 22, 2 - 3.7 / 22)),
        # J1 = max(x1 - 1, 1 - 2 x1) + 0.2 (x1 - x2)^2, strictly convex with a kink at 2/3 whose subdifferential
        # [-2, 1] + 0.4 (2/3 - x2) holds 0 for x2 in [-13/3, 19/6]; BR2 = 1 + x1/2 = 4/3: the kink, unique.
        _Game("ns-max-kink", "nonsmooth",
              (_p("p1", "x1", "max(x1 - 1, 1 - 2*x1) + 0.2*(x1 - x2)**2"), _p("p2", "x2", "(x2 - 1 - 0.5*x1)**2")),
              lambda i, a: (np.maximum(a[0] - 1, 1 - 2 * a[0]) + 0.2 * (a[0] - a[1]) ** 2) if i == 0 else
              (a[1] - 1 - 0.5 * a[0]) ** 2,
              (("far right", (3.0, 0.0)),),
              "unique; the kink x1 = 2/3, x2 = 4/3 (by hand)", reference=(2 / 3, 4 / 3)),
        # min of two wells (nonconvex and nonsmooth): J1 = min((x1 - 1)^2, (x1 + 2)^2 + 0.5) + 0.1 x1 x2, BR2 = 1 +
        # 0.2 x1. In the right well 2 (x1 - 1) + 0.1 (1 + 0.2 x1) = 0: x1 = 1.9/2.02, value 0.115 against 0.259 in
        # the left well; the left well's fixed point (x1 ~ -2.06, x2 ~ 0.59) is beaten by the right well (0.058
        # against 0.38): unique. Start: the left well.
        _Game("ns-min-wells", "nonsmooth",
              (_p("p1", "x1", "min((x1 - 1)**2, (x1 + 2)**2 + 0.5) + 0.1*x1*x2"),
               _p("p2", "x2", "(x2 - 1 - 0.2*x1)**2")),
              lambda i, a: (np.minimum((a[0] - 1) ** 2, (a[0] + 2) ** 2 + 0.5) + 0.1 * a[0] * a[1]) if i == 0 else
              (a[1] - 1 - 0.2 * a[0]) ** 2,
              (("left well", (-2.0, 0.6)),),
              "unique; x1 = 1.9/2.02, x2 = 1 + 0.38/2.02 (by hand)", reference=(1.9 / 2.02, 1 + 0.38 / 2.02)),
        # L1 terms on a bounded player, separable: y1 on (0, 2]: 2 (y1 - 3.5) + 1 + 0.2 x3 < 0 up to the bound 2
        # (for x3 < 10); y2: (y2 + 0.3)^2 + 1.5 |y2| has 0 in 0.6 + [-1.5, 1.5] at the kink y2 = 0; BR3 = 2 - 0.5 y1
        # = 1. Unique (strictly convex players, BR1 constant). Start: outside the box.
        _Game("ns-l1-box", "nonsmooth",
              (_p("p1", "y1 y2", "(y1 - 3.5)**2 + (y2 + 0.3)**2 + abs(y1) + 1.5*abs(y2) + 0.2*y1*x3", [-1, -1], [2, 2]),
               _p("p2", "x3", "(x3 - 2 + 0.5*y1)**2")),
              lambda i, a: ((a[0] - 3.5) ** 2 + (a[1] + 0.3) ** 2 + A(a[0]) + 1.5 * A(a[1]) + 0.2 * a[0] * a[2])
              if i == 0 else (a[2] - 2 + 0.5 * a[0]) ** 2,
              (("outside the box", (-2.0, 3.0, 0.0)),),
              "unique; y1 = 2 (bound), y2 = 0 (kink), x3 = 1 (by hand)", reference=(2.0, 0.0, 1.0)),
        # |x1^2 - 1| has kinks (minima, value 0) at +-1; tilt c = 0.3 - 0.2 x2, BR2 = 0.5 x1 + 0.5. At x1 = -1: x2 = 0,
        # c = 0.3 > 0, so -1 (value -0.3) beats +1 (0.3): consistent. At x1 = 1: x2 = 1, c = 0.1 > 0 favours -1:
        # not an equilibrium. Unique. Start: the other kink (1, 1), a local minimum of p1.
        _Game("ns-abs-wells", "nonsmooth",
              (_p("p1", "x1", "abs(x1**2 - 1) + 0.3*x1 - 0.2*x1*x2"), _p("p2", "x2", "(x2 - 0.5*x1 - 0.5)**2")),
              lambda i, a: (A(a[0] ** 2 - 1) + 0.3 * a[0] - 0.2 * a[0] * a[1]) if i == 0 else
              (a[1] - 0.5 * a[0] - 0.5) ** 2,
              (("other kink", (1.0, 1.0)),),
              "unique; the kink x1 = -1, x2 = 0 (by hand)", reference=(-1.0, 0.0)),
        # max((x1 - 2)^2, 0.5 (x1 - 2)^2 + 1): the second branch holds for |x1 - 2| <= sqrt 2; its minimum with
        # 0.2 x1 x2 is x1 = 2 - 0.2 x2; BR2 = 1 - 0.05 x1: x1 = 1.8/0.99 (on that branch, away from the kinks),
        # unique (convex players, contraction 0.01). Start beyond the kink at 2 + sqrt 2.
        _Game("ns-max-smooth-side", "nonsmooth",
              (_p("p1", "x1", "max((x1 - 2)**2, 0.5*(x1 - 2)**2 + 1) + 0.2*x1*x2"),
               _p("p2", "x2", "(x2 - 1)**2 + 0.1*x1*x2")),
              lambda i, a: (np.maximum((a[0] - 2) ** 2, 0.5 * (a[0] - 2) ** 2 + 1) + 0.2 * a[0] * a[1]) if i == 0 else
              ((a[1] - 1) ** 2 + 0.1 * a[0] * a[1]),
              (("beyond the kink", (5.0, 0.0)),),
              "unique; x1 = 1.8/0.99, x2 = 1 - 0.09/0.99 (by hand)", reference=(1.8 / 0.99, 1 - 0.09 / 0.99)),
        # Three players with L1 couplings: BR3(x1) = 2.5 for x1 <= 2.5, BR2(x3) = x3 on [1, 3] (the kink),
        # BR1(x2) = 2 for x2 >= 2; so (2, 2.5, 2.5); for x1 > 2.5 the chain returns 2 again: unique.
        _Game("ns-abs-3p", "nonsmooth",
              (_p("p1", "x1", "abs(x1 - x2) + 0.5*(x1 - 1)**2"), _p("p2", "x2", "abs(x2 - x3) + 0.5*(x2 - 2)**2"),
               _p("p3", "x3", "0.5*(x3 - 3)**2 + 0.5*abs(x3 - x1)")),
              lambda i, a: (A(a[0] - a[1]) + 0.5 * (a[0] - 1) ** 2, A(a[1] - a[2]) + 0.5 * (a[1] - 2) ** 2,
                            0.5 * (a[2] - 3) ** 2 + 0.5 * A(a[2] - a[0]))[i],
              (("origin", (0.0, 0.0, 0.0)),),
              "unique; (2, 2.5, 2.5) by chasing the best responses by hand", reference=(2.0, 2.5, 2.5)),
    ]


def _unbounded() -> list[_Game]:
    E = np.exp
    return [
        # x1^3/3 - 2 x1 + 0.3 x1 x2 -> -inf as x1 -> -inf for every x2. Start: the KKT point where p1 sits at its
        # local minimum (x1^2 = 2 - 0.3 x2, x2 = 1 - 0.05 x1).
        _Game("ub-cubic", "unbounded",
              (_p("p1", "x1", "x1**3/3 - 2*x1 + 0.3*x1*x2"), _p("p2", "x2", "(x2 - 1)**2 + 0.1*x1*x2")),
              lambda i, a: (a[0] ** 3 / 3 - 2 * a[0] + 0.3 * a[0] * a[1]) if i == 0 else
              ((a[1] - 1) ** 2 + 0.1 * a[0] * a[1]),
              (("local minimum", (1.3113620517524083, 0.9344318974123795)),),
              "no equilibrium: p1 unbounded below (x1 -> -inf)", has_gne=False),
        # A two-variable player with a cubic in y2 (unbounded as y2 -> -inf); start at its local minimum.
        _Game("ub-cubic-2d", "unbounded",
              (_p("p1", "y1 y2", "(y1 - 1)**2 + 0.2*y2**3 - y2 + 0.5*y1*x3"), _p("p2", "x3", "(x3 + 0.5*y2)**2")),
              lambda i, a: ((a[0] - 1) ** 2 + 0.2 * a[1] ** 3 - a[1] + 0.5 * a[0] * a[2]) if i == 0 else
              (a[2] + 0.5 * a[1]) ** 2,
              (("local minimum", (1.1613743060919757, 1.2909944487358056, -0.6454972243679028)),),
              "no equilibrium: p1 unbounded below (y2 -> -inf)", has_gne=False),
        # A concave player; the start is the game's KKT point (x1 = 0.08/0.6, x2 = 0.5 x1 + 0.1), a maximum of J1.
        _Game("ub-concave", "unbounded",
              (_p("p1", "x1", "-0.5*x1**2 + 0.8*x1*x2"), _p("p2", "x2", "(x2 - 0.5*x1 - 0.1)**2")),
              lambda i, a: (-0.5 * a[0] ** 2 + 0.8 * a[0] * a[1]) if i == 0 else (a[1] - 0.5 * a[0] - 0.1) ** 2,
              (("KKT point", (0.08 / 0.6, 0.04 / 0.6 + 0.1)),),
              "no equilibrium: p1 concave, unbounded below", has_gne=False),
        # Convex near 0, decreasing beyond |x1| = 50 and negative beyond 71 (x1^2 - 2e-4 x1^4).
        _Game("ub-quartic-far", "unbounded",
              (_p("p1", "x1", "x1**2 - 0.0002*x1**4 + 0.2*x1*x2"), _p("p2", "x2", "(x2 - 0.5*x1)**2")),
              lambda i, a: (a[0] ** 2 - 2e-4 * a[0] ** 4 + 0.2 * a[0] * a[1]) if i == 0 else (a[1] - 0.5 * a[0]) ** 2,
              (("near the local minimum", (0.3, 0.2)),),
              "no equilibrium: p1 unbounded below for |x1| > ~71", has_gne=False),
        # The same in two variables: y1^2 + 2 y2^2 - 1e-3 (y1^2 + y2^2)^2 turns down beyond radius ~ 22-32.
        _Game("ub-quartic-far-2d", "unbounded",
              (_p("p1", "y1 y2", "y1**2 + 2*y2**2 - 0.001*(y1**2 + y2**2)**2 + 0.1*y1*x3"),
               _p("p2", "x3", "(x3 - y2)**2")),
              lambda i, a: (a[0] ** 2 + 2 * a[1] ** 2 - 1e-3 * (a[0] ** 2 + a[1] ** 2) ** 2 + 0.1 * a[0] * a[2])
              if i == 0 else (a[2] - a[1]) ** 2,
              (("near the local minimum", (0.5, -0.5, 0.0)),),
              "no equilibrium: p1 unbounded below far from 0", has_gne=False),
        # Linear in x1 >= 0 with slope x2 - 3 < 0 for every x2 the game allows (BR2 = 1 - 0.1 x1 <= 1).
        _Game("ub-linear", "unbounded",
              (_p("p1", "x1", "x1*(x2 - 3)", [0], [INF]), _p("p2", "x2", "(x2 - 1)**2 + 0.2*x2*x1")),
              lambda i, a: (a[0] * (a[1] - 3)) if i == 0 else ((a[1] - 1) ** 2 + 0.2 * a[1] * a[0]),
              (("inside", (0.5, 1.0)),),
              "no equilibrium: p1 runs to +inf (its LP is unbounded for x2 < 3)", has_gne=False),
        # No minimiser: 3 exp(x1 - x2/2) > 0 decreases towards 0 as x1 -> -inf.
        _Game("ub-exp", "unbounded",
              (_p("p1", "x1", "3*exp(x1 - 0.5*x2)"), _p("p2", "x2", "(x2 + 1)**2")),
              lambda i, a: 3 * E(a[0] - 0.5 * a[1]) if i == 0 else (a[1] + 1) ** 2,
              (("origin", (0.0, -1.0)),),
              "no equilibrium: p1's cost has no minimiser (infimum 0 not attained)", has_gne=False),
        # No minimiser in two variables: softplus(y2 - 2 y1) + (y1 + y2 - 1)^2 -> 0 along y1 + y2 = 1, y1 -> +inf.
        _Game("ub-softplus-2d", "unbounded",
              (_p("p1", "y1 y2", "log(1 + exp(y2 - 2*y1)) + (y1 + y2 - 1)**2"), _p("p2", "x3", "(x3 - y1)**2")),
              lambda i, a: (np.logaddexp(0.0, a[1] - 2 * a[0]) + (a[0] + a[1] - 1) ** 2) if i == 0 else
              (a[2] - a[0]) ** 2,
              (("middle", (0.3, 0.7, 0.3)),),
              "no equilibrium: p1's cost has no minimiser (infimum 0 along y1 + y2 = 1)", has_gne=False),
        # Linear cost, unbounded only along directions the rows leave open: c = (-1 + 0.1 x3, -1) with x3 = 1;
        # rows y1 + 2 y2 <= 4, y1 - y2 >= -1: d = (2, -1) keeps y1 + 2 y2 and raises y1 - y2, c.d = -0.8 < 0.
        _Game("ub-lp-rows", "unbounded",
              (_p("p1", "y1 y2", "-y1 - y2 + 0.1*y1*x3", constraints=("y1 + 2*y2 <= 4", "y1 - y2 >= -1")),
               _p("p2", "x3", "(x3 - 1)**2")),
              lambda i, a: (-a[0] - a[1] + 0.1 * a[0] * a[2]) if i == 0 else (a[2] - 1) ** 2,
              (("vertex", (2.0, 1.0, 1.0)),),
              "no equilibrium: p1 unbounded along (2, -1), feasible through its rows", has_gne=False,
              rows=lambda i, a: [a[0] + 2 * a[1] - 4, -1 - (a[0] - a[1])] if i == 0 else []),
        # An indefinite quadratic in a cone |y2| <= 1 + 2 y1: along the cone's edge (1, 2) the cost falls like -3 t^2,
        # but y2 alone is blocked and y1 alone rises. Start: the interior saddle (y1 = -0.1 x3, y2 = 0), x3 = 0.5.
        _Game("ub-saddle-cone", "unbounded",
              (_p("p1", "y1 y2", "y1**2 - y2**2 + 0.2*y1*x3", constraints=("y2 <= 1 + 2*y1", "-y2 <= 1 + 2*y1")),
               _p("p2", "x3", "(x3 - 0.5)**2 + 0.01*x3*y1")),
              lambda i, a: (a[0] ** 2 - a[1] ** 2 + 0.2 * a[0] * a[2]) if i == 0 else
              ((a[2] - 0.5) ** 2 + 0.01 * a[2] * a[0]),
              (("saddle", (-0.05002501250625312, 0.0, 0.5002501250625313)),),
              "no equilibrium: p1 unbounded along the cone's edge", has_gne=False,
              rows=lambda i, a: [a[1] - 1 - 2 * a[0], -a[1] - 1 - 2 * a[0]] if i == 0 else []),
        # Three players, the third cubic (unbounded as x3 -> -inf); start at the KKT point near its local minimum.
        _Game("ub-cubic-3p", "unbounded",
              (_p("p1", "x1", "(x1 - 0.5*x3)**2"), _p("p2", "x2", "(x2 - x1 + 1)**2"),
               _p("p3", "x3", "x3**3 - 3*x3 + 0.2*x3*(x1 + x2)")),
              lambda i, a: ((a[0] - 0.5 * a[2]) ** 2, (a[1] - a[0] + 1) ** 2,
                            a[2] ** 3 - 3 * a[2] + 0.2 * a[2] * (a[0] + a[1]))[i],
              (("local minimum", (0.5, -0.5, 1.0)),),
              "no equilibrium: p3 unbounded below", has_gne=False),
    ]


def _infeasible() -> list[_Game]:
    return [
        _Game("inf-shared-rows", "infeasible",
              (_p("p1", "x1", "(x1 - 1)**2 + 0.5*x1*x2"), _p("p2", "x2", "(x2 - 2)**2")),
              lambda i, a: ((a[0] - 1) ** 2 + 0.5 * a[0] * a[1]) if i == 0 else (a[1] - 2) ** 2,
              (("origin", (0.0, 0.0)),),
              "no equilibrium: x1 + 2 x2 >= 4 and x1 + 2 x2 <= 2", has_gne=False,
              rows=lambda i, a: [4 - a[0] - 2 * a[1], a[0] + 2 * a[1] - 2],
              shared=("x1 + 2*x2 >= 4", "x1 + 2*x2 <= 2")),
        # Own rows of one player: y2 <= y1 - 2 and y2 >= 0.5 + 0.5 y1 need y1 >= 5, y2 >= 3, against y1 + y2 <= 1.
        _Game("inf-own-rows", "infeasible",
              (_p("p1", "y1 y2", "y1**2 + y2**2 + y1*x3",
                  constraints=("y1 + y2 <= 1", "y2 >= 0.5 + 0.5*y1", "y1 - y2 >= 2")),
               _p("p2", "x3", "(x3 - 1)**2")),
              lambda i, a: (a[0] ** 2 + a[1] ** 2 + a[0] * a[2]) if i == 0 else (a[2] - 1) ** 2,
              (("origin", (0.0, 0.0, 0.0)),),
              "no equilibrium: p1's own rows contradict each other", has_gne=False,
              rows=lambda i, a: [a[0] + a[1] - 1, 0.5 + 0.5 * a[0] - a[1], 2 - a[0] + a[1]] if i == 0 else []),
        # Each player's own row is satisfiable for every choice of the other, but not both at once:
        # x1 >= x2 + 1 and x2 >= x1 + 0.5.
        _Game("inf-crossed-rows", "infeasible",
              (_p("p1", "x1", "x1**2", constraints=("x1 >= x2 + 1",)),
               _p("p2", "x2", "x2**2", constraints=("x2 >= x1 + 0.5",))),
              lambda i, a: a[i] ** 2,
              (("origin", (0.0, 0.0)),),
              "no equilibrium: the two players' own rows have no common point", has_gne=False,
              rows=lambda i, a: [a[1] + 1 - a[0]] if i == 0 else [a[0] + 0.5 - a[1]]),
        _Game("inf-bounds-vs-shared", "infeasible",
              (_p("p1", "x1", "(x1 - 0.5)**2 + 0.1*x1*x2", [0], [1]), _p("p2", "x2", "(x2 - 0.3)**2", [0], [1])),
              lambda i, a: ((a[0] - 0.5) ** 2 + 0.1 * a[0] * a[1]) if i == 0 else (a[1] - 0.3) ** 2,
              (("inside the box", (0.5, 0.5)),),
              "no equilibrium: x1 + x2 >= 2.5 on [0, 1]^2", has_gne=False,
              rows=lambda i, a: [2.5 - a[0] - a[1]], shared=("x1 + x2 >= 2.5",)),
        # The disk (x1 - 1)^2 + (x2 + 0.5)^2 <= 0.5 lies 2.3/sqrt 2 = 1.63 > sqrt 0.5 from the line x2 = x1 + 0.8.
        _Game("inf-disk-halfplane", "infeasible",
              (_p("p1", "x1", "(x1 - 2)**2 + x1*x2"), _p("p2", "x2", "(x2 + 1)**2")),
              lambda i, a: ((a[0] - 2) ** 2 + a[0] * a[1]) if i == 0 else (a[1] + 1) ** 2,
              (("disk centre", (1.0, -0.5)),),
              "no equilibrium: a disk and a half-plane that miss", has_gne=False,
              rows=lambda i, a: [(a[0] - 1) ** 2 + (a[1] + 0.5) ** 2 - 0.5, a[0] + 0.8 - a[1]],
              shared=("(x1 - 1)**2 + (x2 + 0.5)**2 <= 0.5", "x2 >= x1 + 0.8")),
        # Own nonconvex set of one player: the unit disk and y1 y2 >= 1 (within the disk y1 y2 <= 1/2).
        _Game("inf-disk-hyperbola", "infeasible",
              (_p("p1", "y1 y2", "(y1 - 1)**2 + (y2 - 1)**2 + 0.1*y1*x3",
                  constraints=("y1**2 + y2**2 <= 1", "y1*y2 >= 1")),
               _p("p2", "x3", "(x3 - y1)**2")),
              lambda i, a: ((a[0] - 1) ** 2 + (a[1] - 1) ** 2 + 0.1 * a[0] * a[2]) if i == 0 else (a[2] - a[0]) ** 2,
              (("near the disk's edge", (0.7, 0.7, 0.7)),),
              "no equilibrium: p1's own set is empty", has_gne=False,
              rows=lambda i, a: [a[0] ** 2 + a[1] ** 2 - 1, 1 - a[0] * a[1]] if i == 0 else []),
        # Equalities against bounds, three players: x1 = x2 >= 0.3 and x3 >= 0.5 give a sum >= 1.1, not 1.
        _Game("inf-equalities-3p", "infeasible",
              (_p("p1", "x1", "(x1 - 0.4)**2", [0.3], [INF]), _p("p2", "x2", "(x2 - 0.2)**2 + 0.1*x1*x2"),
               _p("p3", "x3", "(x3 - 1)**2", [0.5], [INF])),
              lambda i, a: ((a[0] - 0.4) ** 2, (a[1] - 0.2) ** 2 + 0.1 * a[0] * a[1], (a[2] - 1) ** 2)[i],
              (("feasible for the bounds", (0.4, 0.4, 0.5)),),
              "no equilibrium: x1 + x2 + x3 == 1, x1 == x2 with x1 >= 0.3, x3 >= 0.5", has_gne=False,
              eq_rows=lambda i, a: [a[0] + a[1] + a[2] - 1, a[0] - a[1]],
              shared=("x1 + x2 + x3 == 1", "x1 - x2 == 0")),
    ]


def _nonfinite() -> list[_Game]:
    return [
        # 0 * log of a negative number: NaN at every point (IEEE), though a symbolic "0 * anything" would hide it.
        _Game("nan-zero-log", "nan",
              (_p("p1", "x1", "(x1 - 1)**2 + 0*log(-3 - x2**2)"), _p("p2", "x2", "(x2 - x1)**2")),
              lambda i, a: ((a[0] - 1) ** 2 + 0 * np.log(-3 - a[1] ** 2)) if i == 0 else (a[1] - a[0]) ** 2,
              (("origin", (0.5, 0.0)),),
              "no equilibrium: p1's cost is NaN everywhere", has_gne=False),
        # 1/0 = inf in p2's cost at every point.
        _Game("inf-div-zero", "nan",
              (_p("p1", "x1", "(x1 - 1)**2"), _p("p2", "x2", "(x2 - 2)**2 + x2/(x1 - x1)")),
              lambda i, a: (a[0] - 1) ** 2 if i == 0 else ((a[1] - 2) ** 2 + a[1] / (a[0] - a[0])),
              (("origin", (0.0, 0.0)),),
              "no equilibrium: p2's cost is infinite or NaN everywhere", has_gne=False),
        # sqrt of a negative number on the whole box [0, 3].
        _Game("nan-sqrt-box", "nan",
              (_p("p1", "x1", "(x1 - 1)**2 + sqrt(x1 - 5)", [0], [3]), _p("p2", "x2", "(x2 - x1)**2")),
              lambda i, a: ((a[0] - 1) ** 2 + np.sqrt(a[0] - 5)) if i == 0 else (a[1] - a[0]) ** 2,
              (("inside", (1.0, 1.0)),),
              "no equilibrium: p1's cost is NaN on its whole box", has_gne=False),
        # acos of a number > 1 at every point of a two-variable player.
        _Game("nan-acos-2d", "nan",
              (_p("p1", "y1 y2", "y1**2 + (y2 - 1)**2 + acos(2 + y1**2 + y2**2)"), _p("p2", "x3", "(x3 - y1)**2")),
              lambda i, a: (a[0] ** 2 + (a[1] - 1) ** 2 + np.arccos(2 + a[0] ** 2 + a[1] ** 2)) if i == 0 else
              (a[2] - a[0]) ** 2,
              (("origin", (0.0, 1.0, 0.0)),),
              "no equilibrium: p1's cost is NaN everywhere", has_gne=False),
    ]


def _no_pure() -> list[_Game]:
    return [
        # Both players strictly concave on [-1, 1]: best responses are vertices. BR1 = +1 if x2 < -0.05, -1 if
        # x2 > -0.05 (J1(1) - J1(-1) = 4 x2 + 0.2); BR2 = +1 if x1 > 0, -1 if x1 < 0 (J2(1) - J2(-1) = -4 x1).
        # A pure equilibrium is a vertex pair: x1 = 1 -> x2 = 1 -> x1 = -1; x1 = -1 -> x2 = -1 -> x1 = 1: none.
        # Start: the interior KKT point (0.025, -0.025), a maximum for both.
        _Game("nopure-concave-box", "no pure NE",
              (_p("p1", "x1", "2*x1*x2 - x1**2 + 0.1*x1", [-1], [1]), _p("p2", "x2", "-2*x1*x2 - x2**2", [-1], [1])),
              lambda i, a: (2 * a[0] * a[1] - a[0] ** 2 + 0.1 * a[0]) if i == 0 else (-2 * a[0] * a[1] - a[1] ** 2),
              (("KKT point", (0.025, -0.025)),),
              "no pure equilibrium (matching pennies on vertices, proof at the game)", has_gne=False),
        # Tilted double wells: f(x) = (x^2 - 1)^2 + c x has its global minimum on the side opposite c (f(-s|x|) <
        # f(s|x|)), at +-1 if c = 0, never at 0. So BR1 has sign -sign(x2) and BR2 sign +sign(x1), both nonzero: a
        # pure equilibrium would need sign(x1) = -sign(x2) = -sign(x1). None. Starts: the KKT point at the origin
        # (both at a local maximum) and a KKT point with both players at local minima.
        _Game("nopure-wells", "no pure NE",
              (_p("p1", "x1", "(x1**2 - 1)**2 + 0.5*x1*x2"), _p("p2", "x2", "(x2**2 - 2)**2 - 0.3*x1*x2")),
              lambda i, a: ((a[0] ** 2 - 1) ** 2 + 0.5 * a[0] * a[1]) if i == 0 else
              ((a[1] ** 2 - 2) ** 2 - 0.3 * a[0] * a[1]),
              (("KKT point at the origin", (0.0, 0.0)), ("two local minima", (0.8944618346819121, 1.4306954705977066))),
              "no pure equilibrium (sign cycle, proof at the game)", has_gne=False),
        # An odd cycle of anti-coordination: BR_i has sign -sign(x_{i+1}), never 0, so sign(x1) = -sign(x2) =
        # sign(x3) = -sign(x1): no pure equilibrium.
        _Game("nopure-cycle-3p", "no pure NE",
              tuple(_p(f"p{k + 1}", f"x{k + 1}", f"(x{k + 1}**2 - 1)**2 + 0.4*x{k + 1}*x{(k + 1) % 3 + 1}")
                    for k in range(3)),
              lambda i, a: (a[i] ** 2 - 1) ** 2 + 0.4 * a[i] * a[(i + 1) % 3],
              (("all positive", (0.9486832980505138,) * 3),),
              "no pure equilibrium (odd sign cycle, proof at the game)", has_gne=False),
    ]


# --------------------------------------------------------------------------------------------------------------
# problems
# --------------------------------------------------------------------------------------------------------------


def games() -> list[_Game]:
    """Every game of the family (each with its starts)."""
    return _games()


def problems() -> list[Problem]:
    out = []
    for g in _games():
        for label, start in g.starts:
            name = f"{g.name} @ {label}" if len(g.starts) > 1 else g.name
            out.append(Problem(
                family=FAMILY, name=name, start=label, config_yaml=g.config_yaml(start, g.name),
                has_gne=g.has_gne,
                reference=None if g.reference is None else np.array(g.reference, dtype=float),
                reference_tol=1e-5,
                reference_source=g.derivation,
                best_response_gaps=lambda a, g=g: best_response_gaps(g, a),
                kind=g.kind,
                costs=g.costs,
                notes=g.derivation))
    return out


# --------------------------------------------------------------------------------------------------------------
# the references, recomputed
# --------------------------------------------------------------------------------------------------------------


def best_response_iteration(game: _Game, a0: Sequence[float], iterations: int = 200) -> np.ndarray:
    """Gauss-Seidel iteration of the check's global best responses from a0 (clipped into the bounds)."""
    a = np.clip(np.array(a0, dtype=float), game.lower, game.upper)
    for _ in range(iterations):
        old = a.copy()
        for i in range(len(game.players)):
            r = best_response(game, i, a)
            if r.point is not None and r.gap > 0:
                a[game.slices[i]] = r.point
        if np.max(np.abs(a - old)) <= 1e-12:
            break
    return a


def _stationarity_polish(game: _Game, a: np.ndarray) -> np.ndarray:
    """Newton's method (scipy.optimize.root) on the players' stationarity with complex-step gradients, variables at
    a bound held there: the best-response iteration's point to rounding (smooth costs only)."""
    at_bound = (np.abs(a - game.lower) <= 1e-7) | (np.abs(a - game.upper) <= 1e-7)
    fixed = np.where(np.abs(a - game.lower) <= 1e-7, game.lower, game.upper)
    free = ~at_bound
    owner = np.concatenate([np.full(s, i) for i, s in enumerate(game.sizes)])
    h = 1e-30

    def full(y: np.ndarray) -> np.ndarray:
        b = np.where(at_bound, fixed, 0.0).astype(complex)
        b[free] = y
        return b

    def grad(y: np.ndarray) -> np.ndarray:
        out = []
        for k in np.flatnonzero(free):
            b = full(y)
            b[k] += 1j * h
            out.append(np.imag(game.cost(int(owner[k]), b)) / h)
        return np.array(out, dtype=float)

    if not free.any():
        return np.where(at_bound, fixed, a)
    sol = optimize.root(grad, a[free], method="hybr", options={"xtol": 1e-14})
    b = np.where(at_bound, fixed, a)
    if np.max(np.abs(grad(sol.x))) <= 1e-12 and np.max(np.abs(sol.x - a[free])) <= 1e-5:
        b[free] = sol.x
    return b


def compute_references(names: Sequence[str] | None = None) -> dict[str, np.ndarray]:
    """Every equilibrium of the family recomputed: the best-response iteration from the game's first start, then (for
    the smooth kinds) Newton's method on the stationarity of the free variables."""
    out = {}
    for g in _games():
        if not g.has_gne or (names is not None and g.name not in names):
            continue
        a = best_response_iteration(g, g.starts[0][1])
        out[g.name] = _stationarity_polish(g, a) if g.kind == "nonconvex" else a
    return out


def fixed_points(game: _Game, lo: float = -10.0, hi: float = 10.0, m: int = 4001) -> list[tuple[float, float]]:
    """A two-player game of scalar players: the pure equilibria, as the fixed points of x1 -> BR1(BR2(x1)), with
    both best responses taken over a grid of m points on [lo, hi] (or the players' boxes), clustered."""
    assert game.sizes == [1, 1]
    axes = [np.linspace(max(lo, game.lower[k]), min(hi, game.upper[k]), m) for k in range(2)]
    X1, X2 = np.meshgrid(axes[0], axes[1], indexing="ij")
    a = np.stack([X1, X2])
    with np.errstate(all="ignore"):
        J1 = np.where(np.isfinite(game.cost(0, a)), game.cost(0, a), INF)
        J2 = np.where(np.isfinite(game.cost(1, a)), game.cost(1, a), INF)
    br1 = axes[0][np.argmin(J1, axis=0)]  # BR1 at each x2 of the grid
    br2 = axes[1][np.argmin(J2, axis=1)]  # BR2 at each x1 of the grid
    composite = br1[np.clip(np.searchsorted(axes[1], br2), 0, m - 1)]
    step = max(axes[0][1] - axes[0][0], axes[1][1] - axes[1][0])
    close = np.abs(composite - axes[0]) <= 3 * step
    found: list[tuple[float, float]] = []
    for k in np.flatnonzero(close):
        if not found or axes[0][k] - found[-1][0] > 10 * step:
            found.append((float(axes[0][k]), float(br2[k])))
    return found


def _main() -> None:
    refs = compute_references()
    for g in _games():
        if not g.has_gne and g.kind != "no pure NE":
            continue
        line = f"{g.name}: "
        if g.name in refs:
            a = refs[g.name]
            stored = ("none stored" if g.reference is None
                      else f"{np.max(np.abs(a - np.array(g.reference))):.1e} from the stored")
            gaps = best_response_gaps(g, a)
            line += f"{a.tolist()!r} ({stored}; gaps <= {max(gaps.values()):.1e})"
        if g.sizes == [1, 1] and g.rows is None:
            line += f"; scan: {len(fixed_points(g))} fixed point(s) {fixed_points(g)}"
        print(line, flush=True)


if __name__ == "__main__":
    _main()
