"""The states panel (a) of a closed loop's figure draws (gnerun/view/states.py, `gnerun figures --states`): the
states chosen, every state but the clocks by default, a legend grouped by agent where that is shorter, and a clear
error for a name that is not a state."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from gnerun.view.figures import make_figures
from gnerun.view.states import agent_numbers, clock_states

from .conftest import CONFIGS, run_cli

SIX = ["--set", "game.parameters.N=6", "--set", "game.x0=[0.3,-0.2,-0.4,0.5,-0.9,-0.6,0.6,-1.1,1.2,0.1,-1.3,0.9]",
       "--set", "run.steps=12", "--set", "run.K=[2]"]
ROBOTS = [f"robot{i}" for i in range(1, 7)]


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    import matplotlib.pyplot as plt

    plt.close("all")


@pytest.fixture(scope="module")
def six(tmp_path_factory) -> Path:
    """A closed loop of six robots (12 states), simulated by the CLI."""
    run = tmp_path_factory.mktemp("six") / "run"
    proc = run_cli("simulate", str(CONFIGS / "formation_ring.yaml"), *SIX, "--out", str(run), "--quiet")
    assert proc.returncode == 0, proc.stderr
    return run


def _drawn_states(svg: Path) -> list[str]:
    return re.findall(r'<g id="state-(\w+)"', svg.read_text())


def test_figures_states_draws_exactly_the_chosen_states(six: Path, tmp_path: Path) -> None:
    proc = run_cli("figures", str(six), "--out", str(tmp_path / "f"), "--format", "svg", "--states", "py2, px5,py2")
    assert proc.returncode == 0, proc.stderr
    assert _drawn_states(tmp_path / "f" / "formation-ring-study2.svg") == ["py2", "px5"]  # in the order asked, once
    proc = run_cli("figures", str(six), "--out", str(tmp_path / "all"), "--format", "svg")
    assert proc.returncode == 0, proc.stderr
    assert _drawn_states(tmp_path / "all" / "formation-ring-study2.svg") == [f"p{c}{i}" for i in range(1, 7)
                                                                            for c in "xy"]


@pytest.mark.parametrize(("states", "message"), [
    ("px1,pz2", "error: --states: formation-ring has no state 'pz2' (did you mean 'py2' or 'px2'?); its states: "
                "px1, py1, px2, py2, px3, py3, px4, py4, px5, py5, px6, py6"),
    ("speed", "error: --states: formation-ring has no state 'speed'; its states: px1, py1, px2, py2, px3, py3, px4, "
              "py4, px5, py5, px6, py6"),
    (" , ", "error: --states ' , ': no state names (comma-separated, e.g. --states px1,py1)"),
])
def test_an_unknown_state_is_an_input_error_with_the_nearest_names(six: Path, tmp_path: Path, states: str,
                                                                    message: str) -> None:
    proc = run_cli("figures", str(six), "--out", str(tmp_path / "f"), "--states", states)
    assert proc.returncode == 2 and proc.stderr.strip() == message, proc.stderr
    assert "Traceback" not in proc.stderr and not (tmp_path / "f").exists()


def test_states_of_a_solve_alone_are_an_input_error(tmp_path: Path) -> None:
    run = tmp_path / "solve"
    assert run_cli("solve", str(CONFIGS / "harker.yaml"), "--out", str(run), "--quiet").returncode == 0
    proc = run_cli("figures", str(run), "--out", str(tmp_path / "f"), "--states", "x1")
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.strip() == ("error: --states: no closed loop among the runs (the states are drawn for "
                                   "`gnerun simulate` runs)")


def test_many_states_are_grouped_by_agent_and_titles_name_the_error(six: Path) -> None:
    """Twelve states: a colour per robot, a line style per kind (px{i}, py{i}): 8 legend entries, not 12; panel (b)
    says it shows the solver's error to z*(t), not a tracking error."""
    ax_x, ax_e = make_figures([six])["formation-ring-study2"].axes
    assert [t.get_text() for t in ax_x.get_legend().get_texts()] == [*ROBOTS, "px{i}", "py{i}"]
    lines = {ln.get_label(): ln for ln in ax_x.get_lines()}
    assert lines["px3"].get_color() == lines["py3"].get_color() != lines["px4"].get_color()
    assert lines["px3"].get_linestyle() == lines["px4"].get_linestyle() != lines["py3"].get_linestyle()
    assert ax_e.get_title() == r"(b) solver error $\|z^K - z^*(t)\|$"
    # two states of one robot: a legend entry per state, as the paper's figure has
    ax_x, _ = make_figures([six], states=["px1", "py1"])["formation-ring-study2"].axes
    assert [t.get_text() for t in ax_x.get_legend().get_texts()] == ["px1", "py1"]


def _clock_log(path: Path, dynamics: str) -> None:
    from gnerun.log.mcap_log import RunLog
    from gnerun.log.messages import MpcError, MpcState

    config = ("name: clocked\nsolver: {kind: ssn}\ngame: {kind: dynamic, states: [p1, v1, tc], parameters: {h: 0.5}, "
              f"dynamics: {dynamics}, agents: [{{name: a, inputs: {{u1: {{}}}}}}]}}\n")
    with RunLog(path, config_yaml=config, metadata={"version": "0", "log_time": "simulated"}) as log:
        for t in range(40):
            log.write("/K2/mpc/state", MpcState(t=t, x=[0.01 * t, 0.1, float(t)], u=[0.0]), log_time=t * 10**9)
            log.write("/K2/mpc/error", MpcError(t=t, e_norm=1e-3, e_norm_agent={}), log_time=t * 10**9)


@pytest.mark.parametrize("dynamics", ["{ode: {p1: v1, v1: u1, tc: '1'}, dt: 0.1}",
                                      "{p1: p1 + h*v1, v1: v1 + h*u1, tc: tc + h}"])
def test_a_clock_is_left_out_unless_chosen(tmp_path: Path, dynamics: str) -> None:
    """A state that counts time (dtc/dt = 1, or tc + h) would flatten the others: left out, and said so."""
    _clock_log(tmp_path / "c.mcap", dynamics)
    ax_x, _ = make_figures([tmp_path / "c.mcap"])["clocked-study2"].axes
    assert [ln.get_label() for ln in ax_x.get_lines()] == ["p1", "v1"]
    assert [t.get_text() for t in ax_x.get_legend().get_texts()] == ["p1", "v1", "not drawn: tc (clock)"]
    ax_x, _ = make_figures([tmp_path / "c.mcap"], states=["tc", "p1"])["clocked-study2"].axes
    assert [ln.get_label() for ln in ax_x.get_lines()] == ["tc", "p1"]


def test_clocks_are_states_that_count_time_and_nothing_else() -> None:
    game = {"states": ["a", "b", "c", "d", "e"], "parameters": {"h": 0.1, "z": 0.0}}
    ode = {"a": "1", "b": "h", "c": "z", "d": "a", "e": "1 + t"}
    assert clock_states({"game": {**game, "dynamics": {"ode": ode, "dt": 0.1}}}) == ["a", "b"]
    update = {"a": "a + h", "b": "b + 1", "c": "c + z", "d": "2*d + h", "e": "e + a"}
    assert clock_states({"game": {**game, "dynamics": update}}) == ["a", "b"]
    assert clock_states({"game": {**game, "dynamics": {"A": [[1]], "B": [[1]]}}}) == []


def test_agents_are_found_by_the_number_their_inputs_end_in() -> None:
    def game(agents, states):
        return {"game": {"states": states, "agents": agents}}

    cars = [{"name": "pedestrian", "inputs": {"w3": {}, "a3": {}}}, {"name": "car1", "inputs": {"w1": {}, "a1": {}}}]
    assert agent_numbers(game(cars, ["px1", "px3"])) == {"3": "pedestrian", "1": "car1"}
    # inputs without one number: the numbers left over, in order, when as many are left as agents
    plain = [{"name": "left", "inputs": {"steer": {}}}, {"name": "right", "inputs": {"gas": {}}}]
    assert agent_numbers(game(plain, ["x1", "y1", "x2", "y2"])) == {"1": "left", "2": "right"}
    assert agent_numbers(game(plain, ["x1", "y1"])) == {}
    mixed = [{"name": "both", "inputs": {"u1": {}, "u2": {}}}]
    assert agent_numbers(game(mixed, ["x1"])) == {"1": "both"}


def test_a_grouped_legend_keeps_the_reference_overlay(tmp_path: Path) -> None:
    """Three vehicles with p, v, w states (9 states: 3 agents + 3 kinds = 6 entries) and a reference on p2: r(t) is
    drawn dashed in p2's colour, with one legend entry for it."""
    from gnerun.log.mcap_log import RunLog
    from gnerun.log.messages import MpcError, MpcState, RuntimeValues

    states = [f"{k}{i}" for i in (1, 2, 3) for k in "pvw"]
    agents = ", ".join(f"{{name: car{i}, inputs: {{u{i}: {{}}}}}}" for i in (1, 2, 3))
    config = f"name: refs\nsolver: {{kind: ssn}}\ngame: {{kind: dynamic, states: [{', '.join(states)}], " \
             f"agents: [{agents}]}}\n"
    with RunLog(tmp_path / "r.mcap", config_yaml=config, metadata={"version": "0", "log_time": "simulated"}) as log:
        for t in range(10):
            log.write("/K1/mpc/state", MpcState(t=t, x=[0.1 * j * t for j in range(9)], u=[0.0]), log_time=t * 10**9)
            log.write("/K1/mpc/error", MpcError(t=t, e_norm=1e-3, e_norm_agent={}), log_time=t * 10**9)
            log.write("/K1/mpc/parameters", RuntimeValues(t=t, references={"p2": 0.5}), log_time=t * 10**9)
    ax_x, *_ = make_figures([tmp_path / "r.mcap"])["refs-study2"].axes
    assert [t.get_text() for t in ax_x.get_legend().get_texts()] == ["car1", "car2", "car3", "p{i}", "v{i}", "w{i}",
                                                                    "reference r(t)"]
    lines = {ln.get_label(): ln for ln in ax_x.get_lines()}
    assert list(lines["reference of p2"].get_ydata()) == [0.5] * 10
    assert lines["reference of p2"].get_color() == lines["p2"].get_color()
