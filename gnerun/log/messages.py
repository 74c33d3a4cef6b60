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


class MpcState(Message):
    """The plant at sampling time t and the input applied (``/K<k>/mpc/state``); u is null at the last t. With it:
    the solver's status at t (empty at the last t), whether the applied plan was a fallback (not z^K(t)), and the
    largest constraint violation at u(t) and the state it produced."""

    t: int
    x: list[float | None]
    u: list[float | None] | None
    status: str = ""
    fallback: bool = False
    constraint_violation: float | None = None


class MpcIterate(Message):
    """Iterate k of the K solver steps at sampling time t (``/K<k>/mpc/iterate``); k = 0 is the warm start."""

    t: int
    k: int
    residual_norm: float | None
    error_norm: float | None  # ||z^k(t) - z*(t)||


class MpcError(Message):
    """The tracking error e(t) = z^K(t) - z*(t) (``/K<k>/mpc/error``)."""

    t: int
    e_norm: float | None
    e_norm_agent: dict[str, float | None]


TOPICS: dict[str, type[Message]] = {
    "/solve/iterate": SolveIterate,
    "/mpc/state": MpcState,
    "/mpc/iterate": MpcIterate,
    "/mpc/error": MpcError,
    "/log": LogEntry,
}
