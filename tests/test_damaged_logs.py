"""Damaged and edited run logs: generated variants of real logs (bit flips, patched lengths and sizes, cuts,
zeroed ranges, garbage, edited messages and attachments) go through inspect, recover, figures and replay.

The only outcomes allowed are exit code 0 (what can be read is used; the note says what was damaged) or 2 (one
line that says the log is damaged), never a traceback. A copy that recover writes is a finished, indexed log
whose messages are messages of the damaged one. The variants are derandomized (the same on every machine);
their count is checked (at least 200).
"""

from __future__ import annotations

import json
import random
import struct
from collections import Counter
from collections.abc import Iterator
from pathlib import Path

import pytest
import zstandard
from mcap.writer import CompressionType, Writer
from typer.testing import CliRunner

from gnerun.cli import app
from gnerun.language.config import load_config
from gnerun.log.mcap_log import MCAP_MAGIC, DamagedLog, read_run
from gnerun.runs.closed_loop import simulate
from gnerun.runs.solving import solve

from .conftest import CONFIGS, run_cli

OUTCOMES: Counter[str] = Counter()


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> dict[str, bytes]:
    root = tmp_path_factory.mktemp("logs")
    simulate(load_config(CONFIGS / "paper_study2.yaml", {"run.steps": 5, "run.K": [1, 3]}), out=root / "loop")
    solve(load_config(CONFIGS / "fk_a12.yaml"), out=root / "solve")
    return {name: (root / name / "run.mcap").read_bytes() for name in ("loop", "solve")}


def _records(data: bytes) -> Iterator[tuple[int, int, int]]:
    """(offset, opcode, length) of every top-level record (the framing: opcode u8, length u64)."""
    pos = len(MCAP_MAGIC)
    while pos + 9 <= len(data) - len(MCAP_MAGIC):
        opcode, length = data[pos], struct.unpack_from("<Q", data, pos + 1)[0]
        yield pos, opcode, length
        pos += 9 + length


def _patched(data: bytes, offset: int, value: int, width: int = 8) -> bytes:
    fmt = {8: "<Q", 4: "<I"}[width]
    return data[:offset] + struct.pack(fmt, value % (1 << (8 * width))) + data[offset + width:]


CHUNK, ATTACHMENT = 0x06, 0x09


def variants(logs: dict[str, bytes]) -> Iterator[tuple[str, bytes]]:
    """(name, bytes): at least 200 damaged or edited logs."""
    rng = random.Random(18)
    for source, data in logs.items():
        for i in range(30):  # bit flips, 1 to 3 anywhere
            d = bytearray(data)
            for _ in range(rng.randint(1, 3)):
                pos = rng.randrange(len(d))
                d[pos] ^= 1 << rng.randrange(8)
            yield f"{source}: bit flips {i}", bytes(d)
        records = list(_records(data))
        lengths = [0, 1, 7, 2**31, 2**40, 2**63, 2**64 - 1]
        for j, (pos, _opcode, length) in enumerate(records[:: max(1, len(records) // 12)]):
            for value in rng.sample(lengths, 2) + [length + 1]:
                yield f"{source}: record {j} length {value}", _patched(data, pos + 1, value)
        chunks = [(pos, length) for pos, opcode, length in records if opcode == CHUNK]
        for j, (pos, _length) in enumerate(chunks[:6]):  # the chunk's own sizes and compressed data
            body = pos + 9  # start time u64, end time u64, uncompressed size u64, crc u32, compression str, data
            for value in (0, 10, 2**33, 2**62):
                yield f"{source}: chunk {j} uncompressed size {value}", _patched(data, body + 16, value)
            comp_len = struct.unpack_from("<I", data, body + 28)[0]
            records_at = body + 32 + comp_len
            yield f"{source}: chunk {j} records length 2**60", _patched(data, records_at, 2**60)
            yield f"{source}: chunk {j} zstd frame zeroed", (data[:records_at + 8] + b"\0" * 16
                                                             + data[records_at + 24:])
        for pos, opcode, _length in records:
            if opcode == ATTACHMENT:  # name string length, then the data length further on
                yield f"{source}: attachment name length", _patched(data, pos + 9 + 16, 2**31, 4)
        for i in range(15):  # cut anywhere
            yield f"{source}: cut {i}", data[: rng.randrange(len(data))]
        for i in range(10):  # a range zeroed
            a = rng.randrange(len(data))
            yield f"{source}: zeroed {i}", data[:a] + b"\0" * 64 + data[a + 64:]
        yield f"{source}: garbage appended", data + bytes(rng.randrange(256) for _ in range(500))
        yield f"{source}: the data section twice", data[:-len(MCAP_MAGIC)] + data[len(MCAP_MAGIC):]
    yield "empty file", b""
    yield "the magic alone", MCAP_MAGIC
    yield "the magic twice", MCAP_MAGIC * 2
    yield "random bytes", bytes(rng.randrange(256) for _ in range(4000))
    yield "random bytes after the magic", MCAP_MAGIC + bytes(rng.randrange(256) for _ in range(4000))
    yield from edited()


def _written(messages: list[tuple[str, object]], config: bytes = b"name: x\n", chunked: bool = True) -> bytes:
    """A log written by another tool: gnerun's topics, with payloads chosen by the test."""
    import io

    out = io.BytesIO()
    w = Writer(out, compression=CompressionType.ZSTD if chunked else CompressionType.NONE)
    w.start(profile="gnerun", library="test")
    schema = w.register_schema(name="x", encoding="jsonschema", data=b"{}")
    channels: dict[str, int] = {}
    w.add_attachment(create_time=0, log_time=0, name="config.yaml", media_type="application/yaml", data=config)
    w.add_metadata("gnerun.run", {"config_name": "x" * 500, "version": "\x1b[31mred"})
    for t, (topic, payload) in enumerate(messages):
        if topic not in channels:
            channels[topic] = w.register_channel(topic=topic, message_encoding="json", schema_id=schema)
        data = payload if isinstance(payload, bytes) else json.dumps(payload).encode()
        w.add_message(channel_id=channels[topic], log_time=t, publish_time=t, data=data, sequence=t)
    w.finish()
    return out.getvalue()


STATE = {"t": 0, "x": [1.0, 2.0, 3.0], "u": [0.1, 0.2, 0.3]}
ERROR = {"t": 0, "e_norm": 0.5, "e_norm_agent": {"a": 0.1}}
ITERATE = {"k": 0, "z": [1.0], "residual_norm": 1.0, "log10_residual_norm": 0.0, "error_norm": None,
           "step_norm": None, "active_set_changes": 0}


def edited() -> Iterator[tuple[str, bytes]]:
    """Logs with edited payloads: each message or attachment wrong in one way."""
    wrong: list[tuple[str, object]] = [
        ("/K1/mpc/state", [1, 2, 3]), ("/K1/mpc/state", {"t": 0}), ("/K1/mpc/state", {**STATE, "x": "abc"}),
        ("/K1/mpc/state", {**STATE, "t": "zero"}), ("/K1/mpc/state", b"{not json"), ("/K1/mpc/state", b"\xff\xfe"),
        ("/K1/mpc/error", {**ERROR, "e_norm_agent": [1, 2]}), ("/K1/mpc/error", {"t": 0, "e_norm": "x"}),
        ("/K1/mpc/error", b"[" * 20000 + b"]" * 20000), ("/solve/iterate", {**ITERATE, "k": None}),
        ("/solve/iterate", {**ITERATE, "z": {"a": 1}}), ("/log", {"level": 3}), ("/log", "text"),
        ("/K99999999999999999999/mpc/state", STATE), ("/other/topic", [1, 2]), ("/other/topic", {"a": 1}),
        ("/K1/mpc/state", {**STATE, "x": [1e308, -1e308, 1e-320]}),
        ("/K1/mpc/iterate", {"t": 0, "k": 0, "residual_norm": None, "error_norm": None}),
    ]
    good = [("/K1/mpc/state", STATE), ("/K1/mpc/error", ERROR), ("/solve/iterate", ITERATE)]
    for i, item in enumerate(wrong):
        yield f"edited message {i}: {item[0]}", _written(good + [item] + good)
        yield f"edited message {i} alone, unchunked", _written([item], chunked=False)
    configs = [b"!!python/object/apply:os.system ['echo hi']", b"- a\n- b\n", b"[" * 20000 + b"]" * 20000,
               b"a: " + b"{b: " * 5000 + b"1" + b"}" * 5000, b"\xff\xfe", b"", b"name: [1, 2", b"x: *nope",
               b"a: &a [*a]", b"game: {kind: dynamic, states: 7, agents: {x: 1}}", b"game: {states: [x1], agents: ab}",
               b"game: {states: [px1, py1], parameters: [1, 2], agents: [{name: a, constraints: 5}]}",
               b"game: {states: [px1, py1], agents: [{name: a, constraints: ['px1 <= ']}], shared_constraints: 7}"]
    for i, config in enumerate(configs):
        yield f"edited config {i}", _written(good, config=config)


def _without_nulls(message: dict) -> dict:
    return {k: _without_nulls(v) if isinstance(v, dict) else v for k, v in message.items() if v is not None}


def _invoke(*args: str):
    result = CliRunner().invoke(app, list(args))
    text = result.output
    assert result.exception is None or isinstance(result.exception, SystemExit), (args, repr(result.exception))
    assert "Traceback" not in text, (args, text)
    assert result.exit_code in (0, 2), (args, result.exit_code, text)
    if result.exit_code == 2:
        lines = [line for line in text.splitlines() if line.strip()]
        assert len(lines) == 1 and lines[0].startswith("error: "), (args, text)
    return result


@pytest.mark.slow
def test_every_damaged_log_is_read_in_part_or_refused_in_one_line(logs, tmp_path: Path) -> None:
    count = 0
    for name, data in variants(logs):
        count += 1
        run = tmp_path / f"v{count}"
        run.mkdir()
        (run / "run.mcap").write_bytes(data)
        inspected = _invoke("inspect", str(run))
        try:
            record = read_run(run)
        except DamagedLog as e:
            assert inspected.exit_code == 2 and "damaged log" in str(e), (name, inspected.output)
            OUTCOMES["refused"] += 1
            recovered = _invoke("recover", str(run))
            assert recovered.exit_code == 2 and not (run / "run.recovered.mcap").exists(), name
            continue
        assert inspected.exit_code == 0, (name, inspected.output)
        OUTCOMES["damage noted" if record.damage else "read"] += 1
        if record.damage:
            assert "damaged log" in inspected.output, (name, inspected.output)
        # recover keeps what can be kept: a finished copy of the readable messages, read back through its index
        recovered = _invoke("recover", str(run))
        assert recovered.exit_code == 0, (name, recovered.output)
        copy = read_run(run / "run.recovered.mcap")
        assert copy.complete and all("config.yaml" in d for d in copy.damage), name  # its text is kept as it was
        for topic, msgs in copy.messages.items():  # (the copy leaves missing values out, as gnerun writes)
            assert msgs == [_without_nulls(m) for m in record.messages[topic][: len(msgs)]], (name, topic)
        if count % 12 == 0:  # the readers that draw: one variant in twelve (matplotlib and rerun take longer)
            _invoke("figures", str(run), "--out", str(tmp_path / "figs"), "--format", "png")
            _invoke("replay", str(run), "--save", str(tmp_path / "r.rrd"))
    print(f"\ndamaged logs: {count} variants: " + ", ".join(f"{k} {v}" for k, v in sorted(OUTCOMES.items())))
    assert count >= 200
    assert OUTCOMES["refused"] >= 5 and OUTCOMES["damage noted"] >= 50 and OUTCOMES["read"] >= 1, OUTCOMES


@pytest.mark.slow
def test_the_real_command_line_says_damaged_log_in_one_line(logs, tmp_path: Path) -> None:
    """In real processes: an empty log, a random one, and an unfinished one whose chunk claims 2**62 bytes (a
    MemoryError before such logs were read at the reader level)."""
    data = logs["loop"]
    chunk = next(pos for pos, opcode, _ in _records(data) if opcode == CHUNK)
    cases = {"empty": b"", "random": bytes(random.Random(1).randrange(256) for _ in range(3000)),
             "huge chunk": _patched(data, chunk + 9 + 16, 2**62)[: len(data) * 3 // 4]}
    for name, content in cases.items():
        run = tmp_path / name.replace(" ", "-")
        run.mkdir()
        (run / "run.mcap").write_bytes(content)
        for command in (["inspect", str(run)], ["recover", str(run)], ["figures", str(run), "--out", str(tmp_path)],
                        ["replay", str(run), "--save", str(tmp_path / "x.rrd")]):
            proc = run_cli(*command)
            assert "Traceback" not in proc.stderr + proc.stdout, (name, command, proc.stderr)
            if name == "huge chunk":
                assert proc.returncode == 0, (command, proc.stderr)
                if command[0] == "inspect":
                    assert "damaged log: a damaged chunk" in proc.stdout
            else:
                [line] = proc.stderr.strip().splitlines()
                assert proc.returncode == 2 and "damaged log" in line, (name, command, proc.stderr)


def test_a_damaged_chunk_in_the_middle_loses_that_chunk_only(logs, tmp_path: Path) -> None:
    data = logs["loop"]
    full = tmp_path / "full"
    full.mkdir()
    (full / "run.mcap").write_bytes(data)
    whole = read_run(full)
    chunks = [(pos, length) for pos, opcode, length in _records(data) if opcode == CHUNK]
    pos, length = chunks[len(chunks) // 2]
    middle = pos + 9 + length // 2
    (full / "run.mcap").write_bytes(data[:middle] + bytes([data[middle] ^ 0xFF]) + data[middle + 1:])
    damaged = read_run(full)
    lost = whole.message_count - damaged.message_count
    assert not damaged.complete and damaged.damage and 0 < lost < whole.message_count // 4
    # what is kept is the log's own, in order, with the damaged chunk's messages missing
    for topic, msgs in damaged.messages.items():
        assert all(m in whole.messages[topic] for m in msgs)
    assert zstandard  # the chunks are zstd-compressed: the damage reached the compressed data
