"""One writer per run or sweep directory (gnerun/runs/lock.py): concurrent writers started together, in real
processes; the second is refused with the holder's pid and nothing is lost or mixed."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader

from gnerun.errors import InputError
from gnerun.log.mcap_log import read_run
from gnerun.log.sweep_index import read_index
from gnerun.runs.lock import LOCK_FILE, DirectoryBusy, DirectoryLock, locked
from gnerun.runs.sweep import load_sweep

from .conftest import CONFIGS, gnerun_command

HOLD = """
import sys, time
from gnerun.runs.lock import DirectoryLock
lock = DirectoryLock.acquire(sys.argv[1])
print("locked", flush=True)
time.sleep(float(sys.argv[2]))
"""


def _holder(directory: Path, seconds: float) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, "-c", HOLD, str(directory), str(seconds)], stdout=subprocess.PIPE,
                            text=True, stdin=subprocess.DEVNULL)
    assert proc.stdout.readline().strip() == "locked"
    return proc


def test_a_second_process_is_refused_with_the_holders_pid_and_the_lock_dies_with_its_holder(tmp_path) -> None:
    proc = _holder(tmp_path, 60)
    try:
        assert (tmp_path / LOCK_FILE).read_text().strip() == str(proc.pid)
        with pytest.raises(DirectoryBusy, match=f"in use by another gnerun process \\(pid {proc.pid}\\)"):
            DirectoryLock.acquire(tmp_path)
    finally:
        proc.kill()  # SIGKILL: no clean-up at all
        proc.wait()
    with locked(tmp_path) as lock:  # the kernel released it; the stale file is reused
        assert (tmp_path / LOCK_FILE).read_text().strip() == str(os.getpid())
        with pytest.raises(DirectoryBusy, match="in use by another writer in this process"):
            DirectoryLock.acquire(tmp_path)  # the lock is the open directory's, not the process's
        with lock.lent():  # handed over explicitly, once, to the next writer in this thread
            with locked(tmp_path) as borrowed:
                assert borrowed.lock is lock
                with pytest.raises(DirectoryBusy):
                    DirectoryLock.acquire(tmp_path)
            with locked(tmp_path):  # given back: lent again
                pass
        assert (tmp_path / LOCK_FILE).exists()
    assert not (tmp_path / LOCK_FILE).exists()  # removed by its holder when done


def test_a_planted_link_as_the_lock_file_is_refused(tmp_path) -> None:
    target = tmp_path / "precious"
    target.write_text("keep me\n")
    run = tmp_path / "run"
    run.mkdir()
    (run / LOCK_FILE).symlink_to(target)
    with pytest.raises(InputError, match="symbolic link"):
        DirectoryLock.acquire(run)
    assert target.read_text() == "keep me\n"


def _start(*args: str) -> subprocess.Popen:
    return subprocess.Popen([*gnerun_command(), *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            stdin=subprocess.DEVNULL)


@pytest.mark.slow
def test_two_simulate_force_into_one_directory_at_once(tmp_path) -> None:
    """Started together with different configs: one runs, the other is refused (exit 2, the holder's pid), and
    the directory holds one run whose config.yaml, run.mcap and summary.json agree."""
    out = tmp_path / "run"
    procs = {K: _start("simulate", str(CONFIGS / "paper_study2.yaml"), "--out", str(out), "--force", "-q",
                       "--set", f"run.K={K}", "--set", "run.steps=1000") for K in ("[1,3]", "[2,5]")}
    results = {K: (p.wait(timeout=300), *p.communicate()) for K, p in procs.items()}
    codes = sorted(rc for rc, _, _ in results.values())
    assert codes == [0, 2], results
    (winner,) = [K for K, (rc, _, _) in results.items() if rc == 0]
    (loser,) = [K for K, (rc, _, _) in results.items() if rc == 2]
    [line] = results[loser][2].strip().splitlines()
    assert line.startswith(f"error: {out}: the run directory is in use by another gnerun process (pid "
                           f"{procs[winner].pid})"), line
    K = json.loads(winner)
    assert yaml.safe_load((out / "config.yaml").read_text())["run"]["K"] == K
    assert json.loads((out / "summary.json").read_text())["K"] == K
    with open(out / "run.mcap", "rb") as f:
        assert make_reader(f).get_summary() is not None  # finished and indexed
    record = read_run(out)
    assert record.complete and not record.damage
    assert {t for t in record.messages if t.endswith("/mpc/state")} == {f"/K{k}/mpc/state" for k in K}
    assert yaml.safe_load(record.config_yaml)["run"]["K"] == K
    assert sorted(p.name for p in out.iterdir()) == ["config.yaml", "run.mcap", "summary.json"]  # no lock left


SWEEP = """
base: {base}
command: simulate
set:
  run.K: [1]
grid:
  run.steps: [300, 320, 340, 360]
"""


def test_two_sweeps_resuming_one_directory_at_once(tmp_path) -> None:
    """Two sweeps started together on one directory: the second is refused with the first one's pid; every point
    log is finished, indexed and agrees with its summary, and a third run finds every point finished."""
    spec = tmp_path / "sweep.yaml"
    spec.write_text(SWEEP.format(base=CONFIGS / "paper_study2.yaml"))
    out = tmp_path / "out"
    procs = [_start("sweep", str(spec), "--out", str(out), "--workers", "1", "-q") for _ in range(2)]
    results = [(p.wait(timeout=300), *p.communicate()) for p in procs]
    assert sorted(rc for rc, _, _ in results) == [0, 2], results
    winner = next(p for p, (rc, _, _) in zip(procs, results, strict=True) if rc == 0)
    [line] = next(err for rc, _, err in results if rc == 2).strip().splitlines()
    assert f"the sweep directory is in use by another gnerun process (pid {winner.pid})" in line, line
    sw = load_sweep(spec)
    rows = read_index(out)
    assert [r["status"] for r in rows] == ["completed"] * 4
    for point, row in zip(sw.points, rows, strict=True):
        run = out / point.directory
        summary = json.loads((run / "summary.json").read_text())
        record = read_run(run)
        assert record.complete and not record.damage
        steps = point.params["run.steps"]
        assert summary["by_K"]["1"]["completed_steps"] == steps == len(record.messages["/K1/mpc/error"])
        assert [m["t"] for m in record.messages["/K1/mpc/error"]] == list(range(steps))
        assert row["final_e"] == summary["by_K"]["1"]["final_e_norm"]
    third = subprocess.run([*gnerun_command(), "sweep", str(spec), "--out", str(out)], capture_output=True,
                           text=True, timeout=120, stdin=subprocess.DEVNULL)
    assert third.returncode == 0 and "0 run, 4 already finished (skipped), 0 failed" in third.stdout, third.stdout


def test_a_point_directory_written_by_another_process_is_an_error_row_and_runs_again(tmp_path) -> None:
    from gnerun.runs.sweep import run_sweep

    spec = tmp_path / "sweep.yaml"
    spec.write_text(SWEEP.format(base=CONFIGS / "paper_study2.yaml").replace("[300, 320, 340, 360]", "[5, 6]"))
    sw = load_sweep(spec)
    out = tmp_path / "out"
    busy = out / sw.points[1].directory
    busy.mkdir(parents=True)
    proc = _holder(busy, 120)
    try:
        result = run_sweep(sw, out, workers=1, force=True)  # force: the directory holds no sweep yet
    finally:
        proc.kill()
        proc.wait()
    rows = read_index(out)
    assert result.failed == 1 and [r["status"] for r in rows] == ["completed", "error"]
    assert f"in use by another gnerun process (pid {proc.pid})" in rows[1]["message"]
    assert not (busy / "run.mcap").exists()  # nothing written into it
    again = run_sweep(sw, out, workers=1)
    assert (again.ran, again.skipped, again.failed) == (1, 1, 0)


def test_runs_started_together_without_out_get_a_directory_each(tmp_path) -> None:
    """The default directory has the second in its name: runs of one config started together are not refused by
    each other's directory (nor by the lock), and a run that stops before writing leaves no empty one."""
    procs = [subprocess.Popen([*gnerun_command(), "solve", str(CONFIGS / "fk_a12.yaml"), "-q"], cwd=tmp_path,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL)
             for _ in range(3)]
    results = [(p.wait(timeout=120), p.communicate()[1]) for p in procs]
    assert [rc for rc, _ in results] == [0, 0, 0], results
    runs = sorted((tmp_path / "runs").iterdir())
    assert len(runs) == 3 and all((r / "summary.json").is_file() for r in runs)
    # refused once its game is built (jn on shared constraints): the directory claimed for it is gone
    refused = subprocess.run([*gnerun_command(), "solve", str(CONFIGS / "harker.yaml"), "--set", "solver.kind=jn",
                              "-q"], cwd=tmp_path, capture_output=True, text=True, timeout=120,
                             stdin=subprocess.DEVNULL)
    assert refused.returncode == 2 and "needs independent constraint sets" in refused.stderr, refused.stderr
    assert sorted((tmp_path / "runs").iterdir()) == runs


def test_the_lock_is_taken_before_anything_is_written(tmp_path) -> None:
    """A run refused for a busy directory writes nothing there (not even config.yaml)."""
    out = tmp_path / "run"
    out.mkdir()
    proc = _holder(out, 120)
    try:
        # refused at once, not after waiting for the holder's 120 s: the timeout is a hang guard, not a timing
        refused = subprocess.run([*gnerun_command(), "solve", str(CONFIGS / "fk_a12.yaml"), "--out", str(out),
                                  "--force"], capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)
    finally:
        proc.kill()
        proc.wait()
    assert refused.returncode == 2 and f"(pid {proc.pid})" in refused.stderr
    assert sorted(p.name for p in out.iterdir()) == [LOCK_FILE]
