"""Figures and inspection from run logs alone, including logs of runs that were killed."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from gnerun.language.config import load_config
from gnerun.log.mcap_log import read_run
from gnerun.runs.closed_loop import simulate
from gnerun.runs.solving import solve
from gnerun.view.figures import make_figures, write_figures

from .conftest import CONFIGS, run_cli


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("runs")
    out = {"clean": root / "clean", "noisy": root / "noisy", "study2": root / "study2", "study3": root / "study3"}
    solve(load_config(CONFIGS / "paper_study1.yaml"), out=out["clean"])
    solve(load_config(CONFIGS / "paper_study1_disturbed.yaml"), out=out["noisy"])
    simulate(load_config(CONFIGS / "paper_study2.yaml", {"run.steps": 12}), out=out["study2"])
    simulate(load_config(CONFIGS / "paper_study3.yaml", {"run.steps": 10}), out=out["study3"])
    return out


def _as_logged(values) -> np.ndarray:
    return np.array([1e-17 if v == 0 else v if v is not None and v > 0 else math.nan for v in values], dtype=float)


def test_the_plotted_data_are_the_logged_data(runs) -> None:
    figures = make_figures([runs["clean"], runs["noisy"], runs["study2"], runs["study3"]])
    assert sorted(figures) == ["paper-study2-study2", "paper-study3-study3", "study1"]
    # Study 1: one panel per solve, ||z^k - z*|| against k
    for ax, run in zip(figures["study1"].axes, ("clean", "noisy"), strict=True):
        [line] = ax.get_lines()
        iterates = read_run(runs[run]).messages["/solve/iterate"]
        np.testing.assert_array_equal(line.get_xdata(), [m["k"] for m in iterates])
        np.testing.assert_array_equal(line.get_ydata(), _as_logged([m["error_norm"] for m in iterates]))
        assert ax.get_yscale() == "log"
    # Study 2: x(t) of the largest K, ||e(t)|| per K
    record = read_run(runs["study2"])
    ax_x, ax_e = figures["paper-study2-study2"].axes
    states = record.messages["/K7/mpc/state"]
    for j, line in enumerate(ax_x.get_lines()):
        np.testing.assert_array_equal(line.get_ydata(), [m["x"][j] for m in states])
    assert [t.get_text() for t in ax_e.get_legend().get_texts()] == [f"K = {k}" for k in (1, 2, 3, 5, 7)]
    for line, K in zip(ax_e.get_lines(), (1, 2, 3, 5, 7), strict=True):
        np.testing.assert_array_equal(line.get_ydata(), _as_logged([m["e_norm"] for m in record.messages[
            f"/K{K}/mpc/error"]]))
    # Study 3: per-agent errors, one panel per K
    record = read_run(runs["study3"])
    for ax, K in zip(figures["paper-study3-study3"].axes, (2, 5), strict=True):
        errors = record.messages[f"/K{K}/mpc/error"]
        for line, agent in zip(ax.get_lines(), ("agent1", "agent2", "agent3"), strict=True):
            assert line.get_label() == agent
            np.testing.assert_array_equal(line.get_ydata(), _as_logged([m["e_norm_agent"][agent] for m in errors]))


def test_figures_are_written_as_png_and_pdf(runs, tmp_path: Path) -> None:
    written = write_figures([runs["study2"]], tmp_path, ["png", "pdf"])
    assert sorted(p.name for p in written) == ["paper-study2-study2.pdf", "paper-study2-study2.png"]
    assert (tmp_path / "paper-study2-study2.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (tmp_path / "paper-study2-study2.pdf").read_bytes()[:5] == b"%PDF-"


def _truncated(run: Path, tmp_path: Path, fraction: float) -> Path:
    data = (run / "run.mcap").read_bytes()
    target = tmp_path / f"killed-{fraction}.mcap"
    target.write_bytes(data[: int(len(data) * fraction)])
    return target


def test_a_truncated_log_keeps_every_complete_chunk(runs, tmp_path: Path) -> None:
    full = read_run(runs["study2"])
    assert full.complete
    for fraction in (0.3, 0.6, 0.95):
        cut = read_run(_truncated(runs["study2"], tmp_path, fraction))
        assert not cut.complete and cut.config_yaml == full.config_yaml and cut.metadata == full.metadata
        assert 0 < cut.message_count <= full.message_count
        if fraction < 0.9:  # cut inside the data section (at 0.95 only the index is lost)
            assert cut.message_count < full.message_count
        for topic, msgs in cut.messages.items():  # a prefix of what was written
            assert msgs == full.messages[topic][: len(msgs)]


def test_cli_inspect_and_figures_on_finished_and_killed_runs(runs, tmp_path: Path) -> None:
    proc = run_cli("inspect", str(runs["study2"]))
    assert proc.returncode == 0, proc.stderr
    assert "finished log" in proc.stdout and "status: completed" in proc.stdout and "/K7/mpc/error" in proc.stdout
    killed = _truncated(runs["study2"], tmp_path, 0.6)
    proc = run_cli("inspect", str(killed))
    assert proc.returncode == 0, proc.stderr
    assert "unfinished log" in proc.stdout and "status: incomplete" in proc.stdout
    proc = run_cli("figures", str(killed), str(runs["clean"]), "--out", str(tmp_path / "f"), "--format", "png")
    assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in (tmp_path / "f").iterdir()) == ["paper-study1-study1.png", "paper-study2-study2.png"]


@pytest.mark.parametrize("args, needle", [
    (["figures", "nowhere", "--out", "x"], "no run log here"),
    (["inspect", "nowhere"], "no run log here"),
    (["figures", str(CONFIGS), "--out", "x"], "no run log here"),
])
def test_bad_runs_are_input_errors(args, needle) -> None:
    proc = run_cli(*args)
    assert proc.returncode == 2 and needle in proc.stderr and "Traceback" not in proc.stderr


def test_bad_format(runs) -> None:
    proc = run_cli("figures", str(runs["clean"]), "--format", "gif")
    assert proc.returncode == 2 and "choose from png, pdf, svg" in proc.stderr


def test_recover_writes_an_indexed_copy(runs, tmp_path: Path) -> None:
    killed = _truncated(runs["study2"], tmp_path, 0.6)
    cut = read_run(killed)
    target = tmp_path / "repaired.mcap"
    proc = run_cli("recover", str(killed), "--out", str(target))
    assert proc.returncode == 0, proc.stderr
    repaired = read_run(target)
    assert repaired.complete  # readable through its index again
    assert repaired.messages == cut.messages and repaired.log_times == cut.log_times
    assert repaired.config_yaml == cut.config_yaml and repaired.metadata == cut.metadata
