"""The run log: an MCAP file that the solver loops write to (SPEC §5).

JSON messages with JSON Schemas generated from :mod:`gnerun.messages`, zstd-compressed chunks,
the ``gnerun.run`` metadata record and the resolved ``config.yaml`` as an attachment. The log is a
sink: loops call :meth:`RunLog.write` and :meth:`RunLog.flush`; nothing in the maths knows about it.
Every flush closes the current chunk and writes it to the file, so a killed run keeps every
message written before its last flush.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import IO, Any

import numpy as np
from mcap.writer import CompressionType, Writer

from .messages import TOPICS, LogEntry, Message

PROFILE = "gnerun"


def json_ready(obj: Any) -> Any:
    """numpy values to Python, NaN and Inf to None, recursively (JSON has no NaN)."""
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
        self._file: IO[bytes] = open(self.path, "wb")  # noqa: SIM115 - closed in close()
        self._writer = Writer(self._file, compression=CompressionType.ZSTD)
        self._writer.start(profile=PROFILE, library="gnerun")
        self._channels: dict[str, int] = {}
        self._sequence = 0
        self._closed = False
        now = time.time_ns()
        self._writer.add_metadata("gnerun.run", {k: str(v) for k, v in metadata.items()})
        self._writer.add_attachment(create_time=now, log_time=now, name="config.yaml",
                                    media_type="application/yaml", data=config_yaml.encode())
        self.flush()

    def _channel(self, topic: str, model: type[Message]) -> int:
        channel = self._channels.get(topic)
        if channel is None:
            schema = json.dumps(model.model_json_schema(), sort_keys=True).encode()
            schema_id = self._writer.register_schema(name=f"gnerun.{model.__name__}", encoding="jsonschema",
                                                     data=schema)
            channel = self._writer.register_channel(topic=topic, message_encoding="json", schema_id=schema_id)
            self._channels[topic] = channel
        return channel

    def write(self, topic: str, message: Message, *, log_time: int | None = None) -> None:
        """Append ``message`` on ``topic`` (its model's schema is registered on first use)."""
        model = type(message)
        expected = TOPICS.get(topic) or next((m for t, m in TOPICS.items() if topic.endswith(t)), None)
        if expected is not None and expected is not model:
            raise TypeError(f"topic {topic} carries {expected.__name__}, not {model.__name__}")
        t = time.time_ns() if log_time is None else log_time
        data = json.dumps(json_ready(message.model_dump()), separators=(",", ":"), allow_nan=False).encode()
        self._writer.add_message(channel_id=self._channel(topic, model), log_time=t, publish_time=t, data=data,
                                 sequence=self._sequence)
        self._sequence += 1

    def log(self, level: str, text: str) -> None:
        """A ``/log`` text event."""
        self.write("/log", LogEntry(level=level, message=text))

    def flush(self) -> None:
        """Close the chunk in progress and write it out (a killed run keeps it)."""
        self._writer.flush()

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        try:
            self._writer.finish()
        finally:
            self._file.close()

    def __enter__(self) -> RunLog:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def read_messages(path: str | Path) -> list[tuple[str, dict, int]]:
    """All messages of a run log as (topic, decoded JSON, log_time), in log-time order."""
    from mcap.reader import make_reader

    out = []
    with open(path, "rb") as f:
        reader = make_reader(f)
        for _schema, channel, message in reader.iter_messages(log_time_order=True):
            out.append((channel.topic, json.loads(message.data), message.log_time))
    return out
