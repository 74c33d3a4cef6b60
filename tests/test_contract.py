"""The solver contract: every solver kind x globalization x formulation x complementarity that applies, on the FK
library's pairs and the bounded LQ family, ends with the status of one table (scipy's KNOWN_BAD): converged unless
listed in ``KNOWN_BAD`` (refused: the solver refuses the game with the reason, an ``InputError``). A converged solve
has ||Phi|| <= tol and lands on the literature's solution where it is isolated and known (``ELSEWHERE``: the
known exceptions), and a solve never takes more than max_iter iterations.

The grid and the solves are benchmarks/identical.py's (the identity check of refactorings runs the same cases).
"""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.identical import Case, _label, solve, solver_grid
from benchmarks.problems import fk, lq
from gnerun.language.config import load_config

PROBLEMS = fk.problems() + lq.lq_problems()
# their grids take 2 to 30 s each (the rest: 7 s together)
SLOW = ("A.10b", "A.10c", "A.10d", "A.10e", "LQ T=40 generalized")

# converged to another solution than the literature's (A.3 has several from x0 = 10 under Fischer-Burmeister)
ELSEWHERE = {("A.3 x0 = 10", ("ssn", glob, "fischer_burmeister", "condensed"))
             for glob in ("auto", "hybrid", "line_search", "none")}

KNOWN_BAD: dict[tuple[str, ...], dict[str, list[str]]] = {
    ('jn', 'auto'): {
        'refused': [
            'A.1 x0 = 0.01', 'A.1 x0 = 0.1', 'A.1 x0 = 1', 'A.2 x0 = 0.01', 'A.2 x0 = 0.1', 'A.2 x0 = 1', 'A.3 x0 = 0',
            'A.3 x0 = 1', 'A.3 x0 = 10', 'A.4 x0 = 0', 'A.4 x0 = 1', 'A.4 x0 = 10', 'A.5 x0 = 0', 'A.5 x0 = 1',
            'A.5 x0 = 10', 'A.6 x0 = 0', 'A.6 x0 = 1', 'A.6 x0 = 10', 'A.7 x0 = 0', 'A.7 x0 = 1', 'A.7 x0 = 10',
            'A.8 x0 = 0', 'A.8 x0 = 1', 'A.8 x0 = 10', 'A.9a x0 = 0', 'A.9b x0 = 0', 'A.10a x0 = y = 0, x = 0, p = 1/P',
            'A.10b x0 = y = 0, x = 0, p = 1/P', 'A.10c x0 = y = 0, x = 0, p = 1/P', 'A.10d x0 = y = 0, x = 0, p = 1/P',
            'A.10e x0 = y = 0, x = 0, p = 1/P', 'A.11 x0 = 0', 'A.13 x0 = 0', 'A.14 x0 = 0.01', 'A.16 (P = 75) x0 = 10',
            'A.16 (P = 100) x0 = 10', 'A.16 (P = 150) x0 = 10', 'A.16 (P = 200) x0 = 10', 'A.17 x0 = 0', 'A.18 x0 = 0',
            'A.18 x0 = 1', 'A.18 x0 = 10', 'LQ T=5 generalized u = 0, lambda = 0',
            'LQ T=20 generalized u = 0, lambda = 0', 'LQ T=40 generalized u = 0, lambda = 0',
        ],
    },
    ('jn', 'none'): {
        'refused': [
            'A.1 x0 = 0.01', 'A.1 x0 = 0.1', 'A.1 x0 = 1', 'A.2 x0 = 0.01', 'A.2 x0 = 0.1', 'A.2 x0 = 1', 'A.3 x0 = 0',
            'A.3 x0 = 1', 'A.3 x0 = 10', 'A.4 x0 = 0', 'A.4 x0 = 1', 'A.4 x0 = 10', 'A.5 x0 = 0', 'A.5 x0 = 1',
            'A.5 x0 = 10', 'A.6 x0 = 0', 'A.6 x0 = 1', 'A.6 x0 = 10', 'A.7 x0 = 0', 'A.7 x0 = 1', 'A.7 x0 = 10',
            'A.8 x0 = 0', 'A.8 x0 = 1', 'A.8 x0 = 10', 'A.9a x0 = 0', 'A.9b x0 = 0', 'A.10a x0 = y = 0, x = 0, p = 1/P',
            'A.10b x0 = y = 0, x = 0, p = 1/P', 'A.10c x0 = y = 0, x = 0, p = 1/P', 'A.10d x0 = y = 0, x = 0, p = 1/P',
            'A.10e x0 = y = 0, x = 0, p = 1/P', 'A.11 x0 = 0', 'A.13 x0 = 0', 'A.14 x0 = 0.01', 'A.16 (P = 75) x0 = 10',
            'A.16 (P = 100) x0 = 10', 'A.16 (P = 150) x0 = 10', 'A.16 (P = 200) x0 = 10', 'A.17 x0 = 0', 'A.18 x0 = 0',
            'A.18 x0 = 1', 'A.18 x0 = 10', 'LQ T=5 generalized u = 0, lambda = 0',
            'LQ T=20 generalized u = 0, lambda = 0', 'LQ T=40 generalized u = 0, lambda = 0',
        ],
    },
    ('distributed', 'auto'): {
        'diverged': [
            'A.1 x0 = 0.01', 'A.1 x0 = 0.1', 'A.1 x0 = 1', 'A.2 x0 = 0.01', 'A.2 x0 = 0.1', 'A.2 x0 = 1', 'A.3 x0 = 10',
            'A.8 x0 = 0', 'A.8 x0 = 1', 'A.8 x0 = 10', 'A.13 x0 = 0', 'A.14 x0 = 0.01', 'A.16 (P = 75) x0 = 10',
            'A.16 (P = 100) x0 = 10',
        ],
        'max_iter': [
            'A.3 x0 = 0', 'A.3 x0 = 1', 'A.10a x0 = y = 0, x = 0, p = 1/P', 'A.10b x0 = y = 0, x = 0, p = 1/P',
            'A.10c x0 = y = 0, x = 0, p = 1/P', 'A.10d x0 = y = 0, x = 0, p = 1/P', 'A.10e x0 = y = 0, x = 0, p = 1/P',
            'A.15 x0 = 0', 'A.16 (P = 150) x0 = 10', 'A.16 (P = 200) x0 = 10', 'A.17 x0 = 0', 'A.18 x0 = 0',
            'A.18 x0 = 1', 'A.18 x0 = 10', 'LQ T=5 generalized u = 0, lambda = 0',
            'LQ T=20 generalized u = 0, lambda = 0', 'LQ T=40 generalized u = 0, lambda = 0',
        ],
        'refused': [
            'LQ T=5 variational u = 0, lambda = 0', 'LQ T=20 variational u = 0, lambda = 0',
            'LQ T=40 variational u = 0, lambda = 0',
        ],
    },
    ('distributed', 'none'): {
        'singular_jacobian': [
            'A.1 x0 = 0.01', 'A.1 x0 = 0.1', 'A.1 x0 = 1', 'A.2 x0 = 0.01', 'A.2 x0 = 0.1', 'A.2 x0 = 1', 'A.3 x0 = 10',
            'A.4 x0 = 10', 'A.6 x0 = 0', 'A.6 x0 = 1', 'A.6 x0 = 10', 'A.7 x0 = 1', 'A.7 x0 = 10', 'A.8 x0 = 0',
            'A.8 x0 = 1', 'A.8 x0 = 10', 'A.10c x0 = y = 0, x = 0, p = 1/P', 'A.10e x0 = y = 0, x = 0, p = 1/P',
            'A.13 x0 = 0', 'A.14 x0 = 0.01', 'A.17 x0 = 0', 'A.18 x0 = 0', 'A.18 x0 = 1', 'A.18 x0 = 10',
            'LQ T=5 generalized u = 0, lambda = 0', 'LQ T=20 generalized u = 0, lambda = 0',
            'LQ T=40 generalized u = 0, lambda = 0',
        ],
        'max_iter': [
            'A.3 x0 = 0', 'A.3 x0 = 1', 'A.10a x0 = y = 0, x = 0, p = 1/P', 'A.10b x0 = y = 0, x = 0, p = 1/P',
            'A.10d x0 = y = 0, x = 0, p = 1/P', 'A.15 x0 = 0', 'A.16 (P = 150) x0 = 10', 'A.16 (P = 200) x0 = 10',
        ],
        'nan': [
            'A.9a x0 = 0', 'A.16 (P = 75) x0 = 10', 'A.16 (P = 100) x0 = 10',
        ],
        'refused': [
            'LQ T=5 variational u = 0, lambda = 0', 'LQ T=20 variational u = 0, lambda = 0',
            'LQ T=40 variational u = 0, lambda = 0',
        ],
    },
    ('ssn', 'line_search', 'min', 'condensed'): {
        'singular_jacobian': [
            'A.1 x0 = 1', 'A.2 x0 = 0.01', 'A.2 x0 = 0.1', 'A.2 x0 = 1', 'A.3 x0 = 10', 'A.4 x0 = 10', 'A.6 x0 = 0',
            'A.6 x0 = 1', 'A.6 x0 = 10', 'A.7 x0 = 10', 'A.8 x0 = 0', 'A.8 x0 = 1', 'A.8 x0 = 10', 'A.9a x0 = 0',
            'A.9b x0 = 0', 'A.10a x0 = y = 0, x = 0, p = 1/P', 'A.10b x0 = y = 0, x = 0, p = 1/P',
            'A.10c x0 = y = 0, x = 0, p = 1/P', 'A.10d x0 = y = 0, x = 0, p = 1/P', 'A.10e x0 = y = 0, x = 0, p = 1/P',
            'A.11 x0 = 0', 'A.13 x0 = 0', 'A.16 (P = 75) x0 = 10', 'A.16 (P = 100) x0 = 10', 'A.16 (P = 150) x0 = 10',
            'A.16 (P = 200) x0 = 10', 'A.17 x0 = 0', 'A.18 x0 = 0', 'A.18 x0 = 1', 'A.18 x0 = 10',
            'LQ T=5 variational u = 0, lambda = 0', 'LQ T=5 generalized u = 0, lambda = 0',
            'LQ T=20 variational u = 0, lambda = 0', 'LQ T=20 generalized u = 0, lambda = 0',
            'LQ T=40 variational u = 0, lambda = 0', 'LQ T=40 generalized u = 0, lambda = 0',
        ],
    },
    ('ssn', 'none', 'min', 'condensed'): {
        'singular_jacobian': [
            'A.1 x0 = 1', 'A.2 x0 = 0.01', 'A.2 x0 = 0.1', 'A.2 x0 = 1', 'A.3 x0 = 10', 'A.4 x0 = 10', 'A.6 x0 = 0',
            'A.6 x0 = 1', 'A.6 x0 = 10', 'A.7 x0 = 10', 'A.8 x0 = 0', 'A.8 x0 = 1', 'A.8 x0 = 10', 'A.9a x0 = 0',
            'A.9b x0 = 0', 'A.10a x0 = y = 0, x = 0, p = 1/P', 'A.10b x0 = y = 0, x = 0, p = 1/P',
            'A.10c x0 = y = 0, x = 0, p = 1/P', 'A.10d x0 = y = 0, x = 0, p = 1/P', 'A.10e x0 = y = 0, x = 0, p = 1/P',
            'A.11 x0 = 0', 'A.13 x0 = 0', 'A.16 (P = 75) x0 = 10', 'A.16 (P = 100) x0 = 10', 'A.16 (P = 150) x0 = 10',
            'A.16 (P = 200) x0 = 10', 'A.17 x0 = 0', 'A.18 x0 = 0', 'A.18 x0 = 1', 'A.18 x0 = 10',
            'LQ T=5 variational u = 0, lambda = 0', 'LQ T=5 generalized u = 0, lambda = 0',
            'LQ T=20 variational u = 0, lambda = 0', 'LQ T=20 generalized u = 0, lambda = 0',
            'LQ T=40 variational u = 0, lambda = 0', 'LQ T=40 generalized u = 0, lambda = 0',
        ],
    },
    ('ssn', 'line_search', 'fischer_burmeister', 'condensed'): {
        'singular_jacobian': [
            'A.2 x0 = 0.1', 'A.8 x0 = 1', 'A.8 x0 = 10', 'A.13 x0 = 0', 'A.16 (P = 75) x0 = 10',
            'A.16 (P = 100) x0 = 10', 'A.18 x0 = 0', 'A.18 x0 = 1', 'A.18 x0 = 10',
            'LQ T=5 generalized u = 0, lambda = 0', 'LQ T=20 generalized u = 0, lambda = 0',
            'LQ T=40 generalized u = 0, lambda = 0',
        ],
        'line_search_failed': [
            'A.6 x0 = 10', 'A.8 x0 = 0', 'A.10b x0 = y = 0, x = 0, p = 1/P', 'A.10d x0 = y = 0, x = 0, p = 1/P',
        ],
        'max_iter': [
            'A.10e x0 = y = 0, x = 0, p = 1/P',
        ],
    },
    ('ssn', 'none', 'fischer_burmeister', 'condensed'): {
        'singular_jacobian': [
            'A.2 x0 = 0.1', 'A.4 x0 = 1', 'A.6 x0 = 10', 'A.8 x0 = 0', 'A.8 x0 = 1', 'A.8 x0 = 10',
            'A.10b x0 = y = 0, x = 0, p = 1/P', 'A.10d x0 = y = 0, x = 0, p = 1/P', 'A.10e x0 = y = 0, x = 0, p = 1/P',
            'A.13 x0 = 0', 'A.16 (P = 75) x0 = 10', 'A.16 (P = 100) x0 = 10', 'A.18 x0 = 0', 'A.18 x0 = 1',
            'A.18 x0 = 10', 'LQ T=5 generalized u = 0, lambda = 0', 'LQ T=20 generalized u = 0, lambda = 0',
            'LQ T=40 generalized u = 0, lambda = 0',
        ],
        'max_iter': [
            'A.4 x0 = 10',
        ],
        'nan': [
            'A.9a x0 = 0',
        ],
    },
    ('ssn', 'interior_point', 'min', 'condensed'): {
        'diverged': [
            'A.10c x0 = y = 0, x = 0, p = 1/P',
        ],
    },
    ('ssn', 'interior_point', 'fischer_burmeister', 'condensed'): {
        'diverged': [
            'A.10c x0 = y = 0, x = 0, p = 1/P',
        ],
    },
    ('ssn', 'line_search', 'min', 'sparse'): {
        'singular_jacobian': [
            'LQ T=5 variational u = 0, lambda = 0', 'LQ T=5 generalized u = 0, lambda = 0',
            'LQ T=20 variational u = 0, lambda = 0', 'LQ T=20 generalized u = 0, lambda = 0',
            'LQ T=40 variational u = 0, lambda = 0', 'LQ T=40 generalized u = 0, lambda = 0',
        ],
    },
    ('ssn', 'none', 'min', 'sparse'): {
        'singular_jacobian': [
            'LQ T=5 variational u = 0, lambda = 0', 'LQ T=5 generalized u = 0, lambda = 0',
            'LQ T=20 variational u = 0, lambda = 0', 'LQ T=20 generalized u = 0, lambda = 0',
            'LQ T=40 variational u = 0, lambda = 0', 'LQ T=40 generalized u = 0, lambda = 0',
        ],
    },
}


def _contract(problem) -> list[str]:
    name = f"{problem.name} {problem.start}"
    games: dict = {}
    broken = []
    for options in solver_grid(problem.family == "lq"):
        if any(k.startswith("disturbance") for k in options):
            continue
        key = tuple(options.values())
        expected = next((s for s, names in KNOWN_BAD.get(key, {}).items() if name in names), "converged")
        result = solve(Case(problem.family, name, _label(options), problem.config_yaml, options), games)
        status = "refused" if result["status"] == "error: InputError" else result["status"]
        if status != expected:
            broken.append(f"{key}: {status} (expected {expected}): {result['message']}")
            continue
        if status == "refused":
            continue
        solver = load_config(text=problem.config_yaml, overrides=options).solver
        residual = result["residuals"][-1]
        if status == "converged":
            a = result["z"][: problem.reference.size] if problem.reference is not None else None
            if not residual <= solver.tol:
                broken.append(f"{key}: converged at ||Phi|| = {residual:.1e}")
            elif a is not None and (name, key) not in ELSEWHERE and not np.max(
                    np.abs(a - problem.reference)) <= problem.reference_tol:
                broken.append(f"{key}: converged {np.max(np.abs(a - problem.reference)):.1e} from the literature's "
                              "solution")
        elif not result["message"]:
            broken.append(f"{key}: {status} without a message")
        if result["k"] > solver.max_iter:
            broken.append(f"{key}: {result['k']} iterations (max_iter {solver.max_iter})")
    return broken


@pytest.mark.parametrize("problem", [
    pytest.param(p, id=f"{p.name} {p.start}", marks=[pytest.mark.slow] if p.name.startswith(SLOW) else [])
    for p in PROBLEMS])
def test_every_solver_meets_its_table(problem):
    broken = _contract(problem)
    assert not broken, "\n".join(broken)


def test_the_table_names_known_cases():
    names = {f"{p.name} {p.start}" for p in PROBLEMS}
    for key, table in KNOWN_BAD.items():
        for status, listed in table.items():
            assert set(listed) <= names, (key, status, set(listed) - names)
