"""Size estimates before building (gnerun/language/size.py): they agree with the compiled games, huge configs are
refused or warned about with the estimate in the message while validate stays fast, and a closed loop allocates
nothing by run.steps."""

from __future__ import annotations

import json
import signal
import subprocess
import time

import pytest
import yaml

from gnerun.errors import ConfigError
from gnerun.game.compile import compile_game
from gnerun.language.config import load_config
from gnerun.language.size import DENSE_LIMIT, SPARSE_WARN, estimate

from .conftest import CONFIGS, gnerun_command, shipped_configs
from .test_reliability import _wait_for_steps


@pytest.mark.parametrize("path", shipped_configs(), ids=lambda p: p.stem)
def test_the_estimate_counts_what_the_compiled_game_has(path) -> None:
    cfg = load_config(path)
    size = estimate(cfg)
    game = compile_game(cfg)
    assert size.decisions == game.n
    # rows that depend on no decision (an initial state's constraint) are checked, not compiled: at most that many
    assert game.m <= size.multipliers <= game.m + len(cfg.game.agents) * 4 + 8, (size.multipliers, game.m)
    assert size.nodes > 0 and size.states == (0 if cfg.game.kind == "static" else game.nx * (cfg.game.horizon + 1))


def test_the_estimate_takes_the_formulation_auto_takes() -> None:
    from gnerun.language import size
    from gnerun.language.config import LinearDynamics
    from gnerun.runs import solving
    from gnerun.runs.solving import SPARSE_FROM

    assert (size.SPARSE_WORK, size.SPARSE_FROM) == (solving.SPARSE_WORK, solving.SPARSE_FROM)
    checked = 0
    for path in shipped_configs():
        cfg = load_config(path)
        if cfg.game.kind == "dynamic":
            game = compile_game(cfg)
            dense = solving.formulation(cfg, game) == "condensed"
            size_ = estimate(cfg)
            if not isinstance(cfg.game.dynamics, LinearDynamics) and size_.decisions + size_.multipliers < SPARSE_FROM:
                # expressions that may be found linear when compiled: below SPARSE_FROM unknowns counted as dense
                assert size_.dense, path.stem
                continue
            if game.lq.linear_dynamics and not isinstance(cfg.game.dynamics, LinearDynamics):
                assert size_.dense or not dense, path.stem  # counted as nonlinear: dense or agreeing
                continue
            assert size_.dense == dense, path.stem
            checked += 1
    assert checked >= 5


def _validate(*args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    """validate in a real process; the timeout catches a hang (it is not a timing measurement)."""
    return subprocess.run([*gnerun_command(), "validate", *args], capture_output=True, text=True, timeout=timeout,
                          stdin=subprocess.DEVNULL)


@pytest.mark.slow
def test_validate_stays_fast_on_huge_configs(tmp_path) -> None:
    study2 = str(CONFIGS / "paper_study2.yaml")
    # horizon 10,000 for ssn: the sparse formulation, linear in T: a warning, and validate does not build it
    proc = _validate(study2, "--set", "game.horizon=10000")
    assert proc.returncode == 0, proc.stderr
    warning, certificate = proc.stderr.strip().splitlines()  # the game, and the certificate a solve would build
    assert "a large certificate" in certificate and "the largest with 30,003 unknowns" in certificate, certificate
    assert warning.startswith(f"warning: {study2}: a large game: estimated 130,013 unknowns in the sparse "
                              "formulation (30,003 decisions, 40,004 multipliers") and f"{SPARSE_WARN:,}" in warning
    assert "not built, as it is large" in proc.stdout
    # and for jn and distributed: a dense system of 70,007 unknowns, refused where horizon is written
    row = (CONFIGS / "paper_study2.yaml").read_text().splitlines().index("  horizon: 10") + 1
    for kind in ("jn", "distributed"):
        config = tmp_path / f"{kind}.yaml"
        config.write_text((CONFIGS / "paper_study2.yaml").read_text().replace("  horizon: 10", "  horizon: 10000")
                          .replace("kind: ssn", f"kind: {kind}").replace("globalization: none", "globalization: auto"))
        proc = _validate(str(config))
        assert proc.returncode == 2
        [line] = proc.stderr.strip().splitlines()
        assert line.startswith(f"error: {config}:{row}:12: game.horizon: the game is too large: estimated 70,007 "
                               "unknowns in the dense formulation") and f"the limit is {DENSE_LIMIT:,}" in line, line
    # 5,000 agents written out
    agents = [{"name": f"p{i}", "variables": {f"x{i}": {"lower": 0, "upper": 10}},
               "cost": f"x{i}**2 - x{i}*x{(i + 1) % 5000}"} for i in range(5000)]
    many = tmp_path / "many.yaml"
    many.write_text(yaml.safe_dump({"name": "many", "game": {"kind": "static", "agents": agents}}))
    proc = _validate(str(many))
    assert proc.returncode == 2 and "estimated 15,000 unknowns in the dense formulation (5,000 decisions, 10,000 " \
                                    "multipliers)" in proc.stderr, proc.stderr
    # a K list of 20,000
    klist = tmp_path / "klist.yaml"
    data = yaml.safe_load((CONFIGS / "paper_study2.yaml").read_text())
    data["run"]["K"] = list(range(1, 20001))
    klist.write_text(yaml.safe_dump(data))
    proc = _validate(str(klist))
    assert proc.returncode == 2 and "run.K: List should have at most 1000 items" in proc.stderr


def test_validate_does_not_build_a_game_of_many_expression_nodes() -> None:
    """30 cars of the merge: 15,900 unknowns (below the sparse warning) but 147,330 expression nodes, which took
    validate 13 s to build; now a warning with the estimate, and validate answers without building."""
    merge = str(CONFIGS / "algames_merge_n.yaml")
    proc = _validate(merge, "--set", "game.parameters.N=30")
    assert proc.returncode == 0, proc.stderr
    warning, certificate = proc.stderr.strip().splitlines()  # the game, and the certificate a solve would build
    assert "a large certificate" in certificate and "the largest with 8,780 unknowns" in certificate, certificate
    assert warning.startswith(f"warning: {merge}: a large game: estimated 15,900 unknowns in the sparse formulation") \
        and "147,330 expression nodes" in warning and "(more than 100,000 expression nodes)" in warning, warning
    assert "not built, as it is large" in proc.stdout


def test_a_config_past_the_limit_is_refused_by_the_library_too() -> None:
    with pytest.raises(ConfigError, match="the game is too large: estimated 70,007 unknowns"):
        load_config(CONFIGS / "paper_study2.yaml", {"game.horizon": 10000, "solver.kind": "distributed"})


def test_ten_million_steps_stream_instead_of_allocating(tmp_path) -> None:
    """run.steps 10^7 used to allocate GBs before the first step; now the loop's memory is that of its steps."""
    out = tmp_path / "run"
    proc = subprocess.Popen([*gnerun_command(), "simulate", str(CONFIGS / "paper_study2.yaml"), "--out", str(out),
                             "--set", "run.steps=10000000", "--set", "run.K=[1]"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL)
    try:
        _wait_for_steps(out, proc, 50_000)
        time.sleep(1)
        with open(f"/proc/{proc.pid}/status") as f:
            peak_kb = next(int(line.split()[1]) for line in f if line.startswith("VmHWM:"))
        proc.send_signal(signal.SIGINT)
        _, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    print(f"run.steps 10^7: peak resident memory {peak_kb / 1024:.0f} MB")
    assert peak_kb < 400 * 1024  # the arrays of 10^7 steps alone would be 12 GB
    assert stderr.splitlines()[0].startswith("warning: ") and "up to 10,000,000 solver steps" in stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "interrupted" and summary["steps"] == 10_000_000
    assert 0 < summary["by_K"]["1"]["completed_steps"] == len(summary["by_K"]["1"]["u"]) < 10_000_000


def test_the_certificates_agent_problems_are_estimated_before_a_solve() -> None:
    """paper_study1 at horizon 2,000: the certificate built each agent's own problem (4,002 to 6,003 unknowns,
    condensed and dense) in 377 s and 6.3 GB with no word; now solve and validate warn with that estimate, and
    simulate, which builds no certificate, does not."""
    cfg = load_config(CONFIGS / "paper_study1.yaml", {"game.horizon": 2000})
    assert cfg.size.responses == (4002, 4002, 6003)
    [warning] = [w for w in cfg.size_warnings("solve") if "certificate" in w]
    assert "the largest with 6,003 unknowns: about 374 s and 6.3 GB for the 3 agents" in warning
    assert any("certificate" in w for w in cfg.size_warnings("validate"))
    assert not any("certificate" in w for w in cfg.size_warnings("simulate"))
    off = load_config(CONFIGS / "paper_study1.yaml", {"game.horizon": 2000, "run.certificate": False})
    assert not any("certificate" in w for w in off.size_warnings("solve"))
    assert not any("certificate" in w for w in load_config(CONFIGS / "paper_study1.yaml").size_warnings("solve"))
