"""Agent-distributed proximal response: same equilibria as the centralised methods, Study 3, isolation."""

from __future__ import annotations

import numpy as np
import pytest

from gnerun.errors import InputError
from gnerun.game.compile import agent_problem, compile_agent_problem, compile_game
from gnerun.language.config import load_config
from gnerun.runs.closed_loop import simulate
from gnerun.runs.solving import make_solver, solve

from .conftest import CONFIGS

STUDY3 = CONFIGS / "paper_study3.yaml"


@pytest.mark.parametrize("scheme, inner", [("jacobi", "jn"), ("gauss_seidel", "jn"), ("gauss_seidel", "ssn")])
def test_distributed_cournot_equals_the_centralised_equilibrium(scheme: str, inner: str) -> None:
    central = solve(load_config(CONFIGS / "cournot_mss.yaml"))
    dist = solve(load_config(CONFIGS / "cournot_mss.yaml", {
        "solver.kind": "distributed", "solver.scheme": scheme, "solver.inner": inner, "solver.tau": 0.0,
        "solver.tol": 1e-10, "solver.max_iter": 100}))
    assert dist.status == "converged", dist.message
    np.testing.assert_allclose(dist.a, central.a, atol=1e-8)


@pytest.mark.parametrize("scheme, rounds", [("gauss_seidel", 60), ("jacobi", 400)])
def test_distributed_study3_equals_the_centralised_gne(scheme: str, rounds: int) -> None:
    central = solve(load_config(CONFIGS / "paper_study1.yaml"))
    dist = solve(load_config(STUDY3, {"solver.scheme": scheme, "solver.max_iter": rounds}))
    assert dist.status == "converged", dist.message
    np.testing.assert_allclose(dist.z, central.z, atol=1e-9)  # decisions and every agent's multipliers


def test_study3_per_agent_errors_vanish_faster_with_more_rounds() -> None:
    sim = simulate(load_config(STUDY3))
    assert sorted(sim) == [2, 5]
    settle = {}
    for K, r in sim.items():
        assert not any(s in ("singular_jacobian", "diverged", "nan", "subproblem_failed") for s in r.status)
        for agent, e in r.e_norm_agent.items():
            assert e[0] > 1e-4, agent  # the first sampling time starts far from z*
            assert np.all(e[-10:] <= 1e-9), (K, agent, e[-10:])  # e_i(t) -> 0
        worst = np.max(np.vstack(list(r.e_norm_agent.values())), axis=0)
        settle[K] = int(np.argmax(worst <= 1e-8))
        assert worst[settle[K]] <= 1e-8
    assert settle[5] < settle[2]
    assert np.sum(sim[5].e_norm[:5]) < 0.1 * np.sum(sim[2].e_norm[:5])


def test_an_agent_computes_with_its_own_cost_and_constraints_only() -> None:
    # change everything that belongs to agents 2 and 3: agent 1's proximal problem must not change at all,
    # even where the others' costs are undefined (NaN everywhere)
    cfg = load_config(STUDY3)
    other = load_config(STUDY3, {
        "game.agents.1.stage_cost": "sqrt(-1 - x2**2)",
        "game.agents.1.constraints": ["u2 <= -7"],
        "game.agents.2.stage_cost": "exp(u3) * x1",
        "game.agents.2.constraints": ["u3 == u1"],
    })
    mine = compile_agent_problem(cfg, 0, 0.3)
    theirs = compile_agent_problem(other, 0, 0.3)
    game = compile_game(cfg)
    taken = agent_problem(compile_game(other), 0, 0.3)  # from the other game's expressions, as the solvers build it
    assert mine.n == game.agent_slices[0].stop  # its own inputs only
    assert mine.nx == game.nx + game.n  # parameters: the plant state, the others' decisions, its own centre
    assert mine.m == game.multiplier_slices[0].stop - game.multiplier_slices[0].start
    rng = np.random.default_rng(0)
    for _ in range(5):
        z = rng.standard_normal(mine.size)
        p = rng.standard_normal(mine.nx)
        a, b, c = mine.kkt_parts(z, p), theirs.kkt_parts(z, p), taken.kkt_parts(z, p)
        for field in ("L", "c", "dL_dz", "dc_da"):
            np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
            np.testing.assert_array_equal(getattr(a, field), getattr(c, field))
            assert np.all(np.isfinite(getattr(a, field)))
    # and the proximal term is the only addition to its own cost: tau enters the Hessian as tau * I
    plain = compile_agent_problem(cfg, 0, 0.0)
    z = rng.standard_normal(mine.size)
    p = rng.standard_normal(mine.nx)
    diff = mine.kkt_parts(z, p).dL_dz[:, : mine.n] - plain.kkt_parts(z, p).dL_dz[:, : mine.n]
    np.testing.assert_allclose(diff, 0.3 * np.eye(mine.n), atol=1e-12)


@pytest.mark.parametrize("name", ["fk_a01.yaml", "variational_gne.yaml", "formation_ring.yaml", "moving_obstacle.yaml",
                                  "paper_study3.yaml"])
def test_an_agent_problem_from_the_games_expressions_is_the_one_compiled_from_the_config(name: str) -> None:
    # static and dynamic, generalized and variational (shared rows carried: stage by stage after the agent's own),
    # runtime parameters (moving_obstacle): the same rows in the same order, the same values to the bit
    cfg = load_config(CONFIGS / name)
    game = compile_game(cfg)
    rng = np.random.default_rng(1)
    for agent in (0, len(game.agent_names) - 1):
        for tau in (0.0, 0.7):
            old, new = compile_agent_problem(cfg, agent, tau), agent_problem(game, agent, tau)
            assert new.constraints == old.constraints
            assert new.agent_names == old.agent_names and new.variable_names == old.variable_names
            for field in ("a_start", "a_lower", "a_upper", "x0"):
                np.testing.assert_array_equal(getattr(new, field), getattr(old, field))
            for _ in range(3):
                z, p = rng.standard_normal(old.size), rng.standard_normal(old.nx)
                np.testing.assert_array_equal(new.costs(z[: old.n], p), old.costs(z[: old.n], p))
                a, b = old.kkt_parts(z, p), new.kkt_parts(z, p)
                for field in ("L", "c", "dL_dz", "dc_da"):
                    np.testing.assert_array_equal(getattr(b, field), getattr(a, field))
    with pytest.raises(ValueError, match="smoothing"):
        agent_problem(compile_game(cfg, smoothing=0.1), 0, 0.0)


def test_the_round_hands_each_agent_only_the_others_last_decisions() -> None:
    cfg = load_config(STUDY3, {"solver.scheme": "jacobi"})
    game = compile_game(cfg)
    solver = make_solver(cfg, game)
    seen = []
    for agent in solver.agents:
        original = agent.respond

        def spy(x, others, own, multipliers, _original=original, _name=agent.name):
            seen.append((_name, others.copy(), own.copy()))
            return _original(x, others, own, multipliers)

        agent.respond = spy
    state = solver.init()
    a0 = state.z[: game.n].copy()
    solver.step(state)
    assert [name for name, _, _ in seen] == game.agent_names
    for (_, others, own), sl in zip(seen, game.agent_slices, strict=True):
        np.testing.assert_array_equal(own, a0[sl])
        np.testing.assert_array_equal(others, np.delete(a0, np.arange(sl.start, sl.stop)))


def test_distributed_refuses_what_it_cannot_do() -> None:
    with pytest.raises(InputError, match="variational"):
        solve(load_config(CONFIGS / "fk_a11.yaml", {"solver.kind": "distributed"}))
    with pytest.raises(InputError, match="disturbance"):
        solve(load_config(STUDY3, {"disturbance.kind": "jacobian_noise", "disturbance.scale": 1e-3}))


# Two players: each agent's "others" is one scalar. A Cournot duopoly with inverse demand 10 - (q1 + q2) and unit
# costs c_i has the closed-form equilibrium q_i = (10 - 2 c_i + c_j) / 3: (10/3, 7/3) for c = (1, 2).
DUOPOLY = """
name: duopoly
game:
  kind: static
  agents:
    - name: firm1
      variables: {q1: {lower: 0, upper: 10, start: 0}}
      cost: "-(10 - q1 - q2)*q1 + 1*q1"
    - name: firm2
      variables: {q2: {lower: 0, upper: 10, start: 0}}
      cost: "-(10 - q1 - q2)*q2 + 2*q2"
solver: {kind: distributed, tol: 1.0e-11, max_iter: 200}
"""


@pytest.mark.parametrize("scheme", ["jacobi", "gauss_seidel"])
@pytest.mark.parametrize("inner", ["ssn", "jn"])
def test_two_player_distributed_games_reach_the_closed_form_equilibrium(scheme: str, inner: str) -> None:
    cfg = load_config(text=DUOPOLY, overrides={"solver.scheme": scheme, "solver.inner": inner})
    res = solve(cfg)
    assert res.status == "converged", res.message
    np.testing.assert_allclose(res.a, [10 / 3, 7 / 3], atol=1e-9)
    a12 = solve(load_config(CONFIGS / "fk_a12.yaml", {"solver.kind": "distributed", "solver.scheme": scheme,
                                                        "solver.inner": inner, "solver.max_iter": 200}))
    assert a12.status == "converged", a12.message
    np.testing.assert_allclose(a12.a, [16 / 3, 16 / 3], atol=1e-9)


def test_a_two_player_agent_problem_sees_the_other_player() -> None:
    # agent 1's proximal problem with the other's decision as a parameter: its cost at (q1; q2) is firm 1's cost
    cfg = load_config(text=DUOPOLY)
    problem = compile_agent_problem(cfg, 0, 0.0)
    assert problem.n == 1
    for q1, q2 in [(1.0, 2.0), (3.0, 0.5)]:
        p = np.array([q2, q1])  # (x: none, others: q2, centre: q1)
        assert problem.costs(np.array([q1]), p)[0] == pytest.approx(-(10 - q1 - q2) * q1 + q1)
