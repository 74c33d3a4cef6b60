"""The Facchinei–Kanzow GNEP test library (Examples A.1–A.18) as gnerun static-game configs.

Source of the problem statements: F. Facchinei and C. Kanzow, "Penalty methods for the solution of generalized
Nash equilibrium problems (with complete test problems)", technical report, Sapienza University of Rome, 2009,
Appendix A (the library of SIAM J. Optim. 20(5), 2010). Start points: the library's standard ones, used by
FK 2010 and by A. Dreves, F. Facchinei, C. Kanzow and S. Sagratella, SIAM J. Optim. 21(3), 2011: A.1, A.2 from
x0 = 0.01, 0.1, 1 (every component); A.3–A.8 from 0, 1, 10; A.9a/b from 0; A.10a–e from y = 0, x = 0,
p = 1/P; A.11 from 0; A.12 from (2, 0); A.13 from 0; A.14 from 0.01; A.15 from 0; A.16 (P = 75, 100, 150,
200) from 10; A.17 from 0; A.18 from 0, 1, 10 -- 44 problem/start pairs.

Every problem is written twice, independently:

* as gnerun expressions (``config_yaml``: costs, bounds, each player's own constraints, and the constraints that
  every player carries as ``shared_constraints`` with ``equilibrium: generalized``, i.e. the concatenated KKT
  system of the GNEP as Dreves et al. solve it), generated from the published data below;
* in numpy (``_Game.cost`` and ``_Game.cons``, vectorised over a trailing axis so that complex-step derivatives
  are exact), which never goes through gnerun's parser.

From the numpy writing alone the module computes best-response gaps (SciPy SLSQP, several starts) and the
references (a Newton / least-squares solve of the Fischer–Burmeister form of the concatenated KKT system, then
the gap check): ``compute_references()`` recomputes what ``_REFERENCES`` stores. No iteration counts of the
publications are recorded (``Problem.published`` is empty).

The data follow the report's appendix. They were cross-checked against public transcriptions: the GNEkit
collection (documentation and code, all problems), P. Krupa's A.3 script for nashopt, a Julia GNEP collection
(A.8, A.11, A.13, A.17) and MacMPEC's gnash models (the firm data of A.16). Where these disagree with each other
or with the report's own data, the report's definitions are followed and the choice is commented at the problem.
The approximate solutions printed with the problems (``printed``) are penalty-method points of the report; where
they differ from the exact solutions by more than rounding, the problem's notes say so.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize

from . import Problem

CostFn = Callable[[int, np.ndarray], np.ndarray]
ConsFn = Callable[[int, np.ndarray], np.ndarray]

FK = "Facchinei-Kanzow 2009"

# --------------------------------------------------------------------------------------------------------------
# expression builders (the gnerun writing)
# --------------------------------------------------------------------------------------------------------------


def _num(c: float) -> str:
    """Shortest round-trip text of a number; integers without a decimal point."""
    c = float(c)
    if c == int(c) and abs(c) < 1e15:
        return str(int(c))
    return repr(c)


def _sum(terms: Sequence[tuple[float | str, str]], const: float = 0.0) -> str:
    """``c1*t1 + c2*t2 + ... + const``; a coefficient may be an expression (then parenthesised)."""
    parts: list[tuple[str, str]] = []
    for c, t in terms:
        if isinstance(c, str):
            parts.append(("+", f"({c})*{t}"))
            continue
        if c == 0:
            continue
        mag = abs(c)
        parts.append(("-" if c < 0 else "+", t if mag == 1 else f"{_num(mag)}*{t}"))
    if const != 0 or not parts:
        parts.append(("-" if const < 0 else "+", _num(abs(const))))
    text = ("-" if parts[0][0] == "-" else "") + parts[0][1]
    for sign, t in parts[1:]:
        text += f" {sign} {t}"
    return text


def _total(names: Sequence[str]) -> str:
    return "(" + " + ".join(names) + ")"


def _quad_terms(A: np.ndarray | list, x: Sequence[str]) -> list[tuple[float | str, str]]:
    """Terms of 1/2 x^T A x for symmetric A (entries may be expressions)."""
    out: list[tuple[float | str, str]] = []
    n = len(x)
    for i in range(n):
        aii = A[i][i]
        out.append((f"({aii})/2" if isinstance(aii, str) else 0.5 * aii, f"{x[i]}**2"))
        for j in range(i + 1, n):
            out.append((0.5 * (A[i][j] + A[j][i]), f"{x[i]}*{x[j]}"))
    return out


# --------------------------------------------------------------------------------------------------------------
# the problem container
# --------------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Player:
    name: str
    variables: list[str]
    lower: list[float]
    upper: list[float]
    cost: str
    constraints: list[str] = field(default_factory=list)  # own rows (gnerun text)


@dataclass(frozen=True)
class _Game:
    """One test problem: its gnerun writing (players, shared) and its numpy writing (cost, cons)."""

    label: str  # "A.3"
    slug: str  # "a03"
    players: list[_Player]
    shared: list[str]
    cost: CostFn  # J_i(a) for a of shape (n,) or (n, k)
    cons: ConsFn  # agent i's non-bound rows, own then shared, as g(a) (<= 0, or == 0 where eq says so)
    eq: list[np.ndarray]  # per agent: which non-bound rows are equalities
    starts: list[tuple[str, np.ndarray]]
    parameters: dict[str, float] = field(default_factory=dict)
    isolated: bool = True
    has_gne: bool = True
    notes: str = ""
    printed: np.ndarray | None = None  # approximate solution printed with the problem
    printed_tol: float = 0.0  # agreement to expect with ``printed`` (its printed precision)
    printed_source: str = ""
    published: dict[str, dict[str, str]] = field(default_factory=dict)  # start label -> anchors

    @property
    def sizes(self) -> list[int]:
        return [len(p.variables) for p in self.players]

    @property
    def n(self) -> int:
        return sum(self.sizes)

    @property
    def slices(self) -> list[slice]:
        off = np.cumsum([0, *self.sizes])
        return [slice(int(off[i]), int(off[i + 1])) for i in range(len(self.sizes))]

    @property
    def lower(self) -> np.ndarray:
        return np.array([v for p in self.players for v in p.lower], dtype=float)

    @property
    def upper(self) -> np.ndarray:
        return np.array([v for p in self.players for v in p.upper], dtype=float)

    def rows(self, i: int, a: np.ndarray) -> np.ndarray:
        """All rows of agent i's problem in gnerun's order: per variable lower, upper bound; own; shared."""
        sl = self.slices[i]
        out = []
        for j, (lo, up) in enumerate(zip(self.players[i].lower, self.players[i].upper, strict=True)):
            v = a[sl.start + j]
            if math.isfinite(lo):
                out.append(lo - v)
            if math.isfinite(up):
                out.append(v - up)
        extra = self.cons(i, a)
        return np.concatenate([np.array(out, dtype=np.result_type(a)).reshape((-1, *a.shape[1:])), extra])

    def eq_rows(self, i: int) -> np.ndarray:
        nb = sum(math.isfinite(v) for v in self.players[i].lower) + sum(
            math.isfinite(v) for v in self.players[i].upper)
        return np.concatenate([np.zeros(nb, dtype=bool), self.eq[i]])

    def config_yaml(self, start_label: str, start: np.ndarray, name: str) -> str:
        lines = [f"name: {name}", "game:", "  kind: static"]
        if self.parameters:
            lines.append("  parameters: {" + ", ".join(f"{k}: {_num(v)}" for k, v in self.parameters.items())
                         + "}")
        lines.append("  agents:")
        k = 0
        for p in self.players:
            lines.append(f"    - name: {p.name}")
            lines.append("      variables:")
            for v, lo, up in zip(p.variables, p.lower, p.upper, strict=True):
                fields = []
                if math.isfinite(lo):
                    fields.append(f"lower: {_num(lo)}")
                if math.isfinite(up):
                    fields.append(f"upper: {_num(up)}")
                fields.append(f"start: {_num(start[k])}")
                k += 1
                lines.append(f"        {v}: {{{', '.join(fields)}}}")
            lines.append(f'      cost: "{p.cost}"')
            if p.constraints:
                lines.append("      constraints:")
                lines += [f'        - "{c}"' for c in p.constraints]
        if self.shared:
            lines.append("  shared_constraints:")
            lines += [f'    - "{c}"' for c in self.shared]
        lines.append("  equilibrium: generalized")
        return "\n".join(lines) + "\n"


def _split(a: np.ndarray, sizes: Sequence[int]) -> list[np.ndarray]:
    off = np.cumsum([0, *sizes])
    return [a[off[i]:off[i + 1]] for i in range(len(sizes))]


def _col(v: np.ndarray, like: np.ndarray) -> np.ndarray:
    """v shaped to broadcast against ``like`` (whose first axis it matches)."""
    return np.asarray(v).reshape((-1,) + (1,) * (like.ndim - 1))


def _stack(rows: Sequence[np.ndarray | float], like: np.ndarray) -> np.ndarray:
    return np.array([np.broadcast_to(r, like.shape[1:]) for r in rows], dtype=np.result_type(like, float))


def _none(like: np.ndarray) -> np.ndarray:
    return np.zeros((0, *like.shape[1:]), dtype=np.result_type(like, float))


INF = math.inf

# --------------------------------------------------------------------------------------------------------------
# A.1, A.2, A.14: the internet switching model (Kesselman et al.), N = 10, B = 1
# --------------------------------------------------------------------------------------------------------------


def _switch_cost(x: np.ndarray, i: int, B: float, power: int) -> np.ndarray:
    S = np.sum(x, axis=0)
    return -x[i] / S * (1 - S / B) ** power


def _a01() -> _Game:
    """A.1: player 1 has 0.3 <= x1 <= 0.5 only; players 2..10 carry x1 + ... + x10 <= B and x_nu >= 0.01."""
    N, B = 10, 1.0
    names = [f"x{i + 1}" for i in range(N)]
    S = _total(names)
    players = []
    for i in range(N):
        lo, up = (0.3, 0.5) if i == 0 else (0.01, INF)
        own = [] if i == 0 else [f"{' + '.join(names)} <= B"]
        players.append(_Player(f"p{i + 1}", [names[i]], [lo], [up], f"-{names[i]}/{S}*(1 - {S}/B)", own))

    def cost(i: int, a: np.ndarray) -> np.ndarray:
        return _switch_cost(a, i, B, 1)

    def cons(i: int, a: np.ndarray) -> np.ndarray:
        return _none(a) if i == 0 else _stack([np.sum(a, axis=0) - B], a)

    return _Game("A.1", "a01", players, [], cost, cons, [np.zeros(0 if i == 0 else 1, bool) for i in range(N)],
                 [(s, np.full(N, float(v))) for s, v in (("0.01", 0.01), ("0.1", 0.1), ("1", 1.0))],
                 parameters={"B": B},
                 notes="Internet switching model with a privileged player 1 (bounds only). The coupling constraint "
                       "is inactive at the solution, so the GNE is isolated: x1 = 0.3 (its lower bound) and "
                       "x2 = ... = x10 = y with 81 y^2 - 2.6 y - 0.21 = 0. The printed approximate solution "
                       "(0.29923815, 0.06951128, ...) violates x1 >= 0.3 by 7.6e-4 (a penalty-method artefact); "
                       "with x1 = 0.29923815 its y solves the same first-order condition.",
                 printed=np.array([0.29923815223336] + [0.06951127617805] * 9), printed_tol=1e-3,
                 printed_source="FK 2009, A.1 (approximate solution, as transcribed in the GNEkit documentation)")


def _a02() -> _Game:
    """A.2: A.1 with players 2..5 squaring (1 - S/B), players 5, 6 also carrying S >= 0.99, x9 <= 0.06, x10 <= 0.05.

    Upper bounds only where the report states them (one transcription adds x_nu <= B to every player as a
    training box; it is implied by S <= B for the players that carry it)."""
    N, B = 10, 1.0
    names = [f"x{i + 1}" for i in range(N)]
    S = _total(names)
    total = " + ".join(names)
    sq = {1, 2, 3, 4}  # players 2..5 (0-based)
    players = []
    eq = []
    for i in range(N):
        lo = 0.3 if i == 0 else 0.01
        up = {0: 0.5, 8: 0.06, 9: 0.05}.get(i, INF)
        own: list[str] = []
        if i > 0:
            own.append(f"{total} <= B")
        if i in (4, 5):
            own.append(f"{total} >= 0.99")
        power = "**2" if i in sq else ""
        cost = f"-{names[i]}/{S}*(1 - {S}/B){power}"
        players.append(_Player(f"p{i + 1}", [names[i]], [lo], [up], cost, own))
        eq.append(np.zeros(len(own), bool))

    def cost(i: int, a: np.ndarray) -> np.ndarray:
        return _switch_cost(a, i, B, 2 if i in sq else 1)

    def cons(i: int, a: np.ndarray) -> np.ndarray:
        s = np.sum(a, axis=0)
        rows: list[np.ndarray] = []
        if i > 0:
            rows.append(s - B)
        if i in (4, 5):
            rows.append(0.99 - s)
        return _stack(rows, a) if rows else _none(a)

    return _Game("A.2", "a02", players, [], cost, cons, eq,
                 [(s, np.full(N, float(v))) for s, v in (("0.01", 0.01), ("0.1", 0.1), ("1", 1.0))],
                 parameters={"B": B}, isolated=False,
                 notes="Players 5 and 6 both carry the active constraint x1 + ... + x10 >= 0.99 with their own "
                       "multipliers: the GNEs form a continuum (x5 and x6 trade the remaining share), so no isolated "
                       "reference. The printed approximate solution (0.29963, 0.00998 x3, 0.59852, 0.02187, "
                       "0.00999 x4) is a penalty-method point that violates the bounds x_nu >= 0.01 by ~2e-5.",
                 printed=np.array([0.29962894677774] + [0.00997828224734] * 3 + [0.59852469355630, 0.02187270661760]
                                  + [0.00999093169361] * 4), printed_tol=1e-3,
                 printed_source="FK 2009, A.2 (one approximate solution, as transcribed in the GNEkit documentation)")


def _a14() -> _Game:
    """A.14: the symmetric internet switching model: every player carries S <= B and x_nu >= 0.01."""
    N, B = 10, 1.0
    names = [f"x{i + 1}" for i in range(N)]
    S = _total(names)
    players = [_Player(f"p{i + 1}", [names[i]], [0.01], [INF], f"-{names[i]}/{S}*(1 - {S}/B)") for i in range(N)]

    def cost(i: int, a: np.ndarray) -> np.ndarray:
        return _switch_cost(a, i, B, 1)

    def cons(i: int, a: np.ndarray) -> np.ndarray:
        return _stack([np.sum(a, axis=0) - B], a)

    return _Game("A.14", "a14", players, [f"{' + '.join(names)} <= B"], cost, cons, [np.zeros(1, bool)] * N,
                 [("0.01", np.full(N, 0.01))], parameters={"B": B},
                 notes="The shared constraint is inactive at the solution x_nu = (N-1)/N^2 * B = 0.09: the GNE is "
                       "isolated (the unconstrained Nash equilibrium).",
                 printed=np.full(N, 0.09), printed_tol=1e-6,
                 printed_source="FK 2009, A.14 (x* = (0.09, ..., 0.09))")


# --------------------------------------------------------------------------------------------------------------
# A.3 - A.6: three players, n = (3, 2, 2), quadratic costs 1/2 x'A x + x'(B x_-nu + b)
# --------------------------------------------------------------------------------------------------------------

_V37 = [["x1", "x2", "x3"], ["x4", "x5"], ["x6", "x7"]]
_A3 = [np.array([[20, 5, 3], [5, 5, -5], [3, -5, 15]], float), np.array([[11, -1], [-1, 9]], float),
       np.array([[48, 39], [39, 53]], float)]
_B3 = [np.array([[-6, 10, 11, 20], [10, -4, -17, 9], [15, 8, -22, 21]], float),
       np.array([[20, 1, -3, 12, 1], [10, -4, 8, 16, 21]], float),
       np.array([[10, -2, 22, 12, 16], [9, 19, 21, -4, 20]], float)]
_b3 = [np.array([1, -1, 1], float), np.array([1, 0], float), np.array([-1, 2], float)]


def _others(x: list[np.ndarray], i: int) -> np.ndarray:
    return np.concatenate([x[j] for j in range(len(x)) if j != i], axis=0)


def _quadratic_game(label: str, slug: str, A: list[np.ndarray], B: list[np.ndarray], b: list[np.ndarray],
                    lo: float, up: float, dependent: bool, nonlinear: bool, rhs: float, **kw) -> _Game:
    """A.3 (dependent=False, nonlinear=False), A.4 (dependent), A.5 (other data), A.6 (dependent, nonlinear).

    ``dependent``: the diagonal of A^nu gains squares of rivals' variables (A^1_11 += (x^2_1)^2,
    A^1_22 += (x^2_2)^2, A^2_11 += (x^3_1)^2, A^3_22 += (x^1_1)^2).
    """
    V = _V37
    dep = {0: {0: "x4", 1: "x5"}, 1: {0: "x6"}, 2: {1: "x1"}} if dependent else {0: {}, 1: {}, 2: {}}
    players = []
    for i in range(3):
        Ai: list[list[float | str]] = [[float(v) for v in row] for row in A[i]]
        for k, y in dep[i].items():
            Ai[k][k] = f"{_num(A[i][k][k])} + {y}**2"
        xo = [v for j in range(3) if j != i for v in V[j]]
        terms = _quad_terms(Ai, V[i])
        for r, xr in enumerate(V[i]):
            terms += [(B[i][r][c], f"{xr}*{xo[c]}") for c in range(len(xo))]
            terms.append((b[i][r], xr))
        players.append(_Player(f"p{i + 1}", V[i], [lo] * len(V[i]), [up] * len(V[i]), _sum(terms)))
    # own constraints (FK A.3): player 1: x1+x2+x3 <= 20, x1+x2-x3 <= x4-x7+rhs; player 2: x4-x5 <= x2+x3-x6+7;
    # player 3: x7 <= x1+x3-x4+4. A.6 changes rhs to 3.7 and adds one nonlinear constraint per player.
    own = [["x1 + x2 + x3 <= 20", f"x1 + x2 - x3 <= x4 - x7 + {_num(rhs)}"], ["x4 - x5 <= x2 + x3 - x6 + 7"],
           ["x7 <= x1 + x3 - x4 + 4"]]
    if nonlinear:
        own[0].append("x1**4 + x6*x2 <= x4 + 2")
        own[1].append("(x4 - 2)**2 + x5**2 <= 0.75 + x1**2")
        own[2].append("2*x6**2 - (x7 - 2)**2 <= x4*x6 + 1.5")
    players = [_Player(p.name, p.variables, p.lower, p.upper, p.cost, own[i]) for i, p in enumerate(players)]

    def cost(i: int, a: np.ndarray) -> np.ndarray:
        x = _split(a, [3, 2, 2])
        xi = x[i]
        Axi = A[i] @ xi
        if dependent:
            extra = {0: [(0, x[1][0]), (1, x[1][1])], 1: [(0, x[2][0])], 2: [(1, x[0][0])]}[i]
            Axi = Axi + _stack([sum(y ** 2 * xi[k] for kk, y in extra if kk == k) for k in range(len(xi))], a)
        return 0.5 * np.sum(xi * Axi, axis=0) + np.sum(xi * (B[i] @ _others(x, i) + _col(b[i], xi)), axis=0)

    def cons(i: int, a: np.ndarray) -> np.ndarray:
        x1, x2, x3, x4, x5, x6, x7 = a
        if i == 0:
            rows = [x1 + x2 + x3 - 20, x1 + x2 - x3 - (x4 - x7 + rhs)]
            if nonlinear:
                rows.append(x1 ** 4 + x6 * x2 - (x4 + 2))
        elif i == 1:
            rows = [x4 - x5 - (x2 + x3 - x6 + 7)]
            if nonlinear:
                rows.append((x4 - 2) ** 2 + x5 ** 2 - (0.75 + x1 ** 2))
        else:
            rows = [x7 - (x1 + x3 - x4 + 4)]
            if nonlinear:
                rows.append(2 * x6 ** 2 - (x7 - 2) ** 2 - (x4 * x6 + 1.5))
        return _stack(rows, a)

    neq = [2, 1, 1] if not nonlinear else [3, 2, 2]
    return _Game(label, slug, players, [], cost, cons, [np.zeros(k, bool) for k in neq],
                 [(s, np.full(7, float(v))) for s, v in (("0", 0), ("1", 1), ("10", 10))], **kw)


def _a03() -> _Game:
    return _quadratic_game(
        "A.3", "a03", _A3, _B3, _b3, -10.0, 10.0, False, False, 5.0,
        notes="Constant, indefinite Jaco-Hessian; every constraint belongs to one player (no shared rows). The GNEs "
              "are isolated but not unique: at least five (known_equilibria('A.3')), e.g. (1.963, -1.394, 5.189, "
              "-3.133, -10, -0.040, 1.639), which gnerun reaches from x0 = 10. The reference is the one the report "
              "prints.",
        printed=np.array([-0.38046562696258, -0.12266997083581, -0.99322817120517, 0.39034789080544,
                          1.16385412687962, 0.05039533464000, 0.01757740533460]), printed_tol=1e-4,
        printed_source="FK 2009, A.3 (approximate solution, as transcribed in the GNEkit documentation)")


def _a04() -> _Game:
    return _quadratic_game(
        "A.4", "a04", _A3, _B3, _b3, 1.0, 10.0, True, False, 5.0,
        notes="A.3 with the diagonal of A^nu depending on rivals' variables and bounds 1 <= x <= 10; isolated.",
        printed=np.array([0.99982626069210, 0.99996267821636, 0.99987070414176, 0.99985869062731,
                          0.99983447394048, 0.99991824127925, 0.99991381820076]), printed_tol=2e-4,
        printed_source="FK 2009, A.4 (approximate solution, within 2e-4 of the bounds x = 1, as transcribed in the "
                       "GNEkit documentation)")


_A5 = [np.array([[20, 6, 0], [6, 6, -1], [0, -1, 8]], float), np.array([[11, 1], [1, 7]], float),
       np.array([[28, 14], [14, 29]], float)]
_B5 = [np.array([[-1, -2, -4, -3], [0, -3, 0, -4], [0, 1, 9, 6]], float),
       np.array([[-1, 0, 0, -7, 4], [-2, -3, 1, 4, 11]], float),
       np.array([[-4, 0, 9, -7, 4], [-3, -4, 6, 4, 11]], float)]


def _a05() -> _Game:
    return _quadratic_game(
        "A.5", "a05", _A5, _B5, _b3, 0.0, 10.0, False, False, 5.0,
        notes="Constant positive definite Jaco-Hessian, bounds 0 <= x <= 10; isolated.",
        printed=np.array([-0.00006229891126, 0.20279012064850, -0.00003469558295, -0.00028322020054,
                          0.07258934064261, 0.02531280162415, -0.00007396699835]), printed_tol=5e-4,
        printed_source="FK 2009, A.5 (approximate solution; its small negative entries violate x >= 0 by up to "
                       "2.8e-4; as transcribed in the GNEkit documentation)")


_B6 = [np.array([[-2, 0, 1, 2], [1, -4, -7, 9], [3, 8, 22, 21]], float),
       np.array([[-2, 1, -3, 12, -1], [0, -4, 8, 16, 21]], float),
       np.array([[1, -7, 22, -12, 16], [2, -9, 21, 1, 21]], float)]
_b6 = [np.array([1, -2, -3], float), np.array([1, 2], float), np.array([1, -2], float)]


def _a06() -> _Game:
    return _quadratic_game(
        "A.6", "a06", _A3, _B6, _b6, 1.0, 10.0, True, True, 3.7,
        notes="Nonlinear own constraints (one nonconvex: player 3's), rival-dependent A^nu, bounds 1 <= x <= 10; "
              "no shared rows, isolated. The approximate solution that the public transcription (GNEkit) attributes "
              "to the report, (0.99988, 2.31571, 0.99989, 1.31500, 0.99990, 0.99992, 1.09709), is not a GNE of "
              "the data as transcribed (best-response gaps ~4-11 by the independent check): there player 1's gradient "
              "is positive in x2 while its only active row, x1^4 + x6 x2 <= x4 + 2, bounds x2 from above (the point "
              "would fit that row reversed, but player 2's x4 = 1.315 is then still unexplained). The A.6 data could "
              "not be checked against the report itself, so no printed value is asserted for A.6.")


# --------------------------------------------------------------------------------------------------------------
# A.7: four players with five variables each, constant symmetric positive definite Jaco-Hessian M (20 x 20)
# --------------------------------------------------------------------------------------------------------------

_M7 = np.array([
    [110, -3, 22, -14, -27, 1, 9, 19, -2, 23, -7, -20, -4, 22, -19, 22, 3, 13, -12, 18],
    [-3, 79, -9, -21, 18, 61, 0, 14, 58, -11, 4, -16, 20, -19, 13, -17, -1, 24, 22, 5],
    [22, -9, 90, 28, 22, -9, -21, -1, -5, 29, 15, -7, 4, 30, 2, 9, -1, -19, -60, 4],
    [-14, -21, 28, 106, 11, -33, -42, 14, 28, -10, 3, 6, 13, 22, -8, 6, -3, 15, -3, 0],
    [-27, 18, 22, 11, 134, 4, -4, -29, 39, -62, 74, 2, 4, -34, -1, 13, 8, 18, 12, 35],
    [1, 61, -9, -33, 4, 119, -14, 12, 12, -6, -23, -14, 16, -4, 15, -2, 8, 16, 9, -9],
    [9, 0, -21, -42, -4, -14, 72, -14, 6, -9, 12, 2, -24, 13, 29, 17, 13, -1, 19, 21],
    [19, 14, -1, 14, -29, 12, -14, 92, -10, 5, 8, 0, -4, 23, 8, -50, -11, 48, -8, 3],
    [-2, 58, -5, 28, 39, 12, 6, -10, 124, -39, -4, -16, 24, -18, 26, 4, 13, 29, 43, 23],
    [23, -11, 29, -10, -62, -6, -9, 5, -39, 130, -42, -21, 21, 68, -24, -21, -30, -54, -23, 9],
    [-7, 4, 15, 3, 74, -23, 12, 8, -4, -42, 138, -4, -24, -12, -27, 24, 21, 2, -10, 18],
    [-20, -16, -7, 6, 2, -14, 2, 0, -16, -21, -4, 89, -11, -14, -16, -32, -7, -5, 13, -4],
    [-4, 20, 4, 13, 4, 16, -24, -4, 24, 21, -24, -11, 107, 31, -3, -2, -22, 17, 4, 22],
    [22, -19, 30, 22, -34, -4, 13, 23, -18, 68, -12, -14, 31, 116, -1, 5, -18, -16, -43, 27],
    [-19, 13, 2, -8, -1, 15, 29, 8, 26, -24, -27, -16, -3, -1, 98, -4, -2, 50, 23, 8],
    [22, -17, 9, 6, 13, -2, 17, -50, 4, -21, 24, -32, -2, 5, -4, 102, 46, -29, -17, -1],
    [3, -1, -1, -3, 8, 8, 13, -11, 13, -30, 21, -7, -22, -18, -2, 46, 110, -16, 24, 12],
    [13, 24, -19, 15, 18, 16, -1, 48, 29, -54, 2, -5, 17, -16, 50, -29, -16, 102, 45, 14],
    [-12, 22, -60, -3, 12, 9, 19, -8, 43, -23, -10, 13, 4, -43, 23, -17, 24, 45, 119, 21],
    [18, 5, 4, 0, 35, -9, 21, 3, 23, 9, 18, -4, 22, 27, 8, -1, 12, 14, 21, 59]], float)

# own constraint of player nu: coefficients on all 20 variables and right-hand side (c^T x <= r)
_C7: list[tuple[dict[int, float], float]] = [
    ({0: 1, 1: 2, 2: -1, 3: 3, 4: -4, 6: 1, 7: -3}, 2.0),  # x^1_1+2x^1_2-x^1_3+3x^1_4-4x^1_5 <= 2-x^2_2+3x^2_3
    ({5: -1, 6: 3, 7: -2, 8: 1, 9: 3, 10: 1, 14: -3, 17: 2}, 4.0),  # ... <= 4 - x^3_1 + 3x^3_5 - 2x^4_3
    ({10: -2, 11: 3, 12: 1, 13: -1, 14: -2, 0: 1, 19: -4}, 4.0),  # ... <= 4 - x^1_1 + 4x^4_5
    ({15: 4, 16: -2, 17: -3, 18: -6, 19: 5, 0: 1, 1: 1, 5: -1, 6: -1}, 3.0),  # ... <= 3 - x^1_1 - x^1_2 + x^2_1 + x^2_2
]


def _a07() -> _Game:
    """A.7: J_nu = 1/2 x_nu' M_{nu,nu} x_nu + x_nu' M_{nu,-nu} x_-nu, 1 <= x <= 5, one linear constraint each."""
    V = [[f"x{5 * i + k + 1}" for k in range(5)] for i in range(4)]
    allv = [v for b in V for v in b]
    players = []
    for i in range(4):
        sl = slice(5 * i, 5 * i + 5)
        terms = _quad_terms(_M7[sl, sl], V[i])
        for r in range(5):
            terms += [(_M7[5 * i + r, c], f"{V[i][r]}*{allv[c]}") for c in range(20) if not sl.start <= c < sl.stop]
        coeffs, rhs = _C7[i]
        con = _sum([(c, allv[k]) for k, c in sorted(coeffs.items())]) + f" <= {_num(rhs)}"
        players.append(_Player(f"p{i + 1}", V[i], [1.0] * 5, [5.0] * 5, _sum(terms), [con]))

    def cost(i: int, a: np.ndarray) -> np.ndarray:
        sl = slice(5 * i, 5 * i + 5)
        xi = a[sl]
        rest = np.concatenate([a[:sl.start], a[sl.stop:]], axis=0)
        Mr = np.concatenate([_M7[sl, :sl.start], _M7[sl, sl.stop:]], axis=1)
        return 0.5 * np.sum(xi * (_M7[sl, sl] @ xi), axis=0) + np.sum(xi * (Mr @ rest), axis=0)

    def cons(i: int, a: np.ndarray) -> np.ndarray:
        coeffs, rhs = _C7[i]
        c = np.zeros(20)
        for k, v in coeffs.items():
            c[k] = v
        return _stack([np.tensordot(c, a, axes=(0, 0)) - rhs], a)

    return _Game("A.7", "a07", players, [], cost, cons, [np.zeros(1, bool)] * 4,
                 [(s, np.full(20, float(v))) for s, v in (("0", 0), ("1", 1), ("10", 10))],
                 notes="Constant positive definite Jaco-Hessian, linear own constraints (no shared rows); isolated.",
                 printed=np.array([0.99988245735506, 0.99985542095046, 0.99989138444537, 0.99988866261891,
                                   0.99984494662577, 0.99986703246906, 0.99986897052169, 0.99992059068103,
                                   0.99981225576918, 1.00013812006334, 0.99987211313045, 1.84253230021096,
                                   0.99986555230493, 0.99987070302597, 0.99987574778109, 0.99993185140789,
                                   0.99988068741824, 0.99984157413000, 0.99986193178624, 0.99983143496263]),
                 printed_tol=3e-4,
                 printed_source="FK 2009, A.7 (approximate solution, as transcribed in the GNEkit documentation)")


# --------------------------------------------------------------------------------------------------------------
# A.8, A.11, A.17: small games with a continuum of GNEs
# --------------------------------------------------------------------------------------------------------------


def _a08() -> _Game:
    """A.8 (Facchinei, Fischer, Piccialli): players 1 and 2 carry x3 <= x1 + x2 <= 1; 0 <= x3 <= 2."""
    own = ["x1 + x2 <= 1", "x1 + x2 >= x3"]
    players = [_Player("p1", ["x1"], [0.0], [INF], "-x1", own),
               _Player("p2", ["x2"], [0.0], [INF], "(x2 - 0.5)**2", own),
               _Player("p3", ["x3"], [0.0], [2.0], "(x3 - 1.5*x1)**2")]

    def cost(i: int, a: np.ndarray) -> np.ndarray:
        x1, x2, x3 = a
        return [-x1, (x2 - 0.5) ** 2, (x3 - 1.5 * x1) ** 2][i]

    def cons(i: int, a: np.ndarray) -> np.ndarray:
        x1, x2, x3 = a
        return _stack([x1 + x2 - 1, x3 - (x1 + x2)], a) if i < 2 else _none(a)

    return _Game("A.8", "a08", players, [], cost, cons, [np.zeros(2, bool), np.zeros(2, bool), np.zeros(0, bool)],
                 [(s, np.full(3, float(v))) for s, v in (("0", 0), ("1", 1), ("10", 10))], isolated=False,
                 notes="Players 1 and 2 carry the same two constraints (player 3 does not): the GNEs are "
                       "(alpha, 1 - alpha, 1.5 alpha), alpha in [1/2, 2/3], a continuum; no isolated reference.")


def _a11() -> _Game:
    """A.11 (Facchinei, Fischer, Piccialli): (x1 - 1)^2 and (x2 - 1/2)^2 with shared x1 + x2 <= 1."""
    players = [_Player("p1", ["x1"], [-INF], [INF], "(x1 - 1)**2"),
               _Player("p2", ["x2"], [-INF], [INF], "(x2 - 0.5)**2")]

    def cost(i: int, a: np.ndarray) -> np.ndarray:
        return (a[0] - 1) ** 2 if i == 0 else (a[1] - 0.5) ** 2

    def cons(i: int, a: np.ndarray) -> np.ndarray:
        return _stack([a[0] + a[1] - 1], a)

    return _Game("A.11", "a11", players, ["x1 + x2 <= 1"], cost, cons, [np.zeros(1, bool)] * 2,
                 [("0", np.zeros(2))], isolated=False,
                 notes="Jointly convex; the GNEs are (alpha, 1 - alpha), alpha in [1/2, 1], a continuum; the "
                       "variational (normalized) equilibrium is (3/4, 1/4) (configs/fk_a11.yaml solves that one). "
                       "FK and Dreves et al. solve the plain GNEP's KKT system, as configured here.")


def _a17() -> _Game:
    """A.17 (Nabetani): player 1 (x1, x2), player 2 (x3), shared x1 + 2x2 - x3 <= 14, 3x1 + 2x2 + x3 <= 30."""
    players = [_Player("p1", ["x1", "x2"], [0.0, 0.0], [INF, INF],
                       "x1**2 + x1*x2 + x2**2 + (x1 + x2)*x3 - 25*x1 - 38*x2"),
               _Player("p2", ["x3"], [0.0], [INF], "x3**2 + (x1 + x2)*x3 - 25*x3")]

    def cost(i: int, a: np.ndarray) -> np.ndarray:
        x1, x2, x3 = a
        if i == 0:
            return x1 ** 2 + x1 * x2 + x2 ** 2 + (x1 + x2) * x3 - 25 * x1 - 38 * x2
        return x3 ** 2 + (x1 + x2) * x3 - 25 * x3

    def cons(i: int, a: np.ndarray) -> np.ndarray:
        x1, x2, x3 = a
        return _stack([x1 + 2 * x2 - x3 - 14, 3 * x1 + 2 * x2 + x3 - 30], a)

    return _Game("A.17", "a17", players, ["x1 + 2*x2 - x3 <= 14", "3*x1 + 2*x2 + x3 <= 30"], cost, cons,
                 [np.zeros(2, bool)] * 2, [("0", np.zeros(3))], isolated=False,
                 notes="Jointly convex with both shared constraints active: the GNEs are (alpha, 11 - alpha, "
                       "8 - alpha), alpha in [0, 2]; the variational equilibrium is (0, 11, 8). No isolated reference.")


# --------------------------------------------------------------------------------------------------------------
# A.12, A.13, A.15, A.16: oligopolies and markets
# --------------------------------------------------------------------------------------------------------------


def _a12() -> _Game:
    """A.12 (Krawczyk-Uryasev duopoly): J_nu = x_nu (rho (x1 + x2) + lambda - d), d = 20, lambda = 4, rho = 1."""
    players = [_Player(f"p{i + 1}", [f"x{i + 1}"], [-10.0], [10.0], f"x{i + 1}*(x1 + x2 - 16)") for i in range(2)]

    def cost(i: int, a: np.ndarray) -> np.ndarray:
        return a[i] * (a[0] + a[1] - 16)

    def cons(i: int, a: np.ndarray) -> np.ndarray:
        return _none(a)

    return _Game("A.12", "a12", players, [], cost, cons, [np.zeros(0, bool)] * 2, [("(2, 0)", np.array([2.0, 0.0]))],
                 notes="A Nash game (bounds only) with the unique equilibrium (16/3, 16/3).",
                 printed=np.array([16 / 3, 16 / 3]), printed_tol=1e-4, printed_source="FK 2009, A.12 (16/3, 16/3)")


# Krawczyk-Uryasev river basin: c1, c2 per player; emission e and the two monitoring coefficients u
_C13 = np.array([[0.10, 0.12, 0.15], [0.01, 0.05, 0.01]])
_E13 = np.array([0.5, 0.25, 0.75])
_U13 = np.array([[6.5, 5.0, 5.5], [4.583, 6.25, 3.75]])


def _a13() -> _Game:
    """A.13 (river basin pollution): J_nu = x_nu (c1 + c2 x_nu - d1 + d2 S), shared sum_nu u_nu,l e_nu x_nu <= 100.

    The constraint coefficients are the products u e: (3.25, 1.25, 4.125) and (2.2915, 1.5625, 2.8125). Some
    public transcriptions print 2.29115 or 2.814 for two of them; the products of the report's data are used.
    """
    coef = _U13 * _E13  # (2, 3)
    names = ["x1", "x2", "x3"]
    players = [_Player(f"p{i + 1}", [names[i]], [0.0], [INF],
                       f"{names[i]}*({_num(_C13[0, i])} + {_num(_C13[1, i])}*{names[i]} - 3 + 0.01*(x1 + x2 + x3))")
               for i in range(3)]
    shared = [_sum([(coef[row, k], names[k]) for k in range(3)]) + " <= 100" for row in range(2)]

    def cost(i: int, a: np.ndarray) -> np.ndarray:
        return a[i] * (_C13[0, i] + _C13[1, i] * a[i] - 3.0 + 0.01 * np.sum(a, axis=0))

    def cons(i: int, a: np.ndarray) -> np.ndarray:
        return np.tensordot(coef, a, axes=(1, 0)) - 100.0

    return _Game("A.13", "a13", players, shared, cost, cons, [np.zeros(2, bool)] * 3, [("0", np.zeros(3))],
                 isolated=False,
                 notes="All three players carry the active shared constraint 3.25 x1 + 1.25 x2 + 4.125 x3 <= 100: the "
                       "GNEs form a continuum. The printed point (21.1448, 16.0279, 2.7260) is the normalized "
                       "(variational) equilibrium of Krawczyk and Uryasev, one GNE among many.",
                 printed=np.array([21.14480155732168, 16.02785326538717, 2.7259709656438]), printed_tol=1e-3,
                 printed_source="FK 2009, A.13 (the normalized equilibrium, as transcribed in the GNEkit "
                                "documentation)")


_P15 = {"c": [0.04, 0.035, 0.125, 0.0166, 0.05, 0.05], "d": [2.0, 1.75, 1.0, 3.25, 3.0, 3.0],
        "up": [80.0, 80.0, 50.0, 55.0, 30.0, 40.0]}


def _a15() -> _Game:
    """A.15 (Contreras, Klusch, Krawczyk electricity market): psi(x) = 2 sum x - 378.4; a Nash game."""
    groups = [[0], [1, 2], [3, 4, 5]]
    names = [f"x{k + 1}" for k in range(6)]
    psi = "(2*" + _total(names) + " - 378.4)"
    players = []
    for i, g in enumerate(groups):
        own = _total([names[k] for k in g]) if len(g) > 1 else names[g[0]]
        quad = " + ".join(f"{_num(_P15['c'][k] / 2)}*{names[k]}**2 + {_num(_P15['d'][k])}*{names[k]}" for k in g)
        players.append(_Player(f"p{i + 1}", [names[k] for k in g], [0.0] * len(g), [_P15["up"][k] for k in g],
                               f"{psi}*{own} + {quad}"))

    def cost(i: int, a: np.ndarray) -> np.ndarray:
        ps = 2 * np.sum(a, axis=0) - 378.4
        g = groups[i]
        c, d = np.array(_P15["c"])[g], np.array(_P15["d"])[g]
        xi = a[g]
        return ps * np.sum(xi, axis=0) + np.sum(0.5 * _col(c, xi) * xi ** 2 + _col(d, xi) * xi, axis=0)

    def cons(i: int, a: np.ndarray) -> np.ndarray:
        return _none(a)

    return _Game("A.15", "a15", players, [], cost, cons, [np.zeros(0, bool)] * 3, [("0", np.zeros(6))],
                 notes="A Nash game (bounds only), isolated. The printed approximate solution is ~2e-3 from the "
                       "exact one (its best-response gaps are ~1e-7).",
                 printed=np.array([46.66150692423980, 32.15293850189938, 15.00419467998705, 22.10485810522063,
                                   12.34076570922471, 12.34076570922471]), printed_tol=3e-3,
                 printed_source="FK 2009, A.15 (approximate solution, as transcribed in the GNEkit documentation)")


_P16 = {"c": [10.0, 8.0, 6.0, 4.0, 2.0], "K": [5.0] * 5, "delta": [1.2, 1.1, 1.0, 0.9, 0.8], "gamma": 1.1}
_PRINTED16 = {75: [10.403965, 13.035817, 15.407354, 17.381556, 18.771308],
              100: [14.050088, 17.798379, 20.907187, 23.111429, 24.132916],
              150: [23.588799, 28.684248, 32.021533, 33.287258, 32.418182],
              200: [35.785329, 40.748959, 42.802485, 41.966381, 38.696846]}


def _a16(P: int) -> _Game:
    """A.16 (Murphy-Sherali-Soyster oligopoly, Outrata et al.) with the shared cap x1 + ... + x5 <= P."""
    names = [f"x{k + 1}" for k in range(5)]
    S = _total(names)
    g = _P16["gamma"]
    players = []
    for i in range(5):
        c, K, d = _P16["c"][i], _P16["K"][i], _P16["delta"][i]
        x = names[i]
        players.append(_Player(f"p{i + 1}", [x], [0.0], [INF],
                               f"{_num(c)}*{x} + {_num(d)}/{_num(1 + d)}*{_num(K)}**(-1/{_num(d)})*{x}**({_num(1 + d)}/"
                               f"{_num(d)}) - 5000**(1/gamma)*{x}*{S}**(-1/gamma)"))

    def cost(i: int, a: np.ndarray) -> np.ndarray:
        c, K, d = _P16["c"][i], _P16["K"][i], _P16["delta"][i]
        x = a[i]
        return c * x + d / (1 + d) * K ** (-1 / d) * x ** ((1 + d) / d) - 5000 ** (1 / g) * x * np.sum(a, axis=0) ** (
            -1 / g)

    def cons(i: int, a: np.ndarray) -> np.ndarray:
        return _stack([np.sum(a, axis=0) - P], a)

    return _Game(f"A.16 (P = {P})", f"a16-P{P}", players, [f"{' + '.join(names)} <= P"], cost, cons,
                 [np.zeros(1, bool)] * 5, [("10", np.full(5, 10.0))], parameters={"P": float(P), "gamma": g},
                 isolated=False,
                 notes=f"The shared cap x1 + ... + x5 <= {P} is active (the unconstrained Nash equilibrium sums to "
                       "~204.3) and every player carries it: the GNEs form a continuum. The printed point is the "
                       "normalized (variational) equilibrium.",
                 printed=np.array(_PRINTED16[P]), printed_tol=1e-5,
                 printed_source=f"FK 2009, A.16 with P = {P} (normalized equilibrium, as transcribed in the GNEkit "
                                "documentation)")


# --------------------------------------------------------------------------------------------------------------
# A.18: electricity market (Pang-Fukushima, Nabetani-Tseng-Fukushima), 2 firms x 3 nodes x 2 plants
# --------------------------------------------------------------------------------------------------------------

_S18 = [(40.0, 500.0, (0, 3, 6, 9)), (35.0, 400.0, (1, 4, 7, 10)), (32.0, 600.0, (2, 5, 8, 11))]


def _a18() -> _Game:
    """A.18: S_j = a_j - a_j/b_j * (sum of the four supplies at node j); |S_i - S_j| <= 1 shared (six rows)."""
    names = [f"x{k + 1}" for k in range(12)]
    price = [f"({_num(p)} - {_num(p)}/{_num(q)}*{_total([names[k] for k in idx])})" for p, q, idx in _S18]
    players = []
    for i in range(2):
        o = 6 * i
        cost = " + ".join(f"(15 - {price[j]})*({names[o + j]} + {names[o + j + 3]})" for j in range(3))
        own = [f"{names[o]} + {names[o + 1]} + {names[o + 2]} <= 100",
               f"{names[o + 3]} + {names[o + 4]} + {names[o + 5]} <= 50"]
        players.append(_Player(f"p{i + 1}", names[o:o + 6], [0.0] * 6, [INF] * 6, cost, own))
    pairs = [(i, j) for i in range(3) for j in range(3) if i != j]
    shared = [f"{price[j]} - {price[i]} <= 1" for i, j in pairs]

    def prices(a: np.ndarray) -> list[np.ndarray]:
        return [p - p / q * np.sum(a[list(idx)], axis=0) for p, q, idx in _S18]

    def cost(i: int, a: np.ndarray) -> np.ndarray:
        S = prices(a)
        o = 6 * i
        return sum((15 - S[j]) * (a[o + j] + a[o + j + 3]) for j in range(3))

    def cons(i: int, a: np.ndarray) -> np.ndarray:
        o = 6 * i
        S = prices(a)
        return _stack([a[o] + a[o + 1] + a[o + 2] - 100, a[o + 3] + a[o + 4] + a[o + 5] - 50]
                      + [S[j] - S[i2] - 1 for i2, j in pairs], a)

    return _Game("A.18", "a18", players, shared, cost, cons, [np.zeros(8, bool)] * 2,
                 [(s, np.full(12, float(v))) for s, v in (("0", 0), ("1", 1), ("10", 10))],
                 isolated=False,
                 notes="Both firms carry the six price-difference constraints S_j - S_i <= 1 (|S_i - S_j| <= 1 "
                       "written as linear pairs), one of which binds with positive multipliers for both firms; the "
                       "two plants of a firm also have the same cost. The GNEs form a continuum: the independent KKT "
                       "solve reaches a different production plan from every start, all with the same prices. No "
                       "isolated reference.")


# --------------------------------------------------------------------------------------------------------------
# A.9a, A.9b: QoS-constrained power minimisation on K channels (Pang, Scutari, Facchinei, Wang), N = 7
# --------------------------------------------------------------------------------------------------------------

# Channel gains h^{nu mu}_k, printed in the report as a table with one column per receiver nu and one row per
# (transmitter mu, channel k), mu-major: H[mu*K + k, nu] (the direct gains h^{nu nu} fall on the block
# diagonal, which fixes the orientation). A.9b's table has 112 rows.
_H9A = """
0.0362 0.0008 0.0018 0.0022 0.0085 0.0008 0.0060
0.2211 0.0003 0.0014 0.0074 0.0005 0.0037 0.0006
0.3356 0.0032 0.0027 0.0043 0.0007 0.0012 0.0003
0.0077 0.0039 0.0032 0.0073 0.0089 0.0006 0.0002
0.0036 0.0019 0.0032 0.0014 0.0017 0.0038 0.0046
0.1811 0.0013 0.0014 0.0024 0.0010 0.0000 0.0121
0.0442 0.0093 0.0002 0.0036 0.0096 0.0031 0.0042
0.3507 0.0017 0.0004 0.0042 0.0034 0.0061 0.0129
0.0145 0.1487 0.0001 0.0013 0.0001 0.0005 0.0008
0.0035 0.1341 0.0021 0.0001 0.0000 0.0001 0.0000
0.0042 0.3074 0.0024 0.0002 0.0001 0.0004 0.0004
0.0006 0.3358 0.0017 0.0008 0.0002 0.0004 0.0022
0.0007 0.0083 0.0045 0.0003 0.0002 0.0000 0.0019
0.0024 0.2214 0.0011 0.0000 0.0001 0.0006 0.0016
0.0034 0.1261 0.0079 0.0002 0.0002 0.0007 0.0001
0.0032 0.0288 0.0059 0.0004 0.0001 0.0001 0.0014
0.0040 0.0051 0.1475 0.0042 0.0002 0.0000 0.0005
0.0030 0.0002 0.0300 0.0003 0.0000 0.0001 0.0001
0.0046 0.0014 0.2207 0.0089 0.0000 0.0001 0.0003
0.0059 0.0005 0.3028 0.0024 0.0002 0.0001 0.0002
0.0037 0.0002 0.0828 0.0008 0.0003 0.0001 0.0001
0.0023 0.0003 0.0167 0.0009 0.0014 0.0001 0.0002
0.0009 0.0001 0.0956 0.0001 0.0005 0.0000 0.0003
0.0006 0.0028 0.0566 0.0018 0.0000 0.0001 0.0002
0.0005 0.0002 0.0004 0.0991 0.0057 0.0000 0.0003
0.0000 0.0000 0.0016 0.0377 0.0003 0.0002 0.0003
0.0014 0.0001 0.0002 0.8100 0.0035 0.0001 0.0000
0.0019 0.0002 0.0016 0.3608 0.0141 0.0000 0.0000
0.0013 0.0005 0.0014 0.0617 0.0014 0.0006 0.0000
0.0016 0.0003 0.0004 0.0723 0.0016 0.0005 0.0001
0.0007 0.0000 0.0028 0.3314 0.0126 0.0002 0.0000
0.0011 0.0001 0.0002 0.0953 0.0026 0.0000 0.0001
0.0001 0.0000 0.0001 0.0009 0.0993 0.0015 0.0001
0.0002 0.0003 0.0003 0.0013 0.1702 0.0210 0.0000
0.0007 0.0000 0.0002 0.0024 1.1062 0.0033 0.0004
0.0012 0.0002 0.0006 0.0014 0.2817 0.0091 0.0004
0.0003 0.0003 0.0004 0.0008 0.5208 0.0024 0.0001
0.0001 0.0001 0.0001 0.0006 0.3959 0.0010 0.0001
0.0004 0.0001 0.0011 0.0009 0.1057 0.0029 0.0004
0.0000 0.0001 0.0000 0.0020 0.0932 0.0058 0.0006
0.0002 0.0010 0.0006 0.0001 0.0001 0.3905 0.0028
0.0004 0.0001 0.0000 0.0001 0.0009 0.1322 0.0032
0.0001 0.0009 0.0001 0.0003 0.0018 0.3691 0.0130
0.0004 0.0007 0.0003 0.0001 0.0018 0.1142 0.0022
0.0009 0.0010 0.0002 0.0001 0.0019 0.1127 0.0046
0.0017 0.0014 0.0000 0.0001 0.0022 0.1665 0.0015
0.0009 0.0001 0.0000 0.0002 0.0015 0.0066 0.0042
0.0004 0.0006 0.0005 0.0001 0.0022 0.2389 0.0026
0.0008 0.0054 0.0004 0.0001 0.0001 0.0040 0.1110
0.0005 0.0013 0.0008 0.0004 0.0000 0.0006 0.0834
0.0033 0.0063 0.0001 0.0004 0.0000 0.0013 0.4948
0.0012 0.0079 0.0000 0.0000 0.0001 0.0029 0.0355
0.0002 0.0095 0.0002 0.0002 0.0001 0.0003 0.3045
0.0010 0.0018 0.0000 0.0002 0.0003 0.0009 0.5359
0.0003 0.0045 0.0002 0.0001 0.0002 0.0007 0.0328
0.0005 0.0035 0.0006 0.0000 0.0008 0.0008 0.2950
"""

_H9B = """
0.0129 0.0010 0.0015 0.0008 0.0005 0.0088 0.0048
0.0037 0.0062 0.0020 0.0044 0.0043 0.0040 0.0029
0.0514 0.0114 0.0024 0.0094 0.0063 0.0057 0.0045
0.1382 0.0087 0.0096 0.0113 0.0040 0.0144 0.0114
0.1824 0.0026 0.0180 0.0068 0.0054 0.0140 0.0157
0.1193 0.0002 0.0135 0.0007 0.0094 0.0043 0.0132
0.0290 0.0002 0.0033 0.0019 0.0116 0.0016 0.0089
0.0188 0.0020 0.0016 0.0075 0.0192 0.0065 0.0105
0.0550 0.0074 0.0038 0.0070 0.0270 0.0076 0.0157
0.0642 0.0134 0.0024 0.0020 0.0194 0.0056 0.0136
0.0495 0.0166 0.0004 0.0019 0.0052 0.0058 0.0041
0.0318 0.0160 0.0009 0.0042 0.0017 0.0067 0.0001
0.0287 0.0098 0.0050 0.0027 0.0030 0.0050 0.0027
0.0585 0.0025 0.0102 0.0004 0.0010 0.0020 0.0021
0.0843 0.0001 0.0092 0.0002 0.0002 0.0027 0.0000
0.0586 0.0002 0.0032 0.0001 0.0002 0.0077 0.0027
0.0028 0.0288 0.0208 0.0004 0.0000 0.0002 0.0011
0.0066 0.0136 0.0127 0.0000 0.0001 0.0000 0.0006
0.0088 0.0500 0.0094 0.0001 0.0002 0.0003 0.0017
0.0039 0.0251 0.0125 0.0000 0.0002 0.0006 0.0010
0.0016 0.0091 0.0147 0.0000 0.0001 0.0003 0.0003
0.0061 0.1168 0.0130 0.0005 0.0000 0.0001 0.0005
0.0098 0.1155 0.0088 0.0009 0.0001 0.0002 0.0002
0.0121 0.0029 0.0044 0.0006 0.0001 0.0001 0.0008
0.0142 0.1913 0.0019 0.0001 0.0003 0.0000 0.0021
0.0106 0.4811 0.0009 0.0001 0.0004 0.0001 0.0011
0.0035 0.3142 0.0017 0.0002 0.0004 0.0003 0.0002
0.0004 0.0131 0.0044 0.0000 0.0003 0.0006 0.0016
0.0002 0.1289 0.0049 0.0002 0.0002 0.0007 0.0014
0.0009 0.3551 0.0038 0.0009 0.0001 0.0004 0.0002
0.0031 0.2986 0.0099 0.0014 0.0001 0.0001 0.0017
0.0034 0.1287 0.0202 0.0010 0.0000 0.0003 0.0029
0.0023 0.0011 0.0609 0.0017 0.0002 0.0001 0.0002
0.0028 0.0021 0.0588 0.0012 0.0001 0.0004 0.0002
0.0025 0.0071 0.0554 0.0028 0.0001 0.0004 0.0001
0.0008 0.0096 0.1574 0.0099 0.0000 0.0002 0.0000
0.0007 0.0045 0.2024 0.0192 0.0002 0.0001 0.0000
0.0036 0.0003 0.0726 0.0165 0.0005 0.0000 0.0001
0.0051 0.0025 0.0497 0.0032 0.0004 0.0000 0.0004
0.0024 0.0038 0.1986 0.0029 0.0004 0.0001 0.0004
0.0000 0.0016 0.2281 0.0205 0.0005 0.0002 0.0002
0.0008 0.0005 0.1334 0.0312 0.0004 0.0004 0.0000
0.0012 0.0007 0.0762 0.0231 0.0003 0.0006 0.0001
0.0006 0.0005 0.0209 0.0103 0.0004 0.0004 0.0001
0.0021 0.0005 0.0115 0.0042 0.0002 0.0001 0.0001
0.0043 0.0004 0.1096 0.0032 0.0000 0.0003 0.0001
0.0041 0.0005 0.1429 0.0034 0.0002 0.0004 0.0001
0.0026 0.0012 0.0759 0.0028 0.0004 0.0001 0.0002
0.0006 0.0001 0.0016 0.0492 0.0066 0.0011 0.0002
0.0002 0.0002 0.0014 0.0128 0.0003 0.0008 0.0002
0.0007 0.0002 0.0013 0.1154 0.0011 0.0000 0.0001
0.0005 0.0001 0.0018 0.1459 0.0010 0.0003 0.0001
0.0011 0.0000 0.0010 0.0509 0.0017 0.0005 0.0005
0.0016 0.0000 0.0001 0.0136 0.0077 0.0001 0.0006
0.0017 0.0000 0.0000 0.0487 0.0095 0.0001 0.0002
0.0014 0.0000 0.0003 0.0591 0.0041 0.0004 0.0000
0.0003 0.0002 0.0017 0.0434 0.0016 0.0002 0.0003
0.0003 0.0004 0.0030 0.0570 0.0015 0.0001 0.0005
0.0027 0.0004 0.0016 0.1731 0.0001 0.0004 0.0003
0.0030 0.0001 0.0005 0.3232 0.0019 0.0003 0.0000
0.0007 0.0000 0.0025 0.2794 0.0055 0.0001 0.0001
0.0019 0.0001 0.0030 0.0914 0.0076 0.0002 0.0002
0.0051 0.0002 0.0008 0.0519 0.0119 0.0000 0.0001
0.0039 0.0001 0.0004 0.1091 0.0139 0.0004 0.0000
0.0000 0.0001 0.0000 0.0003 0.0301 0.0023 0.0003
0.0003 0.0001 0.0000 0.0010 0.0167 0.0070 0.0002
0.0008 0.0000 0.0001 0.0018 0.0398 0.0089 0.0009
0.0007 0.0001 0.0003 0.0021 0.0606 0.0049 0.0021
0.0004 0.0003 0.0005 0.0014 0.0857 0.0010 0.0015
0.0002 0.0001 0.0002 0.0003 0.1207 0.0012 0.0003
0.0002 0.0001 0.0001 0.0002 0.0936 0.0021 0.0005
0.0005 0.0008 0.0003 0.0007 0.0217 0.0026 0.0007
0.0004 0.0011 0.0005 0.0008 0.0188 0.0035 0.0002
0.0001 0.0005 0.0003 0.0003 0.0808 0.0027 0.0003
0.0004 0.0000 0.0001 0.0002 0.1234 0.0007 0.0003
0.0007 0.0001 0.0000 0.0006 0.1248 0.0013 0.0000
0.0004 0.0000 0.0002 0.0007 0.0850 0.0029 0.0011
0.0002 0.0000 0.0003 0.0003 0.0287 0.0024 0.0022
0.0005 0.0001 0.0002 0.0000 0.0210 0.0009 0.0015
0.0003 0.0001 0.0000 0.0000 0.0432 0.0002 0.0005
0.0001 0.0002 0.0001 0.0002 0.0008 0.1341 0.0150
0.0004 0.0003 0.0001 0.0002 0.0027 0.0507 0.0035
0.0006 0.0002 0.0000 0.0001 0.0016 0.0187 0.0001
0.0004 0.0001 0.0000 0.0001 0.0001 0.0037 0.0008
0.0003 0.0003 0.0001 0.0001 0.0020 0.0046 0.0019
0.0007 0.0005 0.0000 0.0001 0.0032 0.0153 0.0121
0.0005 0.0006 0.0000 0.0000 0.0014 0.0351 0.0198
0.0001 0.0005 0.0000 0.0000 0.0001 0.0956 0.0113
0.0006 0.0005 0.0001 0.0003 0.0001 0.1673 0.0011
0.0011 0.0007 0.0002 0.0003 0.0006 0.1522 0.0008
0.0008 0.0009 0.0002 0.0002 0.0020 0.0527 0.0034
0.0006 0.0007 0.0002 0.0002 0.0022 0.0005 0.0057
0.0006 0.0003 0.0001 0.0004 0.0004 0.0801 0.0051
0.0003 0.0000 0.0000 0.0003 0.0003 0.2297 0.0004
0.0000 0.0000 0.0000 0.0001 0.0011 0.3127 0.0043
0.0001 0.0000 0.0001 0.0001 0.0003 0.2574 0.0162
0.0009 0.0038 0.0000 0.0000 0.0003 0.0018 0.1630
0.0024 0.0009 0.0000 0.0001 0.0006 0.0052 0.3698
0.0035 0.0016 0.0001 0.0001 0.0007 0.0053 0.2515
0.0021 0.0019 0.0002 0.0001 0.0003 0.0016 0.0571
0.0003 0.0017 0.0002 0.0002 0.0000 0.0005 0.0774
0.0004 0.0016 0.0003 0.0003 0.0001 0.0019 0.0623
0.0013 0.0018 0.0007 0.0001 0.0001 0.0012 0.0244
0.0015 0.0054 0.0012 0.0001 0.0001 0.0000 0.2083
0.0015 0.0094 0.0010 0.0002 0.0000 0.0004 0.3246
0.0009 0.0066 0.0004 0.0003 0.0001 0.0007 0.1571
0.0001 0.0011 0.0000 0.0003 0.0007 0.0005 0.0440
0.0004 0.0003 0.0000 0.0003 0.0012 0.0004 0.0953
0.0007 0.0022 0.0000 0.0002 0.0009 0.0003 0.1190
0.0002 0.0045 0.0000 0.0001 0.0004 0.0009 0.1166
0.0001 0.0082 0.0001 0.0001 0.0001 0.0015 0.0703
0.0004 0.0085 0.0001 0.0000 0.0001 0.0008 0.0079
"""

_SIGMA9 = 0.3162


def _gains(table: str, K: int) -> np.ndarray:
    """h[nu, mu, k] (receiver nu, transmitter mu, channel k) from the printed table H[mu*K + k, nu]."""
    H = np.array(table.split(), dtype=float).reshape(7 * K, 7)
    return H.reshape(7, K, 7).transpose(2, 0, 1)


def _a09(which: str) -> _Game:
    """A.9: player nu: min sum_k x^nu_k s.t. x^nu >= 0, sum_k log2(1 + h^{nu nu}_k x^nu_k / (sigma^2 +
    sum_{mu != nu} h^{nu mu}_k x^mu_k)) >= L, sigma = 0.3162; A.9a: K = 8, L = 8; A.9b: K = 16, L = 16."""
    K = 8 if which == "a" else 16
    L = float(K)
    h = _gains(_H9A if which == "a" else _H9B, K)
    N = 7
    V = [[f"p{nu + 1}_{k + 1}" for k in range(K)] for nu in range(N)]
    players = []
    for nu in range(N):
        logs = []
        for k in range(K):
            interf = " + ".join(f"{_num(h[nu, mu, k])}*{V[mu][k]}" for mu in range(N) if mu != nu and h[nu, mu, k])
            logs.append(f"log(1 + {_num(h[nu, nu, k])}*{V[nu][k]}/(s2 + {interf}))")
        con = "(" + " + ".join(logs) + ")/log(2) >= L"
        players.append(_Player(f"u{nu + 1}", V[nu], [0.0] * K, [INF] * K, " + ".join(V[nu]), [con]))

    def cost(i: int, a: np.ndarray) -> np.ndarray:
        return np.sum(a[i * K:(i + 1) * K], axis=0)

    def cons(i: int, a: np.ndarray) -> np.ndarray:
        x = a.reshape((N, K, *a.shape[1:]))
        hh = h[i].reshape((N, K) + (1,) * (a.ndim - 1))
        signal = hh[i] * x[i]
        interference = np.sum(hh * x, axis=0) - signal
        rate = np.sum(np.log(1 + signal / (_SIGMA9 ** 2 + interference)), axis=0) / math.log(2)
        return _stack([L - rate], a)

    return _Game(f"A.9{which}", f"a09{which}", players, [], cost, cons, [np.zeros(1, bool)] * N,
                 [("0", np.zeros(N * K))], parameters={"s2": _SIGMA9 ** 2, "L": L},
                 notes=f"N = 7 users, K = {K} channels, n = {N * K}. Each user's QoS constraint is its own (no shared "
                       "rows), so the GNE is isolated. The gains table is read as H[mu*K + k, nu] = h^{nu mu}_k "
                       "(column nu = receiver nu), which puts the direct gains h^{nu nu} on the block diagonal.")


# --------------------------------------------------------------------------------------------------------------
# A.10a-e: Arrow-Debreu economy as a GNEP: F firms, C consumers, one market player, P goods
# --------------------------------------------------------------------------------------------------------------

_Q10C_1 = np.array([
    [68.22249416536778, 12.12481199690621, -8.35496210217478, -6.81177486915109, -4.66752803051747, 3.64100170417482],
    [12.12481199690621, 53.51450780426463, -21.77618227261339, -15.00376305863444, -0.11788350473544,
     2.03354709400720],
    [-8.35496210217478, -21.77618227261339, 35.44033408387684, 4.35160649036518, 19.17472558234163,
     -3.40090742729160],
    [-6.81177486915109, -15.00376305863444, 4.35160649036518, 52.25155022199242, -5.99490328518247,
     20.40443259092577],
    [-4.66752803051747, -0.11788350473544, 19.17472558234163, -5.99490328518247, 23.32798561358070,
     -3.58535668529727],
    [3.64100170417482, 2.03354709400720, -3.40090742729160, 20.40443259092577, -3.58535668529727,
     10.21258119890765]])
_Q10C_2 = np.array([
    [61.74633559943146, -23.83006225091380, 16.78581949473039, 14.42073900860500, -2.75188745616575,
     13.44307656650567],
    [-23.83006225091380, 37.64246654306209, -3.76510322128227, 16.32022449045404, -39.90743633716275,
     11.38657250296817],
    [16.78581949473039, -3.76510322128227, 53.34843665848310, 4.60388415537161, -23.04611587657949,
     -25.31392346426841],
    [14.42073900860500, 16.32022449045404, 4.60388415537161, 40.69699687713468, -30.78019133996427,
     17.08866411420883],
    [-2.75188745616575, -39.90743633716275, -23.04611587657949, -30.78019133996427, 66.22678445157413,
     -12.28091080313848],
    [13.44307656650567, 11.38657250296817, -25.31392346426841, 17.08866411420883, -12.28091080313848,
     41.37849544246254]])

# log-utility data of A.10b, d, e (the first P entries are used): consumers i <= C/2 use (a, b), the others (c, d)
_LOG10 = {"a": [1, 2, 4, 6, 8, 7, 8, 10, 1, 5, 2, 4], "b": [50, 60, 70, 60, 60, 50, 50, 80, 60, 70, 70, 80],
          "c": [10, 6, 4, 10, 1, 2, 6, 4, 9, 4, 5, 1], "d": [50, 60, 50, 70, 70, 60, 50, 50, 80, 50, 60, 70]}
_XI10 = ([2, 3, 4, 1, 6, 1, 3, 6, 2, 10, 3, 4], [6, 5, 4, 3, 2, 8, 4, 6, 2, 0, 6, 0])


@dataclass(frozen=True)
class _Economy:
    F: int
    C: int
    P: int
    kind: str  # "quadratic" | "log"
    Q: list[np.ndarray]  # per consumer (quadratic)
    bvec: list[np.ndarray]  # per consumer (quadratic: linear term; log: shift inside the log)
    wvec: list[np.ndarray]  # per consumer (log: weights)
    xi: list[np.ndarray]  # endowments


def _economy(which: str) -> _Economy:
    """The data of A.10a-e. Consumers are numbered i = 1..C in the formulas. In A.10c the first C/2 consumers
    use the first matrix and the others the second (one public transcription applies the first to all, which
    contradicts the report's two-group definition); in A.10b/d/e the log utilities of the two groups use
    (a, b) and (c, d) with the shifts 2(i + F) and i + F."""
    F, C, P = {"a": (2, 5, 3), "b": (4, 20, 5), "c": (6, 30, 6), "d": (6, 30, 10), "e": (7, 40, 12)}[which]
    Q: list[np.ndarray] = []
    bvec: list[np.ndarray] = []
    wvec: list[np.ndarray] = []
    xi: list[np.ndarray] = []
    for i in range(1, C + 1):
        first = i <= C // 2
        if which == "a":
            first = i <= 2
            Q.append(np.array([[6, -2, 5], [-2, 6, -7], [5, -7, 20]], float) if first
                     else np.array([[6, 1, 0], [1, 7, -5], [0, -5, 7]], float))
            bvec.append(np.full(3, 30.0 + i + F) if first else np.full(3, 30.0 + 2 * (i + F)))
            xi.append(np.array([2, 3, 4], float) if first else np.array([6, 5, 4], float))
            continue
        xi.append(np.array(_XI10[0 if first else 1][:P], float))
        if which == "c":
            Q.append(_Q10C_1 if first else _Q10C_2)
            bvec.append(np.array([50, 60, 70, 60, 60, 50], float) + i + F if first
                        else np.array([50, 60, 50, 70, 70, 60], float) + 2 * (i + F))
        else:
            # consumer i: sum_k (a_k + i + F) log(x_k + b_k + 2 (i + F)) or sum_k (c_k + i + F) log(x_k + d_k + i + F)
            w, s = (_LOG10["a"], _LOG10["b"]) if first else (_LOG10["c"], _LOG10["d"])
            wvec.append(np.array(w[:P], float) + i + F)
            bvec.append(np.array(s[:P], float) + (2 * (i + F) if first else i + F))
    return _Economy(F, C, P, "quadratic" if which in "ac" else "log", Q, bvec, wvec, xi)


def _a10(which: str) -> _Game:
    """A.10: firm j: max p'y^j s.t. y^j >= 0, |y^j|^2 <= 10 j; consumer i: max u_i(x^i) s.t. x^i >= 0,
    p'x^i <= p'xi^i; market: max p'(sum_i x^i - sum_j y^j - sum_i xi^i) s.t. p >= 0, sum_k p_k = 1."""
    e = _economy(which)
    F, C, P = e.F, e.C, e.P
    Y = [[f"y{j + 1}_{k + 1}" for k in range(P)] for j in range(F)]
    X = [[f"x{i + 1}_{k + 1}" for k in range(P)] for i in range(C)]
    p = [f"q{k + 1}" for k in range(P)]
    xi_tot = np.sum(e.xi, axis=0)
    players = []
    for j in range(F):
        players.append(_Player(f"firm{j + 1}", Y[j], [0.0] * P, [INF] * P,
                               "-(" + " + ".join(f"{p[k]}*{Y[j][k]}" for k in range(P)) + ")",
                               [" + ".join(f"{y}**2" for y in Y[j]) + f" <= {10 * (j + 1)}"]))
    for i in range(C):
        if e.kind == "quadratic":
            terms = _quad_terms(e.Q[i], X[i]) + [(-b, x) for b, x in zip(e.bvec[i], X[i], strict=True)]
            cost = _sum(terms)
        else:
            cost = "-(" + " + ".join(f"{_num(w)}*log({x} + {_num(s)})"
                                     for w, s, x in zip(e.wvec[i], e.bvec[i], X[i], strict=True)) + ")"
        budget = " + ".join(f"{p[k]}*{X[i][k]}" for k in range(P)) + " <= " + " + ".join(
            f"{_num(e.xi[i][k])}*{p[k]}" for k in range(P) if e.xi[i][k])
        players.append(_Player(f"consumer{i + 1}", X[i], [0.0] * P, [INF] * P, cost, [budget]))
    excess = []
    for k in range(P):
        excess.append(f"{p[k]}*(" + " + ".join(X[i][k] for i in range(C)) + " - "
                      + " - ".join(Y[j][k] for j in range(F)) + f" - {_num(xi_tot[k])})")
    players.append(_Player("market", p, [0.0] * P, [INF] * P, "-(" + " + ".join(excess) + ")",
                           [" + ".join(p) + " == 1"]))

    def blocks(a: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        y = a[:F * P].reshape((F, P, *a.shape[1:]))
        x = a[F * P:(F + C) * P].reshape((C, P, *a.shape[1:]))
        return y, x, a[(F + C) * P:]

    def cost(i: int, a: np.ndarray) -> np.ndarray:
        y, x, q = blocks(a)
        if i < F:
            return -np.sum(q * y[i], axis=0)
        if i < F + C:
            c = i - F
            xc = x[c]
            if e.kind == "quadratic":
                return 0.5 * np.sum(xc * (e.Q[c] @ xc), axis=0) - np.sum(_col(e.bvec[c], xc) * xc, axis=0)
            return -np.sum(_col(e.wvec[c], xc) * np.log(xc + _col(e.bvec[c], xc)), axis=0)
        z = np.sum(x, axis=0) - np.sum(y, axis=0) - _col(xi_tot, q)
        return -np.sum(q * z, axis=0)

    def cons(i: int, a: np.ndarray) -> np.ndarray:
        y, x, q = blocks(a)
        if i < F:
            return _stack([np.sum(y[i] ** 2, axis=0) - 10 * (i + 1)], a)
        if i < F + C:
            c = i - F
            return _stack([np.sum(q * x[c], axis=0) - np.sum(q * _col(e.xi[c], q), axis=0)], a)
        return _stack([np.sum(q, axis=0) - 1], a)

    N = F + C + 1
    start = np.concatenate([np.zeros((F + C) * P), np.full(P, 1.0 / P)])
    eq = [np.zeros(1, bool)] * (F + C) + [np.ones(1, bool)]
    data = ("quadratic utilities -1/2 x'Q x + b'x" if e.kind == "quadratic"
            else "log utilities sum_k w_k log(x_k + s_k)")
    return _Game(f"A.10{which}", f"a10{which}", players, [], cost, cons, eq,
                 [("y = 0, x = 0, p = 1/P", start)],
                 notes=f"F = {F} firms, C = {C} consumers, P = {P} goods: N = {N} players, n = {N * P}; {data}. Every "
                       "constraint is its owner's (the market's simplex is an equality); no shared rows.")


# --------------------------------------------------------------------------------------------------------------
# the library
# --------------------------------------------------------------------------------------------------------------


@functools.cache
def _all_games() -> tuple[_Game, ...]:
    return (_a01(), _a02(), _a03(), _a04(), _a05(), _a06(), _a07(), _a08(), _a09("a"), _a09("b"),
            *[_a10(w) for w in "abcde"], _a11(), _a12(), _a13(), _a14(), _a15(),
            *[_a16(P) for P in (75, 100, 150, 200)], _a17(), _a18())


def games() -> list[_Game]:
    """Every test problem of the library, in the report's order."""
    return list(_all_games())


def _config_name(game: _Game, start_label: str) -> str:
    label = start_label.replace("(", "").replace(")", "").replace(", ", "-").replace(" ", "")
    if game.slug.startswith("a10"):
        label = "std"
    return f"fk-{game.slug}-x0-{label}"


# --------------------------------------------------------------------------------------------------------------
# independent numerics: complex-step derivatives, best responses (SLSQP), KKT solve (Fischer-Burmeister)
# --------------------------------------------------------------------------------------------------------------

_CS = 1e-30  # complex-step size: derivatives exact to rounding


def _perturbed(game: _Game, i: int, a: np.ndarray) -> np.ndarray:
    """a + i h e_j for every own variable j of agent i, as an (n, n_i) complex array."""
    sl = game.slices[i]
    ni = sl.stop - sl.start
    A = np.repeat(a.astype(complex)[:, None], ni, axis=1)
    A[sl, :] += 1j * _CS * np.eye(ni)
    return A


def own_gradient(game: _Game, i: int, a: np.ndarray) -> np.ndarray:
    """grad_{a_i} J_i(a) by complex-step differentiation of the numpy cost."""
    return np.imag(game.cost(i, _perturbed(game, i, a))) / _CS


def own_rows(game: _Game, i: int, a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Agent i's rows (bounds, own, shared) at a and their Jacobian with respect to a_i (complex step)."""
    return np.real(game.rows(i, a.astype(float))), np.imag(game.rows(i, _perturbed(game, i, a))) / _CS


def best_response_gaps(game: _Game, a: np.ndarray, starts: int = 3, seed: int = 0,
                       feas_tol: float = 1e-10) -> dict[str, float]:
    """J_i(a) - min {J_i(y, a_-i) : y in agent i's feasible set given a_-i}, per agent, by SLSQP from a_i and
    ``starts`` random points (complex-step gradients of the numpy writing; nothing from gnerun).

    The minimum is taken over the SLSQP end points whose rows hold to ``feas_tol`` (and a_i itself when it is
    feasible); ``nan`` if none does.
    """
    a = np.asarray(a, dtype=float)
    rng = np.random.default_rng(seed)
    out: dict[str, float] = {}
    for i, player in enumerate(game.players):
        sl = game.slices[i]
        eq = game.eq[i]
        lo = np.array(player.lower)
        up = np.array(player.upper)

        def full(y: np.ndarray, sl: slice = sl) -> np.ndarray:
            b = a.copy()
            b[sl] = y
            return b

        def f(y: np.ndarray, i: int = i) -> float:
            return float(np.real(game.cost(i, full(y))))

        def df(y: np.ndarray, i: int = i) -> np.ndarray:
            return own_gradient(game, i, full(y))

        def g(y: np.ndarray, i: int = i) -> np.ndarray:
            return np.real(game.cons(i, full(y)))

        def dg(y: np.ndarray, i: int = i) -> np.ndarray:
            return np.imag(game.cons(i, _perturbed(game, i, full(y)))) / _CS

        cons = []
        if np.any(~eq):
            cons.append({"type": "ineq", "fun": lambda y, g=g, eq=eq: -g(y)[~eq],
                         "jac": lambda y, dg=dg, eq=eq: -dg(y)[~eq]})
        if np.any(eq):
            cons.append({"type": "eq", "fun": lambda y, g=g, eq=eq: g(y)[eq], "jac": lambda y, dg=dg, eq=eq: dg(y)[eq]})
        bounds = [(None if not math.isfinite(lo_) else lo_, None if not math.isfinite(up_) else up_)
                  for lo_, up_ in zip(lo, up, strict=True)]

        def violation(y: np.ndarray, g: Callable = g, eq: np.ndarray = eq, lo: np.ndarray = lo,
                      up: np.ndarray = up) -> float:
            r = g(y)
            v = [0.0, float(np.max(lo - y, initial=0.0)), float(np.max(y - up, initial=0.0))]
            if r.size:
                v += [float(np.max(r[~eq], initial=0.0)), float(np.max(np.abs(r[eq]), initial=0.0))]
            return max(v)

        ai = a[sl]
        y0s = [np.clip(ai, lo, up)]
        for _ in range(starts):
            scale = 1.0 + np.abs(ai)
            base = ai + scale * rng.standard_normal(ai.size)
            boxed = np.isfinite(lo) & np.isfinite(up)
            y = base.copy()
            y[boxed] = lo[boxed] + (up[boxed] - lo[boxed]) * rng.random(int(boxed.sum()))
            y0s.append(np.clip(y, lo, up))
        values = [f(ai)] if violation(ai) <= feas_tol else []
        for y0 in y0s:
            with np.errstate(all="ignore"):
                try:
                    res = optimize.minimize(f, y0, jac=df, bounds=bounds, constraints=cons, method="SLSQP",
                                            options={"maxiter": 500, "ftol": 1e-15})
                except (ValueError, FloatingPointError):
                    continue
            if np.all(np.isfinite(res.x)) and violation(res.x) <= feas_tol and np.isfinite(f(res.x)):
                values.append(f(res.x))
        out[player.name] = f(ai) - min(values) if values else math.nan
    return out


def _fb(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return u + v - np.sqrt(u * u + v * v)


def kkt_residual(game: _Game, z: np.ndarray) -> np.ndarray:
    """The concatenated KKT system of the GNEP in Fischer-Burmeister form, z = (a, lambda) in gnerun's order:
    [grad_{a_i} J_i + Jg_i^T lambda_i]_i; FB(-g, lambda) on inequality rows, g on equality rows."""
    n = game.n
    a, lam = z[:n], z[n:]
    stat, comp = [], []
    k = 0
    for i in range(len(game.players)):
        g, J = own_rows(game, i, a)
        li = lam[k:k + g.size]
        k += g.size
        stat.append(own_gradient(game, i, a) + J.T @ li)
        comp.append(np.where(game.eq_rows(i), g, _fb(-g, li)))
    return np.concatenate(stat + comp)


def n_rows(game: _Game) -> int:
    """m: the number of rows (multipliers) of the KKT system."""
    return sum(game.eq_rows(i).size for i in range(len(game.players)))


def feasibility(game: _Game, a: np.ndarray) -> float:
    """The largest violation of any agent's rows at a."""
    worst = 0.0
    for i in range(len(game.players)):
        g, _ = own_rows(game, i, a)
        eq = game.eq_rows(i)
        worst = max(worst, float(np.max(g[~eq], initial=0.0)), float(np.max(np.abs(g[eq]), initial=0.0)))
    return worst


def _jacobian_groups(game: _Game) -> tuple[np.ndarray, list[np.ndarray]]:
    """Sparsity pattern of the KKT residual's Jacobian (probed at two random points) and a greedy grouping of
    its columns into structurally orthogonal sets, for grouped finite differences."""
    rng = np.random.default_rng(7)
    size = game.n + n_rows(game)
    pattern = np.zeros((size, size), dtype=bool)
    lo, up = game.lower, game.upper
    for _ in range(2):
        box_lo = np.where(np.isfinite(lo), lo, 0.0)
        box_up = np.where(np.isfinite(up), up, box_lo + 2.0)
        a = box_lo + (box_up - box_lo) * (0.1 + 0.8 * rng.random(game.n))
        z = np.concatenate([a, 0.5 + rng.random(size - game.n)])
        f0 = kkt_residual(game, z)
        for j in range(size):
            zj = z.copy()
            zj[j] += 1e-6 * (1.0 + abs(z[j]))
            pattern[:, j] |= kkt_residual(game, zj) != f0
    groups: list[list[int]] = []
    used: list[np.ndarray] = []
    for j in range(size):
        for g, rows in zip(groups, used, strict=True):
            if not np.any(rows & pattern[:, j]):
                g.append(j)
                rows |= pattern[:, j]
                break
        else:
            groups.append([j])
            used.append(pattern[:, j].copy())
    return pattern, [np.array(g) for g in groups]


def solve_kkt(game: _Game, a0: np.ndarray, lam0: float = 0.0,
              groups: tuple[np.ndarray, list[np.ndarray]] | None = None) -> tuple[np.ndarray, float]:
    """A zero of :func:`kkt_residual` from (a0, lam0): Newton with backtracking, then SciPy's Levenberg-Marquardt
    where that stalls, both with a grouped central-difference Jacobian; returns (z, ||residual||)."""
    z0 = np.concatenate([a0, np.full(n_rows(game), lam0)])
    pattern, cols = groups if groups is not None else _jacobian_groups(game)

    def fun(z: np.ndarray) -> np.ndarray:
        return kkt_residual(game, z)

    def jac(z: np.ndarray) -> np.ndarray:
        J = np.zeros((z.size, z.size))
        for g in cols:
            h = 6e-6 * (1.0 + np.abs(z[g]))
            zp, zm = z.copy(), z.copy()
            zp[g] += h
            zm[g] -= h
            d = fun(zp) - fun(zm)
            for j, hj in zip(g, h, strict=True):
                rows = pattern[:, j]
                J[rows, j] = d[rows] / (2 * hj)
        return J

    with np.errstate(all="ignore"):
        z = _newton(fun, jac, z0)
        if not np.linalg.norm(fun(z)) <= 1e-11:
            try:
                res = optimize.least_squares(fun, z, jac=jac, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15,
                                             max_nfev=100 * z0.size)
            except ValueError:  # a residual that is not finite
                return z0, math.inf
            z = res.x
    r = fun(z)
    return z, float(np.linalg.norm(r)) if np.all(np.isfinite(r)) else math.inf


def _newton(fun: Callable[[np.ndarray], np.ndarray], jac: Callable[[np.ndarray], np.ndarray], z: np.ndarray,
            max_iter: int = 60) -> np.ndarray:
    """Newton's method on a (semismooth) square system with Armijo backtracking on 1/2 ||F||^2; least-squares
    steps where the Jacobian is singular. Returns the best point reached."""
    f = fun(z)
    best = (float(np.linalg.norm(f)), z)
    for _ in range(max_iter):
        if not np.all(np.isfinite(f)) or best[0] <= 1e-13:
            break
        J = jac(z)
        step = np.linalg.lstsq(J, -f, rcond=None)[0]
        phi = 0.5 * float(f @ f)
        t = 1.0
        while t > 1e-10:
            zt = z + t * step
            ft = fun(zt)
            if np.all(np.isfinite(ft)) and 0.5 * float(ft @ ft) <= (1 - 1e-4 * t) * phi:
                break
            t *= 0.5
        else:
            break
        z, f = zt, ft
        if float(np.linalg.norm(f)) < best[0]:
            best = (float(np.linalg.norm(f)), z)
    return best[1]


def compute_references(labels: Sequence[str] | None = None, tries: int = 4, seed: int = 1,
                       verbose: bool = False) -> dict[str, np.ndarray]:
    """Recompute the isolated references with the numpy writing alone.

    For each problem with an isolated GNE: solve the Fischer-Burmeister KKT system from every start point of the
    library and from ``tries`` random points (one for n > 30), with multipliers 0 and 1 (for n > 100 only until one
    is found, multipliers 0); keep the zeros (residual <= 1e-9) that are feasible and have best-response gaps
    <= 1e-7; return the first such point.
    """
    rng = np.random.default_rng(seed)
    out: dict[str, np.ndarray] = {}
    for game in games():
        if not game.isolated or not game.has_gne or (labels is not None and game.label not in labels):
            continue
        lo, up = game.lower, game.upper
        a0s = [s for _, s in game.starts]
        box_lo = np.where(np.isfinite(lo), lo, -1.0)
        box_up = np.where(np.isfinite(up), up, np.maximum(box_lo, 0.0) + 2.0)
        a0s += [box_lo + (box_up - box_lo) * rng.random(game.n) for _ in range(tries if game.n <= 30 else 1)]
        found: list[np.ndarray] = []
        groups = _jacobian_groups(game)
        large = game.n > 100  # one solve from the library's start point (more only if it fails)
        for a0 in a0s:
            if large and found:
                break
            for lam0 in (0.0,) if large else (0.0, 1.0):
                z, r = solve_kkt(game, a0, lam0, groups)
                a = z[:game.n]
                if verbose:
                    print(game.label, "residual", r, "feasibility", feasibility(game, a))
                if r > 1e-9 or feasibility(game, a) > 1e-9 or any(np.max(np.abs(a - b)) < 1e-6 for b in found):
                    continue
                gaps = best_response_gaps(game, a)
                if verbose:
                    print(game.label, "new candidate, largest gap", max(gaps.values()))
                if max(gaps.values()) <= 1e-7:
                    found.append(a)
        if found:
            out[game.label] = found[0]
            if len(found) > 1 and verbose:
                print(game.label, "has", len(found), "distinct GNEs:", found)
    return out


# --------------------------------------------------------------------------------------------------------------
# stored references (recomputed by compute_references()) and the Problem list
# --------------------------------------------------------------------------------------------------------------

_REFERENCES: dict[str, list[float]] = {
    "A.1": [
        0.3, 0.06943641558133247, 0.06943641558133248, 0.06943641558133247, 0.06943641558133248, 0.06943641558133248,
        0.06943641558133248, 0.06943641558133248, 0.06943641558133247, 0.06943641558133248
    ],
    "A.3": [
        -0.38046287798199396, -0.1226711107558029, -0.9932207741557904, 0.39034385507117875, 1.1638405633796403,
        0.05039544619206443, 0.017579151220211288
    ],
    "A.4": [
        1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0
    ],
    "A.5": [
        0.0, 0.2028985507246377, 0.0, 0.0, 0.07246376811594213, 0.02536231884057971, 0.0
    ],
    "A.6": [
        1.0, 1.0, 1.0, 1.1339745962155574, 1.0, 1.0, 1.0
    ],
    "A.7": [
        1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.842696629213487, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0,
        1.0
    ],
    "A.9a": [
        0.0, 1.1514395521058078, 1.267378577537698, 0.0, 0.0, 1.0395624126255163, 0.0, 1.3258435584301984,
        0.6078946036876708, 0.5901157034387954, 0.9726641808440126, 1.0372925750104993, 0.0, 0.870176405043792,
        0.5453851422736748, 0.0, 1.3479808133027877, 0.0, 1.5495709455634377, 1.688673955923678, 0.8182324076237464,
        0.0, 0.9103456134594746, 0.240675124023705, 0.2486367380577195, 0.0, 1.1735141373036102, 1.0315684317338245,
        0.0, 0.0, 1.0214543832840959, 0.21086405943439557, 0.0, 0.1940781239642582, 0.6904318144576768,
        0.3765710125288852, 0.5932276270029803, 0.5275841800511405, 0.0, 0.0, 0.9397752542240126, 0.3784365093544464,
        0.9122146299821169, 0.28761354211108126, 0.2956899968350081, 0.5866695201303462, 0.0, 0.7434504880753776,
        0.1605787260278194, 0.0, 0.867067073278312, 0.0, 0.7628726704142246, 0.8817727671513619, 0.0,
        0.6924644852811948
    ],
    "A.9b": [
        0.0, 0.0, 2.074769217540344, 3.4636978683742243, 3.654911064622424, 3.3063981766752706, 0.27958135847504184,
        0.0, 2.022164209074204, 2.3179099191983665, 1.9094545196988593, 0.7353869570887437, 0.566884385042222,
        2.3069088897228807, 2.8428658764681396, 2.263175015036512, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0394551918584853,
        1.0272200103960136, 0.0, 1.1976421971543831, 1.6081575992090384, 1.479331777725973, 0.0, 1.0634816459985814,
        1.5900030193359262, 1.5517154411276608, 1.1136049365834686, 0.9664283676413391, 0.9323003445837662,
        0.689705326321014, 1.7614153603795022, 1.806920009183913, 0.4461304955304823, 0.4147688981046277,
        2.1189185928342806, 2.1431525024487468, 1.817642705572787, 1.2272848842507094, 0.0, 0.0, 1.4025841197882065,
        1.6382264197976624, 0.9111335265470497, 0.8473129876489601, 0.0, 1.8484694731056834, 1.8162076821432949, 0.0,
        0.0, 0.8020447298236084, 1.1271673770869846, 0.0, 0.06246117133354851, 2.156912754586546, 2.5989976511897237,
        2.551231209267828, 1.747216709291643, 0.8335603378839148, 1.9714478446028418, 0.8509233844053461, 0.0,
        1.5039889722573199, 2.518478363258777, 3.0257800843481575, 3.339248818156075, 3.239839436800742, 0.0, 0.0,
        2.599805923093097, 3.519773043617408, 3.5658956558065973, 3.044941532433532, 0.3553664055662093, 0.0,
        1.4442957934556466, 1.8363317395534058, 0.45310883972286614, 0.0, 0.0, 0.0, 0.0, 0.0, 1.5693629860491796,
        1.9260187878318966, 1.8221420610440273, 0.42927075304372037, 0.0, 1.2114048811505889, 2.1522241606001113,
        2.272756360616794, 2.160165312110414, 1.3379104632958119, 1.8489171576441186, 1.6830199324798008, 0.0,
        0.03230602667376384, 0.0, 0.0, 1.5548814596799418, 1.7026594750115722, 1.2612915825261741, 0.0,
        1.0741734774830423, 1.1763088502386976, 1.204032959549885, 0.5217973462382023, 0.0
    ],
    "A.10a": [
        1.0247202842652743, 2.4237550586810834, 1.7536703665550015, 1.4491733236467634, 3.427707275857185,
        2.4800644163138803, 4.171990118072573, 4.135151687930244, 1.1619455559478413, 4.269432395856797,
        4.111765079568833, 1.1373299445465208, 3.614113509294079, 4.728206552960645, 5.769789285574682,
        3.7972225564731374, 4.654580714158636, 5.764551952603746, 3.980331603652196, 4.580954875356653,
        5.759314619632833, 0.19698031187278994, 0.4659144887568724, 0.33710519937033756
    ],
    "A.10b": [
        1.5026671806230278, 1.1737607941902721, 1.2164797908701335, 1.5022043114250683, 1.621060167742319,
        2.1250923065700276, 1.6599484341256971, 1.720362218601329, 2.1244377106726695, 2.292525274643991,
        2.602695903705361, 2.033013331469948, 2.107004804167835, 2.601894190737239, 2.807758572655824,
        3.0053343612460535, 2.347521588380548, 2.432959581740268, 3.0044086228501365, 3.2421203354846364, 0.0, 0.0,
        0.0, 3.6069915793263734, 10.611982988513544, 0.0, 0.0, 0.0, 4.040914370216334, 10.209875342991461, 0.0, 0.0,
        0.0, 4.424151186128923, 9.854737385365562, 0.0, 0.0, 0.0, 4.766839222059191, 9.537175178056998, 0.0, 0.0,
        0.6477233549685433, 4.830710700216813, 8.991920659533902, 0.0, 1.0840346052589251, 1.2760506423219768,
        4.474315626777328, 8.065757287994344, 0.0, 2.2592502468444104, 1.808069331760074, 4.094172180186251,
        7.167851748512147, 0.0, 3.3372227958819214, 2.3088119489346983, 3.739355987389225, 6.340357000566405, 0.0,
        4.334159434462739, 2.783491172556534, 3.4056458394208744, 5.571537912234055, 0.0, 5.2628553063432655,
        3.2362222752917194, 3.0897092028870268, 4.85212990568157, 9.809562205372972, 5.448805721344356,
        5.230960532612388, 0.0, 0.0, 9.360054465206531, 5.634500270654813, 5.607045322793281, 0.0, 0.0,
        8.937002740515618, 5.813420937862048, 5.956986095468417, 0.0, 0.0, 8.537189407796426, 5.986391573492224,
        6.283962528442496, 0.0, 0.0, 8.157898291363763, 6.154107635782041, 6.590658765316768, 0.0, 0.0,
        7.796820641885447, 6.317160264231782, 6.879356328152882, 0.0, 0.0, 7.451981505113623, 6.476055132390501,
        7.152006880400376, 0.0, 0.0, 7.121681501811297, 6.631227354707328, 7.41028976037693, 0.0, 0.0,
        6.804450382526596, 6.783053378514712, 7.655657878761386, 0.0, 0.0, 6.499009669475447, 6.931860549318634,
        7.889374636144326, 0.0, 0.0, 0.21417193423748068, 0.16729361156315645, 0.17338225864721468,
        0.2141059624822549, 0.2310462330698932
    ],
    "A.10c": [
        4.671580449326876e-10, 2.358767117649423, 1.3048879667904443, 0.6070649521511223, 1.1731416378048483,
        0.9943318964708074, 6.323584995801912e-10, 3.335800448259459, 1.8453902600124672, 0.8585194885738047,
        1.6590728147685603, 1.4061976534889076, 7.269668933305766e-10, 4.085504490991509, 2.2601322566662194,
        1.0514673406208312, 2.031940921153145, 1.7222333642732328, 7.833507040375618e-10, 4.717534235298718,
        2.609775933580745, 1.2141299043033142, 2.3462832756104577, 1.988663792940921, 8.272532291735049e-10,
        5.274363618155193, 2.9178181967647405, 1.3574384997689217, 2.6232244493679855, 2.223393712704153,
        8.570803621410728e-10, 5.777775860296315, 3.196309690134172, 1.4869993734989773, 2.8735984086358624,
        2.4356057813263794, 0.5829593200093552, 2.6180620159819528, 4.2808720027933305, 0.0, 0.473651514351546,
        6.4440663382884855, 0.5934590697011463, 2.6503559966626895, 4.330484553130062, 0.0, 0.49519002848692545,
        6.555894091453127, 0.6039588193929378, 2.682649977343427, 4.380097103466792, 0.0, 0.5167285426223055,
        6.667721844617762, 0.6144585690847297, 2.7149439580241643, 4.4297096538035206, 0.0, 0.5382670567576866,
        6.779549597782392, 0.6249583187765206, 2.7472379387048997, 4.4793222041402485, 0.0, 0.5598055708930688,
        6.891377350947034, 0.6354580684683122, 2.779531919385637, 4.528934754476981, 0.0, 0.5813440850284469,
        7.003205104111673, 0.6459578181601038, 2.811825900066374, 4.57854730481371, 0.0, 0.6028825991638278,
        7.115032857276308, 0.6564575678518956, 2.844119880747111, 4.628159855150438, 0.0, 0.6244211132992101,
        7.22686061044094, 0.66712289799073, 2.874876312867727, 4.6757735573602695, 0.0, 0.6464645778209247,
        7.3367665699099875, 0.6837029674084965, 2.850709600231681, 4.651985921187993, 0.0, 0.6865454974726475,
        7.378023671012581, 0.7002830368262628, 2.8265428875956378, 4.62819828501572, 0.0, 0.7266264171243701,
        7.419280772115172, 0.7168631062440293, 2.8023761749595937, 4.6044106488434435, 0.0, 0.7667073367760954,
        7.460537873217768, 0.7334431756617966, 2.7782094623235496, 4.5806230126711664, 0.0, 0.8067882564278195,
        7.501794974320348, 0.7500232450795632, 2.7540427496875046, 4.556835376498889, 0.0, 0.846869176079544,
        7.543052075422939, 0.76660331449733, 2.729876037051464, 4.5330477403266185, 0.0, 0.8869500957312655,
        7.58430917652553, 2.3978406660607896, 6.021191664933899, 3.0430014251801554, 2.8915002947329835,
        6.867616626546573, 1.1566966796612599, 2.39086579847989, 5.977387872194066, 3.064490784512338,
        2.937568932020957, 6.882548645769599, 1.1866642499103695, 2.3838909308989926, 5.9335840794542385,
        3.0859801438445227, 2.9836375693089314, 6.89748066499263, 1.2166318201594795, 2.376916063318121,
        5.8897802867144815, 3.107469503176723, 3.0297062065969005, 6.912412684215705, 1.2465993904085861,
        2.3699411957372196, 5.8459764939746455, 3.1289588625089064, 3.075774843884874, 6.927344703438728,
        1.2765669606576973, 2.3629663281563156, 5.802172701234801, 3.150448221841088, 3.1218434811728484,
        6.942276722661748, 1.3065345309068082, 2.3559914605754346, 5.758368908495022, 3.1719375811732844,
        3.1679121184608197, 6.957208741884811, 1.3365021011559175, 2.3490165929945426, 5.714565115755209,
        3.1934269405054727, 3.2139807557487914, 6.972140761107849, 1.366469671405028, 2.342041725413664,
        5.67076132301543, 3.214916299837666, 3.260049393036762, 6.98707278033091, 1.396437241654133,
        2.3350668578327514, 5.626957530275568, 3.2364056591698467, 3.306118030324737, 7.0020047995539185,
        1.4264048119032477, 2.3280919902519144, 5.583153737535902, 3.2578950185020648, 3.3521866676127066,
        7.016936818777054, 1.456372382152348, 2.321117122670943, 5.539349944795879, 3.279384377834208,
        3.398255304900683, 7.031868837999954, 1.4863399524014707, 2.3141422550900717, 5.495546152056119,
        3.300873737166405, 3.4443239421886536, 7.046800857223026, 1.516307522650574, 2.3071673875092227,
        5.451742359316425, 3.3223630964986213, 3.490392579476624, 7.061732876446146, 1.5462750928996791,
        2.300192519928281, 5.407938566576479, 3.343852455830778, 3.5364612167646, 7.076664895669096,
        1.5762426631487942, 0.0, 0.3663709535424082, 0.2026792068966326, 0.09429119293631018, 0.1822159624267594,
        0.15444268419789092
    ],
    "A.10d": [
        1.1041209740821483, 0.8894246070986352, 0.9341041653859475, 0.989608145917225, 1.045141658622038,
        1.0991234973850597, 1.1790093027918247, 0.9595237534697231, 0.8319583465161027, 0.9136021342197769,
        1.5614628560475656, 1.2578363420672511, 1.321022779358008, 1.3995172613910323, 1.478053508224399,
        1.5543953567248994, 1.6673709461722461, 1.3569715055760205, 1.1765667769725683, 1.2920285288266136,
        1.9123936248127198, 1.540528608996824, 1.6179158740101827, 1.7140515883126684, 1.8102384538401795,
        1.9037377412637202, 2.0421040150317964, 1.6619438920787548, 1.4409941259468826, 1.5824053143720171,
        2.208241948164296, 1.778849214197271, 1.8682083307718955, 1.979216291834451, 2.09028331724408,
        2.1982469947701153, 2.3580186055836494, 1.9190475069394461, 1.6639166930322051, 1.827204268439556,
        2.468889553430964, 1.9888138823335921, 2.088720411868686, 2.2128310853584483, 2.337007794795759,
        2.4577148558203032, 2.636344947147154, 2.14556033878405, 1.860315417258331, 2.0428764765043086,
        2.7045330008059962, 2.1786364520670696, 2.2880785718039167, 2.4240350027989233, 2.5600637725500817,
        2.6922917328966744, 2.8879711938345194, 2.3503435920808977, 2.0378734362140465, 2.237859056756166, 0.0, 0.0,
        0.0, 1.2036666223254113, 8.162761027517258, 8.918960340179627, 8.833797098908732, 7.426657996023063, 0.0,
        0.0, 0.0, 0.0, 0.0, 1.7510297473503225, 8.136840487934581, 9.004296515574007, 8.583734674996016,
        7.09987771370605, 0.0, 0.0, 0.0, 0.0, 0.0, 2.248838775832243, 8.116133397668957, 9.069803097370198,
        8.338293752418709, 6.835562506922044, 0.0, 0.0, 0.0, 0.0, 0.0, 2.7054455217956264, 8.09976108548851,
        9.118822151903993, 8.096695426457192, 6.623184553951509, 0.0, 0.0, 0.0, 0.0, 0.0, 3.1274248175572494,
        8.087031831484552, 9.153984667569361, 7.858326516800005, 6.454455995144324, 0.0, 0.0, 0.0, 0.0, 0.0,
        3.5200232464804584, 8.077393657146498, 9.177390119952124, 7.622697717946954, 6.3227632859295495, 0.0, 0.0,
        0.0, 0.0, 0.0, 3.887478433590757, 8.070400733675754, 9.190734239333183, 7.389413821608795, 6.222764717231787,
        0.0, 0.0, 0.0, 0.0, 0.0, 4.233250458036109, 8.065689035724063, 9.19540161282341, 7.158152134778937,
        6.150098710080245, 0.0, 0.0, 0.0, 0.0, 0.0, 4.560192367536193, 8.062958402038962, 9.192533917512938,
        6.928646577259031, 6.101168874797863, 0.0, 0.0, 0.0, 0.0, 0.0, 4.870677705991165, 8.06195911863697,
        9.183080951990584, 6.700675788211293, 6.072983256948114, 0.0, 0.0, 0.0, 0.0, 0.0, 5.166697187640436,
        8.062481747983888, 9.1678393215237, 6.474054110159787, 6.0630324753894165, 0.0, 0.0, 0.0, 0.0, 0.0,
        5.449932888856998, 8.064349323480966, 9.147482126687555, 6.248624669732601, 6.069196200320214, 0.0, 0.0, 0.0,
        0.0, 0.0, 5.626138919173143, 7.969570715164972, 9.03299247652713, 5.937522493211731, 5.975205581834145,
        0.6100053049989502, 0.0, 0.0, 0.0, 0.0, 5.718177302718677, 7.800916447807386, 8.84548850264757,
        5.560932683438542, 5.80708645061348, 1.5680914997496866, 0.10891510529202549, 0.0, 0.13455204996407769, 0.0,
        5.759234034520298, 7.591490147315564, 8.615648791057755, 5.148200198425192, 5.602727213103051,
        2.441978615356791, 0.40101567136552735, 10.352231610575025, 7.4521832157049595, 7.0897300449755845, 0.0, 0.0,
        0.0, 0.0, 4.994494411537013, 3.8771310298537256, 8.864572779653377, 9.976006762936771, 7.519908814828131,
        7.246057741438321, 0.0, 0.0, 0.0, 0.0, 5.120188813485209, 3.783375651540866, 9.04684948125005,
        9.614797431108578, 7.586823975685115, 7.392353678143254, 0.0, 0.0, 0.0, 0.0, 5.236117215850393,
        3.704349380248379, 9.21886930162326, 9.267158271321867, 7.653006708376219, 7.52958347902426, 0.0, 0.0, 0.0,
        0.0, 5.343219661373665, 3.6386344409692475, 9.381619534153145, 8.931823671677055, 7.718525322263948,
        7.658592690427346, 0.0, 0.0, 0.0, 0.0, 5.442319296288632, 3.5849893623238245, 9.535964699985826,
        8.607680656884725, 7.783439888396235, 7.78012488326028, 0.0, 0.0, 0.0, 0.0, 5.534139992911763,
        3.5423223981241776, 9.682665056409952, 8.293746551201767, 7.8478034451123095, 7.894836576226874, 0.0, 0.0,
        0.0, 0.0, 5.619320877531972, 3.50966961637016, 9.822391854983628, 7.989150452429238, 7.911662997954678,
        8.003309612917441, 0.0, 0.0, 0.0, 0.0, 5.698428379609351, 3.4861767266161197, 9.95573999637682,
        7.693117779348678, 7.975060353696495, 8.106061485557586, 0.0, 0.0, 0.0, 0.0, 5.77196628202771,
        3.471083922152773, 10.083238585792955, 7.404957313743015, 8.038032819726684, 8.203553992142746, 0.0, 0.0,
        0.0, 0.0, 5.840384148884972, 3.463713169189265, 10.205359784378544, 7.124050279478521, 8.100613793490409,
        8.296200532624656, 0.0, 0.0, 0.0, 0.0, 5.9040844283910605, 3.4634574942457172, 10.322526269141832,
        6.8498410945804435, 8.162833261629213, 8.384372287385265, 0.0, 0.0, 0.0, 0.0, 5.963428467662511,
        3.4697719126224578, 10.435117550077864, 6.581829504739153, 8.224718224562862, 8.468403472786257, 0.0, 0.0,
        0.0, 0.0, 6.018741629040245, 3.482165711955437, 10.543475343654926, 6.319563863351241, 8.286293059189225,
        8.5485958307236, 0.0, 0.0, 0.0, 0.0, 6.070317660711062, 3.500195860434083, 10.647908163122105,
        6.062635367759983, 8.347579829972444, 8.625222479357538, 0.0, 0.0, 0.0, 0.0, 6.118422445420779,
        3.523461352980823, 10.748695255648979, 0.1110158394496281, 0.08942880508749783, 0.09392119205046438,
        0.09950194011713155, 0.10508565754957723, 0.11051335912031596, 0.11854562184833287, 0.09647705048973557,
        0.08365075602552409, 0.09185977826179245
    ],
    "A.10e": [
        1.003198945569202, 0.8371223442206791, 0.876058043278859, 0.9451662174989068, 0.9881032043884026,
        1.0385186282560455, 1.1052386193819463, 0.9030345172522558, 0.7845284877548506, 0.8618310410946501,
        0.8050457142461939, 0.7305971941647486, 1.4187375545823562, 1.1838697725624425, 1.2389331662309988,
        1.336666883483833, 1.3973889526703918, 1.4686871288568006, 1.5630434451884645, 1.2770836615891827,
        1.109490827450964, 1.2188131467901775, 1.1385065674173027, 1.0332204606195161, 1.7375915438253848,
        1.4499384323413793, 1.5173770413383563, 1.637075910305803, 1.7114449531223284, 1.7987670287462072,
        1.9143294432568105, 1.564101664869341, 1.3588432007765787, 1.492735150715914, 1.3943800794899852,
        1.2654314601606074, 2.0063978911384006, 1.6742446884413582, 1.7521160865577166, 1.8903324349978143,
        1.9762064087768048, 2.077037256512092, 2.210477238763896, 1.80606903450451, 1.5690569755097037,
        1.7236620821893016, 1.610091428492386, 1.4611943883294962, 2.2432210372488517, 1.871862467161417,
        1.9589253370069817, 2.1134559123639023, 2.2094659337978393, 2.322198248680353, 2.4713886842960444,
        2.019246566604753, 1.7542590289049573, 1.9271127930070513, 1.8001369420493591, 1.6336649903229892,
        2.457325527142664, 2.0505225956231663, 2.145895191094269, 2.31517495498874, 2.420348663960581,
        2.5438407276024395, 2.7072706615039164, 2.21197378738856, 1.921694483676702, 2.1110462951734954,
        1.9719512195176103, 1.78959033321272, 2.654214925498333, 2.214817539743324, 2.3178317165737226,
        2.5006747591216905, 2.6142753484777397, 2.747662022273429, 2.924186526269006, 2.3892047579567377,
        2.0756672750449154, 2.2801906068923294, 2.1299507539337963, 1.9329784843214952, 0.0, 0.0, 0.0,
        1.8673887364310633, 9.124277882443403, 9.929883554547652, 10.10263545977672, 8.786158676611306, 0.0, 0.0,
        0.0, 0.0, 0.0, 0.0, 0.0, 2.345090933006242, 9.100949983518852, 9.997731127747441, 9.869815870275353,
        8.518619209495036, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.781207680479149, 9.082041906493775,
        10.04875766351035, 9.640947681045754, 8.304277755384133, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
        3.1823749547706695, 9.066848360639748, 10.08564736993787, 9.415400349491394, 8.134645269649665, 0.0, 0.0,
        0.0, 0.0, 0.0, 0.0, 0.0, 3.5538881306048333, 9.05480653820182, 10.110542190868605, 9.19267071535918,
        8.002947666175556, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 3.9000242414133792, 9.04546186368934,
        10.125172157864782, 8.97235237998152, 7.9037135677109855, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
        4.224275543850866, 9.038443169955393, 10.130949865504872, 8.754113513254742, 7.832475519439249, 0.0, 0.0,
        0.0, 0.0, 0.0, 0.0, 0.0, 4.450794335759661, 8.950966110252107, 10.053977667721718, 8.4639434202395,
        7.6874541662201255, 0.0, 0.0, 0.0, 0.5528928915001518, 0.0, 0.0, 0.0, 4.58985855611978, 8.791979315652586,
        9.903189699754654, 8.109842338063416, 7.477475285156707, 0.0, 0.0, 0.0, 1.5975684616759642, 0.0, 0.0, 0.0,
        4.718571586154254, 8.640064942641102, 9.751055914342476, 7.762064127989755, 7.29380786818418, 0.0, 0.0, 0.0,
        2.605896406294414, 0.0, 0.0, 0.0, 4.817541532957886, 8.473006256292134, 9.578182827372764, 7.400746629409961,
        7.1081293081562364, 0.15634218702825123, 0.0, 0.0, 3.5577497699243197, 0.0, 0.0, 0.0, 4.7793429160355405,
        8.178228486151308, 9.282131050327875, 6.925245972782867, 6.7865177610369924, 1.0593094295159002,
        0.20893634938309863, 0.0, 4.327430863827313, 0.0, 0.05484247795686753, 0.0, 4.729618938583747,
        7.884757454579646, 8.981456251322731, 6.4509135639392925, 6.479828973008013, 1.90956371508447,
        0.4389432234477483, 0.0, 5.065524161356543, 0.0, 0.5563071263784098, 0.0, 4.629910833482342,
        7.551710431876233, 8.639208547330329, 5.9411995072161154, 6.138848009153676, 2.6736660342803975,
        0.6094113027545086, 0.0, 5.727814465772853, 0.0, 1.0341873744791017, 0.0, 4.532101675611415,
        7.231378422486025, 8.303873847004887, 5.442852901085258, 5.823705116359425, 3.405739572890899,
        0.7757142483271109, 0.0, 6.377821525840053, 0.0, 1.4909513571760395, 0.0, 4.435992737935398, 6.9224307854812,
        7.974728696473527, 4.9546841286244625, 5.531696310443905, 4.1091361800469635, 0.9382879462538316, 0.0,
        7.016830797363576, 0.0, 1.9287344271507725, 0.0, 4.341412088075085, 6.62371629219331, 7.651147186207255,
        4.475663970698794, 5.260482189363531, 4.786755770164985, 1.097509511465262, 0.0, 7.645954416261937, 0.0,
        2.3493934128215175, 0.0, 4.2482102196135365, 6.3342338742152755, 7.332585047049196, 4.004897454146563,
        5.008028490471393, 5.441120007955614, 1.2537068699880263, 0.0, 8.266159457250092, 0.0, 2.754550595859312,
        0.0, 4.156256511155225, 6.05310891388612, 7.018566759631778, 3.5416026550487074, 4.772557910613219,
        6.07443203205998, 1.4071665256133608, 0.0, 8.878290838233767, 0.0, 3.1456296111997317, 0.0,
        4.065436335761283, 5.779573889585365, 6.7086750314472985, 3.0850933952714077, 4.55251077559122,
        6.688625209041394, 1.5581399000361498, 0.0, 9.48309001778626, 10.577379992951672, 6.976526744626904,
        7.416819742244987, 0.0, 0.0, 0.0, 0.0, 4.8651513722713355, 2.2857259955808473, 8.826870231372903,
        7.856087393377448, 0.0, 10.274275617587673, 7.0125280847839155, 7.502737890166284, 0.0, 0.0, 0.0, 0.0,
        4.918629738440057, 2.2304446336482178, 8.930714584229644, 7.985580517888871, 0.0, 9.980482285296782,
        7.0485294249409955, 7.583324868158325, 0.0, 0.0, 0.0, 0.0, 4.966936193449895, 2.1840929939047036,
        9.029139760850956, 8.1121729286808, 0.0, 9.695245046641006, 7.084530765098157, 7.659012933242161, 0.0, 0.0,
        0.0, 0.0, 5.010490081448801, 2.145947044821399, 9.122585153905089, 8.236099818756864, 0.0, 9.417888420543937,
        7.12053210525534, 7.730188841700144, 0.0, 0.0, 0.0, 0.0, 5.049666605095534, 2.115358968714652,
        9.211443904199092, 8.35757162396382, 0.0, 9.14780620603933, 7.156533445412435, 7.797199682503576, 0.0, 0.0,
        0.0, 0.0, 5.084802484724892, 2.0917473907401005, 9.296068830407911, 8.47677719698297, 0.0, 8.884452822257837,
        7.192534785569638, 7.860357835726359, 0.0, 0.0, 0.0, 0.0, 5.116200768638019, 2.074589073537885,
        9.37677746933697, 8.593886505229511, 0.0, 8.62733591573194, 7.2285361257267295, 7.9199452053379575, 0.0, 0.0,
        0.0, 0.0, 5.144134939448637, 2.0634118272951145, 9.453856378592931, 8.7090529339297, 0.0, 8.376010023800733,
        7.264537465883859, 7.976216847310606, 0.0, 0.0, 0.0, 0.0, 5.168852433806456, 2.0577884326577673,
        9.527564824580319, 8.822415260194632, 0.0, 8.130071122189571, 7.300538806040907, 8.029404091479583, 0.0, 0.0,
        0.0, 0.0, 5.190577670999363, 2.0573314116070915, 9.598137955899421, 8.934099351636013, 0.0, 7.8891519161045,
        7.336540146198017, 8.079717237694817, 0.0, 0.0, 0.0, 0.0, 5.209514668560927, 2.0616885113981254,
        9.665789544005243, 9.044219633355395, 0.0, 7.652917759176871, 7.372541486355087, 8.127347892487203, 0.0, 0.0,
        0.0, 0.0, 5.225849309133541, 2.0705387906416686, 9.73071435844499, 9.152880359333723, 0.0, 7.421063104722468,
        7.408542826512204, 8.1724710009489, 0.0, 0.0, 0.0, 0.0, 5.239751311651024, 2.083589215894988,
        9.79309023228388, 9.260176717989957, 0.0, 7.189543985623522, 7.440386741938089, 8.211443016906884, 0.0, 0.0,
        0.0, 0.0, 5.247685974094739, 2.0958524017329627, 9.849213472131208, 9.361964701752783, 0.033345203284784616,
        6.931787575017754, 7.438941260606965, 8.217722752473955, 0.0, 0.0, 0.0, 0.0, 5.2239049771230945,
        2.0740725384525027, 9.872104751392433, 9.428656769818005, 0.33369264325367365, 6.678381446534033,
        7.438200283879645, 8.222521462428537, 0.0, 0.0, 0.0, 0.0, 5.198687197420195, 2.056652730948191,
        9.893490556449756, 9.494909292747552, 0.6283895060613429, 6.429061279232999, 7.438121006413495,
        8.225929133136862, 0.0, 0.0, 0.0, 0.0, 5.172119933176749, 2.0433280644388385, 9.913462359153659,
        9.560748977082007, 0.9177791179148124, 6.183583740439262, 7.438664021800448, 8.228028605645157, 0.0, 0.0,
        0.0, 0.0, 5.144283550718087, 2.0338546595599825, 9.93210436808113, 9.626200408742502, 1.202177543387296,
        5.94172444308623, 7.439792991772424, 8.228896271090289, 0.0, 0.0, 0.0, 0.0, 5.115252159136938,
        2.028007625121397, 9.949494235423076, 9.691286259417417, 1.4818762386178357, 5.703276137067728,
        7.441474353297422, 8.228602686438984, 0.0, 0.0, 0.0, 0.0, 5.085094207643222, 2.025579245394048,
        9.965703682893889, 9.75602746930737, 1.7571444005652554, 0.09221898294864211, 0.07695240463377147,
        0.08053156566000481, 0.0868843290556984, 0.0908313081462534, 0.0954657419587419, 0.10159897181424378,
        0.08301137587547082, 0.07211771857868028, 0.07922374962049389, 0.07400376298524122, 0.06716008872275776
    ],
    "A.12": [
        5.333333333333333, 5.333333333333333
    ],
    "A.14": [
        0.09000000000000001, 0.09, 0.09000000000000001, 0.09000000000000001, 0.09, 0.09000000000000001,
        0.09000000000000001, 0.09000000000000001, 0.09000000000000001, 0.09000000000000001
    ],
    "A.15": [
        46.66162197326001, 32.15403037589608, 15.003128505250944, 22.107190344271036, 12.33958719429866,
        12.339587194298051
    ],
}


# Further isolated GNEs, found by the same independent method from random start points (200 for A.3) and kept
# under the same tests; ``_REFERENCES`` holds the one the report prints. A.3 has at least five.
_OTHER_EQUILIBRIA: dict[str, list[list[float]]] = {
    "A.3": [
        [0.626889466225791, 10.0, 9.373110533774213, 1.8688592347661788, 10.0, 0.3353408911982389, -10.0],
        [-0.8039027804428321, -0.3062095142768687, -2.3540626361808883, 0.9701401790732516, 3.1227929746614396,
         0.07511948459529103, -0.12810559569697177],
        [-0.901779685589555, -4.401727679619797, -2.1791108128183883, -2.0033863583948035, -2.454128444156363,
         -0.03158057819974359, 2.9224958599868622],
        [1.9630374054083461, -1.3943674277445415, 5.188843136315971, -3.1328766544950497, -10.0,
         -0.03978803989177305, 1.6392484066723536],
    ],
}


def known_equilibria(label: str) -> list[np.ndarray]:
    """Every independently verified isolated GNE of a problem: the reference first, then the others."""
    out = [np.array(_REFERENCES[label], dtype=float)] if label in _REFERENCES else []
    return out + [np.array(a, dtype=float) for a in _OTHER_EQUILIBRIA.get(label, [])]


# How the large references were located (the checks that accept them are the same as for the others).
_REFERENCE_ORIGIN = {
    label: "the Newton/least-squares solve was started from a 5%-perturbed copy of the end point of gnerun's default "
           "solver (from the library's start point the solve takes from many minutes to hours at these sizes); the "
           "solve and every check use the numpy writing only"
    for label in ("A.10c", "A.10d", "A.10e")
}


def _reference_source(game: _Game) -> str:
    text = ("computed with numpy/SciPy only: the Fischer-Burmeister form of the concatenated KKT system (complex-step "
            "derivatives of an independent numpy writing) solved by Newton/Levenberg-Marquardt")
    text += (f"; {_REFERENCE_ORIGIN[game.label]}" if game.label in _REFERENCE_ORIGIN
             else ", from the library's start points and random points")
    text += "; kept where the point is feasible and every best-response gap (SLSQP, several starts) is <= 1e-7"
    if game.printed is not None:
        text += f"; agrees with {game.printed_source} to {game.printed_tol:g}"
    else:
        text += "; no solution of this problem is printed in the publications"
    return text


def problems() -> list[Problem]:
    """One :class:`Problem` per problem/start pair of the library (44 pairs)."""
    out = []
    for game in games():
        ref = _REFERENCES.get(game.label) if game.isolated else None
        for label, start in game.starts:
            out.append(Problem(
                family="fk", name=game.label, start=f"x0 = {label}",
                config_yaml=game.config_yaml(label, start, _config_name(game, label)),
                has_gne=game.has_gne,
                reference=None if ref is None else np.array(ref, dtype=float),
                reference_tol=1e-5 * max(1.0, float(np.max(np.abs(ref)))) if ref is not None else 1e-4,
                reference_source=_reference_source(game) if ref is not None else "",
                best_response_gaps=lambda a, game=game: best_response_gaps(game, a),
                published=dict(game.published.get(label, {})),
                notes=game.notes,
            ))
    return out


def game_of(problem: Problem) -> _Game:
    """The numpy writing behind a Problem of this module."""
    for game in games():
        if game.label == problem.name:
            return game
    raise KeyError(problem.name)
