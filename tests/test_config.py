"""Config loading: strict schema, positions of every error, overrides, the resolved config."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from gnerun.errors import ConfigError, InputError
from gnerun.language.config import load_config, parse_override
from gnerun.language.yaml_source import MAX_CONFIG_BYTES
from gnerun.solvers.globalization import resolve

from .conftest import CONFIGS, shipped_configs

SHIPPED = shipped_configs()

STATIC = """\
name: t
game:
  kind: static
  parameters: {c: 2.0}
  agents:
    - name: p1
      variables: {x1: {lower: 0, upper: 10}}
      cost: "x1**2 - c*x1*x2"
    - name: p2
      variables:
        x2: {lower: 0}
      cost: 'x2**2 + x1*x2'
      constraints:
        - x1 + x2 <= 4
solver:
  tol: 1.0e-10
"""


def _problems(text: str) -> list[str]:
    with pytest.raises(ConfigError) as err:
        load_config("cfg.yaml", text=text)
    return err.value.problems


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.name)
def test_shipped_configs_load_and_round_trip(path: Path) -> None:
    cfg = load_config(path)
    again = load_config(path, text=cfg.resolved_yaml())  # (data files are found next to it)
    assert again == cfg
    assert again.config_hash() == cfg.config_hash()


def _cournot_200() -> str:
    from benchmarks.wall import cournot_yaml

    return cournot_yaml(200)  # 200 expanded costs of ~2,400 characters each: long scalars, folded at the width


@pytest.mark.parametrize("path", [*SHIPPED, "cournot-200"], ids=lambda p: getattr(p, "name", p))
def test_the_resolved_yaml_is_the_text_of_pyyamls_own_emitter(path: Path | str) -> None:
    # where libyaml's faster emitter writes config.yaml, it writes PyYAML's text: the same file, the same config_hash
    import yaml

    from gnerun.language import config as config_module

    class Python(yaml.SafeDumper):
        pass

    Python.add_representer(list, config_module._represent_list)
    cfg = load_config(path) if isinstance(path, Path) else load_config(text=_cournot_200())
    data = cfg.model_dump(mode="json")
    for optional in ("runtime", "references"):
        if not data["game"].get(optional) and optional in data["game"]:
            data["game"].pop(optional)
    assert cfg.resolved_yaml() == yaml.dump(data, Dumper=Python, sort_keys=False, allow_unicode=True, width=100)


def test_defaults_are_filled_in() -> None:
    cfg = load_config("cfg.yaml", text=STATIC)
    assert cfg.version == 1
    assert cfg.solver.kind == "ssn" and cfg.solver.complementarity == "min" and cfg.solver.max_iter == 300
    assert cfg.solver.globalization == "auto" and resolve(cfg.solver) == "hybrid"
    assert cfg.disturbance.kind == "none" and cfg.disturbance.plant.kind == "none"
    assert cfg.game.equilibrium == "generalized" and cfg.game.shared_constraints == []
    resolved = cfg.resolved_yaml()
    for key in ("complementarity: min", "tie_tol:", "min_rcond:", "globalization: auto", "warm_start: shift",
                "initial: solve", "safeguard: fallback"):
        assert key in resolved


@pytest.mark.parametrize("needle, line, column, path", [
    ("name: t\n", 1, 1, "colour"),  # top level
    ("  tol: 1.0e-10\n", 16, 3, "solver.tolerance"),
    ("      cost: \"x1**2", 8, 7, "game.agents.0.costs"),
    ("{lower: 0, upper: 10}", 7, 34, "game.agents.0.variables.x1.uper"),
])
def test_unknown_keys_are_located(needle: str, line: int, column: int, path: str) -> None:
    key = path.rsplit(".", 1)[-1]
    if key == "colour":
        text = "colour: red\n" + STATIC
    elif key == "tolerance":
        text = STATIC.replace("  tol: 1.0e-10\n", "  tolerance: 1.0e-10\n")
    elif key == "costs":
        text = STATIC.replace('      cost: "x1**2 - c*x1*x2"', '      costs: "x1**2 - c*x1*x2"')
    else:
        text = STATIC.replace("{lower: 0, upper: 10}", "{lower: 0, uper: 10}")
    problems = _problems(text)
    matching = [p for p in problems if f"{path}: unknown key" in p]
    assert matching, problems
    assert matching[0].startswith(f"cfg.yaml:{line}:{column}: "), matching[0]


def test_unknown_key_lists_the_allowed_ones() -> None:
    [problem] = _problems(STATIC.replace("  tol: 1.0e-10\n", "  tolerance: 1.0e-10\n"))
    assert "allowed here:" in problem and "tol" in problem and "max_iter" in problem


def test_yaml_syntax_error_position() -> None:
    [problem] = _problems("name: x\ngame: [1, 2\nsolver: {}\n")
    assert problem.startswith("cfg.yaml:3:7: YAML syntax error") or problem.startswith("cfg.yaml:3:")
    assert "YAML syntax error" in problem


def test_duplicate_keys_are_errors() -> None:
    problems = _problems(STATIC.replace("solver:\n  tol: 1.0e-10\n", "solver:\n  tol: 1.0e-10\n  tol: 2\n"))
    assert problems == ["cfg.yaml:17:3: solver.tol: duplicate key"]


@pytest.mark.parametrize("content, fragment", [
    ("", "empty"),
    ("- 1\n- 2\n", "must be a mapping"),
    ("name: [\n", "YAML syntax error"),
])
def test_malformed_documents(content: str, fragment: str) -> None:
    assert fragment in _problems(content)[0]


@pytest.mark.parametrize("content, fragment", [
    ("name: !!python/object/apply:os.system ['true']\n", "1:7: the YAML tag '!!python/object/apply:os.system' is not"),
    ("name: !!binary AAAA\n", "tag '!!binary'"),
    ("name: !mine x\n", "tag '!mine'"),
    ("name: x\nrun: {K: [1]}\x00\n", "2:14: not a YAML text: character U+0000"),
    ("name: x\nsolver: {max_iter: " + "9" * 5000 + "}\n", "2:20: solver.max_iter: cannot read '999"),
    ("a: &a [*a]\n", "1:4: a recursive alias"),
    ("a0: &a0 [x]\n" + "".join(f"a{i}: &a{i} [*a{i - 1}]\n" for i in range(1, 80)), "(through aliases)"),
    ("name: " + "[" * 100 + "]" * 100 + "\n", "1:70: the document is nested deeper than 64 levels"),
    ("a: &a [x, x, x, x, x, x, x, x, x, x]\n" + "".join(
        f"{c}: &{c} [{', '.join([f'*{p}'] * 10)}]\n" for p, c in zip("abcdef", "bcdefg", strict=True)), "alias bomb"),
    ('"\\r": 1\n', "'\\r': unknown key"),
    ("solver: {' tol': 1}\n", "solver.' tol': unknown key"),
])
def test_hostile_documents_are_refused_in_one_line(content: str, fragment: str) -> None:
    problems = _problems(content)
    assert any(fragment in p for p in problems), problems
    assert all("\n" not in p and "\r" not in p for p in problems)


@pytest.mark.parametrize("variable, fragment", [
    ("{lower: .nan}", "lower: the lower bound is NaN"),
    ("{lower: .inf}", "lower bound +.inf admits no value"),
    ("{upper: -.inf}", "upper bound -.inf admits no value"),
    ("{start: .nan}", "start: Input should be a finite number"),
])
def test_non_finite_numbers(variable: str, fragment: str) -> None:
    assert any(fragment in p for p in _problems(STATIC.replace("{lower: 0, upper: 10}", variable, 1)))
    assert any("solver.tol: Input should be a finite number" in p
               for p in _problems(STATIC.replace("tol: 1.0e-10", "tol: .inf")))
    cfg = load_config(text=STATIC.replace("{lower: 0, upper: 10}", "{lower: -.inf, upper: .inf}", 1))
    assert math.isinf(cfg.game.agents[0].variables["x1"].lower)  # +-.inf: no bound, as leaving it out


def test_unreadable_files(tmp_path: Path) -> None:
    big = tmp_path / "big.yaml"
    big.write_text("name: x\n# " + "a" * MAX_CONFIG_BYTES + "\n")
    binary = tmp_path / "bin.yaml"
    binary.write_bytes(b"name: \xff\xfe\x00x\n")
    for path, fragment in [(big, "the limit is"), (binary, "not UTF-8"), (tmp_path / "missing.yaml", "no such file"),
                           (tmp_path, "is a directory")]:
        with pytest.raises(ConfigError, match=fragment):
            load_config(path)


def test_type_errors_and_missing_fields_are_located() -> None:
    problems = _problems(STATIC.replace("  tol: 1.0e-10", "  tol: -1"))
    assert problems[0].startswith("cfg.yaml:16:8: solver.tol: ")
    dyn = (CONFIGS / "paper_study2.yaml").read_text().replace("horizon: 10", "horizon: ten")
    problems = _problems(dyn)
    assert any(":9:12: game.horizon:" in p for p in problems), problems
    problems = _problems(STATIC.replace('      cost: \'x2**2 + x1*x2\'\n', ""))
    assert problems[0].startswith("cfg.yaml:9:7: game.agents.1.cost: required field is missing"), problems


@pytest.mark.parametrize("replace, expected", [
    # plain, double-quoted, single-quoted scalars: the column of the offending character in the file
    (("- x1 + x2 <= 4", "- x1 + y2 <= 4"), "cfg.yaml:14:16: game.agents.1.constraints.0: unknown name 'y2'"),
    (('cost: "x1**2 - c*x1*x2"', 'cost: "x1**2 - d*x1*x2"'), "cfg.yaml:8:22: game.agents.0.cost: unknown name 'd'"),
    (("cost: 'x2**2 + x1*x2'", "cost: 'x2**2 + x1*x2)'"), "cfg.yaml:12:27: game.agents.1.cost: unbalanced ')'"),
])
def test_expression_errors_point_into_the_line(replace, expected: str) -> None:
    problems = _problems(STATIC.replace(*replace))
    assert problems[0].startswith(expected), problems
    assert "of expression" in problems[0]


def test_dynamic_game_checks() -> None:
    base = (CONFIGS / "paper_study2.yaml").read_text()
    cases = [
        (base.replace("x0: [1, 3, 5]", "x0: [1, 3]"), "game.x0: has 2 entries for 3 states"),
        (base.replace("[0, 0, 0.2]]\n    B:", "[0, 0, 0.2], [1, 1, 1]]\n    B:"), "game.dynamics.A: must be 3 x 3"),
        (base.replace('      stage_cost: "(x3 - 1)**2"', '      stage_cost: "(x3 - 1)**2"\n      terminal_cost: "u3"'),
         "game.agents.2.terminal_cost: unknown name 'u3'"),
        (base.replace("inputs: [u2]", "inputs: [x1]"), "input 'x1' is already declared as state"),
        (base.replace("inputs: [u2]", "inputs: [sin]"), "is the name of a function"),
        (base.replace("name: agent2", "name: agent1"), "agent 'agent1' is declared twice"),
    ]
    for text, fragment in cases:
        problems = _problems(text)
        assert any(fragment in p for p in problems), (fragment, problems)
    expr_dyn = base.replace("""    A: [[0.5, 0, 0], [0, 0.3, 0], [0, 0, 0.2]]
    B: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]""", """    x1: "0.5*x1 + u1"
    x2: "0.3*x2 + u2"
    x4: "x3 + u3\"""")
    problems = _problems(expr_dyn)
    assert any("no equation for state 'x3'" in p for p in problems)
    assert any("'x4' is not a declared state" in p for p in problems)


def test_overrides() -> None:
    path = CONFIGS / "paper_study2.yaml"
    cfg = load_config(path, {"solver.tol": 1e-12, "run.K": [1, 7]})
    assert cfg.solver.tol == 1e-12 and cfg.run.K == [1, 7]
    cfg = load_config(path, ["run.K=[2,3]", "game.agents.0.stage_cost=u1**2", "disturbance.kind=jacobian_noise",
                             "disturbance.plant.kind=gaussian"])
    assert cfg.run.K == [2, 3] and cfg.game.agents[0].stage_cost == "u1**2"
    assert cfg.disturbance.kind == "jacobian_noise" and cfg.disturbance.plant.kind == "gaussian"
    with pytest.raises(InputError, match="no such list element"):
        load_config(path, ["game.agents.9.stage_cost=u1"])
    for hostile, fragment in [("solver.tol=!!python/object/apply:os.system ['true']", "tag '!!python/object/apply"),
                              ("solver.tol=" + "[" * 5000, "nested deeper than 64"),
                              ("name=!!binary AAAA", "!!binary")]:
        with pytest.raises(InputError, match=re.escape(fragment)):
            load_config(path, [hostile])
    with pytest.raises(InputError, match="not valid: YAML syntax error"):
        load_config(path, ["run.K=[1,"])
    with pytest.raises(ConfigError) as err:
        load_config(path, ["solver.tol=-3"])
    assert str(err.value).startswith("--set solver.tol=-3: solver.tol:")
    with pytest.raises(ConfigError) as err:
        load_config(path, ["solver.colour=red"])
    assert str(err.value).startswith("--set solver.colour=red: solver.colour: unknown key")


@pytest.mark.parametrize("text, expected", [
    ("a.b=1", ("a.b", 1)),
    ("a.b=", ("a.b", "")),
    ("a.b=x=y", ("a.b", "x=y")),
    ("run.K=[1, 7]", ("run.K", [1, 7])),
    ("game.agents.0.cost=x1**2 + 1", ("game.agents.0.cost", "x1**2 + 1")),
])
def test_parse_override(text: str, expected) -> None:
    assert parse_override(text) == expected


@pytest.mark.parametrize("text", ["=1", "a..b=1", "a.b", ".a=1"])
def test_parse_override_rejects(text: str) -> None:
    with pytest.raises(InputError):
        parse_override(text)


def test_other_config_versions_are_refused() -> None:
    problems = _problems("version: 2\n" + STATIC)
    assert problems[0].startswith("cfg.yaml:1:10: version:")


def test_the_replaced_line_search_key_says_what_replaced_it() -> None:
    [problem] = _problems(STATIC.replace("  tol: 1.0e-10\n", "  tol: 1.0e-10\n  line_search: true\n"))
    assert "solver.line_search" in problem and "globalization: line_search" in problem
    assert problem.startswith("cfg.yaml:") and problem.split(":")[1].isdigit()


def test_josephy_newton_takes_no_globalization_of_semismooth_newton() -> None:
    [problem] = _problems(STATIC.replace("  tol: 1.0e-10\n", "  tol: 1.0e-10\n  kind: jn\n  globalization: hybrid\n"))
    assert "solver.globalization" in problem and "Josephy-Newton" in problem
    jn = load_config("cfg.yaml", text=STATIC.replace("  tol: 1.0e-10\n", "  tol: 1.0e-10\n  kind: jn\n"))
    assert resolve(jn.solver) == "none"
