"""`python -m benchmarks montecarlo [COUNT [WORKERS]]`: a Monte Carlo over initial states, one compiled game per
worker.

ALGAMES's random merges (benchmarks/problems/trajectory.py, its draws of seed 0): each worker process compiles the
game once, for the first draw, and puts every draw's x0 it is given in force by ``CompiledGame.adopt`` (what a sweep
worker does with the points it runs), then solves it by `gnerun.solve` with the default method and its certificate
(WORKERS processes, default 1: one core each). The draws' configs differ from the first in x0 and in the constant of
each terminal cost (an offset, which moves no equilibrium); each draw is solved under its own x0 with the first
draw's constants. Printed: the compile, solves per second (and per core), the solver's times (median, p90, max) and
the certificate's median, iterations (median, p90), and how many ended converged (certified), and of those how many
within 50 ms of solver time.
"""

from __future__ import annotations

import json
import statistics
import time

import numpy as np

from gnerun import compile_game, load_config, solve

from .__main__ import RESULTS
from .problems import trajectory


def _draws(task: tuple[list[int], list[list[float]]]) -> tuple[float, list[dict]]:
    """One worker: the game compiled once, then the given draws (index, x0) solved in it; (compile time, rows)."""
    indices, states = task
    first = trajectory.merge_problems(1)[0]
    t0 = time.perf_counter()
    game = compile_game(load_config(text=first.config_yaml))
    compile_s = time.perf_counter() - t0
    rows = []
    for k, x0 in zip(indices, states, strict=True):
        cfg = load_config(text=first.config_yaml, overrides={"game.x0": x0, "run.reference": "none"})
        t = time.perf_counter()
        result = solve(cfg, game=game)
        rows.append({"draw": k, "status": result.status, "iterations": result.iterations, "solver_s": result.time_s,
                     "certificate_s": result.certificate_time_s, "wall_s": time.perf_counter() - t})
    return compile_s, rows


def main(argv: list[str]) -> int:
    count = int(argv[0]) if argv else 100
    workers = int(argv[1]) if len(argv) > 1 else 1
    states = [[float(v) for v in x0] for x0 in trajectory.merge_initial_states(count)]
    tasks = [(list(range(w, count, workers)), states[w::workers]) for w in range(workers)]
    t0 = time.perf_counter()
    if workers == 1:
        done = [_draws(tasks[0])]
    else:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn")) as pool:
            done = list(pool.map(_draws, tasks))
    wall = time.perf_counter() - t0
    compile_s = max(c for c, _ in done)
    rows = sorted((r for _, part in done for r in part), key=lambda r: r["draw"])
    its = [r["iterations"] for r in rows]
    converged = sum(r["status"] == "converged" for r in rows)
    summary = {
        "draws": count, "workers": workers, "compiles": workers, "compile_s": compile_s,
        "solves_per_second": count / wall, "solves_per_second_per_core": count / wall / workers,
        "median_solver_ms": 1e3 * statistics.median(r["solver_s"] for r in rows),
        "median_certificate_ms": 1e3 * statistics.median(r["certificate_s"] for r in rows),
        "median_iterations": statistics.median(its), "p90_iterations": float(np.percentile(its, 90)),
        "converged_certified": converged,
        "converged_within_50ms": sum(r["status"] == "converged" and r["solver_s"] <= 0.05 for r in rows),
        "p90_solver_ms": 1e3 * float(np.percentile([r["solver_s"] for r in rows], 90)),
        "max_solver_ms": 1e3 * max(r["solver_s"] for r in rows),
    }
    print("| draws | workers (compiles) | compile | solves/s (per core) | solver (median, p90, max) | certificate "
          "(median) | iterations median / p90 | converged, certified (within 50 ms of solver time) |")
    print("|---|---|---|---|---|---|---|---|")
    print(f"| {count} | {workers} | {compile_s:.2f} s | {summary['solves_per_second']:.2f} "
          f"({summary['solves_per_second_per_core']:.2f}) | "
          f"{summary['median_solver_ms']:.1f}, {summary['p90_solver_ms']:.1f}, {summary['max_solver_ms']:.0f} ms | "
          f"{summary['median_certificate_ms']:.1f} ms | "
          f"{summary['median_iterations']:.0f} / {summary['p90_iterations']:.0f} | {converged} of {count} "
          f"({summary['converged_within_50ms']}) |")
    RESULTS.mkdir(exist_ok=True)
    out = RESULTS / f"montecarlo-{time.strftime('%Y%m%dT%H%M%SZ', time.gmtime())}.json"
    out.write_text(json.dumps({"summary": summary, "rows": rows}, indent=2) + "\n")
    print(f"written: {out}")
    return 0
