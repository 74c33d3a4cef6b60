"""`python -m benchmarks runtime`: what runtime parameters cost per iteration against the same game with constants.

Each scenario is compiled twice in the same process: with its runtime parameters (inputs of the compiled functions,
appended to the state) and with the same values written in as constants (compile-time parameters, the time t a
number). Both solve the same game from the same start with the same iterates (checked); the table gives the median
time of one solver step over those iterates, each measured over repeats, and the ratio runtime / constants.
Scenarios: the tracking game (configs/tracking.yaml: A and w runtime, t in the costs), the moving obstacle
(configs/moving_obstacle.yaml: the pedestrian's path from a data file, per-stage values) and a Cournot duopoly with
a runtime demand intercept.
"""

from __future__ import annotations

import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from gnerun import compile_game, load_config, make_solver
from gnerun.solvers.driver import iterate

from .__main__ import RESULTS, _median_time

CONFIGS = Path(__file__).resolve().parent.parent / "configs"


def _tracking() -> tuple[object, object]:
    runtime = load_config(CONFIGS / "tracking.yaml")
    data = runtime.model_dump(mode="json")
    game = data["game"]
    values = {name: spec["value"] for name, spec in game.pop("runtime").items()}
    game["parameters"].update(values)
    for agent in game["agents"]:  # t at sampling time 0: the stage's tau * dt
        agent["stage_cost"] = agent["stage_cost"].replace("(t + dt)", "(tau*dt + dt)")
        agent["terminal_cost"] = agent["terminal_cost"].replace("(t)", f"({game['horizon'] + 1}*dt)")
    return runtime, load_config(data)


OBSTACLE_T = 2.0  # the sampling time measured: the pedestrian on the road, the cars close to it
OBSTACLE_X0 = "[1.5, 0.0, 1.0, 0.0, 0.9, 0.5, 1.0, 0.0]"


def _obstacle() -> tuple[object, object]:
    runtime = load_config(CONFIGS / "moving_obstacle.yaml", [f"game.x0={OBSTACLE_X0}"])
    compiled = compile_game(runtime)
    compiled.set_parameters(t=OBSTACLE_T)
    values = compiled.parameters  # the table at the stages' times of t = 2 s
    data = runtime.model_dump(mode="json")
    game = data["game"]
    game.pop("runtime")
    T = game["horizon"]
    for agent in game["agents"]:
        rows = []
        for con in agent["constraints"]:
            text = con if isinstance(con, str) else con["expr"]
            if "ox[tau + 1]" not in text:
                rows.append(con)
                continue
            for tau in range(T + 1):  # one row per stage, with that stage's numbers
                rows.append({"expr": text.replace("ox[tau + 1]", repr(values["ox"][tau + 1]))
                                         .replace("oy[tau + 1]", repr(values["oy"][tau + 1])), "stages": [tau]})
        agent["constraints"] = rows
    return runtime, load_config(data)


def _cournot() -> tuple[object, object]:
    def config(runtime: bool) -> dict:
        where = "runtime" if runtime else "parameters"
        values = {"a": 10.0} if runtime else {"a": 10.0, "c": 1.0}
        return {"game": {"kind": "static", "parameters": {"c": 1.0}, where: values,
                         "agents": [{"name": f"f{i}", "variables": {f"q{i}": {"lower": 0, "start": 0}},
                                     "cost": f"-(a - q1 - q2 - q3 - c)*q{i} + 0.1*q{i}**2"} for i in (1, 2, 3)]}}
    return load_config(config(True)), load_config(config(False))


SCENARIOS = {"tracking (A, w, t)": _tracking, "moving obstacle (data file)": _obstacle,
             "Cournot (runtime intercept)": _cournot}


def _steps(cfg, repeats: int) -> tuple[list[np.ndarray], float]:
    game = compile_game(cfg)
    if game.runtime is not None and "ox" in game.runtime.entries:
        game.set_parameters(t=OBSTACLE_T)
    solver = make_solver(cfg, game)
    states: list = []
    iterate(solver, solver.init(), on_iterate=states.append)
    if len(states) < 2:  # solved at once (an LQ game's path method): the whole solve
        return [s.z for s in states], _median_time(lambda: iterate(solver, solver.init()), repeats)
    per_step = statistics.mean(_median_time(lambda s=s: solver.step(s), repeats) for s in states[:-1])
    return [s.z for s in states], per_step


def main(argv: list[str]) -> int:
    repeats = int(argv[0]) if argv else 7
    rows = []
    print("| scenario | iterations | step, constants | step, runtime | runtime / constants |")
    print("|---|---|---|---|---|")
    for name, build in SCENARIOS.items():
        runtime, constant = build()
        z_rt, t_rt = _steps(runtime, repeats)
        z_c, t_c = _steps(constant, repeats)
        same = len(z_rt) == len(z_c) and max(float(np.max(np.abs(a - b)))
                                             for a, b in zip(z_rt, z_c, strict=True)) < 1e-8
        if not same:
            print(f"{name}: the two compilations do not take the same iterates", file=sys.stderr)
            return 1
        rows.append({"scenario": name, "iterations": len(z_rt) - 1, "step_constants_s": t_c, "step_runtime_s": t_rt,
                     "ratio": t_rt / t_c})
        print(f"| {name} | {len(z_rt) - 1} | {t_c * 1e3:.3f} ms | {t_rt * 1e3:.3f} ms | {t_rt / t_c:.2f} |")
    RESULTS.mkdir(exist_ok=True)
    out = RESULTS / f"runtime-{time.strftime('%Y%m%dT%H%M%SZ', time.gmtime())}.json"
    out.write_text(json.dumps({"repeats": repeats, "rows": rows}, indent=2) + "\n")
    print(f"written: {out}")
    return 0
