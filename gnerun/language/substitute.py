"""Expressions of the expansion (:mod:`gnerun.language.expand`): templates parsed once, and their trees with the
holes ``{...}``, templated names, entries ``name[i]``, indices, definitions and aggregates written in."""

from __future__ import annotations

import math
import re
from typing import Any

from ..errors import did_you_mean
from .expr import (
    CONSTANTS,
    INTEGER_OPERATORS,
    Binary,
    Call,
    ExpressionError,
    Index,
    Name,
    Node,
    Num,
    Unary,
    children,
    evaluate,
    first_column_of,
    names_in,
    numpy_functions,
    unparse,
)
from .families import NAME, Families, Scope, quiet
from .integers import IntegerError, integer_value, is_integer_expression
from .located import Problem
from .templates import Aggregate, Entry, Hole, Template, Word, parse_template
from .yaml_source import PathKey

_TEMPLATE = re.compile(r"\{([^{}]*)\}")
_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")  # a number literal, as text


class Substitution:
    """The expressions of one expansion: the vector and numeric parameters, the definitions (expanded trees) and
    the templates parsed so far; integers and aggregate ranges are the ``families``'."""

    def __init__(self, families: Families):
        self.families = families
        self.vectors: dict[str, list] = {}
        self.scalars: dict[str, float] = {}  # numeric parameters (for numbers written as expressions)
        self.runtime: set[str] = set()  # the names of runtime parameters (their entries stay indices)
        self.definitions = families.definitions  # expanded trees (shared wherever they are used)
        self.definition_names: dict[int, set[str]] = {}  # the names in each definition's tree, by the tree's id
        self.templates: dict[str, Template] = {}  # parsed once per text
        self.changed = False  # whether the expression being expanded had anything written in

    def parameters(self, game: dict) -> tuple[dict[str, Any], dict[str, int]]:
        """The game's parameters that stay (numbers: vectors and matrices are written in where used), and the
        integers a template may use (integer parameters and T)."""
        base: dict[str, int] = {}
        params = game.get("parameters", {})
        kept: dict[str, Any] = {}
        if isinstance(params, dict):
            for name, value in params.items():
                if isinstance(value, list):
                    self.vectors[name] = checked_vector(value, ("game", "parameters", name))
                    continue
                kept[name] = value
                if isinstance(value, int | float) and not isinstance(value, bool):
                    self.scalars[name] = value
                if isinstance(value, int) and not isinstance(value, bool):
                    base[name] = value
        runtime = game.get("runtime")
        if isinstance(runtime, dict):
            self.runtime = self.families.runtime = {k for k in runtime if isinstance(k, str)}
        horizon = game.get("horizon")
        if isinstance(horizon, int) and not isinstance(horizon, bool):
            base["T"] = horizon
        return kept, base

    def template(self, text: str, path: PathKey, scope: Scope, *, key: bool = False) -> str:
        """``{...}`` in a string that is not an expression (a name, or a mapping ``key``): the integers written in."""
        if "{" not in text and "}" not in text:
            return text
        try:
            out = _TEMPLATE.sub(lambda m: str(self.families.integer(m.group(1), path, scope, m.start(1) + 1)), text)
        except Problem as p:
            p.key = key
            raise
        if "{" in out or "}" in out:
            raise Problem(path, f"unbalanced or nested braces in {text!r} (a template is {{integer expression}})",
                           scope.indices, key=key)
        return out

    def parsed(self, text: str, path: PathKey, scope: Scope) -> Template:
        template = self.templates.get(text)
        if template is None:
            try:
                template = parse_template(text)
            except ExpressionError as e:
                raise Problem(path, e.message, scope.indices, column=e.column, quote=True) from None
            self.templates[text] = template
        return template

    def expression(self, text: str, path: PathKey, scope: Scope) -> str:
        """An expression (or a constraint) with its indices, entries, definitions and aggregates written in: the tree
        expanded and written back with the parentheses it needs (:func:`~gnerun.language.expr.unparse`); a text
        without any of them is kept as it was written."""
        return _written(*self.expanded(text, path, scope), text)

    def expanded(self, text: str, path: PathKey, scope: Scope) -> tuple[Node, str | None, Node | None, bool]:
        template = self.parsed(text, path, scope)
        self.changed = False
        lhs = self.substitute(template.lhs, path, scope)
        rhs = None if template.relation is None else self.substitute(template.rhs, path, scope)
        return lhs, template.relation, rhs, self.changed

    def number(self, value: Any, path: PathKey, scope: Scope) -> Any:
        """A number written as an expression of the indices and numeric parameters (``-0.8 - 0.2*(i - 1)``,
        ``pi/12``, ``-umax``, ``2*v[i]``), evaluated when the config is loaded; a number as it is."""
        if not isinstance(value, str):
            return value
        tree, relation, _, _ = self.expanded(value, path, scope)
        if relation is not None:
            raise Problem(path, f"{value!r} is a comparison, not a number", scope.indices)
        env = dict(self.scalars)
        unknown = sorted(dag_names(tree, self.definition_names) - set(env) - set(CONSTANTS))
        if unknown:
            what = {"lower": "a bound", "upper": "a bound", "start": "a start value", "dt": "dynamics.dt"}.get(
                next((p for p in reversed(path) if isinstance(p, str)), ""), "an entry of x0")
            runtime = (" (it is a runtime parameter: write a bound that changes at run time as a constraint, "
                       f"e.g. u <= {unknown[0]})") if unknown[0] in self.runtime else ""
            raise Problem(path, f"{unknown[0]!r} in {value!r} is not a number known when the config is loaded: "
                                 f"{what} is an expression of numbers, numeric parameters (and entries name[i]), "
                                 f"indices and pi{runtime}", scope.indices, column=first_column_of(tree, unknown[0]))
        with quiet():
            number = float(evaluate(tree, env, numpy_functions()))
        if not math.isfinite(number):
            raise Problem(path, f"{value!r} is {number}, not a finite number", scope.indices)
        return number

    def substitute(self, node: Any, path: PathKey, scope: Scope) -> Node:
        """The plain tree of a template tree (an explicit stack: no recursion, whatever the length of a sum)."""
        values: list[Node] = []
        stack: list[tuple[Any, Scope, int]] = [(node, scope, -1)]  # -1: not visited; otherwise children to combine
        while stack:
            n, sc, state = stack.pop()
            if isinstance(n, Num | Name | Word | Hole | Entry):
                values.append(self._leaf(n, path, sc))
            elif state < 0:
                self.families.tick(path, sc)
                if isinstance(n, Aggregate):
                    self.changed = True
                    count, lo, hi = self._aggregate_range(n, path, sc)
                    stack.append((n, sc, count))
                    stack.extend((n.body, sc.bind(n.index, v), -1) for v in range(hi, lo - 1, -1))
                elif isinstance(n, Unary):
                    stack.extend(((n, sc, 1), (n.operand, sc, -1)))
                elif isinstance(n, Binary):
                    stack.extend(((n, sc, 2), (n.right, sc, -1), (n.left, sc, -1)))
                else:  # Call
                    stack.append((n, sc, len(n.args)))
                    stack.extend((a, sc, -1) for a in reversed(n.args))
            else:
                children = values[len(values) - state:] if state else []
                del values[len(values) - state:]
                if isinstance(n, Aggregate):
                    values.append(_aggregate(n, children))
                elif isinstance(n, Unary):
                    values.append(Unary(n.op, children[0], n.column))
                elif isinstance(n, Binary):
                    node = Binary(n.op, children[0], children[1], n.column)
                    values.append(self._integer(node, path, sc) if n.op in INTEGER_OPERATORS else node)
                else:
                    values.append(Call(n.function, tuple(children), n.column))
        return values[0]

    def _leaf(self, n: Num | Name | Word | Hole | Entry, path: PathKey, sc: Scope) -> Node:
        """A leaf of a template tree with its index, definition, templated name, hole or entry written in."""
        if isinstance(n, Num):
            return n
        if isinstance(n, Name):
            return self._name(n.id, n.column, sc, path)
        self.changed = True
        if isinstance(n, Word):
            return self._name(self._word(n, path, sc), n.column, sc, path)
        if isinstance(n, Hole):
            return Num(self.families.value(n.expr.tree, n.expr.text, path, sc, n.column + 1), n.column)
        if n.name in self.runtime:
            return self._runtime_entry(n, path, sc)
        return Num(self._entry(n, path, sc), n.column)

    def _runtime_entry(self, entry: Entry, path: PathKey, scope: Scope) -> Index:
        """``name[i]`` of a runtime parameter stays an index (looked up when the game is compiled): an index that
        uses the stage index tau is kept as an expression, any other is written in as its integer."""
        indices = []
        for index in entry.indices:
            if "tau" in names_in(index) and "tau" not in scope.indices:
                indices.append(self.substitute(index, path, scope))
            else:
                indices.append(Num(self.families.value(index, unparse(index), path, scope), entry.column))
        return Index(entry.name, tuple(indices), entry.column)

    def _integer(self, node: Binary, path: PathKey, sc: Scope) -> Num:
        """``a // b`` or ``a % b`` in an expression, written out as its value: both operands must be integers known
        now (indices, integer parameters, T, whole numbers; :mod:`gnerun.language.integers`)."""
        other = is_integer_expression(node, sc.base)
        if other is not None:
            raise Problem(path, f"'{node.op}' is integer arithmetic, written out when the config is loaded: its "
                                 f"operands are integers (indices, integer parameters, T), but {unparse(node)!r} "
                                 f"uses {other!r}", sc.indices, column=node.column)
        try:
            value = integer_value(node, sc.base)
        except IntegerError as e:
            raise Problem(path, f"in the integer expression {unparse(node)!r}: {e.message}", sc.indices,
                           column=e.column) from None
        self.changed = True
        return Num(int(value), node.column)

    def _aggregate_range(self, n: Aggregate, path: PathKey, sc: Scope) -> tuple[int, int, int]:
        """The number of terms of an aggregate and its range, counted (its index checked) before it is written out."""
        if n.index in sc.base or n.index in sc.indices:
            raise Problem(path, f"index {n.index!r} of {n.function}() is already in use here",
                           sc.indices, column=n.column)
        if n.index in self.definitions:
            raise Problem(path, f"index {n.index!r} of {n.function}() is the name of a definition",
                           sc.indices, column=n.column)
        self.families.take(n.index, path, n.column, sc)
        lo, hi = self.families.bounds(n.lo, n.hi, n.range_text, path, sc)
        count = max(0, hi - lo + 1)
        self.families.count(count, path, sc)
        if not count and n.function in ("max", "min"):
            raise Problem(path, f"{n.function}() over the empty range {n.range_text!r}", sc.indices,
                           column=n.column)
        return count, lo, hi

    def _name(self, word: str, column: int, scope: Scope, path: PathKey) -> Node:
        if word in scope.indices:
            self.changed = True
            return Num(scope.indices[word], column)
        tree = self.definitions.get(word)
        if tree is not None:
            self.changed = True
            return tree
        if word in self.vectors:  # its entries are written in; the parameter itself is no number
            shape = "vector" if all(not isinstance(v, list) for v in self.vectors[word]) else "matrix"
            raise Problem(path, f"{word!r} is a {shape} parameter: an expression uses one of its entries, "
                                f"{word}[i]" + ("" if shape == "vector" else "[j]") + " (indexed from 1)",
                           scope.indices, column=column)
        return Name(word, column)

    def _word(self, word: Word, path: PathKey, scope: Scope) -> str:
        """A templated name (``x{i}``) with its integers written in; what it makes must be a name."""
        starts = iter(m.start(1) for m in _TEMPLATE.finditer(word.text))  # where each {...} of the word begins
        text = "".join(p if isinstance(p, str) else
                       str(self.families.value(p.tree, p.text, path, scope, word.column + next(starts)))
                       for p in word.pieces)
        if NAME.fullmatch(text) is None:
            raise Problem(path, f"{word.text!r} makes {text!r}, which is not a name (a template inside a name must "
                                 "give a non-negative integer)", scope.indices, column=word.column)
        return text

    def _entry(self, entry: Entry, path: PathKey, scope: Scope) -> float:
        """``name[i]``, ``name[i][j]`` of a vector or matrix parameter: the entry (1-based)."""
        if entry.name not in self.vectors:
            known = ", ".join(sorted(self.vectors)) or "none"
            raise Problem(path, f"{entry.name!r} is indexed but is not a vector or matrix parameter"
                                 f"{did_you_mean(entry.name, self.vectors)} (those here: {known})", scope.indices,
                          column=entry.column)
        value: Any = self.vectors[entry.name]
        for index in entry.indices:
            k = self.families.value(index, unparse(index), path, scope, 1)
            if not isinstance(value, list):
                raise Problem(path, f"{entry.name!r} has fewer dimensions than indices", scope.indices,
                               column=entry.column)
            if not 1 <= k <= len(value):
                raise Problem(path, f"index {k} of {entry.name!r} is outside 1..{len(value)}", scope.indices,
                               column=entry.column)
            value = value[k - 1]
        if isinstance(value, list):
            raise Problem(path, f"{entry.name!r} needs more indices (it is a matrix)", scope.indices,
                           column=entry.column)
        return value


def checked_vector(value: list, path: PathKey) -> list:
    """A vector or matrix parameter, its shape and entries checked; an entry written as a number that YAML reads as
    text (``1e-3``: YAML 1.1's floats need a dot) is that number."""
    def check(v: Any, depth: int) -> Any:
        if isinstance(v, list):
            if depth >= 2 or not v:
                raise Problem(path, "a parameter is a number, a vector (list) or a matrix (list of lists)")
            return [check(x, depth + 1) for x in v]
        if isinstance(v, str) and _NUMBER.fullmatch(v.strip()):
            v = float(v)
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise Problem(path, f"the entries of a vector or matrix parameter must be finite numbers, not {v!r}")
        return v
    return check(value, 0)


def _written(lhs: Node, relation: str | None, rhs: Node | None, changed: bool, text: str) -> str:
    if not changed:
        return text
    return unparse(lhs) if relation is None else f"{unparse(lhs)} {relation} {unparse(rhs)}"


def _aggregate(node: Aggregate, terms: list[Node]) -> Node:
    """The terms of an aggregate as one tree: a sum and a product left to right (as written out), max and min as a
    call (one term: the term itself)."""
    if not terms:
        return Num(0 if node.function == "sum" else 1, node.column)
    if node.function in ("sum", "prod"):
        op = "+" if node.function == "sum" else "*"
        out = terms[0]
        for t in terms[1:]:
            out = Binary(op, out, t, node.column)
        return out
    return Call(node.function, tuple(terms), node.column) if len(terms) > 1 else terms[0]


def dag_names(node: Node, known: dict[int, set[str]]) -> set[str]:
    """The names in a tree whose subtrees may be shared (definitions): each shared subtree is visited once, and a
    subtree whose names are ``known`` (a definition's, by its id) not at all."""
    names: set[str] = set()
    seen: set[int] = set()
    stack = [node]
    while stack:
        n = stack.pop()
        if id(n) in seen:
            continue
        seen.add(id(n))
        if id(n) in known:
            names |= known[id(n)]
        elif isinstance(n, Name):
            names.add(n.id)
        else:
            stack.extend(children(n))
    return names
