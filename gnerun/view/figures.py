"""Paper-style figures from run logs alone (`gnerun figures`).

- Study 1 (solve runs): ||z^k - z*|| against k on a log scale, one panel per run, side by side (the clean
  and the disturbed solve of Fig. 1).
- Study 2 (closed loops): x(t) of the loop with the largest K, and ||e(t)|| per K on a log scale (Fig. 2).
- Study 3 (distributed closed loops): ||e_i(t)|| per agent, one panel per K (Fig. 3).
- Games with positions (closed loops): the paths in the plane and the pairwise distances against the required
  ones (:mod:`gnerun.view.paths`).

Everything plotted is read from the MCAP log (:func:`gnerun.log.mcap_log.read_run`), so any run from any
machine, finished or killed, can be drawn without solving again. Values that are null in the log, or
zero (no point on a log axis), are left as gaps.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

from ..log.mcap_log import RunRecord, read_run
from .paths import has_positions, paths_figure

_K_TOPIC = re.compile(r"^/K(\d+)/mpc/(state|error|iterate)$")


# An error of exactly 0 (the iterate is z* to the last bit) has no logarithm: it is drawn at this value,
# below any rounding-level error, and the axes say so.
ZERO_AT = 1e-17


def _log_values(values: list[float | None]) -> list[float]:
    return [ZERO_AT if v == 0 else v if v is not None and v > 0 and math.isfinite(v) else math.nan for v in values]


def _note_zeros(ax, values: list[float | None]) -> None:
    if any(v == 0 for v in values) and not getattr(ax, "_gnerun_zero_note", False):
        # room below the zeros' line for the note
        ax.set_ylim(bottom=ZERO_AT / 30)
        ax.text(0.99, 0.01, f"exact 0 drawn at {ZERO_AT:.0e}", transform=ax.transAxes, ha="right", va="bottom",
                fontsize=6, color="0.4")
        ax._gnerun_zero_note = True


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


def closed_loops(run: RunRecord) -> dict[int, dict[str, list[dict]]]:
    """Per K: the messages of /K<k>/mpc/state, /error, /iterate."""
    out: dict[int, dict[str, list[dict]]] = {}
    for topic, msgs in run.messages.items():
        m = _K_TOPIC.match(topic)
        if m:
            out.setdefault(int(m.group(1)), {})[m.group(2)] = msgs
    return dict(sorted(out.items()))


def _style() -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.rcParams.update({"font.size": 9, "axes.grid": True, "grid.alpha": 0.3, "lines.linewidth": 1.4,
                         "legend.fontsize": 8, "figure.dpi": 110, "savefig.bbox": "tight"})


def study1_figure(runs: list[RunRecord]):
    """||z^k - z*|| vs k, one panel per solve run."""
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    fig, axes = plt.subplots(1, len(runs), figsize=(3.4 * len(runs), 2.8), squeeze=False, sharey=True)
    for ax, run, label in zip(axes[0], runs, "abcdefgh", strict=False):
        its = run.messages.get("/solve/iterate", [])
        values = [m.get("error_norm") for m in its]
        ax.semilogy([m["k"] for m in its], _log_values(values), "o-", ms=3, label=disturbance(run))
        _note_zeros(ax, values)
        ax.set_xlabel("iteration k")
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_title(f"({label}) {run_name(run)}", fontsize=9)
        ax.legend(loc="upper right")
    axes[0][0].set_ylabel(r"$\|z^k - z^*\|$")
    fig.tight_layout()
    return fig


def study2_figure(run: RunRecord):
    """x(t) of the loop with the largest K, and ||e(t)|| per K."""
    import matplotlib.pyplot as plt

    loops = closed_loops(run)
    fig, (ax_x, ax_e) = plt.subplots(1, 2, figsize=(7.0, 2.8), sharex=True)  # e(t) = 0 leaves no point
    K_max = max(loops)
    states = loops[K_max].get("state", [])
    names = (run.config.get("game") or {}).get("states") or []
    nx = len(states[0]["x"]) if states else 0
    for j in range(nx):
        ax_x.plot([m["t"] for m in states], [m["x"][j] if m["x"][j] is not None else math.nan for m in states],
                  label=names[j] if j < len(names) else f"x{j + 1}")
    ax_x.set_xlabel("t")
    ax_x.set_ylabel("x(t)")
    ax_x.set_title(f"(a) x(t), K = {K_max}", fontsize=9)
    ax_x.legend(loc="best")
    for K, topics in loops.items():
        errors = topics.get("error", [])
        values = [m.get("e_norm") for m in errors]
        ax_e.semilogy([m["t"] for m in errors], _log_values(values), "o-", ms=2.5, label=f"K = {K}")
        _note_zeros(ax_e, values)
    ax_e.set_xlabel("t")
    ax_e.set_ylabel(r"$\|e(t)\|$")
    ax_e.set_title("(b) tracking error", fontsize=9)
    ax_e.legend(loc="best")
    fig.tight_layout()
    return fig


def study3_figure(run: RunRecord):
    """||e_i(t)|| per agent, one panel per K."""
    import matplotlib.pyplot as plt

    loops = closed_loops(run)
    fig, axes = plt.subplots(1, len(loops), figsize=(3.4 * len(loops), 2.8), squeeze=False, sharey=True)
    for ax, (K, topics), label in zip(axes[0], loops.items(), "abcdefgh", strict=False):
        errors = topics.get("error", [])
        agents = list(errors[0]["e_norm_agent"]) if errors else []
        for agent in agents:
            values = [m["e_norm_agent"].get(agent) for m in errors]
            ax.semilogy([m["t"] for m in errors], _log_values(values), "o-", ms=2.5, label=agent)
            _note_zeros(ax, values)
        ax.set_xlabel("t")
        ax.set_title(f"({label}) K = {K}", fontsize=9)
        ax.legend(loc="best")
    axes[0][0].set_ylabel(r"$\|e_i(t)\|$")
    fig.tight_layout()
    return fig


def make_figures(paths: list[str | Path]) -> dict[str, object]:
    """The figures the given runs contain, by file stem: study1 (all solve runs together),
    <name>-study2 for closed loops, <name>-study3 for distributed closed loops."""
    _style()
    runs = [read_run(p) for p in paths]
    figures: dict[str, object] = {}
    solves = [r for r in runs if "/solve/iterate" in r.messages]
    if solves:
        figures["study1" if len(solves) > 1 else f"{run_name(solves[0])}-study1"] = study1_figure(solves)
    for run in runs:
        loops = closed_loops(run)
        if loops:
            kind = "study3" if solver_kind(run) == "distributed" else "study2"
            figures[f"{run_name(run)}-{kind}"] = (study3_figure if kind == "study3" else study2_figure)(run)
            if has_positions(run):
                figures[f"{run_name(run)}-paths"] = paths_figure(run, loops)
    return figures


# ---------------------------------------------------------------------------------------------
# Sweeps (from the index table alone)
# ---------------------------------------------------------------------------------------------

SCALE_AXES = ("disturbance.scale", "disturbance.plant.scale")


def _groups(rows: list[dict], axes: list[str], exclude: tuple[str, ...]) -> dict[str, list[dict]]:
    """Rows by the values of the axes that are neither plotted nor averaged (seeds), and by K."""
    from ..runs.sweep import SEED_AXES

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
    import matplotlib.pyplot as plt

    from ..runs.sweep import loglog_slope

    fig, ax = plt.subplots(figsize=(4.2, 3.2))
    for label, group in _groups(rows, axes, (scale_axis,)).items():
        xs = [r[scale_axis] for r in group if r.get("status") != "error"]
        ys = [r.get("asymptotic_e") for r in group if r.get("status") != "error"]
        mx, my = _seed_means(group, lambda r: r[scale_axis], "asymptotic_e")
        slope = loglog_slope(mx, my)
        line, = ax.loglog(mx, _log_values(my), "o-", ms=3,
                          label=(f"{label}: " if label else "mean over seeds: ")
                          + (f"slope {slope:.3f}" if slope is not None else "no fit"))
        ax.loglog(xs, _log_values(ys), ".", ms=3, alpha=0.35, color=line.get_color())
    ax.set_xlabel(f"disturbance scale ({scale_axis})")
    ax.set_ylabel(r"asymptotic $\|e(t)\|$ (mean, 2nd half)")
    ax.set_title(f"{name}: error against disturbance", fontsize=9)
    ax.legend(loc="upper left")
    fig.tight_layout()
    return fig


def k_figure(name: str, rows: list[dict], axes: list[str]):
    """max_t ||e(t)|| against K (Theorem "bounded error"), mean over seeds."""
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    fig, ax = plt.subplots(figsize=(4.2, 3.2))
    for label, group in _groups(rows, axes, ("run.K",)).items():
        ks, ys = _seed_means(group, lambda r: r["K"], "max_e")
        ax.semilogy(ks, _log_values(ys), "o-", ms=3, label=label or "max e")
        _note_zeros(ax, ys)
    ax.set_xlabel("K (solver iterations per sampling time)")
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_ylabel(r"$\max_t \|e(t)\|$")
    ax.set_title(f"{name}: tracking error against K", fontsize=9)
    ax.legend(loc="best")
    fig.tight_layout()
    return fig


def sweep_figures(sweep_dir: str | Path) -> dict[str, object]:
    """The figures a sweep's index supports: <name>-iss (a disturbance-scale axis), <name>-k (a run.K axis)."""
    import json

    from ..runs.sweep import SWEEP_JSON, read_index

    _style()
    meta = json.loads((Path(sweep_dir) / SWEEP_JSON).read_text())
    rows = read_index(sweep_dir)
    axes, name = list(meta["axes"]), str(meta["name"])
    figures: dict[str, object] = {}
    for scale_axis in SCALE_AXES:
        if scale_axis in axes:
            figures[f"{name}-iss"] = iss_figure(name, rows, axes, scale_axis)
            break
    if "run.K" in axes:
        figures[f"{name}-k"] = k_figure(name, rows, axes)
    return figures


def write_figures(paths: list[str | Path], out: str | Path, formats: list[str],
                  sweeps: list[str | Path] = ()) -> list[Path]:
    """Draw and save; returns the files written."""
    import matplotlib.pyplot as plt

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    drawn = make_figures(paths) if paths else {}
    for s in sweeps:
        drawn.update(sweep_figures(s))
    for stem, fig in drawn.items():
        for fmt in formats:
            target = out / f"{stem}.{fmt}"
            fig.savefig(target)
            written.append(target)
        plt.close(fig)
    return written
