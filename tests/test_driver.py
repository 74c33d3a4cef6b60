"""The driver loop (gnerun/solvers/driver.py) on a bare step function, and the status module's light imports."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace

import numpy as np

from gnerun.solvers.driver import Solver, iterate
from gnerun.solvers.status import FAILURES, SSNState, Status


class Halving:
    """||Phi|| halves every step; converged below tol; a failure at step ``fail_at``."""

    def __init__(self, tol: float = 1e-3, max_iter: int = 50, fail_at: int | None = None):
        self.tol, self.max_iter, self.fail_at = tol, max_iter, fail_at
        self.steps = 0

    def init(self, z0=None, x=None, rng=None) -> SSNState:
        z = np.ones(1)
        return SSNState(z=z, x=np.zeros(0), k=0, phi=z, residual_norm=1.0, parts=None, active=np.zeros(0, bool),
                        z_prev=None, active_prev=None, status=Status.RUNNING, message="", rng=None)

    def step(self, state: SSNState) -> SSNState:
        self.steps += 1
        if state.k + 1 == self.fail_at:
            return replace(state, status=Status.SINGULAR_JACOBIAN, message="singular")
        z = state.z / 2
        return replace(state, z=z, phi=z, residual_norm=float(z[0]), k=state.k + 1, z_prev=state.z)

    def terminate(self, state: SSNState) -> tuple[bool, Status]:
        if state.status in FAILURES:
            return True, state.status
        if state.residual_norm <= self.tol:
            return True, Status.CONVERGED
        return (True, Status.MAX_ITER) if state.k >= self.max_iter else (False, Status.RUNNING)

    def finish(self, state: SSNState) -> SSNState:
        done, status = self.terminate(state)
        return replace(state, status=status, message=status.value) if done else state


def test_iterate_steps_to_the_end_and_finishes() -> None:
    solver = Halving()
    assert isinstance(solver, Solver)
    seen: list[int] = []
    state = iterate(solver, solver.init(), on_iterate=lambda s: seen.append(s.k))
    assert state.status == Status.CONVERGED and state.k == 10  # 2^-10 < 1e-3
    assert seen == list(range(11)) and solver.steps == 10


def test_max_steps_stop_and_unfinished() -> None:
    solver = Halving()
    state = iterate(solver, solver.init(), 4)
    assert state.k == 4 and state.status == Status.RUNNING  # not done: finish leaves it running
    state = iterate(solver, solver.init(), stop=lambda s: s.k >= 2)
    assert state.k == 2
    state = iterate(solver, solver.init(), finish=False)
    assert state.k == 10 and state.status == Status.RUNNING


def test_a_failed_step_is_no_new_iterate() -> None:
    solver = Halving(fail_at=3)
    seen: list[int] = []
    state = iterate(solver, solver.init(), on_iterate=lambda s: seen.append(s.k))
    assert state.status == Status.SINGULAR_JACOBIAN and seen == [0, 1, 2]


def test_the_status_module_imports_nothing_heavy() -> None:
    code = ("import sys, gnerun.solvers.status, gnerun.solvers.driver; "
            "print(sorted(m for m in ('scipy', 'casadi', 'gnerun.game', 'gnerun.solvers.ssn') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_a_final_state_keeps_every_field_but_its_status_and_message() -> None:
    """``SSNState.ended`` (a solve's finish, by the constructor) against ``dataclasses.replace`` on every field: a
    field added to SSNState and not passed on would fail here."""
    import dataclasses

    values = {f.name: object() for f in dataclasses.fields(SSNState)}
    state = SSNState(**values)
    ended = state.ended(Status.CONVERGED, "done")
    expected = dataclasses.replace(state, status=Status.CONVERGED, message="done")
    for f in dataclasses.fields(SSNState):
        assert getattr(ended, f.name) is getattr(expected, f.name), f.name
