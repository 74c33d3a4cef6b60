"""Closed loops of games with positions: the paths in the plane and the pairwise distances (`gnerun figures`).

A game has positions when its states come in pairs ``px<i>``, ``py<i>`` (or ``x<i>``, ``y<i>``), one pair per
vehicle. A shared constraint written as a distance, ``(px1 - px2)**2 + (py1 - py2)**2 >= R`` with R an expression
of the parameters and the stage tau, gives the pair's required distance sqrt(R), drawn at tau = 0 (the step the
plant takes). Sampling times whose solver step failed and those where the safeguard applied a fallback plan are
marked on both panels. Everything is read from the log.
"""

from __future__ import annotations

import math
import re

from ..language.expr import evaluate, numpy_functions, parse_constraint
from ..log.mcap_log import RunRecord

_X = re.compile(r"^p?x(\d+)$")
_DISTANCE = re.compile(r"^\(\s*(\w+)\s*-\s*(\w+)\s*\)\s*\*\*\s*2\s*\+\s*\(\s*(\w+)\s*-\s*(\w+)\s*\)\s*\*\*\s*2\s*>=")
# the failure statuses of a sampling time (the solvers' FAILURES, which view does not import)
FAILED = {"singular_jacobian", "diverged", "nan", "subproblem_failed", "line_search_failed",
          "infeasible_stage_constraint", "stalled"}


def vehicles(state_names: list[str]) -> list[tuple[str, int, int]]:
    """(label, index of its x position, index of its y position) per vehicle, from the state names."""
    index = {name: k for k, name in enumerate(state_names)}
    out = []
    for name, k in index.items():
        m = _X.match(name)
        if m:
            y = name.replace("x", "y", 1)
            if y in index:
                out.append((m.group(1), k, index[y]))
    return out


def required_distances(config: dict) -> dict[tuple[str, str], float]:
    """The distance each pair of position states must keep at tau = 0, from the shared constraints written as
    squared distances (x positions of the two vehicles as the key)."""
    game = config.get("game") or {}
    params = {k: v for k, v in (game.get("parameters") or {}).items() if isinstance(v, int | float)}
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


def has_positions(run: RunRecord) -> bool:
    return len(vehicles(list((run.config.get("game") or {}).get("states") or []))) >= 1


def paths_figure(run: RunRecord, loops: dict[int, dict[str, list[dict]]]):
    """Panel (a): every vehicle's path per K; panel (b): pairwise distances per K against the required ones."""
    import matplotlib.pyplot as plt

    from .figures import _legend, _panels, failed_steps, fallback_steps

    names = list((run.config.get("game") or {}).get("states") or [])
    cars = vehicles(names)
    required = required_distances(run.config)
    fig, (ax_p, ax_d), width = _panels(2)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    styles = ["-", "--", ":", "-."]
    any_marked = False
    for n, (K, topics) in enumerate(loops.items()):
        states = [m for m in topics.get("state", []) if m.get("x") is not None]
        ls = styles[n % len(styles)]
        steps = set(failed_steps(states)) | set(fallback_steps(states))
        marked = [m for m in states if m["t"] in steps]
        any_marked = any_marked or bool(marked)
        for c, (label, ix, iy) in enumerate(cars):
            xs = [_num(m["x"][ix]) for m in states]
            ys = [_num(m["x"][iy]) for m in states]
            ax_p.plot(xs, ys, ls, color=colors[c % len(colors)], lw=1.0,
                      label=f"{label}, K = {K}" if len(loops) > 1 else label)
            if xs:
                ax_p.plot(xs[:1], ys[:1], "o", color=colors[c % len(colors)], ms=3)
            ax_p.plot([_num(m["x"][ix]) for m in marked], [_num(m["x"][iy]) for m in marked], "x",
                      color="k", ms=3, mew=0.6)
        for p, (a, b) in enumerate((a, b) for i, a in enumerate(cars) for b in cars[i + 1:]):
            t = [m["t"] for m in states]
            d = [math.hypot(_num(m["x"][a[1]]) - _num(m["x"][b[1]]), _num(m["x"][a[2]]) - _num(m["x"][b[2]]))
                 for m in states]
            ax_d.plot(t, d, ls, color=colors[p % len(colors)], lw=1.0,
                      label=f"{a[0]}-{b[0]}, K = {K}" if len(loops) > 1 else f"{a[0]}-{b[0]}")
            ax_d.plot([ti for ti, m in zip(t, states, strict=True) if m["t"] in steps],
                      [di for di, m in zip(d, states, strict=True) if m["t"] in steps], "x", color="k", ms=3, mew=0.6)
    for p, (a, b) in enumerate((a, b) for i, a in enumerate(cars) for b in cars[i + 1:]):
        r = required.get((names[a[1]], names[b[1]]))
        if r is not None:
            ax_d.axhline(r, color=colors[p % len(colors)], lw=0.8, ls=(0, (1, 1)))
    if required:
        ax_d.plot([], [], color="0.4", lw=0.8, ls=(0, (1, 1)), label="required")
    if any_marked:  # (in the paths' legend: the distances' marks are the same)
        ax_p.plot([], [], "x", color="k", ms=3, mew=0.6, label="fallback / failed step")
    ax_p.set_xlabel("x")
    ax_p.set_ylabel("y")
    xlo, xhi = ax_p.get_xlim()
    ylo, yhi = ax_p.get_ylim()
    if 1 / 3 <= (yhi - ylo) / max(xhi - xlo, 1e-12) <= 3:  # true proportions, unless a road squeezes them flat
        ax_p.set_aspect("equal", adjustable="datalim")
    ax_p.set_title("(a) paths")
    ax_d.set_xlabel("t")
    ax_d.set_ylabel("distance")
    ax_d.set_title("(b) pairwise distances")
    for ax in (ax_p, ax_d):
        _legend(ax, width)
    return fig


def _num(v) -> float:
    return math.nan if v is None else float(v)
