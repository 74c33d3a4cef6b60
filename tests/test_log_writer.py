"""The run log written by a process of its own (gnerun/log/writer.py, ``run.log_writer: process``): the same log as
one written inline, a loop process killed without clean-up still leaves a finished log, a refused write reaches the
loop as a WriteError, and Ctrl-C ends the run as it does with an inline log."""

from __future__ import annotations

import json
import math
import signal
import threading
import time
from multiprocessing import Pipe

import numpy as np
import pytest
from mcap.reader import make_reader

import gnerun
from gnerun.errors import WriteError
from gnerun.language.config import load_config
from gnerun.log import writer
from gnerun.log.mcap_log import read_run
from gnerun.log.messages import SamplingTime

from .conftest import CONFIGS, refuse_log_write, run_cli
from .test_reliability import _start, _steps_are_whole, _wait_for_steps


def _record(**changes) -> SamplingTime:
    rng = np.random.default_rng(0)
    base = dict(K=3, t=7, iterates=[(0, 0.5, 0.25), (1, 1e-3, 1e-4), (2, 1e-12, math.nan)], x=rng.normal(size=12),
                u=rng.normal(size=6), status="converged", fallback=False, constraint_violation=0.0,
                e_norm=1e-12, e_norm_agent={"car1": 1e-13, "car2": math.nan}, plan=rng.normal(size=(41, 12)))
    return SamplingTime(**(base | changes))


@pytest.mark.parametrize("changes", [{}, {"u": None, "plan": None, "status": ""},
                                     {"iterates": [(0, 2.0, None)], "e_norm": math.nan, "fallback": True},
                                     {"iterates": [], "e_norm_agent": {}, "x": np.array([math.inf, -1.5])}],
                         ids=["whole", "the last state", "no reference", "nothing solved"])
def test_a_packed_sampling_time_makes_the_same_messages(changes: dict) -> None:
    record = _record(**changes)
    again = SamplingTime.unpack(record.pack())
    mine, theirs = record.messages(), again.messages()
    assert [topic for topic, _ in mine] == [topic for topic, _ in theirs]
    assert [m.to_json() for _, m in mine] == [m.to_json() for _, m in theirs]


def _topics(path) -> dict[str, list]:
    record = read_run(path)
    assert record.complete
    out = {topic: messages for topic, messages in record.messages.items() if topic != "/log"}
    out["/log"] = [m["message"] for m in record.messages["/log"]]
    out["times"] = {topic: times for topic, times in record.log_times.items() if topic != "/log"}
    return out


def test_a_log_written_by_a_process_holds_what_an_inline_one_holds(tmp_path) -> None:
    over = {"run.K": [1, 3], "run.steps": 6}
    inline = gnerun.simulate(load_config(CONFIGS / "paper_study2.yaml", over), out=tmp_path / "inline")
    process = gnerun.simulate(load_config(CONFIGS / "paper_study2.yaml", over | {"run.log_writer": "process"}),
                              out=tmp_path / "process")
    for K in (1, 3):
        np.testing.assert_array_equal(inline[K].x, process[K].x)
    a, b = _topics(tmp_path / "inline"), _topics(tmp_path / "process")
    assert a.keys() == b.keys() and "/K3/mpc/state" in a and a["/K3/mpc/iterate"]
    for topic in a:
        if topic != "/log":
            assert a[topic] == b[topic], topic
    # the /log texts: the same events (their timings differ)
    assert [text.split(":")[0] for text in a["/log"]] == [text.split(":")[0] for text in b["/log"]]
    # the plans' predicted states of games in the plane, rolled out by the writer, and runtime parameters (messages
    # the loop makes itself): the same
    for name, over in (("algames_merge_mpc", {"run.K": [3], "run.steps": 3, "run.reference": "none"}),
                       ("moving_obstacle", {"run.K": [10], "run.steps": 3})):
        for writer_kind in ("inline", "process"):
            gnerun.simulate(load_config(CONFIGS / f"{name}.yaml", over | {"run.log_writer": writer_kind}),
                            out=tmp_path / f"{name}-{writer_kind}")
        a, b = _topics(tmp_path / f"{name}-inline"), _topics(tmp_path / f"{name}-process")
        K = over["run.K"][0]
        states = b[f"/K{K}/mpc/state"]
        assert len(states) == 4 and all("plan" in m for m in states[:3])
        if name == "algames_merge_mpc":
            assert all(len(m["plan"]) == 41 * 12 for m in states[:3])
        else:
            assert len(b[f"/K{K}/mpc/parameters"]) == 3
        assert a == b


def test_the_writer_finishes_the_log_of_a_loop_process_killed_without_clean_up(tmp_path) -> None:
    out = tmp_path / "run"
    proc = _start(out, "--set", "run.log_writer=process")
    _wait_for_steps(out, proc, 20_000)
    proc.send_signal(signal.SIGKILL)
    proc.communicate(timeout=30)
    end = time.monotonic() + 60  # the writer, a process of its own, finishes what it received
    while time.monotonic() < end:
        with open(out / "run.mcap", "rb") as f:
            if f.seek(0, 2) > 8 and f.seek(-8, 2) >= 0 and f.read(8) == b"\x89MCAP0\r\n":
                break
        time.sleep(0.05)
    record = read_run(out)
    assert record.complete
    with open(out / "run.mcap", "rb") as f:
        assert make_reader(f).get_summary() is not None  # finished and indexed
    assert _steps_are_whole(record) > 0


def test_ctrl_c_ends_a_run_whose_log_a_process_writes_as_it_ends_any_run(tmp_path) -> None:
    out = tmp_path / "run"
    proc = _start(out, "--set", "run.log_writer=process")
    _wait_for_steps(out, proc, 20_000)
    proc.send_signal(signal.SIGINT)
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, stderr
    assert stderr.strip().splitlines() == [f"interrupted: {out} holds a finished log and a summary with status "
                                           "interrupted"]
    record = read_run(out)
    assert record.complete
    n = _steps_are_whole(record)
    assert json.loads((out / "summary.json").read_text())["by_K"]["1"]["completed_steps"] == n
    assert any("interrupted" in e["message"] for e in record.messages["/log"])


def _served(path, ops: list[tuple]) -> list[tuple]:
    """The writer (serve, in a thread of this process: its monkeypatches apply) given ``ops`` and the close: its
    news after the opening."""
    source, pipe = Pipe(duplex=False)
    replies_in, replies = Pipe(duplex=False)
    serving = threading.Thread(target=writer.serve, args=(source, replies))
    serving.start()
    pipe.send((str(path), "name: x\n", {"version": "test"}))
    assert replies_in.recv() == ("ready",)
    for op in [*ops, ("close", None)]:
        pipe.send(op)
    serving.join(30)
    news = []
    while replies_in.poll(1):
        news.append(replies_in.recv())
    return news


def test_a_write_the_disk_refuses_is_reported_once_and_the_log_keeps_what_came_before(tmp_path, monkeypatch) -> None:
    refuse_log_write(monkeypatch, 6, OSError(28, "No space left on device"))
    # 5 messages each: the sixth is refused
    news = _served(tmp_path / "run.mcap", [("sampling", _record(t=t, iterates=[(0, 1.0, None), (1, 0.1, None),
                                                                              (2, 0.01, None)]).pack(), t)
                                           for t in range(4)])
    assert news == [("broken", "No space left on device"), ("closed", "No space left on device")]
    assert len(read_run(tmp_path / "run.mcap").messages["/K3/mpc/iterate"]) == 3  # the first sampling time


def test_a_call_the_writer_cannot_carry_out_stops_the_log_there_readable(tmp_path) -> None:
    news = _served(tmp_path / "run.mcap", [("sampling", _record(t=0).pack(), 0),
                                           ("sampling", ("not", "a", "record"), 1),
                                           ("sampling", _record(t=2).pack(), 2)])  # not written: the log stops
    assert [kind for kind, _ in news] == ["broken", "closed"]
    assert news[0][1].startswith("the log writer failed: ValueError") and news[1][1] == news[0][1]
    record = read_run(tmp_path / "run.mcap")
    assert record.complete and [m["t"] for m in record.messages["/K3/mpc/state"]] == [0]


def test_a_writer_that_ends_is_a_write_error_in_the_loop_process(tmp_path) -> None:
    log = writer.LogProcess(tmp_path / "run.mcap", config_yaml="name: x\n", metadata={"version": "test"})
    log.sampling_time(_record())
    log.flush()
    end = time.monotonic() + 30
    while "/K3/mpc/state" not in read_run(tmp_path / "run.mcap").messages and time.monotonic() < end:
        time.sleep(0.01)  # written by the writer: it polls its pipe
    log._process.kill()
    log._process.wait()
    with pytest.raises(WriteError, match="cannot write the run log: the log writer process ended"):
        for t in range(100):  # the pipe's buffer may take a few before the end shows
            log.sampling_time(_record(t=t))
            log.flush()
    log.close()  # reported once
    assert read_run(tmp_path / "run.mcap").messages["/K3/mpc/state"]  # what it wrote before is readable


def test_a_log_the_writer_cannot_open_is_an_oserror_at_once(tmp_path) -> None:
    (tmp_path / "dir").mkdir()
    with pytest.raises(OSError):
        writer.LogProcess(tmp_path / "dir", config_yaml="name: x\n", metadata={})


def test_the_cli_times_a_run_whose_log_a_process_writes_on_one_clock(tmp_path) -> None:
    """The timing line's parts add up to its wall time: having waited for the writer, the process's own start is
    no longer read from /proc (which would put the end on another scale than the startup)."""
    proc = run_cli("simulate", str(CONFIGS / "paper_study2.yaml"), "--set", "run.steps=3", "--set", "run.K=[1]",
                   "--set", "run.log_writer=process", "--out", str(tmp_path / "run"))
    assert proc.returncode == 0, proc.stderr
    [line] = [row for row in proc.stdout.splitlines() if row.startswith("wall ")]
    parts = dict(part.rsplit(" ", 1) for part in line.split(": ", 1)[1].split(", "))
    assert float(parts["logging"]) > 0.05  # the writer's start is the run's
    assert float(parts["other"]) >= 0.0, line
