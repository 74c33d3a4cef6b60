"""`gnerun replay`: Rerun recordings built from run logs alone.

Every run becomes a subtree named after its config: solves on the timeline ``iteration``
(``<run>/solve/error_norm`` ...), closed loops on the timeline ``t`` (``<run>/K<k>/x/<state>``,
``<run>/K<k>/u/<input>``, ``<run>/K<k>/e_norm``, ``<run>/K<k>/e_agent/<agent>``), the ``/log`` text on the
timeline of its run (``t`` or ``iteration``; ``log_time`` for logs of earlier versions, stamped with the wall
clock), and the resolved config as a text document. Rerun's time-series view has no log axis, so every
error and residual also has a ``log10_`` series; as in `gnerun figures`, values below
:data:`figures.FLOOR` are drawn in a band under a floor line, one row per series. Failed and fallback
sampling times are marked (``<run>/K<k>/failed_steps``, ``fallback_steps``). A closed loop of a game with positions
also draws its paths in the plane (``<run>/plane``, :func:`draw_paths`). The blueprint has a tab of the paths (a 2D
view per K, on the timeline ``t``) and one tab per figure of the paper that the runs contain: Fig. 1 (||z^k - z*||
against k, one view per solve, side by side), Fig. 2 (x(t), a view per vehicle beyond :data:`LEGEND_ROWS` states;
||e(t)|| per K, or ||Phi|| without z*), Fig. 3 (||e_i(t)|| per agent, one view per K, or ||Phi||), and tabs for the
log and the configs. Rerun's views have no axis titles: each view's name says what its axes show, and views that the
paper compares share their y range; each legend sits in the upper right corner, over room the time axis leaves for it
beyond the data.

rerun-sdk is imported here only, so that ``gnerun --help`` stays fast.
"""

from __future__ import annotations

import contextlib
import math
import os
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import InputError, Unavailable
from ..files import output_directory, output_file, write_bytes
from ..log.mcap_log import RunRecord, read_run
from ..log.messages import level_name
from ..log.topics import LOG, SOLVE_ITERATE
from .figures import (
    FLOOR,
    band_for,
    below_floor,
    closed_loops,
    disturbance,
    final_residuals,
    final_status,
    has_errors,
    number,
    run_name,
    solve_has_errors,
    solver_kind,
)
from .panels import failed_steps, fallback_steps
from .paths import loop_positions, position_edges, vehicle_names, vehicles

APPLICATION_ID = "gnerun"

# matplotlib's tab10, so that the Rerun views and `gnerun figures` colour alike
PALETTE = [(31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189), (140, 86, 75),
           (227, 119, 194), (127, 127, 127), (188, 189, 34), (23, 190, 207)]
MARK_COLOUR = (235, 235, 235)  # failed steps: light on the viewer's dark background
FALLBACK_COLOUR = (255, 221, 87)  # fallback steps (a colour no series has)
FLOOR_COLOUR = (150, 150, 150)
EDGE_COLOUR = (120, 120, 120)  # a constraint edge that binds every vehicle (a road's, an arena's)
TRAIL_BLOCK = 100  # sampling times per logged piece of a trail (a trail logged whole at every t would grow as t^2)


def _log10(v: float | None) -> float | None:
    """log10 of a positive error or residual (None for zeros and missing values: see the floor band)."""
    v = number(v)
    return math.log10(v) if v > 0 else None


def _entity_name(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_\-]", "_", text) or "run"


@dataclass
class Trace:
    """A series of a log view: its values as logged; what is drawn (log10, or a row of the band) is decided
    once every run is read."""

    entity: str
    timeline: str
    points: list[tuple[int, float]] = field(default_factory=list)  # (time, value; NaN where missing)
    failed: list[int] = field(default_factory=list)  # times marked as failed steps
    fallback: list[int] = field(default_factory=list)
    marks: str = ""  # the entity prefix of its markers ("<run>/K<k>/"), "" for none
    on_trace: bool = True  # markers at the trace's values (else along the view's top)


@dataclass
class Series:
    """The entities of one figure view, with the range of the data they show (for fixed axes)."""

    entities: list[str] = field(default_factory=list)
    labels: list[str] = field(default_factory=list)  # their legend entries
    t: list[int] = field(default_factory=list)  # [first, last] time
    y: list[float] = field(default_factory=list)  # [lowest, highest] value as drawn
    traces: list[Trace] = field(default_factory=list)  # log views: the series to draw
    group: str = ""  # views of one group share their y range (and band)
    floor: str | None = None  # the floor line's entity, when the view has a band

    def span(self, time: int) -> None:
        self.t = [min(self.t[0], time), max(self.t[1], time)] if self.t else [time, time]

    def add(self, time: int, value: float) -> None:
        self.span(time)
        self.y = [min(self.y[0], value), max(self.y[1], value)] if self.y else [value, value]


@dataclass
class Plane:
    """A 2D view of the paths in the plane of one closed loop."""

    title: str
    origin: str
    contents: list[str]
    bounds: tuple[float, float, float, float]  # x0, x1, y0, y1 as logged (y up)
    end: int  # the loop's last sampling time


@dataclass
class Contents:
    """What the blueprint's figure views show: ``fig1:<run>``, ``fig2_x``, ``fig2_e``, ``fig3:<run>: K = <k>``."""

    views: dict[str, Series] = field(default_factory=dict)
    titles: dict[str, str] = field(default_factory=dict)  # view key -> its name in the viewer
    planes: list[Plane] = field(default_factory=list)
    logs: list[str] = field(default_factory=list)
    configs: list[str] = field(default_factory=list)
    ends: dict[str, int] = field(default_factory=dict)  # timeline -> last time logged on it

    def view(self, key: str) -> Series:
        return self.views.setdefault(key, Series())

    def reach(self, timeline: str, value: int) -> None:
        self.ends[timeline] = max(self.ends.get(timeline, value), value)


LEGEND_ROWS = 8  # Fig. 2a: more states than this are drawn in a view per group (by the number their names end in)


def state_groups(states: list[str]) -> list[list[int]]:
    """The indices of the states each view of Fig. 2a draws: all in one, or, for more than :data:`LEGEND_ROWS`, one
    view per number the names end in (px1, py1, th1, v1: vehicle 1), so that every legend fits its view."""
    if len(states) <= LEGEND_ROWS:
        return [list(range(len(states)))]
    groups: dict[str, list[int]] = {}
    for j, name in enumerate(states):
        m = re.search(r"\d+$", name)
        groups.setdefault(m.group(0) if m else "", []).append(j)
    return list(groups.values()) if len(groups) > 1 else [list(range(len(states)))]


def _names(run: RunRecord) -> tuple[str, list[str], list[str], str]:
    game = run.config.get("game") or {}
    states = list(game.get("states") or [])
    inputs = [u for agent in game.get("agents") or [] for u in (agent.get("inputs") or {})]
    return run_name(run), states, inputs, solver_kind(run)


def _time_base(run: RunRecord) -> tuple[str, float] | None:
    """The timeline and seconds per step of a log whose log_time is the run's own time (a closed loop's simulated
    time: ``t``; a solve's iterations: ``iteration``), None for the wall clock of earlier logs."""
    base = run.metadata.get("log_time", "")
    if base.startswith("simulated"):
        return "t", float((run.config.get("run") or {}).get("sampling_time") or 1.0)
    if base.startswith("iteration"):
        return "iteration", 1.0
    return None


def log_run(rec, run: RunRecord, prefix: str, contents: Contents, several: bool = False) -> None:
    """Log one run's messages into the recording ``rec`` under ``prefix`` (``several``: legends name the run).
    The log views' series are collected in ``contents`` and drawn by :func:`draw_log_views`."""
    logger = _RunLogger(rec, run, prefix, contents, several)
    logger.text()
    logger.solve()
    logger.closed_loops()
    logger.paths()


class _RunLogger:
    """:func:`log_run` of one run: its config and text log, its solve's iterates (Fig. 1) and its closed loops
    (Fig. 2 and 3)."""

    def __init__(self, rec, run: RunRecord, prefix: str, contents: Contents, several: bool):
        import rerun as rr

        self.rr, self.rec, self.run, self.prefix, self.contents, self.several = rr, rec, run, prefix, contents, several
        self.name, self.states, self.inputs, self.kind = _names(run)

    def scalar(self, entity: str, timeline: str, time: int, value: float | None, view: str | None = None) -> None:
        value = number(value)
        if not math.isfinite(value):
            return
        self.rec.set_time(timeline, sequence=time)
        self.contents.reach(timeline, time)
        self.rec.log(entity, self.rr.Scalars(value))
        if view is not None:
            self.contents.view(view).add(time, value)

    def show(self, view: str, entity: str, label: str) -> None:
        """Put ``entity`` into a figure view, with its legend label and a colour of its own there."""
        series = self.contents.view(view)
        if entity in series.entities:
            return
        color = PALETTE[len(series.entities) % len(PALETTE)]
        series.entities.append(entity)
        series.labels.append(label)
        self.rec.log(entity, self.rr.SeriesLines(names=label, colors=color, widths=2.0), static=True)

    def trace(self, view: str, group: str, entity: str, label: str, timeline: str) -> Trace:
        """A series of a log view (drawn once every run is read)."""
        self.show(view, entity, label)
        series = self.contents.view(view)
        series.group = group
        found = next((tr for tr in series.traces if tr.entity == entity), None)
        if found is None:
            found = Trace(entity, timeline)
            series.traces.append(found)
        return found

    def text(self) -> None:
        """The run's config and its text log."""
        rec, run, prefix, contents = self.rec, self.run, self.prefix, self.contents
        if run.config_yaml:
            rec.log(f"{prefix}/config", self.rr.TextDocument(run.config_yaml, media_type="text/plain"), static=True)
            contents.configs.append(f"{prefix}/config")
        base = _time_base(run)
        for msg, t in zip(run.messages.get(LOG, []), run.log_times.get(LOG, []), strict=True):
            if base is None:  # (Rerun stamps everything with the wall clock on its own timeline log_time)
                rec.set_time("log_time", timestamp=t * 1e-9)
            else:  # at the run's own time: the sampling time t or the iteration k, beside the figures
                rec.set_time(base[0], sequence=round(t * 1e-9 / base[1]))
            level = {"warning": "WARN", "error": "ERROR", "debug": "DEBUG", "fatal": "CRITICAL"}.get(level_name(msg),
                                                                                                      "INFO")
            rec.log(f"{prefix}/log", self.rr.TextLog(msg.get("message", ""), level=level))
        if LOG in run.messages:
            contents.logs.append(f"{prefix}/log")
        rec.reset_time()

    def solve(self) -> None:
        """A solve's iterates, and Fig. 1."""
        run, prefix, name = self.run, self.prefix, self.name
        iterates = run.messages.get(SOLVE_ITERATE, [])
        solve_errors = solve_has_errors(run)  # (none without z*: Fig. 1 then shows ||Phi(z^k)||)
        for m in iterates:
            for key in ("error_norm", "residual_norm", "step_norm"):
                self.scalar(f"{prefix}/solve/{key}", "iteration", m["k"], m.get(key))
                if key == "residual_norm" and solve_errors:  # (else Fig. 1's series, drawn with the floor)
                    self.scalar(f"{prefix}/solve/log10_{key}", "iteration", m["k"], _log10(m.get(key)))
        if iterates:
            status = final_status(run)
            view = f"fig1:{prefix}"
            key, what = ("error_norm", "||z^k - z*||") if solve_errors else ("residual_norm", "||Phi(z^k)||")
            self.contents.titles[view] = (f"Fig. 1: {name} ({disturbance(run) or 'solve'}"
                                          + (f"; {status}" if status and status != "converged" else "")
                                          + f"): log10 {what}{'' if solve_errors else ' (no z*)'} (y) against "
                                            "iteration k (x)")
            tr = self.trace(view, "fig1", f"{prefix}/solve/log10_{key}", name if self.several else what, "iteration")
            tr.points = [(m["k"], number(m.get(key))) for m in iterates]
        self.rec.reset_time()

    def closed_loops(self) -> None:
        """Every closed loop's states, inputs and errors, and Fig. 2 (one solver) or Fig. 3 (distributed)."""
        loops = closed_loops(self.run)
        with_errors = has_errors(loops)  # (none without z*: Fig. 2b then shows the residual)
        for K, topics in loops.items():
            base = f"{self.prefix}/K{K}"
            x_view = "fig2_x" if K == max(loops) and self.kind != "distributed" else None
            states_K = topics.get("state", [])
            failed, fallback = failed_steps(states_K), fallback_steps(states_K)
            # without z*: the residual of each sampling time's last iterate, drawn in Fig. 2b or 3 instead
            residuals = [] if with_errors else [(t, number(v)) for t, v in
                                                zip(*final_residuals(topics.get("iterate", [])), strict=True)]
            groups = state_groups(self.states) if x_view else []
            keys = {j: x_view if len(groups) == 1 else f"{x_view}:{g}" for g, group in enumerate(groups) for j in group}
            self._states(K, base, states_K, keys, x_view if len(groups) == 1 else None)
            for key in dict.fromkeys([x_view] if len(groups) == 1 else keys.values()):
                shown = [self.states[j] for j, k in keys.items() if k == key]
                self.contents.titles[key] = (f"Fig. 2a: x(t) (y) against sampling time t (x), K = {K}"
                                             + ("" if len(groups) == 1 else f": {', '.join(shown)}"))
                for t in failed + fallback:
                    self.contents.view(key).span(t)
            errors = topics.get("error", [])
            for m in errors:
                self.scalar(f"{base}/e_norm", "t", m["t"], m.get("e_norm"))
                for agent, v in (m.get("e_norm_agent") or {}).items():
                    self.scalar(f"{base}/e_agent/{agent}", "t", m["t"], v)
            marks = (failed, fallback, base)
            if self.kind != "distributed":
                self._fig2_e(K, errors, residuals, with_errors, marks)
            else:
                self._fig3(K, errors, residuals, with_errors, marks)
        self.rec.reset_time()

    def _states(self, K: int, base: str, states_K: list, x_views: dict[int, str], x_view: str | None) -> None:
        """The states and inputs of one K; state j also in Fig. 2a's view ``x_views[j]`` (else ``x_view``; None: not
        drawn there)."""
        states, inputs = self.states, self.inputs
        for m in states_K:
            for j, v in enumerate(m.get("x") or []):
                entity = f"{base}/x/{states[j] if j < len(states) else f'x{j + 1}'}"
                view = x_views.get(j, x_view)
                if view:
                    self.show(view, entity, f"{entity.rsplit('/', 1)[1]} (K = {K})")
                self.scalar(entity, "t", m["t"], v, view)
            for j, v in enumerate(m.get("u") or []):
                self.scalar(f"{base}/u/{inputs[j] if j < len(inputs) else f'u{j + 1}'}", "t", m["t"], v)
            if m.get("constraint_violation") is not None:
                self.scalar(f"{base}/constraint_violation", "t", m["t"], m["constraint_violation"])

    def paths(self) -> None:
        """The paths in the plane (:func:`draw_paths`)."""
        draw_paths(self.rec, self.run, self.prefix, self.contents)

    def _fig2_e(self, K: int, errors: list, residuals: list, with_errors: bool, marks: tuple) -> None:
        """Fig. 2b: the error (or, without z*, the residual) of one K."""
        failed, fallback, base = marks
        what = "||e(t)||" if with_errors else "||Phi(z^K(t))|| (no z*)"
        title = f"Fig. 2b: log10 {what} (y) against sampling time t (x), per K"
        if self.contents.titles.get("fig2_e", title) != title:  # runs with and without z*
            title = "Fig. 2b: log10 ||e(t)||, or ||Phi(z^K(t))|| without z* (y), against sampling time t (x), per K"
        self.contents.titles["fig2_e"] = title
        label = f"{self.name}: K = {K}" if self.several else f"K = {K}"
        if with_errors:
            tr = self.trace("fig2_e", "fig2_e", f"{base}/log10_e_norm", label, "t")
            tr.points = [(m["t"], number(m.get("e_norm"))) for m in errors]
        else:
            tr = self.trace("fig2_e", "fig2_e", f"{base}/log10_residual_norm", label + " (||Phi||)", "t")
            tr.points = residuals
        tr.failed, tr.fallback, tr.marks = failed, fallback, base

    def _fig3(self, K: int, errors: list, residuals: list, with_errors: bool, marks: tuple) -> None:
        """Fig. 3: each agent's error (or, without z*, the residual) of one K of a distributed run."""
        failed, fallback, base = marks
        view = f"fig3:{self.name}: K = {K}"
        what = "||e_i(t)||" if with_errors else "||Phi(z^K(t))|| (no z*)"
        self.contents.titles[view] = f"Fig. 3: log10 {what} (y) against sampling time t (x), {self.name}: K = {K}"
        agents = dict.fromkeys(a for m in errors for a in (m.get("e_norm_agent") or {}))
        for i, agent in enumerate(agents):
            tr = self.trace(view, "fig3", f"{base}/log10_e_agent/{agent}", agent, "t")
            tr.points = [(m["t"], number((m.get("e_norm_agent") or {}).get(agent))) for m in errors]
            if i == 0:  # the K's failures, along the top of its view
                tr.failed, tr.fallback, tr.marks, tr.on_trace = failed, fallback, base, False
        if not with_errors:
            tr = self.trace(view, "fig3", f"{base}/log10_residual_norm", "||Phi||", "t")
            tr.points = residuals
            tr.failed, tr.fallback, tr.marks = failed, fallback, base


def _lighter(colour: tuple[int, int, int], share: float = 0.5) -> tuple[int, int, int]:
    return tuple(round(c + share * (255 - c)) for c in colour)


def _dimmer(colour: tuple[int, int, int], share: float = 0.45) -> tuple[int, int, int]:
    return tuple(round(c * (1 - share)) for c in colour)


def _finite(point) -> bool:
    return all(v is not None and math.isfinite(v) for v in point)


def _plan(m: dict) -> list[list[float]]:
    """The states a sampling time's plan predicts, a row per stage (none in logs of earlier versions)."""
    plan, nx = m.get("plan") or [], len(m.get("x") or [])
    return [plan[k:k + nx] for k in range(0, len(plan) - nx + 1, nx)] if nx else []


def draw_paths(rec, run: RunRecord, prefix: str, contents: Contents) -> None:
    """The paths in the plane of a closed loop whose game has positions (:func:`paths.vehicles`, as `gnerun figures`
    finds them), one 2D view per K on the timeline ``t``: under ``<run>/plane/K<k>/<agent>/``, each vehicle's trail up
    to t (``trail/<n>``, LineStrips2D in pieces of :data:`TRAIL_BLOCK` sampling times), its position at t with the
    agent's name (``position``, Points2D) and the states its applied plan predicts at t (``plan``, LineStrips2D of
    every other stage: dashed, lighter); the constraints on one vehicle's position alone where they hold with equality
    at tau = 0 (``<run>/plane/edges``, grey where they bind every vehicle, else in the vehicle's colour, dimmer). A
    vehicle has the colour of its place in the game (as in `gnerun figures`). Rerun's 2D views draw y downwards: the
    plane is logged under a transform that flips y (``<run>/plane``), so that y points up and values read as logged."""
    import rerun as rr

    names = list((run.config.get("game") or {}).get("states") or [])
    cars = vehicles(names)
    loops = closed_loops(run)
    if not cars or not loops:
        return
    labels = vehicle_names(run.config, cars)
    xs, ys = loop_positions(cars, loops)
    for topics in loops.values():  # and where the plans go (the view holds them whole)
        for m in topics.get("state", []):
            xs += [row[ix] for row in _plan(m) for _, ix, _ in cars]
            ys += [row[iy] for row in _plan(m) for _, _, iy in cars]
    xs, ys = [v for v in xs if math.isfinite(v)], [v for v in ys if math.isfinite(v)]
    if not xs or not ys:
        return
    plane = f"{prefix}/plane"
    rec.log(plane, rr.Transform3D(scale=[1.0, -1.0, 1.0]), static=True)
    edges = position_edges(run.config, cars, xs, ys)
    bounds = (min(xs), max(xs), min(ys), max(ys))
    if edges is not None:
        colours = [EDGE_COLOUR if len(who) == len(cars) else _dimmer(PALETTE[min(who) % len(PALETTE)])
                   for _, who in edges.lines]
        rec.log(f"{plane}/edges", rr.LineStrips2D([line for line, _ in edges.lines], colors=colours,
                                                  radii=rr.Radius.ui_points(1.5), draw_order=0.0), static=True)
        bounds = edges.limits
    for K, topics in loops.items():
        states = [m for m in topics.get("state", []) if m.get("x") is not None]
        base = f"{plane}/K{K}"
        for c, ((_, ix, iy), label) in enumerate(zip(cars, labels, strict=True)):
            entity = f"{base}/{_entity_name(label)}"
            colour = PALETTE[c % len(PALETTE)]
            trail: list[list[float]] = []
            for m in states:
                rec.set_time("t", sequence=m["t"])
                contents.reach("t", m["t"])
                point = [m["x"][ix], m["x"][iy]]
                if _finite(point):
                    trail.append(point)
                    piece = (len(trail) - 1) // TRAIL_BLOCK
                    rec.log(f"{entity}/trail/{piece}", rr.LineStrips2D([trail[max(piece * TRAIL_BLOCK - 1, 0):]],
                                                                       colors=colour, radii=rr.Radius.ui_points(1.5),
                                                                       draw_order=2.0))
                    rec.log(f"{entity}/position", rr.Points2D([point], colors=colour, labels=label, show_labels=True,
                                                              radii=rr.Radius.ui_points(5.0), draw_order=4.0))
                else:
                    rec.log(f"{entity}/position", rr.Clear(recursive=False))
                plan = [p for p in ([row[ix], row[iy]] for row in _plan(m)) if _finite(p)]
                if len(plan) >= 2:
                    rec.log(f"{entity}/plan", rr.LineStrips2D([plan[k:k + 2] for k in range(0, len(plan) - 1, 2)],
                                                              colors=_lighter(colour), radii=rr.Radius.ui_points(1.0),
                                                              draw_order=3.0))
                else:  # (the state that ends the loop has no plan)
                    rec.log(f"{entity}/plan", rr.Clear(recursive=False))
        name = run_name(run)
        contents.planes.append(Plane(f"Paths: {name}, K = {K}: y against x, trail up to t, plan at t (dashed)",
                                     prefix, [f"{plane}/edges", f"{base}/**"], bounds,
                                     max((m["t"] for m in states), default=0)))
    rec.reset_time()


def draw_log_views(rec, contents: Contents) -> None:
    """Log the series of the log views: log10 of each value at or above the floor, the series' row of the
    band below it (exact zeros included), nothing where it is missing; the floor line, and the markers of
    failed and fallback steps. Views of one group share one y range."""
    import rerun as rr

    groups: dict[str, list[tuple[str, Series]]] = {}
    for key, series in contents.views.items():
        if series.traces:
            groups.setdefault(series.group, []).append((key, series))
    for members in groups.values():
        values = [v for _, s in members for tr in s.traces for _, v in tr.points]
        above = [v for v in values if v >= FLOOR]
        has_band = any(below_floor(v) for v in values)
        rows = max(len(s.traces) for _, s in members)
        band = band_for(max(above) * 10 if above else FLOOR * 30, rows) if has_band else None
        if band is not None:
            lo, hi = math.log10(band.bottom), math.log10(band.top)
        elif above:
            lo, hi = math.log10(min(above)) - 0.3, math.log10(max(above)) + 0.3
        else:
            lo, hi = math.log10(FLOOR) - 1, math.log10(FLOOR) + 1
        for key, series in members:
            for i, tr in enumerate(series.traces):
                drawn = {}
                for time, v in tr.points:
                    y = math.log10(v) if v >= FLOOR else math.log10(band.row(i)) if band and below_floor(v) else None
                    series.span(time)
                    if y is None:
                        continue
                    drawn[time] = y
                    rec.set_time(tr.timeline, sequence=time)
                    contents.reach(tr.timeline, time)
                    rec.log(tr.entity, rr.Scalars(y))
                for what, times, marker, colour in (("failed_steps", tr.failed, "cross", MARK_COLOUR),
                                                    ("fallback_steps", tr.fallback, "down", FALLBACK_COLOUR)):
                    if not times:
                        continue
                    entity = f"{tr.marks}/{what}"
                    label = f"{tr.marks.rsplit('/', 1)[-1].replace('K', 'K = ')}: {what.replace('_', ' ')}"
                    series.entities.append(entity)
                    series.labels.append(label)
                    rec.log(entity, rr.SeriesPoints(names=label, colors=colour, markers=marker,
                                                    marker_sizes=8.0), static=True)
                    for time in times:
                        series.span(time)
                        rec.set_time(tr.timeline, sequence=time)
                        contents.reach(tr.timeline, time)
                        rec.log(entity, rr.Scalars(drawn.get(time, hi - 0.05 * (hi - lo)) if tr.on_trace
                                                   else hi - 0.05 * (hi - lo)))
            series.y = [lo, hi]
            if band is not None and series.t:
                series.floor = f"floor/{_entity_name(key)}"
                series.entities.append(series.floor)
                series.labels.append(f"floor {FLOOR:.0e}")  # (below it: a row per series)
                rec.log(series.floor, rr.SeriesLines(names=series.labels[-1], colors=FLOOR_COLOUR, widths=1.0),
                        static=True)
                for time in series.t:
                    rec.set_time(series.traces[0].timeline, sequence=time)
                    rec.log(series.floor, rr.Scalars(math.log10(FLOOR)))
    rec.reset_time()


@dataclass
class FigureView:
    """One paper figure as a blueprint container, with the timeline its x axis runs on."""

    slug: str  # file name of its screenshot
    title: str
    timeline: str
    container: object  # a rerun.blueprint container


WINDOW_POINTS = 1500  # the width a window's views share, in points, that the room for their legends is reckoned on


def _legend_room(series: Series, across: int) -> float:
    """The share of the width of a view, one of ``across`` side by side, that its legend takes (about 7 points a
    character and 40 for the marker and the padding)."""
    if not series.labels:
        return 0.0
    return min(0.5, (7 * max(len(label) for label in series.labels) + 40) / (WINDOW_POINTS / across))


def _series_view(name: str, series: Series, margin: bool = True, across: int = 1):
    """A time-series view whose axes are fixed to its data (with a margin), so that every viewer and every
    screenshot shows all of it; its time axis reaches beyond the last time by the room its legend takes (in the
    upper right corner), so that the legend covers no data."""
    import rerun as rr
    import rerun.blueprint as rrb

    kwargs = {}
    if series.t and series.y:
        lo, hi = series.y
        pad = (0.05 * (hi - lo) if hi > lo else 0.5) if margin else 0.0
        kwargs["axis_y"] = rrb.ScalarAxis(range=(lo - pad, hi + pad))
        t0, t1 = series.t
        t1 = max(t1, t0 + 1)
        room = _legend_room(series, across)
        kwargs["axis_x"] = rrb.archetypes.TimeAxis(view_range=rr.TimeRange(
            start=rr.TimeRangeBoundary.absolute(seq=t0),
            end=rr.TimeRangeBoundary.absolute(seq=t1 + math.ceil((t1 - t0) * room / (1 - room)))))
    return rrb.TimeSeriesView(name=name, contents=series.entities, plot_legend=rrb.components.Corner2D.RightTop,
                              **kwargs)


def _plane_view(plane: Plane):
    """A 2D view of the paths of one closed loop (:func:`draw_paths`), its bounds the paths and the nearest constraint
    edges, with a margin (the plane is drawn with y flipped: the bounds too)."""
    import rerun.blueprint as rrb

    x0, x1, y0, y1 = plane.bounds
    floor = max(x1 - x0, y1 - y0, 1e-3) / 20
    mx, my = 0.05 * max(x1 - x0, floor), 0.05 * max(y1 - y0, floor)
    return rrb.Spatial2DView(name=plane.title, origin=plane.origin, contents=plane.contents,
                             visual_bounds=rrb.VisualBounds2D(x_range=(x0 - mx, x1 + mx), y_range=(-y1 - my, -y0 + my)))


def figure_views(contents: Contents) -> list[FigureView]:
    """The paths in the plane (games with positions), then the paper figures that the runs contain, in the paper's
    order."""
    import rerun.blueprint as rrb

    views, titles = contents.views, contents.titles
    out = []
    if contents.planes:
        planes = [_plane_view(plane) for plane in contents.planes]
        out.append(FigureView("paths", "Paths", "t", (rrb.Horizontal if len(planes) <= 3 else rrb.Grid)(
            *planes, name="Paths")))
    fig1 = [key for key, s in views.items() if key.startswith("fig1:") and s.entities]
    if fig1:
        out.append(FigureView("fig1", "Fig. 1: solves", "iteration", rrb.Horizontal(
            *[_series_view(titles[key], views[key], margin=False, across=len(fig1)) for key in fig1],
            name="Fig. 1: solves")))
    if views.get("fig2_e") and views["fig2_e"].entities:
        x_keys = [key for key in views if key.startswith("fig2_x") and views[key].entities] or ["fig2_x"]
        x_views = [_series_view(titles.get(key, "Fig. 2a: x(t) (y) against sampling time t (x)"),
                                views.get(key, Series()), across=2) for key in x_keys]
        out.append(FigureView("fig2", "Fig. 2: closed loop", "t", rrb.Horizontal(
            x_views[0] if len(x_views) == 1 else rrb.Vertical(*x_views),
            _series_view(titles["fig2_e"], views["fig2_e"], margin=False, across=2), name="Fig. 2: closed loop")))
    fig3 = [key for key, s in views.items() if key.startswith("fig3:") and s.entities]
    if fig3:
        out.append(FigureView("fig3", "Fig. 3: per agent", "t", (rrb.Horizontal if len(fig3) <= 3 else rrb.Grid)(
            *[_series_view(titles[key], views[key], margin=False, across=min(len(fig3), 3)) for key in fig3],
            name="Fig. 3: per agent")))
    return out


def blueprint(contents: Contents):
    """The paths in the plane (games with positions), one tab per paper figure the runs contain, then the log and the
    configs."""
    import rerun.blueprint as rrb

    figures = figure_views(contents)
    tabs = [f.container for f in figures]
    if contents.logs:
        tabs.append(rrb.TextLogView(name="Log", contents=contents.logs))
    if contents.configs:
        tabs.append(rrb.Tabs(*[rrb.TextDocumentView(name=c.split("/")[0], origin=c) for c in contents.configs],
                             name="Config"))
    parts = [rrb.Tabs(*tabs)]
    if figures:
        parts.append(rrb.TimePanel(timeline=figures[0].timeline))
    return rrb.Blueprint(*parts, collapse_panels=False)


def record(paths: list[str | Path | RunRecord], rec) -> Contents:
    """Log every run (a path, or a log read already) into the recording ``rec``; returns what the figure views
    should show."""
    contents = Contents()
    used: set[str] = set()
    for path in paths:
        run = path if isinstance(path, RunRecord) else read_run(path)
        base = _entity_name(_names(run)[0])
        prefix, i = base, 2
        while prefix in used:
            prefix, i = f"{base}_{i}", i + 1
        used.add(prefix)
        log_run(rec, run, prefix, contents, several=len(paths) > 1)
    draw_log_views(rec, contents)
    return contents


def _stream():
    import rerun as rr

    return rr.RecordingStream(APPLICATION_ID)


def save(paths: list[str | Path], target: str | Path) -> Path:
    """Write a Rerun recording (.rrd) of the runs, with the figure blueprint."""
    runs = [read_run(path) for path in paths]  # a damaged log is refused before the recording is begun
    target = output_file(target, "recording")
    rec = _stream()
    rec.save(target)
    rec.send_blueprint(blueprint(record(runs, rec)))
    rec.flush()
    rec.disconnect()
    return target


def spawn(paths: list[str | Path]) -> None:
    """Open the runs in the native viewer (needs a display)."""
    rec = _stream()
    rec.spawn()
    rec.send_blueprint(blueprint(record(paths, rec)))
    rec.flush()


def rerun_executable() -> list[str]:
    """The `rerun` command line that rerun-sdk installs (next to this interpreter when possible)."""
    import shutil
    import sys

    script = Path(sys.executable).parent / "rerun"
    if script.exists():
        return [str(script)]
    found = shutil.which("rerun")
    return [found] if found else [sys.executable, "-m", "rerun"]


def viewer_binary() -> list[str]:
    """The viewer's own binary (the `rerun` script runs it as its child; started directly, it is the process that
    learns of our death), or the script where the binary is not found."""
    try:
        import rerun_cli
    except ImportError:
        return rerun_executable()
    binary = Path(rerun_cli.__file__).parent / "rerun"
    return [str(binary)] if binary.is_file() and os.access(binary, os.X_OK) else rerun_executable()


def serve_command(rrd: Path, web_port: int, grpc_port: int) -> list[str]:
    """The web viewer and its gRPC server for a saved recording, bound to 127.0.0.1 only."""
    return [*viewer_binary(), "--serve-web", "--bind", "127.0.0.1", "--web-viewer-port", str(web_port),
            "--port", str(grpc_port), str(rrd)]


def _start(command: list[str], **kwargs):
    """A viewer process in a process group of its own (the terminal's Ctrl-C reaches us, not it; stopping the group
    stops it and any child of it). On Linux it gets SIGTERM when we die, however we die (SIGKILL included): a viewer
    never outlives the gnerun that started it."""
    import subprocess

    parent = os.getpid()

    def die_with_parent() -> None:  # in the child, before the viewer starts
        if sys.platform.startswith("linux"):
            import ctypes
            import signal

            with contextlib.suppress(OSError, AttributeError):
                ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
            if os.getppid() != parent:  # we died before the line above
                os._exit(1)

    return subprocess.Popen(command, stdin=subprocess.DEVNULL, start_new_session=True, preexec_fn=die_with_parent,
                            **kwargs)


def has_open(pid: int, path: Path) -> bool | None:
    """Whether process ``pid`` has ``path`` open (None where /proc cannot tell)."""
    target = str(path.resolve())
    try:
        fds = os.listdir(f"/proc/{pid}/fd")
    except OSError:
        return None
    for fd in fds:
        with contextlib.suppress(OSError):
            if os.readlink(f"/proc/{pid}/fd/{fd}") == target:
                return True
    return False


def _stop(proc, grace: float = 10.0) -> None:
    import os
    import signal
    import subprocess

    for sig in (signal.SIGTERM, signal.SIGKILL):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            pass
        try:
            proc.wait(timeout=grace)
            break
        except subprocess.TimeoutExpired:
            continue
    # the group may outlive its leader
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


def check_ports(*ports: int) -> None:
    """Each port is a TCP port number, the ports differ, and none is taken on 127.0.0.1 (bad input, exit 2)."""
    import socket

    for port in ports:
        if not 1 <= port <= 65535:
            raise InputError(f"port {port}: a TCP port is a number in 1..65535")
    if len(set(ports)) != len(ports):
        raise InputError(f"the web viewer and its data server need two ports, not {ports[0]} twice")
    for port in ports:
        with socket.socket() as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as the viewer binds
            try:
                s.bind(("127.0.0.1", port))
            except OSError as e:
                raise InputError(f"port {port} on 127.0.0.1 cannot be used: {e.strerror or e} (choose another with "
                                 "--web-port or --grpc-port)") from None


def _listening(port: int) -> bool:
    import socket

    with socket.socket() as s:
        s.settimeout(0.5)
        return s.connect_ex(("127.0.0.1", port)) == 0


def serve(rrd: Path, web_port: int, grpc_port: int, ready=None, timeout: float = 60.0, loaded=None) -> int:
    """Run the web viewer until it stops, or until we are interrupted or terminated (then stop it too).
    ``ready()`` is called once both ports answer; a viewer that stops before is an error with its last words.
    ``loaded()`` is called once the viewer has read the recording and closed it (it serves from memory then): a
    temporary recording can go at once, so that nothing of it is left if we are killed."""
    import os
    import signal
    import subprocess
    import tempfile
    import time

    output = tempfile.TemporaryFile()
    proc = _start(serve_command(rrd, web_port, grpc_port), env=dict(os.environ, RERUN_APP_ONLY="true"),
                  stdout=output, stderr=subprocess.STDOUT)

    def stop(signum, frame):  # SIGTERM: take the viewer down with us
        raise KeyboardInterrupt

    previous = {sig: signal.signal(sig, stop) for sig in (signal.SIGTERM, signal.SIGHUP)}
    try:
        deadline = time.monotonic() + timeout
        while not (_listening(web_port) and _listening(grpc_port)):
            if proc.poll() is not None:
                output.seek(0)
                lines = [ln for ln in output.read().decode(errors="replace").splitlines() if ln.strip()]
                raise Unavailable("the web viewer stopped before it served: " + (lines[-1][:200] if lines
                                                                                 else f"exit code {proc.returncode}"))
            if time.monotonic() > deadline:
                raise Unavailable(f"the web viewer did not answer on ports {web_port} and {grpc_port} within "
                                  f"{timeout:g} s")
            time.sleep(0.2)
        if ready is not None:
            ready()
        if loaded is not None:
            while has_open(proc.pid, rrd) and proc.poll() is None:
                time.sleep(0.1)
            if proc.poll() is None:
                loaded()
        return proc.wait()
    except KeyboardInterrupt:
        return 0
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        _stop(proc)
        output.close()


def web_url(web_port: int, grpc_port: int) -> str:
    return f"http://127.0.0.1:{web_port}/?url=rerun%2Bhttp://127.0.0.1:{grpc_port}/proxy"


# headless screenshots ------------------------------------------------------------------------------

VULKAN_HINT = ("headless screenshots need a Vulkan driver and none was found; on Debian or Ubuntu install "
               "one with `apt-get install mesa-vulkan-drivers` (a software rasteriser is enough)")

TOAST_SECONDS = 8.0  # how long the viewer's start-up notification may stay, from its first frame (about 4 s)
_ICD_DIRS = ("/usr/share/vulkan/icd.d", "/etc/vulkan/icd.d", "/usr/local/share/vulkan/icd.d")


def vulkan_available() -> bool:
    """Whether a Vulkan driver (an ICD manifest) is installed, e.g. Mesa's lavapipe."""
    import os

    for var in ("VK_DRIVER_FILES", "VK_ICD_FILENAMES"):
        if any(Path(f).is_file() for f in os.environ.get(var, "").split(os.pathsep) if f):
            return True
    return any(Path(d).is_dir() and any(Path(d).glob("*.json")) for d in _ICD_DIRS)


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class _HeadlessViewer:
    """A headless Rerun viewer on 127.0.0.1, started and stopped by us (its log kept for error messages)."""

    def __init__(self, size: str, timeout: float) -> None:
        import os
        import subprocess
        import tempfile
        import time

        from rerun.experimental import ViewerClient

        self.port = _free_port()
        self.url = f"rerun+http://127.0.0.1:{self.port}/proxy"
        self._tmp = tempfile.TemporaryDirectory(prefix="gnerun-viewer-")
        self._log_path = Path(self._tmp.name) / "viewer.log"
        env = dict(os.environ, RERUN_APP_ONLY="true")  # a tool's viewer: no analytics opt-in prompt
        if not os.environ.get("XDG_RUNTIME_DIR"):
            env["XDG_RUNTIME_DIR"] = self._tmp.name
        with open(self._log_path, "wb") as log:
            self.proc = _start([*viewer_binary(), "--headless", "--bind", "127.0.0.1", "--port", str(self.port),
                                "--hide-welcome-screen", "--window-size", size], stdout=log, stderr=subprocess.STDOUT,
                               env=env)
        self.started = time.monotonic()
        deadline = self.started + timeout
        while True:
            if self.proc.poll() is not None:
                self.close()
                raise Unavailable(self._failure())
            try:
                self.client = ViewerClient.connect(self.url)
                self.client.get_state()
                self.client.take_screenshot()  # its first frame, which shows the start-up notification
                self.started = time.monotonic()
                return
            except Exception:  # noqa: BLE001 - not listening yet
                if time.monotonic() > deadline:
                    self.close()
                    raise Unavailable(f"the headless viewer did not start within {timeout:g} s") from None
                time.sleep(0.2)

    def _failure(self) -> str:
        text = self._log_path.read_text(errors="replace") if self._log_path.exists() else ""
        if "adapter" in text.lower() or "vulkan" in text.lower():
            return VULKAN_HINT.replace("none was found", "none works")
        lines = [ln for ln in text.splitlines() if ln.strip()]
        return "the headless viewer stopped: " + (lines[-1] if lines else "no output")

    def outlive_notifications(self) -> None:
        """Until the start-up notification, which covers the views' top right corner, is gone: the viewer draws
        frames only when asked, and a notification counts down and fades out only while frames are drawn, so
        frames are asked for until it has had its time (on a busy machine a notification outlived a wait)."""
        import time

        while time.monotonic() < self.started + TOAST_SECONDS:
            self.client.take_screenshot()
            time.sleep(0.25)

    def close(self) -> None:
        _stop(self.proc)
        self._tmp.cleanup()


def _wait_for(client, expected_views: set[str], timeline: str, ends: dict[str, int], timeout: float) -> None:
    """Until the viewer shows exactly the figure's views, with every timeline's data arrived."""
    import time

    deadline = time.monotonic() + timeout
    while True:
        state = client.get_state()
        names = {v.name for v in state.views if v.visible}
        arrived = {tl.name: tl.end for rec in state.recordings for tl in rec.timelines}
        if (names == expected_views and not state.loading
                and all(arrived.get(name) == end for name, end in ends.items())):
            return
        if time.monotonic() > deadline:
            raise Unavailable(f"the viewer did not show {sorted(expected_views)} on timeline {timeline!r} "
                               f"within {timeout:g} s (it shows {sorted(names)})")
        time.sleep(0.2)


def _settled_screenshot(client, attempts: int = 8) -> bytes:
    """A screenshot once the viewer has stopped changing (two identical frames in a row)."""
    import time

    previous = client.take_screenshot()
    for _ in range(attempts):
        time.sleep(0.2)
        png = client.take_screenshot()
        if png == previous:
            return png
        previous = png
    return previous


def _view_names(container) -> set[str]:
    import rerun.blueprint as rrb

    if isinstance(container, rrb.View):
        return {str(container.name)}
    return set().union(*(_view_names(c) for c in container.contents)) if container.contents else set()


def check_size(size: str) -> None:
    if not re.fullmatch(r"\d{2,5}x\d{2,5}", size):
        raise InputError(f"--size must look like 1600x900, not {size!r}")


PATHS_AT = 0.5  # the screenshot of the paths shows this share of the closed loop behind the time cursor


def screenshots(paths: list[str | Path], out_dir: str | Path, size: str = "1600x900",
                timeout: float = 60.0) -> list[Path]:
    """One PNG per paper figure the runs contain, and one of the paths in the plane (``paths.png``, at the middle
    sampling time), taken by a headless viewer (needs a Vulkan driver)."""
    import rerun.blueprint as rrb

    check_size(size)
    if not vulkan_available():
        raise Unavailable(VULKAN_HINT)
    out_dir = output_directory(out_dir, "screenshot folder")
    viewer = _HeadlessViewer(size, timeout)
    written = []
    try:
        rec = _stream()
        rec.connect_grpc(viewer.url)
        contents = record(paths, rec)
        rec.flush()
        for fig in figure_views(contents):
            rec.send_blueprint(rrb.Blueprint(fig.container, rrb.TimePanel(timeline=fig.timeline, state="collapsed"),
                                             collapse_panels=True), make_active=True)
            rec.flush()
            _wait_for(viewer.client, _view_names(fig.container), fig.timeline, contents.ends, timeout)
            # the paths midway (trails behind, plans ahead); the other figures at the end
            at = (max(plane.end for plane in contents.planes) * PATHS_AT if fig.slug == "paths"
                  else contents.ends.get(fig.timeline))
            if at is not None:
                viewer.client.set_time(fig.timeline, sequence=round(at), play_state="paused")
            viewer.outlive_notifications()
            png = _settled_screenshot(viewer.client)
            target = out_dir / f"{fig.slug}.png"
            write_bytes(target, png)
            written.append(target)
        rec.disconnect()
    finally:
        viewer.close()
    return written
