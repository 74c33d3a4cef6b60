"""gnerun: Newton-type equilibrium seeking in games and game-theoretic MPC.

The public API is loaded lazily, so that ``gnerun --help`` does not import numpy or CasADi.
"""

__version__ = "0.1.0"

_API = {
    "load_config": "gnerun.language.config",
    "Config": "gnerun.language.config",
    "compile_game": "gnerun.game.compile",
    "CompiledGame": "gnerun.game.compile",
    "make_solver": "gnerun.solvers.factory",
    "solve": "gnerun.runs.solving",
    "SolveResult": "gnerun.runs.solving",
    "simulate": "gnerun.runs.closed_loop",
    "Simulation": "gnerun.runs.closed_loop",
    "ClosedLoopResult": "gnerun.runs.closed_loop",
    "StepReport": "gnerun.runs.closed_loop",
    "SemismoothNewton": "gnerun.solvers.ssn",
    "Status": "gnerun.solvers.status",
    "iterate": "gnerun.solvers.driver",
    "ConfigError": "gnerun.errors",
    "InputError": "gnerun.errors",
}

__all__ = ["__version__", *_API]


def __getattr__(name: str) -> object:
    module = _API.get(name)
    if module is None:
        raise AttributeError(f"module 'gnerun' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    # the public API only (not the subpackages, which importing the API adds as attributes)
    return sorted(__all__)
