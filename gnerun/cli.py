"""The `gnerun` command line: thin commands over the library.

Exit codes: 0 success (a run that ended without converging is still a success: its status says so),
2 bad input (config, arguments, unreadable file), 1 anything else. Errors are one line on stderr;
``--debug`` shows the traceback. Heavy modules (numpy, CasADi, scipy, mcap) are imported inside
the commands, so that ``gnerun --help`` stays fast.
"""

from __future__ import annotations

import contextlib
import errno
import os
import sys
import time
import traceback
from collections.abc import Iterator
from pathlib import Path
from typing import Annotated, NoReturn

import typer
from typer.core import TyperCommand

from . import __version__
from .errors import MAX_MESSAGE, InputError, Unavailable, one_line, shorten
from .threads import single_threaded_blas

IMPORTED = time.perf_counter()  # the wall clock's start where the process's own is unknown (see _started_s)

EXAMPLES = """Examples:

\b
  gnerun solve configs/harker.yaml               (prints the equilibrium x)
  gnerun solve configs/paper_study1.yaml --set solver.tol=1e-12
  gnerun simulate configs/paper_study2.yaml --out runs/s2
  gnerun figures runs/s2 --out figures           (PNG at 300 dpi, and PDF)
  gnerun replay runs/s2 --save runs/s2/replay.rrd
  gnerun inspect runs/s2

Run logs (run.mcap) also open in Foxglove and Lichtblick as they are.
Run `gnerun COMMAND --help` for a command's options."""

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
    help="Newton-type equilibrium seeking in games and game-theoretic MPC (semismooth Newton on the "
    "KKT system of generalized Nash games). Every iterate is logged to MCAP.",
    epilog=EXAMPLES,
)

_options = {"debug": False}


class _Command(TyperCommand):
    """A command whose help names its arguments plainly (``CONFIG``, ``RUN...``), as its usage line does."""

    def collect_usage_pieces(self, ctx) -> list[str]:
        pieces = [self.options_metavar] if self.options_metavar else []
        return pieces + [p.metavar or p.name.upper() for p in self.get_params(ctx) if p.param_type_name == "argument"]

    def format_options(self, ctx, formatter) -> None:
        params = self.get_params(ctx)
        arguments = [(p.metavar or p.name.upper(), p.help or "") for p in params if p.param_type_name == "argument"]
        options = [r for p in params if p.param_type_name == "option" and (r := p.get_help_record(ctx))]
        for title, rows in (("Arguments", arguments), ("Options", options)):
            if rows:
                with formatter.section(title):
                    formatter.write_dl(rows)

ConfigArg = Annotated[Path, typer.Argument(help="Experiment config (YAML).", show_default=False,
                                            metavar="CONFIG")]
SetOpt = Annotated[
    list[str] | None,
    typer.Option("--set", help="Override a config field (the value is read as YAML, e.g. --set run.K=[1,7]); "
                 "repeat it for several fields.", show_default=False, metavar="KEY.PATH=VALUE"),
]
OutOpt = Annotated[
    Path | None,
    typer.Option("--out", help="Run directory (default: runs/<config name>-<UTC timestamp>/, -2/ for a second run in "
                 "that second).", show_default=False,
                 metavar="DIR"),
]
QuietOpt = Annotated[bool, typer.Option("--quiet", "-q", help="Print nothing but errors.")]
VerboseOpt = Annotated[bool, typer.Option("--verbose", "-v", help="Print every iterate row (past 20 rows the table "
                                          "is thinned: every 10th iterate, each phase change, the last).")]
ForceOpt = Annotated[bool, typer.Option("--force", help="Write into an existing, non-empty run directory.")]


def _version(value: bool) -> None:
    if value:
        typer.echo(f"gnerun {__version__}")
        raise typer.Exit()


@app.callback()
def _main(
    debug: Annotated[bool, typer.Option("--debug", help="Show Python tracebacks for errors.")] = False,
    version: Annotated[bool | None, typer.Option("--version", callback=_version, is_eager=True,
                                                 help="Print the version and exit.")] = None,
) -> None:
    _options["debug"] = debug


def _fail(exc: BaseException) -> NoReturn:
    if _options["debug"]:
        traceback.print_exception(exc)
    if isinstance(exc, OSError) and exc.errno == errno.ENAMETOOLONG:  # a path given on the command line
        exc = InputError(f"{shorten(str(exc.filename), 100)}: {exc.strerror} (a path component is at most 255 bytes, "
                         "a path at most 4,096)")
    if isinstance(exc, InputError):  # one line already (InputError escapes what it quotes)
        typer.echo(f"error: {exc.cli}", err=True)
        raise typer.Exit(2)
    if isinstance(exc, Unavailable):
        typer.echo(f"error: {one_line(shorten(str(exc), MAX_MESSAGE))}", err=True)
        raise typer.Exit(1)
    typer.echo(f"error: {type(exc).__name__}: {one_line(shorten(str(exc), MAX_MESSAGE))} (run with --debug for the "
               "traceback)", err=True)
    raise typer.Exit(1)


@contextlib.contextmanager
def _reported() -> Iterator[None]:
    """Every failure inside becomes one message and an exit code; so does a Ctrl-C that reaches it (during loading
    or imports, before a command's own handler, which says what the run left behind)."""
    try:
        yield
    except typer.Exit:
        raise
    except KeyboardInterrupt:
        typer.echo("interrupted", err=True)
        raise typer.Exit(130) from None
    except Exception as e:  # noqa: BLE001 - the one place where errors become messages
        _fail(e)


def _load(config: Path, overrides: list[str] | None, clock: _Clock | None = None):
    clock = clock if clock is not None else _Clock()
    with clock("imports"):
        from .language.config import load_config
    with clock("load"):
        return load_config(config, overrides or [])


def _fmt(v: float | None, spec: str = ".3e") -> str:
    if v is None or v != v:
        return "-"
    return format(v, spec)


def _plural(n: int, noun: str) -> str:
    return f"{n} {noun}{'s' if n != 1 else ''}"


def _method(cfg) -> str:
    """The configured method as a header says it: the complementarity map only where semismooth Newton runs."""
    s = cfg.solver
    ssn_map = "min map" if s.complementarity == "min" else "Fischer-Burmeister map"
    if s.kind == "ssn":
        return f"ssn ({ssn_map})"
    if s.kind == "jn":
        return "jn (Josephy-Newton)"
    inner = f"inner ssn, {ssn_map}" if s.inner == "ssn" else "inner jn"
    return f"distributed ({s.scheme.replace('_', '-')}, {inner})"


SOLUTION_ROWS = 24  # rows of the solution table before it is cut short (summary.json holds everything)
SOLUTION_STAGES = 7  # values per row before a horizon is summarised by its first and last stages


def _solution_lines(solution: dict) -> list[str]:
    """The solution as a compact table: one row per agent and variable (a static game's value, or a dynamic
    game's inputs by stage; a long horizon as its first three and last two stages)."""
    def value(v: float | None) -> str:
        return "-" if v is None or v != v else f"{v:.4g}"

    def shorten(items: list[str]) -> list[str]:
        return [*items[:3], "...", *items[-2:]] if len(items) > SOLUTION_STAGES else items

    rows = [(agent, name, [value(x) for x in v] if isinstance(v, list) else [value(v)])
            for agent, variables in solution.items() for name, v in variables.items()]
    if not rows:
        return []
    stages = max((len(v) for variables in solution.values() for v in variables.values() if isinstance(v, list)),
                 default=0)
    wa, wv = max(len(r[0]) for r in rows), max(len(r[1]) for r in rows)
    if not stages:  # a static game
        lines = ["solution:"] + [f"  {a:<{wa}}  {v:<{wv}} = {values[0]}" for a, v, values in rows[:SOLUTION_ROWS]]
    else:
        header = shorten([str(tau) for tau in range(stages)])
        wn = max(len(x) for r in rows for x in [*r[2], *header])
        wa, wv = max(wa, len("agent")), max(wv, len("input"))
        lines = [f"solution (inputs by stage tau = 0..{stages - 1}):",
                 f"  {'agent':<{wa}}  {'input':<{wv}}  " + " ".join(f"{x:>{wn}}" for x in header)]
        lines += [f"  {a:<{wa}}  {v:<{wv}}  " + " ".join(f"{x:>{wn}}" for x in shorten(values))
                  for a, v, values in rows[:SOLUTION_ROWS]]
    if len(rows) > SOLUTION_ROWS:
        lines.append(f"  ... {len(rows) - SOLUTION_ROWS} more (summary.json holds the whole solution)")
    return lines


ROWS_IN_FULL = 20  # iterate rows printed before the table is thinned (--verbose prints every row)
ROWS_EVERY = 10  # past them: the iterates k = 0 mod 10, each phase change, and the last


class _IterateTable:
    """The iterate rows of a solve, printed as they are made. Past ``ROWS_IN_FULL`` rows only every ``ROWS_EVERY``-th
    iterate, the first of each phase (gnerun.solvers.hybrid) and the last are printed, then a line says how many
    were left out; ``verbose`` prints every row."""

    def __init__(self, verbose: bool):
        self.verbose = verbose
        self.rows = self.hidden = 0
        self.phase: str | None = None
        self.withheld: str | None = None  # the last row not printed: printed at the end if it is the last row
        self.seconds = 0.0  # time spent printing

    @staticmethod
    def header(phases: bool) -> str:
        return (f"{'k':>4}  {'||Phi||':>10}  {'||z-z*||':>10}  {'||dz||':>10}  {'changes':>7}"
                + (f"  {'phase':<8}" if phases else "")).rstrip()

    def add(self, k: int, residual_norm: float, error_norm: float | None, step_norm: float, changes: int,
            phase: str | None) -> None:
        t0 = time.perf_counter()
        line = (f"{k:>4}  {_fmt(residual_norm):>10}  {_fmt(error_norm):>10}  {_fmt(step_norm):>10}  {changes:>7}"
                + (f"  {phase}" if phase is not None else ""))
        shown = (self.verbose or self.rows < ROWS_IN_FULL or k % ROWS_EVERY == 0
                 or (self.rows > 0 and phase != self.phase))
        self.rows += 1
        self.phase = phase
        if shown:
            typer.echo(line)
            self.withheld = None
        else:
            self.hidden += 1
            self.withheld = line
        self.seconds += time.perf_counter() - t0

    def close(self) -> None:
        """The last row if it was not printed, and how many rows were left out."""
        t0 = time.perf_counter()
        if self.withheld is not None:
            typer.echo(self.withheld)
            self.hidden -= 1
            self.withheld = None
        if self.hidden:
            typer.echo(f"  ... {_plural(self.hidden, 'row')} not shown; --verbose shows all")
        self.seconds += time.perf_counter() - t0


_STARTED: list[float] = []  # the process's start on time.perf_counter's scale, found once


def _wall_s() -> float:
    """Seconds since this process started (:func:`_started_s` the first time, then on the same scale: a child waited
    for later, such as a log writer, would make /proc's reading switch scales)."""
    if not _STARTED:
        _STARTED.append(time.perf_counter() - _started_s())
    return time.perf_counter() - _STARTED[0]


def _started_s() -> float:
    """Seconds since this process started (Linux: /proc; elsewhere since the CLI was imported).

    A shell runs the last command of ``bash -c '...; gnerun solve ...'`` in its own process (exec): /proc then dates
    gnerun from the shell's start, and every command before it (a venv made, a pip install) would count as startup.
    Such a process has waited for children (their CPU time is counted in its own, fields 16 and 17), which an
    interpreter starting gnerun has not: then the time since the CLI was imported is taken, as elsewhere."""
    try:
        stat = Path("/proc/self/stat").read_text().rsplit(")", 1)[1].split()  # fields 3.. (the name may hold spaces)
        if int(stat[13]) + int(stat[14]) == 0:  # fields 16, 17: no child waited for before
            uptime = float(Path("/proc/uptime").read_text().split()[0])
            return uptime - int(stat[19]) / os.sysconf("SC_CLK_TCK")  # field 22: the start, in clock ticks since boot
    except (OSError, ValueError, IndexError, AttributeError):
        pass
    return time.perf_counter() - IMPORTED


class _Clock:
    """Where a command's wall time goes: the parts measured, in the order first measured, and the rest."""

    def __init__(self) -> None:
        self.parts: dict[str, float] = {}

    @classmethod
    def started(cls) -> _Clock:
        """A clock whose first part is the startup: the interpreter, the CLI's import, the command line read."""
        clock = cls()
        clock.add("startup", _wall_s())
        return clock

    def add(self, name: str, seconds: float) -> None:
        self.parts[name] = self.parts.get(name, 0.0) + seconds

    @contextlib.contextmanager
    def __call__(self, name: str) -> Iterator[None]:
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.add(name, time.perf_counter() - t0)

    def line(self, order: tuple[str, ...]) -> str:
        """``wall W s: part p, ..., other o``: the parts in ``order`` (then any other measured), ``other`` the wall
        time none of them measured (the interpreter's start, the command line, printing the results)."""
        wall = _wall_s()
        parts = [(name, self.parts[name]) for name in order if name in self.parts]
        parts += [(name, v) for name, v in self.parts.items() if name not in order]
        parts.append(("other", wall - sum(v for _, v in parts)))
        spec = ".2f" if wall < 10 else ".1f"
        return f"wall {wall:{spec}} s: " + ", ".join(f"{name} {v:{spec}}" for name, v in parts)


# the timing line's parts, in this order (other last): what the command does, first to last
TIMING_ORDER = ("startup", "imports", "load", "compile", "reference", "solve", "certificate", "logging")


ExpandOpt = Annotated[bool, typer.Option("--expand", help="Print the config as it runs: families, templates, "
                                                         "sums and definitions written out, every default filled in.")]


@app.command(cls=_Command, short_help="Check a config or a sweep spec without running it.")
def validate(config: ConfigArg, set_: SetOpt = None, quiet: QuietOpt = False, expand: ExpandOpt = False) -> None:
    """Check a config (or a sweep spec and every point of it) without running it; print every problem found."""
    from .errors import ConfigError

    with _reported():
        try:
            from .language.config import is_sweep_spec
            from .language.yaml_source import read_yaml

            if is_sweep_spec(read_yaml(config)[0]):
                from .runs.sweep import load_sweep

                if set_:
                    raise ConfigError(["--set applies to configs; a sweep's fixed overrides are its `set:`"])
                sw = load_sweep(config)
                if not quiet:
                    typer.echo(f"{config}: ok (sweep '{sw.spec.name}': {len(sw.points)} points, {sw.spec.mode} of "
                               f"{', '.join(sw.axes)}, {sw.spec.command} {sw.base.name})")
                return
            cfg = _load(config, set_)
        except ConfigError as e:
            for p in e.problems:
                typer.echo(f"error: {p}", err=True)
            raise typer.Exit(2) from None
        large = cfg.size_warnings("validate")
        _warn(config, large, quiet)
        if not cfg.size.problems()[1]:  # a game of a size that builds in seconds is built
            from .game.compile import compile_game
            from .solvers.factory import make_solver

            game = compile_game(cfg)
            make_solver(cfg, game)  # refuses what the configured method cannot solve
    if expand:
        typer.echo(cfg.resolved_yaml(), nl=False)
        return
    if quiet:
        return
    if cfg.size.problems()[1]:
        typer.echo(f"{config}: ok ({cfg.game.kind} game '{cfg.name}': {len(cfg.game.agents)} agents, "
                   f"{cfg.size.decisions} decisions, {cfg.size.multipliers} multipliers; not built, as it is large: "
                   "`gnerun solve` builds it)")
    else:
        typer.echo(f"{config}: ok ({cfg.game.kind} game '{cfg.name}': {len(game.agent_names)} agents, "
                   f"{game.n} decisions, {game.m} multipliers)")


def _warn(config: Path, warnings: list[str], quiet: bool) -> None:
    if not quiet:
        for w in warnings:
            typer.echo(f"warning: {config}: {w}", err=True)


@app.command(cls=_Command, short_help="Solve one equilibrium problem and print the solution.")
def solve(config: ConfigArg, out: OutOpt = None, set_: SetOpt = None, quiet: QuietOpt = False,
          force: ForceOpt = False, verbose: VerboseOpt = False) -> None:
    """Solve one equilibrium problem (a static game, or a dynamic game at its x0)."""
    clock = _Clock.started()
    with _reported():
        cfg = _load(config, set_, clock)
        _warn(config, cfg.size_warnings("solve"), quiet)
        with clock("imports"):
            from .runs.rundir import claim_default_run_dir, remove_if_empty
            from .runs.solving import solve as run_solve
            from .solvers import certificate  # noqa: F401 - loaded by every solve's end: its time is the imports'
            from .solvers.driver import phase

        out_dir = out if out is not None else claim_default_run_dir(cfg)
        table = _IterateTable(verbose)

        def show(state, error_norm: float | None) -> None:
            if quiet:
                return
            if state.k == 0:
                typer.echo(f"gnerun solve {config}: {_method(cfg)}, tol {cfg.solver.tol:.0e}, disturbance "
                           f"{cfg.disturbance.kind}")
                typer.echo(table.header(phase(state) is not None))
            table.add(state.k, state.residual_norm, error_norm, state.step_norm, state.active_set_changes,
                      phase(state))

        try:
            stage = (lambda text: typer.echo(f"... {text}", err=True)) if not quiet and sys.stderr.isatty() else None
            result = run_solve(cfg, out=out_dir, force=force, on_iterate=show, on_stage=stage)
            for name, seconds in (("compile", result.compile_time_s), ("reference", result.reference_time_s),
                                  ("solve", result.time_s), ("certificate", result.certificate_time_s),
                                  ("logging", result.logging_time_s + table.seconds)):
                clock.add(name, seconds)
        except KeyboardInterrupt:
            typer.echo(_interrupted(out_dir), err=True)
            raise typer.Exit(130) from None
        finally:
            if out is None:
                remove_if_empty(out_dir)
    if quiet:
        return
    table.close()
    cert = result.certificate
    typer.echo(f"status: {result.status}: {result.message}")
    for line in _solution_lines(result.solution):
        typer.echo(line)
    if "best_response_gap" in cert:
        kinds = cert.get("best_response_kind", {})
        gaps = ", ".join(f"{k} {_fmt(v, '.1e')}" + (f" ({kinds[k]})" if k in kinds else "")
                         for k, v in cert["best_response_gap"].items())
        checked = f"best-response gaps: {gaps}"
    else:
        checked = "best responses not checked (run.certificate: false)"
    typer.echo(f"certificate: KKT residual {_fmt(cert['kkt_residual'], '.1e')}; {checked}")
    checking = f"certificate {result.certificate_time_s * 1e3:.0f} ms; " if "best_response_gap" in cert else ""
    typer.echo(f"solver time {result.time_s * 1e3:.2f} ms ({_plural(result.iterations, 'iteration')}); {checking}"
               f"compile {result.compile_time_s * 1e3:.0f} ms")
    if result.kernels is not None and not result.kernels.quiet:
        typer.echo(result.kernels.line())
    typer.echo(f"run directory: {result.run_dir}")
    typer.echo(clock.line(TIMING_ORDER))


@app.command(cls=_Command, short_help="Run the closed loop (time-distributed CG-MPC) once per K.")
def simulate(config: ConfigArg, out: OutOpt = None, set_: SetOpt = None, quiet: QuietOpt = False,
             force: ForceOpt = False, verbose: Annotated[bool, typer.Option(
                 "--verbose", "-v", help="Print the iterate rows of the solve at t = 0 (run.initial: solve).")] = False
             ) -> None:
    """Run the closed loop (time-distributed CG-MPC) for every K in run.K."""
    clock = _Clock.started()
    with _reported():
        cfg = _load(config, set_, clock)
        if cfg.game.kind != "dynamic":  # before the header: nothing runs
            raise InputError(f"{config}: simulate needs a dynamic game (game.kind: dynamic); use `gnerun solve` "
                             "for a static game")
        _warn(config, cfg.size_warnings("simulate"), quiet)
        with clock("imports"):
            from .runs.closed_loop import simulate as run_simulate
            from .runs.rundir import claim_default_run_dir, remove_if_empty

        out_dir = out if out is not None else claim_default_run_dir(cfg)
        if not quiet:
            typer.echo(f"gnerun simulate {config}: K = {cfg.run.K}, {_plural(cfg.run.steps, 'step')}, "
                       f"{_method(cfg)}, warm start {cfg.run.warm_start}, solver disturbance {cfg.disturbance.kind}, "
                       f"plant {cfg.disturbance.plant.kind}")
        try:
            with _progress(cfg, enabled=not quiet and sys.stdout.isatty()) as progress:
                sim = run_simulate(cfg, out=out_dir, force=force, progress=progress)
            for name, seconds in (("compile", sim.compile_time_s), ("reference", sim.reference_time_s),
                                  ("solve", sim.solver_time_s), ("logging", sim.log_time_s)):
                clock.add(name, seconds)
        except KeyboardInterrupt:
            typer.echo(_interrupted(out_dir), err=True)
            raise typer.Exit(130) from None
        finally:
            if out is None:
                remove_if_empty(out_dir)
    if quiet:
        return
    first = _first_sampling_time(cfg, sim, verbose)
    steps = "t>=1" if first else "step"  # with t = 0 solved to tolerance, the step times are those of the MPC steps
    typer.echo(f"{'K':>4}  {'max e':>10}  {'final e':>10}  {'median ' + steps:>12}  {'max ' + steps:>10}  "
               f"{'failed':>6}  {'fallback':>8}  {'max violation':>13}")
    for K, r in sim.items():
        failed = len(r.failed_steps)
        finite = r.e_norm[r.e_norm == r.e_norm]
        times = sorted(r.solve_time_s[1 if first else 0:r.done])
        median = _ms(float(times[len(times) // 2])) if times else "-"
        typer.echo(f"{K:>4}  {_fmt(float(finite.max()) if finite.size else None):>10}  {_fmt(float(r.e_norm[-1])):>10}"
                   f"  {median:>12}  {_ms(float(times[-1])) if times else '-':>10}  {failed:>6}"
                   f"  {len(r.fallback_steps):>8}  {_fmt(r.max_constraint_violation):>13}")
    worst = {K: r for K, r in sim.items() if r.max_constraint_violation > 1e-9}  # above rounding
    for K, r in worst.items():
        v = r.constraint_violation
        t = max(range(r.done), key=lambda i: v[i] if v[i] == v[i] else -1.0)
        typer.echo(f"K={K}: largest violation {_fmt(r.max_constraint_violation)} at t = {t}: {r.worst_constraint[t]}")
    for r in sim.values():
        if r.message:  # a loop that ended early: why
            typer.echo(one_line(r.message))
    if (kernels := sim.kernels) is not None and not kernels.quiet:
        typer.echo(kernels.line())
    typer.echo(f"run directory: {sim.run_dir}")
    typer.echo(clock.line(TIMING_ORDER))


def _first_sampling_time(cfg, sim, verbose: bool) -> bool:
    """The line on sampling time 0 when it was solved to tolerance (run.initial: solve), made once for every K (and
    with ``verbose`` its iterate rows); False where there is none to report (t = 0 is then a step like the others)."""
    first = sim.first
    if cfg.run.initial != "solve" or first is None or not first.solves or not sim:
        return False
    r = next(r for r in sim.values() if not r.shares_first)
    if not r.done:  # stopped before t = 0 was done
        return False
    if verbose:
        import numpy as np

        z_star = r.z_star[0]
        table = _IterateTable(verbose=True)
        typer.echo("t = 0, the solve to tolerance:")
        typer.echo(table.header(any(row.phase is not None for row in first.states)))
        for row in first.states:
            error = None if z_star is None or not np.all(np.isfinite(z_star)) else float(np.linalg.norm(row.z - z_star))
            table.add(row.k, row.residual_norm, error, row.step_norm, row.active_set_changes, row.phase)
        table.close()
    makers = [K for K, s in sim.items() if not s.shares_first]  # the loops that solved t = 0 (one, unless a
    # parameters callback gave the loops different runtime values at t = 0)
    by = (f"once for K = {', '.join(str(K) for K in sim)}" if len(makers) == 1 else
          f"{_plural(len(makers), 'time')} (by K = {', '.join(str(K) for K in makers)}: different runtime values)")
    typer.echo(f"t = 0, solved to tolerance {by}: {r.status[0]}, {_plural(int(r.iterations[0]), 'iteration')}, "
               f"{_ms(float(r.solve_time_s[0]))}; step times below: t >= 1")
    return True


@app.command(cls=_Command, short_help="Run a grid of runs and write their index table (resumable).")
def sweep(
    spec: Annotated[Path, typer.Argument(help="Sweep spec (YAML): base config, set, grid.", show_default=False,
                                         metavar="SWEEP")],
    out: Annotated[Path | None, typer.Option("--out", help="Sweep directory (default: runs/<sweep name>/; "
                                             "running again resumes it).", show_default=False, metavar="DIR")] = None,
    executor: Annotated[str, typer.Option("--executor", help="local (process pool) or dask.",
                                          metavar="local|dask")] = "local",
    workers: Annotated[int, typer.Option("--workers", help="Worker processes (local, and a dask LocalCluster); at "
                                         "most the CPUs of this machine, unless --force-workers.",
                                         metavar="N")] = 2,
    force_workers: Annotated[bool, typer.Option("--force-workers", help="Allow more --workers than CPUs.")] = False,
    address: Annotated[str | None, typer.Option("--address", help="A running Dask scheduler: tcp://host:8786 or "
                                                "its scheduler file (default: a LocalCluster).",
                                                show_default=False, metavar="ADDRESS")] = None,
    quiet: QuietOpt = False,
    force: Annotated[bool, typer.Option("--force", help="Write into an existing non-sweep directory.")] = False,
) -> None:
    """Run a grid of runs (every point a run directory) and write the index table; resumable."""
    with _reported():
        from .runs.sweep import check_executor, default_sweep_dir, load_sweep, run_sweep, stop_resource_tracker

        check_executor(executor, workers, address, force_workers)  # before the points are loaded
        sw = load_sweep(spec)
        out_dir = out if out is not None else default_sweep_dir(sw)
        if not quiet:
            where = f"dask at {address}" if address else f"{executor}, {workers} worker{'s' * (workers > 1)}"
            typer.echo(f"gnerun sweep {spec}: {len(sw.points)} points ({sw.spec.mode} of "
                       f"{', '.join(sw.axes)}), {sw.spec.command} {sw.base.name}, {where}")

        def progress(done: int, total: int, task: dict, rows: list[dict]) -> None:
            if quiet:
                return
            params = " ".join(f"{k}={v}" for k, v in task["params"].items())
            figures = "; ".join(
                f"{'K=' + str(r['K']) + ' ' if r['K'] is not None and 'run.K' not in task['params'] else ''}"
                f"{r['status']}" + (f", max e {_fmt(r['max_e'], '.2e')}, final e {_fmt(r['final_e'], '.2e')}"
                                    if r["status"] != "error" else f": {r['message']}") for r in rows)
            typer.echo(f"[{done}/{total}] {params}: {figures}")

        try:
            result = run_sweep(sw, out_dir, executor=executor, workers=workers, address=address, force=force,
                               progress=progress)
        except KeyboardInterrupt:
            typer.echo(f"interrupted: {out_dir} holds the index of the finished points; run again to resume",
                       err=True)
            raise typer.Exit(130) from None
        finally:
            stop_resource_tracker()  # the pool is gone: no process of the sweep outlives it
    if not quiet:
        typer.echo(f"{result.ran} run, {result.skipped} already finished (skipped), {result.failed} failed; "
                   f"{result.wall_s:.1f} s with {executor}; the game compiled {result.games_compiled} "
                   f"time{'s' * (result.games_compiled != 1)} for the {result.ran} points run")
        typer.echo("index: " + ", ".join(str(p) for p in result.index_files))


def _existing_logs(runs: list[Path]) -> list[Path]:
    from .errors import InputError
    from .log.mcap_log import run_log_path

    for run in runs:
        log = run_log_path(run)
        if not log.exists() or log.is_dir():  # anything else that is there is refused by the reader, with its kind
            raise InputError(f"{run}: no run log here (expected a run directory or its run.mcap)")
    return runs


@app.command(cls=_Command, short_help="Draw the paper's figures from run logs and sweep directories.")
def figures(
    runs: Annotated[list[Path], typer.Argument(
        help="Run directories or their run.mcap files, and sweep directories.", show_default=False, metavar="RUN...")],
    out: Annotated[Path, typer.Option("--out", help="Folder for the figures.", metavar="DIR")] = Path("figures"),
    format_: Annotated[str, typer.Option("--format", help="Comma-separated: png, pdf, svg.",
                                         metavar="FORMATS")] = "png,pdf",
    states: Annotated[str | None, typer.Option(
        "--states", help="Comma-separated states that panel (a) of a closed loop draws (default: all but clocks).",
        metavar="NAMES", show_default=False)] = None,
    quiet: QuietOpt = False,
) -> None:
    """Paper-style figures (Studies 1-3) from run logs, the paths of games with positions, and sweep figures from
    sweep directories."""
    with _reported():
        from .errors import InputError
        from .view.figures import write_figures

        formats = [f.strip().lower() for f in format_.split(",") if f.strip()]
        bad = [f for f in formats if f not in ("png", "pdf", "svg")]
        if bad or not formats:
            raise InputError(f"--format {format_}: choose from png, pdf, svg")
        from .log.sweep_index import is_sweep_dir

        chosen = None if states is None else [s.strip() for s in states.split(",") if s.strip()]
        if chosen == []:
            raise InputError(f"--states {states!r}: no state names (comma-separated, e.g. --states px1,py1)")
        sweeps = [r for r in runs if is_sweep_dir(r)]
        written = write_figures(_existing_logs([r for r in runs if r not in sweeps]), out, formats, sweeps=sweeps,
                                states=chosen)
        if not written:
            raise InputError("the runs hold nothing to draw (no /solve/iterate and no /K<k>/mpc topics" +
                             ("; no sweep row on a run.K or disturbance-scale axis)" if sweeps else ")"))
    if not quiet:
        for path in written:
            typer.echo(str(path))


@app.command(cls=_Command, short_help="Show a run log's topics, counts, time range, status and config.")
def inspect(run: Annotated[Path, typer.Argument(help="A run directory or its run.mcap.", show_default=False,
                                                metavar="RUN")]) -> None:
    """Topics, message counts, time range, status and config of a run, finished or not."""
    with _reported():
        import datetime as dt

        from .errors import InputError, shorten
        from .files import read_json_object
        from .log.mcap_log import read_run

        record = read_run(_existing_logs([run])[0])
        summary_file = record.path.parent / "summary.json"
        status = "unknown"
        if summary_file.exists() or summary_file.is_symlink():
            try:
                status = shorten(str(read_json_object(summary_file).get("status", "unknown")), 60)
            except InputError as e:
                status = f"unknown ({e})"
        elif not record.complete:
            status = "incomplete: the run did not finish (no summary.json)"
        times = [t for ts in record.log_times.values() for t in ts]
    typer.echo(f"{record.path}: {one_line(record.note)}")
    meta = {k: one_line(shorten(v, 80)) for k, v in record.metadata.items()}  # a log may have been edited
    typer.echo(f"config: {meta.get('config_name', '?')} (hash {meta.get('config_hash', '?')[:12]}, gnerun "
               f"{meta.get('version', '?')}, seed {meta.get('seed', '?')}, {meta.get('git_describe', '?')})")
    typer.echo(f"status: {status}")
    if times and meta.get("log_time", "").startswith("simulated"):  # a closed loop's own time axis
        ts = float((record.config.get("run") or {}).get("sampling_time") or 1.0)
        first, last = min(times) / 1e9, max(times) / 1e9
        typer.echo(f"time range: {first:g} .. {last:g} s of simulated time (t = {first / ts:g} .. {last / ts:g}, "
                   f"sampling time {ts:g} s)")
    elif times and meta.get("log_time", "").startswith("iteration"):  # a solve's: 1 s per iteration
        typer.echo(f"time range: iterations k = {min(times) / 1e9:g} .. {max(times) / 1e9:g} (1 s each)")
    elif times:  # logs of earlier versions: the wall clock
        first, last = (dt.datetime.fromtimestamp(t / 1e9, dt.UTC) for t in (min(times), max(times)))
        typer.echo(f"time range: {first.isoformat(timespec='seconds')} .. {last.isoformat(timespec='seconds')} "
                   f"({(max(times) - min(times)) / 1e9:.3f} s)")
    typer.echo(f"{'topic':<24} {'messages':>8}")
    for topic, msgs in sorted(record.messages.items()):
        typer.echo(f"{one_line(shorten(topic, 60)):<24} {len(msgs):>8}")
    if record.config:
        typer.echo("config.yaml:")
        for line in record.config_yaml.rstrip().splitlines():
            typer.echo(f"  {one_line(line)}")


@app.command(cls=_Command, short_help="Open runs in Rerun: viewer, .rrd file, web viewer or screenshots.")
def replay(
    runs: Annotated[list[Path], typer.Argument(help="Run directories or their run.mcap files.", show_default=False,
                                               metavar="RUN...")],
    save: Annotated[Path | None, typer.Option("--save", help="Write the recording to FILE.rrd.",
                                              show_default=False, metavar="FILE.rrd")] = None,
    spawn: Annotated[bool, typer.Option("--spawn", help="Open the native viewer (needs a display).")] = False,
    serve: Annotated[bool, typer.Option("--serve", help="Serve the web viewer on 127.0.0.1, print its URL.")] = False,
    screenshot: Annotated[Path | None, typer.Option(
        "--screenshot", help="Write one PNG per paper figure to DIR, and paths.png of the paths in the plane (games "
        "with positions), taken by a headless viewer (needs a Vulkan driver, e.g. Debian's mesa-vulkan-drivers).",
        show_default=False, metavar="DIR")] = None,
    size: Annotated[str, typer.Option("--size", help="Screenshot size in points (--screenshot).",
                                      metavar="WIDTHxHEIGHT")] = "1600x900",
    web_port: Annotated[int, typer.Option("--web-port", help="Port of the web viewer (--serve).",
                                          metavar="PORT")] = 9090,
    grpc_port: Annotated[int, typer.Option("--grpc-port", help="Port of its data server (--serve).",
                                           metavar="PORT")] = 9876,
    quiet: QuietOpt = False,
) -> None:
    """Open runs in Rerun: one timeline per kind of run, one view per paper figure, the paths in the plane of games
    with positions (built from the logs only)."""
    with _reported():
        import os
        import tempfile

        from .errors import InputError
        from .files import output_directory, output_file
        from .view import replay as rp

        runs = _existing_logs(runs)
        rp.check_size(size)
        if not (save or spawn or serve or screenshot):
            if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
                raise InputError("no display for the viewer: use --save FILE.rrd, --serve or --screenshot DIR")
            spawn = True
        # every target is checked before any work: a folder, the ports, a recording (created empty: checked last)
        if screenshot is not None:
            output_directory(screenshot, "screenshot folder (--screenshot)", create=False)
        if serve:
            rp.check_ports(web_port, grpc_port)
        if save is not None:
            new = not save.exists() and not save.is_symlink()
            output_file(save, "recording (--save)")
            try:
                rp.save(runs, save)
            except BaseException:
                if new:  # a refused log leaves no recording behind
                    save.unlink(missing_ok=True)
                raise
            if not quiet:
                typer.echo(f"saved {save}")
        if screenshot is not None:
            for path in rp.screenshots(runs, screenshot, size=size):
                if not quiet:
                    typer.echo(f"wrote {path}")
        if spawn:
            rp.spawn(runs)
        if serve:
            with tempfile.TemporaryDirectory(prefix="gnerun-replay-", ignore_cleanup_errors=True) as tmp:
                rrd = save if save is not None else Path(tmp) / "replay.rrd"
                if save is None:
                    rp.save(runs, rrd)
                import shutil

                # a temporary recording goes once the viewer has read it: a killed replay leaves nothing behind
                rp.serve(rrd, web_port, grpc_port,
                         ready=lambda: (typer.echo(f"web viewer: {rp.web_url(web_port, grpc_port)} (Ctrl-C stops it)"),
                                        sys.stdout.flush()),
                         loaded=None if save is not None else lambda: shutil.rmtree(tmp, ignore_errors=True))


@app.command(cls=_Command, short_help="Write a finished, indexed copy of a killed run's log.")
def recover(
    run: Annotated[Path, typer.Argument(help="A run directory or its run.mcap.", show_default=False, metavar="RUN")],
    out: Annotated[Path | None, typer.Option("--out", help="The repaired copy (default: run.recovered.mcap beside "
                                                          "the log).", show_default=False, metavar="FILE")] = None,
    quiet: QuietOpt = False,
    force: Annotated[bool, typer.Option("--force", help="Overwrite an existing copy.")] = False,
) -> None:
    """Write a finished, indexed copy of a run log whose writer was killed (or of a damaged one: every record
    that can be read)."""
    with _reported():
        import contextlib

        from .errors import InputError
        from .files import replaceable_file
        from .log.mcap_log import recover as recover_log
        from .log.mcap_log import run_log_path
        from .runs.lock import locked

        source = run_log_path(_existing_logs([run])[0])
        target = out if out is not None else source.with_name("run.recovered.mcap")
        if target.resolve() == source.resolve():
            raise InputError(f"{target}: the copy must not overwrite the log it repairs")
        # beside the log, the copy is written into the run directory: not while a run writes there
        beside = target.parent.resolve() == source.parent.resolve()
        with locked(source.parent) if beside else contextlib.nullcontext():
            replaceable_file(target, "repaired copy")  # a link, a directory or a special file: refused, --force or not
            if target.exists() and not force:
                raise InputError(f"{target}: exists (use --force to overwrite it)")
            record = recover_log(source, target)
    if not quiet:
        typer.echo(f"{target}: {record.message_count} messages recovered ({one_line(record.note)})")


def _interrupted(out_dir: Path) -> str:
    """What an interrupted solve or simulate left behind, in one line."""
    if (out_dir / "summary.json").is_file():
        return f"interrupted: {out_dir} holds a finished log and a summary with status interrupted"
    if (out_dir / "run.mcap").is_file():
        return f"interrupted: {out_dir} holds the log of what was done"
    return "interrupted"


def _ms(seconds: float) -> str:
    return f"{seconds * 1e3:.3f} ms"


class _progress:
    """A progress bar per K on a terminal; nothing otherwise."""

    def __init__(self, cfg, enabled: bool):
        self.cfg = cfg
        self.enabled = enabled
        self.bar = None
        self.tasks: dict[int, int] = {}

    def __enter__(self):
        if not self.enabled:
            return None
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

        self.bar = Progress(TextColumn("K={task.fields[K]:<3}"), BarColumn(), MofNCompleteColumn(),
                            TextColumn("e(t) {task.fields[e]}"), TimeElapsedColumn())
        self.bar.__enter__()
        for K in dict.fromkeys(self.cfg.run.K):
            self.tasks[K] = self.bar.add_task("", total=self.cfg.run.steps, K=K, e="-")
        return self.update

    def update(self, step) -> None:
        self.bar.update(self.tasks[step.K], completed=step.t + 1, e=_fmt(step.e_norm, ".2e"))

    def __exit__(self, *exc) -> None:
        if self.bar is not None:
            self.bar.__exit__(*exc)


def main() -> None:
    """Entry point of the `gnerun` console script."""
    single_threaded_blas()
    from .runs.interrupt import terminate_like_ctrl_c

    terminate_like_ctrl_c()
    code: int | str | None = 0
    try:
        app(standalone_mode=True)
    except KeyboardInterrupt:
        typer.echo("interrupted", err=True)
        code = 130
    except SystemExit as e:
        code = e.code
    from .game.building import abandoned

    if abandoned():  # a stopped build still runs in its helper thread: end now, everything is written
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code if isinstance(code, int) else 1)
    sys.exit(code)


if __name__ == "__main__":
    main()
