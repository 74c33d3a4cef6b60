"""The min-map step through the reduced system equals the step through the whole JPhi, and the LQ fast path
evaluates the same L and c as the compiled CasADi functions."""

from __future__ import annotations

import numpy as np
import pytest

from gnerun.game.compile import compile_game
from gnerun.language.config import load_config
from gnerun.runs.solving import make_solver
from gnerun.solvers.ssn import Status

from .conftest import CONFIGS

CASES = ["paper_study1", "harker", "fk_a11", "fk_a12", "nonlinear_gne", "variational_gne", "vehicles"]


def _full_step(solver, state) -> np.ndarray:
    """z + dz with JPhi(z) dz = -Phi(z), the whole system (the reference)."""
    J = solver.jacobian(state.parts, state.z, state.active)
    return state.z + np.linalg.solve(J, -state.phi)


@pytest.mark.parametrize("name", CASES)
def test_reduced_step_equals_the_full_newton_step(name: str) -> None:
    cfg = load_config(CONFIGS / f"{name}.yaml", {"solver.kind": "ssn", "solver.globalization": "none",
                                                  "solver.complementarity": "min", "solver.formulation": "condensed"})
    game = compile_game(cfg)
    solver = make_solver(cfg, game)
    assert solver.reduced
    rng = np.random.default_rng(3)
    # along the method's own iterates, and from random points (multipliers of both signs, all branches)
    states = [solver.init()]
    for _ in range(4):
        nxt = solver.step(states[-1])
        if nxt.status != Status.RUNNING or nxt.residual_norm < 1e-9:
            break
        states.append(nxt)
    for _ in range(5):
        z = game.z_start() + rng.normal(scale=0.5, size=game.size)
        states.append(solver.init(z))
    checked = 0
    for state in states:
        J = solver.jacobian(state.parts, state.z, state.active)
        if np.linalg.cond(J) > 1e8:
            continue
        expected = _full_step(solver, state)
        got = solver.step(state)
        assert got.status in (Status.RUNNING, Status.CONVERGED), got.message
        np.testing.assert_allclose(got.z, expected, rtol=1e-8, atol=1e-8 * (1 + np.abs(expected).max()))
        checked += 1
    assert checked >= 3


def test_lq_games_are_recognised_and_evaluated_exactly() -> None:
    rng = np.random.default_rng(0)
    for name, affine in [("paper_study1", True), ("harker", True), ("fk_a11", True), ("vehicles", False),
                         ("nonlinear_gne", False)]:
        game = compile_game(load_config(CONFIGS / f"{name}.yaml"))
        assert game.affine is affine, name
        for _ in range(5):
            z = rng.normal(size=game.size) * 3
            x = game.x0 + rng.normal(size=game.nx)
            parts = game.kkt_parts(z, x)
            L, c, dL, dc = game._kkt(z[: game.n], z[game.n:], x)  # the compiled CasADi functions
            np.testing.assert_allclose(parts.L, L.reshape(-1), rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(parts.c, c.reshape(-1), rtol=1e-12, atol=1e-12)
            np.testing.assert_array_equal(parts.dL_dz, dL)
            np.testing.assert_array_equal(parts.dc_da, dc)


def test_lq_step_cache_follows_the_state() -> None:
    """The cached end point of an LQ step belongs to one plant state: a new x gives a new step."""
    cfg = load_config(CONFIGS / "paper_study2.yaml")
    game = compile_game(cfg)
    solver = make_solver(cfg, game)
    for x in (np.array([1.0, 3.0, 5.0]), np.array([0.2, -1.0, 2.0]), np.array([1.0, 3.0, 5.0])):
        state = solver.init(game.z_start(), x)
        while not solver.terminate(state)[0]:
            state = solver.step(state)
        assert state.status == Status.RUNNING and state.residual_norm <= cfg.solver.tol
        fresh = make_solver(cfg, game)  # no cache
        ref = fresh.init(game.z_start(), x)
        while not fresh.terminate(ref)[0]:
            ref = fresh.step(ref)
        np.testing.assert_allclose(state.z, ref.z, atol=1e-12)


def _lq_family(T: int, equilibrium: str):
    from benchmarks.problems import lq

    cfg = load_config(text=lq.lq_yaml(T, equilibrium), overrides={"solver.globalization": "none"})
    return cfg, compile_game(cfg)


@pytest.mark.parametrize("equilibrium", ["variational", "generalized"])
def test_the_schur_complement_step_equals_the_reduced_system_step(equilibrium: str) -> None:
    """Where P = dL/da is invertible an LQ step solves the Schur complement S_AA = C_A P^-1 E_A instead of the
    reduced system: the same point, from the method's own iterates and from random active sets."""
    cfg, game = _lq_family(10, equilibrium)
    schur = make_solver(cfg, game)
    plain = make_solver(cfg, game)
    plain.lq._dual_cache = None  # the reduced system itself
    assert schur.lq.dual is not None and plain.lq.dual is None
    rng = np.random.default_rng(1)
    actives = [schur.init().active]
    for _ in range(40):
        actives.append(rng.random(game.m) < 0.15)
    checked = 0
    for active in actives:
        got, rcond = schur.lq.point(active, game.x0)
        ref, _ = plain.lq.point(active, game.x0)
        if ref is None:
            assert got is None
            continue
        assert got is not None, rcond
        np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-9)
        checked += 1
    assert checked >= 5


def test_more_active_rows_than_decisions_is_singular_without_a_factorisation() -> None:
    cfg, game = _lq_family(5, "variational")
    solver = make_solver(cfg, game)
    active = np.zeros(game.m, dtype=bool)
    active[: game.n + 1] = True
    z, rcond = solver.lq.point(active, game.x0)
    assert z is None and rcond == 0.0
    state = solver.init()
    state.active = active
    J = solver.jacobian(state.parts, state.z, active)
    assert np.linalg.matrix_rank(J) < J.shape[0]  # the claim: JPhi itself is singular there


def test_the_levenberg_marquardt_step_of_an_lq_game_minimises_its_objective() -> None:
    """In the multipliers alone: lambda_A minimises ||c_A(a(lambda))||^2 + mu ||lambda_A - lambda_A^k||^2 with
    a(lambda) the decisions at which L = 0 and the other multipliers zero; checked against the least-squares
    solution of that objective, written column by column from the compiled game's residuals (it is affine)."""
    cfg, game = _lq_family(10, "generalized")
    solver = make_solver(cfg, game)
    n = game.n
    state = solver.step(solver.init())  # the unconstrained equilibrium: many violated rows, a singular step
    A = np.flatnonzero(state.active)
    assert A.size > n
    mu = 0.3
    z = solver.regularized_point(state, mu)
    assert z is not None
    L, c = game.kkt_residual(z, game.x0)
    assert np.abs(L).max() < 1e-9
    assert np.all(np.delete(z[n:], A) == 0.0)

    dL = game.lq.cache["dL"]

    def decisions(lam_A: np.ndarray) -> np.ndarray:
        lam = np.zeros(game.m)
        lam[A] = lam_A
        L0, _ = game.kkt_residual(np.concatenate([np.zeros(n), lam]), game.x0)
        return np.linalg.solve(dL[:, :n], -L0)

    def residual(lam_A: np.ndarray) -> np.ndarray:
        lam = np.zeros(game.m)
        lam[A] = lam_A
        _, c = game.kkt_residual(np.concatenate([decisions(lam_A), lam]), game.x0)
        return np.concatenate([c[A], np.sqrt(mu) * (lam_A - state.z[n + A])])

    # the residual is affine in lambda_A: its matrix column by column, then the stacked least-squares problem
    k = A.size
    r0 = residual(np.zeros(k))
    M = np.column_stack([residual(e) - r0 for e in np.eye(k)])
    ref = np.linalg.lstsq(M, -r0, rcond=None)[0]
    assert np.abs(residual(ref)).max() < 1e3  # a finite optimum, checked by perturbation below
    for d in np.eye(k)[:5] * 1e-4:
        assert np.sum(residual(ref + d) ** 2) > np.sum(residual(ref) ** 2)
    np.testing.assert_allclose(z[n + A], ref, atol=1e-8)
    np.testing.assert_allclose(z[:n], decisions(ref), atol=1e-8)
