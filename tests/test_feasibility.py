"""Phase 1 (gnerun/solvers/feasibility.py): the smallest largest violation of a game's rows, against closed forms,
and the status that names an infeasible game."""

from __future__ import annotations

import numpy as np
import pytest

from gnerun import compile_game, load_config, solve
from gnerun.solvers.feasibility import phase_one

STATIC = """
game:
  kind: static
  agents:
    - name: p1
      variables: {{y1: {{lower: {lo1}, upper: 4, start: 0}}}}
      cost: "(y1 - 2)**2 + y1*y2"
    - name: p2
      variables: {{y2: {{start: 0}}}}
      cost: "(y2 + 1)**2"
  shared_constraints: {shared}
  equilibrium: {equilibrium}
"""


def _static(shared: list[str], lo1: float = -4, equilibrium: str = "variational"):
    return load_config(text=STATIC.format(shared=shared, lo1=lo1, equilibrium=equilibrium))


@pytest.mark.parametrize("equilibrium", ["variational", "generalized"])
def test_contradictory_rows_have_their_violation_in_closed_form(equilibrium: str) -> None:
    """y1 + y2 >= 5 and y1 + y2 <= 2: no point is within less than 1.5 of both (the midpoint of the gap)."""
    game = compile_game(_static(["y1 + y2 >= 5", "y1 + y2 <= 2"], equilibrium=equilibrium))
    out = phase_one(game)
    assert out.proven and out.infeasible
    assert out.violation == pytest.approx(1.5, abs=1e-9)
    assert sorted(out.rows) == ["y1 + y2 <= 2", "y1 + y2 >= 5"]  # a generalized game's copies of a row, once


def test_bounds_against_a_row() -> None:
    """y1 in [3, 4] and y1 + y2 <= 1 with y2 >= 3 (a row of p2's): y1 + y2 >= 6, so the row is off by 5 at best;
    spread over the three rows that meet there, the largest violation is 5/3."""
    cfg = _static(["y1 + y2 <= 1", "y2 >= 3"], lo1=3)
    out = phase_one(compile_game(cfg))
    assert out.proven and out.violation == pytest.approx(5 / 3, abs=1e-9)
    assert set(out.rows) == {"y1 + y2 <= 1", "y2 >= 3", "y1 >= 3"}


def test_a_feasible_game_has_no_violation() -> None:
    out = phase_one(compile_game(_static(["y1 + y2 <= 2"])))
    assert out.proven and not out.infeasible and out.violation <= 1e-12 and out.rows == []


def test_nonlinear_rows_are_searched_not_proven() -> None:
    """The disk y1^2 + y2^2 <= 1 and the line y1 + y2 >= 3 miss each other: the smallest largest violation t solves
    2 (s - ... ) by symmetry at y1 = y2 = s: 2 s^2 - 1 = t and 3 - 2 s = t, so s = (-1 + sqrt(1 + 4*... ))."""
    game = compile_game(_static(["y1**2 + y2**2 <= 1", "y1 + y2 >= 3"]))
    out = phase_one(game)
    # on the diagonal: 2 s^2 - 1 = 3 - 2 s  ->  s^2 + s - 2 = 0  ->  s = 1, t = 1
    assert not out.proven and out.infeasible
    assert out.violation == pytest.approx(1.0, abs=1e-6)


def test_an_infeasible_static_game_ends_infeasible() -> None:
    res = solve(_static(["y1 - y2 >= 6", "y1 - y2 <= 1"]))
    assert res.status == "infeasible"
    assert "cannot all hold" in res.message and "2.5" in res.message
    assert res.certificate["infeasibility"]["proven"] is True
    assert res.certificate["infeasibility"]["violation"] == pytest.approx(2.5, abs=1e-9)


DYNAMIC = """
game:
  kind: dynamic
  horizon: 3
  states: [s1, s2]
  dynamics:
    s1: "s1 + 0.1*v1"
    s2: "s2 + 0.1*v2"
  x0: [0, 0]
  agents:
    - name: a1
      inputs: {v1: {lower: -1, upper: 1}}
      stage_cost: "(s1 - 1)**2 + 0.1*v1**2"
    - name: a2
      inputs: {v2: {lower: -1, upper: 1}}
      stage_cost: "(s2 + 1)**2 + 0.1*v2**2"
  shared_constraints:
    - {expr: "s1 + s2 >= 1", stages: [3]}
  equilibrium: variational
"""


def test_a_dynamic_game_whose_inputs_cannot_reach_a_shared_row_ends_infeasible() -> None:
    """From x0 = 0 with |v| <= 1 and steps of 0.1, s1 + s2 at tau = 3 (four inputs in) is at most 0.8: the row
    s1 + s2 >= 1 is off by 0.2 at best, shared between the row and the eight input bounds that meet there."""
    cfg = load_config(text=DYNAMIC)
    game = compile_game(cfg)
    out = phase_one(game)
    assert out.proven and out.infeasible and out.violation == pytest.approx(0.2 / (1 + 8 * 0.1), rel=1e-9)
    assert out.rows[0] == "s1 + s2 >= 1 [tau=3]"
    assert set(out.rows[1:]) == {f"v{i} <= 1 [tau={tau}]" for i in (1, 2) for tau in range(4)}
    res = solve(cfg)
    assert res.status == "infeasible" and "s1 + s2 >= 1" in res.message
    # from a state where the row can be met, the same game is solved
    ok = solve(load_config(text=DYNAMIC, overrides={"game.x0": [1.0, 0.5]}))
    assert ok.status == "converged"
    assert np.isfinite(ok.z).all()


def test_nonlinear_rows_satisfied_by_a_plain_plan_are_not_called_infeasible() -> None:
    """Only p3 has rows, sin(3 u3) <= 0.28 and x1 <= 0.72 from stage 1 on, with x0 = -0.46: the zero plan satisfies
    every row (sin 0 = 0, x1 stays -0.46), but a local search from the start values (u3 = 0.55, where sin(3 u3) is
    near its maximum and its derivative near zero) stalled at a violation of 0.105 and called the game infeasible.
    The design screened before the searches finds a point that satisfies every row."""
    cfg = load_config(text="""
game:
  kind: dynamic
  horizon: 3
  states: [x1]
  dynamics: {x1: "x1 + sin(0.34*u1 + 0.81*u2 + 0.43*u3)"}
  x0: [-0.46]
  agents:
    - {name: p1, inputs: {u1: {lower: -1.04, upper: 1.9, start: -0.07}}, stage_cost: "(u1 - 1)**2"}
    - {name: p2, inputs: {u2: {lower: -1.53, upper: 0.56, start: -1.45}}, stage_cost: "(u2 + 1)**2"}
    - name: p3
      inputs: {u3: {lower: -0.98, upper: 0.81, start: 0.55}}
      stage_cost: "(u3 - 0.5)**2"
      constraints: ["sin(3*u3) <= 0.28", {expr: "x1 <= 0.72", stages: 1..T}]
""")
    game = compile_game(cfg)
    x = np.asarray(cfg.game.x0, dtype=float)
    assert game.constraint_values(np.zeros(game.n), x)[0].max() <= 0  # the zero plan is feasible
    out = phase_one(game, x)
    assert not out.infeasible and not out.proven
    assert game.constraint_values(out.point, x)[0].max() <= 0


def test_a_violated_constant_row_is_named_before_an_unbounded_player() -> None:
    """p1's row |x1 - x1| >= 0.71 is the constant 0 >= 0.71: no point satisfies it, whatever the players do. p2's cost
    0.88 x2^3 falls without bound as x2 -> -inf as well; the status names the rows that cannot hold, and the message
    the player without a best response."""
    res = solve(load_config(text="""
game:
  kind: static
  agents:
    - name: p1
      variables: {x1: {lower: -4, upper: 0.8, start: -3.7}}
      cost: "0.11*(x1 + 0.45)**2"
      constraints: ["abs(x1 - x1) >= 0.71"]
    - name: p2
      variables: {x2: {start: 0.54}}
      cost: "0.27*(x2 - 0.74)**2 + 0.88*x2**3 - 0.78*x2*x1"
"""), out=None)
    assert res.status == "infeasible_stage_constraint"
    assert "abs(x1 - x1) >= 0.71" in res.message
