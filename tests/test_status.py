"""gnerun/solvers/status.py: ``evolve`` makes what ``dataclasses.replace`` makes."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from gnerun.solvers.hybrid import Memory
from gnerun.solvers.status import SSNState, Status, evolve


def _state() -> SSNState:
    memory = Memory(phase="newton", merits=(1.0, 0.5), best=0.5, stalls=2, interior=None, handover=1e-2,
                    origin=np.arange(3.0), handover0=1e-2, attempt=1, decouple=True)
    return SSNState(z=np.arange(3.0), x=np.zeros(2), k=4, phi=np.ones(3), residual_norm=math.sqrt(3.0), parts=None,
                    active=np.array([0, 2]), z_prev=None, active_prev=None, status=Status.RUNNING, message="",
                    rng=np.random.default_rng(0), search=memory)


def _fields(obj) -> dict:
    return {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}


@pytest.mark.parametrize("changes", [{}, {"k": 5, "status": Status.CONVERGED}, {"search": None, "rcond": 0.25}])
def test_evolve_is_replace_for_the_iterate_state(changes: dict) -> None:
    state = _state()
    mine, theirs = evolve(state, **changes), dataclasses.replace(state, **changes)
    assert type(mine) is SSNState and mine is not state
    a, b = _fields(mine), _fields(theirs)
    assert a.keys() == b.keys() and all(a[k] is b[k] for k in a)  # the same objects, none copied


def test_evolve_is_replace_for_the_frozen_memory() -> None:
    memory = _state().search
    mine = evolve(memory, phase="interior", stalls=0, best=math.inf)
    theirs = dataclasses.replace(memory, phase="interior", stalls=0, best=math.inf)
    assert _fields(mine) == {k: v for k, v in _fields(theirs).items()} | {"origin": mine.origin}
    assert mine.origin is memory.origin and hash(mine.merits) == hash(theirs.merits)
    with pytest.raises(dataclasses.FrozenInstanceError):
        mine.best = 0.0  # still frozen
    with pytest.raises(TypeError, match="no field 'nonsense'"):
        evolve(memory, nonsense=1)


def test_evolve_leaves_a_dataclass_with_post_init_or_derived_fields_to_replace() -> None:
    @dataclasses.dataclass
    class Checked:
        a: int
        twice: int = dataclasses.field(init=False, default=0)

        def __post_init__(self) -> None:
            self.twice = 2 * self.a

    assert evolve(Checked(1), a=4).twice == 8
