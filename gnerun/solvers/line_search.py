"""Backtracking line search (Armijo), on bare numbers.

The search asks a ``trial(t)`` function for the merit at step length t and returns the accepted length with
what the trial computed there, so that the accepted point is never evaluated twice (scipy's
``_nonlin_line_search`` does the same). The sufficient-decrease test uses the directional derivative of the
merit along the direction actually taken (``slope``), not the one an exact Newton step would have: under
perturbations or a regularised direction the two differ. A search that accepts no length is a result
(``None``), never an exception and never a silently tiny step.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

T = TypeVar("T")


def backtrack(merit0: float, slope: float, trial: Callable[[float], tuple[float, T]], *, t0: float = 1.0,
              sigma: float = 1e-4, beta: float = 0.5, t_min: float = 1e-12) -> tuple[float, T] | None:
    """The first t = t0 beta^j >= t_min with merit(t) <= merit0 + sigma t slope, and what ``trial(t)`` returned.

    ``slope`` must be negative (a descent direction); otherwise, or when no length is accepted, ``None``.
    """
    if not (slope < 0.0 and math.isfinite(slope) and math.isfinite(merit0)):
        return None
    t = t0
    while t >= t_min:
        merit, value = trial(t)
        if merit <= merit0 + sigma * t * slope:  # False for NaN
            return t, value
        t *= beta
    return None


@dataclass(frozen=True, slots=True)
class Armijo:
    """The backtracking search as an object a globalization is given (:func:`backtrack` with these constants)."""

    t0: float = 1.0
    sigma: float = 1e-4
    beta: float = 0.5
    t_min: float = 1e-12

    def search(self, merit0: float, slope: float, trial: Callable[[float], tuple[float, T]]) -> tuple[float, T] | None:
        """The accepted step length and what ``trial`` computed there, or ``None`` (see :func:`backtrack`)."""
        return backtrack(merit0, slope, trial, t0=self.t0, sigma=self.sigma, beta=self.beta, t_min=self.t_min)
