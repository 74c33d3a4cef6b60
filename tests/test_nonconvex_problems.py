"""The nonconvex family (benchmarks/problems/nonconvex.py): configs, the two writings of every game against each other,
the stored references and the independent best-response check's power to fail. Nothing here solves a game with
gnerun: the family is a yardstick for gnerun's answers, and these tests check the yardstick."""

from __future__ import annotations

import math

import numpy as np
import pytest

import gnerun
from benchmarks.problems import nonconvex as nc

GAMES = nc.games()
PROBLEMS = nc.problems()
BY_NAME = {g.name: g for g in GAMES}


def test_family_shape() -> None:
    assert 30 <= len(PROBLEMS) <= 50
    assert len({p.name for p in PROBLEMS}) == len(PROBLEMS)
    assert {p.kind for p in PROBLEMS} == set(nc.KINDS)
    for p in PROBLEMS:
        assert p.family == "nonconvex" and p.best_response_gaps is not None and p.costs is not None
        assert "solver:" not in p.config_yaml and "reference: none" in p.config_yaml
        assert p.has_gne == (p.kind in ("nonconvex", "nonsmooth"))
        assert (p.reference is not None) == p.has_gne  # every equilibrium of the family is unique and stored


@pytest.mark.parametrize("game", GAMES, ids=lambda g: g.name)
def test_two_writings_agree(game) -> None:
    """gnerun's compiled costs (from the config's expressions) equal the numpy writing at random points."""
    cfg = gnerun.load_config(text=game.config_yaml(game.starts[0][1], game.name))
    compiled = gnerun.compile_game(cfg)
    assert compiled.n == game.n
    assert compiled.agent_names == [p.name for p in game.players]
    rng = np.random.default_rng(0)
    for _ in range(5):
        a = rng.uniform(-2.5, 2.5, game.n)
        mine = game.costs(a)
        theirs = np.asarray(compiled.costs(a), dtype=float)
        finite = np.isfinite(mine)
        if game.kind != "nan":
            assert finite.all()
        # a cost that is NaN or infinite in numpy need not be so in gnerun's evaluation (the point of the nan kind)
        np.testing.assert_allclose(theirs[finite], mine[finite], rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("game", [g for g in GAMES if g.rows is not None or g.eq_rows is not None],
                         ids=lambda g: g.name)
def test_rows_agree_with_the_config(game) -> None:
    """The numpy rows hold exactly where gnerun's constraint rows hold (feasibility, compared at random points)."""
    cfg = gnerun.load_config(text=game.config_yaml(game.starts[0][1], game.name))
    compiled = gnerun.compile_game(cfg)
    rng = np.random.default_rng(1)
    eq = compiled.equality_mask
    for _ in range(50):
        a = rng.uniform(-3, 3, game.n)
        c = compiled.constraint(a)
        for i in range(len(game.players)):
            rows = compiled.agents.constraint_rows(i)
            theirs = bool(np.all(np.where(eq[rows], np.abs(c[rows]), c[rows]) <= 1e-12))
            mine = float(game.violation(i, a)) <= 1e-12
            assert mine == theirs, (a, i)


def test_kkt_starts_are_kkt_points() -> None:
    """Starts labelled as stationary points are: every player's own gradient vanishes there (bounds inactive)."""
    for g in GAMES:
        for label, start in g.starts:
            if label not in ("local maximum", "local minimum", "KKT point", "KKT point at the origin", "saddle",
                             "two local minima", "all positive"):
                continue
            a = np.array(start, dtype=float)
            for i in range(len(g.players)):
                for k in range(g.slices[i].start, g.slices[i].stop):
                    h = 1e-30
                    b = a.astype(complex)
                    b[k] += 1j * h
                    grad = float(np.imag(g.cost(i, b)) / h)
                    assert abs(grad) <= 1e-9, (g.name, label, i, k, grad)


@pytest.mark.parametrize("game", [g for g in GAMES if g.has_gne], ids=lambda g: g.name)
def test_references_have_no_gap(game) -> None:
    a = np.array(game.reference, dtype=float)
    gaps = nc.best_response_gaps(game, a)
    scale = np.maximum(1.0, np.abs(game.costs(a)))
    assert all(gap <= 1e-9 * s for gap, s in zip(gaps.values(), scale, strict=True)), gaps


@pytest.mark.parametrize("name", ["nc-tilted-well", "nc-well-at-max", "nc-sin-box", "nc-quartic", "nc-cos-box-2d"])
def test_references_recomputed(name: str) -> None:
    """The best-response iteration from the game's hard start, polished by Newton's method, reaches the reference."""
    a = nc.compute_references([name])[name]
    np.testing.assert_allclose(a, BY_NAME[name].reference, rtol=0, atol=1e-10)


@pytest.mark.parametrize("name", ["nc-tilted-well", "nc-gauss", "nc-sin-box", "nc-quartic", "ns-min-wells",
                                  "ns-abs-wells"])
def test_one_fixed_point(name: str) -> None:
    """The scan of BR1 o BR2 finds one equilibrium, next to the reference."""
    game = BY_NAME[name]
    found = nc.fixed_points(game)
    assert len(found) == 1
    assert abs(found[0][0] - game.reference[0]) <= 0.05


@pytest.mark.parametrize("name", ["nopure-wells", "nopure-concave-box"])
def test_no_fixed_point(name: str) -> None:
    assert nc.fixed_points(BY_NAME[name]) == []


@pytest.mark.parametrize("game", [g for g in GAMES if g.has_gne], ids=lambda g: g.name)
def test_the_check_rejects_the_hard_starts(game) -> None:
    """Each hard start of a game with an equilibrium is a point where some player improves alone (or an infeasible
    one): the check must say so, else it could not catch a solver that stays there."""
    for label, start in game.starts:
        gaps = nc.best_response_gaps(game, np.array(start, dtype=float))
        assert max(gaps.values()) > 1e-3, (label, gaps)


@pytest.mark.parametrize("name, point, player", [
    ("nc-gauss", (-1.99, 0.204), "p1"),  # the shallow basin's KKT point
    ("nc-well-at-max", (0.06262279120668492, 1.0), "p1"),  # the local maximum
    ("ns-abs-kink", (5.0, 2.0), "p1"),
    ("ns-abs-wells", (1.0, 1.0), "p1"),  # the other kink, a local minimum of p1
])
def test_the_check_finds_improvements(name: str, point: tuple, player: str) -> None:
    assert nc.best_response_gaps(BY_NAME[name], np.array(point))[player] > 1e-2


@pytest.mark.parametrize("name, point, player", [
    ("ub-cubic", (1.3113620517524083, 0.9344318974123795), "p1"),
    ("ub-concave", (0.08 / 0.6, 0.04 / 0.6 + 0.1), "p1"),
    ("ub-quartic-far", (0.0, 0.0), "p1"),
    ("ub-linear", (0.5, 0.95), "p1"),
    ("ub-lp-rows", (2.0, 1.0, 1.0), "p1"),
    ("ub-saddle-cone", (-0.05002501250625312, 0.0, 0.5002501250625313), "p1"),
    ("ub-cubic-3p", (0.5, -0.5, 1.0), "p3"),
])
def test_the_check_sees_unbounded_players(name: str, point: tuple, player: str) -> None:
    r = nc.best_response_report(BY_NAME[name], np.array(point))[player]
    assert r.gap == math.inf and "unbounded" in r.note


@pytest.mark.parametrize("name", ["ub-exp", "ub-softplus-2d"])
def test_the_check_sees_no_minimiser(name: str) -> None:
    """The infimum 0 is not attained: the check finds values down to rounding, so the gap is the candidate's cost."""
    game = BY_NAME[name]
    a = np.array(game.starts[0][1])
    r = nc.best_response_report(game, a)["p1"]
    assert r.value <= 1e-12 and r.gap == pytest.approx(game.costs(a)[0], rel=1e-9)


@pytest.mark.parametrize("game", [g for g in GAMES if g.kind == "infeasible"], ids=lambda g: g.name)
def test_infeasible_games_have_no_feasible_grid_point(game) -> None:
    """No point of a grid over [-4, 4]^n satisfies every player's rows at once (the games are infeasible), and the
    check calls every start infeasible for some player."""
    m = {2: 201, 3: 41}[game.n]
    axes = [np.linspace(-4, 4, m)] * game.n
    a = np.stack([g.ravel() for g in np.meshgrid(*axes, indexing="ij")])
    worst = np.max([game.violation(i, a) for i in range(len(game.players))], axis=0)
    assert worst.min() > 1e-3
    gaps = nc.best_response_gaps(game, np.array(game.starts[0][1]))
    assert math.inf in gaps.values()


@pytest.mark.parametrize("game", [g for g in GAMES if g.kind == "nan"], ids=lambda g: g.name)
def test_nan_games_are_not_finite_anywhere(game) -> None:
    rng = np.random.default_rng(2)
    a = rng.uniform(-5, 5, (game.n, 1000))
    a = np.clip(a, game.lower[:, None], game.upper[:, None])
    with np.errstate(all="ignore"):
        bad = [~np.isfinite(np.asarray(game.cost(i, a)) * np.ones(1000)) for i in range(len(game.players))]
    assert np.any(bad, axis=0).all()
    gaps = nc.best_response_gaps(game, np.array(game.starts[0][1]))
    assert any(math.isnan(v) for v in gaps.values())
