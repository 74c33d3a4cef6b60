"""Reliability: numerical faults are statuses, killed and interrupted runs keep every completed step, output
directories are checked, runs are reproducible, configs are versioned."""

from __future__ import annotations

import json
import math
import os
import random
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from gnerun import simulate, solve
from gnerun.game.compile import compile_game
from gnerun.language.config import ConfigError, load_config
from gnerun.log.mcap_log import read_run
from gnerun.log.messages import level_name
from gnerun.solvers.certificate import kkt_residuals

from .conftest import CONFIGS, gnerun_command, run_cli

STATIC_SQRT = """
name: nan-game
game:
  kind: static
  agents:
    - name: p1
      variables: {x1: {start: -1.0}}
      cost: "x1**2 - sqrt(x1)"
"""

# (name, config, status): one injected fault each
FAULTS = [
    ("singular JPhi: a plain GNE whose agents share one constraint",
     lambda: load_config(CONFIGS / "fk_a11.yaml", {"game.equilibrium": "generalized", "solver.globalization": "none"}),
     "singular_jacobian"),
    ("NaN from an expression: sqrt of a negative number", lambda: load_config(text=STATIC_SQRT), "nan"),
    ("divergence under large noise on JPhi",
     lambda: load_config(CONFIGS / "paper_study1.yaml", {"disturbance.kind": "jacobian_noise",
                                                         "disturbance.scale": 1.0, "solver.divergence_limit": 1e4}),
     "diverged"),
    ("max_iter without convergence", lambda: load_config(CONFIGS / "nonlinear_gne.yaml", {"solver.max_iter": 2}),
     "max_iter"),
]


def _log_entries(run: Path) -> list[dict]:
    """The /log entries as {level name, message}."""
    return [{"level": level_name(e), "message": e["message"]} for e in read_run(run).messages.get("/log", [])]


@pytest.mark.parametrize(("name", "make", "status"), FAULTS, ids=[f[2] for f in FAULTS])
def test_a_numerical_fault_is_a_status_a_message_and_a_log_entry(name: str, make, status: str, tmp_path) -> None:
    cfg = make()
    res = solve(cfg, out=tmp_path / "run")
    assert res.status == status, (name, res.message)
    assert res.message and not res.success
    assert res.residual_norm > cfg.solver.tol or not math.isfinite(res.residual_norm)
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["status"] == status and summary["message"] == res.message
    entries = [e for e in _log_entries(tmp_path / "run") if e["message"].startswith(f"status {status}")]
    assert len(entries) == 1 and entries[0]["level"] == "warning"
    assert res.message in entries[0]["message"]


def test_the_cli_reports_a_fault_as_a_result_not_a_crash(tmp_path) -> None:
    cfg = tmp_path / "nan.yaml"
    cfg.write_text(STATIC_SQRT)
    proc = run_cli("solve", str(cfg), "--out", str(tmp_path / "run"))
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr + proc.stdout
    assert "status: nan" in proc.stdout and "not finite" in proc.stdout


NOISY_LOOP = {"disturbance.kind": "jacobian_noise", "disturbance.scale": 3.0, "solver.divergence_limit": 1e4,
              "run.K": [3], "run.steps": 20}


def test_simulate_continues_after_failed_steps_and_lists_them(tmp_path) -> None:
    sim = simulate(load_config(CONFIGS / "paper_study2.yaml", NOISY_LOOP), out=tmp_path / "run")
    r = sim[3]
    failed = [t for t, s in enumerate(r.status) if s in ("diverged", "singular_jacobian", "nan")]
    assert 0 < len(failed) < r.steps and r.ended == "completed" and r.completed == r.steps
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["status"] == "completed"
    assert summary["by_K"]["3"]["failed_steps"] == failed and summary["by_K"]["3"]["completed_steps"] == r.steps
    assert np.all(np.isfinite(r.u)) and np.all(np.isfinite(r.x))  # the plant never got a diverged input
    warnings = [e["message"] for e in _log_entries(tmp_path / "run") if e["level"] == "warning"]
    assert [int(w.split(" t=")[1].split(":")[0]) for w in warnings if "on_failure: continue" in w] == failed


def test_simulate_stops_at_the_first_failed_step_when_asked(tmp_path) -> None:
    cfg = load_config(CONFIGS / "paper_study2.yaml", {**NOISY_LOOP, "run.on_failure": "stop"})
    sim = simulate(cfg, out=tmp_path / "run")
    r = sim[3]
    first = next(t for t, s in enumerate(r.status) if s == "diverged")
    assert sim.status == "stopped" and r.ended == "stopped" and r.completed == first + 1 == len(r.status)
    assert np.all(np.isnan(r.u[first:])) and np.all(np.isfinite(r.u[:first]))
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["status"] == "stopped"
    assert summary["by_K"]["3"]["failed_steps"] == [first] and summary["by_K"]["3"]["ended"] == "stopped"
    assert len(summary["by_K"]["3"]["e_norm"]) == len(summary["by_K"]["3"]["x"]) == first + 1
    record = read_run(tmp_path / "run")
    assert [m["t"] for m in record.messages["/K3/mpc/error"]] == list(range(first + 1))
    assert any("on_failure: stop" in e["message"] for e in record.messages["/log"])


@pytest.mark.slow
def test_converged_always_means_the_residual_meets_the_tolerance() -> None:
    """Over seeded random perturbations of three solvers: a converged result has ||Phi|| <= tol, checked
    again by an independent evaluation of the KKT residual."""
    rng = random.Random(7)
    cases = []
    for name, kind, n, most in (("paper_study1", "jacobian_noise", 40, 12), ("cournot_mss", "pseudogradient", 10, 8)):
        for _ in range(n):
            cases.append((name, {"disturbance.kind": kind, "disturbance.scale": 10 ** rng.uniform(-6, 0),
                                 "disturbance.seed": rng.randrange(10**6), "solver.max_iter": rng.randrange(1, most)}))
    for _ in range(5):
        cases.append(("paper_study3", {"solver.max_iter": rng.randrange(1, 30)}))
    seen = set()
    for name, over in cases:
        cfg = load_config(CONFIGS / f"{name}.yaml", over)
        res = solve(cfg)
        seen.add(res.status)
        if res.status == "converged":
            assert res.residual_norm <= cfg.solver.tol
            game = compile_game(cfg)
            assert kkt_residuals(game, res.z, game.x0)["kkt_residual"] <= cfg.solver.tol
        else:
            assert not res.residual_norm <= cfg.solver.tol or res.iterations >= cfg.solver.max_iter
    assert {"converged", "max_iter"} <= seen
    # closed loops: a converged sampling time meets the tolerance too
    sim = simulate(load_config(CONFIGS / "paper_study2.yaml", NOISY_LOOP | {"disturbance.scale": 0.1}))
    r = sim[3]
    assert all(res <= 1e-12 for res, s in zip(r.residual_norm, r.status, strict=True) if s == "converged")


# killed and interrupted runs --------------------------------------------------------------------------------

LONG_LOOP = ["--set", "run.steps=20000", "--set", "run.K=[1]", "-q"]  # minutes: it is killed long before


def _start(out: Path, *extra: str, **kw) -> subprocess.Popen:
    return subprocess.Popen([*gnerun_command(), "simulate", str(CONFIGS / "paper_study2.yaml"), "--out", str(out),
                             *LONG_LOOP, *extra], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            stdin=subprocess.DEVNULL, **kw)


def _wait_for_steps(out: Path, proc: subprocess.Popen, size: int, timeout: float = 60) -> None:
    log = out / "run.mcap"
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if log.is_file() and log.stat().st_size > size:
            return
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.05)
    raise AssertionError("the run did not start")


def _steps_are_whole(record, K: int = 1) -> int:
    """Every sampling time in the log has its state, its error and its iterates: returns how many."""
    states = [m["t"] for m in record.messages[f"/K{K}/mpc/state"]]
    errors = [m["t"] for m in record.messages[f"/K{K}/mpc/error"]]
    iterates = sorted({m["t"] for m in record.messages[f"/K{K}/mpc/iterate"]})
    n = len(errors)
    assert n > 0
    assert errors == list(range(n)) and states[:n] == list(range(n)) and iterates == list(range(n))
    return n


@pytest.mark.slow
def test_sigkill_at_a_random_step_leaves_every_completed_step_readable(tmp_path) -> None:
    out = tmp_path / "run"
    proc = _start(out)
    _wait_for_steps(out, proc, 20_000)
    time.sleep(random.Random(os.getpid()).uniform(0.0, 1.5))  # a random step
    proc.send_signal(signal.SIGKILL)
    proc.communicate(timeout=30)
    record = read_run(out)
    assert not record.complete
    n = _steps_are_whole(record)
    print(f"SIGKILL: {n} completed sampling times recovered")
    # the recovered steps are the run's: the same config, run to n steps in-process, gives the same loop
    again = simulate(load_config(CONFIGS / "paper_study2.yaml", {"run.steps": n, "run.K": [1]}))[1]
    np.testing.assert_array_equal([m["x"] for m in record.messages["/K1/mpc/state"][:n]], again.x[:n])
    np.testing.assert_array_equal([m["e_norm"] for m in record.messages["/K1/mpc/error"]],
                                  [None if not math.isfinite(v) else v for v in again.e_norm])
    # and every reader gets them
    inspected = run_cli("inspect", str(out))
    assert inspected.returncode == 0 and "incomplete" in inspected.stdout
    assert f"/K1/mpc/error {n:>{8 + 24 - len('/K1/mpc/error')}}" in inspected.stdout
    figs = run_cli("figures", str(out), "--out", str(tmp_path / "figs"), "--format", "png")
    assert figs.returncode == 0, figs.stderr
    assert list((tmp_path / "figs").glob("*.png"))
    replay = run_cli("replay", str(out), "--save", str(tmp_path / "run.rrd"))
    assert replay.returncode == 0, replay.stderr
    from rerun.chunk import RrdReader

    e_points = 0
    for chunk in RrdReader(tmp_path / "run.rrd").stream().to_chunks():
        if chunk.entity_path.endswith("/K1/e_norm") and "Scalars:scalars" in chunk.to_record_batch().schema.names:
            e_points += chunk.to_record_batch().num_rows
    assert e_points == n


def test_sigint_ends_the_run_cleanly_with_an_indexed_log_and_an_interrupted_summary(tmp_path) -> None:
    out = tmp_path / "run"
    proc = _start(out)
    _wait_for_steps(out, proc, 20_000)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, stderr
    [line] = stderr.strip().splitlines()
    assert "Traceback" not in stderr and line == f"interrupted: {out} holds a finished log and a summary with " \
                                                 "status interrupted"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "interrupted"
    loop = summary["by_K"]["1"]
    assert loop["ended"] == "interrupted"
    with open(out / "run.mcap", "rb") as f:
        assert make_reader(f).get_summary() is not None  # finished and indexed
    record = read_run(out)
    assert record.complete
    n = _steps_are_whole(record)
    print(f"SIGINT: {n} sampling times in the finished log")
    assert loop["completed_steps"] == n
    assert len(loop["e_norm"]) == len(loop["u"]) == len(loop["x"]) == n and None not in loop["e_norm"]
    assert any("interrupted" in e["message"] for e in record.messages["/log"])


# output directories ---------------------------------------------------------------------------------------


def test_an_unwritable_run_directory_is_one_clear_message(tmp_path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    for out in (blocker / "run", Path("/proc/gnerun-run")):
        proc = run_cli("solve", str(CONFIGS / "fk_a12.yaml"), "--out", str(out), "-q")
        assert proc.returncode == 2, proc.stderr
        [line] = proc.stderr.strip().splitlines()
        assert line.startswith(f"error: {out}") and "cannot write the run directory" in line


def _limit_file_size(limit: int):
    def apply() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # writes past the limit fail with EFBIG, like a full disk
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return apply


@pytest.mark.slow
@pytest.mark.skipif(sys.platform != "linux", reason="RLIMIT_FSIZE as a stand-in for a full disk")
def test_a_full_disk_leaves_what_was_flushed_readable(tmp_path) -> None:
    out = tmp_path / "run"
    proc = subprocess.run([*gnerun_command(), "simulate", str(CONFIGS / "paper_study2.yaml"), "--out", str(out),
                           *LONG_LOOP], capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL,
                          preexec_fn=_limit_file_size(200_000))
    assert proc.returncode == 1, proc.stderr
    [line] = proc.stderr.strip().splitlines()
    assert "cannot write the run log" in line and "File too large" in line and "Traceback" not in line
    assert (out / "run.mcap").stat().st_size <= 200_000
    record = read_run(out)
    n = _steps_are_whole(record)
    assert n > 10
    inspected = run_cli("inspect", str(out))
    assert inspected.returncode == 0, inspected.stderr


# reproducibility and versions ---------------------------------------------------------------------------


def _without_times(value):
    if isinstance(value, dict):
        return {k: _without_times(v) for k, v in value.items() if "time" not in k}
    if isinstance(value, list):
        return [_without_times(v) for v in value]
    return value


def _payloads(run: Path) -> dict[str, list[bytes]]:
    out: dict[str, list[bytes]] = {}
    with open(run / "run.mcap", "rb") as f:
        for _, channel, message in make_reader(f).iter_messages(log_time_order=False):
            out.setdefault(channel.topic, []).append(message.data)
    return out


@pytest.mark.slow
def test_the_same_config_and_seed_give_the_same_run(tmp_path) -> None:
    over = {"disturbance.kind": "jacobian_noise", "disturbance.scale": 0.05, "disturbance.seed": 11,
            "disturbance.plant.kind": "gaussian", "disturbance.plant.scale": 0.05, "disturbance.plant.seed": 5,
            "run.steps": 12, "run.K": [1, 3]}
    for command, cfg in (("simulate", load_config(CONFIGS / "paper_study2.yaml", over)),
                         ("solve", load_config(CONFIGS / "paper_study1_disturbed.yaml"))):
        runs = [tmp_path / f"{command}-{i}" for i in range(2)]
        for run in runs:
            (simulate if command == "simulate" else solve)(cfg, out=run)
        a, b = (json.loads((r / "summary.json").read_text()) for r in runs)
        assert _without_times(a) == _without_times(b)
        assert _payloads(runs[0]) == _payloads(runs[1])
        for run in runs:
            meta = read_run(run).metadata
            assert meta["config_hash"] == cfg.config_hash() and meta["seed"] == str(cfg.disturbance.seed)
            assert meta["version"] == __import__("gnerun").__version__
    # another seed gives another run
    other = load_config(CONFIGS / "paper_study2.yaml", over | {"disturbance.seed": 12})
    simulate(other, out=tmp_path / "other")
    assert _payloads(tmp_path / "other") != _payloads(tmp_path / "simulate-0")


def test_version_1_is_the_default_and_other_versions_are_refused() -> None:
    text = (CONFIGS / "harker.yaml").read_text()
    assert load_config(text=text).version == 1
    assert load_config(text="version: 1\n" + text) == load_config(text=text)
    for bad in ("2", "0", "'1'", "1.5", "null"):
        with pytest.raises(ConfigError) as err:
            load_config(text=f"version: {bad}\n" + text)
        assert str(err.value).startswith("<string>:1:10: version:")
