"""Where a character of an expanded expression was written (:mod:`gnerun.language.expand`): an expression of a
family's copy is a template with its indices, entries, sums and definitions written in, and written back as text
(:func:`~gnerun.language.expr.unparse`); a problem found in that text is reported at the template's character.

The nodes of the expanded tree keep the columns of the text they were parsed from (the template's, or a definition's:
a definition's tree is shared wherever its name is used). Parsing the expanded text again gives the same tree (what
:func:`~gnerun.language.expr.unparse` guarantees), so walking the two trees side by side pairs each character of the
expanded text that starts a node with the node's column in the template."""

from __future__ import annotations

from .expr import ExpressionError, Node, Num, Unary, children, parse_constraint, parse_expression


def written_at(text: str, column: int, roots: list[Node],
               definitions: dict[str, Node]) -> tuple[int, str | None] | None:
    """The column of the template (and the name of the definition it lies in, if any) of the node that starts at
    character ``column`` of ``text``, the expansion written back from the trees ``roots`` (one: an expression; two: a
    constraint's sides); None where the text is not theirs or no node starts there."""
    try:
        parsed = parse_expression(text) if len(roots) == 1 else parse_constraint(text)
    except ExpressionError:
        return None
    written = [parsed.tree] if len(roots) == 1 else [parsed.lhs, parsed.rhs]
    regions = {id(tree): name for name, tree in definitions.items()}
    stack: list[tuple[Node, Node, str | None]] = [(w, r, None) for w, r in zip(written, roots, strict=True)]
    while stack:
        w, r, region = stack.pop()
        region = regions.get(id(r), region)
        if isinstance(r, Num) and isinstance(w, Unary) and isinstance(w.operand, Num):  # -3 is written as -(3)
            if column in (w.column, w.operand.column):
                return r.column, region
            continue
        if type(w) is not type(r):
            return None
        if w.column == column:
            return r.column, region
        ws, rs = children(w), children(r)
        if len(ws) != len(rs):
            return None
        stack.extend((a, b, region) for a, b in zip(ws, rs, strict=True))
    return None
