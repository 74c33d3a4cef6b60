"""Messages that point at the mistake: the cause first, "did you mean", allowed-here lists of that exact place, one
message per template, and a template's character (file:line:column, the index values, a caret under the template's
line). Each case asserts the exact text, through the command line where it is about what a user reads."""

from __future__ import annotations

from pathlib import Path

import pytest

from gnerun.errors import ConfigError, Names, excerpt
from gnerun.language.config import (
    ContinuousDynamics,
    DynamicGame,
    SharedConstraint,
    StaticAgent,
    Variable,
    copies_text,
    load_config,
    schema_at,
)

from .conftest import CONFIGS, run_cli

HARKER = (CONFIGS / "harker.yaml").read_text()
RING = (CONFIGS / "formation_ring.yaml").read_text()


def _config(tmp_path: Path, text: str, old: str, new: str, name: str = "case.yaml") -> tuple[Path, list[str]]:
    """``text`` with ``old`` replaced by ``new`` (once, and it is there) written to a file; and the file's lines."""
    assert text.count(old) == 1, old
    path = tmp_path / name
    path.write_text(text.replace(old, new))
    return path, path.read_text().splitlines()


def _line(lines: list[str], fragment: str) -> int:
    """The 1-based number of the only line that holds ``fragment``."""
    [number] = [i + 1 for i, line in enumerate(lines) if fragment in line]
    return number


def _problems(text: str) -> list[str]:
    with pytest.raises(ConfigError) as err:
        load_config(text=text, path="cfg.yaml")
    return err.value.problems


# 1. the cause first --------------------------------------------------------------------------------------------------


def test_a_misspelt_key_is_the_message_and_the_field_it_names_is_not_reported_missing(tmp_path: Path) -> None:
    config, lines = _config(tmp_path, HARKER, "      variables: {x1:", "      variable: {x1:")
    proc = run_cli("validate", str(config))
    assert proc.returncode == 2
    line = _line(lines, "variable: {x1:")
    assert proc.stderr == (f"error: {config}:{line}:7: game.agents.0.variable: unknown key; did you mean 'variables'? "
                           "(allowed here: name, variables, cost, constraints, for)\n")


def test_a_field_missing_where_an_unknown_key_was_written_comes_after_it() -> None:
    # 'objective' is not a misspelling of cost: both are reported, the unknown key first
    problems = _problems(HARKER.replace('      cost: "x1**2 + 8/3', '      objective: "x1**2 + 8/3'))
    assert problems == [
        "cfg.yaml:10:7: game.agents.0.objective: unknown key (allowed here: name, variables, cost, constraints, for)",
        "cfg.yaml:8:7: game.agents.0.cost: required field is missing",
    ]


# 2. did you mean -----------------------------------------------------------------------------------------------------


def test_a_misspelt_key_under_an_ode_is_named_with_the_odes_keys(tmp_path: Path) -> None:
    config, lines = _config(tmp_path, RING, "    integrator: rk4", "    integrater: rk4")
    proc = run_cli("solve", str(config))
    assert proc.returncode == 2
    assert proc.stderr == (f"error: {config}:{_line(lines, 'integrater')}:5: game.dynamics.integrater: unknown key; "
                           "did you mean 'integrator'? (allowed here: ode, integrator, dt)\n")


@pytest.mark.parametrize(("word", "names", "closest"), [
    ("integrater", ["ode", "integrator", "dt"], "integrator"),
    ("variable", ["name", "variables", "cost"], "variables"),
    ("tolerance", ["kind", "tol", "max_iter"], "tol"),  # an abbreviation
    ("Tol", ["tol"], "tol"),
    ("uxx7", [f"u{c}{i}" for c in "xy" for i in range(1, 5001)], "ux7"),  # by pattern, keeping the numbers
    ("xx2", ["N", "pi"] + [f"x{i}" for i in range(1, 11)], "x2"),
    ("zeta", ["x1", "x2", "pi"], None),
    ("x3", ["x1", "x2"], None),  # not a guess among the numbers
    ("y10", [f"x{i}" for i in range(1, 11)], None),  # the same answer as for y2 (its copy i = 2)
    ("speeed", ["speed"] + [f"x{i}" for i in range(1, 5001)], "speed"),
])
def test_names_suggests_the_closest_name(word: str, names: list[str], closest: str | None) -> None:
    assert Names(names).closest(word) == closest


def test_an_unknown_function_suggests_one() -> None:
    [problem] = _problems(HARKER.replace('cost: "x1**2 + 8/3*x1*x2', 'cost: "sqr(x1) + 8/3*x1*x2'))
    assert problem.startswith("cfg.yaml:10:14: game.agents.0.cost: unknown function 'sqr'; did you mean 'sqrt'? "
                              "(functions: sqrt, exp,"), problem


# 3. allowed here: the schema of that exact place ---------------------------------------------------------------------


def test_a_misspelt_section_of_the_game_lists_every_key_of_the_game_with_definitions(tmp_path: Path) -> None:
    config, lines = _config(tmp_path, RING, "  shared_constraints:", "  shared_constraint:")
    proc = run_cli("validate", str(config))
    assert proc.returncode == 2
    assert proc.stderr == (
        f"error: {config}:{_line(lines, 'shared_constraint:')}:3: game.shared_constraint: unknown key; did you mean "
        "'shared_constraints'? (allowed here: kind, horizon, states, dynamics, x0, parameters, runtime, references, "
        "agents, shared_constraints, equilibrium, definitions)\n")


def test_dynamics_with_a_misspelt_ode_are_an_ode_with_a_misspelt_key() -> None:
    # two keys of the ode's form: its misspelt ode, its dt (before, the dynamics were read as x(t+1) of states named
    # odes and dt: "odes: Input should be a valid string")
    problems = _problems(RING.replace("    ode:\n", "    odes:\n"))
    assert problems == ["cfg.yaml:21:5: game.dynamics.odes: unknown key; did you mean 'ode'? "
                        "(allowed here: ode, integrator, dt)"]


@pytest.mark.parametrize(("loc", "model"), [
    (("game", "dynamic", "dynamics", "continuous"), ContinuousDynamics),  # the branch pydantic's location names
    (("game", "dynamic"), DynamicGame),
    (("game", "static", "agents", 3), StaticAgent),
    (("game", "static", "agents", 0, "variables", "x1"), Variable),
    (("game", "dynamic", "shared_constraints", 2, "options"), SharedConstraint),
    (("game", "nonsense"), None),
])
def test_schema_at_follows_the_union_branch_the_error_names(loc: tuple, model: object) -> None:
    assert schema_at(loc) is model


# 4. one message per template -----------------------------------------------------------------------------------------


def test_a_mistake_in_every_copy_of_a_family_is_one_message(tmp_path: Path) -> None:
    config, lines = _config(tmp_path, RING, '"ux{i}": {lower: -1.5', '"ux{i}": {lowr: -1.5')
    proc = run_cli("validate", str(config), "--set", "game.parameters.N=6")
    assert proc.returncode == 2
    assert proc.stderr == (f"error: {config}:{_line(lines, 'lowr')}:19 (in 6 copies, for i = 1..6): "
                           "game.agents.0.inputs.ux1.lowr: unknown key; did you mean 'lower'? "
                           "(allowed here: lower, upper, start)\n")


def test_a_misspelt_field_of_a_family_is_one_message(tmp_path: Path) -> None:
    config, lines = _config(tmp_path, RING, "      inputs:\n", "      input:\n")
    proc = run_cli("validate", str(config), "--set", "game.parameters.N=6")
    assert proc.returncode == 2
    assert proc.stderr == (f"error: {config}:{_line(lines, 'input:')}:7 (in 6 copies, for i = 1..6): "
                           "game.agents.0.input: unknown key; did you mean 'inputs'? (allowed here: name, inputs, "
                           "stage_cost, terminal_cost, constraints, for)\n")


def test_a_mistake_in_the_pairs_of_a_family_is_one_message_with_its_pairs() -> None:
    text = RING.replace("(py{i} - py{j})**2 >= D**2", "(py{i} - py{j})**2 >= DD**2")
    lines = text.splitlines()
    line = _line(lines, "DD**2")
    assert _problems(text) == [
        f"cfg.yaml:{line}:{lines[line - 1].index('DD') + 1} (in 6 copies, for (i, j) = (1, 2), (1, 3), (1, 4), ..., "
        "(3, 4)): game.shared_constraints.0.expr: unknown name 'DD'; did you mean 'D'? (known here: D, N, dt, gx, gy, "
        "pi, px1, px2, px3, px4, py1, py2, py3, py4, rho, speed, t, tau, ux1, ux2, ux3, ux4, uy1, uy2, uy3, uy4) at "
        "column 44 of expression '(px{i} - px{j})**2 + (py{i} - py{j})**2 >= DD**2'"]


def test_a_mistake_in_some_copies_names_those() -> None:
    # x{i + 1} is a name for i = 1..3 only: the copy i = 4 alone is wrong
    text = RING.replace("+ 0.05*(ux{i}**2 + uy{i}**2)", "+ 0.05*(ux{i}**2 + uy{i}**2) + px{i + 1}")
    line = _line(text.splitlines(), "px{i + 1}")
    [problem] = _problems(text)
    assert problem.startswith(f"cfg.yaml:{line}:42 (for i = 4): game.agents.0.stage_cost: unknown name 'px5' (known "
                              "here: D, N,"), problem  # px5 is not a misspelling of px4
    assert problem.endswith(f"\n  {line} |           + 0.05*(ux{{i}}**2 + uy{{i}}**2) + px{{i + 1}}\n"
                            "     |                                          ^^^^^^^^^"), problem


@pytest.mark.parametrize(("bindings", "text"), [
    ([{"i": 1}, {"i": 2}, {"i": 3}, {"i": 5}], "i = 1..3, 5"),
    ([{"i": -1}, {"i": 0}], "i = -1, 0"),
    ([{"i": i, "j": j} for i in (1, 2, 3) for j in (1, 2)], "i = 1..3, j = 1, 2"),
    ([{"i": i, "j": j} for i in range(1, 5) for j in range(i + 1, 5)], "(i, j) = (1, 2), (1, 3), (1, 4), ..., (3, 4)"),
])
def test_copies_text(bindings: list[dict[str, int]], text: str) -> None:
    assert copies_text(bindings) == text


def test_a_problem_of_a_definition_is_reported_once_at_the_definition() -> None:
    text = (CONFIGS / "fk_a01.yaml").read_text().replace('S: "sum(x{k} for', 'S: "sum(xx{k} for')
    assert _problems(text) == [
        "cfg.yaml:10:13: game.definitions.S: unknown name 'xx1'; did you mean 'x1'? (known here: B, N, pi, x1, x10, "
        "x2, x3, x4, x5, x6, x7, x8, x9) at column 5 of expression 'sum(xx{k} for k in 1..N)'"]


# 5. a template's character -------------------------------------------------------------------------------------------


def test_a_name_in_a_folded_template_is_shown_at_its_character_with_a_caret(tmp_path: Path) -> None:
    config, lines = _config(tmp_path, RING, "+ 0.05*(ux{i}**2", "+ 0.05*(uxx{i}**2")
    line = _line(lines, "uxx{i}")
    proc = run_cli("validate", str(config), "--set", "game.parameters.N=6", "--set",
                   "game.x0=[0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]")
    assert proc.returncode == 2
    assert proc.stderr == (
        f"error: {config}:{line}:19 (in 6 copies, for i = 1..6): game.agents.0.stage_cost: unknown name 'uxx1'; "
        "did you mean 'ux1'? (known here: D, N, dt, gx, gy, pi, px1, px2, px3, px4, px5, px6, py1, py2, py3, py4, py5, "
        "py6, rho, speed, t, tau, ux1, ux2, ux3, ux4, ux5, ux6, uy1, uy2, uy3, uy4, uy5, uy6)\n"
        f"  {line} |           + 0.05*(uxx{{i}}**2 + uy{{i}}**2)\n"
        "     |                   ^^^^^^\n")
    proc = run_cli("solve", str(config))  # the first problem, with its excerpt, from any command
    assert proc.returncode == 2
    assert proc.stderr.splitlines()[1:] == [f"  {line} |           + 0.05*(uxx{{i}}**2 + uy{{i}}**2)",
                                            "     |                   ^^^^^^"]


LITERAL = """\
name: literal
game:
  kind: static
  parameters: {N: 3, w: [0.5, 1.5, 2.5]}
  agents:
    - for: {i: 1..N}
      name: "p{i}"
      variables: {"x{i}": {lower: 0}}
      cost: |
        (x{i} - w[i])**2
          + 0.1*sum(x{k} for k in 1..N)*x{i}
          + z{i % N + 1}*x{i}
"""


def test_a_name_in_a_literal_block_after_substitutions_that_change_lengths() -> None:
    # before the name: an entry w[i] written in as 0.5 and a sum written out; the name itself: a template of 12
    # characters that makes 'z2'
    assert _problems(LITERAL) == [
        "cfg.yaml:12:13 (in 3 copies, for i = 1..3): game.agents.0.cost: unknown name 'z2' (known here: N, pi, x1, x2, "
        "x3)\n"
        "  12 |           + z{i % N + 1}*x{i}\n"
        "     |             ^^^^^^^^^^^^"]


def test_a_name_in_a_sum_is_shown_in_the_sums_body() -> None:
    assert _problems(LITERAL.replace("sum(x{k}", "sum(y{k}").replace("z{i % N + 1}", "x{i % N + 1}")) == [
        "cfg.yaml:11:21 (in 3 copies, for i = 1..3): game.agents.0.cost: unknown name 'y1' (known here: N, pi, x1, x2, "
        "x3)\n"
        "  11 |           + 0.1*sum(y{k} for k in 1..N)*x{i}\n"
        "     |                     ^^^^"]


def test_a_one_line_template_is_quoted_as_written_at_the_templates_column() -> None:
    text = (CONFIGS / "fk_a01.yaml").read_text().replace('cost: "-x{i}/S*(1 - S/B)"',
                                                         'cost: "-x{i}/S*(1 - S/B) + y{i}"')
    assert _problems(text) == [
        "cfg.yaml:18:34 (in 9 copies, for i = 2..10): game.agents.1.cost: unknown name 'y2' (known here: B, N, pi, x1, "
        "x10, x2, x3, x4, x5, x6, x7, x8, x9) at column 21 of expression '-x{i}/S*(1 - S/B) + y{i}'"]


def test_a_block_scalar_without_templates_is_shown_at_its_character() -> None:
    text = HARKER.replace('cost: "x1**2 + 8/3*x1*x2 - 34*x1"', "cost: >-\n        x1**2\n          + 8/3*x1*x3\n"
                                                               "          - 34*x1")
    assert _problems(text) == ["cfg.yaml:12:20: game.agents.0.cost: unknown name 'x3' (known here: pi, x1, x2)\n"
                               "  12 |           + 8/3*x1*x3\n"
                               "     |                    ^^"]


def test_a_syntax_error_in_a_template_block_has_a_caret() -> None:
    problems = _problems(RING.replace("+ 0.05*(ux{i}**2 + uy{i}**2)", "+ 0.05*(ux{i}**2 * * uy{i}**2)"))
    assert problems == ["cfg.yaml:36:30: unexpected '*'\n"
                        "  36 |           + 0.05*(ux{i}**2 * * uy{i}**2)\n"
                        "     |                              ^"]


def test_an_excerpt_of_a_long_line_is_a_window_around_the_column() -> None:
    line = "x" * 150 + "y" + "x" * 150
    shown, caret = excerpt(line, 7, 151).split("\n")
    assert shown.startswith("   7 | ...") and shown.endswith("...")
    assert shown[caret.index("^")] == "y"


def test_a_config_given_as_data_has_one_message_per_template_too() -> None:
    import yaml

    data = yaml.safe_load(RING.replace("+ 0.05*(ux{i}**2", "+ 0.05*(uxx{i}**2"))
    with pytest.raises(ConfigError) as err:
        load_config(data)
    [problem] = err.value.problems
    assert problem.startswith("config dict, at game.agents.0.stage_cost (in 4 copies, for i = 1..4): "
                              "game.agents.0.stage_cost: unknown name 'uxx1'; did you mean 'ux1'?"), problem
