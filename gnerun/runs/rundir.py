"""Run directories: config.yaml, run.mcap, summary.json."""

from __future__ import annotations

import contextlib
import datetime as dt
import functools
import json
import math
import shutil
import subprocess
import time
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path

from .. import __version__
from ..errors import InputError, WriteError, shorten
from ..files import replace_text, write_text
from ..language.config import Config
from ..language.runtime import data_path
from ..log.mcap_log import RunLog, json_ready
from ..log.messages import Message, SamplingTime, SolveIterate
from ..log.plans import PlanStates
from ..log.topics import SOLVE_ITERATE
from ..log.writer import LogProcess, open_log
from .interrupt import Stopped
from .lock import DirectoryLock, contents


def default_run_dir(cfg: Config, root: str | Path = "runs") -> Path:
    stamp = dt.datetime.now(dt.UTC).strftime("%Y%m%dT%H%M%SZ")
    return Path(root) / f"{cfg.name}-{stamp}"


def claim_default_run_dir(cfg: Config, root: str | Path = "runs") -> Path:
    """:func:`default_run_dir`, claimed by creating it: a run of the same config started in the same second (in
    parallel, or just after) gets ``<name>-<timestamp>-2/`` and so on, instead of being refused by the other's
    directory. Where no directory can be made, the path is returned for the run to say why."""
    base = default_run_dir(cfg, root)
    for i in range(1, 1000):
        path = base if i == 1 else base.with_name(f"{base.name}-{i}")
        try:
            path.mkdir(parents=True)
            return path
        except FileExistsError:
            continue
        except OSError:
            return path
    return path


def remove_if_empty(path: Path) -> None:
    """Remove a claimed run directory that the run left empty (it stopped before writing anything)."""
    with contextlib.suppress(OSError):
        path.rmdir()  # only ever removes an empty directory


@functools.lru_cache(maxsize=1)
def git_describe() -> str:
    """``git describe`` of the gnerun sources, or "unknown" outside a checkout."""
    here = Path(__file__).resolve().parent
    try:
        out = subprocess.run(["git", "-C", str(here), "describe", "--always", "--dirty", "--tags"],
                             capture_output=True, text=True, timeout=5, check=False)
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return out.stdout.strip() if out.returncode == 0 and out.stdout.strip() else "unknown"


def data_copies(cfg: Config) -> dict[str, tuple[Path, str]]:
    """The data files of a config's runtime parameters and where a run directory keeps their copies (data/<file>,
    relative to it: the config.yaml written there names the copies, so that the run can be run again from it)."""
    out: dict[str, tuple[Path, str]] = {}
    taken: dict[str, Path] = {}
    for name, spec in cfg.game.runtime.items():
        if spec.file is None:
            continue
        source = data_path(cfg.source, spec.file).resolve()
        target = f"data/{source.name}"
        if taken.get(target, source) != source:
            target = f"data/{name}-{source.name}"
        taken[target] = source
        out[name] = (source, target)
    return out


class RunDirectory:
    """An open run directory and its MCAP log; it holds the directory's lock until :meth:`close`."""

    def __init__(self, path: Path, log: RunLog | LogProcess, lock: DirectoryLock | None = None):
        self.path = path
        self.log_sink = log
        self._lock = lock
        self.summary_written = False
        self.time_s = 0.0  # the time spent writing the directory (messages made, log, summary; :meth:`timed`)
        self._depth = 0

    @contextlib.contextmanager
    def timed(self) -> Iterator[None]:
        """Count the time of the block in :attr:`time_s` (a block inside another is counted once)."""
        self._depth += 1
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self._depth -= 1
            if not self._depth:
                self.time_s += time.perf_counter() - t0

    @classmethod
    def create(cls, out: str | Path, cfg: Config, *, command: str, force: bool = False) -> RunDirectory:
        """The run directory at ``out`` with its config.yaml and an open log (written by a process of its own for
        a closed loop with ``run.log_writer: process``)."""
        t0 = time.perf_counter()
        run = cls._create(out, cfg, command=command, force=force)
        run.time_s += time.perf_counter() - t0
        return run

    @classmethod
    def _create(cls, out: str | Path, cfg: Config, *, command: str, force: bool) -> RunDirectory:
        path = Path(out)
        shown = shorten(str(path), 100)
        try:
            if path.exists() and not path.is_dir():
                raise InputError(f"{shown}: exists and is not a directory")
            path.mkdir(parents=True, exist_ok=True)
        except OSError as e:  # a name too long, a path through a file, no permission
            raise InputError(f"{shown}: cannot write the run directory: {e.strerror or e}") from None
        lock = DirectoryLock.acquire(path)
        made: list[Path] = []  # what a directory that could not be made complete loses again: none is left half-made
        try:
            if contents(path) and not force:
                raise InputError(f"{path}: the run directory exists and is not empty (force=True overwrites it)",
                                 cli=f"{path}: the run directory exists and is not empty (use --force to overwrite)")
            copies = data_copies(cfg)
            for source, target in copies.values():
                made.append(path / target)
                (path / target).parent.mkdir(exist_ok=True)
                shutil.copyfile(source, path / target)  # the data file is only read
            config_yaml = cfg.resolved_yaml({name: target for name, (_, target) in copies.items()})
            for stale in ("summary.json", "summary.json.tmp"):  # unlink never follows a link
                (path / stale).unlink(missing_ok=True)
            made.append(path / "config.yaml")
            write_text(path / "config.yaml", config_yaml)
            metadata = {
                "version": __version__,
                "config_hash": cfg.config_hash(None if copies else config_yaml),  # config.yaml's text, as written
                "seed": str(cfg.disturbance.seed),
                "git_describe": git_describe(),
                "command": command,
                "config_name": cfg.name,
                "created_utc": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
                # the log's time axis is the run's own: a closed loop's simulated time, a solve's iterations
                "log_time": (f"simulated: t x run.sampling_time ({cfg.run.sampling_time:g} s)"
                             if command == "simulate" else "iteration: k x 1 s"),
            }
            made.append(path / "run.mcap")
            log = open_log(path / "run.mcap", config_yaml=config_yaml, metadata=metadata,
                           process=command == "simulate" and cfg.run.log_writer == "process")
            log.set_time(0)  # the run's start on its own time axis
        except BaseException as exc:
            for f in made:
                with contextlib.suppress(OSError):
                    f.unlink()
            lock.release()
            if isinstance(exc, OSError):
                raise InputError(f"{path}: cannot write the run directory: {exc.strerror or exc}") from None
            raise
        return cls(path, log, lock)

    def write_iterate(self, state, error_norm: float | None) -> None:
        """Iterate k at log_time k seconds (and what follows, until the next iterate)."""
        with self.timed():
            self.at(state.k)
            r = state.residual_norm
            self.log_sink.write(SOLVE_ITERATE, SolveIterate(
                k=state.k,
                z=state.z.tolist(),
                residual_norm=r,
                log10_residual_norm=math.log10(r) if r > 0 and math.isfinite(r) else None,
                error_norm=error_norm,
                step_norm=state.step_norm,
                active_set_changes=state.active_set_changes,
            ))
            self.log_sink.flush()

    def write(self, topic: str, message: Message) -> None:
        with self.timed():
            self.log_sink.write(topic, message)

    def flush(self) -> None:
        with self.timed():
            self.log_sink.flush()

    def plan_states(self, plan_states: PlanStates) -> bool:
        """Whether the log computes the plans' predicted states itself (a log written by a process of its own)."""
        return self.log_sink.plan_states(plan_states)

    def sampling_time(self, record: SamplingTime) -> None:
        """A closed loop's sampling time, flushed."""
        with self.timed():
            self.log_sink.sampling_time(record)

    def at(self, seconds: float) -> None:
        """Stamp what follows (messages and /log) with this simulated time."""
        self.log_sink.set_time(round(seconds * 1e9))

    def log(self, level: str, text: str) -> None:
        with self.timed():
            self.log_sink.log(level, text)
            self.log_sink.flush()

    def write_summary(self, summary: dict) -> None:
        with self.timed():
            try:
                text = json.dumps(json_ready(summary), indent=2, allow_nan=False) + "\n"
                replace_text(self.path / "summary.json", text)
                self.summary_written = True
            except OSError as e:
                raise WriteError(f"{self.path / 'summary.json'}: cannot write the summary: {e.strerror or e} "
                                 "(is the disk full?); the run log holds every flushed step") from None

    def close(self) -> None:
        try:
            with self.timed():
                self.log_sink.close()
        finally:
            if self._lock is not None:
                self._lock.release()


@contextlib.contextmanager
def numerical_warnings(run: RunDirectory | None) -> Iterator[None]:
    """numpy's RuntimeWarnings (overflow, invalid values: iterates beyond the range of doubles) become warning lines
    in the run's ``/log``, once per place, instead of lines on stderr: the solver's status already says what they
    led to (diverged, nan, ...). Without a run they are left to Python as usual."""
    if run is None:
        yield
        return
    with warnings.catch_warnings():
        warnings.simplefilter("default", RuntimeWarning)  # once per place in the code
        shown = warnings.showwarning

        def show(message, category, filename, lineno, file=None, line=None) -> None:
            if not issubclass(category, RuntimeWarning):
                shown(message, category, filename, lineno, file, line)
                return
            where = f"{Path(filename).parent.name}/{Path(filename).name}:{lineno}"
            with contextlib.suppress(WriteError):
                run.log("warning", f"floating-point trouble: {message} ({where}); the status says where it led")

        warnings.showwarning = show
        yield


def ended_by(exc: BaseException) -> tuple[str, str]:
    """The status and message of a run that an exception ended: ``interrupted`` for Ctrl-C (a second one stops at
    once), ``error`` for anything else (a callback that raised, a failure inside the solver, a log that cannot be
    written)."""
    if isinstance(exc, KeyboardInterrupt | Stopped):
        return "interrupted", ("interrupted at once (KeyboardInterrupt: Ctrl-C before the run could stop at the end "
                               "of a step, a second signal, or a callback); the summary holds what was done")
    text = str(exc).strip()
    return "error", f"the run stopped: {type(exc).__name__}" + (f": {text}" if text else "")


@contextlib.contextmanager
def recording(run: RunDirectory | None,
              summary: Callable[[BaseException], dict] | None = None) -> Iterator[RunDirectory | None]:
    """Whatever ends the run, the directory is complete: an exception that ends it is logged to ``/log``, and unless
    the run wrote its summary, ``summary(exc)`` is written as ``summary.json`` (status ``error`` or ``interrupted``,
    and the message); the log is always closed (a finished MCAP) and the directory's lock released. Numerical
    warnings go to the log too (:func:`numerical_warnings`)."""
    with numerical_warnings(run):
        try:
            yield run
        except BaseException as exc:
            if run is not None:
                # the error that ends the run is on its way: nothing here may replace it (a log that cannot be written,
                # a summary that cannot be made), and the lock is released whatever happens
                try:
                    with contextlib.suppress(Exception):
                        run.log("error", f"the run stopped: {type(exc).__name__}: {exc}")
                    if summary is not None and not run.summary_written:
                        with contextlib.suppress(Exception):
                            run.write_summary(summary(exc))
                finally:
                    with contextlib.suppress(Exception):
                        run.close()
            raise
        else:
            if run is not None:
                run.close()
