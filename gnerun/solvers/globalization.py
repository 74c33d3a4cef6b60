"""``solver.globalization``: each value of the option and the constructor of its method.

A globalization wraps the semismooth Newton method of the configured formulation (the paper's local method,
:class:`~gnerun.solvers.ssn.SemismoothNewton`) and is a solver itself (:class:`~gnerun.solvers.driver.Solver`).
``GLOBALIZATIONS`` is the whole table: a new globalization is one new entry (and its value in
``SolverConfig.globalization``). ``auto`` is resolved here, once (:func:`resolve`).

- ``none``: the local method as it is;
- ``line_search``: Armijo backtracking on 1/2||Phi||^2 along the Newton direction
  (:mod:`gnerun.solvers.line_search_newton`, with the search of :mod:`gnerun.solvers.line_search` as an object);
- ``hybrid``: the default, a watchdog on the Newton steps and an interior-point phase (:mod:`gnerun.solvers.hybrid`);
- ``interior_point``: that interior-point phase alone.
"""

from __future__ import annotations

from collections.abc import Callable

from ..language.config import SolverConfig
from .hybrid import HybridNewton
from .line_search import Armijo
from .line_search_newton import LineSearchNewton
from .ssn import SemismoothNewton

FALLBACK = "hybrid"  # the globalization a failed solve is retried with where a converged one is needed (z*)


def resolve(options: SolverConfig) -> str:
    """The globalization in effect: ``auto`` is ``hybrid`` for semismooth Newton (also the inner one of
    ``distributed``) and ``none`` for Josephy-Newton, which solves each step's affine VI exactly."""
    if options.globalization != "auto":
        return options.globalization
    return "none" if options.kind == "jn" else "hybrid"


GLOBALIZATIONS: dict[str, Callable[[SemismoothNewton], object]] = {
    "none": lambda newton: newton,
    "line_search": lambda newton: LineSearchNewton(newton, Armijo()),
    "hybrid": lambda newton: HybridNewton(newton, handover=True),
    "interior_point": lambda newton: HybridNewton(newton, handover=False),
}


def globalized(newton: SemismoothNewton):
    """``newton`` inside the globalization its options ask for (:data:`GLOBALIZATIONS`)."""
    return GLOBALIZATIONS[resolve(newton.options)](newton)
