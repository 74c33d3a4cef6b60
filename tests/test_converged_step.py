"""A step at a converged state keeps the solution: no phase change, no interior restart, the same status.

Before, the default solver left the paper's game's solution in 4 more steps (its interior phase began, status back
to running) and FK A.1 from x0 = 0.1 went from ||Phi|| = 3.7e-16 to 1.7e-7 in 20 steps.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from benchmarks.problems import fk, trajectory
from gnerun.game.compile import compile_game
from gnerun.language.config import load_config
from gnerun.runs.solving import iterate, make_solver, reference_solution
from gnerun.solvers.ssn import Status

ROOT = Path(__file__).resolve().parent.parent


def _fk(label: str, start: str) -> str:
    return next(p.config_yaml for p in fk.problems() if p.name == label and p.start == start)


def _cases():
    paper = (ROOT / "configs" / "paper_study1.yaml").read_text()
    for glob in ("auto", "hybrid", "interior_point", "line_search", "none"):
        yield pytest.param(paper, {"solver.globalization": glob, "solver.max_iter": 100}, id=f"paper-{glob}")
    yield pytest.param(paper, {"solver.formulation": "sparse", "solver.globalization": "auto"}, id="paper-sparse")
    fk_a1 = _fk("A.1", "x0 = 0.1")
    for glob in ("auto", "interior_point", "none"):
        yield pytest.param(fk_a1, {"solver.globalization": glob}, id=f"fk-a1-{glob}")
    yield pytest.param(fk_a1, {"solver.complementarity": "fischer_burmeister"}, id="fk-a1-fb")
    yield pytest.param(_fk("A.7", "x0 = 0"), {"solver.kind": "distributed"}, id="fk-a7-distributed")
    yield pytest.param(_fk("A.18", "x0 = 0"), {"solver.globalization": "auto"}, id="fk-a18")
    merge = trajectory.merge_problems(1, seed=0)[0].config_yaml
    yield pytest.param(merge, {}, id="merge")
    yield pytest.param(merge, {"solver.formulation": "sparse"}, id="merge-sparse")


@pytest.mark.parametrize(("text", "overrides"), list(_cases()))
def test_twenty_steps_past_convergence_keep_the_solution(text, overrides):
    cfg = load_config(text=text, overrides=overrides)
    game = compile_game(cfg)
    solver = make_solver(cfg, game)
    converged = iterate(solver, solver.init())
    assert converged.status == Status.CONVERGED, converged.message
    running = replace(converged, status=Status.RUNNING, message="")  # as a driver loop sees it before finish
    for start in (converged, running):
        state = start
        for _ in range(20):
            state = solver.step(state)
        assert np.array_equal(state.z, converged.z)
        assert state.k == converged.k
        assert state.residual_norm == converged.residual_norm
        assert state.status == start.status
        assert state.search is start.search  # the globalization's memory (its phase) untouched
        assert solver.terminate(state) == (True, Status.CONVERGED)


def test_jn_keeps_the_solution():
    cfg = load_config(ROOT / "configs" / "variational_gne.yaml", overrides={"solver.kind": "jn"})
    game = compile_game(cfg)
    solver = make_solver(cfg, game)
    converged = iterate(solver, solver.init())
    assert converged.status == Status.CONVERGED
    state = converged
    for _ in range(20):
        state = solver.step(state)
    assert state is converged


def test_polishing_still_steps_on_from_a_solution():
    """The reference solution z* is polished by Newton steps past tol (``iteration``, not ``step``)."""
    cfg = load_config(ROOT / "configs" / "paper_study1.yaml", overrides={"solver.tol": 1e-6})
    game = compile_game(cfg)
    ref = reference_solution(game, cfg, game.z_start())
    assert ref.converged
    assert ref.residual_norm < 1e-12
