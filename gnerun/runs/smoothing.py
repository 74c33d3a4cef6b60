"""Games with abs, min or max of their decisions: a smoothing homotopy where the Newton methods fail.

The derivative of abs(u) jumps at u = 0, so the KKT system of a game whose costs or rows have abs, min or max of the
decisions is discontinuous at their kinks, and an equilibrium that sits at a kink (an L1 input cost that holds an
input at its reference, a max of two costs at their crossing) is a zero of no continuous function the Newton methods
can approach: they stall. Smoothing replaces abs(u) by sqrt(u^2 + mu^2) - mu and max, min(u, v) by
(u + v +- sqrt((u - v)^2 + mu^2))/2, each within mu of the original (Chen and Mangasarian 1996; the smoothing
Newton methods of Qi, Sun and Zhou 2000), and follows the solutions of the smoothed games as mu goes to zero
(``LEVELS``), each level warm-started from the last. The last level's point is within about mu of an equilibrium at a
kink; whether it is one is then the certificate's to say, on the original game (gnerun.solvers.certificate: a box
search for small players, probes of the branches around a kink): the KKT residual of the nonsmooth system, with one
branch's derivative at the kink, is no measure there.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ..game.compile import compile_game
from ..language.config import Config
from ..solvers.driver import iterate
from ..solvers.factory import make_solver
from ..solvers.status import SSNState

# mu, times max(1, |a^0|_inf): from 10 to 1e-8 by factors of sqrt(10) (by factors of 10, a level's start can lie a
# few mu from the next level's kink, past which a full Newton step lands in another branch)
LEVELS = tuple(float(10.0 ** (1 - k / 2)) for k in range(19))
CLOSE_ENOUGH = 1e-4  # a homotopy stopped after a level of at most this mu (relative) still ends there
RESTART_FROM = 1e-2  # the first relative mu of a homotopy started again from best responses
LEVEL_TOL = 1e-3  # each level is solved to ||Phi|| <= max(tol, LEVEL_TOL mu): its solution is within ~mu anyway


@dataclass
class Smoothed:
    """The end of :func:`smoothing_homotopy`."""

    z: np.ndarray  # the last level's solution
    levels: list[tuple[float, str, int]]  # (mu, status, iterations) per level solved
    iterations: int  # in all levels

    @property
    def mu(self) -> float:
        """The last level solved."""
        return [mu for mu, status, _ in self.levels if status == "converged"][-1]


def smoothing_homotopy(cfg: Config, z0: np.ndarray, x: np.ndarray | None = None,
                       on_iterate: Callable[[SSNState], None] | None = None, k0: int = 0,
                       first: float = LEVELS[0]) -> Smoothed | None:
    """Solve the smoothed games for mu in ``LEVELS`` from z0, each from the last one's solution, by the semismooth
    Newton method with Armijo backtracking on ||Phi||^2 (the smoothed abs has a curvature of 1/mu at its kink and
    nearly none away from it: a full step from a level's start overshoots, and the merit's descent keeps it), or,
    where that fails, the default method. None if no level down to ``CLOSE_ENOUGH`` converges. ``on_iterate`` sees
    every iterate of every level, numbered on from ``k0``; ``first`` is the relative mu to begin with (a start
    already near an equilibrium, such as a best response, begins small: a large mu smooths its basin away)."""
    z = np.asarray(z0, dtype=float)
    scale = max(1.0, float(np.max(np.abs(z), initial=0.0)))
    levels: list[tuple[float, str, int]] = []
    k = k0
    for level in (mu for mu in LEVELS if mu <= first):
        mu = level * scale
        game = compile_game(cfg, smoothing=mu)
        state = None
        for globalization in ("line_search", "hybrid"):
            solver = cfg.solver.model_copy(update={"globalization": globalization, "max_iter": max(cfg.solver.max_iter,
                                                                                                   200),
                                                   "tol": max(cfg.solver.tol, LEVEL_TOL * mu)})
            solver_ = make_solver(cfg.model_copy(update={"solver": solver}), game, disturbed=False)
            offset = k

            def seen(state: SSNState, offset: int = offset) -> None:
                if on_iterate is not None:
                    on_iterate(replace(state, k=offset + state.k))

            state = iterate(solver_, solver_.init(z, x), on_iterate=seen)
            k += state.k
            if state.converged:
                break
        levels.append((mu, str(state.status), state.k))
        if not state.converged:
            break
        z = state.z
    solved = [mu for mu, status, _ in levels if status == "converged"]
    if not solved or solved[-1] > CLOSE_ENOUGH * scale:
        return None
    return Smoothed(z, levels, k - k0)
