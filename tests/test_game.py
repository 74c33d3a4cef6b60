"""gnerun.game.compile: exact derivatives against central differences, the condensed games against hand-written
numpy models (the paper's Study 1 and a nonlinear unicycle-like game), layout, sparsity and dynamics.

Every reference here is computed independently of gnerun: finite differences, explicit numpy roll-outs
of xi(tau+1) = f(xi(tau), a(tau)) with the SPEC §3 convention (stage cost on xi(tau+1), tau = 0..T,
constraints on (xi(tau+1), a(tau)) at every stage), and closed forms.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
import scipy.sparse as sp

from gnerun.game.compile import CompiledGame, compile_game
from gnerun.language.config import load_config
from gnerun.runs.solving import solve

from .conftest import CONFIGS, shipped_configs

H_FD = 1e-6  # central-difference step
RTOL_FD = 1e-6

# A nonlinear dynamic game: unicycle-like kinematics (cos, sin, tanh, exp), stage costs with products of
# states and inputs, a terminal cost, bounds, a private constraint of agent 1 that involves agent 2's
# input (GNE coupling), a coupled equality of agent 2 and a nonlinear shared constraint on the states.
NONLINEAR = """
name: nonlinear-dynamic
game:
  kind: dynamic
  horizon: 3
  states: [x1, x2, x3]
  parameters: {dt: 0.1, k: 0.5}
  dynamics:
    x1: "x1 + dt*cos(x3)*u1"
    x2: "x2 + dt*sin(x3)*u1 + k*tanh(w)"
    x3: "x3 + dt*exp(-u2)*w"
  x0: [0.2, -0.1, 0.3]
  agents:
    - name: a1
      inputs: {u1: {lower: -2, upper: 2.5, start: 0.5}, w: {lower: -1.5}}
      stage_cost: "(x1 - 1)**2 + x1*x2*u1 + 0.1*w**2"
      terminal_cost: "2*x1**2"
      constraints: ["x1 + u2 <= 3"]
    - name: a2
      inputs: {u2: {upper: 1}}
      stage_cost: "(x2 + 1)**2 + exp(0.1*u2)*x3 + u1*u2"
      constraints: ["u2*u1 == 0.1"]
  shared_constraints: ["x1**2 + x2**2 <= 4"]
  equilibrium: EQUILIBRIUM
"""
NONLINEAR_T = 3
EQUILIBRIA = ("generalized", "variational")


def nonlinear_config(equilibrium: str):
    return load_config("nonlinear-dynamic.yaml", text=NONLINEAR.replace("EQUILIBRIUM", equilibrium))


def _central(f: Callable[[np.ndarray], np.ndarray], v: np.ndarray, h: float = H_FD) -> np.ndarray:
    """Central-difference Jacobian of f at v (columns: d f / d v_k)."""
    cols = []
    for k in range(v.size):
        e = np.zeros(v.size)
        e[k] = h
        cols.append((np.atleast_1d(f(v + e)) - np.atleast_1d(f(v - e))) / (2 * h))
    return np.column_stack(cols)


def _assert_matches_fd(exact: np.ndarray, fd: np.ndarray, what: str) -> None:
    assert exact.shape == fd.shape, what
    np.testing.assert_allclose(exact, fd, rtol=RTOL_FD, atol=RTOL_FD * (1.0 + np.abs(exact).max(initial=0.0)),
                               err_msg=what)


# --- 1. exact derivatives against central differences --------------------------------------------


def _fd_games() -> list[tuple[str, object]]:
    games = [(p.stem, load_config(p)) for p in shipped_configs()]
    games += [(f"nonlinear-{eq}", nonlinear_config(eq)) for eq in EQUILIBRIA]
    return games


FD_GAMES = _fd_games()
# the ALGAMES trajectory games take 10-70 s each here: in the full suite only
FD_PARAMS = [pytest.param(name, cfg, id=name, marks=[pytest.mark.slow] if name.startswith("algames") else [])
             for name, cfg in FD_GAMES]


def _random_point(name: str, game: CompiledGame, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A random primal point in the expressions' domain, and a random state."""
    if name.startswith("cournot"):
        a = rng.uniform(20.0, 60.0, game.n)  # q**(-1/eta) and q**((1 + b)/b) need q > 0
    elif name.startswith("fk_a09"):
        a = rng.uniform(0.1, 2.0, game.n)  # powers: the rates' logarithms need 1 + SINR > 0
    else:
        a = game.a_start + 0.5 * rng.standard_normal(game.n)
    x = game.x0 + 0.2 * rng.standard_normal(game.nx)
    return a, x


def test_every_shipped_config_is_checked() -> None:
    names = {name for name, _ in FD_GAMES}
    assert {"paper_study1", "paper_study1_disturbed", "harker", "fk_a11", "fk_a12", "nonlinear_gne"} <= names


@pytest.mark.parametrize("name, cfg", FD_PARAMS)
def test_exact_derivatives_match_central_differences(name: str, cfg) -> None:
    game = compile_game(cfg)
    rng = np.random.default_rng(20240611)
    n, m = game.n, game.m
    for _ in range(2 if game.size < 500 else 1):  # one point on the largest games
        a, x = _random_point(name, game, rng)
        lam = rng.uniform(0.0, 2.0, m)
        z = np.concatenate([a, lam])
        parts = game.kkt_parts(z, x)
        assert parts.L.shape == (n,) and parts.c.shape == (m,)
        assert parts.dL_dz.shape == (n, n + m) and parts.dc_da.shape == (m, n)

        _assert_matches_fd(parts.dL_dz, _central(lambda v, x=x: game.kkt_parts(v, x).L, z), f"{name}: dL/dz")
        if m:
            _assert_matches_fd(parts.dc_da, _central(lambda v, x=x, lam=lam: game.kkt_parts(np.r_[v, lam], x).c, a),
                               f"{name}: dc/da")
        F, H = game.pseudogradient(a, x)
        _assert_matches_fd(H, _central(lambda v, x=x: game.pseudogradient(v, x)[0], a), f"{name}: H = dF/da")
        dJ = game.cost_gradients(a, x)
        assert dJ.shape == (len(game.agent_slices), n)
        _assert_matches_fd(dJ, _central(lambda v, x=x: game.costs(v, x), a), f"{name}: grad J")
        # F_i = grad_{a_i} J_i, by differences of agent i's own cost over its own block only
        F_fd = np.concatenate([
            _central(lambda v, i=i, sl=sl, a=a, x=x: game.costs(np.r_[a[: sl.start], v, a[sl.stop:]], x)[i], a[sl])[0]
            for i, sl in enumerate(game.agent_slices)
        ])
        _assert_matches_fd(F, F_fd, f"{name}: F")
        np.testing.assert_array_equal(game.own_gradients(a, x), F)  # the same expression, without H
        # L at lambda = 0 is the pseudogradient [KKT_concatenated]
        np.testing.assert_allclose(game.kkt_parts(np.r_[a, np.zeros(m)], x).L, F, rtol=1e-12, atol=1e-12)


# --- 2. the nonlinear game against an explicit numpy roll-out -------------------------------------


def _nonlinear_numpy(a: np.ndarray, x: np.ndarray, equilibrium: str, T: int = NONLINEAR_T):
    """Costs and constraints of NONLINEAR by hand. Constraints are keyed by (label, owner): owner 0/1 for
    an agent's own rows, and for the shared constraint each agent (generalized) or None (variational)."""
    dt, k = 0.1, 0.5
    a1 = a[: 2 * (T + 1)].reshape(T + 1, 2)  # time-major: (u1(tau), w(tau)) per stage
    a2 = a[2 * (T + 1):]
    xi = np.array(x, dtype=float)
    J = np.zeros(2)
    cons: dict[tuple[str, int | None], float] = {}
    for tau in range(T + 1):
        u1, w = a1[tau]
        u2 = a2[tau]
        x1, x2, x3 = xi
        xi = np.array([x1 + dt * np.cos(x3) * u1,
                       x2 + dt * np.sin(x3) * u1 + k * np.tanh(w),
                       x3 + dt * np.exp(-u2) * w])
        x1, x2, x3 = xi  # stage costs and constraints see the state the inputs of stage tau produce
        J[0] += (x1 - 1) ** 2 + x1 * x2 * u1 + 0.1 * w**2
        J[1] += (x2 + 1) ** 2 + np.exp(0.1 * u2) * x3 + u1 * u2
        s = f" [tau={tau}]"
        cons[("u1 >= -2" + s, 0)] = -2 - u1
        cons[("u1 <= 2.5" + s, 0)] = u1 - 2.5
        cons[("w >= -1.5" + s, 0)] = -1.5 - w
        cons[("x1 + u2 <= 3" + s, 0)] = x1 + u2 - 3
        cons[("u2 <= 1" + s, 1)] = u2 - 1
        cons[("u2*u1 == 0.1" + s, 1)] = u2 * u1 - 0.1
        shared = x1**2 + x2**2 - 4
        for owner in ((0, 1) if equilibrium == "generalized" else (None,)):
            cons[("x1**2 + x2**2 <= 4" + s, owner)] = shared
    J[0] += 2 * xi[0] ** 2  # terminal cost on xi(T+1)
    return J, cons


def _keys(game: CompiledGame) -> list[tuple[str, int | None]]:
    return [(c.label, c.owner) for c in game.constraints]


@pytest.mark.parametrize("equilibrium", EQUILIBRIA)
def test_nonlinear_game_equals_a_numpy_rollout(equilibrium: str) -> None:
    game = compile_game(nonlinear_config(equilibrium))
    T = NONLINEAR_T
    assert (game.n, game.nx, game.horizon) == (3 * (T + 1), 3, T)
    rng = np.random.default_rng(7)
    for _ in range(4):
        a = 0.7 * rng.standard_normal(game.n)
        x = rng.standard_normal(3)
        lam = rng.uniform(0.0, 1.0, game.m)
        J, cons = _nonlinear_numpy(a, x, equilibrium)
        np.testing.assert_allclose(game.costs(a, x), J, rtol=1e-13, atol=1e-13)
        keys = _keys(game)
        assert sorted(keys, key=str) == sorted(cons, key=str)  # the same rows, each once
        parts = game.kkt_parts(np.r_[a, lam], x)
        np.testing.assert_allclose(parts.c, [cons[key] for key in keys], rtol=1e-13, atol=1e-13)
        # agent i's Lagrangian J_i + sum over its rows (own, and common shared) of lambda_j c_j,
        # differentiated by central differences over a_i, is L_i  [KKT_concatenated]
        lam_of = dict(zip(keys, lam, strict=True))
        for i, sl in enumerate(game.agent_slices):
            def lagrangian(v, i=i, sl=sl, a=a, x=x, lam_of=lam_of):
                b = a.copy()
                b[sl] = v
                Jb, cb = _nonlinear_numpy(b, x, equilibrium)
                return Jb[i] + sum(lam_of[key] * val for key, val in cb.items() if key[1] in (i, None))

            _assert_matches_fd(parts.L[sl], _central(lagrangian, a[sl])[0], f"L of agent {i}")
    # the state x defaults to x0
    a = rng.standard_normal(game.n)
    np.testing.assert_array_equal(game.costs(a), game.costs(a, np.array([0.2, -0.1, 0.3])))
    with pytest.raises(ValueError):
        game.costs(a, np.zeros(4))


# --- 2. the paper's Study 1 against a hand-written numpy model ----------------------------------

A_PAPER = np.diag([0.5, 0.3, 0.2])
X0_PAPER = np.array([1.0, 3.0, 5.0])


def _paper_rollout(a: np.ndarray, x: np.ndarray, T: int):
    """eq:player1 with the SPEC convention, by explicit roll-out: costs and constraints keyed by label."""
    u = a.reshape(3, T + 1)  # agent-major; one input per agent, so time inside
    xi = np.array(x, dtype=float)
    J = np.zeros(3)
    cons: dict[str, tuple[int, float]] = {}
    for tau in range(T + 1):
        ut = u[:, tau]
        xi = A_PAPER @ xi + ut  # B = I
        J[0] += (xi[0] - 1) ** 2 - xi[0] * xi[1]
        J[1] += (xi[1] - 1) ** 2 + xi[0] * xi[1]
        J[2] += (xi[2] - 1) ** 2
        s = f" [tau={tau}]"
        cons["u1 + u2 + u3 <= 1" + s] = (0, ut[0] + ut[1] + ut[2] - 1)
        cons["u2 <= 0.5" + s] = (1, ut[1] - 0.5)
        cons["u3 >= u1 + u2" + s] = (2, ut[0] + ut[1] - ut[2])
        cons["u3 >= 0" + s] = (2, -ut[2])
    return J, cons


def _paper_condensed(a: np.ndarray, x: np.ndarray, T: int):
    """The same game condensed by hand: s_k = xi_k(1..T+1) = p_k + S_k u_k (A diagonal, B = I), and the exact
    gradients grad_{u_i} J_i = S_i^T dl_i/ds."""
    u = a.reshape(3, T + 1)
    t = np.arange(T + 1)
    s, S = [], []
    for k in range(3):
        r = A_PAPER[k, k]
        Sk = np.where(t[:, None] >= t[None, :], r ** np.maximum(t[:, None] - t[None, :], 0), 0.0)
        s.append(r ** (t + 1) * x[k] + Sk @ u[k])
        S.append(Sk)
    grads = [S[0].T @ (2 * (s[0] - 1) - s[1]),
             S[1].T @ (2 * (s[1] - 1) + s[0]),
             S[2].T @ (2 * (s[2] - 1))]
    return s, grads


FAMILIES = ("u1 + u2 + u3 <= 1", "u2 <= 0.5", "u3 >= u1 + u2", "u3 >= 0")


def _paper_stationarity(a: np.ndarray, lam_of: dict[str, float], x: np.ndarray, T: int) -> np.ndarray:
    """(grad_{u_i} (J_i + lambda_i^T g_i))_i by hand: d g / d u_i(tau) is +1 for the rows of agents 1 and 2,
    -1 for both rows of agent 3."""
    per_stage = {fam: np.array([lam_of[f"{fam} [tau={t}]"] for t in range(T + 1)]) for fam in FAMILIES}
    _, grads = _paper_condensed(a, x, T)
    return np.concatenate([grads[0] + per_stage["u1 + u2 + u3 <= 1"],
                           grads[1] + per_stage["u2 <= 0.5"],
                           grads[2] - per_stage["u3 >= u1 + u2"] - per_stage["u3 >= 0"]])


@pytest.mark.parametrize("T", [10, 5])
def test_paper_costs_and_constraints_equal_the_numpy_model(T: int) -> None:
    game = compile_game(load_config(CONFIGS / "paper_study1.yaml", {"game.horizon": T}))
    rng = np.random.default_rng(100 + T)
    labels = [c.label for c in game.constraints]
    for _ in range(5):
        a = rng.standard_normal(game.n)
        x = 3 * rng.standard_normal(3)
        J, cons = _paper_rollout(a, x, T)
        np.testing.assert_allclose(game.costs(a, x), J, rtol=1e-12, atol=1e-12)
        assert sorted(labels) == sorted(cons)
        c = game.kkt_parts(np.r_[a, np.zeros(game.m)], x).c
        np.testing.assert_allclose(c, [cons[label][1] for label in labels], atol=1e-13)
        assert [ci.owner for ci in game.constraints] == [cons[label][0] for label in labels]
        # the condensed model agrees with the roll-out, and its gradients with gnerun's pseudogradient
        s, grads = _paper_condensed(a, x, T)
        Jc = [np.sum((s[0] - 1) ** 2 - s[0] * s[1]), np.sum((s[1] - 1) ** 2 + s[0] * s[1]), np.sum((s[2] - 1) ** 2)]
        np.testing.assert_allclose(Jc, J, rtol=1e-12)
        np.testing.assert_allclose(game.pseudogradient(a, x)[0], np.concatenate(grads), rtol=1e-12, atol=1e-11)
        lam = rng.uniform(0.0, 3.0, game.m)
        np.testing.assert_allclose(game.kkt_parts(np.r_[a, lam], x).L,
                                   _paper_stationarity(a, dict(zip(labels, lam, strict=True)), x, T),
                                   rtol=1e-12, atol=1e-11)


@pytest.mark.parametrize("T", [10, 5])
def test_paper_solution_satisfies_the_numpy_kkt_conditions(T: int) -> None:
    res = solve(load_config(CONFIGS / "paper_study1.yaml", {"game.horizon": T}))
    assert res.status == "converged"
    game = res.game
    np.testing.assert_array_equal(res.x, X0_PAPER)
    a, lam = res.z[: game.n], res.z[game.n:]
    lam_of = {c.label: v for c, v in zip(game.constraints, lam, strict=True)}
    assert np.max(np.abs(_paper_stationarity(a, lam_of, X0_PAPER, T))) <= 1e-9  # stationarity
    _, cons = _paper_rollout(a, X0_PAPER, T)
    g = np.array([cons[label][1] for label in lam_of])
    mult = np.array(list(lam_of.values()))
    assert np.max(g) <= 1e-9  # primal feasibility
    assert np.min(mult) >= -1e-9  # dual feasibility
    assert np.max(np.abs(g * mult)) <= 1e-9  # complementarity
    # the equilibrium is not trivial: agent 3's coupled constraint is active somewhere
    assert max(lam_of[f"u3 >= u1 + u2 [tau={t}]"] for t in range(T + 1)) > 1e-6


# --- 3. sizes and layout --------------------------------------------------------------------------


def test_paper_sizes_and_blocks() -> None:
    game = compile_game(load_config(CONFIGS / "paper_study1.yaml"))
    T = 10
    assert (game.n, game.m, game.size, game.nx) == (33, 44, 77, 3)
    np.testing.assert_array_equal(game.x0, X0_PAPER)
    assert game.agent_slices == [slice(0, 11), slice(11, 22), slice(22, 33)]
    assert game.multiplier_slices == [slice(0, 11), slice(11, 22), slice(22, 44)]
    assert game.shared_slice.stop - game.shared_slice.start == 0
    np.testing.assert_array_equal(game.z_start(), np.zeros(77))
    assert not game.equality_mask.any() and game.equality_mask.shape == (44,)
    # multipliers agent by agent, stage-major within an agent: agent 3 has two rows per stage
    labels = [c.label for c in game.constraints]
    assert labels[:2] == ["u1 + u2 + u3 <= 1 [tau=0]", "u1 + u2 + u3 <= 1 [tau=1]"]
    assert labels[22:26] == ["u3 >= u1 + u2 [tau=0]", "u3 >= 0 [tau=0]", "u3 >= u1 + u2 [tau=1]", "u3 >= 0 [tau=1]"]
    assert [c.stage for c in game.constraints[22:44:2]] == list(range(T + 1))
    lam = np.arange(44.0)
    by_agent = game.multipliers_by_agent(lam)
    assert by_agent == {"agent1": list(lam[:11]), "agent2": list(lam[11:22]), "agent3": list(lam[22:])}


def test_time_major_inputs_within_an_agent() -> None:
    game = compile_game(nonlinear_config("generalized"))
    T = NONLINEAR_T
    # crafted a: agent 1's entry for (input j, stage tau) is 100 + 10*tau + j, agent 2's is 200 + 10*tau
    a = np.concatenate([[100 + 10 * tau + j for tau in range(T + 1) for j in range(2)],
                        [200 + 10 * tau for tau in range(T + 1)]]).astype(float)
    assert game.agent_slices == [slice(0, 8), slice(8, 12)]
    assert game.variable_names == [["u1", "w"], ["u2"]]
    assert game.solution_by_agent(a) == {
        "a1": {"u1": [100.0, 110.0, 120.0, 130.0], "w": [101.0, 111.0, 121.0, 131.0]},
        "a2": {"u2": [200.0, 210.0, 220.0, 230.0]},
    }
    np.testing.assert_array_equal(game.first_inputs(a), [100.0, 101.0, 200.0])
    # start values (u1: 0.5, w: 0, u2: 0) repeat per stage in the same order; multipliers start at 0
    np.testing.assert_array_equal(game.z_start(), np.r_[np.tile([0.5, 0.0], T + 1), np.zeros(T + 1 + game.m)])
    # and the maths agrees: the inputs of stage tau >= 1 cannot move xi(1), i.e. the stage-0 rows of c
    parts = game.kkt_parts(np.r_[0.1 * np.ones(game.n), np.zeros(game.m)])
    stage0 = [j for j, c in enumerate(game.constraints) if c.stage == 0]
    later = [2, 3, 4, 5, 6, 7, 9, 10, 11]  # (u1, w)(1..3) of agent 1 and u2(1..3) of agent 2
    assert np.all(parts.dc_da[np.ix_(stage0, later)] == 0)
    assert np.any(parts.dc_da[np.ix_(stage0, [0, 1, 8])] != 0)


def test_paper_first_inputs_and_solution_by_agent() -> None:
    game = compile_game(load_config(CONFIGS / "paper_study1.yaml", {"game.horizon": 2}))
    a = np.arange(9.0)
    assert game.solution_by_agent(a) == {"agent1": {"u1": [0.0, 1.0, 2.0]}, "agent2": {"u2": [3.0, 4.0, 5.0]},
                                         "agent3": {"u3": [6.0, 7.0, 8.0]}}
    np.testing.assert_array_equal(game.first_inputs(a), [0.0, 3.0, 6.0])


def test_variational_shared_constraints_have_one_common_multiplier_block() -> None:
    T = NONLINEAR_T
    var = compile_game(nonlinear_config("variational"))
    gen = compile_game(nonlinear_config("generalized"))
    shared = "x1**2 + x2**2 <= 4"
    # variational: one row per stage, owner None, all in shared_slice after the agents' blocks
    sv = var.shared_slice
    assert (sv.start, sv.stop) == (var.multiplier_slices[-1].stop, var.m) and sv.stop - sv.start == T + 1
    assert [c.label for c in var.constraints[sv]] == [f"{shared} [tau={t}]" for t in range(T + 1)]
    assert all(c.owner is None for c in var.constraints[sv])
    assert not any(c.label.startswith(shared) for c in var.constraints[: sv.start])
    # each agent's own problem includes the common rows
    for i in range(2):
        assert set(range(sv.start, sv.stop)) <= set(var.agents.constraint_rows(i).tolist())
    assert "shared" in var.multipliers_by_agent(np.zeros(var.m))
    # z_i = (a_i, lambda_i) leaves the common multipliers out
    assert not set((var.n + np.arange(sv.start, sv.stop)).tolist()) & set(np.r_[var.agent_indices(0),
                                                                              var.agent_indices(1)].tolist())
    # generalized: no common block; each agent carries its own copy, with its own multiplier
    assert gen.shared_slice.stop == gen.shared_slice.start
    assert gen.m == var.m + (T + 1)
    for i, ms in enumerate(gen.multiplier_slices):
        copies = [c for c in gen.constraints[ms] if c.label.startswith(shared)]
        assert len(copies) == T + 1 and all(c.owner == i for c in copies)
    assert "shared" not in gen.multipliers_by_agent(np.zeros(gen.m))


@pytest.mark.parametrize("equilibrium", EQUILIBRIA)
def test_shared_multipliers_enter_stationarity_in_closed_form(equilibrium: str) -> None:
    # F&K A.11: L_i = 2(x1 - 1) + mu_1, 2(x2 - 1/2) + mu_2, with mu_1 = mu_2 the common multiplier if variational
    game = compile_game(load_config(CONFIGS / "fk_a11.yaml", {"game.equilibrium": equilibrium}))
    x1, x2 = 0.3, -0.4
    if equilibrium == "variational":
        assert game.m == 1 and (game.shared_slice.start, game.shared_slice.stop) == (0, 1)
        assert game.constraints[0].owner is None
        lam, mu = np.array([0.7]), (0.7, 0.7)
    else:
        assert game.m == 2 and [c.owner for c in game.constraints] == [0, 1]
        lam, mu = np.array([0.7, 0.2]), (0.7, 0.2)
    parts = game.kkt_parts(np.r_[x1, x2, lam])
    np.testing.assert_allclose(parts.L, [2 * (x1 - 1) + mu[0], 2 * (x2 - 0.5) + mu[1]], atol=1e-15)
    np.testing.assert_allclose(parts.c, np.full(game.m, x1 + x2 - 1), atol=1e-15)


def test_equality_constraints_set_the_equality_mask() -> None:
    eq = compile_game(load_config("e.yaml", text="""
game:
  kind: static
  agents:
    - name: p
      variables: {x: {lower: -1, start: 0.2}}
      cost: "x**2"
      constraints: ["x == 0.5", "2*x >= y"]
    - name: q
      variables: {y: {}}
      cost: "(y - x)**2"
      constraints: ["x + y == 1"]
"""))
    assert [c.label for c in eq.constraints] == ["x >= -1", "x == 0.5", "2*x >= y", "x + y == 1"]
    np.testing.assert_array_equal(eq.equality_mask, [False, True, False, True])
    assert [c.owner for c in eq.constraints] == [0, 0, 0, 1]
    np.testing.assert_allclose(eq.kkt_parts(np.array([0.2, 0.9, 0, 0, 0, 0])).c, [-1.2, -0.3, 0.5, 0.1], atol=1e-15)
    np.testing.assert_array_equal(eq.z_start(), [0.2, 0, 0, 0, 0, 0])
    dyn = compile_game(nonlinear_config("generalized"))
    np.testing.assert_array_equal(dyn.equality_mask, ["==" in c.label for c in dyn.constraints])
    assert dyn.equality_mask.sum() == NONLINEAR_T + 1


def test_bounds_become_owner_constraints_with_labels() -> None:
    game = compile_game(load_config(CONFIGS / "fk_a12.yaml"))
    assert [c.label for c in game.constraints] == ["x1 >= -10", "x1 <= 10", "x2 >= -10", "x2 <= 10"]
    assert [c.owner for c in game.constraints] == [0, 0, 1, 1]
    assert all(c.stage is None and not c.equality for c in game.constraints)
    assert game.multiplier_slices == [slice(0, 2), slice(2, 4)]
    np.testing.assert_allclose(game.kkt_parts(np.array([3.0, -4.0, 0, 0, 0, 0])).c, [-13, -7, -6, -14])
    np.testing.assert_array_equal(game.agents.constraint_rows(1), [2, 3])
    # dynamic bounds: one row per bound and stage, owned by the input's agent
    dyn = compile_game(nonlinear_config("variational"))
    rows = {(c.label, c.owner, c.stage) for c in dyn.constraints}
    for tau in range(NONLINEAR_T + 1):
        assert {(f"u1 >= -2 [tau={tau}]", 0, tau), (f"u1 <= 2.5 [tau={tau}]", 0, tau),
                (f"w >= -1.5 [tau={tau}]", 0, tau), (f"u2 <= 1 [tau={tau}]", 1, tau)} <= rows
    assert not any(c.label.startswith("u2 >=") or c.label.startswith("w <=") for c in dyn.constraints)


# --- 4. the structural pattern of JPhi --------------------------------------------------------------


@pytest.mark.parametrize("name, cfg", FD_PARAMS)
def test_jacobian_sparsity_covers_every_numerical_nonzero(name: str, cfg) -> None:
    game = compile_game(cfg)
    pattern = game.pattern.jacobian()
    assert sp.issparse(pattern) and pattern.format == "csr" and pattern.dtype == bool
    assert pattern.shape == (game.size, game.size)
    dense = pattern.toarray().astype(bool)
    n = game.n
    rng = np.random.default_rng(3)
    for _ in range(3):
        a, x = _random_point(name, game, rng)
        parts = game.kkt_parts(np.r_[a, rng.uniform(0.0, 2.0, game.m)], x)
        assert not np.any((parts.dL_dz != 0) & ~dense[:n]), "a nonzero of dL/dz outside the pattern"
        assert not np.any((parts.dc_da != 0) & ~dense[n:, :n]), "a nonzero of dc/da outside the pattern"
    # the multiplier branch of every complementarity row (d lambda_j / d lambda_j) is in the pattern
    assert all(dense[n + j, n + j] for j in range(game.m))


def test_jacobian_sparsity_of_the_paper_game_is_structural() -> None:
    game = compile_game(load_config(CONFIGS / "paper_study1.yaml"))
    dense = game.pattern.jacobian().toarray().astype(bool)
    n = game.n
    # agent 3's cost does not involve x1, x2: its stationarity rows do not depend on a_1 or a_2
    assert not dense[22:33, 0:22].any()
    # the row of "u2 <= 0.5 [tau=3]" touches u2(3) and its own multiplier only
    j = [c.label for c in game.constraints].index("u2 <= 0.5 [tau=3]")
    assert set(np.flatnonzero(dense[n + j])) == {11 + 3, n + j}


# --- 5. the plant model -----------------------------------------------------------------------------


def test_step_dynamics_equals_the_hand_written_dynamics() -> None:
    rng = np.random.default_rng(11)
    paper = compile_game(load_config(CONFIGS / "paper_study1.yaml"))
    nonlinear = compile_game(nonlinear_config("generalized"))
    for _ in range(5):
        x, u = rng.standard_normal(3), rng.standard_normal(3)
        np.testing.assert_allclose(paper.step_dynamics(x, u), A_PAPER @ x + u, rtol=1e-15, atol=1e-15)
        u1, w, u2 = u  # plant input order: agents in order, each agent's inputs in order
        expected = [x[0] + 0.1 * np.cos(x[2]) * u1,
                    x[1] + 0.1 * np.sin(x[2]) * u1 + 0.5 * np.tanh(w),
                    x[2] + 0.1 * np.exp(-u2) * w]
        np.testing.assert_allclose(nonlinear.step_dynamics(x, u), expected, rtol=1e-14, atol=1e-15)
    # the plant applied to the first inputs of a plan gives the state the stage-0 rows see
    a = rng.standard_normal(nonlinear.n)
    x = rng.standard_normal(3)
    x1 = nonlinear.step_dynamics(x, nonlinear.first_inputs(a))
    c = nonlinear.kkt_parts(np.r_[a, np.zeros(nonlinear.m)], x).c
    j = [c_.label for c_ in nonlinear.constraints].index("x1 + u2 <= 3 [tau=0]")
    assert c[j] == pytest.approx(x1[0] + a[8] - 3, abs=1e-14)
    with pytest.raises(ValueError):
        compile_game(load_config(CONFIGS / "fk_a12.yaml")).step_dynamics(np.zeros(0), np.zeros(2))


# --- row classes and the warm-start shift ---------------------------------------------------------


def test_coupled_and_affine_rows_by_hand() -> None:
    paper = compile_game(load_config(CONFIGS / "paper_study1.yaml", {"game.horizon": 2}))
    labels = [c.label for c in paper.constraints]
    # agent 1's u1 + u2 + u3 <= 1 and agent 3's u3 >= u1 + u2 involve the others' inputs; u2 <= 0.5, u3 >= 0 do not
    assert paper.pattern.coupled_rows() == [j for j, label in enumerate(labels)
                                    if label.startswith(("u1 + u2 + u3 <= 1", "u3 >= u1 + u2"))]
    assert paper.lq.linear_rows.all()  # input constraints of a linear game
    game = compile_game(nonlinear_config("variational"))
    labels = [c.label for c in game.constraints]
    coupled = [j for j, label in enumerate(labels) if label.startswith(("x1 + u2", "u2*u1"))]
    assert game.pattern.coupled_rows() == coupled
    # bounds are affine; x1(1) = x1 + dt cos(x3) u1(0) is affine in a (x3 is the given state), x1(tau+1) for
    # tau >= 1 is not; products of inputs and the state circle are not
    affine = [label.startswith(("u1 >=", "u1 <=", "w >=", "u2 <=")) or label == "x1 + u2 <= 3 [tau=0]"
              for label in labels]
    np.testing.assert_array_equal(game.lq.linear_rows, affine)


def test_shift_drops_stage_zero_and_repeats_the_last_stage() -> None:
    game = compile_game(nonlinear_config("variational"))
    T = NONLINEAR_T
    z = np.arange(game.size, dtype=float)
    shifted = game.shift(z)
    n = game.n
    before, after = game.solution_by_agent(z[:n]), game.solution_by_agent(shifted[:n])
    for agent, inputs in before.items():
        for name, plan in inputs.items():
            assert after[agent][name] == plan[1:] + plan[-1:]
    # multipliers: every (label family, owner) sequence over the stages is shifted the same way
    families: dict[tuple[str, int | None], list[int]] = {}
    for j, c in enumerate(game.constraints):
        families.setdefault((c.label.rsplit(" [tau=", 1)[0], c.owner), []).append(j)
    for rows in families.values():
        assert len(rows) == T + 1
        seq = z[n + np.array(rows)]
        np.testing.assert_array_equal(shifted[n + np.array(rows)], np.r_[seq[1:], seq[-1]])
