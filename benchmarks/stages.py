"""The sparse formulation's factorisations, banded LU on the stage order against SuperLU, on the matrices the solver
factorises (`python -m benchmarks stages`; its rows are part of `python -m benchmarks`).

Each case solves a game in the sparse formulation and records every matrix the Newton and interior steps factorise;
both factorisations then run on the same matrices in the same process: assembly from the nonzeros, the LU and the
reciprocal condition estimate (LAPACK dgbtrf + dgbcon on the stage-ordered band; SuperLU with the game's column
ordering + ``onenormest``), then the solution of one right-hand side by each (their relative difference). The
structure's limit: the flops of one banded LU, 2 n kl (kl + ku), at the GFLOP/s of a dense 39 x 39 LU measured in the
same run.
"""

from __future__ import annotations

import math
import os
import statistics
import sys
import time
from dataclasses import dataclass
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from scipy.linalg import lapack  # noqa: E402

from gnerun.game.compile import compile_game  # noqa: E402
from gnerun.game.sparse import KeptLayout, Ordering, SparseKKT  # noqa: E402
from gnerun.language.config import load_config  # noqa: E402
from gnerun.solvers import interior_point, reduced  # noqa: E402
from gnerun.solvers.driver import iterate  # noqa: E402
from gnerun.solvers.factory import make_solver  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


@dataclass
class Case:
    name: str
    config_yaml: str | None = None
    path: Path | None = None
    overrides: dict | None = None
    starts: list[np.ndarray] | None = None  # initial states to solve from (None: the config's)


def cases(quick: bool) -> list[Case]:
    from .problems import formation, lq, trajectory

    merges = trajectory.merge_problems(2 if quick else 5)
    crossings = trajectory.intersection_problems(1 if quick else 3)

    def starts(problems) -> list[np.ndarray]:
        return [np.asarray(load_config(text=p.config_yaml).game.x0) for p in problems]

    out = [Case("ALGAMES merge, 21 knots", merges[0].config_yaml, starts=starts(merges)),
           Case("ALGAMES merge, 41 knots", path=ROOT / "configs" / "algames_merge_mpc.yaml"),
           Case("ALGAMES intersection, 41 knots", crossings[0].config_yaml, starts=starts(crossings)),
           Case("formation ring, 6 robots", formation.formation_problems(1)[0].config_yaml)]
    out += [Case(f"bounded LQ, T = {T}", lq.lq_yaml(T, "generalized")) for T in ((40,) if quick else (40, 80))]
    return out


def record(case: Case, limit: int = 400) -> tuple[SparseKKT, list[tuple], int]:
    """Solve the case in the sparse formulation; the system and what it factorised (kind, nonzeros, keep, at, add,
    eliminate)."""
    cfg = load_config(case.path, case.overrides) if case.path else load_config(text=case.config_yaml)
    cfg = cfg.model_copy(update={"solver": cfg.solver.model_copy(update={"formulation": "sparse"})})
    game = compile_game(cfg)
    solver = make_solver(cfg, game)
    system: SparseKKT = solver.newton.system
    seen: list[tuple] = []
    factor = system.factor_kept

    def recording(kind, data, keep, at=None, add=None, estimate=True, eliminate=None):
        if len(seen) < limit:
            seen.append((kind, data.copy(), keep.copy(), None if at is None else at.copy(),
                         None if add is None else add.copy(), eliminate))
        return factor(kind, data, keep, at, add, estimate, eliminate)

    system.factor_kept = recording
    fused = interior_point.FUSED, reduced.FUSED
    interior_point.FUSED = reduced.FUSED = False  # every matrix through factor_kept (the compiled steps: the same)
    iterations = 0
    try:
        for x0 in case.starts or [None]:
            state = iterate(solver, solver.init(None, x0))
            iterations += state.k
    finally:
        interior_point.FUSED, reduced.FUSED = fused
    del system.factor_kept
    return system, seen, iterations


def _time(fn, repeats: int, *args, **kwargs) -> float:
    """Median time of ``fn(*args, **kwargs)`` over ``repeats`` calls after one warm-up."""
    fn(*args, **kwargs)
    samples = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn(*args, **kwargs)
        samples.append(time.perf_counter() - t0)
    return statistics.median(samples)


def dense_gflops(n: int = 39, repeats: int = 2000) -> float:
    """GFLOP/s of LAPACK's LU (dgetrf) of a dense n x n matrix (2/3 n^3 flops), median of ``repeats``."""
    A = np.random.default_rng(0).standard_normal((n, n)) + n * np.eye(n)
    return 2.0 / 3.0 * n**3 / _time(lapack.dgetrf, repeats, A) / 1e9


@dataclass
class Comparison:
    name: str
    size: int  # rows of the matrices factorised (the largest)
    lower: int
    upper: int
    banded_s: float  # median time of one factorisation, banded (assembly, LU, condition estimate)
    superlu_s: float  # the same by SuperLU
    lu_banded_s: float  # the LU alone (dgbtrf)
    lu_superlu_s: float  # the LU alone (splu)
    difference: float  # largest relative difference of the two solutions (matrices the solver would use)
    rcond_ratio: float  # largest ratio of the two condition estimates (max / min; the same matrices)
    matrices: int
    iterations: int
    singular: int = 0  # matrices of the sample whose condition estimate is below min_rcond (the solver refuses them)
    backward: float = 0.0  # largest backward error of either solution, ||M x - b|| / (||M|| ||x|| + ||b||), all

    @property
    def flops(self) -> float:
        return 2.0 * self.size * self.lower * (self.lower + self.upper)


def compare(case: Case, repeats: int = 5, sample: int = 12) -> Comparison:
    """Both factorisations of up to ``sample`` of the recorded matrices (evenly spaced), timed on the same ones. The
    two solutions are compared where the solver would use them (a condition estimate of at least the default
    ``solver.min_rcond``): on a numerically singular matrix any two backward-stable solutions may differ without
    bound, so there each one's backward error is what is checked."""
    from scipy.sparse import linalg as spla

    from gnerun.language.config import SolverConfig

    min_rcond = SolverConfig().min_rcond
    system, seen, iterations = record(case)
    order = system.stage_order
    picked = [seen[i] for i in np.unique(np.linspace(0, len(seen) - 1, min(sample, len(seen))).astype(int))]
    banded, superlu, lu_b, lu_s, diffs, rconds, sizes = [], [], [], [], [], [], []
    singular, backward = 0, 0.0
    rng = np.random.default_rng(0)
    for _, data, keep, at, add, eliminate in picked:  # the matrices as factorised (the interior's: eliminated)
        band = KeptLayout(order, keep, at, banded=True, eliminate=eliminate)
        csc = KeptLayout(order, keep, at, banded=False, eliminate=eliminate)
        ordering = Ordering()
        ordering.factor(csc.csc(data, add))  # its column ordering, chosen by fill (once per game in a solve)
        lu1, r1 = band.factor(data, add)
        lu2, r2 = ordering.factor(csc.csc(data, add))
        lu2 = csc.eliminated(lu2, data, add)
        if lu1 is None or lu2 is None:
            continue
        b = rng.standard_normal(keep.size)
        x1, x2 = lu1.solve(b), lu2.solve(b)
        M = KeptLayout(order, keep, at, banded=False).csc(data, add)  # the matrix itself (before any elimination)
        norm = float(abs(M).sum(axis=0).max())
        for x in (x1, x2):
            backward = max(backward, float(np.abs(M @ x - b).max() / (norm * np.abs(x).max() + np.abs(b).max())))
        if min(r1, r2) < min_rcond:
            singular += 1
        else:
            diffs.append(float(np.abs(x1 - x2).max() / max(np.abs(x2).max(), 1e-300)))
            rconds.append(max(r1, r2) / max(min(r1, r2), 1e-300))
        ab, M = band.band(data, add), csc.csc(data, add)
        banded.append(_time(band.factor, repeats, data, add))
        superlu.append(_time(lambda o, c, d, a: o.factor(c.csc(d, a)), repeats, ordering, csc, data, add))
        lu_b.append(_time(lapack.dgbtrf, repeats, ab, band.lower, band.upper))
        lu_s.append(_time(spla.splu, repeats, M, permc_spec=ordering.spec))
        sizes.append((band.size, band.lower, band.upper))
    size, lower, upper = max(sizes)
    return Comparison(case.name, size, lower, upper, statistics.median(banded), statistics.median(superlu),
                      statistics.median(lu_b), statistics.median(lu_s), max(diffs, default=math.nan),
                      max(rconds, default=math.nan), len(seen), iterations, singular, backward)


def main(argv: list[str] | None = None) -> int:
    quick = "--quick" in (argv or [])
    gflops = dense_gflops()
    print(f"dense 39 x 39 LU: {gflops:.2f} GFLOP/s")
    print("| case | n | kl, ku | banded | SuperLU | ratio | LU alone: banded, SuperLU | limit | difference | rcond | "
          "singular | backward error |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for case in cases(quick):
        c = compare(case)
        limit = c.flops / (gflops * 1e9)
        print(f"| {c.name} | {c.size} | {c.lower}, {c.upper} | {c.banded_s * 1e6:.0f} us | "
              f"{c.superlu_s * 1e6:.0f} us | {c.superlu_s / c.banded_s:.2f} | "
              f"{c.lu_banded_s * 1e6:.0f}, {c.lu_superlu_s * 1e6:.0f} us | {limit * 1e6:.0f} us | "
              f"{c.difference:.1e} | {c.rcond_ratio:.2f} | {c.singular} | {c.backward:.0e} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
