"""The integer expressions of the config language (gnerun/language/integers.py, SPEC §3c): ``%`` and ``//`` with
Python's signs, ``min``/``max`` in ranges, exact division; newlines as whitespace; bounds, start values and dt written
as expressions of parameters; ``dt`` as a name of a game with an ode. Each against an independent reference (Python's
integers, the same game written out by hand), and each refusal as the command line reports it: exit 2, one line,
file:line:column."""

from __future__ import annotations

import itertools
import re

import numpy as np
import pytest

from gnerun.game.compile import compile_game
from gnerun.language.config import load_config
from gnerun.language.expr import parse_expression
from gnerun.language.integers import IntegerError, integer_value

from .conftest import CONFIGS, run_cli
from .test_expand import _same_functions

# the arithmetic, against Python's integers ------------------------------------------------------------------------


@pytest.mark.parametrize("op", ["%", "//", "+", "-", "*"])
def test_integer_operators_are_pythons_on_every_sign(op: str) -> None:
    tree = parse_expression(f"a {op} b").tree
    pairs = [(a, b) for a, b in itertools.product(range(-9, 10), range(-4, 5)) if b or op not in "%//"]
    for a, b in pairs:
        assert integer_value(tree, {"a": a, "b": b}) == eval(f"{a} {op} {b}"), (a, op, b)  # noqa: S307 - the reference
    # one evaluation for every copy of a family at once gives the same values
    a, b = (np.array(v, dtype=float) for v in zip(*pairs, strict=True))
    np.testing.assert_array_equal(integer_value(tree, {"a": a, "b": b}), [eval(f"{x} {op} {y}") for x, y in pairs])  # noqa: S307


@pytest.mark.parametrize(("text", "env", "expected"), [
    ("i % N + 1", {"i": 4, "N": 4}, 1), ("(i - 2) % N + 1", {"i": 1, "N": 4}, 4), ("N/2", {"N": 4}, 2),
    ("min(i + 2, N)", {"i": 3, "N": 4}, 4), ("max(i - 1, 1)", {"i": 1}, 1), ("-i // 2", {"i": 3}, -2),
    ("2**10 % 1000", {}, 24), ("(-1)**(-3)", {}, -1), ("sqrt(N)", {"N": 9}, 3), ("abs(i - N)", {"i": 1, "N": 4}, 3),
])
def test_integer_expressions(text: str, env: dict, expected: int) -> None:
    assert integer_value(parse_expression(text).tree, env) == expected


@pytest.mark.parametrize(("text", "env", "phrase", "column"), [
    ("i - N*(i/N) + 1", {"i": 1, "N": 4}, "i/N is 1/4 = 0.25, not an integer", 9),
    ("N/3", {"N": 4}, "write // for floor division and % for the remainder", 2),
    ("i % (N - 4)", {"i": 1, "N": 4}, "a division by zero", 3),
    ("0.5*N", {"N": 4}, "the number 0.5 is not an integer", 1),
    ("2**(-1)", {}, "not an integer", 2),
    ("2**60", {}, "out of range", 2),
    ("sqrt(N)", {"N": 5}, "sqrt(N) is 2.23606797749979, not an integer", 1),
])
def test_a_value_that_is_not_an_integer_is_refused_at_its_node(text: str, env: dict, phrase: str,
                                                                column: int) -> None:
    with pytest.raises(IntegerError) as err:
        integer_value(parse_expression(text).tree, env)
    assert phrase in err.value.message and err.value.column == column, (err.value.message, err.value.column)


# a ring written with % is the ring written out by hand ----------------------------------------------------------

RING = """\
name: ring
game:
  kind: static
  parameters: {N: 5, umax: 2.5, w: [[0, 1, 0, 0, 2], [0, 0, 1, 0, 0], [0, 0, 0, 1, 0], [0, 3, 0, 0, 1], [1, 0, 0, 0, 0]
  ]}
  agents:
    - for: {i: 1..N}
      name: "p{i}"
      variables: {"x{i}": {lower: -umax, upper: "2*umax", start: "0.1*w[i][i % N + 1]"}}
      cost: >-
        (x{i} - x{i % N + 1})**2
          + (1 + w[i][(i % N) + 1])*x{i}**2
          + (i // 2)*x{i} - x{(i - 2) % N + 1}*x{i}
  shared_constraints:
    - for: {i: 1..N, j: "i+1..min(i+2, N)"}
      expr: "x{i} + x{j} <= 3"
"""


def _ring_by_hand(n: int = 5) -> str:
    """The same ring, every index written out by Python's arithmetic."""
    w = [[0, 1, 0, 0, 2], [0, 0, 1, 0, 0], [0, 0, 0, 1, 0], [0, 3, 0, 0, 1], [1, 0, 0, 0, 0]]
    agents = "".join(
        f"    - name: p{i}\n"
        f"      variables: {{x{i}: {{lower: -2.5, upper: 5.0, start: {0.1 * w[i - 1][i % n]}}}}}\n"
        f"      cost: \"(x{i} - x{i % n + 1})**2 + {1 + w[i - 1][i % n]}*x{i}**2 + {i // 2}*x{i}"
        f" - x{(i - 2) % n + 1}*x{i}\"\n" for i in range(1, n + 1))
    pairs = "".join(f"    - \"x{i} + x{j} <= 3\"\n" for i in range(1, n + 1) for j in range(i + 1, min(i + 2, n) + 1))
    return f"name: ring\ngame:\n  kind: static\n  agents:\n{agents}  shared_constraints:\n{pairs}"


def test_a_ring_written_with_modulo_is_the_ring_written_out() -> None:
    template, hand = load_config(text=RING), load_config(text=_ring_by_hand())
    assert [c for c in template.game.shared_constraints] == [c for c in hand.game.shared_constraints]
    assert template.game.agents[0].variables == hand.game.agents[0].variables
    _same_functions(compile_game(template), compile_game(hand), np.random.default_rng(3))
    # the previous neighbour of agent 1 is agent N, the next of agent N is agent 1
    assert "x5*x1" in template.game.agents[0].cost and "(x5 - x1)**2" in template.game.agents[4].cost


def test_a_multi_line_expression_is_the_one_line_expression() -> None:
    one_line = RING.replace(">-\n        (x{i} - x{i % N + 1})**2\n          + ", '"(x{i} - x{i % N + 1})**2 + ')
    one_line = one_line.replace(
        "\n          + (i // 2)*x{i} - x{(i - 2) % N + 1}*x{i}\n", ' + (i // 2)*x{i} - x{(i - 2) % N + 1}*x{i}"\n')
    assert one_line != RING and ">-" not in one_line
    assert load_config(text=one_line).game == load_config(text=RING).game
    # tabs, carriage returns and newlines are whitespace in a plain expression too
    text = RING.replace('expr: "x{i} + x{j} <= 3"', 'expr: "x{i}\\t+\\r\\nx{j}\\n<= 3"')
    assert load_config(text=text).game.shared_constraints == load_config(text=RING).game.shared_constraints


@pytest.mark.parametrize("text", ["(px1 - 1)**2 + 0.1*u1**2", "-x**2 // 3 % 2 + max(a, b, 2)", "a <= b + 1"])
def test_newlines_tabs_and_carriage_returns_are_whitespace_between_tokens(text: str) -> None:
    from gnerun.language.expr import parse_constraint, unparse

    spread = text.replace(" ", "\n\t ").replace("(", "(\r\n  ").replace(",", "\n,")
    assert spread != text
    if "<=" in text:
        a, b = parse_constraint(text), parse_constraint(spread)
        assert (unparse(a.lhs), unparse(a.rhs)) == (unparse(b.lhs), unparse(b.rhs))
    else:
        assert unparse(parse_expression(spread).tree) == unparse(parse_expression(text).tree)


# bounds, start values and dt written as expressions -----------------------------------------------------------------


def test_bounds_and_start_values_are_numbers_in_the_resolved_config() -> None:
    cfg = load_config(text=RING)
    variables = cfg.game.agents[3].variables["x4"]
    assert (variables.lower, variables.upper, variables.start) == (-2.5, 5.0, pytest.approx(0.1))
    assert "lower: -2.5" in cfg.resolved_yaml() and "umax" not in cfg.resolved_yaml().split("agents:")[1]
    # a config without a template of its own is expanded for them
    text = (CONFIGS / "harker.yaml").read_text().replace("game:\n", "game:\n  parameters: {top: 10}\n").replace(
        "upper: 10", "upper: top")
    assert load_config(text=text).game.agents == load_config(CONFIGS / "harker.yaml").game.agents


MCP = (CONFIGS / "mcp_demo.yaml").read_text()


def test_dt_is_a_name_of_a_game_with_an_ode() -> None:
    """dt in the costs is dynamics.dt, itself an expression of a parameter; declaring the parameter dt (the shipped
    configs' way) gives the same game."""
    with_name = MCP.replace('stage_cost: "', 'stage_cost: "dt*').replace("    dt: 0.1\n", "    dt: h/2\n").replace(
        "parameters: {", "parameters: {h: 0.2, ")
    by_hand = MCP.replace('stage_cost: "', 'stage_cost: "0.1*')
    declared = MCP.replace('stage_cost: "', 'stage_cost: "dt*').replace("parameters: {", "parameters: {dt: 0.1, ")
    a, b, c = (load_config(text=t) for t in (with_name, by_hand, declared))
    assert a.game.dynamics.dt == 0.1 and "dynamics:\n    ode:" in a.resolved_yaml()
    ga, gb, gc = (compile_game(x) for x in (a, b, c))
    _same_functions(ga, gb, np.random.default_rng(0), tol=1e-12)
    _same_functions(gc, gb, np.random.default_rng(1), tol=1e-12)


# refusals on the command line ---------------------------------------------------------------------------------------

DYNAMIC = """\
game:
  kind: dynamic
  horizon: 3
  parameters: {umax: 1}
  states: [x1]
  dynamics: {ode: {x1: "u1"}, dt: 0.1}
  x0: [1]
  agents:
    - name: a
      inputs: {u1: {lower: -umax}}
      stage_cost: "x1**2 + u1**2"
"""

CASES = [  # name, config, the text the error points at (line, column), phrase
    ("an inexact division in an index", RING.replace("x{i % N + 1})**2", "x{i - N*(i/N) + 1})**2"),
     (11, 27), "i/N is 1/5 = 0.2, not an integer; '/' divides exactly in an integer expression: write // for floor "
               "division and % for the remainder"),
    ("an inexact division in a range", RING.replace("min(i+2, N)", "min(i+2, N/2)"), (15, 41),
     "N/2 is 5/2 = 2.5, not an integer"),
    ("% of a decision variable", RING.replace("(i // 2)*x{i}", "(x{i} % 2)*x{i}"), (13, 19),
     "'%' is integer arithmetic"),
    ("// of a variable in a plain config", (CONFIGS / "harker.yaml").read_text().replace('"x1**2 +', '"x1 // 2 +'),
     None, "'//' is integer arithmetic, written out when the config is loaded: its operands are integers (indices, "
           "integer parameters, T), but 'x1 // 2' uses 'x1'"),
    ("% by zero in a key", RING.replace('"x{i}": {lower', '"x{i % (N - 5)}": {lower'), (9, 24), "a division by zero"),
    ("a bound naming a variable", RING.replace("lower: -umax", "lower: -x1"), (9, 36),
     "'x1' in '-x1' is not a number known when the config is loaded"),
    ("a bound naming a state", DYNAMIC.replace("lower: -umax", "lower: -x1"), (10, 29),
     "'x1' in '-x1' is not a number known when the config is loaded"),
    ("a bound that is not finite", RING.replace('upper: "2*umax"', 'upper: "umax/0"'), None,
     "'umax/0' is inf, not a finite number"),
    ("a dt naming an input", DYNAMIC.replace("dt: 0.1", "dt: 2*u1"), (6, 37),
     "'u1' in '2*u1' is not a number known when the config is loaded: dynamics.dt"),
    ("a dt that is not positive", DYNAMIC.replace("dt: 0.1", "dt: -umax"), (6, 35), "greater than 0"),
    ("a parameter dt unlike dynamics.dt", DYNAMIC.replace("{umax: 1}", "{umax: 1, dt: 0.2}"), (6, 35),
     "is 0.1, but the parameter dt is 0.2 ("),
    ("a state named dt", DYNAMIC.replace("[x1]", "[x1, dt]").replace('{x1: "u1"}', '{x1: "u1", dt: "0"}').replace(
        "x0: [1]", "x0: [1, 0]"), None, "state 'dt' is the name of the sampling time"),
    ("a definition named dt", DYNAMIC.replace("  states:", '  definitions: {dt: "2"}\n  states:'), None,
     "definition 'dt' has the name of the sampling time dt"),
    ("a line of a block scalar", RING.replace("+ (1 + w[i]", "+ (1 + q[i]"), (12, 18),
     "'q' is indexed but is not a vector or matrix parameter"),
]


@pytest.mark.parametrize(("name", "text", "at", "phrase"), CASES, ids=[c[0] for c in CASES])
def test_each_refusal_is_one_located_line_with_exit_2(name: str, text: str, at: tuple | None, phrase: str,
                                                      tmp_path) -> None:
    config = tmp_path / "case.yaml"
    config.write_text(text)
    proc = run_cli("validate", str(config), cwd=tmp_path)
    assert proc.returncode == 2, (name, proc.stdout, proc.stderr)
    lines = proc.stderr.rstrip("\n").split("\n")
    assert phrase in lines[0], lines
    m = re.match(rf"error: {re.escape(str(config))}:(\d+):(\d+)", lines[0])
    assert m is not None, lines
    if at is not None:
        assert (int(m[1]), int(m[2])) == at, lines
        assert text.splitlines()[at[0] - 1][at[1] - 1:].strip(), "the column is on the line's text"
    if len(lines) > 1:  # a string written over several lines: its line, and a caret under the character
        source = text.splitlines()[int(m[1]) - 1]
        assert len(lines) == 3 and lines[1] == f"{m[1]:>4} | {source}", lines
        assert lines[2].startswith(f"     | {' ' * (int(m[2]) - 1)}^"), lines
    assert "Traceback" not in proc.stderr
