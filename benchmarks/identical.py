"""`python -m benchmarks identical record OUT.npz` / `compare OUT.npz`: every solve of a small grid, iterate by iterate.

A refactoring of the solvers must leave every iterate and every status as it was. ``record`` solves each case of the
grid (below) and writes, per case, the final status and message, the iteration count, ||z_k|| and ||Phi(z_k)|| of
every iterate and the final z; ``compare`` solves the grid again and requires an exact match (bit for bit), printing
each difference with its size. Record with the code before the change, compare with the code after it.

The grid (:func:`cases`): the FK library's pairs and the bounded LQ family under every solver kind x
globalization x formulation x complementarity that applies; the paper's configs (solve only, their own solver and
the grid's); 10 ALGAMES merges and 10 T-intersections under the robustness suite's methods (and the sparse
formulation for the default), and ``certified_solve`` (the certificate's restarts) on the merges and intersections
with the default method.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from gnerun.game.compile import compile_game  # noqa: E402
from gnerun.language.config import load_config  # noqa: E402
from gnerun.runs.solving import certified_solve, iterate, make_solver  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent

GLOBALIZATIONS = ("auto", "hybrid", "interior_point", "line_search", "none")
COMPLEMENTARITY = ("min", "fischer_burmeister")
DISTURBANCES = {
    "jacobian_noise": {"disturbance.kind": "jacobian_noise", "disturbance.scale": 1e-3, "disturbance.seed": 3},
    "residual": {"disturbance.kind": "residual", "disturbance.scale": 1e-3, "disturbance.seed": 3},
}
ROBUSTNESS = {  # benchmarks/robustness.py's methods
    "default": {},
    "local": {"solver.globalization": "none"},
    "FB + line search": {"solver.globalization": "line_search", "solver.complementarity": "fischer_burmeister"},
    "interior point": {"solver.globalization": "interior_point"},
}


@dataclass
class Case:
    family: str
    name: str
    label: str  # the solver options, as text
    config_yaml: str
    overrides: dict
    certified: bool = False

    @property
    def key(self) -> str:
        return f"{self.family} | {self.name} | {self.label}"


def _label(overrides: dict) -> str:
    return ", ".join(f"{k.split('.', 1)[1]}={v}" for k, v in overrides.items()) or "config"


def solver_grid(dynamic: bool) -> Iterator[dict]:
    """Every solver kind x globalization x formulation x complementarity that applies (validation refuses the
    rest; a refusal is recorded as such)."""
    formulations = ("condensed", "sparse") if dynamic else ("condensed",)
    for form in formulations:
        for compl in COMPLEMENTARITY:
            if form == "sparse" and compl != "min":
                continue
            for glob in GLOBALIZATIONS:
                yield {"solver.kind": "ssn", "solver.globalization": glob, "solver.complementarity": compl,
                       "solver.formulation": form}
    for glob in ("auto", "none"):
        yield {"solver.kind": "jn", "solver.globalization": glob}
    for glob in ("auto", "none"):
        yield {"solver.kind": "distributed", "solver.globalization": glob}
    for d in DISTURBANCES.values():  # the full (unreduced) system's perturbed steps
        for glob in ("none", "hybrid"):
            yield {"solver.kind": "ssn", "solver.globalization": glob, **d}


def cases(merges: int = 10) -> list[Case]:
    from .problems import fk, lq, trajectory

    out: list[Case] = []
    for fam in (fk.problems(), lq.lq_problems()):
        for p in fam:
            dynamic = p.family == "lq"
            for o in solver_grid(dynamic):
                out.append(Case(p.family, f"{p.name} {p.start}", _label(o), p.config_yaml, o))
    for name in ("paper_study1", "paper_study2", "paper_study3", "paper_study1_disturbed"):
        text = (ROOT / "configs" / f"{name}.yaml").read_text()
        out.append(Case("paper", name, "config", text, {}))
        if name == "paper_study1":
            for o in solver_grid(True):
                out.append(Case("paper", name, _label(o), text, o))
    for p in trajectory.merge_problems(merges, seed=0) + trajectory.intersection_problems(merges, seed=0):
        for method, o in ROBUSTNESS.items():
            out.append(Case(p.family, p.name, method, p.config_yaml, dict(o)))
        o = {"solver.formulation": "sparse"}
        out.append(Case(p.family, p.name, _label(o), p.config_yaml, o))
        out.append(Case(p.family, p.name, "default, certified", p.config_yaml, {}, certified=True))
    return out


def solve(case: Case, games: dict) -> dict:
    """One case: status, message, iterations, ||z_k||, ||Phi(z_k)|| and the final z (or the refusal)."""
    try:
        cfg = load_config(text=case.config_yaml, overrides=case.overrides or None)
    except Exception as e:  # noqa: BLE001 - a refused combination is recorded as refused
        return {"status": f"refused: {type(e).__name__}", "message": str(e).splitlines()[0][:200], "k": -1,
                "z_norms": np.zeros(0), "residuals": np.zeros(0), "z": np.zeros(0)}
    data = cfg.model_dump(mode="json")
    key = json.dumps(data["game"], sort_keys=True)
    if key not in games:
        if len(games) > 4:
            games.clear()
        games[key] = compile_game(cfg)
    game = games[key]
    z_norms: list[float] = []
    residuals: list[float] = []

    def record(state) -> None:
        z_norms.append(math.sqrt(float(state.z @ state.z)))
        residuals.append(state.residual_norm)

    try:
        solver = make_solver(cfg, game)
        if case.certified:
            outcome = certified_solve(game, solver, solver.init(), on_iterate=record)
            state, status, message = outcome.state, str(outcome.status), outcome.message
        else:
            state = iterate(solver, solver.init(), on_iterate=record)
            status, message = str(state.status), state.message
    except Exception as e:  # noqa: BLE001 - an exception is an outcome to compare too
        return {"status": f"error: {type(e).__name__}", "message": str(e).splitlines()[0][:200] if str(e) else "",
                "k": -1, "z_norms": np.array(z_norms), "residuals": np.array(residuals), "z": np.zeros(0)}
    return {"status": status, "message": message, "k": state.k, "z_norms": np.array(z_norms),
            "residuals": np.array(residuals), "z": np.array(state.z, dtype=float)}


def run_all(selected: list[Case], verbose: bool = True) -> dict[str, dict]:
    games: dict = {}
    results = {}
    t0 = time.perf_counter()
    for i, case in enumerate(selected):
        t = time.perf_counter()
        results[case.key] = solve(case, games)
        if verbose:
            r = results[case.key]
            print(f"[{i + 1}/{len(selected)} {time.perf_counter() - t0:6.1f}s] {case.key}: {r['status']} "
                  f"k={r['k']} ({time.perf_counter() - t:.2f}s)", flush=True)
    return results


def save(path: str, results: dict[str, dict]) -> None:
    arrays: dict[str, np.ndarray] = {}
    manifest = []
    for i, (key, r) in enumerate(results.items()):
        manifest.append({"key": key, "status": r["status"], "message": r["message"], "k": r["k"]})
        for field in ("z_norms", "residuals", "z"):
            arrays[f"{i}.{field}"] = r[field]
    np.savez_compressed(path, manifest=np.array(json.dumps(manifest)), **arrays)


def load(path: str) -> dict[str, dict]:
    with np.load(path) as f:
        manifest = json.loads(str(f["manifest"]))
        out = {}
        for i, m in enumerate(manifest):
            out[m["key"]] = {**m, **{field: f[f"{i}.{field}"] for field in ("z_norms", "residuals", "z")}}
    return out


def differences(old: dict[str, dict], new: dict[str, dict]) -> list[str]:
    """Every difference between two recordings, with its size."""
    out = []
    for key in old.keys() | new.keys():
        if key not in new or key not in old:
            out.append(f"{key}: only in the {'recording' if key in old else 'new run'}")
            continue
        a, b = old[key], new[key]
        for field in ("status", "k", "message"):
            if a[field] != b[field]:
                out.append(f"{key}: {field} {a[field]!r} -> {b[field]!r}")
        for field in ("z_norms", "residuals", "z"):
            x, y = np.asarray(a[field]), np.asarray(b[field])
            if x.shape != y.shape:
                out.append(f"{key}: {field} has {x.shape} entries, now {y.shape}")
            elif not np.array_equal(x, y, equal_nan=True):
                with np.errstate(invalid="ignore"):
                    size = float(np.nanmax(np.abs(x - y)))
                out.append(f"{key}: {field} differs by up to {size:.3e} (at {int(np.sum(x != y))} entries)")
    return sorted(out)


def main(argv: list[str]) -> int:
    import argparse

    parser = argparse.ArgumentParser(prog="python -m benchmarks identical", description=__doc__.splitlines()[0])
    parser.add_argument("command", choices=("record", "compare"))
    parser.add_argument("path")
    parser.add_argument("--merges", type=int, default=10, help="merges and intersections each (default 10)")
    parser.add_argument("--only", default="", help="cases whose key contains this text")
    parser.add_argument("--quiet", action="store_true")
    args = parser.parse_args(argv)
    selected = [c for c in cases(args.merges) if args.only in c.key]
    results = run_all(selected, verbose=not args.quiet)
    if args.command == "record":
        save(args.path, results)
        print(f"recorded {len(results)} solves to {args.path}")
        return 0
    old = load(args.path)
    if args.only:
        old = {k: v for k, v in old.items() if args.only in k}
    diff = differences(old, results)
    for line in diff:
        print(line)
    print(f"{len(results)} solves compared: {'identical' if not diff else f'{len(diff)} difference(s)'}")
    return 0 if not diff else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
