"""The compiled banded triangular solves: LAPACK's dtbtrs to the bit, on bands shaped like the interior step's
(-I on the diagonal, the dynamics' Jacobian in 4 diagonals below) and on others; LAPACK's solves where nothing is
compiled; the same interior-point iterates either way."""

from __future__ import annotations

import ctypes

import numpy as np
import pytest
from scipy.linalg import lapack

from gnerun.game import banded
from gnerun.game.kernels import compiler


def _lapack(band: np.ndarray, b: np.ndarray, transpose: bool) -> tuple[np.ndarray, int]:
    y, info = lapack.dtbtrs(band.T, b, uplo="L", trans="T" if transpose else "N")
    return y, info


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and np.array_equal(a.view(np.int64), b.view(np.int64))


def _dynamics_band(rng: np.random.Generator, n: int, below: int = 4) -> np.ndarray:
    """-I on the diagonal, a Jacobian's entries below (some exactly zero, of several magnitudes), as the defects'
    block of a trajectory game."""
    band = np.zeros((n, below + 1))
    band[:, 0] = -1.0
    entries = rng.standard_normal((n, below)) * 10.0 ** rng.integers(-3, 2, (n, below))
    entries[rng.random((n, below)) < 0.3] = 0.0
    band[:, 1:] = entries
    return band


def _right_hand_sides(rng: np.random.Generator, n: int, m: int) -> np.ndarray:
    b = rng.standard_normal((n, m)) * 10.0 ** rng.integers(-4, 4, (n, m))
    b[rng.random((n, m)) < 0.3] = 0.0  # the decisions' block is sparse: exact zeros, and a few negative ones
    b[rng.random((n, m)) < 0.05] = -0.0
    return b


@pytest.fixture
def compiled() -> None:
    if compiler() is None:
        pytest.skip("no C compiler")
    if banded.status().startswith("lapack (the processor"):
        pytest.skip(banded.status())
    assert banded.status() == "compiled"


@pytest.mark.parametrize("n, m", [(240, 40), (480, 80), (104, 26), (7, 1), (1, 3), (130, 67)])
def test_the_compiled_solves_are_lapacks_to_the_bit(compiled, n: int, m: int) -> None:
    rng = np.random.default_rng(n * 1000 + m)
    for draw in range(5):
        band = _dynamics_band(rng, n)
        if draw == 4:  # any diagonal, not only -1
            band[:, 0] = rng.uniform(0.5, 2.0, n) * rng.choice([-1.0, 1.0], n)
        b = _right_hand_sides(rng, n, m)
        for transpose in (False, True):
            ref, info = _lapack(band, b, transpose)
            got = b.copy()
            assert info == 0 and banded.solve(band, got, transpose) == 0
            assert _same_bits(ref, got), np.flatnonzero(ref.view(np.int64) != got.view(np.int64))


def test_a_narrower_band_and_one_wider_than_the_matrix(compiled) -> None:
    rng = np.random.default_rng(3)
    for n, below in ((50, 0), (50, 1), (50, 2), (3, 5), (1, 4)):
        band = _dynamics_band(rng, n, below)
        b = _right_hand_sides(rng, n, 9)
        for transpose in (False, True):
            got = b.copy()
            assert banded.solve(band, got, transpose) == 0
            assert _same_bits(_lapack(band, b, transpose)[0], got)


def test_a_zero_on_the_diagonal_is_reported_as_lapack_does(compiled) -> None:
    rng = np.random.default_rng(4)
    band = _dynamics_band(rng, 20)
    band[[6, 11], 0] = 0.0
    b = _right_hand_sides(rng, 20, 5)
    for transpose in (False, True):
        got = b.copy()
        assert banded.solve(band, got, transpose) == _lapack(band, b, transpose)[1] == 7
        assert _same_bits(got, b)  # untouched


def test_the_check_at_loading_refuses_a_solve_one_bit_off(compiled) -> None:
    kernel = banded._STATE["kernel"]
    assert banded._agrees(kernel)

    def one_bit_off(n, k, band, m, b, transpose):
        info = kernel(n, k, band, m, b, transpose)
        out = np.ctypeslib.as_array((ctypes.c_double * (n * m)).from_address(b))
        out[-1] = np.nextafter(out[-1], np.inf)
        return info

    assert not banded._agrees(one_bit_off)


def test_without_a_compiler_the_solves_are_lapacks(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(banded, "_STATE", {})
    monkeypatch.setattr(banded, "compiler", lambda: None)
    assert banded.status() == "lapack (no C compiler found: gcc, cc or $CC)"
    rng = np.random.default_rng(5)
    band = _dynamics_band(rng, 30)
    b = _right_hand_sides(rng, 30, 4)
    for transpose in (False, True):
        got = b.copy()
        assert banded.solve(band, got, transpose) == 0
        assert _same_bits(_lapack(band, b, transpose)[0], got)
    band[2, 0] = 0.0
    got = b.copy()
    assert banded.solve(band, got) == 3 and _same_bits(got, b)


def test_a_merge_takes_the_same_iterates_with_either_solve(compiled, monkeypatch: pytest.MonkeyPatch) -> None:
    """ALGAMES's merge through the interior phase (the players' blocks of the Schur complement at every step):
    every iterate the same to the bit with the compiled solves and with LAPACK's."""
    from benchmarks.problems import trajectory
    from gnerun.game.compile import compile_game
    from gnerun.language.config import load_config
    from gnerun.runs.solving import make_solver
    from gnerun.solvers import interior_point
    from gnerun.solvers.driver import iterate

    cfg = load_config(text=trajectory.merge_problems(1)[0].config_yaml)
    game = compile_game(cfg)
    calls = []
    complement = interior_point._AgentBlocks.complement

    def counted(self, data, D):
        calls.append(self)
        return complement(self, data, D)

    monkeypatch.setattr(interior_point._AgentBlocks, "complement", counted)
    runs = []
    for state in ({"kernel": None, "status": "lapack (as a reference)"}, dict(banded._STATE)):
        monkeypatch.setattr(banded, "_STATE", state)
        iterates: list[np.ndarray] = []
        solver = make_solver(cfg, game)
        final = iterate(solver, solver.init(), on_iterate=lambda s, seen=iterates: seen.append(s.z.copy()))
        runs.append((final.k, iterates))
    assert calls and runs[0][0] == runs[1][0] and len(runs[0][1]) == len(runs[1][1]) > 1
    assert all(_same_bits(a, b) for a, b in zip(runs[0][1], runs[1][1], strict=True))
