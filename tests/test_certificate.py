"""gnerun.solvers.certificate: best responses, gaps and KKT residuals against closed forms.

References: Facchinei & Kanzow (2010) Examples A.11 (variational GNE (3/4, 1/4), common multiplier 1/2)
and A.12 (NE (16/3, 16/3)), Harker's game (GNE (5, 9), and the segment x1 + x2 = 15, 9 <= x1 <= 10),
whose agents' problems are one-dimensional convex quadratics: the best response is the clipped
stationary point, in closed form. The paper's Study 1 is checked end to end.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from gnerun.game.compile import CompiledGame, compile_game
from gnerun.language.config import load_config
from gnerun.runs.solving import solve
from gnerun.solvers.certificate import best_response, certificate, kkt_residuals

from .conftest import CONFIGS

GAP_TOL = 1e-8
BR_TOL = 1e-7  # SLSQP's decision accuracy on these one-dimensional problems


def _game(name: str, overrides: dict | None = None) -> CompiledGame:
    return compile_game(load_config(CONFIGS / f"{name}.yaml", overrides))


def _z(game: CompiledGame, a, multipliers: dict[tuple[str, int | None], float] | None = None) -> np.ndarray:
    """z = (a, lambda) with lambda given by (label, owner); unnamed multipliers are 0."""
    lam = np.zeros(game.m)
    keys = [(c.label, c.owner) for c in game.constraints]
    for key, value in (multipliers or {}).items():
        lam[keys.index(key)] = value
    return np.r_[np.asarray(a, dtype=float), lam]


# closed-form costs and best responses -------------------------------------------------------------


def a12_cost(i: int, a: np.ndarray) -> float:
    return float(a[i] * (a[0] + a[1] - 16))


def a12_br(other: float) -> float:  # argmin_{-10 <= t <= 10} t (t + other - 16)
    return float(np.clip((16 - other) / 2, -10, 10))


def a11_cost(i: int, a: np.ndarray) -> float:
    return float((a[0] - 1) ** 2) if i == 0 else float((a[1] - 0.5) ** 2)


def a11_br(i: int, other: float) -> float:  # argmin (t - target)^2 s.t. t + other <= 1
    return min(1.0 if i == 0 else 0.5, 1 - other)


def harker_cost(i: int, a: np.ndarray) -> float:
    x1, x2 = a
    return float(x1**2 + 8 / 3 * x1 * x2 - 34 * x1) if i == 0 else float(x2**2 + 5 / 4 * x1 * x2 - 24.25 * x2)


def harker_br(i: int, other: float) -> float:  # clipped stationary point on [0, min(10, 15 - other)]
    stationary = (34 - 8 / 3 * other) / 2 if i == 0 else (24.25 - 5 / 4 * other) / 2
    return float(min(max(stationary, 0.0), 10.0, 15.0 - other))


def _with(a: np.ndarray, i: int, value: float) -> np.ndarray:
    b = np.array(a, dtype=float)
    b[i] = value
    return b


CASES = {  # name: (cost J_i(a), best response of agent i to the other's decision, known equilibrium)
    "fk_a12": (a12_cost, lambda i, other: a12_br(other), (16 / 3, 16 / 3)),
    "fk_a11": (a11_cost, a11_br, (0.75, 0.25)),  # the variational equilibrium
    "harker": (harker_cost, harker_br, (5.0, 9.0)),
}


# --- 1. best responses and gaps ---------------------------------------------------------------------


@pytest.mark.parametrize("name", list(CASES))
@pytest.mark.parametrize("agent", [0, 1])
def test_best_response_has_the_closed_form(name: str, agent: int) -> None:
    cost, br, star = CASES[name]
    game = _game(name)
    # the opponent at the equilibrium and at values that put the best response on each kind of bound
    for other in (star[1 - agent], -10.0, -3.0, 0.0, 2.5, 9.0, 10.0):
        a = np.zeros(2)
        a[1 - agent] = other
        if name == "harker" and not 0 <= other <= 10:
            continue  # the opponent's own bounds; the best response is still defined, but keep to the box
        value, decision, note = best_response(game, agent, a)
        expected = br(agent, other)
        assert note == "ok"
        assert decision.shape == (1,)
        assert decision[0] == pytest.approx(expected, abs=BR_TOL), (name, agent, other)
        assert value == pytest.approx(cost(agent, _with(a, agent, expected)), abs=1e-9)


@pytest.mark.parametrize("name", list(CASES))
def test_gaps_vanish_at_the_known_equilibrium(name: str) -> None:
    cost, br, star = CASES[name]
    game = _game(name)
    a = np.array(star)
    for i in range(2):
        value, decision, note = best_response(game, i, a)
        np.testing.assert_array_equal(a, star)  # the candidate is not modified
        assert note == "ok"
        assert decision[0] == pytest.approx(star[i], abs=BR_TOL)
        assert abs(cost(i, a) - value) <= GAP_TOL
    cert = certificate(game, _z(game, a))
    assert set(cert["best_response_gap"]) == set(game.agent_names)
    assert all(abs(g) <= GAP_TOL for g in cert["best_response_gap"].values())
    assert all(note.startswith("ok") for note in cert["best_response_note"].values())


def game_limit(name: str) -> float:
    """The right-hand side of the shared constraint x1 + x2 <= . (none in A.12)."""
    return {"fk_a12": np.inf, "fk_a11": 1.0, "harker": 15.0}[name]


# (0.9, 0.6) in A.11 and (9, 9) in Harker violate the shared constraint: each agent's best response
# is then feasible and may cost more than the candidate, so a gap can be negative (A.11 there: both).
PERTURBED = {
    "fk_a12": [(0.0, 16 / 3), (9.0, -10.0), (-10.0, 10.0)],
    "fk_a11": [(0.5, 0.25), (0.2, 0.1), (0.9, 0.6)],
    "harker": [(3.0, 9.0), (9.0, 9.0), (0.0, 2.0)],
}


@pytest.mark.parametrize("name", list(CASES))
def test_gaps_away_from_the_equilibrium_equal_the_closed_form(name: str) -> None:
    cost, br, _ = CASES[name]
    game = _game(name)
    for point in PERTURBED[name]:
        a = np.array(point)
        gaps = certificate(game, _z(game, a))["best_response_gap"]
        expected = [cost(i, a) - cost(i, _with(a, i, br(i, a[1 - i]))) for i in range(2)]
        assert max(np.abs(expected)) > 0.1  # the points are not equilibria
        if point[0] + point[1] <= game_limit(name):  # at a feasible candidate no gap is negative
            assert min(expected) >= 0 and max(expected) > 0.1
        for i, agent_name in enumerate(game.agent_names):
            assert gaps[agent_name] == pytest.approx(expected[i], abs=1e-8), (name, point, agent_name)


def test_harker_gaps_vanish_along_its_segment_of_equilibria() -> None:
    # x1 + x2 = 15 with 9 <= x1 <= 10: both agents are blocked by the shared constraint
    game = _game("harker")
    for x1 in (9.0, 9.5, 10.0):
        gaps = certificate(game, _z(game, [x1, 15 - x1]))["best_response_gap"]
        assert all(abs(g) <= GAP_TOL for g in gaps.values()), (x1, gaps)


def test_generalized_a11_segment_is_an_equilibrium_but_off_it_is_not() -> None:
    game = _game("fk_a11", {"game.equilibrium": "generalized"})
    gaps = certificate(game, _z(game, [0.6, 0.4]))["best_response_gap"]  # on x1 + x2 = 1, 1/2 <= x1 <= 1
    assert all(abs(g) <= GAP_TOL for g in gaps.values())
    gaps = certificate(game, _z(game, [0.3, 0.7]))["best_response_gap"]  # x1 < 1/2: agent 2 would lower x2
    assert gaps["p1"] == pytest.approx(0.0, abs=GAP_TOL)
    assert gaps["p2"] == pytest.approx(0.2**2, abs=1e-9)  # (0.7 - 0.5)^2 - 0


def test_best_response_accepts_an_integer_candidate() -> None:
    game = _game("fk_a12")
    value, decision, _ = best_response(game, 0, np.array([0, 5]))  # best response to x2 = 5 is 11/2
    assert decision[0] == pytest.approx(5.5, abs=BR_TOL)
    assert value == pytest.approx(-30.25, abs=1e-9)


# --- 2. KKT residuals -------------------------------------------------------------------------------


def test_kkt_residual_vanishes_at_known_primal_dual_solutions() -> None:
    cases = [
        (_game("fk_a12"), [16 / 3, 16 / 3], {}),  # interior NE, all multipliers 0
        (_game("fk_a11"), [0.75, 0.25], {("x1 + x2 <= 1", None): 0.5}),  # variational: common multiplier 1/2
        # generalized A.11 at (0.6, 0.4): lambda_1 = -2(x1 - 1) = 0.8, lambda_2 = -2(x2 - 1/2) = 0.2
        (_game("fk_a11", {"game.equilibrium": "generalized"}), [0.6, 0.4],
         {("x1 + x2 <= 1", 0): 0.8, ("x1 + x2 <= 1", 1): 0.2}),
        (_game("harker"), [5.0, 9.0], {}),  # shared constraint inactive
        # Harker on its segment at (9.5, 5.5): lambda_1 = -(2 x1 + 8/3 x2 - 34) = 1/3,
        # lambda_2 = -(2 x2 + 5/4 x1 - 24.25) = 1.375
        (_game("harker"), [9.5, 5.5], {("x1 + x2 <= 15", 0): 1 / 3, ("x1 + x2 <= 15", 1): 1.375}),
    ]
    for game, a, mult in cases:
        r = kkt_residuals(game, _z(game, a, mult))
        assert set(r) == {"kkt_residual", "stationarity", "primal_infeasibility", "dual_infeasibility",
                          "complementarity"}
        assert all(v <= 1e-12 for v in r.values()), (game.agent_names, a, r)
        assert all(v >= 0 for v in r.values())


def test_kkt_residual_with_an_active_bound_multiplier() -> None:
    # semicopositive NE (3, 1): agent 2 sits at its lower bound x2 >= 1 with multiplier dJ2/dx2 = x1 = 3
    game = compile_game(load_config(CONFIGS / "semicopositive_ne.yaml"))
    z = _z(game, [3.0, 1.0], {("x2 >= 1", 1): 3.0})
    assert kkt_residuals(game, z)["kkt_residual"] <= 1e-14
    # with the wrong multiplier, stationarity is off by exactly the error
    r = kkt_residuals(game, _z(game, [3.0, 1.0], {("x2 >= 1", 1): 2.5}))
    assert r["stationarity"] == pytest.approx(0.5) and r["kkt_residual"] == pytest.approx(0.5)
    assert r["primal_infeasibility"] == 0 and r["dual_infeasibility"] == 0 and r["complementarity"] == 0


def test_kkt_residual_components_on_crafted_points() -> None:
    # A.11, variational: L = (2(x1 - 1) + mu, 2(x2 - 1/2) + mu), c = x1 + x2 - 1
    game = _game("fk_a11")
    r = kkt_residuals(game, np.array([0.8, 0.3, -0.1]))
    assert r["stationarity"] == pytest.approx(0.5)  # |2(0.8 - 1) - 0.1| = |2(0.3 - 0.5) - 0.1|
    assert r["primal_infeasibility"] == pytest.approx(0.1)
    assert r["dual_infeasibility"] == pytest.approx(0.1)
    assert r["complementarity"] == pytest.approx(0.01)
    assert r["kkt_residual"] == pytest.approx(0.5)  # max(|L|, |min(-c, mu)|) = max(0.5, 0.1)
    # A.11, generalized, feasible with slack and stationary: only complementarity (and min(-c, lambda)) is off
    gen = _game("fk_a11", {"game.equilibrium": "generalized"})
    r = kkt_residuals(gen, _z(gen, [0.5, 0.4], {("x1 + x2 <= 1", 0): 1.0, ("x1 + x2 <= 1", 1): 0.2}))
    assert r["stationarity"] == pytest.approx(0.0, abs=1e-15)
    assert r["primal_infeasibility"] == 0 and r["dual_infeasibility"] == 0
    assert r["complementarity"] == pytest.approx(0.1)  # max(|1.0 * -0.1|, |0.2 * -0.1|)
    assert r["kkt_residual"] == pytest.approx(0.1)  # max(|min(0.1, 1.0)|, |min(0.1, 0.2)|)
    # A.12 at (12, 1): c = (-22, 2, -11, -9), lambda = (0, 0.5, 0.3, -0.2)
    a12 = _game("fk_a12")
    z = _z(a12, [12.0, 1.0], {("x1 <= 10", 0): 0.5, ("x2 >= -10", 1): 0.3, ("x2 <= 10", 1): -0.2})
    r = kkt_residuals(a12, z)
    # L1 = 2 x1 + x2 - 16 - lambda_1lo + lambda_1up = 9.5, L2 = x1 + 2 x2 - 16 - 0.3 - 0.2 = -2.5
    np.testing.assert_allclose(a12.kkt_parts(z).L, [9.5, -2.5])
    assert r["stationarity"] == pytest.approx(9.5)
    assert r["primal_infeasibility"] == pytest.approx(2.0)
    assert r["dual_infeasibility"] == pytest.approx(0.2)
    assert r["complementarity"] == pytest.approx(3.3)  # |0.3 * -11|
    assert r["kkt_residual"] == pytest.approx(9.5)


def test_kkt_residual_of_equality_constraints() -> None:
    game = compile_game(load_config("e.yaml", text="""
game:
  kind: static
  agents:
    - name: p
      variables: {x: {lower: -1}}
      cost: "x**2"
      constraints: ["x == 0.5"]
"""))
    # solution x = 1/2, lower bound inactive, equality multiplier -1 (free sign): 2x + mu = 0
    assert kkt_residuals(game, np.array([0.5, 0.0, -1.0]))["kkt_residual"] == 0.0
    r = kkt_residuals(game, np.array([0.7, -0.2, -1.0]))
    assert r["stationarity"] == pytest.approx(0.6)  # 2(0.7) - (-0.2) + (-1)
    assert r["primal_infeasibility"] == pytest.approx(0.2)  # |h| = |0.7 - 0.5|
    assert r["dual_infeasibility"] == pytest.approx(0.2)  # the bound's multiplier only: mu of == is free
    assert r["complementarity"] == pytest.approx(0.34)  # |-0.2 * (-1 - 0.7)|, equality excluded
    value, decision, note = best_response(game, 0, np.array([0.7]))
    assert note == "ok" and decision[0] == pytest.approx(0.5, abs=1e-9) and value == pytest.approx(0.25)


def test_kkt_residual_is_positive_away_from_the_solution() -> None:
    rng = np.random.default_rng(5)
    for name in ("fk_a12", "fk_a11", "harker"):
        game = _game(name)
        for _ in range(5):
            z = np.r_[rng.uniform(-5, 5, game.n), rng.uniform(-1, 1, game.m)]
            r = kkt_residuals(game, z)
            assert r["kkt_residual"] > 1e-3
            assert r["kkt_residual"] >= r["stationarity"] - 1e-15


# --- 3. the paper's Study 1 -------------------------------------------------------------------------


def test_certificate_of_the_solved_paper_game() -> None:
    res = solve(load_config(CONFIGS / "paper_study1.yaml"))
    assert res.status == "converged"
    cert = certificate(res.game, res.z, res.x)
    assert cert["kkt_residual"] <= 1e-10
    assert set(cert["best_response_gap"]) == {"agent1", "agent2", "agent3"}
    assert all(abs(g) <= GAP_TOL for g in cert["best_response_gap"].values()), cert["best_response_gap"]
    assert all(note.startswith("ok") for note in cert["best_response_note"].values())
    assert res.certificate["kkt_residual"] == pytest.approx(cert["kkt_residual"], abs=1e-14)
    # moving agent 2 off its equilibrium plan (feasibly: u2 <= 1/2 still holds) gives it a positive gap,
    # and leaves the KKT residual positive
    game = res.game
    z = res.z.copy()
    z[game.agent_slices[1]] -= 0.3
    off = certificate(game, z, res.x)
    assert off["best_response_gap"]["agent2"] > 1e-3
    assert off["kkt_residual"] > 1e-3


def test_a_local_maximum_of_a_player_is_found_from_the_corners_of_its_box() -> None:
    # FK A.2: at this point players 2-4 sit at a stationary point of their (nonconvex) costs, a local maximum in
    # their own decision; the best response from the candidate stays there, the one from the lower bound does not.
    # The independent check of benchmarks/problems/fk.py (numpy costs, its own SLSQP) gives the same gap.
    from benchmarks.problems import fk

    problem = next(p for p in fk.problems() if p.name == "A.2" and p.start == "x0 = 1")
    game = compile_game(load_config(text=problem.config_yaml))
    a = np.array([0.3, 0.1938, 0.1938, 0.1938, 0.0685, 0.01, 0.01, 0.01, 0.01, 0.01])
    gaps = certificate(game, np.concatenate([a, np.zeros(game.m)]))["best_response_gap"]
    independent = problem.best_response_gaps(a)
    for name in ("p2", "p3", "p4"):
        assert gaps[name] == pytest.approx(independent[name], rel=1e-6) and gaps[name] > 1e-3


def test_newton_best_responses_find_the_same_gaps() -> None:
    """The same point of FK A.2 certified by Newton solves of the players' own problems: the same gaps as the
    independent check, and no player at the equilibrium of Harker's game can gain."""
    from benchmarks.problems import fk
    from gnerun.solvers.certificate import NewtonResponses

    problem = next(p for p in fk.problems() if p.name == "A.2" and p.start == "x0 = 1")
    cfg = load_config(text=problem.config_yaml)
    game = compile_game(cfg)
    a = np.array([0.3, 0.1938, 0.1938, 0.1938, 0.0685, 0.01, 0.01, 0.01, 0.01, 0.01])
    cert = certificate(game, np.concatenate([a, np.zeros(game.m)]), responses=NewtonResponses(cfg, game))
    independent = problem.best_response_gaps(a)
    for name in ("p2", "p3", "p4"):
        assert cert["best_response_gap"][name] == pytest.approx(independent[name], rel=1e-6)
        assert cert["best_response_gap"][name] > 1e-3 and cert["best_response_note"][name].startswith("ok (Newton")
    cfg = load_config(CONFIGS / "harker.yaml")
    game = compile_game(cfg)
    star = np.array([5.0, 9.0])
    cert = certificate(game, _z(game, star), responses=NewtonResponses(cfg, game))
    assert all(abs(g) <= GAP_TOL for g in cert["best_response_gap"].values())
    # Harker's players are convex QPs: one solve of each, no Newton start and no agent problem compiled
    assert all(note.startswith("ok (convex") for note in cert["best_response_note"].values())
    assert "agent_problems" not in game.derived


@pytest.mark.parametrize("x2", [0.0, 3.0, 9.0, 12.5])
def test_a_convex_players_gap_is_its_exact_best_response(x2) -> None:
    """Harker's player 1 away from the equilibrium: min x1^2 + 8/3 x1 x2 - 34 x1 over 0 <= x1 <= 10, x1 + x2 <= 15,
    whose best response is the clipped stationary point (34 - 8/3 x2) / 2; the certificate's one QP solve gives
    that response and the gap J1(x1) - J1(best) in closed form, for a candidate x1 = 1 (its multipliers zero)."""
    cfg = load_config(CONFIGS / "harker.yaml")
    game = compile_game(cfg)
    from gnerun.solvers.certificate import NewtonResponses

    cert = certificate(game, _z(game, np.array([1.0, x2])), responses=NewtonResponses(cfg, game))
    best = min(max((34 - 8 / 3 * x2) / 2, 0.0), 10.0, 15.0 - x2)

    def J1(x1: float) -> float:
        return x1**2 + 8 / 3 * x1 * x2 - 34 * x1

    assert cert["best_response_gap"]["p1"] == pytest.approx(J1(1.0) - J1(best), rel=1e-12, abs=1e-12)
    assert cert["best_response_kind"]["p1"] == "global (convex)"
    assert cert["best_response_note"]["p1"].startswith("ok (convex")


def test_a_player_curved_down_however_slightly_is_not_called_convex() -> None:
    """1e6 (x - 0.3)^2 - 1e-5 y^2 + x x2 on |x| <= 10, |y| <= 1000: the Hessian diag(2e6, -2e-5) is indefinite,
    though its least eigenvalue is 1e-11 of its largest. At the KKT point y = 0 the player gains 1e-5 1000^2 = 10 by
    y = +-1000: the certificate finds that gain (not "global (convex)" with a zero gap), and the solve ends at
    y = +-1000, certified by the stationary points of its faces."""
    text = """
game:
  kind: static
  agents:
    - name: p1
      variables: {x: {lower: -10, upper: 10, start: 0}, y: {lower: -1000, upper: 1000, start: 0}}
      cost: "1e6*(x - 0.3)**2 - 1e-5*y**2 + x*x2"
    - name: p2
      variables: {x2: {lower: -1, upper: 1, start: 0}}
      cost: "(x2 - 0.5)**2"
"""
    cfg = load_config(text=text)
    game = compile_game(cfg)
    x = 0.3 - 0.5 / 2e6  # p1's stationary x against x2 = 0.5
    cert = certificate(game, _z(game, np.array([x, 0.0, 0.5])))
    assert cert["best_response_kind"]["p1"] != "global (convex)"
    assert cert["best_response_gap"]["p1"] == pytest.approx(1e-5 * 1000**2, rel=1e-9)
    assert cert["best_response_kind"]["p2"] == "global (convex)"  # (x2 - 0.5)^2 is
    res = solve(cfg, out=None)
    assert res.status == "converged"
    assert abs(res.solution["p1"]["y"]) == 1000.0 and res.solution["p1"]["x"] == pytest.approx(x, abs=1e-12)
    assert res.certificate["best_response_kind"]["p1"] == "global (QP faces)"  # (an LQ player, not convex)


def test_a_player_without_rows_beside_one_with_rows_is_certified() -> None:
    """A dynamic game whose first player has no constraint and whose second has one (inactive at the solution): the
    certificate builds the first player's own problem with no multipliers (it raised CasADi's error on an empty
    substitution). The equilibrium is the stationary point of both players' costs in closed form."""
    cfg = load_config(text="""
game:
  kind: dynamic
  horizon: 0
  states: [x1]
  dynamics: {x1: "x1 + 0.4*u1 + 0.6*u2"}
  x0: [-1.47]
  agents:
    - name: p1
      inputs: {u1: {start: 0}}
      stage_cost: "(x1 + 0.58)**2 + 0.01*u1**2"
    - name: p2
      inputs: {u2: {start: 0}}
      stage_cost: "(x1 + 0.5)**2 + 0.01*u2**2"
      constraints: ["x1**2 <= 0.45"]
""")
    res = solve(cfg, out=None)
    # 2 b_i (x1 - r_i) + 0.02 u_i = 0 with x1 = -1.47 + 0.4 u1 + 0.6 u2, b = (0.4, 0.6), r = (-0.58, -0.5)
    b, r = np.array([0.4, 0.6]), np.array([-0.58, -0.5])
    A = 2 * np.outer(b, b) + 0.02 * np.eye(2)
    u = np.linalg.solve(A, -2 * b * (-1.47 - r))
    assert res.status == "converged"
    assert [res.solution["p1"]["u1"][0], res.solution["p2"]["u2"][0]] == pytest.approx(u, abs=1e-10)
    assert (-1.47 + b @ u) ** 2 < 0.45  # the row is inactive
    assert all(abs(g) <= 1e-12 for g in res.certificate["best_response_gap"].values())


def _concave_in_two(y4_bounds: str):
    """p1: -(y1^2 + y2^2) + y3^2 + y4^2 - 0.5 y1 + 0.3 y2 + x2 y3 with y1, y2, y3 in [-1, 1] (y4: ``y4_bounds``), and
    p2: (x2 - 0.5)^2 on [-1, 1]; the config, the game, p1's stationary point against x2 = 0.5 and p1's cost there."""
    cfg = load_config(text=_static([
        ("p1", "y1", "-(y1**2 + y2**2) + y3**2 + y4**2 - 0.5*y1 + 0.3*y2 + x2*y3",
         "start: 0, lower: -1, upper: 1}, y2: {start: 0, lower: -1, upper: 1}, y3: {start: 0, lower: -1, upper: 1}, "
         "y4: {start: 0" + y4_bounds),
        ("p2", "x2", "(x2 - 0.5)**2", "start: 0, lower: -1, upper: 1")]))
    y = np.array([-0.25, 0.15, -0.25, 0.0])
    J = -(y[0] ** 2 + y[1] ** 2) + y[2] ** 2 + y[3] ** 2 - 0.5 * y[0] + 0.3 * y[1] + 0.5 * y[2]
    return cfg, compile_game(cfg), y, J


def test_a_small_nonconvex_lq_player_is_answered_by_its_faces() -> None:
    """p1: -(y1^2 + y2^2) + y3^2 + y4^2 - 0.5 y1 + 0.3 y2 + x2 y3 on [-1, 1]^4, concave in y1 and y2 (four decisions:
    past the box search). At its stationary point (-0.25, 0.15, -0.25, 0) it is at a maximum in y1 and y2; its best
    response against x2 = 0.5 is (1, -1, -0.25, 0), cost -1.5 - 1.3 - 0.0625 = -2.8625, a corner of the faces y1 = 1,
    y2 = -1: the certificate enumerates its faces and gives that gap exactly; the solve ends there, certified."""
    cfg, game, y, J = _concave_in_two(", lower: -1, upper: 1")
    cert = certificate(game, _z(game, np.r_[y, 0.5]))
    assert cert["best_response_kind"]["p1"] == "global (QP faces)"
    assert cert["best_response_gap"]["p1"] == pytest.approx(J - (-2.8625), abs=1e-12)
    res = solve(cfg, out=None)
    assert res.status == "converged" and res.certificate["best_response_kind"]["p1"] == "global (QP faces)"
    assert [res.solution["p1"][v] for v in ("y1", "y2", "y3", "y4")] == pytest.approx([1, -1, -0.25, 0], abs=1e-9)


def test_dependent_equalities_make_no_faces_proof() -> None:
    """p1: -(y1^2 + y2^2) + 0.1 y1 on [-1, 1]^2 with y1 + y2 = 0 written twice (and once doubled): every face's KKT
    system is singular, so the faces enumerate nothing; the candidate, the maximum y1 = 0.025 on the line, gains
    2.10125 at y1 = -1, which the general path finds (no proof by faces is claimed)."""
    text = _static([("p1", "y1", "-(y1**2 + y2**2) + 0.1*y1 + 0*x2",
                     "start: 0, lower: -1, upper: 1}, y2: {start: 0, lower: -1, upper: 1"),
                    ("p2", "x2", "(x2 - 0.5)**2", "start: 0, lower: -1, upper: 1")])
    rows = '      constraints: ["y1 + y2 == 0", "2*y1 + 2*y2 == 0"]\n'
    text = text.replace('      cost: "-(y1', rows + '      cost: "-(y1', 1)
    game = compile_game(load_config(text=text))
    cert = certificate(game, _z(game, np.array([0.025, -0.025, 0.5])))
    assert cert["best_response_kind"]["p1"] != "global (QP faces)"
    assert cert["best_response_gap"]["p1"] == pytest.approx(-2 * 0.025**2 + 0.1 * 0.025 + 2.1, abs=1e-8)


def test_a_nonconvex_lq_player_with_an_unbounded_decision_gets_no_faces_proof() -> None:
    """The same player with y4 unbounded: a quadratic need not be bounded below on an unbounded polyhedron, so its
    faces' stationary points are only starts; the gap (the same closed form) is a statement about the starts."""
    _, game, y, J = _concave_in_two("")
    cert = certificate(game, _z(game, np.r_[y, 0.5]))
    assert cert["best_response_kind"]["p1"].startswith("over ")
    assert cert["best_response_gap"]["p1"] == pytest.approx(J - (-2.8625), abs=1e-9)


def test_best_responses_gain_nothing_from_violating_a_priced_constraint() -> None:
    # FK A.10c at its equilibrium: SLSQP's best responses may break a consumer's budget by ~1e-8; at the candidate's
    # multipliers (~100) that looked like a gain of ~1e-6 before violations were charged
    from benchmarks.problems import fk
    from gnerun.runs.solving import iterate, make_solver

    problem = next(p for p in fk.problems() if p.name == "A.10c")
    cfg = load_config(text=problem.config_yaml)
    game = compile_game(cfg)
    solver = make_solver(cfg, game)
    state = iterate(solver, solver.init())
    assert state.status == "converged"
    gaps = certificate(game, state.z)["best_response_gap"]
    assert max(gaps.values()) <= 1e-9


def test_a_solve_says_when_it_computes_the_exact_solution_and_the_certificate() -> None:
    stages: list[str] = []
    res = solve(load_config(CONFIGS / "harker.yaml"), on_stage=stages.append)
    assert res.status == "converged"
    assert len(stages) == 2 and "exact solution" in stages[0] and "best response" in stages[1]
    stages.clear()
    solve(load_config(CONFIGS / "harker.yaml", {"run.reference": "none", "run.certificate": False}),
          on_stage=stages.append)
    assert stages == []


UNBOUNDED = """
game:
  kind: static
  agents:
    - name: p1
      variables: {x1: {start: 0}}
      cost: "-(x1)**2 + x1*x2"
    - name: p2
      variables: {x2: {start: 0}}
      cost: "(x2 - 1)**2 + x1*x2"
"""


def test_a_player_unbounded_below_is_no_equilibrium() -> None:
    """p1's cost -(x1)^2 + x1 x2 has no minimum: the only KKT point, (2/5, 4/5), is p1's maximum. Every Newton best
    response of p1 runs away without converging, and SLSQP stops at the stationary candidate; a feasible point where
    p1's cost is lower still proves that p1 can improve, so the point is not certified and the solve does not end
    converged."""
    from gnerun.solvers.certificate import NewtonResponses

    cfg = load_config(text=UNBOUNDED)
    game = compile_game(cfg)
    kkt = np.array([0.4, 0.8])
    cert = certificate(game, _z(game, kkt), responses=NewtonResponses(cfg, game))
    assert cert["kkt_residual"] <= 1e-12
    assert cert["best_response_gap"]["p1"] > 1.0  # p1 gains at least 1 by moving away (J = -x1^2 + 0.8 x1)
    assert abs(cert["best_response_gap"]["p2"]) <= GAP_TOL  # p2's cost is convex: it is at its best response
    res = solve(cfg, out=None)
    assert res.status != "converged"
    assert res.certificate["best_response_gap"]["p1"] > 1.0


# --- games with nonconvex, unbounded, nonsmooth and non-finite players ---------------------------------------------
# Each is checked against what the game is, computed here without gnerun: closed forms, or a dense grid of the
# player's cost with the others fixed.


def _static(agents: list[tuple[str, str, str, str]], extra: str = "") -> str:
    """A static game: (name, variable, cost, bounds and start as YAML flow items) per agent."""
    lines = ["game:", "  kind: static", "  agents:"]
    for name, var, cost, spec in agents:
        lines += [f"    - name: {name}", f"      variables: {{{var}: {{{spec}}}}}", f'      cost: "{cost}"']
    return "\n".join(lines) + "\n" + extra


def _grid_min(f, lo: float, hi: float, n: int = 2_000_001) -> tuple[float, float]:
    g = np.linspace(lo, hi, n)
    v = f(g)
    k = int(np.argmin(v))
    return float(v[k]), float(g[k])


def test_a_player_unbounded_below_at_a_local_minimum_is_named() -> None:
    """p1's cost x1^3 - 12 x1 + x1 x2 falls like x1^3 as x1 -> -inf for every x2: no equilibrium. At the KKT point
    where p1 sits at its local minimum (x1 = sqrt((12 - x2)/3)) every local best response returns there."""
    cfg = load_config(text=_static([("p1", "x1", "x1**3 - 12*x1 + x1*x2", "start: 2"),
                                    ("p2", "x2", "(x2 - 0.5*x1)**2", "start: 1")]))
    res = solve(cfg)
    assert res.status == "unbounded_player"
    ray = res.certificate["unbounded"]["p1"]
    assert ray["direction"] == [-1.0] and ray["unbounded_below"] and ray["costs"][-1] < -1e20
    assert "p1 has no best response" in res.message and "decreases without bound" in res.message
    x1, x2 = res.solution["p1"]["x1"], res.solution["p2"]["x2"]
    assert x1 == pytest.approx(np.sqrt((12 - x2) / 3), rel=1e-9)  # the KKT point: its local minimum


def test_a_linear_player_without_a_best_response_is_named_not_diverged() -> None:
    """p1's cost (x2 - 3) x1 is linear in x1 >= 0 with p2 at x2 = 1: it falls without bound as x1 grows. The solver
    cannot end anywhere; the status says why."""
    cfg = load_config(text=_static([("p1", "x1", "(x2 - 3)*x1", "lower: 0, start: 0"),
                                    ("p2", "x2", "(x2 - 1)**2 + 0*x1", "start: 0")]))
    res = solve(cfg)
    assert res.status == "unbounded_player"
    assert res.certificate["unbounded"]["p1"]["direction"] == [1.0]


def _pole_fall(res, player: str) -> tuple[dict, float, float]:
    """A pole in the certificate: its entry, the decades of distance its approach spans, and the fall per decade (by
    least squares)."""
    pole = res.certificate["unbounded"][player]
    d, c = np.log10(pole["steps"]), np.asarray(pole["costs"])
    return pole, float(d[0] - d[-1]), float(np.polyfit(d, c, 1)[0])


def test_a_pole_in_a_bounded_set_is_named_not_diverged() -> None:
    """p1's cost log(x1) + x1 x2 on 0 <= x1 <= 1 falls like log(x1) as x1 -> 0 whatever x2 in [-1, 1] (x1 x2 is at
    most x1 in size): it has no best response, and the game no equilibrium. No ray leaves the box; the certificate
    approaches the pole at x1 = 0, where the cost falls by ln 10 per decade of the distance (exactly: log)."""
    cfg = load_config(text=_static([("p1", "x1", "log(x1) + x1*x2", "lower: 0, upper: 1, start: 0.5"),
                                    ("p2", "x2", "(x2 - x1)**2", "lower: -1, upper: 1, start: 0")]))
    res = solve(cfg)
    assert res.status == "unbounded_player"
    pole = res.certificate["unbounded"]["p1"]
    assert pole["pole"] == [0.0] and pole["direction"] == [-1.0]
    np.testing.assert_allclose(-np.diff(pole["costs"][-10:]), np.log(10.0), rtol=1e-6)  # x1 x2 negligible there
    assert "p1 has no best response" in res.message and "approaching (x1 = 0), where it is not finite" in res.message


def test_a_pole_inside_a_bounded_set_is_named() -> None:
    """p1's cost -tan(x1) + x1 x2 on 0 <= x1 <= 3 falls without bound as x1 -> pi/2 from below: a KKT point the
    solver reaches is no equilibrium, and the status says p1 has no best response there, at the pole."""
    cfg = load_config(text=_static([("p1", "x1", "-tan(x1) + x1*x2", "lower: 0, upper: 3, start: 1"),
                                    ("p2", "x2", "(x2 - x1)**2", "lower: -1, upper: 1, start: 0")]))
    res = solve(cfg)
    assert res.status == "unbounded_player"
    pole = res.certificate["unbounded"]["p1"]
    assert pole["unbounded_below"] and abs(pole["pole"][0] - np.pi / 2) < 1e-12 and pole["costs"][-1] < -1e15
    assert "decreases without bound approaching (x1 = 1.5708)" in res.message


def test_a_pole_at_the_edge_of_the_domain_is_not_certified_away() -> None:
    """p1's cost (x1 - 1)^2 + y1^2 + 0.5 log(x1 + 1.5) + 0.1 x1 x2 has a local minimum at x1 ~ 0.87, where the solver
    ends at a KKT point, but on -2 <= x1 <= 2 it falls like 0.5 log(x1 + 1.5) as x1 -> -1.5 (and is not defined
    below): no best response. The gain appears only within 1e-5 of the edge, which no design point or local solve
    reached ("converged" over 276 starts before); the segments along x1 from the point find the edge of the domain
    and bisect it: the fall keeps its pace of 0.5 ln 10 per decade of the distance."""
    j1 = "(x1 - 1)**2 + 0.5*log(x1 + 1.5) + 0.1*x1*x2"
    cfg = load_config(text=_static([("p1", "x1", j1, "lower: -2, upper: 2, start: 0.5"),
                                    ("p2", "x2", "(x2 - 0.5)**2", "lower: -1, upper: 1, start: 0")]))
    res = solve(cfg)
    assert res.status == "unbounded_player"
    pole, span, fall = _pole_fall(res, "p1")
    assert pole["pole"][0] == pytest.approx(-1.5, abs=1e-15) and pole["direction"] == [-1.0]
    assert span >= 8 and fall == pytest.approx(0.5 * np.log(10.0), rel=0.05)


def test_a_pole_is_named_when_the_solve_stalls_outside_the_domain() -> None:
    """p1's cost 0.1 exp(x1/2) + 1.29 log(x1 - 0.195) + 0.2 x1 x2 on -2.29 <= x1 <= 1.86, started at -1.21 where
    log is not defined: the solve stalls outside the domain, where no best response can be checked. The pole at
    0.195 (the cost falls like 1.29 log of the distance) is sought from the lowest point of a design where the cost
    is defined: the status says p1 has no best response, instead of "stalled"."""
    j1 = "0.1*exp(0.5*x1) + 1.29*log(x1 - 0.195) + 0.2*x1*x2"
    cfg = load_config(text=_static([("p1", "x1", j1, "lower: -2.29, upper: 1.86, start: -1.21"),
                                    ("p2", "x2", "(x2 - 0.3*x1)**2", "lower: -2, upper: 2, start: 0")]))
    res = solve(cfg)
    assert res.status == "unbounded_player"
    pole, _, fall = _pole_fall(res, "p1")
    assert pole["pole"][0] == pytest.approx(0.195, abs=1e-15) and "p1" in res.certificate["not_finite"]
    assert fall == pytest.approx(1.29 * np.log(10.0), rel=0.05)


def test_a_best_response_found_at_a_two_sided_pole_is_a_pole() -> None:
    """p1's cost 0.1 exp(x1/2) + 1.38 log|x1 + 0.504| + 0.2 x1 x2 falls without end on both sides of -0.504; a local
    solve of its best response ends within rounding of it (cost about -50). Approached from there along its
    coordinate, the cost keeps falling by 1.38 ln 10 per decade of the distance: a pole, not a best response."""
    j1 = "0.1*exp(0.5*x1) + 1.38*log(abs(x1 + 0.504)) + 0.2*x1*x2"
    cfg = load_config(text=_static([("p1", "x1", j1, "lower: -2.88, upper: 2.24, start: 0.24"),
                                    ("p2", "x2", "(x2 - 0.3*x1)**2", "lower: -2, upper: 2, start: 0")]))
    res = solve(cfg)
    assert res.status == "unbounded_player"
    pole, span, fall = _pole_fall(res, "p1")
    assert pole["pole"][0] == pytest.approx(-0.504, abs=1e-12)
    assert span >= 8 and fall == pytest.approx(1.38 * np.log(10.0), rel=0.05)


def test_a_pole_in_a_dynamic_game_is_named() -> None:
    """a1's stage cost 0.1 u1^2 + 0.2 log(x1) + 0.1 x1 x2 with x1(tau+1) = x1(tau) + u1(tau), x1(0) = 1 and
    |u1| <= 0.5: two stages of u1 = -0.5 bring x1 to 0, where log falls without bound. a1 has no best response (the
    solve stalled before), and the pole the certificate approaches is a plan whose x1 reaches 0 at some stage."""
    cfg = load_config(text="""
game:
  kind: dynamic
  horizon: 5
  states: [x1, x2]
  dynamics: {x1: "x1 + u1", x2: "x2 + u2"}
  x0: [1.0, 1.0]
  agents:
    - {name: a1, inputs: {u1: {lower: -0.5, upper: 0.5, start: 0}}, stage_cost: "0.1*u1**2 + 0.2*log(x1) + 0.1*x1*x2"}
    - {name: a2, inputs: {u2: {lower: -0.5, upper: 0.5, start: 0}}, stage_cost: "(x2 - 0.5)**2 + u2**2"}
""")
    res = solve(cfg)
    assert res.status == "unbounded_player" and "a1 has no best response" in res.message
    x1 = 1.0 + np.cumsum(res.certificate["unbounded"]["a1"]["pole"])  # x1(1..T+1) along the plan approached
    assert np.min(np.abs(x1)) < 1e-12 and np.all(x1 >= -1e-12)


def test_a_cost_that_ends_finite_at_its_domain_edge_keeps_its_equilibrium() -> None:
    """p1's cost x1 log(x1) - x1 x2 tends to 0 at x1 = 0 (no pole, though log(0) is not finite): its best response
    to x2 is exp(x2 - 1), and with p2's x2 = 0.5 x1 the equilibrium solves x1 = exp(0.5 x1 - 1), certified."""
    cfg = load_config(text=_static([("p1", "x1", "x1*log(x1) - x1*x2", "lower: 0, upper: 2, start: 1"),
                                    ("p2", "x2", "(x2 - 0.5*x1)**2", "start: 0")]))
    res = solve(cfg)
    assert res.status == "converged" and "unbounded" not in res.certificate
    x1 = res.solution["p1"]["x1"]
    assert x1 == pytest.approx(np.exp(0.5 * x1 - 1), rel=1e-9)


def test_a_better_basin_is_found_and_certified_on_the_box() -> None:
    """p1 has a shallow well near x1 = -2 and a deep one near x1 = 4, coupled weakly to p2 (x2 = 0.3 x1). Started in
    the shallow well, the solver reaches its KKT point; the certificate finds the deep well (a design point there is
    already better as it is), the solve restarts from it and ends certified, each gap global on a box."""
    j1 = "-1.5*exp(-(x1 + 2)**2) - 3*exp(-(x1 - 4)**2/2) + 0.02*(x1 - x2)**2"
    cfg = load_config(text=_static([("p1", "x1", j1, "start: -2.1"), ("p2", "x2", "(x2 - 0.3*x1)**2", "start: -0.6")]))
    res = solve(cfg)
    assert res.status == "converged"
    x1, x2 = res.solution["p1"]["x1"], res.solution["p2"]["x2"]
    assert x2 == pytest.approx(0.3 * x1, abs=1e-9)

    def j(g):
        return -1.5 * np.exp(-(g + 2) ** 2) - 3 * np.exp(-(g - 4) ** 2 / 2) + 0.02 * (g - x2) ** 2

    best, arg = _grid_min(j, -50, 50)
    assert x1 == pytest.approx(arg, abs=1e-4) and x1 > 3  # the deep well: p1's global best response
    # x1 and x2 have no bounds: the box searched is 100 times the point's size around it, and says so
    assert res.certificate["best_response_kind"] == {"p1": "global on the search box", "p2": "global on the search box"}
    box = res.certificate["best_response_box"]["p1"]
    assert box["lower"][0] <= x1 - 100 * abs(x1) and box["upper"][0] >= x1 + 100 * abs(x1)
    assert res.certificate["best_response_gap"]["p1"] <= 1e-9
    assert j(np.array([x1]))[0] - best <= 1e-9


def test_a_box_searched_around_an_unbounded_decision_is_called_a_search_box() -> None:
    """min(x^2, 0.001 (x - 500)^2 - 1) on x >= -1: the candidate x = 0 is the best point of the box searched around it
    (100 times its size), but x = 500, outside it, is cheaper. The claim says it covers the search box only; with the
    bound x <= 1000 the box is the player's own, the branch and bound finds the far well and the solve ends there."""
    text = _static([("p1", "x1", "min(x1**2, 0.001*(x1 - 500)**2 - 1) + 0*x2", "start: 0, lower: -1"),
                    ("p2", "x2", "(x2 - 0.5)**2", "start: 0, lower: -1, upper: 1")])
    res = solve(load_config(text=text), out=None)
    assert res.certificate["best_response_kind"]["p1"] == "global on the search box"
    assert res.certificate["best_response_kind"]["p2"] == "global on the box"
    assert res.certificate["best_response_box"]["p1"]["upper"][0] < 500  # (the far well lies outside it)
    bounded = solve(load_config(text=text.replace("start: 0, lower: -1}", "start: 0, lower: -1, upper: 1000}", 1)),
                    out=None)
    assert bounded.status == "converged" and bounded.certificate["best_response_kind"]["p1"] == "global on the box"
    assert bounded.solution["p1"]["x1"] == pytest.approx(500.0, abs=1e-6)  # the global minimum, cost -1


def test_a_row_broken_by_rounding_at_the_candidate_does_not_empty_the_box() -> None:
    """p2's row 0.1 x1 <= 0.03 is p1's decision alone; at x1 = 0.3 + 2.4e-12 (a point a solve accepts) it is +2.4e-13.
    p2 gains 0.7296 in its narrow well at y2 = -2.2 (0.01 5.2^2 - 1 against 0 at y2 = 3): the box search finds it
    instead of discarding the box on that row."""
    text = _static([("p1", "x1", "(x1 - 1)**2", "start: 0, lower: 0, upper: 1"),
                    ("p2", "y2", "0.01*(y2 - 3)**2 - exp(-1e6*(y2 + 2.2)**2) + 0*x1", "start: 3, lower: -5, upper: 5")],
                   '  shared_constraints: ["0.1*x1 <= 0.03"]\n  equilibrium: generalized\n')
    game = compile_game(load_config(text=text))
    z = np.zeros(game.size)
    z[:2] = [0.3 + 2.4e-12, 3.0]
    assert game.constraint_values(z[:2], None)[0].max() > 0  # the row, broken by rounding
    cert = certificate(game, z)
    assert cert["best_response_kind"]["p2"] == "global on the box"
    assert cert["best_response_gap"]["p2"] == pytest.approx(1 - 0.01 * 5.2**2, rel=1e-6)


def test_the_starts_spread_with_the_size_of_the_decision() -> None:
    """A one-dimensional, unbounded player with wells near x1 = -30 and +30, the left one lower by about 120: at the
    KKT point in the right well, starts perturbed by N(0, 1) (not by the decision's size) stay in that well; the
    certificate's starts (scaled to the size of the candidate, and a design over a box around it) reach the other."""
    from scipy.optimize import brentq

    j1 = "(x1**2 - 900)**2/1e4 + 2*x1 + 0.01*x1*x2"
    cfg = load_config(text=_static([("p1", "x1", j1, "start: 30"), ("p2", "x2", "(x2 - 1)**2 + 0*x1", "start: 1")]))
    game = compile_game(cfg)
    x1 = brentq(lambda t: 4 * t * (t**2 - 900) / 1e4 + 2 + 0.01, 20, 40)  # p1's stationary point in the right well

    def j(g):
        return (g**2 - 900) ** 2 / 1e4 + 2 * g + 0.01 * g

    best, arg = _grid_min(j, -100, 100)
    cert = certificate(game, _z(game, [x1, 1.0]))
    assert cert["best_response_gap"]["p1"] == pytest.approx(j(x1) - best, rel=1e-6) and arg < -25
    assert cert["best_response_gap"]["p2"] <= 1e-12


def test_a_cost_undefined_at_the_point_is_never_converged() -> None:
    """NaN and infinite costs: x1/(x2 - x2) is x1/0 (infinite), and 0*log(-1 - x1**2) is undefined everywhere,
    although CasADi simplifies it to 0; both end nan, with the player named."""
    for cost in ("x1/(x2 - x2) + x1**2", "(x1 - 1)**2 + 0*log(-1 - x1**2)"):
        cfg = load_config(text=_static([("p1", "x1", cost, "start: 0.5"), ("p2", "x2", "(x2 - x1)**2", "start: 0")]))
        res = solve(cfg)
        assert res.status == "nan", (cost, res.status, res.message)
        assert res.certificate["not_finite"] == ["p1"] and res.certificate["best_response_gap"]["p1"] is None


def test_a_kkt_point_at_a_kink_is_checked_branch_by_branch() -> None:
    """p1 (four decisions in [-1, 1]) has the cost -|y1| + |y|^2 + 0.1 y2 x5: at y = 0 the derivative CasADi takes of
    -|y1| is 0, so y = 0 is a KKT point, yet -|y1| + y1^2 is lowest at y1 = +-1/2 (by 1/4). The certificate sees the
    kink, compares the branches and finds the gap; the solve leaves the point and ends at a true equilibrium."""
    txt = """
game:
  kind: static
  agents:
    - name: p1
      variables:
        y1: {lower: -1, upper: 1, start: 0}
        y2: {lower: -1, upper: 1, start: 0}
        y3: {lower: -1, upper: 1, start: 0}
        y4: {lower: -1, upper: 1, start: 0}
      cost: "-abs(y1) + y1**2 + y2**2 + y3**2 + y4**2 + 0.1*y2*x5"
    - name: p2
      variables: {x5: {start: 0}}
      cost: "(x5 - 0.1*y1)**2"
"""
    cfg = load_config(text=txt)
    game = compile_game(cfg)
    from gnerun.solvers.certificate import NewtonResponses

    cert = certificate(game, np.zeros(game.size), None, None, NewtonResponses(cfg, game))
    assert cert["kinks"] == {"p1": ["fabs"]}
    assert cert["best_response_gap"]["p1"] == pytest.approx(0.25, abs=1e-9)
    res = solve(cfg)
    assert res.status == "converged"
    y1, x5 = res.solution["p1"]["y1"], res.solution["p2"]["x5"]
    assert abs(y1) == pytest.approx(0.5, abs=1e-9) and x5 == pytest.approx(0.1 * y1, abs=1e-9)


def test_abs_min_max_games_are_not_solved_as_linear_quadratic() -> None:
    """abs(x1 - 2) + 0.2 x1^2 against (x2 + x1)^2: the equilibrium is (2, -2), at the kink. Taken as affine, the game
    was 'solved' from z = 0 with the derivative of abs at 0; now the solve either certifies the kink or does not
    end converged."""
    cfg = load_config(text=_static([("p1", "x1", "abs(x1 - 2) + 0.2*x1**2 + 0*x2", "start: 0"),
                                    ("p2", "x2", "(x2 + x1)**2", "start: 0")]))
    assert not compile_game(cfg).affine
    res = solve(cfg)
    if res.status == "converged":
        assert res.solution["p1"]["x1"] == pytest.approx(2.0, abs=1e-6)
    else:
        assert "abs, min or max" in res.message  # the failure says what the game has


def test_without_best_responses_a_kkt_point_is_not_called_converged(tmp_path) -> None:
    """A concave player: its KKT point is its maximum. With run.certificate false the solve ends kkt_point, 'not
    certified', in the summary and on the command line's status line."""
    import json
    import subprocess
    import sys

    text = _static([("p1", "x1", "-(x1 - 1)**2 + x1*x2", "lower: -5, upper: 5, start: 0"),
                    ("p2", "x2", "(x2 - 0.5)**2", "start: 0")], "run: {certificate: false, reference: none}\n")
    config = tmp_path / "concave.yaml"
    config.write_text("name: concave\n" + text)
    res = solve(load_config(config))
    assert res.status == "kkt_point" and "not certified" in res.message
    out = subprocess.run([sys.executable, "-m", "gnerun.cli", "solve", str(config), "--out", str(tmp_path / "run")],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    status = next(line for line in out.stdout.splitlines() if line.startswith("status:"))
    assert status.startswith("status: kkt_point") and "not certified" in status
    assert json.loads((tmp_path / "run" / "summary.json").read_text())["status"] == "kkt_point"
    # with the certificate the point is found to be p1's maximum: the solve leaves it for p1's best response, the
    # bound -5 (-(x1 - 1)^2 + 0.5 x1 is -38.5 there, -13.5 at 5), and ends at the equilibrium (-5, 0.5)
    assert res.solution["p1"]["x1"] == pytest.approx(1.25, abs=1e-9)  # the KKT point (p1's maximum)
    full = solve(load_config(config, {"run.certificate": True}))
    assert full.status == "converged" and full.solution["p1"]["x1"] == pytest.approx(-5.0, abs=1e-9)


def test_a_fixed_decision_gets_an_empty_box_not_a_crash() -> None:
    """p1 owns x1 (a double well) and y1 fixed by lower = upper = 0.5. The certificate's design over p1's box is
    degenerate along y1: it is drawn there at the fixed value, and the gap is the double well's, on a grid."""
    text = """game:
  kind: static
  agents:
    - name: p1
      variables: {x1: {start: 1.9}, y1: {lower: 0.5, upper: 0.5, start: 0.5}}
      cost: "(x1**2 - 4)**2 + x1 + y1*x2"
    - name: p2
      variables: {x2: {start: 0}}
      cost: "(x2 - 0.1*x1)**2"
"""
    game = compile_game(load_config(text=text))
    x1 = 1.9371  # near p1's right-hand stationary point; the gap is measured from wherever x1 is
    z = _z(game, [x1, 0.5, 0.1 * x1])

    def j(g):
        return (g**2 - 4) ** 2 + g + 0.5 * 0.1 * x1

    best, arg = _grid_min(j, -10, 10)
    cert = certificate(game, z)
    assert arg < -1.9  # the left well is the deeper one
    assert cert["best_response_gap"]["p1"] == pytest.approx(j(x1) - best, rel=1e-6)
    with pytest.raises(Exception, match="not a boolean"):
        load_config(text=text.replace("upper: 0.5", "upper: false"))


def test_the_certificates_time_is_reported_apart(tmp_path) -> None:
    from .conftest import run_cli

    proc = run_cli("solve", str(CONFIGS / "harker.yaml"), "--out", str(tmp_path / "run"))
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["certificate_time_s"] > 0 and summary["time_s"] > 0
    line = next(t for t in proc.stdout.splitlines() if t.startswith("solver time"))
    assert f"certificate {summary['certificate_time_s'] * 1e3:.0f} ms" in line
    unchecked = solve(load_config(CONFIGS / "harker.yaml", ["run.certificate=false"]))
    assert unchecked.certificate_time_s == 0.0


@pytest.mark.parametrize("config", ["formation_ring.yaml", "fk_a01.yaml", "nonlinear_gne.yaml", "algames_merge.yaml",
                                    "overtaking.yaml"])
def test_the_recession_cone_reads_the_players_own_row_jacobian(config: str) -> None:
    """The Jacobian of a player's rows in its own decisions, as the certificate's ray search reads it: from the
    player's own problem where its local solves built its dense derivatives (condensed games), or from its part of
    the game's sparse system, the states' response to its decisions solved through the dynamics (the merge and the
    overtaking game, solved sparse); either way the game's own dense values to rounding."""
    from gnerun.solvers.certificate import NewtonResponses

    cfg = load_config(CONFIGS / config)
    game = compile_game(cfg)
    res = solve(cfg, game=game)
    a = np.asarray(res.z)[: game.n]
    responses = NewtonResponses(cfg, game)
    found = 0
    for agent in range(len(game.agent_names)):
        rows, sl = game.agents.constraint_rows(agent), game.agent_slices[agent]
        if not rows.size:
            continue
        own = responses.rows_jacobian(agent, a, None)
        ref = game.constraint_values(a)[1][rows][:, sl]
        assert own is not None and own.shape == ref.shape
        assert np.abs(own - ref).max() <= 1e-14 * max(1.0, float(np.abs(ref).max()))
        found += 1
    assert found


@pytest.mark.parametrize("config", ["formation_ring.yaml", "fk_a01.yaml", "variational_gne.yaml",
                                    "moving_obstacle.yaml", "paper_study3.yaml"])
def test_a_players_derivatives_taken_from_the_games_are_its_own(config: str) -> None:
    """A player's own problem given its dense derivatives as blocks of the game's (what the certificate's local
    solves use): L, c, dL/dz and dc/da at random points and multipliers equal those it builds by differentiating its
    own stationarity and rows, to rounding; and nothing is given where the game has not built its derivatives."""
    from gnerun.game.compile import agent_problem, derivatives_from_game

    cfg = load_config(CONFIGS / config)
    game = compile_game(cfg)
    assert not derivatives_from_game(agent_problem(game, 0, 0.0, cfg), game, 0)  # not built yet: not given
    game.kkt_parts(game.z_start())  # the game's derivatives built
    rng = np.random.default_rng(5)
    for agent in range(len(game.agent_names)):
        own, given = agent_problem(game, agent, 0.0, cfg), agent_problem(game, agent, 0.0, cfg)
        assert derivatives_from_game(given, game, agent)
        sl = game.agent_slices[agent]
        for _ in range(3):
            a = game.a_start + 0.3 * rng.standard_normal(game.n)
            z = np.concatenate([a[sl], np.abs(rng.standard_normal(own.m))])
            p = np.concatenate([game._x(None), a[: sl.start], a[sl.stop:], a[sl]])
            for u, v in zip(own.kkt_parts(z, p), given.kkt_parts(z, p), strict=True):
                u, v = np.asarray(u), np.asarray(v)
                assert u.shape == v.shape
                assert np.abs(u - v).max(initial=0.0) <= 1e-14 * max(1.0, float(np.abs(u).max(initial=0.0)))


@pytest.mark.parametrize("config", ["algames_merge.yaml", "formation_ring.yaml"])
def test_polished_local_solves_end_at_minima_in_fewer_iterations(config: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """The certificate's local solves from each player's starts (the merge's cars, solved sparse; the formation's
    robots, condensed), polished by Newton steps once ||Phi|| <= POLISH where the player's block needs no shift: every
    start the interior phase alone solves converges, in fewer iterations in all; where the interior phase alone
    converges from its first starting point the two end at the same point (to 1e-7); and no polished end point is a
    point SciPy's SLSQP, started there on the player's own problem, can lower the player's cost from (a local minimum,
    checked independently of the method)."""
    from scipy.optimize import minimize

    from gnerun.game.agents import OwnProblem
    from gnerun.solvers import certificate as cert_module
    from gnerun.solvers.certificate import NewtonResponses, response_starts
    from gnerun.solvers.driver import iterate
    from gnerun.solvers.status import Status

    cfg = load_config(CONFIGS / config, {"run.certificate": False})
    game = compile_game(cfg)
    a = np.asarray(solve(cfg, game=game).z)[: game.n]

    def ends(polish: float) -> list[tuple[int, np.ndarray, bool, int, int]]:
        monkeypatch.setattr(cert_module, "POLISH", polish)
        game.derived.pop("response_solvers", None)  # the solvers are built with POLISH and kept with the game
        responses, out = NewtonResponses(cfg, game), []
        for agent, sl in enumerate(game.agent_slices):
            problem, solver, _ = responses._solver(agent)
            p = np.concatenate([game._x(None), a[: sl.start], a[sl.stop:], a[sl]])
            for start in response_starts(game, agent, a).local:
                state = iterate(solver, solver.init(np.concatenate([start, np.zeros(problem.m)]), p))
                out.append((agent, state.z[: problem.n].copy(), state.status == Status.CONVERGED, state.k,
                            state.search.attempt))
        return out

    polished, plain = ends(cert_module.POLISH), ends(0.0)
    assert sum(k for *_, k, _ in polished) < sum(k for *_, k, _ in plain)
    same = 0
    for (agent, u, ended, _, _), (_, v, converged, _, attempt) in zip(polished, plain, strict=True):
        assert ended or not converged
        if not ended:
            continue
        if converged and attempt == 0:
            assert np.abs(u - v).max() <= 1e-7 * max(1.0, float(np.abs(v).max()))
            same += 1
        own = OwnProblem(game, agent, a, None)
        cost = own.objective(u)[0]
        res = minimize(own.objective, u, jac=True, method="SLSQP", constraints=own.constraints(),
                       options={"maxiter": 200, "ftol": 1e-14})
        assert own.violation(res.x) > 1e-9 or res.fun >= cost - 1e-9 * max(1.0, abs(cost))
    assert same


CONCAVE_BOX = """
name: concave-box
game:
  kind: static
  agents:
    - name: p1
      variables: {x1: {lower: -1, upper: 2, start: 0.5}}
      cost: "-(x1 - 0.5)**2 + 0.1*x1*x2"
    - name: p2
      variables: {x2: {start: 0}}
      cost: "(x2 - 1)**2"
"""


def test_a_polished_local_solve_started_at_a_concave_players_maximum_descends_to_a_bound(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """p1's cost is concave on [-1, 2]: its stationary point x1 = 0.55 (x2 = 1) is its maximum, its minima are the
    bounds (the lower one the lowest). A local solve started there leaves it for the lower bound: Newton steps polish
    only where p1's block of the barrier matrix needs no shift; without that condition they polish the iterate back to
    the maximum, a KKT point of p1's problem."""
    from gnerun.solvers import interior_point
    from gnerun.solvers.certificate import NewtonResponses

    cfg = load_config(text=CONCAVE_BOX)
    game = compile_game(cfg)
    a = np.array([0.55, 1.0])
    (end, converged), = NewtonResponses(cfg, game).solve_from(0, a, None, [a[:1]])
    assert converged and end[0] == pytest.approx(-1.0, abs=1e-9)
    game.derived.pop("response_solvers", None)
    monkeypatch.setattr(interior_point.InteriorPoint, "convex_at", lambda self, it, parts: True)
    (end, converged), = NewtonResponses(cfg, game).solve_from(0, a, None, [a[:1]])
    assert converged and end[0] == pytest.approx(0.55, abs=1e-9)


@pytest.mark.slow
def test_a_large_players_gain_is_found_from_its_best_compared_points(monkeypatch: pytest.MonkeyPatch) -> None:
    """The 6-robot formation from draw 7 of seed 1 (benchmarks/problems/formation.py: 26 decisions per robot, checked
    "over N starts"): the solve ends converged only where the independent check (SLSQP from each robot's plan and
    three random ones) finds no robot that gains alone. Without local solves from a large player's best compared
    points, it ended converged at a point where robot 4 gains 2e-3 alone (7e-5 of its cost)."""
    from benchmarks.problems import formation
    from gnerun.runs.solving import certified_solve, make_solver
    from gnerun.solvers import certificate as cert_module
    from gnerun.solvers.certificate import NewtonResponses

    problem = formation.formation_problems(8)[7]
    cfg = load_config(text=problem.config_yaml)

    def solved() -> tuple[str, float]:
        game = compile_game(cfg)
        solver = make_solver(cfg, game)
        out = certified_solve(game, solver, solver.init(), None, responses=NewtonResponses(cfg, game))
        a = out.state.z[: game.n]
        scale = np.maximum(1.0, np.abs(game.costs(a)))
        gaps = np.array(list(problem.best_response_gaps(a).values()))
        return out.status, float(np.max(gaps / scale))

    status, gap = solved()
    assert status != "converged" or gap <= cert_module.GAP_TOL
    monkeypatch.setattr(cert_module, "LOCAL_FROM_DESIGN_LARGE", 0)
    status, gap = solved()
    assert status == "converged" and gap > 10 * cert_module.GAP_TOL  # the false certificate they prevent
