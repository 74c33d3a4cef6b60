"""The low-discrepancy design (gnerun/solvers/design.py) against scipy's scrambled Sobol design."""

from __future__ import annotations

import numpy as np
import pytest

from gnerun.solvers.certificate import DESIGN_LARGE, DESIGN_SMALL
from gnerun.solvers.design import kronecker


@pytest.mark.parametrize("d", [1, 2, 3, 4, 6, 22, 40])
def test_the_design_covers_the_box_as_a_scrambled_sobol_design_does(d: int) -> None:
    """The certificate's design (a randomly shifted Kronecker sequence, DESIGN_SMALL points for at most three
    decisions, DESIGN_LARGE above) against scipy's scrambled Sobol design of 64 or 16 points, by the centered L2
    discrepancy (scipy.stats.qmc.discrepancy), mean of 20 seeds: no higher, and (in few dimensions) a tenth of
    uniform random points' at most; every point in [0, 1)^d, reproducible from the seed."""
    qmc = pytest.importorskip("scipy.stats").qmc
    n, sobol_n = (DESIGN_SMALL, 64) if d <= 3 else (DESIGN_LARGE, 16)
    ours = [qmc.discrepancy(kronecker(d, n, np.random.default_rng(s))) for s in range(20)]
    sobol = [qmc.discrepancy(qmc.Sobol(d, scramble=True, seed=np.random.default_rng(s)).random(sobol_n))
             for s in range(20)]
    uniform = [qmc.discrepancy(np.random.default_rng(s).random((n, d))) for s in range(20)]
    print(f"d = {d}: ours {np.mean(ours):.4g}, Sobol {np.mean(sobol):.4g}, uniform {np.mean(uniform):.4g}")
    assert np.mean(ours) <= np.mean(sobol)
    if d <= 3:
        assert np.mean(ours) <= 0.1 * np.mean(uniform)
    u = kronecker(d, n, np.random.default_rng(3))
    assert u.shape == (n, d) and np.all((u >= 0.0) & (u < 1.0))
    assert np.array_equal(u, kronecker(d, n, np.random.default_rng(3)))
