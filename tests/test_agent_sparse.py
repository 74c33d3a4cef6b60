"""A player's best response through the game's sparse system (gnerun.game.sparse.AgentSparseKKT): the certificate of
a game solved in the sparse formulation solves each player's problem as a part of the game's own system instead of
building the player's dense derivatives. Checked against the player's own (condensed) problem."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gnerun.game.compile import compile_agent_problem, compile_game
from gnerun.game.sparse import AgentSparseKKT, sparse_system
from gnerun.language.config import load_config
from gnerun.solvers.certificate import NewtonResponses
from gnerun.solvers.driver import iterate
from gnerun.solvers.factory import make_solver
from gnerun.solvers.status import Status

ROOT = Path(__file__).resolve().parents[1]


def _sparse(name: str, **overrides):
    cfg = load_config(ROOT / "configs" / f"{name}.yaml", {"solver.formulation": "sparse", **overrides})
    game = compile_game(cfg)
    sparse_system(cfg, game)
    return cfg, game


@pytest.mark.parametrize("name", ["algames_intersection", "formation_ring", "vehicles"])
def test_the_part_of_the_system_is_the_players_problem(name):
    """L_i and c_i of the part equal the player's own problem's (condensed) residual at random points, whatever the
    others' decisions; the generalized games' shared rows and the variational ring's common rows alike."""
    cfg, game = _sparse(name)
    rng = np.random.default_rng(2)
    for agent in range(len(game.agent_names)):
        problem = compile_agent_problem(cfg, agent, 0.0)
        rows = game.agents.constraint_rows(agent)
        labels = [game.constraints[r].label for r in rows]
        order = [labels.index(c.label) for c in problem.constraints]  # unique labels in these games
        view = AgentSparseKKT(game.derived["sparse"], problem, agent, rows[order])
        sl = game.agent_slices[agent]
        for _ in range(2):
            a = game.z_start()[:game.n] + 0.3 * rng.standard_normal(game.n)
            z = np.concatenate([a[sl], rng.random(problem.m)])
            p = np.concatenate([game._x(None), a[:sl.start], a[sl.stop:], a[sl]])
            L, c = problem.kkt_residual(z, p)
            Lv, cv = view.residual(z, p)
            assert np.allclose(Lv, L, rtol=1e-10, atol=1e-10) and np.allclose(cv, c, rtol=1e-12, atol=1e-12)
            parts = view.evaluate(z, p)
            assert np.allclose(parts.L, L, rtol=1e-10, atol=1e-10)
            assert view.matrix(parts.J).shape == (view.size, view.size)


def test_the_best_responses_are_those_of_the_players_own_problem():
    """The certificate's local solves from the same starts end at the same points through the game's system as
    through the player's dense problem."""
    cfg, game = _sparse("algames_intersection")
    solver = make_solver(cfg, game)
    state = iterate(solver, solver.init())
    assert state.status == Status.CONVERGED
    a = state.z[:game.n]  # the equilibrium: each player's best response is near its part of it
    rng = np.random.default_rng(0)
    sparse_way = NewtonResponses(cfg, game)
    game2 = compile_game(cfg)  # no sparse system: the player's own condensed problem
    dense_way = NewtonResponses(cfg, game2)
    for agent in range(len(game.agent_names)):
        sl = game.agent_slices[agent]
        starts = [a[sl] + 0.05 * rng.standard_normal(sl.stop - sl.start) for _ in range(2)]
        assert "sparse" in game.derived and "sparse" not in game2.derived
        ends_s = sparse_way.solve_from(agent, a, None, starts)
        ends_d = dense_way.solve_from(agent, a, None, starts)
        assert type(sparse_way._solver(agent)[1].newton).__name__ == "SparseSemismoothNewton"
        for (es, cs), (ed, cd) in zip(ends_s, ends_d, strict=True):
            assert cs and cd
            assert np.max(np.abs(es - a[sl])) <= 1e-6  # an equilibrium: nobody moves
            assert np.max(np.abs(es - ed)) <= 1e-7 * max(1.0, np.max(np.abs(ed)))


def test_a_players_part_is_banded_in_the_games_stages_and_its_solver_is_kept_per_game():
    """The agent's problem is compiled as a static game (one stage), but its part of the game's system keeps the
    game's stages: ordered by them, its matrix is banded (an intersection car: a band of a few dozen, not the width
    of the matrix), so its solves take banded LU. A second certificate on the same game (another candidate, as in a
    Monte Carlo or a closed loop) reuses each player's problem, system and solver."""
    cfg, game = _sparse("algames_intersection")
    first = NewtonResponses(cfg, game)
    second = NewtonResponses(cfg, game)
    for agent in range(len(game.agent_names)):
        problem, solver, _ = first._solver(agent)
        system = solver.newton.system
        assert system.stages == game.derived["sparse"].stages == game.horizon + 1
        order = system.stage_order
        assert order.lower + order.upper + 1 <= 0.25 * system.size, (order.lower, order.upper, system.size)
        assert second._solver(agent)[1] is solver and second._solver(agent)[0] is problem
