"""Paper-style figures from run logs alone (`gnerun figures`).

- Study 1 (solve runs): ||z^k - z*|| against k on a log scale, one panel per run, side by side (the clean
  and the disturbed solve of Fig. 1).
- Study 2 (closed loops): x(t) of the loop with the largest K, and ||e(t)|| per K on a log scale (Fig. 2).
- Study 3 (distributed closed loops): ||e_i(t)|| per agent, one panel per K (Fig. 3).

Everything plotted is read from the MCAP log (:func:`gnerun.mcap_log.read_run`), so any run from any
machine, finished or killed, can be drawn without solving again. Values that are null in the log, or
zero (no point on a log axis), are left as gaps.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

from .mcap_log import RunRecord, read_run

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
        values = [m["error_norm"] for m in its]
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
        values = [m["e_norm"] for m in errors]
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
            values = [m["e_norm_agent"][agent] for m in errors]
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
        if closed_loops(run):
            kind = "study3" if solver_kind(run) == "distributed" else "study2"
            figures[f"{run_name(run)}-{kind}"] = (study3_figure if kind == "study3" else study2_figure)(run)
    return figures


def write_figures(paths: list[str | Path], out: str | Path, formats: list[str]) -> list[Path]:
    """Draw and save; returns the files written."""
    import matplotlib.pyplot as plt

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for stem, fig in make_figures(paths).items():
        for fmt in formats:
            target = out / f"{stem}.{fmt}"
            fig.savefig(target)
            written.append(target)
        plt.close(fig)
    return written
