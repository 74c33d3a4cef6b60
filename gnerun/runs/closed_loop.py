"""`gnerun simulate`: time-distributed CG-MPC with a fixed iteration budget K [eq:TDO].

At every sampling time t the solver takes at most K steps from the warm start, every agent's first
input u(t) of the plan chosen by the safeguard (:mod:`gnerun.runs.safeguard`: z^K(t) itself unless it is not
converged and a better plan is at hand) is applied, and the plant moves to x(t+1) = f(x(t), u(t)) + w(t).
Alongside, z*(t), the exact solution at x(t), is computed (to tolerance, outside the K budget) to measure the tracking
error e(t) = z^K(t) - z*(t) of Theorem "bounded error": the solution the solver reaches from the same
warm start without a budget (then from z*(t-1), then cold), i.e. the isolated solution the iterates
track, which is the one equilibrium when it is unique.

The budget K is a maximum: once ||Phi|| <= tol the remaining steps are skipped, because a solution
is a fixed point of the Newton step.

With ``run.initial: solve`` the first sampling time is solved to tolerance from the start values, which does not
depend on K: the loops of one run share that solve and z*(0) (:class:`FirstSamplingTime`), made once.
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..game.building import no_check, polled
from ..game.compile import CompiledGame, StageConstraints, compile_game, compile_stage_constraints
from ..game.kernels import kernel_report
from ..language.config import Config, PlantDisturbance
from ..language.runtime import References
from ..language.vehicles import vehicles
from ..log import topics
from ..log.mcap_log import json_ready
from ..log.messages import MpcState, RuntimeValues, SamplingTime
from ..log.plans import PlanStates
from ..solvers.driver import IterateRow, iterate
from ..solvers.factory import make_solver
from ..solvers.status import FAILURES, Status
from .interrupt import Interrupt, Stopped
from .reference import ReferenceSolver
from .rundir import RunDirectory, ended_by, recording
from .safeguard import Fallback, PaperRule
from .solving import own_reference


@dataclass
class ClosedLoopResult:
    """One closed loop (one K). Arrays are indexed by sampling time t and hold the times run (``done`` of the
    ``steps`` planned: fewer if the loop stopped or was interrupted); they grow as the loop runs, so a loop of
    10^7 planned steps takes memory for the steps it makes only."""

    K: int
    x: np.ndarray  # (done + 1, nx): x(0) .. x(steps) for a completed loop; (done, nx): the states reached otherwise
    u: np.ndarray  # (done, nu): the inputs applied (NaN at a time where the loop stopped)
    w: np.ndarray  # (done, nx): the plant disturbances
    e_norm: np.ndarray  # (done,): ||z^K(t) - z*(t)|| (nan where z* is unknown)
    e_norm_agent: dict[str, np.ndarray]  # ||z_i^K(t) - z_i^*(t)||, z_i = (a_i, lambda_i)
    residual_norm: np.ndarray  # (done,): ||Phi(z^K(t); x(t))||
    iterations: np.ndarray  # (done,): solver steps taken (<= K)
    solve_time_s: np.ndarray  # (done,): time of the solver steps alone
    status: list[str]  # per t: converged | incomplete (K steps, tol not met) | a failure status
    reference_status: list[str]  # per t: the status of the z*(t) solve
    constraint_violation: np.ndarray  # (done,): the largest violation of a stage-0 row at u(t) and x(t + 1)
    worst_constraint: list[str | None]  # per t: that row's label (None when every row holds)
    fallback: np.ndarray  # (done,): True where the applied plan was not z^K(t) (run.safeguard)
    z: np.ndarray = field(repr=False)  # (done, size): z^K(t)
    z_star: np.ndarray = field(repr=False)  # (done, size): z*(t)
    completed: int | None = None  # sampling times done; fewer than steps if the loop stopped or was interrupted
    ended: str = "completed"  # completed | stopped (on_failure: stop) | diverged (the plant) | interrupted | error
    planned: int | None = None  # run.steps
    message: str = ""  # why a loop ended early (diverged, error)
    parameters: list[dict] = field(default_factory=list)  # per t: the runtime values in force (games with any)
    references: list[dict] = field(default_factory=list)  # per t: r(t) of the states with a reference
    reference_time_s: float = 0.0  # the time of the z*(t) solves this loop made (not in the summary: a timing)
    shares_first: bool = False  # t = 0 was another loop's solve (FirstSamplingTime): solve_time_s[0] is its time

    @property
    def steps(self) -> int:
        """Sampling times planned (run.steps)."""
        return int(self.u.shape[0]) if self.planned is None else self.planned

    @property
    def done(self) -> int:
        """Sampling times run."""
        return int(self.u.shape[0]) if self.completed is None else self.completed

    @property
    def failed_steps(self) -> list[int]:
        failures = {str(f) for f in FAILURES}
        return [t for t, s in enumerate(self.status) if s in failures]

    @property
    def fallback_steps(self) -> list[int]:
        return [int(t) for t in np.flatnonzero(self.fallback[: self.done])]

    @property
    def max_constraint_violation(self) -> float:
        """The worst violation over the sampling times run (nan if a state or input was not finite)."""
        v = self.constraint_violation[: self.done]
        return float(v.max()) if v.size and np.all(np.isfinite(v)) else (0.0 if not v.size else math.nan)

    @property
    def final_e_norm(self) -> float:
        return float(self.e_norm[self.done - 1]) if self.done else math.nan

    def summary(self, game: CompiledGame) -> dict:
        done = self.done
        references = _by_name(self.references[:done])  # r(t) of the states with a reference, per state
        return json_ready({
            "K": self.K,
            "ended": self.ended,
            **({"message": self.message} if self.message else {}),
            "completed_steps": done,
            "x": self.x.tolist(),  # x(0..steps), or the states reached
            "u": self.u[:done].tolist(),
            "w": self.w[:done].tolist(),
            "e_norm": self.e_norm[:done].tolist(),
            "e_norm_agent": {k: v[:done].tolist() for k, v in self.e_norm_agent.items()},
            "residual_norm": self.residual_norm[:done].tolist(),
            "iterations": self.iterations[:done].tolist(),
            "solve_time_s": self.solve_time_s[:done].tolist(),
            "status": self.status,
            "reference_status": self.reference_status,
            "failed_steps": self.failed_steps,
            "fallback_steps": self.fallback_steps,
            "constraint_violation": self.constraint_violation[:done].tolist(),
            "worst_constraint": self.worst_constraint[:done],
            "max_constraint_violation": self.max_constraint_violation,
            "max_e_norm": _nanmax(self.e_norm),
            "final_e_norm": self.final_e_norm,
            "median_solve_time_s": float(np.median(self.solve_time_s[:done])) if done else math.nan,
            "max_solve_time_s": float(np.max(self.solve_time_s[:done])) if done else math.nan,
            **({"parameters": _by_name(self.parameters[:done])} if any(self.parameters) else {}),
            **({"reference": references,
                "tracking_error": {s: (self.x[:done, game.state_names.index(s)] - r).tolist()
                                   for s, r in references.items()}} if references else {}),
        })


def _by_name(values: list[dict]) -> dict[str, list]:
    """Per-sampling-time records {name: value} as {name: [value per t]}."""
    return {name: [v[name] for v in values] for name in (values[0] if values else {})}


def _nanmax(v: np.ndarray) -> float:
    finite = v[np.isfinite(v)]
    return float(finite.max()) if finite.size else math.nan


class Simulation(dict[int, ClosedLoopResult]):
    """Closed-loop results indexed by K (``sim[7].e_norm``), and where they were written."""

    run_dir: Path | None = None
    game: CompiledGame | None = None
    interrupted: bool = False

    error: str | None = None  # what ended the run, if an exception did (status error)
    first: FirstSamplingTime | None = None  # sampling time 0, shared by the loops (its solve made once)
    compile_time_s: float = 0.0  # the game, its stage constraints and the solver's system, built before the loops
    log_time_s: float = 0.0  # writing the run directory (0 without one)

    @property
    def kernels(self):
        """How the sparse system was evaluated (compiled C or interpreted), where the loops took that formulation."""
        return None if self.game is None else kernel_report(self.game)

    @property
    def solver_time_s(self) -> float:
        """The solver's time over every loop, the shared t = 0 solve counted once."""
        return float(sum(r.solve_time_s[int(r.shares_first):r.done].sum() for r in self.values()))

    @property
    def reference_time_s(self) -> float:
        """The time of the z*(t) solves over every loop (z*(0) counted once where it was shared)."""
        return float(sum(r.reference_time_s for r in self.values()))

    @property
    def status(self) -> str:
        """completed | stopped (a loop ended at a failed step, on_failure: stop) | diverged (the plant's state left
        the solver's range) | interrupted (Ctrl-C) | error (an exception ended the run: ``error`` says which)."""
        if self.error is not None:
            return "error"
        if self.interrupted:
            return "interrupted"
        for ended in ("diverged", "stopped"):
            if any(r.ended == ended for r in self.values()):
                return ended
        return "completed"

    def summary(self) -> dict:
        assert self.game is not None
        return {
            "command": "simulate",
            "status": self.status,
            **({"message": self.error} if self.error is not None else {}),
            "K": list(self),
            "steps": next(iter(self.values())).steps if self else 0,
            "state_names": self.game.state_names,
            "input_names": [u for names in self.game.variable_names for u in names],
            "agents": self.game.agent_names,
            "by_K": {str(k): r.summary(self.game) for k, r in self.items()},
            **({"kernels": self.kernels.as_dict()} if self.kernels is not None else {}),
        }


class PlantNoise:
    """w(t), seeded: gaussian, uniform on [-scale, scale], or constant."""

    def __init__(self, spec: PlantDisturbance, nx: int):
        self.spec = spec
        self.scale = np.broadcast_to(np.asarray(spec.scale, dtype=float), (nx,)).copy()
        self.rng = np.random.default_rng(spec.seed)

    def __call__(self) -> np.ndarray:
        kind = self.spec.kind
        if kind == "gaussian":
            return self.scale * self.rng.standard_normal(self.scale.size)
        if kind == "uniform":
            return self.scale * self.rng.uniform(-1.0, 1.0, self.scale.size)
        if kind == "constant":
            return self.scale.copy()
        return np.zeros(self.scale.size)


@dataclass(frozen=True)
class StepReport:
    """One sampling time of a closed loop, as it happens (what ``simulate``'s ``progress`` callback receives)."""

    K: int
    t: int
    steps: int
    x: np.ndarray  # x(t)
    u: np.ndarray  # u(t), the inputs applied
    status: str  # converged | incomplete | a failure status
    fallback: bool  # the applied plan was not z^K(t) (run.safeguard)
    constraint_violation: float  # at u(t) and the state x(t + 1) it produced
    iterations: int
    residual_norm: float  # ||Phi(z^K(t); x(t))||
    e_norm: float  # ||z^K(t) - z*(t)|| (nan with run.reference: none)
    solve_time_s: float


# progress(report) is called after every sampling time
Progress = Callable[[StepReport], None]
# parameters(t, x) -> {name: value}: the runtime values at the sampling time of time t (seconds) and plant state x
RuntimeCallback = Callable[[float, np.ndarray], "Mapping[str, object] | None"]


@dataclass(frozen=True)
class Sample:
    """One sampling time as a closed loop recorded it."""

    u: np.ndarray  # the inputs applied (NaN where the loop stopped)
    w: np.ndarray  # the plant disturbance
    e_norm: float  # ||z^K(t) - z*(t)|| (nan where z* is unknown)
    e_norm_agent: dict[str, float]
    residual_norm: float
    iterations: int
    solve_time_s: float
    status: str  # converged | incomplete | a failure status
    reference_status: str
    constraint_violation: float
    worst_constraint: str | None
    fallback: bool
    z: np.ndarray
    z_star: np.ndarray


class LoopRecord:
    """What a closed loop has made so far: the state of every sampling time begun and the record of every sampling
    time done. The loop fills it as it runs, so that whoever started it can still take the result of the sampling
    times done when an exception ends the loop (:meth:`result`)."""

    def __init__(self, K: int, steps: int, game: CompiledGame):
        self.K, self.steps = K, steps
        self.nx, self.size = game.nx, game.size
        self.nu = sum(len(v) for v in game.variable_names)
        self.agents = game.agent_names
        self.xs: list[np.ndarray] = []  # x(t) of every sampling time begun, then the state the loop ended in
        self.samples: list[Sample] = []
        self.parameters: list[dict] = []  # the runtime values of every sampling time begun
        self.references: list[dict] = []  # r(t) of the states with a reference, every sampling time begun
        self.reached: np.ndarray | None = np.array(game.x0, dtype=float)  # the state after the last time done

    def add(self, sample: Sample, reached: np.ndarray | None) -> None:
        """Sampling time t done: its record and the state it produced."""
        self.samples.append(sample)
        if reached is not None:
            self.reached = reached

    def result(self, ended: str, completed: int | None = None, message: str = "") -> ClosedLoopResult:
        """The loop's result: ``completed`` sampling times (default: those recorded), every array cut to them."""
        per_step = len(self.samples) if completed is None else completed
        samples = self.samples[:per_step]

        def rows(values: list, width: int) -> np.ndarray:
            return np.array(values, dtype=float).reshape(len(values), width)

        def column(name: str, dtype: type = float) -> np.ndarray:
            return np.array([getattr(s, name) for s in samples], dtype=dtype)

        if ended == "completed":
            xs = self.xs[:per_step + 1]
        elif ended in ("diverged", "error") and self.reached is not None:
            xs = [*self.xs[:per_step], self.reached]  # and the state the last sampling time done reached
        else:
            xs = self.xs[:per_step]
        return ClosedLoopResult(
            K=self.K, x=rows(xs, self.nx), u=rows([s.u for s in samples], self.nu),
            w=rows([s.w for s in samples], self.nx), e_norm=column("e_norm"),
            e_norm_agent={a: np.array([s.e_norm_agent[a] for s in samples], dtype=float) for a in self.agents},
            residual_norm=column("residual_norm"), iterations=column("iterations", int),
            solve_time_s=column("solve_time_s"), status=[s.status for s in samples],
            reference_status=[s.reference_status for s in samples],
            constraint_violation=column("constraint_violation"),
            worst_constraint=[s.worst_constraint for s in samples], fallback=column("fallback", bool),
            z=rows([s.z for s in samples], self.size), z_star=rows([s.z_star for s in samples], self.size),
            completed=per_step, ended=ended, planned=self.steps, message=message,
            parameters=self.parameters[:per_step], references=self.references[:per_step])


class LoopLog:
    """A closed loop's messages in the run log: per sampling time its iterates, the state with the inputs applied
    and the tracking error (topics /K<k>/mpc/iterate, /state, /error), on the loop's own time axis."""

    def __init__(self, run: RunDirectory, K: int, sampling_time: float, game: CompiledGame | None = None):
        """``game``: the plans' predicted states are logged (computed here, or by a log written by a process of its
        own, which gets the plans' decisions)."""
        self.run, self.K, self.dt = run, K, sampling_time
        self.game = game
        self.remote_plans = game is not None and run.plan_states(PlanStates(game.plans.rollout_function,
                                                                            game.plans.stage_order))

    def at(self, t: int) -> None:
        self.run.at(t * self.dt)

    def log(self, level: str, text: str) -> None:
        self.run.log(level, text)

    def sampling_time(self, t: int, trace: list, z_star: np.ndarray | None, x: np.ndarray, u: np.ndarray | None,
                      sample: Sample, a: np.ndarray | None = None) -> None:
        """Sampling time t (flushed): its iterates, the state with the inputs applied and the states its plan (the
        applied decisions ``a``) predicts, the error."""
        iterates = [(k, r, None if z_star is None else float(np.linalg.norm(zk - z_star))) for k, r, zk in trace]
        plan = plan_inputs = None
        if a is not None and self.game is not None:
            if self.remote_plans:
                plan_inputs = a
            else:
                plan = self.game.predicted_states(a, x)
        self.run.sampling_time(SamplingTime(
            K=self.K, t=t, iterates=iterates, x=x, u=u, status=sample.status, fallback=bool(sample.fallback),
            constraint_violation=float(sample.constraint_violation), e_norm=sample.e_norm,
            e_norm_agent=dict(sample.e_norm_agent), plan=plan, plan_inputs=plan_inputs))

    def parameters(self, t: int, values: dict, references: dict) -> None:
        with self.run.timed():
            self.run.write(topics.mpc(self.K, topics.MPC_PARAMETERS), RuntimeValues.of(t, values, references))

    def last_state(self, t: int, x: np.ndarray, status: str) -> None:
        """The state the loop ended in, which no solver step produced (status: '' or diverged)."""
        with self.run.timed():
            self.run.write(topics.mpc(self.K, "state"), MpcState(t=t, x=x.tolist(), u=None, status=status,
                                                                  fallback=False, constraint_violation=None))


class FirstSamplingTime:
    """The first sampling time's solve, which does not depend on K: with ``run.initial: solve`` the solve to tolerance
    from the start values, and z*(0) where it is solved for. The first loop makes them, the loops of the other K take
    them as they are (its iterates, its time, the solver's random state after it), so that a run of several K solves
    at t = 0 once. Shared only between loops whose t = 0 is the same: the same x(0) and runtime values."""

    def __init__(self) -> None:
        self.key: str | None = None  # x(0) and the runtime values at t = 0 of the loop that made them
        self.solved: tuple | None = None  # (state, trace, time) of the t = 0 solve to tolerance, as it ended
        self.states: list = []  # its iterates (IterateRow), for a caller that shows them
        self.reference = None  # z*(0) where it was solved for (a Reference)
        self.solves = 0  # t = 0 solves to tolerance made (one per run whatever the number of K)

    def matches(self, key: str) -> bool:
        """Whether what was made at t = 0 is for this loop's t = 0 (the first loop to ask sets the key)."""
        if self.key is None:
            self.key = key
        return self.key == key


class ClosedLoop:
    """One closed loop of ``cfg.run.steps`` sampling times with at most K solver steps each (:func:`closed_loop`).

    Built once per loop: the solver, the z*(t) solver (:class:`~gnerun.runs.reference.ReferenceSolver`), the
    safeguard (:class:`~gnerun.runs.safeguard.PaperRule` or :class:`~gnerun.runs.safeguard.Fallback`), the plant
    noise; every sampling time goes to one :class:`LoopRecord` and, with a run directory, to one :class:`LoopLog`.
    """

    def __init__(self, cfg: Config, game: CompiledGame, K: int, run: RunDirectory | None = None,
                 progress: Progress | None = None, interrupt: Interrupt | None = None,
                 stage: StageConstraints | None = None, record: LoopRecord | None = None,
                 parameters: RuntimeCallback | None = None, first: FirstSamplingTime | None = None):
        self.cfg, self.game, self.K = cfg, game, K
        self.first = first if first is not None else FirstSamplingTime()
        self.shares_first = False  # t = 0 was taken from another loop's (its time is not this loop's)
        self.reference_time_s = 0.0  # the time of the z*(t) solves this loop made
        self.parameters = parameters
        self.references = References(cfg, game.runtime)
        self.solver = make_solver(cfg, game)
        self.stage = stage if stage is not None else compile_stage_constraints(cfg, game)
        self.reference = ReferenceSolver(cfg, game) if cfg.run.reference == "exact" else None
        self.safeguard = (Fallback(game, self.solver, self.stage) if cfg.run.safeguard == "fallback"
                          else PaperRule())
        self.plant = PlantNoise(cfg.disturbance.plant, game.nx)
        # the plans' predicted states are logged for Rerun's paths view: games with positions in the plane only
        self.plans = bool(vehicles(game.state_names))
        self.log = (LoopLog(run, K, cfg.run.sampling_time, game if self.plans else None) if run is not None
                    else None)
        self.progress, self.interrupt = progress, interrupt
        self.record = record if record is not None else LoopRecord(K, cfg.run.steps, game)
        self.agent_idx = [game.agent_indices(i) for i in range(len(game.agent_names))]
        self.nu = sum(len(v) for v in game.variable_names)
        self.z_star_prev = game.z_start()  # z*(t-1), a start of the z*(t) solve
        # a converged iterate of the loop is the reference's own where the loop's solver is the reference's method,
        # undisturbed (a distributed loop is measured against centralised SSN: always solved again)
        self.own_reference = own_reference(cfg)
        self.rng = None  # the solver's random state, from one sampling time to the next

    def _iterate(self, state, budget: int, seen: list | None = None, solver=None) -> tuple[object, list, float]:
        """Up to ``budget`` solver steps from ``state``, stopped at convergence or a failed step (whose iterate is
        not kept): the last state, the iterates as (k, ||Phi||, z^k) from the start on, the steps' time. ``seen``
        receives every state made (:class:`~gnerun.solvers.driver.IterateRow`); ``solver``: another than the loop's."""
        trace: list = []

        def keep(s) -> None:  # a failed step's iterate is not kept
            if seen is not None:
                seen.append(IterateRow.of(s))
            if s.status not in FAILURES:
                trace.append((s.k, s.residual_norm, s.z))

        t0 = time.perf_counter()
        state = iterate(solver or self.solver, state, budget, keep, finish=False, ends=FAILURES | {Status.CONVERGED})
        return state, trace, time.perf_counter() - t0

    def _interrupted(self, t: int, plural: bool = False) -> None:
        if self.log is not None:
            self.log.log("warning", f"K={self.K}: interrupted ({self.interrupt.reason}) after {t} sampling "
                                    f"time{'s' * (plural or t != 1)}")

    def _z_star(self, t: int, x: np.ndarray, z_warm: np.ndarray, solved=None) -> tuple[np.ndarray | None, str]:
        """z*(t) (None where it is not found, or not asked for: run.reference none) and the status of its solve.
        Where the loop's own solve from z_warm converged (``solved``, its state; undisturbed, by the reference's
        method), the unbudgeted solve from z_warm would take the same iterates: z*(t) is that iterate
        (:meth:`~gnerun.runs.reference.ReferenceSolver.reached`), not solved for again."""
        if self.reference is None:
            return None, "skipped"
        if solved is not None:
            ref = self.reference.reached(solved)
        elif t == 0 and self.first.reference is not None and self.first.matches(self._first_key(x)):
            ref = self.first.reference  # z*(0), from the start values: the same for every K
        else:
            t0 = time.perf_counter()
            ref = self.reference.track(z_warm, self.z_star_prev, x, self.interrupt)
            self.reference_time_s += time.perf_counter() - t0
            if t == 0 and self.first.matches(self._first_key(x)):
                self.first.reference = ref
        if ref.converged:
            self.z_star_prev = ref.z
        elif self.log is not None:
            self.log.log("warning", f"K={self.K} t={t}: the exact solution z*(t) was not found ({ref.message}); "
                                    "e(t) is not available")
        return (ref.z if ref.converged else None), str(ref.status)

    def _solve(self, t: int, x: np.ndarray, z_warm: np.ndarray, seen: list | None = None,
               solver=None) -> tuple[object, list, float]:
        """The solver steps of sampling time t from z_warm: at most K (at t = 0 with run.initial: solve, the solver's
        max_iter); the last state, the iterates (:meth:`_iterate`) and the time of init and steps. ``solver``: another
        than the loop's (the t = 0 solve's own)."""
        cfg = self.cfg
        solver = solver or self.solver
        budget = cfg.solver.max_iter if t == 0 and cfg.run.initial == "solve" else self.K
        t0 = time.perf_counter()
        state = solver.init(z_warm, x, self.rng, warm=t > 0)
        elapsed = time.perf_counter() - t0
        state, trace, stepping = self._iterate(state, budget, seen, solver)
        self.rng = state.rng
        return state, trace, elapsed + stepping

    def _first_solve(self, x: np.ndarray, z_warm: np.ndarray) -> tuple[object, list, float]:
        """Sampling time 0. With ``run.initial: solve`` its solve to tolerance from the start values does not depend
        on K: the first loop makes it (:class:`FirstSamplingTime`), the others take a copy of it as it ended, the
        solver's random state included, and go on from there as if they had made it. It is made by a solver of its
        own, so that every loop's solver starts t = 1 alike, with nothing kept from a solve before (a factorisation
        kept per active set reproduces a step to rounding, not bit for bit): each K's loop is that of K run alone."""
        first = self.first
        if self.cfg.run.initial != "solve" or not first.matches(self._first_key(x)):
            return self._solve(0, x, z_warm)
        if first.solved is None:
            seen: list = []
            state, trace, elapsed = self._solve(0, x, z_warm, seen, make_solver(self.cfg, self.game))
            first.solved, first.states = copy.deepcopy((state, trace, elapsed)), seen
            first.solves += 1
            return state, trace, elapsed
        state, trace, elapsed = copy.deepcopy(first.solved)
        self.rng = state.rng
        self.shares_first = True
        return state, trace, elapsed

    def _first_key(self, x: np.ndarray) -> str:
        """What sampling time 0 depends on besides the config: x(0) and the runtime values in force."""
        values = self.record.parameters[0] if self.record.parameters else {}
        return repr((np.asarray(x, dtype=float).tobytes(), json_ready(values)))

    def _runtime_values(self, t: int, x: np.ndarray) -> None:
        """The runtime values of sampling time t in force (the declared ones at its time, data files interpolated at
        its stages' times, and what the ``parameters`` callback gives), recorded and logged."""
        game = self.game
        if game.runtime is None and self.parameters is None and not self.references:
            return
        now = t * self.cfg.run.sampling_time
        values = None
        if self.parameters is not None:
            try:
                values = self.parameters(now, x.copy())
            except Exception as exc:
                raise InputError(f"the parameters callback failed at t = {now:g} s: {type(exc).__name__}: "
                                 f"{exc}") from exc
            if values is not None and not isinstance(values, Mapping):
                raise InputError(f"the parameters callback returned {type(values).__name__} at t = {now:g} s; it "
                                 "returns {name: value} (or None)")
        try:
            game.set_parameters(dict(values or {}), now)
        except (InputError, ValueError) as exc:
            raise InputError(f"the parameters callback at t = {now:g} s: {exc}") from None
        record = game.parameters
        references = self.references.at(now, game.p) if self.references else {}
        self.record.parameters.append(record)
        self.record.references.append(references)
        if self.log is not None:
            self.log.parameters(t, record, references)

    def _diverged(self, t: int, size_of_x: float) -> str:
        limit, plant = self.cfg.solver.divergence_limit, self.cfg.disturbance.plant
        return (f"K={self.K} t={t}: the plant's state x(t + 1) "
                + ("is not finite" if math.isinf(size_of_x) else
                   f"reached |x| = {size_of_x:.3g}, beyond solver.divergence_limit = {limit:g}")
                + f" (plant disturbance {plant.kind}, scale {plant.scale}); the closed loop ends here (diverged)")

    def run(self) -> ClosedLoopResult:
        cfg, game, rec, log = self.cfg, self.game, self.record, self.log
        steps = cfg.run.steps
        message = ""
        x = np.array(game.x0, dtype=float)
        z_warm = game.z_start()
        applied_z = z_warm  # the plan applied at the last sampling time
        self.z_star_prev, self.rng = game.z_start(), None
        ended, completed = "completed", steps

        for t in range(steps):
            if log is not None:
                log.at(t)
            if self.interrupt is not None and self.interrupt.requested:
                ended, completed = "interrupted", t
                self._interrupted(t)
                break
            rec.xs.append(x)
            self._runtime_values(t, x)
            state, trace, elapsed = self._first_solve(x, z_warm) if t == 0 else self._solve(t, x, z_warm)
            _, final = self.solver.terminate(state)
            try:
                z_star, ref_status = self._z_star(t, x, z_warm, state if final == Status.CONVERGED
                                                  and self.own_reference else None)
            except Stopped:  # a stop request during z*(t): this sampling time is not run
                rec.xs.pop()
                ended, completed = "interrupted", t
                self._interrupted(t, plural=True)
                break
            failed = final in FAILURES
            solved = self._solved(state, final, failed, z_star, ref_status, elapsed)
            if failed:
                self._warn_failed(t, final, state)
            if failed and cfg.run.on_failure == "stop":
                sample = Sample(u=np.full(self.nu, np.nan), w=np.zeros(game.nx), constraint_violation=math.nan,
                                worst_constraint=None, fallback=False, **solved)
                rec.add(sample, None)
                if log is not None:
                    log.sampling_time(t, trace, z_star, x, None, sample)
                ended, completed = "stopped", t + 1
                break
            applied = self.safeguard.apply(x, trace, state.z, state.k, final == Status.CONVERGED, failed,
                                           None if t == 0 else applied_z)
            applied_z = applied.z
            if not failed:
                self._note_fallback(t, applied, state)
            x_next, sample = self._plant_step(x, applied, solved)
            rec.add(sample, x_next)
            if log is not None:  # (the plan's predicted states are for the paths view: computed for the log only)
                with log.run.timed():
                    log.sampling_time(t, trace, z_star, x, sample.u, sample, applied.z[: game.n])
            if self.progress is not None:
                self.progress(StepReport(self.K, t, steps, x.copy(), sample.u.copy(), sample.status,
                                         bool(applied.fallback), float(sample.constraint_violation), int(state.k),
                                         float(state.residual_norm), solved["e_norm"], float(elapsed)))
            size_of_x = float(np.max(np.abs(x_next))) if np.all(np.isfinite(x_next)) else math.inf
            if size_of_x > cfg.solver.divergence_limit:
                ended, completed = "diverged", t + 1
                message = self._diverged(t, size_of_x)
                if log is not None:
                    log.at(t + 1)
                    log.last_state(t + 1, x_next, "diverged")
                    log.log("warning", message)
                break
            x = x_next
            z_next = self.safeguard.next_start(trace, applied, state.z, failed)
            z_warm = game.shift(z_next) if cfg.run.warm_start == "shift" else z_next
        else:
            rec.xs.append(x)
            if log is not None:
                log.at(steps)
                log.last_state(steps, x, "")
                log.run.flush()

        result = rec.result(ended, completed, message)
        result.reference_time_s, result.shares_first = self.reference_time_s, self.shares_first
        return result

    def _solved(self, state, final: Status, failed: bool, z_star: np.ndarray | None, ref_status: str,
                elapsed: float) -> dict:
        """What a sampling time's solve gives its Sample: the errors to z*(t) (NaN without it), the status, z."""
        status = "converged" if final == Status.CONVERGED else str(final) if failed else "incomplete"
        z = state.z
        e = math.nan if z_star is None else float(np.linalg.norm(z - z_star))
        e_agent = {a: math.nan if z_star is None else float(np.linalg.norm(z[idx] - z_star[idx]))
                   for a, idx in zip(self.game.agent_names, self.agent_idx, strict=True)}
        return dict(e_norm=e, e_norm_agent=e_agent, residual_norm=state.residual_norm, iterations=state.k,
                    solve_time_s=elapsed, status=status, reference_status=ref_status, z=z,
                    z_star=np.full(self.game.size, np.nan) if z_star is None else z_star)

    def _warn_failed(self, t: int, final: Status, state) -> None:
        if self.log is None:
            return
        cfg = self.cfg
        action = ("the closed loop stops here (on_failure: stop)" if cfg.run.on_failure == "stop" else
                  "the plant gets the best plan at hand (safeguard: fallback)"
                  if cfg.run.safeguard == "fallback" else
                  "the plant gets the inputs of the last iterate before it (on_failure: continue)")
        self.log.log("warning", f"K={self.K} t={t}: {final}: {state.message}; {action}")

    def _note_fallback(self, t: int, applied, state) -> None:
        plan = applied.plan
        if plan is not None and applied.fallback and self.log is not None:
            which = "the shifted previous plan" if plan.k < 0 else f"iterate {plan.k}"
            self.log.log("info", f"K={self.K} t={t}: fallback to {which} (||Phi|| {plan.residual_norm:.2e}, first "
                                 f"step violation {plan.violation:.2e}; z^K: ||Phi|| {state.residual_norm:.2e})")

    def _plant_step(self, x: np.ndarray, applied, solved: dict) -> tuple[np.ndarray, Sample]:
        """The applied plan's first inputs into the plant (with its disturbance): x(t + 1) and the sampling time's
        Sample with the first stage's violation."""
        game = self.game
        u = game.first_inputs(applied.z[: game.n])
        w = self.plant()
        with np.errstate(all="ignore"):  # a plant that overflows is reported by run, as a state that diverged
            x_next = game.step_dynamics(x, u) + w
            violation, label = self.stage.violation(x_next, u)
        return x_next, Sample(u=u, w=w, constraint_violation=violation, worst_constraint=label,
                              fallback=applied.fallback, **solved)


def closed_loop(cfg: Config, game: CompiledGame, K: int, run: RunDirectory | None = None,
                progress: Progress | None = None, interrupt: Interrupt | None = None,
                stage: StageConstraints | None = None, record: LoopRecord | None = None,
                parameters: RuntimeCallback | None = None, first: FirstSamplingTime | None = None
                ) -> ClosedLoopResult:
    """One closed loop of ``cfg.run.steps`` sampling times with at most K solver steps each.

    ``run.initial`` says whether the first sampling time is solved without a budget, ``run.safeguard`` which plan
    the plant receives (:mod:`gnerun.runs.safeguard`), ``run.warm_start`` how that plan warm-starts the next
    sampling time. A failed solver step (singular JPhi, NaN, divergence) is recorded in ``status`` and ``/log``; then
    ``run.on_failure`` decides: ``continue`` applies the best plan at hand (safeguard: fallback) or the inputs of the
    last iterate before the failed step (safeguard: none) and goes on, ``stop`` ends this loop at that step. Every
    sampling time reports the largest violation of a stage-0 constraint row at the inputs applied and the state they
    produced (plant disturbance included).
    Nothing is allocated by the number of steps planned: the result's arrays hold the sampling times run.
    A plant state that is not finite, or beyond ``solver.divergence_limit``, ends the loop there (``ended``: diverged),
    with the state it reached. ``record`` (a :class:`LoopRecord`) receives the loop's progress as it is made.
    At every sampling time the game's runtime values are put in force (``parameters(t, x)`` gives any of them).
    ``first`` (a :class:`FirstSamplingTime`) shares sampling time 0's solve to tolerance and z*(0) between the loops
    of several K: the loop that finds it made takes it instead of solving again.
    """
    return ClosedLoop(cfg, game, K, run, progress, interrupt, stage, record, parameters, first).run()


def simulate(cfg: Config, out: str | Path | None = None, *, force: bool = False,
             progress: Progress | None = None, parameters: RuntimeCallback | None = None,
             game: CompiledGame | None = None) -> Simulation:
    """One closed loop per K in ``cfg.run.K``; ``out`` as in :func:`gnerun.solve`. ``parameters(t, x)``, called at
    every sampling time with its time t (seconds) and the plant state x, returns runtime values {name: value} (a
    number, a vector, a matrix, or per-stage values) that replace the declared ones there; nothing is recompiled.
    A callback that raises, or returns a value of the wrong shape, ends the run with an InputError (the log and
    summary.json of the sampling times done are written). ``game``: as in :func:`gnerun.solve`."""
    if cfg.game.kind != "dynamic":
        raise InputError(f"{cfg.source or cfg.name}: simulate needs a dynamic game (game.kind: dynamic); "
                         "solve a static game with gnerun.solve", cli=f"{cfg.source or cfg.name}: simulate needs a "
                         "dynamic game (game.kind: dynamic); use `gnerun solve` for a static game")
    started = time.perf_counter()
    with polled(no_check):  # built in a helper thread: a signal reaches this one at once (KeyboardInterrupt)
        if game is None:
            game = compile_game(cfg)
        else:
            game.adopt(cfg)
        stage = game.derived.get("stage")
        if stage is None:
            stage = game.derived["stage"] = compile_stage_constraints(cfg, game)
        make_solver(cfg, game)  # the sparse system, where the loops take it, is built now: once, before the run
        if cfg.run.warm_start == "shift":
            game.shift_changed_rows  # noqa: B018 (found once, before the loop: it evaluates c at a test point)
    sim = Simulation()
    sim.compile_time_s = time.perf_counter() - started
    run = RunDirectory.create(out, cfg, command="simulate", force=force) if out is not None else None
    sim.game = game
    sim.first = first = FirstSamplingTime()
    sim.run_dir = run.path if run is not None else None
    interrupt = Interrupt()

    def failed(exc: BaseException) -> dict:  # the summary of a run an exception ended: the loops as far as they went
        status, sim.error = ended_by(exc)
        sim.interrupted = status == "interrupted"
        if status == "interrupted":
            sim.error = None
        out = sim.summary()
        out["message"] = ended_by(exc)[1]
        return out

    with recording(run, failed), interrupt.installed(), polled(interrupt.check):  # builds in the loop stop too
        if run is not None:
            run.at(0.0)
            run.log("info", f"simulate {cfg.name}: K = {cfg.run.K}, {cfg.run.steps} steps, warm start "
                            f"{cfg.run.warm_start}, initial {cfg.run.initial}, safeguard {cfg.run.safeguard}, "
                            f"solver {cfg.solver.kind}, solver disturbance "
                            f"{cfg.disturbance.kind}, plant {cfg.disturbance.plant.kind}, on_failure "
                            f"{cfg.run.on_failure}")
            for warning in cfg.size_warnings("simulate"):
                run.log("warning", warning)
        for K in dict.fromkeys(cfg.run.K):
            if interrupt.requested:
                break
            record = LoopRecord(K, cfg.run.steps, game)
            try:
                sim[K] = r = closed_loop(cfg, game, K, run, progress, interrupt, stage, record, parameters, first)
            except Stopped:  # a stop request while something was built: the loop as far as it went
                sim[K] = record.result("interrupted")
                break
            except BaseException as exc:  # the loop as far as it went, for the summary
                status, message = ended_by(exc)
                sim[K] = record.result(status, message=message)
                raise
            if run is not None:
                errors = (f"max e {_nanmax(r.e_norm):.3e}, final e {r.final_e_norm:.3e}" if cfg.run.reference != "none"
                          else "no e (run.reference: none)")
                run.log("info", f"K={K}: {r.ended} after {r.done} sampling time{'s' * (r.done != 1)}, {errors}, "
                                f"failed steps {r.failed_steps}, fallback steps {r.fallback_steps}, max constraint "
                                f"violation {r.max_constraint_violation:.3e}")
        sim.interrupted = interrupt.requested
        if run is not None:
            with run.timed():
                run.write_summary(sim.summary())
    if run is not None:
        sim.log_time_s = run.time_s  # closed: the log's last chunk written
    if sim.interrupted:
        raise KeyboardInterrupt  # after the summary and a finished log: the caller decides what it means
    return sim
