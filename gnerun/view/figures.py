"""Paper-style figures from run logs alone (`gnerun figures`).

- Study 1 (solve runs): ||z^k - z*|| against k on a log scale, one panel per run, side by side (the clean
  and the disturbed solve of Fig. 1), on one y range; ||Phi(z^k)|| for a solve without z*.
- Study 2 (closed loops): x(t) of the loop with the largest K (the states chosen with ``--states``, else all but
  the clocks: :mod:`gnerun.view.states`), and the solver's error ||e(t)|| = ||z^K(t) - z*(t)|| per K on a log scale
  (Fig. 2); a loop without z* (run.reference none) has no e(t), and shows ||Phi|| of each sampling time's last
  iterate instead. A game with references adds the tracking error |x(t) - r(t)| per K.
- Study 3 (distributed closed loops): ||e_i(t)|| per agent, one panel per K, on one y range (Fig. 3); ||Phi||
  without z*.
- Games with positions (closed loops): the paths in the plane and each vehicle's distance to the nearest other
  against the required one, the closest pair named (:mod:`gnerun.view.paths`).

Everything plotted is read from the MCAP log (:func:`gnerun.log.mcap_log.read_run`), so any run from any
machine, finished or killed, written by this version or an earlier one, can be drawn without solving again.

Errors below :data:`FLOOR` (rounding level, exact zeros included) are not drawn as values: a log axis would
turn rounding noise into a zig-zag and put every exact zero on one line, hiding all but the last series.
They are drawn in a grey band under the axis, each series on a row of its own. Missing values (z* unknown)
are gaps. Failed sampling times (a failure status) and fallback steps (the budgeted iterate not applied)
are marked where the log records them. Figures are one column of the paper wide (IEEEtran, 3.5 in; wider
for more than two panels), PNGs at 300 dpi, PDFs with embedded TrueType fonts.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import InputError
from ..files import open_for_writing, output_directory, read_json_object
from ..log.mcap_log import RunRecord, read_run
from ..log.sweep_index import SEED_AXES, SWEEP_JSON, loglog_slope, read_index
from ..log.topics import LOG, SOLVE_ITERATE, parse_mpc
from .panels import FAILED_LABEL, FALLBACK_LABEL, K_STYLES, failed_steps, fallback_steps, k_line, legend, panels
from .paths import has_positions, paths_figure
from .states import KIND_STYLES, selected_states, state_groups

FLOOR = 1e-13  # errors below this are rounding level (about 500 machine epsilons): drawn in the band
ROW_DECADES = 0.5  # the band's rows are this far apart (in decades)
DPI = 300
MARKERS = "osD^vPX*ph"
# points: the last series' markers, how much larger each earlier series' are, how much larger the first's at most
MARKER_SIZE, MARKER_STEP, MARKER_SPREAD = 3.0, 0.8, 2.0


def run_name(run: RunRecord) -> str:
    return str(run.config.get("name", run.path.parent.name))


def solver_kind(run: RunRecord) -> str:
    return str((run.config.get("solver") or {}).get("kind", ""))


def disturbance(run: RunRecord) -> str:
    if not run.config_yaml:
        return ""
    d = run.config.get("disturbance") or {}
    kind = d.get("kind", "none")
    return "undisturbed" if kind == "none" else f"{kind.replace('_', ' ')}, scale {d.get('scale', 0):g}"


def final_status(run: RunRecord) -> str | None:
    """The status a solve ended with, from its last ``status ...`` entry in /log (None if it has none)."""
    for entry in reversed(run.messages.get(LOG, [])):
        text = entry.get("message", "")
        if text.startswith("status "):
            return text.split()[1].rstrip(":")
    return None


def closed_loops(run: RunRecord) -> dict[int, dict[str, list[dict]]]:
    """Per K: the messages of /K<k>/mpc/state, /error, /iterate."""
    out: dict[int, dict[str, list[dict]]] = {}
    for topic, msgs in run.messages.items():
        parsed = parse_mpc(topic)
        if parsed:
            out.setdefault(parsed[0], {})[parsed[1]] = msgs
    return dict(sorted(out.items()))


def has_errors(loops: dict[int, dict[str, list[dict]]]) -> bool:
    """Whether the closed loops logged any tracking error (none without z*: run.reference none)."""
    return any(not math.isnan(number(m.get("e_norm"))) for topics in loops.values() for m in topics.get("error", []))


def final_residuals(iterates: list[dict]) -> tuple[list[int], list[float | None]]:
    """Per sampling time, ||Phi|| of its last iterate (after its K steps, or fewer where it converged)."""
    last: dict[int, dict] = {}
    for m in iterates:
        if m["t"] not in last or m.get("k", 0) >= last[m["t"]].get("k", 0):
            last[m["t"]] = m
    return sorted(last), [last[t].get("residual_norm") for t in sorted(last)]


def agent_names(run: RunRecord, errors: list[dict]) -> list[str]:
    """The agents of a closed loop's per-agent errors, in the config's order (a missing value is left out of a
    message, so no single message need name them all)."""
    seen = dict.fromkeys(k for m in errors for k in (m.get("e_norm_agent") or {}))
    configured = [a.get("name") for a in (run.config.get("game") or {}).get("agents") or []]
    return [a for a in configured if a in seen] + [a for a in seen if a not in configured]


DRAWABLE = 1e300  # a larger magnitude is left as a gap: an axis spanning it overflows


def number(v: object) -> float:
    """A logged value as a float (NaN where it is missing, or too large to draw)."""
    return float(v) if isinstance(v, int | float) and not isinstance(v, bool) and abs(v) < DRAWABLE else math.nan


def below_floor(v: float) -> bool:
    return 0 <= v < FLOOR


# ---------------------------------------------------------------------------------------------
# Log axes with a floor band
# ---------------------------------------------------------------------------------------------


@dataclass
class _Series:
    x: list[float]
    y: list[float]  # as logged (NaN where missing)
    style: dict
    failed: list[int] = field(default_factory=list)  # x values marked as failed steps
    fallback: list[int] = field(default_factory=list)


@dataclass(frozen=True)
class Band:
    """The y range of a log axis with the floor band: ``bottom`` .. ``top``, rows ``spacing`` decades apart."""

    bottom: float
    top: float
    spacing: float
    rows: int

    def row(self, i: int) -> float:
        return FLOOR * 10 ** (-(i + 1) * self.spacing)


def band_for(top: float, rows: int) -> Band:
    """A band a fixed share of the axis high (more for more rows), so that its rows stay apart."""
    above = max(math.log10(top / FLOOR), 1.0)
    share = min(0.35, 0.1 + 0.045 * rows)
    decades = above * share / (1 - share)
    return Band(FLOOR * 10 ** -decades, top, decades / (rows + 1), rows)


class FloorAxis:
    """Series on a log y axis whose values below :data:`FLOOR` are drawn in a band under the floor, one row per
    series, with a legend entry that says so."""

    def __init__(self, ax, what: str = "series") -> None:
        self.ax = ax
        self.what = what  # the legend's note: "below 1e-13: a row per <what>"
        self.series: list[_Series] = []
        self.band: Band | None = None

    def add(self, x: list[float], y: list[float], *, failed: list[int] = (), fallback: list[int] = (),
            **style) -> None:
        self.series.append(_Series(list(x), [number(v) for v in y], style, list(failed), list(fallback)))

    def has_band(self) -> bool:
        return any(below_floor(v) for s in self.series for v in s.y)

    def top(self) -> float | None:
        ys = [v for s in self.series for v in s.y if v >= FLOOR]
        return max(ys) * 10 if ys else None

    def bottom(self) -> float | None:
        ys = [v for s in self.series for v in s.y if v >= FLOOR]
        return min(ys) / 3 if ys else None

    def plotted(self, i: int) -> list[float]:
        """Series i as drawn: values, its row for values below the floor, NaN where missing or negative."""
        row = self.band.row(i) if self.band else math.nan
        return [v if v >= FLOOR else row if below_floor(v) else math.nan for v in self.series[i].y]

    def draw(self, band: Band | None | bool = True, limits: tuple[float, float] | None = None) -> None:
        """Draw the series. ``band``: the shared band of panels on one y range (True: this axis' own, when it
        has values below the floor); ``limits``: the shared y range without a band."""
        from matplotlib.ticker import FixedLocator, FuncFormatter, NullLocator

        ax = self.ax
        if band is True:
            band = band_for(self.top() or FLOOR * 30, len(self.series)) if self.has_band() else None
        self.band = band or None
        if self.band is None and limits is None and self.top() is not None:
            limits = (self.bottom(), self.top())
        if self.band is not None:
            limits = (self.band.bottom, self.band.top)
        ax.set_yscale("log")
        for i, s in enumerate(self.series):
            y = self.plotted(i)
            # each series' markers a little smaller than the one's before, drawn over it: series that are equal
            # (the same iterates for several K) show as markers inside markers, none hidden
            size = MARKER_SIZE + min(MARKER_STEP, MARKER_SPREAD / max(len(self.series) - 1, 1)) * (
                len(self.series) - 1 - i)
            ax.plot(s.x, y, marker=MARKERS[i % len(MARKERS)], mfc="none", ms=size, **s.style)
            top = limits[1] / 1.6 if limits else FLOOR
            for marks, marker, label in ((s.failed, "x", FAILED_LABEL), (s.fallback, "v", FALLBACK_LABEL)):
                if marks:
                    at = dict(zip(s.x, y, strict=True))
                    where = [at.get(t, math.nan) for t in marks]
                    ax.plot(marks, [v if v == v else top for v in where], linestyle="none", marker=marker, ms=5,
                            mew=1.0, color="black", mfc="none" if marker == "v" else "black", label=label, zorder=5)
        if limits:
            ax.set_ylim(*limits)
        if self.band is None:
            return
        b = self.band
        ax.axhspan(b.bottom, FLOOR, color="0.9", zorder=0, lw=0, gid="floor band")
        ax.axhline(FLOOR, color="0.55", lw=0.6, ls="--", zorder=1)
        # ticks: decades from the floor up (at most 5 labels), and the band labelled as a band
        lo, hi = round(math.log10(FLOOR)), math.floor(math.log10(b.top))
        stride = max(1, math.ceil((hi - lo) / 4))
        decades = [10.0 ** e for e in range(lo, hi + 1, stride)]
        middle = math.sqrt(b.bottom * FLOOR)
        ax.yaxis.set_major_locator(FixedLocator([middle, *decades]))
        ax.yaxis.set_major_formatter(FuncFormatter(
            lambda v, _: f"<$10^{{{lo}}}$" if v == middle else f"$10^{{{round(math.log10(v))}}}$"))
        ax.yaxis.set_minor_locator(NullLocator())


    def notes(self) -> list:
        """The band's legend entry (the note that says what the band holds), if it has one."""
        from matplotlib.patches import Patch

        if self.band is None:
            return []
        text = f"< {FLOOR:.0e}" + (f": a row per {self.what}" if len(self.series) > 1 else " (rounding level)")
        return [Patch(facecolor="0.9", edgecolor="0.55", lw=0.5, ls="--", label=text)]


def share_floor(axes: list[FloorAxis]) -> None:
    """Draw panels on one y range (the same band and limits)."""
    tops = [t for a in axes if (t := a.top()) is not None]
    bottoms = [b for a in axes if (b := a.bottom()) is not None]
    if any(a.has_band() for a in axes):
        band = band_for(max(tops, default=FLOOR * 30), max(len(a.series) for a in axes))
        for a in axes:
            a.draw(band)
    else:
        limits = (min(bottoms), max(tops)) if tops else None
        for a in axes:
            a.draw(None, limits)


# ---------------------------------------------------------------------------------------------
# Layout
# ---------------------------------------------------------------------------------------------


def _style() -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.rcParams.update({
        "font.size": 7, "axes.titlesize": 7, "axes.labelsize": 7, "xtick.labelsize": 6, "ytick.labelsize": 6,
        "legend.fontsize": 6, "axes.grid": True, "grid.alpha": 0.3, "grid.linewidth": 0.4, "axes.linewidth": 0.6,
        "lines.linewidth": 1.0, "lines.markersize": 3.0, "lines.markeredgewidth": 0.7, "xtick.major.width": 0.6,
        "ytick.major.width": 0.6, "figure.dpi": DPI, "savefig.dpi": DPI,
        # fonts embedded as TrueType (Type 42), not Type 3: what journals ask for
        "pdf.fonttype": 42, "ps.fonttype": 42,
    })


def _integer_ticks(ax) -> None:
    from matplotlib.ticker import MaxNLocator

    ax.xaxis.set_major_locator(MaxNLocator(nbins=5, integer=True))


def _mark_steps(ax, failed: list[int], fallback: list[int]) -> None:
    """Failed and fallback sampling times of a panel of one K, as shaded columns."""
    for i, t in enumerate(failed):
        ax.axvspan(t - 0.5, t + 0.5, color="0.6", alpha=0.35, lw=0, zorder=0, label=FAILED_LABEL if i == 0 else None)
    for i, t in enumerate(fallback):
        ax.axvspan(t - 0.5, t + 0.5, facecolor="none", edgecolor="0.4", hatch="////", lw=0, zorder=0,
                   label=FALLBACK_LABEL if i == 0 else None)


# ---------------------------------------------------------------------------------------------
# The paper's figures
# ---------------------------------------------------------------------------------------------


def solve_has_errors(run: RunRecord) -> bool:
    """Whether a solve logged ||z^k - z*|| (not without z*: run.reference none)."""
    return any(not math.isnan(number(m.get("error_norm"))) for m in run.messages.get(SOLVE_ITERATE, []))


def study1_figure(runs: list[RunRecord]):
    """||z^k - z*|| vs k, one panel per solve run, on one y range (a solve without z*, run.reference none:
    ||Phi(z^k)||)."""
    fig, axes, width = panels(len(runs))
    floors = []
    with_errors = [solve_has_errors(run) for run in runs]
    for ax, run, label, errors in zip(axes, runs, "abcdefghijklmnop", with_errors, strict=False):
        its = run.messages.get(SOLVE_ITERATE, [])
        status = final_status(run)
        text = disturbance(run) + (f"; {status}" if status and status != "converged" else "")
        floor = FloorAxis(ax, "run")
        floor.add([m["k"] for m in its], [m.get("error_norm" if errors else "residual_norm") for m in its],
                  label=(text or run_name(run)) + ("" if errors else ": ||Phi(z^k)||, no z*"), color="C0")
        floors.append(floor)
        ax.set_xlabel("iteration k")
        _integer_ticks(ax)
        ax.set_title(f"({label}) {run_name(run)}")
    share_floor(floors)
    for ax in axes[1:]:
        ax.sharey(axes[0])
        ax.tick_params(labelleft=False)
    axes[0].set_ylabel(r"$\|z^k - z^*\|$" if all(with_errors) else r"$\|\Phi(z^k)\|$" if not any(with_errors)
                       else r"$\|z^k - z^*\|$, $\|\Phi(z^k)\|$")
    for ax, floor in zip(axes, floors, strict=True):
        legend(ax, width, floor.notes())
    return fig


def references(topics: dict[str, list[dict]]) -> dict[str, tuple[list[int], list[float]]]:
    """r(t) of the states with a reference (game.references), from a loop's /K<k>/mpc/parameters: {state: (t, r)}."""
    out: dict[str, tuple[list[int], list[float]]] = {}
    for m in topics.get("parameters", []):
        for state, r in (m.get("references") or {}).items():
            ts, rs = out.setdefault(state, ([], []))
            ts.append(m["t"])
            rs.append(number(r))
    return out


def tracking_errors(topics: dict[str, list[dict]], names: list[str]) -> tuple[list[int], list[float]]:
    """|x(t) - r(t)| over the referenced states (the 2-norm), per sampling time."""
    refs = references(topics)
    x_at = {m["t"]: m.get("x") for m in topics.get("state", []) if m.get("x")}
    by_t: dict[int, float] = {}
    for state, (ts, rs) in refs.items():
        j = names.index(state) if state in names else None
        for t, r in zip(ts, rs, strict=True):
            if j is not None and t in x_at:
                by_t[t] = by_t.get(t, 0.0) + (number(x_at[t][j]) - r) ** 2
    ts = sorted(by_t)
    return ts, [math.sqrt(by_t[t]) for t in ts]


def study2_figure(run: RunRecord, states: list[str] | None = None):
    """x(t) of the loop with the largest K, and ||e(t)|| = ||z^K(t) - z*(t)|| per K, the solver's error (a loop
    without z*, run.reference none, has no e(t): its residual ||Phi(z^K(t))|| per K instead). ``states``: the states
    panel (a) draws (default: every state but the clocks, :mod:`gnerun.view.states`). A game with references
    (game.references) draws r(t) dashed over its states, and a panel of the tracking error |x(t) - r(t)| per K
    before the solver's error."""
    from matplotlib.lines import Line2D

    loops = closed_loops(run)
    K_max = max(loops)
    names = list((run.config.get("game") or {}).get("states") or [])
    drawn, clocks = selected_states(run.config, states, run_name(run))
    groups = state_groups(run.config, drawn)
    tracked = references(loops[K_max])
    if tracked:
        fig, (ax_x, ax_r, ax_e), width = panels(3)
    else:
        fig, (ax_x, ax_e), width = panels(2)
    logged = loops[K_max].get("state", [])
    nx = max((len(m.get("x") or []) for m in logged), default=0)
    t = [m["t"] for m in logged]
    columns = [(names.index(s), s) for s in drawn] if names else [(j, f"x{j + 1}") for j in range(nx)]
    if groups:
        agent_of, kind_of = groups
        agents, kinds = list(dict.fromkeys(agent_of.values())), list(dict.fromkeys(kind_of.values()))
    handles = []
    for n, (j, name) in enumerate(columns):
        if j >= nx:
            continue
        style = ({"color": f"C{agents.index(agent_of[name]) % 10}", "ls": KIND_STYLES[kinds.index(kind_of[name])]}
                 if groups else {"ls": ("-", "--", ":")[n // 10 % 3]})
        line, = ax_x.plot(t, [number((m.get("x") or [math.nan] * nx)[j]) for m in logged], label=name,
                          gid=f"state-{name}", **style)  # (the id of its group in an SVG)
        if name in tracked:
            ax_x.plot(*tracked[name], color=line.get_color(), ls=(0, (4, 2)), lw=1.0, label=f"reference of {name}")
    if groups:  # a colour per agent, a line style per kind of state
        handles = ([Line2D([], [], color=f"C{i % 10}", label=a) for i, a in enumerate(agents)]
                   + [Line2D([], [], color="0.3", ls=KIND_STYLES[i], label=k) for i, k in enumerate(kinds)])
        if any(name in tracked for _, name in columns):
            handles.append(Line2D([], [], color="0.3", ls=(0, (4, 2)), lw=1.0, label="reference r(t)"))
    _mark_steps(ax_x, failed_steps(logged), fallback_steps(logged))
    if groups:
        found = dict(zip(*reversed(ax_x.get_legend_handles_labels()), strict=True))
        handles += [found[k] for k in (FAILED_LABEL, FALLBACK_LABEL) if k in found]
    if clocks:  # said where the states are named
        handles.append(Line2D([], [], ls="none", label=f"not drawn: {', '.join(clocks)} (clock)"))
    if tracked:
        for i, (K, topics) in enumerate(loops.items()):
            lw, alpha = k_line(i, len(loops))  # equal errors of several K (they often are) all show
            ax_r.plot(*tracking_errors(topics, names), label=f"K = {K}", color=f"C{i % 10}", lw=lw, alpha=alpha,
                      ls=K_STYLES[i % len(K_STYLES)])
        ax_r.set_xlabel("t")
        ax_r.set_ylabel(r"$|x(t) - r(t)|$")
        ax_r.set_title(f"(b) tracking error to the reference ({', '.join(tracked)})")
        _integer_ticks(ax_r)
        legend(ax_r, width)
    ax_x.set_xlabel("t")
    ax_x.set_ylabel("x(t)")
    ax_x.set_title(f"(a) x(t), K = {K_max}")
    _integer_ticks(ax_x)
    floor = FloorAxis(ax_e, "K")
    errors_logged = has_errors(loops)
    for i, (K, topics) in enumerate(loops.items()):
        states_K = topics.get("state", [])
        if errors_logged:
            errors = topics.get("error", [])
            t_K, values = [m["t"] for m in errors], [m.get("e_norm") for m in errors]
        else:
            t_K, values = final_residuals(topics.get("iterate", []))
        floor.add(t_K, values, failed=failed_steps(states_K), fallback=fallback_steps(states_K), label=f"K = {K}",
                  color=f"C{i % 10}")
    floor.draw()
    ax_e.set_xlabel("t")
    ax_e.set_ylabel(r"$\|e(t)\|$" if errors_logged else r"$\|\Phi(z^K(t))\|$")
    letter = "c" if tracked else "b"
    ax_e.set_title(f"({letter}) " + (SOLVER_ERROR if errors_logged else "residual (no z*)"))
    _integer_ticks(ax_e)
    legend(ax_x, width, handles, own=not groups)
    legend(ax_e, width, floor.notes())
    return fig


SOLVER_ERROR = r"solver error $\|z^K - z^*(t)\|$"  # e(t): the iterate's distance to the equilibrium, not to a reference


def study3_figure(run: RunRecord):
    """||e_i(t)|| per agent, one panel per K, on one y range (a loop without z*, run.reference none, has no
    e_i(t): its residual ||Phi(z^K(t))|| instead)."""
    loops = closed_loops(run)
    fig, axes, width = panels(len(loops))
    floors = []
    errors_logged = has_errors(loops)
    for ax, (K, topics), label in zip(axes, loops.items(), "abcdefghijklmnop", strict=False):
        errors = topics.get("error", [])
        states = topics.get("state", [])
        floor = FloorAxis(ax, "agent")
        for i, agent in enumerate(agent_names(run, errors)):
            floor.add([m["t"] for m in errors], [(m.get("e_norm_agent") or {}).get(agent) for m in errors],
                      label=agent, color=f"C{i % 10}")
        if not errors_logged:
            floor.add(*final_residuals(topics.get("iterate", [])), label="residual (no z*)", color="C0")
        _mark_steps(ax, failed_steps(states), fallback_steps(states))
        floors.append(floor)
        ax.set_xlabel("t")
        ax.set_title(f"({label}) K = {K}")
        _integer_ticks(ax)
    share_floor(floors)
    for ax in axes[1:]:
        ax.sharey(axes[0])
        ax.tick_params(labelleft=False)
    axes[0].set_ylabel(r"$\|e_i(t)\|$" if errors_logged else r"$\|\Phi(z^K(t))\|$")
    for ax, floor in zip(axes, floors, strict=True):
        legend(ax, width, floor.notes())
    return fig


def make_figures(paths: list[str | Path], states: list[str] | None = None) -> dict[str, object]:
    """The figures the given runs contain, by file stem: study1 (all solve runs together),
    <name>-study2 for closed loops, <name>-study3 for distributed closed loops, <name>-paths for closed loops
    with positions. ``states``: the states the x(t) panel of a closed loop draws (``gnerun figures --states``)."""
    _style()
    runs = [read_run(p) for p in paths]
    if states is not None and not any(closed_loops(r) and solver_kind(r) != "distributed" for r in runs):
        raise InputError("--states: no closed loop among the runs (the states are drawn for `gnerun simulate` runs)")
    figures: dict[str, object] = {}
    solves = [r for r in runs if SOLVE_ITERATE in r.messages]
    if solves:
        figures["study1" if len(solves) > 1 else f"{run_name(solves[0])}-study1"] = study1_figure(solves)
    for run in runs:
        loops = closed_loops(run)
        if loops:
            kind = "study3" if solver_kind(run) == "distributed" else "study2"
            figures[f"{run_name(run)}-{kind}"] = study3_figure(run) if kind == "study3" else study2_figure(run, states)
            if has_positions(run):
                figures[f"{run_name(run)}-paths"] = paths_figure(run, loops)
    return figures


# ---------------------------------------------------------------------------------------------
# Sweeps (from the index table alone)
# ---------------------------------------------------------------------------------------------

SCALE_AXES = ("disturbance.scale", "disturbance.plant.scale")


def _groups(rows: list[dict], axes: list[str], exclude: tuple[str, ...]) -> dict[str, list[dict]]:
    """Rows by the values of the axes that are neither plotted nor averaged (seeds), and by K."""
    keys = [a for a in axes if a not in exclude and a not in SEED_AXES]
    with_K = "run.K" not in exclude and len({r.get("K") for r in rows}) > 1
    out: dict[str, list[dict]] = {}
    for r in rows:
        label = ", ".join([f"{k.rsplit('.', 1)[-1]} {r.get(k)}" for k in keys] + ([f"K = {r.get('K')}"] if with_K
                                                                                   else []))
        out.setdefault(label, []).append(r)
    return out


def _seed_means(rows: list[dict], x_of, y_key: str) -> tuple[list[float], list[float]]:
    by_x: dict[float, list[float]] = {}
    for r in rows:
        y = r.get(y_key)
        if r.get("status") != "error" and y is not None and math.isfinite(y):
            by_x.setdefault(x_of(r), []).append(y)
    xs = sorted(by_x)
    return xs, [sum(by_x[x]) / len(by_x[x]) for x in xs]


def iss_figure(name: str, rows: list[dict], axes: list[str], scale_axis: str):
    """Asymptotic ||e|| against the disturbance scale on log-log axes, seeds as dots, their mean as a
    line, and the fitted slope (the ISS gain's order) in the legend."""
    fig, (ax,), width = panels(1)
    floor = FloorAxis(ax, "group")
    dots = []
    for i, (label, group) in enumerate(_groups(rows, axes, (scale_axis,)).items()):
        ok = [r for r in group if r.get("status") != "error"]
        mx, my = _seed_means(group, lambda r: r[scale_axis], "asymptotic_e")
        slope = loglog_slope(mx, my)
        floor.add(mx, my, color=f"C{i % 10}", label=(f"{label}: " if label else "mean over seeds: ")
                  + (f"slope {slope:.3f}" if slope is not None else "no fit"))
        dots.append(([r[scale_axis] for r in ok], [number(r.get("asymptotic_e")) for r in ok], f"C{i % 10}"))
    floor.draw()
    for xs, ys, colour in dots:  # the seeds, where they are above the floor
        ax.plot(xs, [y if y >= FLOOR else math.nan for y in ys], ".", ms=2.5, alpha=0.35, color=colour)
    ax.set_xscale("log")
    ax.set_xlabel(f"disturbance scale ({scale_axis})")
    ax.set_ylabel(r"asymptotic $\|e(t)\|$ (mean, 2nd half)")
    ax.set_title(f"{name}: error against disturbance")
    legend(ax, width, floor.notes())
    return fig


def k_figure(name: str, rows: list[dict], axes: list[str]):
    """max_t ||e(t)|| against K (Theorem "bounded error"), mean over seeds."""
    fig, (ax,), width = panels(1)
    floor = FloorAxis(ax, "line")
    budgets = set()
    for i, (label, group) in enumerate(_groups(rows, axes, ("run.K",)).items()):
        ks, ys = _seed_means(group, lambda r: r["K"], "max_e")
        budgets.update(ks)
        floor.add(ks, ys, label=label or "max e", color=f"C{i % 10}")
    floor.draw()
    ax.set_xlabel("K (solver iterations per sampling time)")
    if 0 < len(budgets) <= 12:  # every K of the sweep
        ax.set_xticks(sorted(budgets))
    else:
        _integer_ticks(ax)
    ax.set_ylabel(r"$\max_t \|e(t)\|$")
    ax.set_title(f"{name}: tracking error against K")
    legend(ax, width, floor.notes())
    return fig


def sweep_figures(sweep_dir: str | Path) -> dict[str, object]:
    """The figures a sweep's index supports: <name>-iss (a disturbance-scale axis), <name>-k (a run.K axis)."""
    _style()
    meta = read_json_object(Path(sweep_dir) / SWEEP_JSON)
    axes, name = meta.get("axes"), meta.get("name")
    if not isinstance(axes, list) or not all(isinstance(a, str) for a in axes) or not isinstance(name, str):
        raise InputError(f"{Path(sweep_dir) / SWEEP_JSON}: damaged {SWEEP_JSON}: no sweep name and axes in it")
    rows = [r for r in read_index(sweep_dir) if _as_written(r, axes)]
    figures: dict[str, object] = {}
    for scale_axis in SCALE_AXES:
        scaled = [r for r in rows if r.get(scale_axis) is not None]
        if scale_axis in axes and scaled:
            figures[f"{name}-iss"] = iss_figure(name, scaled, axes, scale_axis)
            break
    budgets = [r for r in rows if r.get("K") is not None]  # a solve's rows have no K
    if "run.K" in axes and budgets:
        figures[f"{name}-k"] = k_figure(name, budgets, axes)
    return figures


def _as_written(row: dict, axes: list[str]) -> bool:
    """A row of the index with the types gnerun writes (an edited one is left out, as a damaged message is): K an
    integer or empty, the drawn errors and a disturbance scale numbers or empty, the parameters' values hashable."""
    def number(v) -> bool:
        return v is None or isinstance(v, int | float) and not isinstance(v, bool)

    K = row.get("K")
    return ((K is None or isinstance(K, int) and not isinstance(K, bool))
            and all(number(row.get(k)) for k in ("max_e", "asymptotic_e", *SCALE_AXES))
            and all(isinstance(row.get(a), str | int | float | list | type(None)) for a in axes))


def file_stem(name: str) -> str:
    """A figure's file name from a name read in a log (which may have been edited): one plain path component."""
    stem = re.sub(r"[^A-Za-z0-9._=+-]+", "_", name).lstrip(".")[:120]
    return stem or "figure"


def write_figures(paths: list[str | Path], out: str | Path, formats: list[str],
                  sweeps: list[str | Path] = (), states: list[str] | None = None) -> list[Path]:
    """Draw and save; returns the files written. ``states``: as :func:`make_figures`."""
    import matplotlib.pyplot as plt

    output_directory(out, "figures folder", create=False)  # checked before any work, made once there is a figure
    written = []
    drawn = make_figures(paths, states) if paths or states is not None else {}
    for s in sweeps:
        drawn.update(sweep_figures(s))
    if drawn:
        out = output_directory(out, "figures folder")
    for stem, fig in drawn.items():
        for fmt in formats:
            target = out / f"{file_stem(stem)}.{fmt}"
            with open_for_writing(target) as f:
                fig.savefig(f, format=fmt, dpi=DPI)
            written.append(target)
        plt.close(fig)
    return written
