"""`python -m benchmarks`: gnerun's speed against baselines run in the same process.

(`python -m benchmarks robustness` runs the robustness suite instead: benchmarks/robustness.py; `python -m benchmarks
certificate` what the certificate costs next to the solve: benchmarks/certificate.py; `python -m benchmarks identical
record|compare OUT.npz` whether a change left every iterate and status as it was: benchmarks/identical.py; `python -m
benchmarks runtime` what runtime parameters cost per iteration against constants: benchmarks/runtime.py; `python -m
benchmarks montecarlo` random merges solved with one compiled game: benchmarks/montecarlo.py; `python -m benchmarks
stages` the sparse formulation's banded factorisation against SuperLU: benchmarks/stages.py; `python -m benchmarks
condensed` the condensed KKT function compiled against interpreted on the FK library and the paper's game, iterate by
iterate: benchmarks/condensed.py; `python -m benchmarks wall` what the certificate adds to the wall time of one
`gnerun solve` process: benchmarks/wall.py.)

Prints a markdown table and writes JSON to benchmarks/results/. Every number is a median over repeats;
every ratio is baseline time / gnerun time, both measured here, in this run.

Measured:
- paper game (configs/paper_study1.yaml), T = 10: one SSN iteration (`solver.step`, along a solve from
  z = 0); whole solves against the straightforward dense SSN (Jacobian rebuilt from a CasADi evaluation,
  np.linalg.solve; the same iterates) and scipy.optimize.root on the Fischer-Burmeister system; the same
  at T = 100 (where the automatic choice is the sparse formulation);
- one closed-loop step of the paper's Study 2 with K = 7 (warm start, K steps at most, plant update), with
  logging off and with MCAP logging on (the messages `gnerun simulate` writes, flushed every step);
- the scalable family of benchmarks/family.py over N agents and horizons T: time per iteration with one
  solver (what is kept per active set reused) and with a fresh solver (every factorisation new);
- the sparse formulation's factorisation (benchmarks/stages.py): banded LU on the stage order against SuperLU on
  the matrices a solve factorises (merge at 21 and 41 knots, intersection, 6-robot formation ring, bounded LQ at
  T = 40, 80), the structure's limit (one banded LU's flops at a dense 39 x 39 LU's GFLOP/s), and the time per
  iteration on the merge and the intersection with each, as a multiple of the limit;
- `gnerun --help` (a fresh process) and the config load + compile time of the paper game;
- if nashopt is installed (`pip install -e ".[bench]"`), nashopt's solvers on configs/variational_gne.yaml,
  a game both can state (benchmarks/peers.py).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small dense systems: threads only add overhead

import numpy as np  # noqa: E402
from scipy import optimize  # noqa: E402

from gnerun import __version__  # noqa: E402
from gnerun.game.compile import CompiledGame, compile_game  # noqa: E402
from gnerun.language.config import load_config  # noqa: E402
from gnerun.log.mcap_log import RunLog  # noqa: E402
from gnerun.log.messages import MpcError, MpcIterate, MpcState  # noqa: E402
from gnerun.runs.solving import formulation, make_solver  # noqa: E402
from gnerun.solvers import hybrid, interior_point  # noqa: E402
from gnerun.solvers.driver import iterate  # noqa: E402
from gnerun.solvers.status import Status  # noqa: E402

from . import peers  # noqa: E402
from .family import family_config  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
RESULTS = Path(__file__).resolve().parent / "results"


def _median_time(fn, repeats: int, inner: int | None = None) -> float:
    """Median over ``repeats`` samples of the time of one call; each sample runs long enough (>= 20 ms) for
    the clock and the machine's noise."""
    t0 = time.perf_counter()
    fn()  # warm up
    once = time.perf_counter() - t0
    if inner is None:
        inner = max(1, int(0.02 / max(once, 1e-7)))
    samples = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(inner):
            fn()
        samples.append((time.perf_counter() - t0) / inner)
    return statistics.median(samples)


# gnerun ------------------------------------------------------------------------------------------


def gnerun_solve(cfg, game: CompiledGame):
    """A cold solve from the config's start; returns (iterations, final state)."""
    solver = make_solver(cfg, game)

    def run():
        return iterate(solver, solver.init())

    return solver, run


def per_iteration(cfg, game: CompiledGame, repeats: int) -> tuple[float, float, int, float]:
    """(time per iteration, time per solve, iterations, final ||Phi||) of gnerun's SSN: whole solves (the
    evaluation at the start included) with one solver, so what it keeps per active set is reused."""
    _, run = gnerun_solve(cfg, game)
    state = run()
    t = _median_time(run, repeats)
    return t / max(state.k, 1), t, state.k, state.residual_norm


def step_time(cfg, game: CompiledGame, repeats: int) -> float:
    """Median time of one `solver.step` (one iteration: the Newton step and Phi at the new iterate), over
    the iterates of a solve from the config's start."""
    solver, _ = gnerun_solve(cfg, game)
    states: list = []
    iterate(solver, solver.init(), on_iterate=states.append)
    return statistics.mean(_median_time(lambda s=s: solver.step(s), repeats) for s in states[:-1])


def cold_per_iteration(cfg, game: CompiledGame, repeats: int) -> float:
    """Time per iteration of a solve by a fresh solver: every factorisation is new (nothing kept)."""
    samples = []
    for _ in range(repeats):
        solver = make_solver(cfg, game)
        t0 = time.perf_counter()
        state = iterate(solver, solver.init())
        samples.append((time.perf_counter() - t0) / max(state.k, 1))
    return statistics.median(samples)


# baselines ---------------------------------------------------------------------------------------


def dense_ssn(game: CompiledGame, tol: float, max_iter: int = 50, tie_tol: float = 1e-12):
    """The straightforward dense SSN: evaluate L, c and their derivatives (one CasADi call), rebuild JPhi,
    np.linalg.solve. Same min map and tie rule as gnerun."""
    n, m = game.n, game.m
    x = game.x0

    def run():
        z = game.z_start()
        for k in range(max_iter + 1):
            L, c, dL, dc = game._kkt(z[:n], z[n:], x)
            L, c = L.reshape(-1), c.reshape(-1)
            lam = z[n:]
            phi = np.concatenate([L, np.minimum(-c, lam)])
            if np.linalg.norm(phi) <= tol or k == max_iter:
                return z, k, float(np.linalg.norm(phi))
            active = -c < lam - tie_tol
            J = np.zeros((n + m, n + m))
            J[:n] = dL
            J[n:][active, :n] = -dc[active]
            idx = np.flatnonzero(~active)
            J[n + idx, n + idx] = 1.0
            z = z + np.linalg.solve(J, -phi)
        return z, max_iter, float("nan")

    return run


def scipy_root_fb(game: CompiledGame, tol: float):
    """scipy.optimize.root (hybr, exact Jacobian) on the Fischer-Burmeister reformulation of the KKT system."""
    n, m = game.n, game.m
    x = game.x0

    def fun(z):
        L, c, dL, dc = game._kkt(z[:n], z[n:], x)
        L, c = L.reshape(-1), c.reshape(-1)
        a, lam = -c, z[n:]
        r = np.sqrt(a * a + lam * lam)
        phi = np.concatenate([L, a + lam - r])
        with np.errstate(invalid="ignore", divide="ignore"):
            r_safe = np.where(r > 0, r, 1.0)
            da = np.where(r > 0, 1 - a / r_safe, 1 - 1 / np.sqrt(2))
            db = np.where(r > 0, 1 - lam / r_safe, 1 - 1 / np.sqrt(2))
        J = np.zeros((n + m, n + m))
        J[:n] = dL
        J[n:, :n] = -da[:, None] * dc
        J[n + np.arange(m), n + np.arange(m)] = db
        return phi, J

    def run():
        sol = optimize.root(fun, game.z_start(), jac=True, method="hybr", tol=tol * 1e-3)
        return sol.x, sol.nfev, float(np.linalg.norm(fun(sol.x)[0]))

    return run


# closed loop -------------------------------------------------------------------------------------


def closed_loop_step(cfg, game: CompiledGame, K: int, steps: int, log: RunLog | None) -> float:
    """Median time of one closed-loop step: K SSN steps at most from the warm start, first inputs applied,
    plant moved, warm start kept; with ``log``, the messages of `gnerun simulate` written and flushed."""
    solver = make_solver(cfg, game)
    times = []
    for _ in range(3):
        x = np.array(game.x0, dtype=float)
        z_warm = game.z_start()
        for t in range(steps):
            t0 = time.perf_counter()
            trace = []
            state = iterate(solver, solver.init(z_warm, x), K, finish=False,
                            on_iterate=lambda s, trace=trace: trace.append((s.k, s.residual_norm)))
            z = state.z
            u = game.first_inputs(z[: game.n])
            if log is not None:
                for k, r in trace:
                    log.write("/K7/mpc/iterate", MpcIterate(t=t, k=k, residual_norm=r, error_norm=None))
                log.write("/K7/mpc/state", MpcState(t=t, x=x.tolist(), u=u.tolist()))
                log.write("/K7/mpc/error", MpcError(t=t, e_norm=None, e_norm_agent={}))
                log.flush()
            x = game.step_dynamics(x, u)
            z_warm = z
            times.append(time.perf_counter() - t0)
    return statistics.median(times)


# the run -----------------------------------------------------------------------------------------


def _stdout_to_stderr(fn):
    """Call fn with file descriptor 1 pointing at stderr (HiGHS, under nashopt, prints a banner from C)."""
    sys.stdout.flush()
    saved = os.dup(1)
    os.dup2(2, 1)
    try:
        return fn()
    finally:
        sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)



def cli_help_time(repeats: int = 5) -> float:
    exe = Path(sys.executable).parent / "gnerun"
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "gnerun.cli"]
    samples = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        subprocess.run([*cmd, "--help"], capture_output=True, check=True)
        samples.append(time.perf_counter() - t0)
    return statistics.median(samples)


def fresh_solve(cfg, game: CompiledGame, repeats: int) -> tuple[float, object]:
    """Median time of a whole solve by a fresh solver (nothing kept from an earlier solve), and its final state."""
    return paired_fresh_solves([cfg], game, repeats)[0]


def paired_fresh_solves(cfgs: list, game: CompiledGame, repeats: int) -> list[tuple[float, object]]:
    """:func:`fresh_solve` for several configs of one game, their solves taken in turn (a slow moment of a shared
    machine then slows each of them alike, not the one measured at that time): per config, the median time and the
    final state."""
    samples: list[list[float]] = [[] for _ in cfgs]
    states: list = [None] * len(cfgs)
    for r in range(repeats + 1):
        for i, cfg in enumerate(cfgs):
            solver = make_solver(cfg, game)
            t0 = time.perf_counter()
            state = iterate(solver, solver.init())
            if r:  # the first round warms up
                samples[i].append(time.perf_counter() - t0)
            states[i] = state
    return [(statistics.median(ts), st) for ts, st in zip(samples, states, strict=True)]


def robust_rows(row, reps: int, quick: bool) -> None:
    """The globalized default where the local method converges too (its cost per solve, target <= 2x), the bounded
    LQ family against nashopt (target: at least as fast as its fastest successful method), and the time per
    iteration on ALGAMES's merge and intersection (target <= 5 ms)."""
    from .problems import fk, lq, trajectory

    def with_method(cfg, method: str):
        return cfg.model_copy(update={"solver": cfg.solver.model_copy(update={"globalization": method})})

    cases = [("paper game T = 10", load_config(ROOT / "configs" / "paper_study1.yaml")),
             ("nonlinear_gne", load_config(ROOT / "configs" / "nonlinear_gne.yaml"))]
    cases += [(f"FK {p.name} from {p.start}", load_config(text=p.config_yaml)) for p in fk.problems()]
    worst = 0.0
    for name, cfg in cases:
        game = compile_game(cfg)
        (t_local, s_local), (t_default, s_default) = paired_fresh_solves(
            [with_method(cfg, "none"), with_method(cfg, "auto")], game, max(5, reps))
        if s_local.status != Status.CONVERGED:
            continue
        per = (t_default / max(s_default.k, 1)) / (t_local / max(s_local.k, 1))
        worst = max(worst, t_default / t_local)
        row(f"globalized (default) vs local, where both converge: {name}", t_default, "local", t_local,
            target="ratio >= 0.5", met=t_default <= 2 * t_local,
            note=f"{s_default.k} vs {s_local.k} iterations; the default's iteration costs {per:.2f}x the local one")
    row("globalized vs local: the largest whole-solve time ratio (default / local)", None, target="<= 2",
        met=worst <= 2, note=f"{worst:.2f}")
    peers_there = peers.available()
    for T in (5, 20) if quick else lq.HORIZONS:
        for eq in lq.EQUILIBRIA:
            cfg = load_config(text=lq.lq_yaml(T, eq))
            game = compile_game(cfg)
            t_g, s = fresh_solve(cfg, game, max(3, reps // 3))
            note = f"{s.k} iterations, {s.status}; a fresh solver per solve"
            if not peers_there:
                row(f"bounded LQ T = {T}, {eq}: whole solve", t_g, note=note + "; nashopt not installed")
                continue
            results = [r for r in _stdout_to_stderr(lambda T=T, eq=eq: peers.lq_family_peers(
                T, eq, max(3, reps // 4), siconos=False)) if r.success and r.time_s]
            fastest = min(results, key=lambda r: r.time_s, default=None)
            if fastest is None:
                row(f"bounded LQ T = {T}, {eq}: whole solve", t_g, note=note + "; no nashopt method succeeded")
                continue
            row(f"bounded LQ T = {T}, {eq}: whole solve vs nashopt's fastest ({fastest.method})", t_g,
                f"nashopt {fastest.method}", fastest.time_s, target="ratio >= 1", met=fastest.time_s >= t_g,
                note=note)
    for label, problems in (("ALGAMES merge", trajectory.merge_problems(3 if quick else 10)),
                            ("ALGAMES intersection", trajectory.intersection_problems(2 if quick else 5))):
        cfg = load_config(text=problems[0].config_yaml)
        game = compile_game(cfg)
        solver = make_solver(cfg, game)
        # one warm-up solve: what the solver builds once per game (the interior matrix's elimination layout, ~10 ms
        # to order) is not counted per iteration, as in a closed loop or a Monte Carlo of one compiled game
        iterate(solver, solver.init(None, np.asarray(load_config(text=problems[0].config_yaml).game.x0)))
        per, its, whole, decoupled = [], [], [], 0
        for p in problems:
            x0 = np.asarray(load_config(text=p.config_yaml).game.x0)
            t0 = time.perf_counter()
            first = solver.step(solver.init(None, x0))
            t1 = time.perf_counter()
            state = iterate(solver, first)
            t2 = time.perf_counter()
            # the first iteration of a cold merge is the cars' decoupled plans (SLSQP, gnerun.solvers.hybrid): timed
            # apart, the per-iteration time is the Newton and interior-point steps'
            alone = first.search is not None and math.isfinite(first.search.abandon)
            decoupled += alone
            per.append((t2 - t1) / max(state.k - 1, 1) if alone else (t2 - t0) / max(state.k, 1))
            whole.append(t2 - t0)
            its.append(state.k)
        goal = 0.3e-3 if "merge" in label else 0.6e-3  # the structure allows about this (benchmarks/stages.py)
        floor, parts = compiled_calls(solver, problems)
        row(f"{label} ({game.size} unknowns, {formulation(cfg, game)}): one iteration", statistics.median(per),
            target=f"<= {goal * 1e3:g} ms", met=statistics.median(per) <= goal,
            note=f"median over {len(problems)} random initial states, after one warm-up solve; iterations "
                 f"{min(its)}-{max(its)}; whole solve median {statistics.median(whole) * 1e3:.1f} ms"
                 + (f", its first iteration the players' decoupled plans in {decoupled} (not counted here)"
                    if decoupled else "")
                 + f"; the compiled calls alone {us(floor)} per iteration ({parts}), the rest Python and numpy")


# the calls of one iteration into compiled code (gnerun.game.banded's C, the CasADi kernels), by what they compute
_COMPILED = (("interior step", "gnerun.game.banded", "InteriorStep", "__call__"),
             ("Newton point", "gnerun.game.banded", "ReducedPoint", "__call__"),
             ("layouts", "gnerun.game.banded", "KeptLayouts", "__call__"),
             ("LU", "gnerun.game.banded", None, "lu_factor"), ("solves", "gnerun.game.banded", None, "lu_solve"),
             ("solves", "gnerun.game.banded", "EliminatedSolve", "__call__"),
             ("estimate", "gnerun.game.banded", None, "lu_inverse_norm"),
             ("complement", "gnerun.game.banded", "PlayersComplement", "__call__"),
             ("shifts", "gnerun.game.banded", "PlayersComplement", "shifts"),
             ("stage recursion", "gnerun.game.banded", "PlayersDefinite", "__call__"),
             ("CasADi", "gnerun.game.evaluator", "Evaluator", "__call__"))


def compiled_calls(solver, problems) -> tuple[float, str]:
    """The time per iteration spent inside the calls into compiled code (timers around each, in their own solves
    after the timed ones: the timers' cost is not in the row's time), and the share of each: what an iteration costs
    with no Python between the calls."""
    import importlib

    spent: dict[str, float] = dict.fromkeys([label for label, *_ in _COMPILED], 0.0)
    saved = []
    for label, module, cls, name in _COMPILED:
        owner = importlib.import_module(module)
        owner = getattr(owner, cls) if cls else owner
        original = getattr(owner, name)
        saved.append((owner, name, original))

        def timed(*args, _original=original, _label=label, **kwargs):
            t0 = time.perf_counter()
            try:
                return _original(*args, **kwargs)
            finally:
                spent[_label] += time.perf_counter() - t0

        setattr(owner, name, timed)
    steps = 0
    try:
        for p in problems:
            before = dict(spent)
            first = solver.step(solver.init(None, np.asarray(load_config(text=p.config_yaml).game.x0)))
            spent.update(before)  # the first iteration's calls (the decoupled plans) are not counted
            state = iterate(solver, first)
            steps += state.k - 1
    finally:
        for owner, name, original in saved:
            setattr(owner, name, original)
    per = {label: v / max(steps, 1) for label, v in spent.items()}
    return sum(per.values()), ", ".join(f"{label} {us(v)}" for label, v in sorted(per.items(), key=lambda kv: -kv[1]))


def trajectory_iteration_rows(row, quick: bool) -> None:
    """Newton iterations per solve on ALGAMES's random merges and intersections (the default solver, one compiled
    game per scenario; target: a median of at most 15 and every draw converged), against the method as it was
    before Mehrotra's predictor-corrector step (``interior_point.PREDICT_AFTER`` = inf), the hand-over's
    active-set correction (``hybrid.HANDOVER_ROUNDS`` = 0, a refused hand-over retried at 0.1 ||Phi|| instead of
    ``hybrid.HANDOVER_RETRY``), the first-step rule (``hybrid.FIRST_STEP`` = inf), the slack reset
    (``hybrid.RESET_ABOVE`` = inf) and the players' decoupled plans (``hybrid.DECOUPLE_ABOVE`` = inf), in the same run,
    draw by draw. A solve that begins with the decoupled plans counts the decoupled game's solve inside that first
    iteration too (its own iterations are Newton and interior-point steps on the same system): the target is judged on
    that count; the solver's own (one iteration for the decoupled plans) is in the note."""
    from unittest import mock

    from .problems import trajectory

    before = {"HANDOVER_ROUNDS": 0, "HANDOVER_RETRY": 0.1, "FIRST_STEP": math.inf, "RESET_ABOVE": math.inf,
              "DECOUPLE_ABOVE": math.inf}
    for label, problems in (("ALGAMES merges", trajectory.merge_problems(10 if quick else 100)),
                            ("ALGAMES intersections", trajectory.intersection_problems(3 if quick else 20))):
        cfg = load_config(text=problems[0].config_yaml)
        game = compile_game(cfg)
        counts: dict[str, list[tuple[int, bool]]] = {"now": [], "before": []}
        own: list[int] = []  # the solver's own count (the decoupled game's solve one iteration)
        for p in problems:
            x0 = np.asarray(load_config(text=p.config_yaml).game.x0)
            for which in ("now", "before"):
                with contextlib.ExitStack() as stack:
                    if which == "before":
                        stack.enter_context(mock.patch.multiple(hybrid, **before))
                        stack.enter_context(mock.patch.object(interior_point, "PREDICT_AFTER", math.inf))
                    solver = make_solver(cfg, game)
                    state = iterate(solver, solver.init(None, x0))
                inner = getattr(state.search, "alone", 0) if state.search is not None else 0
                counts[which].append((state.k + max(inner - 1, 0), state.status == Status.CONVERGED))
                if which == "now":
                    own.append(state.k)

        def summary(rows: list[tuple[int, bool]]) -> tuple[float, float, int, str]:
            its = [k for k, _ in rows]
            med, p90, ok = statistics.median(its), float(np.percentile(its, 90)), sum(c for _, c in rows)
            return med, p90, ok, f"median {med:g}, p90 {p90:.0f}, {ok}/{len(rows)} converged"

        med, _, ok, now = summary(counts["now"])
        _, _, _, was = summary(counts["before"])
        row(f"{label} ({len(problems)} random draws, {formulation(cfg, game)}): Newton iterations per solve", None,
            target="median <= 15, all converged", met=med <= 15 and ok == len(problems),
            note=f"{now} (the decoupled game's solve counted by its own iterations; as the solver counts, that solve "
                 f"one iteration: median {statistics.median(own):g}, p90 {np.percentile(own, 90):.0f}); before the "
                 f"predictor-corrector step, the hand-over's active-set correction, the first-step rule, the slack "
                 f"reset and the decoupled plans: {was}")


def factorization_rows(row, quick: bool) -> None:
    """The sparse formulation's factorisation: banded LU on the stage order against SuperLU on the same matrices (the
    ones a solve factorises; assembly, LU and condition estimate), the structure's limit (the flops of one banded LU
    at the GFLOP/s of a dense 39 x 39 LU, measured here) and the time per iteration on the merge (the sparse
    formulation forced) and the intersection, with the banded factorisation and with SuperLU, as a multiple of the
    limit (benchmarks/stages.py)."""
    from . import stages
    from .problems import trajectory

    gflops = stages.dense_gflops()
    row("dense 39 x 39 LU (dgetrf): this machine's GFLOP/s at a stage's size", None, note=f"{gflops:.2f} GFLOP/s")
    limits = {}
    for case in stages.cases(quick):
        c = stages.compare(case, repeats=3 if quick else 7)
        limit = c.flops / (gflops * 1e9)
        limits[case.name] = limit
        row(f"{c.name}: one factorisation, banded LU vs SuperLU", c.banded_s, "SuperLU", c.superlu_s,
            target="ratio >= 1", met=c.banded_s <= c.superlu_s,
            note=f"n = {c.size}, kl = {c.lower}, ku = {c.upper}; LU alone {us(c.lu_banded_s)} vs "
                 f"{us(c.lu_superlu_s)}; limit {us(limit)} ({c.flops / 1e6:.2f} MFLOP); solutions agree to "
                 f"{c.difference:.0e} (relative), condition estimates to a factor {c.rcond_ratio:.2f}"
                 + (f" (on the {c.singular} numerically singular matrices of the sample, rcond below min_rcond, which "
                    "the solver refuses, they are not compared)" if c.singular else "")
                 + f"; backward errors at most {c.backward:.0e}")
    for label, problems, limit in (
            ("ALGAMES merge", trajectory.merge_problems(3 if quick else 10), limits["ALGAMES merge, 21 knots"]),
            ("ALGAMES intersection", trajectory.intersection_problems(2 if quick else 5),
             limits["ALGAMES intersection, 41 knots"])):
        cfg = load_config(text=problems[0].config_yaml)
        cfg = cfg.model_copy(update={"solver": cfg.solver.model_copy(update={"formulation": "sparse"})})
        game = compile_game(cfg)
        times = {}
        for banded in (True, False):
            solver = make_solver(cfg, game)
            order = solver.newton.system.stage_order
            order.banded = banded
            order.layouts.clear()  # the layouts kept from the other arm would keep its factorisation
            per, its = [], []
            for rep in range(2):  # the first round warms up (the orderings and layouts of the game)
                for p in problems:
                    x0 = np.asarray(load_config(text=p.config_yaml).game.x0)
                    t0 = time.perf_counter()
                    state = iterate(solver, solver.init(None, x0))
                    if rep:
                        per.append((time.perf_counter() - t0) / max(state.k, 1))
                        its.append(state.k)
            times[banded] = (statistics.median(per), its)
        order.banded = None
        order.layouts.clear()
        (t_band, its_band), (t_lu, its_lu) = times[True], times[False]
        row(f"{label} ({game.size} unknowns, sparse): one iteration, banded LU vs SuperLU", t_band, "SuperLU", t_lu,
            note=f"median over {len(problems)} random initial states, iterations {its_band} (SuperLU {its_lu}); "
                 f"{t_band / limit:.0f}x the structure's limit ({us(limit)} per banded LU)")
    elimination_rows(row, quick)


def elimination_rows(row, quick: bool) -> None:
    """The interior step's matrix factorised with its inequality multipliers eliminated (``interior_point.ELIMINATE``)
    against K as it is: time per iteration on the merge and the intersection in the sparse formulation, one solver,
    the two alternating per initial state (which goes first too), after a round that warms up both. Both take their
    interior steps by the numpy code (``interior_point.FUSED`` off: the compiled step is for the eliminated matrix
    only, and the row is about the elimination)."""
    from .problems import trajectory

    before, fused = interior_point.ELIMINATE, interior_point.FUSED
    interior_point.FUSED = False
    for label, problems in (("ALGAMES merge", trajectory.merge_problems(3 if quick else 10)),
                            ("ALGAMES intersection", trajectory.intersection_problems(2 if quick else 5))):
        cfg = load_config(text=problems[0].config_yaml)
        cfg = cfg.model_copy(update={"solver": cfg.solver.model_copy(update={"formulation": "sparse"})})
        game = compile_game(cfg)
        solver = make_solver(cfg, game)
        per: dict[bool, list[float]] = {True: [], False: []}
        its: dict[bool, list[int]] = {True: [], False: []}
        for rep in range(2):
            for i, p in enumerate(problems):
                x0 = np.asarray(load_config(text=p.config_yaml).game.x0)
                for eliminate in (True, False) if i % 2 == 0 else (False, True):
                    interior_point.ELIMINATE = eliminate
                    t0 = time.perf_counter()
                    state = iterate(solver, solver.init(None, x0))
                    if rep:
                        per[eliminate].append((time.perf_counter() - t0) / max(state.k, 1))
                        its[eliminate].append(state.k)
        interior_point.ELIMINATE = before
        row(f"{label} ({game.size} unknowns, sparse): one iteration, inequality multipliers eliminated vs not "
            "(the interior step by numpy in both)",
            statistics.median(per[True]), "not eliminated", statistics.median(per[False]),
            note=f"median over {len(problems)} random initial states, iterations {its[True]} "
                 f"(not eliminated {its[False]})")
    interior_point.FUSED = fused


def merge_compile_rows(row, cars: tuple[int, ...]) -> None:
    """configs/algames_merge_n.yaml (one file for any N): load and expand, compile, and the first step (which builds
    the derivatives the solver needs), then the rest of a cold solve from zero inputs; the target is the 8-car
    merge compiled, derivatives included, in <= 3 s. Then the same per car in the sparse formulation at every N:
    the target is a compile time per car that does not grow with N (at most 1.5 times the 3-car one at 8 cars,
    whose pairs of cars are 9 times as many)."""
    path = ROOT / "configs" / "algames_merge_n.yaml"
    for N in cars:
        t0 = time.perf_counter()
        cfg = load_config(path, {"game.parameters.N": N})
        t1 = time.perf_counter()
        game = compile_game(cfg)
        solver = make_solver(cfg, game)
        state = solver.step(solver.init())
        t2 = time.perf_counter()
        state = iterate(solver, state)
        t3 = time.perf_counter()
        row(f"ALGAMES merge, N = {N} cars ({game.size} unknowns, {formulation(cfg, game)}): load, compile and first "
            "step", t2 - t0, target="<= 3 s" if N == 8 else "", met=(t2 - t0 <= 3.0) if N == 8 else None,
            note=f"load and expand {us(t1 - t0)}, {us((t2 - t1) / N)} per car; then the solve: {state.k} iterations, "
                 f"{us(t3 - t2)}, {state.status}")
    per_car = {}
    for N in cars:
        t0 = time.perf_counter()
        cfg = load_config(path, {"game.parameters.N": N, "solver.formulation": "sparse"})
        game = compile_game(cfg)
        solver = make_solver(cfg, game)
        solver.step(solver.init())
        per_car[N] = (time.perf_counter() - t0) / N
    first, last = per_car[cars[0]], per_car[cars[-1]]
    row(f"ALGAMES merge, sparse formulation: load, compile and first step per car, N = {cars[-1]}", last,
        target=f"<= 1.5 x N = {cars[0]}", met=last <= 1.5 * first,
        note=", ".join(f"N = {N}: {us(v)}" for N, v in per_car.items()))


def trajectory_loop_rows(row, quick: bool) -> None:
    """Closed loops of the field's trajectory games with the defaults and logging on: ALGAMES's 41-knot MPC merge
    (target >= 40 Hz, median step <= 25 ms) and MCPTrajectoryGameSolver's demo at K = 1, 3, 5, 10 x 50 steps with
    run.reference: none (target <= 60 s wall, compile included). A sampling time's wall time runs from one progress
    report to the next: the solver, the safeguard, the log and the plant."""
    from gnerun import simulate

    def loop(path: Path, overrides: dict, tmp: str | None) -> tuple[list[float], object]:
        marks: list[float] = []
        cfg = load_config(path, overrides)
        t0 = time.perf_counter()
        sim = simulate(cfg, out=None if tmp is None else Path(tmp) / "run", force=True,
                       progress=lambda step: marks.append(time.perf_counter()))
        return [t0, *marks], sim

    steps = 20 if quick else 50
    good, fast, rates = [], [], {}
    for K in (3, 5):
        with tempfile.TemporaryDirectory() as tmp:
            marks, sim = loop(ROOT / "configs" / "algames_merge_mpc.yaml",
                              {"run.K": [K], "run.steps": steps, "run.reference": "none"}, tmp)
        r = sim[K]
        walls = np.diff(marks)[1:]  # t >= 1: the first sampling time is solved without a budget (run.initial)
        hz = walls.size / walls.sum()
        converged = r.status.count("converged")
        if hz >= 40 and np.median(walls) <= 25e-3 and converged > steps / 2:
            good.append(f"K = {K}")
        rates[K] = 1.0 / float(np.median(walls))
        if K == 3 and rates[K] >= 1000 and converged == steps:
            fast.append(f"K = {K}")
        row(f"ALGAMES MPC merge (41 knots, 3 cars), K = {K}: median sampling time, logging on", float(np.median(walls)),
            note=f"{hz:.0f} Hz over t = 1..{steps - 1} (p90 {np.percentile(walls, 90) * 1e3:.1f} ms, max "
                 f"{walls.max() * 1e3:.0f} ms); {converged} of {steps} sampling times converged, "
                 f"{len(r.fallback_steps)} fallback steps, worst violation {r.max_constraint_violation:.1e}; "
                 f"first sampling time (solved) {np.diff(marks)[0]:.2f} s")
    with tempfile.TemporaryDirectory() as tmp:
        marks, sim = loop(ROOT / "configs" / "algames_merge_mpc.yaml",
                          {"run.K": [3], "run.steps": steps, "run.reference": "none", "run.log_writer": "process"}, tmp)
    walls = np.diff(marks)[1:]
    rates["process"] = 1.0 / float(np.median(walls))
    converged = sim[3].status.count("converged")
    if rates["process"] >= 1000 and converged == steps:
        fast.append("K = 3 (run.log_writer: process)")
    row("ALGAMES MPC merge (41 knots, 3 cars), K = 3: median sampling time, logging on, run.log_writer: process",
        float(np.median(walls)), note=f"{rates['process']:.0f} Hz (inline {rates[3]:.0f} Hz); {converged} of {steps} "
                                      "sampling times converged; the log written by a process of its own")
    marks, sim = loop(ROOT / "configs" / "algames_merge_mpc.yaml",
                      {"run.K": [3], "run.steps": steps, "run.reference": "none"}, None)
    walls = np.diff(marks)[1:]
    row("ALGAMES MPC merge (41 knots, 3 cars), K = 3: median sampling time, logging off (no run directory)",
        float(np.median(walls)), note=f"{1.0 / float(np.median(walls)):.0f} Hz; {sim[3].status.count('converged')} "
                                      f"of {steps} sampling times converged: the solver, the safeguard and the plant")
    row("ALGAMES MPC merge: a K with most sampling times converged at >= 40 Hz, median <= 25 ms", None,
        target="one K", met=bool(good), note=", ".join(good) or "none")
    row("ALGAMES MPC merge, K = 3: median sampling rate >= 1 kHz, every sampling time converged", None,
        target=">= 1 kHz", met=bool(fast),
        note=", ".join(fast) or f"{rates[3]:.0f} Hz at K = 3 (inline log), {rates['process']:.0f} Hz (log process)")
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        marks, sim = loop(ROOT / "configs" / "mcp_demo.yaml",
                          {"run.K": [1, 3, 5, 10], "run.steps": 50, "run.reference": "none"}, tmp)
        wall = time.perf_counter() - t0
    worst = max(r.max_constraint_violation for r in sim.values())
    row("MCPTrajectoryGameSolver demo, K = 1, 3, 5, 10 x 50 steps, run.reference: none: wall time", wall,
        target="<= 60 s", met=wall <= 60,
        note=f"compile and logging included; fallback steps {[len(r.fallback_steps) for r in sim.values()]}, "
             f"worst violation {worst:.1e}")


def kernel_rows(row, quick: bool) -> None:
    """Compiled stage kernels (solver.compile): one evaluation of the sparse system and one iteration of solves from
    random states (after one warm-up solve), compiled C against CasADi's interpreter in the same process (the same
    iterates); the compiler's time on an empty cache and the second build's (a cache hit: nothing compiled)."""
    from gnerun.game.sparse import compile_sparse

    from .problems import trajectory

    cases = [("ALGAMES merge, 21 knots", trajectory.merge_problems(3 if quick else 10)),
             ("ALGAMES intersection", trajectory.intersection_problems(2 if quick else 5)),
             ("MPC merge, 41 knots", [load_config(ROOT / "configs" / "algames_merge_mpc.yaml")])]
    with tempfile.TemporaryDirectory() as cache:
        saved = os.environ.get("GNERUN_CACHE_DIR")
        os.environ["GNERUN_CACHE_DIR"] = cache
        try:
            for label, problems in cases:
                cfgs = [p if not hasattr(p, "config_yaml") else load_config(text=p.config_yaml) for p in problems]
                per_mode = {}
                for mode in ("compiled", "interpreted"):
                    cfg = cfgs[0].model_copy(update={"solver": cfgs[0].solver.model_copy(
                        update={"compile": mode, "formulation": "sparse"})})
                    game = compile_game(cfg)
                    t0 = time.perf_counter()
                    system = compile_sparse(cfg, game)
                    built = time.perf_counter() - t0
                    z = game.z_start()
                    t_eval = _median_time(lambda system=system, z=z: system.evaluate(z, None), 7, 20)
                    game.derived["sparse"] = system
                    solver = make_solver(cfg, game)
                    iterate(solver, solver.init(None, np.asarray(cfgs[0].game.x0)))  # warm-up (as in robust_rows)
                    per, its = [], []
                    for c in cfgs * (5 if len(cfgs) == 1 else 1):  # one config: five solves of it (one is noise)
                        t0 = time.perf_counter()
                        state = iterate(solver, solver.init(None, np.asarray(c.game.x0)))
                        per.append((time.perf_counter() - t0) / max(state.k, 1))
                        its.append(state.k)
                    per_mode[mode] = (t_eval, statistics.median(per), its, built, system.kernels)
                (ec, ic, its_c, built_c, rep), (ei, ii, its_i, _, _) = per_mode["compiled"], per_mode["interpreted"]
                row(f"{label}: sparse system evaluation, compiled stage kernels vs interpreted", ec, "interpreted", ei,
                    target="ratio >= 1", met=ei >= ec, note=f"{rep.stages} stage functions for {rep.horizon} stages")
                row(f"{label}: one iteration (sparse), compiled vs interpreted", ic, "interpreted", ii,
                    target="ratio >= 1", met=ii >= ic,
                    note=f"median over {len(its_c)} solves; iterations {its_c} and {its_i}")
                game = compile_game(cfgs[0])
                cfg = cfgs[0].model_copy(update={"solver": cfgs[0].solver.model_copy(
                    update={"compile": "compiled", "formulation": "sparse"})})
                t0 = time.perf_counter()
                again = compile_sparse(cfg, game).kernels
                t_again = time.perf_counter() - t0
                row(f"{label}: sparse system build, a second time (cache hit)", t_again, "first build", built_c,
                    target="cache hit", met=again.cache_hit,
                    note=f"first: gcc {rep.compile_s:.2f} s; the second compiles nothing")
        finally:
            if saved is None:
                del os.environ["GNERUN_CACHE_DIR"]
            else:
                os.environ["GNERUN_CACHE_DIR"] = saved


def us(v: float) -> str:
    return f"{v * 1e6:,.1f} µs" if v < 1e-3 else f"{v * 1e3:,.2f} ms" if v < 1 else f"{v:,.2f} s"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats and a smaller family grid")
    args = parser.parse_args(argv)
    reps = 5 if args.quick else 21
    rows: list[dict] = []

    def row(name: str, gnerun_s: float | None, baseline: str = "", baseline_s: float | None = None,
            target: str = "", met: bool | None = None, note: str = "") -> None:
        ratio = baseline_s / gnerun_s if baseline_s and gnerun_s else None
        rows.append({"benchmark": name, "gnerun_s": gnerun_s, "baseline": baseline, "baseline_s": baseline_s,
                     "ratio": ratio, "target": target, "met": met, "note": note})
        print(f"  {name}: {us(gnerun_s) if gnerun_s else '-'}"
              + (f" vs {baseline} {us(baseline_s)} (x{ratio:.1f})" if ratio else ""), file=sys.stderr, flush=True)

    # 4. CLI start and compile
    t_help = cli_help_time()
    row("`gnerun --help` (fresh process)", t_help, target="<= 0.3 s", met=t_help <= 0.3)
    paper = ROOT / "configs" / "paper_study1.yaml"
    t0 = time.perf_counter()
    cfg = load_config(paper)
    t_load = time.perf_counter() - t0
    t0 = time.perf_counter()
    game = compile_game(cfg)
    make_solver(cfg, game)  # the derivatives the solver needs are built on first use: count them here
    t_compile = time.perf_counter() - t0
    row("paper game: config load", t_load, note="reported")
    row("paper game: compile (parse, condense, differentiate, first solver)", t_compile, note="reported")
    merge_compile_rows(row, (3, 5, 8) if not args.quick else (3, 8))

    # 1. and 3. the paper game at T = 10 and T = 100
    for T, target_dense in ((10, 5.0), (100, 20.0)):
        cfg_T = load_config(paper, {"game.horizon": T})
        game_T = game if T == 10 else compile_game(cfg_T)
        form = formulation(cfg_T, game_T)
        it, solve_t, k, res = per_iteration(cfg_T, game_T, reps)
        dense = dense_ssn(game_T, cfg_T.solver.tol)
        zd, kd, resd = dense()
        t_dense = _median_time(dense, reps)
        size = f"{game_T.size} unknowns, {form}"
        if T == 10:
            st = step_time(cfg_T, game_T, reps)
            row(f"paper game T = {T} ({size}): one SSN iteration (`solver.step`)", st, target="<= 20 µs",
                met=st <= 20e-6, note=f"mean over the {k} iterations of a solve from z = 0; ||Phi|| = {res:.1e}")
        else:
            row(f"paper game T = {T} ({size}): one SSN iteration (whole solve / iterations)", it,
                note=f"{k} iterations, ||Phi|| = {res:.1e}")
        row(f"paper game T = {T}: whole solve vs dense SSN", solve_t, "dense SSN", t_dense,
            target=f"ratio >= {target_dense:g}", met=t_dense / solve_t >= target_dense,
            note=f"gnerun {k} iterations ({us(solve_t / max(k, 1))} each, the start's evaluation included), "
                 f"dense {kd} ({us(t_dense / max(kd, 1))} each), ||Phi|| = {resd:.1e}; the same iterates")
        root = scipy_root_fb(game_T, cfg_T.solver.tol)
        zr, nfev, resr = root()
        t_root = _median_time(root, max(3, reps // 4))
        row(f"paper game T = {T}: whole solve vs scipy.optimize.root (FB)", solve_t, "scipy root", t_root,
            target="ratio >= 50", met=t_root / solve_t >= 50,
            note=f"root: {nfev} evaluations, ||Phi_FB|| = {resr:.1e}; same solution to "
                 f"{np.abs(zr[:game_T.n] - zd[:game_T.n]).max():.0e}")

    # 1. closed loop
    cfg2 = load_config(ROOT / "configs" / "paper_study2.yaml")
    game2 = compile_game(cfg2)
    t_off = closed_loop_step(cfg2, game2, 7, cfg2.run.steps, None)
    row("Study 2 closed-loop step, K = 7, logging off", t_off, target="<= 0.2 ms", met=t_off <= 0.2e-3)
    with tempfile.TemporaryDirectory() as tmp, RunLog(Path(tmp) / "run.mcap", config_yaml="{}", metadata={}) as log:
        t_on = closed_loop_step(cfg2, game2, 7, cfg2.run.steps, log)
    row("Study 2 closed-loop step, K = 7, MCAP logging on", t_on, target="<= 0.3 ms", met=t_on <= 0.3e-3)

    # 2. the family
    grid = {3: (10, 25, 50, 100, 200), 5: (10, 25, 50, 100, 200), 10: (10, 25, 50, 100, 200)}
    if args.quick:
        grid = {3: (10, 50, 200)}
    family: dict[str, dict] = {}
    for N, Ts in grid.items():
        for T in Ts:
            t0 = time.perf_counter()
            cfg_f = family_config(N, T)
            game_f = compile_game(cfg_f)
            make_solver(cfg_f, game_f)  # builds the sparse system or the dense derivatives
            t_c = time.perf_counter() - t0
            form = formulation(cfg_f, game_f)
            it, _, k, res = per_iteration(cfg_f, game_f, max(3, reps // 3))
            cold = cold_per_iteration(cfg_f, game_f, max(3, reps // 3))
            family[f"N{N}-T{T}"] = {"N": N, "T": T, "unknowns": game_f.size, "formulation": form, "iteration_s": it,
                                    "cold_iteration_s": cold, "iterations": k, "residual": res, "compile_s": t_c}
            row(f"family N = {N}, T = {T} ({game_f.size} unknowns, {form}): one iteration", it,
                note=f"{k} iterations; {us(cold)} with a fresh solver (every factorisation new); "
                     f"compile {t_c:.2f} s")
    # the automatic choice of formulation: both, around the crossover
    crossover = [] if args.quick else [(3, 25), (3, 50), (5, 25), (5, 50), (10, 25)]
    for N, T in crossover:
        base = family_config(N, T)
        game_f = compile_game(base)
        times = {}
        for form in ("condensed", "sparse"):
            cfg_f = base.model_copy(update={"solver": base.solver.model_copy(update={"formulation": form})})
            it, _, k, _ = per_iteration(cfg_f, game_f, max(3, reps // 3))
            times[form] = (it, cold_per_iteration(cfg_f, game_f, max(3, reps // 3)))
        auto = formulation(base, game_f)
        (ci, cc), (si, sc) = times["condensed"], times["sparse"]
        row(f"family N = {N}, T = {T} ({game_f.size} unknowns): condensed vs sparse per iteration", si,
            "condensed", ci, note=f"fresh solvers: sparse {us(sc)}, condensed {us(cc)}; auto takes {auto}")
    for N, Ts in grid.items():
        if 50 in Ts and 200 in Ts:
            f200, f50 = family[f"N{N}-T200"], family[f"N{N}-T50"]
            r = f200["iteration_s"] / f50["iteration_s"]
            rc = f200["cold_iteration_s"] / f50["cold_iteration_s"]
            row(f"family N = {N}: t(T = 200) / t(T = 50)", None, target="<= 5", met=max(r, rc) <= 5,
                note=f"{r:.1f} (fresh solver: {rc:.1f})")
            rows[-1]["ratio"] = r

    # 5. robust solving: the globalized default against the local method, the LQ family against its peers, the
    # trajectory games' cost per iteration
    robust_rows(row, reps, args.quick)
    trajectory_iteration_rows(row, args.quick)
    factorization_rows(row, args.quick)

    # 6. closed loops on the trajectory games
    trajectory_loop_rows(row, args.quick)
    kernel_rows(row, args.quick)

    # 3. peers: nashopt (optional extra `bench`) on a game both can state, last (importing it loads JAX)
    if peers.available():
        for r in _stdout_to_stderr(lambda: peers.peer_rows(10, max(3, reps // 4))):
            row(r["benchmark"], r["gnerun_s"], r["baseline"], r["baseline_s"],
                note=f"max |u - u_gnerun| = {r['max_abs_diff']:.1e}; {r['note']}")
    else:
        row("nashopt on configs/variational_gne.yaml", None, note="nashopt not installed (`pip install -e '.[bench]'`)")

    machine = {"python": platform.python_version(), "platform": platform.platform(), "processor":
               platform.processor() or platform.machine(), "cpus": os.cpu_count(),
               "numpy": np.__version__, "openblas_threads": os.environ.get("OPENBLAS_NUM_THREADS")}
    RESULTS.mkdir(parents=True, exist_ok=True)
    stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
    out = RESULTS / f"bench-{stamp}.json"
    out.write_text(json.dumps({"gnerun": __version__, "machine": machine, "rows": rows, "family": family},
                              indent=2))

    print(f"gnerun {__version__}, {machine['processor']}, {machine['cpus']} CPUs, Python {machine['python']}, "
          f"numpy {machine['numpy']}, OPENBLAS_NUM_THREADS={machine['openblas_threads']}\n")
    print("| benchmark | gnerun | baseline | ratio | target | met |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        g = us(r["gnerun_s"]) if r["gnerun_s"] else r["note"]
        b = f"{r['baseline']} {us(r['baseline_s'])}" if r["baseline_s"] else ""
        ratio = f"{r['ratio']:.1f}" if r["ratio"] else ""
        met = "" if r["met"] is None else ("yes" if r["met"] else "**no**")
        print(f"| {r['benchmark']} | {g} | {b} | {ratio} | {r['target']} | {met} |")
    print(f"\nJSON: {out.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    if sys.argv[1:2] == ["robustness"]:
        from .robustness import main as robustness

        sys.exit(robustness(sys.argv[2:]))
    if sys.argv[1:2] == ["certificate"]:
        from .certificate import main as certificate_cost

        sys.exit(certificate_cost(sys.argv[2:]))
    if sys.argv[1:2] == ["runtime"]:
        from .runtime import main as runtime_cost

        sys.exit(runtime_cost(sys.argv[2:]))
    if sys.argv[1:2] == ["montecarlo"]:
        from .montecarlo import main as montecarlo

        sys.exit(montecarlo(sys.argv[2:]))
    if sys.argv[1:2] == ["stages"]:
        from .stages import main as stages_main

        sys.exit(stages_main(sys.argv[2:]))
    if sys.argv[1:2] == ["condensed"]:
        from .condensed import main as condensed

        sys.exit(condensed(sys.argv[2:]))
    if sys.argv[1:2] == ["wall"]:
        from .wall import main as wall

        sys.exit(wall(sys.argv[2:]))
    if sys.argv[1:2] == ["identical"]:
        from .identical import main as identical

        sys.exit(identical(sys.argv[2:]))
    sys.exit(main())
