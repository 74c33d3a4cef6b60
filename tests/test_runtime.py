"""Runtime parameters (gnerun.language.runtime): inputs of the compiled functions, changed without recompiling.

Every number here is checked against an independent reference: a closed-form equilibrium, a numpy roll-out of the
condensed costs, numpy's interpolation, or a game compiled with the value written in as a constant.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import gnerun
from gnerun.errors import InputError
from gnerun.game.compile import compile_game
from gnerun.language.config import load_config
from gnerun.log.mcap_log import read_run

from .conftest import CONFIGS

# a Cournot duopoly with a runtime demand intercept a: price a - q1 - q2, unit cost c; NE q_i = (a - c) / 3
COURNOT = {
    "game": {
        "kind": "static",
        "parameters": {"c": 1.0},
        "runtime": {"a": 10.0},
        "agents": [
            {"name": "f1", "variables": {"q1": {"lower": 0, "start": 0}}, "cost": "-(a - q1 - q2 - c)*q1"},
            {"name": "f2", "variables": {"q2": {"lower": 0, "start": 0}}, "cost": "-(a - q1 - q2 - c)*q2"},
        ],
    },
    "run": {"reference": "none"},
}


def test_a_runtime_number_changes_the_equilibrium_without_recompiling(monkeypatch) -> None:
    cfg = load_config(COURNOT)
    game = compile_game(cfg)
    import gnerun.runs.solving as solving

    def no_compile(*args, **kwargs):
        raise AssertionError("compiled again")

    monkeypatch.setattr(solving, "compile_game", no_compile)
    for a in (4.0, 10.0, 25.5):
        result = gnerun.solve(cfg, parameters={"a": a}, game=game)
        assert result.status == "converged"
        q = result.a
        np.testing.assert_allclose(q, [(a - 1.0) / 3] * 2, rtol=0, atol=1e-12)
        assert result.summary()["parameters"] == {"a": a}


def test_a_runtime_number_gives_the_game_with_the_constant_written_in() -> None:
    rng = np.random.default_rng(3)
    cfg = load_config(COURNOT)
    game = compile_game(cfg)
    for a in (2.0, 7.25):
        constant = {**COURNOT, "game": {**COURNOT["game"], "runtime": {}, "parameters": {"c": 1.0, "a": a}}}
        reference = compile_game(load_config(constant))
        game.set_parameters({"a": a})
        for _ in range(5):
            z = rng.normal(size=game.size)
            L, c = game.kkt_residual(z)
            L0, c0 = reference.kkt_residual(z)
            assert np.array_equal(L, L0) and np.array_equal(c, c0)


def _integrator(cost: str, terminal: str = "0", runtime: dict | None = None, horizon: int = 4) -> dict:
    """x(t + 1) = x(t) + u(t), one agent (an optimal control problem: its cost is checked by a numpy roll-out)."""
    return {"game": {"kind": "dynamic", "horizon": horizon, "states": ["x"], "x0": [0.3],
                     "dynamics": {"A": [[1.0]], "B": [[1.0]]}, "runtime": runtime or {},
                     "agents": [{"name": "p", "inputs": ["u"], "stage_cost": cost, "terminal_cost": terminal}]},
            "run": {"reference": "none", "sampling_time": 0.5, "steps": 4}}


def _rollout(x0: float, u: np.ndarray) -> np.ndarray:
    """x(1), ..., x(T + 1)."""
    return x0 + np.cumsum(u)


def test_per_stage_values_are_read_at_their_stage() -> None:
    T = 4
    runtime = {"r": {"per_stage": True, "value": 0.0}}
    cfg = load_config(_integrator("(x - r)**2 + 0.5*(x - r[tau + 1])**2 + u**2", "3*(x - r)**2", runtime, T))
    game = compile_game(cfg)
    rng = np.random.default_rng(0)
    for _ in range(4):
        r = rng.normal(size=T + 2)  # stages 0..T and the terminal cost's T + 1
        game.set_parameters({"r": r})
        u = rng.normal(size=T + 1)
        xs = _rollout(0.3, u)
        expected = sum((xs[k] - r[k]) ** 2 + 0.5 * (xs[k] - r[k + 1]) ** 2 + u[k] ** 2 for k in range(T + 1))
        expected += 3 * (xs[T] - r[T + 1]) ** 2
        assert game.costs(u)[0] == pytest.approx(expected, rel=1e-14)
    # T + 1 values: the last serves the terminal cost too; one number: every stage
    game.set_parameters({"r": np.arange(T + 1.0)})
    assert game.parameters["r"] == [0.0, 1.0, 2.0, 3.0, 4.0, 4.0]
    game.set_parameters({"r": 2.5})
    assert game.parameters["r"] == [2.5] * (T + 2)


def test_t_is_the_stages_absolute_time() -> None:
    T, dt = 3, 0.5
    cfg = load_config(_integrator("(x - sin(w*t))**2 + u**2", "(x - sin(w*t))**2", {"w": 0.7}, T))
    game = compile_game(cfg)
    rng = np.random.default_rng(1)
    for t_k in (0.0, 1.5, 12.25):
        game.set_parameters({"w": 1.3}, t=t_k)
        u = rng.normal(size=T + 1)
        xs = _rollout(0.3, u)
        times = t_k + dt * np.arange(T + 2)
        expected = sum((xs[k] - np.sin(1.3 * times[k])) ** 2 + u[k] ** 2 for k in range(T + 1))
        expected += (xs[T] - np.sin(1.3 * times[T + 1])) ** 2
        assert game.costs(u)[0] == pytest.approx(expected, rel=1e-13)
        assert game.parameters["t"] == t_k


def _write_table(path, times, values, name="r") -> None:
    rows = "".join(f"{float(t)!r},{float(v)!r}\n" for t, v in zip(times, values, strict=True))
    path.write_text("t," + name + "\n" + rows)


@pytest.mark.parametrize("interpolation", ["linear", "hold"])
def test_a_data_file_is_interpolated_at_the_stages_times(tmp_path, interpolation) -> None:
    times = np.array([0.0, 0.7, 1.0, 2.5, 4.0, 9.0])
    values = np.array([1.0, -2.0, 0.5, 3.0, 3.5, -1.0])
    _write_table(tmp_path / "ref.csv", times, values)
    data = _integrator("(x - r)**2 + u**2", "0", {"r": {"file": "ref.csv", "interpolation": interpolation}})
    (tmp_path / "game.yaml").write_text(json.dumps(data))
    cfg = load_config(tmp_path / "game.yaml")
    game = compile_game(cfg)
    for t_k in (0.0, 0.35, 2.0, 5.5):
        game.set_parameters(t=t_k)
        stage_times = t_k + 0.5 * np.arange(cfg.game.horizon + 2)
        if interpolation == "linear":
            expected = np.interp(stage_times, times, values)
        else:  # the last row at or before each time, found by a plain scan
            expected = [values[max(k for k in range(len(times)) if times[k] <= s)] for s in stage_times]
        np.testing.assert_allclose(game.parameters["r"], expected, rtol=0, atol=1e-15)


def test_npy_tables_by_field_and_by_column_number(tmp_path) -> None:
    times = np.linspace(0, 10, 11)
    structured = np.zeros(11, dtype=[("time", float), ("ox", float)])
    structured["time"], structured["ox"] = times, times**2
    np.save(tmp_path / "s.npy", structured)
    np.save(tmp_path / "plain.npy", np.column_stack([times, -times]))
    runtime = {"ox": {"file": str(tmp_path / "s.npy"), "time": "time"},
               "oy": {"file": str(tmp_path / "plain.npy"), "time": 0, "column": 1}}
    game = compile_game(load_config(_integrator("(x - ox - oy)**2 + u**2", "0", runtime)))
    game.set_parameters(t=1.25)
    stage_times = 1.25 + 0.5 * np.arange(6)
    np.testing.assert_allclose(game.parameters["ox"], np.interp(stage_times, times, times**2), atol=1e-14)
    np.testing.assert_allclose(game.parameters["oy"], -stage_times, atol=1e-14)


def test_the_closed_loop_window_moves_and_the_run_keeps_its_data(tmp_path) -> None:
    times = np.arange(0, 20.0, 0.25)
    _write_table(tmp_path / "ref.csv", times, np.sin(times))
    before = (tmp_path / "ref.csv").read_bytes()
    data = _integrator("(x - r[tau + 1])**2 + u**2", "(x - r)**2", {"r": {"file": "ref.csv"}})
    data["run"].update(K=[1, 3], steps=12)
    (tmp_path / "game.yaml").write_text(json.dumps(data))
    cfg = load_config(tmp_path / "game.yaml")
    sim = gnerun.simulate(cfg, tmp_path / "run")
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    for K in (1, 3):
        recorded = summary["by_K"][str(K)]["parameters"]["r"]
        assert len(recorded) == 12
        for k, values in enumerate(recorded):  # sampling time k: the table at k dt + tau dt
            np.testing.assert_allclose(values, np.interp(0.5 * k + 0.5 * np.arange(6), times, np.sin(times)),
                                       atol=1e-15)
        # the log holds the same values on its own topic
        logged = read_run(tmp_path / "run").messages[f"/K{K}/mpc/parameters"]
        assert [m["values"]["r"] for m in logged] == recorded
    # an LQ loop solves exactly at every sampling time: the plant follows the unconstrained optimum of each window
    assert sim[1].status == ["converged"] * 12
    # the data file is only read, and the run directory holds a copy that its config.yaml names
    assert (tmp_path / "ref.csv").read_bytes() == before
    assert (tmp_path / "run" / "data" / "ref.csv").read_bytes() == before
    again = load_config(tmp_path / "run" / "config.yaml")
    assert again.game.runtime["r"].file == "data/ref.csv"
    rerun = gnerun.simulate(again)
    np.testing.assert_array_equal(rerun[3].x, sim[3].x)


def test_a_parameters_callback_moves_the_goal(tmp_path) -> None:
    data = _integrator("(x - g)**2 + 0.1*u**2", "(x - g)**2", {"g": 0.0})
    data["run"].update(K=[2], steps=20)
    cfg = load_config(data)
    seen = []

    def goals(t, x):
        seen.append((t, x.copy()))
        return {"g": 1.0 if t >= 2.0 else -1.0}

    sim = gnerun.simulate(cfg, tmp_path / "run", parameters=goals)
    x = sim[2].x[:, 0]
    assert [t for t, _ in seen] == pytest.approx(0.5 * np.arange(20))
    np.testing.assert_array_equal([s[1][0] for s in seen], x[:20])  # the callback sees the plant state
    assert x[4] < -0.9 and x[-1] > 0.99  # toward -1, then toward 1 once the goal moved at t = 2 s
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["by_K"]["2"]["parameters"]["g"] == [-1.0] * 4 + [1.0] * 16


@pytest.mark.parametrize(("returned", "fragment"), [
    ({"g": [1.0, 2.0]}, "has shape (2,), the parameter needs one number"),
    ({"h": 1.0}, "not a runtime parameter of this game"),
    ({"g": float("nan")}, "not finite"),
    ([1.0], "returned list"),
    ({"g": "far"}, "is not a number"),
])
def test_a_callback_of_the_wrong_shape_ends_the_run_with_a_clear_error(tmp_path, returned, fragment) -> None:
    data = _integrator("(x - g)**2 + 0.1*u**2", "0", {"g": 0.0})
    data["run"].update(K=[1], steps=5)
    cfg = load_config(data)
    calls = []

    def callback(t, x):
        calls.append(t)
        return {"g": 0.5} if t < 1.0 else returned

    with pytest.raises(InputError, match=".*") as info:
        gnerun.simulate(cfg, tmp_path / "run", parameters=callback)
    assert fragment in str(info.value) and "t = 1 s" in str(info.value)
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["status"] == "error" and summary["by_K"]["1"]["completed_steps"] == 2
    assert read_run(tmp_path / "run").messages["/log"]  # a finished, readable log


def test_a_callback_that_raises_ends_the_run_with_its_message(tmp_path) -> None:
    cfg = load_config(_integrator("(x - g)**2 + u**2", "0", {"g": 0.0}))

    def broken(t, x):
        raise RuntimeError("tracker lost")

    with pytest.raises(InputError, match="parameters callback failed at t = 0 s: RuntimeError: tracker lost"):
        gnerun.simulate(cfg, tmp_path / "run", parameters=broken)
    assert json.loads((tmp_path / "run" / "summary.json").read_text())["status"] == "error"


def test_an_embedded_solver_takes_runtime_values_with_the_state() -> None:
    cfg = load_config(COURNOT)
    game = compile_game(cfg)
    solver = gnerun.make_solver(cfg, game)
    for a in (3.0, 40.0):
        state = gnerun.iterate(solver, solver.init(game.z_start(), game.with_parameters(None, {"a": a})))
        np.testing.assert_allclose(state.z[: game.n], [(a - 1) / 3] * 2, atol=1e-12)
    assert game.parameters == {"a": 10.0}  # the values in force are untouched


def test_runtime_vectors_and_matrices_are_indexed_from_one() -> None:
    runtime = {"goal": [1.0, -2.0], "Q": [[1.0, 0.0], [0.0, 4.0]]}
    data = {"game": {"kind": "static", "runtime": runtime, "agents": [
        {"name": "p1", "variables": {"y1": {"start": 0}}, "cost": "Q[1][1]*(y1 - goal[1])**2"},
        {"name": "p2", "variables": {"y2": {"start": 0}}, "cost": "Q[2][2]*(y2 - goal[2])**2 + Q[1][2]*y1*y2"}]},
            "run": {"reference": "none"}}
    cfg = load_config(data)
    game = compile_game(cfg)
    result = gnerun.solve(cfg, game=game, parameters={"goal": [3.0, 5.0], "Q": [[2.0, 1.0], [0.0, 1.0]]})
    # y1 = 3; y2 minimises (y2 - 5)^2 + y1 y2: y2 = 5 - y1/2
    np.testing.assert_allclose(result.a, [3.0, 3.5], atol=1e-12)


def test_games_without_runtime_values_compile_as_before() -> None:
    for name in ("paper_study1", "paper_study2", "paper_study3"):
        cfg = load_config(CONFIGS / f"{name}.yaml")
        game = compile_game(cfg)
        assert game.runtime is None and game.p.size == 0
        assert "runtime" not in cfg.resolved_yaml()


def test_a_declared_reference_is_logged_with_the_tracking_error_and_drawn(tmp_path) -> None:
    cfg = load_config(CONFIGS / "tracking.yaml", ["run.K=[1, 3]", "run.steps=30"])
    gnerun.simulate(cfg, tmp_path / "run")
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    times = 0.1 * np.arange(30)
    for K in ("1", "3"):
        loop = summary["by_K"][K]
        x = np.array(loop["x"])[:30, 0]
        np.testing.assert_allclose(loop["reference"]["p1"], np.sin(0.8 * times), rtol=0, atol=1e-15)
        np.testing.assert_allclose(loop["tracking_error"]["p1"], x - np.sin(0.8 * times), rtol=0, atol=1e-15)
        logged = read_run(tmp_path / "run").messages[f"/K{K}/mpc/parameters"]
        assert [m["references"]["p1"] for m in logged] == loop["reference"]["p1"]
    from gnerun.view.figures import make_figures

    fig = make_figures([tmp_path / "run"])["tracking-study2"]
    titles = [ax.get_title() for ax in fig.axes if ax.get_visible()]
    assert titles[1] == "(b) tracking error to the reference (p1)"
    assert titles[2] == r"(c) solver error $\|z^K - z^*(t)\|$"
    ax_r = fig.axes[1]
    for K, line in zip(("1", "3"), ax_r.get_lines(), strict=True):  # |x - r| per K, as the summary has it
        np.testing.assert_allclose(line.get_ydata(), np.abs(summary["by_K"][K]["tracking_error"]["p1"]), atol=1e-15)


def test_a_sweep_over_a_runtime_parameter_compiles_once_per_worker(tmp_path) -> None:
    from gnerun.runs.sweep import load_sweep, run_sweep

    spec = tmp_path / "sweep.yaml"
    spec.write_text(f"""version: 1
name: w-sweep
base: {CONFIGS / "tracking.yaml"}
command: simulate
set: {{run.K: [2], run.steps: 8, run.reference: none}}
mode: product
grid:
  game.runtime.w.value: [0.3, 0.9, 1.5, 2.1]
""")
    result = run_sweep(load_sweep(spec), tmp_path / "out", workers=1)
    assert result.ran == 4 and result.failed == 0 and result.games_compiled == 1
    assert json.loads((tmp_path / "out" / "sweep.json").read_text())["games_compiled"] == 1
    # each point is the run of its own config, compiled on its own
    for point in load_sweep(spec).points:
        run = tmp_path / "out" / point.directory
        alone = gnerun.simulate(load_config(run / "config.yaml"))
        summary = json.loads((run / "summary.json").read_text())
        np.testing.assert_array_equal(np.array(summary["by_K"]["2"]["x"]), alone[2].x)
        assert summary["by_K"]["2"]["parameters"]["w"] == [point.params["game.runtime.w.value"]] * 8
