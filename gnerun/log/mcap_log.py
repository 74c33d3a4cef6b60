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
import io
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

import numpy as np
from mcap.writer import CompressionType, Writer

from ..errors import InputError, WriteError, shorten
from ..files import open_for_writing, read_regular
from ..language.yaml_source import parse_yaml
from .messages import TOPICS, LogEntry, Message, SamplingTime
from .topics import LOG

if TYPE_CHECKING:
    from .plans import PlanStates  # casadi: loaded where plans are computed, not where logs are read

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
        self._plan_states: PlanStates | None = None
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
            expected = model_for(topic)
            if expected is not None and expected is not model:
                raise TypeError(f"topic {topic} carries {expected.__name__}, not {model.__name__}")
            channel = self._checked[(topic, model)] = self._channel(topic, message)
        t = self.now() if log_time is None else log_time
        data = message.to_json()  # compact; missing and non-finite values left out (JSON has no NaN)
        self._writer.add_message(channel_id=channel, log_time=t, publish_time=t, data=data, sequence=self._sequence)
        self._sequence += 1

    def plan_states(self, plan_states: PlanStates) -> bool:
        """Use ``plan_states`` for sampling times that carry a plan's decisions; False: the loop computes the states
        (in the loop's process, its compiled function is faster)."""
        self._plan_states = plan_states
        return False

    def sampling_time(self, record: SamplingTime) -> None:
        """A closed loop's sampling time: its messages (:meth:`~gnerun.log.messages.SamplingTime.messages`), then a
        flush."""
        for topic, message in record.messages(self._plan_states):
            self.write(topic, message)
        self.flush()

    def log(self, level: str, text: str) -> None:
        """A ``/log`` text event (a foxglove.Log; ``level``: debug, info, warning or error)."""
        t = self.now()
        self.write(LOG, LogEntry.make(level, text, t), log_time=t)

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
    damage: list[str] = field(default_factory=list)  # what could not be read (a damaged or edited log)

    @property
    def message_count(self) -> int:
        return sum(len(v) for v in self.messages.values())

    @functools.cached_property
    def config(self) -> dict:
        """The resolved config as a mapping ({} when the log has none, or one that is not a config)."""
        return _config_mapping(self.config_yaml)[0]


class DamagedLog(InputError):
    """A run log with nothing that can be read: empty, not MCAP, or damaged from its start."""


MAX_LOG_BYTES = 8 * 2**30  # a log is read into memory, as its messages are
MAX_CHUNK_BYTES = 256 * 2**20  # a chunk that claims more is damaged (gnerun's chunks hold one step)
MCAP_MAGIC = b"\x89MCAP0\r\n"


def _config_mapping(text: str | None) -> tuple[dict, str | None]:
    """The config.yaml attachment as a mapping, read as configs are (plain data, bounded depth and size), and why
    it is not one (None: it is, or there is none)."""
    if not text:
        return {}, None
    try:
        data, _ = parse_yaml(text, "config.yaml")
    except InputError as e:
        return {}, f"its config.yaml attachment is not plain YAML ({shorten(str(e), 120)})"
    if not isinstance(data, dict):
        return {}, f"its config.yaml attachment is a {type(data).__name__}, not a config"
    wrong = _config_shape(data)
    if wrong:
        return {}, f"its config.yaml attachment is not a gnerun config ({wrong})"
    return data, None


def _config_shape(data: dict) -> str | None:
    """What of the fields the readers use (name, states, parameters, agents with their inputs and constraints, the
    shared constraints, solver and disturbance kinds, the disturbance scale) has the wrong type in a config read from
    a log (None: all are right)."""
    def names(v: object) -> bool:
        return isinstance(v, list) and all(isinstance(x, str) for x in v)

    game, solver, dist = data.get("game", {}), data.get("solver", {}), data.get("disturbance", {})
    checks = [("name", isinstance(data.get("name", ""), str)), ("game", isinstance(game, dict)),
              ("solver", isinstance(solver, dict)), ("disturbance", isinstance(dist, dict))]
    if all(ok for _, ok in checks):
        agents = game.get("agents", [])
        agents_ok = isinstance(agents, list) and all(isinstance(a, dict) for a in agents)
        checks += [("game.states", names(game.get("states", []))), ("game.agents", agents_ok),
                   ("game.parameters", isinstance(game.get("parameters", {}), dict)),
                   ("game.shared_constraints", isinstance(game.get("shared_constraints", []), list)),
                   ("solver.kind", isinstance(solver.get("kind", ""), str)),
                   ("disturbance.kind", isinstance(dist.get("kind", ""), str)),
                   ("disturbance.scale", isinstance(dist.get("scale", 0), int | float)
                    and not isinstance(dist.get("scale", 0), bool))]
        if agents_ok:
            checks += [("game.agents.inputs", all(isinstance(a.get("inputs", {}), dict) or names(a.get("inputs"))
                                                  for a in agents)),
                       ("game.agents.constraints", all(isinstance(a.get("constraints", []), list) for a in agents))]
    return next((f"{key} has the wrong type" for key, ok in checks if not ok), None)


def model_for(topic: str) -> type[Message] | None:
    """The message model of a gnerun topic (``/K7/mpc/state`` carries MpcState), or None for another topic."""
    return TOPICS.get(topic) or next((m for t, m in TOPICS.items() if topic.endswith(t)), None)


def _decode(topic: str, data: bytes, log_time: int) -> dict:
    """A message as the readers use it (its JSON object, as logged), checked against its topic's model (of this
    version or an earlier one), so that a damaged or edited message is refused here (ValueError) and never reaches
    a figure as a wrong type."""
    value = json.loads(data)
    if not isinstance(value, dict):
        raise ValueError(f"a message on {topic} is not a JSON object")
    model = model_for(topic)
    if model is not None:
        model.from_logged(value, log_time)
    return value


_INDEX_LIMIT = 2**53  # t and k are counts: anything larger is damage (and no timeline could hold it)


def _inconsistent(msg: dict, lengths: dict[str, int]) -> str | None:
    """Why a decoded message cannot belong with the messages before it on its topic (None: it can): a count out
    of range, or a vector of another length than the earlier ones' (``lengths``: vector -> its length, filled in
    here; a vector may be left out, for a non-finite entry, but readers take the others as one series)."""
    for key in ("t", "k"):
        if key in msg and isinstance(msg[key], int) and not 0 <= msg[key] < _INDEX_LIMIT:
            return f"has {key} = {shorten(str(msg[key]), 30)}"
    for key in ("x", "z", "u"):
        if isinstance(msg.get(key), list):
            known = lengths.setdefault(key, len(msg[key]))
            if len(msg[key]) != known:
                return f"has {len(msg[key])} entries in {key}, an earlier message {known}"
    return None


def run_log_path(path: str | Path) -> Path:
    """RUN is a run directory or its .mcap file."""
    p = Path(path)
    return p / "run.mcap" if p.is_dir() else p


class _Reading:
    """What one pass over a log collected."""

    def __init__(self) -> None:
        self.triples: list[tuple[str, int, dict]] = []
        self.config_yaml: str | None = None
        self.metadata: dict[str, str] = {}
        self.damage: list[str] = []
        self.records = 0

    def message(self, topic: str, log_time: int, data: bytes) -> None:
        try:
            self.triples.append((topic, log_time, _decode(topic, data, log_time)))
        except (ValueError, RecursionError) as e:  # pydantic's ValidationError is a ValueError
            self.damage.append(f"a message on {shorten(topic, 40)} at {log_time} is not readable "
                               f"({type(e).__name__})")

    def attachment(self, name: str, data: bytes) -> None:
        if name == "config.yaml":
            try:
                self.config_yaml = data.decode()
            except UnicodeDecodeError:
                self.damage.append("its config.yaml attachment is not UTF-8 text")

    def meta(self, name: str, values: dict) -> None:
        if name == "gnerun.run":
            self.metadata = {str(k): str(v) for k, v in values.items()}


def _read_indexed(data: bytes) -> _Reading:
    """Through the summary and index of a finished log; raises on any damage to them (the caller then reads
    record by record)."""
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    got = _Reading()
    reader = make_reader(io.BytesIO(data), validate_crcs=True)
    if reader.get_summary() is None:
        raise McapError("no summary")
    got.records = 1  # the summary
    for _schema, channel, message in reader.iter_messages(log_time_order=True):
        got.message(channel.topic, message.log_time, message.data)
    for a in reader.iter_attachments():
        got.attachment(a.name, a.data)
    for md in reader.iter_metadata():
        got.meta(md.name, md.metadata)
    return got


def _read_records(data: bytes, got: _Reading) -> str | None:
    """Record by record from the start, keeping every record that can be read: a chunk that is damaged inside
    (its CRC, its compressed data, its sizes) is skipped; damage to the records' framing ends the reading.
    Returns how the reading ended (None: at the footer), and notes the damage in ``got``."""
    import zstandard
    from mcap.exceptions import EndOfFile
    from mcap.records import Attachment, Channel, Chunk, Footer, Header, Message, Metadata
    from mcap.stream_reader import StreamReader, breakup_chunk

    channels: dict[int, str] = {}

    def take(record) -> None:
        got.records += 1
        if isinstance(record, Channel):
            channels[record.id] = record.topic
        elif isinstance(record, Message):
            if record.channel_id in channels:
                got.message(channels[record.channel_id], record.log_time, record.data)
            else:
                got.damage.append(f"a message of an unknown channel ({record.channel_id})")
        elif isinstance(record, Attachment):
            got.attachment(record.name, record.data)
        elif isinstance(record, Metadata):
            got.meta(record.name, record.metadata)

    stream = StreamReader(io.BytesIO(data), skip_magic=False, emit_chunks=True, record_size_limit=len(data))
    records = stream.records
    while True:
        try:
            record = next(records)
        except StopIteration:
            return None
        except EndOfFile:
            return "it ends in an incomplete record"
        except Exception as e:  # noqa: BLE001 - damaged framing: what was read before is kept
            got.damage.append(f"the records end in damage after {got.records} readable ones ({type(e).__name__})")
            return "damaged"
        if isinstance(record, Header | Footer):
            got.records += 1
            if isinstance(record, Footer):
                return None
            continue
        if not isinstance(record, Chunk):
            take(record)
            continue
        try:
            if record.compression == "zstd":
                declared = zstandard.frame_content_size(record.data)
                if max(record.uncompressed_size, declared) > MAX_CHUNK_BYTES:
                    raise ValueError(f"claims {max(record.uncompressed_size, declared)} bytes")
            elif record.compression != "" or record.uncompressed_size > MAX_CHUNK_BYTES:
                raise ValueError(f"compression {record.compression!r}")
            inner = breakup_chunk(record, validate_crc=True)
        except Exception as e:  # noqa: BLE001 - ZstdError, a CRC mismatch, a truncated inner record...
            got.damage.append(f"a damaged chunk ({type(e).__name__}: {shorten(str(e), 80)})")
            continue
        got.records += 1
        for inner_record in inner:
            take(inner_record)


def read_run(path: str | Path) -> RunRecord:
    """Read a run log. A finished log is read through its index; a log whose writer was killed (no summary, a
    truncated last chunk) or that was damaged is read record by record, keeping every record that can be read
    (the note says what was skipped). A log with nothing readable is a :class:`DamagedLog` (exit code 2)."""
    file = run_log_path(path)
    data = read_regular(file, MAX_LOG_BYTES, "run log")
    if not data:
        raise DamagedLog(f"{file}: damaged log: the file is empty")
    if not data.startswith(MCAP_MAGIC):
        raise DamagedLog(f"{file}: damaged log: not an MCAP file (it does not start with the MCAP magic bytes)")
    try:
        got = _read_indexed(data)
        complete, note = True, "finished log, read through its index"
    except Exception as exc:  # noqa: BLE001 - any damage to the summary or the index: read record by record
        got = _Reading()
        ended = _read_records(data, got)
        complete = False
        note = "unfinished log (no index): read record by record"
        if ended == "it ends in an incomplete record":
            note += f"; {ended}"
        if type(exc).__name__ != "McapError" or str(exc) != "no summary":
            note += f" after {type(exc).__name__}"
    if got.records == 0 and not got.triples:
        raise DamagedLog(f"{file}: damaged log: no record can be read ({len(data)} bytes)")
    if not got.triples and got.config_yaml is None and not got.metadata:
        raise DamagedLog(f"{file}: damaged log: it holds no message, no config and no metadata")
    _, why = _config_mapping(got.config_yaml)
    if why:
        got.damage.append(why)
    got.triples.sort(key=lambda t: t[1])
    messages: dict[str, list[dict]] = {}
    times: dict[str, list[int]] = {}
    lengths: dict[str, dict[str, int]] = {}
    for topic, t, msg in got.triples:
        why = _inconsistent(msg, lengths.setdefault(topic, {}))
        if why:
            got.damage.append(f"a message on {shorten(topic, 40)} at {t} {why}")
            continue
        messages.setdefault(topic, []).append(msg)
        times.setdefault(topic, []).append(t)
    if got.damage:
        more = f" and {len(got.damage) - 1} more" if len(got.damage) > 1 else ""
        note += f"; damaged log: {got.damage[0]}{more} (every readable record kept)"
    return RunRecord(file, messages, times, got.config_yaml, got.metadata, complete, note, got.damage)


def recover(path: str | Path, target: str | Path) -> RunRecord:
    """Write a finished, indexed copy of a run log (e.g. of a killed run) with every message that can be read."""
    import os

    record = read_run(path)
    target = Path(target)
    tmp = target.with_name(target.name + ".tmp")  # the copy appears whole or not at all
    try:
        tmp.unlink(missing_ok=True)
        with RunLog(tmp, config_yaml=record.config_yaml or "", metadata=record.metadata) as log:
            order = sorted((t, topic, i) for topic, times in record.log_times.items() for i, t in enumerate(times))
            for t, topic, i in order:
                model = model_for(topic)
                if model is None:
                    continue
                message: Message = model.from_logged(record.messages[topic][i], t)
                log.write(topic, message, log_time=t)
        os.replace(tmp, target)
    finally:
        tmp.unlink(missing_ok=True)
    return record


def read_messages(path: str | Path) -> list[tuple[str, dict, int]]:
    """All messages of a run log as (topic, decoded JSON, log_time), in log-time order."""
    record = read_run(path)
    out = [(topic, msg, t) for topic in record.messages
           for msg, t in zip(record.messages[topic], record.log_times[topic], strict=True)]
    return sorted(out, key=lambda x: x[2])
