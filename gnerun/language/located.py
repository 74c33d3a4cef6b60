"""A problem at a place of a config document, found while its templates are counted (:mod:`gnerun.language.extent`)
or expanded (:mod:`gnerun.language.expand`), and which places of a game section hold expressions."""

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


class Problem(Exception):
    """A located problem: the document path, the message, the family indices it holds for."""

    def __init__(self, path: PathKey, message: str, bindings: dict[str, int] | None = None, *, key: bool = False,
                 column: int | None = None):
        super().__init__(message)
        self.path = path
        self.message = message
        self.bindings = dict(bindings or {})
        self.key = key  # located at the mapping key of ``path``
        self.column = column  # located at this character of the string at ``path``


def is_expression(logical: tuple) -> bool:
    """Whether the place ``logical`` (list indices and keys as "*") holds an expression."""
    return any(len(p) == len(logical) and all(a == "*" or a == b for a, b in zip(p, logical, strict=True))
               for p in EXPRESSIONS)
