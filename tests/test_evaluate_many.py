"""Costs and constraint values at many points at once (gnerun.game.agents.AgentFunctions.evaluate_many), as the
certificate's starts, rays and probes use them: the same numbers as one evaluation per point, in blocks that are never
mostly padding."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gnerun.game.agents import BATCHES, batch_size
from gnerun.game.compile import compile_game
from gnerun.language.config import load_config

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("left", [1, 5, 8, 13, 28, 33, 64, 77, 100, 513, 1500])
def test_the_blocks_cover_the_points_and_are_at_most_half_padding(left: int) -> None:
    sizes, rest = [], left
    while rest > 0:
        size = batch_size(rest)
        assert size in BATCHES
        sizes.append(size)
        rest -= min(size, rest)
    padding = sum(sizes) - left
    # at most half of what is evaluated is padding (a block of 512 for 77 points was 435 evaluations of nothing)
    assert padding < BATCHES[0] or 2 * padding <= sum(sizes)
    assert sizes == sorted(sizes, reverse=True)


@pytest.fixture(scope="module")
def merge():
    cfg = load_config(ROOT / "configs" / "algames_merge.yaml")
    return compile_game(cfg)


@pytest.mark.parametrize("k", [1, 13, 77])
def test_the_values_at_many_points_are_those_of_one_evaluation_per_point(merge, k: int) -> None:
    game = merge
    rng = np.random.default_rng(k)
    A = 0.3 * rng.standard_normal((k, game.n))
    V = rng.standard_normal((k, game.n))
    J, C, dJ = game.agents.evaluate_many(A, None, V)
    assert J.shape == (k, len(game.agent_names)) and C.shape == (k, game.m) and dJ.shape == J.shape
    h = 1e-6
    for i in range(k):
        np.testing.assert_array_equal(J[i], game.costs(A[i]))
        np.testing.assert_array_equal(C[i], game.constraint_values(A[i])[0])
        central = (game.costs(A[i] + h * V[i]) - game.costs(A[i] - h * V[i])) / (2 * h)
        np.testing.assert_allclose(dJ[i], central, rtol=1e-6, atol=1e-8 * max(1.0, np.abs(central).max()))
    J2, C2 = game.agents.evaluate_many(A)
    np.testing.assert_array_equal(J2, J)
    np.testing.assert_array_equal(C2, C)
