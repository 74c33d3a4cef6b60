"""README.md and docs/: every link and image resolves, no label of the paper's LaTeX source is left for the reader to
resolve, and every page is in the site's navigation and in README's map."""

from __future__ import annotations

import re
import unicodedata
from pathlib import Path

import pytest
import yaml

from .conftest import ROOT

DOCS = ROOT / "docs"
PAGES = sorted(DOCS.glob("*.md"))
TEXTS = [ROOT / "README.md", *PAGES]
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
# a LaTeX label: [eq:TDO], [semi_newton], [KKT_concatenated], [eq:proximal_response, eq:Semi_proximal]; the paper's
# labels without ':' or '_' are listed
LABEL = re.compile(r"\[(?:[A-Za-z][\w^*]*[:_][\w:^*-]*(?:,\s*)?)+\](?!\()|\[(?:Hessian|uniqueness|C1|state)\](?!\()")


def prose(text: str) -> str:
    """The text without fenced code blocks and inline code: what a reader reads as prose."""
    text = re.sub(r"^```.*?^```", "", text, flags=re.S | re.M)
    return re.sub(r"`[^`\n]*`", "", text)


def slug(heading: str) -> str:
    """The anchor Python-Markdown's toc extension gives a heading (its default slugify)."""
    text = re.sub(r"`([^`]*)`", r"\1", heading)
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", text)
    text = unicodedata.normalize("NFKD", text).encode("ascii", "ignore").decode()
    text = re.sub(r"[^\w\s-]", "", text).strip().lower()
    return re.sub(r"[-\s]+", "-", text)


def anchors(path: Path) -> set[str]:
    text = re.sub(r"^```.*?^```", "", path.read_text(), flags=re.S | re.M)
    return {slug(m.group(1)) for m in re.finditer(r"^#{1,6} (.+?)\s*$", text, re.M)}


def test_slug_is_python_markdowns() -> None:
    assert slug("Globalization (`solver.globalization`)") == "globalization-solverglobalization"
    assert slug("Foxglove / Lichtblick") == "foxglove-lichtblick"
    assert slug("Runtime parameters, time and data") == "runtime-parameters-time-and-data"


@pytest.mark.parametrize("path", TEXTS, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_every_link_and_image_resolves(path: Path) -> None:
    for target in LINK.findall(prose(path.read_text())):
        if re.match(r"[a-z]+:", target):  # https:, mailto:
            continue
        file, _, anchor = target.partition("#")
        resolved = (path.parent / file).resolve() if file else path
        assert resolved.exists(), f"{path.name}: {target} does not exist"
        if anchor:
            assert resolved.suffix == ".md", f"{path.name}: {target}: an anchor in a file that is not a page"
            assert anchor in anchors(resolved), f"{path.name}: {target}: no heading has the anchor #{anchor}"


@pytest.mark.parametrize("path", TEXTS, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_no_unresolved_paper_label(path: Path) -> None:
    found = LABEL.findall(prose(path.read_text()))
    assert not found, f"{path.name}: cite the paper's equation by its number and words, not its LaTeX label: {found}"


def test_the_label_pattern_finds_labels_and_nothing_else() -> None:
    cited = ("the method [semi_newton], perturbed [eq:inexact_seminewton], "
             "[eq:proximal_response, eq:Semi_proximal], [Hessian]")
    assert LABEL.findall(cited) == ["[semi_newton]", "[eq:inexact_seminewton]",
                                    "[eq:proximal_response, eq:Semi_proximal]", "[Hessian]"]
    plain = "on [-scale, scale], the box [0, 1], [a link](solvers.md#x), [The certificate](solvers.md), ‖z‖_inf"
    assert LABEL.findall(plain) == []


def test_every_page_is_in_the_navigation_and_in_readmes_map() -> None:
    site = yaml.safe_load((ROOT / "mkdocs.yml").read_text())
    nav = [next(iter(item.values())) for item in site["nav"]]
    assert sorted(nav) == sorted(p.name for p in PAGES) and nav[:2] == ["index.md", "tutorial.md"]
    assert site["strict"] is True
    readme = (ROOT / "README.md").read_text()
    mapped = re.findall(r"^- \[[^\]]+\]\(docs/([\w-]+\.md)\)", readme, re.M)
    assert mapped == [page for page in nav if page != "index.md"], "README's map lists the pages in the site's order"


def test_readme_keeps_the_set_up_commands() -> None:
    """CI and users copy these two lines as they are."""
    readme = (ROOT / "README.md").read_text()
    assert ("python3 -m venv .venv && . .venv/bin/activate && pip install -e . && gnerun solve "
            "configs/paper_study1.yaml\n") in readme
    assert 'python3 -m venv .venv && . .venv/bin/activate && pip install -e ".[test]" && pytest -q\n' in readme
    assert 'pytest -m "not slow" -q\n' in readme
