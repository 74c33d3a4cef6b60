"""Low-discrepancy designs: points spread evenly over a box, for the certificate's starts, phase 1's screening and a
start inside the costs' domain."""

from __future__ import annotations

import numpy as np


def kronecker(d: int, count: int, rng: np.random.Generator) -> np.ndarray:
    """``count`` points of a low-discrepancy design in [0, 1)^d: the Kronecker sequence frac(u + k alpha),
    k = 1..count, with alpha_j = phi_d^-j (phi_d the positive root of x^(d+1) = x + 1, the golden ratio for d = 1:
    Roberts' R_d sequence) and a uniform random shift u drawn from ``rng`` (randomised quasi-Monte Carlo).

    Measured against scipy's scrambled Sobol design by the centered discrepancy (tests/test_certificate.py): at the
    same size it is 1.0-1.9 times Sobol's in 4-40 dimensions and 1.4-5.7 times in 1-3, so the certificate's design is
    larger (its ``DESIGN_SMALL``, ``DESIGN_LARGE``): 256 of its points in 1-3 dimensions lie below 64 Sobol points'
    discrepancy, 32 below 16 Sobol points' in 4-40 (the sizes a Sobol design had here). Without scipy.stats, whose
    import (0.3-0.5 s) a certified solve otherwise paid for its design alone."""
    phi = 2.0
    for _ in range(64):  # the fixed point of x = (1 + x)^(1/(d+1)): contracting, to rounding in a few dozen steps
        phi = (1.0 + phi) ** (1.0 / (d + 1))
    alpha = phi ** -np.arange(1, d + 1, dtype=float)
    u = rng.random(d)
    return np.mod(u + np.arange(1, count + 1, dtype=float)[:, None] * alpha, 1.0)
