"""Source positions of an expanded document (:mod:`gnerun.language.expand`): every key and value written out keeps
the ``file:line:column`` of the template it came from, and a copy of a family notes its index values."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from .families import Scope
from .yaml_source import PathKey, SourceMap


class Positions:
    """Copies positions from the source map of a document (``src``) to the source map of its expansion (``out``)."""

    def __init__(self, src: SourceMap):
        self.src = src
        self.out = SourceMap(src.file, overridden=dict(src.overridden), text=src.text)

    def copy(self, src: PathKey, dst: PathKey, *, key: bool = False, scope: Scope | None = None) -> None:
        """The position of ``src`` (a key's, or else a value's or its nearest enclosing value's) given to ``dst``."""
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
            table_dst[dst] = replace(pos, single_line=False, span=None) if changed else pos
        if scope is not None and scope.indices and not key:
            self.out.notes[dst] = "for " + ", ".join(f"{k} = {v}" for k, v in scope.indices.items())

    def copy_subtree(self, value: Any, src: PathKey, dst: PathKey) -> None:
        """The positions of everything under ``src``, moved under ``dst``."""
        for table_src, table_dst in ((self.src.values, self.out.values), (self.src.keys, self.out.keys)):
            for p, pos in table_src.items():
                if p[:len(src)] == src:
                    table_dst[dst + p[len(src):]] = pos
