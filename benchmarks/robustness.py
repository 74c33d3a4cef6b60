"""`python -m benchmarks robustness`: does the solver solve the field's problems from their ordinary starts?

The suite (``benchmarks/problems``): the Facchinei-Kanzow GNEP library A.1-A.18 at the literature's starting
points, the bounded LQ dynamic game at T = 5, 20, 40 (variational and generalized), ALGAMES's ramp merge and
T-intersection from random initial states (cold start from zero inputs), the MCPTrajectoryGameSolver demo, and a
two-car overtaking game in ALGAMES's style from zero inputs and three other starts.
Every problem is solved with each method asked for, with default settings otherwise (the configs carry no
``solver:`` block, and the iteration limit is the default one). A result counts as **certified** when the solver
says converged, every agent's best-response gap is at most ``GAP_TOL`` by the problem's own check (written
without gnerun: numpy costs, scipy or DAQP best responses), and, where the literature's solution is isolated and
known, the solution is within the problem's tolerance of it. Time is the solver's alone (``init`` and the
steps), without compilation and without the certificate; games that differ only in their initial state (the
random merges) are compiled once and solved from each state, as a user of the Python API would.

Prints markdown tables (the README's robustness section) and writes JSON to benchmarks/results/.
"""

from __future__ import annotations

import json
import math
import statistics
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from gnerun import __version__, compile_game, load_config, make_solver
from gnerun.runs.solving import certified_solve
from gnerun.solvers.certificate import NewtonResponses

from .problems import Problem

RESULTS = Path(__file__).resolve().parent / "results"
GAP_TOL = 1e-6  # a best-response gap above this, relative to max(1, |J_i|), is not an equilibrium
REAL_TIME = 0.3  # seconds: ALGAMES's bound for a merge
SINGLES = ("fk", "lq", "mcp-demo", "overtaking")  # families reported problem by problem (the others as a distribution)

METHODS = {
    "default": {},
    "local": {"solver.globalization": "none"},
    "FB + line search": {"solver.globalization": "line_search", "solver.complementarity": "fischer_burmeister"},
    "interior point": {"solver.globalization": "interior_point"},
}


@dataclass
class Outcome:
    family: str
    name: str
    start: str
    method: str
    status: str
    iterations: int
    time_s: float
    residual: float
    certified: bool
    max_gap: float | None
    reference_error: float | None
    size: tuple[int, int]
    restarts: int  # restarts from best responses at KKT points that were not equilibria
    note: str = ""


def problems(which: set[str], count: int, seed: int) -> list[Problem]:
    from .problems import fk, lq, trajectory

    out: list[Problem] = []
    if "fk" in which:
        out += fk.problems()
    if "lq" in which:
        out += lq.lq_problems()
    if "merge" in which:
        out += trajectory.merge_problems(count, seed=seed)
    if "intersection" in which:
        out += trajectory.intersection_problems(count, seed=seed)
    if "mcp-demo" in which:
        out.append(trajectory.mcp_demo_problem())
    if "overtaking" in which:
        out += trajectory.overtaking_problems()
    return out


class _Compiled:
    """Compiled games and solvers by config, the initial state left out: the random merges share one game."""

    def __init__(self) -> None:
        self._cache: dict[str, tuple] = {}

    def get(self, cfg):
        data = cfg.model_dump(mode="json")
        data.pop("name", None)
        x0 = data["game"].pop("x0", None)
        key = json.dumps(data, sort_keys=True)
        if key not in self._cache:
            if len(self._cache) > 8:
                self._cache.clear()
            game = compile_game(cfg)
            solver = make_solver(cfg, game)
            solver.init()  # first-use costs (derivatives built on first use) are compilation, not solving
            self._cache[key] = (game, solver, NewtonResponses(cfg, game))
        game, solver, responses = self._cache[key]
        return game, solver, responses, None if x0 is None else np.asarray(x0, dtype=float)


def run(problem: Problem, method: str, compiled: _Compiled, certify: bool = True) -> Outcome:
    """Solve ``problem`` as ``gnerun solve`` does (:func:`~gnerun.runs.solving.certified_solve`: a KKT point at
    which a player can improve alone is left from that player's best response), then check it independently."""
    cfg = load_config(text=problem.config_yaml, overrides=METHODS[method] or None)
    game, solver, responses, x0 = compiled.get(cfg)
    outcome = certified_solve(game, solver, solver.init(None, x0), x0, responses=responses)
    state, elapsed = outcome.state, outcome.time_s
    a = state.z[: game.n]
    max_gap = ref_err = None
    certified = False
    note = "" if state.status == "converged" else state.message
    if outcome.improving:
        note = f"a KKT point at which {', '.join(outcome.improving)} can improve alone"
    if state.status == "converged" and not outcome.improving and certify:
        certified = True
        if problem.best_response_gaps is not None:
            gaps = problem.best_response_gaps(a)
            scale = np.maximum(1.0, np.abs(game.costs(a, x0)))  # gaps relative to the size of each cost
            max_gap = max(gaps.values())
            if not all(g <= GAP_TOL * s for g, s in zip(gaps.values(), scale, strict=True)):
                certified = False
                note = f"best-response gap {max_gap:.1e}"
        if problem.reference is not None:
            ref_err = float(np.max(np.abs(a - problem.reference)))
            if not ref_err <= problem.reference_tol:
                certified = False
                note = f"{ref_err:.1e} from the literature's solution"
    return Outcome(problem.family, problem.name, problem.start, method, str(state.status), state.k, elapsed,
                   state.residual_norm, certified, max_gap, ref_err, (game.n, game.m), outcome.restarts, note)


# ------------------------------------------------------------------------------------------------
def _ms(s: float) -> str:
    return f"{s * 1e3:.1f} ms" if s < 1 else f"{s:.2f} s"


def _cell(o: Outcome) -> str:
    if o.certified:
        return f"✓ {o.iterations} it, {_ms(o.time_s)}"
    if o.status == "converged":
        return f"✗ converged, not certified ({o.note})"
    return f"✗ {o.status} ({o.iterations} it)"


def tables(outcomes: list[Outcome], published: dict[tuple[str, str, str], dict[str, str]],
           methods: list[str]) -> str:
    lines: list[str] = []
    by = {(o.family, o.name, o.start, o.method): o for o in outcomes}
    pairs = list(dict.fromkeys((o.family, o.name, o.start) for o in outcomes))
    singles = [p for p in pairs if p[0] in SINGLES]
    if singles:
        lines += ["| problem | start | n, m | " + " | ".join(methods) + " | published |",
                  "|---|---|---|" + "---|" * len(methods) + "---|"]
        for fam, name, start in singles:
            first = by[(fam, name, start, methods[0])]
            pub = "; ".join(f"{k}: {v}" for k, v in published.get((fam, name, start), {}).items())
            lines.append(f"| {name} | {start} | {first.size[0]}, {first.size[1]} | "
                         + " | ".join(_cell(by[(fam, name, start, m)]) for m in methods) + f" | {pub} |")
        lines.append("")
        for m in methods:
            rows = [by[(f, n, s, m)] for f, n, s in singles]
            fk_rows = [o for o in rows if o.family == "fk"]
            if fk_rows:
                lines.append(f"- {m}: FK library {sum(o.certified for o in fk_rows)} of {len(fk_rows)} "
                             "problem/start pairs certified")
        lines.append("")
    for fam in ("merge", "intersection"):
        group = [p for p in pairs if p[0] == fam]
        if not group:
            continue
        lines += [f"| {fam}: method | converged | certified | within {REAL_TIME} s | iterations (median, p90) | "
                  "time (median, p90, max) |", "|---|---|---|---|---|---|"]
        for m in methods:
            rows = [by[(*p, m)] for p in group]
            ok = [o for o in rows if o.certified]
            its = [o.iterations for o in ok]
            ts = [o.time_s for o in ok]
            fast = sum(o.time_s <= REAL_TIME for o in ok)
            lines.append(f"| {m} | {sum(o.status == 'converged' for o in rows)} / {len(rows)} | {len(ok)} | {fast} | "
                         + (f"{statistics.median(its):.0f}, {np.percentile(its, 90):.0f} | "
                            f"{_ms(statistics.median(ts))}, {_ms(float(np.percentile(ts, 90)))}, {_ms(max(ts))} |"
                            if ok else "- | - |"))
        pub = published.get((fam, "", ""), {})
        if pub:
            lines.append("")
            lines += [f"- published, {k}: {v}" for k, v in pub.items()]
        lines.append("")
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    import argparse

    parser = argparse.ArgumentParser(prog="python -m benchmarks robustness", description=__doc__.splitlines()[0])
    parser.add_argument("--families", default="fk,lq,merge,intersection,mcp-demo,overtaking",
                        help="comma-separated: fk, lq, merge, intersection, mcp-demo, overtaking")
    parser.add_argument("--methods", default="default,local,FB + line search",
                        help=f"comma-separated, of: {', '.join(METHODS)}")
    parser.add_argument("--count", type=int, default=100, help="random initial states per trajectory scenario")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--quick", action="store_true", help="10 random states per scenario")
    parser.add_argument("--no-json", action="store_true")
    args = parser.parse_args(argv)
    methods = [m.strip() for m in args.methods.split(",")]
    for m in methods:
        if m not in METHODS:
            parser.error(f"unknown method {m!r} (one of: {', '.join(METHODS)})")
    count = 10 if args.quick else args.count
    suite = problems({f.strip() for f in args.families.split(",")}, count, args.seed)
    compiled = _Compiled()
    outcomes: list[Outcome] = []
    published: dict[tuple[str, str, str], dict[str, str]] = {}
    for problem in suite:
        key = (problem.family, problem.name, problem.start) if problem.family in SINGLES else \
              (problem.family, "", "")
        if problem.published:
            published.setdefault(key, {}).update(problem.published)
        for m in methods:
            o = run(problem, m, compiled)
            outcomes.append(o)
            print(f"{o.family} {o.name} {o.start} [{m}]: {o.status} in {o.iterations} it, {_ms(o.time_s)}"
                  + ("" if o.certified else f" -- not certified: {o.note}"), file=sys.stderr, flush=True)
    text = tables(outcomes, published, methods)
    print(text)
    if not args.no_json:
        RESULTS.mkdir(parents=True, exist_ok=True)
        stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
        out = RESULTS / f"robustness-{stamp}.json"
        out.write_text(json.dumps({"gnerun": __version__, "count": count, "seed": args.seed, "methods": methods,
                                   "outcomes": [_jsonable(asdict(o)) for o in outcomes]}, indent=1))
        print(f"\nJSON: {out.relative_to(RESULTS.parent.parent)}")
    return 0


def _jsonable(d: dict) -> dict:
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in d.items()}
