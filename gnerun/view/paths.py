"""Closed loops of games with positions: the paths in the plane and the distances between vehicles (`gnerun figures`).

A game has positions when its states come in pairs ``px<i>``, ``py<i>`` (or ``x<i>``, ``y<i>``), one pair per
vehicle, labelled by the name of the agent that drives it. Many vehicles stay readable: a colour per vehicle, a line
style per K, one legend entry per vehicle and per K; the distances are each vehicle's to its nearest other (not one
curve per pair), and the closest pair of the run is named and marked. A shared constraint written as a distance,
``(px1 - px2)**2 + (py1 - py2)**2 >= R`` with R an expression of the parameters and the stage tau, gives the pair's
required distance sqrt(R), drawn at tau = 0 (the step the plant takes). The constraints on one vehicle's position
alone (a road's or a lane's edges, an arena) are drawn where they hold with equality, in the vehicle's colour (grey
where they are the same for every vehicle, their outside shaded), and the panel reaches the nearest edge on each
side of the paths. Sampling times whose solver step failed and those where the safeguard applied a fallback plan are
marked on both panels. Everything is read from the log.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from ..language.expr import CONSTANTS, Constraint, evaluate, numpy_functions, parse_constraint
from ..language.vehicles import vehicles
from ..log.mcap_log import RunRecord
from .panels import K_STYLES, failed_steps, fallback_steps, k_line, legend, panels
from .states import agent_numbers, parameters

_DISTANCE = re.compile(r"^\(\s*(\w+)\s*-\s*(\w+)\s*\)\s*\*\*\s*2\s*\+\s*\(\s*(\w+)\s*-\s*(\w+)\s*\)\s*\*\*\s*2\s*>=")


def required_distances(config: dict) -> dict[tuple[str, str], float]:
    """The distance each pair of position states must keep at tau = 0, from the shared constraints written as
    squared distances (x positions of the two vehicles as the key)."""
    game = config.get("game") or {}
    params = parameters(game)
    out: dict[tuple[str, str], float] = {}
    for spec in game.get("shared_constraints") or []:
        text = spec.get("expr") if isinstance(spec, dict) else spec
        if not isinstance(text, str):
            continue
        m = _DISTANCE.match(text.strip())
        if not m:
            continue
        try:
            rhs = float(evaluate(parse_constraint(text).rhs, {**params, "tau": 0.0, "pi": math.pi},
                                 numpy_functions()))
        except Exception:  # a right-hand side that uses states or inputs is not a fixed distance
            continue
        if rhs > 0:
            out[(m.group(1), m.group(2))] = math.sqrt(rhs)
    return out


def position_constraints(config: dict, cars: list[tuple[str, int, int]]) -> list[tuple[int, Constraint]]:
    """The constraints on one vehicle's position alone (every agent's own and the shared ones whose names, besides
    the parameters and tau, are one vehicle's x and y positions), with the index of that vehicle in ``cars``."""
    game = config.get("game") or {}
    names = list(game.get("states") or [])
    params = set(parameters(game))
    specs = [spec for agent in game.get("agents") or [] if isinstance(agent, dict)
             for spec in agent.get("constraints") or []] + list(game.get("shared_constraints") or [])
    out = []
    for spec in specs:
        text = spec.get("expr") if isinstance(spec, dict) else spec
        if not isinstance(text, str):
            continue
        try:
            con = parse_constraint(text)
        except Exception:  # a log's config is data: one that does not parse is not drawn
            continue
        free = con.names - params - set(CONSTANTS) - {"tau"}
        for c, (_, ix, iy) in enumerate(cars):
            if free and free <= {names[ix], names[iy]}:
                out.append((c, con))
    return out


def has_positions(run: RunRecord) -> bool:
    return len(vehicles(list((run.config.get("game") or {}).get("states") or []))) >= 1


def vehicle_names(config: dict, cars: list[tuple[str, int, int]]) -> list[str]:
    """Each vehicle's label: the name of the agent that drives it (:func:`agent_numbers`), else "vehicle <number>"."""
    by_number = agent_numbers(config)
    return [by_number.get(number, f"vehicle {number}") for number, _, _ in cars]


def paths_figure(run: RunRecord, loops: dict[int, dict[str, list[dict]]]):
    """Panel (a): every vehicle's path per K (a colour per vehicle, a line style per K); panel (b): each vehicle's
    distance to the nearest other per K (the pair's distance for two vehicles) against the required one, with the
    closest pair of the run marked on both panels. One legend entry per vehicle and per K, never per pair."""
    import matplotlib.pyplot as plt
    import numpy as np
    from matplotlib.lines import Line2D

    names = list((run.config.get("game") or {}).get("states") or [])
    cars = vehicles(names)
    who = vehicle_names(run.config, cars)
    required = required_distances(run.config)
    fig, (ax_p, ax_d), width = panels(2)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    many = len(loops) > 1
    any_marked = False
    closest = None  # (distance, K, t, a, b) over every K and sampling time
    for n, (K, topics) in enumerate(loops.items()):
        states = [m for m in topics.get("state", []) if m.get("x") is not None]
        ls = K_STYLES[n % len(K_STYLES)]
        # the first K widest and lightest, each later one narrower on top of it: equal paths show both
        lw, alpha = k_line(n, len(loops))
        steps = set(failed_steps(states)) | set(fallback_steps(states))  # shows
        marked = [m for m in states if m["t"] in steps]
        any_marked = any_marked or bool(marked)
        t = np.array([m["t"] for m in states])
        xy = np.array([[[_num(m["x"][ix]), _num(m["x"][iy])] for _, ix, iy in cars] for m in states]).reshape(
            len(states), len(cars), 2)
        for c, label in enumerate(who):
            color = colors[c % len(colors)]
            ax_p.plot(xy[:, c, 0], xy[:, c, 1], ls, color=color, lw=lw, alpha=alpha,
                      label=f"{label}, K = {K}" if many else label)
            if len(t):
                ax_p.plot(xy[:1, c, 0], xy[:1, c, 1], "o", color=color, ms=3)
            ax_p.plot([_num(m["x"][cars[c][1]]) for m in marked], [_num(m["x"][cars[c][2]]) for m in marked], "x",
                      color="k", ms=3, mew=0.6)
        # distances: d[t, a, b], the pair's; infinite on the diagonal (no vehicle is its own nearest)
        d = np.hypot(xy[:, :, None, 0] - xy[:, None, :, 0], xy[:, :, None, 1] - xy[:, None, :, 1])
        d[:, np.arange(len(cars)), np.arange(len(cars))] = np.inf
        with np.errstate(invalid="ignore"):
            finite = np.where(np.isfinite(d), d, np.inf)
        if len(t) and np.isfinite(finite).any():
            k, a, b = np.unravel_index(np.argmin(finite), finite.shape)
            if closest is None or finite[k, a, b] < closest[0]:
                closest = (float(finite[k, a, b]), K, int(t[k]), min(a, b), max(a, b), xy[k, a], xy[k, b])
        curves = ([(f"{who[0]}-{who[1]}", d[:, 0, 1], "0.2")] if len(cars) == 2 else
                  [(who[c], np.where(np.isnan(d[:, c]).any(axis=1), np.nan, d[:, c].min(axis=1)) if len(t) else
                    np.zeros(0), colors[c % len(colors)]) for c in range(len(cars))] if len(cars) > 2 else [])
        at = np.isin(t, sorted(steps))
        for label, y, color in curves:
            ax_d.plot(t, y, ls, color=color, lw=lw, alpha=alpha, label=f"{label}, K = {K}" if many else label)
            ax_d.plot(t[at], y[at], "x", color="k", ms=3, mew=0.6)
    # one entry per vehicle, per K, then what is drawn on both panels
    handles = [Line2D([], [], color=colors[c % len(colors)], lw=1.2, label=label) for c, label in enumerate(who)]
    if many:
        handles += [Line2D([], [], color="0.3", ls=K_STYLES[n % len(K_STYLES)], lw=k_line(n, len(loops))[0],
                           alpha=k_line(n, len(loops))[1], label=f"K = {K}") for n, K in enumerate(loops)]
    if any_marked:
        handles.append(Line2D([], [], ls="none", marker="x", color="k", ms=3, mew=0.6,
                              label="fallback / failed step"))
    notes = []
    clearances = sorted({round(r, 12) for pair, r in required.items()
                         if any(names[a[1]] == pair[0] for a in cars) and any(names[b[1]] == pair[1] for b in cars)})
    for r in clearances:
        ax_d.axhline(r, color="0.3", lw=0.8, ls=(0, (1, 1)))
    if clearances:
        notes.append(Line2D([], [], color="0.3", lw=0.8, ls=(0, (1, 1)),
                            label="required " + ", ".join(f"{r:.3g}" for r in clearances)))
    if closest is not None:
        r, K, t0, a, b, pa, pb = closest
        style = {"color": "k", "lw": 0.6, "ls": ":", "marker": "o", "mfc": "none", "ms": 4, "mew": 0.6}
        ax_d.plot([t0], [r], **{**style, "ls": "none"}, zorder=5)
        ax_p.plot([pa[0], pb[0]], [pa[1], pb[1]], **style, zorder=5)
        notes.append(Line2D([], [], **style, label=f"closest: {who[a]}-{who[b]}\n{r:.3g} at {_when(run, t0)}"
                            + (f", K = {K}" if many else "")))
    _edges(ax_p, run.config, cars, colors, loops)
    ax_p.set_xlabel("x")
    ax_p.set_ylabel("y")
    xlo, xhi = ax_p.get_xlim()
    ylo, yhi = ax_p.get_ylim()
    if 1 / 3 <= (yhi - ylo) / max(xhi - xlo, 1e-12) <= 3:  # true proportions, unless a road squeezes them flat
        ax_p.set_aspect("equal", adjustable="datalim")
    ax_p.set_title("(a) paths")
    ax_d.set_xlabel("t")
    ax_d.set_ylabel("distance to the nearest other" if len(cars) > 2 else "distance")
    ax_d.set_title("(b) nearest distance" if len(cars) > 2 else "(b) distance")
    edge = [h for h in ax_p.get_legend_handles_labels()[0] if h.get_label() == "constraint edge"]
    legend(ax_p, width, handles + edge, own=False)
    legend(ax_d, width, notes, own=False)
    return fig


def _when(run: RunRecord, t: int) -> str:
    """A sampling time, and in seconds where the log's config gives the sampling time."""
    seconds = (run.config.get("run") or {}).get("sampling_time")
    shown = isinstance(seconds, int | float) and seconds > 0 and seconds != 1 and t > 0  # (not where it is t itself)
    return f"t = {t}" + (f" ({t * seconds:.3g} s)" if shown else "")


GRID = 600  # points per side of the grid the edges are traced on


@dataclass
class Edges:
    """The vehicles' own position constraints where they hold with equality (:func:`position_edges`)."""

    gx: np.ndarray  # the grid the constraints are evaluated on
    gy: np.ndarray
    groups: list[tuple[np.ndarray, set[int]]]  # g(X, Y) (<= 0 where it holds) and the vehicles it binds
    lines: list[tuple[np.ndarray, set[int]]]  # each traced edge (n x 2: x, y) and the vehicles it binds
    limits: tuple[float, float, float, float]  # the nearest edge on each side of the paths: x0, x1, y0, y1
    floor: float  # the smallest extent of the paths' band


def position_edges(config: dict, cars: list[tuple[str, int, int]], xs: list[float],
                   ys: list[float]) -> Edges | None:
    """The constraints of :func:`position_constraints` traced where they hold with equality on a grid three times the
    extent of the positions ``xs``, ``ys`` (evaluated at tau = 0), with the nearest edge on each side of them; None
    where there is nothing to trace."""
    import contourpy

    xs = [v for v in xs if math.isfinite(v)]
    ys = [v for v in ys if math.isfinite(v)]
    constraints = position_constraints(config, cars)
    if not xs or not ys or not constraints:
        return None
    x0, x1, y0, y1 = min(xs), max(xs), min(ys), max(ys)
    floor = max(x1 - x0, y1 - y0, 1e-3) / 20  # a path along one axis still gets a band across it
    sx, sy = max(x1 - x0, floor), max(y1 - y0, floor)
    gx = np.linspace(x0 - sx, x1 + sx, GRID)
    gy = np.linspace(y0 - sy, y1 + sy, GRID)
    X, Y = np.meshgrid(gx, gy)
    game = config.get("game") or {}
    names = list(game.get("states") or [])
    params = parameters(game)
    groups: list[tuple[np.ndarray, set[int]]] = []  # g(X, Y) (<= 0 where it holds) and the vehicles it binds
    for c, con in constraints:
        _, ix, iy = cars[c]
        try:
            with np.errstate(all="ignore"):
                g = np.broadcast_to(np.asarray(con.residual({**params, "tau": 0.0, names[ix]: X, names[iy]: Y},
                                                            numpy_functions()), dtype=float), X.shape)
        except Exception:  # a log's config is data: a constraint that cannot be evaluated is not drawn
            continue
        same = next((group for group in groups if np.array_equal(group[0], g, equal_nan=True)), None)
        if same is None:
            groups.append((g, {c}))
        else:
            same[1].add(c)
    lo_x, hi_x, lo_y, hi_y = x0, x1, y0, y1
    lines = []
    for g, who in groups:
        for line in contourpy.contour_generator(gx, gy, np.where(np.isfinite(g), g, np.nan)).lines(0.0):
            lines.append((line, who))
            # the nearest edge on each side, where it crosses the paths' band
            across_y = line[(line[:, 0] >= x0) & (line[:, 0] <= x1), 1]
            across_x = line[(line[:, 1] >= y0) & (line[:, 1] <= y1), 0]
            below, above = across_y[across_y < y0], across_y[across_y > y1]
            left, right = across_x[across_x < x0], across_x[across_x > x1]
            lo_y = min(lo_y, below.max()) if below.size else lo_y
            hi_y = max(hi_y, above.min()) if above.size else hi_y
            lo_x = min(lo_x, left.max()) if left.size else lo_x
            hi_x = max(hi_x, right.min()) if right.size else hi_x
    if not lines:
        return None
    return Edges(gx, gy, groups, lines, (lo_x, hi_x, lo_y, hi_y), floor)


def loop_positions(cars: list[tuple[str, int, int]],
                   loops: dict[int, dict[str, list[dict]]]) -> tuple[list[float], list[float]]:
    """Every x and every y position the closed loops' vehicles took."""
    xs, ys = [], []
    for topics in loops.values():
        for m in topics.get("state", []):
            if m.get("x") is not None:
                xs += [_num(m["x"][ix]) for _, ix, _ in cars]
                ys += [_num(m["x"][iy]) for _, _, iy in cars]
    return xs, ys


def _edges(ax, config: dict, cars: list[tuple[str, int, int]], colors: list[str],
           loops: dict[int, dict[str, list[dict]]]) -> None:
    """The vehicles' own position constraints where they hold with equality (:func:`position_edges`), in the
    vehicle's colour (grey where they bind every vehicle, their outside shaded); the axes then reach from the paths to
    the nearest edge on each side."""
    edges = position_edges(config, cars, *loop_positions(cars, loops))
    if edges is None:
        return
    X, Y = np.meshgrid(edges.gx, edges.gy)
    for g, who in edges.groups:
        if len(who) == len(cars) and np.any(g > 0):  # outside the road (or the arena) of every vehicle
            ax.contourf(X, Y, np.where(np.isfinite(g), g > 0, False).astype(float), levels=[0.5, 1.5],
                        colors=["0.88"], zorder=0)
    for line, who in edges.lines:
        color = "0.35" if len(who) == len(cars) else colors[min(who) % len(colors)]
        ax.plot(line[:, 0], line[:, 1], color=color, lw=2.2, alpha=0.35, solid_capstyle="butt", zorder=1)
    ax.plot([], [], color="0.35", lw=2.2, alpha=0.35, label="constraint edge")
    lo_x, hi_x, lo_y, hi_y = edges.limits
    mx, my = 0.05 * max(hi_x - lo_x, edges.floor), 0.05 * max(hi_y - lo_y, edges.floor)
    ax.set_xlim(lo_x - mx, hi_x + mx)
    ax.set_ylim(lo_y - my, hi_y + my)


def _num(v) -> float:
    return math.nan if v is None else float(v)
