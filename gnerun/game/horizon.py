"""The receding horizon of a dynamic game's plan z = (a, lambda): the inputs the plant receives from a plan, and the
shifted plan that warm-starts the next sampling time (the MPC convention, ``run.warm_start: shift``)."""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING

import numpy as np

from .evaluator import Evaluator

if TYPE_CHECKING:
    from .compile import CompiledGame


class Horizon:
    """The plans of one compiled game (``game.plans``); a static game's plan is its own shift."""

    def __init__(self, game: CompiledGame):
        self.game = game

    def shift(self, z: np.ndarray) -> np.ndarray:
        """Shifted warm start of a dynamic game: the inputs drop stage 0 and repeat stage T; a row's multiplier moves
        with its constraint to the stage before (the last stage keeps its own), except where that stage's row is
        another function (a constraint that depends on tau, e.g. a safety margin that grows over the first stages,
        :attr:`changed_rows`) or the constraint does not hold at the next stage (``stages``): there it starts
        from zero."""
        if self.game.kind != "dynamic":
            return np.array(z, dtype=float)
        take, zero = self._shift_take
        out = np.asarray(z, dtype=float)[take]
        out[zero] = 0.0
        return out

    @functools.cached_property
    def _shift_take(self) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`shift` as one gather: the entry of z each entry of the shifted plan takes, and the entries that start
        from zero instead (no source, or a row :attr:`changed_rows` names)."""
        source = self._shift_source
        zero = source < 0
        zero[self.game.n:] |= self.changed_rows
        return np.maximum(source, 0), np.flatnonzero(zero)

    @functools.cached_property
    def _shift_source(self) -> np.ndarray:
        """For every entry of z, the entry it takes in a shifted plan (-1: none, it starts from zero)."""
        n, T = self.game.n, self.game.horizon
        source = np.arange(self.game.size)
        for sl in self.game.agent_slices:  # an agent's inputs are time-major, the same at every stage
            b = source[sl].reshape(T + 1, (sl.stop - sl.start) // (T + 1))
            source[sl] = np.concatenate([b[1:], b[-1:]]).reshape(-1)
        # rows are matched by constraint (owner, text, carriers, and which occurrence at its stage) and stage
        seen: dict[tuple, int] = {}
        keys = []
        for info in self.game.constraints:
            base = (info.owner, info.label.rsplit(" [tau=", 1)[0], info.carriers, info.stage)
            seen[base] = seen.get(base, -1) + 1
            keys.append((*base[:3], seen[base]))
        row = {(*key, info.stage): j for j, (key, info) in enumerate(zip(keys, self.game.constraints, strict=True))}
        for j, (key, info) in enumerate(zip(keys, self.game.constraints, strict=True)):
            if info.stage is not None and info.stage < T:
                nxt = row.get((*key, info.stage + 1))
                source[n + j] = -1 if nxt is None else n + nxt
        source.flags.writeable = False
        return source

    @functools.cached_property
    def changed_rows(self) -> np.ndarray:
        """Rows of c whose multiplier the shift would take from a different function: the row at stage tau compared
        with the same constraint at tau + 1 on the same states and inputs (a shifted plan, one random point: two
        different functions differ there almost surely)."""
        changed = np.zeros(self.game.m, dtype=bool)
        if self.game.kind != "dynamic" or not self.game.m or self.game._dynamics is None:
            return changed
        rng = np.random.default_rng(0)
        a = self.game.a_start + rng.uniform(-0.5, 0.5, self.game.n)
        x = self.game.x0 + rng.uniform(-0.5, 0.5, self.game.nx)
        x1 = self.game.step_dynamics(x, self.first_inputs(a))
        source = self._shift_source
        a_shift = a[source[: self.game.n]]
        before, after = self.game.constraint(a, x), self.game.constraint(a_shift, x1)
        rows = source[self.game.n:] - self.game.n  # the row each multiplier comes from (negative: none)
        moved = (rows >= 0) & (rows != np.arange(self.game.m))
        with np.errstate(invalid="ignore"):
            differ = ~np.isclose(after, before[np.maximum(rows, 0)], rtol=1e-9, atol=1e-12, equal_nan=True)
        changed = moved & differ
        changed.flags.writeable = False
        return changed

    def first_inputs(self, a: np.ndarray) -> np.ndarray:
        """u(0): every agent's first input, in agent order (what the plant receives)."""
        return np.asarray(a)[self._first]

    @functools.cached_property
    def _first(self) -> np.ndarray:
        """The places of u(0) in a: the first stage's of :attr:`stage_order`."""
        return self.stage_order[: sum(len(v) for v in self.game.variable_names)]

    @functools.cached_property
    def rollout_function(self):
        """x(0) and the stages' inputs (nu x (T + 1)) -> x(1..T+1): the plant model accumulated over the horizon."""
        return self.game._dynamics.function.mapaccum("rollout", self.game.horizon + 1)

    @functools.cached_property
    def _rollout(self) -> Evaluator:
        return Evaluator(self.rollout_function)

    @functools.cached_property
    def stage_order(self) -> np.ndarray:
        """The places in a of u(0), u(1), ..., u(T), each stage's inputs in agent order (the stages'
        inputs stage by stage: ``a[stage_order]``)."""
        game = self.game
        blocks = zip(game.agent_slices, game.variable_names, strict=True)
        order = np.hstack([np.arange(sl.start, sl.stop).reshape(game.horizon + 1, len(v)) for sl, v in blocks])
        order = order.reshape(-1)
        order.flags.writeable = False
        return order

    def predicted_states(self, a: np.ndarray, x: np.ndarray) -> np.ndarray:
        """The states the plan's inputs lead to from x under the plant model: x(0) = x, x(tau + 1) = f(x(tau), u(tau))
        for tau = 0..T: a (T + 2) x nx array (the states the stage costs see, after x; a plan that diverges gives
        non-finite values from there on)."""
        x = np.asarray(x, dtype=float)
        with np.errstate(all="ignore"):
            states = self._rollout(x, np.asarray(a, dtype=float)[self.stage_order])[0]
        return np.vstack([x, states.T])
