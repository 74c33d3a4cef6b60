"""The real `gnerun` command, run as a subprocess."""

from __future__ import annotations

import json
import re
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from gnerun.log.mcap_log import read_messages

from .conftest import CONFIGS, gnerun_command, run_cli

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


def test_solve_prints_the_solution(tmp_path: Path) -> None:
    # Harker's game: its variational equilibrium is x = (5, 9) (Harker 1991; Facchinei & Kanzow 2010)
    proc = run_cli("solve", str(CONFIGS / "harker.yaml"), "--out", str(tmp_path / "h"))
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    i = lines.index("solution:")
    assert lines[i + 1].split() == ["p1", "x1", "=", "5"] and lines[i + 2].split() == ["p2", "x2", "=", "9"]
    assert "(1 iteration)" in proc.stdout and "1 iterations" not in proc.stdout


def test_solve_summarises_a_long_horizon(tmp_path: Path) -> None:
    proc = run_cli("solve", str(CONFIGS / "paper_study1.yaml"), "--out", str(tmp_path / "s"))
    assert proc.returncode == 0, proc.stderr
    solution = json.loads((tmp_path / "s" / "summary.json").read_text())["solution"]
    lines = proc.stdout.splitlines()
    i = lines.index("solution (inputs by stage tau = 0..10):")
    assert lines[i + 1].split() == ["agent", "input", "0", "1", "2", "...", "9", "10"]
    for line, (agent, inputs) in zip(lines[i + 2: i + 5], solution.items(), strict=True):
        [(name, values)] = inputs.items()
        shown = [float(v) for v in line.split()[2:] if v != "..."]
        assert line.split()[:2] == [agent, name] and len(line) <= 100
        np.testing.assert_allclose(shown, values[:3] + values[-2:], rtol=1e-3, atol=1e-12)  # 4 digits


def test_headers_name_the_method_as_configured(tmp_path: Path) -> None:
    proc = run_cli("solve", str(CONFIGS / "variational_gne.yaml"), "--out", str(tmp_path / "jn"))
    assert proc.returncode == 0, proc.stderr
    header = proc.stdout.splitlines()[0]
    assert "jn (Josephy-Newton)" in header and "map" not in header  # no complementarity map in Josephy-Newton
    proc = run_cli("solve", str(CONFIGS / "harker.yaml"), "--out", str(tmp_path / "fb"), "--set",
                   "solver.complementarity=fischer_burmeister")
    assert "ssn (Fischer-Burmeister map)" in proc.stdout.splitlines()[0]


def test_simulate_refuses_a_static_game_before_anything_runs(tmp_path: Path) -> None:
    proc = run_cli("simulate", str(CONFIGS / "harker.yaml"), "--out", str(tmp_path / "run"))
    assert proc.returncode == 2 and proc.stdout == ""
    _no_traceback(proc)
    assert len(proc.stderr.strip().splitlines()) == 1 and "simulate needs a dynamic game" in proc.stderr
    assert not (tmp_path / "run").exists()


COMMANDS = ("validate", "solve", "simulate", "sweep", "figures", "inspect", "replay", "recover")


def test_help_says_everything_plainly() -> None:
    top = run_cli("--help").stdout
    listed = top.split("Commands:")[1].split("Examples:")[0].strip().splitlines()
    assert [line.split()[0] for line in listed] == list(COMMANDS)  # one line each: nothing wraps
    for line in listed:
        assert line.rstrip().endswith(".") and "…" not in line and "..." not in line, line
    assert "gnerun solve configs/harker.yaml" in top.split("Examples:")[1]
    for command in COMMANDS:
        text = run_cli(command, "--help").stdout
        assert not re.search(r"\{\w+\}|<(path|str|int|float|bool|list\[\w+\])>", text), (command, text)
        assert text.splitlines()[0].startswith(f"Usage: gnerun {command} [OPTIONS] ")
    solve_help = run_cli("solve", "--help").stdout
    assert "--set KEY.PATH=VALUE" in solve_help and "repeat it" in solve_help
    assert "CONFIG  Experiment config" in solve_help
    assert "sweep" not in run_cli("replay", "--help").stdout
    assert "sweep directories" in run_cli("figures", "--help").stdout


def test_python_callers_get_python_in_error_messages() -> None:
    from gnerun import ConfigError, InputError, load_config

    with pytest.raises(ConfigError) as err:
        load_config(CONFIGS / "fk_a12.yaml", overrides={"solver.tl": 1})
    assert str(err.value).startswith("overrides['solver.tl'] = 1: solver.tl: unknown key")
    with pytest.raises(InputError) as err:
        load_config(CONFIGS / "fk_a12.yaml", overrides={"game.agents.5.cost": "x1"})
    assert "--set" not in str(err.value) and "overrides['game.agents.5.cost'] = 'x1'" in str(err.value)
    with pytest.raises(ConfigError) as err:  # the same as CLI text
        load_config(CONFIGS / "fk_a12.yaml", ["solver.tl=1"])
    assert str(err.value).startswith("--set solver.tl=1: solver.tl: unknown key")


def test_what_to_do_next_is_said_in_python_to_python_and_in_options_on_the_command_line(tmp_path: Path) -> None:
    import gnerun

    two_problems = {"solver.tl": 1, "solver.kind": "foo"}
    with pytest.raises(gnerun.ConfigError) as err:
        gnerun.load_config(CONFIGS / "fk_a12.yaml", overrides=two_problems)
    assert str(err.value).endswith("(and 1 more problem: all of them in the error's .problems)")
    assert len(err.value.problems) == 2 and "gnerun" not in str(err.value)
    bad = tmp_path / "bad.yaml"
    bad.write_text((CONFIGS / "fk_a12.yaml").read_text() + "extra: 1\nmore: 2\n")
    proc = run_cli("solve", str(bad))
    assert proc.returncode == 2 and proc.stderr.rstrip().endswith(
        "(and 1 more problem: run `gnerun validate` for all)"), proc.stderr
    cfg = gnerun.load_config(CONFIGS / "harker.yaml")
    gnerun.solve(cfg, out=tmp_path / "run")
    with pytest.raises(gnerun.InputError) as err:
        gnerun.solve(cfg, out=tmp_path / "run")
    assert "force=True" in str(err.value) and "--force" not in str(err.value)
    with pytest.raises(gnerun.InputError) as err:
        gnerun.simulate(cfg)
    assert "gnerun.solve" in str(err.value) and "`gnerun solve`" not in str(err.value)
    proc = run_cli("solve", str(CONFIGS / "harker.yaml"), "--out", str(tmp_path / "run"))
    assert proc.returncode == 2 and "(use --force to overwrite)" in proc.stderr and "force=True" not in proc.stderr


def test_the_public_namespace_is_the_api() -> None:
    import subprocess
    import sys

    import gnerun

    api = sorted(gnerun.__all__)
    assert dir(gnerun) == api and {"Any", "annotations", "import_module"}.isdisjoint(dir(gnerun))
    # also in a fresh interpreter, after the API was used (its subpackages are loaded then)
    out = subprocess.run([sys.executable, "-c", "import gnerun; gnerun.load_config; gnerun.solve; print(dir(gnerun))"],
                         capture_output=True, text=True, check=True).stdout
    assert out.strip() == str(api)


def test_no_docstring_cites_the_specification() -> None:
    """Users have the README and the docstrings, not the project's specification."""
    import ast

    package = Path(__file__).resolve().parent.parent / "gnerun"
    for path in package.rglob("*.py"):
        tree = ast.parse(path.read_text())
        for node in [tree, *ast.walk(tree)]:
            if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
                doc = ast.get_docstring(node) or ""
                assert "SPEC" not in doc, (path, getattr(node, "name", "module"))
        assert "SPEC §" not in path.read_text(), path


SIX_ROBOTS = ["--set", "game.parameters.N=6",
              "--set", "game.x0=[0.3,-0.2,-0.4,0.5,-0.9,-0.6,0.6,-1.1,1.2,0.1,-1.3,0.9]"]
ROW = re.compile(r"^\s+\d+\s")
TIMING = re.compile(r"^wall (?P<wall>\d+\.\d+) s: (?P<parts>.*)$")


def _timing(stdout: str) -> tuple[float, dict[str, float]]:
    """The timing line (the last line): the wall time and its parts, in order."""
    m = TIMING.match(stdout.splitlines()[-1])
    assert m, stdout.splitlines()[-1]
    parts = {name: float(v) for name, v in (p.split() for p in m["parts"].split(", "))}
    return float(m["wall"]), parts


def _assert_sums_to_wall(wall: float, parts: dict[str, float]) -> None:
    # each number is rounded to 0.01 s (below 10 s) or 0.1 s; "other" is the wall time less the parts measured
    step = 0.01 if wall < 10 else 0.1
    assert abs(sum(parts.values()) - wall) <= step / 2 * (len(parts) + 1) + 1e-9
    assert parts["other"] >= -0.02 and all(v >= 0 for name, v in parts.items() if name != "other")


def test_long_solves_thin_their_rows_and_verbose_shows_all(tmp_path: Path) -> None:
    """71 iterations of the 6-robot formation: the first 20 rows, then every 10th iterate, the first row of each phase
    of the default method and the last row, and a line that counts the rows left out; --verbose prints them all."""
    full = run_cli("solve", str(CONFIGS / "formation_ring.yaml"), *SIX_ROBOTS, "--out", str(tmp_path / "v"),
                   "--verbose")
    assert full.returncode == 0, full.stderr
    iterates = [m for t, m, _ in read_messages(tmp_path / "v" / "run.mcap") if t == "/solve/iterate"]
    rows = [line.split() for line in full.stdout.splitlines() if ROW.match(line)]
    assert [int(r[0]) for r in rows] == [m["k"] for m in iterates] and len(rows) > 40
    assert full.stdout.splitlines()[1].split() == ["k", "||Phi||", "||z-z*||", "||dz||", "changes", "phase"]
    assert "not shown" not in full.stdout
    phases = [r[-1] for r in rows]
    assert {"newton", "interior"} <= set(phases)
    expected = [r for i, r in enumerate(rows) if i < 20 or int(r[0]) % 10 == 0 or i == len(rows) - 1
                or phases[i] != phases[i - 1]]

    thin = run_cli("solve", str(CONFIGS / "formation_ring.yaml"), *SIX_ROBOTS, "--out", str(tmp_path / "t"))
    assert thin.returncode == 0, thin.stderr
    shown = [line.split() for line in thin.stdout.splitlines() if ROW.match(line)]
    assert [r[0] for r in shown] == [r[0] for r in expected]
    assert shown[-1][0] == str(iterates[-1]["k"])
    lines = thin.stdout.splitlines()
    notice = lines.index(f"  ... {len(rows) - len(shown)} rows not shown; --verbose shows all")
    assert lines[notice - 1].split() == shown[-1] and lines[notice + 1].startswith("status: converged")


def test_a_short_solve_prints_every_row(tmp_path: Path) -> None:
    proc = run_cli("solve", str(CONFIGS / "paper_study1.yaml"), "--out", str(tmp_path / "s"))
    assert proc.returncode == 0, proc.stderr
    iterations = json.loads((tmp_path / "s" / "summary.json").read_text())["iterations"]
    assert len([line for line in proc.stdout.splitlines() if ROW.match(line)]) == iterations + 1
    assert "not shown" not in proc.stdout


def test_solve_ends_with_where_the_wall_time_went(tmp_path: Path) -> None:
    proc = run_cli("solve", str(CONFIGS / "paper_study1.yaml"), "--out", str(tmp_path / "s"))
    assert proc.returncode == 0, proc.stderr
    wall, parts = _timing(proc.stdout)
    assert list(parts) == ["startup", "imports", "load", "compile", "reference", "solve", "certificate", "logging",
                           "other"]
    _assert_sums_to_wall(wall, parts)
    summary = json.loads((tmp_path / "s" / "summary.json").read_text())
    for name, key in (("solve", "time_s"), ("certificate", "certificate_time_s"), ("compile", "compile_time_s")):
        assert parts[name] == pytest.approx(summary[key], abs=0.006)
    assert proc.stdout.splitlines()[-2] == f"run directory: {tmp_path / 's'}"
    assert run_cli("solve", str(CONFIGS / "paper_study1.yaml"), "--out", str(tmp_path / "q"), "-q").stdout == ""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the process's start is read from /proc")
def test_startup_is_not_what_a_shell_ran_before_it_became_gnerun(tmp_path: Path) -> None:
    """`bash -c '...; exec gnerun solve ...'`: the shell's process becomes gnerun, and /proc dates it from the shell's
    start. The commands before it (0.3 s of CPU in a child, then one second of sleep) are not gnerun's startup."""
    burn = "python3 -c 'import time\nt = time.process_time()\nwhile time.process_time() - t < 0.3: pass'"
    solve = shlex.join([*gnerun_command(), "solve", str(CONFIGS / "paper_study1.yaml"), "--out", str(tmp_path / "s")])
    proc = subprocess.run(["bash", "-c", f"{burn} && sleep 1 && exec {solve}"], capture_output=True, text=True,
                          timeout=120, stdin=subprocess.DEVNULL)
    assert proc.returncode == 0, proc.stderr
    wall, parts = _timing(proc.stdout)
    assert parts["startup"] < 1.0 and wall < parts["startup"] + 60
    _assert_sums_to_wall(wall, parts)


def test_simulate_reports_t0_apart_and_ends_with_its_timing(tmp_path: Path) -> None:
    """t = 0, solved to tolerance once for every K, is a line of its own; the table's step times are those of t >= 1;
    --verbose adds the iterate rows of the t = 0 solve; the last line is the timing."""
    out = tmp_path / "run"
    proc = run_cli("simulate", str(CONFIGS / "formation_ring.yaml"), "--out", str(out), "--set", "run.K=[1,3,10]",
                   "--set", "run.steps=5", "--verbose")
    assert proc.returncode == 0, proc.stderr
    by_K = json.loads((out / "summary.json").read_text())["by_K"]
    lines = proc.stdout.splitlines()
    first = by_K["1"]
    i = lines.index("t = 0, the solve to tolerance:")
    rows = [line.split() for line in lines[i + 2: i + 2 + first["iterations"][0] + 1]]
    assert [int(r[0]) for r in rows] == list(range(first["iterations"][0] + 1))
    assert [float(r[1]) for r in rows][-1] == pytest.approx(first["residual_norm"][0], rel=1e-3)
    line = next(s for s in lines if s.startswith("t = 0, solved"))
    assert line == (f"t = 0, solved to tolerance once for K = 1, 3, 10: converged, {first['iterations'][0]} "
                    f"iterations, {first['solve_time_s'][0] * 1e3:.3f} ms; step times below: t >= 1")
    header = lines.index(line) + 1
    assert lines[header].split() == ["K", "max", "e", "final", "e", "median", "t>=1", "max", "t>=1", "failed",
                                     "fallback", "max", "violation"]
    for row in (s.split() for s in lines[header + 1: header + 4]):
        steps = sorted(by_K[row[0]]["solve_time_s"][1:])  # t >= 1
        assert row[4] == row[6] == "ms"
        assert float(row[3]) == pytest.approx(steps[len(steps) // 2] * 1e3, abs=1e-3)
        assert float(row[5]) == pytest.approx(steps[-1] * 1e3, abs=1e-3)
    wall, parts = _timing(proc.stdout)
    assert list(parts) == ["startup", "imports", "load", "compile", "reference", "solve", "logging", "other"]
    _assert_sums_to_wall(wall, parts)
    quiet = run_cli("simulate", str(CONFIGS / "formation_ring.yaml"), "--out", str(tmp_path / "q"), "--set",
                    "run.steps=2")
    assert "t = 0, the solve to tolerance:" not in quiet.stdout and "t = 0, solved to tolerance once" in quiet.stdout
