"""The smoothing homotopy (gnerun/runs/smoothing.py): equilibria at kinks of abs, min and max, which the Newton
methods cannot converge to, reached by smoothed games and certified on the original one; checked against
closed-form subgradient conditions and against the same game written with epigraph variables (smooth, no abs)."""

from __future__ import annotations

import numpy as np
import pytest

from gnerun import load_config, solve
from gnerun.runs.smoothing import CLOSE_ENOUGH, LEVELS, smoothing_homotopy

KINK = """
game:
  kind: static
  agents:
    - name: p1
      variables: {x1: {start: 3}}
      cost: "2*abs(x1 - 0.7) + 0.5*(x1 - x2)**2"
    - name: p2
      variables: {x2: {start: 0}}
      cost: "(x2 - 0.4*x1 - 0.1)**2"
run: {reference: none}
"""


def test_an_equilibrium_at_a_kink_is_reached_and_certified() -> None:
    """p2's best response is x2 = 0.4 x1 + 0.1; p1's is the kink x1 = 0.7 as long as |x2 - 0.7| <= 2 (the
    subgradient 2 [-1, 1] + (x1 - x2) contains 0): the equilibrium is (0.7, 0.38). The unsmoothed solve stalls (the
    derivative of abs jumps there); the smoothed games reach it and the certificate proves it on the original game."""
    res = solve(load_config(text=KINK))
    assert res.status == "converged" and res.message.startswith("converged by smoothing")
    assert res.solution["p1"]["x1"] == pytest.approx(0.7, abs=1e-6)
    assert res.solution["p2"]["x2"] == pytest.approx(0.38, abs=1e-6)
    assert set(res.certificate["best_response_kind"].values()) == {"global on the search box"}  # (unbounded)
    assert max(res.certificate["best_response_gap"].values()) <= 1e-6


def test_the_homotopy_follows_the_smoothed_solutions_down() -> None:
    sm = smoothing_homotopy(load_config(text=KINK), np.array([3.0, 0.0]))
    assert sm is not None and sm.levels[0][0] == pytest.approx(LEVELS[0] * 3.0)  # scaled by the start's size
    mus = [mu for mu, _, _ in sm.levels]
    assert mus == sorted(mus, reverse=True) and sm.mu <= CLOSE_ENOUGH * 3.0
    # every level converged but possibly the last tried (its curvature, 1/mu, at the arithmetic's limits)
    assert all(status == "converged" for _, status, _ in sm.levels[:-1])
    # within about mu of the kink: the smoothed abs' derivative is (x1 - 0.7)/sqrt((x1 - 0.7)^2 + mu^2) there
    assert abs(sm.z[0] - 0.7) <= 1e-6


L1 = """
game:
  kind: dynamic
  horizon: 1
  states: [s1, s2]
  dynamics:
    s1: "s1 + 0.5*v1"
    s2: "s2 + 0.5*v2 + 0.1*v1"
  x0: [0, 1]
  agents:
    - name: a1
      inputs: {v1: {lower: -2, upper: 2, start: 0}}
      stage_cost: "(s1 - 1)**2 + 0.6*abs(v1 - 0.3) + 0.1*s1*s2"
    - name: a2
      inputs: {v2: {lower: -2, upper: 2, start: 0}}
      stage_cost: "(s2 - 0.5)**2 + 0.2*v2**2"
run: {reference: none}
"""

EPIGRAPH = """
game:
  kind: dynamic
  horizon: 1
  states: [s1, s2]
  dynamics:
    s1: "s1 + 0.5*v1"
    s2: "s2 + 0.5*v2 + 0.1*v1"
  x0: [0, 1]
  agents:
    - name: a1
      inputs: {v1: {lower: -2, upper: 2, start: 0}, e1: {start: 1}}
      stage_cost: "(s1 - 1)**2 + 0.6*e1 + 0.1*s1*s2"
      constraints: ["e1 >= v1 - 0.3", "e1 >= 0.3 - v1"]
    - name: a2
      inputs: {v2: {lower: -2, upper: 2, start: 0}}
      stage_cost: "(s2 - 0.5)**2 + 0.2*v2**2"
run: {reference: none}
"""


def test_an_l1_input_cost_in_a_dynamic_game_matches_its_epigraph_form() -> None:
    """a1 pays 0.6 |v1 - 0.3| at each stage. The same game with an epigraph decision e1 >= |v1 - 0.3| (smooth,
    solved by the Newton methods directly) has the same equilibrium inputs."""
    res = solve(load_config(text=L1))
    ref = solve(load_config(text=EPIGRAPH))
    assert ref.status == "converged"
    assert res.status == "converged", res.message
    np.testing.assert_allclose(res.solution["a1"]["v1"], ref.solution["a1"]["v1"], atol=1e-6)
    np.testing.assert_allclose(res.solution["a2"]["v2"], ref.solution["a2"]["v2"], atol=1e-6)
    assert min(abs(v - 0.3) for v in res.solution["a1"]["v1"]) <= 1e-6  # an input held at its reference: the kink


def test_a_kink_equilibrium_that_restarts_end_short_of_is_reached_by_smoothing() -> None:
    """p1 minimises 2.1 |sin(3.01 x1)| - 0.29 exp(0.7 x1) + 0.19 min(x1, -0.66) on [-3.8, -1.8], alone (p2's
    decision adds a constant): its best response is the kink x1 = -3 pi / 3.01, where the smooth stationary points
    the restarts reach are not minima; p2's cost falls with x22 on [-0.5, 2] (x21 is free to be anything). The
    unsmoothed solve ended not_an_equilibrium; the smoothing homotopy, tried after it, ends certified at the kink."""
    res = solve(load_config(text="""
game:
  kind: static
  agents:
    - name: p1
      variables: {x11: {lower: -3.8, upper: -1.8, start: -1.8}}
      cost: "2.1*abs(sin(3.01*x11)) - 0.29*exp(0.7*x11) + 0.19*min(x11, -0.66) - 1.95*x22**2"
    - name: p2
      variables: {x21: {lower: -2.5, upper: -1.5, start: -1.5}, x22: {lower: -0.5, upper: 2.0, start: 0.0}}
      cost: "-1.27*min(x22, -1.45) - 1.9*x22 + 1.45*abs(x11)"
run: {reference: none}
"""), out=None)
    g = np.linspace(-3.8, -1.8, 2_000_001)
    j1 = 2.1 * np.abs(np.sin(3.01 * g)) - 0.29 * np.exp(0.7 * g) + 0.19 * np.minimum(g, -0.66)
    assert g[np.argmin(j1)] == pytest.approx(-3 * np.pi / 3.01, abs=1e-5)  # the best response is the kink
    assert res.status == "converged" and res.message.startswith("converged by smoothing")
    assert res.solution["p1"]["x11"] == pytest.approx(-3 * np.pi / 3.01, abs=1e-6)
    assert res.solution["p2"]["x22"] == pytest.approx(2.0, abs=1e-9)
