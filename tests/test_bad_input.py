"""Bad input and output targets that cannot work: exit code 2 and one line that says what is wrong (file:line:column
for configs), never a traceback, and nothing written anywhere; the real command line as a subprocess."""

from __future__ import annotations

import json
import os
import socket
import subprocess
from pathlib import Path

import pytest

from gnerun.errors import MAX_MESSAGE
from gnerun.log.mcap_log import read_run
from gnerun.log.messages import level_name

from .conftest import CONFIGS, gnerun_command, run_cli

STUDY2 = str(CONFIGS / "paper_study2.yaml")
STUDY3 = str(CONFIGS / "paper_study3.yaml")


def _one_line_exit_2(proc: subprocess.CompletedProcess) -> str:
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    assert "Traceback" not in proc.stderr + proc.stdout
    [line] = proc.stderr.strip().splitlines()
    assert line.startswith("error: ") and len(line) <= MAX_MESSAGE + 20, line[:300]
    return line


CONFIG_CASES = [
    ("seed -1", ["--set", "disturbance.seed=-1"], "disturbance.seed: Input should be greater than or equal to 0"),
    ("plant seed -1", ["--set", "disturbance.plant.seed=-1"], "disturbance.plant.seed: Input should be greater"),
    ("inner_max_iter 10**18", ["--set", f"solver.inner_max_iter={10**18}"], "solver.inner_max_iter: Input should "
                                                                              "be less than or equal to 1000000"),
    ("NUL in the name", ["--set", 'name="a\\0b"'], "contains a NUL character"),
    ("300-character name", ["--set", "name=" + "n" * 300], "is 300 bytes long; a name is at most 100"),
    ("a name with a slash", ["--set", "name=../../escaped"], "is not one path component"),
    ("an absolute name", ["--set", "name=/tmp/escaped"], "is not one path component"),
    ("a nested name", ["--set", "name=a/b/c"], "is not one path component"),
    ("a hidden name", ["--set", "name=.."], "starts with '.'"),
    ("a K list of 20,000", ["--set", f"run.K={list(range(1, 20001))}"], "run.K: List should have at most 1000"),
]


@pytest.mark.parametrize(("case", "args", "fragment"), CONFIG_CASES, ids=[c[0] for c in CONFIG_CASES])
def test_bad_config_values_are_refused_by_validate_and_by_the_run(case, args, fragment, tmp_path) -> None:
    for command in (["validate", STUDY3], ["solve", STUDY3, "--out", str(tmp_path / "run")]):
        line = _one_line_exit_2(run_cli(*command, *args, cwd=tmp_path))
        assert fragment in line and line.startswith("error: --set "), (case, line)
    assert not (tmp_path / "run").exists() and not (tmp_path / "runs").exists()
    assert not Path("/tmp/escaped").exists()


def test_a_bad_name_in_a_file_is_located(tmp_path) -> None:
    config = tmp_path / "x.yaml"
    text = (CONFIGS / "fk_a12.yaml").read_text().replace("name: fk-a12", "name: ../../out")
    config.write_text(text)
    row = text.splitlines().index("name: ../../out") + 1
    line = _one_line_exit_2(run_cli("solve", str(config), cwd=tmp_path))
    assert line.startswith(f"error: {config}:{row}:7: name: '../../out' is not one path component"), line
    assert list(tmp_path.iterdir()) == [config]


@pytest.mark.parametrize(("name", "fragment"), [("..", "starts with '.'"), (".", "starts with '.'"),
                                               ("../../escaped", "is not one path component"),
                                               ("/tmp/escaped", "is not one path component"),
                                               ("n" * 300, "is 300 bytes long; a name is at most 100"),
                                               ('"a\\0b"', "contains a NUL character")],
                         ids=["dotdot", "dot", "relative", "absolute", "300 bytes", "NUL"])
def test_a_sweep_name_stays_inside_runs(name: str, fragment: str, tmp_path) -> None:
    """A sweep's name names its default directory runs/<name>/: refused where it is written unless it is one plain
    path component, by validate and by the sweep (even with --force), which writes nothing anywhere."""
    work = tmp_path / "work"
    work.mkdir()
    spec = tmp_path / "sweep.yaml"
    spec.write_text(f"name: {name}\nbase: {STUDY2}\nset: {{run.K: [1]}}\ngrid:\n  run.steps: [2, 3]\n")
    for command in (["validate", str(spec)], ["sweep", str(spec), "--force", "-q"]):
        line = _one_line_exit_2(run_cli(*command, cwd=work))
        assert line.startswith(f"error: {spec}:1:7: name: ") and fragment in line, line
    assert list(work.iterdir()) == [] and sorted(p.name for p in tmp_path.iterdir()) == ["sweep.yaml", "work"]
    assert not Path("/tmp/escaped").exists()


def test_a_sweep_named_by_its_file_gets_a_plain_directory(tmp_path) -> None:
    from gnerun.runs.sweep import default_sweep_dir, load_sweep

    spec = tmp_path / (".." + "x" * 200 + ".yaml")
    spec.write_text(f"base: {STUDY2}\ngrid:\n  run.steps: [2, 3]\n")
    directory = default_sweep_dir(load_sweep(spec))
    assert directory.parent == Path("runs") and directory.name == "x" * 100


def test_huge_values_are_shortened_in_the_message(tmp_path) -> None:
    """A 20,000-digit literal and a 60,000-element list, given with --set or written in the file."""
    digits, items = "1" * 20_000, "[" + ",".join(["1"] * 60_000) + "]"
    text = (CONFIGS / "paper_study2.yaml").read_text()
    for key, value in (("solver.tol", digits), ("solver.kind", digits), ("game.x0", digits)):
        line = _one_line_exit_2(run_cli("validate", STUDY2, "--set", f"{key}={value}"))
        assert f"({len(key) + 20_001} characters)" in line and len(line) < 700, line[:200]
    for key in (f"game.{digits}", f"game.agents.{digits}.name", "game.agents.\u00b2.name"):  # not list indices
        line = _one_line_exit_2(run_cli("validate", STUDY2, "--set", f"{key}=1"))
        assert len(line) < 700 and line.startswith("error: --set game."), line[:200]
    for old, new in (("x0: [1, 3, 5]", f"x0: {items}"), ("x0: [1, 3, 5]", f"x0: [1, 3, {digits}]"),
                     ("kind: ssn", f"kind: {digits}"), ("x0: [1, 3, 5]", f"x0: [1, 3, 5]\n  {digits}: 1")):
        assert old in text
        config = tmp_path / "huge.yaml"
        config.write_text(text.replace(old, new, 1))
        line = _one_line_exit_2(run_cli("validate", str(config)))
        assert line.startswith(f"error: {config}:") and len(line) < 700, line[:200]


def test_output_targets_that_cannot_work(tmp_path) -> None:
    run = tmp_path / "run"
    assert run_cli("solve", str(CONFIGS / "fk_a12.yaml"), "--out", str(run), "-q").returncode == 0
    a_file = tmp_path / "a-file"
    a_file.write_text("keep\n")
    cases = [
        (["figures", str(run), "--out", str(a_file)], "exists and is not a directory"),
        (["replay", str(run), "--screenshot", str(a_file)], "exists and is not a directory"),
        (["replay", str(run), "--save", "/proc/gnerun-x.rrd"], "cannot write the recording"),
        (["replay", str(run), "--save", str(tmp_path)], "is a directory; the recording (--save) is a file"),
        (["figures", str(run), "--out", "/proc/gnerun-figures"], "cannot create the figures folder"),
        (["recover", str(run), "--out", str(tmp_path), "--force"], "is a directory; the repaired copy is a regular"),
        (["recover", str(run), "--out", "/proc/gnerun-x.mcap", "--force"], "cannot write the repaired copy"),
        (["recover", str(run), "--out", str(a_file / "x.mcap")], "cannot write the repaired copy"),
        (["sweep", str(CONFIGS / "k_sweep.yaml"), "--out", "/proc"], "/proc: cannot write the sweep directory"),
        (["solve", str(CONFIGS / "fk_a12.yaml"), "--out", "/proc"], "/proc: cannot write the run directory"),
    ]
    for args, fragment in cases:
        line = _one_line_exit_2(run_cli(*args))
        assert fragment in line, (args, line)
    assert a_file.read_text() == "keep\n" and not Path("/proc/gnerun-x.rrd").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a-file", "run"]
    assert sorted(p.name for p in run.iterdir()) == ["config.yaml", "run.mcap", "summary.json"]


def _taken_port() -> socket.socket:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen()
    return s


def test_serve_refuses_taken_and_invalid_ports_before_printing_a_url(tmp_path) -> None:
    run = tmp_path / "run"
    assert run_cli("solve", str(CONFIGS / "fk_a12.yaml"), "--out", str(run), "-q").returncode == 0
    with _taken_port() as taken:
        port = taken.getsockname()[1]
        for args, fragment in ((["--web-port", str(port)], f"port {port} on 127.0.0.1 cannot be used"),
                               (["--grpc-port", str(port)], f"port {port} on 127.0.0.1 cannot be used"),
                               (["--web-port", "0"], "port 0: a TCP port is a number in 1..65535"),
                               (["--grpc-port", "70000"], "port 70000: a TCP port"),
                               (["--web-port", "9123", "--grpc-port", "9123"], "need two ports, not 9123 twice")):
            env = dict(os.environ, TMPDIR=str(tmp_path / "tmp"))
            (tmp_path / "tmp").mkdir(exist_ok=True)
            proc = subprocess.run([*gnerun_command(), "replay", str(run), "--serve", *args], capture_output=True,
                                  text=True, timeout=60, stdin=subprocess.DEVNULL, env=env)
            line = _one_line_exit_2(proc)
            assert fragment in line and "http://" not in proc.stdout, (args, line)
            assert not list((tmp_path / "tmp").iterdir())  # no temporary recording left behind


@pytest.mark.slow
def test_tampered_summaries_and_sweep_files(tmp_path) -> None:
    run = tmp_path / "run"
    assert run_cli("solve", str(CONFIGS / "fk_a12.yaml"), "--out", str(run), "-q").returncode == 0
    for content, fragment in (("[1, 2]", "a JSON list, not an object"), ("{not json", "not valid JSON")):
        (run / "summary.json").write_text(content)
        proc = run_cli("inspect", str(run))
        assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr
        assert f"status: unknown ({run / 'summary.json'}: damaged summary.json: {fragment}" in proc.stdout
    spec = tmp_path / "sweep.yaml"
    spec.write_text(f"base: {CONFIGS / 'paper_study2.yaml'}\nset: {{run.K: [1]}}\ngrid:\n  run.steps: [3, 4]\n")
    out = tmp_path / "sweep"
    assert run_cli("sweep", str(spec), "--out", str(out), "-q").returncode == 0
    points = sorted((out / "points").iterdir())
    (points[0] / "summary.json").write_text("[]")
    (points[1] / "point.json").write_text("{")
    again = run_cli("sweep", str(spec), "--out", str(out))
    assert again.returncode == 0 and "2 run, 0 already finished" in again.stdout, again.stdout + again.stderr
    assert json.loads((points[0] / "summary.json").read_text())["status"] == "completed"
    for content in ("[1]", "{", '{"name": 3, "axes": "x"}'):
        (out / "sweep.json").write_text(content)
        line = _one_line_exit_2(run_cli("figures", str(out), "--out", str(tmp_path / "figs")))
        assert "damaged sweep.json" in line, line


def test_an_edited_sweep_index_is_drawn_in_part_or_refused_in_one_line(tmp_path) -> None:
    """index.csv edited by hand: rows with values of the wrong type are left out, a file that is not text is a
    damaged index; a solve sweep over run.K (rows without K) draws no K figure instead of failing."""
    from typer.testing import CliRunner

    from gnerun.cli import app

    out = tmp_path / "sweep"
    out.mkdir()
    (out / "sweep.json").write_text(json.dumps({"name": "s", "axes": ["run.K"]}))
    header = "point,directory,run.K,K,status,max_e,asymptotic_e"
    good = ['0,points/a,[1],1,completed,2.5,0.1', '1,points/b,[2],2,completed,1.5,0.1']
    figures = ["figures", str(out), "--out", str(tmp_path / "figs"), "--format", "png"]
    for k in ("abc", "[1]", "1e999", '"{""a"": 1}"', "true"):
        (out / "index.csv").write_text("\n".join([header, f"2,points/c,[3],{k},completed,1,0.1", *good]) + "\n")
        result = CliRunner().invoke(app, figures)
        assert result.exit_code == 0 and result.exception is None, (k, result.output)
    for bad in ("2,points/c,[3]", "2", "2,points/c,[3],3,completed,1,0.1,extra,cells"):  # rows cut short, too long
        (out / "index.csv").write_text("\n".join([header, bad, *good]) + "\n")
        result = CliRunner().invoke(app, figures)
        assert result.exit_code == 0 and result.exception is None, (bad, result.output)
    solves = ['0,points/a,[1],,converged,2.5,0.1', '1,points/b,[2],,converged,1.5,0.1']  # a solve has no K
    for content in (b"\xff\xfe\x00", b"point,max_e\n0,1\n", b"garbage", "\n".join([header, *solves]).encode()):
        (out / "index.csv").write_bytes(content)
        result = CliRunner().invoke(app, figures)
        assert result.exit_code == 2 and isinstance(result.exception, SystemExit), (content, result.output)
        [line] = result.output.strip().splitlines()
        assert "damaged index.csv" in line or "nothing to draw" in line, line
    (out / "index.csv").write_bytes(b"\xff\xfe\x00")
    line = _one_line_exit_2(run_cli(*figures))  # the real command line too
    assert line == f"error: {out / 'index.csv'}: damaged index.csv: 'utf-8' codec can't decode byte 0xff in " \
                   "position 0: invalid start byte", line


def test_a_bad_sweep_value_of_any_length_is_located_in_the_sweep_file(tmp_path) -> None:
    """A grid value whose echo is shortened (a list of 105 characters) is still located at its line."""
    spec = tmp_path / "sweep.yaml"
    value = "[" + ", ".join(["1.6581975061448995e-28"] * 3) + "]"
    spec.write_text(f"base: {STUDY2}\ngrid:\n  disturbance.scale: [{value}, 0.01]\n")
    line = _one_line_exit_2(run_cli("validate", str(spec)))
    assert line.startswith(f"error: {spec}:3:22: disturbance.scale: Input should be a valid number (point 0: "), line


def test_a_sweep_axis_with_a_value_twice_is_refused(tmp_path) -> None:
    spec = tmp_path / "sweep.yaml"
    spec.write_text(f"base: {CONFIGS / 'paper_study2.yaml'}\ngrid:\n  run.steps: [3, 4, 3]\n")
    line = _one_line_exit_2(run_cli("validate", str(spec)))
    assert line.startswith(f"error: {spec}:3:3: grid: points 0 and 2 have the same parameters (run.steps=3)"), line


def test_numerical_overflow_is_a_line_in_the_log_not_a_warning_on_stderr(tmp_path) -> None:
    out = tmp_path / "run"
    proc = run_cli("solve", STUDY2, "--out", str(out), "--set", "game.x0=[1e300, 1e300, 1e300]", "-q")
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] != "converged"
    warnings = [e["message"] for e in read_run(out).messages["/log"] if level_name(e) == "warning"]
    assert any(w.startswith("floating-point trouble: overflow encountered") for w in warnings), warnings


@pytest.mark.parametrize("command", ["solve", "simulate", "sweep", "figures"])
def test_an_out_path_too_long_is_one_short_line_with_exit_2(command: str, tmp_path) -> None:
    """A 300-character path component (ENAMETOOLONG) and a 5,000-character path: exit code 2, the path shortened."""
    for out in (tmp_path / ("a" * 300), Path(str(tmp_path / "/".join(["b" * 250] * 20))) / ("c" * 300)):
        source = {"solve": CONFIGS / "harker.yaml", "simulate": STUDY2, "sweep": CONFIGS / "k_sweep.yaml",
                  "figures": CONFIGS}[command]
        args = [command, str(source), "--out", str(out)] + (["--workers", "1"] if command == "sweep" else [])
        if command == "figures":
            run = tmp_path / "run"
            if not run.exists():
                assert run_cli("solve", str(CONFIGS / "harker.yaml"), "--out", str(run), "-q").returncode == 0
            args = ["figures", str(run), "--out", str(out / "figs")]
        line = _one_line_exit_2(run_cli(*args))
        assert "File name too long" in line and len(line) < 400, line
        assert not os.path.exists(out)
