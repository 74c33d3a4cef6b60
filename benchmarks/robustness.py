"""`python -m benchmarks robustness`: does the solver solve the field's problems from their ordinary starts?

The suite (``benchmarks/problems``): the Facchinei-Kanzow GNEP library A.1-A.18 at the literature's starting
points, the bounded LQ dynamic game at T = 5, 20, 40 (variational and generalized), ALGAMES's ramp merge and
T-intersection from random initial states (cold start from zero inputs), the MCPTrajectoryGameSolver demo, and a
two-car overtaking game in ALGAMES's style from zero inputs and three other starts, and the six-robot ring formation
of configs/formation_ring.yaml from 30 random initial positions (``benchmarks/problems/formation.py``).
Every problem is solved with each method asked for, with default settings otherwise (the configs carry no
``solver:`` block, and the iteration limit is the default one). A result counts as **certified** when the solver
says converged, every agent's best-response gap is at most ``GAP_TOL`` by the problem's own check (written
without gnerun: numpy costs, scipy or DAQP best responses), and, where the literature's solution is isolated and
known, the solution is within the problem's tolerance of it. Time is the solver's alone (``init`` and the
steps), without compilation and without the certificate; games that differ only in their initial state (the
random merges) are compiled once and solved from each state, as a user of the Python API would.

The nonconvex family (``benchmarks/problems/nonconvex.py``: nonconvex, nonsmooth, unbounded, infeasible, NaN games and
games with no pure equilibrium) is solved as a user solves a config, ``gnerun.solve(cfg, out=None)`` with
``run.reference: none`` and the certificate on, and each outcome is put in one of five classes (:func:`classify`):
**certified** (converged, and the problem's own check agrees: every gap at most ``GAP_TOL`` max(1, |J_i|) and the
reference matched where known), **false certificate** (converged, but the game has no equilibrium or the check finds a
player who improves alone: must be 0), **miss** (the game has an equilibrium and none was certified), **named refusal**
(no equilibrium, and the status says why: ``NAMED_REFUSALS``) and **unnamed refusal** (no equilibrium, and a generic
failure status, or a name that gives another reason). Its time is the whole ``solve`` (compile and certificate
included); the independent check's time is not counted.

Prints markdown tables (docs/robustness.md) and writes JSON to benchmarks/results/.
"""

from __future__ import annotations

import json
import math
import re
import statistics
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

import gnerun
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
    "default (condensed)": {"solver.formulation": "condensed"},  # the formulation auto took for most of them before
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
    # the nonconvex family
    kind: str = ""  # the problem's kind ("nonconvex", "unbounded", ...)
    outcome_class: str = ""  # one of CLASSES
    has_gne: bool = True
    gaps: dict[str, float] | None = None  # the problem's own check, per agent
    certificate_gaps: dict[str, float | None] | None = None  # gnerun's certificate, per agent
    certificate_kind: dict[str, str] | None = None  # what gnerun's certificate says each gap is ("global on the box")
    wall_s: float | None = None  # the whole solve: compile, iterations, certificate


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
    if "formation" in which:
        from .problems import formation

        out += formation.formation_problems(min(count, 30))
    if "nonconvex" in which:
        from .problems import nonconvex

        out += nonconvex.problems()
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
    status = outcome.status  # what gnerun solve would say: the certificate's conclusion
    note = "" if status == "converged" else outcome.message
    if outcome.improving:
        note = f"a KKT point at which {', '.join(outcome.improving)} can improve alone"
    if status == "converged" and certify:
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
    return Outcome(problem.family, problem.name, problem.start, method, str(status), state.k, elapsed,
                   state.residual_norm, certified, max_gap, ref_err, (game.n, game.m), outcome.restarts, note)


# ------------------------------------------------------------------------------------------------
# the nonconvex family: five classes of outcome

CLASSES = ("certified", "false certificate", "miss", "named refusal", "unnamed refusal")
# the statuses that say why a game without an equilibrium has none, by the game's kind; not_an_equilibrium (a KKT
# point at which a player improves alone) is true of every point of such a game, the others name the reason
NAMED_REFUSALS = {
    "unbounded": frozenset({"unbounded_player", "not_an_equilibrium"}),
    "infeasible": frozenset({"infeasible", "infeasible_stage_constraint"}),
    "nan": frozenset({"nan", "not_an_equilibrium"}),
    "no pure NE": frozenset({"not_an_equilibrium"}),
}
NAMED = frozenset().union(*NAMED_REFUSALS.values())


def classify(problem: Problem, status: str, gaps: dict[str, float] | None, costs: np.ndarray | None,
             reference_error: float | None) -> tuple[str, str]:
    """(class, why) of one outcome; ``gaps`` and ``costs`` are the problem's own check at gnerun's answer."""
    if status == "converged":
        if not problem.has_gne:
            return "false certificate", f"converged on a game with no equilibrium ({problem.kind})"
        if gaps is None or costs is None:
            return "false certificate", "converged at a point that is not finite"
        scale = np.maximum(1.0, np.abs(costs))
        bad = [name for (name, g), s in zip(gaps.items(), scale, strict=True) if not g <= GAP_TOL * s]
        if bad:
            return "false certificate", "; ".join(f"{name} improves alone by {gaps[name]:.3g}" for name in bad)
        if problem.reference is not None and not (reference_error is not None
                                                  and reference_error <= problem.reference_tol):
            return "false certificate", f"{reference_error:.1e} from the equilibrium"
        return "certified", ""
    if problem.has_gne:
        return "miss", f"{status} on a game with an equilibrium"
    if status in NAMED_REFUSALS.get(problem.kind, frozenset()):
        return "named refusal", ""
    if status in NAMED:
        return "unnamed refusal", f"{status}, but the game is {problem.kind}"
    return "unnamed refusal", status


def run_as_user(problem: Problem, method: str) -> Outcome:
    """Solve ``problem`` as ``gnerun solve`` does (the config's own run block: no reference solve, the certificate on;
    the method's overrides only), then classify the outcome by the problem's own check."""
    cfg = load_config(text=problem.config_yaml, overrides=METHODS[method] or None)
    t0 = time.perf_counter()
    try:
        res = gnerun.solve(cfg, out=None)
    except Exception as e:  # a crash is an outcome too
        wall = time.perf_counter() - t0
        status = f"error: {type(e).__name__}"
        cls, why = classify(problem, status, None, None, None)
        return Outcome(problem.family, problem.name, problem.start, method, status, 0, wall, math.nan, False, None,
                       None, (0, 0), 0, f"{why}: {e}"[:300], kind=problem.kind, outcome_class=cls,
                       has_gne=problem.has_gne, wall_s=wall)
    wall = time.perf_counter() - t0
    a = np.asarray(res.a, dtype=float)
    gaps = costs = ref_err = None
    if np.all(np.isfinite(a)):
        gaps = problem.best_response_gaps(a) if problem.best_response_gaps is not None else None
        costs = problem.costs(a) if problem.costs is not None else np.asarray(res.game.costs(a, res.x), dtype=float)
    if problem.reference is not None:
        ref_err = float(np.max(np.abs(a - problem.reference)))
    status = str(res.status)
    cls, why = classify(problem, status, gaps, costs, ref_err)
    values = list((gaps or {}).values())
    max_gap = (math.nan if any(math.isnan(g) for g in values) else max(values)) if values else None
    restarts = re.search(r"after (\d+) restart", res.message)
    cert = res.certificate or {}
    note = why if cls != "certified" else ""
    if status != "converged":
        note = f"{note}: {res.message}" if note and note != status else res.message
    return Outcome(problem.family, problem.name, problem.start, method, status, res.iterations, res.time_s,
                   res.residual_norm, cls == "certified", max_gap, ref_err, (res.game.n, res.game.m),
                   int(restarts.group(1)) if restarts else 0, note[:300], kind=problem.kind, outcome_class=cls,
                   has_gne=problem.has_gne, gaps=gaps, certificate_gaps=cert.get("best_response_gap"),
                   certificate_kind=cert.get("best_response_kind"), wall_s=wall)


def _gap(g: float | None) -> str:
    if g is None:
        return "-"
    if math.isnan(g):
        return "nan"
    if math.isinf(g):
        return "inf"
    return f"{g:.1e}"


def _kinds(o: Outcome) -> str:
    if not o.certificate_kind:
        return "-"
    return "; ".join(sorted(set(map(str, o.certificate_kind.values()))))


def nonconvex_tables(outcomes: list[Outcome], methods: list[str]) -> str:
    lines: list[str] = []
    for m in methods:
        rows = [o for o in outcomes if o.family == "nonconvex" and o.method == m]
        if not rows:
            continue
        lines += [f"Nonconvex family, method {m}:", "",
                  "| problem | kind | status | class | max gap (own check) | gnerun's certificate | time |",
                  "|---|---|---|---|---|---|---|"]
        for o in rows:
            cls = o.outcome_class if o.outcome_class in ("certified", "named refusal") else f"**{o.outcome_class}**"
            why = f" ({o.note})" if o.outcome_class not in ("certified", "named refusal") and o.note else ""
            lines.append(f"| {o.name} | {o.kind} | {o.status} | {cls}{why} | {_gap(o.max_gap)} | {_kinds(o)} | "
                         f"{_ms(o.wall_s or 0.0)} |")
        lines += ["", "| kind | problems | " + " | ".join(CLASSES) + " |", "|---|---|" + "---|" * len(CLASSES)]
        for kind in dict.fromkeys(o.kind for o in rows):
            group = [o for o in rows if o.kind == kind]
            lines.append(f"| {kind} | {len(group)} | "
                         + " | ".join(str(sum(o.outcome_class == c for o in group)) for c in CLASSES) + " |")
        counts = {c: sum(o.outcome_class == c for o in rows) for c in CLASSES}
        total = sum(o.wall_s or 0.0 for o in rows)
        lines += ["", f"- {m}: nonconvex family, {len(rows)} problems: {counts['certified']} certified, "
                      f"{counts['false certificate']} false certificates (must be 0), {counts['miss']} misses, "
                      f"{counts['named refusal']} named refusals, {counts['unnamed refusal']} unnamed refusals; "
                      f"{_ms(total)} in all", ""]
    return "\n".join(lines)


def nonconvex_summary(outcomes: list[Outcome], methods: list[str]) -> dict[str, dict[str, int]]:
    out = {}
    for m in methods:
        rows = [o for o in outcomes if o.family == "nonconvex" and o.method == m]
        if rows:
            out[m] = {c: sum(o.outcome_class == c for o in rows) for c in CLASSES} | {"problems": len(rows)}
    return out


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
    for fam in ("merge", "intersection", "formation"):
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
    parser.add_argument("--families", default="fk,lq,merge,intersection,mcp-demo,overtaking,formation,nonconvex",
                        help="comma-separated: fk, lq, merge, intersection, mcp-demo, overtaking, formation (at "
                             "most 30 starts), nonconvex")
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
            if problem.family == "nonconvex":
                o = run_as_user(problem, m)
                outcomes.append(o)
                print(f"{o.family} {o.name} [{m}]: {o.status} in {o.iterations} it, {_ms(o.wall_s or 0.0)}: "
                      f"{o.outcome_class}" + (f" ({o.note})" if o.note else ""), file=sys.stderr, flush=True)
                continue
            o = run(problem, m, compiled)
            outcomes.append(o)
            print(f"{o.family} {o.name} {o.start} [{m}]: {o.status} in {o.iterations} it, {_ms(o.time_s)}"
                  + ("" if o.certified else f" -- not certified: {o.note}"), file=sys.stderr, flush=True)
    text = tables([o for o in outcomes if o.family != "nonconvex"], published, methods)
    family = nonconvex_tables(outcomes, methods)
    text = f"{text}\n{family}" if text and family else text or family
    print(text)
    if not args.no_json:
        RESULTS.mkdir(parents=True, exist_ok=True)
        stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
        out = RESULTS / f"robustness-{stamp}.json"
        out.write_text(json.dumps({"gnerun": __version__, "count": count, "seed": args.seed, "methods": methods,
                                   "nonconvex": nonconvex_summary(outcomes, methods),
                                   "outcomes": [_jsonable(asdict(o)) for o in outcomes]}, indent=1))
        print(f"\nJSON: {out.relative_to(RESULTS.parent.parent)}")
    return 0


def _jsonable(d):
    """JSON without NaN and infinities: a non-finite number becomes its name ("nan", "inf") inside the nonconvex
    family's gap dictionaries, None elsewhere (as before)."""
    if isinstance(d, dict):
        return {k: (_finite_or_name(v) if isinstance(v, dict) else _jsonable(v)) for k, v in d.items()}
    if isinstance(d, float) and not math.isfinite(d):
        return None
    return d


def _finite_or_name(d: dict) -> dict:
    return {k: (str(v) if isinstance(v, float) and not math.isfinite(v) else v) for k, v in d.items()}
