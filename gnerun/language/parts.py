"""What the size estimate, the checks and the compiler read from a validated config's parts, with none of the
schema's classes: a constraint's expression, stages and carriers, the kind of a game's dynamics, and why the sparse
formulation cannot solve a game."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .config import Config, DisturbanceConfig, SharedSpec, SolverConfig, StageConstraint


def constraint_text(c: StageConstraint | SharedSpec) -> str:
    """The expression of a constraint, with options or not."""
    return c if isinstance(c, str) else c.expr


def constraint_stages(c: StageConstraint | SharedSpec) -> list[int] | None:
    """The stages a constraint is imposed at (None: every stage)."""
    return None if isinstance(c, str) else c.stages


def constraint_agents(c: StageConstraint | SharedSpec) -> list[str] | None:
    """The agents that carry a shared constraint (None: every agent; an agent's own constraint names none)."""
    return getattr(c, "agents", None)


def dynamics_kind(dynamics: Any) -> str:
    """linear (``A``, ``B``), continuous (an ``ode`` and ``dt``) or expressions (x(t+1), one per state)."""
    if isinstance(dynamics, dict):
        return "expressions"
    return "continuous" if hasattr(dynamics, "ode") else "linear"


def sparse_obstacles(cfg: Config) -> list[str]:
    """Why the sparse formulation cannot solve this config (empty: it can)."""
    return obstacles(cfg.game.kind == "static", cfg.solver, cfg.disturbance)


def obstacles(static: bool, solver: SolverConfig, disturbance: DisturbanceConfig) -> list[str]:
    """:func:`sparse_obstacles` of a game, static or not, solved with these options."""
    why = []
    if static:
        why.append("a static game has no states to keep")
    if solver.kind != "ssn":
        why.append(f"solver.kind is {solver.kind!r} (the sparse formulation is for 'ssn')")
    if solver.complementarity != "min":
        why.append("it takes min-map steps (solver.complementarity: min)")
    if disturbance.kind in ("jacobian_noise", "residual") and disturbance.scale > 0:
        why.append(f"disturbance {disturbance.kind!r} perturbs the whole condensed JPhi or its right-hand side")
    return why
