"""Bad runtime parameters and data files: exit code 2, one line at the config's file:line:column, nothing written
anywhere, no data file modified (the real command line as a subprocess)."""

from __future__ import annotations

import re

import pytest

from .conftest import run_cli
from .test_bad_input import _one_line_exit_2

GAME = """\
name: rt
game:
  kind: dynamic
  horizon: 4
  parameters: {{N: 2}}
  runtime:
{runtime}
  states: [x]
  dynamics: {{x: "{dynamics}"}}
  x0: [0]
  agents:
    - name: p
      inputs: [u]
      stage_cost: "{cost}"
run: {{K: [1], steps: 6, sampling_time: 0.5}}
"""

GOOD_TABLE = "t,r\n" + "".join(f"{0.5 * k},{k % 3}\n" for k in range(40))


def _case(runtime: str, cost: str = "(x - r)**2 + u**2", dynamics: str = "x + u", table: str | None = GOOD_TABLE,
          extra: str = "") -> tuple[str, str | None]:
    return GAME.format(runtime=runtime, cost=cost, dynamics=dynamics) + extra, table


CASES = {
    "a table shorter than the run": (
        _case("    r: {file: ref.csv}", table="t,r\n0,1\n2.5,2\n"),
        "game.runtime.r.file", "the table spans t = 0 .. 2.5 s; the run needs t = 0 .. 5 s"),
    "a NaN in the data": (
        _case("    r: {file: ref.csv}", table="t,r\n0,1\n1,nan\n20,3\n"),
        "game.runtime.r.file", "column 'r' has a value that is not a finite number in data row 2"),
    "text in the data": (
        _case("    r: {file: ref.csv}", table="t,r\n0,1\n1,fast\n20,3\n"),
        "game.runtime.r.file", "data row 2, column 'r': 'fast' is not a number"),
    "a missing column": (
        _case("    r: {file: ref.csv, column: speed}"),
        "game.runtime.r.file", "has no value column 'speed' (columns: t, r)"),
    "a missing time column": (
        _case("    r: {file: ref.csv, time: time}"),
        "game.runtime.r.file", "has no time column 'time' (columns: t, r)"),
    "a file that is not there": (
        _case("    r: {file: nowhere.csv}"),
        "game.runtime.r.file", "nowhere.csv: no such file"),
    "a directory": (
        _case("    r: {file: folder}"),
        "game.runtime.r.file", "folder: not a regular file"),
    "times that go back": (
        _case("    r: {file: ref.csv}", table="t,r\n0,1\n5,2\n4,2\n20,3\n"),
        "game.runtime.r.file", "the times must increase (data row 3: 4 after 5)"),
    "a runtime parameter as a range bound": (
        _case("    n: 2", cost="sum(u**k for k in 1..n) + (x - 1)**2"),
        "", "'n' in 'n' is a runtime parameter; ranges, templates and indices need integers"),
    "an index that is not an integer": (
        _case("    r: {per_stage: true, value: 0}", cost="(x - r[tau/2])**2 + u**2"),
        "game.agents.0.stage_cost", "the index of 'r' is 0.5, not an integer (at tau = 1)"),
    "an index outside the stages": (
        _case("    r: {per_stage: true, value: 0}", cost="(x - r[tau + 2])**2 + u**2"),
        "game.agents.0.stage_cost", "index 6 of 'r' is outside 0..5 (at tau = 4)"),
    "a vector without its index": (
        _case("    g: [1, 2]", cost="(x - g)**2 + u**2"),
        "game.agents.0.stage_cost", "'g' is a runtime vector: use its entries (g[1])"),
    "a runtime number indexed": (
        _case("    g: 1", cost="(x - g[1])**2 + u**2"),
        "game.agents.0.stage_cost", "'g' is indexed but is a runtime number"),
    "a runtime value in the dynamics": (
        _case("    g: 1", dynamics="x + g*u", cost="(x - g)**2 + u**2"),
        "game.dynamics.x", "'g' is a runtime value: the dynamics are compiled with constants"),
    "t in the dynamics": (
        _case("    g: 1", dynamics="x + t*u", cost="(x - g)**2 + u**2"),
        "game.dynamics.x", "'t' is a runtime value"),
    "a per-stage list of the wrong length": (
        _case("    r: {per_stage: true, value: [1, 2]}"),
        "game.runtime.r.value", "a per-stage value is one number or a list of 5 (stages 0..T) or 6 numbers"),
    "a file and a value": (
        _case("    r: {file: ref.csv, value: 1}"),
        "game.runtime.r", "a data file gives the values at every stage: leave out value and per_stage"),
    "a ragged matrix": (
        _case("    Q: [[1, 2], [3]]", cost="Q[1][1]*x**2 + u**2"),
        "game.runtime.Q.value", "a matrix's rows must have the same number of entries"),
    "a runtime name taken": (
        _case("    x: 1", cost="x**2 + u**2"),
        "game.runtime.x", "is already declared"),
}


@pytest.mark.parametrize("case", list(CASES), ids=list(CASES))
def test_bad_runtime_input_is_refused_where_it_is_written(case, tmp_path) -> None:
    (text, table), path, fragment = CASES[case]
    config = tmp_path / "game.yaml"
    config.write_text(text)
    (tmp_path / "folder").mkdir()
    if table is not None:
        (tmp_path / "ref.csv").write_text(table)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()}
    for command in (["validate", str(config)], ["simulate", str(config), "--out", str(tmp_path / "run")]):
        line = _one_line_exit_2(run_cli(*command, cwd=tmp_path))
        assert re.match(rf"error: {re.escape(str(config))}:\d+:\d+: ", line), line
        assert f"{path}: " in line and fragment in line, line  # (expansion's messages name no field)
    assert not (tmp_path / "run").exists() and not (tmp_path / "runs").exists()
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()} == before  # nothing modified


def test_the_location_is_the_line_of_the_field(tmp_path) -> None:
    text, table = _case("    r: {file: ref.csv}", table="t,r\n0,1\n1,nan\n20,3\n")
    (tmp_path / "game.yaml").write_text(text)
    (tmp_path / "ref.csv").write_text(table)
    line = _one_line_exit_2(run_cli("validate", str(tmp_path / "game.yaml")))
    row = text.splitlines().index("    r: {file: ref.csv}") + 1
    assert f"game.yaml:{row}:" in line, line


def test_a_runtime_parameter_as_a_bound_is_refused_with_the_way_out(tmp_path) -> None:
    text, _ = _case("    umax: 1.0", cost="(x - 1)**2 + u**2")
    text = text.replace("      inputs: [u]", "      inputs: {u: {lower: -umax, upper: 2}}")
    (tmp_path / "game.yaml").write_text(text)
    line = _one_line_exit_2(run_cli("validate", str(tmp_path / "game.yaml")))
    row = text.splitlines().index("      inputs: {u: {lower: -umax, upper: 2}}") + 1
    assert f"game.yaml:{row}:" in line
    assert "it is a runtime parameter: write a bound that changes at run time as a constraint, e.g. u <= umax" in line
