"""The driver loop: one solver's steps from a state to the end, for every caller.

A solver is a step function (STYLE.md, after optimistix): ``init(z0, x, rng) -> state``, ``step(state) -> state``
(exactly one iteration; a failed or converged state comes back unchanged), ``terminate(state) -> (done, status)``
and ``finish(state) -> state`` (the final status and its message). :func:`iterate` runs the steps: a solve, an
agent's proximal response, a best response of the certificate, the benchmarks. A new status is handled once, in
``terminate``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from .status import SSNState, Status


@runtime_checkable
class Solver(Protocol):
    """What :func:`iterate` needs of a solver (every solver of :mod:`gnerun.solvers` has it)."""

    def init(self, z0: np.ndarray | None = None, x: np.ndarray | None = None,
             rng: np.random.Generator | None = None, warm: bool = False) -> SSNState:
        """The state at z0 for the plant state x; ``warm``: z0 is a closed loop's warm start (the plan of the last
        sampling time), which only the globalized method's first step takes into account."""

    def step(self, state: SSNState) -> SSNState: ...

    def terminate(self, state: SSNState) -> tuple[bool, Status]: ...

    def finish(self, state: SSNState) -> SSNState: ...


@dataclass(frozen=True, slots=True)
class IterateRow:
    """What a table of iterates shows of one: k, ||Phi||, ||z^k - z^{k-1}||, the active-set changes, the phase of a
    method that has phases (gnerun.solvers.hybrid: newton, interior, search; None otherwise), and z^k."""

    k: int
    residual_norm: float
    step_norm: float
    active_set_changes: int
    phase: str | None
    z: np.ndarray

    @classmethod
    def of(cls, state: SSNState) -> IterateRow:
        return cls(state.k, state.residual_norm, state.step_norm, state.active_set_changes, phase(state), state.z)


def phase(state: SSNState) -> str | None:
    """The phase of the method that made ``state`` (None for a method without phases)."""
    return getattr(getattr(state, "search", None), "phase", None)


def iterate(solver: Solver, state: SSNState, max_steps: int | None = None,
            on_iterate: Callable[[SSNState], None] | None = None, *,
            stop: Callable[[SSNState], bool] | None = None, finish: bool = True,
            ends: frozenset[Status] | None = None) -> SSNState:
    """Step ``solver`` from ``state`` until ``terminate`` says done, ``max_steps`` steps were taken (None: no limit
    but the solver's max_iter) or ``stop(state)`` says so before a step (it may also raise, as a stop request does);
    then ``finish`` (unless not ``finish``: the state as the last step left it). ``on_iterate`` sees the state
    given and every new iterate after it (a step that makes none, a failed one, is not shown). With ``ends``, only
    those statuses of ``terminate`` end the loop: a closed loop's budget of K steps is not cut by max_iter."""
    if on_iterate is not None:
        on_iterate(state)
    steps = 0
    while True:
        done, status = solver.terminate(state)
        if (done if ends is None else status in ends):
            break
        if (max_steps is not None and steps >= max_steps) or (stop is not None and stop(state)):
            break
        previous = state.k
        state = solver.step(state)
        steps += 1
        if on_iterate is not None and state.k != previous:
            on_iterate(state)
    return solver.finish(state) if finish else state
