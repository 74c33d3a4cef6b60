"""The globalized semismooth Newton method (the default): each mechanism on a game that needs it, and the status
contract across every globalization."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from benchmarks.problems import fk, lq
from gnerun.game.compile import compile_game
from gnerun.language.config import load_config
from gnerun.runs.solving import iterate, make_solver, solve
from gnerun.solvers import avi, hybrid, interior_point
from gnerun.solvers.certificate import kkt_residuals
from gnerun.solvers.ssn import FAILURES, SemismoothNewton, Status

from .conftest import CONFIGS

# A player whose cost is linear in its own variable, starting at its active bound with a zero multiplier: the
# min-map row picks the multiplier branch and the Newton matrix has a zero row and column (NUMERICS §5).
LINEAR_AT_BOUND = """
name: linear-at-bound
game:
  kind: static
  agents:
    - name: p1
      variables: {x1: {lower: 0, upper: 2, start: 0}}
      cost: "-x1"
    - name: p2
      variables: {x2: {lower: -1, upper: 1, start: 0}}
      cost: "(x2 - 0.25*x1)**2"
"""


@pytest.fixture
def no_decoupled_start(monkeypatch: pytest.MonkeyPatch) -> None:
    """The globalized method from the configured start, without its first step on cold-started trajectory games
    (the players' decoupled plans), so that the mechanisms after it meet the starts that need them."""
    monkeypatch.setattr(hybrid, "DECOUPLE_ABOVE", np.inf)


@pytest.fixture
def no_avi_step(monkeypatch: pytest.MonkeyPatch) -> None:
    """The globalized method without its first step on LQ games (the affine VI's solution, gnerun.solvers.avi), so
    that the mechanisms after it meet the games that need them."""
    monkeypatch.setattr(avi, "UP_TO", -1)


def _fk(name: str, start: str):
    return next(p for p in fk.problems() if p.name == name and p.start == start)


def _solved(problem, **over):
    cfg = load_config(text=problem.config_yaml, overrides=over)
    game = compile_game(cfg)
    solver = make_solver(cfg, game)
    return game, solver, iterate(solver, solver.init())


def test_a_degenerate_start_is_singular_for_the_local_method_and_solved_by_the_default() -> None:
    local = solve(load_config(text=LINEAR_AT_BOUND, overrides={"solver.globalization": "none"}))
    assert local.status == "singular_jacobian" and local.iterations == 0
    res = solve(load_config(text=LINEAR_AT_BOUND))
    assert res.status == "converged", res.message
    # p1 takes its upper bound, p2 answers x2 = x1/4
    assert res.solution == {"p1": {"x1": pytest.approx(2.0, abs=1e-10)}, "p2": {"x2": pytest.approx(0.5, abs=1e-10)}}
    assert max(res.certificate["best_response_gap"].values()) <= 1e-9


def test_a_continuum_of_equilibria_ends_at_one_certified_point(no_avi_step: None) -> None:
    # FK A.11 as a plain GNE: both players carry x1 + x2 <= 1 with their own multipliers; every point of the segment
    # x1 + x2 = 1, x1 in [1/2, 1], is an equilibrium (player 1 wants 1, player 2 wants 1/2); JPhi is singular at
    # every one of them, and the Levenberg-Marquardt steps end at one
    res = solve(load_config(CONFIGS / "fk_a11.yaml", {"game.equilibrium": "generalized"}))
    assert res.status == "converged", res.message
    x1, x2 = res.solution["p1"]["x1"], res.solution["p2"]["x2"]
    assert x1 + x2 == pytest.approx(1.0, abs=1e-9) and 0.5 - 1e-9 <= x1 <= 1.0 + 1e-9
    assert res.certificate["kkt_residual"] <= 1e-9
    assert max(res.certificate["best_response_gap"].values()) <= 1e-9


@pytest.mark.parametrize("avi_step", [True, False])
@pytest.mark.parametrize("T", [5, 20])
def test_the_bounded_lq_family_is_solved_in_both_equilibria(T: int, avi_step: bool,
                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    """With the affine VI's solution as the first step (one iteration), and without it (the Newton and interior
    phases)."""
    if not avi_step:
        monkeypatch.setattr(avi, "UP_TO", -1)
    for problem in (p for p in lq.lq_problems() if f"T={T} " in p.name):
        game, _, state = _solved(problem)
        assert state.status == Status.CONVERGED, (problem.name, state.message)
        assert (state.k == 1) == avi_step, (problem.name, state.k)
        gaps = problem.best_response_gaps(state.z[: game.n])  # independent: each agent's QP by DAQP
        assert max(gaps.values()) <= 1e-8, (problem.name, gaps)
        if problem.reference is not None:
            np.testing.assert_allclose(state.z[: game.n], problem.reference, atol=1e-8)


def test_a_stalled_interior_phase_restarts_from_its_next_starting_point(monkeypatch: pytest.MonkeyPatch) -> None:
    # FK A.6 from x = 10 (decisions at their upper bounds, a pseudogradient of size 1e4): the interior starts with
    # small multipliers stall; the start scaled by the pseudogradient converges (the players' answers to the plans
    # where the first start stalled solve it too: set aside here)
    monkeypatch.setattr(hybrid, "response_round", lambda game, a, x: None)
    game, solver, state = _solved(_fk("A.6", "x0 = 10"))
    assert state.status == Status.CONVERGED, state.message
    assert state.search.attempt >= 1
    np.testing.assert_allclose(state.z[: game.n], _fk("A.6", "x0 = 10").reference, atol=1e-6)


def test_without_restarts_the_same_start_stalls(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(hybrid, "RESTARTS", 0)
    monkeypatch.setattr(hybrid, "PIVOTS", 0)
    monkeypatch.setattr(hybrid, "response_round", lambda game, a, x: None)  # (the players' answers solve it too)
    _, _, state = _solved(_fk("A.6", "x0 = 10"))
    assert state.status in FAILURES and state.status != Status.CONVERGED


@pytest.mark.parametrize("start", ["x0 = 0", "x0 = 1", "x0 = 10"])
def test_an_lq_game_the_central_path_misses_is_solved_by_pivoting(start: str) -> None:
    # FK A.8: no variational equilibrium exists, and the interior phase's central path (equal multipliers for the
    # copies of a shared row) leads to infeasibility; Lemke's method on the KKT system finds a GNE
    problem = _fk("A.8", start)
    game, _, state = _solved(problem)
    assert state.status == Status.CONVERGED, state.message
    gaps = problem.best_response_gaps(state.z[: game.n])
    assert max(gaps.values()) <= 1e-8, gaps
    x1, x2, x3 = state.z[:3]
    assert x1 + x2 == pytest.approx(1.0, abs=1e-9) and x3 == pytest.approx(1.5 * x1, abs=1e-9)


def test_without_pivoting_that_game_is_not_solved(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(hybrid, "PIVOTS", 0)
    _, _, state = _solved(_fk("A.8", "x0 = 0"))
    assert state.status != Status.CONVERGED


def test_the_default_takes_the_papers_steps_on_the_papers_game() -> None:
    """Study 1: the watchdog accepts every step of the local method, so the iterates are the paper's, bit for bit."""
    cfg = load_config(CONFIGS / "paper_study1.yaml", {"solver.globalization": "auto"})
    game = compile_game(cfg)
    default, local = make_solver(cfg, game), SemismoothNewton(game, cfg.solver)
    a, b = default.init(), local.init()
    while not local.terminate(b)[0]:
        a, b = default.step(a), local.step(b)
        assert np.array_equal(a.z, b.z)
    assert default.terminate(a) == (True, Status.CONVERGED) and a.k == 3


# player 1 maximises x1^2 - x1 x2 / 2 on [-1, 1]: a game without an equilibrium
SADDLE = """
name: saddle
game:
  kind: static
  agents:
    - name: p1
      variables: {x1: {lower: -1, upper: 1, start: 0}}
      cost: "-x1**2 + 0.5*x1*x2"
    - name: p2
      variables: {x2: {lower: -1, upper: 1, start: 0}}
      cost: "(x2 - 0.5*x1)**2"
"""


def test_a_kkt_point_that_is_not_an_equilibrium_has_its_own_status() -> None:
    # player 1 maximises x1^2 - x1 x2 / 2 on [-1, 1]: x1 = 0 is a KKT point (a stationary point with zero
    # multipliers), its best response is the bound opposite in sign to x2 = x1 / 2, so the game has no equilibrium
    # at all: the restarts from best responses cannot find one either
    res = solve(load_config(text=SADDLE))
    assert res.residual_norm <= 1e-10  # the solver did converge ...
    assert res.status == "not_an_equilibrium"  # ... to a point that is not an equilibrium
    # p1's gap at the point reached, by hand: its best response to x2 is a bound, cost -1 - |x2| / 2
    x1, x2 = res.a
    gap = (-x1**2 + 0.5 * x1 * x2) - (-1.0 - 0.5 * abs(x2))
    assert gap >= 0.25  # wherever the restarts end, p1 is far from its best response
    assert "p1" in res.message and res.certificate["best_response_gap"]["p1"] == pytest.approx(gap, abs=1e-6)
    assert not res.success


# A double integrator with explicit Euler steps: the position at tau + 1 does not depend on the input at tau, so
# "p <= 1" at tau = 0 is a condition on the plant state alone (SPEC §3b).
EULER = """
name: euler-wall
game:
  kind: dynamic
  horizon: 6
  states: [p, v]
  dynamics: {p: "p + 0.5*v", v: "v + 0.5*u"}
  x0: [0.0, 1.0]
  agents:
    - name: robot
      inputs: {u: {lower: -2, upper: 2}}
      stage_cost: "(p - 2)**2 + 0.1*u**2"
      constraints: ["p <= 1"]
"""


@pytest.mark.parametrize("globalization", ["none", "auto"])
def test_a_row_no_decision_reaches_is_checked_not_a_singular_newton_row(globalization: str) -> None:
    cfg = load_config(text=EULER, overrides={"solver.globalization": globalization})
    game = compile_game(cfg)
    fixed = np.flatnonzero(game.pattern.zero_gradient_rows)
    assert [game.constraints[j].label for j in fixed] == ["p <= 1 [tau=0]"]
    res = solve(cfg)
    assert res.status == "converged", res.message
    p = res.x[0] + 0.5 * res.x[1]  # p(1), fixed by the state
    assert p <= 1.0
    assert res.certificate["kkt_residual"] <= 1e-9
    assert res.multipliers["robot"][int(fixed[0])] == 0.0


def test_a_violated_row_no_decision_reaches_is_reported_by_its_label() -> None:
    res = solve(load_config(text=EULER, overrides={"game.x0": [0.8, 1.0]}))  # p(1) = 1.3 > 1 whatever u does
    assert res.status == "infeasible_stage_constraint"
    assert "p <= 1 [tau=0]" in res.message and "robot" in res.message and "0.3" in res.message


def test_without_that_rule_the_row_makes_the_newton_matrix_singular(monkeypatch: pytest.MonkeyPatch) -> None:
    # the same game with the rule switched off: the zero row of JPhi is singular as soon as the row is g-branch
    from gnerun.game.pattern import Pattern

    cfg = load_config(text=EULER, overrides={"solver.globalization": "none", "game.x0": [0.8, 1.0]})
    game = compile_game(cfg)
    monkeypatch.setattr(Pattern, "zero_gradient_rows", property(lambda self: np.zeros(self.game.m, dtype=bool)))
    solver = make_solver(cfg, game)
    state = iterate(solver, solver.init())
    assert state.status == Status.SINGULAR_JACOBIAN


GLOBALIZATIONS = ["none", "line_search", "hybrid", "interior_point"]
KNOWN = [("harker.yaml", {"x1": 5.0, "x2": 9.0}), ("fk_a11.yaml", {"x1": 0.75, "x2": 0.25}),
         ("fk_a12.yaml", {"x1": 16 / 3, "x2": 16 / 3})]


@pytest.mark.parametrize("globalization", GLOBALIZATIONS)
@pytest.mark.parametrize(("name", "known"), KNOWN)
def test_every_globalization_reaches_the_known_solution(name: str, known: dict, globalization: str) -> None:
    res = solve(load_config(CONFIGS / name, {"solver.globalization": globalization, "solver.kind": "ssn"}))
    assert res.status == "converged", res.message
    values = {v: x for agent in res.solution.values() for v, x in agent.items()}
    assert values == pytest.approx(known, abs=1e-8)
    assert res.residual_norm <= load_config(CONFIGS / name).solver.tol


@pytest.mark.parametrize("globalization", GLOBALIZATIONS)
def test_every_globalization_keeps_the_status_contract(globalization: str) -> None:
    """Converged means ||Phi|| <= tol and an independent KKT check agrees; every other end is a failure status
    with a message, or max_iter; nothing raises."""
    problems = [_fk("A.2", "x0 = 0.01"), _fk("A.6", "x0 = 10"), _fk("A.17", "x0 = 0")]
    for problem in problems:
        cfg = load_config(text=problem.config_yaml, overrides={"solver.globalization": globalization,
                                                                "solver.max_iter": 120})
        game = compile_game(cfg)
        solver = make_solver(cfg, game)
        state = iterate(solver, solver.init())
        if state.status == Status.CONVERGED:
            assert state.residual_norm <= cfg.solver.tol
            assert kkt_residuals(game, state.z)["kkt_residual"] <= 10 * cfg.solver.tol
        else:
            assert state.status in FAILURES | {Status.MAX_ITER}
            assert state.message


def _merge_draw(draw: int):
    """ALGAMES's merge from draw ``draw`` of seed 0: the problem, its config, the compiled game and a default solver."""
    from benchmarks.problems import trajectory

    problem = trajectory.merge_problems(draw + 1)[draw]
    cfg = load_config(text=problem.config_yaml)
    game = compile_game(cfg)
    return problem, cfg, game, make_solver(cfg, game)


@pytest.mark.slow
def test_merges_from_random_states_converge_and_are_equilibria() -> None:
    from benchmarks.problems import trajectory

    problems = trajectory.merge_problems(4, seed=7)
    cfg = load_config(text=problems[0].config_yaml)
    game = compile_game(cfg)
    solver = make_solver(cfg, game)
    for problem in problems:
        x0 = np.asarray(load_config(text=problem.config_yaml).game.x0)
        state = iterate(solver, solver.init(None, x0))
        assert state.status == Status.CONVERGED, state.message
        gaps = problem.best_response_gaps(state.z[: game.n])
        assert max(gaps.values()) <= 1e-5, gaps


@pytest.mark.slow
def test_a_hand_over_refused_on_the_interior_guess_is_taken_on_the_corrected_active_set(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """ALGAMES's merge, draw 0: at the first hand-over try the interior iterate's active set (lambda_j > w_j)
    holds rows that are inactive at the solution, and the plain min-map step climbs; the same step on the active
    set it points to halves ||Phi||."""
    from benchmarks.problems import trajectory

    problem = trajectory.merge_problems(1)[0]
    cfg = load_config(text=problem.config_yaml)
    solver = make_solver(cfg, compile_game(cfg))
    state = iterate(solver, solver.init(), finish=False,
                    stop=lambda s: s.search.phase == "interior" and s.residual_norm <= s.search.handover)
    assert state.search.phase == "interior" and state.status == Status.RUNNING
    taken = solver._handover(state)
    assert taken is not None and taken.residual_norm <= hybrid.HANDOVER_DECREASE * state.residual_norm
    monkeypatch.setattr(hybrid, "HANDOVER_ROUNDS", 0)
    assert solver._handover(state) is None


@pytest.mark.slow
def test_a_newton_step_that_climbs_after_the_hand_over_is_taken_on_the_corrected_active_set(
        monkeypatch: pytest.MonkeyPatch, no_decoupled_start: None) -> None:
    """ALGAMES's merge, draw 6 of seed 0, from the configured start: after the hand-over a min-map Newton step
    multiplies ||Phi|| 750-fold (a row the step leaves with a violated constraint); the same step on the active set it
    points to is taken instead, at least halving ||Phi||, and the solve converges to an equilibrium in fewer iterations
    than with the climb left to the watchdog."""
    problem, cfg, game, _ = _merge_draw(6)
    taken: list[tuple[float, float]] = []
    corrected = hybrid.HybridNewton._corrected

    def spy(self, state, z, c):
        out = corrected(self, state, z, c)
        if state.search.phase == "newton" and out is not None:
            taken.append((state.residual_norm, out.residual_norm))
        return out

    monkeypatch.setattr(hybrid.HybridNewton, "_corrected", spy)
    solver = make_solver(cfg, game)
    state = iterate(solver, solver.init())
    assert state.status == Status.CONVERGED, state.message
    assert max(problem.best_response_gaps(state.z[: game.n]).values()) <= 1e-5
    assert taken and all(after <= hybrid.HANDOVER_DECREASE * before for before, after in taken)
    monkeypatch.setattr(hybrid, "CORRECT_ABOVE", np.inf)
    solver = make_solver(cfg, game)
    plain = iterate(solver, solver.init())
    assert plain.status == Status.CONVERGED and state.k < plain.k


def test_a_kkt_point_that_is_not_an_equilibrium_is_left_from_the_best_responses(monkeypatch) -> None:
    """FK A.2 from x = 1: the method reaches a KKT point at which players 2 to 4 (nonconvex in their own
    variables) can improve alone; from their best responses it reaches an equilibrium."""
    from gnerun.runs import solving

    problem = _fk("A.2", "x0 = 1")
    res = solve(load_config(text=problem.config_yaml))
    assert res.status == "converged" and "restart" in res.message, res.message
    assert max(problem.best_response_gaps(res.a).values()) <= 1e-9
    monkeypatch.setattr(solving, "CERTIFY_RESTARTS", 0)
    res = solve(load_config(text=problem.config_yaml))
    assert res.status == "not_an_equilibrium"
    assert max(problem.best_response_gaps(res.a).values()) > 1e-4


def test_a_certificate_restart_begins_in_the_interior_phase_with_the_warm_barrier(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # SADDLE has no equilibrium, so certified_solve restarts from p1's best response; each restart
    # must be a warm interior start (lambda_i w_i = WARM on every inequality row), not a cold init
    from gnerun.runs import solving
    from gnerun.solvers import interior_point

    cfg = load_config(text=SADDLE)
    game = compile_game(cfg)
    solver = make_solver(cfg, game)
    starts = []
    original = solver.restart

    def spy(z0, x=None, rng=None):
        state = original(z0, x, rng)
        starts.append(state)
        return state

    monkeypatch.setattr(solver, "restart", spy)
    out = solving.certified_solve(game, solver, solver.init())
    assert out.restarts == len(starts) >= 1
    for state in starts:
        it = state.search.interior
        assert state.search.phase == "interior" and it is not None
        lam = it.z[game.n + solver.interior.I]
        scaled = lam * np.maximum(it.w, 1.0)  # a start's multipliers are mu / max(w, 1)
        assert np.all(scaled >= interior_point.WARM * (1 - 1e-12))
        assert np.any(np.isclose(scaled, interior_point.WARM))


@pytest.mark.parametrize("noisy", [False, True])
def test_a_restart_that_would_repeat_an_earlier_one_is_not_run(monkeypatch: pytest.MonkeyPatch, noisy: bool) -> None:
    # every restart of this solver goes back to the first start, so it reaches the same KKT point, where the
    # certificate finds the same best response: the second restart would start where the first did and repeat it.
    # A solver that draws noise (a solver-side disturbance) is not a function of its start: its restarts all run
    from gnerun.runs import solving

    cfg = load_config(text=SADDLE, overrides={"disturbance.kind": "residual", "disturbance.scale": 1e-14}
                      if noisy else None)
    game = compile_game(cfg)
    solver = make_solver(cfg, game)
    first = solver.init()
    starts = []

    def back(z0, x=None, rng=None):
        starts.append(z0[: game.n].copy())
        return solver.init(first.z, x, rng)

    monkeypatch.setattr(solver, "restart", back)
    from gnerun.solvers import certificate as certificates

    computed = []
    original = certificates.certificate

    def counted(game, z, *args, **kwargs):
        computed.append(z.copy())
        return original(game, z, *args, **kwargs)

    monkeypatch.setattr(certificates, "certificate", counted)
    notes: list[str] = []
    out = solving.certified_solve(game, solver, first, note=notes.append)
    assert out.status == "not_an_equilibrium"
    if noisy:
        assert out.restarts == solving.CERTIFY_RESTARTS and out.repeats is None
        assert len(computed) == solving.CERTIFY_RESTARTS + 1  # every KKT point certified anew
        return
    assert out.restarts == len(starts) == 1 and out.repeats == 1
    assert "another would have started where restart 1 did" in out.message
    assert "no restart again" in notes[-1]
    # the restart ended at the KKT point of the first certificate: the agent that could improve is checked again,
    # the other's check stands as the first certificate made it
    assert len(computed) == 2 and any("ended at the KKT point of the last certificate" in n for n in notes)
    fresh = original(game, out.state.z)
    assert out.certificate["best_response_gap"] == fresh["best_response_gap"]
    assert out.certificate["best_response_kind"] == fresh["best_response_kind"]
    assert out.certificate["kkt_residual"] == fresh["kkt_residual"]


@pytest.mark.slow
def test_a_first_newton_step_that_climbs_hands_a_nonlinear_game_to_the_interior_phase(
        monkeypatch: pytest.MonkeyPatch, no_decoupled_start: None) -> None:
    """ALGAMES's merge, draw 0, from the configured start: the first Newton step from z^0 multiplies ||Phi|| by 8.5;
    that iteration is the interior phase's first step instead (||Phi|| falls), where the watchdog took three climbing
    steps before."""
    _, cfg, game, solver = _merge_draw(0)
    start = solver.init()
    first = solver.step(start)
    assert first.search.phase == "interior" and first.residual_norm < start.residual_norm
    # the same point as a closed loop's warm start: the Newton step is kept, climbing (a budget of K steps from the
    # last plan is better spent on Newton steps than on leaving it for the interior)
    warm = solver.step(solver.init(warm=True))
    assert warm.search.phase == "newton" and warm.residual_norm > 8.0 * start.residual_norm
    monkeypatch.setattr(hybrid, "FIRST_STEP", np.inf)
    monkeypatch.setattr(hybrid, "LATER_STEP", np.inf)
    phases = _newton_steps_before_the_interior_phase(cfg, game)
    assert len(phases) == 5 and phases[1] > 8.0 * phases[0], phases  # z^0, three climbing steps, the interior start


@pytest.mark.slow
def test_a_later_newton_step_from_z0_that_climbs_hands_a_nonlinear_game_to_the_interior_phase(
        monkeypatch: pytest.MonkeyPatch, no_decoupled_start: None) -> None:
    """ALGAMES's merge, draw 61 of seed 0, from the configured start: the first Newton step from z^0 raises ||Phi||
    1.48-fold (kept), the second 7.4-fold (more than LATER_STEP); that iteration is the interior phase's first step
    instead, and the solve converges in 13 iterations, where the watchdog kept the Newton phase for 19 steps (17 of them
    Levenberg-Marquardt steps) and the solve took 31."""
    problem, cfg, game, solver = _merge_draw(61)
    start = solver.init()
    first = solver.step(start)
    assert first.search.phase == "newton" and start.residual_norm < first.residual_norm <= 1.5 * start.residual_norm
    second = solver.step(first)
    assert second.search.phase == "interior" and second.residual_norm < first.residual_norm
    state = iterate(solver, start)
    assert state.status == Status.CONVERGED and state.k == 13
    assert max(problem.best_response_gaps(state.z[: game.n]).values()) <= 1e-5
    phases = []
    with monkeypatch.context() as m:  # the rule as it was: the first step alone
        m.setattr(hybrid, "LATER_STEP", np.inf)
        solver = make_solver(cfg, game)
        before = iterate(solver, solver.init(), on_iterate=lambda s: phases.append(s.search.phase))
    assert before.status == Status.CONVERGED and before.k == 31 and phases[:20] == ["newton"] * 20


def test_an_lq_games_first_newton_step_may_climb(no_avi_step: None) -> None:
    """FK A.7 from 0 (affine KKT system): the first min-map Newton step multiplies ||Phi|| by 22 and the next two
    solve the game; the rule for nonlinear games leaves it alone."""
    cfg = load_config(text=_fk("A.7", "x0 = 0").config_yaml)
    game = compile_game(cfg)
    solver = make_solver(cfg, game)
    state = iterate(solver, solver.init())
    assert state.converged and state.k == 3, (state.k, state.message)
    merits = _newton_steps_before_the_interior_phase(cfg, game)
    assert merits[1] > 20.0 * merits[0], merits


def _newton_steps_before_the_interior_phase(cfg, game) -> list[float]:
    solver = make_solver(cfg, game)
    state = solver.init()
    merits = [state.residual_norm]
    while state.search.phase == "newton" and not solver.terminate(state)[0]:
        state = solver.step(state)
        merits.append(state.residual_norm)
    return merits


def test_a_levenberg_marquardt_step_that_barely_moves_ends_the_newton_phase(no_avi_step: None) -> None:
    """On the generalized LQ game the Newton phase meets a stationary point of ||Phi|| that is no solution (the
    copies of the shared row make JPhi singular): one Levenberg-Marquardt step there that changes ||Phi|| by less
    than FLAT hands over to the interior phase at once, not after the watchdog's WATCHDOG steps."""
    cfg = load_config(text=lq.lq_yaml(5, "generalized"))
    game = compile_game(cfg)
    merits = _newton_steps_before_the_interior_phase(cfg, game)
    assert len(merits) <= 4, merits
    newton = merits[:-1]  # the last entry is the first interior iterate
    assert all(abs(b - a) >= hybrid.FLAT * a for a, b in zip(newton, newton[1:], strict=False))


def test_without_that_rule_the_newton_phase_lingers(monkeypatch: pytest.MonkeyPatch, no_avi_step: None) -> None:
    monkeypatch.setattr(hybrid, "FLAT", 0.0)
    cfg = load_config(text=lq.lq_yaml(5, "generalized"))
    merits = _newton_steps_before_the_interior_phase(cfg, compile_game(cfg))
    assert len(merits) > 4, merits


# A six-robot formation (configs/formation_ring.yaml, N = 6) from a start where the interior phase's barrier path is
# long: the interior phase alone wanders for 300 iterations; the line-search phase after SLOW iterations converges.
FORMATION_X0 = [0.3, -0.2, -0.4, 0.5, -0.9, -0.6, 0.6, -1.1, 1.2, 0.1, -1.3, 0.9]


def _formation(**over):
    return load_config(CONFIGS / "formation_ring.yaml",
                       overrides={"game.parameters.N": 6, "game.x0": FORMATION_X0, "run.reference": "none", **over})


def test_a_long_barrier_path_is_left_for_the_line_search_phase_and_ends_at_an_equilibrium() -> None:
    from benchmarks.problems.formation import FormationModel

    res = solve(_formation())
    assert res.status == "converged", res.message
    assert res.iterations > hybrid.SLOW  # the line-search phase began at SLOW
    model = FormationModel(6, np.asarray(FORMATION_X0))
    U = model.plans(res.a)
    assert U[:, 0, 0].tolist() == pytest.approx(res.solution["robot1"]["ux1"], abs=0)
    assert all((model.clearances(U, i) >= -1e-9).all() for i in range(6))
    game = compile_game(_formation())  # the numpy model is gnerun's game: the same costs at the solution and at zero
    for a in (res.a, np.zeros_like(res.a)):
        assert game.costs(a) == pytest.approx([model.cost(model.plans(a), i) for i in range(6)], rel=1e-12)
    # each robot's best response to the others by SLSQP (numpy, independent of gnerun): none improves
    assert max(model.best_response_gaps(res.a).values()) <= 1e-6
    # the check finds the improvement where there is one: at zero inputs every robot gains
    assert min(model.best_response_gaps(np.zeros_like(res.a)).values()) > 1e-2


def test_without_the_line_search_phase_that_start_is_not_solved(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(hybrid, "SLOW", 10**6)
    monkeypatch.setattr(hybrid, "response_round", lambda game, a, x: None)  # (the robots' answers reach a KKT point)
    res = solve(_formation(**{"run.certificate": False}))
    assert res.status == "stalled", res.message  # every interior start stalls
    assert "after 3 start(s)" in res.message


@pytest.mark.slow
def test_a_cold_merge_starts_from_the_players_decoupled_plans(monkeypatch: pytest.MonkeyPatch) -> None:
    """ALGAMES's merge, draw 4 of seed 0: the first iteration is the cars' plans as if each were alone (the rows that
    two cars' decisions reach left out, solved to ||Phi|| <= ALONE_TOL), ||Phi|| 70 times lower than at zero inputs,
    where each car's own rows hold (to ALONE_TOL) and SLSQP on its problem without the others' rows finds nothing
    better; from there the solve converges to an
    equilibrium in 12 iterations, where from zero inputs it stalls twice and takes 54 (a round of best responses
    among them)."""
    problem, cfg, game, solver = _merge_draw(4)
    start = solver.init()
    assert start.search.decouple and start.residual_norm > hybrid.DECOUPLE_ABOVE
    first = solver.step(start)
    assert first.k == 1 and first.search.phase == "newton"
    assert first.residual_norm <= hybrid.DECOUPLED_GAIN * start.residual_norm
    assert np.array_equal(first.search.origin, first.z) and np.array_equal(first.search.start, start.z)
    # each car's plan alone: its own rows hold, and it is a best response on its problem without the joint rows
    from scipy.optimize import minimize

    from gnerun.game.agents import OwnProblem

    joint = game.pattern.joint_rows
    plans = first.z[: game.n]
    for i, sl in enumerate(game.agent_slices):
        alone = OwnProblem(game, i, plans, start.x)
        own = ~joint[alone.rows] & ~alone.eq  # (the merge has no equality rows)
        assert np.max(alone.at(plans[sl])[2][own], initial=0.0) <= hybrid.ALONE_TOL
        res = minimize(alone.objective, plans[sl].copy(), jac=True, method="SLSQP",
                       constraints=[{"type": "ineq", "fun": lambda ai, p=alone, k=own: -p.at(ai)[2][k],
                                     "jac": lambda ai, p=alone, k=own: -p.at(ai)[3][k]}], options={"maxiter": 200})
        feasible = np.max(alone.at(res.x)[2][own], initial=0.0) <= 1e-8
        assert not feasible or alone.objective(res.x)[0] >= alone.objective(plans[sl])[0] - 1e-8
    state = iterate(solver, start)
    assert state.status == Status.CONVERGED and state.k <= 15, (state.k, state.message)
    assert max(problem.best_response_gaps(state.z[: game.n]).values()) <= 1e-5
    monkeypatch.setattr(hybrid, "DECOUPLE_ABOVE", np.inf)
    solver = make_solver(cfg, game)
    plain = iterate(solver, solver.init())
    assert plain.status == Status.CONVERGED and plain.k > 3 * state.k, plain.k


@pytest.mark.slow
def test_decoupled_plans_that_drive_through_each_other_give_way_to_the_configured_start(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The overtaking game from "car 1 brakes": planned alone, the faster car drives through the slower one;
    ||Phi|| there is 90 times lower than at the start, but the interior phase from it climbs above ||Phi(z^0)||.
    That iterate's place is taken by the configured start, and the solve goes on as it would have without the
    decoupled plans: the same solution, in the same iterations after the trial."""
    from benchmarks.problems import trajectory

    problem = next(p for p in trajectory.overtaking_problems() if "brakes" in p.start)
    cfg = load_config(text=problem.config_yaml)
    game = compile_game(cfg)
    solver = make_solver(cfg, game)
    start = solver.init()
    states: list = []
    state = iterate(solver, start, on_iterate=states.append)
    assert states[1].residual_norm <= hybrid.DECOUPLED_GAIN * start.residual_norm
    back = next(k for k, s in enumerate(states) if k > 1 and np.array_equal(s.z, start.z))
    assert all(s.search.abandon == start.residual_norm for s in states[1:back])
    assert states[back].search.abandon == np.inf
    monkeypatch.setattr(hybrid, "DECOUPLE_ABOVE", np.inf)
    solver = make_solver(cfg, game)
    plain = iterate(solver, solver.init())
    assert state.status == plain.status == Status.CONVERGED
    assert state.k == plain.k + back and np.allclose(state.z, plain.z, atol=1e-9)
    assert max(problem.best_response_gaps(state.z[: game.n]).values()) <= 1e-5


def test_the_interior_phase_begins_at_the_decoupled_plans(monkeypatch: pytest.MonkeyPatch) -> None:
    """From the cars' decoupled plans the interior phase begins at once, without the Newton step first
    (``hybrid.PLANS_INTERIOR``): on ALGAMES's merges that step climbs and is refused, so the solves take the same
    iterates bit for bit with it and without it, and without it no Newton step is tried from the plans."""
    from benchmarks.problems import trajectory

    problems = trajectory.merge_problems(4)
    cfg = load_config(text=problems[0].config_yaml)
    game = compile_game(cfg)
    tried = _candidates(monkeypatch, lambda memory: memory.abandon < np.inf and memory.interior is None)
    runs = {}
    for first in (False, True):
        monkeypatch.setattr(hybrid, "PLANS_INTERIOR", first)
        tried.clear()
        solver = make_solver(cfg, game)
        runs[first] = []
        for p in problems:
            x0 = np.asarray(load_config(text=p.config_yaml).game.x0)
            state = iterate(solver, solver.init(None, x0), on_iterate=lambda s, r=runs[first]: r.append(s.z))
            assert state.status == Status.CONVERGED and state.search.alone > 0  # (from the plans)
        assert sum(tried) == (0 if first else len(problems))
    assert len(runs[True]) == len(runs[False])
    assert all(np.array_equal(a, b) for a, b in zip(runs[True], runs[False], strict=True))


def test_the_interior_phase_begins_at_a_cold_start_near_stationary(monkeypatch: pytest.MonkeyPatch) -> None:
    """ALGAMES's intersections from the configured start values (zero inputs, ||Phi(z^0)|| <= QUICK_BELOW): the
    interior phase begins at once (``hybrid.QUICK_INTERIOR``). The Newton step from there climbs and is refused, so
    the solves take the same iterates bit for bit with it and without it, and without it no Newton step is tried from
    z^0. A start handed to the solver that is not the start values (an equilibrium with its decisions moved by 1e-2)
    keeps its Newton step, which converges from there in a few iterations."""
    from benchmarks.problems import trajectory

    problems = trajectory.intersection_problems(3)
    cfg = load_config(text=problems[0].config_yaml)
    game = compile_game(cfg)
    # a Newton step tried from z^0
    tried = _candidates(monkeypatch, lambda memory: len(memory.merits) == 1 and memory.interior is None)
    runs: dict[bool, list[np.ndarray]] = {}
    solutions = []
    for leap in (False, True):
        monkeypatch.setattr(hybrid, "QUICK_INTERIOR", leap)
        tried.clear()
        solver = make_solver(cfg, game)
        runs[leap] = []
        for p in problems:
            x0 = np.asarray(load_config(text=p.config_yaml).game.x0)
            start = solver.init(None, x0)
            assert start.search.quick and start.search.leap == leap
            state = iterate(solver, start, on_iterate=lambda s, r=runs[leap]: r.append(s.z))
            assert state.status == Status.CONVERGED
            solutions.append((x0, state.z))
        assert sum(tried) == (0 if leap else len(problems))
    assert len(runs[True]) == len(runs[False])
    assert all(np.array_equal(a, b) for a, b in zip(runs[True], runs[False], strict=True))
    rng = np.random.default_rng(0)
    solver = make_solver(cfg, game)
    for x0, z in solutions[len(problems):]:
        moved = z.copy()
        moved[:game.n] += 1e-2 * rng.standard_normal(game.n)
        tried.clear()
        start = solver.init(moved, x0)
        assert start.search.quick and not start.search.leap  # near stationary, but not the start values
        state = iterate(solver, start)
        assert tried[:1] == [True]  # the Newton step first
        assert state.status == Status.CONVERGED and state.k <= 5, state.k


def _candidates(monkeypatch: pytest.MonkeyPatch, which) -> list[bool]:
    """Records ``which(memory)`` at every Newton step the hybrid method tries (``HybridNewton._candidate``)."""
    tried: list[bool] = []
    candidate = hybrid.HybridNewton._candidate

    def recorded(self, state, memory):
        tried.append(which(memory))
        return candidate(self, state, memory)

    monkeypatch.setattr(hybrid.HybridNewton, "_candidate", recorded)
    return tried


def _through(state) -> int:
    """Iterations counted through the decoupled game's solve (its own iterations inside the first)."""
    return state.k + max(state.search.alone - 1, 0)


def test_the_barrier_from_the_decoupled_plans_shrinks_faster(monkeypatch: pytest.MonkeyPatch) -> None:
    """ALGAMES's merge, draw 4 of seed 0: the decoupled game's own solve and the interior phase from its plans take
    the faster barrier (eps shrinks once H_eps is solved to KAPPA_PLANS eps instead of KAPPA eps). Counted through the
    decoupled solve the merge takes fewer iterations than at the usual pace, and reaches the same equilibrium."""
    problem, cfg, game, solver = _merge_draw(4)
    paces: list[float] = []
    measure = interior_point.InteriorPoint.measure

    def measured(self, *args, **kwargs):
        it = measure(self, *args, **kwargs)
        paces.append(it.kappa)
        return it

    monkeypatch.setattr(interior_point.InteriorPoint, "measure", measured)
    states: list = []
    state = iterate(solver, solver.init(), on_iterate=states.append)
    assert state.status == Status.CONVERGED and state.search.alone > 1
    assert paces and set(paces) == {interior_point.KAPPA_PLANS}  # the decoupled solve's steps and those after it
    assert all(s.search.abandon < np.inf for s in states[1:])  # the plans kept: z^0 from them to the end
    monkeypatch.setattr(interior_point, "KAPPA_PLANS", interior_point.KAPPA)
    usual_solver = make_solver(cfg, game)
    usual = iterate(usual_solver, usual_solver.init())
    assert usual.status == Status.CONVERGED and _through(state) < _through(usual), (_through(state), _through(usual))
    assert np.allclose(state.z[:game.n], usual.z[:game.n], atol=1e-8)
    assert max(problem.best_response_gaps(state.z[: game.n]).values()) <= 1e-5


def test_the_configured_start_takes_over_after_three_stalled_steps_from_the_plans(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The overtaking game from "car 1 brakes": from the cars' plans alone (the faster car driving through the slower
    one) the interior phase makes no progress; after FAST_STALL steps without a new best ||Phi||, not STALL, the
    configured start takes over, at the usual barrier's pace."""
    from benchmarks.problems import trajectory

    problem = next(p for p in trajectory.overtaking_problems() if "brakes" in p.start)
    cfg = load_config(text=problem.config_yaml)
    game = compile_game(cfg)
    backs, fast_stall = [], hybrid.FAST_STALL
    for stall in (fast_stall, hybrid.STALL):
        monkeypatch.setattr(hybrid, "FAST_STALL", stall)
        solver = make_solver(cfg, game)
        start = solver.init()
        states: list = []
        state = iterate(solver, start, on_iterate=states.append)
        assert state.status == Status.CONVERGED
        back = next(k for k, s in enumerate(states) if k > 1 and np.array_equal(s.z, start.z))
        after = [s.search.interior.kappa for s in states[back:] if s.search.phase == "interior"]
        assert after and set(after) == {interior_point.KAPPA}
        backs.append(back)
    assert backs[0] == 2 + fast_stall < backs[1], backs  # the plans at k = 1, their interior phase from k = 2


def test_a_start_near_stationary_begins_its_interior_phase_at_the_faster_barrier(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """ALGAMES's T-intersection, draw 0 of seed 0, from zero inputs (||Phi(z^0)|| about 0.5, below QUICK_BELOW): the
    first interior start takes the faster barrier (KAPPA_PLANS) and converges in fewer iterations than at the usual
    pace, to the same equilibrium; a closed loop's warm start keeps the usual pace."""
    from benchmarks.problems import trajectory

    problem = trajectory.intersection_problems(1)[0]
    cfg = load_config(text=problem.config_yaml)
    game = compile_game(cfg)
    solver = make_solver(cfg, game)
    start = solver.init()
    assert start.residual_norm <= hybrid.QUICK_BELOW and start.search.quick and not start.search.decouple
    assert not solver.init(warm=True).search.quick
    states: list = []
    state = iterate(solver, start, on_iterate=states.append)
    interior = [s for s in states if s.search.phase == "interior"]
    assert interior and all(s.search.fast and s.search.interior.kappa == interior_point.KAPPA_PLANS for s in interior)
    monkeypatch.setattr(hybrid, "QUICK_BELOW", -1.0)
    usual_solver = make_solver(cfg, game)
    usual = iterate(usual_solver, usual_solver.init())
    assert state.status == usual.status == Status.CONVERGED and state.k < usual.k, (state.k, usual.k)
    assert np.allclose(state.z[:game.n], usual.z[:game.n], atol=1e-8)
    assert max(problem.best_response_gaps(state.z[: game.n]).values()) <= 1e-5


def test_a_first_start_that_stalls_at_the_faster_barrier_begins_again_at_the_usual_pace() -> None:
    """The overtaking game from zero inputs (||Phi(z^0)|| 0.03): at the faster barrier the first interior start stalls;
    after FAST_STALL steps without a new best ||Phi|| the same start is taken again at the usual pace, and the solve
    converges to an equilibrium."""
    from benchmarks.problems import trajectory

    problem = next(p for p in trajectory.overtaking_problems() if "zero inputs" in p.start)
    cfg = load_config(text=problem.config_yaml)
    game = compile_game(cfg)
    solver = make_solver(cfg, game)
    states: list = []
    state = iterate(solver, solver.init(), on_iterate=states.append)
    fast = [k for k, s in enumerate(states) if s.search.phase == "interior" and s.search.fast]
    usual = [k for k, s in enumerate(states) if s.search.phase == "interior" and not s.search.fast]
    assert fast and usual and max(fast) < min(usual)
    again = states[min(usual)]
    assert again.search.attempt == 0 and again.search.interior.kappa == interior_point.KAPPA
    assert state.status == Status.CONVERGED
    assert max(problem.best_response_gaps(state.z[: game.n]).values()) <= 1e-5


def test_the_decoupled_plans_are_only_a_cold_start_of_a_trajectory_game_far_from_stationary() -> None:
    """Not for a closed loop's warm start, nor where ||Phi(z^0)|| <= DECOUPLE_ABOVE (ALGAMES's intersection from zero
    inputs), nor for static games (FK A.2); the rows that couple the players are those two players' decisions reach,
    as the structural nonzeros of dc/da say (found without building dc/da)."""
    from benchmarks.problems import trajectory

    _, cfg, game, solver = _merge_draw(0)
    assert solver.init().search.decouple and not solver.init(warm=True).search.decouple
    assert "_derivatives" not in game.__dict__  # the sparse formulation's solver built no condensed derivatives
    joint = game.pattern.joint_rows
    owner = np.zeros(game.n, dtype=int)
    for i, sl in enumerate(game.agent_slices):
        owner[sl] = i
    rows, cols = game.pattern.constraint_nonzeros()
    reached = np.zeros((len(game.agent_slices), game.m), dtype=bool)
    reached[owner[cols], rows] = True
    assert joint.any() and np.array_equal(joint, reached.sum(axis=0) > 1)
    cfg = load_config(text=trajectory.intersection_problems(1)[0].config_yaml)
    game = compile_game(cfg)
    start = make_solver(cfg, game).init()
    assert start.residual_norm < hybrid.DECOUPLE_ABOVE and not start.search.decouple
    cfg = load_config(text=_fk("A.2", "x0 = 1").config_yaml)
    assert not make_solver(cfg, compile_game(cfg)).init().search.decouple



def test_a_method_without_rows_solves_the_game_without_them() -> None:
    """KKTSystem.without_rows: the globalized method with player 1's coupled row x1^2 + x2^2 <= r^2 left out (its
    multiplier held at zero, its complementarity not in Phi) ends where the same game written without that row ends,
    and away from the game's own solution, where the row is active."""
    text = (CONFIGS / "nonlinear_gne.yaml").read_text()
    cfg = load_config(text=text)
    game = compile_game(cfg)
    joint = game.pattern.joint_rows
    assert joint.sum() == 1
    newton = make_solver(cfg, game).newton
    alone = hybrid.HybridNewton(newton.without_rows(joint))
    left_out = iterate(alone, alone.init())
    free_cfg = load_config(text=text.replace('      constraints: ["x1**2 + x2**2 <= r**2"]\n', ""))
    free_game = compile_game(free_cfg)
    assert free_game.m == game.m - 1
    free = iterate(make_solver(free_cfg, free_game), make_solver(free_cfg, free_game).init())
    full = solve(cfg)
    assert left_out.converged and free.converged and full.status == "converged"
    assert np.allclose(left_out.z[: game.n], free.z[: game.n], atol=1e-9)
    assert np.all(left_out.z[game.n:][joint] == 0.0)
    assert np.abs(full.a - free.z[: game.n]).max() > 1e-3


def test_a_newton_step_kept_on_its_result_makes_no_condition_estimate() -> None:
    """The Newton phase's steps on a nonlinear game's sparse system: a step that halves ||Phi|| and moves z by little
    (hybrid._taken) is kept without the estimate (rcond NaN), with the iterate the estimated step makes; any other
    is estimated, with the number the eager estimate gives, and refused as singular below solver.min_rcond."""
    problem, cfg, game, solver = _merge_draw(0)
    states: list = []
    iterate(solver, solver.init(None, np.asarray(cfg.game.x0)), on_iterate=states.append)
    state = next(s for s in states if s.search.phase == "newton" and 1e-9 < s.residual_norm < 1e-2)
    newton = solver.newton
    z, rcond = newton.newton_point(state)
    assert z is not None and rcond >= cfg.solver.min_rcond
    eager = newton.iteration(state)
    kept = newton.iteration(state, taken=hybrid._taken)
    assert hybrid._taken(state, kept) and np.isnan(kept.rcond)
    np.testing.assert_array_equal(kept.z, eager.z)
    assert newton.iteration(state, taken=lambda s, new: False).rcond == rcond
    # refused on its result: judged by the estimate, as a step without the rule is
    assert not hybrid._taken(state, replace(kept, residual_norm=0.6 * state.residual_norm))
    long = kept.z.copy()
    long[0] = state.z[0] + 2.0 * max(np.abs(state.z).max(), 1.0)
    assert not hybrid._taken(state, replace(kept, z=long))
    strict = make_solver(cfg.model_copy(update={"solver": cfg.solver.model_copy(update={"min_rcond": 2 * rcond})}),
                         game).newton
    assert strict.iteration(state, taken=lambda s, new: False).status == Status.SINGULAR_JACOBIAN
    assert strict.iteration(state, taken=hybrid._taken).status == Status.RUNNING
    assert strict.step(state).status == Status.SINGULAR_JACOBIAN  # the plain method estimates every step


def test_a_hand_over_kept_on_its_result_makes_no_condition_estimate() -> None:
    """The hand-over from the interior phase follows the same rule: its Newton points, judged on the residual, are
    estimated where refused and kept without the estimate where they halve ||Phi|| with a short step; the point kept
    is the estimated one (draw 0: the interior guess and its first correction refused, the second kept)."""
    problem, cfg, game, solver = _merge_draw(0)
    calls: list = []
    judged = solver._judged_point

    def recorded(state, active):
        out = judged(state, active)
        calls.append((state, active, out))
        return out

    solver._judged_point = recorded
    solved = iterate(solver, solver.init(None, np.asarray(cfg.game.x0)))
    assert solved.status == Status.CONVERGED
    *refused, (state, active, kept) = calls
    assert refused and all(not out[2] and out[1] >= cfg.solver.min_rcond for _, _, out in refused)
    z, left_out, halved, candidate, _ = kept
    assert halved and np.isnan(left_out) and np.isnan(candidate.rcond)
    z_eager, rcond = solver.newton.newton_point(replace(state, active=active))
    np.testing.assert_array_equal(z, z_eager)
    strict = make_solver(cfg.model_copy(update={"solver": cfg.solver.model_copy(update={"min_rcond": 2 * rcond})}),
                         game)
    assert strict.newton.newton_point(replace(state, active=active))[0] is None  # estimated: singular
    assert strict._judged_point(state, active)[0] is not None


# Costs undefined at their bound (x log x and log x at x = 0), from the start values 0 that a bound of 0 suggests.
AT_THE_DOMAINS_EDGE = """
name: domain-edge
game:
  kind: static
  agents:
    - name: p1
      variables: {x1: {lower: 0, upper: 1}}
      cost: "x1*log(x1) - 0.5*x1*x2"
    - name: p2
      variables: {x2: {lower: 0, upper: 5}}
      cost: "-log(x2) + 0.5*x2 + 0.1*x1*x2"
"""


def test_a_start_outside_the_costs_domain_is_pushed_into_the_bounds() -> None:
    """Phi is not finite at the start (0 log 0, -log 0): the local method stops there, the default starts its decisions
    1e-2 inside their bounds (IPOPT's bound push) and solves the game. The equilibrium from the first-order conditions
    (interior): log x1 + 1 = x2 / 2 and 1 / x2 = 0.5 + 0.1 x1 (x1 = 0.864), certified."""
    cfg = load_config(text=AT_THE_DOMAINS_EDGE)
    game = compile_game(cfg)
    local = make_solver(cfg.model_copy(update={"solver": cfg.solver.model_copy(update={"globalization": "none"})}),
                        game).init(None, None)
    assert local.status == Status.NAN and "Phi(z^0) is not finite" in local.message
    default = make_solver(cfg, game)
    first = default.init(None, None)
    np.testing.assert_array_equal(first.z[: game.n], [0.01, 0.01])  # 1e-2 of max(1, |bound|), at most of the width
    res = solve(cfg)
    assert res.status == "converged"
    x1, x2 = res.solution["p1"]["x1"], res.solution["p2"]["x2"]
    assert 0.8 < x1 < 0.9 and np.log(x1) + 1.0 == pytest.approx(0.5 * x2, abs=1e-10)  # ||Phi|| <= tol
    assert 1.0 / x2 == pytest.approx(0.5 + 0.1 * x1, abs=1e-10)


def test_a_cost_undefined_everywhere_is_still_nan() -> None:
    text = AT_THE_DOMAINS_EDGE.replace("x1*log(x1) - 0.5*x1*x2", "sqrt(-1 - x1**2) + x1*x2")
    res = solve(load_config(text=text))
    assert res.status == "nan" and "Phi(z^0) is not finite" in res.message
