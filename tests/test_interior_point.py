"""The interior-point phase: its Newton direction against the unreduced system, both linear-algebra forms, the
per-player convexification, the interior start."""

from __future__ import annotations

import numpy as np
import pytest

from gnerun.game.compile import compile_game
from gnerun.language.config import load_config
from gnerun.runs.solving import make_solver
from gnerun.solvers import hybrid, interior_point
from gnerun.solvers.interior_point import InteriorPoint, convexify
from gnerun.solvers.sparse_ssn import SparseSemismoothNewton
from gnerun.solvers.ssn import SemismoothNewton

from .conftest import CONFIGS


def _interior(newton, z: np.ndarray, w: np.ndarray, eps: float, x=None):
    ip = InteriorPoint(newton)
    xv = newton.game.x0 if x is None else x
    parts = newton.evaluate(z, xv)[0]
    it = ip.measure(z, w, parts.L, parts.c, eps)
    return ip, it, parts


def _unreduced_direction(game, parts, z, w, eps, I):
    """Newton's direction for H_eps(a, lambda, w) = (L, c_I + w, c_E, lambda_I o w - eps) = 0, assembled and solved
    as it stands (numpy), without eliminating anything."""
    n, m = game.n, game.m
    E = np.flatnonzero(game.equality_mask)
    k = I.size
    size = n + m + k
    J = np.zeros((size, size))
    J[:n, : n + m] = parts.dL_dz
    J[n + I, :n] = parts.dc_da[I]
    J[n + I, n + m + np.arange(k)] = 1.0
    J[n + E, :n] = parts.dc_da[E]
    lam = z[n + I]
    J[n + m + np.arange(k), n + I] = w
    J[n + m + np.arange(k), n + m + np.arange(k)] = lam
    rhs = -np.concatenate([parts.L, np.zeros(m), lam * w - eps])
    rhs[n + I] = -(parts.c[I] + w)
    rhs[n + E] = -parts.c[E]
    d = np.linalg.solve(J, rhs)
    return d[:n], d[n : n + m], d[n + m :]


@pytest.mark.parametrize(("name", "over"), [
    ("fk_a11.yaml", {"game.equilibrium": "generalized"}),
    ("harker.yaml", {}),
    ("variational_gne.yaml", {"solver.kind": "ssn", "solver.formulation": "condensed"}),
])
def test_the_direction_solves_the_unreduced_newton_system(name: str, over: dict) -> None:
    _check_direction(load_config(CONFIGS / name, over))


@pytest.mark.parametrize("equilibrium", ["variational", "generalized"])
def test_the_direction_of_a_bounded_lq_game_solves_the_unreduced_system(equilibrium: str) -> None:
    """Bounds enter the matrix on its diagonal, shared rows (one copy per player, or one) as a product."""
    from benchmarks.problems import lq

    _check_direction(load_config(text=lq.lq_yaml(4, equilibrium)))


def _check_direction(cfg) -> None:
    game = compile_game(cfg)
    newton = SemismoothNewton(game, cfg.solver)
    rng = np.random.default_rng(3)
    ip = InteriorPoint(newton)
    I = ip.I
    z = np.concatenate([game.a_start + 0.3 * rng.standard_normal(game.n), np.zeros(game.m)])
    z[game.n + I] = rng.uniform(0.1, 2.0, I.size)
    w = rng.uniform(0.1, 2.0, I.size)
    eps = 0.05
    _, it, parts = _interior(newton, z, w, eps)
    lam = z[game.n + I]
    D = w / lam
    da, dlam, _ = ip.linear.direction(parts, it, D, -(it.c[I] + eps / lam))(0.0)
    dw = eps / lam - w - D * dlam[I]
    ref_a, ref_lam, ref_w = _unreduced_direction(game, parts, z, w, eps, I)
    np.testing.assert_allclose(da, ref_a, rtol=1e-9, atol=1e-10)
    np.testing.assert_allclose(dlam, ref_lam, rtol=1e-9, atol=1e-10)
    np.testing.assert_allclose(dw, ref_w, rtol=1e-9, atol=1e-10)


def test_sparse_and_condensed_directions_agree_on_a_dynamic_game() -> None:
    base = load_config(CONFIGS / "variational_gne.yaml", {"solver.kind": "ssn", "solver.globalization": "hybrid"})
    game = compile_game(base)
    dense = make_solver(base.model_copy(update={"solver": base.solver.model_copy(update={"formulation": "condensed"})}),
                        game).newton
    sparse = make_solver(base.model_copy(update={"solver": base.solver.model_copy(update={"formulation": "sparse"})}),
                         game).newton
    assert type(dense) is SemismoothNewton and isinstance(sparse, SparseSemismoothNewton)
    rng = np.random.default_rng(5)
    z = np.concatenate([0.2 * rng.standard_normal(game.n), np.zeros(game.m)])
    directions = []
    for newton in (dense, sparse):
        ip = InteriorPoint(newton)
        I = ip.I
        z[game.n + I] = np.linspace(0.2, 1.5, I.size)
        w = np.linspace(1.5, 0.2, I.size)
        _, it, parts = _interior(newton, z, w, 1e-2)
        lam = z[game.n + I]
        D = w / lam
        directions.append(ip.linear.direction(parts, it, D, -(it.c[I] + 1e-2 / lam))(0.0)[:2])
    np.testing.assert_allclose(directions[0][0], directions[1][0], atol=1e-9)
    np.testing.assert_allclose(directions[0][1], directions[1][1], atol=1e-9)


def test_convexify_leaves_convex_players_alone_and_repairs_the_others() -> None:
    S = np.array([[2.0, 0.5, 0.3, 0.0],
                  [0.5, 1.0, 0.0, 0.1],
                  [1.0, 0.0, -3.0, 1.0],
                  [0.0, 2.0, 1.0, 0.5]])
    blocks = [slice(0, 2), slice(2, 4)]
    out = S.copy()
    convexify(out, blocks)
    np.testing.assert_array_equal(out[:2], S[:2])  # player 1's block is positive definite: untouched
    np.testing.assert_array_equal(out[2:, :2], S[2:, :2])  # only the diagonal of player 2's block moves
    shift = out[2, 2] - S[2, 2]
    assert shift == out[3, 3] - S[3, 3] > 0
    sym = 0.5 * (out[2:, 2:] + out[2:, 2:].T)
    assert np.linalg.eigvalsh(sym).min() > 0
    # the smallest step of the ladder (1e-8 of the block's scale, times 10) that does it
    smaller = 0.5 * (S[2:, 2:] + S[2:, 2:].T) + (shift / 10) * np.eye(2)
    assert np.linalg.eigvalsh(smaller).min() <= 0


def test_the_interior_start() -> None:
    cfg = load_config(CONFIGS / "fk_a12.yaml", {"game.agents.0.variables.x1.start": 10.0})  # at its upper bound
    game = compile_game(cfg)
    ip = InteriorPoint(SemismoothNewton(game, cfg.solver))
    z0 = np.concatenate([game.a_start, np.zeros(game.m)])
    for attempt, (mu, scaled) in enumerate(interior_point.STARTS):
        z, w, eps = ip.start(z0, game.x0, attempt)
        assert np.all(game.a_lower < z[: game.n]) and np.all(z[: game.n] < game.a_upper)
        assert np.all(w >= interior_point.START_FLOOR)
        lam = z[game.n + ip.I]
        # a pair starts on the central path of its eps, or below it where the slack is below 1 (its multiplier is
        # not raised by a small slack)
        np.testing.assert_allclose(lam * np.maximum(w, 1.0), eps)
        assert np.any(w < 1.0)  # the start is at its bound: that row's slack starts at the floor, not at 1
        if not scaled:
            assert eps == mu
        else:
            assert eps >= mu


def test_a_matrix_with_an_infinite_entry_ends_the_phase_instead_of_shifting_forever() -> None:
    """A Cournot game whose firm 2 has no bounds: at the interior start its cost's derivatives overflow; the
    regularisation loop must give up (a status), not multiply an infinite shift forever."""
    from gnerun.runs.solving import solve

    firms = []
    for i in range(1, 4):
        bounds = "{}" if i == 2 else "{lower: 1, upper: 150, start: 10}"
        cost = f"{2 * i}*q{i} + 0.5*q{i}**((1 + 1.{i})/1.{i}) - q{i}*5000**(1/1.1)*(q1 + q2 + q3)**(-1/1.1)"
        firms.append(f'    - {{name: firm{i}, variables: {{q{i}: {bounds}}}, cost: "{cost}"}}')
    text = "game:\n  kind: static\n  agents:\n" + "\n".join(firms) + "\nsolver: {kind: jn, max_iter: 30}\n"
    import signal

    def expire(signum, frame):
        raise TimeoutError("the solve did not return within 30 s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.alarm(30)
    try:
        with np.errstate(all="ignore"):
            res = solve(load_config(text=text), out=None)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
    assert res.status != "converged" or res.residual_norm <= 1e-10
    assert res.message


def test_the_predictor_corrector_target_is_mehrotras() -> None:
    """The target of lambda_I o w after a full step: sigma mu - dlambda_aff o dw_aff, the affine-scaling direction
    (eps = 0) solved here on the unreduced system, sigma = (mu_aff / mu)^3 floored at CENTERING."""
    cfg = load_config(CONFIGS / "harker.yaml")
    game = compile_game(cfg)
    newton = SemismoothNewton(game, cfg.solver)
    rng = np.random.default_rng(3)
    ip = InteriorPoint(newton)
    I, n = ip.I, game.n
    z = np.concatenate([game.a_start + 0.3 * rng.standard_normal(n), np.zeros(game.m)])
    z[n + I] = rng.uniform(0.1, 2.0, I.size)
    w = rng.uniform(0.1, 2.0, I.size)
    _, it, parts = _interior(newton, z, w, 0.05)
    lam = z[n + I]
    target = ip._target(parts, it, w / lam)
    _, ref_lam, ref_w = _unreduced_direction(game, parts, z, w, 0.0, I)
    dlam = ref_lam[I]

    def longest(v, dv):
        return min(1.0, float(np.min(-v[dv < 0] / dv[dv < 0]))) if (dv < 0).any() else 1.0

    t_p, t_d = longest(w, ref_w), longest(lam, dlam)
    assert min(t_p, t_d) >= interior_point.PREDICTED
    mu, mu_aff = np.mean(lam * w), np.mean((w + t_p * ref_w) * (lam + t_d * dlam))
    sigma = min(1.0, max(interior_point.CENTERING, (mu_aff / mu) ** 3))
    np.testing.assert_allclose(target, sigma * mu - dlam * ref_w, rtol=1e-8, atol=1e-12)


def _fk_a3_from_10(monkeypatch: pytest.MonkeyPatch, **constants) -> float:
    from benchmarks.problems import fk
    from gnerun.solvers.driver import iterate

    for name, value in constants.items():
        monkeypatch.setattr(interior_point, name, value)
    problem = next(p for p in fk.problems() if p.name == "A.3" and p.start == "x0 = 10")
    cfg = load_config(text=problem.config_yaml)
    game = compile_game(cfg)
    solver = make_solver(cfg, game)
    state = iterate(solver, solver.init())
    assert state.converged, state.message
    return float(np.max(np.abs(state.z[: game.n] - problem.reference)))


def test_a_blocked_predictor_keeps_the_barriers_target(monkeypatch: pytest.MonkeyPatch) -> None:
    """FK A.3 from its upper bounds: the predictor of the interior start goes 0.5% of the way; taking Mehrotra's
    target anyway leads to another KKT point, 10 away from the literature's equilibrium."""
    assert _fk_a3_from_10(monkeypatch) <= 1e-8
    assert _fk_a3_from_10(monkeypatch, PREDICTED=0.0) > 1.0


@pytest.mark.slow
def test_the_predictor_corrector_step_ends_a_stalled_merge(monkeypatch: pytest.MonkeyPatch) -> None:
    """ALGAMES's merge, draw 4 from zero inputs, without the slack reset: with the barrier's monotone target alone the
    interior phase cycles at eps = 8e-6 and is restarted twice (136 iterations); with Mehrotra's steps it converges
    without a restart. (With the slack reset it cycles at eps = 1.6e-6 either way: 157 iterations.)"""
    from benchmarks.problems import trajectory

    problem = trajectory.merge_problems(5)[4]
    cfg = load_config(text=problem.config_yaml)
    game = compile_game(cfg)
    monkeypatch.setattr(hybrid, "DECOUPLE_ABOVE", np.inf)  # from zero inputs, not the cars' decoupled plans
    monkeypatch.setattr(hybrid, "RESET_ABOVE", np.inf)  # Mehrotra's step alone (with the slack reset it cycles)
    monkeypatch.setattr(hybrid, "response_round", lambda g, a, x: None)  # the restarts from z^0, not the answers
    iterations = _iterations_with(monkeypatch, cfg, game, interior_point, "PREDICT_AFTER",
                                  (interior_point.PREDICT_AFTER, np.inf))
    assert iterations[0] <= 40 < 100 <= iterations[1], iterations


def test_the_slack_reset_moves_only_rows_guessed_inactive_that_are_further_inside() -> None:
    """A row guessed inactive (lambda <= w) whose constraint is further inside than its slack gets w = -c, its
    multiplier scaled so that lambda w stays; a row guessed active, or one no further inside, keeps both."""
    cfg = load_config(CONFIGS / "harker.yaml")
    newton = SemismoothNewton(compile_game(cfg), cfg.solver)
    ip = InteriorPoint(newton)
    assert ip.I.size >= 3
    I, n = ip.I[:3], ip.n
    z = np.zeros(n + newton.game.m)
    z[n + ip.I] = 0.5
    z[n + I] = [0.01, 2.0, 0.01]  # guessed inactive, active, inactive
    w = np.full(ip.I.size, 0.1)
    c = np.zeros(newton.game.m)
    c[ip.I] = -0.05
    c[I] = [-0.4, -0.4, -0.08]  # further inside, further inside, no further
    z_new, w_new = ip.reset_slacks(z, w, c)
    assert w_new[:3].tolist() == [0.4, 0.1, 0.1] and np.all(w_new[3:] == 0.1)
    assert z_new[n + I[0]] * w_new[0] == pytest.approx(0.01 * 0.1)
    assert np.array_equal(z_new[np.arange(z.size) != n + I[0]], z[np.arange(z.size) != n + I[0]])
    assert w[0] == 0.1 and z[n + I[0]] == 0.01  # the inputs are not changed


@pytest.mark.slow
def test_the_slack_reset_shortens_a_merge(monkeypatch: pytest.MonkeyPatch) -> None:
    """ALGAMES's merge, draw 8 from zero inputs: the collision rows' slacks lag behind their (concave) constraints,
    whose linearisation underestimates how far inside a step goes; with the slack reset 16 iterations, without 34."""
    from benchmarks.problems import trajectory

    problem = trajectory.merge_problems(9)[8]
    cfg = load_config(text=problem.config_yaml)
    game = compile_game(cfg)
    monkeypatch.setattr(hybrid, "DECOUPLE_ABOVE", np.inf)  # from zero inputs, not the cars' decoupled plans
    iterations = _iterations_with(monkeypatch, cfg, game, hybrid, "RESET_ABOVE", (hybrid.RESET_ABOVE, np.inf))
    assert iterations[0] <= 20 < 30 <= iterations[1], iterations


def _iterations_with(monkeypatch: pytest.MonkeyPatch, cfg, game, module, name: str, values) -> list[int]:
    """The default solver's iterations from the config's start with ``module.name`` set to each of ``values`` (each
    solve converged)."""
    from gnerun.solvers.driver import iterate

    iterations = []
    for value in values:
        monkeypatch.setattr(module, name, value)
        solver = make_solver(cfg, game)
        state = iterate(solver, solver.init())
        assert state.converged, state.message
        iterations.append(state.k)
    return iterations
