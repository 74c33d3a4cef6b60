"""The Facchinei–Kanzow test library (benchmarks/problems/fk.py) against its independent numpy writing.

Checked here: every config loads with the right players and variables; gnerun's compiled costs and constraint
rows equal the numpy writing at random points (two independent transcriptions of the same published data);
every stored reference is feasible, has vanishing best-response gaps by the SLSQP check (which shares no code
with gnerun), matches closed forms where the problem has one and the approximate solutions printed with the
problems; and the checks fail where they should. gnerun's solver is not exercised (measured elsewhere).
"""

from __future__ import annotations

import numpy as np
import pytest

import gnerun
from benchmarks.problems import Problem, fk

PROBLEMS = fk.problems()
GAMES = {g.label: g for g in fk.games()}
ISOLATED = [label for label, g in GAMES.items() if g.isolated]
SMALL_ISOLATED = [label for label in ISOLATED if GAMES[label].n <= 60]
LARGE_ISOLATED = [label for label in ISOLATED if GAMES[label].n > 60]
ONE_PER_GAME = {p.name: p for p in reversed(PROBLEMS)}
BIG = 100  # configs of more variables than this compile for seconds: their checks are marked slow


def _by_size(item: object, size: int) -> object:
    return pytest.param(item, marks=pytest.mark.slow) if size > BIG else item


def _problem(label: str) -> Problem:
    return ONE_PER_GAME[label]


def _random_point(game: fk._Game, rng: np.random.Generator) -> np.ndarray:
    lo = np.where(np.isfinite(game.lower), game.lower, -2.0)
    up = np.where(np.isfinite(game.upper), game.upper, np.maximum(lo, 0.0) + 3.0)
    a = lo + (up - lo) * rng.random(game.n)
    if game.slug.startswith(("a01", "a02", "a14", "a09", "a10", "a16")):
        a = np.abs(a) + 0.05  # where the costs are defined (positive totals, logs of positive arguments)
    return a


# ----------------------------------------------------------------------------------------------------------
# the list of pairs and the configs
# ----------------------------------------------------------------------------------------------------------


def test_the_library_has_44_problem_start_pairs() -> None:
    assert len(PROBLEMS) == 44
    assert len(GAMES) == 26
    counts = {label: sum(p.name == label for p in PROBLEMS) for label in GAMES}
    for label in ("A.1", "A.2", "A.3", "A.4", "A.5", "A.6", "A.7", "A.8", "A.18"):
        assert counts[label] == 3, label
    assert sum(counts.values()) == 44
    names = [p.config_yaml.splitlines()[0].removeprefix("name: ") for p in PROBLEMS]
    assert len(set(names)) == len(names)
    assert "fk-a01-x0-0.01" in names and "fk-a12-x0-2-0" in names and "fk-a10e-x0-std" in names
    assert all(p.family == "fk" and p.has_gne and p.published == {} for p in PROBLEMS)


@pytest.mark.parametrize("problem", [_by_size(p, fk.game_of(p).n) for p in PROBLEMS],
                         ids=lambda p: f"{p.name}|{p.start}")
def test_config_loads_with_the_players_and_start(problem: Problem) -> None:
    game = fk.game_of(problem)
    cfg = gnerun.load_config(text=problem.config_yaml)
    assert "solver:" not in problem.config_yaml  # gnerun's defaults are what the suite measures
    assert cfg.game.kind == "static" and cfg.game.equilibrium == "generalized"
    assert [a.name for a in cfg.game.agents] == [p.name for p in game.players]
    assert [list(a.variables) for a in cfg.game.agents] == [p.variables for p in game.players]
    start = dict(game.starts)[problem.start.removeprefix("x0 = ")]
    got = np.array([v.start for a in cfg.game.agents for v in a.variables.values()], dtype=float)
    np.testing.assert_array_equal(got, start)
    longest = max(len(e) for a in cfg.game.agents for e in [a.cost, *a.constraints])
    assert longest < 20_000


# ----------------------------------------------------------------------------------------------------------
# transcription: gnerun's compiled game against the numpy writing
# ----------------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("label", [_by_size(label, g.n) for label, g in GAMES.items()])
def test_compiled_costs_and_rows_equal_the_numpy_writing(label: str) -> None:
    game = GAMES[label]
    compiled = gnerun.compile_game(gnerun.load_config(text=_problem(label).config_yaml))
    assert compiled.n == game.n
    assert compiled.m == fk.n_rows(game)
    eq = np.concatenate([game.eq_rows(i) for i in range(len(game.players))])
    assert [c.equality for c in compiled.constraints] == list(eq)
    rng = np.random.default_rng(0)
    for _ in range(3):
        a = _random_point(game, rng)
        mine = np.array([float(np.real(game.cost(i, a))) for i in range(len(game.players))])
        np.testing.assert_allclose(compiled.costs(a), mine, rtol=1e-11, atol=1e-11)
        rows = compiled.kkt_parts(np.concatenate([a, np.zeros(compiled.m)])).c
        mine_rows = np.concatenate([np.real(game.rows(i, a)) for i in range(len(game.players))])
        np.testing.assert_allclose(rows, mine_rows, rtol=1e-11, atol=1e-11)


def test_transcription_check_detects_a_changed_coefficient() -> None:
    label = "A.3"
    text = _problem(label).config_yaml.replace("11*x1*x6", "12*x1*x6", 1)
    assert text != _problem(label).config_yaml
    compiled = gnerun.compile_game(gnerun.load_config(text=text))
    a = _random_point(GAMES[label], np.random.default_rng(1))
    mine = np.array([float(GAMES[label].cost(i, a)) for i in range(3)])
    assert abs(compiled.costs(a)[0] - mine[0]) > 1e-6


# ----------------------------------------------------------------------------------------------------------
# references
# ----------------------------------------------------------------------------------------------------------


def test_references_are_stored_exactly_for_the_isolated_problems() -> None:
    for p in PROBLEMS:
        game = fk.game_of(p)
        if game.isolated:
            assert p.reference is not None and p.reference.shape == (game.n,), p.name
            assert "numpy" in p.reference_source
        else:
            assert p.reference is None, p.name
            assert p.notes


def _check_reference(label: str) -> None:
    game = GAMES[label]
    ref = _problem(label).reference
    assert fk.feasibility(game, ref) <= 1e-9
    gaps = fk.best_response_gaps(game, ref)
    assert set(gaps) == {p.name for p in game.players}
    assert max(gaps.values()) <= 1e-6, gaps
    if game.n <= BIG:  # the independent KKT solve started at a* stays there (a*, with multipliers, is a zero)
        z, r = fk.solve_kkt(game, ref)
        assert r <= 1e-8 and np.max(np.abs(z[:game.n] - ref)) <= 1e-6


@pytest.mark.parametrize("label", SMALL_ISOLATED)
def test_reference_is_feasible_with_vanishing_gaps(label: str) -> None:
    _check_reference(label)


@pytest.mark.slow
@pytest.mark.parametrize("label", LARGE_ISOLATED)
def test_large_reference_is_feasible_with_vanishing_gaps(label: str) -> None:
    _check_reference(label)


def test_a03_has_several_isolated_equilibria() -> None:
    game = GAMES["A.3"]
    eqs = fk.known_equilibria("A.3")
    assert len(eqs) == 5
    np.testing.assert_array_equal(eqs[0], _problem("A.3").reference)
    for k, a in enumerate(eqs):
        assert fk.feasibility(game, a) <= 1e-9
        assert max(fk.best_response_gaps(game, a).values()) <= 1e-6, k
        assert all(np.max(np.abs(a - b)) > 0.1 for b in eqs[:k])


@pytest.mark.parametrize("label", [label for label in ISOLATED if GAMES[label].printed is not None])
def test_reference_agrees_with_the_printed_solution(label: str) -> None:
    game = GAMES[label]
    assert np.max(np.abs(_problem(label).reference - game.printed)) <= game.printed_tol


def test_closed_form_references() -> None:
    y = (2.6 + np.sqrt(2.6 ** 2 + 4 * 81 * 0.21)) / 162  # A.1: x1 = 0.3, 81 y^2 - 2.6 y - 0.21 = 0
    np.testing.assert_allclose(_problem("A.1").reference, [0.3] + [y] * 9, atol=1e-10)
    np.testing.assert_allclose(_problem("A.12").reference, [16 / 3, 16 / 3], atol=1e-10)
    np.testing.assert_allclose(_problem("A.14").reference, [0.09] * 10, atol=1e-10)
    np.testing.assert_allclose(_problem("A.4").reference, np.ones(7), atol=1e-10)
    np.testing.assert_allclose(_problem("A.5").reference, [0, 14 / 69, 0, 0, 5 / 69, 7 / 276, 0], atol=1e-10)
    a7 = np.ones(20)
    a7[11] = 164 / 89
    np.testing.assert_allclose(_problem("A.7").reference, a7, atol=1e-10)


@pytest.mark.parametrize("label", SMALL_ISOLATED)
def test_a_perturbed_reference_has_a_positive_gap(label: str) -> None:
    game = GAMES[label]
    ref = _problem(label).reference
    owner = np.concatenate([np.full(n, i) for i, n in enumerate(game.sizes)])
    for k in range(game.n):  # the first coordinate whose move keeps its owner's problem feasible
        i = int(owner[k])
        for step in (1e-2, -1e-2):
            a = ref.copy()
            a[k] += step * (1 + abs(ref[k]))
            g, _ = fk.own_rows(game, i, a)
            eq = game.eq_rows(i)
            if np.all(g[~eq] <= 1e-12) and np.all(np.abs(g[eq]) <= 1e-12):
                gap = fk.best_response_gaps(game, a)[game.players[i].name]
                assert gap > 1e-7, (k, gap)
                return
    pytest.fail("no feasible perturbation")


def test_gap_check_rejects_non_equilibria_and_accepts_known_ones() -> None:
    a12 = GAMES["A.12"]
    assert fk.best_response_gaps(a12, np.array([0.0, 0.0]))["p1"] == pytest.approx(64.0, rel=1e-6)
    assert max(fk.best_response_gaps(a12, np.array([16 / 3, 16 / 3])).values()) <= 1e-9


@pytest.mark.parametrize("label, points", [
    ("A.11", [[0.5, 0.5], [0.75, 0.25], [1.0, 0.0]]),
    ("A.8", [[0.5, 0.5, 0.75], [0.6, 0.4, 0.9], [2 / 3, 1 / 3, 1.0]]),
    ("A.17", [[0.0, 11.0, 8.0], [1.0, 10.0, 7.0], [2.0, 9.0, 6.0]]),
])
def test_non_isolated_problems_have_a_continuum_of_equilibria(label: str, points: list[list[float]]) -> None:
    game = GAMES[label]
    assert not game.isolated
    for a in points:
        a = np.array(a)
        assert fk.feasibility(game, a) <= 1e-12
        assert max(fk.best_response_gaps(game, a).values()) <= 1e-7, a
    off = np.array(points[0]) + 0.05
    assert fk.feasibility(game, off) > 0 or max(fk.best_response_gaps(game, off).values()) > 1e-7


def test_printed_normalized_equilibria_are_equilibria_of_the_continuum() -> None:
    # A.13 and A.16: the printed points are GNEs (to their printed precision) though not isolated ones
    for label in ("A.13", "A.16 (P = 75)", "A.16 (P = 200)"):
        game = GAMES[label]
        a = game.printed
        assert fk.feasibility(game, a) <= 1e-4, label
        assert max(fk.best_response_gaps(game, np.minimum(a, a * (1 - 1e-9))).values()) <= 1e-3, label


@pytest.mark.slow
def test_compute_references_reproduces_the_stored_ones() -> None:
    fresh = fk.compute_references(["A.3", "A.12", "A.15"], tries=1)
    for label, a in fresh.items():
        np.testing.assert_allclose(a, _problem(label).reference, atol=1e-9)
