"""Integer expressions, evaluated exactly: the indices ``name[i]``, the ranges ``a..b`` of families and aggregates, the
templates ``{...}``, and ``//`` and ``%`` where an expression of decision variables uses them.

An integer expression is an expression of :mod:`gnerun.language.expr` whose names are integers known when the config is
loaded (the indices in scope, the integer parameters and ``T``). Every value in it is an integer, checked node by node
and never rounded:

- ``+ - *``, ``**`` with a non-negative exponent (or a base of 1 or -1), ``abs``, ``min`` and ``max`` of integers
  are integers;
- ``//`` is floor division and ``%`` its remainder, with the sign of the divisor as in Python
  (``-1 // 4 == -1``, ``-1 % 4 == 3``): a ring's next neighbour is ``i % N + 1``;
- ``/`` divides exactly or is an error: ``i/N`` with i = 1 and N = 4 is 1/4, not an index (write ``i // N`` or
  ``i % N``), while ``N/2`` with N = 4 is 2;
- a number is a whole number (``2``, ``2.0``, ``1e3``), and another function's value must be one (``sqrt(N)`` with
  N = 9 is 3).

Values are doubles that hold integers, exact up to 2**53 (beyond that a value is out of range); the environment may
hold numpy arrays, one entry per copy of a family, to evaluate an expression for every copy at once
(:mod:`gnerun.language.extent`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from .expr import Binary, Call, Name, Node, Num, Unary, number_text, numpy_functions, unparse

LIMIT = 2.0**53  # doubles hold every integer up to this exactly
_HINT = "'/' divides exactly in an integer expression: write // for floor division and % for the remainder"


class IntegerError(ValueError):
    """A value of an integer expression that is not an integer (or out of range, or a division by zero), at the
    1-based ``column`` of the node in the text the tree was parsed from."""

    def __init__(self, message: str, column: int):
        super().__init__(message)
        self.message = message
        self.column = column


def _first(mask: Any, *arrays: Any) -> list[float]:
    """The entries of ``arrays`` where ``mask`` first holds (the copy of a family that fails first)."""
    mask, *arrays = (np.ravel(a) for a in np.broadcast_arrays(mask, *arrays))
    k = int(np.argmax(mask))
    return [float(a[k]) for a in arrays]


def _show(v: float) -> str:
    return number_text(float(v)) if np.isfinite(v) else str(float(v))


def _any(mask: Any) -> bool:
    return mask if isinstance(mask, bool) else bool(np.any(mask))


def _checked(v: Any, node: Node, what: Any) -> Any:
    """``v`` if every entry is an integer within range (``what()``: how the value is named in a message)."""
    if isinstance(v, float | int):  # one value (the expansion): plain floats, no arrays
        v = float(v)
        bad, big = not (math.isfinite(v) and v.is_integer()), abs(v) > LIMIT
    else:  # every copy of a family at once (the counts before expanding)
        v = np.asarray(v, dtype=float)
        bad = ~np.isfinite(v) | (v != np.round(v))
        big = ~bad & (np.abs(v) > LIMIT)
    if _any(bad):
        (x,) = _first(bad, v)
        raise IntegerError(f"{what()} is {_show(x)}, not an integer", node.column)
    if _any(big):
        (x,) = _first(big, v)
        raise IntegerError(f"{what()} = {x:.6g} is out of range (an integer expression stays within 2**53)",
                           node.column)
    return v + 0.0  # no negative zero


def _binary(n: Binary, a: Any, b: Any) -> Any:
    scalar = isinstance(a, float) and isinstance(b, float)
    if n.op in ("/", "//", "%"):
        zero = b == 0
        if _any(zero):
            x, y = _first(zero, a, b)
            raise IntegerError(f"{unparse(n)} is {_show(x)} {n.op} {_show(y)}, a division by zero", n.column)
        if n.op == "/":
            inexact = (a % b if scalar else np.mod(a, b)) != 0
            if _any(inexact):
                x, y = _first(inexact, a, b)
                raise IntegerError(f"{unparse(n)} is {_show(x)}/{_show(y)} = {_show(x / y)}, not an integer; {_HINT}",
                                   n.column)
        if scalar:
            return (a % b if n.op == "%" else a // b) + 0.0
        return (np.mod(a, b) if n.op == "%" else np.floor_divide(a, b)) + 0.0
    if n.op == "**":
        negative = (b < 0) & (abs(a) != 1)
        if _any(negative):
            x, y = _first(negative, a, b)
            raise IntegerError(f"{unparse(n)} is {_show(x)}**{_show(y)}, not an integer", n.column)
        big = (abs(a) > 1) & (b * np.log2(np.maximum(abs(a), 1)) > 53)
        if _any(big):
            x, y = _first(big, a, b)
            raise IntegerError(f"{unparse(n)} is {_show(x)}**{_show(y)}, out of range (an integer expression stays "
                               "within 2**53)", n.column)
        out = a**b if scalar else np.power(a, b)
    else:
        out = a + b if n.op == "+" else a - b if n.op == "-" else a * b
    return _checked(out, n, lambda: unparse(n))


def integer_value(node: Node, env: Mapping[str, Any]) -> Any:
    """The value of an integer expression (a double holding an integer, or an array of them), names bound by ``env``;
    :class:`IntegerError` at the first node whose value is not an integer. Every name must be in ``env``."""
    functions = _functions()
    values: list[Any] = []
    stack: list[tuple[Node, bool]] = [(node, False)]
    with np.errstate(all="ignore"):
        while stack:
            n, visited = stack.pop()
            if isinstance(n, Num):
                if not float(n.value).is_integer():
                    raise IntegerError(f"the number {number_text(n.value)} is not an integer", n.column)
                values.append(_checked(n.value, n, lambda n=n: number_text(n.value)))
            elif isinstance(n, Name):
                values.append(_checked(env[n.id], n, lambda n=n: n.id))
            elif not visited:
                stack.append((n, True))
                if isinstance(n, Unary):
                    stack.append((n.operand, False))
                elif isinstance(n, Binary):
                    stack.extend(((n.right, False), (n.left, False)))
                else:
                    stack.extend((a, False) for a in reversed(n.args))
            elif isinstance(n, Unary):
                v = values.pop()
                values.append(-v + 0.0 if n.op == "-" else v)
            elif isinstance(n, Binary):
                b = values.pop()
                a = values.pop()
                values.append(_binary(n, a, b))
            else:
                args = values[len(values) - len(n.args):]
                del values[len(values) - len(n.args):]
                values.append(_checked(functions[n.function](*args), n, lambda n=n: unparse(n)))
    return values[0]


@functools.cache
def _functions() -> dict:
    return numpy_functions()


def is_integer_expression(node: Node, integers: Mapping[str, Any]) -> str | None:
    """None if every name of the tree is one of ``integers`` (so it can be evaluated as an integer expression), or
    else the first other name."""
    stack = [node]
    while stack:
        n = stack.pop()
        if isinstance(n, Name):
            if n.id not in integers:
                return n.id
        elif isinstance(n, Unary):
            stack.append(n.operand)
        elif isinstance(n, Binary):
            stack.extend((n.right, n.left))
        elif isinstance(n, Call):
            stack.extend(reversed(n.args))
    return None
