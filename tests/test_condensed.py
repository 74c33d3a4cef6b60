"""The condensed KKT function compiled to C (gnerun.game.condensed): the same iterates as interpreted on the paper's
game and FK problems; honest about what was done (compiled, cache hit, or interpreted and why); the CLI says so."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

import gnerun.game.condensed as condensed_module
from benchmarks.problems import fk
from gnerun.game.compile import compile_game
from gnerun.game.condensed import condensed_kernels
from gnerun.game.kernels import cache_dir
from gnerun.language.config import load_config
from gnerun.solvers.factory import make_solver

from .conftest import gnerun_command

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(autouse=True)
def _cache(tmp_path_factory, monkeypatch):
    """One cache for this module's tests, apart from the user's."""
    monkeypatch.setenv("GNERUN_CACHE_DIR", str(tmp_path_factory.getbasetemp() / "gnerun-cache"))


def _with(cfg, **solver):
    return cfg.model_copy(update={"solver": cfg.solver.model_copy(update=solver)})


def _iterates(cfg):
    game = compile_game(cfg)
    solver = make_solver(cfg, game)
    state = solver.init(None, np.asarray(cfg.game.x0) if cfg.game.kind == "dynamic" else None)
    zs = [state.z.copy()]
    while not solver.terminate(state)[0]:
        state = solver.step(state)
        zs.append(state.z.copy())
    return zs, solver.finish(state), game.derived["condensed"]


def _fk(name: str, start: str):
    p = next(p for p in fk.problems() if p.name == name and p.start == start)
    return load_config(text=p.config_yaml)


# the paper's GNE (each agent its own constraints, LQ: constant derivatives); FK A.1 (a GNE with bounds), A.2 (a
# nonlinear GNE with equality rows), A.11 (a variational GNE: a common multiplier), A.12 (a Nash game with bounds)
CASES = {
    "paper Study 1": lambda: load_config(ROOT / "configs" / "paper_study1.yaml"),
    "FK A.1": lambda: _fk("A.1", "x0 = 0.1"),
    "FK A.2": lambda: _fk("A.2", "x0 = 1"),
    "FK A.11": lambda: load_config(ROOT / "configs" / "fk_a11.yaml"),
    "FK A.12": lambda: _fk("A.12", "x0 = (2, 0)"),
}


@pytest.mark.parametrize("name", CASES)
def test_compiled_and_interpreted_give_the_same_iterates(name):
    """Every iterate's z to 1e-12 relative, the same iteration count and status, and each way says what it did."""
    cfg = CASES[name]()
    zc, fc, rc = _iterates(_with(cfg, compile="compiled"))
    zi, fi, ri = _iterates(_with(cfg, compile="interpreted"))
    assert rc.mode == "compiled" and rc.operations > 0 and Path(rc.path).parent == cache_dir()
    assert (ri.mode, ri.reason) == ("interpreted", "solver.compile: interpreted")
    assert len(zc) == len(zi) >= 2 and (fc.status, fc.k) == (fi.status, fi.k)
    for u, v in zip(zc, zi, strict=True):
        assert np.max(np.abs(u - v)) <= 1e-12 * max(1.0, np.max(np.abs(v)))


def test_auto_keeps_the_condensed_function_interpreted_and_a_game_can_switch():
    cfg = load_config(ROOT / "configs" / "fk_a11.yaml")
    game = compile_game(cfg)
    interpreted = game._derivatives["kkt"]
    auto = condensed_kernels(cfg, game)
    assert auto.line() == "kernels: interpreted (auto: the condensed KKT function is compiled with solver.compile: " \
                          "compiled)"
    assert auto.as_dict() == {"mode": "interpreted", "function": "condensed", "reason": auto.reason}
    compiled = condensed_kernels(_with(cfg, compile="compiled"), game)
    assert compiled.mode == "compiled" and game._derivatives["kkt"] is not interpreted
    z = np.array([0.3, 0.4, 0.5])
    values = [v.copy() for v in game._derivatives["kkt"](z[:2], z[2:], game._x(None))]
    assert condensed_kernels(_with(cfg, compile="interpreted"), game).mode == "interpreted"
    assert game._derivatives["kkt"] is interpreted
    for u, v in zip(values, interpreted(z[:2], z[2:], game._x(None)), strict=True):
        assert u.shape == v.shape and np.array_equal(u, v)


def test_what_is_not_compiled_says_why(tmp_path, monkeypatch):
    cfg = _with(load_config(ROOT / "configs" / "fk_a12.yaml"), compile="compiled")
    game = compile_game(cfg)
    make_solver(_with(cfg, kind="jn"), game)
    assert game.derived["condensed"].reason == "solver.kind: jn (the condensed KKT function is compiled for ssn)"
    monkeypatch.setattr(condensed_module, "COMPILE_UP_TO", 10)
    report = condensed_kernels(cfg, compile_game(cfg))
    assert report.line() == ("kernels: interpreted (condensed KKT function of 44 operations, compiled up to 10: use "
                             "solver.formulation: sparse)")
    monkeypatch.setattr(condensed_module, "COMPILE_UP_TO", 100_000)
    monkeypatch.setenv("GNERUN_CACHE_DIR", str(tmp_path))  # an empty cache: the compiler runs
    monkeypatch.setenv("CC", "false")  # a compiler that fails: the interpreter stays, and says why
    game = compile_game(cfg)
    assert condensed_kernels(cfg, game).line().startswith("kernels: interpreted (false failed")
    assert game.derived.get("condensed_interpreted") is None
    monkeypatch.setenv("CC", "/nonexistent/cc")
    assert condensed_kernels(cfg, compile_game(cfg)).reason == "no C compiler found (gcc, cc or $CC)"


def _gnerun(*args: str, env: dict) -> subprocess.CompletedProcess:
    return subprocess.run([*gnerun_command(), *args], capture_output=True, text=True, cwd=ROOT,
                          env={**os.environ, **env}, timeout=600, stdin=subprocess.DEVNULL)


def test_the_cli_compiles_the_paper_game_when_asked(tmp_path):
    """`gnerun solve configs/paper_study1.yaml --set solver.compile=compiled`: compiled, then a cache hit; the default
    stays interpreted and says so in summary.json only; the same solution and iterations every time."""
    env = {"GNERUN_CACHE_DIR": str(tmp_path / "cache")}
    runs = {}
    compiled = ["--set", "solver.compile=compiled"]
    for label, extra in (("first", compiled), ("again", compiled), ("default", [])):
        out = tmp_path / label
        r = _gnerun("solve", "configs/paper_study1.yaml", *extra, "--out", str(out), env=env)
        assert r.returncode == 0, r.stderr
        line = next((x for x in r.stdout.splitlines() if x.startswith("kernels:")), None)
        runs[label] = (line, json.loads((out / "summary.json").read_text()))
    library = next((tmp_path / "cache" / "kernels").glob("condensed_kkt_33-*.so"))
    assert runs["first"][0].startswith("kernels: compiled C, the condensed KKT function of 1,706 operations "
                                       "(compiled in ")
    assert runs["first"][0].endswith(f"; {library}); constant derivatives, evaluated once")
    assert runs["again"][0] == (f"kernels: compiled C, the condensed KKT function of 1,706 operations (cache hit; "
                                f"{library}); constant derivatives, evaluated once")
    assert runs["again"][1]["kernels"] == {"mode": "compiled", "function": "condensed", "operations": 1706,
                                           "cache_hit": True, "compile_s": 0.0, "library": str(library)}
    # the default's choice is in summary.json, not on the terminal (nothing was asked, nothing to say)
    assert runs["default"][0] is None
    assert runs["default"][1]["kernels"] == {"mode": "interpreted", "function": "condensed", "reason": (
        "auto: the condensed KKT function is compiled with solver.compile: compiled")}
    z = [np.asarray(s["z"]) for _, s in runs.values()]
    assert all(np.max(np.abs(v - z[0])) <= 1e-12 * max(1.0, np.max(np.abs(z[0]))) for v in z[1:])
    assert len({(s["status"], s["iterations"]) for _, s in runs.values()}) == 1
