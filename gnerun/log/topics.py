"""The names of a run log's topics, built and parsed in one place (writers, readers and figures use these).

- ``/log``: the run's log entries (foxglove.Log);
- ``/solve/iterate``: the iterates of a solve;
- ``/K<k>/mpc/state``, ``/K<k>/mpc/iterate``, ``/K<k>/mpc/error``: the closed loop of budget K, per sampling time;
  ``/K<k>/mpc/parameters`` (and ``/solve/parameters``): the runtime values in force, where the game has any.
"""

from __future__ import annotations

import re

LOG = "/log"
SOLVE_ITERATE = "/solve/iterate"
SOLVE_PARAMETERS = "/solve/parameters"
MPC_KINDS = ("state", "iterate", "error")  # every closed loop's
MPC_PARAMETERS = "parameters"  # a game with runtime parameters: their values per sampling time

_MPC = re.compile(r"^/K(\d+)/mpc/(state|error|iterate|parameters)$")


def mpc(K: int, kind: str) -> str:
    """The topic of one kind of message (state, iterate, error) of the closed loop with budget K."""
    return f"/K{K}/mpc/{kind}"


def parse_mpc(topic: str) -> tuple[int, str] | None:
    """(K, kind) of a closed loop's topic, or None for another topic."""
    m = _MPC.match(topic)
    return (int(m.group(1)), m.group(2)) if m else None
