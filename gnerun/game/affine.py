"""The LQ structure of a compiled game: which parts are affine, piecewise or linear, and an LQ game's constant map.

An LQ game's KKT system is [L; c] = W z + w0(x) with a constant matrix W (``LQStructure.cache``) and offsets w0(x)
(``LQStructure.offsets``), affine in x as well for linear dynamics (``offset_map``). Which rows of c are affine in a
(polyhedral constraints), whether the one-step dynamics are affine, and which costs and rows pass through a piecewise
function of the decisions (abs, min, max: never affine) are read from the expression graph, each once (``game.lq``).
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING

import casadi as ca
import numpy as np

from .building import stoppable
from .tape import piecewise_outputs

if TYPE_CHECKING:
    from .compile import CompiledGame, _Symbolic


def derivatives_affine(sym: _Symbolic, dL: ca.SX, dc: ca.SX) -> bool:
    """dc/da constant and dL/dz constant (in z and x): the structural test of an LQ game's KKT system."""
    # the constraints' derivatives first: the smaller test, and nonlinear constraints end it (a quarter of the
    # derivative set-up of the 5-car merge was the test on dL)
    a, lam, x = sym.a, sym.lam, sym.x
    return not ca.depends_on(ca.vec(dc), ca.vertcat(a, x)) and not ca.depends_on(ca.vec(dL), ca.vertcat(a, lam, x))


def offset_map(sym: _Symbolic, n: int, m: int) -> tuple[np.ndarray, np.ndarray] | None:
    """(Wx, w00) with [L(0; x); c(0; x)] = Wx x + w00 where [L; c] of an affine game is affine in x too, else None."""
    a, lam, x = sym.a, sym.lam, sym.x
    v = ca.vertcat(sym.L, sym.c)
    dv_dx = ca.jacobian(v, x)
    if ca.depends_on(ca.vec(dv_dx), ca.vertcat(a, lam, x)):
        return None
    at_zero = ca.Function("offset_map", [a, lam, x], [ca.densify(dv_dx), ca.densify(v)])
    Wx, w00 = at_zero(np.zeros(n), np.zeros(m), np.zeros(x.numel()))
    return (np.array(Wx, dtype=float).reshape(v.numel(), x.numel()), np.array(w00, dtype=float).reshape(-1))


def affine_rows(c: ca.SX, a: ca.SX, m: int) -> np.ndarray:
    """Which rows of c(a) are affine in a: their second derivatives vanish structurally."""
    linear = np.ones(m, dtype=bool)
    if m == 0:
        return linear
    second = ca.jacobian(ca.vec(ca.jacobian(c, a)), a)  # rows: vec of dc/da, column-major (row index j + m*col)
    rows, _ = second.sparsity().get_triplet()
    for r in rows:
        linear[r % m] = False
    return linear


class LQStructure:
    """The affine and piecewise structure of one compiled game (``game.lq``); each part is built on first use."""

    def __init__(self, game: CompiledGame):
        self.game = game

    @functools.cached_property
    def piecewise_parts(self) -> tuple[np.ndarray, np.ndarray]:
        """Which costs and which constraint rows pass through a piecewise function of the decisions (abs, min, max,
        sign, a comparison): (per agent, per row of c). Their derivatives jump at kinks, so they are never affine,
        and a KKT point at a kink uses one branch's derivative."""
        sym = self.game._symbolic
        f = ca.Function("pieces", [sym.a, sym.x], [ca.vertcat(sym.J, sym.c)])
        flags = piecewise_outputs(f)
        N = len(self.game.agent_names)
        costs, rows = flags[:N].copy(), flags[N:].copy()
        costs.flags.writeable = rows.flags.writeable = False
        return costs, rows

    @property
    def piecewise(self) -> bool:
        """Some cost or constraint is piecewise in the decisions (see :attr:`piecewise_parts`)."""
        costs, rows = self.piecewise_parts
        return bool(costs.any() or rows.any())

    @property
    def offset_map(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(Wx, w00) with [L(0; x); c(0; x)] = Wx x + w00 for an LQ game affine in the state x too, else None."""
        return self.game._derivatives["offset_map"]

    @functools.cached_property
    def cache(self) -> dict:
        """An LQ game's constant matrices (``W``, ``dL``, ``dc``: [L; c] = W z + w0(x)), and what solvers derive from
        them once per game, kept with them (empty for other games)."""
        game = self.game
        if not game.affine:
            return {}
        # the constant derivatives, once; read-only, shared by every KKTParts
        _, _, dL, dc = game._kkt(np.zeros(game.n), np.zeros(game.m), game._x(None))
        # [L; c] = W z + w0(x) in one product
        W = np.vstack([dL, np.hstack([dc, np.zeros((game.m, game.m))])])
        for arr in (dL, dc, W):
            arr.flags.writeable = False
        return {"dL": dL, "dc": dc, "W": W, "x": None}

    def offsets(self, x: np.ndarray) -> np.ndarray:
        """[L(0; x); c(0; x)] of an affine game, evaluated once per state x."""
        cache = self.cache
        key = x.tobytes()
        if key != cache["x"]:
            offset = self.offset_map
            if offset is not None:  # affine in x too: one product
                Wx, w00 = offset
                w0 = Wx @ x
                w0 += w00
            else:
                game = self.game
                L0, c0, _, _ = game._kkt(np.zeros(game.n), np.zeros(game.m), x)
                w0 = np.concatenate([L0.reshape(-1), c0.reshape(-1)])
            w0.flags.writeable = False
            cache.update(x=key, w0=w0)
        return cache["w0"]

    @functools.cached_property
    @stoppable
    def linear_rows(self) -> np.ndarray:
        """Rows of c that are affine in a (polyhedral constraints): no second derivative, and no kink."""
        sym = self.game._symbolic
        return affine_rows(sym.c, sym.a, self.game.m) & ~self.piecewise_parts[1]

    @functools.cached_property
    @stoppable
    def linear_dynamics(self) -> bool:
        """The one-step dynamics affine in (x, u) (a static game: True); tested on one stage, without the
        condensed derivatives."""
        if self.game._dynamics is None:
            return True
        f = self.game._dynamics.function
        x, u = ca.SX.sym("x", f.nnz_in(0)), ca.SX.sym("u", f.nnz_in(1))
        d = ca.jacobian(f(x, u), ca.vertcat(x, u))
        return not ca.depends_on(ca.vec(d), ca.vertcat(x, u))
