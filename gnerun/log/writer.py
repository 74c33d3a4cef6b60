"""A run log written by a process of its own (``run.log_writer: process``).

In a closed loop the log sits on the real-time path: on the 41-knot MPC merge, making a sampling time's messages,
their JSON, mcap's records, the chunk's compression and the flush took about 0.5 ms of a 1.45 ms sampling time in
the loop's own process. A thread does not help (the GIL: the same 1.4-1.5 ms). :class:`LogProcess` has
:class:`~gnerun.log.mcap_log.RunLog`'s interface and hands every call through a pipe to a process that owns the
RunLog; a sampling time crosses as plain numbers (:class:`~gnerun.log.messages.SamplingTime`), which the writer
turns into messages. The writer polls the pipe, pausing 0.2 ms and, while nothing comes, up to 5 ms: a reader
waiting in the kernel cost the loop about 40 us a sampling time to wake.

What a run log promises still holds:
- the writer writes and flushes each sampling time as it receives it;
- a run that ends closes the log: the writer finishes it and ends;
- a loop process killed without clean-up closes the pipe, and the writer finishes the log from what it received;
- a write the disk refuses surfaces in the loop's process as a WriteError at the next flush or at close;
- the writer is a python of its own in a session of its own (nothing of the loop's process is copied, and Ctrl-C
  or a closed terminal reach the loop's process alone), and it ignores SIGINT, SIGTERM and SIGHUP: a stop is the
  loop process's to handle, which ends the run and closes the log.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import pickle
import signal
import subprocess
import sys
import time
import weakref
from multiprocessing.connection import Connection
from pathlib import Path
from typing import TYPE_CHECKING

from ..errors import WriteError
from .mcap_log import RunLog, model_for
from .messages import Message, SamplingTime

if TYPE_CHECKING:
    from .plans import PlanStates  # casadi: loaded where plans are computed, not where logs are read

PAUSE = 2e-4  # seconds between looks at an empty pipe, doubling while it stays empty
MAX_PAUSE = 5e-3
PIPE_BYTES = 2**20  # room for about 450 sampling times of the merge (2.3 kB each) before the loop waits
CHECK_EVERY = 0.05  # seconds between looks for the writer's news while a closed loop runs
CLOSE_TIMEOUT = 120.0  # seconds a closing run waits for the writer to finish the log


def serve(source: Connection, replies: Connection) -> None:
    """The writer: opens the RunLog its first message names, then carries out the calls that come through
    ``source`` until the loop's process closes the log or ends; ``replies`` gets ("ready",) or the OSError of the
    open, ("broken", why) when writing fails, and ("closed", why or None) at the end."""
    try:
        path, config_yaml, metadata = source.recv()
    except EOFError:
        return
    try:
        log = RunLog(path, config_yaml=config_yaml, metadata=metadata)
    except OSError as e:
        replies.send(("oserror", e.errno, e.strerror, e.filename))
        return
    except WriteError as e:  # opened, but its first records were refused
        replies.send(("oserror", None, str(e), path))
        return
    replies.send(("ready",))
    why: str | None = None  # why writing stopped: the disk refused (RunLog.broken), or a call failed
    reported = False
    pause = PAUSE
    try:
        while True:
            if not source.poll(0):
                time.sleep(pause)
                pause = min(2 * pause, MAX_PAUSE)
                continue
            pause = PAUSE
            try:
                kind, *args, t = source.recv()
                if kind == "close":
                    break
                if why is None:
                    log.set_time(t)
                    if kind == "write":
                        log.write(args[0], args[1], log_time=t)
                    elif kind == "log":
                        log.log(*args)
                    elif kind == "sampling":
                        log.sampling_time(SamplingTime.unpack(args[0]))
                    elif kind == "plans":
                        log.plan_states(args[0])
                    else:
                        log.flush()
            except EOFError:  # the loop's process ended without closing the log (killed): finish what came
                break
            except WriteError:
                why = log.broken
            except Exception as e:  # noqa: BLE001 (a call the writer cannot carry out: the log stops there, readable)
                why = f"the log writer failed: {type(e).__name__}: {e}"
            if why is not None and not reported:
                reported = True
                with contextlib.suppress(OSError):
                    replies.send(("broken", why))
    finally:
        with contextlib.suppress(WriteError):
            log.close()
        with contextlib.suppress(OSError):
            replies.send(("closed", why or log.broken))


def _abandon(pipe: Connection, process: subprocess.Popen) -> None:
    """At the interpreter's exit, for a log nobody closed: end the pipe, so that the writer finishes the log."""
    pipe.close()
    with contextlib.suppress(subprocess.TimeoutExpired):
        process.wait(CLOSE_TIMEOUT)


class LogProcess:
    """A run log written by a writer process (:func:`serve`); the interface of
    :class:`~gnerun.log.mcap_log.RunLog`. Opening it waits for the writer to open the file: an OSError there is
    raised here."""

    def __init__(self, path: str | Path, *, config_yaml: str, metadata: dict[str, str]):
        self.path = Path(path)
        env = dict(os.environ)  # gnerun importable as this process imports it, installed or not
        env["PYTHONPATH"] = os.pathsep.join(p for p in (str(Path(__file__).parents[2]), env.get("PYTHONPATH")) if p)
        self._process = subprocess.Popen([sys.executable, "-m", "gnerun.log.writer"], stdin=subprocess.PIPE,
                                         stdout=subprocess.PIPE, start_new_session=True, env=env)
        self._pipe = Connection(os.dup(self._process.stdin.fileno()), readable=False)
        self._replies = Connection(os.dup(self._process.stdout.fileno()), writable=False)
        self._process.stdin.close()
        self._process.stdout.close()
        with contextlib.suppress(OSError, AttributeError):  # Linux: a larger pipe; elsewhere the default
            fcntl.fcntl(self._pipe.fileno(), fcntl.F_SETPIPE_SZ, PIPE_BYTES)
        self._time_ns: int | None = None
        self._checked: set[tuple[str, type]] = set()
        self._broken: str | None = None
        self._closed = False
        self._next_check = 0.0
        try:
            self._put((str(self.path), config_yaml, dict(metadata)))
            reply = self._replies.recv()
        except (OSError, EOFError):
            reply = ("oserror", None, "the log writer process ended", str(self.path))
        if reply[0] != "ready":
            self._closed = True
            self._pipe.close()
            self._replies.close()
            self._process.wait()
            raise OSError(*reply[1:])
        self._finalizer = weakref.finalize(self, _abandon, self._pipe, self._process)

    def set_time(self, time_ns: int | None) -> None:
        """As :meth:`RunLog.set_time <gnerun.log.mcap_log.RunLog.set_time>`."""
        self._time_ns = time_ns

    def now(self) -> int:
        return time.time_ns() if self._time_ns is None else self._time_ns

    @property
    def broken(self) -> str | None:
        """Why writing failed (None while it works, as far as the writer has said)."""
        return self._broken

    def _failed(self, why: str) -> WriteError:
        self._broken = why
        return WriteError(f"{self.path}: cannot write the run log: {why} (is the disk full?); everything flushed "
                          "before is readable (gnerun inspect)")

    def _send(self, op: tuple) -> None:
        if self._broken is not None or self._closed:
            return
        try:
            self._put(op)
        except OSError:  # the writer ended: its reply says why, if it could send one
            self._check()
            raise self._failed("the log writer process ended") from None

    def _put(self, op: tuple) -> None:
        """``op`` into the pipe, pickled plainly (multiprocessing's pickler copies its reducer table at every call;
        the ops hold no file or socket)."""
        self._pipe.send_bytes(pickle.dumps(op, protocol=pickle.HIGHEST_PROTOCOL))

    def _check(self) -> None:
        """The writer's news, without waiting: a write that failed raises here."""
        self._next_check = time.monotonic() + CHECK_EVERY
        while self._broken is None and self._replies.poll():
            try:
                kind, why = self._replies.recv()
            except EOFError:
                raise self._failed("the log writer process ended") from None
            if kind == "broken":
                raise self._failed(why)

    def write(self, topic: str, message: Message, *, log_time: int | None = None) -> None:
        """As :meth:`RunLog.write <gnerun.log.mcap_log.RunLog.write>`."""
        key = (topic, type(message))
        if key not in self._checked:
            expected = model_for(topic)
            if expected is not None and expected is not type(message):
                raise TypeError(f"topic {topic} carries {expected.__name__}, not {type(message).__name__}")
            self._checked.add(key)
        self._send(("write", topic, message, self.now() if log_time is None else log_time))

    def log(self, level: str, text: str) -> None:
        self._send(("log", level, text, self.now()))

    def plan_states(self, plan_states: PlanStates) -> bool:
        """The writer computes the plans' predicted states (:class:`~gnerun.log.plans.PlanStates`, serialized): a
        sampling time hands it the plan's decisions."""
        self._send(("plans", plan_states, self.now()))
        return True

    def sampling_time(self, record: SamplingTime) -> None:
        """As :meth:`RunLog.sampling_time <gnerun.log.mcap_log.RunLog.sampling_time>` (the writer flushes it)."""
        self._send(("sampling", record.pack(), self.now()))
        if time.monotonic() >= self._next_check:  # a look costs a system call: at most every CHECK_EVERY seconds
            self._check()

    def flush(self) -> None:
        self._send(("flush", self.now()))
        self._check()

    def close(self) -> None:
        """Finish the log: the writer writes what it has, closes the file and ends (a failed write raises)."""
        if self._closed:
            return
        self._closed = True
        self._finalizer.detach()
        why = self._broken
        try:
            with contextlib.suppress(OSError):
                self._put(("close", None))
            if self._replies.poll(CLOSE_TIMEOUT):
                with contextlib.suppress(EOFError):
                    while True:  # the last news: ("closed", why)
                        kind, news = self._replies.recv()
                        why = why or news
                        if kind == "closed":
                            break
        finally:
            self._pipe.close()
            self._replies.close()
            with contextlib.suppress(subprocess.TimeoutExpired):
                self._process.wait(CLOSE_TIMEOUT)
        if why is not None and self._broken is None:
            raise self._failed(why)

    def __enter__(self) -> LogProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def open_log(path: str | Path, *, config_yaml: str, metadata: dict[str, str],
             process: bool = False) -> RunLog | LogProcess:
    """A run log at ``path``: written in this process, or (``process``) by a writer process of its own."""
    if process:
        return LogProcess(path, config_yaml=config_yaml, metadata=metadata)
    return RunLog(path, config_yaml=config_yaml, metadata=metadata)


def main() -> None:
    """``python -m gnerun.log.writer``: the writer, its calls on stdin and its replies on stdout."""
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):  # the loop's process ends the log: see above
        signal.signal(sig, signal.SIG_IGN)
    source = Connection(os.dup(0), writable=False)
    replies = Connection(os.dup(1), readable=False)
    os.dup2(2, 1)  # anything printed goes to stderr, not into the replies
    serve(source, replies)
    os._exit(0)  # the log is closed: no interpreter teardown (about 50 ms the closing run would wait for)


if __name__ == "__main__":
    main()
