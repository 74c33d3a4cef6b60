"""`python -m benchmarks montecarlo [COUNT]`: a Monte Carlo over initial states with one compiled game.

ALGAMES's random merges (benchmarks/problems/trajectory.py, its draws of seed 0): the game is compiled once, for
the first draw, and every draw's x0 is put in force by ``CompiledGame.adopt`` (what a sweep worker does with the
points it runs), then solved by `gnerun.solve` with the default method and its certificate, in one process (one
core). The draws' configs differ from the first in x0 and in the constant of each terminal cost (an offset, which
moves no equilibrium); each draw is solved under its own x0 with the first draw's constants. Printed: the compile,
solves per second, the solver's and the certificate's median times, iterations (median, p90), and how many ended
converged (certified).
"""

from __future__ import annotations

import json
import statistics
import time

import numpy as np

from gnerun import compile_game, load_config, solve

from .__main__ import RESULTS
from .problems import trajectory


def main(argv: list[str]) -> int:
    count = int(argv[0]) if argv else 100
    first = trajectory.merge_problems(1)[0]
    states = trajectory.merge_initial_states(count)
    base = load_config(text=first.config_yaml)
    t0 = time.perf_counter()
    game = compile_game(base)
    compile_s = time.perf_counter() - t0
    rows = []
    t0 = time.perf_counter()
    for k, x0 in enumerate(states):
        overrides = {"game.x0": [float(v) for v in x0], "run.reference": "none"}
        cfg = load_config(text=first.config_yaml, overrides=overrides)
        t = time.perf_counter()
        result = solve(cfg, game=game)
        rows.append({"draw": k, "status": result.status, "iterations": result.iterations, "solver_s": result.time_s,
                     "certificate_s": result.certificate_time_s, "wall_s": time.perf_counter() - t})
    wall = time.perf_counter() - t0
    its = [r["iterations"] for r in rows]
    converged = sum(r["status"] == "converged" for r in rows)
    summary = {
        "draws": count, "compiles": 1, "compile_s": compile_s, "solves_per_second_per_core": count / wall,
        "median_solver_ms": 1e3 * statistics.median(r["solver_s"] for r in rows),
        "median_certificate_ms": 1e3 * statistics.median(r["certificate_s"] for r in rows),
        "median_iterations": statistics.median(its), "p90_iterations": float(np.percentile(its, 90)),
        "converged_certified": converged,
    }
    print("| draws | compiles | compile | solves/s per core | solver (median) | certificate (median) | iterations "
          "median / p90 | converged, certified |")
    print("|---|---|---|---|---|---|---|---|")
    print(f"| {count} | 1 | {compile_s:.2f} s | {summary['solves_per_second_per_core']:.2f} | "
          f"{summary['median_solver_ms']:.1f} ms | {summary['median_certificate_ms']:.1f} ms | "
          f"{summary['median_iterations']:.0f} / {summary['p90_iterations']:.0f} | {converged} of {count} |")
    RESULTS.mkdir(exist_ok=True)
    out = RESULTS / f"montecarlo-{time.strftime('%Y%m%dT%H%M%SZ', time.gmtime())}.json"
    out.write_text(json.dumps({"summary": summary, "rows": rows}, indent=2) + "\n")
    print(f"written: {out}")
    return 0
