"""gnerun.language.origins: a character of an expanded expression paired with the template's (or definition's)."""

from __future__ import annotations

import pytest

from gnerun.language.expr import unparse
from gnerun.language.families import Families, Scope
from gnerun.language.origins import written_at
from gnerun.language.substitute import Substitution


def _expanded(template: str, i: int, definitions: dict[str, str] | None = None):
    subst = Substitution(Families({}))
    subst.vectors["w"] = [0.5, 1.5, -2.5]
    for name, text in (definitions or {}).items():
        subst.definitions[name] = subst.expanded(text, ("d",), Scope({}))[0]
    lhs, relation, rhs, _ = subst.expanded(template, ("e",), Scope({"N": 3}, {"i": i}))
    roots = [lhs] if relation is None else [lhs, rhs]
    text = unparse(lhs) if relation is None else f"{unparse(lhs)} {relation} {unparse(rhs)}"
    return text, roots, subst.definitions


@pytest.mark.parametrize(("template", "i", "expanded", "name", "written"), [
    # an entry written in before the name: the expansion is longer or shorter than the template
    ("x{i} + w[i]*yy{i}", 2, "x2 + 1.5*yy2", "yy2", "yy{i}"),
    ("x{i} + w[i]*yy{i}", 3, "x3 + (-2.5)*yy3", "yy3", "yy{i}"),
    # a sum written out: each term's name is the body's
    ("sum(x{k}*q for k in 1..N) + x{i}", 1, "x1*q + x2*q + x3*q + x1", "q", "q for"),
    # a constraint: the right side's columns are the whole text's
    ("x{i} <= {i % N + 1}*cap{i}", 3, "x3 <= 1*cap3", "cap3", "cap{i}"),
    # an operator
    ("x{i}**2 + {i}*y", 2, "x2**2 + 2*y", "+", "+ {i}"),
])
def test_a_character_of_the_expansion_is_the_templates(template: str, i: int, expanded: str, name: str,
                                                       written: str) -> None:
    text, roots, definitions = _expanded(template, i)
    assert text == expanded
    assert written_at(text, text.index(name) + 1, roots, definitions) == (template.index(written) + 1, None)


def test_a_name_inside_a_definition_is_the_definitions() -> None:
    text, roots, definitions = _expanded("x{i} + 2*S", 1, {"S": "sum(xx{k} for k in 1..3)"})
    assert text == "x1 + 2*(xx1 + xx2 + xx3)"
    assert written_at(text, text.index("xx2") + 1, roots, definitions) == (5, "S")


def test_a_text_that_is_not_the_expansion_is_not_paired() -> None:
    text, roots, definitions = _expanded("x{i} + w[i]*yy{i}", 2)
    assert written_at("x2 + yy2", 6, roots, definitions) is None  # another tree
    assert written_at("x2 + (", 1, roots, definitions) is None  # not an expression
    assert written_at(text, 3, roots, definitions) is None  # a space: no node starts there
