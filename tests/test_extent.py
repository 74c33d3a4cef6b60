"""The extent of a config counted before it is expanded (gnerun/language/extent.py): expansion bombs are refused by
`gnerun validate` with exit code 2, one located line and the estimate, in seconds; the counts agree with what the
expansion writes; the wall-clock budget is the last guard."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from gnerun.errors import ConfigError
from gnerun.language import families as families_module
from gnerun.language.config import estimate_before_expanding, load_config
from gnerun.language.expand import Expander
from gnerun.language.extent import MAX_EXPRESSION_NODES, MAX_ITEMS, MAX_NODES, Rows, game_section
from gnerun.language.yaml_source import SourceMap

from .conftest import CONFIGS, run_cli

HANG_S = 60.0  # a hang guard, not a timing: each bomb is answered in about 1 s (process start included), and a bomb
# that was expanded would run for minutes or run out of memory


def _static(agents: list, **game) -> dict:
    return {"name": "bomb", "game": {"kind": "static", **game, "agents": agents}}


def _doubling() -> dict:
    definitions = {"d1": "x1 + 1", **{f"d{k}": f"d{k - 1} + d{k - 1}" for k in range(2, 41)}}
    return _static([{"name": "p", "variables": {"x1": {}}, "cost": "d40"}], definitions=definitions)


def _nested_chain() -> dict:
    definitions = {"d1": "x1 + 1", **{f"d{k}": f"2*d{k - 1}" for k in range(2, 3001)}}
    return _static([{"name": "p", "variables": {"x1": {}}, "cost": "d3000**2"}], definitions=definitions)


def _empty_inner(spec: dict) -> dict:
    return _static([{"name": "p", "variables": {"x1": {}}, "cost": "x1**2"}],
                   shared_constraints=[{"for": spec, "expr": "x1 <= {i}"}])


def _big_definition() -> dict:
    big = " + ".join(f"{k}*x1" for k in range(1, 900))  # 8 KB
    return _static([{"name": "p", "variables": {"x1": {}}, "cost": "sum(D for k in 1..2000)"}], definitions={"D": big})


def _long_expression() -> dict:
    text = " + ".join(f"{k}*x{{i}}" for k in range(1, 2000))[:19990]
    return _static([{"for": {"i": "1..N"}, "name": "p{i}", "variables": {"x{i}": {}}, "cost": text[:text.rfind(" +")]}],
                   parameters={"N": 500})


def _family(n: int) -> dict:
    return _static([{"for": {"i": f"1..{n}"}, "name": "p{i}", "variables": {"x{i}": {}}, "cost": "(x{i} - 1)**2"}])


def _nested(cost: str) -> dict:
    return _static([{"name": "p", "variables": {"x1": {}}, "cost": cost}])


# (name, the config (a document, or a shipped config's name), --set overrides, exit code, a phrase of the message)
BOMBS = [
    ("definitions that double, 40 levels", _doubling, [], 2, "definition 'd14' expands to 32,767 expression nodes"),
    ("3,000 definitions nested in products", _nested_chain, [], 2, "nested deeper than 100 levels"),
    ("a family over 1..10^12 whose inner range is 1..0", lambda: _empty_inner({"i": "1..1000000000000", "j": "1..0"}),
     [], 2, "1,000,000,000,000 values of i"),
    ("a family over 1..10^12 whose inner range is i+1..i",
     lambda: _empty_inner({"i": "1..1000000000000", "j": "i+1..i"}), [], 2, "1,000,000,000,000 values of i"),
    ("10^4 x 10^4 x an empty range", lambda: _empty_inner({"i": "1..10000", "j": "1..10000", "k": "1..0"}), [], 2,
     "100,000,000 values of j"),
    ("a sum of 2,000 copies of an 8 KB definition", _big_definition, [], 2, "expands to 7,191,999 expression nodes"),
    ("a 19,990-character expression in 500 agents", _long_expression, [], 2,
     f"more than {MAX_NODES:,} expression nodes"),
    ("fk_a01 with N = 1000", "fk_a01.yaml", ["game.parameters.N=1000"], 2, f"more than {MAX_NODES:,} expression nodes"),
    ("the merge with N = 400 (80k pairs)", "algames_merge_n.yaml", ["game.parameters.N=400"], 2,
     "the game is too large: estimated 1,692,000 unknowns"),
    ("the merge with N = 100000", "algames_merge_n.yaml", ["game.parameters.N=100000"], 2,
     f"more than {MAX_ITEMS:,} family copies"),
    ("a family of 99,999 agents", lambda: _family(99_999), [], 2, "estimated 99,999 unknowns in the dense formulation"),
    ("max() nested 1,200 deep", lambda: _nested("max(" * 1200 + "x1, 1" + ", 1)" * 1200), [], 2,
     "nested deeper than 100 levels"),
    ("sum() nested 400 deep", lambda: _nested("sum(" * 400 + "x1" + " for k in 1..1)" * 400), [], 2,
     "nested deeper than 100 levels"),
    ("3,000 chained definitions whose sum is small", lambda: _static(
        [{"name": "p", "variables": {"x1": {"start": 1}}, "cost": "d3000**2"}],
        definitions={"d1": "x1", **{f"d{k}": f"d{k - 1} + 1" for k in range(2, 3001)}}), [], 0, "ok"),
]


@pytest.mark.parametrize(("name", "config", "overrides", "code", "phrase"), BOMBS, ids=[b[0] for b in BOMBS])
def test_validate_answers_every_expansion_bomb_at_once(name: str, config, overrides: list[str], code: int,
                                                        phrase: str, tmp_path: Path) -> None:
    if isinstance(config, str):
        path = CONFIGS / config
    else:
        path = tmp_path / "bomb.yaml"
        path.write_text(yaml.safe_dump(config(), sort_keys=False, width=10**9))
    args = [a for o in overrides for a in ("--set", o)]
    proc = run_cli("validate", str(path), *args, timeout=HANG_S)
    assert proc.returncode == code, (name, proc.stderr[-2000:])
    assert "Traceback" not in proc.stderr + proc.stdout
    out = proc.stderr if code else proc.stdout
    lines = [line for line in out.splitlines() if not line.startswith("warning:")]
    assert len(lines) == 1, lines
    assert phrase in lines[0], lines[0]
    if code:
        assert lines[0].startswith(f"error: {path}:"), lines[0]  # located in the file


# the counts against the expansion -------------------------------------------------------------------------

def _counted(game: dict) -> tuple:
    expander = Expander(SourceMap("counts"))
    base = {k: v for k, v in game.get("parameters", {}).items() if isinstance(v, int)}
    extent = game_section(expander, game, base)
    return extent, expander


@settings(max_examples=300, deadline=None)
@given(st.integers(0, 6), st.sampled_from(["1..N", "i..N", "i+1..N", "1..i", "i-1..N-i", "2*i..N+3"]),
       st.sampled_from(["1..0", "j..N", "1..j", "i..j", "1..2"]), st.integers(0, 3))
def test_the_counts_are_the_copies_and_terms_the_expansion_writes(n: int, second: str, third: str, terms: int) -> None:
    game = {"kind": "static", "parameters": {"N": n},
            "agents": [{"name": "p", "variables": {"x1": {}}, "cost": "x1**2"}],
            "shared_constraints": [{"for": {"i": "1..N", "j": second, "k": third},
                                    "expr": f"x1 + sum(x1**2 for m in 1..{terms}) <= i + j + k"}]}
    extent, _ = _counted(game)
    expanded, _ = Expander(SourceMap("counts")).expand({"game": game})
    rows = expanded["game"]["shared_constraints"]
    assert extent.copies[("shared_constraints", "*")] == len(rows)
    from gnerun.language.expr import parse_constraint
    from gnerun.language.size import _nodes

    written = sum(_nodes(c.lhs) + _nodes(c.rhs) for c in map(parse_constraint, rows))
    assert extent.expression_nodes[("shared_constraints", "*")] == written
    assert extent.items >= n + len(rows) + len(rows) * terms  # the values of i, the copies, the terms at least


def test_the_counts_of_the_shipped_templates_are_their_games() -> None:
    """Agents, decisions, states and rows counted before expansion against the games themselves."""
    for name in ("fk_a01.yaml", "fk_a09a.yaml", "algames_merge_n.yaml", "mcp_demo.yaml", "algames_intersection.yaml"):
        cfg = load_config(CONFIGS / name)
        from gnerun.language.yaml_source import read_yaml

        data, _ = read_yaml(CONFIGS / name)
        game = data["game"]
        base = {k: v for k, v in game.get("parameters", {}).items() if isinstance(v, int)}
        if isinstance(game.get("horizon"), int):
            base["T"] = game["horizon"]
        extent = game_section(Expander(SourceMap(name)), game, base)
        field = "variables" if cfg.game.kind == "static" else "inputs"
        assert extent.copies[("agents", "*")] == len(cfg.game.agents), name
        assert extent.copies[("agents", "*", field, "*")] == sum(len(getattr(a, field)) for a in cfg.game.agents), name
        assert extent.copies[("shared_constraints", "*")] == len(cfg.game.shared_constraints), name
        if cfg.game.kind == "dynamic":
            assert extent.copies[("states", "*")] == len(cfg.game.states), name
        early = estimate_before_expanding(extent, game, data)
        assert early is not None and early.decisions == cfg.size.decisions, name
        assert early.multipliers <= cfg.size.multipliers and early.nodes <= cfg.size.nodes, name


def test_a_definition_is_measured_not_written_out() -> None:
    definitions = {"d1": "x1", **{f"d{k}": f"d{k - 1}*d{k - 1}" for k in range(2, 12)}}
    game = {"kind": "static", "definitions": definitions,
            "agents": [{"name": "p", "variables": {"x1": {}}, "cost": "d11"}]}
    extent, expander = _counted(game)
    assert extent.nodes == 2**11 - 1  # d11: 1,024 leaves and 1,023 products
    with pytest.raises(ConfigError, match=r"definition 'd15' expands to 32,767 expression nodes"):
        load_config({"game": {**game, "definitions": {"d1": "x1", **{f"d{k}": f"d{k - 1}*d{k - 1}"
                                                                        for k in range(2, 30)}}}})


def test_rows_of_a_family_with_dependent_ranges() -> None:
    from gnerun.language.extent import Counter

    counter = Counter(Expander(SourceMap("rows")), {"N": 5})
    rows = counter.family({"i": "1..N", "j": "i+1..N"}, Rows(1), ("for",))
    assert rows.n == 10
    assert sorted(zip(rows.columns["i"].tolist(), rows.columns["j"].tolist(), strict=True)) == [
        (i, j) for i in range(1, 6) for j in range(i + 1, 6)]
    assert counter.extent.items == 5 + 10  # every value of i visited, and the pairs


def test_the_limit_on_one_expression_is_the_parsers() -> None:
    assert MAX_EXPRESSION_NODES == 20_000
    cost = "sum(x1**2 for k in 1..6000)"  # 3 nodes a term and the joins: 23,999 nodes, at least as many characters
    with pytest.raises(ConfigError, match=r"this expression expands to 23,999 expression nodes"):
        load_config({"game": {"kind": "static", "agents": [{"name": "p", "variables": {"x1": {}}, "cost": cost}]}})


def test_the_wall_clock_budget_names_the_construct(monkeypatch) -> None:
    monkeypatch.setattr(families_module, "EXPANSION_SECONDS", 0.0)
    with pytest.raises(ConfigError) as err:
        load_config(text=yaml.safe_dump(_family(5000), sort_keys=False))
    assert len(err.value.problems) == 1
    assert re.match(r"<string>:\d+:\d+( \(for i = \d+\))?: expanding (this expression|the family for: \{i: 1..5000\}) "
                    r"took more than 0 s", err.value.problems[0]), \
        err.value.problems[0]
