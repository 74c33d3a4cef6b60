"""The bounded LQ family (benchmarks/problems/lq.py): configs, the hand condensation against gnerun's compiled game,
the stored references (KKT conditions, best-response gaps, closed form) and the checks' power to fail."""

from __future__ import annotations

import math

import numpy as np
import pytest

import gnerun
from benchmarks import peers
from benchmarks.problems import lq

PROBLEMS = lq.lq_problems()


def _horizon(name: str) -> int:
    return int(name.split("T=")[1].split()[0])


def test_six_problems() -> None:
    assert len(PROBLEMS) == 6
    assert {(p.family, _horizon(p.name), p.name.split()[-1]) for p in PROBLEMS} == {
        ("lq", T, eq) for T in lq.HORIZONS for eq in lq.EQUILIBRIA
    }
    for p in PROBLEMS:
        assert p.best_response_gaps is not None
        assert "solver:" not in p.config_yaml
        if p.name.endswith("variational"):
            assert p.reference is not None and p.reference.shape == (3 * (_horizon(p.name) + 1),)
            assert p.reference_source
        else:
            assert p.reference is None


@pytest.mark.parametrize("problem", PROBLEMS, ids=lambda p: p.name)
def test_config_loads_and_compiles(problem) -> None:
    cfg = gnerun.load_config(text=problem.config_yaml)
    game = gnerun.compile_game(cfg)
    assert game.n == 3 * (_horizon(problem.name) + 1)


@pytest.mark.parametrize("T", lq.HORIZONS)
def test_compiled_costs_equal_hand_condensed(T: int) -> None:
    game = gnerun.compile_game(gnerun.load_config(text=lq.lq_yaml(T, "generalized")))
    cond = lq.condense(T)
    rng = np.random.default_rng(T)
    for _ in range(5):
        a = rng.uniform(-1.5, 1.5, cond.n)
        np.testing.assert_allclose(np.asarray(game.costs(a, lq.X0)).ravel(), cond.costs(a), rtol=1e-12, atol=1e-9)


def test_hand_condensed_states_follow_the_dynamics() -> None:
    cond = lq.condense(5)
    a = np.random.default_rng(0).uniform(-1, 1, cond.n)
    u = a.reshape(3, -1)
    x = lq.X0.copy()
    for tau in range(cond.H):
        x = lq.A_DIAG * x + u[:, tau]
        np.testing.assert_allclose(cond.states(a)[:, tau], x, rtol=0, atol=1e-13)
        assert cond.A[tau] @ a + (lq.SHARED_RHS - cond.b[tau]) == pytest.approx(x.sum(), abs=1e-13)


@pytest.mark.parametrize("T", lq.HORIZONS)
def test_references_satisfy_kkt_and_have_no_gap(T: int) -> None:
    cond = lq.condense(T)
    ref = np.array(lq.REFERENCES[T])
    assert lq.vi_kkt_residual(cond, ref) <= 1e-8
    problem = next(p for p in PROBLEMS if p.name == f"LQ T={T} variational")
    for gaps in (lq.best_response_gaps(cond, ref), problem.best_response_gaps(ref)):
        assert set(gaps) == set(lq.AGENTS)
        assert max(gaps.values()) <= 1e-8


@pytest.mark.parametrize("T", lq.HORIZONS)
def test_bounds_and_the_shared_constraint_bind_at_the_references(T: int) -> None:
    # the family is hard because its constraints bind: the shared row at some stage, input bounds at others
    cond = lq.condense(T)
    ref = np.array(lq.REFERENCES[T])
    sums = cond.A @ ref - cond.b  # x1 + x2 + x3 - 3 per stage
    assert np.all(sums <= 1e-9) and np.any(np.abs(sums) <= 1e-9)
    assert np.any(np.abs(np.abs(ref) - lq.BOUND) <= 1e-9)


@pytest.mark.parametrize("T", lq.HORIZONS)
def test_extragradient_reproduces_the_references(T: int) -> None:
    z, _ = lq.solve_vi_extragradient(lq.condense(T))
    assert np.max(np.abs(z - np.array(lq.REFERENCES[T]))) <= 1e-8


@pytest.mark.parametrize("agent", range(3))
def test_a_perturbed_reference_has_a_positive_gap(agent: int) -> None:
    cond = lq.condense(5)
    a = np.array(lq.REFERENCES[5])
    k = cond.block(agent).start + 2
    a[k] += -1e-3 if a[k] > cond.lb[k] + 1e-3 else 1e-3  # downwards stays feasible: states only decrease
    assert lq.vi_kkt_residual(cond, a) > 1e-4
    gaps = lq.best_response_gaps(cond, a)
    assert 1e-8 < gaps[lq.AGENTS[agent]] < math.inf


def test_an_infeasible_point_has_an_infinite_gap() -> None:
    cond = lq.condense(5)
    a = np.array(lq.REFERENCES[5])
    a[cond.block(1).start] = 1.5  # above agent 2's bound
    assert math.isinf(lq.best_response_gaps(cond, a)["agent2"])


def test_binding_constraints_variant(monkeypatch: pytest.MonkeyPatch) -> None:
    """With targets 2 and |u| <= 0.5 bounds and the shared constraint bind: the condensation still matches gnerun,
    and the extragradient's active-set finish gives a KKT point without gaps."""
    monkeypatch.setattr(lq, "TARGET", 2.0)
    monkeypatch.setattr(lq, "BOUND", 0.5)
    cond = lq.condense(5)
    game = gnerun.compile_game(gnerun.load_config(text=lq.lq_yaml(5, "variational")))
    a = np.random.default_rng(1).uniform(-1, 1, cond.n)
    np.testing.assert_allclose(np.asarray(game.costs(a, lq.X0)).ravel(), cond.costs(a), rtol=1e-12, atol=1e-9)
    z, _ = lq.solve_vi_extragradient(cond)
    assert np.sum(cond.h - cond.G @ z <= 1e-9) >= 3  # several constraints active
    assert lq.vi_kkt_residual(cond, z) <= 1e-10
    assert max(lq.best_response_gaps(cond, z).values()) <= 1e-10


@pytest.mark.parametrize("equilibrium", lq.EQUILIBRIA)
def test_lcp_data_holds_at_the_reference(equilibrium: str) -> None:
    cond = lq.condense(5)
    ref = np.array(lq.REFERENCES[5])
    active = cond.h - cond.G @ ref <= 1e-9
    lam = np.zeros(cond.G.shape[0])
    if active.any():
        lam[active] = lq._active_set_solve(cond, active)[1]
    lam_upper, lam_shared = lam[: cond.n], lam[2 * cond.n :]
    if equilibrium == "generalized":  # at a variational equilibrium every agent's multiplier is the common one
        lam_shared = np.tile(lam_shared, 3)
    M, q = peers.lcp_data(cond, equilibrium)
    v = np.concatenate([ref - cond.lb, lam_upper, lam_shared])
    w = M @ v + q
    assert v.min() >= -1e-12 and w.min() >= -1e-10 and abs(v @ w) <= 1e-9


def test_compute_references_agree_with_nashopt() -> None:
    pytest.importorskip("nashopt")
    pytest.importorskip("daqp")
    refs = lq.compute_references(require_nashopt=True)
    for T, z in refs.items():
        assert np.max(np.abs(z - np.array(lq.REFERENCES[T]))) <= 1e-8


@pytest.mark.slow
def test_family_peers_smoke() -> None:
    pytest.importorskip("nashopt")
    results = peers.lq_family_peers(5, "variational", repeats=1, siconos=False)
    by_method = {r.method: r for r in results}
    for method in ("GNEP_LQ dr_daqp", "GNEP_LQ lemke_dual", "GNEP_LQ qp_gnep", "GNEP_LQ MILP (HiGHS)"):
        assert by_method[method].success, by_method[method]
        assert by_method[method].time_s is not None
