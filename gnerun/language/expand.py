"""Families, templates, sums and definitions: a config's game section expanded before validation.

Everything here rewrites the YAML document as plain data, so the game that is validated, compiled and
recorded in a run directory's ``config.yaml`` is the expanded one. What is expanded:

- ``{...}`` in any string of the game section (a mapping key or a value): an integer expression of the indices in
  scope, the integer parameters and ``T`` (the horizon), spliced into the string;
- ``for: {i: a..b, j: i+1..b}`` in an item of a list (agents, states, constraints, shared constraints,
  dynamics): one copy of the item per index value, indices nested in the order written, a range may use earlier
  indices; in an expression, an index in scope is also a number;
- ``sum(E for k in a..b)`` (and ``prod``, ``max``, ``min``) in an expression: the terms written out;
- ``name[i]`` and ``name[i][j]`` of vector and matrix parameters (1-based): the number spliced in;
- ``definitions``: named subexpressions, spliced in (parenthesised) wherever their name is used.

The expansion is bounded: every family's size and every aggregate's length is counted before anything is built,
and a config that would expand beyond :data:`MAX_ITEMS` items is refused. Errors carry the template's
``file:line:column`` and the index values that produced the failing copy.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace
from typing import Any

from ..errors import ConfigError
from .expr import ExpressionError, evaluate, numpy_functions, parse_expression
from .yaml_source import PathKey, SourceMap

MAX_ITEMS = 100_000  # family copies and aggregate terms one config may expand to
AGGREGATES = ("sum", "prod", "max", "min")
_NAME = re.compile(r"(?<![\w.])([A-Za-z_]\w*)")
_AGGREGATE = re.compile(r"(?<![\w.])(sum|prod|max|min)\s*\(")
_INDEXED = re.compile(r"(?<![\w.])([A-Za-z_]\w*)\s*\[")
_TEMPLATE = re.compile(r"\{([^{}]*)\}")
# where a string is an expression (indices are numbers there, sums and parameter indexing are written out);
# "*" stands for any list index or mapping key
_EXPRESSIONS = (
    ("agents", "*", "stage_cost"), ("agents", "*", "terminal_cost"), ("agents", "*", "cost"),
    ("agents", "*", "constraints", "*"), ("agents", "*", "constraints", "*", "expr"),
    ("shared_constraints", "*"), ("shared_constraints", "*", "expr"),
    ("dynamics", "*"), ("dynamics", "ode", "*"), ("definitions", "*"),
)


class _Problem(Exception):
    def __init__(self, path: PathKey, message: str, bindings: dict[str, int] | None = None):
        super().__init__(message)
        self.path = path
        self.message = message
        self.bindings = dict(bindings or {})


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

    def __init__(self, smap: SourceMap):
        self.src = smap
        self.out = SourceMap(smap.file, overridden=dict(smap.overridden))
        self.items = 0
        self.vectors: dict[str, list] = {}
        self.scalars: dict[str, float] = {}  # numeric parameters (for numbers written as expressions)
        self.definitions: dict[str, str] = {}

    # entry point ---------------------------------------------------------------------------------------
    def expand(self, data: dict) -> tuple[dict, SourceMap]:
        try:
            out = self._document(data)
        except _Problem as p:
            where = self.src.locate(p.path)
            if p.bindings:
                where += " (for " + ", ".join(f"{k} = {v}" for k, v in p.bindings.items()) + ")"
            raise ConfigError([f"{where}: {p.message}"]) from None
        return out, self.out

    def _document(self, data: dict) -> dict:
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
        scope = _Scope(base)
        definitions = game.get("definitions", {})
        if definitions is not None and not isinstance(definitions, dict):
            raise _Problem(("game", "definitions"), "definitions must be a mapping of names to expressions")
        for name, text in (definitions or {}).items():
            path = ("game", "definitions", name)
            if not isinstance(name, str) or _NAME.fullmatch(name) is None:
                raise _Problem(path, f"a definition's name must be a name, not {name!r}")
            if name in kept or name in self.vectors or name in AGGREGATES:
                raise _Problem(path, f"definition {name!r} has the name of a parameter or a function")
            if not isinstance(text, str | int | float) or isinstance(text, bool):
                raise _Problem(path, f"definition {name!r} must be an expression string")
            expanded = self._expression(str(text), path, scope)
            if name in _names(expanded):
                raise _Problem(path, f"definition {name!r} refers to itself")
            self.definitions[name] = expanded
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
        return out

    # families ------------------------------------------------------------------------------------------
    def _family(self, spec: Any, path: PathKey, scope: _Scope) -> list[_Scope]:
        """The scopes of a ``for`` mapping's copies, in order (nested in the order written), counted before
        they are built."""
        if not isinstance(spec, dict) or not spec:
            raise _Problem(path, "for: must map index names to ranges a..b, e.g. {i: 1..N}", scope.indices)
        names = list(spec)
        for name in names:
            if not isinstance(name, str) or _NAME.fullmatch(name) is None:
                raise _Problem(path, f"an index must be a name, not {name!r}", scope.indices)
            if name in scope.base or name in scope.indices:
                raise _Problem(path, f"index {name!r} is already in use here (a parameter, T or an outer index)",
                               scope.indices)
        scopes: list[_Scope] = []

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
                nest(level + 1, current.bind(name, v))

        nest(0, scope)
        return scopes

    def _count(self, n: int, path: PathKey, scope: _Scope) -> None:
        self.items += n
        if self.items > MAX_ITEMS:
            raise _Problem(path, f"the game expands to more than {MAX_ITEMS} family copies and aggregate terms "
                                 "(the limit of one config)", scope.indices)

    def _range(self, text: Any, path: PathKey, scope: _Scope) -> tuple[int, int]:
        if isinstance(text, int) and not isinstance(text, bool):
            return text, text
        if not isinstance(text, str) or text.count("..") != 1:
            raise _Problem(path, f"a range is written a..b (both ends included), not {text!r}", scope.indices)
        a, b = text.split("..")
        return self._integer(a, path, scope), self._integer(b, path, scope)

    def _integer(self, text: str, path: PathKey, scope: _Scope) -> int:
        env = scope.env()
        try:
            parsed = parse_expression(text)
        except ExpressionError as e:
            raise _Problem(path, f"in the integer expression {text.strip()!r}: {e.message}", scope.indices) from None
        for name in _names(text):
            if name not in env:
                known = ", ".join(sorted(env)) or "none"
                raise _Problem(path, f"{name!r} in {text.strip()!r} is not an index, an integer parameter or T "
                                     f"(known here: {known})", scope.indices)
        with _quiet():
            value = evaluate(parsed, env, numpy_functions())
        if not (isinstance(value, int | float) and math.isfinite(value) and float(value).is_integer()):
            raise _Problem(path, f"{text.strip()!r} is {value!r}, not an integer", scope.indices)
        if abs(value) > 10**12:
            raise _Problem(path, f"{text.strip()!r} = {value:.0f} is out of range", scope.indices)
        return int(value)

    # walking -------------------------------------------------------------------------------------------
    def _walk(self, value: Any, src: PathKey, dst: PathKey, scope: _Scope, logical: tuple) -> Any:
        self._copy_position(src, dst, scope=scope)
        if isinstance(value, dict):
            out: dict[Any, Any] = {}
            for k, v in value.items():
                if k == "for":
                    raise _Problem(src + (k,), "for: belongs to an item of a list (agents, states, constraints, "
                                               "shared constraints, dynamics)", scope.indices)
                nk = self._template(k, src + (k,), scope) if isinstance(k, str) else k
                if nk in out:
                    raise _Problem(src + (k,), f"key {nk!r} appears twice after expansion", scope.indices)
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
                    for inner in self._family(item["for"], src + (idx, "for"), scope):
                        self._emit(body, src + (idx,), dst, items, inner, logical)
                else:
                    items.append(self._walk(item, src + (idx,), dst + (len(items),), scope, logical + ("*",)))
            return items
        if isinstance(value, str):
            if logical == ("x0", "*"):
                return self._number(value, src, scope)
            if _matches(logical):
                return self._expression(value, src, scope)
            return self._template(value, src, scope)
        return value

    def _number(self, value: Any, path: PathKey, scope: _Scope) -> Any:
        """A number written as an expression of the indices and numeric parameters (``-0.8 - 0.2*(i - 1)``,
        ``pi/12``), evaluated when the config is loaded; a number as it is."""
        if not isinstance(value, str):
            return value
        text = self._expression(value, path, scope)
        env = {k: v for k, v in self.scalars.items()}
        try:
            parsed = parse_expression(text)
        except ExpressionError as e:
            raise _Problem(path, f"in the number {value!r}: {e.message}", scope.indices) from None
        unknown = sorted(_names(text) - set(env) - {"pi"} - set(numpy_functions()))
        if unknown:
            raise _Problem(path, f"{unknown[0]!r} in {value!r} is not an index or a numeric parameter", scope.indices)
        with _quiet():
            number = float(evaluate(parsed, env, numpy_functions()))
        if not math.isfinite(number):
            raise _Problem(path, f"{value!r} is {number}, not a finite number", scope.indices)
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
                    raise _Problem(src + (idx,), f"{name!r} is declared twice", scope.indices)
                self._copy_position(src + (idx,), dst + (name,), key=True, scope=scope)
                merged[name] = {}
                continue
            if not isinstance(part, dict):
                raise _Problem(src + (idx,), f"an item of {what} must be a mapping (name: ...)", scope.indices)
            if set(part) <= {"for", "names"} and isinstance(part.get("names"), list) and what != "dynamics":
                scopes = self._family(part["for"], src + (idx, "for"), scope) if "for" in part else [scope]
                for inner in scopes:
                    for j, text in enumerate(part["names"]):
                        name = self._template(str(text), src + (idx, "names", j), inner)
                        if name in merged:
                            raise _Problem(src + (idx, "names", j), f"{name!r} is declared twice", inner.indices)
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
                        raise _Problem(src + (idx, k), f"{name!r} is given twice in {what}", inner.indices)
                    self._copy_position(src + (idx, k), dst + (name,), key=True, scope=inner)
                    merged[name] = self._walk(v, src + (idx, k), dst + (name,), inner, logical + ("*",))
        return merged

    # strings -------------------------------------------------------------------------------------------
    def _template(self, text: str, path: PathKey, scope: _Scope) -> str:
        if "{" not in text and "}" not in text:
            return text
        out = _TEMPLATE.sub(lambda m: str(self._integer(m.group(1), path, scope)), text)
        if "{" in out or "}" in out:
            raise _Problem(path, f"unbalanced or nested braces in {text!r} (a template is {{integer expression}})",
                           scope.indices)
        return out

    def _expression(self, text: str, path: PathKey, scope: _Scope) -> str:
        text = self._aggregates(text, path, scope)
        text = self._template(text, path, scope)
        text = self._indexing(text, path, scope)
        indices, definitions = scope.indices, self.definitions

        def name(m: re.Match) -> str:
            word = m.group(1)
            if word in indices:
                return str(indices[word])
            if word in definitions:
                return _operand(definitions[word], "+-*/")
            return word

        return _NAME.sub(name, text) if (indices or definitions) else text

    def _aggregates(self, text: str, path: PathKey, scope: _Scope) -> str:
        """``sum(E for k in a..b)`` (prod, max, min) written out, innermost templates per term."""
        out, pos = [], 0
        while True:
            m = _AGGREGATE.search(text, pos)
            if m is None:
                out.append(text[pos:])
                return "".join(out)
            close = _matching(text, m.end() - 1)
            if close is None:
                out.append(text[pos:])  # the parser reports the unbalanced parenthesis
                return "".join(out)
            inner = text[m.end():close]
            head = _top_level_for(inner)
            if head is None:  # an ordinary call: only its arguments may hold aggregates
                out.append(text[pos:m.end()] + self._aggregates(inner, path, scope) + ")")
                pos = close + 1
                continue
            body, index, rng = head
            if index in scope.base or index in scope.indices:
                raise _Problem(path, f"index {index!r} of {m.group(1)}() is already in use here", scope.indices)
            lo, hi = self._range(rng.strip(), path, scope)
            self._count(max(0, hi - lo + 1), path, scope)
            terms = [self._expression(body.strip(), path, scope.bind(index, v)) for v in range(lo, hi + 1)]
            fn = m.group(1)
            if not terms:
                if fn in ("max", "min"):
                    raise _Problem(path, f"{fn}() over the empty range {rng.strip()!r}", scope.indices)
                written = "0" if fn == "sum" else "1"
            elif fn == "sum":
                written = "(" + " + ".join(_operand(t, "+-") for t in terms) + ")"
            elif fn == "prod":
                written = "(" + "*".join(_operand(t, "+-*/") for t in terms) + ")"
            else:
                written = f"{fn}({', '.join(terms)})" if len(terms) > 1 else _operand(terms[0], "+-*/")
            out.append(text[pos:m.start()] + written)
            pos = close + 1

    def _indexing(self, text: str, path: PathKey, scope: _Scope) -> str:
        """``name[i]``, ``name[i][j]`` of vector and matrix parameters: the entry (1-based)."""
        if "[" not in text:
            return text
        out, pos = [], 0
        while True:
            m = _INDEXED.search(text, pos)
            if m is None:
                rest = text[pos:]
                if "[" in rest or "]" in rest:
                    raise _Problem(path, f"'[' or ']' in {text!r} outside name[index] of a vector parameter",
                                   scope.indices)
                out.append(rest)
                return "".join(out)
            name = m.group(1)
            if name not in self.vectors:
                known = ", ".join(sorted(self.vectors)) or "none"
                raise _Problem(path, f"{name!r} is indexed but is not a vector or matrix parameter "
                                     f"(those here: {known})", scope.indices)
            value: Any = self.vectors[name]
            end = m.end() - 1
            while end < len(text) and text[end] == "[":
                close = text.find("]", end)
                if close < 0:
                    raise _Problem(path, f"unclosed '[' after {name!r}", scope.indices)
                k = self._integer(text[end + 1:close], path, scope)
                if not isinstance(value, list):
                    raise _Problem(path, f"{name!r} has fewer dimensions than indices", scope.indices)
                if not 1 <= k <= len(value):
                    raise _Problem(path, f"index {k} of {name!r} is outside 1..{len(value)}", scope.indices)
                value = value[k - 1]
                end = close + 1
            if isinstance(value, list):
                raise _Problem(path, f"{name!r} needs more indices (it is a matrix)", scope.indices)
            out.append(text[pos:m.start()] + (f"({value!r})" if value < 0 else repr(value)))
            pos = end

    def _vector(self, value: list, path: PathKey) -> list:
        def check(v: Any, depth: int) -> None:
            if isinstance(v, list):
                if depth >= 2 or not v:
                    raise _Problem(path, "a parameter is a number, a vector (list) or a matrix (list of lists)")
                for x in v:
                    check(x, depth + 1)
            elif isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise _Problem(path, f"the entries of a vector or matrix parameter must be finite numbers, not {v!r}")
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


def _operand(text: str, ops: str) -> str:
    """``text`` as one operand where it is spliced in: parenthesised when its outermost operation is one of
    ``ops`` or a unary sign (so that sums and products keep their order of evaluation) and it is not already."""
    from .expr import Binary, Unary

    if text.startswith("(") and _matching(text, 0) == len(text) - 1:
        return text
    try:
        root = parse_expression(text).tree
    except ExpressionError:
        return f"({text})"  # the parser reports the mistake where the expanded expression is read
    if (isinstance(root, Binary) and root.op in ops) or isinstance(root, Unary):
        return f"({text})"
    return text


def _names(text: str) -> set[str]:
    return set(_NAME.findall(text))


def _matches(logical: tuple) -> bool:
    return any(len(p) == len(logical) and all(a == "*" or a == b for a, b in zip(p, logical, strict=True))
               for p in _EXPRESSIONS)


def _matching(text: str, open_at: int) -> int | None:
    depth = 0
    for i in range(open_at, len(text)):
        if text[i] == "(":
            depth += 1
        elif text[i] == ")":
            depth -= 1
            if depth == 0:
                return i
    return None


def _top_level_for(inner: str) -> tuple[str, str, str] | None:
    """``E for k in a..b`` split at its top-level ``for`` (not inside parentheses), or None."""
    depth = 0
    for i, ch in enumerate(inner):
        if ch in "([":
            depth += 1
        elif ch in ")]":
            depth -= 1
        elif depth == 0 and inner.startswith("for", i) and (i == 0 or not (inner[i - 1].isalnum()
                                                                             or inner[i - 1] == "_")):
            m = re.match(r"for\s+([A-Za-z_]\w*)\s+in\s+(.+)$", inner[i:], re.S)
            if m is not None:
                return inner[:i], m.group(1), m.group(2)
    return None


class _quiet:
    def __enter__(self):
        import numpy as np

        self._old = np.seterr(all="ignore")

    def __exit__(self, *exc):
        import numpy as np

        np.seterr(**self._old)
