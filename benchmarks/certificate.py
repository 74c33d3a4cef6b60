"""`python -m benchmarks certificate`: what "certified" costs next to the solve it certifies.

For each scenario, the solve (the default method, from its start, warm functions: every game compiled and solved
once before timing) and the certificate of its answer (gnerun.solvers.certificate with Newton best responses, its
agents' problems built before timing) are timed in turn in the same process, and the ratio certificate / solve is
printed: the price of ``converged`` meaning certified. The first certificate of a game, with its builds, is reported
apart. Scenarios: the paper's Study 1, Harker's game, a nonconvex two-player game (box searches), ALGAMES's merge and
T-intersection from random states.
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import numpy as np

from gnerun import compile_game, load_config, make_solver
from gnerun.runs.solving import iterate
from gnerun.solvers.certificate import NewtonResponses, certificate

from .problems import nonconvex, trajectory

CONFIGS = Path(__file__).resolve().parent.parent / "configs"


def _scenarios(count: int) -> list[tuple[str, list[str]]]:
    out = [("paper Study 1", [(CONFIGS / "paper_study1.yaml").read_text()]),
           ("Harker", [(CONFIGS / "harker.yaml").read_text()]),
           ("nonconvex (nc-gauss-2d)", [p.config_yaml for p in nonconvex.problems() if p.name == "nc-gauss-2d"])]
    out.append(("ALGAMES merge", [p.config_yaml for p in trajectory.merge_problems(count)]))
    out.append(("ALGAMES T-intersection", [p.config_yaml for p in trajectory.intersection_problems(count)]))
    return out


def main(argv: list[str]) -> int:
    count = int(argv[0]) if argv else 5
    print("| scenario | solve (median) | certificate (median) | certificate / solve | first certificate, with builds |")
    print("|---|---|---|---|---|")
    for name, texts in _scenarios(count):
        cfg = load_config(text=texts[0])
        game = compile_game(cfg)
        solver = make_solver(cfg, game)
        responses = NewtonResponses(cfg, game)
        solves, certs, first = [], [], None
        for k, text in enumerate(texts * (3 if len(texts) == 1 else 1)):
            c = load_config(text=text)
            x0 = None if c.game.kind == "static" else np.asarray(c.game.x0, dtype=float)
            t = time.perf_counter()
            state = iterate(solver, solver.init(None, x0))
            solves.append(time.perf_counter() - t)
            t = time.perf_counter()
            certificate(game, state.z, x0, None, responses)
            if k:
                certs.append(time.perf_counter() - t)
            else:
                first = time.perf_counter() - t
        s, c = statistics.median(solves), statistics.median(certs)
        print(f"| {name} | {s * 1e3:.1f} ms | {c * 1e3:.1f} ms | {c / s:.1f} | {first:.2f} s |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
