"""The messages of a run's MCAP log (SPEC §5). Their JSON Schemas are generated from these models."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict


class Message(BaseModel):
    model_config = ConfigDict(extra="forbid", ser_json_inf_nan="null")


class SolveIterate(Message):
    """One iterate z^k of a solve (topic ``/solve/iterate``)."""

    k: int
    z: list[float | None]
    residual_norm: float | None
    log10_residual_norm: float | None
    error_norm: float | None  # ||z^k - z*||, z* from a converged re-solve
    step_norm: float | None  # ||z^k - z^{k-1}||
    active_set_changes: int


class LogEntry(Message):
    """A text event (topic ``/log``): warnings, statuses."""

    level: str  # debug | info | warning | error
    message: str


TOPICS: dict[str, type[Message]] = {
    "/solve/iterate": SolveIterate,
    "/log": LogEntry,
}
