"""Every run ends with a summary (gnerun/runs/rundir.py): whatever goes wrong after a run directory is claimed, the
directory is complete (config.yaml, a finished run.mcap, summary.json with the status and the message) and its lock
released; a failure before leaves no directory. A failure is injected at each stage of solve and simulate. Also: one
writer per directory within a process (threads, callbacks), numbers that break the log's time, plant states that
diverge."""

from __future__ import annotations

import json
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

import gnerun
from gnerun.errors import WriteError
from gnerun.language.config import load_config
from gnerun.log.mcap_log import read_run
from gnerun.runs import closed_loop as closed_loop_module
from gnerun.runs import solving as solving_module
from gnerun.runs.lock import LOCK_FILE, DirectoryBusy
from gnerun.runs.reference import ReferenceSolver

from .conftest import CONFIGS, refuse_log_write, run_cli


class Injected(Exception):
    """The failure a test injects."""


def _complete(run: Path, status: str = "error", finished: bool = True) -> dict:
    """The directory holds config.yaml, a finished log (unless ``finished`` is False: a log that could not be
    written) and summary.json with ``status``; no lock file is left."""
    assert sorted(p.name for p in run.iterdir()) == ["config.yaml", "run.mcap", "summary.json"], list(run.iterdir())
    assert read_run(run).complete is finished
    summary = json.loads((run / "summary.json").read_text())
    assert summary["status"] == status, summary
    assert not (run / LOCK_FILE).exists()
    return summary


def _raiser(message: str):
    def fail(*args, **kwargs):
        raise Injected(message)

    return fail


class _FailingSolver:
    """The configured solver, whose ``fail_at``-th step raises."""

    def __init__(self, solver, fail_at: int):
        self._solver, self._left = solver, fail_at

    def step(self, state):
        self._left -= 1
        if self._left < 0:
            raise Injected("the solver's step failed")
        return self._solver.step(state)

    def __getattr__(self, name):
        return getattr(self._solver, name)


STUDY1 = CONFIGS / "paper_study1.yaml"
STUDY2 = CONFIGS / "paper_study2.yaml"


# solve -----------------------------------------------------------------------------------------------------

def test_a_failure_while_compiling_leaves_no_directory(tmp_path, monkeypatch) -> None:
    monkeypatch.setattr(solving_module, "compile_game", _raiser("compile"))
    with pytest.raises(Injected):
        gnerun.solve(load_config(STUDY1), out=tmp_path / "run")
    assert not (tmp_path / "run").exists()
    monkeypatch.setattr(closed_loop_module, "compile_game", _raiser("compile"))
    with pytest.raises(Injected):
        gnerun.simulate(load_config(STUDY2), out=tmp_path / "loop")
    assert not (tmp_path / "loop").exists()


@pytest.mark.parametrize("stage", ["reference", "iterate 0", "iterate 1", "iterate 2", "solver step 1",
                                   "certificate", "stage callback", "logging", "summary"])
def test_a_failure_at_each_stage_of_a_solve_leaves_a_complete_directory(stage: str, tmp_path, monkeypatch) -> None:
    cfg = load_config(STUDY1)
    on_iterate = on_stage = None
    if stage == "reference":  # the reference solve, or the polish of the solve's own end (an undisturbed solve)
        monkeypatch.setattr(solving_module, "reference_solution", _raiser("the reference solve failed"))
        monkeypatch.setattr(solving_module, "polished", _raiser("the reference solve failed"))
    elif stage.startswith("iterate"):
        k = int(stage.split()[1])

        def on_iterate(state, error):
            if state.k == k:
                raise Injected(f"the callback at iterate {k}")
    elif stage == "solver step 1":
        original = solving_module.make_solver
        monkeypatch.setattr(solving_module, "make_solver", lambda *a, **kw: _FailingSolver(original(*a, **kw), 1))
    elif stage == "certificate":
        import gnerun.solvers.certificate as certificate_module

        monkeypatch.setattr(certificate_module, "check_player", _raiser("the best response failed"))
    elif stage == "stage callback":
        def on_stage(text):
            if "best response" in text:
                raise Injected("the stage callback")
    elif stage == "logging":
        refuse_log_write(monkeypatch, 4, Injected("the log's fourth message"))
    elif stage == "summary":
        from gnerun.solvers import certificate

        monkeypatch.setattr(certificate, "kkt_residuals", _raiser("the certificate's residual failed"))
    with pytest.raises(Injected) as err:
        gnerun.solve(cfg, out=tmp_path / "run", on_iterate=on_iterate, on_stage=on_stage)
    summary = _complete(tmp_path / "run")
    assert str(err.value) in summary["message"] and summary["message"].startswith("the run stopped: Injected")
    assert "while " in summary["message"]
    if stage.startswith("iterate"):
        assert summary["iterations"] == int(stage.split()[1])
    assert "solution" in summary and "z" in summary


def test_a_log_the_disk_refuses_still_gets_a_summary(tmp_path, monkeypatch) -> None:
    """A disk that refuses the log (an OSError: WriteError): the summary is still written (a separate file), the log
    keeps what was flushed before, the lock is released."""
    refuse_log_write(monkeypatch, 6, OSError(28, "No space left on device"))
    with pytest.raises(WriteError):
        gnerun.simulate(load_config(STUDY2, {"run.K": [1], "run.steps": 4}), out=tmp_path / "run")
    summary = _complete(tmp_path / "run", finished=False)
    assert "No space left on device" in summary["message"]
    assert read_run(tmp_path / "run").messages  # what was flushed is readable


# simulate --------------------------------------------------------------------------------------------------

STEPS = 4


@pytest.mark.parametrize("t", range(STEPS))
@pytest.mark.parametrize("raised", [ValueError, SystemExit, KeyboardInterrupt])
def test_a_callback_that_raises_at_any_step_leaves_a_complete_directory(t: int, raised: type, tmp_path) -> None:
    cfg = load_config(STUDY2, {"run.K": [1, 3], "run.steps": STEPS})

    def progress(report) -> None:
        if report.K == 3 and report.t == t:
            raise raised("raised by the callback")
    with pytest.raises(raised):
        gnerun.simulate(cfg, out=tmp_path / "run", progress=progress)
    status = "interrupted" if raised is KeyboardInterrupt else "error"
    summary = _complete(tmp_path / "run", status)
    first, second = summary["by_K"]["1"], summary["by_K"]["3"]
    assert first["ended"] == "completed" and len(first["x"]) == STEPS + 1  # K = 1 ran to its end
    assert second["ended"] == status and second["completed_steps"] == t + 1  # K = 3 to the step whose callback raised
    assert len(second["u"]) == len(second["status"]) == t + 1
    # the states reached (an error), or those at which a sampling time ran (interrupted, as a stop request leaves it)
    assert len(second["x"]) == t + (2 if status == "error" else 1)
    if raised is not KeyboardInterrupt:
        assert summary["message"] == f"the run stopped: {raised.__name__}: raised by the callback"
    assert summary["K"] == [1, 3]


@pytest.mark.parametrize("stage", ["first solve", "solver step 3", "reference", "logging 5", "logging 12",
                                   "constraints"])
def test_a_failure_at_each_stage_of_a_closed_loop_leaves_a_complete_directory(stage: str, tmp_path,
                                                                              monkeypatch) -> None:
    cfg = load_config(STUDY2, {"run.K": [2], "run.steps": STEPS, "run.initial": "start"})
    if stage.startswith("first solve") or stage.startswith("solver step"):
        n = 0 if stage == "first solve" else int(stage.split()[-1])
        original = closed_loop_module.make_solver
        monkeypatch.setattr(closed_loop_module, "make_solver", lambda *a, **kw: _FailingSolver(original(*a, **kw), n))
    elif stage == "reference":
        original_ref, original_reached = ReferenceSolver.solve, ReferenceSolver.reached
        calls = []

        def counted(original):  # z*(t) solved for, or a converged step's own (every sampling time has one)
            def reference(*args, **kwargs):
                calls.append(1)
                if len(calls) == 2:
                    raise Injected("the reference solve failed")
                return original(*args, **kwargs)
            return reference
        monkeypatch.setattr(ReferenceSolver, "solve", counted(original_ref))
        monkeypatch.setattr(ReferenceSolver, "reached", staticmethod(counted(original_reached)))
    elif stage.startswith("logging"):
        n = int(stage.split()[-1])
        refuse_log_write(monkeypatch, n, Injected(f"the log's message {n}"))
    else:
        from gnerun.game.compile import StageConstraints

        monkeypatch.setattr(StageConstraints, "violation", _raiser("the constraint check failed"))
    with pytest.raises(Injected):
        gnerun.simulate(cfg, out=tmp_path / "run")
    summary = _complete(tmp_path / "run")
    loop = summary["by_K"]["2"]
    assert loop["ended"] == "error" and summary["message"].startswith("the run stopped: Injected")
    done = loop["completed_steps"]
    assert len(loop["u"]) == len(loop["status"]) == len(loop["e_norm"]) == done < STEPS
    assert len(loop["x"]) == done + 1


def test_the_cli_reports_a_failure_in_one_line_and_leaves_a_complete_directory(tmp_path) -> None:
    script = ("import sys; from gnerun.game.compile import StageConstraints\n"
              "def fail(*a, **k): raise RuntimeError('injected')\n"
              "StageConstraints.violation = fail\n"
              "from gnerun.cli import main\n"
              f"sys.argv = ['gnerun', 'simulate', {str(STUDY2)!r}, '--out', {str(tmp_path / 'run')!r}, '--set',"
              " 'run.steps=3']\nmain()\n")
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1, proc.stderr
    assert proc.stderr.strip().splitlines() == ["error: RuntimeError: injected (run with --debug for the traceback)"]
    summary = _complete(tmp_path / "run")
    assert summary["message"] == "the run stopped: RuntimeError: injected"


# one writer per directory ----------------------------------------------------------------------------------

def test_a_callback_that_starts_a_second_run_into_the_same_directory_is_refused(tmp_path) -> None:
    out = tmp_path / "run"
    inner = load_config(STUDY2, {"run.K": [1, 3], "run.steps": 3})
    refused = []

    def progress(report) -> None:
        if report.t == 1:
            with pytest.raises(DirectoryBusy, match="in use by another writer in this process") as err:
                gnerun.simulate(inner, out=out, force=True)
            refused.append(str(err.value))
    gnerun.simulate(load_config(STUDY2, {"run.K": [2], "run.steps": 3}), out=out, progress=progress)
    assert refused
    summary = _complete(out, "completed")
    assert summary["K"] == [2] and "K: [2]" in (out / "config.yaml").read_text()  # the directory is one run's


def test_two_threads_writing_into_one_directory_the_second_is_refused(tmp_path) -> None:
    out = tmp_path / "run"
    started, tried = threading.Event(), threading.Event()
    outcome: dict[str, str] = {}

    def first() -> None:
        def hold(report) -> None:
            if report.t == 1:
                started.set()
                tried.wait(120)
        gnerun.simulate(load_config(STUDY2, {"run.K": [2], "run.steps": 3}), out=out, progress=hold)
        outcome["first"] = "ran"

    def second() -> None:
        started.wait(120)
        try:
            gnerun.simulate(load_config(STUDY2, {"run.K": [1, 3], "run.steps": 3}), out=out, force=True)
            outcome["second"] = "ran"
        except DirectoryBusy:
            outcome["second"] = "refused"
        finally:
            tried.set()
    threads = [threading.Thread(target=first), threading.Thread(target=second)]
    for th in threads:
        th.start()
    for th in threads:
        th.join(300)
    assert outcome == {"first": "ran", "second": "refused"}
    summary = _complete(out, "completed")
    assert summary["K"] == [2] and "K: [2]" in (out / "config.yaml").read_text()


# numbers that break time, plants that diverge --------------------------------------------------------------

TIMED = """\
name: timed
game:
  kind: dynamic
  horizon: 3
  states: [p, v]
  dynamics: {ode: {p: "v", v: "u"}, integrator: rk4, dt: DT}
  x0: [1, 0]
  agents:
    - {name: a, inputs: [u], stage_cost: "p**2 + u**2"}
run:
  steps: 30
"""


@pytest.mark.parametrize(("where", "value", "line", "phrase"), [
    ("run.sampling_time", "1e9", 12, "span 3e+10 s"), ("run.sampling_time", "1e10", 12, "span 3e+11 s"),
    ("run.sampling_time", "1e300", 12, "span 3e+301 s"), ("run.sampling_time", "1e-12", 12, "one nanosecond"),
    ("dynamics.dt", "1e10", 6, "span 3e+11 s"), ("dynamics.dt", "1e300", 6, "span 3e+301 s"),
])
def test_a_time_step_the_log_cannot_count_is_refused_at_its_place(where: str, value: str, line: int, phrase: str,
                                                                   tmp_path) -> None:
    text = TIMED.replace("DT", value if where == "dynamics.dt" else "0.1")
    if where == "run.sampling_time":
        text = text.replace("dynamics: {ode: {p: \"v\", v: \"u\"}, integrator: rk4, dt: 0.1}",
                            "dynamics: {p: \"p + 0.1*v\", v: \"v + 0.1*u\"}") + f"  sampling_time: {value}\n"
    config = tmp_path / "timed.yaml"
    config.write_text(text)
    proc = run_cli("simulate", str(config), "--out", str(tmp_path / "run"))
    assert proc.returncode == 2, proc.stderr
    [message] = proc.stderr.strip().splitlines()
    assert message.startswith(f"error: {config}:{line}:") and phrase in message, message
    assert "Traceback" not in proc.stderr and not (tmp_path / "run").exists()


@pytest.mark.parametrize("kind", ["uniform", "constant", "gaussian"])
def test_a_plant_that_diverges_ends_the_loop_with_status_diverged(kind: str, tmp_path) -> None:
    proc = run_cli("simulate", str(STUDY2), "--out", str(tmp_path / "run"), "--set", "run.K=[1,2]", "--set",
                   "run.steps=5", "--set", f"disturbance.plant.kind={kind}", "--set", "disturbance.plant.scale=1e308")
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr + proc.stdout
    summary = _complete(tmp_path / "run", "diverged")
    for loop in summary["by_K"].values():
        assert loop["ended"] == "diverged" and loop["completed_steps"] == 1
        assert "the closed loop ends here (diverged)" in loop["message"]
        assert len(loop["x"]) == 2 and any(v is None or abs(v) > 1e12 for v in loop["x"][1])
    assert "diverged" in proc.stdout
    sim = gnerun.simulate(load_config(STUDY2, {"run.K": [1], "run.steps": 5, "disturbance.plant.kind": kind,
                                               "disturbance.plant.scale": 1e308}))
    assert sim.status == "diverged" and sim[1].ended == "diverged"
    assert not np.all(np.isfinite(sim[1].x[-1])) or np.max(np.abs(sim[1].x[-1])) > 1e12
