"""Which plan a budgeted closed loop applies (``run.safeguard``).

Time-distributed optimisation applies the K-th iterate z^K(t) whether or not it has converged [eq:TDO]; its
guarantees (Liao-McPherson, Nicotra and Kolmanovsky, "Time-distributed optimization for real-time model predictive
control", Automatica 2020; the paper's Theorem "bounded error") hold for a contraction from a good enough warm
start. On nonlinear games with collision constraints a few iterations from a poor warm start can give a plan whose
first input drives the plant into a violation, or one that has diverged, and applying it blindly is what makes
vehicles pass through each other or leave the road. ``safeguard: fallback`` keeps the iterate when it is
converged, and otherwise applies the best plan at hand, as MPC implementations do when their solver runs out of
time (ALGAMES keeps the previous plan's shifted trajectory between re-solves; acados's real-time iteration applies
the feedback of the best available linearisation):

- the candidates are the iterates z^1(t), ..., z^K(t) the solver produced (a failed step's is not one) and the
  fallback plan, the plan applied at t - 1 shifted by one stage (at t = 0 the warm start);
- each is judged by its *first step*: the inputs it applies and the state the model says they produce, checked
  against every constraint row of stage 0 (:class:`~gnerun.game.compile.StageConstraints`), and by ||Phi||, its
  distance from an equilibrium at the current state;
- a candidate whose first step violates no row by more than ``SAFE`` is safe; the safe candidate with the smallest
  ||Phi|| is applied, or, when none is safe, the one whose first step violates least.

A sampling time whose applied plan is not z^K(t) is a fallback step (``fallback_steps`` in summary.json). The
applied plan is the warm start of the next sampling time (shifted with ``warm_start: shift``). ``safeguard: none``
is the paper's rule: z^K(t) is applied (after a failed step, the last iterate before it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..game.compile import CompiledGame, StageConstraints

SAFE = 1e-6  # a first step that violates no stage-0 row by more than this is safe


@dataclass(slots=True, frozen=True)
class Plan:
    """A candidate plan z at the current state: ||Phi(z)||, its first step's largest violation and where it came
    from (``k``: the iterate, or -1 for the fallback plan)."""

    z: np.ndarray
    residual_norm: float
    violation: float
    k: int

    @property
    def safe(self) -> bool:
        return self.violation <= SAFE

    def rank(self) -> tuple[int, float]:
        """Smaller is better: safe before unsafe; among safe plans the smaller ||Phi||, among unsafe the smaller
        violation (a non-finite value last)."""
        if self.safe:
            return 0, finite_or_inf(self.residual_norm)
        return 1, finite_or_inf(self.violation)


def first_step_violation(game: CompiledGame, stage: StageConstraints, x: np.ndarray, z: np.ndarray) -> float:
    """The largest violation of a stage-0 row by the first inputs of z and the state the model says they produce."""
    u = game.first_inputs(z[: game.n])
    if not np.all(np.isfinite(u)):
        return math.nan
    return stage.violation(game.step_dynamics(x, u), u)[0]


def choose(candidates: list[Plan]) -> Plan:
    """The plan to apply among ``candidates`` (module docstring); the first of equally good ones."""
    return min(candidates, key=Plan.rank)


def finite_or_inf(v: float) -> float:
    return v if math.isfinite(v) else math.inf
