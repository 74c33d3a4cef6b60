"""One writer per run or sweep directory: an exclusive lock held for the life of the writer.

The lock is ``fcntl.flock`` on ``.gnerun.lock`` in the directory, a file that holds the writer's pid. A second
writer (another ``simulate --force``, a second sweep resuming the same directory) is refused at once with the
holder's pid; the kernel releases the lock when its holder exits, however it exits, so a killed run never
leaves a directory locked. The holder removes the file when it is done (a file found after a SIGKILL is
unlocked and reused). Within one process the lock is re-entrant: a sweep's worker holds its point's directory
while the run inside it opens the same directory.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import time
from collections.abc import Iterator
from pathlib import Path

from ..errors import InputError
from ..files import open_fd

LOCK_FILE = ".gnerun.lock"


class DirectoryBusy(InputError):
    """Another process writes into the directory."""


_held: dict[tuple[int, int], DirectoryLock] = {}  # (device, inode) of a directory -> this process's lock


class DirectoryLock:
    """An exclusive lock on ``directory`` (see the module docstring); :meth:`release` when done."""

    def __init__(self, directory: Path, fd: int, key: tuple[int, int]):
        self.directory = directory
        self._fd: int | None = fd
        self._key = key
        self._depth = 1

    @classmethod
    def acquire(cls, directory: str | Path, what: str = "run directory") -> DirectoryLock:
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
        held = _held.get(key)
        if held is not None and held._fd is not None:
            held._depth += 1
            return held
        path = directory / LOCK_FILE
        for _ in range(10):  # the file may be removed by a holder that is done between our open and flock
            fd = open_fd(path, os.O_RDWR)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = _holder(fd)
                os.close(fd)
                raise DirectoryBusy(f"{directory}: the {what} is in use by another gnerun process ({holder}); "
                                    "one process writes into it at a time: wait for it to finish, or stop it, "
                                    "or write elsewhere", cli=f"{directory}: the {what} is in use by another gnerun "
                                    f"process ({holder}); one process writes into it at a time: wait for it to "
                                    "finish, or stop it, or choose another --out") from None
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
        if self._fd is None:
            return
        self._depth -= 1
        if self._depth > 0:
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


def release_all() -> None:
    """Release every lock this process holds (a process about to end at once: its lock files go with it)."""
    for lock in list(_held.values()):
        lock._depth = 1
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
def locked(directory: str | Path, what: str = "run directory") -> Iterator[DirectoryLock]:
    """Hold the lock of ``directory`` for the block."""
    lock = DirectoryLock.acquire(directory, what)
    try:
        yield lock
    finally:
        lock.release()


def contents(directory: Path) -> list[Path]:
    """What ``directory`` holds, its lock file aside."""
    return [p for p in directory.iterdir() if p.name != LOCK_FILE]
