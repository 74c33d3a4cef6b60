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
from collections.abc import Callable
from typing import Any

from ..errors import ConfigError
from .expr import CONSTANTS, FUNCTIONS, Node
from .extent import MAX_ITEMS, Extent, game_section
from .families import EXPANSION_SECONDS, NAME, Families, Scope
from .located import Problem, is_expression, is_number
from .origins import written_at
from .positions import Positions
from .substitute import Substitution, dag_names
from .templates import AGGREGATES, Template
from .yaml_source import Origin, PathKey, SourceMap

__all__ = ["EXPANSION_SECONDS", "MAX_ITEMS", "Expander", "expands"]

_AGGREGATE = re.compile(r"(?<![\w.])(sum|prod|max|min)\s*\(")


def expands(data: Any) -> bool:
    """Whether a config document uses anything this module expands (its game section has ``for``, ``{``,
    ``definitions``, list parameters, indexing, aggregates, ``//`` or ``%``, or numbers written as expressions)."""
    game = data.get("game") if isinstance(data, dict) else None
    if not isinstance(game, dict):
        return False
    x0 = game.get("x0")
    parameters = game.get("parameters")
    return (_uses(game) or (isinstance(x0, list) and any(isinstance(v, str | dict) for v in x0))
            or _numbers_as_text(game)
            or isinstance(parameters, dict) and any(isinstance(v, list) for v in parameters.values()))


def _numbers_as_text(game: dict) -> bool:
    """Whether a bound, a start value or the ode's dt is written as an expression (``lower: -umax``)."""
    dynamics = game.get("dynamics")
    if isinstance(dynamics, dict) and "ode" in dynamics and isinstance(dynamics.get("dt"), str):
        return True
    agents = game.get("agents")
    for agent in agents if isinstance(agents, list) else []:
        for field_ in ("variables", "inputs"):
            variables = agent.get(field_) if isinstance(agent, dict) else None
            parts = [variables] if isinstance(variables, dict) else variables if isinstance(variables, list) else []
            for spec in (s for part in parts if isinstance(part, dict) for s in part.values()):
                numbers = [spec.get(k) for k in ("lower", "upper", "start")] if isinstance(spec, dict) else []
                numbers += [v for n in numbers if isinstance(n, list) for v in n]  # a start value per stage
                if any(isinstance(v, str) for v in numbers):
                    return True
    return False


def _uses(value: Any) -> bool:
    if isinstance(value, dict):
        return any(k in ("for", "definitions") or (k == "stages" and isinstance(v, str))
                   or (isinstance(k, str) and "{" in k) or _uses(v) for k, v in value.items())
    if isinstance(value, list):
        return any(_uses(v) for v in value)
    if isinstance(value, str):
        return ("{" in value or "[" in value or "%" in value or "//" in value
                or _AGGREGATE.search(value) is not None and " for " in value)
    return False


class Expander:
    """Expands the game section of one config document (see the module docstring): walks the document and writes
    it out, with the families (:mod:`~gnerun.language.families`), the expressions
    (:mod:`~gnerun.language.substitute`) and the source positions (:mod:`~gnerun.language.positions`) each their
    own object."""

    def __init__(self, smap: SourceMap, early_size: Callable[[Extent, dict, dict], Any] | None = None):
        self.src = smap
        self.early_size = early_size  # (extent, game, document) -> a Size or None: the config's estimate
        self.positions = Positions(smap)
        self.families = Families({})
        self.subst = Substitution(self.families)
        self.written_from: dict[PathKey, tuple[PathKey, Scope]] = {}  # an expression: its template and copy's scope

    @property
    def out(self) -> SourceMap:
        return self.positions.out

    @property
    def vectors(self) -> dict[str, list]:
        return self.subst.vectors

    @property
    def definitions(self) -> dict[str, Node]:
        return self.subst.definitions

    # entry point ---------------------------------------------------------------------------------------
    def expand(self, data: dict) -> tuple[dict, SourceMap]:
        self.families.start()
        try:
            out = self._document(data)
        except Problem as p:
            text = p.path[-1] if p.key else _value_at(data, p.path)
            shown = ""
            if p.column is not None and isinstance(text, str):  # a string written over several lines: an excerpt
                where, _, shown = self.src.point(p.path, p.column, text, key=p.key, quote=p.quote)
            elif p.column is not None:
                where = self.src.locate_in_text(p.path, p.column, key=p.key)
            else:
                where = self.src.locate(p.path, key=p.key)
            if p.bindings:
                where += " (for " + ", ".join(f"{k} = {v}" for k, v in p.bindings.items()) + ")"
            raise ConfigError([f"{where}: {p.message}{shown}"]) from None
        self.out.origins, self.out.source = self.origin, self.src
        return out, self.out

    def origin(self, path: PathKey, column: int, text: str) -> Origin | None:
        """Where character ``column`` of ``text``, the expression at ``path`` of the expansion, was written: the
        template's (or a definition's) text and column (:mod:`gnerun.language.origins`); None where not known."""
        found = self.written_from.get(tuple(path))
        template = _value_at(self.document, found[0]) if found is not None else None
        if found is None or not isinstance(template, str):
            return None
        src, scope = found
        items, deadline = self.families.items, self.families.deadline
        self.families.deadline = math.inf  # (the expansion's budgets were checked when it ran)
        try:  # the same expansion again, to pair its nodes with the text's
            lhs, relation, rhs, changed = self._expanded(template, src, scope)
        except Problem:
            return None
        finally:
            self.families.items, self.families.deadline = items, deadline
        if not changed:
            return Origin(src, template, column) if text == template else None
        at = written_at(text, column, [lhs] if relation is None else [lhs, rhs], self.definitions)
        if at is None:
            return None
        if at[1] is not None:
            definition = _value_at(self.document, ("game", "definitions", at[1]))
            return Origin(("game", "definitions", at[1]), str(definition), at[0], definition=True)
        return Origin(src, template, at[0])

    def _document(self, data: dict) -> dict:
        self.document = data
        out = {}
        for key, value in data.items():
            self.positions.copy((key,), (key,))
            out[key] = self._game(value) if key == "game" and isinstance(value, dict) else value
            if key != "game":
                self.positions.copy_subtree(value, (key,), (key,))
        return out

    def _game(self, game: dict) -> dict:
        kept, base = self.subst.parameters(game)
        taken = names_taken(game, kept, self.vectors)
        # an index may not take these, nor a runtime parameter's name (the parameters in use, T and outer indices are
        # refused as in use); a definition may not take these, tau or T
        self.families.reserved = {**{name: "a runtime parameter" for name in self.subst.runtime}, **taken}
        self._measure(game, base)
        scope = Scope(base)
        self._definitions(game, {**taken, "tau": "the stage index tau", "T": "the horizon T"}, scope)
        out: dict[str, Any] = {}
        for key, value in game.items():
            if key == "definitions":
                continue
            src = ("game", key)
            self.positions.copy(src, src, key=True)
            if key == "parameters" and isinstance(value, dict):
                out[key] = kept
                self.positions.copy_subtree(kept, src, src)
            elif key == "dynamics" and isinstance(value, list | dict):
                out[key] = self._merged(value, src, src, scope, ("dynamics",), "dynamics")
            else:
                out[key] = self._walk(value, src, src, scope, (key,))
        declared = _declared(out)
        for name in self.definitions:
            if name in declared:
                raise Problem(("game", "definitions", name), f"definition {name!r} has the name of {declared[name]}; "
                               "a definition may not shadow a variable, state, input, parameter or constant", key=True)
        for name, (path, column, bindings) in self.families.used.items():
            if name in declared:
                raise Problem(path, f"index {name!r} has the name of {declared[name]}, which it would replace in the "
                                    "expressions of its scope; choose another name", bindings, column=column)
        return out

    def _definitions(self, game: dict, reserved: dict[str, str], scope: Scope) -> None:
        """The game's definitions expanded, in the order written (one may use those before it); ``reserved``: the
        names a definition may not take, and what each is."""
        definitions = game.get("definitions", {})
        if definitions is not None and not isinstance(definitions, dict):
            raise Problem(("game", "definitions"), "definitions must be a mapping of names to expressions")
        for name, text in (definitions or {}).items():
            path = ("game", "definitions", name)
            if not isinstance(name, str) or NAME.fullmatch(name) is None:
                raise Problem(path, f"a definition's name must be a name, not {name!r}")
            shadowed = reserved.get(name)
            if shadowed:
                raise Problem(path, f"definition {name!r} has the name of {shadowed}; a definition may not shadow a "
                                     "variable, state, input, parameter or constant", key=True)
            if not isinstance(text, str | int | float) or isinstance(text, bool):
                raise Problem(path, f"definition {name!r} must be an expression string")
            lhs, relation, _, _ = self._expanded(str(text), path, scope)
            if relation is not None:
                raise Problem(path, f"definition {name!r} is an expression, not a constraint ({relation!r})")
            names = dag_names(lhs, self.subst.definition_names)
            if name in names:
                raise Problem(path, f"definition {name!r} refers to itself")
            self.definitions[name] = lhs
            self.subst.definition_names[id(lhs)] = names

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
        return self.subst.parsed(text, path, Scope({}))

    def integer_tree(self, text: str) -> Node:
        """An integer expression's tree, parsed once per text (ExpressionError if it does not parse)."""
        return self.families.integer_tree(text)

    def _expanded(self, text: str, path: PathKey, scope: Scope) -> tuple[Node, str | None, Node | None, bool]:
        """An expression's tree (and a constraint's relation and right side) expanded, and whether it changed."""
        return self.subst.expanded(text, path, scope)

    # walking -------------------------------------------------------------------------------------------
    def _walk(self, value: Any, src: PathKey, dst: PathKey, scope: Scope, logical: tuple) -> Any:
        self.positions.copy(src, dst, scope=scope)
        if isinstance(value, dict):
            out: dict[Any, Any] = {}
            for k, v in value.items():
                if k == "for":
                    raise Problem(src + (k,), "for: belongs to an item of a list (agents, states, constraints, "
                                               "shared constraints, dynamics)", scope.indices)
                nk = self.subst.template(k, src + (k,), scope, key=True) if isinstance(k, str) else k
                if nk in out:
                    raise Problem(src + (k,), f"key {nk!r} appears twice after expansion", scope.indices)
                self.positions.copy(src + (k,), dst + (nk,), key=True, scope=scope)
                if nk == "stages" and isinstance(v, str):  # a range of stages: the list of tau values
                    lo, hi = self.families.range(v, src + (k,), scope)
                    self.families.count(max(0, hi - lo + 1), src + (k,), scope)
                    out[nk] = list(range(lo, hi + 1))
                    self.positions.copy(src + (k,), dst + (nk,), scope=scope)
                    continue
                if nk == "ode" and logical == ("dynamics",) and isinstance(v, list | dict):
                    out[nk] = self._merged(v, src + (k,), dst + (nk,), scope, logical + (k,), "dynamics")
                    continue
                if nk in ("variables", "inputs") and isinstance(v, list) and any(
                        isinstance(x, dict) and set(x) - {"for", "names"} for x in v):
                    out[nk] = self._merged(v, src + (k,), dst + (nk,), scope, logical + (k,), nk)
                    continue
                discrete = logical == ("dynamics",) and "ode" not in value  # x(t+1) of every state, dt a state
                out[nk] = self._walk(v, src + (k,), dst + (nk,), scope, logical + ("*" if discrete else k,))
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
                    for inner in self.families.family(item["for"], src + (idx, "for"), scope):
                        self._emit(body, src + (idx,), dst, items, inner, logical)
                else:
                    items.append(self._walk(item, src + (idx,), dst + (len(items),), scope, logical + ("*",)))
            return items
        if isinstance(value, str):
            if is_number(logical):
                return self.subst.number(value, src, scope)
            if is_expression(logical):
                self.written_from[dst] = (src, scope)
                return self.subst.expression(value, src, scope)
            return self.subst.template(value, src, scope)
        return value

    def _emit(self, body: dict, src: PathKey, dst: PathKey, items: list, scope: Scope, logical: tuple) -> None:
        """One copy of a family item: ``{names: [...]}`` adds names (states), ``{expr: E}`` adds the expression
        E (constraints), anything else is one item."""
        if set(body) == {"values"} and isinstance(body["values"], list):  # numbers (x0), one list per copy
            for j, value in enumerate(body["values"]):
                items.append(self.subst.number(value, src + ("values", j), scope))
                self.positions.copy(src + ("values", j), dst + (len(items) - 1,), scope=scope)
            return
        if set(body) == {"names"} and isinstance(body["names"], list):
            for j, name in enumerate(body["names"]):
                items.append(self._walk(name, src + ("names", j), dst + (len(items),), scope, logical + ("*",)))
        elif set(body) == {"expr"}:
            items.append(self._walk(body["expr"], src + ("expr",), dst + (len(items),), scope,
                                    logical + ("*",)))
        else:
            items.append(self._walk(body, src, dst + (len(items),), scope, logical + ("*",)))

    def _merged(self, value: list | dict, src: PathKey, dst: PathKey, scope: Scope, logical: tuple,
                what: str) -> Any:
        """A mapping, or a list of mappings (each may be a family; a plain name stands for ``name: {}``) merged
        into one: dynamics, and an agent's variables or inputs."""
        if isinstance(value, dict) and "for" not in value:
            return self._walk(value, src, dst, scope, logical)
        parts = value if isinstance(value, list) else [value]
        merged: dict[str, Any] = {}
        self.positions.copy(src, dst, scope=scope)
        for idx, part in enumerate(parts):
            if isinstance(part, str) and what != "dynamics":
                name = self.subst.template(part, src + (idx,), scope)
                if name in merged:
                    raise Problem(src + (idx,), f"{name!r} is declared twice", scope.indices)
                self.positions.copy(src + (idx,), dst + (name,), key=True, scope=scope)
                merged[name] = {}
                continue
            if not isinstance(part, dict):
                raise Problem(src + (idx,), f"an item of {what} must be a mapping (name: ...)", scope.indices)
            if set(part) <= {"for", "names"} and isinstance(part.get("names"), list) and what != "dynamics":
                scopes = self.families.family(part["for"], src + (idx, "for"), scope) if "for" in part else [scope]
                for inner in scopes:
                    for j, text in enumerate(part["names"]):
                        name = self.subst.template(str(text), src + (idx, "names", j), inner)
                        if name in merged:
                            raise Problem(src + (idx, "names", j), f"{name!r} is declared twice", inner.indices)
                        self.positions.copy(src + (idx, "names", j), dst + (name,), key=True, scope=inner)
                        merged[name] = {}
                continue
            scopes = [scope]
            body = part
            if "for" in part:
                body = {k: v for k, v in part.items() if k != "for"}
                scopes = self.families.family(part["for"], src + (idx, "for"), scope)
            for inner in scopes:
                for k, v in body.items():
                    name = self.subst.template(k, src + (idx, k), inner, key=True) if isinstance(k, str) else k
                    if name in merged:
                        raise Problem(src + (idx, k), f"{name!r} is given twice in {what}", inner.indices)
                    self.positions.copy(src + (idx, k), dst + (name,), key=True, scope=inner)
                    merged[name] = self._walk(v, src + (idx, k), dst + (name,), inner, logical + ("*",))
        return merged


def _value_at(data: Any, path: PathKey) -> Any:
    """The value at ``path`` of a document (None if there is none)."""
    for part in path:
        if (isinstance(data, dict) and part in data
                or isinstance(data, list) and isinstance(part, int) and 0 <= part < len(data)):
            data = data[part]
        else:
            return None
    return data


def _has_ode(game: dict) -> bool:
    dynamics = game.get("dynamics")
    return isinstance(dynamics, dict) and "ode" in dynamics


def names_taken(game: dict, parameters: dict, vectors: dict) -> dict[str, str]:
    """The names that mean something of their own in the game's expressions, and what each is: the functions, the
    constants, the parameters, and in a dynamic game the stage index tau and the time t, in one with an ode the
    sampling time dt. A definition or an index with one of these names would silently replace it."""
    out = {name: "a function" for name in (*FUNCTIONS, *AGGREGATES)}
    out.update((name, "a constant") for name in CONSTANTS)
    out.update((name, "a parameter") for name in (*parameters, *vectors))
    if game.get("kind") == "dynamic" or "horizon" in game:
        out["tau"], out["t"] = "the stage index tau", "the time t"
    if _has_ode(game):
        out["dt"] = "the sampling time dt"
    return out


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
