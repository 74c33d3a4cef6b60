"""Families, templates, sums and definitions: a config's game section expanded before validation.

Everything here rewrites the YAML document as plain data, so the game that is validated, compiled and
recorded in a run directory's ``config.yaml`` is the expanded one. What is expanded:

- ``{...}`` in any string of the game section (a mapping key or a value): an integer expression of the indices in
  scope, the integer parameters and ``T`` (the horizon), spliced into the string;
- ``for: {i: a..b, j: i+1..b}`` in an item of a list (agents, states, constraints, shared constraints,
  dynamics): one copy of the item per index value, indices nested in the order written, a range may use earlier
  indices; in an expression, an index in scope is also a number;
- ``sum(E for k in a..b)`` (and ``prod``, ``max``, ``min``) in an expression: the terms written out;
- ``name[i]`` and ``name[i][j]`` of vector and matrix parameters (1-based): the entry;
- ``definitions``: named subexpressions, written in wherever their name is used.

Expressions are expanded as syntax trees (:mod:`gnerun.language.templates`): an index value, an entry or a definition
becomes a node of the tree, and the tree is written back with the parentheses its structure needs, so that every
number and definition keeps its meaning wherever it lands (``(-3)**2``, ``(x1**2)**0.5``).

The expansion is bounded: every family's size and every aggregate's length is counted before anything is built,
and a config that would expand beyond :data:`MAX_ITEMS` items is refused; a wall-clock budget of
:data:`EXPANSION_SECONDS` is the last guard. Errors carry the template's ``file:line:column`` and the index values
that produced the failing copy.
"""

from __future__ import annotations

import math
import re
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

from ..errors import ConfigError
from .expr import (
    CONSTANTS,
    FUNCTIONS,
    Binary,
    Call,
    ExpressionError,
    Name,
    Node,
    Num,
    Unary,
    evaluate,
    names_in,
    numpy_functions,
    parse_expression,
    unparse,
)
from .extent import MAX_ITEMS, Extent, game_section
from .located import Problem, is_expression
from .templates import AGGREGATES, Aggregate, Entry, Hole, Template, Word, parse_template
from .yaml_source import PathKey, SourceMap

EXPANSION_SECONDS = 60.0  # the expansion's wall-clock budget behind the estimate (a game at the limits: ~10 s)
_NAME = re.compile(r"(?<![\w.])([A-Za-z_]\w*)")
_AGGREGATE = re.compile(r"(?<![\w.])(sum|prod|max|min)\s*\(")
_TEMPLATE = re.compile(r"\{([^{}]*)\}")
@dataclass(frozen=True)
class _Scope:
    """The integers a template may use: integer parameters and T (``base``), and the indices of the families
    and aggregates around it, innermost last."""

    base: dict[str, int]
    indices: dict[str, int] = field(default_factory=dict)

    def env(self) -> dict[str, int]:
        return {**self.base, **self.indices}

    def bind(self, name: str, value: int) -> _Scope:
        return _Scope(self.base, {**self.indices, name: value})


def expands(data: Any) -> bool:
    """Whether a config document uses anything this module expands (its game section has ``for``, ``{``,
    ``definitions``, list parameters, indexing or aggregates)."""
    game = data.get("game") if isinstance(data, dict) else None
    if not isinstance(game, dict):
        return False
    x0 = game.get("x0")
    return _uses(game) or (isinstance(x0, list) and any(isinstance(v, str | dict) for v in x0))


def _uses(value: Any) -> bool:
    if isinstance(value, dict):
        return any(k in ("for", "definitions") or (k == "stages" and isinstance(v, str))
                   or (isinstance(k, str) and "{" in k) or _uses(v) for k, v in value.items())
    if isinstance(value, list):
        return any(_uses(v) for v in value)
    if isinstance(value, str):
        return "{" in value or "[" in value or _AGGREGATE.search(value) is not None and " for " in value
    return False


class Expander:
    """Expands the game section of one config document (see the module docstring)."""

    def __init__(self, smap: SourceMap, early_size: Callable[[Extent, dict, dict], Any] | None = None):
        self.src = smap
        self.early_size = early_size  # (extent, game, document) -> a Size or None: the config's estimate
        self.out = SourceMap(smap.file, overridden=dict(smap.overridden))
        self.items = 0
        self.vectors: dict[str, list] = {}
        self.scalars: dict[str, float] = {}  # numeric parameters (for numbers written as expressions)
        self.definitions: dict[str, Node] = {}  # expanded trees (shared wherever they are used)
        self.definition_names: dict[int, set[str]] = {}  # the names in each definition's tree, by the tree's id
        self.templates: dict[str, Template] = {}  # parsed once per text
        self.integers: dict[str, Any] = {}  # integer expressions, parsed once per text
        self.changed = False  # whether the expression being expanded had anything written in
        self.ticks = 0
        self.deadline = math.inf

    # entry point ---------------------------------------------------------------------------------------
    def expand(self, data: dict) -> tuple[dict, SourceMap]:
        self.deadline = time.perf_counter() + EXPANSION_SECONDS
        try:
            out = self._document(data)
        except Problem as p:
            if p.column is not None:
                where = self.src.locate_in_text(p.path, p.column)
            else:
                where = self.src.locate(p.path, key=p.key)
            if p.bindings:
                where += " (for " + ", ".join(f"{k} = {v}" for k, v in p.bindings.items()) + ")"
            raise ConfigError([f"{where}: {p.message}"]) from None
        return out, self.out

    def _document(self, data: dict) -> dict:
        self.document = data
        out = {}
        for key, value in data.items():
            self._copy_position((key,), (key,))
            out[key] = self._game(value) if key == "game" and isinstance(value, dict) else value
            if key != "game":
                self._copy_subtree(value, (key,), (key,))
        return out

    def _game(self, game: dict) -> dict:
        base: dict[str, int] = {}
        params = game.get("parameters", {})
        kept: dict[str, Any] = {}
        if isinstance(params, dict):
            for name, value in params.items():
                if isinstance(value, list):
                    self.vectors[name] = self._vector(value, ("game", "parameters", name))
                    continue
                kept[name] = value
                if isinstance(value, int | float) and not isinstance(value, bool):
                    self.scalars[name] = value
                if isinstance(value, int) and not isinstance(value, bool):
                    base[name] = value
        horizon = game.get("horizon")
        if isinstance(horizon, int) and not isinstance(horizon, bool):
            base["T"] = horizon
        self._measure(game, base)
        scope = _Scope(base)
        definitions = game.get("definitions", {})
        if definitions is not None and not isinstance(definitions, dict):
            raise Problem(("game", "definitions"), "definitions must be a mapping of names to expressions")
        for name, text in (definitions or {}).items():
            path = ("game", "definitions", name)
            if not isinstance(name, str) or _NAME.fullmatch(name) is None:
                raise Problem(path, f"a definition's name must be a name, not {name!r}")
            shadowed = _reserved(name, kept, self.vectors)
            if shadowed:
                raise Problem(path, f"definition {name!r} has the name of {shadowed}; a definition may not shadow a "
                                     "variable, state, input, parameter or constant", key=True)
            if not isinstance(text, str | int | float) or isinstance(text, bool):
                raise Problem(path, f"definition {name!r} must be an expression string")
            lhs, relation, _, _ = self._expanded(str(text), path, scope)
            if relation is not None:
                raise Problem(path, f"definition {name!r} is an expression, not a constraint ({relation!r})")
            names = _dag_names(lhs, self.definition_names)
            if name in names:
                raise Problem(path, f"definition {name!r} refers to itself")
            self.definitions[name] = lhs
            self.definition_names[id(lhs)] = names
        out: dict[str, Any] = {}
        for key, value in game.items():
            if key == "definitions":
                continue
            src = ("game", key)
            self._copy_position(src, src, key=True)
            if key == "parameters" and isinstance(value, dict):
                out[key] = kept
                self._copy_subtree(kept, src, src)
            elif key == "dynamics" and isinstance(value, list | dict):
                out[key] = self._merged(value, src, src, scope, ("dynamics",), "dynamics")
            else:
                out[key] = self._walk(value, src, src, scope, (key,))
        declared = _declared(out)
        for name in self.definitions:
            if name in declared:
                raise Problem(("game", "definitions", name), f"definition {name!r} has the name of {declared[name]}; "
                               "a definition may not shadow a variable, state, input, parameter or constant", key=True)
        return out

    def _measure(self, game: dict, base: dict[str, int]) -> None:
        """Count what the game expands to before expanding it (:mod:`gnerun.language.extent`), and estimate the size
        of the game from the counts (``early_size``, :func:`gnerun.language.config.estimate_before_expanding`): past
        a limit, the config is refused here, with the estimate, before anything is written out."""
        self.extent = extent = game_section(self, game, base)
        size = self.early_size(extent, game, self.document) if self.early_size is not None else None
        too_large = size.problems()[0] if size is not None else []
        if too_large:
            where = ("game", "horizon") if game.get("kind") == "dynamic" and "horizon" in game else ("game", "agents")
            raise Problem(where, too_large[0] + " (estimated before expanding the config)")

    def template(self, text: str, path: PathKey) -> Template:
        """``text`` parsed as a template (a located problem if it does not parse)."""
        return self._parsed(text, path, _Scope({}))

    def integer_tree(self, text: str) -> Node:
        """An integer expression's tree, parsed once per text (ExpressionError if it does not parse)."""
        parsed = self.integers.get(text)
        if parsed is None:
            parsed = self.integers[text] = parse_expression(text).tree
        return parsed

    # families ------------------------------------------------------------------------------------------
    def _family(self, spec: Any, path: PathKey, scope: _Scope) -> list[_Scope]:
        """The scopes of a ``for`` mapping's copies, in order (nested in the order written), counted before
        they are built."""
        if not isinstance(spec, dict) or not spec:
            raise Problem(path, "for: must map index names to ranges a..b, e.g. {i: 1..N}", scope.indices)
        names = list(spec)
        for name in names:
            if not isinstance(name, str) or _NAME.fullmatch(name) is None:
                raise Problem(path, f"an index must be a name, not {name!r}", scope.indices)
            if name in scope.base or name in scope.indices:
                raise Problem(path, f"index {name!r} is already in use here (a parameter, T or an outer index)",
                               scope.indices)
            if name in self.definitions:
                raise Problem(path, f"index {name!r} is the name of a definition", scope.indices)
        scopes: list[_Scope] = []
        described = "the family for: {" + ", ".join(f"{k}: {v}" for k, v in spec.items()) + "}"

        def nest(level: int, current: _Scope) -> None:
            if level == len(names):
                self._count(1, path, current)
                scopes.append(current)
                return
            name = names[level]
            lo, hi = self._range(spec[name], path + (name,), current)
            if level == len(names) - 1 and self.items + max(0, hi - lo + 1) > MAX_ITEMS:
                self._count(max(0, hi - lo + 1), path, current)  # refused before the copies are built
            for v in range(lo, hi + 1):
                self._tick(path, current, described)
                nest(level + 1, current.bind(name, v))

        nest(0, scope)
        return scopes

    def _count(self, n: int, path: PathKey, scope: _Scope) -> None:
        self.items += n
        if self.items > MAX_ITEMS:
            raise Problem(path, f"the game expands to more than {MAX_ITEMS} family copies and aggregate terms "
                                 "(the limit of one config)", scope.indices)

    def _range(self, text: Any, path: PathKey, scope: _Scope) -> tuple[int, int]:
        if isinstance(text, int) and not isinstance(text, bool):
            return text, text
        if not isinstance(text, str) or text.count("..") != 1:
            raise Problem(path, f"a range is written a..b (both ends included), not {text!r}", scope.indices)
        a, b = text.split("..")
        return self._bounds(self._parsed_integer(a, path, scope), self._parsed_integer(b, path, scope), text.strip(),
                            path, scope)

    def _bounds(self, lo: Node, hi: Node, text: str, path: PathKey, scope: _Scope) -> tuple[int, int]:
        """The ends of a range. One that uses no index (a count given by parameters) may be empty (b = a - 1) but not
        shorter: a negative count is a mistake, not an empty family."""
        a = self._value(lo, text.split("..")[0], path, scope)
        b = self._value(hi, text.split("..")[-1], path, scope)
        used = names_in(lo) | names_in(hi)
        if b < a - 1 and not used & set(scope.indices):
            given = ", ".join(f"{k} = {scope.base[k]}" for k in sorted(used) if k in scope.base)
            raise Problem(path, f"the range {text!r} is {a}..{b}, a negative count ({b - a + 1} values"
                                 + (f", with {given}" if given else "") + f"): a range may be empty ({a}..{a - 1}) "
                                 "but not shorter", scope.indices)
        return a, b

    def _parsed_integer(self, text: str, path: PathKey, scope: _Scope) -> Node:
        try:
            return self.integer_tree(text)
        except ExpressionError as e:
            raise Problem(path, f"in the integer expression {text.strip()!r}: {e.message}", scope.indices) from None

    def _integer(self, text: str, path: PathKey, scope: _Scope) -> int:
        return self._value(self._parsed_integer(text, path, scope), text, path, scope)

    def _value(self, tree: Node, text: str, path: PathKey, scope: _Scope) -> int:
        """An integer expression of the indices in scope, the integer parameters and T."""
        env = scope.env()
        for name in names_in(tree):
            if name not in env:
                known = ", ".join(sorted(env)) or "none"
                raise Problem(path, f"{name!r} in {text.strip()!r} is not an index, an integer parameter or T "
                                     f"(known here: {known})", scope.indices)
        with _quiet():
            value = evaluate(tree, env, numpy_functions())
        if not (isinstance(value, int | float) and math.isfinite(value) and float(value).is_integer()):
            raise Problem(path, f"{text.strip()!r} is {value!r}, not an integer", scope.indices)
        if abs(value) > 10**12:
            raise Problem(path, f"{text.strip()!r} = {value:.0f} is out of range", scope.indices)
        return int(value)

    # walking -------------------------------------------------------------------------------------------
    def _walk(self, value: Any, src: PathKey, dst: PathKey, scope: _Scope, logical: tuple) -> Any:
        self._copy_position(src, dst, scope=scope)
        if isinstance(value, dict):
            out: dict[Any, Any] = {}
            for k, v in value.items():
                if k == "for":
                    raise Problem(src + (k,), "for: belongs to an item of a list (agents, states, constraints, "
                                               "shared constraints, dynamics)", scope.indices)
                nk = self._template(k, src + (k,), scope) if isinstance(k, str) else k
                if nk in out:
                    raise Problem(src + (k,), f"key {nk!r} appears twice after expansion", scope.indices)
                self._copy_position(src + (k,), dst + (nk,), key=True, scope=scope)
                if nk == "stages" and isinstance(v, str):  # a range of stages: the list of tau values
                    lo, hi = self._range(v, src + (k,), scope)
                    self._count(max(0, hi - lo + 1), src + (k,), scope)
                    out[nk] = list(range(lo, hi + 1))
                    self._copy_position(src + (k,), dst + (nk,), scope=scope)
                    continue
                if nk == "ode" and logical == ("dynamics",) and isinstance(v, list | dict):
                    out[nk] = self._merged(v, src + (k,), dst + (nk,), scope, logical + (k,), "dynamics")
                    continue
                if nk in ("variables", "inputs") and isinstance(v, list) and any(
                        isinstance(x, dict) and set(x) - {"for", "names"} for x in v):
                    out[nk] = self._merged(v, src + (k,), dst + (nk,), scope, logical + (k,), nk)
                    continue
                out[nk] = self._walk(v, src + (k,), dst + (nk,), scope, logical + (k,))
            return out
        if isinstance(value, list):
            items: list[Any] = []
            for idx, item in enumerate(value):
                if isinstance(item, dict) and "for" in item:
                    body = {k: v for k, v in item.items() if k != "for"}
                    if not body:
                        raise Problem(src + (idx,), "this item has nothing but for: (a family item is an item with "
                                                     "for: {i: a..b} added, e.g. an agent's name, variables and cost)",
                                       scope.indices)
                    for inner in self._family(item["for"], src + (idx, "for"), scope):
                        self._emit(body, src + (idx,), dst, items, inner, logical)
                else:
                    items.append(self._walk(item, src + (idx,), dst + (len(items),), scope, logical + ("*",)))
            return items
        if isinstance(value, str):
            if logical == ("x0", "*"):
                return self._number(value, src, scope)
            if is_expression(logical):
                return self._expression(value, src, scope)
            return self._template(value, src, scope)
        return value

    def _number(self, value: Any, path: PathKey, scope: _Scope) -> Any:
        """A number written as an expression of the indices and numeric parameters (``-0.8 - 0.2*(i - 1)``,
        ``pi/12``), evaluated when the config is loaded; a number as it is."""
        if not isinstance(value, str):
            return value
        tree, relation, _, _ = self._expanded(value, path, scope)
        if relation is not None:
            raise Problem(path, f"{value!r} is a comparison, not a number", scope.indices)
        env = dict(self.scalars)
        unknown = sorted(_dag_names(tree, self.definition_names) - set(env) - set(CONSTANTS))
        if unknown:
            raise Problem(path, f"{unknown[0]!r} in {value!r} is not an index or a numeric parameter", scope.indices)
        with _quiet():
            number = float(evaluate(tree, env, numpy_functions()))
        if not math.isfinite(number):
            raise Problem(path, f"{value!r} is {number}, not a finite number", scope.indices)
        return number

    def _emit(self, body: dict, src: PathKey, dst: PathKey, items: list, scope: _Scope, logical: tuple) -> None:
        """One copy of a family item: ``{names: [...]}`` adds names (states), ``{expr: E}`` adds the expression
        E (constraints), anything else is one item."""
        if set(body) == {"values"} and isinstance(body["values"], list):  # numbers (x0), one list per copy
            for j, value in enumerate(body["values"]):
                items.append(self._number(value, src + ("values", j), scope))
                self._copy_position(src + ("values", j), dst + (len(items) - 1,), scope=scope)
            return
        if set(body) == {"names"} and isinstance(body["names"], list):
            for j, name in enumerate(body["names"]):
                items.append(self._walk(name, src + ("names", j), dst + (len(items),), scope, logical + ("*",)))
        elif set(body) == {"expr"}:
            items.append(self._walk(body["expr"], src + ("expr",), dst + (len(items),), scope,
                                    logical + ("*",)))
        else:
            items.append(self._walk(body, src, dst + (len(items),), scope, logical + ("*",)))

    def _merged(self, value: list | dict, src: PathKey, dst: PathKey, scope: _Scope, logical: tuple,
                what: str) -> Any:
        """A mapping, or a list of mappings (each may be a family; a plain name stands for ``name: {}``) merged
        into one: dynamics, and an agent's variables or inputs."""
        if isinstance(value, dict) and "for" not in value:
            return self._walk(value, src, dst, scope, logical)
        parts = value if isinstance(value, list) else [value]
        merged: dict[str, Any] = {}
        self._copy_position(src, dst, scope=scope)
        for idx, part in enumerate(parts):
            if isinstance(part, str) and what != "dynamics":
                name = self._template(part, src + (idx,), scope)
                if name in merged:
                    raise Problem(src + (idx,), f"{name!r} is declared twice", scope.indices)
                self._copy_position(src + (idx,), dst + (name,), key=True, scope=scope)
                merged[name] = {}
                continue
            if not isinstance(part, dict):
                raise Problem(src + (idx,), f"an item of {what} must be a mapping (name: ...)", scope.indices)
            if set(part) <= {"for", "names"} and isinstance(part.get("names"), list) and what != "dynamics":
                scopes = self._family(part["for"], src + (idx, "for"), scope) if "for" in part else [scope]
                for inner in scopes:
                    for j, text in enumerate(part["names"]):
                        name = self._template(str(text), src + (idx, "names", j), inner)
                        if name in merged:
                            raise Problem(src + (idx, "names", j), f"{name!r} is declared twice", inner.indices)
                        self._copy_position(src + (idx, "names", j), dst + (name,), key=True, scope=inner)
                        merged[name] = {}
                continue
            scopes = [scope]
            body = part
            if "for" in part:
                body = {k: v for k, v in part.items() if k != "for"}
                scopes = self._family(part["for"], src + (idx, "for"), scope)
            for inner in scopes:
                for k, v in body.items():
                    name = self._template(k, src + (idx, k), inner) if isinstance(k, str) else k
                    if name in merged:
                        raise Problem(src + (idx, k), f"{name!r} is given twice in {what}", inner.indices)
                    self._copy_position(src + (idx, k), dst + (name,), key=True, scope=inner)
                    merged[name] = self._walk(v, src + (idx, k), dst + (name,), inner, logical + ("*",))
        return merged

    # strings -------------------------------------------------------------------------------------------
    def _template(self, text: str, path: PathKey, scope: _Scope) -> str:
        """``{...}`` in a string that is not an expression (a name, a key): the integers written in."""
        if "{" not in text and "}" not in text:
            return text
        out = _TEMPLATE.sub(lambda m: str(self._integer(m.group(1), path, scope)), text)
        if "{" in out or "}" in out:
            raise Problem(path, f"unbalanced or nested braces in {text!r} (a template is {{integer expression}})",
                           scope.indices)
        return out

    def _parsed(self, text: str, path: PathKey, scope: _Scope) -> Template:
        template = self.templates.get(text)
        if template is None:
            try:
                template = parse_template(text)
            except ExpressionError as e:
                raise Problem(path, e.describe(), scope.indices, column=e.column) from None
            self.templates[text] = template
        return template

    def _expression(self, text: str, path: PathKey, scope: _Scope) -> str:
        """An expression (or a constraint) with its indices, entries, definitions and aggregates written in: the tree
        expanded and written back with the parentheses it needs (:func:`~gnerun.language.expr.unparse`); a text
        without any of them is kept as it was written."""
        return self._written(*self._expanded(text, path, scope), text)

    def _expanded(self, text: str, path: PathKey, scope: _Scope) -> tuple[Node, str | None, Node | None, bool]:
        template = self._parsed(text, path, scope)
        self.changed = False
        lhs = self._substitute(template.lhs, path, scope)
        rhs = None if template.relation is None else self._substitute(template.rhs, path, scope)
        return lhs, template.relation, rhs, self.changed

    @staticmethod
    def _written(lhs: Node, relation: str | None, rhs: Node | None, changed: bool, text: str) -> str:
        if not changed:
            return text
        return unparse(lhs) if relation is None else f"{unparse(lhs)} {relation} {unparse(rhs)}"

    def _substitute(self, node: Any, path: PathKey, scope: _Scope) -> Node:
        """The plain tree of a template tree (an explicit stack: no recursion, whatever the length of a sum)."""
        values: list[Node] = []
        stack: list[tuple[Any, _Scope, int]] = [(node, scope, -1)]  # -1: not visited; otherwise children to combine
        while stack:
            n, sc, state = stack.pop()
            if isinstance(n, Num):
                values.append(n)
            elif isinstance(n, Name):
                values.append(self._name(n.id, n.column, sc))
            elif isinstance(n, Word):
                self.changed = True
                values.append(self._name(self._word(n, path, sc), n.column, sc))
            elif isinstance(n, Hole):
                self.changed = True
                values.append(Num(self._value(n.expr.tree, n.expr.text, path, sc), n.column))
            elif isinstance(n, Entry):
                self.changed = True
                values.append(Num(self._entry(n, path, sc), n.column))
            elif state < 0:
                self._tick(path, sc)
                if isinstance(n, Aggregate):
                    self.changed = True
                    if n.index in sc.base or n.index in sc.indices:
                        raise Problem(path, f"index {n.index!r} of {n.function}() is already in use here",
                                       sc.indices, column=n.column)
                    if n.index in self.definitions:
                        raise Problem(path, f"index {n.index!r} of {n.function}() is the name of a definition",
                                       sc.indices, column=n.column)
                    lo, hi = self._bounds(n.lo, n.hi, n.range_text, path, sc)
                    count = max(0, hi - lo + 1)
                    self._count(count, path, sc)
                    if not count and n.function in ("max", "min"):
                        raise Problem(path, f"{n.function}() over the empty range {n.range_text!r}", sc.indices,
                                       column=n.column)
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
                    values.append(Binary(n.op, children[0], children[1], n.column))
                else:
                    values.append(Call(n.function, tuple(children), n.column))
        return values[0]

    def _tick(self, path: PathKey, scope: _Scope, what: str = "this expression") -> None:
        """The wall-clock budget of the expansion, the last guard behind the estimate (checked every 4,096 nodes)."""
        self.ticks += 1
        if self.ticks & 4095 == 0 and time.perf_counter() > self.deadline:
            raise Problem(path, f"expanding {what} took more than {EXPANSION_SECONDS:g} s (the expansion's time "
                                 "limit); write the game with fewer or smaller families, sums or definitions",
                           scope.indices)

    def _name(self, word: str, column: int, scope: _Scope) -> Node:
        if word in scope.indices:
            self.changed = True
            return Num(scope.indices[word], column)
        tree = self.definitions.get(word)
        if tree is not None:
            self.changed = True
            return tree
        return Name(word, column)

    def _word(self, word: Word, path: PathKey, scope: _Scope) -> str:
        """A templated name (``x{i}``) with its integers written in; what it makes must be a name."""
        text = "".join(p if isinstance(p, str) else str(self._value(p.tree, p.text, path, scope)) for p in word.pieces)
        if _NAME.fullmatch(text) is None:
            raise Problem(path, f"{word.text!r} makes {text!r}, which is not a name (a template inside a name must "
                                 "give a non-negative integer)", scope.indices, column=word.column)
        return text

    def _entry(self, entry: Entry, path: PathKey, scope: _Scope) -> float:
        """``name[i]``, ``name[i][j]`` of a vector or matrix parameter: the entry (1-based)."""
        if entry.name not in self.vectors:
            known = ", ".join(sorted(self.vectors)) or "none"
            raise Problem(path, f"{entry.name!r} is indexed but is not a vector or matrix parameter (those here: "
                                 f"{known})", scope.indices, column=entry.column)
        value: Any = self.vectors[entry.name]
        for index in entry.indices:
            k = self._value(index, unparse(index), path, scope)
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

    def _vector(self, value: list, path: PathKey) -> list:
        def check(v: Any, depth: int) -> None:
            if isinstance(v, list):
                if depth >= 2 or not v:
                    raise Problem(path, "a parameter is a number, a vector (list) or a matrix (list of lists)")
                for x in v:
                    check(x, depth + 1)
            elif isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise Problem(path, f"the entries of a vector or matrix parameter must be finite numbers, not {v!r}")
        check(value, 0)
        return value

    # positions -----------------------------------------------------------------------------------------
    def _copy_position(self, src: PathKey, dst: PathKey, *, key: bool = False, scope: _Scope | None = None) -> None:
        table_src = self.src.keys if key else self.src.values
        table_dst = self.out.keys if key else self.out.values
        pos = table_src.get(src)
        if pos is None and not key:
            p = src
            while p and p not in self.src.values:
                p = p[:-1]
            pos = self.src.values.get(p)
        if pos is not None:
            changed = src != dst or (scope is not None and scope.indices)
            table_dst[dst] = replace(pos, single_line=False) if changed else pos
        if scope is not None and scope.indices and not key:
            self.out.notes[dst] = "for " + ", ".join(f"{k} = {v}" for k, v in scope.indices.items())

    def _copy_subtree(self, value: Any, src: PathKey, dst: PathKey) -> None:
        for table_src, table_dst in ((self.src.values, self.out.values), (self.src.keys, self.out.keys)):
            for p, pos in table_src.items():
                if p[:len(src)] == src:
                    table_dst[dst + p[len(src):]] = pos


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


def _dag_names(node: Node, known: dict[int, set[str]]) -> set[str]:
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
        elif isinstance(n, Unary):
            stack.append(n.operand)
        elif isinstance(n, Binary):
            stack.extend((n.left, n.right))
        elif isinstance(n, Call):
            stack.extend(n.args)
    return names


def _reserved(name: str, parameters: dict, vectors: dict) -> str | None:
    """What a definition named ``name`` would shadow among the names known before the game is expanded."""
    if name in FUNCTIONS or name in AGGREGATES:
        return "a function"
    if name in CONSTANTS:
        return "a constant"
    if name == "tau":
        return "the stage index tau"
    if name == "T":
        return "the horizon T"
    if name in parameters or name in vectors:
        return "a parameter"
    return None


def _declared(game: dict) -> dict[str, str]:
    """The names an expanded game declares (states, the agents' variables or inputs, parameters), and what each is."""
    out: dict[str, str] = {}
    states = game.get("states")
    if isinstance(states, list):
        out.update((s, "a state") for s in states if isinstance(s, str))
    agents = game.get("agents")
    for agent in agents if isinstance(agents, list) else []:
        if not isinstance(agent, dict):
            continue
        for field_, what in (("variables", "a variable"), ("inputs", "an input")):
            variables = agent.get(field_)
            names = variables if isinstance(variables, list) else list(variables) if isinstance(variables, dict) else []
            who = f" of {agent['name']!r}" if isinstance(agent.get("name"), str) else ""
            out.update((v, what + who) for v in names if isinstance(v, str))
    return out


class _quiet:
    def __enter__(self):
        import numpy as np

        self._old = np.seterr(all="ignore")

    def __exit__(self, *exc):
        import numpy as np

        np.seterr(**self._old)
