"""Compiled games: the KKT system of a (generalized) Nash game with exact derivatives.

``compile_game(cfg)`` parses every expression once, builds CasADi symbolic expressions from the
syntax trees (never from Python source), differentiates them by automatic differentiation and wraps
the result in CasADi Functions that the solvers evaluate at every iterate. Build once, solve many.

Notation (paper §III): the primal variable a = (a_1, ..., a_N); agent i's constraints
g_i(a) <= 0 (equalities h_i(a) = 0 are allowed too) with multipliers lambda_i; z = (a, lambda) with
lambda = (lambda_1, ..., lambda_N[, lambda_shared]). The parts the Newton methods need are

- ``L(z)``   = (grad_{a_i} L_i(a, lambda_i))_i, L_i = J_i + lambda_i^T g_i  [KKT_concatenated]
- ``c(a)``   = the constraint values, one per multiplier, in multiplier order (g or h)
- ``dL/dz`` and ``dc/da`` (dense, exact)
- the pseudogradient ``F(a)`` = (grad_{a_i} J_i)_i [P_gradient] and game Hessian ``H(a)`` [Hessian].

Dynamic games (CG-MPC, [MPC_1]) are condensed: xi(0) = x, xi(tau+1) = f(xi(tau), a(tau)), and
agent i's cost is sum_{tau=0..T} l_i(xi(tau+1), a(tau)) + Psi_i(xi(T+1)) (gnerun's convention: each stage cost
is charged on the state its input produces). Constraints are imposed at every stage tau = 0..T on
(xi(tau+1), a(tau)). Every function then takes the current plant state x as a parameter. Within an
agent, inputs are time-major: a_i = (u_i(0), u_i(1), ..., u_i(T)) with u_i(tau) the agent's inputs.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import casadi as ca
import numpy as np

from ..language.config import (
    Config,
    ContinuousDynamics,
    DynamicGame,
    LinearDynamics,
    StaticGame,
    constraint_agents,
    constraint_stages,
    constraint_text,
)
from ..language.expr import Shared, casadi_functions, evaluate, parse_constraint, parse_expression
from ..language.runtime import RuntimeLayout, runtime_layout
from .affine import LQStructure, derivatives_affine, offset_map
from .agents import AgentFunctions
from .building import stoppable
from .evaluator import DenseOutputs, Evaluator
from .horizon import Horizon
from .pattern import Pattern


@dataclass(frozen=True)
class ConstraintInfo:
    """One row of c(a), i.e. one multiplier."""

    label: str  # e.g. "u3 >= u1 + u2 [tau=4]"
    owner: int | None  # agent index; None for a shared constraint with a common multiplier
    equality: bool
    stage: int | None = None
    carriers: tuple[int, ...] | None = None  # a common multiplier's row: the agents that carry it (None: all)
    bound: bool = False  # the row of a variable's lower or upper bound


class KKTParts(NamedTuple):
    """L, c and their exact derivatives at one point (dense numpy arrays)."""

    L: np.ndarray  # (n,)
    c: np.ndarray  # (m,)
    dL_dz: np.ndarray  # (n, n + m)
    dc_da: np.ndarray  # (m, n)


@dataclass(frozen=True)
class _Symbolic:
    """The KKT system's symbolic parts, from which derivatives are built when first needed."""

    a: ca.SX
    lam: ca.SX
    x: ca.SX
    L: ca.SX  # stationarity, (grad_{a_i} L_i)_i
    c: ca.SX  # constraint values
    F: ca.SX  # pseudogradient
    J: ca.SX  # the agents' costs


@dataclass
class CompiledGame:
    """A game ready for the Newton methods. Create with :func:`compile_game`."""

    kind: str  # "static" | "dynamic"
    agent_names: list[str]
    agent_slices: list[slice]  # primal block of each agent in a
    multiplier_slices: list[slice]  # multiplier block of each agent in lambda
    shared_slice: slice  # common multipliers of variational shared constraints (may be empty)
    variable_names: list[list[str]]  # per agent: its variables (static) or inputs (dynamic)
    constraints: list[ConstraintInfo]
    a_start: np.ndarray
    a_lower: np.ndarray  # bounds of the decision variables (-inf/inf: none); their rows are constraints too
    a_upper: np.ndarray
    x0: np.ndarray  # current state of a dynamic game (empty for static games)
    horizon: int | None
    state_names: list[str]
    equilibrium: str
    n_shared: int  # shared constraints declared per stage
    _symbolic: _Symbolic = field(repr=False)
    _costs: Evaluator = field(repr=False)
    _agent_constraints: list[np.ndarray]  # per agent: row indices of c that constrain its own problem
    runtime: RuntimeLayout | None = field(default=None, repr=False)  # the runtime parameters' layout (None: none)
    p: np.ndarray = field(default_factory=lambda: np.zeros(0))  # the runtime values now in force
    _dynamics: Evaluator | None = field(default=None, repr=False)
    _domain: tuple | None = field(default=None, repr=False)  # where each cost's log, sqrt... are defined
    derived: dict = field(default_factory=dict, repr=False)  # what is built from this game once (sparse system)
    smoothing: float = 0.0  # mu of compile_game(cfg, smoothing): abs, min and max smoothed (0: the game as written)

    # The dense derivatives are built on first use: the sparse formulation of a long horizon never needs
    # the condensed Jacobian, whose construction grows with T^2.
    @functools.cached_property
    @stoppable
    def _derivatives(self) -> dict:
        sym = self._symbolic
        dL = ca.jacobian(sym.L, ca.vertcat(sym.a, sym.lam))
        dc = ca.jacobian(sym.c, sym.a) if self.m else ca.SX(0, self.n)
        return self._derivative_functions(dL, dc)

    def _derivative_functions(self, dL: ca.SX, dc: ca.SX) -> dict:
        """What ``_derivatives`` holds, from the expressions dL/dz and dc/da (kept as ``expressions``: a player's
        own problem takes its blocks, :func:`derivatives_from_game`)."""
        sym = self._symbolic
        a, lam, x, L, c = sym.a, sym.lam, sym.x, sym.L, sym.c
        # abs, min, max of the decisions have a zero second derivative almost everywhere, and are not affine
        affine = derivatives_affine(sym, dL, dc) and not self.lq.piecewise
        kkt = ca.Function("kkt", [a, lam, x], [ca.densify(L), ca.densify(c), dL, dc], ["a", "lam", "x"],
                          ["L", "c", "dL_dz", "dc_da"])
        # [L; c] at z = 0 as a function of the state: for LQ dynamic games it is affine in x as well
        offsets = offset_map(sym, self.n, self.m) if affine else None
        return {"kkt": DenseOutputs(kkt), "sparsity": (dL.sparsity(), dc.sparsity()), "affine": affine,
                "offset_map": offsets, "expressions": (dL, dc)}

    @property
    def _kkt(self) -> Evaluator:
        return self._derivatives["kkt"]

    @functools.cached_property
    @stoppable
    def _residual(self) -> Evaluator:
        """L and c without derivatives: what a line search evaluates at its trial points."""
        sym = self._symbolic
        return Evaluator(ca.Function("kkt_residual", [sym.a, sym.lam, sym.x], [ca.densify(sym.L), ca.densify(sym.c)],
                                     ["a", "lam", "x"], ["L", "c"]))

    @functools.cached_property
    @stoppable
    def _constraints(self) -> Evaluator:
        sym = self._symbolic
        dc = ca.jacobian(sym.c, sym.a) if self.m else ca.SX(0, self.n)
        return Evaluator(ca.Function("constraints", [sym.a, sym.x], [ca.densify(sym.c), ca.densify(dc)],
                                     ["a", "x"], ["c", "dc_da"]))

    def constraint_values(self, a: np.ndarray, x: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """c(a; x) and dc/da alone (what a best response's feasible set needs)."""
        c, dc = self._constraints(a, self._x(x))
        return c.reshape(-1), dc.reshape(self.m, self.n)

    @functools.cached_property
    @stoppable
    def _constraint_only(self) -> Evaluator:
        sym = self._symbolic
        return Evaluator(ca.Function("c", [sym.a, sym.x], [ca.densify(sym.c)], ["a", "x"], ["c"]))

    def constraint(self, a: np.ndarray, x: np.ndarray | None = None) -> np.ndarray:
        """c(a; x) without its derivative (cheap to build for any game)."""
        return self._constraint_only(a, self._x(x))[0].reshape(-1)

    @functools.cached_property
    def lq(self) -> LQStructure:
        """The affine and piecewise structure (gnerun.game.affine): an LQ game's constant map, the linear rows."""
        return LQStructure(self)

    @property
    def piecewise(self) -> bool:
        """:attr:`gnerun.game.affine.LQStructure.piecewise`."""
        return self.lq.piecewise

    @functools.cached_property
    def agents(self) -> AgentFunctions:
        """Each agent's own functions (gnerun.game.agents): what a best-response check reads."""
        return AgentFunctions(self, self._agent_constraints, self._domain)

    @functools.cached_property
    def pattern(self) -> Pattern:
        """The structural nonzeros (gnerun.game.pattern): of JPhi, of dc/da, the rows no decision reaches."""
        return Pattern(self)

    @property
    def _sparsity(self) -> tuple[ca.Sparsity, ca.Sparsity]:
        return self._derivatives["sparsity"]

    @property
    def affine(self) -> bool:
        """L affine in z and c affine in a, with constant derivatives (LQ games)."""
        return self._derivatives["affine"]

    @functools.cached_property
    @stoppable
    def _pseudo(self) -> Evaluator:
        sym = self._symbolic
        H = ca.jacobian(sym.F, sym.a)
        return Evaluator(ca.Function("pseudogradient", [sym.a, sym.x], [ca.densify(sym.F), ca.densify(H)],
                                     ["a", "x"], ["F", "H"]))

    @functools.cached_property
    @stoppable
    def _own_grads(self) -> Evaluator:
        sym = self._symbolic  # F is an expression of the game already: no derivative is built here
        return Evaluator(ca.Function("own_gradients", [sym.a, sym.x], [ca.densify(sym.F)], ["a", "x"], ["F"]))

    @functools.cached_property
    @stoppable
    def _cost_grads(self) -> Evaluator:
        sym = self._symbolic
        return Evaluator(ca.Function("cost_gradients", [sym.a, sym.x], [ca.densify(ca.jacobian(sym.J, sym.a))],
                                     ["a", "x"], ["dJ"]))

    # sizes --------------------------------------------------------------------------------
    @property
    def n(self) -> int:
        """Number of primal unknowns (all agents' decisions)."""
        return int(self.a_start.size)

    @property
    def m(self) -> int:
        """Number of multipliers."""
        return len(self.constraints)

    @property
    def size(self) -> int:
        """Number of unknowns of the KKT system, n + m."""
        return self.n + self.m

    @property
    def nx(self) -> int:
        return int(self.x0.size)

    @property
    def equality_mask(self) -> np.ndarray:
        return np.array([c.equality for c in self.constraints], dtype=bool)

    @property
    def shares_constraints_generalized(self) -> bool:
        """True for a plain GNE whose shared constraints each agent carries with its own multiplier."""
        return self.equilibrium == "generalized" and self.n_shared > 0

    def z_start(self) -> np.ndarray:
        """The config's start values, multipliers zero."""
        return np.concatenate([self.a_start, np.zeros(self.m)])

    def _x(self, x: np.ndarray | None) -> np.ndarray:
        """What the compiled functions take for the state x: x and the runtime values in force (:attr:`p`); an x that
        carries its runtime values already is taken as it is."""
        if x is None:
            x = self.x0
        elif not (type(x) is np.ndarray and x.ndim == 1 and x.dtype == np.float64):
            x = np.asarray(x, dtype=float).reshape(-1)
        if x.size == self.nx:
            return np.concatenate([x, self.p]) if self.p.size else x
        if x.size != self.nx + self.p.size:
            raise ValueError(f"state x has {x.size} entries, the game has {self.nx} states")
        return x

    def set_parameters(self, values: dict | None = None, t: float = 0.0) -> np.ndarray:
        """Put runtime values in force: the declared ones at time ``t`` (data files interpolated at the stages'
        times, ``t`` the time of stage 0), except those ``values`` gives ({name: number, list or array}). Nothing
        is recompiled. Returns p."""
        self.p = self._runtime_vector(values, t)
        return self.p

    def _runtime_vector(self, values: dict | None, t: float) -> np.ndarray:
        """The runtime values at time t: the declared ones, except those ``values`` gives (no runtime parameters:
        the empty vector, and no values may be given)."""
        if self.runtime is None:
            if values:
                raise ValueError(f"runtime values for {', '.join(values)}: this game has no runtime parameters")
            return np.zeros(0)
        return self.runtime.vector(t, values)

    def adopt(self, cfg: Config) -> CompiledGame:
        """This compiled game for ``cfg``, a config that compiles to the same functions (:func:`compile_key`): its
        declared runtime values, data files and x0 replace this game's. Nothing is recompiled."""
        compiled_from = self.derived.get("config")
        if compiled_from is None or compile_key(cfg) != compile_key(compiled_from):
            raise ValueError("the config compiles to another game (it differs in more than runtime values and x0)")
        self.runtime = runtime_layout(cfg)
        self.p = np.zeros(0) if self.runtime is None else self.runtime.vector()
        self.x0 = np.asarray(cfg.game.x0, dtype=float) if cfg.game.kind == "dynamic" else self.x0
        return self

    def with_parameters(self, x: np.ndarray | None = None, values: dict | None = None, t: float = 0.0) -> np.ndarray:
        """The state x with runtime values appended, (x, p), for a solver that embeds the game:
        ``solver.init(z0, game.with_parameters(x, {"r": 0.3}, t))`` solves with those values (every step of that
        solve uses them), whatever values are in force in the game. Nothing is recompiled."""
        x = self.x0 if x is None else np.asarray(x, dtype=float).reshape(-1)
        if x.size != self.nx:
            raise ValueError(f"state x has {x.size} entries, the game has {self.nx} states")
        return np.concatenate([x, self._runtime_vector(values, t)])

    @property
    def parameters(self) -> dict:
        """The runtime values in force, by name (``t``: the time of stage 0, where the game uses the time)."""
        return {} if self.runtime is None else self.runtime.record(self.p)

    # evaluation ---------------------------------------------------------------------------
    def kkt_parts(self, z: np.ndarray, x: np.ndarray | None = None) -> KKTParts:
        """L(z; x), c(a; x), dL/dz and dc/da at z = (a, lambda)."""
        n = self.n
        if self.affine:
            cache = self.lq.cache
            v = cache["W"] @ z
            v += self.lq.offsets(self._x(x))
            return KKTParts(v[:n], v[n:], cache["dL"], cache["dc"])
        L, c, dL, dc = self._kkt(z[:n], z[n:], self._x(x))
        return KKTParts(L.reshape(-1), c.reshape(-1), dL, dc)

    def kkt_residual(self, z: np.ndarray, x: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """L(z; x) and c(a; x) alone (no derivatives, and none built: a sparse formulation's solve or a certificate
        without best responses never needs the condensed ones)."""
        n = self.n
        if "_derivatives" in self.__dict__ and self.affine:  # an LQ game's constant map, where it is known already
            v = self.lq.cache["W"] @ z
            v += self.lq.offsets(self._x(x))
            return v[:n], v[n:]
        L, c = self._residual(z[:n], z[n:], self._x(x))
        return L.reshape(-1), c.reshape(-1)

    def costs(self, a: np.ndarray, x: np.ndarray | None = None) -> np.ndarray:
        """(J_1(a), ..., J_N(a)) at the state x."""
        return self._costs(a, self._x(x))[0].reshape(-1)

    def own_gradients(self, a: np.ndarray, x: np.ndarray | None = None) -> np.ndarray:
        """F(a) = (grad_{a_i} J_i(a))_i, each agent's cost gradient in its own decisions (n), without the game Hessian
        of :meth:`pseudogradient` or the full rows of :meth:`cost_gradients` (whose construction grows like N n: 1 s
        for 200 Cournot firms)."""
        return self._own_grads(a, self._x(x))[0].reshape(-1)

    def cost_gradients(self, a: np.ndarray, x: np.ndarray | None = None) -> np.ndarray:
        """Rows: grad_a J_i(a) with respect to all of a (N x n)."""
        return self._cost_grads(a, self._x(x))[0]

    def pseudogradient(self, a: np.ndarray, x: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """F(a) = (grad_{a_i} J_i)_i and the game Hessian H(a) = dF/da."""
        F, H = self._pseudo(a, self._x(x))
        return F.reshape(-1), H

    def step_dynamics(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The plant model f(x, u) (dynamic games; runtime parameters do not enter it)."""
        if self._dynamics is None:
            raise ValueError("a static game has no dynamics")
        return self._dynamics(x, u)[0].reshape(-1)

    # solutions by name --------------------------------------------------------------------
    def solution_by_agent(self, a: np.ndarray) -> dict[str, dict[str, float | list[float]]]:
        out: dict[str, dict[str, float | list[float]]] = {}
        for name, sl, vars_ in zip(self.agent_names, self.agent_slices, self.variable_names, strict=True):
            block = np.asarray(a[sl], dtype=float)
            if self.kind == "static":
                out[name] = {v: _num(block[j]) for j, v in enumerate(vars_)}
            else:
                per_stage = block.reshape(self.horizon + 1, len(vars_))
                out[name] = {v: [_num(t) for t in per_stage[:, j]] for j, v in enumerate(vars_)}
        return out

    def multipliers_by_agent(self, lam: np.ndarray) -> dict[str, list[float]]:
        out = {name: [_num(v) for v in lam[sl]] for name, sl in zip(self.agent_names, self.multiplier_slices,
                                                                    strict=True)}
        if self.shared_slice.stop > self.shared_slice.start:
            out["shared"] = [_num(v) for v in lam[self.shared_slice]]
        return out

    def agent_indices(self, agent: int) -> np.ndarray:
        """Indices of z_i = (a_i, lambda_i) in z (common multipliers of shared constraints excluded)."""
        ms = self.multiplier_slices[agent]
        return np.r_[np.arange(self.agent_slices[agent].start, self.agent_slices[agent].stop),
                     self.n + np.arange(ms.start, ms.stop)].astype(int)

    # the receding horizon (gnerun.game.horizon): what the plant receives from a plan, and the next plan's start
    @functools.cached_property
    def plans(self) -> Horizon:
        return Horizon(self)

    def shift(self, z: np.ndarray) -> np.ndarray:
        """:meth:`gnerun.game.horizon.Horizon.shift`."""
        return self.plans.shift(z)

    @property
    def shift_changed_rows(self) -> np.ndarray:
        """:attr:`gnerun.game.horizon.Horizon.changed_rows`."""
        return self.plans.changed_rows

    def first_inputs(self, a: np.ndarray) -> np.ndarray:
        """:meth:`gnerun.game.horizon.Horizon.first_inputs`."""
        return self.plans.first_inputs(a)

    def predicted_states(self, a: np.ndarray, x: np.ndarray) -> np.ndarray:
        """:meth:`gnerun.game.horizon.Horizon.predicted_states`."""
        return self.plans.predicted_states(a, x)


def _num(v: float) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None


# ---------------------------------------------------------------------------------------------
# Compilation
# ---------------------------------------------------------------------------------------------


@dataclass
class _Row:
    expr: ca.SX
    info: ConstraintInfo


def _bound_rows(var: ca.SX, name: str, lower: float | None, upper: float | None, owner: int,
                stage: int | None) -> list[_Row]:
    rows = []
    suffix = f" [tau={stage}]" if stage is not None else ""
    if lower is not None and math.isfinite(lower):
        rows.append(_Row(lower - var, ConstraintInfo(f"{name} >= {lower:g}{suffix}", owner, False, stage, bound=True)))
    if upper is not None and math.isfinite(upper):
        rows.append(_Row(var - upper, ConstraintInfo(f"{name} <= {upper:g}{suffix}", owner, False, stage, bound=True)))
    return rows


def _constraint_rows(texts: list, env: dict, fns: dict, owner: int | None, stage: int | None,
                     agent_names: list[str] | None = None, shared: Shared | None = None) -> list[_Row]:
    """The rows of ``texts`` at ``stage`` for ``owner`` (an agent index: the shared constraints it carries; None:
    the common rows of a variational game, each with the agents that carry it)."""
    rows = []
    suffix = f" [tau={stage}]" if stage is not None else ""
    for spec in texts:
        stages = constraint_stages(spec)
        if stages is not None and stage not in stages:
            continue
        carriers = constraint_agents(spec)
        if carriers is not None and owner is not None and agent_names[owner] not in carriers:
            continue
        text = constraint_text(spec)
        con = parse_constraint(text)
        who = None if carriers is None or owner is not None else tuple(agent_names.index(a) for a in carriers)
        info = ConstraintInfo(text + suffix, owner, con.is_equality, stage, who)
        rows.append(_Row(ca.SX(con.residual(env, fns, shared)), info))
    return rows


@dataclass
class _Layout:
    """Sizes and positions of the agents' decisions in a."""

    variable_names: list[list[str]]
    agent_slices: list[slice]
    n: int
    nx: int
    horizon: int | None
    a_start: np.ndarray
    x0: np.ndarray
    a_lower: np.ndarray  # the variables' bounds (-inf/inf: none), as declared
    a_upper: np.ndarray
    runtime: RuntimeLayout | None = None

    @property
    def np(self) -> int:
        """The number of runtime values (appended to the state in every compiled function)."""
        return 0 if self.runtime is None else self.runtime.size


def _bounds(variables) -> tuple[list[float], list[float]]:
    lo = [-math.inf if v.lower is None else float(v.lower) for v in variables]
    hi = [math.inf if v.upper is None else float(v.upper) for v in variables]
    return lo, hi


def _layout(g: StaticGame | DynamicGame, runtime: RuntimeLayout | None = None) -> _Layout:
    if isinstance(g, StaticGame):
        names = [list(a.variables) for a in g.agents]
        sizes = [len(v) for v in names]
        starts = [var.start for a in g.agents for var in a.variables.values()]
        lo, hi = _bounds([var for a in g.agents for var in a.variables.values()])
        return _Layout(names, _slices(sizes), sum(sizes), 0, None, np.asarray(starts, dtype=float), np.zeros(0),
                       np.asarray(lo), np.asarray(hi), runtime)
    T = g.horizon
    names = [list(a.inputs) for a in g.agents]
    sizes = [len(v) * (T + 1) for v in names]
    starts = [var.start[tau] if isinstance(var.start, list) else var.start  # time-major within an agent
              for a in g.agents for tau in range(T + 1) for var in a.inputs.values()]
    lo, hi = [], []
    for a in g.agents:
        l_a, h_a = _bounds(list(a.inputs.values()))
        lo += l_a * (T + 1)
        hi += h_a * (T + 1)
    return _Layout(names, _slices(sizes), sum(sizes), len(g.states), T, np.asarray(starts, dtype=float),
                   np.asarray(g.x0, dtype=float), np.asarray(lo, dtype=float), np.asarray(hi, dtype=float), runtime)


def _slices(sizes: list[int]) -> list[slice]:
    offsets = np.cumsum([0, *sizes])
    return [slice(int(offsets[i]), int(offsets[i + 1])) for i in range(len(sizes))]


@dataclass
class _Expressions:
    costs: dict[int, ca.SX]  # J_i(a; x) of the agents asked for
    own_rows: dict[int, list[_Row]]  # their constraint rows, stage by stage
    shared_common: list[_Row]  # variational shared constraints (one common multiplier each)
    dynamics: ca.Function | None
    defects: list[ca.SX] = field(default_factory=list)  # with given states: f(xi(tau), u(tau)) - xi(tau+1)
    domain: dict = field(default_factory=dict)  # per agent: (kind, margin) of each log, sqrt, asin, acos of its cost
    stage_costs: dict = field(default_factory=dict)  # with given states: per agent, l_i at tau = 0..T, then Psi_i


# long: the static and the dynamic walks share the parsed data and `constrain`; split, each would take a dozen arguments
def _expressions(g: StaticGame | DynamicGame, lay: _Layout, a: ca.SX, x: ca.SX, agents: list[int],
                 *, shared_as_own: bool = False, states: ca.SX | None = None, smoothing: float = 0.0,
                 local_time: bool = False) -> _Expressions:
    """Costs and constraints of ``agents`` only, as CasADi expressions in (a, x); x holds the plant state and then
    the runtime values (``lay.runtime``), if any.

    Other agents' costs and constraints are not even parsed: what is built from here can reach only
    the chosen agents' own data, the common dynamics and parameters. Shared constraints go to each
    chosen agent's own rows when the equilibrium is generalized (or ``shared_as_own``), otherwise to
    the common block.

    Dynamic games are condensed (the states are functions of x and a), unless ``states`` gives the
    states xi(1), ..., xi(T+1) as variables (stage-major): then the dynamics become the defects
    f(xi(tau), u(tau)) - xi(tau+1), with xi(0) = x (the sparse formulation). With ``local_time``, the time t of
    every stage is the first runtime value itself (t + dt in the terminal cost): each stage as if it were the first,
    for stage functions that take their own time (gnerun.game.kernels).
    """
    # where the log, sqrt, asin, acos of each agent's cost are defined is recorded (gnerun.language.expr)
    domain: dict[int, list] = {i: [] for i in agents}
    cost_fns = {i: casadi_functions(domain[i], smoothing) for i in agents}
    fns = fns_f = casadi_functions(smoothing=smoothing)
    params = dict(g.parameters)
    if isinstance(getattr(g, "dynamics", None), ContinuousDynamics):
        params.setdefault("dt", g.dynamics.dt)  # the sampling time, a name of the expressions (a parameter dt: equal)
    rt = lay.runtime
    p = x[lay.nx:]
    x = x[:lay.nx] if rt is not None else x
    per_stage: dict = {}
    dyn_params = dict(params)  # the dynamics see the compile-time parameters only
    if rt is not None:
        common, per_stage = rt.symbols(p)
        params.update(common)
    slices, names = lay.agent_slices, lay.variable_names
    own_shared = g.equilibrium == "generalized" or shared_as_own
    names_of_agents = [ag.name for ag in g.agents]
    costs: dict[int, ca.SX] = {}
    own: dict[int, list[_Row]] = {i: [] for i in agents}
    common: list[_Row] = []

    def constrain(env: dict, stage: int | None, shared: Shared) -> None:
        for i in agents:
            agent = g.agents[i]
            variables = agent.variables if isinstance(g, StaticGame) else agent.inputs
            for vname, var in variables.items():
                own[i] += _bound_rows(env[vname], vname, var.lower, var.upper, i, stage)
            own[i] += _constraint_rows(agent.constraints, env, fns, i, stage, shared=shared)
            if own_shared:
                own[i] += _constraint_rows(g.shared_constraints, env, fns, i, stage, names_of_agents, shared)
        if not own_shared:
            common.extend(_constraint_rows(g.shared_constraints, env, fns, None, stage, names_of_agents, shared))

    if isinstance(g, StaticGame):
        env: dict = dict(params)
        for i, vars_ in enumerate(names):
            env.update({v: a[slices[i].start + j] for j, v in enumerate(vars_)})
        shared = Shared()  # an aggregate written into every cost is built once
        for i in agents:
            costs[i] = ca.SX(evaluate(parse_expression(g.agents[i].cost), env, cost_fns[i], shared))
        constrain(env, None, shared)
        return _Expressions(costs, own, common, None, domain=domain)

    inputs = [(i, j, u) for i, vars_ in enumerate(names) for j, u in enumerate(vars_)]
    continuous = isinstance(g.dynamics, ContinuousDynamics)
    equations = g.dynamics.ode if continuous else g.dynamics
    dyn = None if isinstance(g.dynamics, LinearDynamics) else {s: parse_expression(equations[s]) for s in g.states}

    def rhs(xi: ca.SX, u: ca.SX) -> ca.SX:
        env_f = dict(dyn_params)
        env_f.update({s: xi[k] for k, s in enumerate(g.states)})
        env_f.update({name: u[k] for k, (_, _, name) in enumerate(inputs)})
        return ca.vertcat(*[ca.SX(evaluate(dyn[s], env_f, fns_f)) for s in g.states])

    def f(xi: ca.SX, u: ca.SX) -> ca.SX:
        if isinstance(g.dynamics, LinearDynamics):
            return ca.mtimes(ca.DM(g.dynamics.A), xi) + ca.mtimes(ca.DM(g.dynamics.B), u)
        if continuous:
            return runge_kutta(rhs, xi, u, g.dynamics.dt, g.dynamics.integrator)
        return rhs(xi, u)

    xs, us = ca.SX.sym("xs", lay.nx), ca.SX.sym("us", len(inputs))
    dynamics = ca.Function("f", [xs, us], [ca.densify(f(xs, us))])
    stage_cost = {i: parse_expression(g.agents[i].stage_cost) for i in agents}
    terminal_cost = {i: parse_expression(g.agents[i].terminal_cost) for i in agents}
    total = {i: ca.SX(0) for i in agents}
    stage_costs: dict[int, list[ca.SX]] = {i: [] for i in agents}
    xi = x
    defects: list[ca.SX] = []
    for tau in range(lay.horizon + 1):
        u = ca.vertcat(*[a[slices[i].start + tau * len(names[i]) + j] for i, j, _ in inputs])
        if states is None:
            xi = f(xi, u)  # the state that the inputs of stage tau produce
        else:
            nxt = states[tau * lay.nx:(tau + 1) * lay.nx]
            defects.append(f(xi, u) - nxt)
            xi = nxt
        env = dict(params)
        env["tau"] = float(tau)
        if rt is not None:
            rt.at_stage(env, p, per_stage, tau)
            if local_time and rt.time:
                env["t"] = p[0]
        env.update({s: xi[k] for k, s in enumerate(g.states)})
        env.update({name: u[k] for k, (_, _, name) in enumerate(inputs)})
        shared = Shared()
        for i in agents:
            l_i = evaluate(stage_cost[i], env, cost_fns[i], shared)
            total[i] += l_i
            if states is not None:
                stage_costs[i].append(ca.SX(l_i))
        constrain(env, tau, shared)
    env_T = dict(params)
    if rt is not None:
        rt.at_stage(env_T, p, per_stage, lay.horizon + 1)
        if local_time and rt.time:
            env_T["t"] = p[0] + rt.dt
    env_T.update({s: xi[k] for k, s in enumerate(g.states)})
    shared = Shared()
    for i in agents:
        psi = evaluate(terminal_cost[i], env_T, cost_fns[i], shared)
        costs[i] = ca.SX(total[i] + psi)
        if states is not None:
            stage_costs[i].append(ca.SX(psi))
    return _Expressions(costs, own, common, dynamics, defects, domain, stage_costs)


def shared_rows_carried(common: list, start: int, agent: int) -> np.ndarray:
    """Indices (from ``start``) of the common rows of a variational game that ``agent`` carries: every row whose
    constraint names no agents, and those that name it."""
    return np.array([start + r for r, row in enumerate(common)
                     if row.info.carriers is None or agent in row.info.carriers], dtype=int)


# explicit Runge-Kutta methods as Butcher tableaux (A strictly lower triangular, weights b): forward Euler, Heun's
# second-order method, Kutta's third-order method, the classical fourth-order method
BUTCHER = {
    "euler": ([], [1.0]),
    "rk2": ([[1.0]], [0.5, 0.5]),
    "rk3": ([[0.5], [-1.0, 2.0]], [1.0 / 6.0, 2.0 / 3.0, 1.0 / 6.0]),
    "rk4": ([[0.5], [0.0, 0.5], [0.0, 0.0, 1.0]], [1.0 / 6.0, 1.0 / 3.0, 1.0 / 3.0, 1.0 / 6.0]),
}


def runge_kutta(rhs, x, u, dt: float, method: str):
    """One step of length dt of dx/dt = rhs(x, u) with u held constant, by the explicit method ``method``."""
    A, b = BUTCHER[method]
    k = [rhs(x, u)]
    for row in A:
        k.append(rhs(x + dt * sum((a * kj for a, kj in zip(row, k, strict=False) if a), 0), u))
    return x + dt * sum((w * kj for w, kj in zip(b, k, strict=True) if w), 0)


def _assemble(*, kind: str, a: ca.SX, x: ca.SX, costs: list[ca.SX], own_rows: list[list[_Row]],
              shared_common: list[_Row], agent_names: list[str], lay: _Layout, equilibrium: str, n_shared: int,
              state_names: list[str], dynamics: ca.Function | None, domain: dict | None = None) -> CompiledGame:
    """The KKT system of the agents' problems [KKT_concatenated]; its exact derivatives are built on first use."""
    N = len(costs)
    agent_slices = lay.agent_slices
    rows: list[_Row] = [r for block in own_rows for r in block] + shared_common
    m = len(rows)
    multiplier_slices = _slices([len(b) for b in own_rows])
    shared_slice = slice(multiplier_slices[-1].stop if N else 0, m)
    lam = ca.SX.sym("lam", m)
    c = ca.vertcat(*[r.expr for r in rows]) if rows else ca.SX(0, 1)

    carried = [shared_rows_carried(shared_common, shared_slice.start, i) for i in range(N)]
    grads = []
    for i in range(N):
        Li = costs[i]
        ms = multiplier_slices[i]
        if ms.stop > ms.start:
            Li = Li + ca.dot(lam[ms], c[ms])
        if carried[i].size:
            Li = Li + ca.dot(lam[carried[i].tolist()], c[carried[i].tolist()])
        grads.append(ca.gradient(Li, a[agent_slices[i]]))
    L = ca.vertcat(*grads)
    J = ca.vertcat(*costs)
    F = ca.vertcat(*[ca.gradient(costs[i], a[agent_slices[i]]) for i in range(N)])
    costs_fn = ca.Function("costs", [a, x], [ca.densify(J)], ["a", "x"], ["J"])

    # agent i's own problem: its own rows, plus the common shared rows (they constrain everyone)
    agent_rows = [np.r_[np.arange(ms.start, ms.stop), carried[i]].astype(int)
                  for i, ms in enumerate(multiplier_slices)]
    return CompiledGame(
        kind=kind,
        agent_names=agent_names,
        agent_slices=agent_slices,
        multiplier_slices=multiplier_slices,
        shared_slice=shared_slice,
        variable_names=lay.variable_names,
        constraints=[r.info for r in rows],
        a_start=lay.a_start,
        a_lower=lay.a_lower,
        a_upper=lay.a_upper,
        x0=lay.x0,
        horizon=lay.horizon,
        state_names=state_names,
        equilibrium=equilibrium,
        n_shared=n_shared,
        runtime=lay.runtime,
        p=np.zeros(0) if lay.runtime is None else lay.runtime.vector(),
        _symbolic=_Symbolic(a, lam, x, L, c, F, J),
        _costs=Evaluator(costs_fn),
        _agent_constraints=agent_rows,
        _dynamics=Evaluator(dynamics) if dynamics is not None else None,
        _domain=_domain_function(a, x, [(i, kind, m) for i in sorted(domain or {}) for kind, m in domain[i]]),
    )


def _domain_function(a: ca.SX, x: ca.SX, domain: list) -> tuple[Evaluator, np.ndarray, np.ndarray] | None:
    """The recorded domain conditions (agent, kind, margin) as one function of (a, x), which of them are strict
    (> 0) and whose cost each belongs to."""
    if not domain:
        return None
    margins = ca.vertcat(*[m for _, _, m in domain])
    strict = np.array([kind == "positive" for _, kind, _ in domain], dtype=bool)
    owner = np.array([i for i, _, _ in domain], dtype=int)
    return Evaluator(ca.Function("domain", [a, x], [ca.densify(margins)])), strict, owner


def compile_key(cfg: Config) -> str:
    """What a compiled game depends on: the game without its runtime values (their shapes stay) and x0, and the
    sampling time. Configs of equal keys share one compilation (:meth:`CompiledGame.adopt`)."""
    data = cfg.model_dump(mode="json")
    game = data["game"]
    game.pop("x0", None)
    for spec in (game.get("runtime") or {}).values():
        spec["value"] = list(np.shape(spec["value"])) if spec.get("value") is not None else None
        spec.pop("file", None)  # a data file's column: T + 2 values whatever file
    return hashlib.sha256(json.dumps([game, cfg.run.sampling_time], sort_keys=True).encode()).hexdigest()


@stoppable
def compile_game(cfg: Config, smoothing: float = 0.0) -> CompiledGame:
    """Parse, condense (dynamic games) and differentiate the game of ``cfg`` once. With ``smoothing`` mu > 0, abs, min
    and max are replaced by smooth functions within mu of them (gnerun.language.expr.casadi_functions)."""
    g = cfg.game
    lay = _layout(g, runtime_layout(cfg))
    N = len(g.agents)
    a = ca.SX.sym("a", lay.n)
    x = ca.SX.sym("x", lay.nx + lay.np)  # the plant state, then the runtime values
    ex = _expressions(g, lay, a, x, list(range(N)), smoothing=smoothing)
    game = _assemble(kind=g.kind, a=a, x=x, costs=[ex.costs[i] for i in range(N)],
                     own_rows=[ex.own_rows[i] for i in range(N)], shared_common=ex.shared_common,
                     agent_names=[ag.name for ag in g.agents], lay=lay, equilibrium=g.equilibrium,
                     n_shared=len(g.shared_constraints),
                     state_names=list(g.states) if isinstance(g, DynamicGame) else [], dynamics=ex.dynamics,
                     domain=ex.domain)
    if not smoothing:
        game.derived["config"] = cfg  # what it was compiled from (adopt)
    game.smoothing = smoothing
    return game


@dataclass(frozen=True)
class StageConstraints:
    """The constraint rows of the first stage (tau = 0) as functions of the inputs u applied and the state x_next
    they produce: what a closed loop's applied step must satisfy. Built by :func:`compile_stage_constraints`."""

    function: Evaluator  # (x_next, u[, (x, p)]) -> c
    equality: np.ndarray
    labels: list[str]
    game: CompiledGame | None = None  # where the runtime values in force are read (a game with runtime parameters)

    def violations(self, x_next: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Each row's violation: max(c_j, 0), |c_j| for an equality (0 where it holds)."""
        if not self.labels:
            return np.zeros(0)
        if self.game is not None:
            c = self.function(x_next, u, self.game._x(np.zeros(self.game.nx)))[0].reshape(-1)
        else:
            c = self.function(x_next, u)[0].reshape(-1)
        return np.where(self.equality, np.abs(c), np.maximum(c, 0.0))

    def violation(self, x_next: np.ndarray, u: np.ndarray) -> tuple[float, str | None]:
        """The largest violation and its row's label (0.0 and None when every row holds; nan if not finite)."""
        v = self.violations(x_next, u)
        if not v.size:
            return 0.0, None
        j = int(np.argmax(v))  # (a NaN's place, where there is one: violations are >= 0 or NaN)
        if not math.isfinite(v[j]):
            return math.nan, self.labels[int(np.flatnonzero(~np.isfinite(v))[0])]
        return (float(v[j]), self.labels[j]) if v[j] > 0 else (0.0, None)


@stoppable
def compile_stage_constraints(cfg: Config, game: CompiledGame | None = None) -> StageConstraints:
    """Every agent's and every shared constraint row at tau = 0, in terms of (x_next, u): the stage's rows of the
    game, written with the state as a variable instead of f(x, u), so that they can be checked on the state the
    plant actually reached (with its disturbance). With runtime parameters, the values in force in ``game``."""
    g = cfg.game
    if not isinstance(g, DynamicGame):
        raise ValueError("a static game has no stages")
    lay = _layout(g, runtime_layout(cfg))
    sizes = [len(v) for v in lay.variable_names]
    first = np.concatenate([np.arange(sl.start, sl.start + k) for sl, k in zip(lay.agent_slices, sizes, strict=True)])
    one = _Layout(lay.variable_names, _slices(sizes), sum(sizes), lay.nx, 0, lay.a_start[first], lay.x0,
                  lay.a_lower[first], lay.a_upper[first], lay.runtime)
    u = ca.SX.sym("u", one.n)
    x, x_next = ca.SX.sym("x", lay.nx + lay.np), ca.SX.sym("x_next", lay.nx)
    ex = _expressions(g, one, u, x, list(range(len(g.agents))), states=x_next)
    rows = [replace(r, info=replace(r.info, label=f"{g.agents[r.info.owner].name}: {r.info.label}"))
            for i in range(len(g.agents)) for r in ex.own_rows[i]]
    rows += [replace(r, info=replace(r.info, label=f"shared: {r.info.label}")) for r in ex.shared_common]
    c = ca.vertcat(*[r.expr for r in rows]) if rows else ca.SX(0, 1)
    if lay.runtime is not None:
        fn = ca.Function("stage_constraints", [x_next, u, x], [ca.densify(c)], ["x_next", "u", "x"], ["c"])
        if game is None:
            game = compile_game(cfg)
    else:
        fn = ca.Function("stage_constraints", [x_next, u], [ca.densify(c)], ["x_next", "u"], ["c"])
        game = None
    return StageConstraints(Evaluator(fn), np.array([r.info.equality for r in rows], dtype=bool),
                            [r.info.label for r in rows], game)


@stoppable
def compile_agent_problem(cfg: Config, agent: int, tau: float) -> CompiledGame:
    """Agent ``agent``'s proximal response problem [eq:proximal_response, eq:Semi_proximal]:

        min_{a_i} J_i(a_i, abar_-i) + tau/2 ||a_i - abar_i||^2  s.t.  g_i(a_i, abar_-i) <= 0,

    compiled as a one-agent problem whose parameter vector is p = (x, abar_-i, abar_i): the plant state (with the
    game's runtime values: ``game._x(x)``), the other agents' last decisions (a without agent i's block) and the
    proximal centre. It is built
    from agent i's own cost and constraints only (shared constraints count as its own).
    """
    g = cfg.game
    lay = _layout(g, runtime_layout(cfg))
    sl = lay.agent_slices[agent]
    ni = sl.stop - sl.start
    ai = ca.SX.sym("a_i", ni)
    others = ca.SX.sym("abar_others", lay.n - ni)
    centre = ca.SX.sym("abar_i", ni)
    xs = ca.SX.sym("x", lay.nx + lay.np)  # the plant state and the runtime values
    # row and column slices: a one-element vector sliced by rows alone is 1 x 1, and its empty slice 1 x 0, which
    # vertcat would turn into a structural zero row
    a_full = ca.vertcat(others[: sl.start, :], ai, others[sl.start :, :])
    ex = _expressions(g, lay, a_full, xs, [agent], shared_as_own=True)
    cost = ex.costs[agent] + 0.5 * tau * ca.sumsqr(ai - centre)
    p0 = np.zeros(0) if lay.runtime is None else lay.runtime.vector()
    own_lay = _Layout([lay.variable_names[agent]], [slice(0, ni)], ni, lay.nx + lay.np + lay.n, None,
                      lay.a_start[sl].copy(), np.concatenate([lay.x0, p0, np.zeros(lay.n)]), lay.a_lower[sl].copy(),
                      lay.a_upper[sl].copy())
    return _assemble(kind="static", a=ai, x=ca.vertcat(xs, others, centre), costs=[cost],
                     own_rows=[[_Row(r.expr, replace(r.info, owner=0)) for r in ex.own_rows[agent]]],
                     shared_common=[], agent_names=[g.agents[agent].name],
                     lay=own_lay, equilibrium="generalized", n_shared=0, state_names=[], dynamics=None)


def agent_problem(game: CompiledGame, agent: int, tau: float, cfg: Config | None = None) -> CompiledGame:
    """:func:`compile_agent_problem` built from the game's own expressions instead of its config: agent ``agent``'s
    cost and the rows it carries are the game's (the same expressions, so the same values), with its decisions as
    the variables and p = (x, abar_-i, abar_i) as the parameters; nothing is parsed, evaluated or condensed again
    (0.1-0.2 s per agent of a trajectory game). The rows come in the order that function gives them: stage by stage,
    the agent's own rows, then the shared rows it carries. A smoothed game's expressions are not the player's: its
    problem is compiled from ``cfg`` (the game as written), and without ``cfg`` that is an error."""
    if game.smoothing:
        if cfg is None:
            raise ValueError("an agent's problem is built from the game as written (smoothing 0)")
        return compile_agent_problem(cfg, agent, tau)
    sym = game._symbolic
    a, xs = sym.a, sym.x
    sl = game.agent_slices[agent]
    ni = sl.stop - sl.start
    ai = a[sl.start:sl.stop, :]  # elements of the game's symbols: a valid input of an SX function
    others = ca.vertcat(a[:sl.start, :], a[sl.stop:, :])
    centre = ca.SX.sym("abar_i", ni)
    cost = sym.J[agent] + 0.5 * tau * ca.sumsqr(ai - centre)
    rows = [int(r) for r in game._agent_constraints[agent]]  # its own rows, then the common rows it carries
    common = game.shared_slice.start

    def stage(r: int) -> int:
        s = game.constraints[r].stage
        return -1 if s is None else s

    rows.sort(key=lambda r: (stage(r), r >= common))  # stable: each group keeps its order within a stage
    own = [_Row(sym.c[r], replace(game.constraints[r], owner=0, carriers=None)) for r in rows]
    p0 = np.zeros(0) if game.runtime is None else game.runtime.vector()
    own_lay = _Layout([game.variable_names[agent]], [slice(0, ni)], ni, game.nx + p0.size + game.n, None,
                      game.a_start[sl].copy(), np.concatenate([game.x0, p0, np.zeros(game.n)]),
                      game.a_lower[sl].copy(), game.a_upper[sl].copy())
    problem = _assemble(kind="static", a=ai, x=ca.vertcat(xs, others, centre), costs=[cost], own_rows=[own],
                        shared_common=[], agent_names=[game.agent_names[agent]], lay=own_lay,
                        equilibrium="generalized", n_shared=0, state_names=[], dynamics=None)
    problem.derived["game_rows"] = np.array(rows, dtype=int)  # its row j is the game's row game_rows[j]
    return problem


@stoppable
def derivatives_from_game(problem: CompiledGame, game: CompiledGame, agent: int) -> bool:
    """Give agent ``agent``'s own problem (:func:`agent_problem` at weight 0: its row j is the game's row
    ``problem.derived["game_rows"][j]``) its dense derivatives as blocks of the game's, where the game has built
    them: its rows of dL/dz at its decisions and its rows' multipliers, and its rows of dc/da at its decisions, the
    game's multipliers of those rows replaced by the problem's own. The same expressions as differentiating the
    player's stationarity and rows in its own unknowns, without differentiating again (a robot of the 6-robot
    formation: 25 -> 6 ms); the values agree to rounding (the last bit where CasADi's two derivatives order their
    operations differently). Returns whether it did (not where the game's derivatives are not built, or the blocks
    depend on anything else)."""
    built = game.__dict__.get("_derivatives")
    rows = problem.derived.get("game_rows")
    if built is None or rows is None or game.smoothing or "_derivatives" in problem.__dict__:
        return False
    dL, dc = built["expressions"]
    sl = game.agent_slices[agent]
    own = list(range(sl.start, sl.stop))
    rows = [int(r) for r in rows]
    sym = problem._symbolic
    dL_i = dL[own, own + [game.n + r for r in rows]]
    if rows:  # (a player without rows has no multipliers to replace: CasADi refuses an empty substitution's shapes)
        dL_i = ca.substitute(dL_i, game._symbolic.lam[rows], sym.lam)
    dc_i = dc[rows, own] if rows else ca.SX(0, len(own))
    if ca.depends_on(ca.vec(ca.vertcat(ca.vec(dL_i), ca.vec(dc_i))), game._symbolic.lam):
        return False  # another player's multipliers in its block: not this problem's derivatives
    problem.__dict__["_derivatives"] = problem._derivative_functions(dL_i, dc_i)
    return True
