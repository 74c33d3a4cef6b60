"""Reading and writing files safely (gnerun/files.py): planted symbolic links are never written through, special
files are refused before they are read (a FIFO never blocks), temporary files never outlive a write."""

from __future__ import annotations

import os
import stat
import subprocess
from pathlib import Path

import pytest

from gnerun.errors import InputError
from gnerun.files import read_regular, replace_text, replacing, write_text
from gnerun.log.mcap_log import read_run

from .conftest import CONFIGS, gnerun_command, run_cli

FK = str(CONFIGS / "fk_a12.yaml")


def _run(tmp_path: Path) -> Path:
    run = tmp_path / "run"
    assert run_cli("solve", FK, "--out", str(run), "-q").returncode == 0
    return run


def _precious(tmp_path: Path) -> Path:
    target = tmp_path / "precious.txt"
    target.write_text("keep me\n")
    return target


@pytest.mark.parametrize("name", ["config.yaml", "run.mcap"])
def test_force_never_writes_through_a_planted_link(name: str, tmp_path) -> None:
    run, target = _run(tmp_path), _precious(tmp_path)
    (run / name).unlink()
    (run / name).symlink_to(target)
    proc = run_cli("solve", FK, "--out", str(run), "--force", "-q")
    assert proc.returncode == 2, proc.stderr
    [line] = proc.stderr.strip().splitlines()
    assert line == f"error: {run / name}: is a symbolic link; gnerun does not write through one (remove it, or " \
                   "choose another output)"
    assert target.read_text() == "keep me\n"
    assert not (run / ".gnerun.lock").exists()  # the lock went with the refusal


@pytest.mark.parametrize("name", ["summary.json.tmp", "summary.json"])
def test_a_link_planted_at_the_summary_or_its_temporary_is_replaced_not_followed(name: str, tmp_path) -> None:
    run, target = _run(tmp_path), _precious(tmp_path)
    (run / name).unlink(missing_ok=True)
    (run / name).symlink_to(target)
    proc = run_cli("solve", FK, "--out", str(run), "--force", "-q")
    assert proc.returncode == 0, proc.stderr
    assert target.read_text() == "keep me\n"
    assert not (run / "summary.json").is_symlink() and (run / "summary.json").read_text().startswith("{")
    assert sorted(p.name for p in run.iterdir()) == ["config.yaml", "run.mcap", "summary.json"]


def test_recover_never_overwrites_without_force_nor_through_a_link(tmp_path) -> None:
    run, target = _run(tmp_path), _precious(tmp_path)
    copy = run / "run.recovered.mcap"
    copy.symlink_to(target)
    for extra in ([], ["--force"]):
        proc = run_cli("recover", str(run), *extra)
        assert proc.returncode == 2 and "symbolic link" in proc.stderr, proc.stderr
    assert target.read_text() == "keep me\n"
    copy.unlink()
    copy.write_text("an earlier copy\n")
    proc = run_cli("recover", str(run))
    assert proc.returncode == 2 and "exists (use --force to overwrite it)" in proc.stderr
    assert copy.read_text() == "an earlier copy\n"
    assert run_cli("recover", str(run), "--force").returncode == 0
    assert read_run(copy).complete
    assert not list(run.glob("*.tmp"))


def test_special_files_are_refused_unread(tmp_path) -> None:
    fifo = tmp_path / "fifo.yaml"
    os.mkfifo(fifo)
    run = tmp_path / "run"
    run.mkdir()
    os.mkfifo(run / "run.mcap")
    cases = [(["validate", "/dev/zero"], "/dev/zero: is a character device, not a config file"),
             (["validate", str(fifo)], f"{fifo}: is a FIFO, not a config file"),
             (["solve", str(tmp_path)], f"{tmp_path}: is a directory, not a config file"),
             (["inspect", str(run)], f"{run / 'run.mcap'}: is a FIFO, not a run log")]
    for args, message in cases:
        proc = subprocess.run([*gnerun_command(), *args], capture_output=True, text=True, timeout=60,
                              stdin=subprocess.DEVNULL)  # a hang fails here instead of stalling the suite
        assert proc.returncode == 2, (args, proc.stderr)
        [line] = proc.stderr.strip().splitlines()
        assert line == f"error: {message}", line


def test_recover_never_replaces_a_special_file(tmp_path) -> None:
    """--force overwrites a copy, never a FIFO or a device that stands where the copy goes (it used to replace the
    node with a regular file: `recover --out /dev/null --force` as root)."""
    run = _run(tmp_path)
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    proc = subprocess.run([*gnerun_command(), "recover", str(run), "--out", str(fifo), "--force"],
                          capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)
    assert proc.returncode == 2, proc.stderr
    [line] = proc.stderr.strip().splitlines()
    assert line == f"error: {fifo}: is a FIFO; the repaired copy is a regular file", line
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert not list(tmp_path.glob("*.tmp"))


def test_a_refused_log_leaves_no_output_behind(tmp_path) -> None:
    """replay --save and figures on a damaged log: exit 2, no recording begun (an earlier one left as it was) and
    no figures folder made."""
    run = tmp_path / "run"
    run.mkdir()
    (run / "run.mcap").write_bytes(b"")
    earlier = tmp_path / "earlier.rrd"
    earlier.write_text("an earlier recording\n")
    for args in (["replay", str(run), "--save", str(tmp_path / "new.rrd")],
                 ["replay", str(run), "--save", str(earlier)], ["figures", str(run), "--out", str(tmp_path / "figs")],
                 ["replay", str(run), "--save", str(tmp_path / "x.rrd"), "--serve", "--web-port", "0"]):
        proc = run_cli(*args)
        assert proc.returncode == 2, proc.stderr
    assert earlier.read_text() == "an earlier recording\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["earlier.rrd", "run"]


def test_a_sweep_never_writes_a_point_through_a_planted_link(tmp_path) -> None:
    """A point's directory, or points/, replaced by a link to another directory: the sweep resumes with --force
    semantics inside its points, so it would have written config.yaml, run.mcap and summary.json there."""
    from gnerun.log.sweep_index import read_index
    from gnerun.runs.sweep import load_sweep, run_sweep

    spec = tmp_path / "sweep.yaml"
    spec.write_text(f"base: {CONFIGS / 'paper_study2.yaml'}\nset: {{run.K: [1]}}\ngrid:\n  run.steps: [2, 3]\n")
    sw = load_sweep(spec)
    out = tmp_path / "out"
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / "notes.txt").write_text("mine\n")
    (out / "points").mkdir(parents=True)
    (out / sw.points[0].directory).symlink_to(victim)
    result = run_sweep(sw, out, workers=1, force=True)
    assert result.failed == 1 and [r["status"] for r in read_index(out)] == ["error", "completed"]
    assert "is a symbolic link; gnerun does not write through one" in read_index(out)[0]["message"]
    assert sorted(p.name for p in victim.iterdir()) == ["notes.txt"]
    (out / sw.points[0].directory).unlink()
    for point in (out / "points").iterdir():
        for f in point.iterdir():
            f.unlink()
        point.rmdir()
    (out / "points").rmdir()
    (out / "points").symlink_to(victim)
    again = run_sweep(sw, out, workers=1)
    assert again.failed == 2 and sorted(p.name for p in victim.iterdir()) == ["notes.txt"]


def test_reads_are_capped(tmp_path) -> None:
    big = tmp_path / "big"
    big.write_bytes(b"x" * 1001)
    assert read_regular(big, 1001) == b"x" * 1001
    with pytest.raises(InputError, match="is 1001 bytes; the limit is 1000"):
        read_regular(big, 1000)
    with pytest.raises(InputError, match="is a character device"):
        read_regular("/dev/zero", 10**9)


def test_a_replaced_file_appears_whole_or_not_at_all(tmp_path) -> None:
    target = tmp_path / "summary.json"
    replace_text(target, "first\n")
    with pytest.raises(RuntimeError), replacing(target) as f:
        f.write(b"half of")
        raise RuntimeError("the writer stops here")
    assert target.read_text() == "first\n" and sorted(p.name for p in tmp_path.iterdir()) == ["summary.json"]
    precious = _precious(tmp_path)
    link = tmp_path / "link"
    link.symlink_to(precious)
    with pytest.raises(InputError, match="symbolic link"):
        write_text(link, "overwritten")
    assert precious.read_text() == "keep me\n"
