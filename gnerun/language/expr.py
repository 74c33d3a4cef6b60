"""The expression language of gnerun configs.

Expressions are parsed into a small syntax tree by a hand-written recursive-descent parser and
interpreted over our own node types: nothing is ever evaluated as Python (no eval, exec, compile,
or sympify of raw strings). The grammar:

    constraint := expr ("<=" | ">=" | "==") expr
    expr       := term (("+" | "-") term)*
    term       := unary (("*" | "/" | "//" | "%") unary)*
    unary      := ("-" | "+") unary | power
    power      := atom (("**" | "^") unary)?          # right-associative, binds tighter than unary minus
    atom       := NUMBER | NAME | NAME "(" expr ("," expr)* ")" | "(" expr ")"

so that ``-x**2 == -(x**2)`` and ``2**3**2 == 2**9`` as in Python and in mathematics. Spaces, tabs and newlines
between tokens are whitespace (a YAML block scalar may spread an expression over several lines).
``//`` (floor division) and ``%`` (its remainder, with the sign of the divisor, as in Python) are integer arithmetic:
they belong to the integer expressions of indices, ranges and templates (:mod:`gnerun.language.integers`), and in an
expression of decision variables they are written out when the config is loaded, where both operands are integers
known then (``x{i % N + 1}``, ``w[i][i % N + 1]``, ``(i % 2)*x1``); anywhere else they are refused.
Functions: sqrt exp log log2 log10 sin cos tan asin acos atan sinh cosh tanh abs (one argument), atan2 hypot
(two), min max (two or more); the constant pi.

Every error is an :class:`ExpressionError` carrying the expression and a 1-based column.
Inputs longer than :data:`MAX_LENGTH` characters or nested deeper than :data:`MAX_DEPTH` are refused
before they can exhaust the interpreter's stack.
"""

from __future__ import annotations

import contextlib
import math
import re
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextvars import ContextVar
from dataclasses import dataclass
from typing import Any, NamedTuple

from ..errors import Names, did_you_mean

MAX_LENGTH = 20_000
MAX_DEPTH = 100

UNARY_FUNCTIONS = ("sqrt", "exp", "log", "log2", "log10", "sin", "cos", "tan", "asin", "acos", "atan", "sinh",
                   "cosh", "tanh", "abs")
BINARY_FUNCTIONS = ("atan2", "hypot")
VARIADIC_FUNCTIONS = ("min", "max")
FUNCTIONS = UNARY_FUNCTIONS + BINARY_FUNCTIONS + VARIADIC_FUNCTIONS
CONSTANTS = {"pi": math.pi}  # names every expression knows
RELATIONS = ("<=", ">=", "==")
PRODUCTS = ("*", "/", "//", "%")  # the operators of a term, left-associative
INTEGER_OPERATORS = ("//", "%")  # integer arithmetic only (see the module docstring)


class ExpressionError(ValueError):
    """A malformed expression: ``message`` at 1-based ``column`` of ``expression`` (``whole``: a problem of the whole
    text, its length, which no column of it shows)."""

    def __init__(self, message: str, expression: str, column: int, whole: bool = False):
        self.message = message
        self.expression = expression
        self.column = column
        self.whole = whole
        super().__init__(self.describe())

    def describe(self) -> str:
        shown = self.expression if len(self.expression) <= 120 else self.expression[:117] + "..."
        return f"{self.message} at column {self.column} of expression {shown!r}"


# ---------------------------------------------------------------------------------------------
# Syntax tree
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Num:
    value: float
    column: int


@dataclass(frozen=True)
class Name:
    id: str
    column: int


@dataclass(frozen=True)
class Unary:
    op: str  # "-" or "+"
    operand: Node
    column: int


@dataclass(frozen=True)
class Binary:
    op: str  # + - * / ** // %
    left: Node
    right: Node
    column: int


@dataclass(frozen=True)
class Call:
    function: str
    args: tuple[Node, ...]
    column: int


@dataclass(frozen=True)
class Index:
    """``name[i]`` or ``name[i][j]``: an entry of a runtime parameter (gnerun.language.runtime), looked up when the game
    is compiled; the indices are integer expressions of numbers, integer parameters and the stage index tau."""

    name: str
    indices: tuple[Node, ...]
    column: int


Node = Num | Name | Unary | Binary | Call | Index


@dataclass(frozen=True)
class Expression:
    """A parsed expression and the text it came from."""

    text: str
    tree: Node

    @property
    def names(self) -> set[str]:
        return names_in(self.tree)


@dataclass(frozen=True)
class Constraint:
    """A parsed constraint ``lhs REL rhs``; :meth:`residual` is g with g <= 0 (or g == 0)."""

    text: str
    lhs: Node
    relation: str  # "<=", ">=", "=="
    rhs: Node

    @property
    def names(self) -> set[str]:
        return names_in(self.lhs) | names_in(self.rhs)

    @property
    def is_equality(self) -> bool:
        return self.relation == "=="

    def residual(self, env: Mapping[str, Any], functions: Mapping[str, Callable] | None = None,
                 shared: Shared | None = None) -> Any:
        """g = lhs - rhs for ``<=`` and ``==``, rhs - lhs for ``>=``: feasible iff g <= 0 (or == 0)."""
        lhs = evaluate(self.lhs, env, functions, shared)
        rhs = evaluate(self.rhs, env, functions, shared)
        return rhs - lhs if self.relation == ">=" else lhs - rhs


def children(node: Node) -> tuple[Node, ...]:
    """The operands of a node (none for numbers and names)."""
    if isinstance(node, Unary):
        return (node.operand,)
    if isinstance(node, Binary):
        return (node.left, node.right)
    if isinstance(node, Call):
        return tuple(node.args)
    if isinstance(node, Index):
        return tuple(node.indices)
    return ()


def nodes(node: Node) -> Iterator[Node]:
    """Every node of the tree, parents before their operands (explicit stack: no recursion)."""
    stack = [node]
    while stack:
        n = stack.pop()
        yield n
        stack.extend(reversed(children(n)))


def _names(node: Node) -> list[Name]:
    """Every Name node of the tree (explicit stack: no recursion)."""
    out: list[Name] = []
    stack = [node]
    while stack:
        n = stack.pop()
        if isinstance(n, Name):
            out.append(n)
        else:
            if isinstance(n, Index):  # the table's name is used too
                out.append(Name(n.name, n.column))
            stack.extend(children(n))
    return out


def names_in(node: Node) -> set[str]:
    return {n.id for n in _names(node)}


def first_column_of(node: Node, name: str) -> int | None:
    """Column of the first occurrence of ``name`` in the tree (for error messages)."""
    return min((n.column for n in _names(node) if n.id == name), default=None)


# ---------------------------------------------------------------------------------------------
# Tokenizer
# ---------------------------------------------------------------------------------------------

_TOKEN = re.compile(
    r"""
    (?P<ws>[ \t\r\n]+)
  | (?P<number>(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)
  | (?P<name>[A-Za-z_][A-Za-z0-9_]*)
  | (?P<op>\*\*|<=|>=|==|//|[-+*/^(),%\[\]])
    """,
    re.VERBOSE,
)


class _Token(NamedTuple):
    kind: str  # number | name | op | end
    text: str
    column: int  # 1-based


def _tokenize(text: str) -> list[_Token]:
    tokens: list[_Token] = []
    pos = 0
    for m in _TOKEN.finditer(text):  # one scan; a character no token matches is where two matches do not meet
        if m.start() != pos:
            break
        kind = m.lastgroup or ""
        if kind != "ws":
            tokens.append(_Token(kind, m.group(), pos + 1))
        pos = m.end()
    if pos < len(text):
        ch = text[pos]
        hint = ""
        if ch == ".":
            hint = " (attribute access is not part of the language)"
        elif ch in "'\"":
            hint = " (strings are not part of the language)"
        elif ch in "<>=!":
            hint = " (comparisons are <=, >= and ==, and only in constraints)"
        raise ExpressionError(f"unexpected character {ch!r}{hint}", text, pos + 1)
    tokens.append(_Token("end", "", len(text) + 1))
    return tokens


# ---------------------------------------------------------------------------------------------
# Parser
# ---------------------------------------------------------------------------------------------


class _Parser:
    def __init__(self, text: str):
        self.text = text
        self.tokens = _tokenize(text)
        self.i = 0
        self.depth = 0

    def error(self, message: str, token: _Token | None = None) -> ExpressionError:
        tok = token or self.peek()
        return ExpressionError(message, self.text, tok.column)

    def peek(self) -> _Token:
        return self.tokens[self.i]

    def advance(self) -> _Token:
        tok = self.tokens[self.i]
        self.i += 1
        return tok

    def expect(self, text: str) -> _Token:
        tok = self.peek()
        if tok.kind != "op" or tok.text != text:
            found = "end of expression" if tok.kind == "end" else repr(tok.text)
            raise self.error(f"expected {text!r}, found {found}")
        return self.advance()

    def enter(self) -> None:
        self.depth += 1
        if self.depth > MAX_DEPTH:
            raise self.error(f"expression nested deeper than {MAX_DEPTH} levels")

    def leave(self) -> None:
        self.depth -= 1

    # grammar -------------------------------------------------------------------------------
    def expr(self) -> Node:
        self.enter()
        node = self.term()
        while self.peek().kind == "op" and self.peek().text in "+-":
            tok = self.advance()
            node = Binary(tok.text, node, self.term(), tok.column)
        self.leave()
        return node

    def term(self) -> Node:
        node = self.unary()
        while self.peek().kind == "op" and self.peek().text in PRODUCTS:
            tok = self.advance()
            node = Binary(tok.text, node, self.unary(), tok.column)
        return node

    def unary(self) -> Node:
        tok = self.peek()
        if tok.kind == "op" and tok.text in "+-":
            self.advance()
            self.enter()
            operand = self.unary()
            self.leave()
            return Unary(tok.text, operand, tok.column)
        return self.power()

    def power(self) -> Node:
        base = self.atom()
        tok = self.peek()
        if tok.kind == "op" and tok.text in ("**", "^"):
            self.advance()
            self.enter()
            exponent = self.unary()
            self.leave()
            return Binary("**", base, exponent, tok.column)
        return base

    def atom(self) -> Node:
        tok = self.peek()
        if tok.kind == "number":
            self.advance()
            value = float(tok.text)
            if not math.isfinite(value):
                raise self.error(f"number {tok.text!r} is out of range", tok)
            return Num(value, tok.column)
        if tok.kind == "name":
            self.advance()
            nxt = self.peek()
            if nxt.kind == "op" and nxt.text == "(":
                return self.call(tok)
            if nxt.kind == "op" and nxt.text == "[" and nxt.column == tok.column + len(tok.text):
                return self.index(tok)
            if nxt.kind in ("name", "number"):
                raise self.error(f"unexpected {nxt.text!r} after {tok.text!r} (missing operator?)", nxt)
            return Name(tok.text, tok.column)
        if tok.kind == "op" and tok.text == "(":
            self.advance()
            node = self.expr()
            self.expect(")")
            return node
        if tok.kind == "end":
            raise self.error("unexpected end of expression")
        raise self.error(f"unexpected {tok.text!r}")

    def call(self, name: _Token) -> Node:
        fn = name.text
        if fn not in FUNCTIONS:
            raise self.error(
                f"unknown function {fn!r}{did_you_mean(fn, FUNCTIONS)} (functions: {', '.join(FUNCTIONS)})",
                name,
            )
        self.expect("(")
        args = [self.expr()]
        while self.peek().kind == "op" and self.peek().text == ",":
            self.advance()
            args.append(self.expr())
        self.expect(")")
        if fn in UNARY_FUNCTIONS and len(args) != 1:
            raise self.error(f"{fn}() takes exactly one argument, got {len(args)}", name)
        if fn in BINARY_FUNCTIONS and len(args) != 2:
            raise self.error(f"{fn}() takes exactly two arguments, got {len(args)}", name)
        if fn in VARIADIC_FUNCTIONS and len(args) < 2:
            raise self.error(f"{fn}() takes two or more arguments, got {len(args)}", name)
        return Call(fn, tuple(args), name.column)

    def index(self, name: _Token) -> Node:
        indices = []
        while len(indices) < 2 and self.peek().kind == "op" and self.peek().text == "[":
            self.advance()
            indices.append(self.expr())
            self.expect("]")
        return Index(name.text, tuple(indices), name.column)

    def finish(self) -> None:
        tok = self.peek()
        if tok.kind != "end":
            if tok.kind == "op" and tok.text in RELATIONS:
                raise self.error(f"comparison {tok.text!r} is only allowed in a constraint")
            if tok.kind == "op" and tok.text == ")":
                raise self.error("unbalanced ')'")
            raise self.error(f"unexpected {tok.text!r}")


def _check_text(text: object) -> str:
    if not isinstance(text, str):
        raise ExpressionError(f"expected an expression string, got {type(text).__name__}", str(text), 1)
    if len(text) > MAX_LENGTH:
        raise ExpressionError(f"expression longer than {MAX_LENGTH} characters ({len(text)})", text, 1, whole=True)
    if not text.strip():
        raise ExpressionError("empty expression", text, 1)
    return text


_parsed: ContextVar[dict | None] = ContextVar("gnerun_parsed", default=None)


@contextlib.contextmanager
def parse_cache() -> Iterator[None]:
    """Within the block, an expression or constraint text is parsed once: its tree is kept and given again (loading
    a config checks every expression, then counts its nodes)."""
    token = _parsed.set({})
    try:
        yield
    finally:
        _parsed.reset(token)


def parse_expression(text: str) -> Expression:
    """Parse an arithmetic expression (no comparison)."""
    cache = _parsed.get()
    if cache is not None and (hit := cache.get(("expression", text))) is not None:
        return hit
    text = _check_text(text)
    p = _Parser(text)
    tree = p.expr()
    p.finish()
    parsed = Expression(text, tree)
    if cache is not None:
        cache[("expression", text)] = parsed
    return parsed


def parse_constraint(text: str) -> Constraint:
    """Parse ``lhs <= rhs``, ``lhs >= rhs`` or ``lhs == rhs`` (exactly one relation)."""
    cache = _parsed.get()
    if cache is not None and (hit := cache.get(("constraint", text))) is not None:
        return hit
    text = _check_text(text)
    p = _Parser(text)
    lhs = p.expr()
    tok = p.peek()
    if not (tok.kind == "op" and tok.text in RELATIONS):
        if tok.kind == "end":
            raise p.error("a constraint needs a relation: lhs <= rhs, lhs >= rhs or lhs == rhs")
        raise p.error(f"expected '<=', '>=' or '==', found {tok.text!r}")
    p.advance()
    rhs = p.expr()
    nxt = p.peek()
    if nxt.kind == "op" and nxt.text in RELATIONS:
        raise p.error("chained comparisons are not allowed: write one constraint per relation")
    p.finish()
    parsed = Constraint(text, lhs, tok.text, rhs)
    if cache is not None:
        cache[("constraint", text)] = parsed
    return parsed


# ---------------------------------------------------------------------------------------------
# Interpreter
# ---------------------------------------------------------------------------------------------


def _variadic(fn2: Callable[[Any, Any], Any]) -> Callable[..., Any]:
    def f(*args: Any) -> Any:
        out = args[0]
        for a in args[1:]:
            out = fn2(out, a)
        return out

    return f


def numpy_functions() -> dict[str, Callable]:
    """The function table for floats and numpy arrays."""
    import numpy as np

    table: dict[str, Callable] = {
        "sqrt": np.sqrt,
        "exp": np.exp,
        "log": np.log,
        "sin": np.sin,
        "cos": np.cos,
        "tan": np.tan,
        "tanh": np.tanh,
        "abs": np.abs,
        "log2": np.log2,
        "log10": np.log10,
        "asin": np.arcsin,
        "acos": np.arccos,
        "atan": np.arctan,
        "sinh": np.sinh,
        "cosh": np.cosh,
        "atan2": np.arctan2,
        "hypot": np.hypot,
        "min": _variadic(np.minimum),
        "max": _variadic(np.maximum),
    }
    return table


def casadi_functions(domain: list | None = None, smoothing: float = 0.0) -> dict[str, Callable]:
    """The function table for CasADi symbols (exact derivatives by automatic differentiation).

    With ``domain``, every call of a function with a restricted domain on a symbolic argument appends what must
    hold for the call to be defined: ("positive", v) for log, log2, log10 (v > 0), ("nonnegative", v) for sqrt
    (v >= 0) and for asin, acos (1 - v^2 >= 0). CasADi simplifies 0 * log(v) to 0, so a term that is undefined
    everywhere can vanish from the compiled expression; the recorded conditions keep it checkable.

    With ``smoothing`` mu > 0, abs, min and max are replaced by smooth functions within mu of them:
    abs(u) ~ sqrt(u^2 + mu^2) - mu, and max, min(u, v) ~ (u + v +- sqrt((u - v)^2 + mu^2))/2 (what a smoothing
    homotopy solves, gnerun.runs.solving)."""
    import casadi as ca

    def smooth_abs(v: Any) -> Any:
        return ca.sqrt(v * v + smoothing * smoothing) - smoothing

    def smooth_max(u: Any, v: Any) -> Any:
        return 0.5 * (u + v + ca.sqrt((u - v) * (u - v) + smoothing * smoothing))

    def smooth_min(u: Any, v: Any) -> Any:
        return 0.5 * (u + v - ca.sqrt((u - v) * (u - v) + smoothing * smoothing))

    smooth = smoothing > 0

    def guarded(f: Callable, kind: str, margin: Callable = lambda v: v) -> Callable:
        if domain is None:
            return f

        def g(v: Any) -> Any:
            if isinstance(v, ca.SX) and not v.is_constant():
                domain.append((kind, margin(v)))
            return f(v)

        return g

    return {
        "sqrt": guarded(ca.sqrt, "nonnegative"),
        "exp": ca.exp,
        "log": guarded(ca.log, "positive"),
        "sin": ca.sin,
        "cos": ca.cos,
        "tan": ca.tan,
        "tanh": ca.tanh,
        "abs": smooth_abs if smooth else ca.fabs,
        "log2": guarded(lambda v: ca.log(v) / math.log(2.0), "positive"),
        "log10": guarded(ca.log10, "positive"),
        "asin": guarded(ca.asin, "nonnegative", lambda v: 1 - v * v),
        "acos": guarded(ca.acos, "nonnegative", lambda v: 1 - v * v),
        "atan": ca.atan,
        "sinh": ca.sinh,
        "cosh": ca.cosh,
        "atan2": ca.atan2,
        "hypot": lambda u, v: ca.sqrt(u * u + v * v),
        "min": _variadic(smooth_min if smooth else ca.fmin),
        "max": _variadic(smooth_max if smooth else ca.fmax),
    }


class Shared:
    """The subexpressions of one environment (a compile's names for a stage) built once: a large subtree written more
    than once (an aggregate definition spliced into every agent's cost, ``S = sum(x{k} for k in 1..N)``) is evaluated
    the first time and its value reused, so N costs share one S instead of building N copies of it (the expressions of
    200 Cournot firms: 40,000 additions -> 200, and their derivatives a graph 200 times smaller). Subtrees are matched
    by structure (operators, names, numbers); those with a function call (whose evaluation may record where a log or
    sqrt is defined, or smooth abs, min and max) or a runtime entry are never reused, nor are subtrees of fewer than
    ``SMALLEST`` nodes, so that the derivatives of a game without large repeated subtrees are the same to the bit."""

    SMALLEST = 64

    def __init__(self) -> None:
        self.keys: dict[tuple, int] = {}  # a subtree's structure -> its number
        self.values: dict[int, Any] = {}  # a large subtree's number -> its value


def evaluate(node: Node | Expression, env: Mapping[str, Any], functions: Mapping[str, Callable] | None = None,
             shared: Shared | None = None):
    """Interpret a syntax tree with names bound by ``env``.

    Works for any values that support + - * / ** (floats, numpy arrays, CasADi SX/MX). The tree is
    walked with an explicit stack, so the interpreter's depth does not grow with the expression. ``shared``: the
    large subtrees already evaluated in ``env`` (:class:`Shared`), reused by structure.
    """
    if isinstance(node, Expression):
        node = node.tree
    fns = functions if functions is not None else numpy_functions()
    # Post-order evaluation with an explicit stack: (node, visited) pairs and a value stack; with ``shared``, also
    # each value's structure number (None: not reusable) and its subtree's size
    values: list[Any] = []
    keys: list[int | None] = []
    sizes: list[int] = []
    numbers = shared.keys if shared is not None else None
    stack: list[tuple[Node, bool]] = [(node, False)]
    while stack:
        n, visited = stack.pop()
        if isinstance(n, Num):
            values.append(n.value)
            if numbers is not None:
                keys.append(numbers.setdefault(("n", type(n.value).__name__, repr(n.value)), len(numbers)))
                sizes.append(1)
        elif isinstance(n, Name):
            try:
                values.append(env[n.id])
            except KeyError:
                if n.id not in CONSTANTS:
                    raise KeyError(n.id) from None
                values.append(CONSTANTS[n.id])
            if numbers is not None:
                keys.append(numbers.setdefault(("v", n.id), len(numbers)))
                sizes.append(1)
        elif not visited:
            stack.append((n, True))
            if isinstance(n, Unary):
                stack.append((n.operand, False))
            elif isinstance(n, Binary):
                stack.append((n.right, False))
                stack.append((n.left, False))
            else:  # Call, Index
                for arg in reversed(children(n)):
                    stack.append((arg, False))
        elif isinstance(n, Unary | Binary):
            k = 1 if isinstance(n, Unary) else 2
            operands = values[len(values) - k:]
            del values[len(values) - k:]
            if numbers is None:
                values.append(_apply(n, operands))
                continue
            parts = keys[len(keys) - k:]
            size = 1 + sum(sizes[len(sizes) - k:])
            del keys[len(keys) - k:], sizes[len(sizes) - k:]
            key = None if None in parts else numbers.setdefault((n.op, *parts), len(numbers))
            reuse = key is not None and size >= Shared.SMALLEST
            if reuse and key in shared.values:
                value = shared.values[key]
            else:
                value = _apply(n, operands)
                if reuse:
                    shared.values[key] = value
            values.append(value)
            keys.append(key)
            sizes.append(size)
        else:  # Call, Index: evaluated every time, never reused
            k = len(n.indices) if isinstance(n, Index) else len(n.args)
            args = values[len(values) - k:]
            del values[len(values) - k:]
            if isinstance(n, Index):
                where = [_integer_index(v, n) for v in args]
                try:
                    table = env[n.name + "[]"]
                except KeyError:
                    raise KeyError(n.name) from None
                values.append(table.at(where))
            else:
                values.append(fns[n.function](*args))
            if numbers is not None:
                size = 1 + sum(sizes[len(sizes) - k:])
                del keys[len(keys) - k:], sizes[len(sizes) - k:]
                keys.append(None)
                sizes.append(size)
    return values[0]


def _apply(n: Unary | Binary, operands: list[Any]) -> Any:
    if isinstance(n, Unary):
        return -operands[0] if n.op == "-" else operands[0]
    return _BINARY[n.op](operands[0], operands[1])


def _integer_index(value: Any, node: Index) -> int:
    """An index's value as an int: it must be an exact integer (never rounded)."""
    v = float(value)
    if not v.is_integer():
        raise ValueError(f"the index of {node.name!r} is {v:g}, not an integer")
    return int(v)


def _ieee(op: Callable[[Any, Any], Any]) -> Callable[[Any, Any], Any]:
    """``op`` on symbols and arrays as is; on two plain numbers with IEEE semantics, as CasADi and numpy
    compute (1/0 = inf, 0/0 = nan, (-8)**0.5 = nan, 10**400 = inf) instead of Python's exceptions and
    complex powers."""

    def f(a: Any, b: Any) -> Any:
        if _scalar(a) and _scalar(b):
            import numpy as np

            with np.errstate(all="ignore"):
                return float(op(np.float64(a), np.float64(b)))
        return op(a, b)

    return f


def _scalar(v: Any) -> bool:
    """A plain number: a Python int or float, or a numpy scalar (np.abs of an int is a np.int64)."""
    return isinstance(v, float | int) or (type(v).__module__ == "numpy" and getattr(v, "shape", None) == ())


_BINARY: dict[str, Callable[[Any, Any], Any]] = {
    "+": _ieee(lambda a, b: a + b),
    "-": _ieee(lambda a, b: a - b),
    "*": _ieee(lambda a, b: a * b),
    "/": _ieee(lambda a, b: a / b),
    "**": _ieee(lambda a, b: a**b),
    "//": _ieee(lambda a, b: a // b),  # numpy's floor division and remainder: Python's signs
    "%": _ieee(lambda a, b: a % b),
}


def check_names(parsed: Expression | Constraint, allowed: Iterable[str], what: str = "name") -> None:
    """Raise :class:`ExpressionError` at the first name that is not in ``allowed``."""
    allowed = allowed if isinstance(allowed, set | frozenset) else set(allowed)  # not copied: one per agent
    tree_roots = [parsed.tree] if isinstance(parsed, Expression) else [parsed.lhs, parsed.rhs]
    unknown: list[tuple[int, str]] = []
    for root in tree_roots:
        for name in names_in(root):
            if name not in allowed and name not in CONSTANTS:
                unknown.append((first_column_of(root, name) or 1, name))
    if unknown:
        column, name = min(unknown)
        suggest, known = _known(allowed)
        raise ExpressionError(f"unknown {what} {name!r}{suggest.suggestion(name)} (known here: {known})", parsed.text,
                              column)


_KNOWN: dict[int, tuple[Iterable[str], Names, str]] = {}  # the last sets of names checked against (by their id)


def _known(allowed: Iterable[str]) -> tuple[Names, str]:
    """The names of ``allowed`` and the constants, to suggest from and as the text of a message; the same set is
    checked for every copy of a family, and its names are indexed once (a few sets are kept, with their ids)."""
    hit = _KNOWN.get(id(allowed))
    if hit is None or hit[0] is not allowed:
        known = sorted(set(allowed) | set(CONSTANTS))
        hit = (allowed, Names(known), ", ".join(known) or "none")
        if len(_KNOWN) >= 8:
            _KNOWN.clear()
        _KNOWN[id(allowed)] = hit
    return hit[1], hit[2]


# ---------------------------------------------------------------------------------------------
# Writing a tree back as text
# ---------------------------------------------------------------------------------------------

_SUM, _PRODUCT, _UNARY, _POWER, _ATOM = 1, 2, 3, 4, 5
_PRECEDENCE = {"+": _SUM, "-": _SUM, "*": _PRODUCT, "/": _PRODUCT, "//": _PRODUCT, "%": _PRODUCT, "**": _POWER}


def _negative(value: float) -> bool:
    return value < 0 or (value == 0 and math.copysign(1.0, value) < 0)


def number_text(value: float) -> str:
    """A number as the language writes it: integers without a fraction, other values by Python's shortest repr
    (which reads back to the same double)."""
    if isinstance(value, int) and not isinstance(value, bool):
        return str(value)
    value = float(value)
    if value.is_integer() and abs(value) < 1e15:
        return str(int(value))
    return repr(value)


def _precedence(node: Node) -> int:
    if isinstance(node, Num):
        return _UNARY if _negative(node.value) else _ATOM
    if isinstance(node, Name | Call | Index):
        return _ATOM
    if isinstance(node, Unary):
        return _UNARY
    return _PRECEDENCE[node.op]


def unparse(node: Node) -> str:
    """The text of an expression tree with the parentheses its structure needs, so that parsing the text gives the
    same tree (a negative number comes back as a unary minus of its magnitude, the same value): a sum or a product on
    the right of ``-`` or ``/``, any operand of ``**`` that is not a single atom, a negative number or a unary minus
    wherever it is an operand (``(-3)**2``, ``2**(-1)``, ``x - (-3)``). Shared subtrees (definitions) are written
    wherever they occur. The tree is walked with an explicit stack, and the text is built once: the cost is linear in
    its length, whatever the tree's depth."""
    parts: list[str] = []
    stack: list[Node | str] = [node]

    def operand(child: Node, wrap: bool) -> None:
        if wrap:
            stack.extend((")", child, "("))
        else:
            stack.append(child)

    while stack:
        n = stack.pop()
        if isinstance(n, str):
            parts.append(n)
        elif isinstance(n, Num):
            parts.append("-" + number_text(-n.value) if _negative(n.value) else number_text(n.value))
        elif isinstance(n, Name):
            parts.append(n.id)
        elif isinstance(n, Index):
            for k in range(len(n.indices) - 1, -1, -1):
                stack.extend(("]", n.indices[k], "["))
            stack.append(n.name)
        elif isinstance(n, Call):
            stack.append(")")
            for k in range(len(n.args) - 1, -1, -1):
                stack.append(n.args[k])
                if k:
                    stack.append(", ")
            stack.append(n.function + "(")
        elif isinstance(n, Unary):
            operand(n.operand, _precedence(n.operand) < _POWER)
            stack.append(n.op)
        else:
            left, right = _precedence(n.left), _precedence(n.right)
            if n.op == "**":
                operand(n.right, right < _POWER)
                stack.append("**")
                operand(n.left, left < _ATOM)
            elif n.op in PRODUCTS:
                operand(n.right, right < _POWER)
                stack.append(f" {n.op} " if n.op in INTEGER_OPERATORS else n.op)
                operand(n.left, left < _PRODUCT or (isinstance(n.left, Num) and left == _UNARY))
            else:
                operand(n.right, right <= _SUM or right == _UNARY)
                stack.append(f" {n.op} ")
                operand(n.left, False)
    return "".join(parts)
