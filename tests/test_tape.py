"""Instruction tapes (gnerun/game/tape.py): enclosures checked against sampled values, kinks against their
definition, and the structural test that keeps piecewise games out of the affine fast paths."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from gnerun import compile_game, load_config
from gnerun.game.tape import Tape, UnsupportedTape, kink_function, piecewise_outputs

y = ca.SX.sym("y", 2)
p = ca.SX.sym("p")

EXPRESSIONS = {
    "cubic": y[0] ** 3 / 3 - y[0] + 0.5 * y[0] * p,
    "sin": ca.sin(3 * y[0]) + 0.1 * y[0] * y[1],
    "gaussians": -ca.exp(-(y[0] - 1) ** 2) - 2 * ca.exp(-(y[0] - 6) ** 2),
    "abs": ca.fabs(y[0] - 1) + 0.1 * y[0] ** 2,
    "max": ca.fmax(y[0] - 2, 2 * (2 - y[1])),
    "min": ca.fmin(y[0] * y[1], p - y[0]),
    "log": ca.sqrt(y[0] ** 2 + 1) * ca.log(y[1] + 3),
    "sqrt": ca.sqrt(y[0]),
    "tan": ca.tan(y[0]),
    "atan2": ca.atan2(y[0], y[1]),
    "hypot": ca.hypot(y[0], y[1]),
    "cosh-tanh": ca.cosh(y[0]) - ca.tanh(y[1]),
    "acos": ca.acos(y[0] / 10),
    "powers": y[0] ** -3 + y[1] ** 4 - y[0] ** 0.5,
    "cos": ca.cos(y[0] * y[1]) * ca.sinh(y[1] / 3),
    "if": ca.if_else(y[0] < y[1], y[0], y[1] ** 2),
    "exp-base": 2 ** y[0] - y[1] / (y[0] - 0.5),
}


@pytest.mark.parametrize("name", list(EXPRESSIONS))
def test_an_enclosure_contains_every_value_of_its_box(name: str) -> None:
    """Random boxes (wide, narrow and points), 200 sampled points each: every finite value lies in the enclosure."""
    f = ca.Function("f", [y, p], [EXPRESSIONS[name]])
    tape = Tape(f)
    rng = np.random.default_rng(7)
    B = 60
    centre = rng.uniform(-5, 5, (2, B))
    half = rng.uniform(0, 3, (2, B)) * rng.choice([0.0, 1e-9, 1.0], (1, B))
    lo, hi = centre - half, centre + half
    (L,), (H,) = tape.bounds([lo, np.array([0.7])], [hi, np.array([0.7])])
    mapped = f.map(200)
    for b in range(B):
        pts = rng.uniform(lo[:, b], hi[:, b], (200, 2))
        pts[0], pts[1] = lo[:, b], hi[:, b]
        vals = np.array(mapped(pts.T, 0.7)).ravel()
        inside = np.isnan(vals) | ((vals >= L[0, b]) & (vals <= H[0, b]))
        assert inside.all(), (name, lo[:, b], hi[:, b], L[0, b], H[0, b], vals[~inside][:3])


def test_enclosures_are_tight_on_monotone_pieces() -> None:
    """Not just valid: on a box where the function is monotone the enclosure is the range, to rounding."""
    f = ca.Function("f", [y, p], [ca.exp(y[0]) + ca.sin(y[1])])
    (L,), (H,) = Tape(f).bounds([np.array([[0.0], [0.1]]), np.zeros(1)], [np.array([[1.0], [1.0]]), np.zeros(1)])
    assert L[0, 0] == pytest.approx(1 + np.sin(0.1), abs=1e-14) and H[0, 0] == pytest.approx(np.e + np.sin(1.0),
                                                                                             abs=1e-14)
    assert L[0, 0] <= 1 + np.sin(0.1) and H[0, 0] >= np.e + np.sin(1.0)  # rounded outwards


def test_atan2_is_bounded_by_its_corners_away_from_its_cut() -> None:
    """atan2(y, x) on a box that holds neither the origin nor its cut (y = 0, x < 0) is continuous there, its range
    spanned by the corners' angles; a box across the cut gets [-pi, pi], and a tape with atan2 says it may jump."""
    f = ca.Function("f", [y, p], [ca.atan2(y[0], y[1])])
    tape = Tape(f)
    (L,), (H,) = tape.bounds([np.array([[1.0, -1.0], [-2.0, -2.0]]), np.zeros(1)],
                             [np.array([[2.0, 1.0], [-1.0, -1.0]]), np.zeros(1)])
    corners = [np.arctan2(a, b) for a in (1.0, 2.0) for b in (-2.0, -1.0)]
    assert L[0, 0] == pytest.approx(min(corners), abs=1e-14) and H[0, 0] == pytest.approx(max(corners), abs=1e-14)
    assert (L[0, 1], H[0, 1]) == (-np.pi, np.pi)  # y in [-1, 1] with x < 0: across the cut
    assert tape.jumps and not Tape(ca.Function("g", [y, p], [ca.fabs(y[0]) + ca.fmax(y[0], y[1])])).jumps


def test_kinks_are_measured_where_the_branch_changes() -> None:
    f = ca.Function("f", [y, p], [ca.fabs(y[0] - 1) + ca.fmax(y[1], 2 * y[0]) + ca.fmax(p, 0)])
    tape = Tape(f)
    dist, ops = tape.kinks([np.array([1 + 1e-12, 5.0]), np.zeros(1)])
    assert dist == pytest.approx(1e-12, rel=1e-3) and ops == ["fabs"]
    dist, ops = tape.kinks([np.array([3.0, 6.0]), np.zeros(1)])
    assert dist == 0.0 and ops == ["fmax"]  # y2 = 2 y1
    # max(p, 0) is at its kink (p = 0) but depends on no decision: not a kink of the player's problem
    dist, _ = tape.kinks([np.array([3.0, 0.0]), np.zeros(1)])
    assert dist == pytest.approx(1.0)  # |3 - 1| / 2 and |0 - 6| / 6
    compiled, names = kink_function(f)
    d = np.asarray(compiled(np.array([3.0, 6.0]), 0.0)).ravel()
    assert sorted(names) == ["fabs", "fmax"] and min(d) == 0.0


def test_piecewise_outputs_follow_the_decisions() -> None:
    f = ca.Function("f", [y, p], [ca.vertcat(ca.fabs(y[0]) + y[1], ca.fmax(p, 0) * y[0], y[0] * y[1])])
    np.testing.assert_array_equal(piecewise_outputs(f), [True, False, False])


NONSMOOTH_PAIR = """
game:
  kind: static
  agents:
    - name: p1
      variables: {x1: {lower: -3, upper: 3, start: 0.5}}
      cost: "abs(x1 - x2) + x1**2"
      constraints: ["max(x1, x2) <= 2", "x1 + x2 <= 4"]
    - name: p2
      variables: {x2: {lower: -3, upper: 3, start: 0}}
      cost: "(x2 - 1)**2 + 0.5*x1*x2"
"""


@pytest.mark.parametrize("config", ["algames_merge.yaml", "nonsmooth"])
def test_an_agents_kinks_are_those_of_its_whole_cost_and_rows(config: str) -> None:
    # the agent's kink function walks only its parts that pass through a piecewise function: the same functions, the
    # same distances as walking its whole cost and every row (the merge: a min in each car's ramp rows; a game with
    # abs and max in its costs and rows)
    from .conftest import CONFIGS

    text = (CONFIGS / config).read_text() if config.endswith(".yaml") else NONSMOOTH_PAIR
    game = compile_game(load_config(text=text))
    sym = game._symbolic
    rng = np.random.default_rng(2)
    for agent in range(len(game.agent_names)):
        rows = game.agents.constraint_rows(agent).tolist()
        whole = kink_function(ca.Function("parts", [sym.a, sym.x], [ca.vertcat(sym.J[agent], sym.c[rows])]))
        found = game.agents.kinks(agent)
        assert (whole is None) == (found is None)
        if whole is None:
            continue
        assert sorted(found[1]) == sorted(whole[1])
        for _ in range(3):
            a, x = game.a_start + rng.standard_normal(game.n), game._x(game.x0 if game.nx else None)
            np.testing.assert_array_equal(np.sort(np.asarray(found[0](a, x)).ravel()),
                                          np.sort(np.asarray(whole[0](a, x)).ravel()))


def test_mx_functions_are_refused() -> None:
    x = ca.MX.sym("x")
    with pytest.raises(UnsupportedTape):
        Tape(ca.Function("g", [x], [x * 2]))


GAME = """
game:
  kind: static
  agents:
    - name: p1
      variables: {{x1: {{start: 0}}}}
      cost: "{cost}"
    - name: p2
      variables: {{x2: {{start: 0}}}}
      cost: "(x2 + x1)**2"
"""


@pytest.mark.parametrize("cost, affine", [("0.5*x1**2 - 2*x1 + x1*x2", True), ("abs(x1 - 2) + 0.3*x1**2", False),
                                          ("max(x1, 1 - x1) + x1**2", False), ("min(x1, 0)**2 + x1**2", False)])
def test_a_game_with_abs_min_or_max_of_its_decisions_is_not_affine(cost: str, affine: bool) -> None:
    """Their second derivatives vanish almost everywhere, which made them look linear-quadratic: the KKT system was
    taken as W z + w0 from z = 0 (abs(x1 - 1) + 0.1 x1^2 was 'solved' at x1 = 5)."""
    game = compile_game(load_config(text=GAME.format(cost=cost)))
    assert game.affine is affine
    assert game.lq.piecewise is (not affine)


def test_rows_with_min_or_max_are_not_polyhedral() -> None:
    cfg = load_config(text=GAME.format(cost="x1**2") + '  shared_constraints: ["max(x1, x2) <= 1", "x1 + x2 <= 3"]\n')
    game = compile_game(cfg)
    linear = {c.label: bool(ok) for c, ok in zip(game.constraints, game.lq.linear_rows, strict=True)}
    assert linear == {"max(x1, x2) <= 1": False, "x1 + x2 <= 3": True}



def test_kinks_read_off_the_tape_are_the_compiled_functions() -> None:
    """An agent's kinks at a point, read off its parts' instruction tape (a certificate's first points) and by its
    compiled kink function (from the ``KINK_TAPE_USES``-th on): the same names, at points on a kink of abs and max
    (x1 = x2) and off them; the function is built only once the tape has served its uses."""
    from gnerun.game.agents import KINK_TAPE_USES

    game = compile_game(load_config(text=NONSMOOTH_PAIR))
    x = game._x(None)
    points = [np.array([0.7, 0.7]), np.array([0.7, 0.7 + 1e-9]), np.array([0.7, 0.2]), np.array([-1.0, 2.5])]
    read = [game.agents.kinks_at(0, a, x, 1e-6) for a in points]
    assert read[0] == read[1] and sorted(read[0]) == ["fabs", "fmax"] and read[2] == [] and read[3] == []
    assert 0 not in game.derived.get("kinks", {})  # the tape served: no function built yet
    for _ in range(KINK_TAPE_USES):
        game.agents.kinks_at(0, points[0], x, 1e-6)
    assert 0 in game.derived["kinks"]  # built once the tape's uses are spent
    compiled = [game.agents.kinks_at(0, a, x, 1e-6) for a in points]
    assert [sorted(r) for r in compiled] == [sorted(r) for r in read]
    assert game.agents.kinks_at(1, points[0], x, 1e-6) == []  # p2: nothing piecewise


def test_kinks_fall_back_to_the_compiled_function_where_the_tape_cannot_read(monkeypatch: pytest.MonkeyPatch) -> None:
    """A parts function with an instruction the tape does not read: its kinks come from the compiled function."""
    from gnerun.game import agents

    def refuse(f):
        raise UnsupportedTape("an instruction the tape does not read")

    monkeypatch.setattr(agents, "Tape", refuse)
    game = compile_game(load_config(text=NONSMOOTH_PAIR))
    x = game._x(None)
    assert sorted(game.agents.kinks_at(0, np.array([0.7, 0.7]), x, 1e-6)) == ["fabs", "fmax"]
    assert 0 in game.derived["kinks"]
