"""Template expressions: the expressions of a many-agent config before expansion, as syntax trees.

A template expression is an expression of gnerun's language (:mod:`gnerun.language.expr`) that may also hold

- ``{E}``: an integer expression E of the indices in scope, the integer parameters and ``T``, either alone (a number,
  :class:`Hole`) or inside a name that starts with a letter (``x{i}``, ``px{i+1}``, ``x{i % N + 1}``: a
  :class:`Word`);
- ``name[i]``, ``name[i][j]``: an entry of a vector or matrix parameter (:class:`Entry`; no space before ``[``;
  ``w[i][i % N + 1]``);
- ``sum(E for k in a..b)`` (and ``prod``, ``max``, ``min``): an :class:`Aggregate` over an integer range (its ends may
  use ``min``, ``max``, ``//`` and ``%``: ``k in i+1..min(i+2, N)``);
- names of definitions and of the indices in scope (plain :class:`~gnerun.language.expr.Name` nodes).

Integer expressions (holes, indices, range ends) are evaluated exactly (:mod:`gnerun.language.integers`): ``//`` is
floor division, ``%`` its remainder, and ``/`` must divide exactly (``i/N`` with i = 1, N = 4 is an error, not 0.25
and not 0). Elsewhere ``a // b`` and ``a % b`` are written out as their values when both operands are integers known
then (``(i % 2)*x1``), and are an error otherwise (``x1 % 2``). Newlines are whitespace, like spaces and tabs.

:func:`parse_template` reads such a text into a tree of the expression nodes and these; the expander
(:mod:`gnerun.language.expand`) replaces every template node by plain nodes (numbers, the trees of definitions, the
terms of aggregates), and :func:`~gnerun.language.expr.unparse` writes the result with the parentheses its structure
needs. The expansion works on trees, never on text, so a number or a definition keeps its meaning wherever it lands:
a negative index value as the base of ``**``, a definition that is a power used as a base, a one-term ``max``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from ..errors import did_you_mean
from .expr import (
    BINARY_FUNCTIONS,
    FUNCTIONS,
    MAX_DEPTH,
    MAX_LENGTH,
    PRODUCTS,
    RELATIONS,
    UNARY_FUNCTIONS,
    VARIADIC_FUNCTIONS,
    Binary,
    Call,
    Expression,
    ExpressionError,
    Name,
    Node,
    Num,
    Unary,
    parse_expression,
)

AGGREGATES = ("sum", "prod", "max", "min")


@dataclass(frozen=True, slots=True)
class Hole:
    """``{E}`` alone: the integer E, a number."""

    expr: Expression
    column: int


@dataclass(frozen=True, slots=True)
class Word:
    """A name with templates in it (``x{i}``): literal text and integer expressions, in order."""

    pieces: tuple[str | Expression, ...]
    text: str
    column: int


@dataclass(frozen=True, slots=True)
class Entry:
    """``name[i]`` or ``name[i][j]``: an entry of a vector or matrix parameter (indices from 1)."""

    name: str
    indices: tuple[Node, ...]  # plain integer expressions
    column: int


@dataclass(frozen=True, slots=True)
class Aggregate:
    """``sum(E for k in a..b)``, ``prod``, ``max``, ``min``: E written out for k = a..b."""

    function: str
    body: object  # a template node
    index: str
    lo: Node  # plain integer expressions
    hi: Node
    range_text: str
    column: int


@dataclass(frozen=True, slots=True)
class Template:
    """A parsed template: an expression, or a constraint ``lhs relation rhs`` (``relation`` is None otherwise)."""

    text: str
    lhs: object
    relation: str | None = None
    rhs: object = None


_TOKEN = re.compile(
    r"""
    (?P<ws>[ \t\r\n]+)
  | (?P<number>(?:\d+(?:\.(?!\.)\d*)?|\.\d+)(?:[eE][+-]?\d+)?)
  | (?P<word>(?:[A-Za-z_]|\{[^{}]*\})(?:[A-Za-z0-9_]|\{[^{}]*\})*)
  | (?P<op>\*\*|<=|>=|==|\.\.|//|[-+*/^(),%\[\]])
    """,
    re.VERBOSE,
)
_PIECE = re.compile(r"\{([^{}]*)\}")
_IDENTIFIER = re.compile(r"[A-Za-z_]\w*")


@dataclass(frozen=True, slots=True)
class _Token:
    kind: str  # number | word | op | end
    text: str
    column: int  # 1-based
    end: int  # 1-based column just after the token


def _tokenize(text: str) -> list[_Token]:
    tokens: list[_Token] = []
    pos = 0
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if m is None:
            ch = text[pos]
            if ch in "{}":
                raise ExpressionError(f"unbalanced or nested braces in {text!r} (a template is {{integer expression}})",
                                      text, pos + 1)
            hint = {".": " (attribute access is not part of the language)",
                    "'": " (strings are not part of the language)", '"': " (strings are not part of the language)",
                    }.get(ch, " (comparisons are <=, >= and ==, and only in constraints)" if ch in "<>=!" else "")
            raise ExpressionError(f"unexpected character {ch!r}{hint}", text, pos + 1)
        kind = m.lastgroup or ""
        if kind != "ws":
            tokens.append(_Token(kind, m.group(), pos + 1, m.end() + 1))
        pos = m.end()
    tokens.append(_Token("end", "", len(text) + 1, len(text) + 1))
    return tokens


def integer_expression(text: str, expression: str, column: int) -> Expression:
    """The integer expression between braces or brackets, parsed (its errors located in ``expression``)."""
    try:
        return parse_expression(text)
    except ExpressionError as e:
        raise ExpressionError(f"in the integer expression {text.strip()!r}: {e.message}", expression,
                              column + e.column) from None


class _Parser:
    """The grammar of :mod:`gnerun.language.expr`, with templates, entries and aggregates in its atoms."""

    def __init__(self, text: str):
        self.text = text
        self.tokens = _tokenize(text)
        self.i = 0
        self.depth = 0

    def error(self, message: str, token: _Token | None = None) -> ExpressionError:
        return ExpressionError(message, self.text, (token or self.peek()).column)

    def peek(self) -> _Token:
        return self.tokens[self.i]

    def advance(self) -> _Token:
        tok = self.tokens[self.i]
        self.i += 1
        return tok

    def is_op(self, *texts: str) -> bool:
        tok = self.tokens[self.i]
        return tok.kind == "op" and tok.text in texts

    def expect(self, text: str) -> _Token:
        if not self.is_op(text):
            tok = self.peek()
            found = "end of expression" if tok.kind == "end" else repr(tok.text)
            raise self.error(f"expected {text!r}, found {found}")
        return self.advance()

    def enter(self) -> None:
        self.depth += 1
        if self.depth > MAX_DEPTH:
            raise self.error(f"expression nested deeper than {MAX_DEPTH} levels")

    def expr(self):
        self.enter()
        node = self.term()
        while self.is_op("+", "-"):
            tok = self.advance()
            node = Binary(tok.text, node, self.term(), tok.column)
        self.depth -= 1
        return node

    def term(self):
        node = self.unary()
        while self.is_op(*PRODUCTS):
            tok = self.advance()
            node = Binary(tok.text, node, self.unary(), tok.column)
        return node

    def unary(self):
        if self.is_op("+", "-"):
            tok = self.advance()
            self.enter()
            operand = self.unary()
            self.depth -= 1
            return Unary(tok.text, operand, tok.column)
        return self.power()

    def power(self):
        base = self.atom()
        if self.is_op("**", "^"):
            tok = self.advance()
            self.enter()
            exponent = self.unary()
            self.depth -= 1
            return Binary("**", base, exponent, tok.column)
        return base

    def atom(self):
        tok = self.peek()
        if tok.kind == "number":
            self.advance()
            value = float(tok.text)
            if value == float("inf"):
                raise self.error(f"number {tok.text!r} is out of range", tok)
            self.no_operand_after(tok)
            return Num(value, tok.column)
        if tok.kind == "word":
            self.advance()
            if "{" in tok.text:
                return self.templated(tok)
            if self.is_op("("):
                return self.call(tok)
            if self.is_op("["):
                return self.entry(tok)
            self.no_operand_after(tok)
            return Name(tok.text, tok.column)
        if self.is_op("("):
            self.advance()
            node = self.expr()
            self.expect(")")
            return node
        if tok.kind == "end":
            raise self.error("unexpected end of expression")
        raise self.error(f"unexpected {tok.text!r}")

    def no_operand_after(self, tok: _Token) -> None:
        nxt = self.peek()
        if nxt.kind in ("word", "number") and not (nxt.kind == "word" and nxt.text == "for"):
            raise self.error(f"unexpected {nxt.text!r} after {tok.text!r} (missing operator?)", nxt)

    def templated(self, tok: _Token):
        pieces: list[str | Expression] = []
        pos = 0
        for m in _PIECE.finditer(tok.text):
            if m.start() > pos:
                pieces.append(tok.text[pos:m.start()])
            pieces.append(integer_expression(m.group(1), self.text, tok.column + m.start()))
            pos = m.end()
        if pos < len(tok.text):
            pieces.append(tok.text[pos:])
        if len(pieces) == 1:  # {E} alone: a number
            self.no_operand_after(tok)
            if self.is_op("(", "["):
                raise self.error(f"unexpected {self.peek().text!r} after the number {tok.text!r}")
            return Hole(pieces[0], tok.column)  # type: ignore[arg-type]
        if not isinstance(pieces[0], str):
            raise self.error(f"{tok.text!r} is neither a number {{...}} nor a name: a templated name starts with a "
                             "letter or _ (x{i})", tok)
        if self.is_op("(", "["):
            what = "function" if self.is_op("(") else "vector or matrix parameter"
            raise self.error(f"the name of a {what} has no template in it ({tok.text!r})", tok)
        self.no_operand_after(tok)
        return Word(tuple(pieces), tok.text, tok.column)

    def entry(self, tok: _Token) -> Entry:
        indices = []
        while self.is_op("["):
            bracket = self.peek()
            previous = self.tokens[self.i - 1]
            if bracket.column != previous.end:
                raise self.error(f"a space before '[' in {tok.text!r}'s index: an entry is written {tok.text}[i] "
                                 "(no space before the brackets)", bracket)
            self.advance()
            self.enter()
            index = self.expr()
            self.depth -= 1
            self.expect("]")
            indices.append(self.plain(index, "an index", bracket))
        if self.is_op("["):  # pragma: no cover - the loop above takes every bracket
            raise self.error("unexpected '['")
        self.no_operand_after(tok)
        return Entry(tok.text, tuple(indices), tok.column)

    def plain(self, node, what: str, tok: _Token):
        """``node`` if it is a plain expression (an integer expression of indices and parameters)."""
        stack = [node]
        while stack:
            n = stack.pop()
            if isinstance(n, Unary):
                stack.append(n.operand)
            elif isinstance(n, Binary):
                stack.extend((n.left, n.right))
            elif isinstance(n, Call):
                stack.extend(n.args)
            elif not isinstance(n, Num | Name):
                raise self.error(f"{what} is an integer expression of indices, integer parameters and T (no "
                                 "templates, entries or aggregates in it)", tok)
        return node

    def call(self, name: _Token):
        fn = name.text
        if fn not in FUNCTIONS and fn not in AGGREGATES:
            raise self.error(f"unknown function {fn!r}{did_you_mean(fn, FUNCTIONS + AGGREGATES)} (functions: "
                             f"{', '.join(FUNCTIONS)})", name)
        self.expect("(")
        first = self.expr()
        if self.peek().kind == "word" and self.peek().text == "for":
            return self.aggregate(name, first)
        if fn not in FUNCTIONS:
            raise self.error(f"{fn}() is written {fn}(E for k in a..b)", name)
        args = [first]
        while self.is_op(","):
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

    def aggregate(self, name: _Token, body) -> Aggregate:
        if name.text not in AGGREGATES:
            raise self.error(f"'for' belongs in {', '.join(AGGREGATES)}(E for k in a..b), not in {name.text}()")
        self.advance()  # for
        index = self.advance()
        if index.kind != "word" or not _IDENTIFIER.fullmatch(index.text):
            raise self.error(f"expected an index name after 'for', found {index.text!r}", index)
        keyword = self.advance()
        if keyword.kind != "word" or keyword.text != "in":
            raise self.error(f"expected 'in' after 'for {index.text}'", keyword)
        start = self.peek()
        lo = self.plain(self.expr(), "a range's start", start)
        if not self.is_op(".."):
            raise self.error("a range is written a..b (both ends included)")
        self.advance()
        hi = self.plain(self.expr(), "a range's end", start)
        close = self.expect(")")
        return Aggregate(name.text, body, index.text, lo, hi, self.text[start.column - 1:close.column - 1].strip(),
                         name.column)

    def finish(self) -> None:
        tok = self.peek()
        if tok.kind != "end":
            if self.is_op(*RELATIONS):
                raise self.error(f"comparison {tok.text!r} is only allowed in a constraint")
            if self.is_op(")"):
                raise self.error("unbalanced ')'")
            raise self.error(f"unexpected {tok.text!r}")


def parse_template(text: str) -> Template:
    """Parse a template expression, or a template constraint ``lhs <= rhs`` (``>=``, ``==``); every mistake is an
    :class:`~gnerun.language.expr.ExpressionError` with its column."""
    if len(text) > MAX_LENGTH:
        raise ExpressionError(f"expression longer than {MAX_LENGTH} characters ({len(text)})", text, 1, whole=True)
    if not text.strip():
        raise ExpressionError("empty expression", text, 1)
    p = _Parser(text)
    lhs = p.expr()
    if not p.is_op(*RELATIONS):
        p.finish()
        return Template(text, lhs)
    relation = p.advance().text
    rhs = p.expr()
    if p.is_op(*RELATIONS):
        raise p.error("chained comparisons are not allowed: write one constraint per relation")
    p.finish()
    return Template(text, lhs, relation, rhs)


def is_plain(node) -> bool:
    """Whether a template tree holds no template node (no hole, templated name, entry or aggregate)."""
    stack = [node]
    while stack:
        n = stack.pop()
        if isinstance(n, Unary):
            stack.append(n.operand)
        elif isinstance(n, Binary):
            stack.extend((n.left, n.right))
        elif isinstance(n, Call):
            stack.extend(n.args)
        elif not isinstance(n, Num | Name):
            return False
    return True
