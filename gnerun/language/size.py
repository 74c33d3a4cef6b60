"""The size of a config, estimated before anything is built: unknowns, expression nodes, closed-loop work.

Compiling a game costs time and memory that grow with the KKT system (z = (a, lambda)): linearly in the sparse
formulation (dynamic games solved by ssn, states and costates kept as unknowns), quadratically in a dense one
(static games, jn, distributed, or ``formulation: condensed``: the Jacobian JPhi is a dense matrix). A config
past the limits below is refused when it is loaded, with its estimate; one past the warning levels runs with a
warning, and ``gnerun validate`` does not build it, so that validate stays fast on any config. The limits
follow build times and memory measured on a 2-core machine (docs/failures.md, "Size limits").
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from .expr import Binary, Call, Expression, ExpressionError, Index, Node, Unary, parse_constraint, parse_expression
from .parts import constraint_agents, constraint_stages, constraint_text, dynamics_kind, obstacles, sparse_obstacles

if TYPE_CHECKING:
    from .config import Config, DisturbanceConfig, SolverConfig

DENSE_WARN = 3_000  # unknowns of a dense KKT system: a few seconds to build
DENSE_LIMIT = 8_000  # refused: a dense JPhi of 6.4e7 entries, several GB while it is built
SPARSE_WARN = 30_000  # unknowns of the sparse formulation (states and costates included): about 12 s to build
SPARSE_LIMIT = 250_000  # refused: minutes to build
NODES_WARN = 100_000  # expression nodes over all stages: 25-85 us each to build, so a few seconds
NODES_LIMIT = 10_000_000
# auto's choice (gnerun.runs.solving.formulation): sparse from SPARSE_FROM unknowns with linear dynamics, from
# SPARSE_WORK unknowns times stages with nonlinear ones; dynamics written as expressions may be found linear only when
# compiled, so below SPARSE_FROM unknowns they count as dense here: the estimate errs towards the dense formulation
# and its stricter limits (far above SPARSE_FROM)
SPARSE_FROM = 800
SPARSE_WORK = 1_000
LOOP_STEPS_WARN = 10_000_000  # from this many solver steps of a simulate on (sum over K of run.steps * K)
# The certificate of a solve builds every agent's own problem, condensed and dense (gnerun.game.compile.agent_problem):
# its decisions and constraint rows, the others' decisions as parameters; its time and memory grow with the square of
# the unknowns (the constants below: fitted to measured builds, docs/failures.md "Size limits").
RESPONSE_WARN = DENSE_WARN  # unknowns of the largest agent problem from which a solve warns
RESPONSE_S = 5.5e-6  # seconds per squared unknown of an agent problem
RESPONSE_BYTES = 93  # bytes per squared unknown, kept once built (the agents are built in turn and kept)


@dataclass(frozen=True)
class Size:
    """The estimate of one config."""

    decisions: int  # a: inputs over the stages (dynamic) or variables (static)
    multipliers: int  # lambda: one per constraint row, bounds included
    states: int  # states over the stages (unknowns of the sparse formulation only)
    nodes: int  # expression nodes, every stage counted
    dense: bool  # the Jacobian is a dense matrix
    loop_steps: int  # solver steps a simulate may take: sum over the distinct K of run.steps * K
    responses: tuple[int, ...] = ()  # unknowns of each agent's own problem, which a solve's certificate builds, dense

    @property
    def unknowns(self) -> int:
        """Unknowns of the system the solver factorises."""
        return self.decisions + self.multipliers + (0 if self.dense else 2 * self.states)

    def describe(self) -> str:
        kind = "dense" if self.dense else "sparse"
        text = (f"estimated {self.unknowns:,} unknowns in the {kind} formulation ({self.decisions:,} decisions, "
                f"{self.multipliers:,} multipliers" + ("" if self.dense else f", {self.states:,} states and costates")
                + f"), {self.nodes:,} expression nodes")
        if self.dense:
            text += f", a dense JPhi of {self.unknowns ** 2:.1e} entries ({8 * self.unknowns ** 2 / 2**30:.1f} GiB)"
        return text

    def problems(self) -> tuple[list[str], list[str]]:
        """(reasons to refuse, reasons to warn), each a message with the estimate and the limit."""
        refuse, warn = [], []
        limit, level = (DENSE_LIMIT, DENSE_WARN) if self.dense else (SPARSE_LIMIT, SPARSE_WARN)
        hint = (" (the sparse formulation, linear in the horizon, takes more: solver.kind 'ssn', formulation auto)"
                if self.dense and self.states else "")
        if self.unknowns > limit:
            refuse.append(f"the game is too large: {self.describe()}; the limit is {limit:,} unknowns{hint}")
        elif self.unknowns > level:
            warn.append(f"a large game: {self.describe()}; building it takes a while (more than {level:,} "
                        "unknowns)")
        if self.nodes > NODES_LIMIT:
            refuse.append(f"the game is too large: {self.describe()}; the limit is {NODES_LIMIT:,} expression nodes")
        elif self.nodes > NODES_WARN and not warn:
            warn.append(f"a large game: {self.describe()}; building it takes a while (more than {NODES_WARN:,} "
                        "expression nodes)")
        return refuse, warn

    def certificate_warning(self) -> str | None:
        """A warning for a solve whose certificate builds large agent problems (it runs, and can be stopped)."""
        if not self.responses or max(self.responses) <= RESPONSE_WARN:
            return None
        work = sum(u * u for u in self.responses)
        return (f"a large certificate: run.certificate builds each agent's own problem, condensed and dense, the "
                f"largest with {max(self.responses):,} unknowns: about {RESPONSE_S * work:,.0f} s and "
                f"{RESPONSE_BYTES * work / 1e9:.1f} GB for the {len(self.responses)} agents (more than "
                f"{RESPONSE_WARN:,} unknowns); run.certificate: false checks the KKT residual alone")

    def loop_warning(self) -> str | None:
        """A warning for a simulate whose loops take very many solver steps (they run, stream and can be stopped)."""
        if self.loop_steps >= LOOP_STEPS_WARN:
            return (f"a long closed loop: up to {self.loop_steps:,} solver steps (run.steps times K, over the K "
                    f"values); it streams to the log and Ctrl-C or SIGTERM ends it cleanly")
        return None


def _nodes(node: Node) -> int:
    count, stack = 0, [node]
    while stack:
        n = stack.pop()
        count += 1
        if isinstance(n, Binary):
            stack += (n.left, n.right)
        elif isinstance(n, Unary):
            stack.append(n.operand)
        elif isinstance(n, Call):
            stack.extend(n.args)
        elif isinstance(n, Index):
            stack.extend(n.indices)
    return count


def _expression_nodes(text: str, constraint: bool) -> int:
    try:
        parsed = parse_constraint(text) if constraint else parse_expression(text)
    except ExpressionError:
        return len(text)  # reported elsewhere; its length bounds its size
    if isinstance(parsed, Expression):
        return _nodes(parsed.tree)
    return _nodes(parsed.lhs) + _nodes(parsed.rhs) + 1


def _bounds(variables: dict) -> int:
    return sum((v.lower is not None and math.isfinite(v.lower)) + (v.upper is not None and math.isfinite(v.upper))
               for v in variables.values())


def estimate(cfg: Config) -> Size:
    """The size of ``cfg``'s game (see the module docstring); no derivative is built."""
    g = cfg.game
    dense = bool(sparse_obstacles(cfg)) or cfg.solver.formulation == "condensed"
    if g.kind == "static":
        decisions = sum(len(a.variables) for a in g.agents)
        multipliers = sum(_bounds(a.variables) + len(a.constraints) for a in g.agents)
        nodes = sum(_expression_nodes(a.cost, False) + sum(_expression_nodes(constraint_text(c), True)
                                                           for c in a.constraints) for a in g.agents)
        for c in g.shared_constraints:
            carriers = len(constraint_agents(c) or g.agents) if g.equilibrium == "generalized" else 1
            multipliers += carriers
            nodes += _expression_nodes(constraint_text(c), True)
        responses = tuple(len(a.variables) + _bounds(a.variables) + len(a.constraints)
                          + sum(1 for c in g.shared_constraints if a.name in (constraint_agents(c) or [a.name]))
                          for a in g.agents)
        return Size(decisions, multipliers, 0, nodes, True, 0, responses)
    stages = g.horizon + 1
    auto_condensed = cfg.solver.formulation == "auto"  # decided below, once the size is known

    def at(c) -> int:
        chosen = constraint_stages(c)
        return stages if chosen is None else len(chosen)

    decisions = sum(len(a.inputs) for a in g.agents) * stages
    multipliers = sum(_bounds(a.inputs) * stages + sum(at(c) for c in a.constraints) for a in g.agents)
    nodes = sum((_expression_nodes(a.stage_cost, False) * stages + _expression_nodes(a.terminal_cost, False)
                 + sum(_expression_nodes(constraint_text(c), True) * at(c) for c in a.constraints))
                for a in g.agents)
    for c in g.shared_constraints:
        carriers = len(constraint_agents(c) or g.agents) if g.equilibrium == "generalized" else 1
        multipliers += carriers * at(c)
        nodes += _expression_nodes(constraint_text(c), True) * at(c)
    dynamics = g.dynamics
    linear = dynamics_kind(dynamics) == "linear"
    if linear:
        nodes += 2 * len(g.states) * (len(g.states) + decisions // stages) * stages
    else:
        equations = dynamics.ode if dynamics_kind(dynamics) == "continuous" else dynamics
        nodes += sum(_expression_nodes(text, False) for text in equations.values()) * stages
    loop_steps = cfg.run.steps * sum(dict.fromkeys(cfg.run.K))
    kkt = decisions + multipliers
    if auto_condensed and (kkt < SPARSE_FROM or (not linear and kkt * stages < SPARSE_WORK)):
        dense = True
    responses = tuple((len(a.inputs) + _bounds(a.inputs)) * stages + sum(at(c) for c in a.constraints)
                      + sum(at(c) for c in g.shared_constraints if a.name in (constraint_agents(c) or [a.name]))
                      for a in g.agents)
    return Size(decisions, multipliers, len(g.states) * stages, nodes, dense, loop_steps, responses)


def from_extent(extent: Any, game: dict, solver: SolverConfig, disturbance: DisturbanceConfig) -> Size | None:
    """A lower bound of the size of a game from the counts of its unexpanded config (:mod:`gnerun.language.extent`),
    so that a game too large to build is refused before it is written out, solved with these options; None where
    the game section is not readable enough to tell (its validation says why)."""
    kind = game.get("kind")
    if kind not in ("static", "dynamic"):
        return None
    static = kind == "static"
    stages = 1 if static else extent.stages
    field = "variables" if static else "inputs"
    decisions = extent.copies[("agents", "*", field, "*")] * stages
    multipliers = (extent.keys[("agents", "*", field, "*", "lower")]
                   + extent.keys[("agents", "*", field, "*", "upper")]) * stages
    for rows in (("agents", "*", "constraints", "*"), ("shared_constraints", "*")):
        staged = extent.staged[rows]
        multipliers += (extent.copies[rows] - staged) * stages + staged
    nodes = 0
    for path, n in extent.expression_nodes.items():
        once = path[-1] in ("staged", "cost", "terminal_cost")
        nodes += n * (1 if once else stages)
    states = 0 if static else extent.copies[("states", "*")] * stages
    dense = bool(obstacles(static, solver, disturbance)) or solver.formulation == "condensed"
    dynamics = game.get("dynamics")
    linear = isinstance(dynamics, dict) and "A" in dynamics
    kkt = decisions + multipliers
    if solver.formulation == "auto" and (kkt < SPARSE_FROM or (not linear and kkt * stages < SPARSE_WORK)):
        dense = True
    return Size(decisions, multipliers, states, nodes, dense, 0)
