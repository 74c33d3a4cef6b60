"""Semismooth Newton with Armijo backtracking on 1/2||Phi||^2 (``globalization: line_search``; also the default
method's line-search phase, :mod:`gnerun.solvers.hybrid`)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .line_search import Armijo
from .ssn import SemismoothNewton
from .status import FAILURES, SSNState, Status


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
             rng: np.random.Generator | None = None, warm: bool = False) -> SSNState:
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
            with np.errstate(over="ignore"):  # a trial point far out: its merit is inf, and the step is refused
                return 0.5 * float(phi @ phi), z

        found = self.search.search(0.5 * state.residual_norm**2, slope, trial)
        if found is None:
            return replace(state, status=Status.LINE_SEARCH_FAILED, rcond=rcond,
                           message=f"no step length along the Newton direction from z^{state.k} decreases ||Phi|| = "
                                   f"{state.residual_norm:.2e} (directional derivative {slope:.2e}); the step was not "
                                   "taken (the default solver.globalization: hybrid leaves such points)")
        return newton.advance(state, found[1], rcond=rcond)
