"""What every layer may know of a solve: its :class:`Status`, the statuses that are failures, and the iterate state.

A solver's ``step`` returns an :class:`SSNState`; drivers (:mod:`gnerun.solvers.driver`, the closed loop, the
certificate's best responses) read its status and the view reads the status names from logs. This module imports
nothing of gnerun: the view may import it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from enum import StrEnum
from types import MemberDescriptorType
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from ..game.compile import KKTParts
    from .hybrid import Memory


class Status(StrEnum):
    RUNNING = "running"
    CONVERGED = "converged"
    MAX_ITER = "max_iter"
    SINGULAR_JACOBIAN = "singular_jacobian"
    DIVERGED = "diverged"
    NAN = "nan"
    SUBPROBLEM_FAILED = "subproblem_failed"  # a Josephy-Newton step whose LCP has no solution found
    LINE_SEARCH_FAILED = "line_search_failed"  # no step length along the search direction decreases the merit
    INFEASIBLE_STAGE_CONSTRAINT = "infeasible_stage_constraint"  # a row no decision reaches is violated
    NOT_AN_EQUILIBRIUM = "not_an_equilibrium"  # a KKT point at which an agent can improve alone (certificate)
    STALLED = "stalled"  # the globalized method made no progress from any of its starting points
    # what a solve's certificate concludes (gnerun.runs.solving.certified_solve), never a step's status
    KKT_POINT = "kkt_point"  # a KKT point whose best responses were not (or could not be) checked: not certified
    UNBOUNDED_PLAYER = "unbounded_player"  # a player has no best response: its cost keeps decreasing along a ray
    INFEASIBLE = "infeasible"  # the game's constraints cannot all hold at once (phase 1)


_COPIERS: dict[type, object] = {}


def evolve(obj, **changes):
    """``dataclasses.replace(obj, **changes)`` for the iterate state and the globalization's memory, in half the
    time (4.2 -> 2.2 us on the hybrid method's memory of 24 fields; a Newton step of the hybrid method makes
    two, so does a closed loop's sampling time twice): the new object's fields set directly, as replace's
    ``__init__`` would, for a dataclass whose fields are all ``init`` fields and that has no ``__post_init__``
    (otherwise replace itself), by a function written once per class (:func:`_copier`)."""
    copier = _COPIERS.get(type(obj))
    if copier is None:
        copier = _COPIERS[type(obj)] = _copier(type(obj))
    return copier(obj, changes)


def _copier(cls: type):
    """The function :func:`evolve` calls for ``cls``: each field read from the old object and set on the new one
    through the class's own slot descriptors (frozen or not: what ``object.__setattr__`` does), then the changes; or
    ``dataclasses.replace`` where the class is not plain (a ``__post_init__``, a field that is not ``init``, no
    slots)."""
    names = tuple(f.name for f in fields(cls))
    slots = all(isinstance(cls.__dict__.get(name), MemberDescriptorType) for name in names)
    if hasattr(cls, "__post_init__") or not all(f.init for f in fields(cls)) or not slots:
        return lambda obj, changes: replace(obj, **changes)
    scope = {"_new": object.__new__, "_cls": cls, "_slots": {name: cls.__dict__[name] for name in names}}
    lines = ["def copy(obj, changes):", "    new = _new(_cls)"]
    for i, name in enumerate(names):
        scope[f"_d{i}"] = cls.__dict__[name]
        lines.append(f"    _d{i}.__set__(new, obj.{name})")
    lines += ["    for name, value in changes.items():",
              "        slot = _slots.get(name)",
              "        if slot is None:",
              "            raise TypeError(f'{_cls.__name__} has no field {name!r}')",
              "        slot.__set__(new, value)",
              "    return new"]
    exec("\n".join(lines), scope)  # the source is the class's own field names, as dataclasses writes __init__
    return scope["copy"]


FAILURES = frozenset({Status.SINGULAR_JACOBIAN, Status.DIVERGED, Status.NAN, Status.SUBPROBLEM_FAILED,
                      Status.LINE_SEARCH_FAILED, Status.INFEASIBLE_STAGE_CONSTRAINT, Status.STALLED})


@dataclass(slots=True)
class SSNState:
    """The iterate z^k and everything one step needs, evaluated once at z^k."""

    z: np.ndarray
    x: np.ndarray
    k: int
    phi: np.ndarray  # Phi(z^k)
    residual_norm: float  # ||Phi(z^k)||_2
    parts: KKTParts  # L, c and derivatives at z^k
    active: np.ndarray  # rows whose g-branch is chosen at z^k (min map: -g_j < lambda_j - tie_tol)
    z_prev: np.ndarray | None  # z^{k-1} (None at k = 0)
    active_prev: np.ndarray | None  # the g-branch rows at z^{k-1}
    status: Status
    message: str
    rng: np.random.Generator | None
    rcond: float = math.nan  # reciprocal condition number of the last JPhi factorised
    search: Memory | None = None  # what a globalization keeps between steps (gnerun.solvers.hybrid)

    @property
    def converged(self) -> bool:
        return self.status == Status.CONVERGED

    @property
    def step_norm(self) -> float:
        """||z^k - z^{k-1}||_2 (nan at k = 0); computed when asked, not in the solver loop."""
        if self.z_prev is None:
            return math.nan
        d = self.z - self.z_prev
        return math.sqrt(d @ d)

    def ended(self, status: Status, message: str) -> SSNState:
        """This state with its final ``status`` and ``message`` (what ``dataclasses.replace`` makes, by the
        constructor: a solve's last step, 0.3 instead of 1.8 us of the paper game's 40 us solve)."""
        return SSNState(self.z, self.x, self.k, self.phi, self.residual_norm, self.parts, self.active, self.z_prev,
                        self.active_prev, status, message, self.rng, self.rcond, self.search)

    @property
    def active_set_changes(self) -> int:
        """Rows whose branch changed from z^{k-1} to z^k."""
        return 0 if self.active_prev is None else int(np.count_nonzero(self.active != self.active_prev))
