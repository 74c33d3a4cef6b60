"""docs/tutorial.md as a newcomer follows it: its configs saved under the names the page gives them, its commands
run in order in an empty folder, and the output the page shows compared with what the commands print.

The page's conventions: a ```yaml block is a file when the line before it ends with "`NAME.yaml`:"; every line of
a ```sh block is a gnerun command; a ```text block right after a ```sh block is what those commands print."""

from __future__ import annotations

import json
import re
import shlex
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from .conftest import ROOT, run_cli

TUTORIAL = ROOT / "docs" / "tutorial.md"
FENCE = re.compile(r"^```(\w*)\n(.*?)^```\n", re.S | re.M)
FILE_NAME = re.compile(r"`([\w.-]+\.yaml)`:$")
# lines of a shown output that differ from machine to machine: numbers in e-notation, times, the timing line
VOLATILE = re.compile(r"\d\.\d+e[+-]\d\d|\d ms\b|^wall \d+\.\d+ s: ")


@dataclass
class Command:
    argv: list[str]
    shown: list[str] = field(default_factory=list)  # the output the page shows for its block (on the block's last)


@dataclass
class Tutorial:
    files: dict[str, str]
    commands: list[Command]


def read_tutorial(text: str) -> Tutorial:
    files: dict[str, str] = {}
    commands: list[Command] = []
    last_end, last_lang = 0, ""
    for m in FENCE.finditer(text):
        lang, body = m.group(1), m.group(2)
        before = text[:m.start()].rstrip("\n").rsplit("\n", 1)[-1]
        if lang == "yaml":
            name = FILE_NAME.search(before)
            assert name, f"a yaml block without a file name: the line before it is {before!r}"
            assert name.group(1) not in files, f"{name.group(1)} is written twice"
            files[name.group(1)] = body
        elif lang == "sh":
            for line in body.splitlines():
                if line.strip():
                    argv = shlex.split(line)
                    assert argv[0] == "gnerun", f"not a gnerun command: {line!r}"
                    commands.append(Command(argv[1:]))
        elif lang == "text" and last_lang == "sh" and not text[last_end:m.start()].strip():
            commands[-1].shown = body.splitlines()
        else:
            assert lang in ("text", "python"), f"a ```{lang} block: the tutorial's blocks are yaml, sh and text"
        last_end, last_lang = m.end(), lang
    return Tutorial(files, commands)


def normal(line: str) -> str:
    return " ".join(line.split())


def test_the_tutorial_marks_every_config_and_command() -> None:
    tutorial = read_tutorial(TUTORIAL.read_text())
    assert set(tutorial.files) == {"static.yaml", "rail.yaml"}
    verbs = [c.argv[0] for c in tutorial.commands]
    assert verbs == ["solve", "validate", "solve", "simulate", "simulate", "figures", "replay"]
    # the page shows the output of every block but the --set example: on each block's last command
    assert [bool(c.shown) for c in tutorial.commands] == [True, False, True, True, False, False, True]


def test_read_tutorial_refuses_an_unnamed_config() -> None:
    with pytest.raises(AssertionError, match="without a file name"):
        read_tutorial("Write this:\n\n```yaml\nname: x\n```\n")
    with pytest.raises(AssertionError, match="not a gnerun command"):
        read_tutorial("```sh\npython -c 1\n```\n")
    page = read_tutorial("Save as `a.yaml`:\n```yaml\nname: a\n```\n\n```sh\ngnerun solve a.yaml\n```\n\n"
                         "```text\nstatus: converged\n```\n")
    assert page.files == {"a.yaml": "name: a\n"} and page.commands[0].shown == ["status: converged"]


def test_the_tutorial_runs_as_written(tmp_path: Path) -> None:
    tutorial = read_tutorial(TUTORIAL.read_text())
    for name, body in tutorial.files.items():
        (tmp_path / name).write_text(body)
    printed: list[str] = []
    for command in tutorial.commands:
        proc = run_cli(*command.argv, cwd=tmp_path)
        assert proc.returncode == 0, (command.argv, proc.stdout, proc.stderr)
        assert "Traceback" not in proc.stderr
        printed.append(proc.stdout)
        if command.shown:  # the output shown for a block is that of all its commands
            actual = [normal(line) for out in printed for line in out.splitlines()]
            printed = []
            for line in command.shown:
                if line.startswith("status:"):  # the status and the iterations, before the residual's digits
                    head = normal(line.split("||Phi||")[0])
                    assert any(a.startswith(head) for a in actual), (line, actual)
                elif not VOLATILE.search(line):
                    assert normal(line) in actual, (line, actual)

    # 1. the static game: the halfway point, certified globally, the shared constraint's price 2
    static = json.loads((tmp_path / "runs/static/summary.json").read_text())
    assert static["status"] == "converged"
    assert static["solution"] == {"alice": {"x1": pytest.approx(2)}, "bob": {"x2": pytest.approx(3)}}
    assert static["multipliers"]["shared"] == [pytest.approx(2)]
    assert static["certificate"]["best_response_kind"] == {"alice": "global (convex)", "bob": "global (convex)"}
    assert all(abs(gap) < 1e-9 for gap in static["certificate"]["best_response_gap"].values())
    # 2. the dynamic game: certified, both plans at full speed first, 1 apart
    rail = json.loads((tmp_path / "runs/rail/summary.json").read_text())
    assert rail["status"] == "converged"
    assert all(kind.startswith("over ") for kind in rail["certificate"]["best_response_kind"].values())
    assert rail["solution"]["alice"]["v1"][:3] == pytest.approx([0.5, 0.5, 0.5])
    assert rail["solution"]["bob"]["v2"] == pytest.approx(rail["solution"]["alice"]["v1"])
    # 3. the closed loops: every sampling time solved, the error gone by the end, smaller with more iterations
    loop = json.loads((tmp_path / "runs/rail-loop/summary.json").read_text())
    assert loop["status"] == "completed" and sorted(loop["by_K"], key=int) == ["1", "2", "5"]
    for K, run in loop["by_K"].items():
        assert run["failed_steps"] == [] and run["completed_steps"] == 12, K
        assert run["final_e_norm"] < 1e-10, K
    assert loop["by_K"]["1"]["max_e_norm"] > loop["by_K"]["5"]["max_e_norm"]
    k10 = json.loads((tmp_path / "runs/rail-k10/summary.json").read_text())
    assert sorted(k10["by_K"], key=int) == ["1", "10"] and k10["by_K"]["10"]["completed_steps"] == 6
    # 4. figures and the recording, as the page names them
    for name in ("study1.png", "study1.pdf", "rail-study2.png", "rail-study2.pdf"):
        assert (tmp_path / "figures" / name).stat().st_size > 1000, name
    assert (tmp_path / "rail.rrd").stat().st_size > 1000

