"""`python -m benchmarks condensed`: the condensed KKT function compiled to C (gnerun.game.condensed) against CasADi's
interpreter, on every problem/start pair of the FK library, the paper's game and two condensed trajectory games.

Per case: the solve with ``solver.compile: compiled`` and with ``interpreted`` (the config's own solver otherwise),
every iterate compared (the largest relative difference of z over the iterates, iteration counts and statuses);
gcc's time for the library (in a fresh cache of this run: an FK problem's second start point is a cache hit); the
time of one KKT evaluation (L, c, dL/dz, dc/da) each way (best of 5 x 50), and of one iteration (the best of 5 solves
after a first one). Prints a markdown table and writes
JSON to benchmarks/results/condensed.json. ``--quick``: the paper's game and six FK pairs.
"""

from __future__ import annotations

import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from gnerun.game.compile import compile_game  # noqa: E402
from gnerun.language.config import load_config  # noqa: E402
from gnerun.solvers.factory import make_solver  # noqa: E402

from .problems import fk  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
QUICK_FK = ("A.1", "A.2", "A.7", "A.11", "A.12", "A.16")


def cases(quick: bool) -> list[tuple[str, object]]:
    """(label, config) of every case: the paper's game, the FK pairs, the overtaking game and two vehicles (both
    condensed)."""
    out = [("paper Study 1", load_config(ROOT / "configs" / "paper_study1.yaml"))]
    for p in fk.problems():
        if quick and p.name not in QUICK_FK:
            continue
        out.append((f"FK {p.name} {p.start}", load_config(text=p.config_yaml)))
    if not quick:
        for name in ("vehicles", "overtaking"):
            cfg = load_config(ROOT / "configs" / f"{name}.yaml")
            out.append((name, _with(cfg, formulation="condensed")))
    return out


def _with(cfg, **solver):
    return cfg.model_copy(update={"solver": cfg.solver.model_copy(update=solver)})


def iterates(cfg, game) -> tuple[list[np.ndarray], object, float]:
    """Every iterate of a solve from the config's start, its final state and the time per iteration."""
    solver = make_solver(cfg, game)
    x0 = np.asarray(cfg.game.x0) if cfg.game.kind == "dynamic" else None
    t0 = time.perf_counter()
    state = solver.init(None, x0)
    zs = [state.z.copy()]
    while not solver.terminate(state)[0]:
        state = solver.step(state)
        zs.append(state.z.copy())
    elapsed = time.perf_counter() - t0
    return zs, solver.finish(state), elapsed / max(state.k, 1)


def _evaluation_time(game, z: np.ndarray, repeats: int = 5, calls: int = 50) -> float:
    x = game._x(None)
    kkt = game._derivatives["kkt"]
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(calls):
            kkt(z[:game.n], z[game.n:], x)
        best = min(best, (time.perf_counter() - t0) / calls)
    return best


def compare(label: str, cfg) -> dict:
    runs = {}
    for mode in ("compiled", "interpreted"):
        c = _with(cfg, compile=mode)
        game = compile_game(c)
        zs, final, _ = iterates(c, game)  # the first solve builds what a game builds on first use
        per_iteration = min(iterates(c, game)[2] for _ in range(5))
        report = game.derived["condensed"]
        runs[mode] = (zs, final, per_iteration, _evaluation_time(game, zs[-1]), report)
    (zc, fc, ic, ec, rep), (zi, fi, ii, ei, _) = runs["compiled"], runs["interpreted"]
    same_count = len(zc) == len(zi)
    gaps = [float(np.max(np.abs(u - v)) / max(1.0, float(np.max(np.abs(v))))) if u.size else 0.0
            for u, v in zip(zc, zi, strict=False)]
    return {"case": label, "mode": rep.mode, "reason": rep.reason, "operations": rep.operations,
            "cache_hit": rep.cache_hit, "gcc_s": rep.compile_s,
            "iterations": [len(zc) - 1, len(zi) - 1], "statuses": [str(fc.status), str(fi.status)],
            "same_iterations_and_status": same_count and fc.status == fi.status and fc.k == fi.k,
            "max_relative_difference": max(gaps) if gaps else 0.0,
            "evaluation_s": [ec, ei], "evaluation_speedup": ei / ec, "iteration_s": [ic, ii],
            "iteration_speedup": ii / ic}


def main(argv: list[str]) -> int:
    quick = "--quick" in argv
    saved = os.environ.get("GNERUN_CACHE_DIR")
    rows = []
    with tempfile.TemporaryDirectory() as cache:
        os.environ["GNERUN_CACHE_DIR"] = cache  # a fresh cache: gcc's time is measured
        try:
            for label, cfg in cases(quick):
                rows.append(compare(label, cfg))
                r = rows[-1]
                print(f"{label}: {r['mode']} {r['operations']:,} ops, gcc {r['gcc_s']:.2f} s, "
                      f"evaluation x{r['evaluation_speedup']:.1f}, max diff {r['max_relative_difference']:.1e}",
                      file=sys.stderr)
        finally:
            if saved is None:
                del os.environ["GNERUN_CACHE_DIR"]
            else:
                os.environ["GNERUN_CACHE_DIR"] = saved
    out = ROOT / "benchmarks" / "results" / "condensed.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"quick": quick, "rows": rows}, indent=2))
    print("| case | operations | gcc -O1 | KKT evaluation compiled / interpreted | speed-up | iteration speed-up "
          "| iterations | same iterates (max rel. diff) |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        gcc = "cache hit" if r["cache_hit"] else (f"{r['gcc_s']:.2f} s" if r["mode"] == "compiled" else r["reason"])
        ec, ei = r["evaluation_s"]
        same = "yes" if r["same_iterations_and_status"] else "**no**"
        print(f"| {r['case']} | {r['operations']:,} | {gcc} | {ec * 1e6:.1f} / {ei * 1e6:.1f} us "
              f"| {r['evaluation_speedup']:.1f} | {r['iteration_speedup']:.2f} | {r['iterations'][0]} "
              f"| {same} ({r['max_relative_difference']:.1e}) |")
    compiled = [r for r in rows if r["mode"] == "compiled"]
    agree = sum(r["same_iterations_and_status"] and r["max_relative_difference"] <= 1e-12 for r in rows)
    print(f"\n{agree} of {len(rows)} cases: the same iterates to 1e-12, iteration counts and statuses; "
          f"gcc {sum(r['gcc_s'] for r in compiled):.1f} s in all, median evaluation speed-up "
          f"{statistics.median(r['evaluation_speedup'] for r in compiled):.1f}")
    print(f"JSON: {out.relative_to(ROOT)}")
    return 0 if agree == len(rows) else 1
