"""A problem at a place of a config document, found while its templates are counted (:mod:`gnerun.language.extent`)
or expanded (:mod:`gnerun.language.expand`), and which places of a game section hold expressions and numbers."""

from __future__ import annotations

from .yaml_source import PathKey

# where a string is an expression (indices are numbers there, sums and parameter indexing are written out);
# "*" stands for any list index or mapping key
EXPRESSIONS = (
    ("agents", "*", "stage_cost"), ("agents", "*", "terminal_cost"), ("agents", "*", "cost"),
    ("agents", "*", "constraints", "*"), ("agents", "*", "constraints", "*", "expr"),
    ("shared_constraints", "*"), ("shared_constraints", "*", "expr"),
    ("dynamics", "*"), ("dynamics", "ode", "*"), ("definitions", "*"),
)


# where a string is a number written as an expression of parameters and indices (evaluated when the config is loaded)
NUMBERS = tuple(("agents", "*", kind, "*", field) for kind in ("variables", "inputs")
                for field in ("lower", "upper", "start")) + (
    ("agents", "*", "inputs", "*", "start", "*"), ("x0", "*"), ("dynamics", "dt"),
)


class Problem(Exception):
    """A located problem: the document path, the message, the family indices it holds for."""

    def __init__(self, path: PathKey, message: str, bindings: dict[str, int] | None = None, *, key: bool = False,
                 column: int | None = None, quote: bool = False):
        super().__init__(message)
        self.path = path
        self.message = message
        self.bindings = dict(bindings or {})
        self.key = key  # located at the mapping key of ``path``
        self.column = column  # located at this character of the string at ``path``
        self.quote = quote  # the message says at which column of the string (a string written on one line)


def _matches(logical: tuple, places: tuple) -> bool:
    return any(len(p) == len(logical) and all(a == "*" or a == b for a, b in zip(p, logical, strict=True))
               for p in places)


def is_expression(logical: tuple) -> bool:
    """Whether the place ``logical`` (list indices and keys as "*") holds an expression."""
    return _matches(logical, EXPRESSIONS)


def is_number(logical: tuple) -> bool:
    """Whether the place ``logical`` holds a number, which may be written as an expression of parameters (a bound, a
    start value, an entry of x0, the ode's dt)."""
    return _matches(logical, NUMBERS)
