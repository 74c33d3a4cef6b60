"""The sparse (non-condensed) formulation: the same iterates, solutions and closed loops as the condensed
one, on linear-quadratic and nonlinear dynamic games; its choice and its refusals."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.family import family_config, family_yaml
from gnerun import simulate, solve
from gnerun.game import banded as banded_code
from gnerun.game.compile import compile_game
from gnerun.language.config import ConfigError, load_config
from gnerun.runs.solving import SPARSE_FROM, SPARSE_WORK, formulation, make_solver
from gnerun.solvers import hybrid, interior_point
from gnerun.solvers.driver import iterate
from gnerun.solvers.sparse_ssn import SparseSemismoothNewton
from gnerun.solvers.ssn import SemismoothNewton, Status

from .conftest import CONFIGS, run_cli

VEHICLES_SSN = {"solver.kind": "ssn", "solver.globalization": "none", "solver.complementarity": "min"}
CASES = [
    ("paper_study1", {}),
    ("vehicles", VEHICLES_SSN),  # nonlinear dynamics and costs, a nonconvex shared constraint
    ("vehicles", {**VEHICLES_SSN, "solver.globalization": "line_search"}),
    ("variational_gne", {"solver.kind": "ssn", "solver.globalization": "none"}),  # bounds, a common multiplier
]


def _pair(name: str, overrides: dict):
    base = load_config(CONFIGS / f"{name}.yaml", overrides)
    game = compile_game(base)
    cond = make_solver(base.model_copy(update={"solver": base.solver.model_copy(update={"formulation": "condensed"})}),
                       game)
    sparse = make_solver(base.model_copy(update={"solver": base.solver.model_copy(update={"formulation": "sparse"})}),
                         game)
    # (the line search wraps the Newton method of each formulation: gnerun.solvers.globalization)
    assert type(getattr(cond, "newton", cond)) is SemismoothNewton
    assert isinstance(getattr(sparse, "newton", sparse), SparseSemismoothNewton)
    return game, cond, sparse


@pytest.mark.parametrize(("name", "overrides"), CASES)
def test_sparse_steps_equal_the_condensed_steps(name: str, overrides: dict) -> None:
    """From the same iterate, along the method's path and from random points (multipliers of both signs)."""
    game, cond, sparse = _pair(name, overrides)
    rng = np.random.default_rng(1)
    starts = [game.z_start()] + [game.z_start() + rng.normal(scale=0.3, size=game.size) for _ in range(3)]
    compared = 0
    for z0 in starts:
        a, b = cond.init(z0), sparse.init(z0)
        for _ in range(6):
            scale = 1 + np.abs(a.z).max()
            np.testing.assert_allclose(b.phi, a.phi, rtol=0, atol=1e-10 * scale)
            np.testing.assert_array_equal(b.active, a.active)
            if cond.terminate(a)[0]:
                break
            a, b = cond.step(a), sparse.step(b)
            assert b.status == a.status, (a.message, b.message)
            compared += 1
            if a.status != Status.RUNNING:  # e.g. a singular system from a random start, seen by both
                break
            np.testing.assert_allclose(b.z, a.z, rtol=0, atol=1e-9 * (1 + np.abs(a.z).max()))
    assert compared >= 6


def test_sparse_and_condensed_reach_the_same_solution() -> None:
    for name in ("paper_study1", "vehicles"):
        results = {}
        for f in ("condensed", "sparse"):
            cfg = load_config(CONFIGS / f"{name}.yaml", {"solver.formulation": f})
            results[f] = solve(cfg)
            assert results[f].status == "converged", results[f]
        c, s = results["condensed"], results["sparse"]
        assert s.iterations == c.iterations
        np.testing.assert_allclose(s.z, c.z, rtol=0, atol=1e-9)
        assert max(s.certificate["best_response_gap"].values()) < 1e-7


@pytest.mark.parametrize("name", ["paper_study2", "vehicles"])
def test_sparse_and_condensed_give_the_same_closed_loop(name: str) -> None:
    sims = {}
    for f in ("condensed", "sparse"):
        cfg = load_config(CONFIGS / f"{name}.yaml", {"solver.formulation": f, "run.steps": 12, "run.K": [1, 2, 5]})
        sims[f] = simulate(cfg)
    for K in (1, 2, 5):
        c, s = sims["condensed"][K], sims["sparse"][K]
        np.testing.assert_allclose(s.u, c.u, rtol=0, atol=1e-9)
        np.testing.assert_allclose(s.x, c.x, rtol=0, atol=1e-9)
        np.testing.assert_allclose(s.e_norm, c.e_norm, rtol=0, atol=1e-8)
        assert s.status == c.status
    # the budget matters on this loop: K = 1 and 2 leave an error, K = 5 none (both formulations agree on it)
    if name == "paper_study2":
        assert np.nanmax(sims["sparse"][1].e_norm) > 1 and np.nanmax(sims["sparse"][5].e_norm) < 1e-12


def test_nonlinear_dynamics_choose_by_unknowns_times_stages() -> None:
    """The 41-knot MPC merge (600 unknowns, 40 stages) and the 21-knot 5-car merge (600 unknowns, 20 stages) are
    sparse, two vehicles over 3 stages (U (T + 1) below SPARSE_WORK) condensed; the demo's linear dynamics keep the
    count of unknowns (403 at T = 30: condensed)."""
    mpc = load_config(CONFIGS / "algames_merge_mpc.yaml")
    game = compile_game(mpc)
    assert game.size * 40 >= SPARSE_WORK and formulation(mpc, game) == "sparse"
    five = load_config(CONFIGS / "algames_merge_n.yaml", {"game.parameters.N": 5})
    game = compile_game(five)
    assert game.size == 600 and formulation(five, game) == "sparse"
    short = load_config(CONFIGS / "vehicles.yaml", {"game.horizon": 2})
    game = compile_game(short)
    assert not game.lq.linear_dynamics and game.size * 3 < SPARSE_WORK and formulation(short, game) == "condensed"
    demo = load_config(CONFIGS / "mcp_demo.yaml", {"game.horizon": 30})
    assert formulation(demo, compile_game(demo)) == "condensed"


@pytest.mark.slow
def test_long_horizons_choose_the_sparse_formulation_and_solve() -> None:
    cfg = family_config(3, 120)
    game = compile_game(cfg)
    assert cfg.solver.formulation == "auto" and game.size >= SPARSE_FROM
    assert formulation(cfg, game) == "sparse"
    assert formulation(family_config(3, 10), compile_game(family_config(3, 10))) == "condensed"
    res = solve(cfg)
    assert res.status == "converged" and res.residual_history[-1] <= cfg.solver.tol
    assert max(res.certificate["best_response_gap"].values()) < 1e-7
    # the same solution from the condensed system
    dense = solve(load_config(text=family_yaml(3, 120), overrides={"solver.formulation": "condensed"}))
    np.testing.assert_allclose(res.z, dense.z, rtol=0, atol=1e-9)


def test_a_singular_system_is_a_status_in_the_sparse_formulation_too() -> None:
    """A plain GNE whose agents share one constraint has a continuum of equilibria: JPhi is singular there."""
    text = (CONFIGS / "variational_gne.yaml").read_text()
    text = text.replace("equilibrium: variational", "equilibrium: generalized")
    statuses = {}
    for f in ("condensed", "sparse"):
        cfg = load_config(text=text, overrides={"solver.kind": "ssn", "solver.formulation": f,
                                                "solver.globalization": "none"})
        statuses[f] = solve(cfg)
    assert statuses["condensed"].status == statuses["sparse"].status == "singular_jacobian"
    assert "continuum of equilibria" in statuses["sparse"].message


@pytest.mark.parametrize(("config", "overrides", "reason"), [
    ("harker", {}, "static game"),
    ("paper_study1", {"solver.complementarity": "fischer_burmeister"}, "min-map"),
    ("paper_study1_disturbed", {}, "jacobian_noise"),
    ("variational_gne", {}, "'jn'"),
])
def test_sparse_is_refused_where_it_does_not_apply(config: str, overrides: dict, reason: str) -> None:
    with pytest.raises(ConfigError) as err:
        load_config(CONFIGS / f"{config}.yaml", {**overrides, "solver.formulation": "sparse"})
    assert reason in str(err.value) and "solver.formulation" in str(err.value)


def test_cli_reports_an_inapplicable_formulation_with_exit_code_2(tmp_path) -> None:
    cfg = tmp_path / "static.yaml"
    cfg.write_text((CONFIGS / "harker.yaml").read_text() + "\n")
    proc = run_cli("solve", str(cfg), "--set", "solver.formulation=sparse", "--out", str(tmp_path / "run"))
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert "solver.formulation" in proc.stderr and "static game" in proc.stderr


def test_the_superlu_ordering_is_the_one_with_least_fill() -> None:
    """Ordering factorises the first matrix with every candidate, keeps the one whose L and U have fewest nonzeros,
    and uses it from then on; its factors solve the system."""
    import scipy.sparse as sp

    from gnerun.game import sparse as gs

    rng = np.random.default_rng(0)
    n = 300
    # a banded matrix (minimum degree on M^T M keeps it banded) plus a few dense rows and columns
    M = sp.diags([rng.uniform(1, 2, n - 1), rng.uniform(4, 5, n), rng.uniform(1, 2, n - 1)], [-1, 0, 1]).tolil()
    for k in rng.choice(n, 4, replace=False):
        M[k, :] = rng.uniform(0, 0.01, n)
        M[k, k] = 5.0
    M = M.tocsc()
    fills = {spec: (lambda lu: lu.L.nnz + lu.U.nnz)(gs._splu(M, spec)) for spec in gs.ORDERINGS}
    ordering = gs.Ordering()
    lu, rcond = ordering.factor(M)
    assert ordering.spec == min(fills, key=fills.get)
    b = rng.standard_normal(n)
    np.testing.assert_allclose(M @ lu.solve(b), b, atol=1e-10)
    assert 0 < rcond <= 1
    lu2, _ = ordering.factor(M)  # the kept choice
    np.testing.assert_allclose(lu2.solve(b), lu.solve(b), atol=1e-12)


def test_costates_only_for_the_states_an_agent_reaches() -> None:
    """Agent i's costates cover the states its inputs move through the dynamics, to a fixed point: here agent 1
    drives x1 and, through it, x3; agent 2 drives x2 alone; nobody drives x4."""
    from gnerun.game.sparse import compile_sparse, reachable_states

    cfg = load_config({"name": "reach", "game": {
        "kind": "dynamic", "horizon": 3, "states": ["x1", "x2", "x3", "x4"],
        "dynamics": {"x1": "x1 + u1", "x2": "0.5*x2 + u2**2", "x3": "x3 + 0.1*x1", "x4": "0.9*x4"},
        "x0": [1, 2, 3, 4],
        "agents": [{"name": "one", "inputs": {"u1": {}}, "stage_cost": "x1**2 + x3**2 + u1**2 + x2"},
                   {"name": "two", "inputs": {"u2": {}}, "stage_cost": "(x2 - x1)**2 + u2**2"}]}})
    game = compile_game(cfg)
    system = compile_sparse(cfg, game)
    r1, r2 = reachable_states(_dynamics(cfg), [[0], [1]])
    np.testing.assert_array_equal(r1, [True, False, True, False])
    np.testing.assert_array_equal(r2, [False, True, False, False])
    T1 = 4  # stages 1..T+1
    assert [s.stop - s.start for s in system.costates] == [2 * T1, 1 * T1]
    assert system.size == game.n + 4 * T1 + 3 * T1 + game.m
    # and the steps are still the condensed ones
    cond = make_solver(cfg.model_copy(update={"solver": cfg.solver.model_copy(update={"formulation": "condensed"})}),
                       game)
    sparse = make_solver(cfg.model_copy(update={"solver": cfg.solver.model_copy(update={"formulation": "sparse"})}),
                         game)
    a, b = cond.init(), sparse.init()
    for _ in range(4):
        a, b = cond.step(a), sparse.step(b)
        np.testing.assert_allclose(b.z, a.z, rtol=0, atol=1e-10)


def _dynamics(cfg):
    import casadi as ca

    from gnerun.game.compile import _expressions, _layout

    lay = _layout(cfg.game)
    return _expressions(cfg.game, lay, ca.SX.sym("a", lay.n), ca.SX.sym("x", lay.nx), []).dynamics


@pytest.mark.slow
def test_the_globalized_sparse_method_takes_the_condensed_iterates(monkeypatch: pytest.MonkeyPatch) -> None:
    """On the 3-car merge from zero inputs the default method (its Newton phase kept past a first step that climbs)
    meets singular Newton systems (Levenberg-Marquardt steps) and enters its interior phase; the sparse formulation
    takes the same iterates through all of it: its Levenberg-Marquardt step is the condensed one (the states and
    costates eliminated, not regularised), and its interior direction makes each player's block of the Schur
    complement positive definite as the condensed form does."""
    monkeypatch.setattr(hybrid, "FIRST_STEP", np.inf)
    monkeypatch.setattr(hybrid, "PLANS_INTERIOR", False)  # (the Newton phase from the decoupled plans, kept)
    cfg = load_config(CONFIGS / "algames_merge_n.yaml")
    game = compile_game(cfg)
    solvers = {f: make_solver(cfg.model_copy(update={"solver": cfg.solver.model_copy(update={"formulation": f})}),
                              game) for f in ("condensed", "sparse")}
    a, b = solvers["condensed"].init(), solvers["sparse"].init()
    singular = interior = 0
    # 24 steps: the Newton phase and eight interior steps; later interior steps, at a small barrier eps, amplify the
    # rounding differences of the two forms (the same arithmetic in another order) about fourfold per step
    for _ in range(24):
        a, b = solvers["condensed"].step(a), solvers["sparse"].step(b)
        assert b.search.phase == a.search.phase and b.status == a.status
        np.testing.assert_allclose(b.z, a.z, rtol=0, atol=1e-7 * (1 + np.abs(a.z).max()))
        singular += a.search.phase == "newton" and a.rcond < cfg.solver.min_rcond  # a Levenberg-Marquardt step
        interior += a.search.phase == "interior"
    assert singular >= 3 and interior >= 5


def test_a_sparse_solve_without_best_responses_builds_no_condensed_derivatives() -> None:
    """The condensed KKT derivatives nest through the dynamics and take seconds to build on a long horizon; a solve in
    the sparse formulation whose certificate is the KKT residual alone (run.certificate: false) must not build them,
    and its KKT residual is the one the condensed derivatives' evaluation gives."""
    from gnerun.runs.solving import certified_solve
    from gnerun.solvers.certificate import kkt_residuals

    cfg = load_config(text=family_yaml(3, 60), overrides={"solver.formulation": "sparse"})
    game = compile_game(cfg)
    solver = make_solver(cfg, game)
    out = certified_solve(game, solver, solver.init(), best_responses=False)
    assert out.state.status == Status.CONVERGED
    assert "_derivatives" not in game.__dict__
    residual = out.certificate["kkt_residual"]
    assert residual <= cfg.solver.tol
    assert kkt_residuals(game, out.state.z) == out.certificate
    parts = game.kkt_parts(out.state.z)  # builds them: the same L and c
    L, c = game.kkt_residual(out.state.z)
    np.testing.assert_allclose(L, parts.L, rtol=0, atol=1e-12)
    np.testing.assert_allclose(c, parts.c, rtol=0, atol=1e-12)


@pytest.mark.parametrize("command", ["solve", "simulate"])
def test_the_sparse_system_is_built_with_the_game_before_the_run(command: str, tmp_path, monkeypatch) -> None:
    """solve and simulate build the sparse system once, with the game, before the run directory is claimed (the
    closed loops of every K then take it as built)."""
    import gnerun.game.sparse as sparse_module
    from gnerun.runs import closed_loop, rundir, solving

    built: list[int] = []
    at_claim: list[int] = []
    compile_sparse = sparse_module.compile_sparse
    create = rundir.RunDirectory.create

    def counted(*args, **kwargs):
        built.append(1)
        return compile_sparse(*args, **kwargs)

    def claimed(*args, **kwargs):
        at_claim.append(len(built))
        return create(*args, **kwargs)

    monkeypatch.setattr(sparse_module, "compile_sparse", counted)
    monkeypatch.setattr(rundir.RunDirectory, "create", claimed)
    cfg = load_config(CONFIGS / "paper_study2.yaml",
                      {"solver.formulation": "sparse", "solver.globalization": "none", "run.steps": 3,
                       "run.K": [1, 3], "run.reference": "none", "run.initial": "start"})
    if command == "solve":
        solving.solve(cfg, tmp_path / "run")
    else:
        closed_loop.simulate(cfg, tmp_path / "run")
    assert at_claim == [1] and len(built) == 1


def _merge_system():
    """ALGAMES's merge in the sparse formulation, a point of its solve from the configured start (after the Newton
    phase and a few interior steps: multipliers of all sizes; not from the cars' decoupled plans) and that point's
    parts."""
    cfg = load_config(CONFIGS / "algames_merge.yaml", {"solver.formulation": "sparse"})
    with pytest.MonkeyPatch.context() as m:
        m.setattr(hybrid, "DECOUPLE_ABOVE", np.inf)
        return _stepped(cfg, 15)


def _stepped(cfg, steps: int):
    """The game of ``cfg``, its default solver and the state after ``steps`` steps from the config's start."""
    game = compile_game(cfg)
    solver = make_solver(cfg, game)
    state = solver.init()
    for _ in range(steps):
        state = solver.step(state)
    return game, solver, state


def test_the_stage_order_makes_the_merge_banded() -> None:
    """Every row and column belongs to one stage and touches only the neighbouring ones: ordered stage by stage, the
    band reaches less than a stage (39 unknowns: 6 decisions, 12 states, 12 costates, 9 multipliers) to either side
    of the diagonal, and the order of kinds within a stage makes it about half a stage below."""
    game, solver, _ = _merge_system()
    system = solver.newton.system
    order = system.stage_order
    stages = game.horizon + 1
    assert system.size == 39 * stages
    assert order.upper < 39 and order.lower < 20
    M = system.matrix(np.ones(system.pattern.nnz)).toarray()
    rows, cols = np.argsort(order.row_key, kind="stable"), np.argsort(order.col_key, kind="stable")
    i, j = np.nonzero(M[rows][:, cols])
    assert (i - j).max() <= order.lower and (j - i).max() <= order.upper


def test_banded_and_superlu_factors_solve_the_reduced_and_interior_systems() -> None:
    """Both factorisations of the matrices the steps factorise (the reduced Newton system of an active set, the
    interior matrix with additions to its diagonal) solve them as a dense solve does, and their condition estimates
    bound the true reciprocal condition number from above by less than a factor 3 (LAPACK's estimator)."""
    from gnerun.game.sparse import KeptLayout

    game, solver, state = _merge_system()
    system = solver.newton.system
    J = system.matrix(state.parts.J).toarray()
    n, lam0 = game.n, system.size - game.m
    rng = np.random.default_rng(2)
    A = np.flatnonzero(state.z[n:] > 1e-3)  # the rows whose multipliers the interior phase has made large
    assert 0 < A.size < game.m
    everything = np.arange(system.size)
    at = np.concatenate([np.arange(n), lam0 + np.arange(game.m)])
    add = np.concatenate([rng.uniform(0, 1e-2, n), -rng.uniform(0.1, 10, game.m)])
    for keep, where, extra in ((system.kept(A), None, None), (everything, at, add)):
        M = J[keep][:, keep]
        if where is not None:
            M[where, where] += extra
        b = rng.standard_normal(keep.size)
        x = np.linalg.solve(M, b)
        exact = 1.0 / (np.abs(M).sum(axis=0).max() * np.abs(np.linalg.inv(M)).sum(axis=0).max())
        for banded in (True, False):
            layout = KeptLayout(system.stage_order, keep, where, banded=banded)
            lu, rcond = layout.factor(state.parts.J, extra) if banded else \
                system.orderings["newton"].factor(layout.csc(state.parts.J, extra))
            np.testing.assert_allclose(lu.solve(b), x, rtol=0, atol=1e-9 * np.abs(x).max())
            assert exact * (1 - 1e-9) <= rcond <= 3 * exact


def test_a_condition_estimate_left_out_is_made_later_from_the_same_factors(monkeypatch: pytest.MonkeyPatch) -> None:
    """factor_kept without its estimate (NaN) gives the factors whose estimate rcond_kept then makes: the number
    factor_kept returns with it, to the bit, for the banded LU and SuperLU, with and without additions to the
    diagonal."""
    game, solver, state = _merge_system()
    system = solver.newton.system
    J, n, lam0 = state.parts.J, game.n, system.size - game.m
    A = np.flatnonzero(state.z[n:] > 1e-3)
    everything = np.arange(system.size)
    at = np.concatenate([np.arange(n), lam0 + np.arange(game.m)])
    add = np.concatenate([np.full(n, 1e-3), np.full(game.m, -1.0)])
    for banded in (True, False):
        monkeypatch.setattr(system.stage_order, "banded", banded)
        system.stage_order.layouts.clear()
        for keep, where, extra in ((system.kept(A), None, None), (everything, at, add)):
            assert system.layout(keep, where).banded == banded
            _, rcond = system.factor_kept("newton", J, keep, where, extra)
            factors, left_out = system.factor_kept("newton", J, keep, where, extra, estimate=False)
            assert np.isnan(left_out) and 0.0 < rcond < 1.0
            assert system.rcond_kept(factors, J, keep, where, extra) == rcond
    system.stage_order.layouts.clear()


def test_the_inverse_norm_estimate_is_lapacks() -> None:
    """Hager's and Higham's estimate of ||A^-1||_1 from solves: the one LAPACK's dgecon computes (same algorithm),
    on matrices where it is exact and where it is not."""
    from scipy.linalg import lapack

    from gnerun.game.sparse import inverse_norm

    rng = np.random.default_rng(3)
    for k in range(20):
        n = 5 + 7 * k
        M = rng.standard_normal((n, n)) + (k % 3) * np.eye(n)
        lu, piv, info = lapack.dgetrf(M)
        norm = np.abs(M).sum(axis=0).max()
        rcond, _ = lapack.dgecon(lu, norm)
        est = inverse_norm(lambda b, lu=lu, piv=piv: lapack.dgetrs(lu, piv, b)[0],
                           lambda b, lu=lu, piv=piv: lapack.dgetrs(lu, piv, b, trans=1)[0], n)
        assert est == pytest.approx(1.0 / (rcond * norm), rel=1e-9)
        assert est <= np.abs(np.linalg.inv(M)).sum(axis=0).max() * (1 + 1e-9)


def _unequal_vehicles():
    """configs/vehicles.yaml with the second car's heading fixed: one input (speed) reaching two states against the
    first car's two inputs reaching three (the players' blocks of unequal sizes), at a point of its solve."""
    text = (CONFIGS / "vehicles.yaml").read_text()
    text = text.replace('th2: "th2 + dt*w2"', 'th2: "th2"').replace(", w2: {lower: -1.5, upper: 1.5, start: 0}", "")
    text = text.replace("r*(w2**2 + (v2 - 1)**2)", "r*(v2 - 1)**2")
    cfg = load_config(text=text, overrides={"solver.formulation": "sparse", "solver.globalization": "auto"})
    return _stepped(cfg, 3)


def test_the_compiled_complement_leaves_a_value_that_is_not_finite_to_numpy() -> None:
    """The compiled players' complement skips the zeros beyond each row's length; where a value that is not finite
    would meet one of them (numpy's product is NaN there), the call is numpy's, NaN for NaN, and the next finite call
    is the compiled one again."""
    from gnerun.solvers.interior_point import InteriorPoint

    game, solver, state = _merge_system()
    ip = InteriorPoint(solver.newton)
    templates = ip.linear._blocks()
    D = np.random.default_rng(7).uniform(0.01, 100, ip.I.size)
    data = state.parts.J
    templates._stacked(data, D)  # the first call: compared with numpy
    if not templates.compiled:
        pytest.skip("the banded code is not compiled here")
    bad = D.copy()
    bad[0] = np.inf
    K = templates._stacked(data, bad)
    assert templates.compiled is False and np.array_equal(K, templates._numpy(data, bad), equal_nan=True)
    assert templates._compiled(data, bad) is False
    again = templates._stacked(data, D)
    assert templates.compiled and np.array_equal(again, templates._numpy(data, D))


@pytest.mark.parametrize("system", [_merge_system, _unequal_vehicles], ids=["merge", "unequal players"])
def test_the_players_blocks_of_the_interior_complement(system) -> None:
    """Each player's block of the interior matrix's Schur complement on (a, lambda_E), found stage-structured (banded
    triangular solves with the dynamics' blocks, all players at once), equals the dense complement
    K_ii - K_iR K_RR^-1 K_Ri (R: the states, costates and inequality multipliers)."""
    from gnerun.solvers.interior_point import InteriorPoint

    game, solver, state = system()
    system = solver.newton.system
    ip = InteriorPoint(solver.newton)
    n, lam0 = game.n, system.size - game.m
    D = np.random.default_rng(4).uniform(0.01, 100, ip.I.size)
    K = system.matrix(state.parts.J).toarray()
    K[lam0 + ip.I, lam0 + ip.I] -= D
    R = np.concatenate([np.arange(n, lam0), lam0 + ip.I])
    blocks = ip.linear._blocks().complement(state.parts.J, D)
    assert [b.shape for b in blocks] == [(sl.stop - sl.start,) * 2 for sl in game.agent_slices]
    for sl, block in zip(game.agent_slices, blocks, strict=True):
        i = np.arange(sl.start, sl.stop)
        dense = K[np.ix_(i, i)] - K[np.ix_(i, R)] @ np.linalg.solve(K[np.ix_(R, R)], K[np.ix_(R, i)])
        np.testing.assert_allclose(block, dense, rtol=0, atol=1e-8 * np.abs(dense).max())
    # the compiled complement (gnerun.game.banded.PlayersComplement, where the banded code is compiled) gives numpy's
    # and scipy.sparse's values to the bit (it adds no zeros: only a zero's sign may differ)
    templates = ip.linear._blocks()
    assert templates.compiled == (banded_code.status() == "compiled")
    for scale in (1e-8, 1.0, 1e3):
        D2 = scale * np.random.default_rng(5).uniform(0.01, 100, ip.I.size)
        ours, reference = templates._stacked(state.parts.J, D2), templates._numpy(state.parts.J, D2)
        assert not np.isnan(reference).any() and np.array_equal(ours, reference)
        assert templates.shifts(state.parts.J, D2, recursion=False) == templates._numpy_shifts(reference)
    # and the players' shifts, with scipy's dpotrf: on indefinite blocks (random), one that is not finite, one of inf
    rng = np.random.default_rng(6)
    for case in range(4):
        K = rng.standard_normal(reference.shape) * 10.0 ** rng.uniform(-3, 3)
        if case == 2:
            K[-1, 0] = np.nan
        if case == 3:
            K[-2, 1] = np.inf
        expected = templates._numpy_shifts(K)
        assert any(expected[0]) and expected[1] >= 1.0
        if templates.compiled:
            found = templates._compiled.shifts(K)
            assert list(found[0]) == expected[0] and found[1] == expected[1]
    assert templates._compiled_shifts is (True if templates.compiled else None)
    # another interior phase on the same system (the next draw of a Monte Carlo, a restart) reuses the templates:
    # one set per set of inequality rows (the game's, and the decoupled game's where its solve began with it)
    kept = len(system.agent_blocks)
    again = InteriorPoint(solver.newton)
    assert again.linear._blocks() is ip.linear._blocks()
    assert len(system.agent_blocks) == kept <= 2
    for b, b2 in zip(blocks, again.linear._blocks().complement(state.parts.J, D), strict=True):
        np.testing.assert_array_equal(b, b2)



def _interior_matrices(problems, count: int, monkeypatch: pytest.MonkeyPatch) -> list:
    """Every interior-point matrix (the barrier, K's nonzeros and D) that solves of these problems factorise."""
    from gnerun.solvers import interior_point

    seen = []
    shifts = interior_point.SparseBarrier._shifts
    monkeypatch.setattr(interior_point, "FUSED", False)  # every matrix through the numpy code's shifts

    def recorded(self, data, D):
        seen.append((self, data.copy(), D.copy()))
        return shifts(self, data, D)

    monkeypatch.setattr(interior_point.SparseBarrier, "_shifts", recorded)
    for p in problems[:count]:
        cfg = load_config(text=p.config_yaml)
        game = compile_game(cfg)
        iterate(make_solver(cfg, game), make_solver(cfg, game).init())
    monkeypatch.undo()
    return seen


@pytest.mark.parametrize("family", ["merge", "intersection", "overtaking"])
def test_the_stage_recursion_decides_as_the_players_dense_blocks(family: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """On every interior-point matrix of ALGAMES's merges and intersections and of the overtaking game, the players'
    stage recursion (the reduced Hessian's Riccati recursion over each player's stages) finds every block positive
    definite exactly where the dense blocks' Cholesky factorisations all succeed, on a matrix with no convexifying
    shift; where it says so, the shifts are zero and the scale, made when asked for, is the dense blocks'."""
    from benchmarks.problems import trajectory

    if banded_code.status() != "compiled":
        pytest.skip(f"nothing compiled here: {banded_code.status()}")
    problems = {"merge": lambda: trajectory.merge_problems(3),
                "intersection": lambda: trajectory.intersection_problems(1),
                "overtaking": trajectory.overtaking_problems}[family]()
    seen = _interior_matrices(problems, 3, monkeypatch)
    verdicts = {0: 0, 1: 0}
    for barrier, data, D in seen:
        blocks = barrier._blocks()
        assert blocks._definite is not None  # these games have the stage structure
        verdict = blocks._definite(data, D)
        deltas, scale = blocks.shifts(data, D, recursion=False)
        assert verdict == (1 if not any(deltas) else 0)
        verdicts[verdict] += 1
        if verdict == 1:
            assert blocks.shifts(data, D) == ([0.0] * len(deltas), None)
            barrier._held = interior_point._Factored(None, data, D, np.zeros(0), None, {}, True)
            assert barrier.scale == scale
    assert verdicts[1] > 0 and (family == "intersection" or verdicts[0] > 0)  # both answers met (the intersection:
    # its players' blocks are positive definite at every step of draw 0)


def test_a_hessian_entry_between_two_stages_leaves_the_dense_blocks(monkeypatch: pytest.MonkeyPatch) -> None:
    """A game whose Hessian couples two stages' groups (here a player's u(0) and u(1), as a cost on their difference
    would) has no stage recursion: its players' blocks are formed and tested densely, as before."""
    import scipy.sparse as sp

    game, solver, state = _merge_system()
    system = solver.newton.system
    ip = interior_point.InteriorPoint(solver.newton)
    barrier = ip.linear
    pattern = system.pattern
    numbered = sp.csc_matrix((np.arange(1, pattern.nnz + 1, dtype=float), pattern.indices, pattern.indptr),
                             shape=pattern.shape)
    row_stage, _, col_stage, _ = system.stage_order.stages
    agents = []
    n, S, lam0 = game.n, system.S, barrier.lam0
    P = lam0 - n - S
    for ai, pi, own in zip(game.agent_slices, system.costates, system.states, strict=True):
        agents.append((n + P + own, n + own, np.arange(ai.start, ai.stop), np.arange(n + pi.start, n + pi.stop),
                       np.arange(n + S + pi.start, n + S + pi.stop)))
    lam_I = lam0 + ip.I
    assert interior_point._StageRecursion.build(numbered, agents, lam_I, row_stage, col_stage) is not None
    decisions = np.arange(game.agent_slices[0].start, game.agent_slices[0].stop)
    u0, u1 = decisions[col_stage[decisions] == 0][0], decisions[col_stage[decisions] == 1][0]
    coupled = numbered.tolil()
    coupled[u0, u1] = pattern.nnz + 1.0
    assert interior_point._StageRecursion.build(coupled.tocsc(), agents, lam_I, row_stage, col_stage) is None


def test_the_interior_matrix_solved_with_its_inequality_multipliers_eliminated() -> None:
    """The interior matrix with its inequality multipliers eliminated before the factorisation (the Schur complement
    K_rr + K_rl D^-1 K_lr, banded or by SuperLU, then dlambda_I = D^-1 (K_lr x_r - b_l)) solves the unreduced system
    as the unreduced banded LU does, with D from 1e-10 to 1e4 (1/D up to 1e10, as in the merges' last iterations), on
    a narrower band: 600 unknowns and (kl, ku) = (18, 18) instead of 780 and (18, 27)."""
    game, solver, state = _merge_system()
    system = solver.newton.system
    n, m, lam0 = game.n, game.m, system.size - game.m
    rng = np.random.default_rng(5)
    everything = np.arange(system.size)
    at = np.concatenate([np.arange(n), lam0 + np.arange(m)])
    D = 10.0 ** rng.uniform(-10, 4, m)
    add = np.concatenate([rng.uniform(0, 1e-2, n), -D])
    K = system.matrix(state.parts.J).toarray()
    K[at, at] += add
    b = rng.standard_normal(system.size)
    reference = np.linalg.solve(K, b)
    unreduced, _ = system.factor_kept("interior", state.parts.J, everything, at, add, estimate=False)
    assert np.abs(unreduced.solve(b) - reference).max() <= 1e-10 * np.abs(reference).max()
    for banded in (True, False):
        system.stage_order.banded = banded
        system.stage_order.layouts.clear()  # (a kept layout keeps the factorisation it was made for)
        layout = system.layout(everything, at, lam0 + np.arange(m))
        assert layout.banded == banded
        eliminated, _ = system.factor_kept("interior", state.parts.J, everything, at, add, estimate=False,
                                           eliminate=lam0 + np.arange(m))
        x = eliminated.solve(b)
        np.testing.assert_allclose(x, reference, rtol=0, atol=1e-10 * np.abs(reference).max())
        assert np.abs(K @ x - b).max() <= 1e-8 * np.abs(b).max()
    system.stage_order.banded = None
    system.stage_order.layouts.clear()
    assert (layout.size, system.layout(everything, at).size) == (system.size - m, system.size)
    banded_layout = system.layout(everything, at, lam0 + np.arange(m))
    assert (banded_layout.lower, banded_layout.upper) == (18, 18)
    assert (system.layout(everything, at).lower, system.layout(everything, at).upper) == (18, 27)


def test_the_compiled_eliminated_solve_is_numpys(monkeypatch: pytest.MonkeyPatch) -> None:
    """The eliminated system's solve in one compiled call (gnerun.game.banded.EliminatedSolve) gives numpy's values
    bit for bit: the complement's right-hand side, its banded solve and the eliminated unknowns after it, with D from
    1e-10 to 1e4 (so with the refinement step that an E below 1e-6 asks for) and from 1e-2 to 1e2 (without)."""
    from gnerun.game import banded
    from gnerun.game.sparse import Elimination

    if banded.status() != "compiled":
        pytest.skip(f"nothing compiled here: {banded.status()}")
    game, solver, state = _merge_system()
    system = solver.newton.system
    n, m, lam0 = game.n, game.m, system.size - game.m
    rng = np.random.default_rng(7)
    everything = np.arange(system.size)
    at = np.concatenate([np.arange(n), lam0 + np.arange(m)])
    system.stage_order.banded = True
    try:
        for low, high in ((-10, 4), (-2, 2)):
            add = np.concatenate([rng.uniform(0, 1e-2, n), -(10.0 ** rng.uniform(low, high, m))])
            b = rng.standard_normal(system.size)
            solved = {}
            for compiled in (True, False):
                if not compiled:
                    monkeypatch.setattr(Elimination, "compiled", lambda self, layout: False)
                lu, _ = system.factor_kept("interior", state.parts.J, everything, at, add, estimate=False,
                                           eliminate=lam0 + np.arange(m))
                solved[compiled] = (lu.solve(b), lu.refine)
                assert bool(lu.elimination.compiled(lu.factors.layout)) == compiled
                monkeypatch.undo()
            assert solved[True][1] == (low == -10)  # refined once where an eliminated entry is that small
            assert np.array_equal(solved[True][0], solved[False][0])
            assert np.isfinite(solved[True][0]).all()
    finally:
        system.stage_order.banded = None


def _iterates(problems, fused: bool, monkeypatch: pytest.MonkeyPatch) -> tuple[list[np.ndarray], dict[int, int]]:
    """Every iterate (z, ||Phi||, rcond) of the default solver's solves of these problems, with the compiled interior
    step and Newton point (``fused``) or the numpy code alone; what the compiled step answered (0: its step, else why
    not) and how many Newton points were compiled ("point")."""
    from gnerun.game import banded
    from gnerun.solvers import reduced

    answers: dict = {}
    step, point = banded.InteriorStep.__call__, banded.ReducedPoint.__call__

    def counted(self, *args):
        found = step(self, *args)
        code = found if isinstance(found, int) else 0
        answers[code] = answers.get(code, 0) + 1
        return found

    def points(self, *args):
        found = point(self, *args)
        answers["point"] = answers.get("point", 0) + (found is not None)
        return found

    monkeypatch.setattr(banded.InteriorStep, "__call__", counted)
    monkeypatch.setattr(banded.ReducedPoint, "__call__", points)
    monkeypatch.setattr(interior_point, "FUSED", fused)
    monkeypatch.setattr(reduced, "FUSED", fused)
    out = []
    for p in problems:
        cfg = load_config(text=p.config_yaml)
        game = compile_game(cfg)
        solver = make_solver(cfg, game)
        final = iterate(solver, solver.init(),
                        on_iterate=lambda s: out.extend([s.z, np.array([s.residual_norm, s.rcond])]))
        out.append(np.array([final.k]))
    monkeypatch.undo()
    return out, answers


@pytest.mark.parametrize("family", ["merge", "intersection", "overtaking"])
def test_the_compiled_interior_step_takes_numpys_steps(family: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """With the interior-point step in one compiled call (gnerun.game.banded.InteriorStep: the recursion, the band and
    its elimination, the factorisation, Mehrotra's predictor and the corrector, the steps to the boundary) and the
    min-map Newton point in another (gnerun.game.banded.ReducedPoint: the band, dgbtrf, the condition estimate, the
    solve, z^+), the default solver's iterates on ALGAMES's merges and intersections and the overtaking game are the
    numpy code's bit for bit, every one of them (z, ||Phi||, the estimate); both compiled calls are taken, and where
    the step's case does not hold (a player's block not positive definite) the numpy code takes the step."""
    from benchmarks.problems import trajectory
    from gnerun.game import banded

    if banded.status() != "compiled":
        pytest.skip(f"nothing compiled here: {banded.status()}")
    problems = {"merge": lambda: trajectory.merge_problems(4),
                "intersection": lambda: trajectory.intersection_problems(2),
                "overtaking": lambda: trajectory.overtaking_problems()[:2]}[family]()
    compiled, answers = _iterates(problems, True, monkeypatch)
    numpy_only, none = _iterates(problems, False, monkeypatch)
    assert not none and answers.get(0, 0) > 10 and answers.get("point", 0) > 3
    if family != "intersection":  # (the intersections' blocks are positive definite throughout)
        assert answers.get(1, 0) > 0
    assert len(compiled) == len(numpy_only)
    for a, b in zip(compiled, numpy_only, strict=True):
        assert np.array_equal(a, b, equal_nan=True)


def test_the_compiled_interior_step_leaves_its_other_cases_to_numpy(monkeypatch: pytest.MonkeyPatch) -> None:
    """Where an eliminated entry of D is below 1e-6 (the solve would be refined) or the matrix cannot be factorised
    (a NaN in K), the compiled step says so and the numpy code takes the step, as without it; where every block is
    positive definite and D is moderate, it takes the numpy code's step to the bit, with and without the predictor."""
    from gnerun.game import banded

    if banded.status() != "compiled":
        pytest.skip(f"nothing compiled here: {banded.status()}")
    game, solver, state = _merge_system()
    ip = solver.interior
    n, I = ip.n, ip.I
    lam = np.full(I.size, 1.0)
    z = state.z.copy()
    z[n + I] = lam
    parts = state.parts
    c = parts.c.copy()
    step = ip.linear._step()
    assert step is not None

    def both(w, data, predict):
        it = interior_point.InteriorIterate(z, w, parts.L, c, 1e-3, 1.0, predict)
        D = w / lam
        found = step(data, parts.F, c, z, w, lam, D, 1e-3, predict)
        monkeypatch.setattr(interior_point, "FUSED", False)
        ip.linear._held = None
        reference = ip.step(it, parts if data is parts.J else parts._replace(J=data))
        monkeypatch.undo()
        return found, reference

    for predict in (False, True):
        found, reference = both(np.full(I.size, 0.5), parts.J, predict)
        if isinstance(found, int):
            assert found == 1  # (this point's blocks: not all positive definite)
            continue
        assert np.array_equal(found[0], reference[0]) and np.array_equal(found[1], reference[1])
        assert found[2] == reference[2] and np.isnan(reference[3])
    w = np.full(I.size, 0.5)
    w[3] = 1e-9  # D = 1e-9: the solve would be refined
    found, reference = both(w, parts.J, False)
    assert found in (1, 3) and reference[0] is not None
    bad = parts.J.copy()
    bad[np.flatnonzero(bad)[5]] = np.nan
    found, _ = both(np.full(I.size, 0.5), bad, False)
    assert isinstance(found, int)


def test_the_compiled_bookkeeping_of_the_interior_phase_is_numpys(monkeypatch: pytest.MonkeyPatch) -> None:
    """The interior phase's error of H_eps (``InteriorPoint.measure``) and its slack reset, compiled
    (gnerun.game.banded.Barrier), give numpy's numbers: on random points of the merge's sizes with NaNs, infinities and
    signed zeros among them, the error bit for bit (a NaN where numpy's is) and the reset's z and w array for array,
    the same objects where no row is reset."""
    from gnerun.game import banded

    if banded.status() != "compiled":
        pytest.skip(f"nothing compiled here: {banded.status()}")
    game, solver, state = _merge_system()
    ip = solver.interior
    n, I, E = ip.n, ip.I, ip.E
    compiled = ip._compiled()
    assert compiled
    rng = np.random.default_rng(3)
    resets = 0
    for trial in range(200):
        z = rng.standard_normal(n + game.m)
        w = np.abs(rng.standard_normal(I.size))
        L, c = rng.standard_normal(n), rng.standard_normal(game.m)
        if trial % 4 == 1:
            for v in (z, w, L, c):
                v[rng.integers(v.size)] = [np.nan, np.inf, -np.inf, -0.0][trial % 16 // 4]
        eps = 10.0 ** rng.uniform(-8, 0)
        reference = max(float(np.abs(L).max()), float(np.abs(c[I] + w).max()),
                        float(np.abs(c[E]).max()) if E.size else 0.0, float(np.abs(z[n + I] * w - eps).max()))
        ours = compiled.error(L, c, z, w, eps)
        assert ours == reference or (np.isnan(ours) and np.isnan(reference))
        monkeypatch.setattr(interior_point, "FUSED", False)
        expected = ip.reset_slacks(z, w, c)
        monkeypatch.undo()
        found = ip.reset_slacks(z, w, c)
        if expected[0] is z:
            assert found[0] is z and found[1] is w
        else:
            resets += 1
            assert np.array_equal(found[0], expected[0], equal_nan=True)
            assert np.array_equal(found[1], expected[1], equal_nan=True)
    assert resets > 20


@pytest.mark.parametrize("family", ["merge", "intersection"])
def test_the_compiled_layouts_are_numpys(family: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """The kept matrices' layouts made by the compiled index arithmetic (gnerun.game.banded.KeptLayouts) are the numpy
    code's, array for array and dtype for dtype, on every layout the solves of ALGAMES's merges and two intersections
    make without an elimination, with diagonal additions, and with banded LU forced (the SuperLU layout, forced or
    chosen, stays numpy's)."""
    from benchmarks.problems import trajectory
    from gnerun.game import banded, sparse

    if banded.status() != "compiled":
        pytest.skip(f"nothing compiled here: {banded.status()}")
    problems = trajectory.merge_problems(3) if family == "merge" else trajectory.intersection_problems(2)
    made = []
    init = sparse.KeptLayout.__init__

    def recorded(self, order, keep, at, banded=None, eliminate=None):
        if eliminate is None:
            made.append((order, keep.copy(), None if at is None else at.copy()))
        init(self, order, keep, at, banded, eliminate)

    monkeypatch.setattr(sparse.KeptLayout, "__init__", recorded)
    for p in problems:
        cfg = load_config(text=p.config_yaml)
        solver = make_solver(cfg, compile_game(cfg))
        iterate(solver, solver.init())
    monkeypatch.undo()
    order = made[0][0]
    cases = [(keep, at, None) for _, keep, at in made]
    cases += [(made[0][1], np.arange(0, made[0][1].size, 7), None), (made[0][1], None, True),
              (made[0][1], None, False)]
    compiled = order.compiled_layouts
    assert compiled and len(made) >= 2
    for keep, at, band in cases:
        order.compiled_layouts = compiled
        ours = sparse.KeptLayout(order, keep, at, band)
        order.compiled_layouts = False
        theirs = sparse.KeptLayout(order, keep, at, band)
        names = ["nonzeros", "at", "size", "row_order", "col_order", "lower", "upper", "banded", "flat", "flat_at",
                 "flat_fill"] + (["ld"] if theirs.banded else ["indices", "indptr", "nnz"])
        for name in names:
            a, b = getattr(ours, name), getattr(theirs, name)
            assert (np.array_equal(a, b) and a.dtype == b.dtype) if isinstance(b, np.ndarray) else a == b, name
    order.compiled_layouts = compiled


def test_only_a_diagonal_block_is_eliminated() -> None:
    """Unknowns whose block has off-diagonal entries (the decisions': a player's Hessian) or no diagonal addition
    are refused with the reason."""
    game, solver, _ = _merge_system()
    system = solver.newton.system
    at = np.arange(game.n)
    for eliminate in (np.arange(game.n), np.array([game.n])):
        with pytest.raises(ValueError, match="^the unknowns eliminated must have a diagonal block, added at `at`$"):
            system.layout(np.arange(system.size), at, eliminate)


def test_the_eliminated_layout_outlives_the_active_sets_layouts() -> None:
    """The kept layouts are bounded (64): the least recently used without an elimination goes first, so the interior
    matrix's layout (its ordering searched anew) is not rebuilt after a long Newton phase of many active sets."""
    game, solver, _ = _merge_system()
    system = solver.newton.system
    n, m, lam0 = game.n, game.m, system.size - game.m
    everything = np.arange(system.size)
    at = np.concatenate([np.arange(n), lam0 + np.arange(m)])
    eliminated = system.layout(everything, at, lam0 + np.arange(m))
    first = system.layout(system.kept(np.arange(1)))
    for k in range(2, 80):
        system.layout(system.kept(np.arange(k)))
    assert len(system.stage_order.layouts) == 64
    assert system.layout(everything, at, lam0 + np.arange(m)) is eliminated
    assert system.layout(system.kept(np.arange(1))) is not first


def test_deferred_parts_hold_the_numbers_of_the_whole_evaluation() -> None:
    """L and c from the residual alone are the whole evaluation's, bit for bit, for the game's system and for a
    player's part of it (the certificate's); F, J and F0 come when asked for; a pickle holds the whole parts."""
    import pickle

    from gnerun.game.compile import compile_agent_problem
    from gnerun.game.sparse import AgentSparseKKT, DeferredParts, SparseParts, sparse_system

    cfg = load_config(CONFIGS / "algames_intersection.yaml", {"solver.formulation": "sparse"})
    game = compile_game(cfg)
    system = sparse_system(cfg, game)
    rng = np.random.default_rng(3)
    problem = compile_agent_problem(cfg, 1, 0.0)
    rows = game.agents.constraint_rows(1)
    labels = [game.constraints[r].label for r in rows]
    view = AgentSparseKKT(system, problem, 1, rows[[labels.index(c.label) for c in problem.constraints]])
    sl = game.agent_slices[1]
    for _ in range(5):
        a = game.z_start()[:game.n] + 0.3 * rng.standard_normal(game.n)
        lam = rng.random(game.m) * (rng.random(game.m) < 0.5)
        x = game.x0 + 0.05 * rng.standard_normal(game.nx)
        z_view = np.concatenate([a[sl], rng.random(problem.m)])
        p = np.concatenate([game._x(None), a[:sl.start], a[sl.stop:], a[sl]])
        for sys_, z, at in ((system, np.concatenate([a, lam]), x), (view, z_view, p)):
            whole, deferred = sys_.evaluate(z, at), sys_.deferred(z, at)
            assert isinstance(deferred, DeferredParts) and deferred._parts is None
            assert np.array_equal(deferred.L, whole.L) and np.array_equal(deferred.c, whole.c)
            for name in ("F", "J", "F0"):
                assert np.array_equal(getattr(deferred, name), getattr(whole, name))
            again = pickle.loads(pickle.dumps(sys_.deferred(z, at)))
            assert isinstance(again, SparseParts)
            assert all(np.array_equal(u, v) for u, v in zip(again[4:], whole[4:], strict=True))


def test_a_converging_newton_step_leaves_the_jacobian_of_its_end_unevaluated(monkeypatch: pytest.MonkeyPatch) -> None:
    """A closed loop's sampling time of the MPC merge: two Newton steps from the shifted plan (||Phi|| ~ 1e-3, 1e-6,
    then below tol); the second step's end is evaluated by the residual alone: two whole evaluations, not three."""
    from gnerun.game.sparse import SparseKKT

    cfg = load_config(CONFIGS / "algames_merge_mpc.yaml", {"run.K": [3], "run.steps": 6, "run.reference": "none"})
    game = compile_game(cfg)
    counts = {"whole": 0, "residual": 0}
    evaluate, residual = SparseKKT.evaluate, SparseKKT.residual

    def counted(kind, f):
        def call(self, *args):
            counts[kind] += 1
            return f(self, *args)
        return call
    monkeypatch.setattr(SparseKKT, "evaluate", counted("whole", evaluate))
    monkeypatch.setattr(SparseKKT, "residual", counted("residual", residual))
    seen = []
    simulate(cfg, game=game, progress=lambda report: seen.append((report.iterations, dict(counts))))
    steps = [(k, after["whole"] - before["whole"], after["residual"] - before["residual"])
             for (_, before), (k, after) in zip(seen, seen[1:], strict=False)]
    assert steps and all(s == (2, 2, 1) for s in steps), steps
