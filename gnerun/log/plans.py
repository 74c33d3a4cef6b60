"""The states a logged plan predicts, computed where the log is written.

A closed loop logs, with each sampling time's state, the states the applied plan predicts over its horizon (for
Rerun's paths view). The loop hands a log written by a process of its own (:mod:`gnerun.log.writer`) the plan's
decisions, and the writer rolls them out: the plant model accumulated over the horizon, a CasADi Function that
crosses to the writer serialized.
"""

from __future__ import annotations

import casadi as ca
import numpy as np


class PlanStates:
    """``(a, x) -> `` the states x(0) = x, x(tau + 1) = f(x(tau), u(tau)), tau = 0..T, as a (T + 2) x nx array.

    ``rollout``: x(0), the stages' inputs (nu x (T + 1), stage by stage) -> x(1..T+1) (nx x (T + 1)), the plant
    model's ``mapaccum``; ``order``: the places in a of u(0), u(1), ... (each stage's inputs in agent order).
    """

    def __init__(self, rollout: ca.Function, order: np.ndarray):
        self.rollout = rollout
        self.order = np.asarray(order, dtype=np.intp)
        self.stages = rollout.size1_in(1), rollout.size2_in(1)

    def __call__(self, a: np.ndarray, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        inputs = np.asarray(a, dtype=float)[self.order].reshape(self.stages[1], self.stages[0]).T
        with np.errstate(all="ignore"):  # a plan that diverges gives non-finite values from there on
            states = np.asarray(self.rollout(x, inputs))
        return np.vstack([x, states.T])

    def __reduce__(self):
        return _load, (self.rollout.serialize(), self.order)


def _load(text: str, order: np.ndarray) -> PlanStates:
    return PlanStates(ca.Function.deserialize(text), order)
