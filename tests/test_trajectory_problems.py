"""The trajectory-game benchmarks (benchmarks/problems/trajectory.py): ALGAMES's ramp merge and T-intersection,
MCPTrajectoryGameSolver.jl's demo and the two-car overtaking game as gnerun configs, checked against their independent
numpy models."""

from __future__ import annotations

import dataclasses
import math
from functools import cache

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import gnerun
from benchmarks.problems.trajectory import (
    MERGE_PUBLISHED,
    NOISE_PER_PLAYER,
    GameModel,
    intersection_initial_states,
    intersection_model,
    intersection_problems,
    mcp_demo_model,
    mcp_demo_problem,
    merge_initial_states,
    merge_model,
    merge_problems,
    overtaking_model,
    overtaking_problems,
    planar_double_integrator_step,
    unicycle_rk3_step,
    unicycle_rk4_step,
)
from gnerun.runs.solving import certified_solve

MERGE_X0 = np.array([-0.80, -0.05, 0.0, 0.90, -1.00, -0.05, 0.0, 0.90, -0.90, -0.30, math.pi / 12, 0.95])
INTERSECTION_X0 = np.array([-0.50, -0.15, 0.0, 0.60, 1.40, 0.15, math.pi, 0.60, 0.43, -0.30, math.pi / 2, 0.10])


@cache
def _cases() -> tuple[tuple[str, str, GameModel], ...]:
    """(label, config text, numpy model) for one merge, one intersection, the MCP demo and the overtaking game."""
    merge = merge_problems(1, seed=3)[0]
    inter = intersection_problems(1, seed=4)[0]
    return (
        ("merge", merge.config_yaml, merge_model(merge_initial_states(1, seed=3)[0])),
        ("intersection", inter.config_yaml, intersection_model(intersection_initial_states(1, seed=4)[0])),
        ("mcp-demo", mcp_demo_problem().config_yaml, mcp_demo_model()),
        ("overtaking", overtaking_problems()[0].config_yaml, overtaking_model()),
    )


@cache
def _compiled(label: str):
    text = {c[0]: c[1] for c in _cases()}[label]
    return gnerun.compile_game(gnerun.load_config(text=text))


LABELS = ("merge", "intersection", "mcp-demo", "overtaking")


def _model(label: str) -> GameModel:
    return {c[0]: c[2] for c in _cases()}[label]


def test_every_config_loads_as_a_dynamic_game_without_solver_block():
    problems = merge_problems(4, seed=1) + intersection_problems(2, seed=1) + [mcp_demo_problem()]
    for p in problems:
        assert "\nsolver:" not in p.config_yaml
        cfg = gnerun.load_config(text=p.config_yaml)
        g = cfg.game
        assert g.kind == "dynamic"
        assert g.equilibrium == "variational"
        assert cfg.solver.kind == "ssn"  # gnerun's default, untouched
        for agent in g.agents:
            assert all(v.start == 0 for v in agent.inputs.values())
        for text in [*g.dynamics.values(), *(a.stage_cost for a in g.agents), *g.shared_constraints]:
            assert len(text) < 20_000
    horizons = {p.family: gnerun.load_config(text=p.config_yaml).game.horizon for p in problems}
    assert horizons == {"merge": 19, "intersection": 39, "mcp-demo": 8}  # N = 21, N = 41, MCP horizon 10
    n_shared = {p.family: len(gnerun.load_config(text=p.config_yaml).game.shared_constraints) for p in problems}
    assert n_shared == {"merge": 3, "intersection": 3, "mcp-demo": 1}  # every pair


@pytest.mark.parametrize("label", LABELS)
def test_compiled_dynamics_equal_the_numpy_integrator(label):
    game, model = _compiled(label), _model(label)
    rng = np.random.default_rng(7)
    nu = model.n // (model.horizon + 1)
    for _ in range(25):
        x = rng.normal(size=game.nx) * 2
        u = rng.normal(size=nu) * 2
        np.testing.assert_allclose(game.step_dynamics(x, u), model.step(x, u), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("label", LABELS)
def test_compiled_costs_equal_the_sources_costs(label):
    """gnerun's sum over stages of l(xi(tau+1), a(tau)) + Psi equals the source's objective in the source's own
    indexing (ALGAMES: states before each input, Qf on the last; MCP: X_1..X_10 with U_10 = 0)."""
    game, model = _compiled(label), _model(label)
    rng = np.random.default_rng(11)
    for scale in (0.0, 0.3, 1.5):
        a = scale * rng.normal(size=game.n)
        np.testing.assert_allclose(game.costs(a, model.x0), model.costs(a), rtol=1e-11, atol=1e-12)


@pytest.mark.parametrize("label", LABELS)
def test_compiled_constraints_equal_the_numpy_constraints(label):
    """Every constraint row, compared as a multiset of values at random inputs (c <= 0 in gnerun, g >= 0 here). The
    rows are the same at every stage, so a 4-stage copy of each game suffices (gnerun builds the dense KKT
    derivatives of the 40-stage intersection on first use, which takes seconds)."""
    text = {c[0]: c[1] for c in _cases()}[label]
    game = gnerun.compile_game(gnerun.load_config(text=text, overrides={"game.horizon": 3}))
    model = dataclasses.replace(_model(label), horizon=3)
    rng = np.random.default_rng(5)
    for scale in (0.3, 2.0):
        a = scale * rng.normal(size=game.n)
        c = game.kkt_parts(np.concatenate([a, np.zeros(game.m)]), model.x0)[1]
        g = model.constraint_values(a)
        assert c.shape == g.shape
        np.testing.assert_allclose(np.sort(-c), np.sort(g), atol=1e-12)


def _segment(P: np.ndarray, b1, b2, v) -> np.ndarray:
    """ALGAMES's BoundaryConstraint (src/utils/constraints.jl): (p - b1).v where p projects strictly inside the
    segment b1 -> b2, else 0; <= 0 is feasible."""
    b1, b2, v = (np.asarray(q, dtype=float) for q in (b1, b2, v))
    inside = ((P - b1) @ (b2 - b1) > 0) & ((P - b2) @ (b1 - b2) > 0)
    return np.where(inside, (P - b1) @ v, 0.0)


def _circle(P: np.ndarray, c, r) -> np.ndarray:
    """TrajectoryOptimization's CircleConstraint: r^2 - |p - c|^2 <= 0 is feasible."""
    return r * r - np.sum((P - np.asarray(c)) ** 2, axis=1)


def _rounded(P: np.ndarray, p1, p2, p3, r) -> list[np.ndarray]:
    """ALGAMES's add_rounded_boundary_constraints: two segments and a circle."""
    p1, p2, p3 = (np.asarray(q, dtype=float) for q in (p1, p2, p3))
    x = (p1 - p2) / np.linalg.norm(p1 - p2)
    y = (p3 - p2) / np.linalg.norm(p3 - p2)
    return [_segment(P, p1, p2 + r * x, y), _segment(P, p2 + r * y, p3, x), _circle(P, p2 + r * (x + y), r)]


def _same_feasible_set(model: GameModel, player: int, published: list[np.ndarray], P: np.ndarray) -> None:
    X = np.zeros((P.shape[0], 1, model.x0.size))
    X[:, 0, 4 * player], X[:, 0, 4 * player + 1] = P[:, 0], P[:, 1]
    ours = np.min([c.values(X)[:, 0] for c in model.own[player]], axis=0)
    theirs = np.max(published, axis=0)
    clear = (np.abs(ours) > 1e-9) & ((theirs == 0) | (np.abs(theirs) > 1e-9))  # off every boundary
    assert clear.sum() > 0.9 * P.shape[0]
    np.testing.assert_array_equal((ours >= 0)[clear], (theirs <= 0)[clear])
    assert 0.05 < np.mean(ours >= 0) < 0.95  # both sides sampled


def test_merge_road_edges_have_the_published_feasible_set():
    """monte_carlo_sampling.jl: MergingScenario(6.20, 0.34, 3.2, pi/12), radius 0.08 (merging.jl's three segments)."""
    l0, l2, ramp, ang = 0.34 / 2 - 0.08, 3.1, 3.2, math.pi / 12
    delta = ramp / math.cos(ang) * math.sin(ang)
    b1, b2, b3, b4, b5 = (-l2, l0), (l2, l0), (l2, -l0), (-l2 + ramp, -l0), (-l2, -l0 - delta)
    P = np.random.default_rng(0).uniform([-2.5, -1.0], [2.5, 0.4], size=(20000, 2))
    published = [_segment(P, b1, b2, (0, 1)), _segment(P, b3, b4, (0, -1)),
                 _segment(P, b4, b5, (math.sin(ang), -math.cos(ang)))]
    for player in range(3):
        _same_feasible_set(merge_model(), player, published, P)


def test_intersection_boundaries_have_the_published_feasible_set():
    """3_player_intersection.jl: TIntersectionScenario(4.0, 0.60, 1.0, 0.25, corner radius 0.05), radius 0.08,
    lanes 1, 2, 5 (t_intersection.jl's landmarks and boundaries)."""
    l0, l1, l2, l3, l4, l5, l6 = 0.08, 0.22, 2.0, 1.3, 0.38, 0.47, 0.30
    P = np.random.default_rng(1).uniform([-1.0, -1.0], [1.0, 0.6], size=(20000, 2))
    lanes = {
        0: [_segment(P, (-l2, -l0), (l2, -l0), (0, 1)),
            *_rounded(P, (-l2, -l1), (-l1, -l1), (-l1, -l3), 0.05),
            *_rounded(P, (-l0, -l3), (-l0, -l1), (l2, -l1), 0.05)],
        1: [_segment(P, (-l2, l1), (l2, l1), (0, 1)),
            *_rounded(P, (-l2, l0), (-l1, l0), (-l1, -l3), 0.05),
            *_rounded(P, (-l0, -l3), (-l0, l0), (l2, l0), 0.05)],
        2: [_segment(P, (l4, l6), (l4, -l6), (-1, 0)), _segment(P, (l5, l6), (l5, -l6), (1, 0))],
    }
    for player, published in lanes.items():
        _same_feasible_set(intersection_model(), player, published, P)
    # and near the rounded corners, where the circles decide
    Q = np.random.default_rng(2).uniform([-0.35, -0.35], [0.05, 0.15], size=(20000, 2))
    for player, published in ((0, _rounded(Q, (-l2, -l1), (-l1, -l1), (-l1, -l3), 0.05)
                               + _rounded(Q, (-l0, -l3), (-l0, -l1), (l2, -l1), 0.05)),
                              (1, _rounded(Q, (-l2, l0), (-l1, l0), (-l1, -l3), 0.05)
                               + _rounded(Q, (-l0, -l3), (-l0, l0), (l2, l0), 0.05))):
        model = intersection_model()
        X = np.zeros((Q.shape[0], 1, 12))
        X[:, 0, 4 * player], X[:, 0, 4 * player + 1] = Q[:, 0], Q[:, 1]
        ours = np.min([c.values(X)[:, 0] for c in model.own[player][1:]], axis=0)
        theirs = np.max(published, axis=0)
        clear = (np.abs(ours) > 1e-9) & ((theirs == 0) | (np.abs(theirs) > 1e-9))  # off every boundary
        np.testing.assert_array_equal((ours >= 0)[clear], (theirs <= 0)[clear])


@pytest.mark.parametrize("label", ("merge", "intersection"))
def test_violated_road_constraints_have_a_gradient(label):
    """Wherever a road constraint is violated its value still changes with the position (Newton needs a
    direction back), unlike ALGAMES's segments, which are 0 outside their range."""
    model = _model(label)
    rng = np.random.default_rng(9)
    P = rng.uniform([-1.5, -1.2], [1.5, 0.6], size=(5000, 2))
    for player, own in enumerate(model.own):
        X = np.zeros((P.shape[0], 1, 12))
        X[:, 0, 4 * player], X[:, 0, 4 * player + 1] = P[:, 0], P[:, 1]
        for c in own:
            v = c.values(X)[:, 0]
            bad = v < -1e-6
            for d in ((1e-7, 0.0), (0.0, 1e-7)):
                Xd = X.copy()
                Xd[:, 0, 4 * player] += d[0]
                Xd[:, 0, 4 * player + 1] += d[1]
                if d == (1e-7, 0.0):
                    moved = np.abs(c.values(Xd)[:, 0] - v) > 1e-12
                else:
                    moved |= np.abs(c.values(Xd)[:, 0] - v) > 1e-12
            assert np.all(moved[bad]), f"{label}: {c.expr()} is flat where violated"


def test_the_mcp_demo_costs_by_hand():
    """At zero inputs nobody moves: each player pays |x0 - g|^2 = 2^2 + 0.1^2 at X_1..X_10."""
    game = _compiled("mcp-demo")
    np.testing.assert_allclose(game.costs(np.zeros(game.n), mcp_demo_model().x0), [40.1, 40.1], rtol=1e-14)


def test_unicycle_step_is_a_third_order_runge_kutta_step_of_the_published_ode():
    def ode(_t, s, u):
        out = np.empty_like(s)
        out[0::4] = s[3::4] * np.cos(s[2::4])
        out[1::4] = s[3::4] * np.sin(s[2::4])
        out[2::4], out[3::4] = u[0::2], u[1::2]
        return out

    rng = np.random.default_rng(2)
    x, u = rng.normal(size=12), rng.normal(size=6)
    errors = []
    for dt in (0.15, 0.075):
        exact = solve_ivp(ode, (0, dt), x, args=(u,), rtol=1e-13, atol=1e-13).y[:, -1]
        errors.append(np.max(np.abs(unicycle_rk3_step(x, u, dt) - exact)))
    # Kutta's RK3 (nodes 0, 1/2, 1; weights 1/6, 4/6, 1/6) integrates th and v (linear in t) exactly, so the
    # positions get Simpson's rule of v(t) cos th(t): local error O(dt^5), a ratio of 32 when dt halves
    assert errors[0] < 1e-6
    assert 24 < errors[0] / errors[1] < 40
    dt = 0.15
    th = lambda t: x[2::4] + u[0::2] * t  # noqa: E731
    v = lambda t: x[3::4] + u[1::2] * t  # noqa: E731
    simpson = [dt / 6 * (f(0) + 4 * f(dt / 2) + f(dt)) for f in (lambda t: v(t) * np.cos(th(t)),
                                                                   lambda t: v(t) * np.sin(th(t)))]
    step = unicycle_rk3_step(x, u, dt)
    np.testing.assert_allclose(step[0::4], x[0::4] + simpson[0], rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(step[1::4], x[1::4] + simpson[1], rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(step[2::4], th(dt), rtol=1e-15)
    np.testing.assert_allclose(step[3::4], v(dt), rtol=1e-15)


def test_double_integrator_step_is_exact_zero_order_hold():
    rng = np.random.default_rng(3)
    x, u = rng.normal(size=8), rng.normal(size=4)
    out = planar_double_integrator_step(x, u, 0.1)
    for i in range(2):
        p, v, acc = x[4 * i:4 * i + 2], x[4 * i + 2:4 * i + 4], u[2 * i:2 * i + 2]
        np.testing.assert_allclose(out[4 * i:4 * i + 2], p + 0.1 * v + 0.005 * acc, rtol=1e-15)
        np.testing.assert_allclose(out[4 * i + 2:4 * i + 4], v + 0.1 * acc, rtol=1e-15)


@pytest.mark.parametrize("label", ("merge", "intersection"))
def test_first_stage_positions_depend_on_the_first_input(label):
    """RK3 makes x(1)'s position depend on u(0): the constraints at tau = 0 are Newton rows."""
    model = _model(label)
    a = np.zeros(model.n)
    base = model.rollout(a)[1]
    a[0] = 1.0  # player 1's turn rate at stage 0
    a[1] = 1.0  # and its acceleration
    moved = model.rollout(a)[1]
    assert abs(moved[0] - base[0]) > 1e-4 and abs(moved[1] - base[1]) > 1e-4


@pytest.mark.parametrize("draw", (merge_initial_states, intersection_initial_states))
def test_initial_states_are_reproducible_and_differ_across_seeds(draw):
    first, again, other = draw(12, seed=5), draw(12, seed=5), draw(12, seed=6)
    assert all(np.array_equal(x, y) for x, y in zip(first, again, strict=True))
    assert not any(np.allclose(x, y) for x, y in zip(first, other, strict=True))
    assert all(np.array_equal(x, y) for x, y in zip(draw(4, seed=5), first, strict=False))  # a prefix
    assert len({x.tobytes() for x in first}) == 12


@pytest.mark.parametrize(("draw", "nominal"), ((merge_initial_states, MERGE_X0),
                                               (intersection_initial_states, INTERSECTION_X0)))
def test_initial_states_stay_in_the_published_noise_box_and_fill_it(draw, nominal):
    X = np.array(draw(300, seed=0))
    half = np.tile(NOISE_PER_PLAYER, 3) / 2
    dev = X - nominal
    assert np.all(np.abs(dev) <= half + 1e-15)
    assert np.all(dev.max(axis=0) > 0.8 * half) and np.all(dev.min(axis=0) < -0.8 * half)


def test_merge_draws_that_collide_are_drawn_again():
    """Cars 1 and 2 start 0.2 apart on the same lane, within +-0.03: some raw draws put them closer than 0.16."""
    X = np.array(merge_initial_states(400, seed=0))
    d12 = np.hypot(X[:, 0] - X[:, 4], X[:, 1] - X[:, 5])
    assert d12.min() >= 0.16
    rng = np.random.default_rng(0)
    raw = MERGE_X0 + (rng.random((400, 12)) - 0.5) * np.tile(NOISE_PER_PLAYER, 3)
    assert np.hypot(raw[:, 0] - raw[:, 4], raw[:, 1] - raw[:, 5]).min() < 0.16


def test_problem_fields():
    merges = merge_problems(2, seed=0)
    assert [p.family for p in merges] == ["merge", "merge"]
    assert merges[0].name != merges[1].name and merges[0].config_yaml != merges[1].config_yaml
    assert all(p.reference is None and p.best_response_gaps is not None for p in merges)
    assert "960 of 1000" in merges[0].published["ALGAMES solve time, 1000 random merges"]
    assert MERGE_PUBLISHED == merges[0].published
    inter, demo = intersection_problems(1)[0], mcp_demo_problem()
    assert inter.family == "intersection" and demo.family == "mcp-demo"
    assert "pedestrian" in inter.config_yaml


def test_best_response_gaps_see_that_zero_inputs_are_no_equilibrium():
    gaps = mcp_demo_model().best_response_gaps(np.zeros(mcp_demo_model().n))
    assert set(gaps) == {"player1", "player2"}
    assert min(gaps.values()) > 1.0  # standing still 2 m from the goal: moving towards it pays


def test_best_response_gaps_are_infinite_at_an_infeasible_point():
    model = mcp_demo_model()
    a = np.zeros(model.n)
    a[0::2][: model.horizon + 1] = 50.0  # player 1 accelerates through player 2 and out of the arena
    gaps = model.best_response_gaps(a)
    assert gaps["player1"] == math.inf


def test_an_equilibrium_gnerun_finds_passes_the_independent_check():
    """From a start where player 1 swerves up and player 2 down, gnerun's certified solve (semismooth Newton, and
    restarts from best responses at a KKT point where a player can improve alone) ends on the MCP demo at a point
    where the numpy best responses find nothing better for either player."""
    problem, model = mcp_demo_problem(), mcp_demo_model()
    cfg = gnerun.load_config(text=problem.config_yaml)
    game = gnerun.compile_game(cfg)
    H = model.horizon + 1
    a = np.zeros(game.n)
    swerve = np.where(np.arange(H) < H // 2, 1.0, -1.0)
    a[0:2 * H:2], a[1:2 * H:2] = 2.0, swerve
    a[2 * H::2], a[2 * H + 1::2] = -2.0, -swerve
    solver = gnerun.make_solver(cfg, game)
    outcome = certified_solve(game, solver, solver.init(np.concatenate([a, np.zeros(game.m)]), game.x0), game.x0)
    state = outcome.state
    assert state.status == "converged" and not outcome.improving and state.residual_norm <= 1e-10
    solution = state.z[: game.n]
    assert model.constraint_values(solution).min() >= -1e-9
    gaps = problem.best_response_gaps(solution)
    assert max(gaps.values()) < 1e-6
    X = model.rollout(solution)
    # they swerve past each other on opposite sides (which side is which depends on the restart)
    assert X[-1, 1] * X[-1, 5] < 0 and min(abs(X[-1, 1]), abs(X[-1, 5])) > 0.3


def test_the_head_on_stop_is_no_equilibrium():
    """Both players brake to a stop 1 apart on the line between them (feasible, the collision row active at the last
    stage): each one's goal lies behind the other, and going round the other player pays."""
    model = mcp_demo_model()
    H = model.horizon + 1
    # player 1 moves right and player 2 left at constant deceleration so that they stop 1 apart at x = -+0.5
    # (p(T+1) = p0 + sum_k (T + 1 - k + 1/2) dt^2 u_k for constant u: solve for the constant acceleration)
    weights = np.array([(H - k - 0.5) * 0.01 for k in range(H)])
    acc = 0.5 / weights.sum()
    a = np.zeros(model.n)
    a[0:2 * H:2], a[2 * H::2] = acc, -acc
    X = model.rollout(a)
    assert abs(X[-1, 0] + 0.5) < 1e-12 and abs(X[-1, 4] - 0.5) < 1e-12
    gaps = model.best_response_gaps(a)
    assert min(gaps.values()) > 0.1


def test_unicycle_rk4_step_is_a_fourth_order_runge_kutta_step_of_the_ode():
    """Local error O(dt^5) against an accurate solution of the ODE (a ratio of 32 when dt halves), and th, v (linear
    in t) exact."""
    def ode(_t, s, u):
        out = np.empty_like(s)
        out[0::4] = s[3::4] * np.cos(s[2::4])
        out[1::4] = s[3::4] * np.sin(s[2::4])
        out[2::4], out[3::4] = u[0::2], u[1::2]
        return out

    rng = np.random.default_rng(4)
    x, u = rng.normal(size=8), rng.normal(size=4)
    errors = []
    for dt in (0.2, 0.1):
        exact = solve_ivp(ode, (0, dt), x, args=(u,), rtol=1e-13, atol=1e-13).y[:, -1]
        errors.append(np.max(np.abs(unicycle_rk4_step(x, u, dt) - exact)))
    assert errors[0] < 1e-5
    assert 24 < errors[0] / errors[1] < 40
    step = unicycle_rk4_step(x, u, 0.2)
    np.testing.assert_allclose(step[2::4], x[2::4] + 0.2 * u[0::2], rtol=1e-15)
    np.testing.assert_allclose(step[3::4], x[3::4] + 0.2 * u[1::2], rtol=1e-15)


def test_the_overtaking_problems():
    """Two cars, T = 12 (52 decisions), each car's two road edges and the shared collision row at 13 stages (65
    rows), an RK4 ode; zero inputs first, then three other starts; at zero inputs the cars coincide at x(4) (car 1
    closes 0.5 per second on a gap of 0.4), so the start violates the collision row there by the whole 0.16^2."""
    problems = overtaking_problems()
    assert [p.family for p in problems] == ["overtaking"] * 4
    assert len({p.start for p in problems}) == 4 and problems[0].start.startswith("u = 0")
    starts = []
    for p in problems:
        cfg = gnerun.load_config(text=p.config_yaml)
        g = cfg.game
        assert "\nsolver:" not in p.config_yaml and cfg.solver.globalization == "auto"
        assert g.horizon == 12 and g.equilibrium == "variational" and g.dynamics.integrator == "rk4"
        game = gnerun.compile_game(cfg)
        assert (game.n, game.m) == (52, 65)
        starts.append(game.a_start)
        assert p.best_response_gaps is not None and p.reference is None
    assert not starts[0].any() and all(s.any() for s in starts[1:])
    model = overtaking_model()
    X = model.rollout(np.zeros(model.n))
    assert np.hypot(X[4, 0] - X[4, 4], X[4, 1] - X[4, 5]) == pytest.approx(0.0, abs=1e-12)
    assert model.constraint_values(np.zeros(model.n)).min() == pytest.approx(-0.16 ** 2, abs=1e-12)


def test_the_overtaking_costs_by_hand():
    """At zero inputs each car keeps its lane centre, heading 0 and its desired speed: both costs are zero. Car 1
    accelerating at 0.5 during stage 0 only then drives straight at 1.1: 13 stages of dt 0.1^2, dt 0.1 0.5^2 for the
    input and 10 dt 0.1^2 at the end, 0.026 + 0.005 + 0.02."""
    game = _compiled("overtaking")
    np.testing.assert_allclose(game.costs(np.zeros(game.n)), [0.0, 0.0], atol=1e-15)
    a = np.zeros(game.n)
    a[1] = 0.5
    np.testing.assert_allclose(game.costs(a), [0.051, 0.0], rtol=1e-13, atol=1e-15)


def test_the_overtaking_game_from_zero_inputs_converges_and_is_certified():
    """The default solver (``globalization: auto``) from zero inputs: converged, which ``gnerun.solve`` reports only
    for a point its own certificate confirms; and the independent numpy model's best responses (SLSQP from three
    starts per car) find nothing better for either car. Car 1 passes car 2 and both keep the road."""
    problem, model = overtaking_problems()[0], overtaking_model()
    res = gnerun.solve(gnerun.load_config(text=problem.config_yaml), out=None)
    assert res.status == "converged", res.message
    assert res.residual_norm <= 1e-10
    assert max(res.certificate["best_response_gap"].values()) <= 1e-6
    a = res.z[: model.n]
    assert model.constraint_values(a).min() >= -1e-9
    gaps = problem.best_response_gaps(a)
    costs = model.costs(a)
    assert all(gap <= 1e-6 * max(1.0, abs(cost)) for gap, cost in zip(gaps.values(), costs, strict=True)), gaps
    X = model.rollout(a)
    assert X[-1, 0] > X[-1, 4] + 0.16  # car 1 ends ahead of car 2
