"""Stopping a run on request: Ctrl-C (SIGINT), SIGTERM (a scheduler's or `kill`'s stop) and SIGHUP (a closed
terminal) all ask a run to end cleanly.

While a run holds :meth:`Interrupt.installed`, the first of these signals is a request: the run finishes the
iterate or sampling time in progress, writes its summary with status ``interrupted`` and a finished, indexed
log, and then raises KeyboardInterrupt for the caller (the command line exits with 130). A second signal
interrupts at once (the log is still closed and indexed on the way out).
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator

SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))


class Stopped(Exception):
    """Raised by :meth:`Interrupt.check` between two iterates once a stop was requested."""


_worker = False  # this process is a sweep's worker: the sweep stops it
_listening: list[Interrupt] = []  # in a sweep's worker: the run in progress, which the worker's stop asks to end


def leave_signals_to_the_parent() -> None:
    """In a sweep's worker: runs install no handlers (the sweep stops its workers itself, with SIGTERM, and the
    worker's own handler passes that on with :func:`request_stop`)."""
    global _worker
    _worker = True


def request_stop(signal_name: str) -> bool:
    """In a sweep's worker: ask the run in progress to end as a signal would (at the end of its iterate or sampling
    time: a finished log and a summary of status interrupted); False if no run is listening."""
    for interrupt in _listening:
        interrupt.requested = True
        interrupt.signal = signal_name
    return bool(_listening)


class Interrupt:
    """A stop request from SIGINT, SIGTERM or SIGHUP (see the module docstring).

    Outside the main thread (where signals cannot be handled) this does nothing; in a sweep's worker the signals keep
    their handlers and the worker's stop reaches the run through :func:`request_stop`. A signal that the process
    ignores stays ignored (a job started in the background by a script ignores Ctrl-C; one started by nohup ignores
    SIGHUP): the others still ask the run to stop.
    """

    def __init__(self) -> None:
        self.requested = False
        self.signal: str | None = None  # the name of the signal that asked, e.g. "SIGTERM"

    @property
    def reason(self) -> str:
        """``Ctrl-C`` or the signal's name, for messages."""
        return "Ctrl-C" if self.signal in (None, "SIGINT") else self.signal

    def check(self) -> None:
        """Raise :class:`Stopped` if a stop was requested (called between iterates, where a run may end)."""
        if self.requested:
            raise Stopped

    @contextlib.contextmanager
    def installed(self) -> Iterator[Interrupt]:
        if threading.current_thread() is not threading.main_thread():
            yield self
            return
        if _worker:
            _listening.append(self)
            try:
                yield self
            finally:
                _listening.remove(self)
            return

        def handler(signum, frame) -> None:
            if self.requested:
                raise KeyboardInterrupt
            self.requested = True
            self.signal = signal.Signals(signum).name

        previous = {sig: signal.signal(sig, handler) for sig in SIGNALS if signal.getsignal(sig) is not signal.SIG_IGN}
        try:
            yield self
        finally:
            for sig, old in previous.items():
                signal.signal(sig, old)


def terminate_like_ctrl_c() -> None:
    """SIGTERM and SIGHUP raise KeyboardInterrupt as Ctrl-C does, so that every command ends through the same
    clean-up (locks released, logs closed, temporary files removed) whichever of them stops it."""
    if threading.current_thread() is not threading.main_thread():
        return
    for sig in SIGNALS:
        if sig != signal.SIGINT and signal.getsignal(sig) is signal.SIG_DFL:
            signal.signal(sig, signal.default_int_handler)
