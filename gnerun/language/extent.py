"""The extent of a many-agent config, counted before it is expanded: family copies, aggregate terms and expression
nodes, without writing any of them out.

The counts walk the game section as the expander does (:mod:`gnerun.language.expand`), but a family's copies are
rows of numpy arrays, one column per index, and a range that depends on outer indices is evaluated for all their
values at once: ``for: {i: 1..N, j: i+1..N}`` is two vectorised steps, whatever N is, and a family over 1..10^12
whose inner range is always empty is refused at its first level (10^12 values of i to visit) without visiting one.
An expression's nodes are counted on its template tree: a definition counts the nodes it expands to (computed once,
so that definitions that double at every level are measured, not written out), an aggregate the nodes of its terms.

Everything is a lower bound of what the expansion writes (a construct whose size cannot be counted here, being
malformed, counts nothing and is reported by the expansion), so that a config refused here would be refused after
expanding it too, only later. The limits:

- :data:`MAX_ITEMS` index values visited and aggregate terms (every level of a family counts: an empty inner range
  costs its outer iterations);
- :data:`MAX_EXPRESSION_NODES` nodes in one expanded expression or definition (every node is at least one character,
  and an expression is at most that many characters long);
- :data:`MAX_NODES` expression nodes in the expanded game (its stages not counted).

Games within them may still be refused by their size (:mod:`gnerun.language.size`), which the expander estimates
from these counts before it writes anything.
"""

from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from .expr import MAX_LENGTH, Binary, Call, ExpressionError, Name, Unary, names_in
from .integers import IntegerError, integer_value
from .located import Problem, is_expression
from .templates import Aggregate, Template

if TYPE_CHECKING:
    from .expand import Expander
    from .yaml_source import PathKey

MAX_ITEMS = 100_000  # family index values visited and aggregate terms in one config
MAX_EXPRESSION_NODES = MAX_LENGTH  # one expanded expression: every node is at least one character of its text
MAX_NODES = 1_000_000  # expression nodes in the expanded game (stages not counted): about 10 s to expand and check


@dataclass
class Rows:
    """The copies in scope: the value of every index in each, one column per index (empty: one copy, no index)."""

    n: int
    columns: dict[str, np.ndarray] = field(default_factory=dict)


@dataclass
class Extent:
    """What a game section expands to (lower bounds): copies and keys per logical path (``("agents", "*")`` the
    agents, ``("agents", "*", "inputs", "*")`` their inputs), expression nodes by path, weighted by stages."""

    items: int = 0
    nodes: int = 0
    copies: dict[tuple, int] = field(default_factory=lambda: defaultdict(int))
    keys: dict[tuple, int] = field(default_factory=lambda: defaultdict(int))
    expression_nodes: dict[tuple, int] = field(default_factory=lambda: defaultdict(int))
    staged: dict[tuple, int] = field(default_factory=lambda: defaultdict(int))  # items with their own stages
    stages: int = 1  # of a dynamic game: T + 1


class _Unknown(Exception):
    """A construct the counts leave to the expansion (it reports what is wrong with it)."""


class Counter:
    """Counts one game section (see the module docstring), with the expander's parsed templates and scope."""

    def __init__(self, expander: Expander, base: dict[str, int]):
        self.x = expander
        self.base = base
        self.extent = Extent()
        self.definition_nodes: dict[str, int] = {}
        self._shapes: dict[int, tuple[int, list[Aggregate]]] = {}

    # the limits ----------------------------------------------------------------------------------------
    def _add_items(self, n: int, path: PathKey, what: str) -> None:
        self.extent.items += n
        if self.extent.items > MAX_ITEMS:
            raise Problem(path, f"the game expands to more than {MAX_ITEMS:,} family copies and aggregate terms "
                                 f"(the limit of one config; counted before expanding it, every value of an index "
                                 f"visited, an empty inner range included): {what}")

    def _check_nodes(self, n: int, path: PathKey, what: str) -> None:
        if n > MAX_EXPRESSION_NODES:
            raise Problem(path, f"{what} expands to {n:,.0f} expression nodes, more than one expression may hold "
                                 f"({MAX_EXPRESSION_NODES:,} characters; counted before expanding it)")

    # ranges --------------------------------------------------------------------------------------------
    def _env(self, rows: Rows) -> dict[str, Any]:
        return {**self.base, **rows.columns}

    def _vector(self, tree, rows: Rows) -> np.ndarray:
        """An integer expression for every copy (floats holding integers, :mod:`gnerun.language.integers`), or
        _Unknown."""
        env = self._env(rows)
        if not names_in(tree) <= set(env):
            raise _Unknown
        try:
            v = np.broadcast_to(np.asarray(integer_value(tree, env), dtype=float), (rows.n,))
        except IntegerError:
            raise _Unknown from None
        if np.any(np.abs(v) > 1e12):
            raise _Unknown
        return v

    def _range_text(self, text: Any, rows: Rows) -> tuple[np.ndarray, np.ndarray]:
        if isinstance(text, int) and not isinstance(text, bool):
            v = np.full(rows.n, float(text))
            return v, v
        if not isinstance(text, str) or text.count("..") != 1:
            raise _Unknown
        a, b = text.split("..")
        try:
            lo, hi = self.x.integer_tree(a), self.x.integer_tree(b)
        except ExpressionError:
            raise _Unknown from None
        return self._vector(lo, rows), self._vector(hi, rows)

    def _expand_rows(self, rows: Rows, name: str, lo: np.ndarray, hi: np.ndarray, path: PathKey,
                     what: str) -> Rows:
        lengths = np.maximum(hi - lo + 1, 0)
        total = float(lengths.sum())
        self._add_items(int(min(total, 10 * MAX_ITEMS)), path, what)
        counts = lengths.astype(np.int64)
        parent = np.repeat(np.arange(rows.n), counts)
        starts = np.repeat(np.cumsum(counts) - counts, counts)
        values = np.repeat(lo, counts) + (np.arange(int(total)) - starts)
        columns = {k: v[parent] for k, v in rows.columns.items()}
        columns[name] = values.astype(float)
        return Rows(int(total), columns)

    def family(self, spec: Any, rows: Rows, path: PathKey) -> Rows:
        if not isinstance(spec, dict) or not spec:
            raise _Unknown
        current = rows
        for name, text in spec.items():
            if not isinstance(name, str) or name in current.columns or name in self.base:
                raise _Unknown
            lo, hi = self._range_text(text, current)
            shown = ", ".join(f"{k}: {v}" for k, v in spec.items())
            current = self._expand_rows(current, name, lo, hi, path + (name,), f"for: {{{shown}}} takes "
                                        f"{float(np.maximum(hi - lo + 1, 0).sum()):,.0f} values of {name}")
        return current

    # expressions ---------------------------------------------------------------------------------------
    def _shape(self, node) -> tuple[int, list[Aggregate]]:
        """The nodes of a template tree outside its aggregates (a definition counts the nodes it expands to), and
        its outermost aggregates."""
        key = id(node)
        if key not in self._shapes:
            count, aggregates, stack = 0, [], [node]
            while stack:
                n = stack.pop()
                if isinstance(n, Aggregate):
                    aggregates.append(n)
                    continue
                if isinstance(n, Name):
                    count += self.definition_nodes.get(n.id, 1)
                    continue
                count += 1
                if isinstance(n, Unary):
                    stack.append(n.operand)
                elif isinstance(n, Binary):
                    stack.extend((n.left, n.right))
                elif isinstance(n, Call):
                    stack.extend(n.args)
            self._shapes[key] = (count, aggregates)
        return self._shapes[key]

    def nodes(self, node, rows: Rows, path: PathKey) -> np.ndarray:
        """The nodes ``node`` expands to in each copy."""
        count, aggregates = self._shape(node)
        total = np.full(rows.n, float(count))
        for a in aggregates:
            if a.index in rows.columns or a.index in self.base:
                continue
            try:
                lo, hi = self._vector(a.lo, rows), self._vector(a.hi, rows)
            except _Unknown:
                continue
            lengths = np.maximum(hi - lo + 1, 0)
            inner = self._expand_rows(rows, a.index, lo, hi, path, f"{a.function}(... for {a.index} in "
                                      f"{a.range_text}) takes {float(lengths.sum()):,.0f} terms")
            parent = np.repeat(np.arange(rows.n), lengths.astype(np.int64))
            terms = np.bincount(parent, weights=self.nodes(a.body, inner, path), minlength=rows.n)
            joins = np.maximum(lengths - 1, 0) if a.function in ("sum", "prod") else (lengths > 1)
            total += np.where(lengths > 0, terms + joins, 1.0)
        return total

    def template(self, template: Template, rows: Rows, path: PathKey, what: str) -> np.ndarray:
        n = self.nodes(template.lhs, rows, path)
        if template.relation is not None:
            n = n + self.nodes(template.rhs, rows, path)
        if rows.n:
            self._check_nodes(float(n.max()), path, what)
        return n


def game_section(expander: Expander, game: dict, base: dict[str, int]) -> Extent:
    """The extent of an (unexpanded) game section; raises the expander's problem past a limit."""
    section = _Section(Counter(expander, base), expander)
    section.definitions(game)
    one = Rows(1)
    for key, value in game.items():
        if key in ("definitions", "parameters"):
            continue
        if key == "dynamics" and isinstance(value, list):
            section.merged(value, one, ("dynamics",), ("game", key))
        else:
            section.walk(value, one, (key,), ("game", key))
    section.c.extent.stages = (base["T"] + 1) if "T" in base and game.get("kind") == "dynamic" else 1
    return section.c.extent


class _Section:
    """The walk of :func:`game_section` through a game section, counting into ``c``."""

    def __init__(self, c: Counter, expander: Expander):
        self.c = c
        self.x = expander

    def definitions(self, game: dict) -> None:
        """The nodes every definition expands to (a name counts as its definition's nodes)."""
        definitions = game.get("definitions")
        if not isinstance(definitions, dict):
            return
        for name, text in definitions.items():
            if not isinstance(name, str) or not isinstance(text, str | int | float) or isinstance(text, bool):
                continue
            path = ("game", "definitions", name)
            template = self.x.template(str(text), path)
            self.c.definition_nodes[name] = int(self.c.template(template, Rows(1), path, f"definition {name!r}")[0])

    def expression(self, text: str, rows: Rows, path: PathKey, logical: tuple, staged: bool) -> None:
        c = self.c
        template = self.x.template(text, path)
        n = c.template(template, rows, path, "this expression")
        total = float(n.sum())
        c.extent.nodes += int(total)
        if c.extent.nodes > MAX_NODES:
            raise Problem(path, f"the game expands to more than {MAX_NODES:,} expression nodes (the limit of one "
                                 f"config, its stages not counted; counted before expanding it): {total:,.0f} here")
        c.extent.expression_nodes[logical + (("staged",) if staged else ())] += int(total)

    def walk(self, value: Any, rows: Rows, logical: tuple, path: PathKey, staged: bool = False) -> None:
        if not rows.n:
            return
        if isinstance(value, dict):
            self._mapping(value, rows, logical, path, staged)
        elif isinstance(value, list):
            for idx, item in enumerate(value):
                if isinstance(item, dict) and "for" in item:
                    try:
                        inner = self.c.family(item["for"], rows, path + (idx, "for"))
                    except _Unknown:
                        continue
                    self.emit({k: v for k, v in item.items() if k != "for"}, inner, logical, path + (idx,))
                else:
                    self.c.extent.copies[logical + ("*",)] += rows.n
                    self.walk(item, rows, logical + ("*",), path + (idx,), staged)
        elif isinstance(value, str) and is_expression(logical) and logical[:1] != ("definitions",):
            self.expression(value, rows, path, logical, staged)

    def _mapping(self, value: dict, rows: Rows, logical: tuple, path: PathKey, staged: bool) -> None:
        c = self.c
        staged = staged or "stages" in value
        if staged and logical[:1] in (("agents",), ("shared_constraints",)):
            c.extent.staged[logical] += rows.n
        named = logical[-1:] in (("inputs",), ("variables",)) or logical == ("dynamics", "ode") or (
            logical == ("dynamics",) and not {"ode", "A", "B", "integrator", "dt"} & set(value))
        for k, v in value.items():
            if k == "for":
                continue
            if k in ("lower", "upper") and not (isinstance(v, int | float) and not isinstance(v, bool)
                                                and math.isfinite(v)):
                continue  # no bound, or one the counts do not read
            if k == "stages" and isinstance(v, str):
                try:
                    lo, hi = c._range_text(v, rows)
                except _Unknown:
                    continue
                c._add_items(int(min(float(np.maximum(hi - lo + 1, 0).sum()), 10 * MAX_ITEMS)), path + (k,),
                             f"stages: {v}")
                continue
            key = "*" if named else k
            c.extent.keys[logical + (key,)] += rows.n
            if named:
                c.extent.copies[logical + ("*",)] += rows.n
            if k == "ode" and logical == ("dynamics",) and isinstance(v, list):
                self.merged(v, rows, logical + ("ode",), path + (k,))
            elif k in ("variables", "inputs") and isinstance(v, list):
                self.merged(v, rows, logical + (k,), path + (k,))
            else:
                self.walk(v, rows, logical + (key,), path + (k,), staged)

    def emit(self, body: dict, rows: Rows, logical: tuple, path: PathKey) -> None:
        copies = self.c.extent.copies
        if set(body) in ({"values"}, {"names"}) and isinstance(next(iter(body.values())), list):
            copies[logical + ("*",)] += rows.n * len(next(iter(body.values())))
        elif set(body) == {"expr"}:
            copies[logical + ("*",)] += rows.n
            self.walk(body["expr"], rows, logical + ("*",), path + ("expr",))
        elif body:
            copies[logical + ("*",)] += rows.n
            self.walk(body, rows, logical + ("*",), path)

    def merged(self, value: list, rows: Rows, logical: tuple, path: PathKey) -> None:
        """The list form of dynamics and of an agent's variables or inputs: names, and mappings (families or not)."""
        copies = self.c.extent.copies
        for idx, part in enumerate(value):
            if isinstance(part, str):
                copies[logical + ("*",)] += rows.n
                continue
            if not isinstance(part, dict):
                continue
            inner = rows
            if "for" in part:
                try:
                    inner = self.c.family(part["for"], rows, path + (idx, "for"))
                except _Unknown:
                    continue
            body = {k: v for k, v in part.items() if k != "for"}
            if set(body) == {"names"} and isinstance(body["names"], list):
                copies[logical + ("*",)] += inner.n * len(body["names"])
            else:
                self.walk(body, inner, logical, path + (idx,))
