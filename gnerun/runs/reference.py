"""z*(t), the exact solution a closed loop's iterates are measured against (the tracking error of Theorem "bounded
error"): one object per loop, asked at every sampling time.

Each solve is :func:`gnerun.runs.solving.reference_solution` with the solvers this object built at its first
sampling time. They forget their factorisations per active set before each solve: a kept factor reproduces a step
to rounding, not bit for bit (e(t) of about 1e-14 where a new solver's is 0 on paper_study2), and z*(t) is that of a
new solver at every sampling time.
"""

from __future__ import annotations

import numpy as np

from ..game.compile import CompiledGame
from ..language.config import Config
from ..solvers.status import Status
from .interrupt import Interrupt
from .solving import Reference, reference_solution


class ReferenceSolver:
    """The exact solution z* of the game at a state x, from a given start."""

    def __init__(self, cfg: Config, game: CompiledGame):
        self.cfg, self.game = cfg, game
        self.solvers: dict = {}  # the solvers of reference_solution's attempts, built once

    def solve(self, z0: np.ndarray, x: np.ndarray, interrupt: Interrupt | None = None) -> Reference:
        """z* from z0 at x. A stop request (``interrupt``) raises :class:`~gnerun.runs.interrupt.Stopped` between two
        iterates."""
        return reference_solution(self.game, self.cfg, z0, x, interrupt=interrupt, solvers=self.solvers)

    @staticmethod
    def reached(state) -> Reference:
        """z* where the loop's own solver converged from its warm start (undisturbed, the reference's method): the
        unbudgeted solve from that start takes the same iterates (to rounding), so z* is the loop's iterate, to the
        solver's tolerance, and is not solved for again."""
        return Reference(state.z.copy(), Status.CONVERGED, state.residual_norm, state.k, "the loop's own solve")

    def track(self, z_warm: np.ndarray, z_previous: np.ndarray, x: np.ndarray,
              interrupt: Interrupt | None = None) -> Reference:
        """z*(t): the solution the solver reaches from the loop's warm start with an unlimited budget (so that e(t)
        measures the effect of the budget K, on the branch the loop follows when equilibria are not unique); then
        from z*(t-1), then cold."""
        ref = self.solve(z_warm, x, interrupt)
        for start in (z_previous, self.game.z_start()):
            if ref.converged:
                break
            ref = self.solve(start, x, interrupt)
        return ref
