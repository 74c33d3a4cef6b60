"""The real `gnerun` command, run as a subprocess."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from gnerun.log.mcap_log import read_messages

from .conftest import CONFIGS, run_cli

POSITION = re.compile(r"^error: (?P<file>[^:\s]+):(?P<line>\d+):(?P<col>\d+): ")


def _no_traceback(proc) -> None:
    assert "Traceback" not in proc.stderr and "Traceback" not in proc.stdout


def test_help_lists_the_commands() -> None:
    proc = run_cli("--help")
    assert proc.returncode == 0
    for command in ("solve", "simulate", "validate"):
        assert command in proc.stdout


def test_version() -> None:
    import gnerun

    proc = run_cli("--version")
    assert proc.returncode == 0
    assert proc.stdout.strip() == f"gnerun {gnerun.__version__}"


def test_solve_paper_study1(tmp_path: Path) -> None:
    out = tmp_path / "run"
    proc = run_cli("solve", str(CONFIGS / "paper_study1.yaml"), "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    assert "status: converged" in proc.stdout
    assert "best-response gaps" in proc.stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "converged"
    assert summary["residual_norm"] <= 1e-12
    assert summary["iterations"] <= 7
    assert all(abs(g) <= 1e-8 for g in summary["certificate"]["best_response_gap"].values())
    iterates = [m for t, m, _ in read_messages(out / "run.mcap") if t == "/solve/iterate"]
    assert len(iterates) == summary["iterations"] + 1
    # the table on stdout shows every iterate
    rows = [line for line in proc.stdout.splitlines() if re.match(r"^\s+\d+\s", line)]
    assert len(rows) == summary["iterations"] + 1


def test_default_run_directory_is_under_runs(tmp_path: Path) -> None:
    proc = run_cli("solve", str(CONFIGS / "fk_a12.yaml"), "--quiet", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == ""
    [run] = list((tmp_path / "runs").iterdir())
    assert run.name.startswith("fk_a12-") or run.name.startswith("fk-a12-")
    assert (run / "summary.json").exists()


def test_set_overrides_a_field(tmp_path: Path) -> None:
    out = tmp_path / "run"
    proc = run_cli("solve", str(CONFIGS / "paper_study1.yaml"), "--out", str(out), "--set", "game.horizon=5",
                   "--set", "solver.complementarity=fischer_burmeister", "--quiet")
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert len(summary["solution"]["agent1"]["u1"]) == 6
    assert "complementarity: fischer_burmeister" in (out / "config.yaml").read_text()


def test_a_run_that_does_not_converge_still_exits_zero(tmp_path: Path) -> None:
    out = tmp_path / "run"
    proc = run_cli("solve", str(CONFIGS / "nonlinear_gne.yaml"), "--out", str(out), "--set", "solver.max_iter=1")
    assert proc.returncode == 0, proc.stderr
    assert "status: max_iter" in proc.stdout
    assert json.loads((out / "summary.json").read_text())["status"] == "max_iter"


def test_unknown_key_gives_position_and_exit_2(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    text = (CONFIGS / "fk_a12.yaml").read_text().replace("  kind: ssn\n", "  kind: ssn\n  tolerance: 1\n")
    bad.write_text(text)
    line = text.splitlines().index("  tolerance: 1") + 1
    proc = run_cli("solve", str(bad), "--out", str(tmp_path / "run"))
    assert proc.returncode == 2
    _no_traceback(proc)
    m = POSITION.match(proc.stderr)
    assert m, proc.stderr
    assert (m["file"], int(m["line"]), int(m["col"])) == (str(bad), line, 3)
    assert "solver.tolerance: unknown key" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "run").exists()


def test_bad_expression_gives_the_column_of_the_character(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    text = (CONFIGS / "fk_a12.yaml").read_text().replace('cost: "x1*(x1 + x2 - 16)"', 'cost: "x1*(x1 + y - 16)"')
    bad.write_text(text)
    line_text = next(s for s in text.splitlines() if "x1 + y" in s)
    line = text.splitlines().index(line_text) + 1
    col = line_text.index("y - 16") + 1
    proc = run_cli("solve", str(bad))
    assert proc.returncode == 2
    _no_traceback(proc)
    assert proc.stderr.startswith(f"error: {bad}:{line}:{col}: game.agents.0.cost: unknown name 'y'")


def test_yaml_syntax_error(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\ngame: [1, 2\nsolver: {}\n")
    proc = run_cli("validate", str(bad))
    assert proc.returncode == 2
    _no_traceback(proc)
    assert POSITION.match(proc.stderr), proc.stderr
    assert "YAML syntax error" in proc.stderr


def test_validate_lists_every_problem(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    text = (CONFIGS / "fk_a12.yaml").read_text()
    text = text.replace('cost: "x1*(x1 + x2 - 16)"', 'cost: "x1*(x1 + y - 16)"')
    text = text.replace('cost: "x2*(x1 + x2 - 16)"', 'cost: "x2*(x1 + x2 - 16"')
    bad.write_text(text)
    proc = run_cli("validate", str(bad))
    assert proc.returncode == 2
    _no_traceback(proc)
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 2
    assert all(POSITION.match(s) for s in lines)
    ok = run_cli("validate", str(CONFIGS / "paper_study1.yaml"))
    assert ok.returncode == 0
    assert "33 decisions, 44 multipliers" in ok.stdout


@pytest.mark.parametrize("args, needle", [
    (["solve", "does/not/exist.yaml"], "no such file"),
    (["solve", str(CONFIGS / "fk_a12.yaml"), "--set", "solver.tol"], "expected key.path=value"),
    (["solve", str(CONFIGS / "fk_a12.yaml"), "--set", "solver.tol=-1"], "--set solver.tol=-1: solver.tol"),
    (["solve", str(CONFIGS / "fk_a12.yaml"), "--set", "game.agents.5.cost=x1"], "no such list element"),
    (["solve", str(CONFIGS)], "is a directory"),
])
def test_bad_input_is_one_line_and_exit_2(args: list[str], needle: str) -> None:
    proc = run_cli(*args)
    assert proc.returncode == 2, proc.stderr
    _no_traceback(proc)
    assert needle in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


def test_existing_run_directory_needs_force(tmp_path: Path) -> None:
    out = tmp_path / "run"
    assert run_cli("solve", str(CONFIGS / "fk_a12.yaml"), "--out", str(out), "-q").returncode == 0
    again = run_cli("solve", str(CONFIGS / "fk_a12.yaml"), "--out", str(out), "-q")
    assert again.returncode == 2
    assert "--force" in again.stderr
    forced = run_cli("solve", str(CONFIGS / "fk_a12.yaml"), "--out", str(out), "-q", "--force")
    assert forced.returncode == 0


def test_debug_shows_the_traceback(tmp_path: Path) -> None:
    proc = run_cli("--debug", "solve", "does/not/exist.yaml")
    assert proc.returncode == 2
    assert "Traceback" in proc.stderr
