"""Semismooth Newton: known solutions, convergence order, perturbations, statuses, step-wise API."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gnerun.game.compile import KKTParts, compile_game
from gnerun.language.config import load_config
from gnerun.runs.solving import iterate, make_solver, solve
from gnerun.solvers.ssn import SemismoothNewton, Status

from .conftest import CONFIGS

KNOWN = {
    # config: (solution by variable, reference)
    "harker.yaml": {"x1": 5.0, "x2": 9.0},  # Harker (1991): the GNE reached from (0, 0), also the VE
    "fk_a11.yaml": {"x1": 0.75, "x2": 0.25},  # Facchinei-Kanzow A.11, variational equilibrium
    "fk_a12.yaml": {"x1": 16 / 3, "x2": 16 / 3},  # Facchinei-Kanzow A.12, the NE
}


def _values(solution: dict) -> dict[str, float]:
    return {v: val for agent in solution.values() for v, val in agent.items()}


@pytest.mark.parametrize("complementarity", ["min", "fischer_burmeister"])
@pytest.mark.parametrize("name", sorted(KNOWN))
def test_static_games_reach_known_solutions(name: str, complementarity: str) -> None:
    cfg = load_config(CONFIGS / name, {"solver.complementarity": complementarity})
    res = solve(cfg)
    assert res.status == "converged", res.message
    got = _values(res.solution)
    for var, expected in KNOWN[name].items():
        assert got[var] == pytest.approx(expected, abs=1e-8)
    assert res.residual_norm <= cfg.solver.tol


def test_fk_a11_common_multiplier_is_one_half() -> None:
    # 2(x1 - 1) + mu = 0, 2(x2 - 1/2) + mu = 0, x1 + x2 = 1  =>  mu = 1/2
    res = solve(load_config(CONFIGS / "fk_a11.yaml"))
    assert res.multipliers["shared"] == pytest.approx([0.5], abs=1e-10)


def test_paper_study1_converges_within_the_papers_seven_iterations() -> None:
    cfg = load_config(CONFIGS / "paper_study1.yaml")
    res = solve(cfg)
    assert res.status == "converged", res.message
    assert res.iterations <= 7
    assert res.residual_norm <= 1e-12
    assert np.all(np.asarray(res.z) == res.z)  # finite
    gaps = res.certificate["best_response_gap"]
    assert all(abs(g) <= 1e-8 for g in gaps.values()), gaps
    # the paper's constraints hold at the solution: u1 + u2 + u3 <= 1, u2 <= 1/2, u3 >= u1 + u2, u3 >= 0
    u1, u2, u3 = (np.array(res.solution[f"agent{i}"][f"u{i}"]) for i in (1, 2, 3))
    assert np.all(u1 + u2 + u3 <= 1 + 1e-12)
    assert np.all(u2 <= 0.5 + 1e-12)
    assert np.all(u3 >= u1 + u2 - 1e-12)
    assert np.all(u3 >= -1e-12)


def test_paper_study1_every_jacobian_is_well_conditioned() -> None:
    # NUMERICS §1: after the first step agent 3's constraint sits at a degenerate tie; the tie rule must
    # choose the multiplier row (condition ~160), not the g-row (condition ~4e17).
    cfg = load_config(CONFIGS / "paper_study1.yaml")
    game = compile_game(cfg)
    solver = SemismoothNewton(game, cfg.solver)
    state = solver.init()
    for _ in range(3):
        J = solver.jacobian(state.parts, state.z, state.active)
        assert np.linalg.cond(J) < 1e6
        state = solver.step(state)
    assert state.residual_norm <= 1e-12


def test_tie_takes_the_multiplier_row() -> None:
    cfg = load_config(CONFIGS / "fk_a12.yaml")
    game = compile_game(cfg)
    solver = SemismoothNewton(game, cfg.solver)
    n, m = game.n, game.m
    z = np.zeros(n + m)
    c = np.zeros(m)
    c[0] = -3e-17  # -g = 3e-17, lambda = 0: a tie within tie_tol
    c[1] = 0.5  # -g = -0.5 < lambda = 0: g-branch
    c[2] = -2.0  # -g = 2 > lambda = 0: multiplier row
    c[3] = -1e-9  # -g = 1e-9 > tie_tol: multiplier row
    dc = np.arange(1.0, m * n + 1).reshape(m, n)
    parts = KKTParts(np.zeros(n), c, np.eye(n, n + m), dc)
    phi, active = solver.residual(parts, z)
    J = solver.jacobian(parts, z, active)
    assert list(active) == [False, True, False, False]
    np.testing.assert_array_equal(J[n + 0], np.eye(n + m)[n + 0])
    np.testing.assert_array_equal(J[n + 1, :n], -dc[1])
    np.testing.assert_array_equal(J[n + 1, n:], 0.0)
    np.testing.assert_array_equal(J[n + 2], np.eye(n + m)[n + 2])
    assert phi[n + 1] == -0.5


def _errors(res) -> list[float]:
    return [e for e in res.error_history if e > 0]


def test_convergence_order_is_quadratic_on_a_nonlinear_gne() -> None:
    cfg = load_config(CONFIGS / "nonlinear_gne.yaml")
    res = solve(cfg)
    assert res.status == "converged"
    # the coupled constraint x1^2 + x2^2 <= r^2 is active: a genuine GNE
    assert res.multipliers["p1"][2] > 0.1
    e = _errors(res)
    assert len(e) >= 4
    orders = [math.log(e[k + 1] / e[k]) / math.log(e[k] / e[k - 1]) for k in range(1, len(e) - 1)
              if e[k + 1] > 1e-14]
    # the last ratios measure the asymptotic order
    assert max(orders[-2:]) >= 1.8, orders
    assert orders[-1] >= 1.8, orders


def test_fischer_burmeister_converges_quadratically_too() -> None:
    cfg = load_config(CONFIGS / "nonlinear_gne.yaml", {"solver.complementarity": "fischer_burmeister"})
    res = solve(cfg)
    assert res.status == "converged"
    ref = solve(load_config(CONFIGS / "nonlinear_gne.yaml"))
    np.testing.assert_allclose(res.z, ref.z, atol=1e-10)


def _trajectory(overrides: dict) -> np.ndarray:
    cfg = load_config(CONFIGS / "paper_study1.yaml", overrides)
    game = compile_game(cfg)
    solver = make_solver(cfg, game)
    states = []
    iterate(solver, solver.init(), on_iterate=states.append)
    return np.array([s.z for s in states])


def test_jacobian_noise_is_reproducible_by_seed() -> None:
    base = {"disturbance.kind": "jacobian_noise", "disturbance.scale": 1e-3, "solver.max_iter": 6,
            "solver.tol": 1e-300}
    a = _trajectory({**base, "disturbance.seed": 7})
    b = _trajectory({**base, "disturbance.seed": 7})
    c = _trajectory({**base, "disturbance.seed": 8})
    clean = _trajectory({"solver.max_iter": 6, "solver.tol": 1e-300})
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    assert a.shape == clean.shape
    assert np.max(np.abs(a[2:] - clean[2:])) > 1e-8  # the noise does perturb the iterates


def test_jacobian_noise_slows_but_does_not_stop_convergence() -> None:
    # ISS: noise on JPhi leaves z* a fixed point; the iterates still converge, at a linear rate
    res = solve(load_config(CONFIGS / "paper_study1_disturbed.yaml"))
    clean = solve(load_config(CONFIGS / "paper_study1.yaml"))
    assert res.status == "converged"
    assert res.iterations > clean.iterations
    np.testing.assert_allclose(res.z, clean.z, atol=1e-10)


@pytest.mark.parametrize("distribution", ["normal", "uniform"])
def test_residual_disturbance_has_the_given_norm(distribution: str) -> None:
    scale = 1e-4
    cfg = load_config(CONFIGS / "nonlinear_gne.yaml", {"disturbance.kind": "residual", "disturbance.scale": scale,
                                                        "disturbance.distribution": distribution,
                                                        "solver.max_iter": 8, "solver.tol": 1e-300})
    game = compile_game(cfg)
    solver = make_solver(cfg, game)
    state = solver.init()
    clean = SemismoothNewton(game, cfg.solver)
    for _ in range(5):
        nxt = solver.step(state)
        # eq. inexact_seminewton: Phi(z^k) + JPhi(z^k)(z^{k+1} - z^k) = r^k with ||r^k|| = scale
        J = clean.jacobian(state.parts, state.z, state.active)
        r = state.phi + J @ (nxt.z - state.z)
        assert np.linalg.norm(r) == pytest.approx(scale, rel=1e-6)
        state = nxt
    # ISS: the error settles at the level of the disturbance, not at zero and not beyond
    ref = solve(load_config(CONFIGS / "nonlinear_gne.yaml"))
    err = np.linalg.norm(state.z - ref.z)
    assert 1e-8 * scale < err < 100 * scale


def test_step_is_exactly_one_iteration_and_a_solution_is_a_fixed_point() -> None:
    cfg = load_config(CONFIGS / "paper_study1.yaml")
    game = compile_game(cfg)
    solver = make_solver(cfg, game)
    state = solver.init()
    for k in range(1, 4):  # converged in 3 iterations
        state = solver.step(state)
        assert state.k == k
    assert solver.terminate(state) == (True, Status.CONVERGED)
    assert solver.step(state) is state  # a step at a solution keeps it (no new iterate)
    warm = solver.init(state.z)
    assert warm.k == 0 and solver.terminate(warm)[1] == Status.CONVERGED
    again = solver.step(warm)
    np.testing.assert_allclose(again.z, state.z, atol=1e-12)


def test_init_at_another_state_of_a_dynamic_game() -> None:
    cfg = load_config(CONFIGS / "paper_study1.yaml")
    game = compile_game(cfg)
    solver = make_solver(cfg, game)
    s0 = iterate(solver, solver.init(None, [1.0, 3.0, 5.0]))
    s1 = iterate(solver, solver.init(s0.z, [0.2, -0.4, 1.1]))
    assert s1.converged
    assert not np.allclose(s0.z, s1.z)
    with pytest.raises(ValueError):
        solver.init(None, [1.0, 2.0])


# --- statuses: failure is a status, never an exception -----------------------------------------

STATIC = """
name: t
game:
  kind: static
  agents:
    - name: p1
      variables: {{x1: {{start: {start}}}}}
      cost: "{cost}"
      constraints: {constraints}
    - name: p2
      variables: {{x2: {{start: 0}}}}
      cost: "(x2 - 1)**2"
solver: {{tol: 1.0e-12, max_iter: {max_iter}}}
"""


def _static(cost: str, constraints: str = "[]", start: float = 0.0, max_iter: int = 50, **over):
    return load_config(text=STATIC.format(cost=cost, constraints=constraints, start=start, max_iter=max_iter),
                       overrides=over)


def test_singular_jacobian_is_a_status_of_the_local_method() -> None:
    # the same constraint twice: when it is active, the multipliers are not unique and JPhi is singular
    res = solve(_static("(x1 - 2)**2", '["x1 <= 1", "x1 <= 1"]', **{"solver.globalization": "none"}))
    assert res.status == "singular_jacobian"
    assert "singular" in res.message and "step was not taken" in res.message


def test_the_default_method_solves_where_the_multipliers_are_not_unique() -> None:
    # x1 = 1 with any multipliers mu1 + mu2 = 2 (2 (x1 - 2) + mu1 + mu2 = 0): one of them, certified
    res = solve(_static("(x1 - 2)**2", '["x1 <= 1", "x1 <= 1"]'))
    assert res.status == "converged", res.message
    assert _values(res.solution)["x1"] == pytest.approx(1.0, abs=1e-10)
    assert sum(res.multipliers["p1"]) == pytest.approx(2.0, abs=1e-9) and min(res.multipliers["p1"]) >= 0


def test_plain_gne_with_a_shared_constraint_is_singular_for_the_local_method() -> None:
    # FK A.11 as a plain GNE: a continuum of equilibria; JPhi is singular where the constraint binds
    cfg = load_config(CONFIGS / "fk_a11.yaml", {"game.equilibrium": "generalized", "solver.globalization": "none"})
    res = solve(cfg)
    assert res.status == "singular_jacobian"
    assert "continuum of equilibria" in res.message


def test_nan_is_a_status() -> None:
    res = solve(_static("x1**2 - sqrt(x1)", start=-1.0))  # the gradient 2 x1 - 1/(2 sqrt(x1)) is NaN
    assert res.status == "nan"
    assert "not finite" in res.message and "p1" in res.message


def test_divergence_is_a_status() -> None:
    res = solve(load_config(CONFIGS / "fk_a12.yaml", {"solver.divergence_limit": 1.0}))
    assert res.status == "diverged"
    assert "divergence_limit" in res.message


def test_max_iter_is_a_status_and_not_converged() -> None:
    res = solve(load_config(CONFIGS / "nonlinear_gne.yaml", {"solver.max_iter": 2}))
    assert res.status == "max_iter"
    assert res.iterations == 2
    assert res.residual_norm > 1e-13
    assert not res.success


def test_line_search_rescues_a_start_outside_the_region_of_pure_convergence() -> None:
    over = {"game.agents.0.variables.x1.start": 0.0, "game.agents.1.variables.x2.start": 0.0}
    pure = solve(load_config(CONFIGS / "nonlinear_gne.yaml", {**over, "solver.globalization": "none"}))
    assert pure.status != "converged"
    globalised = solve(load_config(CONFIGS / "nonlinear_gne.yaml", {**over, "solver.globalization": "line_search"}))
    assert globalised.status == "converged"
    ref = solve(load_config(CONFIGS / "nonlinear_gne.yaml"))
    np.testing.assert_allclose(globalised.z, ref.z, atol=1e-10)


def test_equality_constraints() -> None:
    # p1: min (x1 - 2)^2 s.t. x1 + x2 == 1 (its own equality, involving p2's x2); p2: min (x2 - 1)^2
    # => x2 = 1, x1 = 0, multiplier mu with 2(x1 - 2) + mu = 0 => mu = 4
    cfg = _static("(x1 - 2)**2", '["x1 + x2 == 1"]')
    res = solve(cfg)
    assert res.status == "converged"
    assert _values(res.solution) == pytest.approx({"x1": 0.0, "x2": 1.0}, abs=1e-10)
    assert res.multipliers["p1"] == pytest.approx([4.0], abs=1e-10)
