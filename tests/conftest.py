from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
CONFIGS = ROOT / "configs"

# Small dense systems: BLAS threads only add overhead.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


@pytest.fixture(scope="session")
def configs_dir() -> Path:
    return CONFIGS


def gnerun_command() -> list[str]:
    """The installed console script (the real CLI), next to this interpreter when possible."""
    script = Path(sys.executable).parent / "gnerun"
    if script.exists():
        return [str(script)]
    found = shutil.which("gnerun")
    if found:
        return [found]
    return [sys.executable, "-m", "gnerun.cli"]


def run_cli(*args: str, cwd: Path | None = None, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([*gnerun_command(), *args], capture_output=True, text=True, cwd=cwd, timeout=timeout,
                          stdin=subprocess.DEVNULL)


@contextlib.contextmanager
def hang_guard(seconds: float) -> Iterator[None]:
    """Raise TimeoutError in a block that runs longer than ``seconds`` (SIGALRM: the main thread). A guard against
    a hang, set far above the block's time: the suite asserts no timings."""

    def expire(signum, frame):
        raise TimeoutError(f"still running after {seconds} s: a hang")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def shipped_configs() -> list[Path]:
    """The shipped experiment configs (configs/*.yaml without the sweep specs, tested in test_sweep.py)."""
    return sorted(p for p in CONFIGS.glob("*.yaml") if not any(line.startswith("grid:")
                                                              for line in p.read_text().splitlines()))


def refuse_log_write(monkeypatch: pytest.MonkeyPatch, n: int, error: BaseException) -> None:
    """The n-th message any RunLog writes (counted from now) raises ``error`` instead: a disk that refuses it, or a
    failure injected while logging."""
    from gnerun.log.mcap_log import RunLog

    original, calls = RunLog._write, []

    def write(self, *args, **kwargs):
        calls.append(1)
        if len(calls) == n:
            raise error
        return original(self, *args, **kwargs)
    monkeypatch.setattr(RunLog, "_write", write)
