"""The box search of a player's best response (gnerun/solvers/global_response.py) on bare tapes: a witness where a
point of the box is below the threshold, a complete search where none is, against closed-form minima."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from gnerun.game.tape import Tape
from gnerun.solvers.global_response import box_search

y = ca.SX.sym("y", 2)
p = ca.SX.sym("p", 0)


def _tapes(cost, rows=None):
    J = ca.Function("J", [y, p], [cost])
    dJ = ca.Function("dJ", [y, p], [ca.gradient(cost, y)])
    c = ca.Function("c", [y, p], [rows]) if rows is not None else None
    return Tape(J), Tape(dJ), Tape(c) if c is not None else None


def _embed(lo, hi):
    return [lo, np.zeros(0)], [hi, np.zeros(0)]


# a tilted double well in y1 (minima near -1.03 and 0.97, the left one lower by about 0.2) plus (y2 - 0.5)^2
WELLS = (y[0] ** 2 - 1) ** 2 + 0.1 * y[0] + (y[1] - 0.5) ** 2


def _global_min() -> float:
    g = np.linspace(-3, 3, 600001)
    return float(np.min((g**2 - 1) ** 2 + 0.1 * g))


def test_a_point_below_the_threshold_is_found() -> None:
    J, dJ, _ = _tapes(WELLS)
    right = 0.97  # the worse well's value is about 0.097; the better well's about -0.10
    threshold = (right**2 - 1) ** 2 + 0.1 * right - 1e-6
    out = box_search(J, dJ, None, np.zeros(0, dtype=bool), np.array([-3.0, -3.0]), np.array([3.0, 3.0]), _embed,
                     threshold)
    assert out.witness is not None and not out.complete
    w = out.witness
    assert (w[0] ** 2 - 1) ** 2 + 0.1 * w[0] + (w[1] - 0.5) ** 2 < threshold  # it really is below
    assert w[0] < 0  # in the better well


def test_no_point_below_the_global_minimum_is_a_complete_search() -> None:
    J, dJ, _ = _tapes(WELLS)
    threshold = _global_min() - 1e-6
    out = box_search(J, dJ, None, np.zeros(0, dtype=bool), np.array([-3.0, -3.0]), np.array([3.0, 3.0]), _embed,
                     threshold)
    assert out.complete and out.witness is None
    # and just above the minimum the search finds a point instead
    out = box_search(J, dJ, None, np.zeros(0, dtype=bool), np.array([-3.0, -3.0]), np.array([3.0, 3.0]), _embed,
                     _global_min() + 1e-4)
    assert out.witness is not None


def test_rows_restrict_the_search_to_the_feasible_part() -> None:
    """With y1 >= 0.5 the better well is cut off: the minimum is the right well's (about 0.097), and a threshold
    below it has no feasible witness; without the row there is one."""
    J, dJ, c = _tapes(WELLS, ca.vertcat(0.5 - y[0]))
    g = np.linspace(0.5, 3, 400001)
    feasible_min = float(np.min((g**2 - 1) ** 2 + 0.1 * g))
    lo, hi = np.array([-3.0, -3.0]), np.array([3.0, 3.0])
    out = box_search(J, dJ, c, np.zeros(1, dtype=bool), lo, hi, _embed, feasible_min - 1e-6)
    assert out.complete
    out = box_search(J, dJ, None, np.zeros(0, dtype=bool), lo, hi, _embed, feasible_min - 1e-6)
    assert out.witness is not None


def test_an_empty_feasible_set_is_complete_with_no_witness() -> None:
    J, dJ, c = _tapes(WELLS, ca.vertcat(10 - y[0] - y[1]))  # y1 + y2 >= 10 is impossible on [-3, 3]^2
    out = box_search(J, dJ, c, np.zeros(1, dtype=bool), np.array([-3.0, -3.0]), np.array([3.0, 3.0]), _embed,
                     1e9)
    assert out.complete and out.witness is None


@pytest.mark.parametrize("budget", [20, 60])
def test_a_search_out_of_budget_gives_a_valid_lower_bound(budget: int) -> None:
    J, _, _ = _tapes(ca.sin(5 * y[0]) * ca.cos(7 * y[1]) + 0.01 * y[0] ** 2)
    lo, hi = np.array([-3.0, -3.0]), np.array([3.0, 3.0])
    g1, g2 = np.meshgrid(np.linspace(-3, 3, 1201), np.linspace(-3, 3, 1201))
    true_min = float(np.min(np.sin(5 * g1) * np.cos(7 * g2) + 0.01 * g1**2))  # about -0.99901
    # just below the minimum, without the mean-value form: a complete search needs more pieces than the budget
    out = box_search(J, None, None, np.zeros(0, dtype=bool), lo, hi, _embed, true_min - 1e-6, max_pieces=budget)
    assert not out.complete and out.witness is None
    assert out.lower_bound <= true_min


def test_a_row_the_candidate_breaks_by_rounding_is_held_to_what_it_has_there() -> None:
    """A row of the others' decisions alone is a constant for this player; at an accepted point it may be +2e-13.
    Held to exactly zero it discards the whole box and the search ends complete with nothing found; held to the
    candidate's own value, the search finds the better well (WELLS' left one) below the threshold."""
    J, dJ, c = _tapes(WELLS, ca.vertcat(0 * y[0] + 2e-13))
    lo, hi = np.array([-3.0, -3.0]), np.array([3.0, 3.0])
    threshold = _global_min() + 1e-3  # only the better well is below it
    vacuous = box_search(J, dJ, c, np.zeros(1, dtype=bool), lo, hi, _embed, threshold)
    assert vacuous.complete and vacuous.witness is None  # what the search says of a row held to zero
    out = box_search(J, dJ, c, np.zeros(1, dtype=bool), lo, hi, _embed, threshold, candidate=np.array([0.97, 0.5]))
    assert out.witness is not None and out.witness[0] == pytest.approx(-1.03, abs=0.05)
    assert out.witness_value < threshold
    # a row the candidate satisfies exactly keeps its meaning: y1 >= 0.5 still cuts the better well off
    J, dJ, c = _tapes(WELLS, ca.vertcat(0.5 - y[0]))
    out = box_search(J, dJ, c, np.zeros(1, dtype=bool), lo, hi, _embed, threshold, candidate=np.array([0.97, 0.5]))
    assert out.complete and out.witness is None


def test_a_narrow_well_behind_a_jump_is_found_not_bounded_away() -> None:
    """atan2((y1 - 0.3)^2 - 1e-10, -1) is near pi except on |y1 - 0.3| < 1e-5, where it jumps to near -pi (the cut).
    Its gradient's enclosure is finite there, so a mean-value bound would discard that piece as if the cost were
    continuous and the search would end complete with nothing found; bounded by its values alone, the piece is split
    down to the well and its centre is the witness."""
    J, dJ, _ = _tapes(ca.atan2((y[0] - 0.3) ** 2 - 1e-10, -1) + 0 * y[1])
    at_one = float(np.arctan2(0.49 - 1e-10, -1))  # the candidate y1 = 1: the least value outside the well
    out = box_search(J, dJ, None, np.zeros(0, dtype=bool), np.array([0.0, 0.0]), np.array([1.0, 0.0]), _embed,
                     at_one - 1e-9)
    assert out.witness is not None and abs(out.witness[0] - 0.3) < 1e-5 and out.witness_value < -3.14
