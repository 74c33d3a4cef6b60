"""YAML documents with the file position of every node, for file:line:column messages.

PyYAML's composer gives every node a start mark; we build the plain Python data from the node
tree ourselves so that each value's path (``("game", "agents", 0, "cost")``) maps to the line and
column where it was written. Duplicate keys, which PyYAML silently accepts, are errors here.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from .errors import ConfigError

MAX_CONFIG_BYTES = 1_000_000
MAX_NODES = 200_000

PathKey = tuple[str | int, ...]


@dataclass(frozen=True)
class Position:
    line: int  # 1-based
    column: int  # 1-based
    quoted: bool = False  # a single-line quoted scalar: its text starts one column later
    single_line: bool = True


@dataclass
class SourceMap:
    """Where each value (and each mapping key) of a document was written."""

    file: str
    values: dict[PathKey, Position] = field(default_factory=dict)
    keys: dict[PathKey, Position] = field(default_factory=dict)
    overridden: dict[PathKey, str] = field(default_factory=dict)  # path -> the --set text

    def locate(self, path: PathKey, *, key: bool = False) -> str:
        """``file:line:column`` of the value (or key) at ``path``, or of its nearest written ancestor."""
        p = tuple(path)
        for n in range(len(p), 0, -1):
            if p[:n] in self.overridden:
                return f"--set {self.overridden[p[:n]]}"
        if key and p in self.keys:
            pos = self.keys[p]
            return f"{self.file}:{pos.line}:{pos.column}"
        while p and p not in self.values:
            p = p[:-1]
        pos = self.values.get(p, Position(1, 1))
        return f"{self.file}:{pos.line}:{pos.column}"

    def locate_in_text(self, path: PathKey, column: int) -> str:
        """Position of character ``column`` (1-based) of the string value at ``path``."""
        p = tuple(path)
        pos = self.values.get(p)
        if pos is None or any(p[:n] in self.overridden for n in range(len(p), 0, -1)):
            return self.locate(p)
        if not pos.single_line:
            return f"{self.file}:{pos.line}:{pos.column}"
        return f"{self.file}:{pos.line}:{pos.column + column - 1 + (1 if pos.quoted else 0)}"


def _mark_to_position(node: yaml.Node) -> Position:
    mark = node.start_mark
    end = node.end_mark
    quoted = isinstance(node, yaml.ScalarNode) and node.style in ("'", '"')
    single = mark.line == end.line
    return Position(mark.line + 1, mark.column + 1, quoted=quoted, single_line=single)


def _yaml_error_position(err: yaml.YAMLError, file: str) -> str:
    mark = getattr(err, "problem_mark", None) or getattr(err, "context_mark", None)
    problem = getattr(err, "problem", None) or str(err).splitlines()[0]
    context = getattr(err, "context", None)
    where = f"{file}:{mark.line + 1}:{mark.column + 1}" if mark is not None else f"{file}:1:1"
    text = f"{context}, {problem}" if context else problem
    return f"{where}: YAML syntax error: {text}"


def _build(node: yaml.Node, path: PathKey, smap: SourceMap, loader: yaml.SafeLoader, problems: list[str],
           budget: list[int]) -> Any:
    budget[0] -= 1
    if budget[0] < 0:
        raise ConfigError([f"{smap.locate(path)}: the document has more than {MAX_NODES} nodes (alias expansion?)"])
    smap.values[path] = _mark_to_position(node)
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
                problems.append(f"{smap.file}:{pos.line}:{pos.column}: {_dotted(path + (key,))}: duplicate key")
                continue
            smap.keys[path + (key,)] = _mark_to_position(key_node)
            out[key] = _build(value_node, path + (key,), smap, loader, problems, budget)
        return out
    if isinstance(node, yaml.SequenceNode):
        return [_build(v, path + (i,), smap, loader, problems, budget) for i, v in enumerate(node.value)]
    return loader.construct_object(node, deep=True)


def _dotted(path: PathKey) -> str:
    return ".".join(str(p) for p in path) or "<document>"


def read_yaml(path: str | Path) -> tuple[Any, SourceMap]:
    """Read a YAML file into plain data and its :class:`SourceMap`; every problem is a ConfigError."""
    p = Path(path)
    file = str(path)
    try:
        raw = p.read_bytes()
    except FileNotFoundError:
        raise ConfigError([f"{file}: no such file"]) from None
    except IsADirectoryError:
        raise ConfigError([f"{file}: is a directory, not a config file"]) from None
    except OSError as e:
        raise ConfigError([f"{file}: cannot read: {e.strerror or e}"]) from None
    if len(raw) > MAX_CONFIG_BYTES:
        raise ConfigError([f"{file}: config is {len(raw)} bytes; the limit is {MAX_CONFIG_BYTES}"])
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise ConfigError([f"{file}: not UTF-8 text (byte {e.start})"]) from None
    return parse_yaml(text, file)


def parse_yaml(text: str, file: str = "<string>") -> tuple[Any, SourceMap]:
    smap = SourceMap(file)
    loader = yaml.SafeLoader(text)
    problems: list[str] = []
    try:
        node = loader.get_single_node()
        if node is None:
            raise ConfigError([f"{file}:1:1: the config is empty"])
        data = _build(node, (), smap, loader, problems, [MAX_NODES])
    except yaml.YAMLError as e:
        raise ConfigError([_yaml_error_position(e, file)]) from None
    except RecursionError:
        raise ConfigError([f"{file}: the document is nested too deeply"]) from None
    finally:
        loader.dispose()
    if problems:
        raise ConfigError(problems)
    return data, smap
