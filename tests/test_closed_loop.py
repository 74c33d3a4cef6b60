"""Time-distributed CG-MPC (`gnerun simulate`): tracking error, the bounded-error theorem, disturbances, log."""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import linprog

from gnerun.errors import InputError
from gnerun.game.compile import compile_game
from gnerun.language.config import load_config
from gnerun.log.mcap_log import read_messages
from gnerun.runs.closed_loop import simulate
from gnerun.runs.solving import solve

from .conftest import CONFIGS, gnerun_command, run_cli

STUDY2 = CONFIGS / "paper_study2.yaml"


@pytest.fixture(scope="module")
def study2_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("runs") / "study2"
    sim = simulate(load_config(STUDY2), out=out)
    return out, sim


def _exact_closed_loop(steps: int) -> tuple[np.ndarray, np.ndarray]:
    """The exact CG-MPC loop, independently: a cold solve from scratch at every x(t), first inputs applied."""
    A = np.diag([0.5, 0.3, 0.2])
    x = np.array([1.0, 3.0, 5.0])
    xs, us = [x], []
    for _ in range(steps):
        res = solve(load_config(STUDY2, {"game.x0": x.tolist(), "solver.globalization": "hybrid"}))
        assert res.status == "converged"
        u = np.array([res.solution[f"agent{i}"][f"u{i}"][0] for i in (1, 2, 3)])
        x = A @ x + u
        xs.append(x)
        us.append(u)
    return np.array(xs), np.array(us)


def test_large_K_tracks_the_exact_solution_and_trajectory() -> None:
    steps = 12
    sim = simulate(load_config(STUDY2, {"run.K": [20], "run.steps": steps}))
    r = sim[20]
    assert np.all(r.e_norm <= 1e-10), r.e_norm
    x_exact, u_exact = _exact_closed_loop(steps)
    np.testing.assert_allclose(r.x, x_exact, atol=1e-10)
    np.testing.assert_allclose(r.u, u_exact, atol=1e-10)
    assert all(s == "converged" for s in r.status)


def test_K1_starts_with_an_error_that_vanishes_as_the_state_settles(study2_run) -> None:
    _, sim = study2_run
    r = sim[1]
    assert r.e_norm[0] > 1.0  # one Newton step from z = 0 is far from z*(0)
    assert np.all(r.e_norm[-10:] <= 1e-10)  # the paper's observation: e(t) -> 0 regardless of K
    assert np.all(r.iterations <= 1)
    # the states converge to constants (x1 geometrically, with factor 0.5)
    dx = np.linalg.norm(np.diff(r.x, axis=0), axis=1)
    assert dx[-1] <= 1e-7 and np.all(np.diff(dx[-10:]) < 0)


def test_error_shrinks_with_K(study2_run) -> None:
    _, sim = study2_run
    max_e = [float(np.max(sim[K].e_norm)) for K in (1, 2, 3, 5, 7)]
    assert max_e == sorted(max_e, reverse=True)
    assert max_e[0] > 1.0 and max_e[-1] <= 1e-10  # K = 7 keeps e(t) at zero, as in the paper


def _logged(out: Path) -> dict[int, dict[str, list]]:
    by_k: dict[int, dict[str, list]] = defaultdict(lambda: defaultdict(list))
    for topic, msg, _ in read_messages(out / "run.mcap"):
        if topic.startswith("/K"):
            K = int(topic.split("/")[1][1:])
            by_k[K][topic.split("/", 2)[2]].append(msg)
    return by_k


def _fit_bound(e: np.ndarray, dx: np.ndarray, floor: float = 1e-12) -> tuple[float, float]:
    """Smallest alpha + theta with e(t+1) <= alpha e(t) + theta ||dx(t)|| + floor for all t (an LP)."""
    A_ub = -np.column_stack([e[:-1], dx[: len(e) - 1]])
    b_ub = floor - e[1:]
    res = linprog(c=[1.0, 1.0], A_ub=A_ub, b_ub=b_ub, bounds=[(0, None), (0, None)], method="highs")
    assert res.status == 0
    return float(res.x[0]), float(res.x[1])


def test_bounded_error_theorem_holds_on_the_logged_data(study2_run) -> None:
    out, sim = study2_run
    logged = _logged(out)
    alphas = {}
    for K in sim:
        errors = logged[K]["mpc/error"]
        states = logged[K]["mpc/state"]
        e = np.array([m["e_norm"] for m in errors])
        x = np.array([m["x"] for m in states])
        dx = np.linalg.norm(np.diff(x, axis=0), axis=1)
        alpha, theta = _fit_bound(e, dx)
        # the LP's solution holds to its own tolerance (relative 1e-9), not to the last bit
        assert np.all(e[1:] <= (alpha * e[:-1] + theta * dx[: len(e) - 1]) * (1 + 1e-9) + 1e-12 * (1 + 1e-9))
        assert alpha < 1.0  # a contraction: the error is bounded
        alphas[K] = alpha
    ks = sorted(alphas)
    assert [alphas[k] for k in ks] == sorted(alphas.values(), reverse=True), alphas
    assert alphas[ks[0]] > alphas[ks[-1]]


def test_per_K_topics_equal_the_summary(study2_run) -> None:
    out, sim = study2_run
    summary = json.loads((out / "summary.json").read_text())
    assert summary["K"] == [1, 2, 3, 5, 7]
    logged = _logged(out)
    assert sorted(logged) == [1, 2, 3, 5, 7]
    for K, r in sim.items():
        s = summary["by_K"][str(K)]
        states = logged[K]["mpc/state"]
        errors = logged[K]["mpc/error"]
        iterates = logged[K]["mpc/iterate"]
        assert [m["t"] for m in states] == list(range(31))
        assert [m["x"] for m in states] == s["x"]
        assert [m["u"] for m in states[:-1]] == s["u"] and "u" not in states[-1]  # no input after the last state
        assert [m["e_norm"] for m in errors] == s["e_norm"]
        for agent in ("agent1", "agent2", "agent3"):
            assert [m["e_norm_agent"][agent] for m in errors] == s["e_norm_agent"][agent]
        # every iterate of every sampling time, k = 0 being the warm start
        assert len(iterates) == sum(it + 1 for it in s["iterations"])
        last = {m["t"]: m for m in iterates}
        np.testing.assert_allclose([last[t]["error_norm"] for t in range(30)], s["e_norm"], rtol=0, atol=0)
        assert len(s["solve_time_s"]) == 30 and s["failed_steps"] == []
        np.testing.assert_array_equal(np.array(s["x"]), r.x)


def test_agent_errors_split_the_error(study2_run) -> None:
    _, sim = study2_run
    r = sim[1]
    total = np.sqrt(sum(v**2 for v in r.e_norm_agent.values()))
    # z = (a_1, a_2, a_3, lambda_1, lambda_2, lambda_3): the agents' blocks partition z
    np.testing.assert_allclose(total, r.e_norm, rtol=1e-12)


def test_plant_disturbance_is_seeded_and_enters_the_dynamics() -> None:
    over = {"run.K": [2], "run.steps": 8, "disturbance.plant": {"kind": "gaussian", "scale": 0.05, "seed": 3}}
    a = simulate(load_config(STUDY2, over))[2]
    b = simulate(load_config(STUDY2, over))[2]
    c = simulate(load_config(STUDY2, {**over, "disturbance.plant.seed": 4}))[2]
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.e_norm, b.e_norm)
    assert not np.array_equal(a.x, c.x)
    A = np.diag([0.5, 0.3, 0.2])
    np.testing.assert_allclose(a.x[1:] - (a.x[:-1] @ A.T + a.u), a.w, atol=1e-14)
    assert 0.01 < np.std(a.w) < 0.1


@pytest.mark.parametrize("kind, check", [
    ("constant", lambda w: np.allclose(w, [0.1, -0.2, 0.0])),
    ("uniform", lambda w: np.all(np.abs(w) <= np.array([0.1, 0.2, 0.0])) and np.all(w[:, 2] == 0)),
])
def test_plant_disturbance_kinds(kind, check) -> None:
    scale = [0.1, -0.2, 0.0] if kind == "constant" else [0.1, 0.2, 0.0]
    r = simulate(load_config(STUDY2, {"run.K": [3], "run.steps": 5,
                                      "disturbance.plant": {"kind": kind, "scale": scale}}))[3]
    assert check(r.w)


def test_solver_disturbance_applies_at_every_step_and_is_seeded() -> None:
    over = {"run.K": [1], "run.steps": 10, "disturbance.kind": "jacobian_noise", "disturbance.scale": 1e-2,
            "disturbance.seed": 5}
    a = simulate(load_config(STUDY2, over))[1]
    b = simulate(load_config(STUDY2, over))[1]
    clean = simulate(load_config(STUDY2, {"run.K": [1], "run.steps": 10}))[1]
    np.testing.assert_array_equal(a.e_norm, b.e_norm)
    # the noise perturbs every sampling time, so e(t) never drops to zero as in the clean loop
    late = slice(5, 10)
    assert np.all(clean.e_norm[late] <= 1e-10)
    assert np.all(a.e_norm[late] > 1e-10)


def test_shift_warm_start() -> None:
    cfg = load_config(STUDY2, {"game.horizon": 3})
    game = compile_game(cfg)
    z = np.arange(game.size, dtype=float)
    shifted = game.shift(z)
    # agent 1's inputs u1(0..3) sit at z[0:4]: drop u1(0), repeat u1(3)
    np.testing.assert_array_equal(shifted[0:4], [1, 2, 3, 3])
    # agent 3's multipliers: two constraints per stage (u3 >= u1 + u2, u3 >= 0), stage-major
    ms = game.multiplier_slices[2]
    block = z[game.n + ms.start: game.n + ms.stop].reshape(4, 2)
    np.testing.assert_array_equal(shifted[game.n + ms.start: game.n + ms.stop].reshape(4, 2),
                                  np.vstack([block[1:], block[-1:]]))
    sim = simulate(load_config(STUDY2, {"run.K": [1, 20], "run.steps": 10, "run.warm_start": "shift"}))
    exact = simulate(load_config(STUDY2, {"run.K": [20], "run.steps": 10}))[20]
    np.testing.assert_allclose(sim[20].x, exact.x, atol=1e-10)
    assert sim[1].e_norm[0] > 0 and sim[1].e_norm[-1] <= 1e-10


def test_simulate_needs_a_dynamic_game() -> None:
    with pytest.raises(InputError, match="dynamic game"):
        simulate(load_config(CONFIGS / "fk_a12.yaml"))
    proc = run_cli("simulate", str(CONFIGS / "fk_a12.yaml"))
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr and "dynamic game" in proc.stderr


def test_cli_simulate(tmp_path: Path) -> None:
    out = tmp_path / "run"
    proc = run_cli("simulate", str(STUDY2), "--out", str(out), "--set", "run.steps=6", "--set", "run.K=[1,7]")
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    header = next(i for i, s in enumerate(lines) if s.split()[:3] == ["K", "max", "e"])
    rows = [s.split() for s in lines[header + 1: header + 3]]
    assert [r[0] for r in rows] == ["1", "7"]
    summary = json.loads((out / "summary.json").read_text())
    assert float(rows[0][1]) == pytest.approx(summary["by_K"]["1"]["max_e_norm"], rel=1e-3)
    assert "━" not in proc.stdout  # no progress bar when stdout is not a terminal
    quiet = run_cli("simulate", str(STUDY2), "--out", str(tmp_path / "q"), "--set", "run.steps=2", "--quiet")
    assert quiet.returncode == 0 and quiet.stdout == ""


def test_bad_plant_disturbance_is_a_config_error() -> None:
    from gnerun.errors import ConfigError

    with pytest.raises(ConfigError, match="disturbance.plant.scale: has 2 entries for 3 states"):
        load_config(STUDY2, {"disturbance.plant": {"kind": "gaussian", "scale": [0.1, 0.1]}})
    with pytest.raises(ConfigError, match="disturbance.plant.kind"):
        load_config(STUDY2, {"disturbance.plant.kind": "brownian"})


def test_vehicle_game_runs_K1_to_5_without_a_solver_failure() -> None:
    """The defaults (the first sampling time solved, shifted warm starts, the safeguard) keep ||p1 - p2|| >= d at every
    K, and the tracking error shrinks with K."""
    sim = simulate(load_config(CONFIGS / "vehicles.yaml", {"run.K": [1, 2, 3, 4, 5]}))
    game = sim.game
    shared = slice(game.n + game.shared_slice.start, game.n + game.shared_slice.stop)
    max_e = {}
    for K, r in sim.items():
        assert set(r.status) <= {"converged", "incomplete"}, (K, r.status)
        assert set(r.reference_status) == {"converged"}  # every exact solution z*(t) found
        distance = np.hypot(r.x[:, 0] - r.x[:, 3], r.x[:, 1] - r.x[:, 4])
        assert distance.min() >= 1.0 - 1e-6  # ||p1 - p2|| >= d holds along the closed loop
        # the reported violations are those of the logged states
        np.testing.assert_allclose(r.constraint_violation, np.maximum(1.0 - distance[1:] ** 2, 0.0), atol=1e-9)
        assert r.e_norm[-1] <= (1e-3 if K == 1 else 1e-5)  # K = 1 is still settling (2e-4) at t = 49
        max_e[K] = float(np.max(r.e_norm))
        # the collision constraint binds while the vehicles cross
        assert np.max(r.z_star[:, shared]) > 0.5
        # both vehicles get past the intersection towards their goals
        assert r.x[-1, 0] > 6 and r.x[-1, 4] > 6
    assert max_e[1] > 1.0  # small K: a visible tracking error
    assert max_e[1] > max_e[2] > max_e[3] > max_e[5]


def test_the_papers_rule_lets_a_small_budget_violate_the_distance() -> None:
    """K steps from the last iterate, from the start values at t = 0, the K-th iterate applied: time-distributed
    iterations do not enforce constraints by themselves (K = 1 lets the vehicles come to 0.78 d), and the reported
    violation says so."""
    paper = {"run.initial": "start", "run.warm_start": "previous", "run.safeguard": "none"}
    sim = simulate(load_config(CONFIGS / "vehicles.yaml", {"run.K": [1, 3], **paper}))
    for r in sim.values():
        distance = np.hypot(r.x[:, 0] - r.x[:, 3], r.x[:, 1] - r.x[:, 4])
        np.testing.assert_allclose(r.constraint_violation, np.maximum(1.0 - distance[1:] ** 2, 0.0), atol=1e-9)
        assert r.max_constraint_violation == pytest.approx(max(0.0, 1.0 - distance.min() ** 2), abs=1e-9)
        assert not r.fallback_steps
    assert sim[1].max_constraint_violation > 0.3  # (0.78 d)^2 = 0.6 d^2
    assert sim[3].max_constraint_violation <= 1e-9


def test_a_process_that_ignores_ctrl_c_keeps_ignoring_it_in_a_closed_loop() -> None:
    # a sweep's workers ignore SIGINT (the sweep stops them); the closed loop must not re-arm it there, or a worker
    # races the sweep to write an interrupted point's summary
    import signal

    from gnerun.runs.closed_loop import Interrupt

    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with Interrupt().installed():
            assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, previous)
    with Interrupt().installed():  # an ordinary process: Ctrl-C becomes a request
        assert signal.getsignal(signal.SIGINT) not in (signal.SIG_IGN, previous)


def test_without_reference_and_certificate_the_same_solution_and_loop(tmp_path: Path) -> None:
    """run.reference: none skips z* (and the errors), run.certificate: false the best responses: what the solver
    does is unchanged, bit for bit; the summary says what was skipped."""
    cfg = load_config(CONFIGS / "vehicles.yaml", {"run.steps": 6, "run.K": [1, 3]})
    lean = cfg.model_copy(update={"run": cfg.run.model_copy(update={"reference": "none", "certificate": False})})
    full, fast = solve(cfg), solve(lean, out=tmp_path / "solve")
    # the same point: certified by the full solve, a KKT point whose best responses were not checked by the lean one
    assert full.status == "converged" and fast.status == "kkt_point" and np.array_equal(fast.z, full.z)
    assert "not certified" in fast.message
    assert fast.error_history is None and full.error_history is not None
    assert "best_response_gap" not in fast.certificate and fast.certificate["kkt_residual"] < 1e-9
    summary = json.loads((tmp_path / "solve" / "summary.json").read_text())
    assert summary["reference"]["status"] == "skipped" and "best_response_gap" not in summary["certificate"]
    a, b = simulate(cfg), simulate(lean)
    for K in (1, 3):
        np.testing.assert_array_equal(b[K].u, a[K].u)
        np.testing.assert_array_equal(b[K].x, a[K].x)
        assert np.all(np.isnan(b[K].e_norm)) and np.all(np.isfinite(a[K].e_norm))
        assert set(b[K].reference_status) == {"skipped"}


def test_reference_none_never_solves_for_z_star(monkeypatch: pytest.MonkeyPatch) -> None:
    """run.reference: none pays for no exact solution: neither simulate nor solve calls the reference solve (which
    fails here), and the certificate without best responses computes none."""
    from gnerun.runs import closed_loop, solving
    from gnerun.solvers import certificate

    def refused(*args, **kwargs):
        raise AssertionError("the reference solve was called")

    monkeypatch.setattr(closed_loop.ReferenceSolver, "solve", refused)
    monkeypatch.setattr(closed_loop.ReferenceSolver, "reached", staticmethod(refused))  # a converged step's z*
    monkeypatch.setattr(solving, "reference_solution", refused)
    monkeypatch.setattr(certificate, "best_response", refused)
    monkeypatch.setattr(certificate.NewtonResponses, "best_response", refused)
    monkeypatch.setattr(certificate, "check_player", refused)
    cfg = load_config(CONFIGS / "vehicles.yaml", {"run.steps": 4, "run.K": [2], "run.reference": "none",
                                                  "run.certificate": False})
    assert set(simulate(cfg)[2].reference_status) == {"skipped"}
    assert solve(cfg).status == "kkt_point"  # solved, not certified: the best responses were not checked
    with pytest.raises(AssertionError, match="reference solve was called"):  # and the default does call it
        simulate(load_config(CONFIGS / "vehicles.yaml", {"run.steps": 4, "run.K": [2]}))


def test_an_undisturbed_solve_is_its_own_reference_solve(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """With run.reference: exact and no solver-side disturbance, the solve is the reference solve (the same solver
    from the same start): it runs once, z* is its end polished, and every iterate is logged with its error to z*.
    A disturbed solve still solves for z* apart."""
    from gnerun.runs import solving

    calls = []
    original = solving.reference_solution

    def counted(*args, **kwargs):
        calls.append(1)
        return original(*args, **kwargs)

    monkeypatch.setattr(solving, "reference_solution", counted)
    cfg = load_config(CONFIGS / "nonlinear_gne.yaml")
    res = solve(cfg, out=tmp_path / "run")
    assert res.status == "converged" and not calls
    assert res.reference_status == "converged" and res.residual_norm <= cfg.solver.tol
    logged = [np.linalg.norm(z - res.z_star) for z in _iterates(tmp_path / "run")]
    np.testing.assert_array_equal(res.error_history, logged)
    messages = read_messages(tmp_path / "run" / "run.mcap")
    errors = [m["error_norm"] for topic, m, _ in messages if topic == "/solve/iterate"]
    np.testing.assert_allclose(errors, logged, rtol=1e-15)
    assert res.error_history[-1] <= 1e-9 and res.error_history[0] > 0.1
    # the same numbers as the reference solve of a separate solver
    ref = original(res.game, cfg, res.game.z_start(), res.game.x0)
    np.testing.assert_array_equal(ref.z, res.z_star)
    assert len(res.residual_history) == res.iterations + 1
    disturbed = solve(load_config(CONFIGS / "nonlinear_gne.yaml", {"disturbance.kind": "residual",
                                                                  "disturbance.scale": 1e-6}))
    assert calls and disturbed.reference_status == "converged"


def _iterates(run: Path) -> list[np.ndarray]:
    return [np.asarray(m["z"]) for topic, m, _ in read_messages(run / "run.mcap") if topic == "/solve/iterate"]


def test_cli_says_the_best_responses_were_not_checked(tmp_path: Path) -> None:
    proc = run_cli("solve", str(CONFIGS / "harker.yaml"), "--set", "run.certificate=false", "--set",
                   "run.reference=none", "--out", str(tmp_path / "run"))
    assert proc.returncode == 0, proc.stderr
    assert "best responses not checked (run.certificate: false)" in proc.stdout


def test_cli_end_table_gives_each_Ks_fallbacks_and_worst_violation(tmp_path: Path) -> None:
    """The end table's fallback and violation columns, and the row and time of each violation above rounding, are
    those of summary.json: the demo (two fallback steps at K = 1) and Study 2 (the paper's rule breaks agent 1's
    constraint at K = 1)."""
    for config, K, steps in (("mcp_demo.yaml", "[1,3]", 12), ("paper_study2.yaml", "[1,3]", 6)):
        out = tmp_path / config
        proc = run_cli("simulate", str(CONFIGS / config), "--out", str(out), "--set", f"run.K={K}", "--set",
                       f"run.steps={steps}", "--set", "run.reference=none")
        assert proc.returncode == 0, proc.stderr
        by_K = json.loads((out / "summary.json").read_text())["by_K"]
        lines = proc.stdout.splitlines()
        header = next(i for i, s in enumerate(lines) if s.split()[:3] == ["K", "max", "e"])
        assert lines[header].split()[-4:] == ["failed", "fallback", "max", "violation"]
        for row in (s.split() for s in lines[header + 1: header + 3]):
            summary = by_K[row[0]]
            assert int(row[-3]) == len(summary["failed_steps"]) and int(row[-2]) == len(summary["fallback_steps"])
            assert float(row[-1]) == pytest.approx(summary["max_constraint_violation"], rel=1e-3, abs=1e-300)
        worst = [s for s in lines if s.startswith("K=") and "largest violation" in s]
        expected = []
        for k, summary in by_K.items():
            v = summary["constraint_violation"]
            if max(v) > 1e-9:
                t = int(np.argmax(v))
                expected.append(f"K={k}: largest violation {max(v):.3e} at t = {t}: {summary['worst_constraint'][t]}")
        assert worst == expected
    assert "K=1: largest violation 1.518e+00 at t = 1: agent1: u1 + u2 + u3 <= 1 [tau=0]" in worst


def _in_a_terminal(*args: str, timeout: float = 120) -> tuple[int, str]:
    """The CLI with its output on a pseudo-terminal (stdout and stderr), as a user at a terminal sees it."""
    import os
    import pty
    import subprocess
    import threading

    master, slave = pty.openpty()
    proc = subprocess.Popen([*gnerun_command(), *args], stdin=subprocess.DEVNULL, stdout=slave, stderr=slave,
                            env={**os.environ, "COLUMNS": "120", "TERM": "xterm"})
    os.close(slave)
    chunks: list[bytes] = []

    def read() -> None:
        while True:
            try:
                data = os.read(master, 65536)
            except OSError:  # the process has ended and closed the terminal
                return
            if not data:
                return
            chunks.append(data)

    reader = threading.Thread(target=read)
    reader.start()
    try:
        code = proc.wait(timeout)
    finally:
        reader.join(10)
        os.close(master)
    return code, b"".join(chunks).decode(errors="replace")


def test_a_terminal_sees_progress_of_simulate_and_of_a_long_solve(tmp_path: Path) -> None:
    """At a terminal, simulate shows a progress bar per K, and solve says what it does besides iterating (the exact
    solution, the certificate) as it starts it; --quiet shows neither."""
    code, text = _in_a_terminal("simulate", str(STUDY2), "--out", str(tmp_path / "s"), "--set", "run.K=[1,3]",
                                "--set", "run.steps=6")
    assert code == 0, text
    assert "━" in text and "K=1" in text and "K=3" in text and "6/6" in text
    code, text = _in_a_terminal("solve", str(CONFIGS / "harker.yaml"), "--out", str(tmp_path / "h"))
    assert code == 0, text
    stages = [s.strip() for s in text.splitlines() if s.startswith("... ")]
    assert stages == ["... solving; the iterates are shown when its end, polished, gives the exact solution z* of "
                      "their error norms (run.reference: none shows them as they come)",
                      "... checking the best response of each of 2 agents (run.certificate: false skips it)"]
    assert text.index("... checking") < text.index("status: converged")
    code, text = _in_a_terminal("simulate", str(STUDY2), "--out", str(tmp_path / "q"), "--set", "run.steps=2",
                                "--quiet")
    assert code == 0 and text.strip() == "", text


def test_the_reference_solver_is_built_once_and_solves_as_a_new_one() -> None:
    """z*(t) of a closed loop: the solvers are built at the first sampling time and kept, and each solve gives
    bit for bit what a new solver gives (kept factorisations per active set would change z* in its last bits)."""
    from gnerun.runs.reference import ReferenceSolver
    from gnerun.runs.solving import reference_solution

    cfg = load_config(CONFIGS / "paper_study2.yaml")
    game = compile_game(cfg)
    reference = ReferenceSolver(cfg, game)
    rng = np.random.default_rng(0)
    z0 = game.z_start()
    built = None
    for _ in range(15):
        x = game.x0 + rng.standard_normal(game.x0.shape)
        kept = reference.solve(z0, x)
        new = reference_solution(game, cfg, z0, x)
        assert kept.converged and np.array_equal(kept.z, new.z)
        if built is None:
            built = {k: id(s) for k, s in reference.solvers.items()}
        assert {k: id(s) for k, s in reference.solvers.items()} == built


def test_a_converged_sampling_times_reference_is_its_own_iterate(monkeypatch: pytest.MonkeyPatch) -> None:
    """Where the loop's solve converged (undisturbed), z*(t) is its iterate, not solved for again: it agrees with a
    fresh solve at the same state (Study 2's game has one equilibrium) to the solver's tolerance; where the loop did
    not converge (K = 1), and in a disturbed loop, z*(t) is solved for."""
    from gnerun.runs import closed_loop
    from gnerun.runs.solving import reference_solution

    solved = []
    original = closed_loop.ReferenceSolver.solve

    def counting(self, *args, **kwargs):
        solved.append(1)
        return original(self, *args, **kwargs)

    monkeypatch.setattr(closed_loop.ReferenceSolver, "solve", counting)
    cfg = load_config(CONFIGS / "paper_study2.yaml", {"run.K": [1, 7], "run.steps": 8})
    sim = simulate(cfg)
    game = compile_game(cfg)
    for K in (1, 7):
        loop = sim[K]
        for t in range(8):
            fresh = reference_solution(game, cfg, game.z_start(), loop.x[t])
            assert np.max(np.abs(loop.z_star[t] - fresh.z)) <= 1e-10
            if loop.status[t] == "converged":
                assert np.array_equal(loop.z_star[t], loop.z[t]) and loop.e_norm[t] == 0.0
    not_converged = sum(s != "converged" for K in (1, 7) for s in sim[K].status)
    assert not_converged > 0 and len(solved) == not_converged  # a solve per sampling time that did not converge
    solved.clear()
    disturbed = load_config(CONFIGS / "paper_study1_disturbed.yaml", {"run.K": [7], "run.steps": 3})
    simulate(disturbed)
    assert len(solved) == 3


@pytest.mark.parametrize("config, overrides, z_star_solves", [
    # z*(0) is the loop's own converged iterate: not solved for
    ("formation_ring.yaml", {"run.K": [1, 3, 10], "run.steps": 4}, 0),
    # a perturbed solver: the loops of K > 1 go on with the random state the t = 0 solve left; z*(0) solved apart
    ("paper_study2.yaml", {"run.K": [1, 2, 5], "run.steps": 4, "run.initial": "solve",
                           "disturbance": {"kind": "jacobian_noise", "scale": 1e-2, "seed": 3}}, 1),
    # the distributed method, whose solvers keep factorisations from one sampling time to the next; z*(0) by SSN
    ("paper_study3.yaml", {"run.K": [2, 5], "run.steps": 4, "run.initial": "solve"}, 1),
])
def test_the_first_sampling_time_is_solved_once_for_every_K(config: str, overrides: dict, z_star_solves: int,
                                                            monkeypatch, tmp_path: Path) -> None:
    """With run.initial: solve, t = 0 (a solve to tolerance from the start values, which does not depend on K) is
    solved by the first loop and taken by the others; each K's loop is, bit for bit, the loop of that K run alone,
    and its log holds the same t = 0 iterates."""
    import gnerun.runs.closed_loop as closed_loop

    cfg = load_config(CONFIGS / config, overrides)
    solves: list[int] = []  # the budgets of the solver's step loops

    def counted(solver, state, max_steps=None, *args, **kwargs):
        solves.append(max_steps)
        return iterate(solver, state, max_steps, *args, **kwargs)

    iterate = closed_loop.iterate
    monkeypatch.setattr(closed_loop, "iterate", counted)
    at_x0: list[bool] = []  # z*(t) solves: at x(0) or not
    track = closed_loop.ReferenceSolver.track

    def tracked(self, z_warm, z_previous, x, interrupt=None):
        at_x0.append(np.array_equal(x, cfg.game.x0))
        return track(self, z_warm, z_previous, x, interrupt)

    monkeypatch.setattr(closed_loop.ReferenceSolver, "track", tracked)
    together = simulate(cfg, out=tmp_path / "together")
    assert solves.count(cfg.solver.max_iter) == 1 and together.first.solves == 1
    assert at_x0.count(True) == z_star_solves
    assert [r.shares_first for r in together.values()] == [False] + [True] * (len(cfg.run.K) - 1)
    steps = cfg.run.steps
    assert len(solves) == 1 + (steps - 1) * len(cfg.run.K)
    def logged(run: Path, K: int) -> list:
        return [(t, m) for t, m, _ in read_messages(run / "run.mcap") if t.startswith(f"/K{K}/")]

    for K, r in together.items():
        solves.clear()
        alone = simulate(load_config(CONFIGS / config, {**overrides, "run.K": [K]}), out=tmp_path / f"K{K}")[K]
        assert solves.count(cfg.solver.max_iter) == 1
        assert logged(tmp_path / "together", K) == logged(tmp_path / f"K{K}", K)  # every iterate, bit for bit
        for name in ("x", "u", "w", "e_norm", "residual_norm", "iterations", "z", "z_star", "constraint_violation",
                     "fallback"):
            assert np.array_equal(getattr(r, name), getattr(alone, name), equal_nan=True), (K, name)
        assert r.status == alone.status and r.reference_status == alone.reference_status
        assert r.solve_time_s[0] == together[cfg.run.K[0]].solve_time_s[0]  # the one t = 0 solve's time
    at_0 = defaultdict(list)
    for topic, msg, _ in read_messages(tmp_path / "together" / "run.mcap"):
        if topic.endswith("/mpc/iterate") and msg["t"] == 0:
            at_0[topic].append(msg)
    assert len(at_0) == len(cfg.run.K) and len({json.dumps(v) for v in at_0.values()}) == 1
    K = cfg.run.K[0]
    assert len(at_0[f"/K{K}/mpc/iterate"]) == together[K].iterations[0] + 1


def test_loops_whose_first_sampling_time_differs_solve_it_each() -> None:
    """A parameters callback that gives each loop other runtime values at t = 0 (here: the goal moves on every call)
    makes t = 0 a different problem per K: each loop solves its own; one that gives the same values shares it."""
    cfg = load_config(CONFIGS / "formation_ring.yaml", {"run.K": [1, 3], "run.steps": 2})
    calls = iter(range(100))
    moving = simulate(cfg, parameters=lambda t, x: {"gx": 0.1 * next(calls)})
    assert [r.shares_first for r in moving.values()] == [False, False]
    assert moving[1].parameters[0] != moving[3].parameters[0]
    assert not np.array_equal(moving[1].z[0], moving[3].z[0])
    fixed = simulate(cfg, parameters=lambda t, x: {"gx": 0.5})
    assert [r.shares_first for r in fixed.values()] == [False, True] and fixed.first.solves == 1
    assert np.array_equal(fixed[1].z[0], fixed[3].z[0])
