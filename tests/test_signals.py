"""SIGTERM and SIGHUP stop solve, simulate and sweep as Ctrl-C does (gnerun/runs/interrupt.py): real processes
and real signals; a finished, indexed log, a summary with status interrupted, exit code 130, and no process of
a sweep left behind."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader

from gnerun.log.mcap_log import read_run
from gnerun.log.sweep_index import read_index
from gnerun.runs.sweep import available_cpus

from .conftest import CONFIGS, gnerun_command
from .test_reliability import _start, _steps_are_whole, _wait_for_steps


def _ignore_ctrl_c() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # as a job started in the background by a script


def _signalled(proc: subprocess.Popen, out: Path, sig: signal.Signals, size: int) -> tuple[str, str]:
    """Send ``sig`` once the run's log has grown past ``size`` bytes; its output (it is killed if it hangs)."""
    try:
        _wait_for_steps(out, proc, size)
        proc.send_signal(sig)
        return proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP], ids=["SIGTERM", "SIGHUP"])
def test_a_signal_ends_simulate_like_ctrl_c(sig: signal.Signals, tmp_path) -> None:
    out = tmp_path / "run"
    proc = _start(out, preexec_fn=_ignore_ctrl_c if sig == signal.SIGTERM else None)
    _, stderr = _signalled(proc, out, sig, 20_000)
    assert proc.returncode == 130, stderr
    assert stderr.strip().splitlines() == [f"interrupted: {out} holds a finished log and a summary with status "
                                           "interrupted"]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "interrupted" and summary["by_K"]["1"]["ended"] == "interrupted"
    with open(out / "run.mcap", "rb") as f:
        assert make_reader(f).get_summary() is not None  # finished and indexed
    record = read_run(out)
    n = _steps_are_whole(record)
    assert summary["by_K"]["1"]["completed_steps"] == n
    assert any(f"interrupted ({sig.name})" in e["message"] for e in record.messages["/log"])
    assert sorted(p.name for p in out.iterdir()) == ["config.yaml", "run.mcap", "summary.json"]  # no temporary left


# the agent-distributed method converges linearly and never meets this tolerance: it iterates until stopped
LONG_SOLVE = ["--set", "solver.tol=1e-300", "--set", "solver.max_iter=1000000", "--set", "run.reference=none", "-q"]


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP], ids=["SIGINT", "SIGTERM", "SIGHUP"])
def test_a_signal_ends_solve_with_a_summary_and_a_finished_log(sig: signal.Signals, tmp_path) -> None:
    out = tmp_path / "run"
    proc = subprocess.Popen([*gnerun_command(), "solve", str(CONFIGS / "paper_study3.yaml"), "--out", str(out),
                             *LONG_SOLVE], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            stdin=subprocess.DEVNULL)
    _, stderr = _signalled(proc, out, sig, 30_000)
    assert proc.returncode == 130, stderr
    assert stderr.strip().splitlines() == [f"interrupted: {out} holds a finished log and a summary with status "
                                           "interrupted"]
    summary = json.loads((out / "summary.json").read_text())
    record = read_run(out)
    assert record.complete
    iterates = record.messages["/solve/iterate"]
    assert summary["status"] == "interrupted" and summary["iterations"] == iterates[-1]["k"] > 0
    assert summary["z"] == iterates[-1]["z"] and len(summary["residual_history"]) == len(iterates)
    reason = "Ctrl-C" if sig == signal.SIGINT else sig.name
    assert summary["message"].startswith(f"interrupted ({reason}) after {iterates[-1]['k']} iteration")
    assert summary["certificate"]["kkt_residual"] is not None


CHAIN = """
name: chain
game:
  kind: static
  parameters: {N: 600}
  agents:
    - for: {i: 1..N-1}
      name: "p{i}"
      variables: {"x{i}": {lower: 0, upper: 10, start: 1}}
      cost: "x{i}**2 - x{i}*x{i+1}"
    - name: "last"
      variables: {"x{N}": {lower: 0, upper: 10, start: 1}}
      cost: "x{N}**2"
"""


def test_a_signal_during_the_certificate_ends_solve_too(tmp_path) -> None:
    """600 agents: the solve converges in one iteration and the certificate (a best response per agent) takes about 2 s
    (0.8 s at 400 agents left a loaded machine too little time to signal it); a signal then stops the certificate
    between two best responses instead of being ignored."""
    config = tmp_path / "chain.yaml"
    config.write_text(CHAIN)
    out = tmp_path / "run"
    proc = subprocess.Popen([*gnerun_command(), "solve", str(config), "--out", str(out), "-q"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while not (out / "run.mcap").is_file() or len(read_run(out).messages.get("/solve/iterate", [])) < 2:
            assert time.monotonic() < deadline and proc.poll() is None, proc.communicate()
            time.sleep(0.1)
        time.sleep(0.2)  # into the certificate
        proc.send_signal(signal.SIGTERM)
        _, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, stderr
    assert stderr.strip().splitlines() == [f"interrupted: {out} holds a finished log and a summary with status "
                                           "interrupted"]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "interrupted" and summary["message"].startswith("interrupted (SIGTERM) after 1 ")
    assert summary["certificate"]["kkt_residual"] is not None and "best_response_gap" not in summary["certificate"]
    assert read_run(out).complete


SWEEP = f"""
base: {CONFIGS / "paper_study2.yaml"}
set:
  run.K: [1]
grid:
  run.steps: [4, 200000, 300000]
"""


def _group(pgid: int) -> list[str]:
    """The live (not zombie) processes of a process group."""
    out = subprocess.run(["ps", "-o", "stat=,pid=,args=", "-g", str(pgid)], capture_output=True, text=True).stdout
    return [line for line in out.splitlines() if line.strip() and not line.strip().startswith("Z")]


def _sweep_started(tmp_path: Path) -> tuple[subprocess.Popen, Path]:
    spec = tmp_path / "sweep.yaml"
    spec.write_text(SWEEP)
    out = tmp_path / "out"
    # a session of its own: its process group holds the sweep, its workers and their resource tracker
    proc = subprocess.Popen([*gnerun_command(), "sweep", str(spec), "--out", str(out), "--workers", "2"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL,
                            start_new_session=True)
    deadline = time.monotonic() + 120
    while not (out / "index.csv").is_file() or len(read_index(out)) < 1:
        assert time.monotonic() < deadline and proc.poll() is None, proc.communicate()
        time.sleep(0.2)
    assert len(_group(proc.pid)) >= 3  # the sweep and its two workers
    return proc, out


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP], ids=["SIGTERM", "SIGHUP"])
def test_a_signal_to_the_sweep_alone_stops_its_workers_too(sig: signal.Signals, tmp_path) -> None:
    proc, out = _sweep_started(tmp_path)
    err, left = _stopped(proc, lambda: proc.send_signal(sig))  # to the sweep's process only, as `kill PID` does
    _assert_stopped_in_one_line(proc, out, err, left)
    assert json.loads((out / "sweep.json").read_text())["finished"] == 1
    assert [r["run.steps"] for r in read_index(out)] == [4]
    assert not list(out.rglob("*.tmp")) and not list(out.rglob(".gnerun.lock"))


def _stopped(proc: subprocess.Popen, stop) -> tuple[str, list]:
    """``stop()`` a running sweep and wait for it: its stderr, and the processes of its group left (then killed)."""
    try:
        stop()
        _, err = proc.communicate(timeout=60)
    finally:
        left = _group(proc.pid)
        if left:
            os.killpg(proc.pid, signal.SIGKILL)
    return err, left


def _assert_stopped_in_one_line(proc: subprocess.Popen, out: Path, err: str, left: list) -> None:
    assert proc.returncode == 130, err
    assert err.strip().splitlines() == [f"interrupted: {out} holds the index of the finished points; run again to "
                                        "resume"]
    assert not left, left


def _workers(pgid: int) -> list[int]:
    """The pids of a sweep's workers (its children that run points)."""
    out = subprocess.run(["ps", "-ww", "-o", "pid=,args=", "--ppid", str(pgid)], capture_output=True, text=True).stdout
    return [int(line.split()[0]) for line in out.splitlines() if "spawn_main" in line]


@pytest.mark.slow
@pytest.mark.parametrize(("sig", "twice"), [(signal.SIGTERM, False), (signal.SIGHUP, False), (signal.SIGTERM, True)],
                         ids=["SIGTERM", "SIGHUP", "SIGTERM-twice"])
def test_a_signal_to_the_sweeps_process_group_stops_it_in_one_line(sig: signal.Signals, twice: bool,
                                                                    tmp_path) -> None:
    """As a closed terminal (SIGHUP) or `kill -- -PGID` (SIGTERM) sends it: to the sweep, its workers and the
    resource tracker at once. A worker gets the sweep's own stop on top (twice: at once): it ends its point once,
    with a finished log and a summary of status interrupted; no helper process dies loudly on the way."""
    proc, out = _sweep_started(tmp_path)
    try:
        workers = _workers(proc.pid)
        assert len(workers) == 2
        deadline = time.monotonic() + 120
        while sum(f.stat().st_size > 20_000 for f in out.glob("points/*/run.mcap")) < 2:  # both long runs under way
            assert time.monotonic() < deadline and proc.poll() is None, proc.communicate()
            time.sleep(0.1)
    except BaseException:
        _stopped(proc, lambda: os.killpg(proc.pid, signal.SIGKILL))
        raise

    def stop() -> None:
        os.killpg(proc.pid, sig)
        if twice:
            for pid in workers:
                os.kill(pid, sig)

    err, left = _stopped(proc, stop)
    _assert_stopped_in_one_line(proc, out, err, left)
    statuses = []
    for point in sorted((out / "points").iterdir()):
        record = read_run(point)
        assert record.complete and not record.damage, (point.name, record.damage)
        statuses.append(json.loads((point / "summary.json").read_text())["status"])
    assert sorted(statuses) == ["completed", "interrupted", "interrupted"]
    assert not list(out.rglob("*.tmp")) and not list(out.rglob(".gnerun.lock"))


@pytest.mark.slow
def test_a_hang_up_of_a_dask_sweeps_process_group_stops_it_in_one_line(tmp_path) -> None:
    """A closed terminal with a Dask LocalCluster: its processes start with hang-ups blocked as a local pool's do,
    the sweep stops the cluster, and nothing prints a traceback (the points in progress are left as killed runs')."""
    pytest.importorskip("dask.distributed")
    spec = tmp_path / "sweep.yaml"
    spec.write_text(SWEEP)
    out = tmp_path / "out"
    proc = subprocess.Popen([*gnerun_command(), "sweep", str(spec), "--out", str(out), "--workers", "2", "--executor",
                             "dask"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            stdin=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while not (out / "index.csv").is_file() or len(read_index(out)) < 1:
            assert time.monotonic() < deadline and proc.poll() is None, proc.communicate()
            time.sleep(0.2)
        os.killpg(proc.pid, signal.SIGHUP)
        _, err = proc.communicate(timeout=90)
    finally:
        time.sleep(1)  # the cluster's processes end as their parents do
        left = _group(proc.pid)
        if left:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, err
    assert err.strip().splitlines() == [f"interrupted: {out} holds the index of the finished points; run again to "
                                        "resume"]
    assert not left, left


@pytest.mark.slow
def test_a_killed_sweep_leaves_no_worker_running(tmp_path) -> None:
    """SIGKILL gives the sweep no chance to stop its workers: they stop themselves (their parent died)."""
    proc, out = _sweep_started(tmp_path)
    proc.kill()
    proc.wait(timeout=30)
    deadline = time.monotonic() + 30
    while _group(proc.pid) and time.monotonic() < deadline:
        time.sleep(0.2)
    left = _group(proc.pid)
    if left:
        os.killpg(proc.pid, signal.SIGKILL)
    assert not left, left


def test_workers_are_bounded_by_the_cpus_unless_forced(tmp_path) -> None:
    spec = tmp_path / "sweep.yaml"
    spec.write_text(SWEEP.replace("[4, 200000, 300000]", "[2, 3]"))
    too_many = str(available_cpus() + 1)
    refused = subprocess.run([*gnerun_command(), "sweep", str(spec), "--out", str(tmp_path / "a"), "--workers",
                              too_many], capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)
    assert refused.returncode == 2
    [line] = refused.stderr.strip().splitlines()
    assert line.startswith(f"error: --workers {too_many}: this machine has {available_cpus()} CPU") \
        and "--force-workers" in line
    assert not (tmp_path / "a").exists()
    forced = subprocess.run([*gnerun_command(), "sweep", str(spec), "--out", str(tmp_path / "b"), "--workers",
                             too_many, "--force-workers", "-q"], capture_output=True, text=True, timeout=300,
                            stdin=subprocess.DEVNULL)
    assert forced.returncode == 0, forced.stderr
    assert [r["status"] for r in read_index(tmp_path / "b")] == ["completed", "completed"]
    help_text = subprocess.run([*gnerun_command(), "sweep", "--help"], capture_output=True, text=True).stdout
    assert "--force-workers" in help_text and "CPUs" in help_text


def test_a_sweep_worker_leaves_every_signal_to_the_sweep() -> None:
    from gnerun.runs import interrupt

    handlers = {sig: signal.getsignal(sig) for sig in interrupt.SIGNALS}
    interrupt.leave_signals_to_the_parent()
    try:
        assert not interrupt.request_stop("SIGTERM")  # no run listens
        with interrupt.Interrupt().installed() as request:
            assert {sig: signal.getsignal(sig) for sig in interrupt.SIGNALS} == handlers
            assert not request.requested
            assert interrupt.request_stop("SIGTERM")  # the worker's stop, passed on as a request
            assert request.requested and request.reason == "SIGTERM"
        assert not interrupt.request_stop("SIGTERM")
    finally:
        interrupt._worker = False
    with interrupt.Interrupt().installed() as request:  # an ordinary process: each of them is a request
        for sig in interrupt.SIGNALS:
            assert signal.getsignal(sig) not in (handlers[sig], signal.SIG_IGN)
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(0.1)
        assert request.requested and request.reason == "SIGTERM"
    assert {sig: signal.getsignal(sig) for sig in interrupt.SIGNALS} == handlers


def _iterates(out: Path) -> int:
    try:
        return len(read_run(out).messages.get("/solve/iterate", []))
    except Exception:  # noqa: BLE001 - not written yet
        return 0


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_a_signal_stops_the_certificates_build_at_once(sig: signal.Signals, tmp_path) -> None:
    """The certificate builds each agent's own problem, condensed and dense: at horizon 1,000 one agent's build is
    about 30 s of CasADi calls that hold no Python frame (at 2,000, 377 s in all, and signals waited for it). A signal
    once the solve's iterates are written stops the build at once: a summary of status interrupted, exit code 130."""
    out = tmp_path / "run"
    proc = subprocess.Popen([*gnerun_command(), "solve", str(CONFIGS / "paper_study1.yaml"), "--set",
                             "game.horizon=1000", "--set", "run.reference=none", "--out", str(out), "-q"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 240
        while _iterates(out) < 4 and proc.poll() is None and time.monotonic() < deadline:  # converged in 3
            time.sleep(0.2)
        assert proc.poll() is None, proc.communicate()
        time.sleep(1.0)  # well inside the first agent's build
        t0 = time.monotonic()
        proc.send_signal(sig)
        _, stderr = proc.communicate(timeout=60)
        elapsed = time.monotonic() - t0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, stderr
    assert elapsed < 10, elapsed  # a hang guard (the build once held signals ~30 s): the process is gone in 0.5 s
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "interrupted" and summary["iterations"] == 3, summary["message"]
    assert sorted(p.name for p in out.iterdir()) == ["config.yaml", "run.mcap", "summary.json"]
    assert read_run(out).complete


def test_a_signal_while_compiling_ends_at_once_with_no_directory(tmp_path) -> None:
    """Compiling the sparse system of horizon 3,000 takes seconds of CasADi calls: Ctrl-C ends it at once, and no
    run directory is left (or, if the compile had ended, a complete one)."""
    out = tmp_path / "run"
    proc = subprocess.Popen([*gnerun_command(), "solve", str(CONFIGS / "paper_study1.yaml"), "--set",
                             "game.horizon=3000", "--out", str(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL)
    try:
        # the config is loaded once its size warning is out (about 1 s on a quiet machine, more on a loaded one);
        # its game is then being built for several seconds
        first = proc.stderr.readline()
        assert "a large game" in first, first
        time.sleep(1.0)
        t0 = time.monotonic()
        proc.send_signal(signal.SIGINT)
        _, rest = proc.communicate(timeout=60)
        stderr = first + rest
        elapsed = time.monotonic() - t0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, stderr
    assert elapsed < 10, elapsed  # a hang guard: the compile ends about 0.15 s after the signal
    if out.exists():
        assert json.loads((out / "summary.json").read_text())["status"] == "interrupted"
    else:
        assert stderr.strip().splitlines()[-1] == "interrupted"
