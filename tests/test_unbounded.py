"""Rays (gnerun/solvers/unbounded.py) on bare cost sequences and cones: what shows a cost without a minimum, and
what does not."""

from __future__ import annotations

import numpy as np
import pytest

from gnerun.solvers.unbounded import (
    STEPS,
    approach_point,
    descending_ray,
    flat_directions,
    free_directions,
    no_descent,
    nonnegative_least_squares,
    pole_approach,
    pole_segment,
    ray_points,
    recession_direction,
)


def _ray(f, y0: np.ndarray, d: np.ndarray):
    points, t = ray_points(y0, [d], max(1.0, float(np.max(np.abs(y0)))))
    costs = np.array([f(q) for q in points])
    return descending_ray([d], t, costs, np.ones(STEPS, dtype=bool), f(y0))


def test_costs_unbounded_below_or_without_a_minimiser_are_shown() -> None:
    e = np.array([1.0])
    assert _ray(lambda q: q[0] ** 3 / 3 - q[0], np.array([1.0]), -e).unbounded_below  # a local minimum of a cubic
    assert _ray(lambda q: q[0] ** 2 - 1e-6 * q[0] ** 4, np.array([0.0]), e) is not None  # rises first, falls far out
    ray = _ray(lambda q: np.exp(-q[0]), np.array([20.0]), e)  # no minimiser: decays to 0, underflows
    assert ray is not None and not ray.unbounded_below
    ray = _ray(lambda q: -q[0] / (1 + abs(q[0])), np.array([3e3]), e)  # tends to -1, never reaches it
    assert ray is not None


def test_costs_with_a_minimum_are_not() -> None:
    e = np.array([1.0])
    assert _ray(lambda q: (q[0] - 1) ** 2, np.array([1.0]), e) is None  # the minimum itself
    assert _ray(lambda q: (q[0] - 1) ** 2, np.array([-5.0]), e) is None  # descends, then rises again
    assert _ray(lambda q: np.cos(q[0]), np.array([np.pi]), e) is None
    assert _ray(lambda q: max(1 - q[0], 0.0) * 0 + 3.0, np.array([0.0]), e) is None  # flat: nothing is lower


def test_an_infeasible_point_on_the_ray_ends_it() -> None:
    d = np.array([1.0])
    points, t = ray_points(np.array([0.0]), [d], 1.0)
    costs = -points[:, 0]
    ok = points[:, 0] <= 50  # a bound at 50
    assert descending_ray([d], t, costs, ok, 0.0) is None
    assert descending_ray([d], t, costs, np.ones_like(ok), 0.0) is not None


def test_directions_respect_the_bounds() -> None:
    lo = np.array([0.0, -np.inf, -1.0])
    hi = np.array([np.inf, np.inf, 1.0])
    dirs = free_directions(lo, hi, np.array([1.0, -2.0, 0.5]), 0, [np.array([-1.0, 1.0, 1.0])])
    assert dirs
    for d in dirs:
        assert abs(np.linalg.norm(d) - 1) < 1e-12
        assert d[2] == 0.0  # a coordinate bounded on both sides never moves along a ray
    assert free_directions(np.zeros(2), np.ones(2), None, 0) == []


def test_flat_and_recession_directions() -> None:
    H = np.array([[2.0, 2.0], [2.0, 2.0]])  # flat along (1, -1)
    flat = flat_directions(H)
    assert any(abs(abs(d @ np.array([1, -1]) / np.sqrt(2)) - 1) < 1e-12 for d in flat)
    assert flat_directions(np.eye(2)) == []
    # rows y1 + 2 y2 <= 4, y2 - y1 <= 1 (gradients (1, 2) and (-1, 1)); cost gradient (-0.9, -1): the cone's descent
    # direction is (2, -1) up to scale
    d = recession_direction(np.array([-0.9, -1.0]), np.array([[1.0, 2.0], [-1.0, 1.0]]), np.zeros(2, dtype=bool))
    assert d is not None and d @ np.array([-0.9, -1.0]) < 0 and d @ np.array([1.0, 2.0]) <= 1e-12
    assert recession_direction(np.array([1.0, 1.0]), -np.eye(2), np.zeros(2, dtype=bool)) is None  # y >= 0, cost up


def test_multipliers_spare_the_linear_program_only_where_it_finds_no_descent() -> None:
    """Random cones in 6 dimensions, 2-9 rows (some equalities): where a gradient is balanced by nonnegative
    multipliers of its rows (a KKT point, up to 1e-14 or 1e-11), :func:`no_descent` proves what the linear program
    finds (no direction); where it is not (a multiplier negative, or a part of the gradient no row balances), the
    proof is not claimed and the linear program runs. Every claim is checked against the linear program."""
    rng = np.random.default_rng(7)
    claimed = unbalanced = 0
    for trial in range(300):
        n, m = 6, int(rng.integers(2, 10))
        C = rng.standard_normal((m, n))
        eq = rng.random(m) < 0.2
        lam = np.where(rng.random(m) < 0.6, rng.random(m) * 3.0, 0.0)
        kind = trial % 3
        if kind == 2:  # a multiplier of an inequality negative: the cone does not hold -g
            lam[np.flatnonzero(~eq)[:1]] = -1.0
        g = -C.T @ lam
        if kind == 1:
            g = g + rng.standard_normal(n)  # a part no row balances (when m < n, a true descent)
        noisy = g + rng.standard_normal(n) * (1e-14 if trial % 2 else 1e-11)
        floor = 1e-12 * max(1.0, float(np.max(np.abs(noisy))))
        given = lam + rng.standard_normal(m) * 1e-12 * (rng.random(m) < 0.5)
        lp = recession_direction(noisy, C, eq)
        if no_descent(noisy, C, eq, given, floor):
            claimed += 1
            assert lp is None, (trial, noisy @ lp)
            assert recession_direction(noisy, C, eq, given) is None
        elif lp is not None:
            unbalanced += 1
            d = recession_direction(noisy, C, eq, given)
            assert d is not None and np.allclose(d, lp)
    assert claimed >= 60 and unbalanced >= 60, (claimed, unbalanced)


def test_nonnegative_least_squares_agrees_with_scipys() -> None:
    """Lawson-Hanson against scipy.optimize.nnls on 200 random problems (tall, wide and square, with and without an
    exact nonnegative solution): the same residual norm to 1e-10 (relative), x >= 0, and the optimality conditions
    (the gradient A'(b - Ax) is <= 0 where x = 0 and 0 where x > 0, to 1e-9 of its scale)."""
    from scipy.optimize import nnls

    rng = np.random.default_rng(11)
    for trial in range(200):
        m, n = int(rng.integers(2, 30)), int(rng.integers(1, 60))
        A = rng.standard_normal((m, n))
        b = A @ np.maximum(rng.standard_normal(n), 0.0) if trial % 2 else rng.standard_normal(m)
        x = nonnegative_least_squares(A, b)
        ref, rnorm = nnls(A, b, maxiter=50 * n)
        assert np.all(x >= 0.0)
        assert np.linalg.norm(A @ x - b) == pytest.approx(rnorm, rel=1e-10, abs=1e-10 * max(1.0, np.linalg.norm(b)))
        grad = A.T @ (b - A @ x)
        scale = 1e-9 * max(1.0, float(np.abs(A).sum() * np.abs(b).max()))
        assert np.all(grad[x == 0.0] <= scale) and np.all(np.abs(grad[x > 0.0]) <= scale), trial


def test_the_multipliers_of_every_row_can_prove_it() -> None:
    """A cone whose rows in use (positive multipliers) leave a part of g unbalanced, which the other rows' span
    holds: the given multipliers and their least-squares refit do not prove that nothing descends, nonnegative least
    squares over every row does, as the linear program agrees."""
    C = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, -1.0, -1.0]])
    eq = np.zeros(4, dtype=bool)
    g = -C.T @ np.array([2.0, 0.0, 0.0, 0.0]) - C.T @ np.array([0.0, 0.0, 0.0, 1e-6])  # row 4 holds a little
    given = np.array([2.0, 0.0, 0.0, 0.0])  # the part along row 4 is not in row 1's span
    floor = 1e-12 * max(1.0, float(np.max(np.abs(g))))
    assert recession_direction(g, C, eq) is None  # the linear program: the cone is {0}
    assert no_descent(g, C, eq, given, floor)


def _pole(f, start: float, target: float, lower: float, upper: float, feasible=lambda q: True):
    """pole_approach on the 1-D segment from start through target to the edge of [lower, upper]."""
    segment = pole_segment(np.array([start]), np.array([target]), np.array([lower]), np.array([upper]))

    def values(points):
        with np.errstate(all="ignore"):
            costs = np.array([float(f(q[0])) for q in points])
        return costs, np.array([bool(feasible(q[0])) for q in points])

    return pole_approach(values, [segment])


def test_poles_in_a_bounded_set_are_shown() -> None:
    ray = _pole(np.log, 0.5, 1e-7, 0.0, 1.0)  # log(x) on [0, 1]: -inf at the bound, no minimiser
    assert ray is not None and not ray.unbounded_below and ray.pole[0] == 0.0 and ray.direction[0] == -1.0
    assert np.allclose(-np.diff(ray.costs), np.log(10.0))  # ln 10 per decade of the distance, to the end
    assert ray.costs[-1] < -35 and ray.steps[-1] < 1e-15
    ray = _pole(lambda x: -np.tan(x), 1.0, 1.5, 0.0, 3.0)  # -tan(x) on [0, 3]: -inf below pi/2, +inf above
    assert ray is not None and ray.unbounded_below and abs(ray.pole[0] - np.pi / 2) < 1e-12
    ray = _pole(lambda x: -1.0 / (x - 0.25) ** 2, 1.0, 0.5, -1.0, 1.0)  # on a scanned point: -inf there
    assert ray is not None and ray.unbounded_below and abs(ray.pole[0] - 0.25) < 1e-12
    assert "decreases without bound approaching (x = 0.25)" in ray.describe(["x"])
    ray = _pole(lambda x: -1.0 / (x - 0.2501) ** 2, 1.0, 0.5, -1.0, 1.0)  # between two: both neighbours higher
    assert ray is not None and ray.unbounded_below and abs(ray.pole[0] - 0.2501) < 1e-12
    ray = _pole(lambda x: -np.exp(x), 0.0, 10.0, -1.0, 1000.0)  # overflows to -inf beyond x = 709.78: no minimum
    assert ray is not None and ray.unbounded_below and ray.costs[-1] < -1e308 and 709 < ray.pole[0] < 710


def test_finite_limits_jumps_and_edges_are_not_poles() -> None:
    assert _pole(lambda x: x * np.log(x), 0.5, 0.1, 0.0, 1.0) is None  # tends to 0 (NaN at 0 itself)
    assert _pole(np.sqrt, 0.5, 0.01, -1.0, 1.0) is None  # its domain ends at 0 with the value 0
    assert _pole(lambda x: np.floor(4 * x) - 2 * x, 0.9, 0.6, 0.0, 1.0) is None  # jumps, bounded
    assert _pole(lambda x: 1e6 * (x - 0.3) ** 2, 1.0, 0.3, -1.0, 1.0) is None  # a steep minimum
    assert _pole(lambda x: np.arctan2(x - 0.5, -1.0), 0.9, 0.6, 0.0, 1.0) is None  # atan2's cut: a jump of 2 pi
    assert _pole(lambda x: np.log(x), 0.5, 0.2, 0.0, 1.0, feasible=lambda x: x >= 0.1) is None  # a row before 0
    deep = _pole(lambda x: -1e9 * np.exp(-1e4 * (x - 0.3) ** 2), 1.0, 0.5, 0.0, 1.0)  # a well 1e9 deep, 0.01 wide
    assert deep is None
    assert _pole(lambda x: -1e7 + np.sqrt(x), 0.5, 0.1, -1.0, 1.0) is None  # deep, but attained at its domain's edge
    for p in (0.5, 0.1, 0.05, 0.02):  # cusps |x|^p: their fall fades by 10^-p per decade of the distance
        assert _pole(lambda x, p=p: np.abs(x - 0.3) ** p + np.sqrt(x - 0.3), 0.9, 0.6, 0.0, 1.0) is None
    assert pole_segment(np.array([0.5]), np.array([0.5]), np.array([0.0]), np.array([1.0])) is None


def test_a_point_within_rounding_of_a_pole_is_one() -> None:
    def values(f):
        def v(points):
            with np.errstate(all="ignore"):
                return np.array([float(f(q[0])) for q in points]), np.ones(len(points), dtype=bool)
        return v

    e = [np.array([1.0]), np.array([-1.0])]
    ray = approach_point(values(lambda x: np.log(abs(x - 0.3))), np.array([0.3 + 1e-17]), e, 2.0)
    assert ray is not None and ray.pole[0] == 0.3 + 1e-17 and np.all(np.diff(ray.costs) < 0)
    assert approach_point(values(lambda x: (x - 0.3) ** 2), np.array([0.3]), e, 2.0) is None  # a minimum
    assert approach_point(values(lambda x: np.sqrt(abs(x - 0.3))), np.array([0.3]), e, 2.0) is None  # a cusp
