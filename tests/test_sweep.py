"""Sweeps: the spec, the local and Dask executors (LocalCluster and a separate scheduler + worker),
resuming, failed points, the index table against the points' own summaries, the ISS slope, the CLI."""

from __future__ import annotations

import csv
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from gnerun.errors import ConfigError
from gnerun.log.sweep_index import loglog_slope, read_index
from gnerun.runs.sweep import TIMING_COLUMNS, columns, load_sweep, run_sweep

from .conftest import CONFIGS, gnerun_command, run_cli

SMALL = f"""\
name: small-iss
base: {CONFIGS / "paper_study2.yaml"}
set:
  run.K: 3
  run.steps: 12
  solver.complementarity: fischer_burmeister
  disturbance.kind: residual
grid:
  disturbance.scale: {{logspace: [-6, -2, 3]}}
  disturbance.seed: [0, 1]
"""


def _spec(tmp_path: Path, text: str = SMALL, name: str = "sweep.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def _without_timings(rows: list[dict]) -> list[dict]:
    return [{k: v for k, v in r.items() if k not in TIMING_COLUMNS} for r in rows]


def test_the_spec_expands_to_points() -> None:
    product = load_sweep(CONFIGS / "iss_disturbance_sweep.yaml")
    assert len(product.points) == 8 * 5 and product.axes == ["disturbance.scale", "disturbance.seed"]
    scales = sorted({p.params["disturbance.scale"] for p in product.points})
    assert scales == pytest.approx([10.0**k for k in range(-8, 0)], rel=1e-12)
    assert {p.params["disturbance.seed"] for p in product.points} == set(range(5))
    assert all(p.overrides["disturbance.kind"] == "residual" for p in product.points)
    k = load_sweep(CONFIGS / "k_sweep.yaml")
    assert sorted({p.params["run.K"] for p in k.points}) == list(range(1, 9)) and len(k.points) == 16
    assert len({p.config_hash for p in k.points}) == 16 and len({p.directory for p in k.points}) == 16


def test_zip_and_bad_specs_are_located(tmp_path: Path) -> None:
    zipped = _spec(tmp_path, SMALL.replace("grid:", "mode: zip\ngrid:").replace("[-6, -2, 3]", "[-6, -2, 2]"))
    sw = load_sweep(zipped)
    assert [p.params for p in sw.points] == [{"disturbance.scale": 1e-6, "disturbance.seed": 0},
                                            {"disturbance.scale": 1e-2, "disturbance.seed": 1}]
    cases = [
        (SMALL.replace("grid:", "mode: zip\ngrid:"), "sweep.yaml:10:3: grid: mode zip needs axes of one length"),
        (SMALL.replace("[0, 1]", "[0, -1.5]"), "sweep.yaml:10:21: disturbance.seed: Input should be a valid integer"),
        (SMALL.replace("{logspace: [-6, -2, 3]}", "[-1.0]"), "sweep.yaml:9:22: disturbance.scale: Input should be "
                                                             "greater than or equal to 0 (point 0: disturbance.scale"),
        (SMALL.replace("set:", "sets:"), "sweep.yaml:3:1: sets: unknown key; did you mean 'set'? (allowed here: "
                                         "version, name, base, command, set, mode, grid)"),
        (SMALL.replace("paper_study2.yaml", "missing.yaml"), "sweep.yaml:2:7: base: no config file"),
        (SMALL + "  run.K: [1]\n", "sweep.yaml:4:3: set.run.K: also an axis"),
        (SMALL.replace("solver.complementarity", "solver.complementary"), "sweep.yaml:6:25: solver.complementary: "
                                                                          "unknown key"),
    ]
    for i, (text, fragment) in enumerate(cases):
        with pytest.raises(ConfigError) as err:
            load_sweep(_spec(tmp_path, text))
        assert any(fragment in p for p in err.value.problems), (i, err.value.problems)
    with pytest.raises(ConfigError, match="a sweep spec has `base:`"):
        load_sweep(CONFIGS / "paper_study2.yaml")


def _start(*args: str) -> subprocess.Popen:
    dask = Path(sys.executable).parent / "dask"
    return subprocess.Popen([str(dask), *args], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            stdin=subprocess.DEVNULL, start_new_session=True)


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


def _scheduler_address(scheduler_file: Path, proc: subprocess.Popen, timeout: float = 60) -> str:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if scheduler_file.is_file():
            try:
                return json.loads(scheduler_file.read_text())["address"]
            except (ValueError, KeyError):
                pass
        assert proc.poll() is None, proc.stderr.read().decode() if proc.stderr else ""
        time.sleep(0.1)
    raise AssertionError("the dask scheduler did not start")


@pytest.mark.slow
def test_local_and_dask_executors_write_identical_indexes(tmp_path: Path) -> None:
    """Local pool, a Dask LocalCluster, and a separate `dask scheduler` + `dask worker` on 127.0.0.1."""
    pytest.importorskip("distributed")
    sw = load_sweep(_spec(tmp_path))
    local = run_sweep(sw, tmp_path / "local", executor="local", workers=2)
    cluster = run_sweep(sw, tmp_path / "cluster", executor="dask", workers=2)
    scheduler_file = tmp_path / "scheduler.json"
    scheduler = _start("scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                       "--scheduler-file", str(scheduler_file))
    worker = None
    try:
        address = _scheduler_address(scheduler_file, scheduler)
        assert address.startswith("tcp://127.0.0.1:")
        worker = _start("worker", address, "--nworkers", "2", "--nthreads", "1", "--no-dashboard",
                        "--host", "127.0.0.1")
        remote = run_sweep(sw, tmp_path / "remote", executor="dask", address=address)
        by_file = run_sweep(sw, tmp_path / "by-file", executor="dask", address=str(scheduler_file))
    finally:
        for proc in (worker, scheduler):
            if proc is not None:
                _stop(proc)
    assert scheduler.returncode is not None and (worker is None or worker.returncode is not None)
    reference = _without_timings(read_index(tmp_path / "local"))
    assert len(reference) == 6 and all(r["status"] == "completed" for r in reference)
    for result in (cluster, remote, by_file):
        assert result.ran == 6 and result.failed == 0
        assert _without_timings(read_index(result.directory)) == reference
    # the CSV files themselves agree outside the timing columns, and so do the parquet files
    assert _csv_without_timings(tmp_path / "local") == _csv_without_timings(tmp_path / "remote")
    pq = pytest.importorskip("pyarrow.parquet")
    tables = [pq.read_table(d / "index.parquet").drop_columns(list(TIMING_COLUMNS)) for d in
              (tmp_path / "local", tmp_path / "cluster", tmp_path / "remote")]
    assert tables[0].equals(tables[1]) and tables[0].equals(tables[2])
    assert local.executor == "local" and remote.executor == "dask"


@pytest.mark.slow
def test_a_dask_sweep_beside_another_cluster_prints_nothing_of_its_ports(tmp_path: Path) -> None:
    """Port 8787 (a Dask dashboard's default) held by another program: the sweep's LocalCluster, which has no
    dashboard, takes a free port for its HTTP server without a warning on stderr."""
    pytest.importorskip("distributed")
    import socket

    holder = socket.socket()
    try:
        holder.bind(("0.0.0.0", 8787))
        holder.listen()
    except OSError:
        pass  # already held by something else: the case under test
    try:
        proc = run_cli("sweep", str(_spec(tmp_path)), "--out", str(tmp_path / "out"), "--workers", "2", "--executor",
                       "dask", "-q", timeout=300)
    finally:
        holder.close()
    assert proc.returncode == 0, proc.stderr
    assert "in use" not in proc.stderr and "Warning" not in proc.stderr, proc.stderr
    assert len(read_index(tmp_path / "out")) == 6


def _csv_without_timings(d: Path) -> list[list[str]]:
    with (d / "index.csv").open() as f:
        rows = list(csv.reader(f))
    keep = [i for i, c in enumerate(rows[0]) if c not in TIMING_COLUMNS]
    return [[r[i] for i in keep] for r in rows]


@pytest.mark.slow
def test_index_rows_agree_with_each_points_own_run(tmp_path: Path) -> None:
    sw = load_sweep(_spec(tmp_path))
    result = run_sweep(sw, tmp_path / "out", workers=2)
    rows = read_index(tmp_path / "out")
    assert list(rows[0]) == columns(sw) and len(rows) == len(result.rows) == 6
    for point, row in zip(sw.points, rows, strict=True):
        run = tmp_path / "out" / point.directory
        summary = json.loads((run / "summary.json").read_text())
        loop = summary["by_K"]["3"]
        e = np.array([math.nan if v is None else v for v in loop["e_norm"]])
        assert row["point"] == point.index and row["directory"] == point.directory
        assert row["disturbance.scale"] == point.params["disturbance.scale"]
        assert row["max_e"] == np.nanmax(e) and row["final_e"] == e[-1]
        assert row["asymptotic_e"] == pytest.approx(np.mean(e[len(e) // 2:]), rel=1e-15)
        assert row["iterations"] == sum(loop["iterations"]) and row["K"] == 3
        config = (run / "config.yaml").read_text()
        assert "kind: residual" in config and f"seed: {point.params['disturbance.seed']}" in config
        assert (run / "run.mcap").is_file()


def test_the_iss_study_shows_a_linear_gain(tmp_path: Path) -> None:
    """Asymptotic error against ||r^k|| over four decades: slope 1 on log-log axes (Theorem ISS_semi)."""
    sw = load_sweep(_spec(tmp_path, SMALL.replace("[-6, -2, 3]", "[-7, -1, 4]").replace("run.steps: 12",
                                                                                        "run.steps: 20")))
    run_sweep(sw, tmp_path / "out", workers=2)
    rows = read_index(tmp_path / "out")
    scales = sorted({r["disturbance.scale"] for r in rows})
    means = [np.mean([r["asymptotic_e"] for r in rows if r["disturbance.scale"] == s]) for s in scales]
    slope = np.polyfit(np.log10(scales), np.log10(means), 1)[0]
    print(f"ISS slope {slope:.4f} over scales {scales}")
    assert slope == pytest.approx(1.0, abs=0.05)
    assert loglog_slope(scales, means) == pytest.approx(slope, rel=1e-12)
    assert all(0 < m / s < 100 for m, s in zip(means, scales, strict=True))  # a gain, not just a slope


@pytest.mark.slow
def test_resuming_skips_finished_points(tmp_path: Path) -> None:
    spec = _spec(tmp_path)
    sw = load_sweep(spec)
    first = run_sweep(sw, tmp_path / "out", workers=2)
    assert (first.ran, first.skipped) == (6, 0)
    stamps = {p.directory: (tmp_path / "out" / p.directory / "run.mcap").stat().st_mtime_ns for p in sw.points}
    again = run_sweep(sw, tmp_path / "out", workers=2)
    assert (again.ran, again.skipped) == (0, 6)
    assert _without_timings(again.rows) == _without_timings(first.rows)
    assert stamps == {d: (tmp_path / "out" / d / "run.mcap").stat().st_mtime_ns for d in stamps}
    # an interrupted point (no summary) runs again, and so do points added to the grid
    (tmp_path / "out" / sw.points[2].directory / "summary.json").unlink()
    spec.write_text(SMALL.replace("[0, 1]", "[0, 1, 2]"))
    grown = load_sweep(spec)
    third = run_sweep(grown, tmp_path / "out", workers=2)
    assert third.ran == 1 + 3 and third.skipped == 5 and len(third.rows) == 9
    assert stamps[sw.points[0].directory] == (tmp_path / "out" / sw.points[0].directory / "run.mcap").stat().st_mtime_ns


@pytest.mark.slow
def test_a_failing_point_is_recorded_and_the_sweep_goes_on(tmp_path: Path) -> None:
    sw = load_sweep(_spec(tmp_path))
    out = tmp_path / "out"
    blocked = out / sw.points[1].directory
    blocked.parent.mkdir(parents=True)
    blocked.write_text("a file where the point's run directory should be\n")
    result = run_sweep(sw, out, workers=2, force=True)  # force: the directory holds no sweep yet
    rows = read_index(out)
    assert result.failed == 1 and result.ran == 6 and len(rows) == 6
    assert rows[1]["status"] == "error" and "exists and is not a directory" in rows[1]["message"]
    assert all(r["status"] == "completed" for i, r in enumerate(rows) if i != 1)
    blocked.unlink()
    retry = run_sweep(sw, out, workers=2)
    assert (retry.ran, retry.skipped, retry.failed) == (1, 5, 0)
    assert read_index(out)[1]["status"] == "completed"


@pytest.mark.slow
def test_the_cli_runs_a_sweep_and_draws_both_studies(tmp_path: Path) -> None:
    iss = _spec(tmp_path)
    k = _spec(tmp_path, SMALL.replace("  run.K: 3\n", "").replace(
        "  disturbance.scale: {logspace: [-6, -2, 3]}\n  disturbance.seed: [0, 1]\n",
        "  run.K: {range: [1, 4]}\n").replace("name: small-iss", "name: small-k"), "k.yaml")
    for spec, out, n in ((iss, tmp_path / "iss", 6), (k, tmp_path / "k", 4)):
        proc = run_cli("sweep", str(spec), "--out", str(out), "--workers", "2")
        assert proc.returncode == 0, proc.stderr
        assert f"{n} run, 0 already finished (skipped), 0 failed" in proc.stdout
        assert sum(line.startswith("[") for line in proc.stdout.splitlines()) == n
    proc = run_cli("sweep", str(iss), "--out", str(tmp_path / "iss"), "-q")
    assert proc.returncode == 0 and proc.stdout == ""
    proc = run_cli("figures", str(tmp_path / "iss"), str(tmp_path / "k"), "--out", str(tmp_path / "fig"),
                   "--format", "png")
    assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in (tmp_path / "fig").iterdir()) == ["small-iss-iss.png", "small-k-k.png"]
    proc = run_cli("validate", str(iss))
    assert proc.returncode == 0 and "6 points" in proc.stdout


@pytest.mark.slow
def test_the_cli_refuses_bad_sweeps_in_one_line(tmp_path: Path) -> None:
    bad = _spec(tmp_path, SMALL.replace("[0, 1]", "[0, -1.5]"))
    good = _spec(tmp_path, name="good.yaml")
    out = ["--out", str(tmp_path / "never")]
    for args in (["sweep", str(bad), *out], ["validate", str(bad)], ["sweep", str(CONFIGS / "paper_study2.yaml")],
                 ["sweep", str(good), "--executor", "ray", *out],
                 ["sweep", str(good), "--address", "tcp://127.0.0.1:1", *out]):
        proc = run_cli(*args)
        assert proc.returncode == 2, (args, proc.stderr)
        assert "Traceback" not in proc.stderr and len(proc.stderr.splitlines()) == 1, proc.stderr
    proc = run_cli("simulate", str(CONFIGS / "k_sweep.yaml"))
    assert proc.returncode == 2 and "a sweep spec, not a config" in proc.stderr
    notsweep = tmp_path / "occupied"
    notsweep.mkdir()
    (notsweep / "x.txt").write_text("x")
    proc = run_cli("sweep", str(good), "--out", str(notsweep))
    assert proc.returncode == 2 and "holds no sweep" in proc.stderr
    assert not (tmp_path / "never").exists()


def test_ctrl_c_stops_the_sweep_and_its_workers_and_the_sweep_resumes(tmp_path: Path) -> None:
    """SIGINT to the process group (a terminal's Ctrl-C) while long points run: exit 130 with one line at
    once, no worker left, the finished point in the index; the next run skips it."""
    spec = _spec(tmp_path, SMALL.replace("  run.steps: 12\n", "").replace(
        "  disturbance.scale: {logspace: [-6, -2, 3]}\n  disturbance.seed: [0, 1]\n",
        "  run.steps: [4, 200000, 300000]\n"))
    out = tmp_path / "out"
    proc = subprocess.Popen([*gnerun_command(), "sweep", str(spec), "--out", str(out), "--workers", "2"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL,
                            start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while not (out / "index.csv").is_file() or len(read_index(out)) < 1:
            assert time.monotonic() < deadline and proc.poll() is None
            time.sleep(0.2)
        rows = read_index(out)
        assert [r["run.steps"] for r in rows] == [4]
    finally:
        os.killpg(proc.pid, signal.SIGINT)
        t0 = time.monotonic()
        _, err = proc.communicate(timeout=60)
    assert time.monotonic() - t0 < 10 and proc.returncode == 130
    assert err.strip().splitlines() == [f"interrupted: {out} holds the index of the finished points; run again to "
                                        "resume"]
    left = subprocess.run(["ps", "-o", "stat=,args=", "-g", str(proc.pid)], capture_output=True, text=True).stdout
    assert all(line.strip().startswith("Z") for line in left.splitlines()), left  # no worker runs on
    sw = load_sweep(spec)
    assert json.loads((out / "sweep.json").read_text())["finished"] == 1
    # the points in progress ended as stopped runs, their summaries say so (one stopped before its run began has
    # none), and they run again
    summaries = {p.params["run.steps"]: out / p.directory / "summary.json" for p in sw.points}
    assert json.loads(summaries.pop(4).read_text())["status"] == "completed"
    assert all(json.loads(f.read_text())["status"] == "interrupted" for f in summaries.values() if f.exists())
    short = load_sweep(_spec(tmp_path, spec.read_text().replace("[4, 200000, 300000]", "[4, 6]"), "short.yaml"))
    again = run_sweep(short, out)
    assert (again.ran, again.skipped) == (1, 1)
