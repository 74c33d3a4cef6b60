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


def fallback_plan(game: CompiledGame, solver, stage: StageConstraints, x: np.ndarray, trace: list,
                  plan_prev: np.ndarray | None) -> Plan:
    """The plan to apply among the iterates of this sampling time (the last first) and the fallback plan, the plan
    applied at t - 1 shifted (at t = 0 the warm start z^0). ``trace``: (k, ||Phi||, z^k) from the warm start on."""
    candidates = [Plan(zk, r, first_step_violation(game, stage, x, zk), k) for k, r, zk in reversed(trace[1:])]
    if plan_prev is None:
        zf, merit = trace[0][2], trace[0][1]
    else:
        zf = game.shift(plan_prev)
        merit = trace[0][1] if np.array_equal(zf, trace[0][2]) else solver.init(zf, x).residual_norm
    candidates.append(Plan(zf, merit, first_step_violation(game, stage, x, zf), -1))
    return choose(candidates)


@dataclass(slots=True, frozen=True)
class Applied:
    """What the plant gets at one sampling time: the plan whose first inputs are applied, whether it is not z^K(t)
    (a fallback step), and the safeguard's choice where it made one."""

    z: np.ndarray
    fallback: bool
    plan: Plan | None = None


class PaperRule:
    """``safeguard: none``: z^K(t) is applied; after a failed step the last iterate before it (a diverged or NaN one
    is not used). The next sampling time starts from the plan applied."""

    def apply(self, x: np.ndarray, trace: list, z: np.ndarray, k: int, converged: bool, failed: bool,
              plan_prev: np.ndarray | None) -> Applied:
        return Applied(trace[-1][2] if failed else z, failed)

    def next_start(self, trace: list, applied: Applied, z: np.ndarray, failed: bool) -> np.ndarray:
        return applied.z if failed else z


class Fallback:
    """``safeguard: fallback``: an iterate that is not converged is applied only if it is the best plan at hand
    (:func:`fallback_plan`). The solver goes on from its own iterates (time-distributed optimisation), even where
    the plant got another plan: from the best of them (a nonmonotone method's last iterate may have climbed), or
    from the plan applied when no step was taken."""

    def __init__(self, game: CompiledGame, solver, stage: StageConstraints):
        self.game, self.solver, self.stage = game, solver, stage

    def apply(self, x: np.ndarray, trace: list, z: np.ndarray, k: int, converged: bool, failed: bool,
              plan_prev: np.ndarray | None) -> Applied:
        if converged:
            return Applied(z, failed)
        plan = fallback_plan(self.game, self.solver, self.stage, x, trace, plan_prev)
        return Applied(plan.z, failed or plan.k != k, plan)

    def next_start(self, trace: list, applied: Applied, z: np.ndarray, failed: bool) -> np.ndarray:
        if len(trace) > 1:
            return min(trace[1:], key=lambda it: finite_or_inf(it[1]))[2]
        return applied.z if failed else z
