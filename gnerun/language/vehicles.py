"""Vehicles in the plane, read from a dynamic game's state names: a pair of states ``px<i>``, ``py<i>`` (or
``x<i>``, ``y<i>``) is vehicle i's position. The paths figure, Rerun's paths view and the closed loop's logged plans
go by it."""

from __future__ import annotations

import re

_X = re.compile(r"^p?x(\d+)$")


def vehicles(state_names: list[str]) -> list[tuple[str, int, int]]:
    """(label, index of its x position, index of its y position) per vehicle, from the state names."""
    index = {name: k for k, name in enumerate(state_names)}
    out = []
    for name, k in index.items():
        m = _X.match(name)
        if m:
            y = name.replace("x", "y", 1)
            if y in index:
                out.append((m.group(1), k, index[y]))
    return out
