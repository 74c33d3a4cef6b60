"""The MCAP run log, written by real solves and read back with the mcap reader."""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.records import Message
from mcap.stream_reader import StreamReader

from gnerun.language.config import load_config
from gnerun.log.mcap_log import RunLog, read_messages
from gnerun.log.messages import SolveIterate
from gnerun.runs.solving import solve

from .conftest import CONFIGS


@pytest.fixture(scope="module")
def study1_run(tmp_path_factory) -> tuple[Path, object]:
    out = tmp_path_factory.mktemp("runs") / "study1"
    res = solve(load_config(CONFIGS / "paper_study1.yaml"), out=out)
    return out, res


def test_run_directory_holds_config_mcap_and_summary(study1_run) -> None:
    out, res = study1_run
    assert sorted(p.name for p in out.iterdir()) == ["config.yaml", "run.mcap", "summary.json"]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "converged"
    assert summary["iterations"] == res.iterations
    assert len(summary["residual_history"]) == res.iterations + 1
    assert summary["residual_history"][-1] <= 1e-12
    assert set(summary["solution"]) == {"agent1", "agent2", "agent3"}
    assert len(summary["solution"]["agent1"]["u1"]) == 11  # a(0..T), T = 10
    assert set(summary["certificate"]["best_response_gap"]) == {"agent1", "agent2", "agent3"}
    assert summary["error_history"][0] == pytest.approx(np.linalg.norm(res.z_star), rel=1e-12)  # z^0 = 0


def test_every_iterate_is_in_the_log(study1_run) -> None:
    out, res = study1_run
    messages = read_messages(out / "run.mcap")
    topics = {t for t, _, _ in messages}
    assert topics == {"/solve/iterate", "/log"}
    iterates = [m for t, m, _ in messages if t == "/solve/iterate"]
    assert len(iterates) == res.iterations + 1
    assert [m["k"] for m in iterates] == list(range(res.iterations + 1))
    np.testing.assert_array_equal(np.array(iterates[-1]["z"]), res.z)
    summary = json.loads((out / "summary.json").read_text())
    assert [m["residual_norm"] for m in iterates] == summary["residual_history"]
    assert [m["error_norm"] for m in iterates] == summary["error_history"]
    for m in iterates:
        assert m["log10_residual_norm"] == pytest.approx(math.log10(m["residual_norm"]))
    assert "step_norm" not in iterates[0]  # NaN at k = 0 (no step yet) is left out
    logs = [m for t, m, _ in messages if t == "/log"]
    assert any("converged" in m["message"] for m in logs)


def test_config_attachment_and_run_metadata(study1_run) -> None:
    out, _ = study1_run
    config_yaml = (out / "config.yaml").read_text()
    with open(out / "run.mcap", "rb") as f:
        reader = make_reader(f)
        attachments = list(reader.iter_attachments())
        metadata = list(reader.iter_metadata())
        summary = reader.get_summary()
    assert [a.name for a in attachments] == ["config.yaml"]
    assert attachments[0].data.decode() == config_yaml
    assert attachments[0].media_type == "application/yaml"
    [meta] = [m for m in metadata if m.name == "gnerun.run"]
    assert meta.metadata["config_hash"] == hashlib.sha256(config_yaml.encode()).hexdigest()
    assert meta.metadata["version"]
    assert meta.metadata["seed"] == "0"
    assert meta.metadata["git_describe"]
    assert summary is not None and summary.statistics is not None
    assert summary.statistics.message_count == len(read_messages(out / "run.mcap"))
    # the resolved config reloads to the same experiment
    assert load_config(out / "config.yaml") == load_config(CONFIGS / "paper_study1.yaml")


def test_messages_match_their_json_schemas(study1_run) -> None:
    out, _ = study1_run
    with open(out / "run.mcap", "rb") as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages():
            assert schema.encoding == "jsonschema"
            assert channel.message_encoding == "json"
            jsonschema.validate(json.loads(message.data), json.loads(schema.data))


def test_chunks_are_zstd_compressed(study1_run) -> None:
    out, _ = study1_run
    with open(out / "run.mcap", "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.chunk_indexes
    assert all(c.compression == "zstd" for c in summary.chunk_indexes)


def test_nan_inf_and_missing_values_are_left_out(tmp_path: Path) -> None:
    """JSON has no NaN, and a number field of the viewers' schemas admits no null: what is not a finite number is
    not written (an array with such an entry is left out whole, so that no index shifts)."""
    path = tmp_path / "x.mcap"
    with RunLog(path, config_yaml="name: x\n", metadata={"version": "0"}) as log:
        log.write("/solve/iterate", SolveIterate(k=0, z=[1.0, math.nan, math.inf], residual_norm=math.inf,
                                                 log10_residual_norm=None, error_norm=math.nan, step_norm=-math.inf,
                                                 active_set_changes=0))
        log.write("/solve/iterate", SolveIterate(k=1, z=[1.0, 2.0], residual_norm=0.0, error_norm=3.0,
                                                 active_set_changes=2))
    [(topic, first, _), (_, second, _)] = read_messages(path)
    assert topic == "/solve/iterate"
    assert first == {"k": 0, "active_set_changes": 0}
    assert second == {"k": 1, "z": [1.0, 2.0], "residual_norm": 0.0, "error_norm": 3.0, "active_set_changes": 2}
    with open(path, "rb") as f:
        for schema, _, message in make_reader(f).iter_messages():
            jsonschema.validate(json.loads(message.data), json.loads(schema.data))


def test_a_killed_writer_keeps_every_flushed_message(tmp_path: Path) -> None:
    # the bytes on disk after a flush, without finish(): what a SIGKILL leaves behind
    path = tmp_path / "run.mcap"
    log = RunLog(path, config_yaml="name: x\n", metadata={"version": "0"})
    for k in range(3):
        log.write("/solve/iterate", SolveIterate(k=k, z=[float(k)], residual_norm=1.0, log10_residual_norm=0.0,
                                                 error_norm=None, step_norm=None, active_set_changes=0))
        log.flush()
    snapshot = path.read_bytes()
    log.close()
    truncated = tmp_path / "killed.mcap"
    truncated.write_bytes(snapshot)
    messages = []
    with open(truncated, "rb") as f:
        try:
            for record in StreamReader(f, skip_magic=False).records:  # decompresses every complete chunk
                if isinstance(record, Message):
                    messages.append(record)
        except Exception:  # noqa: BLE001 - the stream ends without a footer; what came before counts
            pass
    assert [json.loads(m.data)["k"] for m in messages] == [0, 1, 2]


def test_topic_and_message_type_must_agree(tmp_path: Path) -> None:
    from gnerun.log.messages import LogEntry

    with RunLog(tmp_path / "x.mcap", config_yaml="", metadata={}) as log, pytest.raises(TypeError):
        log.write("/solve/iterate", LogEntry.make("info", "wrong topic", 0))
