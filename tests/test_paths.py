"""The paths and pairwise distances figure of closed loops with positions (gnerun/view/paths.py), drawn from the logs
of real closed loops: the paths and distances as logged, the required distances, the marked steps, and the edges of
the vehicles' own position constraints (the road, the arena)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from gnerun.language.config import load_config
from gnerun.runs.closed_loop import simulate
from gnerun.view.figures import make_figures
from gnerun.view.paths import position_constraints, vehicles

from .conftest import CONFIGS, run_cli

EDGE = 2.82842712474619  # the demo's arena: |px|, |py| <= 2 sqrt 2


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    import matplotlib.pyplot as plt

    plt.close("all")


def _edges(ax) -> list:
    """The traced constraint edges of a paths panel (the wide translucent lines)."""
    return [ln for ln in ax.get_lines() if ln.get_alpha() is not None and ln.get_xdata().size > 1]


def test_the_merge_is_drawn_between_its_road_edges(tmp_path: Path) -> None:
    """ALGAMES's 41-knot MPC merge in real processes: `gnerun simulate`, then `gnerun figures` writes the paths figure;
    its paths and distances are the logged states', the required distance is 0.18, and both edges of the road are
    drawn where the config puts them (the top at py = 0.09, the ramp's edge rising to the road's bottom at -0.09)."""
    run = tmp_path / "merge"
    proc = run_cli("simulate", str(CONFIGS / "algames_merge_mpc.yaml"), "--out", str(run), "--set", "run.K=[2]",
                   "--set", "run.steps=6", "--set", "run.reference=none", "--quiet")
    assert proc.returncode == 0, proc.stderr
    proc = run_cli("figures", str(run), "--out", str(tmp_path / "fig"), "--format", "png")
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "fig" / "algames-merge-mpc-paths.png").stat().st_size > 10_000

    x = np.array(json.loads((run / "summary.json").read_text())["by_K"]["2"]["x"])
    ax_p, ax_d = make_figures([run])["algames-merge-mpc-paths"].axes
    for car, (ix, iy) in enumerate([(0, 1), (4, 5), (8, 9)], start=1):  # labelled by the agents' names
        [path] = [ln for ln in ax_p.get_lines() if ln.get_label() == f"car{car}"]
        np.testing.assert_array_equal(path.get_xdata(), x[:, ix])
        np.testing.assert_array_equal(path.get_ydata(), x[:, iy])
    # each car's distance to the nearest other: car1's is the nearer of car2 and car3
    [d1] = [ln for ln in ax_d.get_lines() if ln.get_label() == "car1"]
    d12, d13 = np.hypot(x[:, 0] - x[:, 4], x[:, 1] - x[:, 5]), np.hypot(x[:, 0] - x[:, 8], x[:, 1] - x[:, 9])
    np.testing.assert_allclose(d1.get_ydata(), np.minimum(d12, d13), rtol=1e-12)
    required = {round(float(ln.get_ydata()[0]), 12) for ln in ax_d.get_lines()
                if ln.get_label().startswith("_") and len(set(ln.get_ydata())) == 1 and ln.get_xdata()[0] == 0}
    assert 0.18 in required

    edges = _edges(ax_p)
    points = np.vstack([np.column_stack([ln.get_xdata(), ln.get_ydata()]) for ln in edges])
    top = points[np.abs(points[:, 1] - 0.09) < 1e-3]
    assert top.size and top[:, 0].min() < x[:, [0, 4, 8]].min() and top[:, 0].max() > x[:, [0, 4, 8]].max()
    ramp = points[points[:, 1] < 0.0]
    bottom = -0.09 + 0.267949192431123 * np.minimum(ramp[:, 0] - 0.2, 0.0)
    assert ramp.size and np.abs(ramp[:, 1] - bottom).max() < 2e-3  # the grid's resolution
    assert ax_p.get_ylim()[1] > 0.09 > x[:, [1, 5, 9]].max()  # the panel reaches the top edge
    assert "constraint edge" in [t.get_text() for t in ax_p.get_legend().get_texts()]
    # the road is the same for every car: drawn once, in grey, its outside shaded
    assert {ln.get_color() for ln in edges} == {"0.35"} and ax_p.collections


def test_the_demo_shows_its_arena_and_its_fallback_steps(tmp_path: Path) -> None:
    """The demo at K = 1 with the defaults: its fallback steps are marked on the distances where the log has them,
    and the arena's edges |px| = 2 sqrt 2 are drawn beside the paths."""
    sim = simulate(load_config(CONFIGS / "mcp_demo.yaml", {"run.K": [1], "run.steps": 12, "run.reference": "none"}),
                   out=tmp_path / "demo")
    r = sim[1]
    assert r.fallback_steps
    ax_p, ax_d = make_figures([tmp_path / "demo"])["mcp-demo-paths"].axes
    marks = [ln for ln in ax_d.get_lines() if ln.get_marker() == "x"]
    assert [list(ln.get_xdata()) for ln in marks] == [r.fallback_steps]
    d = np.hypot(r.x[:, 0] - r.x[:, 4], r.x[:, 1] - r.x[:, 5])
    np.testing.assert_allclose(marks[0].get_ydata(), d[r.fallback_steps], rtol=1e-12)
    sides = sorted({round(float(np.mean(ln.get_xdata())), 6) for ln in _edges(ax_p)
                    if np.ptp(ln.get_xdata()) < 1e-9})
    assert sides == [round(-EDGE, 6), round(EDGE, 6)]
    lo, hi = ax_p.get_xlim()
    assert lo < -EDGE and hi > EDGE


def test_a_vehicles_own_position_constraints_are_found_and_no_others() -> None:
    cfg = load_config(CONFIGS / "algames_intersection.yaml").model_dump(mode="json")
    cars = vehicles(cfg["game"]["states"])
    found = [(c, con.text) for c, con in position_constraints(cfg, cars)]
    assert [c for c, _ in found] == [0, 0, 0, 1, 1, 1, 2, 2]  # lanes and corners, the crosswalk's two sides
    assert all("px" not in text.replace(f"px{c + 1}", "") for c, text in found)  # one vehicle's position alone
    # a constraint on inputs, speeds or two vehicles is none of them
    cfg["game"]["agents"][0]["constraints"] += ["v1 <= 1", "px1 + w1 <= 3", "px1 - px2 >= 0", "py1 <= tau + 1"]
    again = [(c, con.text) for c, con in position_constraints(cfg, cars)]
    assert again == [*found[:3], (0, "py1 <= tau + 1"), *found[3:]]


def _loop_log(path: Path, config: str) -> None:
    from gnerun.log.mcap_log import RunLog
    from gnerun.log.messages import MpcState

    with RunLog(path, config_yaml=config, metadata={"version": "0", "log_time": "simulated"}) as log:
        for t in range(5):
            log.write("/K1/mpc/state", MpcState(t=t, x=[0.1 * t, 0.0, 1.0, 0.2], u=[0.0]), log_time=t * 10**9)


def test_a_logs_config_of_the_wrong_shape_is_left_out_and_odd_constraints_are_not_drawn(tmp_path: Path) -> None:
    """A log's config is data: fields of the wrong type leave the config out (noted as damage: no paths figure),
    and constraints that do not parse or evaluate, or are no text, are not drawn; the others are."""
    from gnerun.log.mcap_log import read_run

    for n, game in enumerate(["{states: [px1, py1], agents: ab}", "{states: [px1, py1], parameters: [1, 2]}",
                              "{states: [px1, py1], agents: [{name: a, constraints: 5}]}",
                              "{states: [px1, py1], shared_constraints: 7}"]):
        _loop_log(tmp_path / f"wrong{n}.mcap", f"name: w\ngame: {game}\n")
        assert any("has the wrong type" in d for d in read_run(tmp_path / f"wrong{n}.mcap").damage), game
        assert not any(k.endswith("-paths") for k in make_figures([tmp_path / f"wrong{n}.mcap"]))
    config = ("name: odd\ngame: {kind: dynamic, states: [px1, py1, px2, py2], parameters: {e: 1.5, s: text},\n"
              "  agents: [{name: a, constraints: [5, {stages: [0]}, 'px1 <= (', 'px1 <= log(-1) + e', 'px1 <= s',\n"
              "                                   {expr: 'px1 <= e'}]}]}\n")
    _loop_log(tmp_path / "odd.mcap", config)
    ax_p, _ = make_figures([tmp_path / "odd.mcap"])["odd-paths"].axes
    [edge] = _edges(ax_p)
    np.testing.assert_allclose(edge.get_xdata(), 1.5, atol=1e-9)  # px1 <= e, the only one drawn


SIX = {"game.parameters.N": 6, "game.x0": [0.3, -0.2, -0.4, 0.5, -0.9, -0.6, 0.6, -1.1, 1.2, 0.1, -1.3, 0.9],
       "run.steps": 30}


def test_six_robots_have_a_legend_per_robot_and_per_K_and_the_closest_pair_named(tmp_path: Path) -> None:
    """The ring of six robots, K = 1 and 3: the figure's legends hold one entry per robot and per K (not one per pair
    and K: 30 before), the robots by their agents' names; panel (b) draws each robot's distance to the nearest other,
    the clearance D = 0.4, and names the closest pair of the run, where it is."""
    sim = simulate(load_config(CONFIGS / "formation_ring.yaml", SIX), out=tmp_path / "six")
    fig = make_figures([tmp_path / "six"])["formation-ring-paths"]
    ax_p, ax_d = fig.axes
    entries = [t.get_text() for ax in fig.axes for t in ax.get_legend().get_texts()]
    robots = [f"robot{i}" for i in range(1, 7)]
    assert entries[:8] == [*robots, "K = 1", "K = 3"] and entries[-2] == "required 0.4"
    assert len(entries) <= 12
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    for ax in fig.axes:  # below the panels, inside the figure
        box, data = ax.get_legend().get_window_extent(renderer), ax.get_window_extent(renderer)
        assert box.y1 <= data.y0 and fig.bbox.y0 <= box.y0 and box.x1 <= fig.bbox.x1
    # each robot's nearest distance per K, and the closest pair over both K
    best = (np.inf, None)
    for K in (1, 3):
        x = sim[K].x
        xy = np.stack([x[:, 0::2], x[:, 1::2]], axis=-1)
        d = np.linalg.norm(xy[:, :, None] - xy[:, None, :], axis=-1)
        d[:, np.arange(6), np.arange(6)] = np.inf
        for i, robot in enumerate(robots):
            [line] = [ln for ln in ax_d.get_lines() if ln.get_label() == f"{robot}, K = {K}"]
            np.testing.assert_allclose(line.get_ydata(), d[:, i].min(axis=1), rtol=1e-12)
        t, a, b = np.unravel_index(np.argmin(d), d.shape)
        best = min(best, (d[t, a, b], (K, t, a, b)), key=lambda v: v[0])
    r, (K, t, a, b) = best
    note = entries[-1]
    assert note == f"closest: robot{a + 1}-robot{b + 1}\n{r:.3g} at t = {t} ({t * 0.1:.3g} s), K = {K}", note
    [mark] = [ln for ln in ax_d.get_lines() if ln.get_marker() == "o"]
    assert (mark.get_xdata()[0], mark.get_ydata()[0]) == (t, pytest.approx(r, rel=1e-12))
    assert 0.4 - 1e-6 <= r  # the clearance holds
