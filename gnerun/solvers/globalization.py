"""``solver.globalization``: each value of the option and the constructor of its method.

A globalization wraps the semismooth Newton method of the configured formulation (the paper's local method,
:class:`~gnerun.solvers.ssn.SemismoothNewton`) and is a solver itself (:class:`~gnerun.solvers.driver.Solver`).
``GLOBALIZATIONS`` is the whole table: a new globalization is one new entry (and its value in
``SolverConfig.globalization``). ``auto`` is resolved here, once (:func:`resolve`).

- ``none``: the local method as it is;
- ``line_search``: Armijo backtracking on 1/2||Phi||^2 along the Newton direction (:class:`LineSearchNewton`, with
  the search of :mod:`gnerun.solvers.line_search` as an object);
- ``hybrid``: the default, a watchdog on the Newton steps and an interior-point phase (:mod:`gnerun.solvers.hybrid`);
- ``interior_point``: that interior-point phase alone.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from ..language.config import SolverConfig
from .hybrid import HybridNewton
from .line_search import Armijo
from .ssn import SemismoothNewton
from .status import FAILURES, SSNState, Status

FALLBACK = "hybrid"  # the globalization a failed solve is retried with where a converged one is needed (z*)


def resolve(options: SolverConfig) -> str:
    """The globalization in effect: ``auto`` is ``hybrid`` for semismooth Newton (also the inner one of
    ``distributed``) and ``none`` for Josephy-Newton, which solves each step's affine VI exactly."""
    if options.globalization != "auto":
        return options.globalization
    return "none" if options.kind == "jn" else "hybrid"


class LineSearchNewton:
    """Semismooth Newton steps shortened by a line search on 1/2||Phi||^2 (``globalization: line_search``): the slope
    of the merit is taken along the direction actually computed (JPhi dz differs from -Phi under perturbations), and
    a search that accepts no length ends the solve as ``line_search_failed``. ``init``, ``terminate`` and ``finish``
    are the Newton method's."""

    def __init__(self, newton: SemismoothNewton, search: Armijo | None = None) -> None:
        self.newton = newton
        self.search = search or Armijo()
        self.game = newton.game
        self.options = newton.options
        self.disturbance = newton.disturbance
        self.condensed = newton.condensed


    def forget(self) -> None:
        """Drop the Newton method's factorisations kept per active set."""
        self.newton.forget()
    def init(self, z0: np.ndarray | None = None, x: np.ndarray | None = None,
             rng: np.random.Generator | None = None) -> SSNState:
        return self.newton.init(z0, x, rng)

    def terminate(self, state: SSNState) -> tuple[bool, Status]:
        return self.newton.terminate(state)

    def finish(self, state: SSNState) -> SSNState:
        return self.newton.finish(state)

    def at_solution(self, state: SSNState) -> bool:
        return self.newton.at_solution(state)

    def step(self, state: SSNState) -> SSNState:
        """One searched iteration; a failed or converged state is returned unchanged."""
        if state.status in FAILURES or self.newton.at_solution(state):
            return state
        return self.iteration(state)

    def iteration(self, state: SSNState) -> SSNState:
        """One searched iteration from ``state``, also at a solution."""
        if state.status in FAILURES:
            return state
        newton = self.newton
        z_new, rcond = newton.newton_point(state)
        if z_new is None:
            return newton.singular(state, rcond)
        dz = z_new - state.z
        if newton.reduced:
            slope = -state.residual_norm**2  # the exact min-map Newton step: JPhi dz = -Phi
        else:
            slope = float(state.phi @ (newton.jacobian(state.parts, state.z, state.active) @ dz))

        def trial(t: float) -> tuple[float, np.ndarray]:
            z = state.z + t * dz
            phi, _ = newton.phi(*newton.kkt_residual(z, state.x), z)
            return 0.5 * float(phi @ phi), z

        found = self.search.search(0.5 * state.residual_norm**2, slope, trial)
        if found is None:
            return replace(state, status=Status.LINE_SEARCH_FAILED, rcond=rcond,
                           message=f"no step length along the Newton direction from z^{state.k} decreases ||Phi|| = "
                                   f"{state.residual_norm:.2e} (directional derivative {slope:.2e}); the step was not "
                                   "taken (the default solver.globalization: hybrid leaves such points)")
        return newton.advance(state, found[1], rcond=rcond)


GLOBALIZATIONS: dict[str, Callable[[SemismoothNewton], object]] = {
    "none": lambda newton: newton,
    "line_search": lambda newton: LineSearchNewton(newton, Armijo()),
    "hybrid": lambda newton: HybridNewton(newton, handover=True),
    "interior_point": lambda newton: HybridNewton(newton, handover=False),
}


def globalized(newton: SemismoothNewton):
    """``newton`` inside the globalization its options ask for (:data:`GLOBALIZATIONS`)."""
    return GLOBALIZATIONS[resolve(newton.options)](newton)
