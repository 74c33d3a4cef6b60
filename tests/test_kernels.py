"""Compiled stage kernels (gnerun.game.kernels): the sparse system built from per-stage Functions is the interpreted
one; compiled to C it gives the same iterates; a second build is a cache hit; without a compiler (or when it fails,
or when asked) the interpreted path is taken and said so."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

import gnerun.game.sparse as sparse_module
from benchmarks.problems import trajectory
from gnerun.game.compile import compile_game
from gnerun.game.kernels import build_library, cache_dir
from gnerun.game.sparse import compile_sparse
from gnerun.language.config import load_config
from gnerun.solvers.factory import make_solver

from .conftest import gnerun_command

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(autouse=True)
def _cache(tmp_path_factory, monkeypatch):
    """One cache for this module's tests, apart from the user's."""
    monkeypatch.setenv("GNERUN_CACHE_DIR", str(tmp_path_factory.getbasetemp() / "gnerun-cache"))


def _with(cfg, **solver):
    return cfg.model_copy(update={"solver": cfg.solver.model_copy(update={"formulation": "sparse", **solver})})


# the merge and the intersection (stage functions shared by the stages), tracking (a reference in time t: every
# stage takes its own time), the moving obstacle (per-stage runtime tables: a Function per stage), the 6-robot ring
# (variational shared constraints carried by their agents), the overtaking game and two vehicles
CONFIGS = ["algames_merge", "algames_intersection", "tracking", "moving_obstacle", "formation_ring", "overtaking",
           "vehicles"]


@pytest.mark.parametrize("name", CONFIGS)
def test_the_stage_kernels_give_the_interpreted_system(name):
    """F, the nonzeros of dF/dw, F0 and the residual (L, c) at random points, from the stage Functions' graph
    (evaluated by CasADi, no compiler) and from the whole-horizon SX function: equal up to rounding."""
    cfg = load_config(ROOT / "configs" / f"{name}.yaml")
    game = compile_game(_with(cfg, compile="interpreted"))
    plain = compile_sparse(_with(cfg, compile="interpreted"), game)
    staged = compile_sparse(_with(cfg, compile="compiled"), game, build_c=False)
    assert plain.kernels.reason == "solver.compile: interpreted"
    assert staged.kernels.reason == "stage kernels not compiled" and staged.kernels.stages >= 1
    rng = np.random.default_rng(4)
    game.set_parameters(None, t=1.3)  # a sampling time other than 0: the stages' own times matter
    for _ in range(3):
        z = np.concatenate([game.z_start()[:game.n] + 0.2 * rng.standard_normal(game.n), rng.random(game.m)])
        a, b = plain.evaluate(z, None), staged.evaluate(z, None)
        for part in ("F", "J", "F0"):
            x, y = getattr(a, part), getattr(b, part)
            assert x.shape == y.shape
            assert np.max(np.abs(x - y)) <= 1e-13 * max(1.0, np.max(np.abs(x))), part
        for x, y in zip(plain.residual(z, None), staged.residual(z, None), strict=True):
            assert np.allclose(x, y, rtol=1e-13, atol=1e-13)
        for system in (plain, staged):  # c alone: the residual's c, by the same operations
            assert np.array_equal(system.constraints(z, None), system.residual(z, None)[1])


def test_a_reference_in_time_shares_one_stage_function():
    """Tracking's cost reads t + dt at every stage: built with each stage's own time, the 21 stages need two
    Functions (the last carries the terminal cost), not 21."""
    cfg = load_config(ROOT / "configs" / "tracking.yaml")
    game = compile_game(cfg)
    staged = compile_sparse(_with(cfg, compile="compiled"), game, build_c=False)
    assert (staged.kernels.stages, staged.kernels.horizon) == (2, 21)


def _iterates(cfg, game, x0):
    solver = make_solver(cfg, game)
    state = solver.init(None, x0)
    zs = [state.z.copy()]
    while True:
        done, _ = solver.terminate(state)
        if done:
            break
        state = solver.step(state)
        zs.append(state.z.copy())
    return zs, solver.finish(state)


def test_compiled_kernels_give_the_interpreted_iterates():
    """Random merges and an intersection solved with the stage kernels compiled to C and interpreted: every iterate
    equal up to rounding, the same iteration count and status, the same solution to 1e-12."""
    problems = trajectory.merge_problems(3, seed=5) + trajectory.intersection_problems(1, seed=5)
    for p in problems:
        cfg = load_config(text=p.config_yaml)
        runs = []
        for mode in ("compiled", "interpreted"):
            c = _with(cfg, compile=mode)
            game = compile_game(c)
            runs.append(_iterates(c, game, np.asarray(cfg.game.x0)))
            assert game.derived["sparse"].kernels.mode == mode
            system = game.derived["sparse"]
            for z in runs[-1][0]:  # c alone, compiled or not, is the residual's c bit for bit (the slack reset's)
                assert np.array_equal(system.constraints(z, game.x0), system.residual(z, game.x0)[1])
        (zc, sc), (zi, si) = runs
        assert len(zc) == len(zi) and sc.status == si.status and sc.k == si.k
        gaps = [np.max(np.abs(u - v)) / max(1.0, np.max(np.abs(v))) for u, v in zip(zc, zi, strict=True)]
        # rounding: most iterates agree to 1e-13; a step through a badly conditioned interior matrix can amplify it
        # for that iterate (1e-8 measured on one merge), and the next ones agree again; a long interior phase of
        # Mehrotra's steps amplifies it over several steps (merge s5#2, 37 iterations: up to 7e-6 mid-solve, median
        # 1e-8) before both meet at the solution
        assert max(gaps) <= 1e-4 and np.median(gaps) <= 1e-7 and gaps[-1] <= 1e-12, gaps


def test_a_second_build_is_a_cache_hit(tmp_path, monkeypatch):
    monkeypatch.setenv("GNERUN_CACHE_DIR", str(tmp_path))
    cfg = _with(load_config(ROOT / "configs" / "vehicles.yaml"), compile="compiled")
    first = compile_sparse(cfg, compile_game(cfg)).kernels
    second = compile_sparse(cfg, compile_game(cfg)).kernels
    assert (first.mode, first.cache_hit) == ("compiled", False) and first.compile_s > 0
    assert (second.mode, second.cache_hit, second.compile_s) == ("compiled", True, 0.0)
    assert second.path == first.path and Path(first.path).parent == cache_dir() == tmp_path / "kernels"
    files = sorted(f.name for f in (tmp_path / "kernels").iterdir())  # the library and its system's layout only
    assert len(files) == 2 and files[0] == Path(first.path).name
    assert files[1].startswith("system-") and files[1].endswith(".npz")


def test_a_cache_hit_builds_nothing(tmp_path, monkeypatch):
    """The same game again, with another x0: the system comes from the cache without its expressions being built,
    and evaluates as the freshly built one."""
    monkeypatch.setenv("GNERUN_CACHE_DIR", str(tmp_path))
    cfg = _with(load_config(ROOT / "configs" / "vehicles.yaml"), compile="compiled")
    game = compile_game(cfg)
    fresh = compile_sparse(cfg, game)
    moved = cfg.model_copy(update={"game": cfg.game.model_copy(update={"x0": [v + 0.1 for v in cfg.game.x0]})})
    game2 = compile_game(moved)

    def refuse(*args, **kwargs):
        raise AssertionError("the expressions were built")

    monkeypatch.setattr(sparse_module, "_expressions", refuse)
    hit = compile_sparse(moved, game2)
    assert hit.kernels.cache_hit and hit.kernels.stages == fresh.kernels.stages
    assert (hit.pattern != fresh.pattern).nnz == 0 and hit.S == fresh.S
    assert all(np.array_equal(u, v) for u, v in zip(hit.states, fresh.states, strict=True))
    z = np.concatenate([game.z_start()[:game.n] + 0.3, np.ones(game.m)])
    x = np.asarray(moved.game.x0)
    for u, v in zip(hit.evaluate(z, x), fresh.evaluate(z, x), strict=True):
        if u is not None:
            assert np.array_equal(u, v)


def test_a_failing_compiler_is_reported(tmp_path, monkeypatch):
    monkeypatch.setenv("GNERUN_CACHE_DIR", str(tmp_path))
    monkeypatch.setenv("CC", "false")  # exits 1
    import casadi as ca

    x = ca.SX.sym("x")
    with pytest.raises(RuntimeError, match="false failed"):
        build_library([ca.Function("square", [x], [x * x])], "square")


def _gnerun(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([*gnerun_command(), *args], capture_output=True, text=True, cwd=ROOT,
                          env={**os.environ, **(env or {})}, timeout=600, stdin=subprocess.DEVNULL)


def test_the_cli_says_how_the_system_is_evaluated(tmp_path):
    """`gnerun solve` of the overtaking game, sparse (auto: compiled): compiled once, then a cache hit on the same
    config; with CC pointing nowhere or `solver.compile=interpreted`, interpreted and said why; the same solution."""
    env = {"GNERUN_CACHE_DIR": str(tmp_path / "cache")}
    args = ["solve", "configs/overtaking.yaml", "--set", "run.certificate=false", "--set", "solver.formulation=sparse"]
    runs = {}
    for label, extra, more_env in (("first", [], {}), ("again", [], {}),
                                   ("no compiler", [], {"CC": "/nonexistent/cc"}),
                                   ("asked", ["--set", "solver.compile=interpreted"], {})):
        out = tmp_path / label.replace(" ", "_")
        r = _gnerun(*args, *extra, "--out", str(out), env={**env, **more_env})
        assert r.returncode == 0, r.stderr
        line = next(x for x in r.stdout.splitlines() if x.startswith("kernels:"))
        runs[label] = (line, json.loads((out / "summary.json").read_text()))
    assert runs["first"][0].startswith("kernels: compiled C, 2 stage functions for 13 stages (compiled in ")
    assert runs["again"][0].startswith("kernels: compiled C, 2 stage functions for 13 stages (cache hit; ")
    assert runs["again"][1]["kernels"]["cache_hit"] is True
    assert runs["no compiler"][0] == "kernels: interpreted (no C compiler found (gcc, cc or $CC))"
    assert runs["asked"][0] == "kernels: interpreted (solver.compile: interpreted)"
    assert runs["asked"][1]["kernels"] == {"mode": "interpreted", "reason": "solver.compile: interpreted"}
    z = [np.asarray(s["z"]) for _, s in runs.values()]
    assert [s["status"] for _, s in runs.values()] == ["kkt_point"] * 4  # not certified
    assert all(np.max(np.abs(v - z[0])) <= 1e-9 * max(1.0, np.max(np.abs(z[0]))) for v in z[1:])
