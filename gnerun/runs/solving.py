"""`gnerun solve`: one equilibrium problem, every iterate logged, a certificate at the end.

The driver loop is the only place where the solver meets the log: the solver steps, the loop
writes each iterate to the :class:`~gnerun.mcap_log.RunLog` sink and flushes it.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..game.building import no_check, polled
from ..game.compile import CompiledGame, compile_game
from ..game.kernels import KernelReport, kernel_report
from ..language.config import Config
from ..log import topics
from ..log.mcap_log import json_ready
from ..log.messages import RuntimeValues
from ..solvers.driver import Solver, iterate
from ..solvers.factory import SPARSE_FROM, SPARSE_WORK, formulation, make_solver  # noqa: F401 - the API's names
from ..solvers.globalization import FALLBACK, resolve
from ..solvers.status import FAILURES, SSNState, Status
from .interrupt import Interrupt, Stopped
from .rundir import RunDirectory, ended_by, recording


@dataclass
class Reference:
    """z*: a converged, undisturbed re-solve (the yardstick of error histories)."""

    z: np.ndarray
    status: Status
    residual_norm: float
    iterations: int
    message: str

    @property
    def converged(self) -> bool:
        return self.status == Status.CONVERGED


def reference_solution(game: CompiledGame, cfg: Config, z0: np.ndarray, x: np.ndarray | None = None,
                       polish: int = 3, interrupt: Interrupt | None = None,
                       solvers: dict[int, Solver] | None = None) -> Reference:
    """Solve undisturbed from z0 with the configured method, then by the globalized semismooth Newton method if
    that fails, and polish. ``solvers`` keeps the solvers built for the attempts from one call to the next (a
    closed loop's z*(t)); each forgets its factorisations before it solves, so the result is a new solver's.

    Polishing takes up to ``polish`` further Newton steps while ||Phi|| keeps decreasing, so that z*
    is accurate to rounding, not just to ``solver.tol``. A stop request (``interrupt``) raises
    :class:`~gnerun.runs.interrupt.Stopped` between two iterates.
    """
    check = (lambda state: interrupt.check()) if interrupt is not None else None
    last: SSNState | None = None
    # the exact solution is the centralised one: a distributed run is measured against SSN's
    first = cfg.solver.model_copy(update={"kind": "ssn"}) if cfg.solver.kind == "distributed" else cfg.solver
    attempts = [first] + ([first.model_copy(update={"kind": "ssn", "globalization": FALLBACK})]
                          if first.kind != "ssn" or resolve(first) != FALLBACK else [])
    for attempt, options in enumerate(attempts):
        opts = options.model_copy(update={"max_iter": max(options.max_iter, 100)})
        if solvers is not None and attempt in solvers:
            solver = solvers[attempt]
            forget = getattr(solver, "forget", None)
            if forget is not None:
                forget()
        else:
            solver = make_solver(cfg.model_copy(update={"solver": opts}), game, disturbed=False)
            if solvers is not None:
                solvers[attempt] = solver
        state = iterate(solver, solver.init(z0, x), on_iterate=check)
        last = state
        if state.converged:
            return polished(solver, state, polish)
    assert last is not None
    return Reference(last.z, last.status, last.residual_norm, last.k, last.message)


def own_reference(cfg: Config) -> bool:
    """Whether the configured method is the reference's, undisturbed (no solver-side disturbance; a distributed run is
    measured against centralised SSN): its converged iterate, polished, is z* itself."""
    return cfg.disturbance.kind == "none" and cfg.solver.kind != "distributed"


def polished(solver: Solver, state: SSNState, polish: int = 3) -> Reference:
    """z* from ``solver``'s converged ``state``: up to ``polish`` further Newton steps while ||Phi|| keeps
    decreasing (accurate to rounding, not just to ``solver.tol``)."""
    polisher = getattr(solver, "polisher", solver)  # its iterations, on from a solution
    for _ in range(polish):
        nxt = polisher.iteration(state)
        if nxt.status != Status.RUNNING or not nxt.residual_norm < state.residual_norm:
            break
        state = nxt
    return Reference(state.z, Status.CONVERGED, state.residual_norm, state.k, state.message)


CERTIFY_RESTARTS = 3  # restarts from the improving players' best responses before not_an_equilibrium
REPEAT_TOL = 1e-9  # a restart's start this close to an earlier one's (relative) is not run: the solve is deterministic


@dataclass
class Certified:
    """The end of :func:`certified_solve`: the last iterate, its certificate, and what the two together say."""

    state: SSNState
    certificate: dict
    improving: dict[str, float]  # agents that can still improve alone (empty: an equilibrium, or not converged)
    restarts: int
    time_s: float  # the solver's time (the certificates excluded)
    status: str = ""  # the solve's status: the solver's, or what the certificate concludes (see conclude)
    message: str = ""
    diagnosis: dict = field(default_factory=dict)  # a failed solve's phase 1 (``infeasibility``), when run
    certificate_time_s: float = 0.0  # the certificates' time (best responses, their builds)
    repeats: int | None = None  # the restart whose start the next one would have repeated (it was not run)


def certified_solve(game: CompiledGame, solver: Solver, state: SSNState, x: np.ndarray | None = None,
                    on_iterate: Callable[[SSNState], None] | None = None,
                    note: Callable[[str], None] | None = None, restarts: int | None = None,
                    best_responses: bool = True, responses=None,
                    on_stage: Callable[[str], None] | None = None, check=None, solved: bool = False) -> Certified:
    """Iterate from ``state`` to the end and certify: converged means that no agent can improve alone. At a KKT
    point where some can (a nonconvex player's saddle or a worse local minimum), those agents move to the best
    responses the certificate found, the multipliers are reset, and the solver starts again from there (one
    iteration), up to ``restarts`` times (default ``CERTIFY_RESTARTS``). ``best_responses=False``: the KKT
    residuals alone (``run.certificate: false``), no best responses and no restarts: a KKT point then ends
    ``kkt_point``. ``responses``: a :class:`~gnerun.solvers.certificate.NewtonResponses` for the best responses
    (SLSQP without); ``on_stage`` is told when the certificate starts; ``check`` is called between agents (a stop
    request may raise there); ``solved``: ``state`` is already where ``iterate`` ended (its iterates shown to
    ``on_iterate`` already), the first certificate is taken there. The status and message are :func:`conclude`'s."""
    from ..solvers.certificate import assess, certificate, kkt_residuals

    restarts = CERTIFY_RESTARTS if restarts is None else restarts
    elapsed = checking = 0.0
    used = 0
    tried: list[np.ndarray] = []  # the restarts' starts (decisions)
    # the last certificate's point, its agents' checks and the agents it could not clear
    last: tuple[np.ndarray, dict, set[str]] | None = None
    while True:
        if solved:
            solved = False
        else:
            t = time.perf_counter()
            state = iterate(solver, state, on_iterate=on_iterate)
            elapsed += time.perf_counter() - t
        if not best_responses:
            return conclude(game, Certified(state, kkt_residuals(game, state.z, x), {}, used, elapsed), x,
                            certified=False)
        best: dict[str, np.ndarray] = {}
        checks: dict = {}
        t = time.perf_counter()
        earlier = None
        if last is not None and state.rng is None and _same_point(state.z, last[0]):
            # a restart that ended where the last certificate was taken (a noise-free solver: the best responses
            # found there lead back here): the agents it cleared stand as it checked them; those that could improve
            # (or were not checked) are checked again here, from their own seeds
            earlier = {name: c for name, c in last[1].items() if name not in last[2]}
            if note is not None:
                note(f"iteration {state.k}: restart {used} ended at the KKT point of the last certificate; "
                     f"{', '.join(sorted(last[2]))} checked again, the others' checks stand")
        elif on_stage is not None:
            on_stage(f"checking the best response of each of {len(game.agent_names)} agents (run.certificate: "
                     "false skips it)")
        cert = certificate(game, state.z, x, best, responses, check, checks, earlier)
        verdict = assess(game, cert, state.z[: game.n], x)
        last = (state.z.copy(), checks, set(verdict.improving) | set(verdict.unchecked))
        checking += time.perf_counter() - t
        improving = verdict.improving if state.status == Status.CONVERGED else {}
        out = Certified(state, cert, improving, used, elapsed, certificate_time_s=checking)
        if (not improving or verdict.unbounded or verdict.not_finite or used >= restarts
                or not all(name in best for name in improving)):
            return conclude(game, out, x)
        z = state.z.copy()
        for i, name in enumerate(game.agent_names):
            if name in improving:
                z[game.agent_slices[i]] = best[name]
        z[game.n:] = 0.0
        # a solver that draws no noise (no rng) is a function of its start: from an earlier restart's start (the same
        # KKT point reached, the same best responses found) a restart would repeat that one's iterations and end there
        a = z[: game.n]
        if state.rng is None:
            out.repeats = next((k + 1 for k, s in enumerate(tried) if _same_point(a, s)), None)
        if out.repeats is not None:
            if note is not None:
                note(f"iteration {state.k}: a KKT point at which {', '.join(improving)} can improve alone; their best "
                     f"responses are where restart {out.repeats} started: no restart again")
            return conclude(game, out, x)
        tried.append(a.copy())
        used += 1
        if note is not None:
            note(f"iteration {state.k}: a KKT point at which {', '.join(improving)} can improve alone; restart "
                 f"{used} from their best responses")
        t = time.perf_counter()
        start = (solver.restart if hasattr(solver, "restart") else solver.init)(z, x, state.rng)
        elapsed += time.perf_counter() - t
        state = replace(start, k=state.k + 1)


def _same_point(z: np.ndarray, earlier: np.ndarray) -> bool:
    """z within ``REPEAT_TOL`` (relative) of an earlier iterate: the same point to a solver without noise."""
    size = max(1.0, float(np.max(np.abs(earlier), initial=0.0)))
    return bool(np.max(np.abs(z - earlier), initial=0.0) <= REPEAT_TOL * size)


def conclude(game: CompiledGame, out: Certified, x: np.ndarray | None = None, certified: bool = True) -> Certified:
    """The solve's status and message from the last iterate and its certificate.

    A KKT point (the solver's ``converged``) is ``converged`` only when every player's best response was checked
    and none improves; otherwise ``nan`` (a cost that is not finite there), ``unbounded_player`` (a player has no
    best response: its cost keeps decreasing along a feasible ray), ``not_an_equilibrium`` (a player improves alone)
    or ``kkt_point`` (best responses not checked: ``run.certificate: false``, or a player's could not be computed).
    A failed solve (the solver's failure statuses and ``max_iter``) is checked for its cause: ``infeasible`` when
    the game's constraints cannot all hold (gnerun.solvers.feasibility), ``unbounded_player`` when the certificate
    at the last iterate found a player without a best response; otherwise the solver's own status stays."""
    from ..solvers.certificate import assess
    from ..solvers.feasibility import phase_one
    state, cert = out.state, out.certificate
    status, message = Status(state.status), state.message
    if status == Status.CONVERGED:
        it = f"{state.k} iteration{'s' * (state.k != 1)}"
        kkt = f"a KKT point (||Phi|| = {state.residual_norm:.2e} after {it})"
        if not certified:
            out.status, out.message = str(Status.KKT_POINT), (
                f"{kkt}, not certified: best responses not checked (run.certificate: false); a KKT point of a game "
                "with nonconvex players may be a saddle or a maximum")
            return out
        verdict = assess(game, cert, state.z[: game.n], x)
        if verdict.not_finite:
            status, message = Status.NAN, (f"{kkt} at which the cost of {', '.join(verdict.not_finite)} is not "
                                           "finite: no equilibrium there")
        elif verdict.unbounded:
            who = "; ".join(f"{name}: {why}" for name, why in verdict.unbounded.items())
            status, message = Status.UNBOUNDED_PLAYER, (
                f"{kkt} at which {', '.join(verdict.unbounded)} has no best response ({who}): not an equilibrium, "
                "and no equilibrium has the other players' decisions as here")
        elif out.improving:
            who = ", ".join(f"{name} by {gap:.2e}" for name, gap in out.improving.items())
            status, message = Status.NOT_AN_EQUILIBRIUM, (
                f"{kkt} that is not an equilibrium: alone, {who} (best response found by the certificate), after "
                f"{out.restarts} restart(s) from the players' best responses"
                + (f" (another would have started where restart {out.repeats} did)" if out.repeats else "")
                + "; a nonconvex player's stationary point, not its minimum (try other start values)")
        elif verdict.unchecked:
            who = "; ".join(f"{name}: {why}" for name, why in verdict.unchecked.items())
            status, message = Status.KKT_POINT, f"{kkt}, not certified: a best response could not be checked ({who})"
        elif out.restarts:
            message += (f" (after {out.restarts} restart(s) from the best responses of players who could improve "
                        "alone at a KKT point)")
    elif status in FAILURES or status == Status.MAX_ITER:
        if status != Status.INFEASIBLE_STAGE_CONSTRAINT:
            a = state.z[: game.n]
            p1 = phase_one(game, x, [a] if np.all(np.isfinite(a)) else [])
            if p1 is not None:
                out.diagnosis["infeasibility"] = {"violation": p1.violation, "rows": p1.rows, "proven": p1.proven,
                                                  "method": p1.method}
                if p1.infeasible:
                    status, message = Status.INFEASIBLE, f"{p1.describe()} (the solver: {message})"
        if status != Status.INFEASIBLE and cert.get("unbounded"):
            verdict = assess(game, cert, state.z[: game.n], x)
            who = "; ".join(f"{name}: {why}" for name, why in verdict.unbounded.items())
            unbounded = f"at the last iterate, {', '.join(verdict.unbounded)} has no best response ({who})"
            if status == Status.INFEASIBLE_STAGE_CONSTRAINT:  # no point satisfies the rows: that comes first
                message += f"; also {unbounded}"
            else:
                status, message = Status.UNBOUNDED_PLAYER, f"{unbounded}; the solver: {message}"
        elif status not in (Status.INFEASIBLE, Status.INFEASIBLE_STAGE_CONSTRAINT) and game.piecewise:
            message += ("; the game has abs, min or max of the decisions, whose derivatives jump at their kinks, so "
                        "its KKT system is discontinuous there and Newton steps cannot converge to an equilibrium at "
                        "a kink: write such a term smoothly (sqrt(u**2 + eps**2) for abs(u)), or as constraints with "
                        "an extra decision (s >= u, s >= -u for s = abs(u))")
    out.status, out.message = str(status), message
    return out


def _smoothable(cfg: Config, game: CompiledGame, outcome: Certified) -> bool:
    """A failed solve of a game with abs, min or max of its decisions, by the default method, whose answer can be
    certified: the smoothing homotopy (gnerun.runs.smoothing) is tried."""
    failed = Status(outcome.status) in FAILURES or outcome.status in (Status.MAX_ITER, Status.NOT_AN_EQUILIBRIUM)
    return (failed and outcome.status not in (Status.INFEASIBLE, Status.INFEASIBLE_STAGE_CONSTRAINT)
            and game.piecewise and cfg.solver.kind == "ssn" and resolve(cfg.solver) == "hybrid" and cfg.run.certificate)


def _smoothed(cfg: Config, game: CompiledGame, solver, outcome: Certified, z0: np.ndarray, x: np.ndarray | None,
              record, note, responses, interrupt: Interrupt, on_stage) -> Certified:
    """The smoothing homotopy after ``outcome`` failed, and the certificate of where it ends on the original game:
    ``converged`` only where every best response is certified there. Where a player improves alone, the homotopy
    starts again from the best responses, up to ``CERTIFY_RESTARTS`` times; otherwise ``outcome`` stays, its
    message saying what the homotopy reached."""
    from ..solvers.certificate import assess, certificate
    from .smoothing import LEVELS, RESTART_FROM, smoothing_homotopy

    if on_stage is not None:
        on_stage("the game has abs, min or max of its decisions: solving smoothed games as they approach it")
    t = time.perf_counter()
    start, k, restarts, total = z0, outcome.state.k + 1, 0, 0
    while True:
        sm = smoothing_homotopy(cfg, start, x, record, k, LEVELS[0] if not restarts else RESTART_FROM)
        if sm is None:
            outcome.message += (f"; smoothing abs, min and max (mu = {LEVELS[0]:g} down to {LEVELS[-1]:g} times the "
                                "start's size) did not converge")
            outcome.time_s += time.perf_counter() - t
            return outcome
        k += sm.iterations
        total += sm.iterations
        best: dict[str, np.ndarray] = {}
        cert = certificate(game, sm.z, x, best, responses, interrupt.check)
        verdict = assess(game, cert, sm.z[: game.n], x)
        how = (f"abs, min and max smoothed within mu of themselves, mu lowered from {sm.levels[0][0]:g} to "
               f"{sm.mu:g} ({total} iterations in smoothed games" +
               (f", {restarts} restart(s) from best responses" if restarts else "") + ")")
        if verdict.certified:
            break
        improving = verdict.improving
        if (restarts >= CERTIFY_RESTARTS or not improving or verdict.unbounded or verdict.not_finite
                or not all(name in best for name in improving)):
            who = ", ".join([*verdict.improving, *verdict.unbounded, *verdict.not_finite, *verdict.unchecked])
            outcome.message += f"; {how} ended at a point that is not certified ({who})"
            outcome.time_s += time.perf_counter() - t
            return outcome
        restarts += 1
        start = sm.z.copy()
        for i, name in enumerate(game.agent_names):
            if name in improving:
                start[game.agent_slices[i]] = best[name]
        start[game.n:] = 0.0
        note(f"the smoothing homotopy ended where {', '.join(improving)} can improve alone: restart {restarts} from "
             "their best responses")
    elapsed = time.perf_counter() - t
    state = replace(solver.init(sm.z, x), k=k)
    note(f"certified at the end of the smoothing homotopy: {how}")
    message = (f"converged by smoothing: an equilibrium where abs, min or max is at its kink, every player's best "
               f"response certified on the original game; {how}; ||Phi|| = {state.residual_norm:.2e} is the "
               f"nonsmooth system's, with one branch's derivative at the kink (the unsmoothed solve: "
               f"{outcome.state.message})")
    return Certified(state, cert, {}, outcome.restarts, outcome.time_s + elapsed, str(Status.CONVERGED), message,
                     outcome.diagnosis, outcome.certificate_time_s)


@dataclass
class SolveResult:
    """The outcome of :func:`solve` (scipy-style: status, message, success, iterations, z)."""

    status: str
    message: str
    iterations: int
    z: np.ndarray
    residual_norm: float
    residual_history: list[float]
    error_history: list[float] | None
    step_norms: list[float]
    active_set_changes: list[int]
    solution: dict
    multipliers: dict
    z_star: np.ndarray | None
    reference_status: str
    certificate: dict
    time_s: float
    compile_time_s: float
    x: np.ndarray
    game: CompiledGame = field(repr=False)
    run_dir: Path | None = None
    parameters: dict = field(default_factory=dict)  # the runtime values the game was solved with
    certificate_time_s: float = 0.0  # the certificate's best responses (excluded from time_s)
    reference_time_s: float = 0.0  # the exact solution z* of the error history (excluded from time_s)
    logging_time_s: float = 0.0  # writing the run directory: log, summary (excluded from time_s)

    @property
    def success(self) -> bool:
        return self.status == Status.CONVERGED

    @property
    def kernels(self) -> KernelReport | None:
        """How the sparse system was evaluated (compiled C or interpreted), where the solve took that formulation."""
        return kernel_report(self.game)

    @property
    def a(self) -> np.ndarray:
        return self.z[: self.game.n]

    @property
    def lam(self) -> np.ndarray:
        return self.z[self.game.n :]

    def _constraint_labels(self) -> dict[str, list[str]]:
        g = self.game
        labels = {name: [c.label for c in g.constraints[sl]]
                  for name, sl in zip(g.agent_names, g.multiplier_slices, strict=True)}
        if g.shared_slice.stop > g.shared_slice.start:
            labels["shared"] = [c.label for c in g.constraints[g.shared_slice]]
        return labels

    def summary(self) -> dict:
        """summary.json."""
        return json_ready({
            "status": self.status,
            "message": self.message,
            "iterations": self.iterations,
            "residual_norm": self.residual_norm,
            "solution": self.solution,
            "multipliers": self.multipliers,
            "constraints": self._constraint_labels(),
            "residual_history": self.residual_history,
            "error_history": self.error_history,
            "step_norm_history": self.step_norms,
            "active_set_changes": self.active_set_changes,
            "reference": {"status": self.reference_status},
            "certificate": self.certificate,
            "x": self.x.tolist(),
            "z": self.z.tolist(),
            "z_star": None if self.z_star is None else self.z_star.tolist(),
            "time_s": self.time_s,
            "certificate_time_s": self.certificate_time_s,
            "compile_time_s": self.compile_time_s,
            **({"kernels": self.kernels.as_dict()} if self.kernels is not None else {}),
            **({"parameters": self.parameters} if self.parameters else {}),
        })


def solve(cfg: Config, out: str | Path | None = None, *, force: bool = False,
          on_iterate: Callable[[SSNState, float | None], None] | None = None,
          on_stage: Callable[[str], None] | None = None, parameters: dict | None = None,
          game: CompiledGame | None = None) -> SolveResult:
    """Solve the config's game (a static game, or a dynamic game at its x0).

    ``out=None`` writes nothing; otherwise ``out`` becomes a run directory with
    ``config.yaml``, ``run.mcap`` (every iterate, flushed as it is made) and ``summary.json``.
    ``on_iterate(state, error_norm)`` sees every iterate as it is made (error_norm = ||z^k - z*||);
    ``on_stage(text)`` is told what a long solve is doing besides iterating (the exact solution, the certificate).
    ``parameters`` ({name: value}) gives runtime values in place of the declared ones (at time t = 0). ``game``: a
    game compiled from a config that differs from ``cfg`` in runtime values and x0 at most, used for ``cfg`` without
    compiling again (:meth:`~gnerun.game.compile.CompiledGame.adopt`).
    """
    t0 = time.perf_counter()
    with polled(no_check):  # built in a helper thread: a signal reaches this one at once (KeyboardInterrupt)
        game = compile_game(cfg) if game is None else game.adopt(cfg)
        solver = make_solver(cfg, game)  # with the sparse system, where the solver takes that formulation
        compile_time = time.perf_counter() - t0
        game.set_parameters(parameters)
        game.kkt_residual(game.z_start(), game.x0)  # built now: what an interrupted solve reports is read from it
    run = RunDirectory.create(out, cfg, command="solve", force=force) if out is not None else None
    interrupt = Interrupt()
    seen: list[SSNState] = []  # the iterates made, for the summary of a solve that an exception ends
    doing = ["solving"]

    def watched(state: SSNState, error_norm: float | None) -> None:
        seen.append(state)
        if on_iterate is not None:
            on_iterate(state, error_norm)

    def stage(text: str) -> None:
        doing[0] = text
        if on_stage is not None:
            on_stage(text)

    def failed(exc: BaseException) -> dict:
        return failed_solve_summary(exc, game, seen, doing[0], time.perf_counter() - t0, compile_time)

    with recording(run, failed), interrupt.installed(), polled(interrupt.check):  # builds (the certificate's) stop too
        result = _solve(cfg, game, solver, run, compile_time, watched, interrupt, stage)
    if run is not None:
        result.logging_time_s = run.time_s  # closed: the log's last chunk written
    if result.status == INTERRUPTED:
        raise KeyboardInterrupt  # after the summary and a finished log: the caller decides what it means
    return result


INTERRUPTED = "interrupted"  # the status of a solve stopped by Ctrl-C, SIGTERM or SIGHUP


def failed_solve_summary(exc: BaseException, game: CompiledGame, seen: list[SSNState], doing: str, elapsed: float,
                         compile_time: float) -> dict:
    """summary.json of a solve that an exception ended (status error, or interrupted at once by a second signal): the
    message with what the solve was doing, and the last iterate made."""
    status, message = ended_by(exc)
    last = seen[-1] if seen else None
    z = last.z if last is not None else game.z_start()
    return json_ready({
        "status": status,
        "message": f"{message} (while {doing})" if status == "error" else message,
        "iterations": last.k if last is not None else 0,
        "residual_norm": last.residual_norm if last is not None else None,
        "solution": game.solution_by_agent(z[: game.n]),
        "multipliers": game.multipliers_by_agent(z[game.n:]),
        "residual_history": [s.residual_norm for s in seen],
        "z": z.tolist(),
        "x": None if game.x0 is None else np.asarray(game.x0, dtype=float).tolist(),
        "time_s": elapsed,
        "compile_time_s": compile_time,
    })


def _solve(cfg: Config, game: CompiledGame, solver: Solver, run: RunDirectory | None,
           compile_time: float, on_iterate: Callable[[SSNState, float | None], None] | None,
           interrupt: Interrupt, on_stage: Callable[[str], None] | None = None) -> SolveResult:
    started = time.perf_counter()
    x = game.x0
    z0 = game.z_start()
    exact = cfg.run.reference == "exact"
    history: list[SSNState] = []
    sink_time = reference_time = 0.0
    ref, z_star = None, None

    def record(state: SSNState) -> None:
        interrupt.check()  # before the iterate is counted: the last one recorded is the result
        keep(state)

    def keep(state: SSNState) -> None:
        nonlocal sink_time
        t = time.perf_counter()
        history.append(state)
        error = None if z_star is None else float(np.linalg.norm(state.z - z_star))
        if run is not None:
            run.write_iterate(state, error)
        if on_iterate is not None:
            on_iterate(state, error)
        sink_time += time.perf_counter() - t

    if run is not None:
        _announce(cfg, game, run)

    def note(text: str) -> None:
        if run is not None:
            run.log("info", text)

    from ..solvers.certificate import NewtonResponses

    responses = NewtonResponses(cfg, game, interrupt.check)  # a stop request is honoured between two steps
    # undisturbed, with the configured method, the solve is the reference solve itself (the same solver from the same
    # start): it runs once, and its iterates are recorded when its end, polished, gives z*
    once = exact and own_reference(cfg)
    early: list[SSNState] = []  # the solve's iterates before z* is known (once)
    first, first_time = None, 0.0
    try:
        if exact:
            t = time.perf_counter()
            if once:
                if on_stage is not None:
                    on_stage("solving; the iterates are shown when its end, polished, gives the exact solution z* of "
                             "their error norms (run.reference: none shows them as they come)")
                first = iterate(solver, solver.init(z0, x), on_iterate=lambda s: (interrupt.check(), early.append(s)))
                first_time = time.perf_counter() - t
                t = time.perf_counter()
            elif on_stage is not None:
                on_stage("solving for the exact solution z* of the error norms (run.reference: none skips it)")
            if first is not None and first.status == Status.CONVERGED:
                ref = polished(solver, first)
            else:  # the fallback method of reference_solution too, where the solve did not converge
                ref = reference_solution(game, cfg, z0, x, interrupt=interrupt)
            reference_time = time.perf_counter() - t
            z_star = ref.z if ref.converged else None
            if run is not None and not ref.converged:
                run.log("warning", f"the undisturbed reference solve did not converge ({ref.message}); "
                                   "error norms are not available")
            for s in early:
                keep(s)
        replayed = sink_time  # the early iterates' recording: not the solver's time
        outcome = certified_solve(game, solver, first if first is not None else solver.init(z0, x), x, record, note,
                                  best_responses=cfg.run.certificate, responses=responses,
                                  on_stage=on_stage, check=interrupt.check, solved=first is not None)
        outcome.time_s += first_time + replayed  # (the sink's time is taken off below)
    except Stopped:
        if early and not history:  # stopped before z* was known: the iterates made, without error norms
            z_star = None
            for s in early:
                keep(s)
        return _interrupted(cfg, game, run, history, z_star, ref, interrupt,
                            time.perf_counter() - started - sink_time, compile_time)
    if _smoothable(cfg, game, outcome):
        try:
            outcome = _smoothed(cfg, game, solver, outcome, z0, x, record, note, responses, interrupt, on_stage)
        except Stopped:
            return _interrupted(cfg, game, run, history, z_star, ref, interrupt,
                                time.perf_counter() - started - sink_time, compile_time)
    state, cert = outcome.state, outcome.certificate
    elapsed = outcome.time_s - sink_time  # the solver alone: the sink's I/O and the certificate are excluded
    if exact and outcome.restarts and state.status == Status.CONVERGED:  # the equilibrium reached, polished
        t = time.perf_counter()
        ref = reference_solution(game, cfg, state.z, x)
        reference_time += time.perf_counter() - t
        z_star = ref.z if ref.converged else None
    if outcome.diagnosis:
        cert = {**cert, **outcome.diagnosis}
    result = _result(game, outcome, history, z_star, ref, cert, elapsed, compile_time, x, run)
    result.reference_time_s = reference_time
    if run is not None:
        run.log("info" if result.success else "warning", f"status {result.status}: {result.message}")
        with run.timed():
            run.write_summary(result.summary())
    return result


def _announce(cfg: Config, game: CompiledGame, run: RunDirectory) -> None:
    run.log("info", f"solve {cfg.name}: {game.n} decisions, {game.m} multipliers, {cfg.solver.kind} "
                    f"({cfg.solver.complementarity}), disturbance {cfg.disturbance.kind}")
    for warning in cfg.size_warnings("solve"):
        run.log("warning", warning)
    if game.runtime is not None:
        run.write(topics.SOLVE_PARAMETERS, RuntimeValues.of(0, game.parameters))


def _result(game: CompiledGame, outcome, history: list[SSNState], z_star: np.ndarray | None, ref, cert: dict,
            elapsed: float, compile_time: float, x, run: RunDirectory | None) -> SolveResult:
    """A finished solve's result: its histories (errors to z* where there is one) and its certificate."""
    state = outcome.state
    errors = None if z_star is None else [float(np.linalg.norm(s.z - z_star)) for s in history]
    return SolveResult(
        status=outcome.status,
        message=outcome.message,
        iterations=state.k,
        z=state.z,
        residual_norm=state.residual_norm,
        residual_history=[s.residual_norm for s in history],
        error_history=errors,
        step_norms=[s.step_norm for s in history],
        active_set_changes=[s.active_set_changes for s in history],
        solution=game.solution_by_agent(state.z[: game.n]),
        multipliers=game.multipliers_by_agent(state.z[game.n :]),
        z_star=z_star,
        reference_status=str(ref.status) if ref is not None else "skipped",
        certificate=cert,
        time_s=elapsed,
        compile_time_s=compile_time,
        x=np.asarray(x, dtype=float),
        game=game,
        run_dir=run.path if run is not None else None,
        parameters=game.parameters,
        certificate_time_s=outcome.certificate_time_s,
    )


def _interrupted(cfg: Config, game: CompiledGame, run: RunDirectory | None, history: list[SSNState],
                 z_star: np.ndarray | None, ref: Reference | None, interrupt: Interrupt, elapsed: float,
                 compile_time: float) -> SolveResult:
    """The result of a solve stopped on request: the last iterate made, its KKT residuals, status interrupted."""
    from ..solvers.certificate import kkt_residuals

    x = game.x0
    state = history[-1] if history else None
    z = state.z if state is not None else game.z_start()
    k = state.k if state is not None else 0
    residual = state.residual_norm if state is not None else float("nan")
    message = (f"interrupted ({interrupt.reason}) after {k} iteration{'s' * (k != 1)}; the summary holds the last "
               "iterate")
    result = SolveResult(
        status=INTERRUPTED, message=message, iterations=k, z=z, residual_norm=residual,
        residual_history=[s.residual_norm for s in history],
        error_history=None if z_star is None else [float(np.linalg.norm(s.z - z_star)) for s in history],
        step_norms=[s.step_norm for s in history], active_set_changes=[s.active_set_changes for s in history],
        solution=game.solution_by_agent(z[: game.n]), multipliers=game.multipliers_by_agent(z[game.n:]),
        z_star=z_star, reference_status=str(ref.status) if ref is not None else "skipped",
        certificate=kkt_residuals(game, z, x), time_s=elapsed, compile_time_s=compile_time,
        x=np.asarray(x, dtype=float), game=game, run_dir=run.path if run is not None else None)
    if run is not None:
        run.log("warning", f"status {INTERRUPTED}: {message}")
        run.write_summary(result.summary())
    return result
