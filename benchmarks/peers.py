"""Optional peer comparison: gnerun's SSN against the PyPI package ``nashopt`` on ``configs/variational_gne.yaml``.

The game (3 agents, scalar inputs, horizon T, inputs at stages tau = 0..T) is condensed here by hand, states as
affine functions of the inputs z = (u1(0..T), u2(0..T), u3(0..T)), the order of gnerun's ``res.z[:n]``:

    x_i(tau + 1) = a_i^(tau + 1) x0_i + sum_{s <= tau} a_i^(tau - s) u_i(s),   a = (0.5, 0.3, 0.2), x0 = (1, 3, 5)

so X_i = (x_i(1), ..., x_i(T + 1)) = M_i z + d_i. The stage costs, summed over tau = 0..T on the state that
u(tau) produces, become

    f1 = |X1 - 1|^2 - X1.X2 + 0.1 |u1|^2,   f2 = |X2 - 1|^2 + X1.X2 + 0.1 |u2|^2,   f3 = |X3 - 1|^2 + 0.1 |u3|^2,

that is f_i = 0.5 z'Q_i z + c_i'z + const, with bounds u1 in [-1, 1], u2 in [-1, 0.5], u3 in [0, 2] and the
shared constraint u1(tau) + u2(tau) + u3(tau) <= 1 (A z <= b, one row per stage), variational equilibrium.

nashopt is given the game twice:
- as matrices (Q_i, c_i, A, b, bounds) to ``nashopt.GNEP_LQ(..., variational=True)``, its linear-quadratic
  class, solved by its default mixed-integer (HiGHS MILP) path and by the variational-only paths ``dr_daqp``
  (its documented fastest), ``qp_gnep`` and ``lemke_dual``;
- as JAX functions (the stage costs evaluated literally on the condensed states, g(z) = A z - b) to
  ``nashopt.GNEP(..., variational=True)``, its general nonlinear class, solved by its default path (the
  Fischer-Burmeister KKT system by scipy ``least_squares``, trf, with JAX Jacobians).

nashopt is imported only inside functions: ``import benchmarks.peers`` works without it. Importing nashopt turns
on ``jax_enable_x64`` process-wide (gnerun does not use JAX, so its numbers are unaffected).

Run it alone: ``python -m benchmarks.peers [T] [repeats]``.

The bounded LQ family of benchmarks/problems/lq.py (horizons 5, 20, 40; variational and generalized) has its own
peers, :func:`lq_family_peers` (the robustness suite calls it): every GNEP_LQ path that accepts the equilibrium
(for plain GNEs only the MILP), the general ``GNEP`` (JAX; ``trf`` least squares, and root ``hybr`` for plain GNEs),
and siconos's LCP semismooth Newton methods (min map; min map and Fischer-Burmeister with the Fischer-Burmeister
line search) when Debian's ``python3-siconos`` is installed; siconos runs in Debian's Python through a subprocess,
each solve timed inside it. Every result carries the median time over the repeats (a warm-up call excluded), the
solution and its check (distance to the variational reference, best-response gaps). ``python -m benchmarks.peers
lq [repeats]`` prints the family's table with gnerun's default and Fischer-Burmeister with line search beside the
peers. Run timings with ``OPENBLAS_NUM_THREADS=1``: on a loaded 2-core machine multithreaded BLAS calls stall.
"""

from __future__ import annotations

import functools
import importlib.util
import json
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

CONFIG = Path(__file__).resolve().parent.parent / "configs" / "variational_gne.yaml"

A_DIAG = np.array([0.5, 0.3, 0.2])  # x(t + 1) = diag(A_DIAG) x(t) + u(t)
X0 = np.array([1.0, 3.0, 5.0])
LOWER = np.array([-1.0, -1.0, 0.0])  # per agent, every stage
UPPER = np.array([1.0, 0.5, 2.0])
SHARED_RHS = 1.0  # u1 + u2 + u3 <= 1 at every stage
R = 0.1  # input weight
DIFF_TOL = 1e-5  # solutions further apart than this are flagged in the note


_import_s: float | None = None  # wall time of this process's first ``import nashopt``, when this module did it


def _import_nashopt() -> None:
    """Import nashopt (raises ImportError), timing the import if this is the process's first."""
    global _import_s
    if sys.modules.get("nashopt") is not None:
        return
    t0 = time.perf_counter()
    import nashopt  # noqa: F401

    _import_s = time.perf_counter() - t0


def available() -> bool:
    """Whether nashopt is importable (installed, and its undeclared import ``qpsolvers`` too)."""
    if importlib.util.find_spec("nashopt") is None:
        return False
    try:
        _import_nashopt()
    except ImportError:
        return False
    return True


@dataclass(frozen=True)
class CondensedGame:
    """The condensed LQ game: agent i minimises 0.5 z'Q[i] z + c[i]'z over its block of z (+ a constant)."""

    T: int
    M: list[np.ndarray]  # X_i = M[i] z + d[i], X_i = (x_i(1), ..., x_i(T + 1))
    d: list[np.ndarray]
    E: list[np.ndarray]  # u_i = E[i] z
    Q: list[np.ndarray]
    c: list[np.ndarray]
    lb: np.ndarray
    ub: np.ndarray
    A: np.ndarray  # shared: A z <= b
    b: np.ndarray

    @property
    def H(self) -> int:
        """Stages per agent, T + 1."""
        return self.T + 1

    @property
    def n(self) -> int:
        """Decision variables, 3 (T + 1)."""
        return 3 * self.H


def condense(T: int) -> CondensedGame:
    """Condense the dynamic game of configs/variational_gne.yaml at horizon T into its LQ form."""
    H = T + 1
    n = 3 * H
    k = np.arange(H)
    E: list[np.ndarray] = []
    M: list[np.ndarray] = []
    d: list[np.ndarray] = []
    for i in range(3):
        Ei = np.zeros((H, n))
        Ei[:, i * H : (i + 1) * H] = np.eye(H)
        lag = np.subtract.outer(k, k)  # row tau (state x(tau + 1)), column s (input u(s)): a^(tau - s), s <= tau
        Gi = np.where(lag >= 0, A_DIAG[i] ** np.clip(lag, 0, None), 0.0)
        E.append(Ei)
        M.append(Gi @ Ei)
        d.append(A_DIAG[i] ** (k + 1) * X0[i])
    one = np.ones(H)
    cross = M[0].T @ M[1] + M[1].T @ M[0]  # Hessian of X1.X2
    cross_lin = M[0].T @ d[1] + M[1].T @ d[0]  # gradient of X1.X2 at z = 0
    Q = [
        2 * M[0].T @ M[0] - cross + 2 * R * E[0].T @ E[0],
        2 * M[1].T @ M[1] + cross + 2 * R * E[1].T @ E[1],
        2 * M[2].T @ M[2] + 2 * R * E[2].T @ E[2],
    ]
    c = [
        2 * M[0].T @ (d[0] - one) - cross_lin,
        2 * M[1].T @ (d[1] - one) + cross_lin,
        2 * M[2].T @ (d[2] - one),
    ]
    return CondensedGame(
        T=T,
        M=M,
        d=d,
        E=E,
        Q=Q,
        c=c,
        lb=np.repeat(LOWER, H),
        ub=np.repeat(UPPER, H),
        A=np.hstack([np.eye(H)] * 3),
        b=np.full(H, SHARED_RHS),
    )


def _median_time(fn: Callable[[], Any], repeats: int) -> tuple[float, Any]:
    """(median wall time of one call over ``repeats`` calls, the last call's result)."""
    samples = []
    out = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        samples.append(time.perf_counter() - t0)
    return statistics.median(samples), out


def gnerun_solution(T: int, repeats: int) -> tuple[np.ndarray, float, str]:
    """(inputs z, median time of the solve loop, a note) of gnerun's SSN; the game is compiled and the solver built
    once, outside the timing; the first solve (a fresh solver) is not in the median."""
    import gnerun
    from gnerun.solvers.driver import iterate

    cfg = gnerun.load_config(CONFIG, {"solver.kind": "ssn", "game.horizon": T})
    game = gnerun.compile_game(cfg)
    solver = gnerun.make_solver(cfg, game)

    def run() -> Any:
        return iterate(solver, solver.init())

    t0 = time.perf_counter()
    run()
    first = time.perf_counter() - t0
    t, state = _median_time(run, repeats)
    note = (
        f"gnerun: SSN init + {state.k} steps (||Phi|| {state.residual_norm:.1e}), solver built once, compile "
        f"excluded, first solve (untimed) {first:.3g} s"
    )
    return np.asarray(state.z[: game.n], dtype=float).copy(), t, note


def _lq_row(
    game: CondensedGame, method: str, z_ref: np.ndarray, gnerun_s: float, repeats: int, label: str
) -> dict[str, Any]:
    """Time ``nashopt.GNEP_LQ(..., variational=True, solver=method).solve()``: the object is built once (not
    timed), one untimed first call (one-time costs: HiGHS start-up, numba compilation where used), then ``repeats``
    calls."""
    from nashopt import GNEP_LQ

    lq = GNEP_LQ(
        [game.H] * 3,
        game.Q,
        game.c,
        lb=game.lb.copy(),
        ub=game.ub.copy(),
        A=game.A,
        b=game.b,
        variational=True,
        solver=method,
    )
    t0 = time.perf_counter()
    lq.solve()
    first = time.perf_counter() - t0
    t, sol = _median_time(lq.solve, repeats)
    x = np.asarray(sol.x, dtype=float)
    note = (
        f"GNEP_LQ(variational=True, solver={method!r}).solve() per call; the GNEP_LQ object is built once, "
        f"outside the timing; first call (untimed) {first:.3g} s; status {getattr(sol, 'status_str', None)}"
    )
    return _row(game.T, label, gnerun_s, t, x, z_ref, note)


def _nonlinear_row(game: CondensedGame, z_ref: np.ndarray, gnerun_s: float, repeats: int) -> dict[str, Any]:
    """Time ``nashopt.GNEP(..., variational=True).solve()`` on JAX cost functions. nashopt re-JITs the KKT residual
    and its Jacobian inside every ``solve()`` call, so the per-call time includes that compilation; the note also
    gives nashopt's own split (``stats.jax_jit_time``)."""
    import jax.numpy as jnp
    from nashopt import GNEP

    M = [jnp.asarray(m) for m in game.M]
    d = [jnp.asarray(v) for v in game.d]
    E = [jnp.asarray(e) for e in game.E]
    A, b = jnp.asarray(game.A), jnp.asarray(game.b)

    def f1(z: Any) -> Any:
        x1, x2 = M[0] @ z + d[0], M[1] @ z + d[1]
        return jnp.sum((x1 - 1) ** 2 - x1 * x2) + R * jnp.sum((E[0] @ z) ** 2)

    def f2(z: Any) -> Any:
        x1, x2 = M[0] @ z + d[0], M[1] @ z + d[1]
        return jnp.sum((x2 - 1) ** 2 + x1 * x2) + R * jnp.sum((E[1] @ z) ** 2)

    def f3(z: Any) -> Any:
        x3 = M[2] @ z + d[2]
        return jnp.sum((x3 - 1) ** 2) + R * jnp.sum((E[2] @ z) ** 2)

    def g(z: Any) -> Any:
        return A @ z - b

    t0 = time.perf_counter()
    gnep = GNEP([game.H] * 3, f=[f1, f2, f3], g=g, ng=game.H, lb=game.lb, ub=game.ub, variational=True)
    setup = time.perf_counter() - t0
    t0 = time.perf_counter()
    gnep.solve(verbose=0)
    first = time.perf_counter() - t0
    stats: list[Any] = []

    def run() -> Any:
        sol = gnep.solve(verbose=0)
        stats.append(sol.stats)
        return sol

    t, sol = _median_time(run, repeats)
    x = np.asarray(sol.x, dtype=float)
    jit = statistics.median(s.jax_jit_time for s in stats)
    note = (
        f"GNEP(variational=True).solve() per call (default path: {sol.stats.solver}, {sol.stats.kkt_evals} KKT "
        f"evaluations, ||KKT residual|| {np.linalg.norm(sol.res):.1e}); every call re-JITs the KKT residual and "
        f"its Jacobian, median {jit:.3g} s of the call (nashopt's stats.jax_jit_time), so {t - jit:.3g} s "
        f"without it; GNEP object built once, outside the timing ({setup:.3g} s); first call (untimed) {first:.3g} s"
    )
    return _row(game.T, "GNEP (nonlinear, JAX)", gnerun_s, t, x, z_ref, note)


def _row(
    T: int, method: str, gnerun_s: float, baseline_s: float, x: np.ndarray, z_ref: np.ndarray, note: str
) -> dict[str, Any]:
    diff = float(np.max(np.abs(x - z_ref)))
    if not diff <= DIFF_TOL:
        note += f"; SOLUTIONS DIFFER: max |u_nashopt - u_gnerun| = {diff:.2e} > {DIFF_TOL:g}"
    return {
        "benchmark": f"variational GNE T = {T}: nashopt {method} vs gnerun SSN",
        "gnerun_s": gnerun_s,
        "baseline": f"nashopt {method}",
        "baseline_s": baseline_s,
        "max_abs_diff": diff,
        "note": note,
    }


# (GNEP_LQ solver name, label); the MILP path first: it is nashopt's default and its only path for non-variational
# equilibria of LQ games.
LQ_METHODS: tuple[tuple[str, str], ...] = (
    ("highs", "GNEP_LQ MILP (HiGHS)"),
    ("dr_daqp", "GNEP_LQ dr_daqp"),
    ("qp_gnep", "GNEP_LQ qp_gnep"),
    ("lemke_dual", "GNEP_LQ lemke_dual"),
)


def peer_rows(T: int = 10, repeats: int = 5) -> list[dict[str, Any]]:
    """One row per nashopt solver path: median times over ``repeats`` and the largest input difference from
    gnerun's SSN solution. Requires nashopt (see :func:`available`)."""
    z_ref, gnerun_s, gnerun_note = gnerun_solution(T, repeats)
    _import_nashopt()
    imported = f"import nashopt {_import_s:.3g} s" if _import_s is not None else "nashopt imported before"
    game = condense(T)
    rows = [_lq_row(game, method, z_ref, gnerun_s, repeats, label) for method, label in LQ_METHODS]
    rows.append(_nonlinear_row(game, z_ref, gnerun_s, repeats))
    for row in rows:
        row["note"] += f"; {gnerun_note}; nashopt {_version()}, {imported}"
    return rows


def _version() -> str:
    """nashopt's installed version (the package has no ``__version__``)."""
    from importlib.metadata import version

    return version("nashopt")


# The bounded LQ family (benchmarks/problems/lq.py) ---------------------------------------------------------------

# GNEP_LQ's paths for variational equilibria: every one it offers (its MILP default included); for plain GNEs only
# the MILP accepts the game.
LQ_VARIATIONAL_PATHS: tuple[str, ...] = (
    "dr_daqp", "lemke_dual", "qp_gnep", "highs", "lemke", "op_extrap", "extragradient", "prox_admm", "log_ipm",
)
LQ_GENERALIZED_PATHS: tuple[str, ...] = ("highs",)
AGREE_TOL = 1e-6  # success, variational: inputs within this of the reference (infinity norm)
GAP_TOL = 1e-8  # success, generalized (no reference): every best-response gap at most this
MILP_TIME_LIMIT = 60.0  # seconds per HiGHS solve
SICONOS_PYTHON = "/usr/bin/python3"  # Debian's python3-siconos lives in the system interpreter, not in the venv
SICONOS_SOLVERS: tuple[tuple[str, str], ...] = (  # (siconos solver id, label): LCP semismooth Newton methods
    ("SICONOS_LCP_NEWTONMIN", "newton_min"),
    ("SICONOS_LCP_NEWTON_MIN_FBLSA", "newton_min_FBLSA"),
    ("SICONOS_LCP_NEWTON_FB_FBLSA", "newton_FB_FBLSA"),
)


@dataclass(frozen=True)
class PeerResult:
    """One peer method on one problem of the LQ family."""

    peer: str  # "nashopt" | "siconos" | "gnerun"
    method: str
    T: int
    equilibrium: str
    time_s: float | None  # median over the timed calls (the warm-up call excluded); None when not timed
    first_s: float | None  # the warm-up call
    success: bool  # a solution within AGREE_TOL of the reference (variational), or with gaps <= GAP_TOL
    status: str  # the method's own status
    iterations: int | None = None
    solution: np.ndarray | None = field(default=None, repr=False)  # inputs in gnerun's order
    max_abs_diff: float | None = None  # against the variational reference
    max_gap: float | None = None  # largest best-response gap
    note: str = ""


@contextmanager
def _stdout_to_stderr() -> Iterator[None]:
    """File descriptor 1 pointed at stderr (HiGHS, under nashopt, prints a banner and warnings from C)."""
    sys.stdout.flush()
    saved = os.dup(1)
    os.dup2(2, 1)
    try:
        yield
    finally:
        sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)


def _lq_reference(T: int, equilibrium: str) -> np.ndarray | None:
    """The variational reference (stored, or computed for another horizon); None for the generalized equilibrium."""
    from benchmarks.problems import lq

    if equilibrium != "variational":
        return None
    if T in lq.REFERENCES:
        return np.array(lq.REFERENCES[T])
    return lq.solve_vi_extragradient(lq.condense(T))[0]


def _checked(
    peer: str, method: str, game: Any, equilibrium: str, x: np.ndarray | None, reference: np.ndarray | None,
    samples: list[float], status: str, iterations: int | None, note: str,
) -> PeerResult:
    """A PeerResult from a solution (or None) and the call times (the first is the warm-up)."""
    from benchmarks.problems.lq import best_response_gaps

    diff = gap = None
    success = False
    if x is not None:
        x = np.asarray(x, dtype=float).reshape(-1)
        if not np.all(np.isfinite(x)):
            status += " (non-finite solution)"
        else:
            gap = max(best_response_gaps(game, x).values())
            diff = float(np.max(np.abs(x - reference))) if reference is not None else None
            success = diff <= AGREE_TOL if diff is not None else gap <= GAP_TOL
    return PeerResult(
        peer=peer,
        method=method,
        T=game.T,
        equilibrium=equilibrium,
        time_s=statistics.median(samples[1:]) if len(samples) > 1 else None,
        first_s=samples[0] if samples else None,
        success=success,
        status=status,
        iterations=iterations,
        solution=x,
        max_abs_diff=diff,
        max_gap=gap,
        note=note,
    )


def _nashopt_status(sol: Any) -> str:
    """nashopt's status of a solution object (its paths name it differently)."""
    if sol is None:
        return "no solution"
    for name in ("status_str", "success", "status"):
        value = getattr(sol, name, None)
        if value is not None:
            return f"{name}={value}"
    return "-"


def _nashopt_lq(game: Any, method: str, equilibrium: str, repeats: int, reference: np.ndarray | None) -> PeerResult:
    """``GNEP_LQ(..., variational=..., solver=method).solve()``: a fresh GNEP_LQ object for every call (built
    outside the timing, so that HiGHS cannot reuse a solved model), one warm-up call, then ``repeats`` timed
    calls. The MILP (``highs``) stops at ``MILP_TIME_LIMIT``; no more calls after a failed warm-up."""
    from nashopt import GNEP_LQ

    variational = equilibrium == "variational"
    label = f"GNEP_LQ {'MILP (HiGHS)' if method == 'highs' else method}"
    options = {"time_limit": MILP_TIME_LIMIT} if method == "highs" else None
    samples: list[float] = []
    sol = None
    try:
        for _ in range(repeats + 1):
            with _stdout_to_stderr():
                lq = GNEP_LQ([game.H] * 3, game.Q, game.c, lb=game.lb.copy(), ub=game.ub.copy(), A=game.A,
                             b=game.b, variational=variational, solver=method)
                t0 = time.perf_counter()
                sol = lq.solve(solver_options=options)
                samples.append(time.perf_counter() - t0)
            if sol is None:
                break
    except Exception as exc:  # a peer's failure is a result, not a crash of the benchmark
        return _checked("nashopt", label, game, equilibrium, None, reference, samples,
                        f"error: {type(exc).__name__}: {exc}"[:200], None, "")
    note = "fresh GNEP_LQ object per call, construction not timed; default options"
    if method == "highs":
        note += f", time limit {MILP_TIME_LIMIT:g} s"
    x = None if sol is None else sol.x
    return _checked("nashopt", label, game, equilibrium, x, reference, samples, _nashopt_status(sol),
                    getattr(sol, "num_iters", None), note)


def _nashopt_general(game: Any, equilibrium: str, repeats: int, reference: np.ndarray | None,
                     solver: str) -> PeerResult:
    """``GNEP(..., variational=...).solve(solver=solver)`` on JAX costs (the stage costs on the condensed states):
    the Fischer-Burmeister KKT system by scipy (``trf``: least_squares; ``hybr``: root). nashopt re-JITs the residual
    and its Jacobian in every call: the time includes it (the note gives the median JIT share)."""
    import jax.numpy as jnp
    from nashopt import GNEP

    from benchmarks.problems.lq import TARGET

    M = [jnp.asarray(m) for m in game.M]
    d = [jnp.asarray(v) for v in game.d]
    A, b = jnp.asarray(game.A), jnp.asarray(game.b)

    def states(z: Any) -> tuple[Any, Any, Any]:
        return M[0] @ z + d[0], M[1] @ z + d[1], M[2] @ z + d[2]

    def f1(z: Any) -> Any:
        x1, x2, _ = states(z)
        return jnp.sum((x1 - TARGET) ** 2 - x1 * x2)

    def f2(z: Any) -> Any:
        x1, x2, _ = states(z)
        return jnp.sum((x2 - TARGET) ** 2 + x1 * x2)

    def f3(z: Any) -> Any:
        return jnp.sum((states(z)[2] - TARGET) ** 2)

    def g(z: Any) -> Any:
        return A @ z - b

    label = f"GNEP (JAX) {solver}"
    samples: list[float] = []
    jit: list[float] = []
    sol = None
    try:
        gnep = GNEP([game.H] * 3, f=[f1, f2, f3], g=g, ng=game.H, lb=game.lb, ub=game.ub,
                    variational=equilibrium == "variational")
        for _ in range(repeats + 1):
            t0 = time.perf_counter()
            sol = gnep.solve(solver=solver, verbose=0)
            samples.append(time.perf_counter() - t0)
            jit.append(sol.stats.jax_jit_time)
    except Exception as exc:
        return _checked("nashopt", label, game, equilibrium, None, reference, samples,
                        f"error: {type(exc).__name__}: {exc}"[:200], None, "")
    note = (f"||KKT residual|| {np.linalg.norm(sol.res):.1e}, {sol.stats.kkt_evals} KKT evaluations; each call "
            f"re-JITs, median JIT {statistics.median(jit[1:] or jit):.3g} s of the call")
    return _checked("nashopt", label, game, equilibrium, sol.x, reference, samples,
                    f"||res|| {np.linalg.norm(sol.res):.1e}", sol.stats.kkt_evals, note)


def lcp_data(game: Any, equilibrium: str) -> tuple[np.ndarray, np.ndarray]:
    """The family's KKT system as an LCP w = M v + q >= 0, v >= 0, v'w = 0, with v = (u - lb, upper-bound multipliers,
    shared multipliers): one shared multiplier per stage (variational) or one per stage and agent (generalized). The
    inputs are ``lb + v[:n]``."""
    n, H = game.n, game.H
    P, q, A = game.P, game.q, game.A
    if equilibrium == "variational":
        rows_sh, cols_sh = A, A.T
    else:  # agent i's stationarity carries its own multipliers; its copy of the constraint rows pairs with them
        cols_sh = np.zeros((n, 3 * H))
        for i in range(3):
            s = game.block(i)
            cols_sh[s, i * H : (i + 1) * H] = A[:, s].T
        rows_sh = np.vstack([A] * 3)
    m_sh = rows_sh.shape[0]
    Mat = np.block([
        [P, np.eye(n), cols_sh],
        [-np.eye(n), np.zeros((n, n)), np.zeros((n, m_sh))],
        [-rows_sh, np.zeros((m_sh, n)), np.zeros((m_sh, m_sh))],
    ])
    b_sh = np.tile(game.b, 1 if equilibrium == "variational" else 3)
    vec = np.concatenate([q + P @ game.lb, game.ub - game.lb, b_sh - rows_sh @ game.lb])
    return Mat, vec


_SICONOS_SCRIPT = r"""
import json, sys, time
import numpy as np
import siconos.numerics as sn

data = json.load(sys.stdin)
M = np.array(data["M"], dtype=float)
q = np.array(data["q"], dtype=float)
out = {}
for name in data["solvers"]:
    times, info, iters, res, z = [], None, None, None, None
    for _ in range(data["repeats"] + 1):
        lcp = sn.LCP(M, q)
        so = sn.SolverOptions(getattr(sn, name))
        so.dparam[sn.SICONOS_DPARAM_TOL] = data["tol"]
        so.iparam[sn.SICONOS_IPARAM_MAX_ITER] = data["max_iter"]
        z, w = np.array(data["z0"], dtype=float), np.zeros(q.size)
        t0 = time.perf_counter()
        info = sn.linearComplementarity_driver(lcp, z, w, so)
        times.append(time.perf_counter() - t0)
        iters, res = so.iparam[sn.SICONOS_IPARAM_ITER_DONE], so.dparam[sn.SICONOS_DPARAM_RESIDU]
    out[name] = {"times": times, "info": int(info), "iterations": int(iters), "residual": float(res),
                 "z": z.tolist()}
print(json.dumps(out))
"""


@functools.cache
def siconos_available() -> bool:
    """Whether Debian's python3-siconos is importable by ``SICONOS_PYTHON``."""
    try:
        done = subprocess.run([SICONOS_PYTHON, "-c", "import siconos.numerics"], capture_output=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return done.returncode == 0


def _siconos(game: Any, equilibrium: str, repeats: int, reference: np.ndarray | None) -> list[PeerResult]:
    """siconos's LCP semismooth Newton methods (min map; min map and Fischer-Burmeister with the FB line search) on
    :func:`lcp_data` from gnerun's start (u = 0, multipliers 0), in Debian's Python through a subprocess; each solve
    is timed inside it (LCP object and options built outside the timing), tolerance 1e-12 on siconos's own residual,
    at most 1000 iterations."""
    M, q = lcp_data(game, equilibrium)
    z0 = np.zeros(q.size)
    z0[: game.n] = -game.lb  # gnerun's start: u = 0, multipliers 0
    payload = {"M": M.tolist(), "q": q.tolist(), "z0": z0.tolist(), "repeats": repeats, "tol": 1e-12,
               "max_iter": 1000, "solvers": [sid for sid, _ in SICONOS_SOLVERS]}
    done = subprocess.run([SICONOS_PYTHON, "-c", _SICONOS_SCRIPT], input=json.dumps(payload), capture_output=True,
                          text=True, timeout=600)
    if done.returncode != 0:
        raise RuntimeError(f"siconos subprocess failed: {done.stderr.strip()[-500:]}")
    out = json.loads(done.stdout.strip().splitlines()[-1])
    results = []
    for sid, label in SICONOS_SOLVERS:
        r = out[sid]
        x = game.lb + np.array(r["z"])[: game.n]
        note = f"LCP of {q.size} unknowns; siconos residual {r['residual']:.1e}; {SICONOS_PYTHON}"
        results.append(_checked("siconos", label, game, equilibrium, x if r["info"] == 0 else None, reference,
                                r["times"], f"info={r['info']}", r["iterations"], note))
    return results


def lq_family_peers(T: int, equilibrium: str, repeats: int = 5, *, siconos: bool = True) -> list[PeerResult]:
    """The peers on the LQ family's problem (T, equilibrium): nashopt's GNEP_LQ by every path that accepts the
    equilibrium, nashopt's general GNEP (JAX; ``trf`` least squares, and for plain GNEs also the default ``hybr``),
    and, when ``siconos`` and Debian's python3-siconos is there, siconos's LCP semismooth Newton methods. Each
    result's solution is checked against the variational reference, or by best-response gaps. Requires nashopt."""
    from benchmarks.problems.lq import EQUILIBRIA, condense

    if equilibrium not in EQUILIBRIA:
        raise ValueError(f"equilibrium must be one of {EQUILIBRIA}, not {equilibrium!r}")
    _import_nashopt()
    game = condense(T)
    reference = _lq_reference(T, equilibrium)
    paths = LQ_VARIATIONAL_PATHS if equilibrium == "variational" else LQ_GENERALIZED_PATHS
    results = [_nashopt_lq(game, method, equilibrium, repeats, reference) for method in paths]
    for solver in ("trf",) if equilibrium == "variational" else ("trf", "hybr"):
        results.append(_nashopt_general(game, equilibrium, repeats, reference, solver))
    if siconos and siconos_available():
        results += _siconos(game, equilibrium, repeats, reference)
    return results


def gnerun_lq(T: int, equilibrium: str, repeats: int = 5, overrides: dict[str, Any] | None = None) -> PeerResult:
    """gnerun on the LQ family's problem, ``gnerun.solve`` with the config's defaults plus ``overrides``: the time is
    the median of ``res.time_s`` (solver time, compile excluded) over ``repeats`` solves after a warm-up solve. An
    exception (e.g. an override the installed gnerun does not know) is a failed result."""
    import gnerun
    from benchmarks.problems.lq import condense, lq_yaml

    label = "default" if not overrides else ", ".join(f"{k.removeprefix('solver.')}={v}" for k, v in overrides.items())
    game = condense(T)
    reference = _lq_reference(T, equilibrium)
    samples: list[float] = []
    try:
        cfg = gnerun.load_config(text=lq_yaml(T, equilibrium), overrides=overrides or {})
        for _ in range(repeats + 1):
            res = gnerun.solve(cfg, out=None)
            samples.append(res.time_s)
    except Exception as exc:
        return _checked("gnerun", label, game, equilibrium, None, reference, [],
                        f"error: {type(exc).__name__}: {exc}"[:200], None, "")
    return _checked("gnerun", label, game, equilibrium, res.z[: res.game.n], reference, samples, res.status,
                    res.iterations, res.message)


def lq_main(repeats: int = 5) -> int:
    """``python -m benchmarks.peers lq [repeats]``: gnerun (default; Fischer-Burmeister with line search) and the
    peers on the whole family, as a markdown table."""
    from benchmarks.problems.lq import EQUILIBRIA, HORIZONS

    fb = {"solver.complementarity": "fischer_burmeister", "solver.globalization": "line_search"}
    print("| T | equilibrium | method | status | iterations | time | success | max abs diff | max gap |")
    print("|---|---|---|---|---|---|---|---|---|")
    for T in HORIZONS:
        for eq in EQUILIBRIA:
            rows = [gnerun_lq(T, eq, repeats), gnerun_lq(T, eq, repeats, fb), *lq_family_peers(T, eq, repeats)]
            for r in rows:
                t = f"{r.time_s * 1e3:.3f} ms" if r.time_s is not None else "-"
                diff = f"{r.max_abs_diff:.1e}" if r.max_abs_diff is not None else "-"
                gap = f"{r.max_gap:.1e}" if r.max_gap is not None else "-"
                print(f"| {T} | {eq} | {r.peer} {r.method} | {r.status} | {r.iterations} | {t} | "
                      f"{'yes' if r.success else '**no**'} | {diff} | {gap} |", flush=True)
    return 0


def main(argv: list[str]) -> int:
    """``python -m benchmarks.peers [T] [repeats]``: print the rows; ``python -m benchmarks.peers lq [repeats]``: the
    LQ family's table. Exit 1 if nashopt is not importable."""
    if not available():
        print("nashopt is not installed (pip install nashopt qpsolvers)", file=sys.stderr)
        return 1
    if argv and argv[0] == "lq":
        return lq_main(int(argv[1]) if len(argv) > 1 else 5)
    T = int(argv[0]) if argv else 10
    repeats = int(argv[1]) if len(argv) > 1 else 5
    for row in peer_rows(T, repeats):
        print(
            f"{row['benchmark']}: gnerun {row['gnerun_s'] * 1e3:.3f} ms, {row['baseline']} "
            f"{row['baseline_s'] * 1e3:.3f} ms, max |du| {row['max_abs_diff']:.1e}\n    {row['note']}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
