"""Building a game's functions without deafening the process to signals.

CasADi builds derivatives and Functions in single C++ calls: the condensed Jacobian of one agent's problem at horizon
2,000 is one call of about a minute. While the main thread is inside such a call, Python runs no signal handler, so
Ctrl-C and SIGTERM wait for it. CasADi releases the GIL during these calls, so the builds marked :func:`stoppable`
run in a helper thread while the calling thread waits in short slices; between two slices it runs the signal handlers
and the ``check`` of :func:`polled` (a stop request raises there, at once). A build that is stopped so is left to finish
in its helper thread, its result dropped; one lock serialises every build of the process, so the next build (in any
thread) waits for it, and no two builds share CasADi's expression graph at the same time.

Without :func:`polled` (a library user's own call), a build runs in the calling thread as before.
"""

from __future__ import annotations

import contextlib
import functools
import threading
from collections.abc import Callable, Iterator
from contextvars import ContextVar
from typing import Any, TypeVar

SLICE_S = 0.05  # how often a waiting caller runs its signal handlers and its check

_check: ContextVar[Callable[[], None] | None] = ContextVar("gnerun_build_check", default=None)
_lock = threading.RLock()  # one build at a time in this process (an abandoned one included)
_helpers: list[threading.Thread] = []  # the helper threads started (the live ones: builds in progress)

F = TypeVar("F", bound=Callable[..., Any])


@contextlib.contextmanager
def polled(check: Callable[[], None]) -> Iterator[None]:
    """Within the block, builds in this thread run in a helper thread and ``check()`` is called every
    :data:`SLICE_S` while they run (it raises to stop waiting)."""
    token = _check.set(check)
    try:
        yield
    finally:
        _check.reset(token)


def abandoned() -> bool:
    """Whether a build that was stopped is still running in its helper thread (a process about to end should end at
    once then: tearing down the interpreter would free CasADi objects while the helper still uses them)."""
    return any(t.is_alive() for t in _helpers)


def no_check() -> None:
    """The check where nothing else asks to stop: the signal handlers alone (Ctrl-C raises KeyboardInterrupt)."""


def stoppable(fn: F) -> F:
    """Mark a build (a function that constructs CasADi expressions or Functions): see the module docstring."""

    @functools.wraps(fn)
    def build(*args: Any, **kwargs: Any) -> Any:
        check = _check.get()
        if check is None or threading.current_thread() is not threading.main_thread():
            with _lock:  # a helper thread's nested builds, or no check: here, after any build in progress
                return fn(*args, **kwargs)
        outcome: dict[str, Any] = {}

        def work() -> None:
            with _lock:
                try:
                    outcome["value"] = fn(*args, **kwargs)
                except BaseException as exc:  # noqa: BLE001 - handed to the caller
                    outcome["error"] = exc

        helper = threading.Thread(target=work, name=f"gnerun-build-{fn.__name__}", daemon=True)
        _helpers[:] = [t for t in _helpers if t.is_alive()] + [helper]
        helper.start()
        while helper.is_alive():
            helper.join(SLICE_S)
            check()
        if "error" in outcome:
            raise outcome["error"]
        return outcome["value"]

    return build  # type: ignore[return-value]
