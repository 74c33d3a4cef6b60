"""Families and integers of the expansion (:mod:`gnerun.language.expand`): the scopes of a ``for:`` mapping's
copies, the ranges ``a..b`` and the integer expressions of indices, integer parameters and ``T``, and the bounds
of the expansion (:data:`~gnerun.language.extent.MAX_ITEMS` copies and terms, a wall-clock budget)."""

from __future__ import annotations

import math
import re
import time
from dataclasses import dataclass, field
from typing import Any

from ..errors import did_you_mean
from .expr import ExpressionError, Node, first_column_of, names_in, parse_expression
from .extent import MAX_ITEMS
from .integers import IntegerError, integer_value
from .located import Problem
from .yaml_source import PathKey

EXPANSION_SECONDS = 60.0  # the expansion's wall-clock budget behind the estimate (a game at the limits: ~10 s)
NAME = re.compile(r"(?<![\w.])([A-Za-z_]\w*)")


@dataclass(frozen=True)
class Scope:
    """The integers a template may use: integer parameters and T (``base``), and the indices of the families
    and aggregates around it, innermost last."""

    base: dict[str, int]
    indices: dict[str, int] = field(default_factory=dict)

    def env(self) -> dict[str, int]:
        return {**self.base, **self.indices}

    def bind(self, name: str, value: int) -> Scope:
        return Scope(self.base, {**self.indices, name: value})


class Families:
    """The families, ranges and integer expressions of one expansion, and its budget of items and time.
    ``definitions`` is the expansion's table of definitions (an index may not take a definition's name)."""

    def __init__(self, definitions: dict[str, Node]):
        self.definitions = definitions
        self.runtime: set[str] = set()  # runtime parameters: not integers known at expansion
        # names an index may not take, and what each is (functions, constants, parameters, tau, t, dt: see
        # expand.names_taken); the names of variables, inputs and states are only known once expanded: ``used``
        # holds where each index name was first taken, for the expander to check against them
        self.reserved: dict[str, str] = {}
        self.used: dict[str, tuple[PathKey, int | None, dict[str, int]]] = {}
        self.items = 0
        self.integers: dict[str, Any] = {}  # integer expressions, parsed once per text
        self.ticks = 0
        self.deadline = math.inf

    def start(self) -> None:
        """Start the expansion's wall clock."""
        self.deadline = time.perf_counter() + EXPANSION_SECONDS

    def integer_tree(self, text: str) -> Node:
        """An integer expression's tree, parsed once per text (ExpressionError if it does not parse)."""
        parsed = self.integers.get(text)
        if parsed is None:
            parsed = self.integers[text] = parse_expression(text).tree
        return parsed

    def family(self, spec: Any, path: PathKey, scope: Scope) -> list[Scope]:
        """The scopes of a ``for`` mapping's copies, in order (nested in the order written), counted before
        they are built."""
        if not isinstance(spec, dict) or not spec:
            raise Problem(path, "for: must map index names to ranges a..b, e.g. {i: 1..N}", scope.indices)
        names = list(spec)
        for name in names:
            if not isinstance(name, str) or NAME.fullmatch(name) is None:
                raise Problem(path, f"an index must be a name, not {name!r}", scope.indices)
            if name in scope.base or name in scope.indices:
                raise Problem(path, f"index {name!r} is already in use here (a parameter, T or an outer index)",
                               scope.indices)
            if name in self.definitions:
                raise Problem(path, f"index {name!r} is the name of a definition", scope.indices)
            self.take(name, path, None, scope)
        scopes: list[Scope] = []
        described = "the family for: {" + ", ".join(f"{k}: {v}" for k, v in spec.items()) + "}"

        def nest(level: int, current: Scope) -> None:
            if level == len(names):
                self.count(1, path, current)
                scopes.append(current)
                return
            name = names[level]
            lo, hi = self.range(spec[name], path + (name,), current)
            if level == len(names) - 1 and self.items + max(0, hi - lo + 1) > MAX_ITEMS:
                self.count(max(0, hi - lo + 1), path, current)  # refused before the copies are built
            for v in range(lo, hi + 1):
                self.tick(path, current, described)
                nest(level + 1, current.bind(name, v))

        nest(0, scope)
        return scopes

    def take(self, name: str, path: PathKey, column: int | None, scope: Scope) -> None:
        """An index named ``name`` is declared at ``path`` (``column``: of an aggregate in an expression): refused where
        it has a reserved name, which inside its scope it would silently replace."""
        what = self.reserved.get(name)
        if what is not None:
            raise Problem(path, f"index {name!r} has the name of {what}, which it would replace in the expressions of "
                                "its scope; choose another name", scope.indices, column=column)
        self.used.setdefault(name, (path, column, dict(scope.indices)))

    def count(self, n: int, path: PathKey, scope: Scope) -> None:
        self.items += n
        if self.items > MAX_ITEMS:
            raise Problem(path, f"the game expands to more than {MAX_ITEMS} family copies and aggregate terms "
                                 "(the limit of one config)", scope.indices)

    def tick(self, path: PathKey, scope: Scope, what: str = "this expression") -> None:
        """The wall-clock budget of the expansion, the last guard behind the estimate (checked every 4,096 nodes)."""
        self.ticks += 1
        if self.ticks & 4095 == 0 and time.perf_counter() > self.deadline:
            raise Problem(path, f"expanding {what} took more than {EXPANSION_SECONDS:g} s (the expansion's time "
                                 "limit); write the game with fewer or smaller families, sums or definitions",
                           scope.indices)

    def range(self, text: Any, path: PathKey, scope: Scope) -> tuple[int, int]:
        if isinstance(text, int) and not isinstance(text, bool):
            return text, text
        if not isinstance(text, str) or text.count("..") != 1:
            raise Problem(path, f"a range is written a..b (both ends included), not {text!r}", scope.indices)
        a, b = text.split("..")
        at = (1, len(a) + 3)  # the columns where the two ends begin
        return self.bounds(self._parsed_integer(a, path, scope, at[0]), self._parsed_integer(b, path, scope, at[1]),
                           text.strip(), path, scope, at)

    def bounds(self, lo: Node, hi: Node, text: str, path: PathKey, scope: Scope,
               at: tuple[int, int] = (1, 1)) -> tuple[int, int]:
        """The ends of a range (their trees' columns counted from ``at``, the columns of the string at ``path`` where
        each begins). One that uses no index (a count given by parameters) may be empty (b = a - 1) but not shorter:
        a negative count is a mistake, not an empty family."""
        a = self.value(lo, text.split("..")[0], path, scope, at[0])
        b = self.value(hi, text.split("..")[-1], path, scope, at[1])
        used = names_in(lo) | names_in(hi)
        if b < a - 1 and not used & set(scope.indices):
            given = ", ".join(f"{k} = {scope.base[k]}" for k in sorted(used) if k in scope.base)
            raise Problem(path, f"the range {text!r} is {a}..{b}, a negative count ({b - a + 1} values"
                                 + (f", with {given}" if given else "") + f"): a range may be empty ({a}..{a - 1}) "
                                 "but not shorter", scope.indices)
        return a, b

    def _parsed_integer(self, text: str, path: PathKey, scope: Scope, at: int | None) -> Node:
        try:
            return self.integer_tree(text)
        except ExpressionError as e:
            raise Problem(path, f"in the integer expression {text.strip()!r}: {e.message}", scope.indices,
                          column=None if at is None else at - 1 + e.column) from None

    def integer(self, text: str, path: PathKey, scope: Scope, at: int | None = None) -> int:
        """The integer expression ``text``, which begins at column ``at`` of the string at ``path``."""
        return self.value(self._parsed_integer(text, path, scope, at), text, path, scope, at)

    def value(self, tree: Node, text: str, path: PathKey, scope: Scope, at: int | None = None) -> int:
        """An integer expression of the indices in scope, the integer parameters and T, evaluated exactly
        (:mod:`gnerun.language.integers`); a problem is located at its node, counting the tree's columns from ``at``
        (the column of the string at ``path`` where ``text`` begins; None: at the string)."""
        env = scope.env()

        def column(c: int | None) -> int | None:
            return None if at is None or c is None else at - 1 + c

        for name in names_in(tree):
            if name in self.runtime and name not in env:
                raise Problem(path, f"{name!r} in {text.strip()!r} is a runtime parameter; ranges, templates and "
                                     "indices need integers known when the game is compiled (declare it under "
                                     "parameters)", scope.indices, column=column(first_column_of(tree, name)))
            if name not in env:
                known = ", ".join(sorted(env)) or "none"
                raise Problem(path, f"{name!r} in {text.strip()!r} is not an index, an integer parameter or T"
                                     f"{did_you_mean(name, env)} (known here: {known})", scope.indices,
                              column=column(first_column_of(tree, name)))
        try:
            value = float(integer_value(tree, env))
        except IntegerError as e:
            raise Problem(path, f"in the integer expression {text.strip()!r}: {e.message}", scope.indices,
                          column=column(e.column)) from None
        if abs(value) > 10**12:
            shown = f"{value:.0f}" if abs(value) < 2**53 else f"about {value:.6g}"  # (a double past 2**53 is not exact)
            raise Problem(path, f"{text.strip()!r} = {shown} is out of range", scope.indices, column=column(1))
        return int(value)


class quiet:
    """numpy's floating-point warnings off while an expression is evaluated (its value is checked after)."""

    def __enter__(self):
        import numpy as np

        self._old = np.seterr(all="ignore")

    def __exit__(self, *exc):
        import numpy as np

        np.seterr(**self._old)
