"""A round of best responses (gnerun/solvers/response_round.py): each player's answer against closed forms, the round's
Jacobi order, and its place in the globalized method (once: after the first interior start from z^0 stalls, answering
the plans where it stalled; else after every interior start from z^0 has failed, answering the start plans)."""

from __future__ import annotations

import numpy as np
import pytest

import gnerun
from benchmarks.problems.trajectory import merge_problems, overtaking_model, overtaking_problems
from gnerun.game.compile import compile_game
from gnerun.language.config import load_config
from gnerun.runs.solving import iterate, make_solver
from gnerun.solvers import hybrid, interior_point, response_round
from gnerun.solvers.response_round import answer_starts, best_answer

from .conftest import CONFIGS

# p1: min (x1 - 2 x2)^2 + x1, so x1 = 2 x2 - 1/2 unless x1 + x2 <= 1 stops it; p2: min (x2 - x1/2 - 1/4)^2, so
# x2 = x1/2 + 1/4 unless the bound or the shared row stops it
STATIC = """
name: answers
game:
  kind: static
  agents:
    - name: p1
      variables: {x1: {lower: -5, upper: 5, start: 0}}
      cost: "(x1 - 2*x2)**2 + x1"
    - name: p2
      variables: {x2: {lower: -1, upper: 1, start: 0.9}}
      cost: "(x2 - 0.5*x1 - 0.25)**2"
  shared_constraints: ["x1 + x2 <= 1"]
  equilibrium: variational
"""


ONE = """
name: one
game:
  kind: static
  agents:
    - name: p1
      variables: {x1: {lower: -5, upper: 5, start: 0}}
      cost: "(x1 - 0.6)**2 + x1"
"""


@pytest.fixture(scope="module")
def static():
    return compile_game(load_config(text=STATIC))


@pytest.mark.parametrize(("x2", "x1"), [(0.3, 0.1), (0.9, 0.1), (-0.2, -0.9)])
def test_an_answer_is_the_closed_form_best_response(static, x2: float, x1: float) -> None:
    """x2 = 0.3: the unconstrained minimiser 2 x2 - 1/2 = 0.1; x2 = 0.9: 1.3 is cut to 1 - x2 = 0.1 by the shared row;
    x2 = -0.2: -0.9."""
    a = np.array([4.0, x2])
    value, decision = best_answer(static, 0, a, None, answer_starts(static, 0, a))
    assert decision == pytest.approx([x1], abs=1e-6)
    assert value == pytest.approx((x1 - 2 * x2) ** 2 + x1, abs=1e-9)


def test_answer_starts_are_the_plan_and_seeded_perturbations_inside_the_bounds(static) -> None:
    a = np.array([4.8, 0.9])
    for agent in (0, 1):
        starts = answer_starts(static, agent, a)
        assert len(starts) == 1 + len(response_round.PERTURBATIONS)
        assert starts[0] == pytest.approx(a[agent:agent + 1])
        assert all(static.a_lower[agent] <= s[0] <= static.a_upper[agent] for s in starts)
        again = answer_starts(static, agent, a)
        assert all(np.array_equal(s, t) for s, t in zip(starts, again, strict=True))  # seeded
    assert len({s[0] for s in answer_starts(static, 0, a)}) == 3  # the perturbations move the plan


def test_a_round_answers_the_start_plans_in_any_order(static) -> None:
    """Jacobi: p2 answers p1's start plan x1 = 0 (x2 = 1/4), not p1's new answer."""
    a = np.array([0.0, 0.9])
    out = response_round.response_round(static, a, None)
    assert out == pytest.approx([0.1, 0.25], abs=1e-6)
    assert a == pytest.approx([0.0, 0.9])  # not changed in place


def test_a_player_without_a_feasible_answer_keeps_its_plan() -> None:
    """p1's own row x1 >= 3 - x2 meets its bound x1 <= 1 only where x2 >= 2, which p2's plan 0 is not."""
    text = STATIC.replace('shared_constraints: ["x1 + x2 <= 1"]', "shared_constraints: []").replace(
        'cost: "(x1 - 2*x2)**2 + x1"', 'cost: "(x1 - 2*x2)**2 + x1"\n      constraints: ["x1 >= 3 - x2"]').replace(
        "lower: -5, upper: 5", "lower: -5, upper: 1")
    game = compile_game(load_config(text=text))
    a = np.array([0.5, 0.0])
    assert best_answer(game, 0, a, None, answer_starts(game, 0, a)) is None
    assert response_round.response_round(game, a, None) == pytest.approx([0.5, 0.5], abs=1e-6)


def test_no_feasible_answer_for_anyone_is_none() -> None:
    text = STATIC.replace('"x1 + x2 <= 1"', '"x1 + x2 <= -7"')
    game = compile_game(load_config(text=text))
    assert response_round.response_round(game, np.array([0.0, 0.9]), None) is None


@pytest.mark.parametrize("config", ["algames_merge.yaml", "nonlinear_gne.yaml"])
def test_a_players_own_problem_is_the_games_functions_restricted_to_it(config: str) -> None:
    """One evaluation of agent i's own problem (what SLSQP reads at every point of a best response) gives the game's
    J_i, its gradient in a_i, the rows of i's feasible set and their Jacobian in a_i (the game's functions, sliced),
    and the gradient and Jacobian match central differences of the values."""
    from gnerun.game.agents import OwnProblem

    game = compile_game(load_config(CONFIGS / config))
    rng = np.random.default_rng(5)
    a = game.z_start()[: game.n] + 0.1 * rng.standard_normal(game.n)
    c_all, dc_all = game.constraint_values(a)
    for agent, sl in enumerate(game.agent_slices):
        rows = game.agents.constraint_rows(agent)
        J, dJ, c, dc = game.agents.own_problem(agent, a)
        assert J == pytest.approx(game.costs(a)[agent], rel=1e-13, abs=1e-13)
        np.testing.assert_allclose(dJ, game.cost_gradients(a)[agent, sl], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(c, c_all[rows], rtol=1e-13, atol=1e-13)
        np.testing.assert_allclose(dc, dc_all[rows][:, sl], rtol=1e-12, atol=1e-12)
        problem = OwnProblem(game, agent, a, None)
        h = 1e-6
        for j in range(min(4, sl.stop - sl.start)):
            e = np.zeros(sl.stop - sl.start)
            e[j] = h
            up, down = problem.at(a[sl] + e), problem.at(a[sl] - e)
            assert (up[0] - down[0]) / (2 * h) == pytest.approx(dJ[j], rel=1e-5, abs=1e-7)
            np.testing.assert_allclose((up[2] - down[2]) / (2 * h), dc[:, j], rtol=1e-5, atol=1e-7)
        assert problem.violation(a[sl]) == pytest.approx(
            max(float(np.max(c[~game.equality_mask[rows]], initial=0.0)),
                float(np.max(np.abs(c[game.equality_mask[rows]]), initial=0.0))))


def _overtaking(start: int = 0):
    # the condensed formulation: the one with the line-search phase (auto takes the sparse one for this game)
    cfg = load_config(text=overtaking_problems()[start].config_yaml, overrides={"solver.formulation": "condensed"})
    game = compile_game(cfg)
    return game, make_solver(cfg, game)


@pytest.fixture
def monotone_barrier(monkeypatch: pytest.MonkeyPatch) -> None:
    """The interior phase with the barrier's monotone target alone (no Mehrotra step in its first start,
    ``interior_point.PREDICT_AFTER``), as these tests were written for: from zero inputs all three of its starts stall
    on the overtaking game, the case the round is for."""
    monkeypatch.setattr(interior_point, "PREDICT_AFTER", np.inf)


def _counted(monkeypatch: pytest.MonkeyPatch, game, answer=None) -> list[np.ndarray]:
    """The plans each round of best responses is asked to answer (``answer``: the round, default the real one)."""
    calls: list[np.ndarray] = []
    answer = answer or hybrid.response_round

    def counted(g, a, x):
        assert g is game
        calls.append(a.copy())
        return answer(g, a, x)

    monkeypatch.setattr(hybrid, "response_round", counted)
    return calls


def test_the_round_answers_the_plans_where_the_first_interior_start_stalled(
        monkeypatch: pytest.MonkeyPatch, monotone_barrier: None) -> None:
    """From zero inputs the first interior start stalls (the cars coincide at a knot, where the collision row has no
    gradient); the round answers the plans where it stalled (not the zero-input start), and the warm interior start
    from the answers converges, to a point both cars' independent numpy best responses confirm, without the other
    starts from z^0. (The line-search phase, which the default tries at iteration SLOW, is set aside here: this is
    the rounds' test.)"""
    monkeypatch.setattr(hybrid, "SLOW", 10**6)
    game, solver = _overtaking()
    calls = _counted(monkeypatch, game)
    states: list = []
    state = iterate(solver, solver.init(), on_iterate=states.append)
    assert len(calls) == 1 and calls[0].any()  # once, answering plans that are not the zero-input start ...
    first = [s for s in states if s.search.attempt == 0 and not s.search.answered]
    assert len(first) > hybrid.STALL  # ... but the first start's after its stall (its last step's plans)
    assert states[len(first)].search.answered and states[len(first)].search.attempt == 0
    assert state.status == "converged", state.message
    assert state.search.answered and state.search.cold == 1 and not state.search.answered_start
    gaps = overtaking_model().best_response_gaps(state.z[: game.n])
    assert max(gaps.values()) <= 1e-6


def test_when_the_answers_to_the_stalled_plans_stall_the_start_plans_are_answered(
        monkeypatch: pytest.MonkeyPatch, monotone_barrier: None) -> None:
    """Answers to the stalled plans that are those plans themselves: the three interior starts from them stall, and
    the second round, the answers to the zero-input plans, starts the solve that converges, to a point both cars'
    independent numpy best responses confirm."""
    monkeypatch.setattr(hybrid, "SLOW", 10**6)
    game, solver = _overtaking()
    real = hybrid.response_round
    calls = _counted(monkeypatch, game, lambda g, a, x: real(g, a, x) if not a.any() else np.array(a, dtype=float))
    state = iterate(solver, solver.init())
    assert len(calls) == 2 and calls[0].any() and not calls[1].any()
    assert state.status == "converged", state.message
    assert state.search.answered_start and state.search.cold == 1
    gaps = overtaking_model().best_response_gaps(state.z[: game.n])
    assert max(gaps.values()) <= 1e-6


def test_an_algames_merge_that_stalls_from_every_start_is_solved_from_the_answers_to_its_stalled_plans() -> None:
    """ALGAMES's merge draw 48 (seed 0), without the cars' decoupled plans as its start: every interior start from
    zero inputs stalls near ||Phi|| = 0.04 (car 3
    between car 1 and the ramp), and cars 1 and 3 collide in the zero-input plans, so no car has a feasible answer to
    them. The answers to the plans where the first start stalled start the solve that converges, certified (the
    solve's own check), and each car's independent numpy best response (SLSQP from three starts) finds nothing
    better."""
    problem = merge_problems(49)[48]
    calls: list[np.ndarray] = []
    real = hybrid.response_round

    def counted(g, a, x):
        calls.append(a.copy())
        return real(g, a, x)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(hybrid, "response_round", counted)
        mp.setattr(hybrid, "DECOUPLE_ABOVE", np.inf)  # from zero inputs, not the cars' decoupled plans
        res = gnerun.solve(load_config(text=problem.config_yaml), out=None)
    assert res.status == "converged", res.message
    assert calls and calls[0].any()  # the first round answers the stalled plans, not the zero inputs
    assert response_round.response_round(compile_game(load_config(text=problem.config_yaml)),
                                         np.zeros(calls[0].size), None) is None
    assert max(res.certificate["best_response_gap"].values()) <= 1e-6
    gaps = problem.best_response_gaps(res.z[: calls[0].size])
    assert max(gaps.values()) <= 1e-6, gaps


def test_without_answers_the_cold_overtaking_start_stalls_and_says_why(monkeypatch: pytest.MonkeyPatch,
                                                                       monotone_barrier: None) -> None:
    """No player ever has an answer: the round is asked twice (the plans where the first start stalled, then the
    start plans after all three starts), and the message says the starts and why."""
    asked: list[np.ndarray] = []
    monkeypatch.setattr(hybrid, "response_round", lambda game, a, x: asked.append(a.copy()))
    monkeypatch.setattr(hybrid, "SLOW", 10**6)
    _, solver = _overtaking()
    state = iterate(solver, solver.init())
    assert state.status == "stalled"
    assert len(asked) == 2 and asked[0].any() and not asked[1].any()
    assert "after 3 start(s): " in state.message, state.message
    assert "no player has a feasible best answer to the others' start plans" in state.message


def test_a_stall_after_the_answers_says_how_many_starts_it_took(monkeypatch: pytest.MonkeyPatch,
                                                                monotone_barrier: None) -> None:
    """Answers that are the plans answered (those where the first start stalled, then the zero-input start): the
    three interior starts from each stall (the line-search phase set aside); the message counts one start from z^0
    and six from the answers."""
    monkeypatch.setattr(hybrid, "response_round", lambda game, a, x: np.array(a, dtype=float))
    monkeypatch.setattr(hybrid, "SLOW", 10**6)
    _, solver = _overtaking()
    state = iterate(solver, solver.init())
    assert state.status == "stalled" and state.search.answered
    assert "after 1 start(s) from z^0 and 6 from the players' best answers" in state.message, state.message


@pytest.mark.parametrize("config", ["paper_study1.yaml", "nonlinear_gne.yaml", "mcp_demo.yaml", "vehicles.yaml"])
def test_games_the_interior_starts_solve_never_ask_for_answers(monkeypatch: pytest.MonkeyPatch, config: str) -> None:
    def refuse(*_):
        raise AssertionError("a round of best responses was asked for")

    monkeypatch.setattr(hybrid, "response_round", refuse)
    cfg = load_config(CONFIGS / config, {"solver.globalization": "auto"})
    game = compile_game(cfg)
    solver = make_solver(cfg, game)
    assert iterate(solver, solver.init()).status == "converged"


def test_one_player_problems_and_the_interior_phase_alone_take_no_round() -> None:
    """A round needs players to answer each other: not for one player (the certificate's and the distributed solver's
    own problems), nor for ``globalization: interior_point``."""
    _, solver = _overtaking()
    assert solver.answers
    assert not hybrid.HybridNewton(solver.newton, handover=False).answers
    one = load_config(text=ONE)
    assert not make_solver(one, compile_game(one)).answers


def test_an_undefined_start_is_no_answer(static) -> None:
    """A start where the cost is not finite gives no answer and raises nothing (failure is a status in the solver)."""
    a = np.array([np.nan, 0.3])
    assert best_answer(static, 0, a, None, [np.array([np.nan])]) is None
    assert best_answer(static, 0, a, None, [np.array([np.nan]), np.array([0.0])])[1] == pytest.approx([0.1], abs=1e-6)


def test_a_failed_line_search_phase_hands_back_to_the_interior_phase(monkeypatch: pytest.MonkeyPatch) -> None:
    """The default from zero inputs, without the round on the plans where the first start stalls (which converges
    before the line-search phase's turn): the line-search phase is tried at iteration SLOW, does not converge within
    its budget on this game, and the interior phase goes on from where it was, to a point both cars' independent
    numpy best responses confirm."""
    real = hybrid.response_round
    monkeypatch.setattr(hybrid, "response_round", lambda g, a, x: real(g, a, x) if not a.any() else None)
    game, solver = _overtaking()
    state = iterate(solver, solver.init())
    assert state.status == "converged", state.message
    assert state.search.searched and state.search.phase != "search" and state.k > hybrid.SLOW
    gaps = overtaking_model().best_response_gaps(state.z[: game.n])
    assert max(gaps.values()) <= 1e-6
