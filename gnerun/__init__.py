"""gnerun: Newton-type equilibrium seeking in games and game-theoretic MPC.

The public API (SPEC §7) is loaded lazily, so that ``gnerun --help`` does not import numpy or CasADi.
"""

from __future__ import annotations

from importlib import import_module
from typing import Any

__version__ = "0.1.0"

_API = {
    "load_config": "gnerun.config",
    "Config": "gnerun.config",
    "compile_game": "gnerun.game",
    "CompiledGame": "gnerun.game",
    "make_solver": "gnerun.solving",
    "solve": "gnerun.solving",
    "SolveResult": "gnerun.solving",
    "simulate": "gnerun.closed_loop",
    "Simulation": "gnerun.closed_loop",
    "ClosedLoopResult": "gnerun.closed_loop",
    "SemismoothNewton": "gnerun.ssn",
    "Status": "gnerun.ssn",
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
