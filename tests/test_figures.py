"""Figures and inspection from run logs alone, including logs of runs that were killed."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from gnerun.language.config import load_config
from gnerun.log.mcap_log import read_run
from gnerun.runs.closed_loop import simulate
from gnerun.runs.solving import solve
from gnerun.view.figures import FLOOR, make_figures, write_figures

from .conftest import CONFIGS, run_cli


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    import matplotlib.pyplot as plt

    plt.close("all")


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("runs")
    out = {"clean": root / "clean", "noisy": root / "noisy", "study2": root / "study2", "study3": root / "study3"}
    solve(load_config(CONFIGS / "paper_study1.yaml"), out=out["clean"])
    solve(load_config(CONFIGS / "paper_study1_disturbed.yaml"), out=out["noisy"])
    simulate(load_config(CONFIGS / "paper_study2.yaml", {"run.steps": 12}), out=out["study2"])
    simulate(load_config(CONFIGS / "paper_study3.yaml", {"run.steps": 10}), out=out["study3"])
    return out


def _series(ax, label: str):
    [line] = [ln for ln in ax.get_lines() if ln.get_label() == label]
    return line


def _check_drawn(ax, line, logged: list) -> float | None:
    """The line shows the logged values: each one at or above the floor as it is, each one below (exact zeros
    included) on one row of the band under the floor, within the axes; a missing one as a gap. Returns the row."""
    y = np.asarray(line.get_ydata(), dtype=float)
    assert len(y) == len(logged)
    rows = set()
    for v, drawn in zip(logged, y, strict=True):
        if v is None:
            assert math.isnan(drawn)
        elif v >= FLOOR:
            assert drawn == v
        else:
            assert 0 <= v and ax.get_ylim()[0] < drawn < FLOOR
            rows.add(drawn)
    assert len(rows) <= 1
    return rows.pop() if rows else None


def test_the_plotted_data_are_the_logged_data(runs) -> None:
    figures = make_figures([runs["clean"], runs["noisy"], runs["study2"], runs["study3"]])
    assert sorted(figures) == ["paper-study2-study2", "paper-study3-study3", "study1"]
    # Study 1: one panel per solve, ||z^k - z*|| against k, on one y range
    axes = figures["study1"].axes
    for ax, run, label in zip(axes, ("clean", "noisy"), ("undisturbed", "jacobian noise, scale 0.001"), strict=True):
        iterates = read_run(runs[run]).messages["/solve/iterate"]
        line = _series(ax, label)
        np.testing.assert_array_equal(line.get_xdata(), [m["k"] for m in iterates])
        _check_drawn(ax, line, [m.get("error_norm") for m in iterates])
        assert ax.get_yscale() == "log"
    assert axes[0].get_ylim() == axes[1].get_ylim()
    # Study 2: x(t) of the largest K, ||e(t)|| per K
    record = read_run(runs["study2"])
    ax_x, ax_e = figures["paper-study2-study2"].axes
    states = record.messages["/K7/mpc/state"]
    for j, name in enumerate(("x1", "x2", "x3")):
        np.testing.assert_array_equal(_series(ax_x, name).get_ydata(), [m["x"][j] for m in states])
    rows = [_check_drawn(ax_e, _series(ax_e, f"K = {K}"), [m.get("e_norm") for m in record.messages[
        f"/K{K}/mpc/error"]]) for K in (1, 2, 3, 5, 7)]
    assert len({r for r in rows if r is not None}) == len([r for r in rows if r is not None])  # a row each
    # Study 3: per-agent errors, one panel per K, on one y range
    record = read_run(runs["study3"])
    axes = figures["paper-study3-study3"].axes
    for ax, K in zip(axes, (2, 5), strict=True):
        errors = record.messages[f"/K{K}/mpc/error"]
        for agent in ("agent1", "agent2", "agent3"):
            _check_drawn(ax, _series(ax, agent), [m["e_norm_agent"].get(agent) for m in errors])
    assert axes[0].get_ylim() == axes[1].get_ylim()


def test_every_K_can_be_seen_where_the_errors_are_equal_or_zero(runs, tmp_path) -> None:
    """K = 3, 5 and 7 of Study 2 solve every sampling time: their errors are equal, at rounding level or exactly 0.
    Each is drawn on a row of its own, so that none hides another; rounding noise is not drawn as values."""
    record = read_run(runs["study2"])
    logged = {K: [m["e_norm"] for m in record.messages[f"/K{K}/mpc/error"]] for K in (1, 2, 3, 5, 7)}
    assert logged[3] == logged[5] == logged[7] and max(logged[7]) < FLOOR and 0 in logged[7]
    ax_e = make_figures([runs["study2"]])["paper-study2-study2"].axes[1]
    last = {K: _series(ax_e, f"K = {K}").get_ydata()[-1] for K in logged}
    assert len(set(last.values())) == len(last)  # every K at a height of its own at the last t
    # the variational GNE: Josephy-Newton solves its affine VI in one step; with noise of 1e-15 on F and H (so that
    # z*(t) is solved for, not the loop's own iterate) the errors are rounding noise
    simulate(load_config(CONFIGS / "variational_gne.yaml", {"run.steps": 8, "disturbance.kind": "pseudogradient",
                                                            "disturbance.scale": 1e-15}), out=tmp_path / "vgne")
    vgne = read_run(tmp_path / "vgne")
    ax_e = make_figures([tmp_path / "vgne"])["variational-gne-study2"].axes[1]
    for K in (1, 2, 5):
        values = [m["e_norm"] for m in vgne.messages[f"/K{K}/mpc/error"]]
        assert max(values) < FLOOR and len(set(values)) > 1  # noise in the log ...
        assert len(set(_series(ax_e, f"K = {K}").get_ydata())) == 1  # ... a flat row in the figure


def test_legends_are_outside_the_data_and_inside_the_figure(runs) -> None:
    for stem, fig in make_figures([runs["clean"], runs["noisy"], runs["study2"], runs["study3"]]).items():
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        page = fig.bbox
        for ax in fig.axes:
            legend = ax.get_legend()
            assert legend is not None, stem
            box, data = legend.get_window_extent(renderer), ax.get_window_extent(renderer)
            assert box.y1 <= data.y0, stem  # below the panel
            assert page.x0 <= box.x0 and box.x1 <= page.x1 and page.y0 <= box.y0, stem  # not cut off


def test_figures_are_300_dpi_at_the_papers_column_width_with_embedded_fonts(runs, tmp_path: Path) -> None:
    from PIL import Image

    written = write_figures([runs["clean"], runs["study2"], runs["study3"]], tmp_path, ["png", "pdf"])
    pngs = [p for p in written if p.suffix == ".png"]
    assert len(pngs) == 3
    for png in pngs:
        image = Image.open(png)
        assert image.size[0] == round(3.5 * 300)  # IEEEtran's column, 3.5 in, at 300 dpi
        assert image.info["dpi"] == pytest.approx((300, 300), abs=0.01)
    for pdf in (p for p in written if p.suffix == ".pdf"):
        data = pdf.read_bytes()
        assert data[:5] == b"%PDF-"
        assert b"/FontFile2" in data  # TrueType fonts embedded (Type 42) ...
        assert b"/Type3" not in data and b"/Subtype /Type3" not in data  # ... not Type 3 bitmaps


def _synthetic_loop(path: Path, kind: str, marks: bool) -> None:
    """A closed-loop log with failed and fallback sampling times, as the closed loop records them."""
    from gnerun.log.mcap_log import RunLog
    from gnerun.log.messages import MpcError, MpcState

    config = f"name: marks\nsolver: {{kind: {kind}}}\ngame: {{kind: dynamic, states: [x1, x2], agents: [{{name: a}}, " \
             "{name: b}]}\n"
    status = {2: "singular_jacobian", 5: "diverged"}
    with RunLog(path, config_yaml=config, metadata={"version": "0", "log_time": "simulated"}) as log:
        for K in (1, 3):
            for t in range(8):
                extra = {"status": status.get(t, "converged"), "fallback": t == 4} if marks else {}
                log.write(f"/K{K}/mpc/state", MpcState(t=t, x=[1.0 / (t + 1), 0.5], u=[0.1, 0.2], **extra),
                          log_time=t * 10**9)
                e = 10.0 ** -t if t < 6 else 0.0
                log.write(f"/K{K}/mpc/error", MpcError(t=t, e_norm=e * K, e_norm_agent={"a": e, "b": e / 2}),
                          log_time=t * 10**9)


@pytest.mark.parametrize("marks", [True, False], ids=["recorded", "not recorded"])
def test_failed_and_fallback_steps_are_marked(tmp_path: Path, marks: bool) -> None:
    _synthetic_loop(tmp_path / "loop.mcap", "ssn", marks)
    _synthetic_loop(tmp_path / "dist.mcap", "distributed", marks)
    figures = make_figures([tmp_path / "loop.mcap", tmp_path / "dist.mcap"])
    ax_x, ax_e = figures["marks-study2"].axes
    labels = {ln.get_label(): ln for ln in ax_e.get_lines()}
    if not marks:  # logs that do not record statuses (earlier versions): nothing is marked
        assert "failed step" not in labels and not any(p.get_label() == "failed step" for p in ax_x.patches)
        return
    failed = [ln for ln in ax_e.get_lines() if ln.get_label() == "failed step"]
    fallback = [ln for ln in ax_e.get_lines() if ln.get_label() == "fallback step"]
    assert len(failed) == len(fallback) == 2  # on each K's curve
    for ln in failed:
        np.testing.assert_array_equal(ln.get_xdata(), [2, 5])
    for ln, K in zip(fallback, (1, 3), strict=True):
        np.testing.assert_array_equal(ln.get_xdata(), [4])
        assert ln.get_ydata()[0] == pytest.approx(K * 1e-4)  # at the K's error at t = 4
    legend = [t.get_text() for t in ax_e.get_legend().get_texts()]
    assert "failed step" in legend and "fallback step" in legend
    # the states' panel and Study 3's panels (one K each) shade the sampling times
    for ax in (ax_x, *figures["marks-study3"].axes):
        steps = [p for p in ax.patches if p.get_gid() != "floor band"]
        assert sorted(round(p.get_x() + p.get_width() / 2) for p in steps) == [2, 4, 5]
        assert {p.get_label() for p in ax.patches} >= {"failed step", "fallback step"}


def _truncated(run: Path, tmp_path: Path, fraction: float) -> Path:
    data = (run / "run.mcap").read_bytes()
    target = tmp_path / f"killed-{fraction}.mcap"
    target.write_bytes(data[: int(len(data) * fraction)])
    return target


def test_a_truncated_log_keeps_every_complete_chunk(runs, tmp_path: Path) -> None:
    full = read_run(runs["study2"])
    assert full.complete
    for fraction in (0.3, 0.6, 0.95):
        cut = read_run(_truncated(runs["study2"], tmp_path, fraction))
        assert not cut.complete and cut.config_yaml == full.config_yaml and cut.metadata == full.metadata
        assert 0 < cut.message_count <= full.message_count
        if fraction < 0.9:  # cut inside the data section (at 0.95 only the index is lost)
            assert cut.message_count < full.message_count
        for topic, msgs in cut.messages.items():  # a prefix of what was written
            assert msgs == full.messages[topic][: len(msgs)]


def test_cli_inspect_and_figures_on_finished_and_killed_runs(runs, tmp_path: Path) -> None:
    proc = run_cli("inspect", str(runs["study2"]))
    assert proc.returncode == 0, proc.stderr
    assert "finished log" in proc.stdout and "status: completed" in proc.stdout and "/K7/mpc/error" in proc.stdout
    killed = _truncated(runs["study2"], tmp_path, 0.6)
    proc = run_cli("inspect", str(killed))
    assert proc.returncode == 0, proc.stderr
    assert "unfinished log" in proc.stdout and "status: incomplete" in proc.stdout
    proc = run_cli("figures", str(killed), str(runs["clean"]), "--out", str(tmp_path / "f"), "--format", "png")
    assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in (tmp_path / "f").iterdir()) == ["paper-study1-study1.png", "paper-study2-study2.png"]


@pytest.mark.parametrize("args, needle", [
    (["figures", "nowhere", "--out", "x"], "no run log here"),
    (["inspect", "nowhere"], "no run log here"),
    (["figures", str(CONFIGS), "--out", "x"], "no run log here"),
])
def test_bad_runs_are_input_errors(args, needle) -> None:
    proc = run_cli(*args)
    assert proc.returncode == 2 and needle in proc.stderr and "Traceback" not in proc.stderr


def test_bad_format(runs) -> None:
    proc = run_cli("figures", str(runs["clean"]), "--format", "gif")
    assert proc.returncode == 2 and "choose from png, pdf, svg" in proc.stderr


def test_recover_writes_an_indexed_copy(runs, tmp_path: Path) -> None:
    killed = _truncated(runs["study2"], tmp_path, 0.6)
    cut = read_run(killed)
    target = tmp_path / "repaired.mcap"
    proc = run_cli("recover", str(killed), "--out", str(target))
    assert proc.returncode == 0, proc.stderr
    repaired = read_run(target)
    assert repaired.complete  # readable through its index again
    assert repaired.messages == cut.messages and repaired.log_times == cut.log_times
    assert repaired.config_yaml == cut.config_yaml and repaired.metadata == cut.metadata


def test_a_real_loop_with_failed_steps_is_marked_where_it_failed(tmp_path: Path) -> None:
    """Large noise on JPhi makes some sampling times fail (diverged, singular): the figure marks those of
    summary.json, on the K's curve, and the fallback steps the safeguard took."""
    import json

    noisy = {"disturbance.kind": "jacobian_noise", "disturbance.scale": 3.0, "solver.divergence_limit": 1e4,
             "run.K": [3], "run.steps": 20}
    simulate(load_config(CONFIGS / "paper_study2.yaml", noisy), out=tmp_path / "run")
    by_K = json.loads((tmp_path / "run" / "summary.json").read_text())["by_K"]["3"]
    assert by_K["failed_steps"]
    ax_x, ax_e = make_figures([tmp_path / "run"])["paper-study2-study2"].axes
    [failed] = [ln for ln in ax_e.get_lines() if ln.get_label() == "failed step"]
    np.testing.assert_array_equal(failed.get_xdata(), by_K["failed_steps"])
    fallback = [ln for ln in ax_e.get_lines() if ln.get_label() == "fallback step"]
    assert [list(ln.get_xdata()) for ln in fallback] == ([by_K["fallback_steps"]] if by_K["fallback_steps"] else [])
    shaded = sorted(round(p.get_x() + p.get_width() / 2) for p in ax_x.patches if p.get_gid() != "floor band")
    assert shaded == sorted(by_K["failed_steps"] + by_K["fallback_steps"])  # a failed step is often a fallback too


def test_a_loop_without_z_star_shows_its_residual(tmp_path: Path) -> None:
    """run.reference: none logs no e(t): panel (b) draws ||Phi|| of each sampling time's last iterate per K."""
    import json

    simulate(load_config(CONFIGS / "paper_study2.yaml", {"run.steps": 6, "run.K": [1, 3], "run.reference": "none"}),
             out=tmp_path / "run")
    record = read_run(tmp_path / "run")
    assert not any("e_norm" in m for K in (1, 3) for m in record.messages[f"/K{K}/mpc/error"])
    assert "no e (run.reference: none)" in record.messages["/log"][-1]["message"]  # (the Log panel: no "nan")
    ax_x, ax_e = make_figures([tmp_path / "run"])["paper-study2-study2"].axes
    assert "Phi" in ax_e.get_ylabel() and ax_e.get_title() == "(b) residual (no z*)"
    by_K = json.loads((tmp_path / "run" / "summary.json").read_text())["by_K"]
    for K in (1, 3):
        last = {}
        for m in record.messages[f"/K{K}/mpc/iterate"]:
            last[m["t"]] = m["residual_norm"]  # the iterates of a sampling time come in the order of k
        assert list(last.values()) == by_K[str(K)]["residual_norm"]
        line = _series(ax_e, f"K = {K}")
        np.testing.assert_array_equal(line.get_xdata(), list(last))
        _check_drawn(ax_e, line, list(last.values()))


def _many_states_loop(path: Path, states: int) -> None:
    """A closed-loop log of a game with many states and fallback steps."""
    from gnerun.log.mcap_log import RunLog
    from gnerun.log.messages import MpcError, MpcState

    names = ", ".join(f"s{j}" for j in range(states))
    config = f"name: many\nsolver: {{kind: ssn}}\ngame: {{kind: dynamic, states: [{names}], agents: [{{name: a}}]}}\n"
    with RunLog(path, config_yaml=config, metadata={"version": "0", "log_time": "simulated"}) as log:
        for K in (2, 3, 5):
            for t in range(12):
                log.write(f"/K{K}/mpc/state", MpcState(t=t, x=[j + 0.1 * t for j in range(states)], u=[0.0],
                                                       status="incomplete", fallback=t in (3, 4)), log_time=t * 10**9)
                log.write(f"/K{K}/mpc/error", MpcError(t=t, e_norm=10.0 ** -t, e_norm_agent={}), log_time=t * 10**9)


@pytest.mark.parametrize("states", [3, 8, 12, 20])
def test_a_game_of_many_states_keeps_its_panels_and_its_legend_below_them(tmp_path: Path, states: int) -> None:
    """The legend of x(t) grows with the states; the figure grows with it, so that the panels keep their height."""
    _many_states_loop(tmp_path / "many.mcap", states)
    fig = make_figures([tmp_path / "many.mcap"])["many-study2"]
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    ax_x, ax_e = fig.axes
    for ax in (ax_x, ax_e):
        legend, data = ax.get_legend().get_window_extent(renderer), ax.get_window_extent(renderer)
        assert data.height / fig.dpi == pytest.approx(1.5, abs=0.05), states  # the panel, whatever its legend
        assert legend.y1 <= data.y0 and fig.bbox.y0 <= legend.y0, states  # below the panel, inside the figure
    labels = [t.get_text() for t in ax_x.get_legend().get_texts()]
    assert labels == [f"s{j}" for j in range(states)] + ["fallback step"]
    assert ax_x.get_legend()._ncols >= 2  # in columns, not one long list
    if states == 3:  # a legend of two rows: the figure's own height
        assert fig.get_figheight() == pytest.approx(2.35)


def test_equal_series_are_drawn_as_markers_inside_markers(tmp_path: Path) -> None:
    """Series of equal values above the floor (K = 3 and 5 taking the same steps) cover each other: each series'
    markers are smaller than the one's before, so that every one shows."""
    _many_states_loop(tmp_path / "many.mcap", 3)
    ax_e = make_figures([tmp_path / "many.mcap"])["many-study2"].axes[1]
    lines = [_series(ax_e, f"K = {K}") for K in (2, 3, 5)]
    assert all(np.array_equal(lines[0].get_ydata(), ln.get_ydata()) for ln in lines)
    sizes = [ln.get_markersize() for ln in lines]
    assert sizes == sorted(sizes, reverse=True) and len(set(sizes)) == 3


def test_a_distributed_loop_without_z_star_shows_its_residual(tmp_path: Path) -> None:
    simulate(load_config(CONFIGS / "paper_study3.yaml", {"run.steps": 4, "run.reference": "none"}),
             out=tmp_path / "run")
    record = read_run(tmp_path / "run")
    axes = make_figures([tmp_path / "run"])["paper-study3-study3"].axes
    assert "Phi" in axes[0].get_ylabel()
    for ax, K in zip(axes, (2, 5), strict=True):
        last = {}
        for m in record.messages[f"/K{K}/mpc/iterate"]:
            last[m["t"]] = m["residual_norm"]
        line = _series(ax, "residual (no z*)")
        np.testing.assert_array_equal(line.get_xdata(), list(last))
        _check_drawn(ax, line, list(last.values()))


def test_a_solve_without_z_star_shows_its_residual(runs, tmp_path: Path) -> None:
    solve(load_config(CONFIGS / "paper_study1.yaml", {"run.reference": "none"}), out=tmp_path / "run")
    iterates = read_run(tmp_path / "run").messages["/solve/iterate"]
    assert not any("error_norm" in m for m in iterates)
    ax_none, ax_noisy = make_figures([tmp_path / "run", runs["noisy"]])["study1"].axes
    line = _series(ax_none, "undisturbed: ||Phi(z^k)||, no z*")
    _check_drawn(ax_none, line, [m["residual_norm"] for m in iterates])
    _check_drawn(ax_noisy, _series(ax_noisy, "jacobian noise, scale 0.001"),
                 [m.get("error_norm") for m in read_run(runs["noisy"]).messages["/solve/iterate"]])
    assert "Phi" in ax_none.get_ylabel() and "z^*" in ax_none.get_ylabel()  # the axis names both
