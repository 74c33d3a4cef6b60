"""The ring formation of configs/formation_ring.yaml from random initial positions, with a numpy model of it.

N robots (single integrators, RK4 of a constant input is exact), each drawn to its ring neighbour at the polygon's
offset and to its own corner of a goal moving along x; pairwise clearance D shared (a variational GNE). The
model below is written from the config's text alone, without gnerun: each robot's cost, its clearance rows, and its
best response to the others by SLSQP (from the candidate and from three random plans), which is the independent
equilibrium check.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from . import Problem

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "formation_ring.yaml"
RHO, D, SPEED, DT, T, UMAX = 0.8, 0.4, 0.3, 0.1, 10, 1.5


def initial_positions(N: int, count: int, seed: int = 1) -> list[np.ndarray]:
    """``count`` starts: positions uniform in [-1.5, 1.5]^2, redrawn until every two robots are 0.5 apart."""
    rng = np.random.default_rng(seed)
    out: list[np.ndarray] = []
    while len(out) < count:
        x0 = rng.uniform(-1.5, 1.5, 2 * N)
        P = x0.reshape(N, 2)
        if (np.linalg.norm(P[:, None] - P[None], axis=2) + 9 * np.eye(N)).min() > 0.5:
            out.append(x0)
    return out


class FormationModel:
    """Robot i's cost and clearance rows at inputs U[tau, robot] = (ux, uy), tau = 0..T, from x0."""

    def __init__(self, N: int, x0: np.ndarray):
        self.N, self.x0 = N, np.asarray(x0, dtype=float).reshape(N, 2)
        self.angle = 2 * np.pi * np.arange(1, N + 1) / N

    def positions(self, U: np.ndarray) -> np.ndarray:
        """P[tau] = xi(tau + 1): the stage cost is charged on the state its input produces."""
        return self.x0 + DT * np.cumsum(U, axis=0)

    def cost(self, U: np.ndarray, i: int) -> float:
        P, ang, j = self.positions(U), self.angle, (i + 1) % self.N
        t = DT * np.arange(T + 1)  # stage tau's time
        p, q = P[:, i], P[:, j]
        total = ((q[:, 0] - p[:, 0] - RHO * (np.cos(ang[j]) - np.cos(ang[i]))) ** 2
                 + (q[:, 1] - p[:, 1] - RHO * (np.sin(ang[j]) - np.sin(ang[i]))) ** 2
                 + 0.5 * ((p[:, 0] - SPEED * (t + DT) - RHO * np.cos(ang[i])) ** 2
                          + (p[:, 1] - RHO * np.sin(ang[i])) ** 2)
                 + 0.05 * (U[:, i] ** 2).sum(axis=1))
        return float(total.sum())

    def clearances(self, U: np.ndarray, i: int) -> np.ndarray:
        """|p_i - p_j|^2 - D^2 >= 0 for every other robot j at every stage."""
        P = self.positions(U)
        d = P - P[:, i : i + 1]
        return np.delete((d**2).sum(axis=2), i, axis=1).reshape(-1) - D**2

    def plans(self, a: np.ndarray) -> np.ndarray:
        """U from gnerun's decision vector (agent by agent, time-major within an agent: ux, uy per stage)."""
        return np.asarray(a, dtype=float).reshape(self.N, T + 1, 2).transpose(1, 0, 2)

    def best_response_gaps(self, a: np.ndarray, seed: int = 3) -> dict[str, float]:
        """Each robot's cost minus the best SLSQP finds for it (the others held), from its plan and three random
        ones; only answers that keep every clearance count."""
        from scipy.optimize import minimize

        U = self.plans(a)
        rng = np.random.default_rng(seed)
        gaps = {}
        for i in range(self.N):
            def with_own(v: np.ndarray, i: int = i) -> np.ndarray:
                V = U.copy()
                V[:, i] = v.reshape(T + 1, 2)
                return V

            own = self.cost(U, i)
            best = own
            for start in [U[:, i].reshape(-1), *rng.uniform(-UMAX, UMAX, (3, 2 * (T + 1)))]:
                r = minimize(lambda v, i=i: self.cost(with_own(v), i), start, method="SLSQP",
                             bounds=[(-UMAX, UMAX)] * (2 * (T + 1)),
                             constraints=[{"type": "ineq", "fun": lambda v, i=i: self.clearances(with_own(v), i)}],
                             options={"ftol": 1e-12, "maxiter": 500})
                if r.success and (self.clearances(with_own(r.x), i) >= -1e-8).all():
                    best = min(best, float(r.fun))
            gaps[f"robot{i + 1}"] = own - best
        return gaps


def config_yaml(N: int, x0: np.ndarray) -> str:
    """configs/formation_ring.yaml with N robots starting at x0."""
    cfg = yaml.safe_load(CONFIG.read_text())
    cfg["game"]["parameters"]["N"] = N
    cfg["game"]["x0"] = [float(v) for v in x0]
    return yaml.safe_dump(cfg, sort_keys=False, width=1000)


def formation_problems(count: int = 30, seed: int = 1, N: int = 6) -> list[Problem]:
    """The ring formation of ``N`` robots from ``count`` random starts (zero inputs)."""
    out = []
    for k, x0 in enumerate(initial_positions(N, count, seed)):
        model = FormationModel(N, x0)
        out.append(Problem(
            family="formation", name=f"ring formation N={N} #{k}", start=f"u = 0; x0 = draw {k} of seed {seed}",
            config_yaml=config_yaml(N, x0), best_response_gaps=model.best_response_gaps,
            notes="configs/formation_ring.yaml; nonconvex clearance rows, no unique equilibrium (no reference)"))
    return out
