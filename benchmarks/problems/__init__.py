"""The field's benchmark games, built from their published definitions, as gnerun configs.

Every module here returns :class:`Problem` instances: a config (YAML text that ``gnerun.load_config(text=...)``
reads), the start point it fixes, and what is known about the solution independently of gnerun. The
robustness suite (``python -m benchmarks robustness``) solves each one and checks the answer.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Problem:
    """One problem and one start point."""

    family: str  # "fk" | "lq" | "merge" | "intersection" | "mcp-demo" | "overtaking" | "formation" | "nonconvex"
    name: str  # e.g. "A.1"
    start: str  # e.g. "x0 = 0.01" (the literature's label of the start point)
    config_yaml: str  # a complete gnerun config; the start point is in its start values
    has_gne: bool = True  # False only where the literature shows the problem has no GNE
    # independent reference: the primal solution a* in gnerun's order (agent by agent, time-major within an
    # agent), when it is isolated and known; None for non-isolated solution sets or unknown solutions
    reference: np.ndarray | None = None
    reference_tol: float = 1e-4  # how close a solution must be to ``reference`` (infinity norm)
    reference_source: str = ""  # where the reference comes from (publication and/or how it was computed)
    # an independent equilibrium check written without gnerun: a -> {agent name: best-response gap}
    # (None when the problem module provides none)
    best_response_gaps: Callable[[np.ndarray], dict[str, float]] | None = field(default=None, repr=False)
    published: dict[str, str] = field(default_factory=dict)  # the anchors' published results for this pair
    notes: str = ""
    kind: str = ""  # what makes the problem hard (the nonconvex family: "nonconvex", "unbounded", ...)
    # each agent's cost at a, written without gnerun (the scale of the gaps); None: gnerun's costs are used
    costs: Callable[[np.ndarray], np.ndarray] | None = field(default=None, repr=False)
