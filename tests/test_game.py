"""Compiled games: exact derivatives against central differences, and the condensed paper game against numpy."""

from __future__ import annotations

import numpy as np
import pytest

from gnerun.certificate import best_response, kkt_residuals
from gnerun.config import load_config
from gnerun.game import compile_game
from gnerun.solving import solve

from .conftest import CONFIGS

VEHICLES = """
name: nonlinear-dynamic
game:
  kind: dynamic
  horizon: 4
  states: [px1, py1, th1, px2, py2, th2]
  parameters: {dt: 0.2, d: 0.5}
  dynamics:
    px1: "px1 + dt*v1*cos(th1)"
    py1: "py1 + dt*v1*sin(th1)"
    th1: "th1 + dt*tanh(w1)"
    px2: "px2 + dt*v2*cos(th2)"
    py2: "py2 + dt*v2*sin(th2)"
    th2: "th2 + dt*w2*exp(-0.1*v2**2)"
  x0: [0, 0, 0.1, 2, 0.3, 3.0]
  agents:
    - name: car1
      inputs: {v1: {lower: 0, upper: 2, start: 0.5}, w1: {lower: -1, upper: 1}}
      stage_cost: "(px1 - 2)**2 + py1**2 + 0.1*w1**2 + 0.05*v1*px2"
      terminal_cost: "3*(px1 - 2)**2"
      constraints: ["v1*v2 <= 3"]
    - name: car2
      inputs: {v2: {lower: 0, upper: 2, start: 0.5}, w2: {lower: -1, upper: 1}}
      stage_cost: "px2**2 + (py2 - 0.3)**2 + 0.1*w2**2 + sin(px1)*0.1"
  shared_constraints: ["(px1 - px2)**2 + (py1 - py2)**2 >= d**2"]
  equilibrium: {equilibrium}
"""


def _games():
    out = [(p.stem, load_config(p)) for p in sorted(CONFIGS.glob("*.yaml"))]
    for eq in ("generalized", "variational"):
        out.append((f"vehicles-{eq}", load_config("vehicles.yaml", text=VEHICLES.replace("{equilibrium}", eq))))
    return out


GAMES = _games()


def _central(f, v, h=1e-6):
    cols = []
    for i in range(v.size):
        e = np.zeros(v.size)
        e[i] = h
        cols.append((f(v + e) - f(v - e)) / (2 * h))
    return np.column_stack(cols)


@pytest.mark.parametrize("name, cfg", GAMES, ids=[g[0] for g in GAMES])
def test_exact_derivatives_match_central_differences(name, cfg) -> None:
    game = compile_game(cfg)
    rng = np.random.default_rng(0)
    n = game.n
    for _ in range(2):
        a = game.a_start + 0.3 * rng.standard_normal(n)
        if name.startswith("cournot"):
            a = rng.uniform(20, 60, n)  # q**(-1/eta) and q**((1+b)/b) need q > 0
        z = np.concatenate([a, rng.uniform(0, 1, game.m)])
        x = game.x0 + 0.1 * rng.standard_normal(game.nx)
        parts = game.kkt_parts(z, x)
        scale = 1.0 + np.abs(parts.dL_dz).max()

        def L(v, x=x):
            return game.kkt_parts(v, x).L

        def c(v, x=x, lam=z[n:]):
            return game.kkt_parts(np.r_[v, lam], x).c

        def F(v, x=x):
            return game.pseudogradient(v, x)[0]

        def J(v, x=x):
            return game.costs(v, x)

        np.testing.assert_allclose(parts.dL_dz, _central(L, z), atol=1e-6 * scale, rtol=1e-6)
        np.testing.assert_allclose(parts.dc_da, _central(c, a), atol=1e-6 * (1 + np.abs(parts.dc_da).max()),
                                   rtol=1e-6)
        F_a, H = game.pseudogradient(a, x)
        np.testing.assert_allclose(H, _central(F, a), atol=1e-6 * (1 + np.abs(H).max()), rtol=1e-6)
        dJ = game.cost_gradients(a, x)
        np.testing.assert_allclose(dJ, _central(J, a), atol=1e-6 * (1 + np.abs(dJ).max()), rtol=1e-6)
        # F is the diagonal blocks of dJ: agent i's gradient with respect to its own decisions
        np.testing.assert_allclose(F_a, np.concatenate([dJ[i, sl] for i, sl in enumerate(game.agent_slices)]))
        pattern = game.jacobian_sparsity().toarray()
        numeric = np.zeros_like(pattern)
        numeric[:n] = parts.dL_dz != 0
        numeric[n:, :n] = parts.dc_da != 0
        assert not np.any(numeric & ~pattern), "a nonzero outside the structural pattern"


def _paper_numpy(a: np.ndarray, x: np.ndarray, T: int):
    """Study 1 written out by hand: xi(tau+1) = A xi(tau) + a(tau); costs on xi(tau+1), tau = 0..T."""
    A = np.diag([0.5, 0.3, 0.2])
    u = a.reshape(3, T + 1)  # agent-major, time inside
    xi = np.zeros((T + 2, 3))
    xi[0] = x
    for t in range(T + 1):
        xi[t + 1] = A @ xi[t] + u[:, t]
    s = xi[1:]
    J = np.array([np.sum((s[:, 0] - 1) ** 2 - s[:, 0] * s[:, 1]),
                  np.sum((s[:, 1] - 1) ** 2 + s[:, 0] * s[:, 1]),
                  np.sum((s[:, 2] - 1) ** 2)])
    c = np.concatenate([u[0] + u[1] + u[2] - 1,  # agent 1, per stage
                        u[1] - 0.5,  # agent 2
                        np.column_stack([u[0] + u[1] - u[2], -u[2]]).reshape(-1)])  # agent 3: two per stage
    return J, c


@pytest.mark.parametrize("T", [5, 10])
def test_condensed_paper_game_equals_a_hand_written_model(T: int) -> None:
    cfg = load_config(CONFIGS / "paper_study1.yaml", {"game.horizon": T})
    game = compile_game(cfg)
    assert (game.n, game.m) == (3 * (T + 1), 4 * (T + 1))
    rng = np.random.default_rng(T)
    for _ in range(5):
        a = rng.standard_normal(game.n)
        x = rng.standard_normal(3)
        J, c = _paper_numpy(a, x, T)
        np.testing.assert_allclose(game.costs(a, x), J, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(game.kkt_parts(np.r_[a, np.zeros(game.m)], x).c, c, atol=1e-12)
    # the solution satisfies the KKT conditions of the hand-written model: stationarity by numpy differences
    res = solve(cfg)
    a, lam = res.a, res.lam
    x0 = np.array([1.0, 3.0, 5.0])

    def lagrangians(v):
        J, c = _paper_numpy(v, x0, T)
        blocks = np.split(lam, [T + 1, 2 * (T + 1)])
        cs = np.split(c, [T + 1, 2 * (T + 1)])
        return np.array([J[i] + blocks[i] @ cs[i] for i in range(3)])

    grad = _central(lagrangians, a, h=1e-5)
    for i in range(3):
        sl = slice(i * (T + 1), (i + 1) * (T + 1))
        np.testing.assert_allclose(grad[i, sl], 0.0, atol=1e-7)
    _, c = _paper_numpy(a, x0, T)
    assert np.all(c <= 1e-10) and np.all(lam >= -1e-12)
    np.testing.assert_allclose(lam * c, 0.0, atol=1e-10)


def test_layout_ordering_and_labels() -> None:
    cfg = load_config(CONFIGS / "paper_study1.yaml", {"game.horizon": 2})
    game = compile_game(cfg)
    a = np.arange(game.n, dtype=float)
    assert game.solution_by_agent(a) == {"agent1": {"u1": [0.0, 1.0, 2.0]}, "agent2": {"u2": [3.0, 4.0, 5.0]},
                                         "agent3": {"u3": [6.0, 7.0, 8.0]}}
    np.testing.assert_array_equal(game.first_inputs(a), [0.0, 3.0, 6.0])
    labels = [c.label for c in game.constraints]
    assert labels[:3] == ["u1 + u2 + u3 <= 1 [tau=0]", "u1 + u2 + u3 <= 1 [tau=1]", "u1 + u2 + u3 <= 1 [tau=2]"]
    assert labels[6:8] == ["u3 >= u1 + u2 [tau=0]", "u3 >= 0 [tau=0]"]
    np.testing.assert_array_equal(game.step_dynamics(np.array([1.0, 1.0, 1.0]), np.array([1.0, 2.0, 3.0])),
                                  [1.5, 2.3, 3.2])


def test_shared_constraints_generalized_and_variational() -> None:
    gen = compile_game(load_config(CONFIGS / "fk_a11.yaml", {"game.equilibrium": "generalized"}))
    var = compile_game(load_config(CONFIGS / "fk_a11.yaml"))
    assert gen.m == 2 and gen.shared_slice.stop == gen.shared_slice.start  # one copy per agent
    assert var.m == 1 and (var.shared_slice.start, var.shared_slice.stop) == (0, 1)  # one common multiplier
    assert [c.owner for c in gen.constraints] == [0, 1] and var.constraints[0].owner is None
    eq = compile_game(load_config("e.yaml", text="""
game:
  kind: static
  agents:
    - name: p
      variables: {x: {lower: -1}}
      cost: "x**2"
      constraints: ["x == 0.5"]
"""))
    assert list(eq.equality_mask) == [False, True]
    assert [c.label for c in eq.constraints] == ["x >= -1", "x == 0.5"]


# --- the certificate, against closed forms ---------------------------------------------------------


def test_best_responses_have_closed_forms() -> None:
    game = compile_game(load_config(CONFIGS / "fk_a12.yaml"))
    # A.12: agent 1 minimises x1 (x1 + x2 - 16) over [-10, 10]: x1 = clip((16 - x2)/2)
    for x2 in (-10.0, 0.0, 16 / 3, 9.0):
        value, br, note = best_response(game, 0, np.array([0.0, x2]))
        expected = float(np.clip((16 - x2) / 2, -10, 10))
        assert note == "ok" and br[0] == pytest.approx(expected, abs=1e-7)
        assert value == pytest.approx(expected * (expected + x2 - 16), abs=1e-9)
    harker = compile_game(load_config(CONFIGS / "harker.yaml"))
    # Harker: agent 1 minimises x1^2 + 8/3 x1 x2 - 34 x1 over [0, 10], x1 <= 15 - x2
    for x2 in (9.0, 3.0):
        _, br, _ = best_response(harker, 0, np.array([0.0, x2]))
        assert br[0] == pytest.approx(min(max((34 - 8 / 3 * x2) / 2, 0), 10, 15 - x2), abs=1e-7)


def test_certificate_at_and_away_from_the_equilibrium() -> None:
    game = compile_game(load_config(CONFIGS / "fk_a11.yaml"))
    star = np.array([0.75, 0.25, 0.5])  # (x1, x2, common multiplier)
    r = kkt_residuals(game, star)
    assert r["kkt_residual"] <= 1e-15
    off = kkt_residuals(game, np.array([0.8, 0.3, -0.1]))
    assert off["primal_infeasibility"] == pytest.approx(0.1)
    assert off["dual_infeasibility"] == pytest.approx(0.1)
    assert off["stationarity"] == pytest.approx(abs(2 * (0.3 - 0.5) - 0.1))
    assert off["complementarity"] == pytest.approx(0.01)
    res = solve(load_config(CONFIGS / "fk_a12.yaml"))
    assert max(abs(g) for g in res.certificate["best_response_gap"].values()) <= 1e-9
    # away from the NE the gap is the closed-form improvement: agent 1 at x1 = 0 against x2 = 16/3
    from gnerun.certificate import certificate

    cert = certificate(compile_game(load_config(CONFIGS / "fk_a12.yaml")), np.r_[0.0, 16 / 3, np.zeros(4)])
    best = 16 / 3  # clip((16 - 16/3)/2)
    assert cert["best_response_gap"]["p1"] == pytest.approx(0.0 - best * (best + 16 / 3 - 16), abs=1e-8)
