"""Template expressions (gnerun/language/templates.py) and their expansion: every number and definition spliced
into an expression keeps its meaning. The property test draws random templates (indices, negative values included,
entries of vector parameters, definitions, holes {E}, aggregates nested in each other) as trees of its own, writes
them with the parentheses a person would write, evaluates its own tree directly, and compares that value with the
value of the text the expander writes."""

from __future__ import annotations

import functools
import math
import re

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from gnerun.errors import ConfigError
from gnerun.language.expand import Expander
from gnerun.language.expr import Binary, children, evaluate, numpy_functions, parse_expression, unparse
from gnerun.language.templates import parse_template
from gnerun.language.yaml_source import SourceMap

CASES = 3000  # drawn templates per run of the property test

# a template tree of the test's own: (kind, ...) tuples
#   ("num", v >= 0), ("x",), ("index", name), ("hole", text, index, offset, op, k): {(index + offset) op k} with op
#   None, % or //, ("entry", k), ("def", name),
#   ("neg", t), ("bin", op, l, r), ("call", fn, args), ("agg", fn, index, lo, hi, body)
ATOM, POWER, UNARY, PRODUCT, SUM = 5, 4, 3, 2, 1
VECTOR = [1.5, -2.5, 0.0, -0.75]
OPS = {"+": SUM, "-": SUM, "*": PRODUCT, "/": PRODUCT, "**": POWER}


def _prec(t: tuple) -> int:
    if t[0] == "neg":
        return UNARY
    if t[0] == "bin":
        return OPS[t[1]]
    return ATOM


def render(t: tuple) -> str:
    """The text a person writes for ``t``: parentheses only where the grammar needs them (``-x**2`` is -(x**2),
    ``**`` is right-associative), every template construct an atom."""
    kind = t[0]
    if kind == "num":
        return repr(t[1]) if not float(t[1]).is_integer() else str(int(t[1]))
    if kind == "x":
        return "x1"
    if kind in ("index", "def"):
        return t[1]
    if kind == "hole":
        return "{" + t[1] + "}"
    if kind == "entry":
        return f"c[{t[1]}]"
    if kind == "neg":
        inner = render(t[1])
        return "-" + (inner if _prec(t[1]) >= POWER else f"({inner})")
    if kind == "call":
        return f"{t[1]}({', '.join(render(a) for a in t[2])})"
    if kind == "agg":
        _, fn, index, lo, hi, body = t
        return f"{fn}({render(body)} for {index} in {lo}..{hi})"
    _, op, left, right = t
    pl, pr = _prec(left), _prec(right)
    if op == "**":
        lw, rw = pl < ATOM, pr < UNARY
    elif op in "*/":
        lw, rw = pl < PRODUCT, pr < UNARY or pr == PRODUCT
    else:
        lw, rw = False, pr == SUM
    lt, rt = render(left), render(right)
    sep = f" {op} " if op in "+-" else op
    return (f"({lt})" if lw else lt) + sep + (f"({rt})" if rw else rt)


def value(t: tuple, env: dict) -> float:
    """``t`` evaluated directly (IEEE doubles, as numpy computes them)."""
    kind = t[0]
    with np.errstate(all="ignore"):
        if kind == "num":
            return np.float64(t[1])
        if kind == "x":
            return np.float64(env["x1"])
        if kind == "index":
            return np.float64(env[t[1]])
        if kind == "def":
            return env[t[1]]
        if kind == "hole":  # Python's integers: % and // with the sign of the divisor
            v = env[t[2]] + t[3]
            return np.float64(v if t[4] is None else v % t[5] if t[4] == "%" else v // t[5])
        if kind == "entry":
            return np.float64(VECTOR[(t[1] if isinstance(t[1], int) else env[t[1]]) - 1])
        if kind == "neg":
            return -value(t[1], env)
        if kind == "call":
            args = [value(a, env) for a in t[2]]
            if t[1] == "abs":
                return np.abs(args[0])
            out = args[0]
            for a in args[1:]:
                out = (np.maximum if t[1] == "max" else np.minimum)(out, a)
            return out
        if kind == "agg":
            _, fn, index, lo, hi, body = t
            terms = [value(body, {**env, index: k}) for k in range(lo, hi + 1)]
            if not terms:
                return np.float64(0.0 if fn == "sum" else 1.0)
            out = terms[0]
            for term in terms[1:]:
                out = {"sum": np.add, "prod": np.multiply, "max": np.maximum, "min": np.minimum}[fn](out, term)
            return out
        _, op, left, right = t
        a, b = value(left, env), value(right, env)
        # ** as the evaluator computes it (np.power(a, 3) and a ** 3 of a numpy double can differ in the last bit)
        return {"+": np.add, "-": np.subtract, "*": np.multiply, "/": np.divide, "**": lambda p, q: p**q}[op](a, b)


def _hole(h: tuple) -> tuple:
    index, off, op, k = h
    text = index + (f" + {off}" if off > 0 else f" - {-off}" if off else "")
    if op is not None:
        text = f"({text}) {op} {k}" if off else f"{text} {op} {k}"
    return ("hole", text, index, off, op, k)


@functools.cache
def trees(indices: tuple[str, ...], definitions: tuple[str, ...], depth: int) -> st.SearchStrategy:
    """Random template trees using the ``indices`` in scope and the ``definitions``."""
    leaves = [st.tuples(st.just("num"), st.sampled_from([0, 1, 2, 3, 0.5, 2.5, 10])), st.just(("x",)),
              st.tuples(st.just("entry"), st.integers(1, len(VECTOR)))]
    if indices:
        leaves.append(st.tuples(st.just("index"), st.sampled_from(indices)))
        leaves.append(st.tuples(st.sampled_from(indices), st.sampled_from([0, 1, -2]),
                                st.sampled_from([None, None, "%", "//"]), st.sampled_from([2, 3, -2])).map(_hole))
    if definitions:
        leaves.append(st.tuples(st.just("def"), st.sampled_from(definitions)))
    leaf = st.one_of(leaves)
    if depth == 0:
        return leaf
    sub = trees(indices, definitions, depth - 1)
    fresh = next(n for n in ("k", "m", "n", "q", "r") if n not in indices)
    inner = trees((*indices, fresh), definitions, depth - 1)
    return st.one_of(
        leaf,
        st.tuples(st.just("neg"), sub),
        st.tuples(st.just("bin"), st.sampled_from(["+", "-", "*", "/", "**"]), sub, sub),
        st.tuples(st.just("bin"), st.just("**"), sub, st.sampled_from([("num", 2), ("num", 3), ("num", 0.5)])),
        st.tuples(st.just("call"), st.just("abs"), st.tuples(sub)),
        st.tuples(st.just("call"), st.sampled_from(["max", "min"]), st.lists(sub, min_size=2, max_size=3).map(tuple)),
        st.tuples(st.sampled_from(["sum", "prod", "max", "min"]), st.integers(-3, 2), st.integers(0, 3), inner).map(
            lambda a: ("agg", a[0], fresh, a[1], a[1] + max(a[2], a[0] in ("max", "min")) - 1, a[3])),
    )


@st.composite
def templates(draw) -> tuple[tuple, dict, tuple[int, int], float]:
    definitions = {}
    for name in ("D1", "D2"):
        definitions[name] = draw(trees((), tuple(definitions), 2))
    body = draw(trees(("i",), tuple(definitions), 3))
    lo = draw(st.integers(-4, 1))
    hi = lo + draw(st.integers(0, 3))
    x1 = draw(st.sampled_from([-1.75, -0.5, 0.0, 0.3, 2.0]))
    return body, definitions, (lo, hi), x1


def _expand(body: tuple, definitions: dict, lo: int, hi: int) -> list[str]:
    """The costs the expander writes for a family over i = lo..hi with cost ``body``."""
    doc = {"game": {"kind": "static", "parameters": {"c": VECTOR},
                    "definitions": {name: render(t) for name, t in definitions.items()},
                    "agents": [{"for": {"i": f"{lo}..{hi}"}, "cost": render(body)}]}}
    out, _ = Expander(SourceMap("property")).expand(doc)
    return [agent["cost"] for agent in out["game"]["agents"]]


@settings(max_examples=CASES, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(templates())
def test_the_expanded_text_evaluates_to_the_template_evaluated_directly(case) -> None:
    body, definitions, (lo, hi), x1 = case
    env: dict = {"x1": x1}
    for name, t in definitions.items():
        env[name] = value(t, env)
    costs = _expand(body, definitions, lo, hi)
    assert len(costs) == hi - lo + 1
    for i, text in zip(range(lo, hi + 1), costs, strict=True):
        expected = value(body, {**env, "i": i})
        got = evaluate(parse_expression(text), {"x1": x1}, numpy_functions())
        assert (math.isnan(expected) and math.isnan(got)) or got == expected, (render(body), i, text)


@settings(max_examples=CASES // 3, deadline=None)
@given(trees(("i",), (), 4), st.integers(-5, 5))
def test_unparse_writes_a_tree_that_parses_back_to_the_same_value(tree, i) -> None:
    """The expanded tree of a template, written by unparse and read again, is the same tree up to the sign of its
    numbers (a negative number is read back as a unary minus of its magnitude)."""
    expander = Expander(SourceMap("unparse"))
    expander.vectors["c"] = VECTOR
    expanded, _, _, _ = expander._expanded(render(tree), ("game", "x"), _scope(i))
    again = parse_expression(unparse(expanded))
    assert _canonical(again.tree) == _canonical(expanded)
    # a division by zero is left out: -(i) at i = 0 is -0.0 in the tree and the integer 0 read back, whose
    # infinities differ in sign (max(0, x1/-(i)) is 0 or inf); a cost that divides by zero is not finite anyway
    assume(not _divides_by_zero(expanded))
    with np.errstate(all="ignore"):
        a = evaluate(expanded, {"x1": 0.7}, numpy_functions())
        b = evaluate(again, {"x1": 0.7}, numpy_functions())
    assert (math.isnan(a) and math.isnan(b)) or a == b


def _divides_by_zero(node) -> bool:
    """Whether a division in the tree has a denominator that evaluates to zero, or a zero is raised to a negative
    power (a division by zero too: (-0.0)**-3 is -inf, 0**-3 is inf), at x1 = 0.7."""
    stack = [node]
    while stack:
        n = stack.pop()
        if isinstance(n, Binary) and n.op in ("/", "**"):
            with np.errstate(all="ignore"):
                value = lambda e: evaluate(e, {"x1": 0.7}, numpy_functions())  # noqa: E731
                if n.op == "/" and value(n.right) == 0:
                    return True
                if n.op == "**" and value(n.left) == 0 and value(n.right) < 0:
                    return True
        stack += children(n)
    return False


def _canonical(node) -> tuple:
    """A tree as nested tuples, without columns, a negative number as a unary minus of its magnitude."""
    from gnerun.language.expr import Binary, Call, Name, Num, Unary

    if isinstance(node, Num):
        v = float(node.value)
        return ("-", ("num", -v)) if v < 0 or math.copysign(1.0, v) < 0 else ("num", v)
    if isinstance(node, Name):
        return ("name", node.id)
    if isinstance(node, Unary):
        return (node.op, _canonical(node.operand))
    if isinstance(node, Binary):
        return (node.op, _canonical(node.left), _canonical(node.right))
    assert isinstance(node, Call)
    return (node.function, *(_canonical(a) for a in node.args))


def _scope(i: int):
    from gnerun.language.families import Scope

    return Scope({}, {"i": i})


# the reported cases, written out ---------------------------------------------------------------------------

def _cost(cost: str, *, definitions: str = "", family: str = "", parameters: str = "{}") -> list[str]:
    from gnerun.language.config import load_config

    item = f"    - for: {{{family}}}\n      name: \"p{{i+10}}\"\n      variables: {{\"x{{i+10}}\": {{}}}}\n" if family \
        else "    - name: p\n      variables: {x1: {start: 1}}\n"
    text = (f"game:\n  kind: static\n  parameters: {parameters}\n" + (f"  definitions: {definitions}\n"
            if definitions else "") + "  agents:\n" + item + f"      cost: \"{cost}\"\n")
    return [a.cost for a in load_config(text=text).game.agents]


def _at(text: str, **env: float) -> float:
    return float(evaluate(parse_expression(text), env, numpy_functions()))


def test_a_negative_index_next_to_a_power_keeps_its_sign() -> None:
    (cost,) = _cost("(x1 - sum(k**2 for k in -3..3))**2")
    assert _at(cost, x1=28.0) == 0.0  # sum of k^2 for k = -3..3 is 28 (the old text made it 0)
    costs = _cost("(x{i+10} - i**2)**2", family="i: -2..2")
    for i, c in zip(range(-2, 3), costs, strict=True):
        assert _at(c, **{f"x{i + 10}": float(i * i)}) == 0.0, c
    costs = _cost("(x{i+10} - {i}**2 + {-i}**2)**2", family="i: -2..2")
    assert _at(costs[0], x8=0.0) == 0.0  # {i}**2 with i = -2 is 4


def test_a_definition_that_is_a_power_stays_one_operand() -> None:
    (cost,) = _cost("(D**0.5 - 3)**2", definitions='{D: "x1**2"}')
    assert _at(cost, x1=3.0) == 0.0 and _at(cost, x1=2.175) != 0.0
    (cost,) = _cost("(max(x1**2 for k in 1..1)**0.5 - 3)**2")
    assert _at(cost, x1=3.0) == 0.0
    (cost,) = _cost("D**2", definitions='{D: "-x1"}')
    assert _at(cost, x1=2.0) == 4.0
    (cost,) = _cost("2**D", definitions='{D: "-x1"}')
    assert _at(cost, x1=1.0) == 0.5


def test_a_negative_entry_or_number_written_in_keeps_its_meaning() -> None:
    (cost,) = _cost("c[2]**2 + x1 - c[2] - c[1]**c[2]", parameters="{c: [2, -3]}")
    assert _at(cost, x1=0.0) == 9 + 3 - 2.0**-3


def test_the_harker_game_with_a_definition_named_like_a_variable_is_refused() -> None:
    from gnerun.language.config import load_config

    text = (ROOT / "configs" / "harker.yaml").read_text().replace("game:\n", 'game:\n  definitions: {x2: "0"}\n')
    with pytest.raises(ConfigError, match=r":\d+:\d+: definition 'x2' has the name of a variable of 'p2'"):
        load_config(text=text)


@pytest.mark.parametrize(("name", "what"), [("pi", "a constant"), ("tau", "the stage index"), ("T", "the horizon"),
                                            ("x1", "a state"), ("u1", "an input of 'a'"), ("c", "a parameter"),
                                            ("sqrt", "a function"), ("sum", "a function")])
def test_a_definition_may_not_shadow_a_name(name: str, what: str) -> None:
    from gnerun.language.config import load_config

    text = f"""
game:
  kind: dynamic
  horizon: 3
  parameters: {{c: 1}}
  definitions: {{{name}: "2*c"}}
  states: [x1]
  dynamics: {{x1: "x1 + u1"}}
  x0: [0]
  agents:
    - {{name: a, inputs: [u1], stage_cost: "(x1 - 1)**2 + u1**2"}}
"""
    with pytest.raises(ConfigError) as err:
        load_config(text=text)
    assert len(err.value.problems) == 1
    assert re.search(rf"<string>:6:\d+: definition '{name}' has the name of {what}", err.value.problems[0]), \
        err.value.problems


@pytest.mark.parametrize(("cost", "expected"), [
    ("x{i}**2", r"'x\{i\}' makes 'x-2', which is not a name"),
    ("c [1]*x1", r"a space before '\['"),
    ("c[1] [1]*x1", r"a space before '\['"),
    ("{i}x1", r"neither a number"),
    ("{i}{i}", r"neither a number"),
    ("sum(x1 for k in 1..3 + 1)", None),  # a range's end is an integer expression: accepted
    ("sum(x1 for k in 1...3)", r"not an integer"),
    ("sqrt(x1 for k in 1..2)", r"'for' belongs in sum, prod, max, min"),
    ("sum(x1)", r"sum\(\) is written sum\(E for k in a..b\)"),
])
def test_template_mistakes_are_located(cost: str, expected: str | None) -> None:
    from gnerun.language.config import load_config

    text = f"""
game:
  kind: static
  parameters: {{c: [[1, 2], [3, 4]]}}
  agents:
    - for: {{i: -2..-2}}
      name: p
      variables: {{x1: {{}}}}
      cost: "{cost}"
"""
    if expected is None:
        load_config(text=text)
        return
    with pytest.raises(ConfigError) as err:
        load_config(text=text)
    assert len(err.value.problems) == 1
    assert re.search(r"<string>:9:\d+", err.value.problems[0]) and re.search(expected, err.value.problems[0]), \
        err.value.problems


def test_deep_nesting_is_a_located_message_not_a_recursion_error() -> None:
    from gnerun.language.config import load_config

    for cost in ("max(" * 1200 + "x1, 1" + ", 1)" * 1200, "sum(" * 400 + "x1" + " for k in 1..1)" * 400,
                 "(" * 5000 + "x1" + ")" * 5000, "-" * 3000 + "x1", "x1" + "**x1" * 3000):
        text = f'game:\n  kind: static\n  agents:\n    - {{name: p, variables: [x1], cost: "{cost}"}}\n'
        with pytest.raises(ConfigError) as err:
            load_config(text=text)
        assert re.search(r"<string>:4:\d+: .*nested deeper than 100 levels", err.value.problems[0]), \
            err.value.problems[0][:300]


def test_parse_template_reads_constraints_and_keeps_plain_text() -> None:
    t = parse_template("x{i} - c[2] <= sum(y{k} for k in 1..N)")
    assert t.relation == "<=" and t.rhs is not None
    with pytest.raises(Exception, match="chained comparisons"):
        parse_template("a <= b <= c")


ROOT = __import__("pathlib").Path(__file__).resolve().parent.parent


# the reported language cases on the command line: exit code 0 or 2, one line ------------------------------

HARKER = (ROOT / "configs" / "harker.yaml").read_text()
FAMILY = """\
name: negative-family
game:
  kind: static
  agents:
    - for: {i: -2..2}
      name: "p{i + 3}"
      variables: {"x{i + 3}": {start: 0}}
      cost: "(x{i + 3} - i**2)**2"
"""
SHARED = """\
game:
  kind: static
  agents:
    - {name: car1, variables: {x1: {}}, cost: "x1**2"}
    - {name: car2, variables: {x2: {}}, cost: "x2**2"}
  shared_constraints:
    - {expr: "x1 + x2 <= 1", agents: AGENTS}
"""
LANGUAGE_CASES = [
    ("a definition named like a variable", HARKER.replace("game:\n", 'game:\n  definitions: {x2: "0"}\n'),
     "definition 'x2' has the name of a variable of 'p2'"),
    ("a definition named pi", HARKER.replace("game:\n", 'game:\n  definitions: {pi: "3"}\n'),
     "definition 'pi' has the name of a constant"),
    ("a definition named tau", (ROOT / "configs" / "paper_study1.yaml").read_text().replace(
        "game:\n", 'game:\n  definitions: {tau: "3"}\n'), "definition 'tau' has the name of the stage index"),
    ("a definition named T", (ROOT / "configs" / "paper_study1.yaml").read_text().replace(
        "game:\n", 'game:\n  definitions: {T: "3"}\n'), "definition 'T' has the name of the horizon"),
    ("a space before an index", HARKER.replace("game:\n", "game:\n  parameters: {c: [1, 2]}\n").replace(
        '"x1**2 +', '"c [1]*x1**2 +'), "a space before '['"),
    ("a negative index in a name", FAMILY.replace('"x{i + 3}": {start: 0}', '"x{i}": {start: 0}').replace(
        "(x{i + 3} - i**2)**2", "(x{i} - i**2)**2"), "which is not a name"),
    ("shared agents []", SHARED.replace("AGENTS", "[]"), "agents: needs at least 1 entry (it has 0)"),
    ('shared agents "car1"', SHARED.replace("AGENTS", '"car1"'), "agents: Input should be a valid list"),
    ("an item with nothing but for", HARKER.replace("  shared_constraints:", "    - for: {i: 1..3}\n"
                                                    "  shared_constraints:"), "this item has nothing but for:"),
    ("a name a template repeats", FAMILY.replace('name: "p{i + 3}"', "name: p"),
     "6:13 (in 4 copies, for i = -1..2): game.agents.1.name: agent 'p' is declared twice"),
    ("max() nested 1,200 deep", HARKER.replace('"x1**2 +', '"' + "max(" * 1200 + "x1" + ", 1)" * 1200 + " +"),
     "nested deeper than 100 levels"),
]


@pytest.mark.parametrize(("name", "text", "phrase"), LANGUAGE_CASES, ids=[c[0] for c in LANGUAGE_CASES])
def test_each_reported_language_case_is_one_line_with_exit_2(name: str, text: str, phrase: str, tmp_path) -> None:
    from .conftest import run_cli

    config = tmp_path / "case.yaml"
    config.write_text(text)
    proc = run_cli("validate", str(config))
    assert proc.returncode == 2, (name, proc.stdout, proc.stderr)
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {config}:") and phrase in lines[0], lines
    assert "Traceback" not in proc.stderr and "function-" not in proc.stderr


def test_the_negative_family_solves_the_game_it_says(tmp_path) -> None:
    """A family i = -2..2 with cost (x - i**2)**2: the agents' solution is i**2 = 4, 1, 0, 1, 4 (the old splicing
    made it -4, -1, 0, 1, 4); and sum(k**2 for k in -3..3) is 28 as validate --expand writes it."""
    import json

    from .conftest import run_cli

    config = tmp_path / "family.yaml"
    config.write_text(FAMILY)
    proc = run_cli("solve", str(config), "--out", str(tmp_path / "run"), "-q")
    assert proc.returncode == 0, proc.stderr
    solution = json.loads((tmp_path / "run" / "summary.json").read_text())["solution"]
    assert [round(v[f"x{i + 3}"], 9) for v, i in zip(solution.values(), range(-2, 3), strict=True)] == [4, 1, 0, 1, 4]
    config.write_text(FAMILY.replace("i**2)**2", "i**2 - sum(k**2 for k in -3..3) + 28)**2"))
    proc = run_cli("validate", "--expand", str(config))
    assert proc.returncode == 0, proc.stderr
    assert "(-3)**2 + (-2)**2 + (-1)**2 + 0**2 + 1**2 + 2**2 + 3**2" in proc.stdout
