"""The affine VI of an LQ game solved in one step (gnerun/solvers/avi.py): solutions against closed forms and the LQ
family's independent references, the multipliers' signs and scales, the games that have no such VI."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.problems import fk, lq
from gnerun.game.compile import compile_game
from gnerun.language.config import load_config
from gnerun.runs.solving import solve
from gnerun.solvers.avi import AffineVI
from gnerun.solvers.ssn import SemismoothNewton

from .conftest import CONFIGS


def _point(game):
    vi = AffineVI.of(game)
    assert vi is not None
    return vi.point(game.lq.offsets(game.x0), game.size)


def _phi_norm(cfg, game, z) -> float:
    newton = SemismoothNewton(game, cfg.solver)
    phi, _ = newton.phi(*game.kkt_residual(z, game.x0), z)
    return float(np.linalg.norm(phi))


@pytest.mark.parametrize("equilibrium", lq.EQUILIBRIA)
@pytest.mark.parametrize("T", [5, 20])
def test_the_lq_family_is_solved_in_one_step(T: int, equilibrium: str) -> None:
    """The variational equilibrium against the family's references (nashopt's DR-DAQP and an extragradient method,
    stored); the plain GNE's copies of the shared row merged: its solution is the variational one, a GNE whose
    copies carry equal multipliers."""
    cfg = load_config(text=lq.lq_yaml(T, equilibrium))
    game = compile_game(cfg)
    z = _point(game)
    assert _phi_norm(cfg, game, z) <= 1e-10
    np.testing.assert_allclose(z[: game.n], lq.REFERENCES[T], atol=1e-8)
    if equilibrium == "generalized":
        shared = [j for j, info in enumerate(game.constraints) if "x1 + x2 + x3" in info.label]
        by_stage: dict[int, list[float]] = {}
        for j in shared:
            by_stage.setdefault(game.constraints[j].stage, []).append(z[game.n + j])
        assert all(len(v) == 3 and np.ptp(v) <= 1e-12 for v in by_stage.values())
        assert max(max(v) for v in by_stage.values()) > 0.1  # the shared row binds


# p1 wants x1 = 4 under 2 x1 <= 3 (a row with coefficient 2 beside its upper bound: x1 = 3/2, multiplier 5/2); p2
# wants x2 = -3.075 under -3 x2 <= 3 (x2 >= -1 as a row with coefficient -3 beside its lower bound: multiplier
# 4.15/3) and has a second, slack upper row on x2 beside its upper bound; p3 minimises x3 + (x3 - x2)^2 at its lower
# bound 0 (multiplier 1 + 2 = 3)
ROWS = """
name: rows
game:
  kind: static
  agents:
    - name: p1
      variables: {x1: {lower: 0, upper: 10}}
      cost: "(x1 - 4)**2"
      constraints: ["2*x1 <= 3"]
    - name: p2
      variables: {x2: {lower: -5, upper: 4}}
      cost: "(x2 + 3)**2 + 0.1*x1*x2"
      constraints: ["-3*x2 <= 3", "x2 <= 2"]
    - name: p3
      variables: {x3: {lower: 0, upper: 1}}
      cost: "x3 + (x3 - x2)**2"
"""


def test_multipliers_have_the_signs_and_scales_of_their_rows() -> None:
    cfg = load_config(text=ROWS)
    game = compile_game(cfg)
    z = _point(game)
    assert _phi_norm(cfg, game, z) <= 1e-12
    a, lam = z[: game.n], dict(zip((c.label for c in game.constraints), z[game.n :], strict=True))
    np.testing.assert_allclose(a, [1.5, -1.0, 0.0], atol=1e-12)
    expected = {"2*x1 <= 3": 2.5, "-3*x2 <= 3": 4.15 / 3, "x3 >= 0": 3.0}
    for label, value in lam.items():
        assert value == pytest.approx(expected.get(label, 0.0), abs=1e-12), label


def test_equality_rows_have_free_multipliers() -> None:
    # variational: 2 (x1 - 1) + mu = 0, 2 (x2 - 2) + mu = 0, x1 + x2 = 1: x = (0, 1), mu = 2
    text = """
name: eq
game:
  kind: static
  agents:
    - {name: p1, variables: {x1: {}}, cost: "(x1 - 1)**2"}
    - {name: p2, variables: {x2: {}}, cost: "(x2 - 2)**2"}
  shared_constraints: ["x1 + x2 == 1"]
  equilibrium: variational
"""
    cfg = load_config(text=text)
    game = compile_game(cfg)
    z = _point(game)
    np.testing.assert_allclose(z, [0.0, 1.0, 2.0], atol=1e-10)
    res = solve(cfg)
    assert res.status == "converged" and res.iterations == 1


def test_a_plain_gne_with_copies_is_solved_at_its_variational_point() -> None:
    # FK A.11 as a plain GNE: a continuum of equilibria; the merged copies give the variational one, (3/4, 1/4)
    cfg = load_config(CONFIGS / "fk_a11.yaml", {"game.equilibrium": "generalized"})
    game = compile_game(cfg)
    z = _point(game)
    np.testing.assert_allclose(z[:2], [0.75, 0.25], atol=1e-12)
    assert z[2] == pytest.approx(z[3], abs=1e-14) and z[2] > 0
    res = solve(cfg)
    assert res.status == "converged" and res.iterations == 1
    assert max(res.certificate["best_response_gap"].values()) <= 1e-9


def test_games_without_such_a_vi_have_none() -> None:
    # the paper's game: agent 3 alone carries u3 >= u1 + u2 (a row coupling agents, not shared)
    assert AffineVI.of(compile_game(load_config(CONFIGS / "paper_study1.yaml"))) is None
    # a nonlinear game
    assert AffineVI.of(compile_game(load_config(CONFIGS / "nonlinear_gne.yaml"))) is None
    # a row shared by two carriers that involves a third player's decision: its copies miss that part
    text = """
name: subset
game:
  kind: static
  agents:
    - {name: p1, variables: {x1: {}}, cost: "(x1 - 1)**2"}
    - {name: p2, variables: {x2: {}}, cost: "(x2 - 1)**2"}
    - {name: p3, variables: {x3: {}}, cost: "(x3 - 1)**2"}
  shared_constraints: [{expr: "x1 + x2 + x3 <= 1", agents: [p1, p2]}]
  equilibrium: generalized
"""
    assert AffineVI.of(compile_game(load_config(text=text))) is None
    # (also in a variational game: the common multiplier enters p1's and p2's stationarity only); carried by all
    # three, the copies make up the whole row
    assert AffineVI.of(compile_game(load_config(text=text.replace("generalized", "variational")))) is None
    assert AffineVI.of(compile_game(load_config(text=text.replace(", agents: [p1, p2]", "")))) is not None
    # larger than the measured break-even size
    assert AffineVI.of(compile_game(load_config(text=lq.lq_yaml(40, "variational")))) is None


def test_no_solution_is_none_and_the_default_goes_on() -> None:
    # FK A.8: the VI on the joint set has no solution (no variational equilibrium); the default solves the plain GNE
    problem = next(p for p in fk.problems() if p.name == "A.8" and p.start == "x0 = 0")
    cfg = load_config(text=problem.config_yaml)
    game = compile_game(cfg)
    vi = AffineVI.of(game)
    assert vi is None or vi.point(game.lq.offsets(game.x0), game.size) is None
    assert solve(cfg).status == "converged"
    # an empty feasible set
    text = """
name: empty
game:
  kind: static
  agents:
    - {name: p1, variables: {x1: {lower: 1}}, cost: "(x1 - 1)**2", constraints: ["x1 <= 0"]}
    - {name: p2, variables: {x2: {}}, cost: "(x2 - x1)**2"}
"""
    game = compile_game(load_config(text=text))
    assert AffineVI.of(game).point(game.lq.offsets(game.x0), game.size) is None
    # a player whose cost is linear in its own decision (P singular): DAQP returns no finite point
    cfg = load_config(text=ROWS.replace("(x1 - 4)**2", "-x1"))
    game = compile_game(cfg)
    assert AffineVI.of(game).point(game.lq.offsets(game.x0), game.size) is None
    assert solve(cfg).status == "converged"
