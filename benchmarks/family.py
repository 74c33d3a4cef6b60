"""A scalable family generalising the paper's game: N agents, scalar dynamics, neighbour-coupled costs and
coupled constraints, horizon T.

Agent i owns state s_i and input u_i, s_i(t+1) = rho_i s_i(t) + u_i(t), and minimises

    sum_tau (s_i - r_i)^2 + 0.5 (s_i - s_{i+1})^2 + 0.1 u_i^2      (indices modulo N: a ring)

subject to -1 <= u_i <= 1 and its own coupled constraint u_i + u_{i+1} <= 1.2 (a generalized Nash game:
agent i's feasible set depends on its neighbour's input). N = 3 has the paper's shape: three agents,
diagonal dynamics, coupled costs through the states, one coupled constraint each.
"""

from __future__ import annotations

from gnerun.language.config import Config, load_config


def family_yaml(N: int, T: int) -> str:
    states = [f"s{i + 1}" for i in range(N)]
    rho = [0.5 + 0.4 * i / max(N - 1, 1) for i in range(N)]
    A = [[rho[i] if i == j else 0.0 for j in range(N)] for i in range(N)]
    lines = [
        f"name: family-N{N}-T{T}",
        "game:",
        "  kind: dynamic",
        f"  horizon: {T}",
        f"  states: [{', '.join(states)}]",
        "  dynamics:",
        f"    A: {A}",
        f"    B: {[[1.0 if i == j else 0.0 for j in range(N)] for i in range(N)]}",
        f"  x0: {[float(1 + (2 * i) % 5) for i in range(N)]}",
        "  agents:",
    ]
    for i in range(N):
        nxt = (i + 1) % N
        r = 1.0 + 0.5 * (i % 3)
        lines += [
            f"    - name: agent{i + 1}",
            f"      inputs: {{u{i + 1}: {{lower: -1, upper: 1}}}}",
            f"      stage_cost: \"(s{i + 1} - {r})**2 + 0.5*(s{i + 1} - s{nxt + 1})**2 + 0.1*u{i + 1}**2\"",
            f"      constraints: [\"u{i + 1} + u{nxt + 1} <= 1.2\"]",
        ]
    lines += [
        "solver:",
        "  kind: ssn",
        "  complementarity: min",
        "  tol: 1.0e-10",
        "  max_iter: 50",
    ]
    return "\n".join(lines) + "\n"


def family_config(N: int, T: int) -> Config:
    return load_config(text=family_yaml(N, T))
