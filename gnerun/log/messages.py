"""The messages of a run's MCAP log and their JSON Schemas.

The schemas are the subset of JSON Schema that Foxglove and Lichtblick read from a ``jsonschema`` channel:
every field has one plain ``type`` (``number``, ``integer``, ``string``, ``boolean``, ``object`` with
``properties``, ``array`` with typed ``items``), never a list of types, ``anyOf``/``oneOf`` or ``$ref``.
A value that is missing or not a finite number (an error norm without z*, a NaN iterate) is left out of its
message: the viewers show a gap, and every message stays valid against its schema (JSON has no NaN, and a
``number`` field admits no ``null``). Per-agent values are named properties (``e_norm_agent.agent1``), so
that each one is a plottable message path. ``/log`` carries the well-known ``foxglove.Log``.
"""

from __future__ import annotations

import json
import math
import types
import typing
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from .topics import mpc


def _absent(v: Any) -> bool:
    return v is None or (isinstance(v, float) and not math.isfinite(v))


def _present(v: Any) -> Any:
    """``v`` without its missing parts (None marks a value to leave out)."""
    if isinstance(v, dict):
        out = {}
        for key, item in v.items():
            item = _present(item)
            if item is not None:
                out[key] = item
        return out
    if isinstance(v, list):
        # an array with a missing entry (a NaN state or iterate) would shift every later index: left out whole
        return None if any(_absent(x) for x in v) else v
    return None if _absent(v) else v


def _left_out(message: BaseModel) -> dict | None:
    """The fields (and keys of mapping fields) that :func:`_present` leaves out of ``message``, as pydantic's
    ``exclude``; None when a field holds something else than numbers, strings, flags and flat lists or mappings of
    them (then the general walk decides)."""
    skip: dict = {}
    for name in type(message).model_fields:
        v = getattr(message, name)
        if isinstance(v, dict):
            keys = set()
            for key, item in v.items():
                if isinstance(item, (dict, list, BaseModel)):
                    return None
                if _absent(item):
                    keys.add(key)
            if keys:
                skip[name] = keys
        elif isinstance(v, list):
            try:
                finite = all(map(math.isfinite, v))
            except TypeError:  # not a list of numbers
                return None
            if not finite:
                skip[name] = True
        elif isinstance(v, BaseModel):
            return None
        elif _absent(v):
            skip[name] = True
    return skip


def _field_schema(annotation: Any, sample: Any) -> dict:
    """The viewer-subset schema of one annotation (``sample``: the value logged, for a mapping's keys)."""
    origin = typing.get_origin(annotation)
    if origin in (typing.Union, types.UnionType):
        (inner,) = [a for a in typing.get_args(annotation) if a is not type(None)]
        return _field_schema(inner, sample)
    if origin is list:
        (item,) = typing.get_args(annotation)
        return {"type": "array", "items": _field_schema(item, None)}
    if origin is dict:
        _, value = typing.get_args(annotation)
        return {"type": "object", "properties": {str(k): _field_schema(value, None) for k in (sample or {})},
                "additionalProperties": False}
    return {"type": {bool: "boolean", int: "integer", float: "number", str: "string"}[annotation]}


class Message(BaseModel):
    model_config = ConfigDict(extra="forbid")

    # schema name of the channel (default: gnerun.<class name>)
    schema_name: ClassVar[str | None] = None

    @classmethod
    def viewer_schema(cls, sample: Message | None = None) -> dict:
        """The JSON Schema of this message. Mappings (per-agent values) get one property per key of ``sample``."""
        properties, required = {}, []
        for name, info in cls.model_fields.items():
            value = getattr(sample, name, None) if sample is not None else None
            properties[name] = _field_schema(info.annotation, value)
            if info.description:
                properties[name]["description"] = info.description
            if info.is_required() and not _optional(info.annotation):
                required.append(name)
        schema = {"title": cls.channel_schema_name(), "type": "object", "properties": properties,
                  "additionalProperties": False}
        if cls.__doc__:
            schema["description"] = " ".join(cls.__doc__.split())
        if required:
            schema["required"] = required
        return schema

    @classmethod
    def channel_schema_name(cls) -> str:
        return cls.schema_name or f"gnerun.{cls.__name__}"

    def to_json(self) -> bytes:
        """Compact JSON with every missing or non-finite value left out."""
        skip = _left_out(self)
        if skip is None:  # nested messages: the general walk
            return json.dumps(_present(self.model_dump()), separators=(",", ":"), allow_nan=False).encode()
        # pydantic's serializer: a plan of 500 numbers in 44 us instead of 320 us through json.dumps
        return self.model_dump_json(exclude=skip or None).encode()

    @classmethod
    def from_logged(cls, data: dict, log_time: int) -> Message:
        """The message as read back from a log (of this version or an earlier one)."""
        return cls.model_validate(data)


def _optional(annotation: Any) -> bool:
    return typing.get_origin(annotation) in (typing.Union, types.UnionType) and type(None) in typing.get_args(
        annotation)


class SolveIterate(Message):
    """One iterate z^k of a solve (topic /solve/iterate)."""

    k: int
    z: list[float] | None = None
    residual_norm: float | None = Field(None, description="||Phi(z^k)||")
    log10_residual_norm: float | None = None
    error_norm: float | None = Field(None, description="||z^k - z*||, z* from a converged re-solve")
    step_norm: float | None = Field(None, description="||z^k - z^(k-1)||")
    active_set_changes: int


class Time(BaseModel):
    """A time as seconds and nanoseconds (foxglove.Time)."""

    model_config = ConfigDict(extra="forbid")

    sec: int
    nsec: int

    @classmethod
    def from_ns(cls, ns: int) -> Time:
        return cls(sec=ns // 1_000_000_000, nsec=ns % 1_000_000_000)


# foxglove.Log's levels
LOG_LEVELS = {"unknown": 0, "debug": 1, "info": 2, "warning": 3, "error": 4, "fatal": 5}
LEVEL_NAMES = {v: k for k, v in LOG_LEVELS.items()}

# the well-known schema, as published by Foxglove (schemas/jsonschema/Log.json): the Log panel looks for it
FOXGLOVE_LOG_SCHEMA = {
    "title": "foxglove.Log",
    "description": "A log message",
    "$comment": "Generated by https://github.com/foxglove/schemas",
    "type": "object",
    "properties": {
        "timestamp": {
            "type": "object",
            "title": "time",
            "properties": {
                "sec": {"type": "integer", "minimum": 0},
                "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999},
            },
            "description": "Timestamp of log message",
        },
        "level": {
            "title": "foxglove.LogLevel",
            "description": "Log level",
            "oneOf": [{"title": name.upper(), "const": value} for name, value in LOG_LEVELS.items()],
        },
        "message": {"type": "string", "description": "Log message"},
        "name": {"type": "string", "description": "Process or node name"},
        "file": {"type": "string", "description": "Filename"},
        "line": {"type": "integer", "minimum": 0, "description": "Line number in the file"},
    },
}


class LogEntry(Message):
    """A text event (topic /log): warnings, statuses; the well-known foxglove.Log."""

    schema_name: ClassVar[str | None] = "foxglove.Log"

    timestamp: Time
    level: int  # LOG_LEVELS
    message: str
    name: str = "gnerun"
    file: str = ""
    line: int = 0

    @classmethod
    def viewer_schema(cls, sample: Message | None = None) -> dict:
        return FOXGLOVE_LOG_SCHEMA

    @classmethod
    def make(cls, level: str, text: str, time_ns: int) -> LogEntry:
        return cls(timestamp=Time.from_ns(time_ns), level=LOG_LEVELS[level], message=text)

    @classmethod
    def from_logged(cls, data: dict, log_time: int) -> LogEntry:
        if isinstance(data.get("level"), str):  # logs written before /log was a foxglove.Log: {level, message}
            return cls.make(data["level"], data["message"], log_time)
        return cls.model_validate(data)


def level_name(entry: dict) -> str:
    """debug | info | warning | error (| fatal, unknown) of a /log message, of this version or an earlier one."""
    level = entry.get("level")
    return level if isinstance(level, str) else LEVEL_NAMES.get(level, "unknown")


class MpcState(Message):
    """The plant at sampling time t and the input applied (/K<k>/mpc/state); u is left out at the last t, whose
    state ends the loop (and whose status is empty). With it: the solver's status at t, whether the applied plan
    was a fallback (not z^K(t)), the largest constraint violation at u(t) and the state it produced, and the states
    the applied plan predicts over its horizon (dynamic games)."""

    t: int
    x: list[float] | None = None
    u: list[float] | None = None
    status: str | None = Field(None, description="the solver's status at t: converged, incomplete (K steps "
                                                 "without reaching tol) or a failure; empty at the last t")
    fallback: bool | None = Field(None, description="the applied plan was a fallback, not the budgeted iterate")
    constraint_violation: float | None = Field(None, description="the largest constraint violation at the "
                                                                 "applied input and the state it produces")
    plan: list[float] | None = Field(None, description="the states the applied plan predicts, x(t) and then those "
                                                      "of each stage tau = 0..T, one after the other (len(x) values "
                                                      "each), to 6 significant digits; left out where the plan is "
                                                      "not finite")


class MpcIterate(Message):
    """Iterate k of the K solver steps at sampling time t (/K<k>/mpc/iterate); k = 0 is the warm start."""

    t: int
    k: int
    residual_norm: float | None = Field(None, description="||Phi(z^k(t))||")
    error_norm: float | None = Field(None, description="||z^k(t) - z*(t)||")


class MpcError(Message):
    """The tracking error e(t) = z^K(t) - z*(t) (/K<k>/mpc/error), in all and per agent."""

    t: int
    e_norm: float | None = Field(None, description="||e(t)||")
    e_norm_agent: dict[str, float | None] = Field(default_factory=dict, description="||e_i(t)|| by agent name")


PLAN_DIGITS = 6  # significant digits of a logged plan: it is drawn, not computed with (half the bytes it would take)


def significant(values: np.ndarray, digits: int = PLAN_DIGITS) -> np.ndarray:
    """``values`` rounded to ``digits`` significant digits (non-finite values as they are)."""
    with np.errstate(all="ignore"):
        scale = 10.0 ** (digits - 1 - np.floor(np.log10(np.abs(np.where(values == 0, 1.0, values)))))
        return np.where(np.isfinite(values) & np.isfinite(scale), np.round(values * scale) / scale, values)


@dataclass
class SamplingTime:
    """One sampling time t of the closed loop with budget K as the log receives it: plain numbers, from which
    :meth:`messages` makes its messages (its iterates, the state with the input applied and the plan's predicted
    states, the error). Plain data crosses to a log written by another process (:mod:`gnerun.log.writer`) at a
    fraction of the messages' cost."""

    K: int
    t: int
    iterates: list[tuple[int, float, float | None]]  # (k, ||Phi(z^k)||, ||z^k - z*|| or None)
    x: np.ndarray
    u: np.ndarray | None
    status: str
    fallback: bool
    constraint_violation: float
    e_norm: float
    e_norm_agent: dict[str, float]
    plan: np.ndarray | None = None  # the states the applied plan predicts, (T + 2) x nx
    plan_inputs: np.ndarray | None = None  # or the applied plan's decisions a, from which messages() computes them

    _ARRAYS = ("x", "u", "plan", "plan_inputs")

    def pack(self) -> tuple:
        """The record as plain values, its arrays as (shape, bytes): what crosses to a writer process, pickled in
        about 2 us; :meth:`unpack` makes it again."""
        arrays = tuple(None if a is None else (a.shape, np.asarray(a, dtype=float).tobytes())
                       for a in (getattr(self, name) for name in self._ARRAYS))
        return (self.K, self.t, tuple(self.iterates), arrays, self.status, self.fallback, self.constraint_violation,
                self.e_norm, tuple(self.e_norm_agent.items()))

    @classmethod
    def unpack(cls, packed: tuple) -> SamplingTime:
        K, t, iterates, arrays, status, fallback, violation, e_norm, e_agent = packed
        values = {name: None if a is None else np.frombuffer(a[1], dtype=float).reshape(a[0])
                  for name, a in zip(cls._ARRAYS, arrays, strict=True)}
        return cls(K=K, t=t, iterates=list(iterates), status=status, fallback=fallback, constraint_violation=violation,
                   e_norm=e_norm, e_norm_agent=dict(e_agent), **values)

    def messages(self, plan_states: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None
                 ) -> list[tuple[str, Message]]:
        """(topic, message) in the order they are written; ``plan_states(a, x)`` the states a plan's decisions
        predict (:class:`~gnerun.log.plans.PlanStates`), where the record carries the decisions."""
        plan = self.plan
        if plan is None and self.plan_inputs is not None and plan_states is not None:
            plan = plan_states(self.plan_inputs, self.x)
        t, K = self.t, self.K
        out: list[tuple[str, Message]] = [(mpc(K, "iterate"), MpcIterate(t=t, k=k, residual_norm=r, error_norm=err))
                                          for k, r, err in self.iterates]
        out.append((mpc(K, "state"), MpcState(
            t=t, x=self.x.tolist(), u=None if self.u is None else self.u.tolist(), status=self.status,
            fallback=self.fallback, constraint_violation=self.constraint_violation,
            plan=None if plan is None else significant(plan).reshape(-1).tolist())))
        out.append((mpc(K, "error"), MpcError(t=t, e_norm=self.e_norm, e_norm_agent=dict(self.e_norm_agent))))
        return out


class RuntimeValues(Message):
    """The runtime parameters' values in force at sampling time t (/K<k>/mpc/parameters; /solve/parameters for a
    solve, t = 0), by name, each flattened: a number as one entry, a vector, a matrix row by row, per-stage values
    over the stages 0..T + 1; ``t`` the time of stage 0 where the game uses the time."""

    t: int
    values: dict[str, list[float]] = Field(default_factory=dict, description="the runtime values by name")
    references: dict[str, float] = Field(default_factory=dict, description="r(t) of the states with a reference "
                                                                           "(game.references), by state")

    @classmethod
    def of(cls, t: int, record: dict, references: dict | None = None) -> RuntimeValues:
        """From a game's record of its runtime values (``CompiledGame.parameters``) and its references at t."""
        import numpy as np

        return cls(t=t, values={k: np.asarray(v, dtype=float).reshape(-1).tolist() for k, v in record.items()},
                   references=references or {})


TOPICS: dict[str, type[Message]] = {
    "/solve/iterate": SolveIterate,
    "/solve/parameters": RuntimeValues,
    "/mpc/parameters": RuntimeValues,
    "/mpc/state": MpcState,
    "/mpc/iterate": MpcIterate,
    "/mpc/error": MpcError,
    "/log": LogEntry,
}
