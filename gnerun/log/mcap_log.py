"""The run log: an MCAP file that the solver loops write to.

JSON messages with JSON Schemas (:mod:`gnerun.log.messages`: the subset Foxglove and Lichtblick read),
zstd-compressed chunks, the ``gnerun.run`` metadata record and the resolved ``config.yaml`` as an
attachment. The log is a sink: loops call :meth:`RunLog.write` and :meth:`RunLog.flush`; nothing in the
maths knows about it. Every flush closes the current chunk and writes it to the file, so a killed run keeps
every message written before its last flush. Messages are stamped with the time set by
:meth:`RunLog.set_time` (a run's own time: a closed loop's simulated time, a solve's iterations), or with
the wall clock.
"""

from __future__ import annotations

import functools
import json
import math
import struct
import time
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np
from mcap.writer import CompressionType, Writer

from ..errors import WriteError
from ..files import open_for_writing
from .messages import TOPICS, LogEntry, Message

PROFILE = "gnerun"


def json_ready(obj: Any) -> Any:
    """numpy values to Python, NaN and Inf to None, recursively (JSON has no NaN; for summary.json)."""
    if isinstance(obj, float | np.floating):
        v = float(obj)
        return v if math.isfinite(v) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.ndarray):
        return json_ready(obj.tolist())
    if isinstance(obj, dict):
        return {str(k): json_ready(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [json_ready(v) for v in obj]
    return obj


class RunLog:
    """An open MCAP run log. Use as a context manager, or call :meth:`close`."""

    def __init__(self, path: str | Path, *, config_yaml: str, metadata: dict[str, str]):
        self.path = Path(path)
        self._file: IO[bytes] = open_for_writing(self.path)  # closed in close(); never through a link
        self._writer = Writer(self._file, compression=CompressionType.ZSTD)
        self._writer.start(profile=PROFILE, library="gnerun")
        self._channels: dict[str, int] = {}
        self._schemas: dict[tuple[str, bytes], int] = {}
        self._time_ns: int | None = None  # None: the wall clock
        self._checked: dict[tuple[str, type], int] = {}
        self._sequence = 0
        self._closed = False
        self._broken: str | None = None  # why writing failed; the log then accepts nothing more
        now = time.time_ns()
        self._writer.add_metadata("gnerun.run", {k: str(v) for k, v in metadata.items()})
        self._writer.add_attachment(create_time=now, log_time=now, name="config.yaml",
                                    media_type="application/yaml", data=config_yaml.encode())
        self.flush()

    def _channel(self, topic: str, message: Message) -> int:
        channel = self._channels.get(topic)
        if channel is None:
            model = type(message)
            # the first message names the keys of per-agent mappings; equal schemas are registered once
            key = (model.channel_schema_name(), json.dumps(model.viewer_schema(message), sort_keys=True).encode())
            schema_id = self._schemas.get(key)
            if schema_id is None:
                schema_id = self._schemas[key] = self._writer.register_schema(name=key[0], encoding="jsonschema",
                                                                              data=key[1])
            channel = self._writer.register_channel(topic=topic, message_encoding="json", schema_id=schema_id)
            self._channels[topic] = channel
        return channel

    def set_time(self, time_ns: int | None) -> None:
        """Stamp the messages that follow with ``time_ns`` (None: the wall clock again)."""
        self._time_ns = time_ns

    def now(self) -> int:
        """The log_time of a message written now."""
        return time.time_ns() if self._time_ns is None else self._time_ns

    def _failed(self, e: OSError) -> WriteError:
        self._broken = e.strerror or str(e)
        return WriteError(f"{self.path}: cannot write the run log: {self._broken} (is the disk full?); "
                          "everything flushed before is readable (gnerun inspect)")

    def write(self, topic: str, message: Message, *, log_time: int | None = None) -> None:
        """Append ``message`` on ``topic`` (its model's schema is registered on first use)."""
        if self._broken is not None:
            return
        try:
            self._write(topic, message, log_time)
        except OSError as e:
            raise self._failed(e) from None

    def _write(self, topic: str, message: Message, log_time: int | None) -> None:
        model = type(message)
        channel = self._checked.get((topic, model))
        if channel is None:
            expected = TOPICS.get(topic) or next((m for t, m in TOPICS.items() if topic.endswith(t)), None)
            if expected is not None and expected is not model:
                raise TypeError(f"topic {topic} carries {expected.__name__}, not {model.__name__}")
            channel = self._checked[(topic, model)] = self._channel(topic, message)
        t = self.now() if log_time is None else log_time
        data = message.to_json()  # compact; missing and non-finite values left out (JSON has no NaN)
        self._writer.add_message(channel_id=channel, log_time=t, publish_time=t, data=data, sequence=self._sequence)
        self._sequence += 1

    def log(self, level: str, text: str) -> None:
        """A ``/log`` text event (a foxglove.Log; ``level``: debug, info, warning or error)."""
        t = self.now()
        self.write("/log", LogEntry.make(level, text, t), log_time=t)

    def flush(self) -> None:
        """Close the chunk in progress and write it out (a killed run keeps it)."""
        if self._broken is not None:
            return
        try:
            self._writer.flush()
        except OSError as e:
            raise self._failed(e) from None

    @property
    def broken(self) -> str | None:
        """Why writing failed (None while it works)."""
        return self._broken

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        try:
            if self._broken is None:
                self._writer.finish()
        except OSError as e:
            raise self._failed(e) from None
        finally:
            try:
                self._file.close()
            except OSError:  # the buffer could not be written: what was flushed is on disk
                pass

    def __enter__(self) -> RunLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass
class RunRecord:
    """Everything a run log holds, read back (see :func:`read_run`)."""

    path: Path
    messages: dict[str, list[dict]]  # topic -> decoded messages, in log-time order
    log_times: dict[str, list[int]]
    config_yaml: str | None
    metadata: dict[str, str]
    complete: bool  # the log was finished (summary and index present)
    note: str  # how it was read

    @property
    def message_count(self) -> int:
        return sum(len(v) for v in self.messages.values())

    @functools.cached_property
    def config(self) -> dict:
        """The resolved config as a mapping ({} when the log has none)."""
        import yaml

        return (yaml.safe_load(self.config_yaml) or {}) if self.config_yaml else {}


def run_log_path(path: str | Path) -> Path:
    """RUN is a run directory or its .mcap file."""
    p = Path(path)
    return p / "run.mcap" if p.is_dir() else p


def read_run(path: str | Path) -> RunRecord:
    """Read a run log. A finished log is read through its index; a log whose writer was killed (no summary,
    a truncated last chunk) is read record by record, keeping every complete chunk."""
    from mcap.exceptions import McapError
    from mcap.reader import make_reader
    from mcap.records import Attachment, Channel, Message, Metadata
    from mcap.stream_reader import StreamReader

    file = run_log_path(path)
    triples: list[tuple[str, int, dict]] = []
    config_yaml: str | None = None
    metadata: dict[str, str] = {}
    with open(file, "rb") as f:
        try:
            reader = make_reader(f)
            summary = reader.get_summary()
            if summary is None:
                raise McapError("no summary")
            for _schema, channel, message in reader.iter_messages(log_time_order=True):
                triples.append((channel.topic, message.log_time, json.loads(message.data)))
            for a in reader.iter_attachments():
                if a.name == "config.yaml":
                    config_yaml = a.data.decode()
            for md in reader.iter_metadata():
                if md.name == "gnerun.run":
                    metadata = dict(md.metadata)
            complete, note = True, "finished log, read through its index"
        except (McapError, ValueError, OSError, EOFError, struct.error) as exc:
            f.seek(0)
            triples, channels = [], {}
            note = "unfinished log (no index): read record by record"
            try:
                for record in StreamReader(f, skip_magic=False).records:
                    if isinstance(record, Channel):
                        channels[record.id] = record.topic
                    elif isinstance(record, Message) and record.channel_id in channels:
                        triples.append((channels[record.channel_id], record.log_time, json.loads(record.data)))
                    elif isinstance(record, Attachment) and record.name == "config.yaml":
                        config_yaml = record.data.decode()
                    elif isinstance(record, Metadata) and record.name == "gnerun.run":
                        metadata = dict(record.metadata)
            except Exception as tail:  # noqa: BLE001 - a truncated record ends what can be read
                note += f"; it ends in an incomplete record ({type(tail).__name__})"
            complete = False
            if not isinstance(exc, McapError) or str(exc) != "no summary":
                note += f" after {type(exc).__name__}"
    triples.sort(key=lambda t: t[1])
    messages: dict[str, list[dict]] = {}
    times: dict[str, list[int]] = {}
    for topic, t, msg in triples:
        messages.setdefault(topic, []).append(msg)
        times.setdefault(topic, []).append(t)
    return RunRecord(file, messages, times, config_yaml, metadata, complete, note)


def recover(path: str | Path, target: str | Path) -> RunRecord:
    """Write a finished, indexed copy of a run log (e.g. of a killed run) with every message that can be read."""
    record = read_run(path)
    with RunLog(target, config_yaml=record.config_yaml or "", metadata=record.metadata) as log:
        order = sorted((t, topic, i) for topic, times in record.log_times.items() for i, t in enumerate(times))
        for t, topic, i in order:
            model = TOPICS.get(topic) or next((m for suffix, m in TOPICS.items() if topic.endswith(suffix)), None)
            if model is None:
                continue
            message: Message = model.from_logged(record.messages[topic][i], t)
            log.write(topic, message, log_time=t)
    return record


def read_messages(path: str | Path) -> list[tuple[str, dict, int]]:
    """All messages of a run log as (topic, decoded JSON, log_time), in log-time order."""
    record = read_run(path)
    out = [(topic, msg, t) for topic in record.messages
           for msg, t in zip(record.messages[topic], record.log_times[topic], strict=True)]
    return sorted(out, key=lambda x: x[2])
