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
"""

from __future__ import annotations

import importlib.util
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
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
    from gnerun.game.compile import compile_game
    from gnerun.language.config import load_config
    from gnerun.runs.solving import make_solver

    cfg = load_config(CONFIG, {"solver.kind": "ssn", "game.horizon": T})
    game = compile_game(cfg)
    solver = make_solver(cfg, game)

    def run() -> Any:
        state = solver.init()
        while not solver.terminate(state)[0]:
            state = solver.step(state)
        return state

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


def main(argv: list[str]) -> int:
    """``python -m benchmarks.peers [T] [repeats]``: print the rows; exit 1 if nashopt is not importable."""
    if not available():
        print("nashopt is not installed (pip install nashopt qpsolvers)", file=sys.stderr)
        return 1
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
