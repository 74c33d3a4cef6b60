"""Josephy-Newton for Nash problems: published solutions, convergence order, ISS under perturbation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gnerun.errors import InputError
from gnerun.game.compile import compile_game
from gnerun.language.config import load_config
from gnerun.runs.closed_loop import simulate
from gnerun.runs.solving import iterate, make_solver, solve

from .conftest import CONFIGS, run_cli

# Murphy, Sherali & Soyster (1982), Table 1: the Cournot equilibrium to two decimals
COURNOT = [36.93, 41.82, 43.71, 42.66, 39.18]


@pytest.fixture(scope="module")
def cournot():
    return solve(load_config(CONFIGS / "cournot_mss.yaml"))


def test_cournot_matches_the_published_equilibrium(cournot) -> None:
    assert cournot.status == "converged"
    q = [cournot.solution[f"firm{i}"][f"q{i}"] for i in range(1, 6)]
    assert [round(v, 2) for v in q] == COURNOT
    assert cournot.certificate["kkt_residual"] <= 1e-10
    assert all(abs(g) <= 1e-8 for g in cournot.certificate["best_response_gap"].values())
    # self-consistency: each firm's first-order condition in closed form, Q the total output
    Q = sum(q)
    eta, c, b, K = 1.1, [10, 8, 6, 4, 2], [1.2, 1.1, 1.0, 0.9, 0.8], 5
    p = 5000 ** (1 / eta) * Q ** (-1 / eta)
    dp = -p / (eta * Q)
    for i in range(5):
        marginal_cost = c[i] + (K ** (-1 / b[i])) * q[i] ** (1 / b[i])
        assert p + q[i] * dp - marginal_cost == pytest.approx(0.0, abs=1e-10)


def test_cournot_converges_quadratically(cournot) -> None:
    e = [v for v in cournot.error_history if v > 1e-13]
    orders = [math.log(e[k + 1] / e[k]) / math.log(e[k] / e[k - 1]) for k in range(1, len(e) - 1)]
    assert orders[-1] >= 1.8, orders


def test_ssn_and_jn_agree_on_the_cournot_game(cournot) -> None:
    ssn = solve(load_config(CONFIGS / "cournot_mss.yaml", {"solver.kind": "ssn"}))
    np.testing.assert_allclose(ssn.a, cournot.a, atol=1e-9)


def test_semicopositive_remark_example() -> None:
    res = solve(load_config(CONFIGS / "semicopositive_ne.yaml"))
    assert res.status == "converged"
    assert res.solution == {"p1": {"x1": pytest.approx(3.0, abs=1e-12)}, "p2": {"x2": pytest.approx(1.0, abs=1e-12)}}
    # H is not monotone: its symmetric part is indefinite
    game = compile_game(load_config(CONFIGS / "semicopositive_ne.yaml"))
    _, H = game.pseudogradient(res.a)
    np.testing.assert_allclose(H, [[1.0, -3.0], [1.0, 0.0]])
    assert np.linalg.eigvalsh((H + H.T) / 2).min() < 0


@pytest.mark.parametrize("name", ["fk_a12.yaml", "fk_a11.yaml", "variational_gne.yaml"])
def test_jn_and_ssn_give_the_same_equilibrium(name: str) -> None:
    # fk_a11 and variational_gne are variational GNEs: JN on the joint feasible set equals SSN's solution
    jn = solve(load_config(CONFIGS / name, {"solver.kind": "jn"}))
    ssn = solve(load_config(CONFIGS / name, {"solver.kind": "ssn"}))
    assert jn.status == ssn.status == "converged"
    np.testing.assert_allclose(jn.z, ssn.z, atol=1e-10)
    if name == "variational_gne.yaml":  # the shared constraint binds: a common multiplier is positive
        assert max(jn.multipliers["shared"]) > 0.5


def test_perturbed_jn_error_grows_linearly_with_the_disturbance() -> None:
    # ISS (Theorem tm:ISS_pert_NE): the error settles at a level proportional to ||v||
    ref = solve(load_config(CONFIGS / "cournot_mss.yaml"))
    scales = [1e-7, 1e-6, 1e-5]
    levels = []
    for s in scales:
        cfg = load_config(CONFIGS / "cournot_mss.yaml", {"disturbance.kind": "pseudogradient",
                                                         "disturbance.scale": s, "disturbance.seed": 1,
                                                         "solver.tol": 1e-300, "solver.max_iter": 40})
        game = compile_game(cfg)
        solver = make_solver(cfg, game)
        states = []
        iterate(solver, solver.init(ref.z), on_iterate=states.append)
        errors = [np.linalg.norm(st.z[: game.n] - ref.a) for st in states[10:]]
        levels.append(float(np.mean(errors)))
    slope = np.polyfit(np.log10(scales), np.log10(levels), 1)[0]
    assert 0.85 <= slope <= 1.15, (levels, slope)


def test_pseudogradient_noise_is_reproducible() -> None:
    over = {"disturbance.kind": "pseudogradient", "disturbance.scale": 1e-3, "solver.max_iter": 5, "solver.tol": 1e-300}
    a = solve(load_config(CONFIGS / "cournot_mss.yaml", {**over, "disturbance.seed": 2}))
    b = solve(load_config(CONFIGS / "cournot_mss.yaml", {**over, "disturbance.seed": 2}))
    c = solve(load_config(CONFIGS / "cournot_mss.yaml", {**over, "disturbance.seed": 3}))
    np.testing.assert_array_equal(a.z, b.z)
    assert not np.array_equal(a.z, c.z)


def test_jn_refuses_generalized_nash_problems() -> None:
    with pytest.raises(InputError, match="involve other agents"):
        solve(load_config(CONFIGS / "paper_study1.yaml", {"solver.kind": "jn"}))
    with pytest.raises(InputError, match="its own multiplier"):
        solve(load_config(CONFIGS / "harker.yaml", {"solver.kind": "jn"}))
    with pytest.raises(InputError, match="polyhedral"):
        solve(load_config(CONFIGS / "nonlinear_gne.yaml", {"solver.kind": "jn", "game.agents.0.constraints": [
            "x1**2 <= 1"]}))
    proc = run_cli("validate", str(CONFIGS / "paper_study1.yaml"), "--set", "solver.kind=jn")
    assert proc.returncode == 2 and "generalized Nash problem" in proc.stderr and "Traceback" not in proc.stderr


def test_jn_closed_loop_equals_ssn_closed_loop() -> None:
    # the paper's dynamics with private constraints only: an NE problem at every sampling time
    over = {"game.agents.0.constraints": ["u1 <= 0.4"], "game.agents.2.constraints": ["u3 >= 0"],
            "run.K": [1, 10], "run.steps": 8}
    jn = simulate(load_config(CONFIGS / "paper_study2.yaml", {**over, "solver.kind": "jn"}))
    ssn = simulate(load_config(CONFIGS / "paper_study2.yaml", over))
    np.testing.assert_allclose(jn[10].x, ssn[10].x, atol=1e-10)
    assert np.all(jn[10].e_norm <= 1e-10)
    # an LQ game with polyhedral sets: one exact JN step solves each affine VI, so K = 1 tracks exactly
    assert np.all(jn[1].e_norm <= 1e-9)
