"""`python -m benchmarks wall [REPEATS]`: what the certificate adds to the wall time of one `gnerun solve`.

What a user waits for: the whole `gnerun solve` process (Python's start, imports, load, compile, solve, certificate,
logging), timed from outside, with the default ``run.certificate: true`` and with ``run.certificate: false``, on
games whose players the certificate treats differently:

- the paper's Study 1 at T = 115 (an open-loop LQ game, 812 unknowns: convex players, one QP each);
- a Cournot oligopoly of 200 firms (linear demand, quadratic costs: 200 convex players of one decision);
- the 6-robot formation ring (configs/formation_ring.yaml with N = 6) from the first three random starts of
  benchmarks/problems/formation.py (nonconvex clearance rows: local solves from many starts per robot).

Each game is run once first (the compiled kernels' disk cache filled), then REPEATS times (default 3) with and without
the certificate, alternating. Printed: the median walls, their ratio (target <= 2), the certificate's own time and
the status of each. JSON: benchmarks/results/wall-<UTC time>.json.
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from .__main__ import RESULTS
from .problems import formation

CONFIGS = Path(__file__).resolve().parent.parent / "configs"
TARGET = 2.0


def cournot_yaml(N: int) -> str:
    """N firms: firm i chooses q_i in [0, 50], pays c_i q_i + d_i q_i^2 / 2 and sells at p = 100 - Q / 2."""
    c = [1.0 + 0.5 * (i % 7) for i in range(1, N + 1)]
    d = [0.5 + 0.3 * (i % 5) for i in range(1, N + 1)]
    return f"""name: cournot-{N}
game:
  kind: static
  parameters:
    N: {N}
    c: {c}
    d: {d}
  definitions:
    Q: "sum(q{{k}} for k in 1..N)"
  agents:
    - for: {{i: 1..N}}
      name: "firm{{i}}"
      variables: {{"q{{i}}": {{lower: 0, upper: 50, start: 1}}}}
      cost: "c[i]*q{{i}} + 0.5*d[i]*q{{i}}**2 - q{{i}}*(100 - 0.5*Q)"
"""


def _games(folder: Path) -> list[tuple[str, Path, list[str]]]:
    cournot = folder / "cournot-200.yaml"
    cournot.write_text(cournot_yaml(200))
    out = [("paper Study 1, T = 115 (812 unknowns)", CONFIGS / "paper_study1.yaml", ["--set", "game.horizon=115"]),
           ("Cournot, 200 firms", cournot, [])]
    for k, problem in enumerate(formation.formation_problems(3)):
        path = folder / f"formation-6-{k}.yaml"
        path.write_text(problem.config_yaml)
        out.append((f"formation ring, 6 robots, start {k}", path, []))
    return out


def _run(config: Path, extra: list[str], certificate: bool, out: Path) -> dict:
    exe = Path(sys.executable).parent / "gnerun"
    cli = [str(exe)] if exe.exists() else [sys.executable, "-m", "gnerun.cli"]
    cmd = [*cli, "solve", str(config), *extra, "--set", f"run.certificate={'true' if certificate else 'false'}",
           "--out", str(out), "--force", "-q"]
    t = time.perf_counter()
    done = subprocess.run(cmd, check=False, capture_output=True, text=True)
    wall = time.perf_counter() - t
    if not (out / "summary.json").exists():
        raise RuntimeError(f"{' '.join(cmd)} wrote no summary.json: {done.stderr[-2000:]}")
    summary = json.loads((out / "summary.json").read_text())
    return {"wall_s": wall, "status": summary["status"], "certificate_s": summary.get("certificate_time_s"),
            "solver_s": summary.get("time_s"), "iterations": summary.get("iterations")}


def main(argv: list[str]) -> int:
    repeats = int(argv[0]) if argv else 3
    rows = []
    print("| game | wall with the certificate (median) | without | ratio | certificate's own time | status (with; "
          "without) | target <= 2 |")
    print("|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for name, config, extra in _games(folder):
            _run(config, extra, True, folder / "run")  # the kernels' disk cache filled
            runs: dict[bool, list[dict]] = {True: [], False: []}
            for _ in range(repeats):
                for on in (True, False):
                    runs[on].append(_run(config, extra, on, folder / "run"))
            on, off = (statistics.median(r["wall_s"] for r in runs[b]) for b in (True, False))
            cert = statistics.median(r["certificate_s"] or 0.0 for r in runs[True])
            row = {"game": name, "with_s": on, "without_s": off, "ratio": on / off, "certificate_s": cert,
                   "status_with": runs[True][-1]["status"], "status_without": runs[False][-1]["status"],
                   "runs": {"with": runs[True], "without": runs[False]}}
            rows.append(row)
            print(f"| {name} | {on:.2f} s | {off:.2f} s | {on / off:.2f} | {cert:.2f} s | {row['status_with']}; "
                  f"{row['status_without']} | {'yes' if on / off <= TARGET else '**no**'} |", flush=True)
    out = RESULTS / f"wall-{time.strftime('%Y%m%dT%H%M%SZ', time.gmtime())}.json"
    out.write_text(json.dumps({"repeats": repeats, "rows": rows}, indent=2) + "\n")
    print(f"\nJSON: {out.relative_to(RESULTS.parent.parent)}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
