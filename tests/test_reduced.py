"""The reduced systems (gnerun/solvers/reduced.py): the same step as the full Newton system, in both formulations,
and the factor cache's capacity."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gnerun.game.compile import compile_game
from gnerun.language.config import load_config
from gnerun.runs.solving import make_solver
from gnerun.solvers.reduced import FactorCache, active_rows, assemble

CONFIGS = Path(__file__).resolve().parent.parent / "configs"


def test_the_dense_reduced_step_is_the_full_newton_step() -> None:
    cfg = load_config(CONFIGS / "nonlinear_gne.yaml", {"solver.globalization": "none"})
    solver = make_solver(cfg, compile_game(cfg))
    state = solver.init()
    compared = 0
    for _ in range(4):
        z_reduced, rcond = solver.reduced_system.point(state, solver.active_rows(state.active))
        J = solver.jacobian(state.parts, state.z, state.active)
        if z_reduced is not None and np.linalg.cond(J) < 1e10:
            dz = np.linalg.solve(J, -state.phi)
            np.testing.assert_allclose(z_reduced, state.z + dz, rtol=0, atol=1e-9 * (1 + np.abs(state.z).max()))
            compared += 1
        state = solver.step(state)
    assert compared >= 2


def test_sparse_and_dense_reduced_systems_take_the_same_step() -> None:
    cfg = load_config(CONFIGS / "paper_study1.yaml", {"solver.globalization": "none"})
    game = compile_game(cfg)
    dense = make_solver(cfg, game)
    sparse = make_solver(cfg.model_copy(update={"solver": cfg.solver.model_copy(update={"formulation": "sparse"})}),
                         game)
    a, b = dense.init(), sparse.init()
    for _ in range(2):
        a, b = dense.step(a), sparse.step(b)
    A = dense.active_rows(a.active)
    np.testing.assert_array_equal(A, sparse.active_rows(b.active))
    za = dense.reduced_system.regularized(a, A, 1e-3)
    zb = sparse.reduced_system.regularized(b, A, 1e-3)
    np.testing.assert_allclose(zb, za, rtol=0, atol=1e-9)


def test_rows_assembly_and_cache() -> None:
    active = np.array([True, False, False, True])
    eq = np.array([False, True, False, False])
    np.testing.assert_array_equal(active_rows(active, eq, True), [0, 1, 3])
    np.testing.assert_array_equal(active_rows(active, eq, False), [0, 3])
    z = assemble(6, np.array([1.0, 2.0]), np.array([1, 3]), np.array([5.0, 7.0]))
    np.testing.assert_array_equal(z, [1.0, 2.0, 0.0, 5.0, 0.0, 7.0])
    cache = FactorCache(2)
    cache.keep(b"a", 1)
    cache.keep(b"b", 2)
    assert cache.keep(b"c", 3) == 3 and dict(cache) == {b"c": 3}  # full: emptied at once
