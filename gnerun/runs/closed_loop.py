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
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..game.building import no_check, polled
from ..game.compile import CompiledGame, StageConstraints, compile_game, compile_stage_constraints
from ..language.config import Config, PlantDisturbance
from ..log.mcap_log import json_ready
from ..log.messages import MpcError, MpcIterate, MpcState
from ..solvers.ssn import FAILURES, Status
from .interrupt import Interrupt, Stopped
from .rundir import RunDirectory, ended_by, recording
from .safeguard import Plan, choose, finite_or_inf, first_step_violation
from .solving import make_solver, reference_solution


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
        })


def _nanmax(v: np.ndarray) -> float:
    finite = v[np.isfinite(v)]
    return float(finite.max()) if finite.size else math.nan


class Simulation(dict[int, ClosedLoopResult]):
    """Closed-loop results indexed by K (``sim[7].e_norm``), and where they were written."""

    run_dir: Path | None = None
    game: CompiledGame | None = None
    interrupted: bool = False

    error: str | None = None  # what ended the run, if an exception did (status error)

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


class LoopRecord:
    """What a closed loop has made so far, sampling time by sampling time: the lists its result is made of. The loop
    fills it as it runs, so that whoever started it can still take the result of the sampling times done when an
    exception ends the loop (:meth:`result`)."""

    def __init__(self, K: int, steps: int, game: CompiledGame):
        self.K, self.steps = K, steps
        self.nx, self.size = game.nx, game.size
        self.nu = sum(len(v) for v in game.variable_names)
        self.agents = game.agent_names
        self.xs: list[np.ndarray] = []  # x(t) of every sampling time begun, then the state the loop ended in
        self.us: list[np.ndarray] = []
        self.ws: list[np.ndarray] = []
        self.e: list[float] = []
        self.e_agent: dict[str, list[float]] = {a: [] for a in self.agents}
        self.res: list[float] = []
        self.its: list[int] = []
        self.times: list[float] = []
        self.viol: list[float] = []
        self.worst: list[str | None] = []  # the last of a sampling time's lists to be filled
        self.fallback: list[bool] = []
        self.status: list[str] = []
        self.ref_status: list[str] = []
        self.zs: list[np.ndarray] = []
        self.zstars: list[np.ndarray] = []
        self.reached: np.ndarray | None = np.array(game.x0, dtype=float)  # the state after the last time done

    def result(self, ended: str, completed: int | None = None, message: str = "") -> ClosedLoopResult:
        """The loop's result: ``completed`` sampling times (default: those fully recorded), every list cut to them."""
        per_step = len(self.worst) if completed is None else completed

        def rows(values: list, width: int, n: int) -> np.ndarray:
            values = values[:n]
            return np.array(values, dtype=float).reshape(len(values), width)

        if ended == "completed":
            xs = self.xs[:per_step + 1]
        elif ended in ("diverged", "error") and self.reached is not None:
            xs = [*self.xs[:per_step], self.reached]  # and the state the last sampling time done reached
        else:
            xs = self.xs[:per_step]
        return ClosedLoopResult(
            K=self.K, x=rows(xs, self.nx, len(xs)), u=rows(self.us, self.nu, per_step),
            w=rows(self.ws, self.nx, per_step), e_norm=np.array(self.e[:per_step], dtype=float),
            e_norm_agent={a: np.array(v[:per_step], dtype=float) for a, v in self.e_agent.items()},
            residual_norm=np.array(self.res[:per_step], dtype=float),
            iterations=np.array(self.its[:per_step], dtype=int),
            solve_time_s=np.array(self.times[:per_step], dtype=float), status=self.status[:per_step],
            reference_status=self.ref_status[:per_step],
            constraint_violation=np.array(self.viol[:per_step], dtype=float), worst_constraint=self.worst[:per_step],
            fallback=np.array(self.fallback[:per_step], dtype=bool), z=rows(self.zs, self.size, per_step),
            z_star=rows(self.zstars, self.size, per_step), completed=per_step, ended=ended, planned=self.steps,
            message=message)


def closed_loop(cfg: Config, game: CompiledGame, K: int, run: RunDirectory | None = None,
                progress: Progress | None = None, interrupt: Interrupt | None = None,
                stage: StageConstraints | None = None, record: LoopRecord | None = None) -> ClosedLoopResult:
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
    """
    solver = make_solver(cfg, game)
    stage = stage if stage is not None else compile_stage_constraints(cfg)
    steps = cfg.run.steps
    nx, size = game.nx, game.size
    nu = sum(len(v) for v in game.variable_names)
    plant = PlantNoise(cfg.disturbance.plant, nx)
    agents = game.agent_names
    agent_idx = [game.agent_indices(i) for i in range(len(agents))]
    guard = cfg.run.safeguard == "fallback"
    shift = cfg.run.warm_start == "shift"

    x = np.array(game.x0, dtype=float)
    rec = record if record is not None else LoopRecord(K, steps, game)
    xs, us, ws, e, e_agent, res, its, times = rec.xs, rec.us, rec.ws, rec.e, rec.e_agent, rec.res, rec.its, rec.times
    viol, worst, fallback, status, ref_status = rec.viol, rec.worst, rec.fallback, rec.status, rec.ref_status
    zs, zstars = rec.zs, rec.zstars
    exact = cfg.run.reference == "exact"  # z*(t) and e(t), or neither (run.reference: none)
    unknown = np.full(size, np.nan)
    limit = cfg.solver.divergence_limit
    message = ""

    z_warm = game.z_start()
    applied = z_warm  # the plan applied at the last sampling time
    z_star_prev = game.z_start()
    rng = None
    topic = f"/K{K}/mpc"
    ended, completed = "completed", steps

    def record(t: int, trace: list, z_star: np.ndarray | None, x: np.ndarray, u: np.ndarray | None) -> None:
        """Sampling time t in the log (flushed): its iterates, the state with the inputs applied, the error."""
        for k, r, zk in trace:
            err = None if z_star is None else float(np.linalg.norm(zk - z_star))
            run.write(f"{topic}/iterate", MpcIterate(t=t, k=k, residual_norm=r, error_norm=err))
        run.write(f"{topic}/state", MpcState(t=t, x=x.tolist(), u=None if u is None else u.tolist(),
                                             status=status[t], fallback=bool(fallback[t]),
                                             constraint_violation=float(viol[t])))
        run.write(f"{topic}/error", MpcError(t=t, e_norm=e[t], e_norm_agent={a: v[t] for a, v in e_agent.items()}))
        run.flush()

    for t in range(steps):
        if run is not None:  # the log's time axis is the loop's own
            run.at(t * cfg.run.sampling_time)
        if interrupt is not None and interrupt.requested:
            ended, completed = "interrupted", t
            if run is not None:
                run.log("warning", f"K={K}: interrupted ({interrupt.reason}) after {t} sampling time{'s' * (t != 1)}")
            break
        xs.append(x)
        # z*(t): the solution the solver reaches from the same warm start with an unlimited budget (so that e(t)
        # measures the effect of the budget K, on the branch the loop follows when equilibria are not unique);
        # then from z*(t-1), then cold
        if not exact:
            z_star = None
            ref_status.append("skipped")
        else:
            try:
                ref = reference_solution(game, cfg, z_warm, x, interrupt=interrupt)
                for start in (z_star_prev, game.z_start()):
                    if ref.converged:
                        break
                    ref = reference_solution(game, cfg, start, x, interrupt=interrupt)
            except Stopped:  # a stop request during z*(t): this sampling time is not run
                xs.pop()
                ended, completed = "interrupted", t
                if run is not None:
                    run.log("warning", f"K={K}: interrupted ({interrupt.reason}) after {t} sampling times")
                break
            z_star = ref.z if ref.converged else None
            ref_status.append(str(ref.status))
        if z_star is not None:
            z_star_prev = z_star
        elif run is not None and exact:
            run.log("warning", f"K={K} t={t}: the exact solution z*(t) was not found ({ref.message}); "
                               "e(t) is not available")

        # run.initial: solve: the first sampling time without a budget (the solver's max_iter)
        budget = cfg.solver.max_iter if t == 0 and cfg.run.initial == "solve" else K
        t0 = time.perf_counter()
        state = solver.init(z_warm, x, rng)
        elapsed = time.perf_counter() - t0
        trace = [(0, state.residual_norm, state.z)]
        for _ in range(budget):
            if solver.terminate(state)[1] in FAILURES | {Status.CONVERGED}:
                break
            t0 = time.perf_counter()
            state = solver.step(state)
            elapsed += time.perf_counter() - t0
            if state.status in FAILURES:
                break
            trace.append((state.k, state.residual_norm, state.z))
        rng = state.rng
        done, final = solver.terminate(state)
        failed = final in FAILURES
        if final == Status.CONVERGED:
            status.append("converged")
        elif failed:
            status.append(str(final))
        else:
            status.append("incomplete")

        z = state.z
        zs.append(z)
        res.append(state.residual_norm)
        its.append(state.k)
        times.append(elapsed)
        zstars.append(unknown if z_star is None else z_star)
        e.append(math.nan if z_star is None else float(np.linalg.norm(z - z_star)))
        for a, idx in zip(agents, agent_idx, strict=True):
            e_agent[a].append(math.nan if z_star is None else float(np.linalg.norm(z[idx] - z_star[idx])))
        if failed and run is not None:
            action = ("the closed loop stops here (on_failure: stop)" if cfg.run.on_failure == "stop" else
                      "the plant gets the best plan at hand (safeguard: fallback)" if guard else
                      "the plant gets the inputs of the last iterate before it (on_failure: continue)")
            run.log("warning", f"K={K} t={t}: {final}: {state.message}; {action}")
        if failed and cfg.run.on_failure == "stop":
            us.append(np.full(nu, np.nan))
            ws.append(np.zeros(nx))
            viol.append(math.nan)
            worst.append(None)
            fallback.append(False)
            if run is not None:
                record(t, trace, z_star, x, None)
            ended, completed = "stopped", t + 1
            break
        if guard and final != Status.CONVERGED:
            plan = _safeguarded(game, solver, stage, x, trace, plan_prev=None if t == 0 else applied)
            applied = plan.z
            fallback.append(failed or plan.k != state.k)
            if fallback[t] and run is not None and not failed:
                which = "the shifted previous plan" if plan.k < 0 else f"iterate {plan.k}"
                run.log("info", f"K={K} t={t}: fallback to {which} (||Phi|| {plan.residual_norm:.2e}, first step "
                                f"violation {plan.violation:.2e}; z^K: ||Phi|| {state.residual_norm:.2e})")
        else:
            # the paper's rule: z^K(t); after a failed step the last iterate before it (a diverged or NaN one is not
            # used)
            applied = trace[-1][2] if failed else z
            fallback.append(failed)
        u = game.first_inputs(applied[: game.n])
        us.append(u)
        w = plant()
        ws.append(w)
        with np.errstate(all="ignore"):  # a plant that overflows is reported below, as a state that diverged
            x_next = game.step_dynamics(x, u) + w
            violation, label = stage.violation(x_next, u)
        viol.append(violation)
        worst.append(label)
        rec.reached = x_next

        if run is not None:
            record(t, trace, z_star, x, u)
        if progress is not None:
            progress(StepReport(K, t, steps, x.copy(), u.copy(), status[t], bool(fallback[t]), float(viol[t]),
                                int(its[t]), float(res[t]), e[t], float(elapsed)))
        size_of_x = float(np.max(np.abs(x_next))) if np.all(np.isfinite(x_next)) else math.inf
        if size_of_x > limit:
            ended, completed = "diverged", t + 1
            message = (f"K={K} t={t}: the plant's state x(t + 1) " + ("is not finite" if math.isinf(size_of_x) else
                       f"reached |x| = {size_of_x:.3g}, beyond solver.divergence_limit = {limit:g}")
                       + f" (plant disturbance {cfg.disturbance.plant.kind}, scale {cfg.disturbance.plant.scale}); "
                       "the closed loop ends here (diverged)")
            if run is not None:
                run.at((t + 1) * cfg.run.sampling_time)
                run.write(f"{topic}/state", MpcState(t=t + 1, x=x_next.tolist(), u=None, status="diverged",
                                                     fallback=False, constraint_violation=None))
                run.log("warning", message)
            break

        x = x_next
        # the solver goes on from its own iterates (time-distributed optimisation), even where the plant got another
        # plan: from the best of them (a nonmonotone method's last iterate may have climbed), or from the plan
        # applied when no step was taken
        z_next = min(trace[1:], key=lambda it: finite_or_inf(it[1]))[2] if guard and len(trace) > 1 else \
            applied if failed else z
        z_warm = game.shift(z_next) if shift else z_next
    else:
        xs.append(x)
        if run is not None:
            run.at(steps * cfg.run.sampling_time)
            run.write(f"{topic}/state", MpcState(t=steps, x=x.tolist(), u=None, status="", fallback=False,
                                                 constraint_violation=None))
            run.flush()

    return rec.result(ended, completed, message)


def _safeguarded(game: CompiledGame, solver, stage: StageConstraints, x: np.ndarray, trace: list,
                 plan_prev: np.ndarray | None) -> Plan:
    """The plan to apply (gnerun.runs.safeguard): among the iterates of this sampling time (the last first) and the
    fallback plan, the plan applied at t - 1 shifted (at t = 0 the warm start z^0)."""
    candidates = [Plan(zk, r, first_step_violation(game, stage, x, zk), k) for k, r, zk in reversed(trace[1:])]
    if plan_prev is None:
        zf, merit = trace[0][2], trace[0][1]
    else:
        zf = game.shift(plan_prev)
        merit = trace[0][1] if np.array_equal(zf, trace[0][2]) else solver.init(zf, x).residual_norm
    candidates.append(Plan(zf, merit, first_step_violation(game, stage, x, zf), -1))
    return choose(candidates)


def simulate(cfg: Config, out: str | Path | None = None, *, force: bool = False,
             progress: Progress | None = None) -> Simulation:
    """One closed loop per K in ``cfg.run.K``; ``out`` as in :func:`gnerun.solve`."""
    if cfg.game.kind != "dynamic":
        raise InputError(f"{cfg.source or cfg.name}: simulate needs a dynamic game (game.kind: dynamic); "
                         "solve a static game with gnerun.solve", cli=f"{cfg.source or cfg.name}: simulate needs a "
                         "dynamic game (game.kind: dynamic); use `gnerun solve` for a static game")
    with polled(no_check):  # built in a helper thread: a signal reaches this one at once (KeyboardInterrupt)
        game = compile_game(cfg)
        stage = compile_stage_constraints(cfg)
        if cfg.run.warm_start == "shift":
            game.shift_changed_rows  # noqa: B018 (found once, before the loop: it evaluates c at a test point)
    run = RunDirectory.create(out, cfg, command="simulate", force=force) if out is not None else None
    sim = Simulation()
    sim.game = game
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
                sim[K] = r = closed_loop(cfg, game, K, run, progress, interrupt, stage, record)
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
            run.write_summary(sim.summary())
    if sim.interrupted:
        raise KeyboardInterrupt  # after the summary and a finished log: the caller decides what it means
    return sim
