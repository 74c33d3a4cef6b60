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


def _same_values(a: np.ndarray, b: np.ndarray) -> bool:
    """The same numbers to the bit, a zero's sign aside: the compiled LU leaves out the updates that add a zero
    (LAPACK's -0 + 0 is +0)."""
    return a.shape == b.shape and not np.isnan(a).any() and np.array_equal(a, b)


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
    if banded.status().startswith(("lapack (the processor", "lapack (the compiled solves round differently")):
        # another processor's OpenBLAS kernels (or another BLAS) sum otherwise: LAPACK's routines are used, as they
        # should be, and there is nothing compiled to compare
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
    stacked = interior_point._AgentBlocks._stacked

    def counted(self, data, D):
        calls.append(self.compiled)
        return stacked(self, data, D)

    monkeypatch.setattr(interior_point._AgentBlocks, "_stacked", counted)
    runs = []
    for state in ({"kernel": None, "status": "lapack (as a reference)"}, dict(banded._STATE)):
        monkeypatch.setattr(banded, "_STATE", state)
        iterates: list[np.ndarray] = []
        solver = make_solver(cfg, game)
        solver.newton.system.agent_blocks.clear()  # the players' blocks built anew, compiled or not
        final = iterate(solver, solver.init(), on_iterate=lambda s, seen=iterates: seen.append(s.z.copy()))
        runs.append((final.k, iterates))
    assert calls and runs[0][0] == runs[1][0] and len(runs[0][1]) == len(runs[1][1]) > 1
    assert not calls[0] and calls[-1]  # numpy's players' blocks, then the compiled ones
    assert all(_same_bits(a, b) for a, b in zip(runs[0][1], runs[1][1], strict=True))


# banded LU (dgbtrf) and its solves (dgbtrs)


def _kkt_band(rng: np.random.Generator, n: int, kl: int, ku: int) -> np.ndarray:
    """A matrix of n rows with kl diagonals below and ku above in LAPACK's band storage with room for the fill
    (Fortran-ordered, 2 kl + ku + 1 rows): entries of several magnitudes, many exactly zero, a few -0, as in the
    stage-ordered KKT matrices the solvers factorise."""
    ab = np.zeros((2 * kl + ku + 1, n), order="F")
    width = kl + ku + 1
    ab[kl:] = rng.standard_normal((width, n)) * 10.0 ** rng.integers(-4, 3, (width, n))
    ab[kl:][rng.random((width, n)) < 0.6] = 0.0
    ab[kl:][rng.random((width, n)) < 0.02] = -0.0
    return ab


def _lapack_lu(ab: np.ndarray, kl: int, ku: int) -> tuple[np.ndarray, np.ndarray, int]:
    return lapack.dgbtrf(ab.copy(order="F"), kl, ku)


def _compiled_lu(ab: np.ndarray, kl: int, ku: int) -> tuple[np.ndarray, np.ndarray, int]:
    lu = ab.copy(order="F")
    out = banded.lu_factor(lu, kl, ku)
    assert out is not None and out[0] is lu
    return out


@pytest.mark.parametrize("n, kl, ku", [(780, 18, 27), (1200, 18, 18), (1640, 18, 29), (325, 13, 13), (1051, 6, 7),
                                       (40, 0, 3), (50, 3, 0), (7, 5, 9), (1, 2, 2), (300, 40, 60)])
def test_the_compiled_lu_and_its_solves_are_lapacks_values_to_the_bit(compiled, n: int, kl: int, ku: int) -> None:
    rng = np.random.default_rng(n + 100 * kl + ku)
    for _ in range(3):
        ab = _kkt_band(rng, n, kl, ku)
        ab[kl + ku][ab[kl + ku] == 0.0] = 1.0  # no zero pivot
        ref, piv, info = _lapack_lu(ab, kl, ku)
        lu, gpiv, ginfo = _compiled_lu(ab, kl, ku)
        assert ginfo == info == 0 and np.array_equal(gpiv, piv) and _same_values(lu, ref)
        if kl and n > 1:
            assert np.any(piv != np.arange(n))  # rows were swapped
        b = _right_hand_sides(rng, n, 4)
        for trans in (0, 1):
            x = b[:, 0].copy()
            assert _same_values(banded.lu_solve(lu, kl, ku, gpiv, x, trans), lapack.dgbtrs(ref, kl, ku, x, piv,
                                                                                         trans=trans)[0])
            assert _same_bits(x, b[:, 0])  # the right-hand side is left as it was
        B = np.asfortranarray(b)
        assert _same_values(banded.lu_solve(lu, kl, ku, gpiv, B), lapack.dgbtrs(ref, kl, ku, B, piv)[0])
        assert _same_values(banded.lu_solve(lu, kl, ku, gpiv, B, 1), lapack.dgbtrs(ref, kl, ku, B, piv, trans=1)[0])


def test_ties_between_pivots_take_the_first_row_as_idamax_does(compiled) -> None:
    rng = np.random.default_rng(6)
    n, kl, ku = 200, 9, 14
    ab = _kkt_band(rng, n, kl, ku)
    ab[kl:] = np.sign(ab[kl:]) * rng.integers(1, 3, ab[kl:].shape)  # entries +-1, +-2: many equal magnitudes
    ref, piv, info = _lapack_lu(ab, kl, ku)
    lu, gpiv, ginfo = _compiled_lu(ab, kl, ku)
    assert ginfo == info and np.array_equal(gpiv, piv) and _same_values(lu, ref)


def test_a_zero_pivot_is_reported_as_lapack_does(compiled) -> None:
    rng = np.random.default_rng(7)
    n, kl, ku = 60, 4, 5
    ab = _kkt_band(rng, n, kl, ku)
    ab[kl + ku:, 20] = 0.0  # column 21 has nothing on or below its diagonal
    ab[kl + ku, 40] = 1.0
    ref, piv, info = _lapack_lu(ab, kl, ku)
    lu, gpiv, ginfo = _compiled_lu(ab, kl, ku)
    assert info > 0 and ginfo == info and np.array_equal(gpiv, piv) and _same_values(lu, ref)  # LAPACK goes on


def test_what_the_compiled_lu_leaves_to_lapack(compiled) -> None:
    rng = np.random.default_rng(8)
    ab = _kkt_band(rng, 300, 40, 70)  # dgbtrf's blocked path (kl >= 32, ku > 64)
    ref, piv, info = _lapack_lu(ab, 40, 70)
    lu, gpiv, ginfo = banded.lu_factor(ab, 40, 70)
    assert lu is ab and _same_values(lu, ref) and np.array_equal(gpiv, piv) and ginfo == info
    ab = _kkt_band(rng, 50, 3, 4)
    ab[3 + 4 + 1, 10] = np.nan
    assert banded.lu_factor(ab, 3, 4) is None  # a value that is not finite, met before LAPACK's idamax would be
    ab = _kkt_band(rng, 50, 3, 4)
    ab[3 + 4, 10] = np.inf
    assert banded.lu_factor(ab, 3, 4) is None
    # an entry of U that is not finite (row 10, column 12: never a value to pivot on); dger would spread its NaNs
    # to rows the compiled update leaves alone
    ab = _kkt_band(rng, 50, 3, 4)
    ab[3 + 4 + 10 - 12, 12] = np.inf
    assert banded.lu_factor(ab, 3, 4) is None and np.isnan(_lapack_lu(ab, 3, 4)[0]).any()
    # a pivot whose reciprocal overflows: the multipliers would not be finite
    ab = _kkt_band(rng, 50, 3, 4)
    ab[3 + 4][ab[3 + 4] == 0.0] = 1.0
    ab[:, 10] = 0.0  # column 10 alone: no update reaches it
    ab[3 + 4, 10], ab[3 + 4 + 2, 10] = 1e-310, 1e-311
    assert banded.lu_factor(ab, 3, 4) is None


@pytest.mark.parametrize("zeros", [0.9, 0.97])
def test_a_band_mostly_zero_inside_factorises_to_lapacks_values(compiled, zeros: float) -> None:
    """The compiled LU leaves out the updates that add zeros (a zero multiplier, a zero in the pivot's row): the
    merge's bands are 91% zero inside. The factors and the solutions are LAPACK's, a zero's sign aside, and some of
    those signs do differ (LAPACK's -0 + 0 is +0), so the skipped updates are real."""
    rng = np.random.default_rng(int(zeros * 100))
    n, kl, ku = 400, 18, 18
    signs = 0
    for _ in range(5):
        ab = _kkt_band(rng, n, kl, ku)
        ab[kl:][rng.random((kl + ku + 1, n)) < zeros] = 0.0
        ab[kl:][rng.random((kl + ku + 1, n)) < 0.02] = -0.0
        ab[kl + ku][ab[kl + ku] == 0.0] = 1.0
        ref, piv, info = _lapack_lu(ab, kl, ku)
        lu, gpiv, ginfo = _compiled_lu(ab, kl, ku)
        assert ginfo == info == 0 and np.array_equal(gpiv, piv) and _same_values(lu, ref)
        signs += int(np.sum(lu.view(np.int64) != ref.view(np.int64)))
        b = _right_hand_sides(rng, n, 1)[:, 0]
        for trans in (0, 1):
            assert _same_values(banded.lu_solve(lu, kl, ku, gpiv, b, trans), lapack.dgbtrs(ref, kl, ku, b, piv,
                                                                                           trans=trans)[0])
    assert signs > 0


def test_the_compiled_condition_estimate_is_inverse_norms_to_the_bit(compiled) -> None:
    from gnerun.game.sparse import inverse_norm

    rng = np.random.default_rng(9)
    for n, kl, ku in ((780, 18, 27), (1200, 18, 18), (1, 0, 0), (2, 1, 1), (9, 2, 3), (300, 6, 7)):
        for _ in range(3):
            ab = _kkt_band(rng, n, kl, ku)
            ab[kl + ku] += np.where(ab[kl + ku] >= 0, 1.0, -1.0) * 10.0 ** rng.integers(-2, 2, n)
            lu, piv, info = _lapack_lu(ab, kl, ku)
            assert info == 0

            def solve(b, trans=0, lu=lu, kl=kl, ku=ku, piv=piv):
                return lapack.dgbtrs(lu, kl, ku, b, piv, trans=trans)[0]

            ref = inverse_norm(solve, lambda b, solve=solve: solve(b, 1), n)
            assert _same_bits(np.array(banded.lu_inverse_norm(lu, kl, ku, piv)), np.array(ref))


def test_the_compiled_norm_is_numpys_to_the_bit(compiled) -> None:
    rng = np.random.default_rng(11)
    for n, kl, ku in ((780, 18, 27), (50, 2, 1), (30, 60, 70), (3, 0, 0)):  # columns of 64, 6, 191 and 1 entries
        ab = _kkt_band(rng, n, kl, ku)
        assert _same_bits(np.array(banded.one_norm(ab)), np.array(float(np.abs(ab).sum(axis=0).max())))
    ab[0, 1] = np.nan
    assert np.isnan(banded.one_norm(ab))


def test_the_check_at_loading_refuses_a_factorisation_or_a_solve_one_bit_off(compiled) -> None:
    factor, solve_lu, *_ = banded._STATE["lu"]
    assert banded._lu_agrees(factor, solve_lu)

    def factor_off(n, kl, ku, ab, ld, ipiv):
        info = factor(n, kl, ku, ab, ld, ipiv)
        out = np.ctypeslib.as_array((ctypes.c_double * (ld * n)).from_address(ab))
        out[ld * n - 1] = np.nextafter(out[ld * n - 1], np.inf)  # U's last diagonal entry
        return info

    def solve_off(n, kl, ku, ab, ld, ipiv, m, b, trans):
        info = solve_lu(n, kl, ku, ab, ld, ipiv, m, b, trans)
        if trans:
            out = np.ctypeslib.as_array((ctypes.c_double * n).from_address(b))
            out[0] = np.nextafter(out[0], np.inf)
        return info

    assert not banded._lu_agrees(factor_off, solve_lu)
    assert not banded._lu_agrees(factor, solve_off)


def test_without_a_compiler_the_lu_is_lapacks(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(banded, "_STATE", {})
    monkeypatch.setattr(banded, "compiler", lambda: None)
    assert banded.status() == "lapack (no C compiler found: gcc, cc or $CC)"
    rng = np.random.default_rng(10)
    ab = _kkt_band(rng, 80, 5, 6)
    lu, piv, info = _lapack_lu(ab, 5, 6)
    got = banded.lu_factor(ab.copy(order="F"), 5, 6)
    assert _same_bits(got[0], lu) and np.array_equal(got[1], piv) and got[2] == info
    assert banded.lu_inverse_norm(lu, 5, 6, piv) is None and banded.one_norm(ab) is None
    b = rng.standard_normal(80)
    for trans in (0, 1):
        assert _same_bits(banded.lu_solve(lu, 5, 6, piv, b, trans), lapack.dgbtrs(lu, 5, 6, b, piv, trans=trans)[0])


def test_the_sparse_formulation_takes_the_same_iterates_with_either_lu(compiled, monkeypatch) -> None:
    """ALGAMES's merge by the default solver, whose Newton systems are the stage-ordered band: every iterate and
    every condition estimate the same to the bit with the compiled LU and with LAPACK's."""
    from benchmarks.problems import trajectory
    from gnerun.game import sparse
    from gnerun.game.compile import compile_game
    from gnerun.language.config import load_config
    from gnerun.runs.solving import make_solver
    from gnerun.solvers.driver import iterate

    cfg = load_config(text=trajectory.merge_problems(1)[0].config_yaml)
    game = compile_game(cfg)
    factor = sparse.KeptLayout.factor
    runs = []
    for state in ({"kernel": None, "lu": None, "status": "lapack (as a reference)"}, dict(banded._STATE)):
        monkeypatch.setattr(banded, "_STATE", state)
        estimates: list[float] = []

        def recorded(self, data, add, estimate=True, seen=estimates):
            out = factor(self, data, add, estimate)
            if self.banded:
                seen.append(out[1])
            return out

        monkeypatch.setattr(sparse.KeptLayout, "factor", recorded)
        iterates: list[np.ndarray] = []
        solver = make_solver(cfg, game)
        final = iterate(solver, solver.init(), on_iterate=lambda s, seen=iterates: seen.append(s.z.copy()))
        runs.append((final.k, iterates, estimates))
    assert runs[0][0] == runs[1][0] and len(runs[0][1]) == len(runs[1][1]) > 1 and len(runs[0][2]) > 1
    assert all(_same_values(a, b) for a, b in zip(runs[0][1], runs[1][1], strict=True))
    assert _same_bits(np.array(runs[0][2]), np.array(runs[1][2]))


def test_a_factorisation_the_compiled_lu_declines_is_lapacks(compiled, monkeypatch: pytest.MonkeyPatch) -> None:
    """KeptLayout.factor on a merge's Newton matrix: the same factors, pivots, condition estimate and solution with
    the compiled LU, with LAPACK's, and where the compiled LU gives up half-way (a value that is not finite): the band
    is assembled again for LAPACK."""
    from benchmarks.problems import trajectory
    from gnerun.game import sparse
    from gnerun.game.compile import compile_game
    from gnerun.language.config import load_config
    from gnerun.runs.solving import make_solver
    from gnerun.solvers import hybrid, reduced

    cfg = load_config(text=trajectory.merge_problems(1)[0].config_yaml)
    game = compile_game(cfg)
    seen = []
    factor = sparse.KeptLayout.factor

    def first(self, data, add, estimate=True):
        if self.banded and not seen:
            seen.append((self, data.copy(), None if add is None else add.copy()))
        return factor(self, data, add, estimate)

    monkeypatch.setattr(sparse.KeptLayout, "factor", first)
    monkeypatch.setattr(hybrid, "DECOUPLE_ABOVE", np.inf)  # the first step a Newton step (not the decoupled plans)
    monkeypatch.setattr(reduced, "FUSED", False)  # its factorisation by KeptLayout.factor, not in one compiled call
    solver = make_solver(cfg, game)
    solver.step(solver.init())
    monkeypatch.setattr(sparse.KeptLayout, "factor", factor)
    layout, data, add = seen[0]
    b = np.random.default_rng(12).standard_normal(layout.size)
    lu_factor = banded.lu_factor

    def gives_up(ab, kl, ku):
        lu_factor(ab, kl, ku)  # ab overwritten by half a factorisation
        ab[:, ab.shape[1] // 2:] = np.nan
        return None

    outcomes = []
    for state, lu in (({"kernel": None, "lu": None, "status": "lapack"}, lu_factor), (dict(banded._STATE), lu_factor),
                      (dict(banded._STATE), gives_up)):
        monkeypatch.setattr(banded, "_STATE", state)
        monkeypatch.setattr(banded, "lu_factor", lu)
        factors, rcond = layout.factor(data, add)
        outcomes.append((factors.lu, np.array(rcond), factors.solve(b), factors.piv))
    assert 0 < outcomes[0][1] < 1
    for other in outcomes[1:]:
        assert all(_same_values(a, o) for a, o in zip(outcomes[0][:3], other[:3], strict=True))
        assert np.array_equal(other[3], outcomes[0][3])
