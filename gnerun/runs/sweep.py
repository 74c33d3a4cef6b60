"""Sweeps: a grid of runs over config fields (`gnerun sweep SWEEP.yaml`).

A sweep spec names a base config, fixed overrides (``set``) and a grid over any field paths, taken as a
product or zipped. Every point is a normal run directory under ``<out>/points/``; the index table
(``index.csv``, and ``index.parquet`` when pyarrow is installed) has one row per point and K with the
point's parameters and its key figures. Points run on a local process pool or on Dask (a LocalCluster,
or a running scheduler: a lab server or an HPC queue through dask-jobqueue). A point is a function of
its config alone, so every executor writes the same index (timings aside).

Re-running a sweep into the same directory skips the points already finished with the same config (their
summary.json exists and their config hash matches); points that failed or were interrupted run again.
A point that fails (an exception, not a solver status) is recorded with status ``error`` and its
message; the sweep goes on.
"""

from __future__ import annotations

import contextlib
import csv
import io
import itertools
import json
import math
import os
import re
import sys
import time
import traceback
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import AfterValidator, BaseModel, ConfigDict, Field, ValidationError, model_validator

from ..errors import ConfigError, InputError, Unavailable, did_you_mean, shorten
from ..files import not_a_link, read_json_object, replace_text, replacing, write_text
from ..language.config import (
    CONFIG_VERSION,
    MAX_NAME_BYTES,
    Config,
    allowed_keys,
    document_path,
    load_config,
    override_label,
    safe_name,
)
from ..language.yaml_source import SourceMap, dotted, read_yaml
from ..log.sweep_index import INDEX_CSV, SWEEP_JSON
from .lock import DirectoryLock, contents, locked, release_all

MAX_POINTS = 10_000  # every point's config is checked before the sweep starts
INDEX_PARQUET = "index.parquet"
SPEC_FILE = "sweep.yaml"
POINT_JSON = "point.json"
TIMING_COLUMNS = ("step_time_median_s", "step_time_max_s", "wall_s")


# ---------------------------------------------------------------------------------------------
# The spec
# ---------------------------------------------------------------------------------------------


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class Logspace(_Strict):
    """``{logspace: [first exponent, last exponent, count]}``: 10**first .. 10**last."""

    logspace: tuple[Annotated[float, Field(ge=-300, le=300)], Annotated[float, Field(ge=-300, le=300)],
                    Annotated[int, Field(ge=1, le=MAX_POINTS)]]


class Linspace(_Strict):
    linspace: tuple[float, float, Annotated[int, Field(ge=1, le=MAX_POINTS)]]


class Range(_Strict):
    """``{range: [first, last]}`` or ``{range: [first, last, step]}``: integers, last included."""

    range: tuple[int, int] | tuple[int, int, int]

    @model_validator(mode="after")
    def _step(self) -> Range:
        first, last, *rest = self.range
        if rest and rest[0] == 0:
            raise ValueError("the step of a range cannot be 0")
        step = rest[0] if rest else (1 if last >= first else -1)
        n = max(0, (last - first) // step + 1)  # len(range(...)) without building it (or overflowing)
        if n == 0:
            raise ValueError(f"range {list(self.range)} is empty (the step goes away from the last value)")
        if n > MAX_POINTS:
            raise ValueError(f"range {list(self.range)} has {n} values; the limit is {MAX_POINTS}")
        return self


Axis = Annotated[list[Any], Field(min_length=1, max_length=MAX_POINTS)] | Logspace | Linspace | Range


def _sweep_name(name: str) -> str:
    return safe_name(name, "the sweep directory runs/<name>/")


class SweepSpec(_Strict):
    version: Literal[1] = CONFIG_VERSION
    name: Annotated[str, AfterValidator(_sweep_name)] = "sweep"
    base: str = Field(description="the base config, relative to the sweep file")
    command: Literal["simulate", "solve"] = "simulate"
    set: dict[str, Any] = Field(default_factory=dict, description="overrides applied to every point")
    mode: Literal["product", "zip"] = "product"
    grid: dict[str, Axis] = Field(min_length=1, description="field path -> values")


def axis_values(axis: Any) -> list[Any]:
    if isinstance(axis, Logspace):
        a, b, n = axis.logspace
        return [float(v) for v in np.logspace(a, b, n)]
    if isinstance(axis, Linspace):
        a, b, n = axis.linspace
        return [float(v) for v in np.linspace(a, b, n)]
    if isinstance(axis, Range):
        first, last, *rest = axis.range
        step = rest[0] if rest else (1 if last >= first else -1)
        return list(range(first, last + (1 if step > 0 else -1), step))
    return list(axis)


class Point(BaseModel):
    """One run of the sweep: its number, parameters and the overrides that make its config."""

    index: int
    params: dict[str, Any]
    overrides: dict[str, Any]
    config_hash: str
    directory: str  # relative to the sweep directory


class Sweep(BaseModel):
    model_config = ConfigDict(arbitrary_types_allowed=True)

    spec: SweepSpec
    source: str
    base: Path
    points: list[Point]

    @property
    def axes(self) -> list[str]:
        return list(self.spec.grid)


def _slug(params: dict[str, Any]) -> str:
    parts = [f"{k.rsplit('.', 1)[-1]}={_short(v)}" for k, v in params.items()]
    return re.sub(r"[^A-Za-z0-9.=_+-]", "", "_".join(parts))[:80]


def _digest(params: dict[str, Any]) -> str:
    """8 hex digits of the parameters: a point keeps its directory when the grid around it changes."""
    import hashlib

    return hashlib.sha256(json.dumps(params, sort_keys=True, default=str).encode()).hexdigest()[:8]


def _short(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    if isinstance(v, list):
        return "-".join(_short(x) for x in v)
    return str(v)


def load_sweep(path: str | Path) -> Sweep:
    """Read and check a sweep spec and every point's config; every problem is a ConfigError."""
    data, smap = read_yaml(path)
    file = str(path)
    if not isinstance(data, dict) or "grid" not in data and "base" not in data:
        kind = "a config" if isinstance(data, dict) and "game" in data else "not a sweep"
        raise ConfigError([f"{file}:1:1: {kind}: a sweep spec has `base:` (a config) and `grid:` (field -> values); "
                           "run configs with `gnerun simulate` or `gnerun solve`"])
    if "name" not in data:  # the file's name, as a name
        data["name"] = _directory_name(Path(file).stem)
    try:
        spec = SweepSpec.model_validate(data)
    except ValidationError as e:
        problems = []
        for err in e.errors():
            path = document_path(err["loc"], data)
            where = smap.locate(path, key=err["type"] == "extra_forbidden")
            message = err["msg"].removeprefix("Value error, ")
            if err["type"] == "extra_forbidden":  # as in a config: the closest key, and the keys of the place
                allowed = allowed_keys(err["loc"], path, data, SweepSpec)
                message = f"unknown key{did_you_mean(str(path[-1]), allowed)} (allowed here: {', '.join(allowed)})"
            problems.append(f"{where}: {dotted(path, '<sweep>')}: {message}")
        raise ConfigError(problems) from None
    base = (Path(file).parent / spec.base).resolve()
    if not base.is_file():
        raise ConfigError([f"{smap.locate(('base',))}: base: no config file {spec.base!r} next to the sweep"])
    for key in spec.grid:
        if key in spec.set:
            raise ConfigError([f"{smap.locate(('set', key), key=True)}: set.{key}: also an axis of the grid"])
    axes = {k: axis_values(v) for k, v in spec.grid.items()}
    if spec.mode == "zip":
        lengths = {k: len(v) for k, v in axes.items()}
        if len(set(lengths.values())) > 1:
            raise ConfigError([f"{smap.locate(('grid',))}: grid: mode zip needs axes of one length, got "
                               + ", ".join(f"{k} {n}" for k, n in lengths.items())])
        combos = list(zip(*axes.values(), strict=True))
    else:
        count = math.prod(len(v) for v in axes.values())
        if count > MAX_POINTS:
            raise ConfigError([f"{smap.locate(('grid',))}: grid: {count} points; the limit is {MAX_POINTS}"])
        combos = list(itertools.product(*axes.values()))
    points = []
    seen: dict[str, int] = {}
    for i, combo in enumerate(combos):
        params = dict(zip(axes, combo, strict=True))
        same = seen.setdefault(json.dumps(params, sort_keys=True, default=str), i)
        if same != i:  # one run directory per point: the same parameters twice would share one
            shown = shorten(", ".join(f"{k}={v!r}" for k, v in params.items()), 200)
            raise ConfigError([f"{smap.locate(('grid',))}: grid: points {same} and {i} have the same parameters "
                               f"({shown}): an axis lists a value twice"])
        overrides = {**spec.set, **params}
        cfg = _point_config(base, overrides, params, i, smap)
        if spec.command == "simulate" and cfg.game.kind != "dynamic":
            raise ConfigError([f"{smap.locate(('command',))}: command: simulate needs a dynamic game; "
                               f"{spec.base} is static (use command: solve)"])
        points.append(Point(index=i, params=params, overrides=overrides, config_hash=cfg.config_hash(),
                            directory=f"points/{_slug(params)}-{_digest(params)}"))
    return Sweep(spec=spec, source=file, base=base, points=points)


def _point_config(base: Path, overrides: dict[str, Any], params: dict[str, Any], i: int, smap: SourceMap) -> Config:
    """The config of one point; a problem in an override is located at its line in the sweep file."""
    try:
        return load_config(base, overrides)
    except ConfigError as e:
        problems = []
        shown = ", ".join(f"{k}={v!r}" for k, v in params.items())
        for p in e.problems:
            for k, v in overrides.items():
                prefix = f"{shorten(override_label(k, v), 100)}: "  # as SourceMap.locate names it
                if p.startswith(prefix):
                    where = smap.locate(("grid", k) if k in params else ("set", k))
                    p = f"{where}: {p[len(prefix):]} (point {i}: {shown})"
                    break
            problems.append(p)
        raise ConfigError(problems) from None


# ---------------------------------------------------------------------------------------------
# Running one point (in a worker)
# ---------------------------------------------------------------------------------------------


def run_point(task: dict[str, Any]) -> list[dict[str, Any]]:
    """Run one point into its run directory and return its index rows; never raises.

    ``task``: base (config path), overrides, out (the point's run directory), command, params, index,
    directory, config_hash. Module-level and plain-data in and out, so that any executor can ship it.
    """
    global _point_in_progress
    out = Path(task["out"])
    t0 = time.perf_counter()
    lock = None
    _point_in_progress = True
    try:
        try:  # the point's directory is written by this point alone
            for part in (out.parent, out):  # points/ and the point's own, never a link planted to elsewhere
                not_a_link(part)
            if out.exists() and not out.is_dir():
                raise InputError(f"{out}: exists and is not a directory")
            out.mkdir(parents=True, exist_ok=True)
            lock = DirectoryLock.acquire(out)
        except (InputError, OSError) as e:
            message = str(e) if isinstance(e, InputError) else f"{out}: cannot write the point: {e.strerror or e}"
            return [_row(task, K=None, status="error", message=message, wall=time.perf_counter() - t0)]
        with lock.lent():  # the run inside writes the point's directory under this lock
            return _run_point(task, out, t0)
    except (_Stopped, KeyboardInterrupt):  # stopped: the point ended (interrupted) or was cut short
        _abandon(143)
    finally:
        _point_in_progress = False
        if lock is not None:
            lock.release()


def _abandon(code: int) -> None:
    """End a stopped worker at once, its locks released (the point's log was closed on the way, or is left as a
    killed run's log is)."""
    release_all()
    os._exit(code)


def _run_point(task: dict[str, Any], out: Path, t0: float) -> list[dict[str, Any]]:
    from ..game.compile import compile_game, compile_key
    from .closed_loop import simulate
    from .solving import solve

    try:
        cfg = load_config(task["base"], task["overrides"])
        # points that differ in runtime values and x0 only share one compiled game per worker
        key = compile_key(cfg)
        compiled = key not in _compiled
        if compiled:
            _compiled.clear()  # one game kept: a sweep over compiled parameters does not accumulate them
            _compiled[key] = compile_game(cfg)
        game = _compiled[key]
        if task["command"] == "simulate":
            simulate(cfg, out=out, force=True, game=game)
        else:
            solve(cfg, out=out, force=True, game=game)
        wall = time.perf_counter() - t0
        replace_text(out / POINT_JSON, json.dumps({"index": task["index"], "params": task["params"],
                                                   "config_hash": task["config_hash"], "wall_s": wall,
                                                   "compiled": compiled, "worker": os.getpid()}) + "\n")
        # from the written summary, as for a point skipped on resume: the same rows either way
        rows = rows_from_summary(task, read_json_object(out / "summary.json"), wall)
        for r in rows:
            r["compiled"] = compiled
        return rows
    except Exception as e:  # noqa: BLE001 - a failed point is a row, never the end of the sweep
        message = f"{type(e).__name__}: {e}" if not isinstance(e, InputError | Unavailable) else str(e)
        try:
            replace_text(out / POINT_JSON, json.dumps({"index": task["index"], "params": task["params"],
                                                       "config_hash": task["config_hash"], "status": "error",
                                                       "message": message,
                                                       "traceback": traceback.format_exc()}) + "\n")
        except (OSError, InputError):
            pass
        return [_row(task, K=None, status="error", message=message.splitlines()[0] if message else "",
                     wall=time.perf_counter() - t0)]


def _row(task: dict[str, Any], *, K: int | None, status: str, message: str = "", iterations: int | None = None,
         failed_steps: int | None = None, max_e: float | None = None, final_e: float | None = None,
         asymptotic_e: float | None = None, step_median: float | None = None, step_max: float | None = None,
         wall: float | None = None) -> dict[str, Any]:
    row: dict[str, Any] = {"point": task["index"], "directory": task["directory"]}
    row.update(task["params"])
    row.update({"K": K, "status": status, "failed_steps": failed_steps, "iterations": iterations, "max_e": max_e,
                "final_e": final_e, "asymptotic_e": asymptotic_e, "step_time_median_s": step_median,
                "step_time_max_s": step_max, "wall_s": wall, "message": message})
    return row


def _finite(values: list[Any]) -> list[float]:
    return [float(v) for v in values if v is not None and math.isfinite(v)]


def rows_from_summary(task: dict[str, Any], summary: dict[str, Any], wall: float | None) -> list[dict[str, Any]]:
    """Index rows from a finished point's summary.json.

    simulate: one row per K; ``asymptotic_e`` is the mean of ||e(t)|| over the second half of the sampling
    times (the level the error settles at), ``iterations`` the solver steps of the whole loop.
    solve: one row; e is ||z^k - z*|| along the iterations.
    """
    if task["command"] == "solve":
        errors = _finite(summary.get("error_history") or [])
        its = summary.get("iterations") or 0
        return [_row(task, K=None, status=summary["status"], message=summary.get("message", ""), iterations=its,
                     max_e=max(errors) if errors else None, final_e=errors[-1] if errors else None,
                     asymptotic_e=errors[-1] if errors else None,
                     step_median=summary["time_s"] / its if its else None, step_max=None, wall=wall)]
    rows = []
    for K, loop in summary["by_K"].items():
        e = loop["e_norm"]
        tail = _finite(e[len(e) // 2:])
        times = _finite(loop["solve_time_s"])
        rows.append(_row(
            task, K=int(K), status=loop["ended"] if loop["ended"] != "completed" else summary["status"],
            iterations=int(sum(loop["iterations"])), failed_steps=len(loop["failed_steps"]),
            max_e=loop["max_e_norm"], final_e=loop["final_e_norm"],
            asymptotic_e=float(np.mean(tail)) if tail else None,
            step_median=float(np.median(times)) if times else None, step_max=max(times) if times else None,
            wall=wall))
    return rows


# ---------------------------------------------------------------------------------------------
# Executors
# ---------------------------------------------------------------------------------------------

Completed = Iterator[tuple[dict[str, Any], list[dict[str, Any]]]]


_point_in_progress = False  # in a worker: run_point is running
_compiled: dict[str, Any] = {}  # in a worker: the game compiled last, by its compile key
STOP_GRACE_S = 5.0  # a stopped worker closes its point within this time, or exits without closing it


class _Stopped(BaseException):
    """SIGTERM in a worker before its run listens for a stop: unwinds the point (its lock released), then the worker
    exits (the executor would otherwise take it as the point's result and go on to the next)."""


def _worker_start(parent: int) -> None:
    """A worker leaves Ctrl-C and a terminal's hang-up to the sweep, which stops it with SIGTERM: the run in progress
    then ends as a stopped run does (at the end of its iterate or sampling time: a finished log, a summary of status
    interrupted, so that the point runs again on resume), its directory's lock is released, and the worker exits.
    A run that does not end within ``STOP_GRACE_S`` is left as a killed run's log is. On Linux a worker also dies
    with the sweep when the sweep is killed (SIGKILL): no worker outlives it."""
    import signal
    import threading

    from .interrupt import leave_signals_to_the_parent, request_stop

    stopping = []

    def stop(signum, frame) -> None:
        if not _point_in_progress:  # idle: nothing to close (and the executor's exit would wait on a dead sweep)
            os._exit(128 + signum)
        if stopping:  # a stop on top (the sweep's, after the process group's): the point is ending already
            return
        stopping.append(signum)
        threading.Timer(STOP_GRACE_S, _abandon, (128 + signum,)).start()
        # a request, not an exception: one raised here could land inside a write of the log and leave half a record
        if not request_stop(signal.Signals(signum).name):
            raise _Stopped  # no run is listening yet (its config is being loaded or its game compiled)

    leave_signals_to_the_parent()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGHUP, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, stop)
    if sys.platform.startswith("linux"):
        import ctypes

        with contextlib.suppress(OSError, AttributeError):
            ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    if os.getppid() != parent:  # the sweep died before the line above
        os._exit(1)


def stop_resource_tracker() -> None:
    """Stop multiprocessing's resource tracker, if the sweep started one, and wait until it has exited: the command
    line calls this once its pool is gone, so that the sweep ends after every process it started (the tracker
    otherwise exits only once the sweep has, outside it). Not for a library caller, whose own resources may still
    be registered with the tracker."""
    from multiprocessing import resource_tracker

    tracker = getattr(resource_tracker, "_resource_tracker", None)
    fd, pid = getattr(tracker, "_fd", None), getattr(tracker, "_pid", None)
    if fd is None or pid is None:
        return
    with contextlib.suppress(OSError):
        os.close(fd)  # the tracker ends once every copy of this pipe is closed (a worker that lingers holds one)
    tracker._fd = tracker._pid = None
    deadline = time.monotonic() + STOP_GRACE_S  # never waits long for it
    while time.monotonic() < deadline:
        try:
            if os.waitpid(pid, os.WNOHANG)[0]:
                return
        except ChildProcessError:
            return
        time.sleep(0.01)


def available_cpus() -> int:
    """The CPUs this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def _local(tasks: list[dict[str, Any]], workers: int) -> Completed:
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    # spawn: workers start clean (no forked BLAS or CasADi state), as on any platform; they stay in the sweep's
    # process group, so that a signal to the group (a terminal's Ctrl-C, a scheduler's stop) reaches them too
    with _hangups_blocked():  # the pool's helpers start with a hang-up blocked (see _hangups_blocked)
        pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                                   initializer=_worker_start, initargs=(os.getpid(),))
    try:
        with _hangups_blocked():
            futures = {pool.submit(run_point, t): t for t in tasks}
        for f in as_completed(futures):
            task = futures[f]
            try:
                rows = f.result()
            except Exception as e:  # noqa: BLE001 - a worker process died (killed, out of memory)
                rows = [_row(task, K=None, status="error", message=f"worker process failed: {e}")]
            yield task, rows
    except BaseException:  # Ctrl-C, or the consumer stopped: stop the points in progress too
        stop = getattr(pool, "terminate_workers", None)  # Python 3.14
        if stop is not None:
            stop()
        else:  # before shutdown, which forgets the processes
            procs = list((getattr(pool, "_processes", None) or {}).values())
            for proc in procs:
                proc.terminate()
            for proc in procs:
                _reaped(proc)
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


@contextlib.contextmanager
def _hangups_blocked() -> Iterator[None]:
    """SIGHUP blocked while the pool starts its processes, which inherit the block: a closed terminal hangs up the
    whole process group, and multiprocessing's resource tracker (which ignores SIGINT and SIGTERM only) would die of
    it and be started again with warnings and tracebacks on stderr; a worker ignores hang-ups once it runs. The sweep
    itself gets a hang-up sent meanwhile once the block ends."""
    import signal

    if not hasattr(signal, "pthread_sigmask") or not hasattr(signal, "SIGHUP"):
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGHUP})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def _reaped(proc, grace: float = 2 * STOP_GRACE_S) -> None:
    """Wait until a stopped worker has exited and is reaped (its pipes close before it is gone: join alone may
    return while it still exits); one still there after ``grace`` seconds is killed."""
    deadline = time.monotonic() + grace
    killed = False
    proc.join(timeout=grace)
    while proc.exitcode is None:  # exitcode reaps it once it has exited
        if time.monotonic() > deadline and not killed:
            proc.kill()
            killed, deadline = True, time.monotonic() + grace
        elif time.monotonic() > deadline:
            return
        time.sleep(0.02)


def _dask(tasks: list[dict[str, Any]], workers: int, address: str | None) -> Completed:
    try:
        from dask.distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise Unavailable("the dask executor needs Dask: pip install 'gnerun[dask]'") from None
    cluster = None
    try:
        if address is None:
            import logging

            # warnings and errors of its own shutdown are not the user's business: Ctrl-C cancels the tasks in
            # progress, and a worker whose heartbeat finds the scheduler gone logs an error with its traceback (a
            # point that fails is reported by its future, in its row of the index)
            with _hangups_blocked():  # its processes, as a local pool's (see _hangups_blocked)
                # no dashboard; its HTTP server (health routes) on a free port of this host, not 8787, which
                # another cluster (another sweep, a notebook) may hold
                cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                       dashboard_address=None, scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},
                                       silence_logs=logging.CRITICAL)
                client = Client(cluster)
        elif Path(address).is_file():  # a scheduler file (`dask scheduler --scheduler-file F`), as on HPC
            client = Client(scheduler_file=address, timeout="20s")
        else:
            client = Client(address, timeout="20s")
    except OSError as e:
        if cluster is not None:
            cluster.close()
        raise Unavailable(f"cannot reach the Dask scheduler at {address}: {e}") from None
    try:
        futures = {client.submit(run_point, t, pure=False, key=f"gnerun-point-{t['index']}-{t['config_hash'][:12]}"):
                   t for t in tasks}
        for f in as_completed(futures):
            task = futures[f]
            try:
                rows = f.result()
            except Exception as e:  # noqa: BLE001 - a worker died or the task could not run there
                rows = [_row(task, K=None, status="error", message=f"dask: {type(e).__name__}: {e}")]
            yield task, rows
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


# ---------------------------------------------------------------------------------------------
# The sweep
# ---------------------------------------------------------------------------------------------


class SweepResult(BaseModel):
    directory: Path
    rows: list[dict[str, Any]]
    ran: int
    skipped: int
    failed: int
    wall_s: float
    executor: str
    index_files: list[Path]
    games_compiled: int = 0  # games the points that ran compiled: points differing in runtime values share one


def _finished(sweep_dir: Path, point: Point) -> tuple[dict[str, Any], dict[str, Any]] | None:
    """(point.json, summary.json) of a point finished with this config, or None: it has to run."""
    out = sweep_dir / point.directory
    try:  # a point whose files are missing or damaged runs again
        meta = read_json_object(out / POINT_JSON)
        summary = read_json_object(out / "summary.json")
    except InputError:
        return None
    if (meta.get("config_hash") == point.config_hash and meta.get("status") != "error"
            and summary.get("status") not in ("interrupted", "error")):
        return meta, summary
    return None


def _task(sweep: Sweep, sweep_dir: Path, p: Point) -> dict[str, Any]:
    return {"index": p.index, "params": p.params, "overrides": p.overrides, "config_hash": p.config_hash,
            "directory": p.directory, "base": str(sweep.base), "command": sweep.spec.command,
            "out": str(sweep_dir.resolve() / p.directory)}  # the point's own components unresolved: see run_point


def check_executor(executor: str, workers: int, address: str | None, force_workers: bool = True) -> None:
    """The executor's options make sense; unless ``force_workers``, workers on this machine (local, or a dask
    LocalCluster) are at most its CPUs: more only slow each other down and each one takes memory."""
    if executor not in ("local", "dask"):
        raise InputError(f"--executor {executor}: choose local or dask")
    if workers < 1:
        raise InputError(f"--workers {workers}: at least 1")
    if address is not None and executor != "dask":
        raise InputError("--address needs --executor dask")
    cpus = available_cpus()
    if address is None and workers > cpus and not force_workers:
        raise InputError(f"--workers {workers}: this machine has {cpus} CPU{'s' * (cpus > 1)} for gnerun; more "
                         "workers than CPUs only slow each other down, and each takes its own memory (about 150 "
                         "MB); use --force-workers to start them anyway")


def run_sweep(sweep: Sweep, out: str | Path, *, executor: str = "local", workers: int = 2,
              address: str | None = None, force: bool = False,
              progress: Callable[[int, int, dict[str, Any], list[dict[str, Any]]], None] | None = None) -> SweepResult:
    """Run the points not yet finished in ``out`` and write the index (after every point)."""
    check_executor(executor, workers, address)
    sweep_dir = Path(out)
    if sweep_dir.exists() and not sweep_dir.is_dir():
        raise InputError(f"{sweep_dir}: exists and is not a directory")
    try:
        sweep_dir.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise InputError(f"{sweep_dir}: cannot write the sweep directory: {e.strerror or e}") from None
    with locked(sweep_dir, "sweep directory"):
        return _run_sweep(sweep, sweep_dir, executor, workers, address, force, progress)


def _run_sweep(sweep: Sweep, sweep_dir: Path, executor: str, workers: int, address: str | None, force: bool,
               progress: Callable[[int, int, dict[str, Any], list[dict[str, Any]]], None] | None) -> SweepResult:
    """run_sweep's work, with the sweep directory locked: no other process writes into it meanwhile."""
    if contents(sweep_dir) and not (sweep_dir / SPEC_FILE).is_file() and not force:
        raise InputError(f"{sweep_dir}: exists, is not empty and holds no sweep (use --force to write into it)")
    try:
        write_text(sweep_dir / SPEC_FILE, Path(sweep.source).read_text())
    except OSError as e:
        raise InputError(f"{sweep_dir}: cannot write the sweep directory: {e.strerror or e}") from None
    t0 = time.perf_counter()
    rows: dict[int, list[dict[str, Any]]] = {}
    tasks = []
    for p in sweep.points:
        task = _task(sweep, sweep_dir, p)
        finished = _finished(sweep_dir, p)
        try:
            if finished is not None:
                meta, summary = finished
                rows[p.index] = rows_from_summary(task, summary, meta.get("wall_s"))
                continue
        except (KeyError, TypeError, ValueError, AttributeError):  # a summary.json edited by hand: run it again
            pass
        tasks.append(task)
    skipped = len(rows)
    failed = 0
    compiled = 0  # the games the points that ran compiled (points sharing a compiled game count none)
    done = skipped
    completed = _local(tasks, workers) if executor == "local" else _dask(tasks, workers, address)
    try:
        for task, task_rows in completed if tasks else ():
            rows[task["index"]] = task_rows
            failed += any(r["status"] == "error" for r in task_rows)
            compiled += any([r.pop("compiled", False) for r in task_rows])  # (not a column of the index)
            done += 1
            if done < len(sweep.points):  # the last one is written below, with the parquet table
                write_index(sweep, sweep_dir, rows, parquet=False)
            if progress is not None:
                progress(done, len(sweep.points), task, task_rows)
    finally:
        files = write_index(sweep, sweep_dir, rows)
        wall = time.perf_counter() - t0
        replace_text(sweep_dir / SWEEP_JSON, json.dumps({
            "name": sweep.spec.name, "source": sweep.source, "base": str(sweep.base), "axes": sweep.axes,
            "mode": sweep.spec.mode, "command": sweep.spec.command, "points": len(sweep.points),
            "finished": len(rows), "ran": len(rows) - skipped, "skipped": skipped, "failed": failed,
            "executor": executor, "workers": workers, "address": address, "wall_s": wall,
            "games_compiled": compiled}, indent=2) + "\n")
    return SweepResult(directory=sweep_dir, rows=[r for i in sorted(rows) for r in rows[i]], ran=len(rows) - skipped,
                       skipped=skipped, failed=failed, wall_s=wall, executor=executor, index_files=files,
                       games_compiled=compiled)


def columns(sweep: Sweep) -> list[str]:
    return ["point", "directory", *sweep.axes, "K", "status", "failed_steps", "iterations", "max_e", "final_e",
            "asymptotic_e", "step_time_median_s", "step_time_max_s", "wall_s", "message"]


def _cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return repr(v)  # round-trips exactly
    if isinstance(v, list | dict):
        return json.dumps(v)
    return str(v)


def write_index(sweep: Sweep, sweep_dir: Path, rows: dict[int, list[dict[str, Any]]], *,
                parquet: bool = True) -> list[Path]:
    """index.csv (and index.parquet when pyarrow is installed and ``parquet``), rows by point; replaced
    atomically."""
    cols = columns(sweep)
    ordered = [r for i in sorted(rows) for r in rows[i]]
    target = sweep_dir / INDEX_CSV
    text = io.StringIO(newline="")
    w = csv.writer(text)
    w.writerow(cols)
    for r in ordered:
        w.writerow([_cell(r.get(c)) for c in cols])
    replace_text(target, text.getvalue())
    written = [target]
    if not parquet:
        return written
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return written
    table = pa.table({c: [_parquet_value(r.get(c)) for r in ordered] for c in cols})
    with replacing(sweep_dir / INDEX_PARQUET) as f:
        pq.write_table(table, f)
    written.append(sweep_dir / INDEX_PARQUET)
    return written


def _parquet_value(v: Any) -> Any:
    return json.dumps(v) if isinstance(v, list | dict) else v


def default_sweep_dir(sweep: Sweep) -> Path:
    """runs/<sweep name>/: one stable place, so that running the sweep again resumes it."""
    return Path("runs") / _directory_name(sweep.spec.name)


def _directory_name(name: str) -> str:
    """``name`` as one plain path component of letters, digits and ``._-`` (never ``.`` or ``..``)."""
    plain = re.sub(r"[^A-Za-z0-9._-]+", "-", name).strip("-").lstrip(".")[:MAX_NAME_BYTES].strip("-")
    return plain or "sweep"
