"""Which states the x(t) panel of a closed loop draws, and how its legend groups them (`gnerun figures --states`).

By default every state but the clocks: a state whose ode right-hand side is a nonzero constant (``tc: 1``), or
whose update adds a constant to it (``tc: tc + dt``), grows with t and would flatten every other curve. A state
belongs to the agent whose inputs end in the same number (``px3`` and ``ux3``: robot3, :func:`agent_numbers`); when
that gives fewer legend entries than one per state, the panel is drawn with a colour per agent and a line style per
kind of state (``px{i}``, ``py{i}``).
"""

from __future__ import annotations

import difflib
import re

from ..errors import InputError
from ..language.expr import CONSTANTS, evaluate, numpy_functions, parse_expression

_NUMBER = re.compile(r"(\d+)$")
KIND_STYLES = ["-", ":", "-.", (0, (5, 1, 1, 1, 1, 1))]  # a line style per kind of state ("--" marks references)


def agent_numbers(config: dict) -> dict[str, str]:
    """The agent of each number that ends state and input names (``px3``, ``ux3``: robot3): an agent whose inputs all
    end in one number is that number's; the others get the numbers left over in the config's order when as many are
    left as agents. Used to label a vehicle (or a state) by the name of the agent that drives it."""
    agents = [a for a in (config.get("game") or {}).get("agents") or [] if isinstance(a, dict)]
    out: dict[str, str] = {}
    left = []
    for agent in agents:
        inputs = agent.get("inputs") or {}
        names = list(inputs) if isinstance(inputs, dict) else [i.get("name") if isinstance(i, dict) else i
                                                                  for i in inputs if isinstance(i, str | dict)]
        found = [_NUMBER.search(n) for n in names if isinstance(n, str)]
        numbers = {m.group(1) for m in found if m}
        if found and all(found) and len(numbers) == 1 and next(iter(numbers)) not in out:
            out[numbers.pop()] = str(agent.get("name"))
        else:
            left.append(str(agent.get("name")))
    states = [s for s in (config.get("game") or {}).get("states") or [] if isinstance(s, str)]
    free = list(dict.fromkeys(m.group(1) for s in states if (m := _NUMBER.search(s)) and m.group(1) not in out))
    if left and len(free) == len(left):
        out.update(zip(free, left, strict=True))
    return out


def parameters(game: dict) -> dict[str, float]:
    """The game's scalar parameters, as a log's config gives them (vectors and matrices are not positions' data), and
    the sampling time dt of an ode, a name of its expressions."""
    params = {k: float(v) for k, v in (game.get("parameters") or {}).items() if isinstance(v, int | float)}
    dynamics = game.get("dynamics")
    if isinstance(dynamics, dict) and "ode" in dynamics and isinstance(dynamics.get("dt"), int | float):
        params.setdefault("dt", float(dynamics["dt"]))
    return params


def clock_states(config: dict) -> list[str]:
    """The states that only count time: dx/dt a nonzero constant (ode), or x(t+1) = x(t) + a nonzero constant."""
    game = config.get("game") or {}
    dynamics = game.get("dynamics")
    if not isinstance(dynamics, dict):
        return []
    params = {**parameters(game), **CONSTANTS}
    ode = dynamics.get("ode")
    rules = ode if isinstance(ode, dict) else dynamics if "A" not in dynamics else {}
    out = []
    for state, text in rules.items():
        if not isinstance(text, str | int | float) or isinstance(text, bool):
            continue
        try:
            expr = parse_expression(str(text))
            if ode is not None:
                clock = not expr.names - set(params) and float(evaluate(expr, params, numpy_functions())) != 0
            else:
                at = [float(evaluate(expr, {**params, state: v}, numpy_functions())) for v in (0.0, 1.0)]
                clock = not expr.names - set(params) - {state} and at[0] != 0 and at[1] - at[0] == 1
        except Exception:  # a log's config is data: a rule that does not parse or evaluate is no clock
            continue
        if clock:
            out.append(state)
    return out


def selected_states(config: dict, chosen: list[str] | None, run: str) -> tuple[list[str], list[str]]:
    """The states the x(t) panel draws (``chosen``, in that order, else every state but the clocks), and the
    clocks left out. A name that is not a state is an input error, with the nearest names."""
    names = [s for s in (config.get("game") or {}).get("states") or [] if isinstance(s, str)]
    if chosen is None:
        clocks = clock_states(config)
        drawn = [s for s in names if s not in clocks]
        return (drawn, clocks) if drawn else (names, [])
    for name in chosen:
        if name not in names:
            near = difflib.get_close_matches(name, names, n=3)
            hint = f" (did you mean {' or '.join(repr(n) for n in near)}?)" if near else ""
            raise InputError(f"--states: {run} has no state {name!r}{hint}; its states: {', '.join(names)}")
    return list(dict.fromkeys(chosen)), []


def state_groups(config: dict, drawn: list[str]) -> tuple[dict[str, str], dict[str, str]] | None:
    """Each drawn state's agent and kind (``px3``: robot3, ``px{i}``), when every drawn state belongs to an agent,
    there are at most four kinds, and agents and kinds together are fewer legend entries than the states; else None
    (a legend entry per state)."""
    by_number = agent_numbers(config)
    agent, kind = {}, {}
    for s in drawn:
        m = _NUMBER.search(s)
        if not m or m.group(1) not in by_number:
            return None
        agent[s] = by_number[m.group(1)]
        kind[s] = s[:m.start()] + "{i}"
    kinds, agents = set(kind.values()), set(agent.values())
    if len(kinds) > len(KIND_STYLES) or len(kinds) + len(agents) >= len(drawn):
        return None
    return agent, kind
