"""Backtracking line search on bare numbers."""

from __future__ import annotations

import math

from gnerun.solvers.line_search import backtrack


def test_the_first_length_with_sufficient_decrease_and_its_trial_value() -> None:
    calls = []

    def trial(t: float) -> tuple[float, str]:
        calls.append(t)
        return (1.0 - 0.4 * t) if t < 0.3 else 2.0, f"point at {t}"

    found = backtrack(1.0, -0.5, trial, sigma=1e-4, beta=0.5)
    assert found == (0.25, "point at 0.25")
    assert calls == [1.0, 0.5, 0.25]  # nothing is evaluated twice


def test_sufficient_decrease_uses_the_given_slope() -> None:
    # f(t) = 1 - 0.1 t decreases, but not by sigma t slope with slope -10 and sigma 0.5 for any t in (0, 1]
    assert backtrack(1.0, -10.0, lambda t: (1.0 - 0.1 * t, t), sigma=0.5) is None
    assert backtrack(1.0, -0.1, lambda t: (1.0 - 0.1 * t, t), sigma=0.5) == (1.0, 1.0)


def test_a_direction_that_does_not_descend_is_refused_without_trials() -> None:
    def never(t: float):
        raise AssertionError("evaluated")

    for slope in (0.0, 1.0, math.nan, math.inf):
        assert backtrack(1.0, slope, never) is None
    assert backtrack(math.nan, -1.0, never) is None


def test_nan_merits_are_never_accepted_and_the_search_ends() -> None:
    assert backtrack(1.0, -1.0, lambda t: (math.nan, t), t_min=1e-3) is None
