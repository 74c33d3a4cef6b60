"""The field's trajectory-game benchmarks as gnerun configs: ALGAMES's 3-car ramp merge and 3-player T-intersection
(two cars and a pedestrian) from random initial states drawn as ALGAMES's Monte Carlo analysis draws them, the
two-player demo game of MCPTrajectoryGameSolver.jl, and a two-car overtaking game in ALGAMES's style (defined here,
below). Every config is built here in Python from the published definitions; nothing is copied from the sources'
code.

Sources
-------
ALGAMES: S. Le Cleac'h, M. Schwager, Z. Manchester, "ALGAMES: A Fast Solver for Constrained Dynamic Games", RSS 2020
(arXiv 1910.09713); journal version "ALGAMES: A Fast Augmented Lagrangian Solver for Constrained Dynamic Games",
Autonomous Robots 2022 (arXiv 2104.08452). The paper's experiments are in the ``rss_2020`` branch of
RoboticExplorationLab/Algames.jl (formerly ALGAMES.jl), read at commit 846a7a5 ("fixing rss2020 experiments"):

- merge: ``experiments/rss_2020/fig_5_monte_carlo/monte_carlo_sampling.jl`` (the Monte Carlo analysis, Fig. 5);
- intersection: ``experiments/rss_2020/fig_4_solve_time_benchmark/t_intersection/3_player_intersection.jl``;
- ``src/scenarios/examples/merging.jl`` and ``t_intersection.jl`` (road boundaries), ``src/utils/constraints.jl``
  (collision and boundary constraints), ``src/sampler/monte_carlo_methods.jl`` (the random draws),
  ``src/solvers/game_problem.jl`` (RK3 by default), ``src/solvers/cost_helpers.jl`` (stage costs times dt),
  ``src/solvers/direct/newton_gradient.jl`` (one multiplier per constraint, common to all players);
- TrajectoryOptimization.jl v1.3 (the version ALGAMES pins): ``src/integration.jl`` (RK3), ``src/objective.jl``
  (``LQRObjective``), ``src/cost.jl`` (stage cost times dt, terminal cost not).

MCPTrajectoryGameSolver.jl (JuliaGameTheoreticPlanning): ``test/Demo.jl`` (``simple_game``,
``demo_model_predictive_game_play``), ``src/solver_setup.jl`` (how the game becomes an MCP);
TrajectoryGamesExamples.jl ``src/dynamics.jl`` (``planar_double_integrator``); TrajectoryGamesBase.jl
``src/environment.jl`` (``PolygonEnvironment``) and ``src/linear_dynamics.jl`` (no default bounds).

ALGAMES's games
---------------
Three players with "inertial unicycle" dynamics, state (px, py, th, v), input (w, a): d/dt (px, py, th, v) =
(v cos th, v sin th, w, a), discretised by TrajectoryOptimization's RK3 with the input held over the step,
k1 = dt f(x), k2 = dt f(x + k1/2), k3 = dt f(x - k1 + 2 k2), x+ = x + (k1 + 4 k2 + k3)/6, written out per state
(th+ = th + dt w and v+ = v + dt a exactly; the positions depend on the input of their own step, so no position
constraint is independent of the decisions). N knots over tf = 3 s (merge N = 21, dt = 0.15; intersection N = 41,
dt = 0.075): N - 1 inputs per player, gnerun horizon T = N - 2. No input bounds in either script.

Costs (``LQRObjective``, stage costs times dt): J_i = sum_{k=1..N-1} dt [1/2 (x_k - xf)' Q_i (x_k - xf) +
1/2 u_i,k' R u_i,k] + 1/2 (x_N - xf)' Qf_i (x_N - xf), Q_i = 0.1 diag(q) and Qf_i = diag(q) on player i's own
(px, py, th, v), R = 0.1 I. ALGAMES charges the state *before* input k (x_1 = x0 included, x_N only in Qf); gnerun
charges the state each input produces (x_2..x_N). Written exactly: the stage cost carries the input term and the
state term of x_2..x_N, and the terminal cost is 1/2 (x_N - xf)' (Qf_i - dt Q_i) (x_N - xf) plus the constant
dt/2 (x0 - xf)' Q_i (x0 - xf); gnerun's J_i then equals ALGAMES's J_i at the problem's x0 (the constant is stale
for any other state, which changes no equilibrium).

Constraints: pairwise collision avoidance (px_i - px_j)^2 + (py_i - py_j)^2 >= (2 * 0.08)^2 (ALGAMES's squared form)
on every pair and knot, shared; road boundaries per player. ALGAMES writes a boundary as a segment whose constraint
is active only where the position projects onto the segment (value 0 elsewhere, a discontinuous function). Here
each boundary is written as a continuous expression with the same feasible set in the region the players can reach:

- merge (road length 6.2, width 0.34, ramp length 3.2 at pi/12): the top edge py <= 0.09 (= 0.34/2 - 0.08), and the
  bottom edge made of the ramp edge (a line at pi/12 in normal form) and the main road's edge py >= -0.09 from
  x = 0.1 on, as py - tan(pi/12) min(px - 0.1, 0) >= -0.09 (vertical distance; ALGAMES's ramp row is the normal
  distance, cos(pi/12) times this, which only rescales its multiplier). The segments' far ends (x = -3.1, 3.1)
  are out of reach and left out.
- intersection (top road 4.0, width 0.6, bottom road 1.0, crosswalk 0.25, corner radius 0.05; lanes 1, 2, 5):
  the cars' lane edges along the top road (py <= -0.08 for car 1, py <= 0.22 for car 2; segment ends x = +-2 out
  of reach); each of the cars' two rounded corners where the bottom road meets the top road (two segments and a
  circle of radius 0.05 in ALGAMES) as one expression max(alpha - r, beta - r, min(alpha, beta, (alpha^2 + beta^2 -
  r^2)/(2r))) >= 0, alpha and beta the coordinates from the circle's centre along the two segments' outward
  normals (same feasible set; a nonzero gradient wherever it is violated); the pedestrian's crosswalk walls
  0.38 <= px3 <= 0.47, active only while -0.3 < py3 < 0.3, as max(px3 - 0.38, py3 - 0.3, -py3 - 0.3) >= 0 and
  max(0.47 - px3, py3 - 0.3, -py3 - 0.3) >= 0 (the pedestrian starts at the segments' end and its goal is past
  the other end, so here the segment semantics matter and are kept exactly).

Constraint knots: merge ``con_inds = 1:N`` (knot 1 is x0, no decision: ALGAMES checks it when drawing x0, see
below, so only knots 2..N remain, gnerun's stages tau = 0..T); intersection ``con_inds = 2:N`` (exactly gnerun's
stages). Equilibrium: ALGAMES gives every constraint one multiplier common to all players
(``newton_gradient.jl``: ``con.lambda[k]`` in every player's gradient), i.e. the variational (normalized) GNE:
``equilibrium: variational``, collisions as ``shared_constraints`` (the road edges, which involve one player only,
are that player's own constraints, equivalent under a common multiplier).

Random initial states (``monte_carlo_methods.jl``): x0 = x0_nominal + (U(0, 1)^12 - 1/2) .* noise, noise = (0.06,
0.06, 2 pi/72, 0.05) per player, i.e. uniform within +-(0.03, 0.03, 2.5 deg, 0.025) of the nominal state; a draw is
rejected, and drawn again, when a constraint is violated at the first constrained knot of the zero-input rollout
(knot 1 = x0 for the merge, knot 2 for the intersection). ALGAMES seeds Julia's generator (``Random.seed!(100)``);
the draws here use numpy's ``default_rng(seed)``: the same distribution, not the same numbers. ALGAMES published a
Monte Carlo analysis of the merge only; the intersection's draws apply the same rule to its nominal state.

MCPTrajectoryGameSolver.jl's demo
---------------------------------
``simple_game``: two planar double integrators (x = (px, py, vx, vy), u = (ax, ay), dt = 0.1, m = 1, exact
zero-order hold: p+ = p + dt v + dt^2/2 u, v+ = v + dt u; no state or input bounds), stage cost
|p_i - g_i|^2 + 0.05 |u_i|^2 summed over the planning horizon, goals g1 = (1, -0.1), g2 = (-1, 0.1), start
(-1, 0, 0, 0) and (1, 0, 0, 0) (``demo_model_predictive_game_play``: its first solve), collision avoidance
|p1 - p2|^2 - 1 >= 0 (radius 1) as a coupling constraint with one multiplier scaled by a per-player premultiplier,
1 by default (variational), and the default ``PolygonEnvironment()``: a square of circumradius 4, |px|, |py| <=
2 sqrt 2, per player. The MCP (``solver_setup.jl``) has planning horizon H = 10 states X_1..X_10 with X_1 = x0 and
inputs U_1..U_10; dynamics X_t = f(X_{t-1}, U_{t-1}); costs on every (X_t, U_t); environment and coupling
constraints on X_2..X_10. U_10 moves no state, so it is 0 at every solution and is dropped: gnerun horizon T = 8
(inputs U_1..U_9, states X_2..X_10), terminal cost the constant |p_i(x0) - g_i|^2 (the X_1 term). Cold start: the
demo's initial guess is the zero-input rollout, as here.

Two-car overtaking
------------------
A scenario of this suite, not a published one, built from ALGAMES's ingredients: two inertial unicycles (state
(px, py, th, v), input (w, a), the same ODE as above) integrated by the classical RK4 step (``integrator: rk4``, the
input held over dt = 0.2), T = 12 (13 stages x 2 inputs x 2 cars = 52 decisions), on a straight two-lane road of
ALGAMES's merge width 0.34 (lanes of 0.17, centres py = -0.085 and 0.085). The faster car 1 (speed and desired speed
1.0) starts 0.4 behind the slower car 2 (0.5) in the right lane; both want to stay in it. Costs in ALGAMES's
quadratic form, charged on the state each input produces: dt (1 (py - (-0.085))^2 + 0.1 th^2 + 1 (v - v_i)^2 +
0.1 (w^2 + a^2)) per stage, and 10 dt ((py + 0.085)^2 + th^2 + (v - v_i)^2) on the last state. Each car's own
constraints are the road's edges for a car of radius 0.08, |py| <= 0.09; the collision distance (px1 - px2)^2 +
(py1 - py2)^2 >= 0.16^2 is shared with one multiplier (variational, as ALGAMES poses it). At zero inputs the cars
are in each other's way from stage 1 on (car 1 closes 0.5 per second on a gap of 0.4 - 0.16) and exactly aligned,
so the collision row's gradient has no sideways part: the start is infeasible and degenerate, and the faster car
has to leave its lane to pass. ALGAMES-class solvers are expected to solve such a scenario from zero inputs; the
starts (:data:`OVERTAKING_STARTS`) are zero inputs, car 1 pulling out, car 1 braking and seeded small inputs.

Independent check
-----------------
:class:`GameModel` re-implements each game in numpy (its own RK3, RK4 and double-integrator steps, the costs in the
sources' indexing, the constraints as numpy functions) and computes each player's best response with the others
fixed by scipy's SLSQP (gradients by central differences) from three starts: the player's current inputs, zero
inputs and a seeded perturbation of the current inputs. The gap J_i(a) - min is a local check: on these nonconvex
games a positive gap from another start can also mean that a different local equilibrium exists.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize

from benchmarks.problems import Problem

__all__ = [
    "GameModel",
    "intersection_initial_states",
    "intersection_model",
    "intersection_problems",
    "mcp_demo_model",
    "mcp_demo_problem",
    "merge_initial_states",
    "merge_model",
    "merge_problems",
    "overtaking_model",
    "overtaking_problems",
    "planar_double_integrator_step",
    "unicycle_rk3_step",
    "unicycle_rk4_step",
]

FEAS_TOL = 1e-6  # a point violating a player's constraints by more than this has an infinite best-response gap
FD_STEP = 1e-6  # central differences for SLSQP's gradients
NOISE_PER_PLAYER = (0.06, 0.06, 2 * math.pi / 72, 0.05)  # ALGAMES's Monte Carlo noise amplitudes, per player

ALGAMES_REPO = "RoboticExplorationLab/Algames.jl, branch rss_2020 (commit 846a7a5)"
MERGE_SCRIPT = "experiments/rss_2020/fig_5_monte_carlo/monte_carlo_sampling.jl"
INTERSECTION_SCRIPT = "experiments/rss_2020/fig_4_solve_time_benchmark/t_intersection/3_player_intersection.jl"
MCP_REPO = "JuliaGameTheoreticPlanning/MCPTrajectoryGameSolver.jl"

# ALGAMES's Monte Carlo analysis of the 3-car merge (1000 draws), as the histogram data of the paper's figure that
# the repository ships (plots/tikz/monte_carlo_paper_1000_direct/*_1000.tikz and .../monte_carlo_paper_1000_ilqgames/,
# committed 2020-02-29 in f0173ae, bins of 0.3 s, 0.3 decades and 8 iterations). The paper's text was not available
# to check the sentence these numbers are quoted in.
MERGE_PUBLISHED: dict[str, str] = {
    "ALGAMES solve time, 1000 random merges": (
        "960 of 1000 in [0, 0.3) s, 22 in [0.3, 0.6) s, 17 in [0.6, 3.6) s (999 counted in the histogram's "
        "range [0, 6] s)"
    ),
    "ALGAMES constraint violation": "995 counted in [1e-6, 1); 992 of them below 1e-3, 3 in [1e-2.1, 1e-0.9)",
    "ALGAMES iterations (Newton steps)": "320 in [0, 8), 627 in [8, 16), 48 in [16, 64) (995 counted)",
    "iLQGames solve time, same draws": "459 of 1000 in [0, 0.3) s, 498 in [0.3, 0.6) s, 43 in [0.6, 2.1) s",
    "source": (
        "ALGAMES (Le Cleac'h, Schwager, Manchester, RSS 2020, arXiv 1910.09713), Monte Carlo analysis; figure data "
        "in RoboticExplorationLab/Algames.jl plots/tikz/monte_carlo_paper_1000_direct/{solve_time,cmax,"
        "iterations}_1000.tikz and plots/tikz/monte_carlo_paper_1000_ilqgames/solve_time_1000.tikz"
    ),
}


# ------------------------------------------------------------------------------------------------
# numbers and expressions as config text
# ------------------------------------------------------------------------------------------------


def _num(v: float) -> str:
    """A number as expression text (15 significant digits, no sign for zero)."""
    v = float(v)
    if v == 0.0:
        return "0"
    return format(v, ".15g")


def _minus(name: str, value: float) -> str:
    """``name - value`` without a double sign (``name`` alone for 0)."""
    if value == 0.0:
        return name
    if value < 0.0:
        return f"({name} + {_num(-value)})"
    return f"({name} - {_num(value)})"


def _affine(terms: Sequence[tuple[float, str]], const: float) -> str:
    """sum c * name + const as expression text (zero coefficients dropped)."""
    parts: list[str] = []
    for c, name in terms:
        if c == 0.0:
            continue
        mag = "" if abs(c) == 1.0 else f"{_num(abs(c))}*"
        sign = "-" if c < 0 else "+"
        parts.append(f"{sign} {mag}{name}")
    if const != 0.0 or not parts:
        parts.append(f"{'-' if const < 0 else '+'} {_num(abs(const))}")
    text = " ".join(parts)
    return text[2:] if text.startswith("+ ") else "-" + text[2:]


def _weighted_squares(weights: Sequence[float], names: Sequence[str], targets: Sequence[float]) -> str:
    """sum w * (name - target)^2 over the nonzero weights."""
    terms = [f"{_num(w)}*{_minus(n, t)}**2" for w, n, t in zip(weights, names, targets, strict=True) if w != 0.0]
    return " + ".join(terms) if terms else "0"


# ------------------------------------------------------------------------------------------------
# dynamics (numpy, independent of the config text)
# ------------------------------------------------------------------------------------------------


def _unicycle_field(x: np.ndarray, u: np.ndarray) -> np.ndarray:
    """d/dt (px, py, th, v) = (v cos th, v sin th, w, a) for every player (states and inputs player-major)."""
    th, v = x[..., 2::4], x[..., 3::4]
    out = np.empty(np.broadcast_shapes(x.shape, u.shape[:-1] + x.shape[-1:]))
    out[..., 0::4] = v * np.cos(th)
    out[..., 1::4] = v * np.sin(th)
    out[..., 2::4] = u[..., 0::2]
    out[..., 3::4] = u[..., 1::2]
    return out


def unicycle_rk3_step(x: np.ndarray, u: np.ndarray, dt: float) -> np.ndarray:
    """One step of TrajectoryOptimization.jl v1.3's RK3 (src/integration.jl) on the inertial unicycles, the input
    held over the step. ``x`` (..., 4p) as (px, py, th, v) per player, ``u`` (..., 2p) as (w, a) per player."""
    x = np.asarray(x, dtype=float)
    u = np.asarray(u, dtype=float)
    k1 = dt * _unicycle_field(x, u)
    k2 = dt * _unicycle_field(x + k1 / 2, u)
    k3 = dt * _unicycle_field(x - k1 + 2 * k2, u)
    return x + (k1 + 4 * k2 + k3) / 6


def unicycle_rk4_step(x: np.ndarray, u: np.ndarray, dt: float) -> np.ndarray:
    """One classical fourth-order Runge-Kutta step of the inertial unicycles, the input held over the step;
    layouts as in :func:`unicycle_rk3_step`."""
    x = np.asarray(x, dtype=float)
    u = np.asarray(u, dtype=float)
    k1 = _unicycle_field(x, u)
    k2 = _unicycle_field(x + dt / 2 * k1, u)
    k3 = _unicycle_field(x + dt / 2 * k2, u)
    k4 = _unicycle_field(x + dt * k3, u)
    return x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def planar_double_integrator_step(x: np.ndarray, u: np.ndarray, dt: float = 0.1, m: float = 1.0) -> np.ndarray:
    """TrajectoryGamesExamples.jl's ``planar_double_integrator`` (exact zero-order hold) for every player:
    ``x`` (..., 4p) as (px, py, vx, vy), ``u`` (..., 2p) as (ax, ay)."""
    x = np.asarray(x, dtype=float)
    u = np.asarray(u, dtype=float) / m
    out = np.array(np.broadcast_to(x, np.broadcast_shapes(x.shape, u.shape[:-1] + x.shape[-1:])))
    out[..., 0::4] += dt * x[..., 2::4] + 0.5 * dt * dt * u[..., 0::2]
    out[..., 1::4] += dt * x[..., 3::4] + 0.5 * dt * dt * u[..., 1::2]
    out[..., 2::4] += dt * u[..., 0::2]
    out[..., 3::4] += dt * u[..., 1::2]
    return out


def _unicycle_rk3_expressions(i: int, dt: float) -> dict[str, str]:
    """The RK3 step of player i written out as gnerun expressions (k2 at th + dt w/2, v + dt a/2; k3 at
    th + dt w, v + dt a)."""
    h = dt / 2
    px, py, th, v, w, a = (f"{s}{i}" for s in ("px", "py", "th", "v", "w", "a"))
    mid_v, mid_th = f"({v} + {_num(h)}*{a})", f"({th} + {_num(h)}*{w})"
    end_v, end_th = f"({v} + {_num(dt)}*{a})", f"({th} + {_num(dt)}*{w})"

    def position(trig: str) -> str:
        return (f"{_num(dt / 6)}*({v}*{trig}({th}) + 4*{mid_v}*{trig}{mid_th} + {end_v}*{trig}{end_th})")

    return {
        px: f"{px} + {position('cos')}",
        py: f"{py} + {position('sin')}",
        th: f"{th} + {_num(dt)}*{w}",
        v: f"{v} + {_num(dt)}*{a}",
    }


# ------------------------------------------------------------------------------------------------
# constraints: one object renders the config text and evaluates the same set in numpy
# ------------------------------------------------------------------------------------------------


def _pos(X: np.ndarray, p: int) -> tuple[np.ndarray, np.ndarray]:
    """Positions of player p (0-based) in states laid out (px, py, *, *) per player."""
    return X[..., 4 * p], X[..., 4 * p + 1]


@dataclass(frozen=True)
class _Bound:
    """px or py of one player below (``upper``) or above a value: a road edge whose segment ends are out of reach."""

    player: int  # 0-based
    axis: str  # "x" | "y"
    upper: bool
    value: float

    def expr(self) -> str:
        return f"p{self.axis}{self.player + 1} {'<=' if self.upper else '>='} {_num(self.value)}"

    def values(self, X: np.ndarray) -> np.ndarray:
        px, py = _pos(X, self.player)
        c = px if self.axis == "x" else py
        return self.value - c if self.upper else c - self.value

    def involves(self, player: int) -> bool:
        return player == self.player


@dataclass(frozen=True)
class _RampEdge:
    """The merge's bottom edge: py >= y_edge + tan(angle) min(px - x_merge, 0) (ramp edge, then the main road's)."""

    player: int
    x_merge: float
    slope: float  # tan of the ramp angle
    y_edge: float

    def expr(self) -> str:
        i = self.player + 1
        shifted = _affine([(1.0, f"px{i}")], -self.x_merge)
        return f"py{i} - {_num(self.slope)}*min({shifted}, 0) >= {_num(self.y_edge)}"

    def values(self, X: np.ndarray) -> np.ndarray:
        px, py = _pos(X, self.player)
        return py - self.slope * np.minimum(px - self.x_merge, 0.0) - self.y_edge

    def involves(self, player: int) -> bool:
        return player == self.player


@dataclass(frozen=True)
class _RoundedCorner:
    """Outside a road block whose corner is rounded: ALGAMES's ``add_rounded_boundary_constraints(p1, p2, p3, r)``,
    i.e. segment p1 -> p2 + r xh, segment p2 + r yh -> p3 and a circle of radius r at c = p2 + r (xh + yh), xh and yh
    the unit vectors from the corner p2 towards p1 and p3. With alpha = -(p - c).xh and beta = -(p - c).yh its
    feasible set is {beta >= r or alpha >= 0} and {alpha >= r or beta >= 0} and {alpha^2 + beta^2 >= r^2} (the far
    ends p1, p3 out of reach), written as max(alpha - r, beta - r, min(alpha, beta, (alpha^2 + beta^2 - r^2)/(2r)))
    >= 0: continuous, the segments' distance on the straight parts and the distance to the circle (to first order)
    on the arc, and a nonzero gradient wherever it is violated."""

    player: int
    center: tuple[float, float]
    xh: tuple[float, float]
    yh: tuple[float, float]
    r: float

    @staticmethod
    def from_landmarks(player: int, p1: Sequence[float], p2: Sequence[float], p3: Sequence[float],
                       r: float) -> _RoundedCorner:
        p1a, p2a, p3a = (np.asarray(p, dtype=float) for p in (p1, p2, p3))
        xh = (p1a - p2a) / np.linalg.norm(p1a - p2a)
        yh = (p3a - p2a) / np.linalg.norm(p3a - p2a)
        c = p2a + r * (xh + yh)
        return _RoundedCorner(player, (float(c[0]), float(c[1])), (float(xh[0]), float(xh[1])),
                              (float(yh[0]), float(yh[1])), float(r))

    def _side(self, d: tuple[float, float], shift: float = 0.0) -> str:
        """-(p - c).d - shift as expression text."""
        i = self.player + 1
        const = d[0] * self.center[0] + d[1] * self.center[1] - shift
        return _affine([(-d[0], f"px{i}"), (-d[1], f"py{i}")], const)

    def expr(self) -> str:
        r = self.r
        alpha, beta = self._side(self.xh), self._side(self.yh)
        arc = f"{_num(1 / (2 * r))}*(({alpha})**2 + ({beta})**2 - {_num(r * r)})"
        return (f"max({self._side(self.xh, r)}, {self._side(self.yh, r)}, min({alpha}, {beta}, {arc})) >= 0")

    def values(self, X: np.ndarray) -> np.ndarray:
        px, py = _pos(X, self.player)
        dx, dy = px - self.center[0], py - self.center[1]
        alpha = -(dx * self.xh[0] + dy * self.xh[1])
        beta = -(dx * self.yh[0] + dy * self.yh[1])
        r = self.r
        arc = (alpha ** 2 + beta ** 2 - r ** 2) / (2 * r)
        return np.maximum(np.maximum(alpha - r, beta - r), np.minimum(np.minimum(alpha, beta), arc))

    def involves(self, player: int) -> bool:
        return player == self.player


@dataclass(frozen=True)
class _Wall:
    """ALGAMES's ``BoundaryConstraint(b1, b2, v)`` with its segment semantics: (p - b1).v <= 0 wherever p projects
    inside the segment b1 -> b2, as max(-(p - b1).v, -s, s - L) >= 0 (s the projection, L the length)."""

    player: int
    b1: tuple[float, float]
    b2: tuple[float, float]
    v: tuple[float, float]

    def _parts(self) -> tuple[tuple[float, float, float], ...]:
        """(cx, cy, c0) of -(p - b1).v, -s and s - L, each cx px + cy py + c0."""
        b1, b2, v = (np.asarray(q, dtype=float) for q in (self.b1, self.b2, self.v))
        L = float(np.linalg.norm(b2 - b1))
        t = (b2 - b1) / L
        return (
            (float(-v[0]), float(-v[1]), float(v @ b1)),
            (float(-t[0]), float(-t[1]), float(t @ b1)),
            (float(t[0]), float(t[1]), float(-(t @ b1) - L)),
        )

    def expr(self) -> str:
        i = self.player + 1
        parts = [_affine([(cx, f"px{i}"), (cy, f"py{i}")], c0) for cx, cy, c0 in self._parts()]
        return f"max({', '.join(parts)}) >= 0"

    def values(self, X: np.ndarray) -> np.ndarray:
        px, py = _pos(X, self.player)
        return np.max([cx * px + cy * py + c0 for cx, cy, c0 in self._parts()], axis=0)

    def involves(self, player: int) -> bool:
        return player == self.player


@dataclass(frozen=True)
class _Collision:
    """(px_i - px_j)^2 + (py_i - py_j)^2 >= distance^2 (ALGAMES's ``CollisionConstraint``, the MCP demo's coupling
    constraint)."""

    i: int
    j: int
    distance: float

    def expr(self) -> str:
        a, b = self.i + 1, self.j + 1
        return f"(px{a} - px{b})**2 + (py{a} - py{b})**2 >= {_num(self.distance ** 2)}"

    def values(self, X: np.ndarray) -> np.ndarray:
        xi, yi = _pos(X, self.i)
        xj, yj = _pos(X, self.j)
        return (xi - xj) ** 2 + (yi - yj) ** 2 - self.distance ** 2

    def involves(self, player: int) -> bool:
        return player in (self.i, self.j)


_Constraint = _Bound | _RampEdge | _RoundedCorner | _Wall | _Collision


def _collisions(players: int, distance: float) -> tuple[_Collision, ...]:
    """Every pair (i < j)."""
    return tuple(_Collision(i, j, distance) for i in range(players) for j in range(i + 1, players))


# ------------------------------------------------------------------------------------------------
# the independent model
# ------------------------------------------------------------------------------------------------


def _central_differences(fun: Callable[[np.ndarray], np.ndarray], v: np.ndarray) -> np.ndarray:
    """Jacobian (m, k) of a batched map (B, k) -> (B, m) by central differences, all perturbations in one batch."""
    k = v.size
    E = FD_STEP * np.eye(k)
    vals = fun(np.concatenate([v + E, v - E]))
    return ((vals[:k] - vals[k:]) / (2 * FD_STEP)).T


@dataclass(frozen=True)
class GameModel:
    """One game re-implemented in numpy: decisions in gnerun's order (agent by agent, time-major within an agent),
    the rollout x(1..T+1) from ``x0``, the costs in the source's own indexing and the constraints per player."""

    agents: tuple[str, ...]
    horizon: int  # gnerun's T: inputs at stages 0..T
    x0: np.ndarray
    step: Callable[[np.ndarray, np.ndarray], np.ndarray]  # (..., nx), (..., N*nu) -> (..., nx)
    cost_fn: Callable[[np.ndarray, np.ndarray], np.ndarray]  # X (..., T+2, nx), U (..., T+1, N*nu) -> (..., N)
    own: tuple[tuple[_Constraint, ...], ...]  # per player, at every stage (on x(tau + 1))
    shared: tuple[_Constraint, ...]
    inputs_per_agent: int = 2
    starts_seed: int = field(default=0, repr=False)

    @property
    def n(self) -> int:
        """Decision variables (all agents, all stages)."""
        return len(self.agents) * self.inputs_per_agent * (self.horizon + 1)

    def block(self, i: int) -> slice:
        """Agent i's inputs in a."""
        size = self.inputs_per_agent * (self.horizon + 1)
        return slice(i * size, (i + 1) * size)

    def inputs(self, a: np.ndarray) -> np.ndarray:
        """a (..., n) -> U (..., T+1, N*nu), inputs of all players per stage (player-major within a stage)."""
        a = np.asarray(a, dtype=float)
        lead = a.shape[:-1]
        N, H, nu = len(self.agents), self.horizon + 1, self.inputs_per_agent
        U = a.reshape(*lead, N, H, nu)
        return np.moveaxis(U, -3, -2).reshape(*lead, H, N * nu)

    def rollout(self, a: np.ndarray) -> np.ndarray:
        """X (..., T+2, nx): x0, then the state each stage's inputs produce."""
        U = self.inputs(a)
        x = np.broadcast_to(self.x0, U.shape[:-2] + self.x0.shape)
        X = [x]
        for t in range(self.horizon + 1):
            x = self.step(x, U[..., t, :])
            X.append(x)
        return np.stack(X, axis=-2)

    def costs(self, a: np.ndarray) -> np.ndarray:
        """(J_1, ..., J_N) at a (or a batch of a)."""
        return self.cost_fn(self.rollout(a), self.inputs(a))

    def constraint_values(self, a: np.ndarray, player: int | None = None) -> np.ndarray:
        """Values g >= 0 (feasible) on x(1..T+1): with ``player``, that player's own constraints and the shared ones
        that involve it; without, every player's own constraints and all shared ones. Shape (..., rows)."""
        X = self.rollout(a)[..., 1:, :]
        if player is None:
            cons = [c for own in self.own for c in own] + list(self.shared)
        else:
            cons = list(self.own[player]) + [c for c in self.shared if c.involves(player)]
        if not cons:
            return np.zeros(X.shape[:-2] + (0,))
        return np.concatenate([c.values(X) for c in cons], axis=-1)

    def state_admissible(self, x: np.ndarray) -> bool:
        """True when every constraint holds at the state ``x``."""
        X = np.asarray(x, dtype=float)[None, :]
        vals = [c.values(X) for own in self.own for c in own] + [c.values(X) for c in self.shared]
        return bool(min(float(np.min(v)) for v in vals) >= 0.0)

    def best_response_gaps(self, a: np.ndarray) -> dict[str, float]:
        """Per agent, J_i(a) - the lowest J_i(a_i', a_-i) that SLSQP finds over its own and the shared constraints
        from three starts (a_i, zero inputs, a seeded perturbation of a_i); ``inf`` when a_i violates them by more
        than ``FEAS_TOL``. A local check (the agents' problems are nonconvex)."""
        a = np.asarray(a, dtype=float).reshape(-1)
        if a.size != self.n:
            raise ValueError(f"expected {self.n} decisions, got {a.size}")
        rng = np.random.default_rng(self.starts_seed)
        gaps: dict[str, float] = {}
        for i, name in enumerate(self.agents):
            s = self.block(i)

            def joint(v: np.ndarray, s: slice = s) -> np.ndarray:
                full = np.broadcast_to(a, v.shape[:-1] + a.shape).copy()
                full[..., s] = v
                return full

            def cost(v: np.ndarray, i: int = i, joint=joint) -> np.ndarray:
                return self.costs(joint(v))[..., i]

            def cons(v: np.ndarray, i: int = i, joint=joint) -> np.ndarray:
                return self.constraint_values(joint(v), i)

            ai = a[s]
            J0 = float(cost(ai))
            if float(np.min(cons(ai), initial=0.0)) < -FEAS_TOL:
                gaps[name] = math.inf
                continue
            best = J0
            starts = [ai, np.zeros_like(ai), ai + 0.1 * rng.standard_normal(ai.size)]
            for v0 in starts:
                res = minimize(
                    lambda v, cost=cost: float(cost(v)),
                    v0,
                    jac=lambda v, cost=cost: _central_differences(lambda b: cost(b)[:, None], v)[0],
                    constraints=[{
                        "type": "ineq",
                        "fun": cons,
                        "jac": lambda v, cons=cons: _central_differences(cons, v),
                    }],
                    method="SLSQP",
                    options={"maxiter": 500, "ftol": 1e-12},
                )
                v = np.asarray(res.x, dtype=float)
                if np.all(np.isfinite(v)) and float(np.min(cons(v), initial=0.0)) >= -FEAS_TOL:
                    best = min(best, float(cost(v)))
            gaps[name] = J0 - best
        return gaps


# ------------------------------------------------------------------------------------------------
# ALGAMES: scenarios
# ------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _AlgamesScenario:
    """One ALGAMES scenario: knots, costs, goal, constraints and how its random initial states are drawn."""

    key: str  # "merge" | "intersection"
    agents: tuple[str, ...]
    knots: int  # N
    tf: float
    x0: tuple[float, ...]  # nominal initial state, (px, py, th, v) per player
    xf: tuple[float, ...]
    q: tuple[float, float, float, float]  # diag of Q_i / 0.1 on the player's own (px, py, th, v); Qf_i = diag(q)
    q_scale: float  # Q_i = q_scale diag(q)
    r: float  # R = r I
    own: tuple[tuple[_Constraint, ...], ...]
    shared: tuple[_Constraint, ...]
    checked_knot: int  # knot (1-based) at which ALGAMES's sampler checks a draw: the first of con_inds

    @property
    def dt(self) -> float:
        return self.tf / (self.knots - 1)

    @property
    def horizon(self) -> int:
        """gnerun's T: N - 1 inputs per player at stages 0..N-2."""
        return self.knots - 2

    def Q(self, i: int) -> np.ndarray:
        """Diagonal of Q_i on player i's own states."""
        return self.q_scale * np.asarray(self.q)

    def Qf(self, i: int) -> np.ndarray:
        return np.asarray(self.q, dtype=float)

    def costs(self, X: np.ndarray, U: np.ndarray) -> np.ndarray:
        """ALGAMES's objectives in its own indexing: X (..., N, nx) knots 1..N (knot 1 = x0), U (..., N-1, 2p)."""
        xf = np.asarray(self.xf)
        out = []
        for i in range(len(self.agents)):
            d = X[..., 4 * i:4 * i + 4] - xf[4 * i:4 * i + 4]
            ui = U[..., 2 * i:2 * i + 2]
            stage = 0.5 * (d[..., :-1, :] ** 2 @ self.Q(i)) + 0.5 * self.r * np.sum(ui ** 2, axis=-1)
            out.append(self.dt * np.sum(stage, axis=-1) + 0.5 * (d[..., -1, :] ** 2 @ self.Qf(i)))
        return np.stack(out, axis=-1)

    def model(self, x0: np.ndarray) -> GameModel:
        dt = self.dt
        return GameModel(
            agents=self.agents,
            horizon=self.horizon,
            x0=np.asarray(x0, dtype=float),
            step=lambda x, u: unicycle_rk3_step(x, u, dt),
            cost_fn=self.costs,
            own=self.own,
            shared=self.shared,
        )

    def admissible(self, x0: np.ndarray) -> bool:
        """ALGAMES's acceptance test of a draw: no constraint violated at the first constrained knot of the
        zero-input rollout (``monte_carlo_sampling``: rollout, then every constraint's value at ``con_inds[1]``)."""
        x = np.asarray(x0, dtype=float)
        for _ in range(self.checked_knot - 1):
            x = unicycle_rk3_step(x, np.zeros(2 * len(self.agents)), self.dt)
        return self.model(x0).state_admissible(x)

    def draws(self, count: int, seed: int) -> list[np.ndarray]:
        """``count`` admissible initial states: x0 + (U(0,1) - 1/2) * noise, rejected draws drawn again."""
        if count < 0:
            raise ValueError("count must be >= 0")
        rng = np.random.default_rng(seed)
        nominal = np.asarray(self.x0, dtype=float)
        noise = np.tile(NOISE_PER_PLAYER, len(self.agents))
        states: list[np.ndarray] = []
        while len(states) < count:
            x0 = nominal + (rng.random(nominal.size) - 0.5) * noise
            if self.admissible(x0):
                states.append(x0)
        return states

    def config_yaml(self, x0: np.ndarray, name: str, header: Sequence[str]) -> str:
        """The gnerun config at the initial state ``x0``."""
        dt = self.dt
        p = len(self.agents)
        states = [f"{s}{i + 1}" for i in range(p) for s in ("px", "py", "th", "v")]
        dynamics: dict[str, str] = {}
        for i in range(p):
            dynamics.update(_unicycle_rk3_expressions(i + 1, dt))
        xf = np.asarray(self.xf)
        x0 = np.asarray(x0, dtype=float)
        agents = []
        for i, agent in enumerate(self.agents):
            names = [f"{s}{i + 1}" for s in ("px", "py", "th", "v")]
            target = xf[4 * i:4 * i + 4]
            Q, Qf = self.Q(i), self.Qf(i)
            state_part = _weighted_squares(0.5 * dt * Q, names, target)
            input_part = f"{_num(0.5 * dt * self.r)}*(w{i + 1}**2 + a{i + 1}**2)"
            terminal = _weighted_squares(0.5 * (Qf - dt * Q), names, target)
            const = 0.5 * dt * float(np.sum(Q * (x0[4 * i:4 * i + 4] - target) ** 2))
            agents.append({
                "name": agent,
                "inputs": {f"w{i + 1}": {"start": 0}, f"a{i + 1}": {"start": 0}},
                "stage_cost": f"{state_part} + {input_part}",
                "terminal_cost": f"{terminal} + {_num(const)}",
                "constraints": [c.expr() for c in self.own[i]],
            })
        return _yaml(name, header, self.horizon, states, dynamics, x0, agents, [c.expr() for c in self.shared],
                     "variational")


def _merge_scenario() -> _AlgamesScenario:
    """ALGAMES's 3-car ramp merge of the Monte Carlo analysis (``monte_carlo_sampling.jl``): players 1 and 2 on the
    main road, player 3 on the ramp; ``MergingScenario(6.20, 0.34, 3.2, pi/12)``, radius 0.08, N = 21, tf = 3."""
    road_length, road_width, ramp_length, ramp_angle, radius = 6.20, 0.34, 3.2, math.pi / 12, 0.08
    l0 = road_width / 2 - radius  # the edges the centre of a car of this radius may reach
    x_merge = -road_length / 2 + ramp_length  # where the ramp's edge meets the main road's bottom edge
    own = tuple(
        (_Bound(i, "y", True, l0), _RampEdge(i, x_merge, math.tan(ramp_angle), -l0)) for i in range(3)
    )
    return _AlgamesScenario(
        key="merge",
        agents=("car1", "car2", "car3"),
        knots=21,
        tf=3.0,
        x0=(-0.80, -0.05, 0.00, 0.90, -1.00, -0.05, 0.00, 0.90, -0.90, -0.30, math.pi / 12, 0.95),
        xf=(1.10, -0.05, 0.00, 0.90, 0.70, -0.05, 0.00, 0.90, 0.90, -0.05, 0.00, 0.90),
        q=(0.0, 10.0, 1.0, 1.0),
        q_scale=0.1,
        r=0.1,
        own=own,
        shared=_collisions(3, 2 * radius),
        checked_knot=1,  # con_inds = 1:N
    )


def _intersection_scenario() -> _AlgamesScenario:
    """ALGAMES's 3-player T-intersection (``3_player_intersection.jl``): car 1 in lane 1 (eastbound), car 2 in lane 2
    (westbound), a pedestrian in lane 5 (the crosswalk); ``TIntersectionScenario(4.0, 0.60, 1.0, 0.25, radius 0.05)``,
    radius 0.08 for all three, N = 41, tf = 3."""
    top_length, road_width, bottom_length, cross_width, corner, radius = 4.0, 0.60, 1.0, 0.25, 0.05, 0.08
    # t_intersection_landmarks, for an actor of radius `radius`
    l6 = road_width / 2
    l5 = road_width / 2 + cross_width - radius
    l4 = road_width / 2 + radius
    l3 = road_width / 2 + bottom_length
    l2 = top_length / 2
    l1 = road_width / 2 - radius
    l0 = radius

    def rc(player: int, p1: tuple[float, float], p2: tuple[float, float], p3: tuple[float, float]) -> _RoundedCorner:
        return _RoundedCorner.from_landmarks(player, p1, p2, p3, corner)

    lane1 = (  # below the centre line; the bottom road's corners left and right of its eastbound half
        _Bound(0, "y", True, -l0),
        rc(0, (-l2, -l1), (-l1, -l1), (-l1, -l3)),
        rc(0, (-l0, -l3), (-l0, -l1), (l2, -l1)),
    )
    lane2 = (  # below the top edge; the corners of the westbound half's turn into the bottom road
        _Bound(1, "y", True, l1),
        rc(1, (-l2, l0), (-l1, l0), (-l1, -l3)),
        rc(1, (-l0, -l3), (-l0, l0), (l2, l0)),
    )
    lane5 = (  # the crosswalk's walls, only across the road
        _Wall(2, (l4, l6), (l4, -l6), (-1.0, 0.0)),
        _Wall(2, (l5, l6), (l5, -l6), (1.0, 0.0)),
    )
    return _AlgamesScenario(
        key="intersection",
        agents=("car1", "car2", "pedestrian"),
        knots=41,
        tf=3.0,
        x0=(-0.50, -0.15, 0.00, 0.60, 1.40, 0.15, math.pi, 0.60, 0.43, -0.30, math.pi / 2, 0.10),
        xf=(1.30, -0.15, 0.00, 0.60, -0.30, 0.15, math.pi, 0.60, 0.43, 0.35, math.pi / 2, 0.30),
        q=(0.0, 1.0, 1.0, 1.0),
        q_scale=0.1,
        r=0.1,
        own=(lane1, lane2, lane5),
        shared=_collisions(3, 2 * radius),
        checked_knot=2,  # con_inds = 2:N
    )


MERGE = _merge_scenario()
INTERSECTION = _intersection_scenario()


def _yaml(name: str, header: Sequence[str], T: int, states: Sequence[str], dynamics: dict[str, str],
          x0: np.ndarray, agents: Sequence[dict], shared: Sequence[str], equilibrium: str,
          ode: tuple[str, float] | None = None) -> str:
    """A gnerun dynamic-game config (no ``solver:`` block); strings as JSON, which YAML reads as they are.
    ``dynamics``: x(t+1) per state, or with ``ode`` = (integrator, dt) dx/dt per state."""
    q = json.dumps
    lines = [f"# {h}" for h in header]
    lines += [
        f"name: {name}",
        "game:",
        "  kind: dynamic",
        f"  horizon: {T}",
        f"  states: [{', '.join(states)}]",
        "  dynamics:",
    ]
    if ode is None:
        lines += [f"    {s}: {q(dynamics[s])}" for s in states]
    else:
        lines.append("    ode:")
        lines += [f"      {s}: {q(dynamics[s])}" for s in states]
        lines += [f"    integrator: {ode[0]}", f"    dt: {_num(ode[1])}"]
    lines.append(f"  x0: [{', '.join(repr(float(v)) for v in x0)}]")
    lines.append("  agents:")
    for ag in agents:
        lines.append(f"    - name: {ag['name']}")
        lines.append("      inputs:")
        for u, spec in ag["inputs"].items():
            lines.append(f"        {u}: {{{', '.join(f'{k}: {_value(v)}' for k, v in spec.items())}}}")
        lines.append(f"      stage_cost: {q(ag['stage_cost'])}")
        lines.append(f"      terminal_cost: {q(ag['terminal_cost'])}")
        lines.append("      constraints:")
        lines += [f"        - {q(c)}" for c in ag["constraints"]]
    lines.append("  shared_constraints:")
    lines += [f"    - {q(c)}" for c in shared]
    lines.append(f"  equilibrium: {equilibrium}")
    return "\n".join(lines) + "\n"


def _value(v) -> str:
    """A start value (a number, or a list of them over the stages) as YAML flow text."""
    if isinstance(v, (list, tuple, np.ndarray)):
        return "[" + ", ".join(_num(float(x)) for x in v) + "]"
    return str(v)


def merge_initial_states(count: int = 100, seed: int = 0) -> list[np.ndarray]:
    """The merge's random initial states, drawn as ALGAMES's Monte Carlo analysis draws them (seeded numpy)."""
    return MERGE.draws(count, seed)


def intersection_initial_states(count: int = 100, seed: int = 0) -> list[np.ndarray]:
    """The intersection's random initial states, by the merge's rule around the intersection's nominal state."""
    return INTERSECTION.draws(count, seed)


def merge_model(x0: np.ndarray | None = None) -> GameModel:
    """The numpy model of the merge at ``x0`` (default: the nominal initial state)."""
    return MERGE.model(np.asarray(MERGE.x0 if x0 is None else x0, dtype=float))


def intersection_model(x0: np.ndarray | None = None) -> GameModel:
    """The numpy model of the intersection at ``x0`` (default: the nominal initial state)."""
    return INTERSECTION.model(np.asarray(INTERSECTION.x0 if x0 is None else x0, dtype=float))


def _algames_problems(sc: _AlgamesScenario, count: int, seed: int, family: str, title: str, source: str,
                      published: dict[str, str], notes: str) -> list[Problem]:
    problems = []
    for k, x0 in enumerate(sc.draws(count, seed)):
        model = sc.model(x0)
        header = [
            f"{title}, random initial state {k} of seed {seed} (ALGAMES's Monte Carlo draw, numpy default_rng).",
            f"Source: {ALGAMES_REPO}, {source}.",
            f"Inertial unicycles, RK3 (TrajectoryOptimization v1.3), N = {sc.knots} knots, dt = {_num(sc.dt)}; "
            "variational GNE (one multiplier per collision).",
        ]
        problems.append(Problem(
            family=family,
            name=f"{title} s{seed}#{k}",
            start=f"u = 0, lambda = 0; x0 = draw {k} of seed {seed}",
            config_yaml=sc.config_yaml(x0, f"algames-{sc.key}-s{seed}-{k}", header),
            reference=None,
            reference_source="",
            best_response_gaps=model.best_response_gaps,
            published=dict(published),
            notes=notes,
        ))
    return problems


def merge_problems(count: int = 100, seed: int = 0) -> list[Problem]:
    """ALGAMES's 3-car ramp merge from ``count`` random initial states (cold start from zero inputs)."""
    notes = (
        "ALGAMES RSS 2020 ramp merge (Monte Carlo analysis script); x0 drawn uniformly within +-(0.03, 0.03, 2.5 deg, "
        "0.025) of the nominal state per player, draws with a collision or off-road x0 redrawn; nonconvex, no "
        "unique equilibrium (no reference): a KKT point can be a local equilibrium from which another start of a "
        "player's best response finds a lower cost (e.g. cars 2 and 3 squeezed side by side), so a positive "
        "best-response gap is not by itself a wrong solution; MERGE_PUBLISHED is the figure data of the paper's "
        "1000-sample analysis (the draws differ: Julia's generator seeded with 100 there)"
    )
    return _algames_problems(MERGE, count, seed, "merge", "ALGAMES ramp merge", MERGE_SCRIPT, MERGE_PUBLISHED, notes)


def intersection_problems(count: int = 100, seed: int = 0) -> list[Problem]:
    """ALGAMES's T-intersection with two cars and a pedestrian, from ``count`` random initial states."""
    notes = (
        "ALGAMES RSS 2020 3-player T-intersection (Fig. 4 solve-time benchmark script: two cars and a pedestrian); "
        "ALGAMES published no Monte Carlo analysis of it: the merge's draw rule around its nominal state; "
        "nonconvex (no reference); no published numbers for this configuration in machine-readable form"
    )
    return _algames_problems(INTERSECTION, count, seed, "intersection", "ALGAMES T-intersection",
                             INTERSECTION_SCRIPT, {}, notes)


# ------------------------------------------------------------------------------------------------
# MCPTrajectoryGameSolver.jl's demo
# ------------------------------------------------------------------------------------------------

MCP_DT = 0.1
MCP_PLANNING_HORIZON = 10  # states X_1..X_10 (X_1 = x0), inputs U_1..U_10
MCP_X0 = (-1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)
MCP_GOALS = ((1.0, -0.1), (-1.0, 0.1))
MCP_INPUT_WEIGHT = 0.05
MCP_COLLISION_RADIUS = 1.0
MCP_ARENA = 4.0 * math.cos(math.pi / 4)  # PolygonEnvironment(4, 4): the square |px|, |py| <= 2 sqrt 2


def _mcp_costs(X: np.ndarray, U: np.ndarray) -> np.ndarray:
    """The demo's costs in the MCP's indexing: sum over t = 1..H of |p_i(X_t) - g_i|^2 + 0.05 |U_i,t|^2, with
    X (..., H, 8) = X_1..X_H (X_1 = x0) and U (..., H - 1, 4) = U_1..U_{H-1} (U_H = 0 at every solution)."""
    out = []
    for i, g in enumerate(MCP_GOALS):
        px, py = X[..., 4 * i], X[..., 4 * i + 1]
        ui = U[..., 2 * i:2 * i + 2]
        out.append(np.sum((px - g[0]) ** 2 + (py - g[1]) ** 2, axis=-1)
                   + MCP_INPUT_WEIGHT * np.sum(ui ** 2, axis=(-2, -1)))
    return np.stack(out, axis=-1)


def _mcp_own(i: int) -> tuple[_Bound, ...]:
    return tuple(_Bound(i, ax, up, MCP_ARENA if up else -MCP_ARENA) for ax in ("x", "y") for up in (True, False))


def mcp_demo_model() -> GameModel:
    """The numpy model of the MCPTrajectoryGameSolver demo game."""
    return GameModel(
        agents=("player1", "player2"),
        horizon=MCP_PLANNING_HORIZON - 2,
        x0=np.asarray(MCP_X0, dtype=float),
        step=lambda x, u: planar_double_integrator_step(x, u, MCP_DT),
        cost_fn=_mcp_costs,
        own=(_mcp_own(0), _mcp_own(1)),
        shared=_collisions(2, MCP_COLLISION_RADIUS),
    )


def _mcp_config_yaml() -> str:
    dt = MCP_DT
    states = [f"{s}{i}" for i in (1, 2) for s in ("px", "py", "vx", "vy")]
    dynamics: dict[str, str] = {}
    for i in (1, 2):
        dynamics[f"px{i}"] = f"px{i} + {_num(dt)}*vx{i} + {_num(0.5 * dt * dt)}*ax{i}"
        dynamics[f"py{i}"] = f"py{i} + {_num(dt)}*vy{i} + {_num(0.5 * dt * dt)}*ay{i}"
        dynamics[f"vx{i}"] = f"vx{i} + {_num(dt)}*ax{i}"
        dynamics[f"vy{i}"] = f"vy{i} + {_num(dt)}*ay{i}"
    agents = []
    for i, (g, own) in enumerate(zip(MCP_GOALS, (_mcp_own(0), _mcp_own(1)), strict=True)):
        k = i + 1
        const = (MCP_X0[4 * i] - g[0]) ** 2 + (MCP_X0[4 * i + 1] - g[1]) ** 2  # the X_1 = x0 term
        agents.append({
            "name": f"player{k}",
            "inputs": {f"ax{k}": {"start": 0}, f"ay{k}": {"start": 0}},
            "stage_cost": (f"{_minus(f'px{k}', g[0])}**2 + {_minus(f'py{k}', g[1])}**2 + "
                           f"{_num(MCP_INPUT_WEIGHT)}*(ax{k}**2 + ay{k}**2)"),
            "terminal_cost": _num(const),
            "constraints": [c.expr() for c in own],
        })
    header = [
        "MCPTrajectoryGameSolver.jl demo (test/Demo.jl: simple_game, first solve of demo_model_predictive_game_play).",
        f"Source: {MCP_REPO}; planar double integrators (TrajectoryGamesExamples.jl), dt = 0.1, planning horizon 10.",
        "U_10 moves no state and is 0 at every solution: dropped, so T = 8 (inputs U_1..U_9, states X_2..X_10).",
    ]
    return _yaml("mcp-demo", header, MCP_PLANNING_HORIZON - 2, states, dynamics, np.asarray(MCP_X0), agents,
                 [c.expr() for c in _collisions(2, MCP_COLLISION_RADIUS)], "variational")


def mcp_demo_problem() -> Problem:
    """The two-player collision-avoidance game of MCPTrajectoryGameSolver.jl's demo, cold start from zero inputs."""
    return Problem(
        family="mcp-demo",
        name="MCPTrajectoryGameSolver demo",
        start="u = 0, lambda = 0 (the demo's initial guess: the zero-input rollout)",
        config_yaml=_mcp_config_yaml(),
        reference=None,
        reference_source="",
        best_response_gaps=mcp_demo_model().best_response_gaps,
        published={},
        notes=(
            "MCPTrajectoryGameSolver.jl test/Demo.jl; solved there by PATH through ParametricMCPs; the repository "
            "publishes no iteration counts or solve times for it. Symmetric swap with goals offset by 0.1 to break "
            "the symmetry; nonconvex (collision constraint), no reference"
        ),
    )


# ------------------------------------------------------------------------------------------------
# Two-car overtaking (ALGAMES's style; see the module docstring)
# ------------------------------------------------------------------------------------------------

OVERTAKING_DT = 0.2
OVERTAKING_HORIZON = 12  # T: stages 0..12, 13 x 2 inputs x 2 cars = 52 decisions
OVERTAKING_RADIUS = 0.08  # each car's; the collision distance is twice this
OVERTAKING_ROAD = 0.34  # the road's width (ALGAMES's merge road): two lanes of 0.17
OVERTAKING_LANE = -OVERTAKING_ROAD / 4  # the right lane's centre, where both cars start and want to be
OVERTAKING_SPEEDS = (1.0, 0.5)  # each car's initial and desired speed: car 1 is the faster one
OVERTAKING_X0 = (-0.6, OVERTAKING_LANE, 0.0, OVERTAKING_SPEEDS[0], -0.2, OVERTAKING_LANE, 0.0, OVERTAKING_SPEEDS[1])
OVERTAKING_WEIGHTS = (1.0, 0.1, 1.0)  # on (py - lane)^2, th^2, (v - v_i)^2, times dt per stage
OVERTAKING_INPUT_WEIGHT = 0.1  # on w^2 + a^2, times dt per stage
OVERTAKING_TERMINAL = 10.0  # the last state: this times dt times ((py - lane)^2 + th^2 + (v - v_i)^2)


def _overtaking_start(kind: str) -> np.ndarray:
    """Start inputs (2 cars, 13 stages, (w, a)) of one kind: ``zero``; ``pull-out``: car 1 turns left at 0.6 for two
    stages and back for two (a lane change's shape); ``brake``: car 1 decelerates at 1 for three stages;
    ``random``: N(0, 0.1^2) inputs for both cars (numpy default_rng(0))."""
    H = OVERTAKING_HORIZON + 1
    U = np.zeros((2, H, 2))
    if kind == "pull-out":
        U[0, 0:2, 0], U[0, 2:4, 0] = 0.6, -0.6
    elif kind == "brake":
        U[0, 0:3, 1] = -1.0
    elif kind == "random":
        U = 0.1 * np.random.default_rng(0).standard_normal(U.shape)
    elif kind != "zero":
        raise ValueError(f"unknown start {kind!r}")
    return U


OVERTAKING_STARTS: dict[str, str] = {
    "zero": "u = 0, lambda = 0 (zero inputs)",
    "pull-out": "car 1 pulls out: w1 = 0.6, 0.6, -0.6, -0.6 at tau = 0..3, else 0",
    "brake": "car 1 brakes: a1 = -1 at tau = 0..2, else 0",
    "random": "seeded inputs: N(0, 0.1^2), default_rng(0)",
}


def _overtaking_costs(X: np.ndarray, U: np.ndarray) -> np.ndarray:
    """The cars' costs in gnerun's indexing: X (..., T + 2, 8) = x(0)..x(T+1), U (..., T + 1, 4); stage tau is charged
    on x(tau + 1) and u(tau), the terminal cost on x(T + 1)."""
    dt = OVERTAKING_DT
    qy, qth, qv = OVERTAKING_WEIGHTS
    out = []
    for i, speed in enumerate(OVERTAKING_SPEEDS):
        py, th, v = X[..., 1:, 4 * i + 1], X[..., 1:, 4 * i + 2], X[..., 1:, 4 * i + 3]
        dy, dv = py - OVERTAKING_LANE, v - speed
        ui = U[..., 2 * i:2 * i + 2]
        stage = dt * (qy * dy ** 2 + qth * th ** 2 + qv * dv ** 2) + dt * OVERTAKING_INPUT_WEIGHT * np.sum(ui ** 2, -1)
        last = OVERTAKING_TERMINAL * dt * (dy[..., -1] ** 2 + th[..., -1] ** 2 + dv[..., -1] ** 2)
        out.append(np.sum(stage, axis=-1) + last)
    return np.stack(out, axis=-1)


def _overtaking_own(i: int) -> tuple[_Bound, ...]:
    """The road's edges for car i's centre: |py| <= road/2 - radius."""
    edge = OVERTAKING_ROAD / 2 - OVERTAKING_RADIUS
    return (_Bound(i, "y", True, edge), _Bound(i, "y", False, -edge))


def overtaking_model() -> GameModel:
    """The numpy model of the overtaking game (its own RK4 step, costs and constraints)."""
    return GameModel(
        agents=("car1", "car2"),
        horizon=OVERTAKING_HORIZON,
        x0=np.asarray(OVERTAKING_X0, dtype=float),
        step=lambda x, u: unicycle_rk4_step(x, u, OVERTAKING_DT),
        cost_fn=_overtaking_costs,
        own=(_overtaking_own(0), _overtaking_own(1)),
        shared=_collisions(2, 2 * OVERTAKING_RADIUS),
    )


def _overtaking_config_yaml(start: str) -> str:
    dt = OVERTAKING_DT
    qy, qth, qv = OVERTAKING_WEIGHTS
    states = [f"{s}{i}" for i in (1, 2) for s in ("px", "py", "th", "v")]
    ode: dict[str, str] = {}
    for i in (1, 2):
        ode.update({f"px{i}": f"v{i}*cos(th{i})", f"py{i}": f"v{i}*sin(th{i})", f"th{i}": f"w{i}", f"v{i}": f"a{i}"})
    U = _overtaking_start(start)
    agents = []
    for i, speed in enumerate(OVERTAKING_SPEEDS):
        k = i + 1
        names = (f"py{k}", f"th{k}", f"v{k}")
        targets = (OVERTAKING_LANE, 0.0, speed)
        state = _weighted_squares([dt * w for w in (qy, qth, qv)], names, targets)
        terminal = _weighted_squares([OVERTAKING_TERMINAL * dt] * 3, names, targets)
        agents.append({
            "name": f"car{k}",
            "inputs": {f"{u}{k}": {"start": U[i, :, j] if U[i, :, j].any() else 0} for j, u in enumerate("wa")},
            "stage_cost": f"{state} + {_num(dt * OVERTAKING_INPUT_WEIGHT)}*(w{k}**2 + a{k}**2)",
            "terminal_cost": terminal,
            "constraints": [c.expr() for c in _overtaking_own(i)],
        })
    header = [
        "Two-car overtaking in ALGAMES's style (benchmarks/problems/trajectory.py): inertial unicycles, RK4,",
        "dt = 0.2, T = 12; the faster car 1 starts 0.4 behind the slower car 2 in the right lane of a two-lane road",
        "of width 0.34;",
        f"start: {OVERTAKING_STARTS[start]}.",
    ]
    return _yaml(f"overtaking-{start}", header, OVERTAKING_HORIZON, states, ode, np.asarray(OVERTAKING_X0), agents,
                 [c.expr() for c in _collisions(2, 2 * OVERTAKING_RADIUS)], "variational", ode=("rk4", dt))


def overtaking_problems() -> list[Problem]:
    """The two-car overtaking game from each of :data:`OVERTAKING_STARTS` (zero inputs first)."""
    model = overtaking_model()
    return [
        Problem(
            family="overtaking",
            name="two-car overtaking",
            start=label,
            config_yaml=_overtaking_config_yaml(start),
            reference=None,
            reference_source="",
            best_response_gaps=model.best_response_gaps,
            published={},
            notes=(
                "a scenario of this suite in ALGAMES's style (no published numbers); nonconvex, no reference: "
                "which car gives way, and where, is not unique"
            ),
        )
        for start, label in OVERTAKING_STARTS.items()
    ]
