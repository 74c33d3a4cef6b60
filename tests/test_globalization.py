"""The globalization table (gnerun/solvers/globalization.py): every value of ``solver.globalization`` has its
constructor, ``auto`` is resolved once, and each entry builds the solver its name says."""

from __future__ import annotations

import typing
from pathlib import Path

import pytest

from gnerun.game.compile import compile_game
from gnerun.language.config import SolverConfig, load_config
from gnerun.runs.solving import make_solver
from gnerun.solvers.globalization import GLOBALIZATIONS, LineSearchNewton, resolve
from gnerun.solvers.hybrid import HybridNewton
from gnerun.solvers.line_search import Armijo
from gnerun.solvers.ssn import SemismoothNewton

CONFIGS = Path(__file__).resolve().parent.parent / "configs"


def test_every_option_value_has_an_entry() -> None:
    values = set(typing.get_args(SolverConfig.model_fields["globalization"].annotation))
    assert values - {"auto"} == set(GLOBALIZATIONS)


@pytest.mark.parametrize(("kind", "globalization", "expected"), [
    ("ssn", "auto", "hybrid"), ("distributed", "auto", "hybrid"), ("jn", "auto", "none"),
    ("ssn", "line_search", "line_search"), ("jn", "none", "none")])
def test_auto_is_resolved_once(kind: str, globalization: str, expected: str) -> None:
    assert resolve(SolverConfig(kind=kind, globalization=globalization)) == expected


@pytest.mark.parametrize(("globalization", "solver_type"), [
    ("none", SemismoothNewton), ("line_search", LineSearchNewton), ("hybrid", HybridNewton),
    ("interior_point", HybridNewton), ("auto", HybridNewton)])
def test_each_entry_builds_its_method(globalization: str, solver_type: type) -> None:
    cfg = load_config(CONFIGS / "harker.yaml", {"solver.globalization": globalization})
    solver = make_solver(cfg, compile_game(cfg))
    assert type(solver) is solver_type
    if isinstance(solver, HybridNewton):
        assert solver.handover == (globalization != "interior_point")
    if isinstance(solver, LineSearchNewton):
        assert solver.search == Armijo()
