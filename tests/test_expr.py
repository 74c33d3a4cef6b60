"""The expression language: values against Python arithmetic, CasADi derivatives, errors, hostile input."""

from __future__ import annotations

import math
import uuid
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from gnerun.language.expr import (
    MAX_DEPTH,
    MAX_LENGTH,
    ExpressionError,
    casadi_functions,
    check_names,
    evaluate,
    parse_constraint,
    parse_expression,
)

# (expression, the same written as a Python function by hand)
CASES = [
    ("x + y * z", lambda x, y, z: x + y * z),
    ("(x + y) * z", lambda x, y, z: (x + y) * z),
    ("-x**2", lambda x, y, z: -(x**2)),
    ("2**3**2", lambda x, y, z: 2 ** (3**2)),
    ("x^2 + y^3", lambda x, y, z: x**2 + y**3),
    ("2**-1 * x", lambda x, y, z: 0.5 * x),
    ("- - x + +y", lambda x, y, z: x + y),
    ("x - y - z", lambda x, y, z: (x - y) - z),
    ("x / y / z", lambda x, y, z: (x / y) / z),
    ("x * y / z * x", lambda x, y, z: ((x * y) / z) * x),
    ("1e-3*x + .5*y + 2.*z + 1.5E+2", lambda x, y, z: 1e-3 * x + 0.5 * y + 2.0 * z + 150.0),
    ("sqrt(abs(x)) + exp(y/5) - log(abs(z) + 1)", lambda x, y, z: math.sqrt(abs(x)) + math.exp(y / 5)
     - math.log(abs(z) + 1)),
    ("sin(x)*cos(y) - tan(z/4) + tanh(x*y)", lambda x, y, z: math.sin(x) * math.cos(y) - math.tan(z / 4)
     + math.tanh(x * y)),
    ("min(x, y) + max(x, y, z)", lambda x, y, z: min(x, y) + max(x, y, z)),
    ("min(x, y, z)**2 - max(x, -y)", lambda x, y, z: min(x, y, z) ** 2 - max(x, -y)),
    ("abs(x)^0.5 * -y", lambda x, y, z: abs(x) ** 0.5 * -y),
    ("log2(abs(x)) + log10(abs(y) + 1) - atan(z)", lambda x, y, z: math.log2(abs(x)) + math.log10(abs(y) + 1)
     - math.atan(z)),
    ("asin(x/4)*acos(y/4) + sinh(z/2) - cosh(x/3)", lambda x, y, z: math.asin(x / 4) * math.acos(y / 4)
     + math.sinh(z / 2) - math.cosh(x / 3)),
    ("atan2(y, x) + hypot(x, z) + pi*z", lambda x, y, z: math.atan2(y, x) + math.hypot(x, z) + math.pi * z),
]


@pytest.mark.parametrize("text, reference", CASES)
def test_values_equal_python_arithmetic(text, reference) -> None:
    rng = np.random.default_rng(1)
    parsed = parse_expression(text)
    for _ in range(20):
        x, y, z = rng.uniform(0.3, 3.0, 3) * rng.choice([-1, 1], 3)
        got = evaluate(parsed, {"x": x, "y": y, "z": z})
        assert float(got) == pytest.approx(reference(x, y, z), rel=1e-13, abs=1e-13)


@pytest.mark.parametrize("text, reference", CASES)
def test_casadi_values_and_derivatives(text, reference) -> None:
    sx = ca.SX.sym("v", 3)
    expr = evaluate(parse_expression(text), {"x": sx[0], "y": sx[1], "z": sx[2]}, casadi_functions())
    f = ca.Function("f", [sx], [expr, ca.gradient(expr, sx)])
    rng = np.random.default_rng(2)
    for _ in range(5):
        v = rng.uniform(0.3, 3.0, 3) * rng.choice([-1, 1], 3)
        value, grad = f(v)
        assert float(value) == pytest.approx(reference(*v), rel=1e-13, abs=1e-13)
        h = 1e-6
        for i in range(3):
            e = np.zeros(3)
            e[i] = h
            fd = (reference(*(v + e)) - reference(*(v - e))) / (2 * h)
            assert float(grad[i]) == pytest.approx(fd, rel=1e-6, abs=1e-6)


def test_constraints_residual_sign() -> None:
    env = {"x": 2.0, "y": 5.0}
    le = parse_constraint("x + 1 <= y")
    ge = parse_constraint("x + 1 >= y")
    eq = parse_constraint("2*x == y - 1")
    assert le.residual(env) == -2.0  # feasible: g <= 0
    assert ge.residual(env) == 2.0  # infeasible
    assert eq.residual(env) == 0.0 and eq.is_equality and not le.is_equality
    assert le.names == {"x", "y"}


@pytest.mark.parametrize("text, column, fragment", [
    ("x + * y", 5, "unexpected '*'"),
    ("x + (y", 7, "expected ')'"),
    ("foo(x)", 1, "unknown function 'foo'"),
    ("sin(x, y)", 1, "exactly one argument"),
    ("max(x)", 1, "two or more"),
    ("x y", 3, "missing operator"),
    ("3 $ x", 3, "unexpected character '$'"),
    ("x + y)", 6, "unbalanced ')'"),
    ("x < 1", 3, "comparisons are"),
    ("", 1, "empty expression"),
    ("x +", 4, "unexpected end"),
    ("x.y", 2, "attribute access"),
])
def test_errors_carry_the_column(text: str, column: int, fragment: str) -> None:
    with pytest.raises(ExpressionError) as err:
        parse_expression(text)
    assert err.value.column == column
    assert fragment in err.value.message
    assert f"column {column}" in err.value.describe() and repr(text) in err.value.describe()


def test_constraint_grammar_errors() -> None:
    with pytest.raises(ExpressionError, match="chained"):
        parse_constraint("x <= y <= z")
    with pytest.raises(ExpressionError, match="needs a relation"):
        parse_constraint("x + y")
    with pytest.raises(ExpressionError, match="only allowed in a constraint"):
        parse_expression("x <= y")


def test_unknown_names_are_reported_at_their_column() -> None:
    with pytest.raises(ExpressionError) as err:
        check_names(parse_expression("x + 2*yy - zz"), {"x", "zz"})
    assert err.value.column == 7 and "'yy'" in err.value.message and "x, zz" in err.value.message
    with pytest.raises(ExpressionError) as err:
        check_names(parse_constraint("x <= q"), {"x"})
    assert err.value.column == 6


HOSTILE = [
    "__import__('os')",
    '__import__("os").system("touch /tmp/pwned")',
    "x.__class__",
    "().__class__.__bases__",
    "lambda: 1",
    "lambda x: x",
    "[1, 2]",
    "{1: 2}",
    "x if y else z",
    "open('f')",
    "exec('1')",
    "eval('1')",
    "a; b",
    "a\nimport os",
    'f"{x}"',
    "x @ y",
    "not x",
    "x and y",
    "x \\ y",
    "ｘ + 1",
    "x\x00",
    "globals()",
    "x = 1",
    "`ls`",
    "x ** y ** __builtins__",
]


@pytest.mark.parametrize("text", HOSTILE)
def test_hostile_strings_are_rejected(text: str) -> None:
    with pytest.raises(ExpressionError):
        check_names(parse_expression(text), {"x", "y", "z", "a", "b"})


def test_canary_file_is_never_created(tmp_path: Path) -> None:
    target = tmp_path / f"canary-{uuid.uuid4().hex}"
    attempts = [
        f"__import__('pathlib').Path('{target}').touch()",
        f"open('{target}', 'w')",
        f"__import__(\"os\").system(\"touch {target}\")",
    ]
    for text in attempts:
        for parse in (parse_expression, parse_constraint):
            with pytest.raises(ExpressionError):
                parse(text)
    assert not target.exists()


@pytest.mark.parametrize("text", [
    "x+" * (MAX_LENGTH // 2 + 1) + "x",
    "x" * 100_000,
    "(" * 10_000 + "x" + ")" * 10_000,
    "-" * 5_000 + "x",
    "x" + "**x" * 5_000,
    "sin(" * 3_000 + "x" + ")" * 3_000,
])
def test_large_and_deep_inputs_are_refused(text: str) -> None:
    # an ExpressionError, not a RecursionError or MemoryError
    with pytest.raises(ExpressionError):
        parse_expression(text)


def test_nesting_below_the_limit_parses() -> None:
    depth = MAX_DEPTH - 2
    parsed = parse_expression("(" * depth + "x" + ")" * depth)
    assert evaluate(parsed, {"x": 3.0}) == 3.0
    long_sum = " + ".join(["x"] * 2000)  # long but flat: fine
    assert evaluate(parse_expression(long_sum), {"x": 1.0}) == 2000.0


@pytest.mark.parametrize("text, expected", [
    ("1/0", math.inf), ("-1/0", -math.inf), ("0/0", math.nan), ("(-8)**0.5", math.nan), ("10**400", math.inf),
    ("2**-1", 0.5), ("(1/0) - (1/0)", math.nan),
])
def test_constant_arithmetic_is_ieee(text: str, expected: float) -> None:
    """Constant subexpressions follow IEEE arithmetic (as CasADi and numpy): no ZeroDivisionError,
    OverflowError or complex number while a config is compiled; the solver then reports nan/inf."""
    for table in (None, casadi_functions()):
        value = float(evaluate(parse_expression(text), {}, table))
        assert (math.isnan(value) and math.isnan(expected)) or value == expected
    x = ca.SX.sym("x")
    f = ca.Function("f", [x], [ca.SX(evaluate(parse_expression(f"x + ({text})"), {"x": x}, casadi_functions()))])
    got = float(f(1.0))
    assert (math.isnan(got) and math.isnan(expected)) or got == expected + 1


def test_pi_is_a_constant_and_not_a_name_to_declare() -> None:
    from gnerun.errors import ConfigError
    from gnerun.language.config import load_config

    assert evaluate(parse_expression("2*pi"), {}) == 2 * math.pi
    with pytest.raises(ExpressionError, match="exactly two arguments"):
        parse_expression("atan2(x)")
    text = 'game: {kind: static, agents: [{name: p, variables: {pi: {}}, cost: "pi**2"}]}'
    with pytest.raises(ConfigError, match="'pi' is the name of a constant"):
        load_config(text=text)


# --- large repeated subtrees built once (gnerun.language.expr.Shared) ----------------------------------------------


def _aggregate_game(N: int, cost: str) -> str:
    return f"""name: aggregate
game:
  kind: static
  parameters: {{N: {N}}}
  definitions:
    S: "sum(0.5*q{{k}} + 0.1 for k in 1..N)"
  agents:
    - for: {{i: 1..N}}
      name: "p{{i}}"
      variables: {{"q{{i}}": {{lower: 0, upper: 50, start: 1}}}}
      cost: "{cost}"
"""


def test_a_large_subtree_written_into_every_cost_is_built_once(monkeypatch: pytest.MonkeyPatch) -> None:
    from gnerun.game.compile import compile_game
    from gnerun.language.config import load_config
    from gnerun.language.expr import Shared

    cfg = load_config(text=_aggregate_game(40, "q{i}**2 - q{i}*(100 - S)"))
    shared = compile_game(cfg)
    monkeypatch.setattr(Shared, "SMALLEST", 10**9)  # nothing reused: every cost its own copy of S
    copies = compile_game(cfg)
    size = [ca.Function("J", [g._symbolic.a], [g._symbolic.J]).n_instructions() for g in (shared, copies)]
    assert size[0] * 10 < size[1]  # one S for 40 costs, against 40 copies of it
    rng = np.random.default_rng(3)
    for _ in range(3):
        z = np.r_[rng.uniform(0, 50, shared.n), rng.standard_normal(shared.m)]
        np.testing.assert_array_equal(shared.costs(z[: shared.n]), copies.costs(z[: shared.n]))
        for ours, theirs in zip(shared.kkt_parts(z), copies.kkt_parts(z), strict=True):
            np.testing.assert_allclose(ours, theirs, rtol=1e-13, atol=1e-12)


def test_a_shared_subtree_under_a_function_still_records_each_cost_s_domain() -> None:
    # log(S) in every cost: the calls are evaluated per cost (never reused), so each cost records where its log is
    # defined, and a point with S < 0 leaves every cost undefined
    from gnerun.game.compile import compile_game
    from gnerun.language.config import load_config

    game = compile_game(load_config(text=_aggregate_game(40, "q{i}**2 - log(S)")))
    a = np.full(game.n, -1.0)  # S = 40 * (-0.5 + 0.1) < 0
    assert game.agents.outside_domain(a).all()
    assert not game.agents.outside_domain(np.ones(game.n)).any()
