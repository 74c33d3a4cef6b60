"""gnerun: Newton-type equilibrium seeking in games and game-theoretic MPC.

The public API (SPEC §7) is loaded lazily, so that ``gnerun --help`` does not import numpy or CasADi.
"""

from __future__ import annotations

from importlib import import_module
from typing import Any

__version__ = "0.1.0"

_API = {
    "load_config": "gnerun.language.config",
    "Config": "gnerun.language.config",
    "compile_game": "gnerun.game.compile",
    "CompiledGame": "gnerun.game.compile",
    "make_solver": "gnerun.runs.solving",
    "solve": "gnerun.runs.solving",
    "SolveResult": "gnerun.runs.solving",
    "simulate": "gnerun.runs.closed_loop",
    "Simulation": "gnerun.runs.closed_loop",
    "ClosedLoopResult": "gnerun.runs.closed_loop",
    "SemismoothNewton": "gnerun.solvers.ssn",
    "Status": "gnerun.solvers.ssn",
    "ConfigError": "gnerun.errors",
    "InputError": "gnerun.errors",
}

__all__ = ["__version__", *_API]


def __getattr__(name: str) -> Any:
    module = _API.get(name)
    if module is None:
        raise AttributeError(f"module 'gnerun' has no attribute {name!r}")
    value = getattr(import_module(module), name)
    globals()[name] = value
    return value
