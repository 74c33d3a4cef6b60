"""The closed loop's safeguard (gnerun/runs/safeguard.py), the stage-0 constraint check, the shifted warm start of rows
that change with tau, and the per-step reports: on bare plans, closed forms and the field's trajectory games."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gnerun.game.compile import compile_game, compile_stage_constraints
from gnerun.language.config import load_config
from gnerun.log.mcap_log import read_run
from gnerun.runs import safeguard
from gnerun.runs.closed_loop import StepReport, simulate
from gnerun.runs.safeguard import SAFE, Plan, choose, first_step_violation
from gnerun.solvers.ssn import FAILURES
from gnerun.view.panels import FAILED
from gnerun.view.paths import required_distances, vehicles

from .conftest import CONFIGS

DEMO = CONFIGS / "mcp_demo.yaml"
EDGE = 2.82842712474619  # the demo's arena: |px|, |py| <= 2 sqrt 2
PAPER_RULE = {"run.initial": "start", "run.warm_start": "previous", "run.safeguard": "none"}


def _plan(r: float, v: float, k: int) -> Plan:
    return Plan(np.zeros(1), r, v, k)


def test_a_safe_plan_beats_an_unsafe_one_and_the_least_residual_wins_among_safe_ones() -> None:
    assert choose([_plan(1e-9, 1e-3, 3), _plan(1.0, 0.0, -1)]).k == -1  # unsafe, however close to equilibrium
    assert choose([_plan(1e-2, 0.0, 3), _plan(1e-3, SAFE / 2, 2), _plan(1.0, 0.0, -1)]).k == 2
    assert choose([_plan(1e-2, 0.5, 3), _plan(1e-3, 0.1, 2)]).k == 2  # none safe: the least violation
    assert choose([_plan(math.nan, 0.0, 3), _plan(5.0, 0.0, -1)]).k == -1  # a non-finite residual is last
    assert choose([_plan(1e-3, 0.0, 3), _plan(1e-3, 0.0, -1)]).k == 3  # ties: the first (the iterate)


def test_the_stage_constraints_are_the_games_first_stage_rows_on_the_state_reached() -> None:
    cfg = load_config(DEMO)
    game = compile_game(cfg)
    stage = compile_stage_constraints(cfg)
    rng = np.random.default_rng(1)
    for _ in range(5):
        a = rng.normal(size=game.n)
        x = game.x0 + rng.normal(size=game.nx)
        u = game.first_inputs(a)
        c, _ = game.constraint_values(a, x)
        first = [j for j, info in enumerate(game.constraints) if info.stage == 0]
        np.testing.assert_allclose(stage.function(game.step_dynamics(x, u), u)[0].ravel(), c[first], atol=1e-12)
    # a closed form: the players 0.5 apart at x_next violate (px1 - px2)^2 + (py1 - py2)^2 >= 1 by 0.75
    value, label = stage.violation(np.array([0.0, 0, 0, 0, 0.5, 0, 0, 0]), np.zeros(4))
    assert value == pytest.approx(0.75) and label.startswith("shared: (px1 - px2)**2")
    # and 3.5 beyond the arena's edge
    value, label = stage.violation(np.array([0.0, 0, 0, 0, EDGE + 3.5, 0, 0, 0]), np.zeros(4))
    assert value == pytest.approx(3.5) and label == "player2: px2 <= edge [tau=0]"
    assert first_step_violation(game, stage, game.x0, game.z_start()) == 0.0


def _distances(x: np.ndarray) -> np.ndarray:
    return np.hypot(x[:, 0] - x[:, 4], x[:, 1] - x[:, 5])


def test_the_demo_stays_safe_at_every_budget_and_reports_its_violations(tmp_path) -> None:
    """MCPTrajectoryGameSolver's demo with the defaults: no applied input lets the distance constraint be violated by
    more than 1e-3 or leaves the arena, at K = 1, 3, 5, 10; the reported violations are those of the logged states."""
    out = tmp_path / "demo"
    sim = simulate(load_config(DEMO, {"run.K": [1, 3, 5, 10], "run.steps": 50, "run.reference": "none"}), out=out)
    logged = read_run(out)
    for K, r in sim.items():
        x = r.x
        assert np.all(np.isfinite(x))
        assert 1.0 - _distances(x[1:]).min() ** 2 <= 1e-3, K
        assert np.abs(x[:, [0, 1, 4, 5]]).max() <= EDGE + 1e-9, K
        # independently of the solver: the violation of every row at u(t) and x(t + 1), from the logged states
        states = logged.messages[f"/K{K}/mpc/state"]
        xs = np.array([m["x"] for m in states])
        viol = np.maximum(1.0 - _distances(xs[1:]) ** 2, 0.0)
        viol = np.maximum(viol, np.max(np.abs(xs[1:, [0, 1, 4, 5]]) - EDGE, axis=1).clip(min=0.0))
        np.testing.assert_allclose([m["constraint_violation"] for m in states[:-1]], viol, atol=1e-12)
        np.testing.assert_allclose(r.constraint_violation, viol, atol=1e-12)
        assert r.max_constraint_violation == pytest.approx(viol.max(), abs=1e-12)
        assert [m["t"] for m in states if m["fallback"]] == r.fallback_steps
        assert [m["status"] for m in states[:-1]] == r.status
    summary = __import__("json").loads((out / "summary.json").read_text())
    for K, r in sim.items():
        s = summary["by_K"][str(K)]
        assert s["fallback_steps"] == r.fallback_steps
        assert s["max_constraint_violation"] == pytest.approx(r.max_constraint_violation, abs=1e-15)
        assert len(s["constraint_violation"]) == len(s["status"]) == 50


def test_a_violation_made_by_the_plant_disturbance_is_reported(tmp_path) -> None:
    """The violation at t is measured at the state the plant reached, w(t) included: the demo's players meet at their
    distance of 1, where the noise on their positions pushes them closer than any plan did."""
    from gnerun.log.mcap_log import read_messages

    noise = {"kind": "gaussian", "scale": [0.02, 0.02, 0, 0, 0.02, 0.02, 0, 0], "seed": 1}
    r = simulate(load_config(DEMO, {"run.K": [3], "run.steps": 30, "run.reference": "none",
                                    "disturbance.plant": noise}), out=tmp_path / "run")[3]
    states = [m for topic, m, _ in read_messages(tmp_path / "run" / "run.mcap") if topic == "/K3/mpc/state"]
    xs = np.array([m["x"] for m in states])
    np.testing.assert_array_equal(xs, r.x)
    assert np.abs(r.w).max() > 0
    expected = np.maximum(1.0 - _distances(xs[1:]) ** 2, 0.0)
    expected = np.maximum(expected, np.max(np.abs(xs[1:, [0, 1, 4, 5]]) - EDGE, axis=1).clip(min=0.0))
    np.testing.assert_allclose([m["constraint_violation"] for m in states[:-1]], expected, atol=1e-12)
    assert expected.max() > 1e-3 and r.max_constraint_violation == pytest.approx(expected.max(), abs=1e-12)
    # what the model alone would have reached from x(t) with u(t) is not what is reported
    game = compile_game(load_config(DEMO))
    model = np.array([game.step_dynamics(xs[t], r.u[t]) for t in range(30)])
    assert not np.allclose(np.maximum(1.0 - _distances(model) ** 2, 0.0), expected, atol=1e-6)


def test_under_the_papers_rule_the_demo_flies_off_at_K1() -> None:
    """The paper's rule on the same game: K = 1 applies iterates whose inputs drive the players out of the arena."""
    sim = simulate(load_config(DEMO, {"run.K": [1], "run.steps": 50, "run.reference": "none", **PAPER_RULE}))
    r = sim[1]
    assert np.abs(r.x[:, [0, 1, 4, 5]]).max() > 2 * EDGE
    assert r.max_constraint_violation > 1.0 and not r.fallback_steps


@pytest.mark.parametrize("safeguard", ["none", "fallback"])
def test_the_safeguard_keeps_the_demo_in_its_arena_from_the_previous_iterate(safeguard: str) -> None:
    """Warm-started from the last iterate as it is (warm_start: previous), the demo's budgeted iterates at K = 2
    drive the players out of the arena (to |p| = 39; at K = 5 they did before the interior phase took Mehrotra's steps,
    and stay inside now); the safeguard applies another plan at the sampling times that need one, and the players keep
    their distance inside the arena at both K."""
    sim = simulate(load_config(DEMO, {"run.K": [2, 5], "run.steps": 50, "run.reference": "none",
                                      "run.warm_start": "previous", "run.safeguard": safeguard}))
    for K, r in sim.items():
        reach = np.abs(r.x[:, [0, 1, 4, 5]]).max()
        if safeguard == "none":
            assert not r.fallback_steps, K
            if K == 2:
                assert reach > EDGE and r.max_constraint_violation > 0.1
        else:
            assert reach <= EDGE and r.max_constraint_violation <= 1e-9, K
            assert 1.0 - _distances(r.x[1:]).min() ** 2 <= 1e-9, K
            assert r.fallback_steps and all(r.status[t] != "converged" for t in r.fallback_steps), K


def test_a_fallback_step_applies_the_shifted_previous_plan(monkeypatch: pytest.MonkeyPatch) -> None:
    """When no iterate of a sampling time beats it, the plant gets the previous plan's second input."""
    monkeypatch.setattr(safeguard, "SAFE", -1.0)  # no plan is safe: the least violation, then the first listed
    applied: list[np.ndarray] = []
    original = safeguard.fallback_plan

    def spy(game, solver, stage, x, trace, plan_prev):
        plan = original(game, solver, stage, x, [trace[0]], plan_prev)  # the iterates withheld: the fallback only
        applied.append((plan_prev, plan))
        return plan

    monkeypatch.setattr(safeguard, "fallback_plan", spy)
    sim = simulate(load_config(DEMO, {"run.K": [3], "run.steps": 5, "run.reference": "none"}))
    r = sim[3]
    game = sim.game
    for t, (previous, plan) in enumerate(applied, start=1):
        assert plan.k == -1
        np.testing.assert_array_equal(r.u[t], game.first_inputs(game.shift(previous)[: game.n]))
    assert r.fallback_steps == [t for t in range(5) if r.status[t] != "converged"]


def test_rows_that_change_with_tau_are_not_given_their_successors_multipliers() -> None:
    """ALGAMES's MPC merge grows the collision radius from 0.09 at the first planned knot to 0.10: the three stage-0
    collision rows are other functions than their successors, and only they start from zero in a shifted plan."""
    game = compile_game(load_config(CONFIGS / "algames_merge_mpc.yaml"))
    changed = np.flatnonzero(game.shift_changed_rows)
    assert len(changed) == 3
    assert all(game.constraints[j].stage == 0 and "min(tau, 1)" in game.constraints[j].label for j in changed)
    z = np.arange(game.size, dtype=float) + 1.0
    shifted = game.shift(z)
    assert np.all(shifted[game.n + changed] == 0.0)
    assert np.count_nonzero(shifted[game.n:] == 0.0) == 3
    for name in ("algames_merge.yaml", "mcp_demo.yaml", "vehicles.yaml", "paper_study2.yaml"):
        assert not compile_game(load_config(CONFIGS / name)).shift_changed_rows.any(), name


def test_the_mpc_merge_keeps_its_distances_at_K2() -> None:
    """ALGAMES's 41-knot MPC merge, 20 sampling times at K = 2: no collision (distance >= 0.18 on the step taken),
    the road kept, every violation reported at zero."""
    sim = simulate(load_config(CONFIGS / "algames_merge_mpc.yaml", {"run.K": [2], "run.steps": 20,
                                                                    "run.reference": "none"}))
    r = sim[2]
    x = r.x
    cars = [(0, 1), (4, 5), (8, 9)]
    for i, (a, b) in enumerate(cars):
        assert np.all(x[1:, b] <= 0.09 + 1e-9)
        for c, d in cars[i + 1:]:
            assert np.hypot(x[1:, a] - x[1:, c], x[1:, b] - x[1:, d]).min() >= 0.18 - 1e-9
    assert r.max_constraint_violation <= 1e-9
    assert sum(s == "converged" for s in r.status) >= 5  # the merge itself (t = 2..15) is where K = 2 falls short


def test_the_progress_callback_sees_every_step_as_it_happens(tmp_path) -> None:
    """The callback sees each sampling time once it is done and logged, before the next one is run."""
    from gnerun.log.mcap_log import read_messages

    seen: list[StepReport] = []
    logged: list[list[tuple[int, int]]] = []

    def progress(step: StepReport) -> None:
        seen.append(step)
        logged.append([(int(topic[2]), m["t"]) for topic, m, _ in read_messages(tmp_path / "run" / "run.mcap")
                       if topic.endswith("/mpc/state")])

    sim = simulate(load_config(DEMO, {"run.K": [1, 3], "run.steps": 8, "run.reference": "none"}), out=tmp_path / "run",
                   progress=progress)
    assert [(s.K, s.t) for s in seen] == [(K, t) for K in (1, 3) for t in range(8)]
    order = [(1, t) for t in range(9)] + [(3, t) for t in range(9)]  # each loop ends with its last state x(8)
    for n, (s, states) in enumerate(zip(seen, logged, strict=True)):
        assert sorted(states) == order[: n + 1 + (s.K == 3)], (s.K, s.t)  # every state so far, none beyond
    for s in seen:
        r = sim[s.K]
        np.testing.assert_array_equal(s.x, r.x[s.t])
        np.testing.assert_array_equal(s.u, r.u[s.t])
        assert s.status == r.status[s.t] and s.fallback == (s.t in r.fallback_steps)
        assert s.constraint_violation == r.constraint_violation[s.t] and s.iterations == r.iterations[s.t]
        assert math.isnan(s.e_norm)  # run.reference: none


def test_the_paths_figure_reads_its_vehicles_and_required_distances() -> None:
    cfg = load_config(CONFIGS / "algames_merge_mpc.yaml")
    assert [(v, i, j) for v, i, j in vehicles(cfg.game.states)] == [("1", 0, 1), ("2", 4, 5), ("3", 8, 9)]
    distances = required_distances(cfg.model_dump(mode="json"))
    assert distances == {("px1", "px2"): pytest.approx(0.18), ("px1", "px3"): pytest.approx(0.18),
                         ("px2", "px3"): pytest.approx(0.18)}
    assert FAILED == {str(s) for s in FAILURES}


STAGED = """
name: staged
game:
  kind: dynamic
  horizon: 5
  states: [x1, x2]
  dynamics: {x1: "x1 + u1", x2: "x2 + u2"}
  x0: [0, 0]
  agents:
    - name: a1
      inputs: {u1: {lower: -1, upper: 1}}
      stage_cost: "(x1 - 2)**2 + 0.1*u1**2"
      constraints: [{expr: "x1 <= 1.5", stages: 1..5}, {expr: "x1 + x2 <= 3", stages: [0, 2, 4]}]
    - name: a2
      inputs: {u2: {lower: -1, upper: 1}}
      stage_cost: "(x2 + 2)**2 + 0.1*u2**2"
"""


def _by_reshape(game, z: np.ndarray) -> np.ndarray:
    """The shift as every stage-major block dropping stage 0 and repeating stage T (rows alike at every stage)."""
    out = z.copy()
    n, stages = game.n, game.horizon + 1
    for sl in [*game.agent_slices, *[slice(n + s.start, n + s.stop) for s in [*game.multiplier_slices,
                                                                                 game.shared_slice]]]:
        if sl.stop > sl.start:
            b = z[sl].reshape(stages, -1)
            out[sl] = np.concatenate([b[1:], b[-1:]]).reshape(-1)
    return out


def test_the_shift_moves_each_multiplier_with_its_constraint() -> None:
    for name in ("algames_merge.yaml", "mcp_demo.yaml", "vehicles.yaml", "paper_study2.yaml"):
        game = compile_game(load_config(CONFIGS / name))
        z = np.random.default_rng(0).normal(size=game.size)
        np.testing.assert_array_equal(game.shift(z), _by_reshape(game, z), err_msg=name)
    # constraints at some stages only: a row takes its constraint's next row, and none where the next stage has no
    # such row (a zero multiplier); the last stage keeps its own
    game = compile_game(load_config(text=STAGED))
    z = np.arange(game.size, dtype=float) + 1.0
    shifted = game.shift(z)
    row = {(c.label, c.owner): j for j, c in enumerate(game.constraints)}
    for j, c in enumerate(game.constraints):
        base, stage = c.label.rsplit(" [tau=", 1)[0], c.stage
        successor = row.get((f"{base} [tau={stage + 1}]", c.owner)) if stage < game.horizon else j
        assert shifted[game.n + j] == (0.0 if successor is None else z[game.n + successor]), c.label
    assert shifted[game.n + row[("x1 + x2 <= 3 [tau=0]", 0)]] == 0.0  # no row at tau = 1
    sim = simulate(load_config(text=STAGED, overrides={"run.K": [1, 3], "run.steps": 6, "run.reference": "none"}))
    assert all(set(r.status) <= {"converged", "incomplete"} for r in sim.values())


def test_the_papers_rule_applies_z_K_or_after_a_failed_step_the_last_iterate_before_it() -> None:
    z0, z1, zK = np.zeros(2), np.ones(2), np.full(2, 2.0)
    trace = [(0, 1.0, z0), (1, 0.5, z1)]
    rule = safeguard.PaperRule()
    ok = rule.apply(np.zeros(1), trace, zK, 2, False, False, None)
    assert ok.z is zK and not ok.fallback and ok.plan is None
    assert rule.next_start(trace, ok, zK, False) is zK
    failed = rule.apply(np.zeros(1), trace, zK, 2, False, True, None)
    assert failed.z is z1 and failed.fallback
    assert rule.next_start(trace, failed, zK, True) is z1


def test_the_fallback_policy_goes_on_from_the_best_iterate_and_keeps_a_converged_one() -> None:
    z0, z1, z2 = np.zeros(2), np.ones(2), np.full(2, 2.0)
    policy = safeguard.Fallback(game=None, solver=None, stage=None)  # a converged iterate needs neither
    converged = policy.apply(np.zeros(1), [(0, 1.0, z0), (1, 0.0, z1)], z1, 1, True, False, None)
    assert converged.z is z1 and not converged.fallback and converged.plan is None
    trace = [(0, 1.0, z0), (1, 0.25, z1), (2, np.nan, z2)]  # a non-finite ||Phi|| ranks last
    assert policy.next_start(trace, converged, z2, False) is z1
    assert policy.next_start(trace[:1], safeguard.Applied(z0, True), z2, True) is z0
    assert policy.next_start(trace[:1], safeguard.Applied(z0, False), z2, False) is z2
