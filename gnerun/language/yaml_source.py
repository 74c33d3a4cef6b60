"""YAML documents with the file position of every node, for file:line:column messages.

PyYAML's composer gives every node a start mark; we build the plain Python data from the node
tree ourselves so that each value's path (``("game", "agents", 0, "cost")``) maps to the line and
column where it was written. Duplicate keys, which PyYAML silently accepts, are errors here.
"""

from __future__ import annotations

import functools
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from ..errors import ConfigError, InputError, excerpt, shorten
from ..files import read_regular

MAX_CONFIG_BYTES = 1_000_000
MAX_NODES = 200_000
MAX_DEPTH = 64  # nested mappings and sequences; a config needs about 6

# Plain data only: tags that construct Python objects (!!python/...), binary data, sets or
# custom tags are refused, whether written explicitly or not.
_PLAIN_TAGS = {"tag:yaml.org,2002:" + t for t in ("str", "int", "float", "bool", "null", "seq", "map", "timestamp")}

PathKey = tuple[str | int, ...]


@dataclass(frozen=True)
class Position:
    line: int  # 1-based
    column: int  # 1-based
    quoted: bool = False  # a single-line quoted scalar: its text starts one column later
    single_line: bool = True
    span: tuple[int, int] | None = None  # a scalar written over several lines: where its source is in the text


@dataclass(frozen=True)
class Origin:
    """Where a character of an expanded expression was written: ``column`` of the string ``text`` at ``path`` of the
    document (a template, or a ``definition`` used in it)."""

    path: PathKey
    text: str
    column: int
    definition: bool = False


# the token that starts at a character of an expression: a (templated) name, a number, an operator
_TOKEN_AT = re.compile(r"(?:[A-Za-z_]|\{[^{}]*\})(?:[A-Za-z0-9_]|\{[^{}]*\})*|\d+(?:\.\d*)?(?:[eE][+-]?\d+)?"
                       r"|\*\*|<=|>=|==|//")


@dataclass
class SourceMap:
    """Where each value (and each mapping key) of a document was written."""

    file: str
    values: dict[PathKey, Position] = field(default_factory=dict)
    keys: dict[PathKey, Position] = field(default_factory=dict)
    overridden: dict[PathKey, str] = field(default_factory=dict)  # path -> its override (`--set a.b=1`)
    notes: dict[PathKey, str] = field(default_factory=dict)  # path -> e.g. "for i = 2" (a family's copy)
    text: str = field(default="", repr=False)  # the document's text (for the lines of multi-line scalars)
    # an expanded document's: the template a character of an expression came from (gnerun.language.expand), and the
    # source map of the document as written
    origins: Callable[[PathKey, int, str], Origin | None] | None = field(default=None, repr=False)
    source: SourceMap | None = field(default=None, repr=False)

    def locate(self, path: PathKey, *, key: bool = False) -> str:
        """``file:line:column`` of the value (or key) at ``path``, or of its nearest written ancestor."""
        p = tuple(path)
        for n in range(len(p), 0, -1):
            if p[:n] in self.overridden:
                return shorten(self.overridden[p[:n]], 100)
        if not self.values and not self.keys:  # data without a text (a config given as a dict)
            return f"{self.file}, at {dotted(p)}"
        if key and p in self.keys:
            pos = self.keys[p]
            return f"{self.file}:{pos.line}:{pos.column}{self._note(p)}"
        while p and p not in self.values:
            p = p[:-1]
        pos = self.values.get(p, Position(1, 1))
        return f"{self.file}:{pos.line}:{pos.column}{self._note(tuple(path))}"

    def has(self, path: PathKey) -> bool:
        """Whether the value at ``path`` was written (in the text or by an override), not filled in by a default."""
        p = tuple(path)
        return p in self.values or any(p[:n] in self.overridden for n in range(len(p), 0, -1))

    def _note(self, path: PathKey) -> str:
        """`` (for i = 2, j = 3)`` when ``path`` lies in a copy of a family (the index values that made it)."""
        for n in range(len(path), 0, -1):
            if path[:n] in self.notes:
                return f" ({self.notes[path[:n]]})"
        return ""

    def locate_in_text(self, path: PathKey, column: int, *, key: bool = False, text: str | None = None) -> str:
        """Position of character ``column`` (1-based) of the string value (or ``key``) at ``path``. A value written
        over several lines (a YAML block scalar ``>-``) is located on its line when its ``text`` is given and is the
        one written there; otherwise at its start."""
        p = tuple(path)
        pos = (self.keys if key else self.values).get(p)
        if pos is None or any(p[:n] in self.overridden for n in range(len(p), 0, -1)):
            return self.locate(p, key=key)
        line, col = self.character(p, column, key=key, text=text) or (pos.line, pos.column)
        return f"{self.file}:{line}:{col}{self._note(p) if not pos.single_line else ''}"

    def character(self, path: PathKey, column: int, *, key: bool = False,
                  text: str | None = None) -> tuple[int, int] | None:
        """Line and column in the file of character ``column`` of the string at ``path`` (see :meth:`locate_in_text`);
        None where it is not known."""
        p = tuple(path)
        pos = (self.keys if key else self.values).get(p)
        if pos is None or any(p[:n] in self.overridden for n in range(len(p), 0, -1)):
            return None
        if not pos.single_line:
            return self._in_lines(pos, column, text)
        return pos.line, pos.column + column - 1 + (1 if pos.quoted else 0)

    def point(self, path: PathKey, column: int, text: str, *, key: bool = False,
              quote: bool = True) -> tuple[str, PathKey, str]:
        """Where character ``column`` of the expression ``text`` at ``path`` was written, the path to name there, and
        how to show it: an excerpt of the file (the line and a caret under the character, on the lines after the
        message) where the text was written over several lines, else (``quote``) `` at column c of expression
        'text'``. An expanded expression is followed back to the template (or definition) it came from
        (``origins``): the position, the column and the text shown are the template's."""
        origin = self.origins(path, column, text) if self.origins is not None and not key else None
        if origin is None or self.source is None:
            smap, at = self, tuple(path)
            where = self.locate_in_text(at, column, key=key, text=text)
        else:
            smap, at, column, text = self.source, origin.path, origin.column, origin.text
            found = smap.character(at, column, text=text)
            where = (f"{smap.file}:{found[0]}:{found[1]}" if found else smap.locate(at)) + (
                "" if origin.definition else self._note(tuple(path)))
        pos = (smap.keys if key else smap.values).get(at)
        found = smap.character(at, column, key=key, text=text)
        if found is not None and pos is not None and not pos.single_line and smap.text:
            line = smap.lines[found[0] - 1]
            token = _TOKEN_AT.match(text, column - 1)
            return where, at, "\n" + excerpt(line, found[0], found[1], len(token.group()) if token else 1)
        shown = text if len(text) <= 120 else text[:117] + "..."
        return where, at, f" at column {column} of expression {shown!r}" if quote else ""

    @functools.cached_property
    def lines(self) -> list[str]:
        """The document's lines (split once)."""
        return self.text.split("\n")  # (as positions count lines: by their newlines)

    def _in_lines(self, pos: Position, column: int, text: str | None) -> tuple[int, int] | None:
        """Line and column of character ``column`` of ``text``, a scalar written over several lines at ``pos``: the
        characters that are not whitespace are the same in the value and in its source (YAML folds only whitespace),
        so the k-th of the value is the k-th of the source; None where they are not (escapes, a rewritten text)."""
        if pos.span is None or text is None or not self.text:
            return None
        start, end = pos.span
        if self.text[start] in "|>":  # a block scalar: its text begins on the line after the indicator
            start = self.text.find("\n", start, end) + 1
            if not start:
                return None
        elif self.text[start] in "'\"":
            start += 1
        wanted = [c for c in text if not c.isspace()]
        at: list[int] = []  # where the characters of the value that are not whitespace are in the document
        for i in range(start, end):
            if len(at) == len(wanted):
                break
            if not self.text[i].isspace():
                at.append(i)
        if not at or [self.text[i] for i in at] != wanted:
            return None
        k = sum(1 for c in text[:max(column - 1, 0)] if not c.isspace())
        return self._line_column(at[k] if k < len(at) else at[-1] + 1)

    def _line_column(self, index: int) -> tuple[int, int]:
        before = self.text[:index]
        return before.count("\n") + 1, index - (before.rfind("\n") + 1) + 1


def _mark_to_position(node: yaml.Node) -> Position:
    mark = node.start_mark
    end = node.end_mark
    quoted = isinstance(node, yaml.ScalarNode) and node.style in ("'", '"')
    single = mark.line == end.line
    span = (mark.index, end.index) if isinstance(node, yaml.ScalarNode) and not single else None
    return Position(mark.line + 1, mark.column + 1, quoted=quoted, single_line=single, span=span)


def _yaml_error_position(err: yaml.YAMLError, file: str) -> str:
    mark = getattr(err, "problem_mark", None) or getattr(err, "context_mark", None)
    problem = getattr(err, "problem", None) or str(err).splitlines()[0]
    context = getattr(err, "context", None)
    where = f"{file}:{mark.line + 1}:{mark.column + 1}" if mark is not None else f"{file}:1:1"
    if "maximum nesting depth" in str(problem):  # libyaml's own bound, far above ours
        return f"{where}: the document is nested deeper than {MAX_DEPTH} levels"
    text = f"{context}, {problem}" if context else problem
    return f"{where}: YAML syntax error: {text}"


def _build(node: yaml.Node, path: PathKey, smap: SourceMap, loader: yaml.SafeLoader, problems: list[str]) -> Any:
    pos = _mark_to_position(node)  # size and depth are bounded by _check_expansion
    where = f"{smap.file}:{pos.line}:{pos.column}"
    if node.tag not in _PLAIN_TAGS:
        tag = node.tag.replace("tag:yaml.org,2002:", "!!")
        raise ConfigError([f"{where}: the YAML tag {tag!r} is not allowed: configs hold plain data "
                           "(mappings, lists, strings, numbers, booleans)"])
    smap.values[path] = pos
    if isinstance(node, yaml.MappingNode):
        loader.flatten_mapping(node)
        out: dict[Any, Any] = {}
        for key_node, value_node in node.value:
            key = loader.construct_object(key_node, deep=True)
            if not isinstance(key, str | int | float | bool) or key is None:
                pos = _mark_to_position(key_node)
                problems.append(f"{smap.file}:{pos.line}:{pos.column}: keys must be plain names")
                continue
            if isinstance(key, bool | float):
                key = str(key).lower() if isinstance(key, bool) else str(key)
            if key in out:
                pos = _mark_to_position(key_node)
                problems.append(f"{smap.file}:{pos.line}:{pos.column}: {dotted(path + (key,))}: duplicate key")
                continue
            smap.keys[path + (key,)] = _mark_to_position(key_node)
            out[key] = _build(value_node, path + (key,), smap, loader, problems)
        return out
    if isinstance(node, yaml.SequenceNode):
        return [_build(v, path + (i,), smap, loader, problems) for i, v in enumerate(node.value)]
    try:
        return loader.construct_object(node, deep=True)
    except (ValueError, OverflowError):  # e.g. an integer with more digits than Python converts
        shown = node.value if len(node.value) <= 40 else node.value[:37] + "..."
        raise ConfigError([f"{where}: {dotted(path)}: cannot read {shown!r} ({len(node.value)} characters) "
                           "as a number"]) from None


if getattr(yaml, "__with_libyaml__", False):
    from yaml._yaml import CParser

    class _Parser(yaml.composer.Composer, CParser, yaml.constructor.SafeConstructor, yaml.resolver.Resolver):
        """libyaml's scanner and parser (8 times faster on a config of 5,000 agents) under PyYAML's composer, whose
        recursion the loader below bounds."""

        def __init__(self, text: str):
            if yaml.reader.Reader.NON_PRINTABLE.search(text):  # the pure-Python reader's check, with its position
                yaml.SafeLoader(text)
            CParser.__init__(self, text)
            yaml.composer.Composer.__init__(self)
            yaml.constructor.SafeConstructor.__init__(self)
            yaml.resolver.Resolver.__init__(self)

        def dispose(self) -> None:
            pass
else:  # pragma: no cover - PyYAML built without libyaml
    _Parser = yaml.SafeLoader


class _Loader(_Parser):
    """A safe loader whose (recursive) composer refuses collections nested deeper than MAX_DEPTH."""

    def __init__(self, text: str, file: str):
        super().__init__(text)
        self.file = file
        self.depth = 0

    def compose_node(self, parent: yaml.Node | None, index: Any) -> yaml.Node:
        collection = self.check_event(yaml.SequenceStartEvent, yaml.MappingStartEvent)
        if collection:
            self.depth += 1
            if self.depth > MAX_DEPTH:
                m = self.peek_event().start_mark
                raise ConfigError([f"{self.file}:{m.line + 1}:{m.column + 1}: the document is nested deeper "
                                   f"than {MAX_DEPTH} levels"])
        try:
            return super().compose_node(parent, index)
        finally:
            if collection:
                self.depth -= 1


def _check_expansion(root: yaml.Node, file: str) -> None:
    """Refuse alias bombs, recursive aliases and nesting through aliases on the node graph, before a
    single value is built: sizes and heights are counted once per node."""
    sizes: dict[int, tuple[int, int]] = {}  # id(node) -> (nodes when expanded, height)
    open_: set[int] = set()

    def refuse(node: yaml.Node, what: str) -> ConfigError:
        m = node.start_mark
        return ConfigError([f"{file}:{m.line + 1}:{m.column + 1}: {what}"])

    def visit(node: yaml.Node, depth: int) -> tuple[int, int]:
        key = id(node)
        if key in open_:
            raise refuse(node, "a recursive alias (an anchor used inside itself)")
        if key not in sizes:
            if depth > MAX_DEPTH:
                raise refuse(node, f"the document is nested deeper than {MAX_DEPTH} levels")
            open_.add(key)
            children: list[yaml.Node] = []
            if isinstance(node, yaml.MappingNode):
                children = [n for pair in node.value for n in pair]
            elif isinstance(node, yaml.SequenceNode):
                children = list(node.value)
            size, height = 1, 1
            for child in children:
                s, h = visit(child, depth + 1)
                size += s
                height = max(height, h + 1)
                if size > MAX_NODES:
                    raise refuse(node, f"the document expands to more than {MAX_NODES} values (an alias bomb?)")
            open_.discard(key)
            sizes[key] = (size, height)
        size, height = sizes[key]
        if depth + height - 1 > MAX_DEPTH:
            raise refuse(node, f"the document is nested deeper than {MAX_DEPTH} levels (through aliases)")
        return size, height

    visit(root, 1)


def _reader_error_position(err: yaml.reader.ReaderError, text: str, file: str) -> str:
    before = text[: err.position]
    line = before.count("\n") + 1
    column = err.position - (before.rfind("\n") + 1) + 1
    return f"{file}:{line}:{column}: not a YAML text: character U+{err.character:04X} is not allowed"


_PLAIN_KEY = re.compile(r"[\w\-]+")


def dotted(path: PathKey, empty: str = "<document>") -> str:
    """``game.agents.0.cost``; a key that is not a plain name is quoted (``solver.' tol'``)."""
    return ".".join(str(p) if isinstance(p, int) or _PLAIN_KEY.fullmatch(p) else repr(p) for p in path) or empty


def read_yaml(path: str | Path) -> tuple[Any, SourceMap]:
    """Read a YAML file into plain data and its :class:`SourceMap`; every problem is a ConfigError."""
    file = str(path)
    try:  # a regular file only (a device or a FIFO is refused unread), read up to the limit
        raw = read_regular(path, MAX_CONFIG_BYTES, "config file")
    except InputError as e:
        raise ConfigError([str(e)]) from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise ConfigError([f"{file}: not UTF-8 text (byte {e.start})"]) from None
    return parse_yaml(text, file)


def parse_yaml(text: str, file: str = "<string>") -> tuple[Any, SourceMap]:
    smap = SourceMap(file, text=text)
    problems: list[str] = []
    try:
        loader = _Loader(text, file)  # a str is checked for special characters here, at once
    except yaml.reader.ReaderError as e:
        raise ConfigError([_reader_error_position(e, text, file)]) from None
    try:
        node = loader.get_single_node()
        if node is None:
            raise ConfigError([f"{file}:1:1: the config is empty"])
        _check_expansion(node, file)
        data = _build(node, (), smap, loader, problems)
    except yaml.YAMLError as e:
        raise ConfigError([_yaml_error_position(e, file)]) from None
    except RecursionError:  # a backstop: depth and recursive aliases are caught above
        raise ConfigError([f"{file}:1:1: the document is nested too deeply"]) from None
    finally:
        loader.dispose()
    if problems:
        raise ConfigError(problems)
    return data, smap
