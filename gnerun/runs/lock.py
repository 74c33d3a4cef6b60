"""One writer per run or sweep directory: an exclusive lock held for the life of the writer.

The lock is ``fcntl.flock`` on ``.gnerun.lock`` in the directory, a file that holds the writer's pid. A second
writer (another ``simulate --force``, a second sweep resuming the same directory) is refused at once with the
holder's pid; the kernel releases the lock when its holder exits, however it exits, so a killed run never
leaves a directory locked. The holder removes the file when it is done (a file found after a SIGKILL is
unlocked and reused).

The lock belongs to the open directory, not to the process: a second writer in the same process (another thread, or a
callback of the run that starts a second run into the same directory) is refused as another process would be. The
one hand-over is explicit: a holder may lend its lock (:meth:`DirectoryLock.lent`) to the next writer of the
directory in the same thread, once (a sweep's worker holds its point's directory while the run inside it writes
there).
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import threading
import time
from collections.abc import Iterator
from pathlib import Path

from ..errors import InputError
from ..files import open_fd

LOCK_FILE = ".gnerun.lock"


class DirectoryBusy(InputError):
    """Another process writes into the directory."""


_held: dict[tuple[int, int], DirectoryLock] = {}  # (device, inode) of a directory -> this process's lock
_guard = threading.Lock()  # one thread at a time takes or gives back a lock


class _Borrowed:
    """A lent lock as its borrower holds it: releasing it gives it back to its holder."""

    def __init__(self, lock: DirectoryLock):
        self.lock = lock
        self.directory = lock.directory

    def release(self) -> None:
        with _guard:
            if self.lock._borrowed is self:
                self.lock._borrowed = None


class DirectoryLock:
    """An exclusive lock on ``directory`` (see the module docstring); :meth:`release` when done."""

    def __init__(self, directory: Path, fd: int, key: tuple[int, int]):
        self.directory = directory
        self._fd: int | None = fd
        self._key = key
        self._lent_to: int | None = None  # the thread that may borrow it (see lent)
        self._borrowed: _Borrowed | None = None

    @contextlib.contextmanager
    def lent(self) -> Iterator[DirectoryLock]:
        """Within the block, the next writer of this directory in this thread takes this lock instead of being
        refused (once: a second writer meanwhile is refused); the holder keeps it and releases it itself."""
        self._lent_to = threading.get_ident()
        try:
            yield self
        finally:
            self._lent_to = None

    @classmethod
    def acquire(cls, directory: str | Path, what: str = "run directory") -> DirectoryLock | _Borrowed:
        """Lock ``directory`` (which exists) or raise :class:`DirectoryBusy` naming the holder's pid; a directory
        where the lock file cannot be made (/proc, a read-only disk) is an :class:`InputError` that says so."""
        try:
            return cls._acquire(Path(directory), what)
        except OSError as e:
            raise InputError(f"{directory}: cannot write the {what}: {e.strerror or e}") from None

    @classmethod
    def _acquire(cls, directory: Path, what: str) -> DirectoryLock:
        st = os.stat(directory)
        key = (st.st_dev, st.st_ino)
        with _guard:
            held = _held.get(key)
            if held is not None and held._fd is not None:
                if held._lent_to == threading.get_ident() and held._borrowed is None:
                    held._borrowed = _Borrowed(held)
                    return held._borrowed
                raise _busy(directory, what, "another writer in this process (a thread, or a callback of the run "
                                             "that writes there)")
            return cls._take(directory, what, key)

    @classmethod
    def _take(cls, directory: Path, what: str, key: tuple[int, int]) -> DirectoryLock:
        path = directory / LOCK_FILE
        for _ in range(10):  # the file may be removed by a holder that is done between our open and flock
            fd = open_fd(path, os.O_RDWR)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = _holder(fd)
                os.close(fd)
                raise _busy(directory, what, f"another gnerun process ({holder})") from None
            try:
                current = os.stat(path, follow_symlinks=False).st_ino
            except FileNotFoundError:
                current = None
            if current != os.fstat(fd).st_ino:
                os.close(fd)
                continue
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
            lock = _held[key] = cls(directory, fd, key)
            return lock
        raise DirectoryBusy(f"{directory}: the {what} is in use (its lock file keeps changing)")

    def release(self) -> None:
        with _guard:
            if self._fd is None:
                return
            fd, self._fd = self._fd, None
            _held.pop(self._key, None)
        try:
            with contextlib.suppress(OSError):  # removed while held: no one can take the old file meanwhile
                path = self.directory / LOCK_FILE
                if os.stat(path, follow_symlinks=False).st_ino == os.fstat(fd).st_ino:
                    os.unlink(path)
        finally:
            os.close(fd)


def _busy(directory: Path, what: str, holder: str) -> DirectoryBusy:
    return DirectoryBusy(f"{directory}: the {what} is in use by {holder}; one writer writes into it at a time: wait "
                         "for it to finish, or stop it, or write elsewhere", cli=f"{directory}: the {what} is in use "
                         f"by {holder}; one writer writes into it at a time: wait for it to finish, or stop it, or "
                         "choose another --out")


def release_all() -> None:
    """Release every lock this process holds (a process about to end at once: its lock files go with it)."""
    for lock in list(_held.values()):
        with contextlib.suppress(OSError):
            lock.release()


def _holder(fd: int) -> str:
    """``pid N`` of the process that holds the lock (it writes its pid just after taking it)."""
    for _ in range(50):
        text = os.pread(fd, 32, 0).decode(errors="replace").strip()
        if text.isdigit():
            return f"pid {text}"
        time.sleep(0.01)
    return "pid unknown"


@contextlib.contextmanager
def locked(directory: str | Path, what: str = "run directory") -> Iterator[DirectoryLock | _Borrowed]:
    """Hold the lock of ``directory`` for the block."""
    lock = DirectoryLock.acquire(directory, what)
    try:
        yield lock
    finally:
        lock.release()


def contents(directory: Path) -> list[Path]:
    """What ``directory`` holds, its lock file aside."""
    return [p for p in directory.iterdir() if p.name != LOCK_FILE]
