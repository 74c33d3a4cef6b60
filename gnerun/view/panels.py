"""The panels every figure is drawn on: one column of the paper wide (IEEEtran), legends below the panels, and
the sampling times a closed loop marks (failed steps, fallback steps), read from its /K<k>/mpc/state messages."""

from __future__ import annotations

import math

from ..solvers.status import FAILURES

COLUMN_WIDTH = 3.5  # inches: the paper's column (IEEEtran \columnwidth)
TEXT_WIDTH = 7.16  # inches: both columns (\textwidth)
PANEL_HEIGHT = 1.6  # inches, without the legend
LEGEND_ROOM = 0.3  # inches under a panel's x label for its legend (two rows); a taller one makes the figure taller
FAILED_LABEL, FALLBACK_LABEL = "failed step", "fallback step"  # (a fallback step: the budgeted iterate not applied)
MARK_LABELS = (FAILED_LABEL, FALLBACK_LABEL)
FAILED = frozenset(str(s) for s in FAILURES)  # the failure statuses of a sampling time, as logged


def panels(n: int):
    """A figure of n panels, one column of the paper wide for up to two panels, both columns for more (four per
    row); the legends go below the panels (:func:`legend`)."""
    import matplotlib.pyplot as plt

    cols = min(n, 4) if n > 2 else n
    rows = math.ceil(n / cols)
    width = COLUMN_WIDTH if cols <= 2 else TEXT_WIDTH
    fig, grid = plt.subplots(rows, cols, figsize=(width, (PANEL_HEIGHT + 0.75) * rows), squeeze=False,
                             layout="constrained")
    axes = [grid[i // cols][i % cols] for i in range(n)]
    for ax in grid.flat[n:]:
        ax.set_visible(False)
    return fig, axes, width / cols


def legend(ax, width: float, notes: list = (), own: bool = True) -> None:
    """The legend of ``ax`` below it (under its x label: outside the data), in as many columns as fit its
    panel's ``width`` (inches); ``notes`` (the floor band's entry) last. ``own=False``: the notes alone, not the
    labels of the panel's lines (a figure whose lines are labelled per series and whose legend is per group)."""
    from matplotlib.transforms import offset_copy

    handles, labels = ax.get_legend_handles_labels() if own else ([], [])
    found = dict(zip(labels, handles, strict=True))
    # the series first, then the marks of failed and fallback steps, then the notes
    entries = {k: v for k, v in found.items() if k not in MARK_LABELS}
    entries.update({k: found[k] for k in MARK_LABELS if k in found})
    entries.update({h.get_label(): h for h in notes})
    if not entries:
        return
    # below the tick labels and the x label (in points, whatever the panel's height)
    anchor = offset_copy(ax.transAxes, fig=ax.figure, y=-24, units="points")
    renderer = ax.figure.canvas.get_renderer()
    for column in range(len(entries), 0, -1):
        legend = ax.legend(list(entries.values()), list(entries), loc="upper center", bbox_to_anchor=(0.5, 0),
                           bbox_transform=anchor, ncol=column, frameon=False, handlelength=1.6, handletextpad=0.4,
                           columnspacing=0.9, borderaxespad=0)
        if column == 1 or legend.get_window_extent(renderer).width <= 0.97 * width * ax.figure.dpi:
            break
        legend.remove()
    # a legend of many rows (a game of many states) gets room of its own instead of squeezing its panel
    fig = ax.figure
    excess = legend.get_window_extent(renderer).height / fig.dpi - LEGEND_ROOM
    grown = getattr(fig, "_legend_growth", 0.0)
    if excess > grown:
        fig.set_figheight(fig.get_figheight() + excess - grown)
        fig._legend_growth = excess


K_STYLES = ["-", "--", ":", "-."]  # a line style per K, where a colour means something else (an agent)


def k_line(n: int, count: int) -> tuple[float, float | None]:
    """Line width and opacity of the n-th of ``count`` K: the first widest and lightest, each later one narrower and
    drawn over it, the last opaque (no opacity set), so that equal curves of several K all show."""
    share = (count - 1 - n) / max(count - 1, 1)
    return 1.0 + 0.8 * share, (1.0 - 0.5 * share) if share else None


def failed_steps(states: list[dict]) -> list[int]:
    """Sampling times whose status is a failure (logs that do not record statuses have none; the last state, which
    no solver step produced, has an empty one)."""
    return [m["t"] for m in states if m.get("status") in FAILED]


def fallback_steps(states: list[dict]) -> list[int]:
    """Sampling times whose budgeted iterate was not applied (the closed-loop safeguard)."""
    return [m["t"] for m in states if m.get("fallback")]
