"""The solver a config asks for: its kind, formulation (condensed or sparse) and globalization, built on a
compiled game."""

from __future__ import annotations

from ..game.compile import CompiledGame
from ..game.condensed import condensed_kernels
from ..game.sparse import sparse_system
from ..language.config import Config, sparse_obstacles
from ..threads import single_threaded_blas
from .driver import Solver
from .globalization import globalized
from .josephy_newton import JosephyNewton
from .proximal_response import ProximalResponse
from .sparse_ssn import SparseSemismoothNewton
from .ssn import SemismoothNewton


def make_solver(cfg: Config, game: CompiledGame, *, disturbed: bool = True) -> Solver:
    """The solver the config asks for (``solver.kind``, ``solver.globalization``), with its disturbance model
    (unless not ``disturbed``). Asks for one BLAS thread (:mod:`gnerun.threads`)."""
    single_threaded_blas()
    disturbance = cfg.disturbance if disturbed else None
    if cfg.solver.kind != "ssn":
        condensed_kernels(cfg, game)  # says why nothing is compiled
    if cfg.solver.kind == "distributed":
        return ProximalResponse(cfg if disturbed else cfg.model_copy(update={"disturbance": type(cfg.disturbance)()}),
                                game)
    if cfg.solver.kind == "jn":
        return JosephyNewton(game, cfg.solver, disturbance)
    if formulation(cfg, game) == "sparse":
        newton: SemismoothNewton = SparseSemismoothNewton(game, cfg.solver, disturbance, sparse_system(cfg, game))
    else:
        condensed_kernels(cfg, game)  # the condensed KKT function compiled, where solver.compile asks for it
        newton = SemismoothNewton(game, cfg.solver, disturbance)
    return globalized(newton)


# auto, nonlinear dynamics: the sparse formulation once the condensed system's size times the number of stages,
# U (T + 1), reaches SPARSE_WORK: the condensed derivatives are dense and nest through the dynamics (their cost grows
# with both), the sparse system's grow with T alone, and its stage kernels are compiled, its matrices banded.
# Measured per iteration, condensed / sparse (second solve from the config's x0, best of 3; this machine,
# OPENBLAS_NUM_THREADS=1, loaded): the 41-knot MPC merge at T = 9 and 19 (U (T + 1) = 1,500 and 6,000) 2.80, 3.35;
# algames_merge_n at N = 2 and 3 (3,600 and 6,000) 2.75, 1.39; tracking (2,646) 2.84; two vehicles at T = 10 and 20
# (1,573 and 5,733) 1.09, 1.69; the intersection (27,200) 5.07; the overtaking game (1,521) 0.90, the one case
# measured where the condensed form is faster. (Before the stage kernels and the banded LU the crossover was 20,000.)
# Linear dynamics: from SPARSE_FROM unknowns, the measured crossover of LQ games, whose condensed matrices are
# constant (no evaluation, factorisations kept per active set): the bounded LQ family's plain GNE at T = 40 (492
# unknowns, 20,000 by the other measure) takes 0.23 s sparse against 16 ms condensed through its interior phase.
SPARSE_WORK = 1_000
SPARSE_FROM = 800


def formulation(cfg: Config, game: CompiledGame) -> str:
    """The formulation a solve uses: the config's choice, or for ``auto`` sparse where it applies and the
    condensed system is large: ``SPARSE_FROM`` unknowns with linear dynamics, ``SPARSE_WORK`` unknowns times stages
    with nonlinear ones."""
    chosen = cfg.solver.formulation
    if chosen != "auto":
        return chosen
    if sparse_obstacles(cfg):
        return "condensed"
    if game.lq.linear_dynamics:
        return "sparse" if game.size >= SPARSE_FROM else "condensed"
    return "sparse" if game.size * ((game.horizon or 0) + 1) >= SPARSE_WORK else "condensed"
