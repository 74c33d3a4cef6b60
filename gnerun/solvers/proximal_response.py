"""Agent-distributed proximal response [eq:proximal_response, eq:Semi_proximal].

Given the current decisions abar, agent i computes

    abar_i^+ = argmin_{a_i} J_i(a_i, abar_-i) + tau/2 ||a_i - abar_i||^2  s.t.  g_i(a_i, abar_-i) <= 0

with an inner Newton method (semismooth Newton on its own KKT system, or Josephy-Newton when its
feasible set is polyhedral), warm-started from its last decision and multipliers. One *round*
updates every agent once: all from the same abar (``jacobi``) or one after the other, each seeing
the others' newest decisions (``gauss_seidel``). In a closed loop K counts rounds.

Information isolation: each :class:`Agent` holds only its own compiled proximal problem
(:func:`gnerun.game.compile.agent_problem`: its own cost and constraints, the common dynamics and parameters, taken
from the game's expressions) and its inner solver; a round hands it the plant state, the others' last
decisions and its own last decision and multipliers, nothing else.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..errors import InputError
from ..game.compile import CompiledGame, agent_problem
from ..language.config import Config, SolverConfig
from .driver import Solver, iterate
from .globalization import globalized
from .josephy_newton import JosephyNewton
from .kkt import KKTSystem
from .ssn import SemismoothNewton
from .status import FAILURES, SSNState, Status


class Agent:
    """One agent's computation: its proximal response problem and the inner Newton method."""

    def __init__(self, name: str, problem: CompiledGame, inner: Solver, max_iter: int):
        self.name = name
        self.problem = problem
        self.inner = inner
        self.max_iter = max_iter

    def respond(self, x: np.ndarray, others: np.ndarray, own: np.ndarray, multipliers: np.ndarray) -> SSNState:
        """The proximal response to the others' last decisions, from the agent's own last (a_i, lambda_i)."""
        p = np.concatenate([x, others, own])
        return iterate(self.inner, self.inner.init(np.concatenate([own, multipliers]), p), self.max_iter)


def make_agents(cfg: Config, game: CompiledGame) -> list[Agent]:
    opts = cfg.solver
    # responses are solved tighter than the rounds' tolerance, or the rounds stall at the inner one
    inner_opts = SolverConfig(**{**opts.model_dump(), "kind": opts.inner, "max_iter": opts.inner_max_iter,
                                 "tol": opts.tol / 100})
    agents = []
    for i, name in enumerate(game.agent_names):
        problem = agent_problem(game, i, opts.tau, cfg)
        if opts.inner == "jn":
            inner: Solver = JosephyNewton(problem, inner_opts)
        else:
            inner = globalized(SemismoothNewton(problem, inner_opts))
        agents.append(Agent(name, problem, inner, opts.inner_max_iter))
    return agents


class ProximalResponse:
    """Rounds of proximal responses. ``init``, ``terminate`` and ``finish`` are the whole game's
    :class:`~gnerun.solvers.kkt.KKTSystem`'s: the coordinator measures ||Phi(z)|| of the whole game to decide
    convergence, the agents never see it."""

    def __init__(self, cfg: Config, game: CompiledGame):
        if game.shared_slice.stop > game.shared_slice.start:
            raise InputError("solver.kind 'distributed' needs each agent to carry its own constraints: with "
                             "equilibrium: variational the shared constraints have common multipliers; use "
                             "equilibrium: generalized, or solver.kind 'ssn' / 'jn'")
        if cfg.disturbance.kind != "none":
            raise InputError("solver.kind 'distributed' takes no solver-side disturbance yet (disturbance.kind "
                             f"{cfg.disturbance.kind!r}); plant disturbances work")
        self.kkt = KKTSystem(game, cfg.solver, None)
        self.game = game
        self.options = cfg.solver
        self.disturbance = self.kkt.disturbance
        self.agents = make_agents(cfg, game)
        self.gauss_seidel = cfg.solver.scheme == "gauss_seidel"

    def init(self, z0: np.ndarray | None = None, x: np.ndarray | None = None,
             rng: np.random.Generator | None = None, warm: bool = False) -> SSNState:
        return self.kkt.init(z0, x, rng)

    def terminate(self, state: SSNState) -> tuple[bool, Status]:
        return self.kkt.terminate(state)

    def finish(self, state: SSNState) -> SSNState:
        return self.kkt.finish(state)

    def at_solution(self, state: SSNState) -> bool:
        return self.kkt.at_solution(state)

    def step(self, state: SSNState) -> SSNState:
        """One round: every agent's proximal response once; a failed or converged state is returned unchanged
        (:meth:`iteration` takes a round from a solution)."""
        if state.status in FAILURES or self.kkt.at_solution(state):
            return state
        return self.iteration(state)

    def iteration(self, state: SSNState) -> SSNState:
        """One round from ``state``, also at a solution."""
        if state.status in FAILURES:
            return state
        game = self.game
        n = game.n
        a, lam = state.z[:n], state.z[n:]
        new_a, new_lam = a.copy(), lam.copy()
        for agent, sl, ms in zip(self.agents, game.agent_slices, game.multiplier_slices, strict=True):
            seen = new_a if self.gauss_seidel else a
            others = np.concatenate([seen[: sl.start], seen[sl.stop :]])
            response = agent.respond(self.game._x(state.x), others, a[sl], lam[ms])
            if response.status in FAILURES:
                return replace(state, status=response.status,
                               message=f"{agent.name}'s proximal response failed in round {state.k + 1}: "
                                       f"{response.message}")
            new_a[sl] = response.z[: sl.stop - sl.start]
            new_lam[ms] = response.z[sl.stop - sl.start :]
        return self.kkt.advance(state, np.concatenate([new_a, new_lam]))
