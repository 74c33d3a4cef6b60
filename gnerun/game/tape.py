"""A compiled function's instruction tape, read three ways: over intervals, at points, and for its kinks.

CasADi keeps an SX Function as a list of scalar instructions (``instruction_id``, ``instruction_input``,
``instruction_output``, ``instruction_constant``) over a work vector. This module evaluates that list

- **over boxes** (:meth:`Tape.bounds`): interval arithmetic, every result rounded outwards by one ulp, so that the
  interval returned contains the function's value at every point of the box where it is defined (a function
  undefined somewhere in a box, such as log near 0 or 1/y across 0, gets the whole line there). Many boxes are
  evaluated at once, one numpy array per work slot. This is what makes a best-response gap a guarantee on a box
  (:mod:`gnerun.solvers.global_response`);
- **at points** (:meth:`Tape.kinks`): the distance of each piecewise instruction (abs, min, max, sign, comparisons)
  whose arguments depend on the first input from its kink, relative to the arguments' size: at a point where one is
  within a tolerance of its kink, the derivative taken is one branch's, and a KKT point there says nothing about
  the other branches;
- **for structure** (:func:`piecewise_outputs`): which outputs pass through a piecewise instruction whose arguments
  depend on the first input. Such an output is never affine, whatever its second derivative (zero almost
  everywhere) says.

Only the scalar instructions of SX Functions exist here (MX Functions are refused at build time).
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

_OP = {getattr(ca, name): name[3:] for name in dir(ca) if name.startswith("OP_")}

# instructions whose value jumps or kinks: a branch is chosen by the arguments' values
PIECEWISE = frozenset({"FABS", "FMIN", "FMAX", "SIGN", "FLOOR", "CEIL", "FMOD", "REMAINDER", "COPYSIGN", "LT", "LE",
                       "EQ", "NE", "NOT", "AND", "OR", "IF_ELSE_ZERO"})
_BINARY = frozenset({"ADD", "SUB", "MUL", "DIV", "POW", "CONSTPOW", "FMIN", "FMAX", "ATAN2", "HYPOT", "LT", "LE",
                     "EQ", "NE", "AND", "OR", "IF_ELSE_ZERO", "COPYSIGN", "FMOD", "REMAINDER"})
_UNARY = frozenset({"ASSIGN", "NEG", "TWICE", "SQ", "INV", "SQRT", "EXP", "LOG", "SIN", "COS", "TAN", "ASIN", "ACOS",
                    "ATAN", "SINH", "COSH", "TANH", "ASINH", "ACOSH", "ATANH", "FABS", "SIGN", "FLOOR", "CEIL", "NOT",
                    "ERF", "LOG1P", "EXPM1"})
_INF = math.inf
# instructions whose value may jump (not Lipschitz across a point of a box): a mean-value bound J(m) + [grad J] (y - m)
# needs a continuous J, and the derivative's tape says nothing of a jump (atan2's cut: its gradient is finite there)
_JUMPS = frozenset({"ATAN2", "SIGN", "FLOOR", "CEIL", "LT", "LE", "EQ", "NE", "AND", "OR", "NOT", "IF_ELSE_ZERO",
                    "COPYSIGN", "FMOD", "REMAINDER"})


class UnsupportedTape(ValueError):
    """A function whose tape has an instruction that intervals are not defined for here."""


class Tape:
    """The instruction list of an SX Function ``f``, evaluated over boxes or at points (see the module docstring)."""

    def __init__(self, f: ca.Function) -> None:
        if not f.is_a("SXFunction"):
            raise UnsupportedTape(f"{f.name()} is not an SX function")
        self.n_in = [f.nnz_in(i) for i in range(f.n_in())]
        self.n_out = [f.nnz_out(i) for i in range(f.n_out())]
        self.size = f.sz_w()
        self.code: list[tuple[str, tuple[int, ...], tuple[int, ...], float]] = []
        for k in range(f.n_instructions()):
            op = _OP.get(f.instruction_id(k), "?")
            if op not in _BINARY and op not in _UNARY and op not in ("CONST", "INPUT", "OUTPUT"):
                raise UnsupportedTape(f"instruction {op} of {f.name()}")
            const = f.instruction_constant(k) if op == "CONST" else 0.0
            self.code.append((op, tuple(f.instruction_input(k)), tuple(f.instruction_output(k)), const))
        self.jumps = any(op in _JUMPS for op, *_ in self.code)  # the function may be discontinuous (_JUMPS)

    # ---------------------------------------------------------------------------------------------- boxes
    def bounds(self, lo: list[np.ndarray], hi: list[np.ndarray]) -> tuple[list[np.ndarray], list[np.ndarray]]:
        """Enclosures of every output over B boxes: ``lo[i]``, ``hi[i]`` are input i's bounds, shaped (nnz_i, B) (or
        (nnz_i,) for an input that is the same in every box); returns per output arrays (nnz_out, B)."""
        B = max((v.shape[1] for v in lo if v.ndim == 2), default=1)
        wl: list[np.ndarray | None] = [None] * self.size
        wh: list[np.ndarray | None] = [None] * self.size
        out_l = [np.zeros((n, B)) for n in self.n_out]
        out_h = [np.zeros((n, B)) for n in self.n_out]
        for op, i, o, const in self.code:
            if op == "CONST":
                wl[o[0]] = wh[o[0]] = np.full(B, const)
            elif op == "INPUT":
                vl, vh = lo[i[0]], hi[i[0]]
                wl[o[0]] = np.broadcast_to(vl[i[1]], (B,)).astype(float)
                wh[o[0]] = np.broadcast_to(vh[i[1]], (B,)).astype(float)
            elif op == "OUTPUT":
                out_l[o[0]][o[1]] = wl[i[0]]
                out_h[o[0]][o[1]] = wh[i[0]]
            elif op in _UNARY:
                wl[o[0]], wh[o[0]] = _unary(op, wl[i[0]], wh[i[0]])
            else:
                wl[o[0]], wh[o[0]] = _binary(op, wl[i[0]], wh[i[0]], wl[i[1]], wh[i[1]])
        return out_l, out_h

    # ---------------------------------------------------------------------------------------------- points
    def kinks(self, args: list[np.ndarray]) -> tuple[float, list[str]]:
        """At the point ``args`` (one vector per input): the smallest relative distance of a piecewise instruction
        whose arguments depend on input 0 from its kink (``inf`` if there is none), and the names of the
        instructions that realise it."""
        best, where = _INF, []
        for op, gap in self._distances(args):
            if gap < best:
                best, where = gap, [op.lower()]
            elif gap == best and op.lower() not in where:
                where.append(op.lower())
        return best, where

    def kinks_within(self, args: list[np.ndarray], tol: float) -> list[str]:
        """At the point ``args``: the names of the piecewise instructions whose arguments depend on input 0 and lie
        within ``tol`` (relative, as :meth:`kinks` measures) of their kink, each name once, in the tape's order (what
        :func:`kink_function`'s distances say at one point, without building that function)."""
        return list(dict.fromkeys(op.lower() for op, gap in self._distances(args) if gap <= tol))

    def _distances(self, args: list[np.ndarray]):
        """The tape evaluated at ``args``: (name, relative distance from its kink) of each piecewise instruction
        whose arguments depend on input 0, in order."""
        w = np.zeros(self.size)
        dep = np.zeros(self.size, dtype=bool)
        for op, i, o, const in self.code:
            if op == "CONST":
                w[o[0]], dep[o[0]] = const, False
                continue
            if op == "INPUT":
                w[o[0]], dep[o[0]] = float(np.asarray(args[i[0]]).reshape(-1)[i[1]]), i[0] == 0
                continue
            if op == "OUTPUT":
                continue
            x = w[i[0]]
            y = w[i[1]] if op in _BINARY else 0.0
            d = bool(dep[i[0]] or (op in _BINARY and dep[i[1]]))
            if op in PIECEWISE and d:
                yield op, _kink_distance(op, x, y)
            with np.errstate(all="ignore"):
                w[o[0]] = _point(op, x, y)
            dep[o[0]] = d


def kink_function(f: ca.Function) -> tuple[ca.Function, list[str]] | None:
    """For the SX Function ``f``: a Function of f's inputs whose outputs are the relative distances of f's piecewise
    nodes whose arguments depend on input 0 from their kinks (what :meth:`Tape.kinks` computes, compiled once for
    evaluation at many points), and the nodes' names; None if there are none."""
    ins = f.sx_in()
    outs = f.call(ins)  # the outputs as expressions of fresh inputs (sx_out would give bare symbols)
    a = ins[0]
    stack = [o[k] for o in outs for k in range(o.numel())]
    seen: set[int] = set()
    rows, names = [], []
    while stack:
        e = stack.pop()
        if e.is_leaf():
            continue
        h = e.element_hash()
        if h in seen:
            continue
        seen.add(h)
        deps = [e.dep(k) for k in range(e.n_dep())]
        stack.extend(deps)
        op = _OP.get(e.op(), "?")
        if op not in PIECEWISE or not any(ca.depends_on(d, a) for d in deps):
            continue
        x = deps[0]
        y = deps[1] if len(deps) > 1 else ca.SX(0)
        if op in ("FABS", "SIGN", "NOT", "IF_ELSE_ZERO", "COPYSIGN"):
            z = y if op == "COPYSIGN" else x
            d = ca.fabs(z) / ca.fmax(1, ca.fabs(z))
        elif op in ("FLOOR", "CEIL"):
            d = ca.fabs(x - ca.floor(x + 0.5)) / ca.fmax(1, ca.fabs(x))
        elif op in ("FMOD", "REMAINDER"):
            r = ca.fmod(x, y)
            d = ca.fmin(ca.fabs(r), ca.fabs(ca.fabs(y) - ca.fabs(r))) / ca.fmax(1, ca.fabs(y))
        else:
            d = ca.fabs(x - y) / ca.fmax(1, ca.fmax(ca.fabs(x), ca.fabs(y)))
        rows.append(d)
        names.append(op.lower())
    if not rows:
        return None
    return ca.Function("kinks", ins, [ca.vertcat(*rows)]), names


def piecewise_outputs(f: ca.Function) -> np.ndarray:
    """Which nonzeros of output 0 of the SX Function ``f`` pass through a piecewise instruction (abs, min, max,
    sign, a comparison...) whose arguments depend on input 0."""
    tape = Tape(f)
    dep = np.zeros(tape.size, dtype=bool)  # depends on input 0
    pw = np.zeros(tape.size, dtype=bool)  # has passed through a piecewise instruction of input 0
    out = np.zeros(tape.n_out[0], dtype=bool)
    for op, i, o, _ in tape.code:
        if op == "CONST":
            dep[o[0]] = pw[o[0]] = False
        elif op == "INPUT":
            dep[o[0]], pw[o[0]] = i[0] == 0, False
        elif op == "OUTPUT":
            if o[0] == 0:
                out[o[1]] = pw[i[0]]
        else:
            args = i[:2] if op in _BINARY else i[:1]
            d = any(dep[j] for j in args)
            pw[o[0]] = any(pw[j] for j in args) or (op in PIECEWISE and d)
            dep[o[0]] = d
    return out


def _kink_distance(op: str, x: float, y: float) -> float:
    """How far the arguments are from switching the instruction's branch, relative to their size."""
    if op in ("FABS", "SIGN", "NOT", "COPYSIGN"):
        z = y if op == "COPYSIGN" else x
        return abs(z) / max(1.0, abs(z))
    if op in ("FLOOR", "CEIL"):
        return abs(x - round(x)) / max(1.0, abs(x))
    if op == "IF_ELSE_ZERO":
        return abs(x) / max(1.0, abs(x))
    if op in ("FMOD", "REMAINDER"):
        r = math.fmod(x, y) if y else 0.0
        return min(abs(r), abs(abs(y) - abs(r))) / max(1.0, abs(y))
    return abs(x - y) / max(1.0, abs(x), abs(y))  # min, max, comparisons


def _point(op: str, x: float, y: float) -> float:
    return float(_POINT[op](x, y))


_POINT = {
    "ASSIGN": lambda x, y: x, "NEG": lambda x, y: -x, "TWICE": lambda x, y: 2 * x, "SQ": lambda x, y: x * x,
    "INV": lambda x, y: np.divide(1.0, x), "SQRT": lambda x, y: np.sqrt(x), "EXP": lambda x, y: np.exp(x),
    "LOG": lambda x, y: np.log(x), "SIN": lambda x, y: np.sin(x), "COS": lambda x, y: np.cos(x),
    "TAN": lambda x, y: np.tan(x), "ASIN": lambda x, y: np.arcsin(x), "ACOS": lambda x, y: np.arccos(x),
    "ATAN": lambda x, y: np.arctan(x), "SINH": lambda x, y: np.sinh(x), "COSH": lambda x, y: np.cosh(x),
    "TANH": lambda x, y: np.tanh(x), "ASINH": lambda x, y: np.arcsinh(x), "ACOSH": lambda x, y: np.arccosh(x),
    "ATANH": lambda x, y: np.arctanh(x), "FABS": lambda x, y: abs(x), "SIGN": lambda x, y: np.sign(x),
    "FLOOR": lambda x, y: np.floor(x), "CEIL": lambda x, y: np.ceil(x), "NOT": lambda x, y: float(not x),
    "ERF": lambda x, y: math.erf(x) if math.isfinite(x) else np.sign(x), "LOG1P": lambda x, y: np.log1p(x),
    "EXPM1": lambda x, y: np.expm1(x),
    "ADD": lambda x, y: x + y, "SUB": lambda x, y: x - y, "MUL": lambda x, y: x * y,
    "DIV": lambda x, y: np.divide(x, y), "POW": lambda x, y: np.power(x, y), "CONSTPOW": lambda x, y: np.power(x, y),
    "FMIN": lambda x, y: min(x, y), "FMAX": lambda x, y: max(x, y), "ATAN2": lambda x, y: np.arctan2(x, y),
    "HYPOT": lambda x, y: np.hypot(x, y), "LT": lambda x, y: float(x < y), "LE": lambda x, y: float(x <= y),
    "EQ": lambda x, y: float(x == y), "NE": lambda x, y: float(x != y), "AND": lambda x, y: float(bool(x and y)),
    "OR": lambda x, y: float(bool(x or y)), "IF_ELSE_ZERO": lambda x, y: y if x else 0.0,
    "COPYSIGN": lambda x, y: np.copysign(x, y), "FMOD": lambda x, y: np.fmod(x, y),
    "REMAINDER": lambda x, y: np.remainder(x, y),
}


# ------------------------------------------------------------------------------------------------ interval rules
def _out(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Round outwards by one ulp; an undefined end (nan) becomes the whole line."""
    lo = np.nextafter(lo, -_INF)
    hi = np.nextafter(hi, _INF)
    bad = np.isnan(lo) | np.isnan(hi)
    if bad.any():
        lo = np.where(bad, -_INF, lo)
        hi = np.where(bad, _INF, hi)
    return lo, hi


def _hull(*vals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    stack = np.vstack(vals)
    bad = np.isnan(stack).any(axis=0)
    lo, hi = np.min(stack, axis=0), np.max(stack, axis=0)
    return np.where(bad, -_INF, lo), np.where(bad, _INF, hi)


def _increasing(f, lo, hi, dom_lo=-_INF, dom_hi=_INF):
    """A function increasing on its domain [dom_lo, dom_hi]; a box reaching outside it gets the whole line."""
    with np.errstate(all="ignore"):
        a, b = f(lo), f(hi)
    outside = (lo < dom_lo) | (hi > dom_hi)
    return _out(np.where(outside, -_INF, a), np.where(outside, _INF, b))


def _mul(al, ah, bl, bh):
    with np.errstate(all="ignore"):
        p = [al * bl, al * bh, ah * bl, ah * bh]
    # 0 * inf is 0 in interval arithmetic (a zero bound times an unbounded one)
    zero = [((al == 0) | (bl == 0)), ((al == 0) | (bh == 0)), ((ah == 0) | (bl == 0)), ((ah == 0) | (bh == 0))]
    p = [np.where(np.isnan(v) & z, 0.0, v) for v, z in zip(p, zero, strict=True)]
    return _out(*_hull(*p))


def _inv(lo, hi):
    across = (lo <= 0) & (hi >= 0)
    with np.errstate(all="ignore"):
        a, b = 1.0 / hi, 1.0 / lo
    return _out(np.where(across, -_INF, a), np.where(across, _INF, b))


def _sq(lo, hi):
    with np.errstate(all="ignore"):
        a, b = lo * lo, hi * hi
    low, high = _out(np.minimum(a, b), np.maximum(a, b))
    return np.where((lo <= 0) & (hi >= 0), 0.0, np.maximum(low, 0.0)), high


def _abs(lo, hi):
    return (np.where(lo >= 0, lo, np.where(hi <= 0, -hi, 0.0)), np.maximum(np.abs(lo), np.abs(hi)))


def _int_power(lo, hi, n: int):
    if n == 0:
        return np.ones_like(lo), np.ones_like(hi)
    if n < 0:
        pl, ph = _int_power(lo, hi, -n)
        return _inv(pl, ph)
    with np.errstate(all="ignore"):
        a, b = lo**n, hi**n
    if n % 2:
        return _out(a, b)
    low, high = _out(np.minimum(a, b), np.maximum(a, b))
    return np.where((lo <= 0) & (hi >= 0), 0.0, np.maximum(low, 0.0)), high


def _pow(al, ah, bl, bh):
    """x ** y: integer exponents by cases; otherwise exp(y log x), defined for x >= 0."""
    if np.all(bl == bh) and np.all(bl == bl[0]) and float(bl[0]).is_integer() and abs(bl[0]) <= 1024:
        return _int_power(al, ah, int(bl[0]))
    with np.errstate(all="ignore"):
        cands = [np.power(al, bl), np.power(al, bh), np.power(ah, bl), np.power(ah, bh)]
        lo, hi = _hull(*cands)
    # x**y is monotone in x and in y for x > 0, so the extremes are at the corners; 0 ** y is 0 for y > 0
    bad = al < 0
    lo, hi = np.where(bad, -_INF, lo), np.where(bad, _INF, hi)
    return _out(lo, hi)


def _periodic(lo, hi, f, peak: float, trough: float):
    """sin or cos: the values at the ends, and 1 or -1 where a peak or a trough lies inside."""
    two_pi = 2 * math.pi
    with np.errstate(all="ignore"):
        a, b = f(lo), f(hi)
        wide = ~((hi - lo) < two_pi)
        k = np.ceil((lo - peak) / two_pi)
        has_peak = wide | (peak + k * two_pi <= hi)
        k = np.ceil((lo - trough) / two_pi)
        has_trough = wide | (trough + k * two_pi <= hi)
    low = np.where(has_trough, -1.0, np.minimum(a, b))
    high = np.where(has_peak, 1.0, np.maximum(a, b))
    low, high = _out(low, high)
    return np.maximum(low, -1.0), np.minimum(high, 1.0)


def _tan(lo, hi):
    with np.errstate(all="ignore"):
        k = np.ceil((lo - math.pi / 2) / math.pi)
        pole = ~((hi - lo) < math.pi) | (math.pi / 2 + k * math.pi <= hi)
        a, b = np.tan(lo), np.tan(hi)
    return _out(np.where(pole, -_INF, a), np.where(pole, _INF, b))


def _cosh(lo, hi):
    with np.errstate(all="ignore"):
        a, b = np.cosh(lo), np.cosh(hi)
    low = np.where((lo <= 0) & (hi >= 0), 1.0, np.minimum(a, b))
    return _out(low, np.maximum(a, b))


def _logic(lo, hi):
    """A truth value's interval: 0 where the argument is exactly 0, 1 where 0 is outside it, [0, 1] otherwise."""
    zero = (lo == 0) & (hi == 0)
    nonzero = (lo > 0) | (hi < 0)
    return np.where(nonzero, 1.0, 0.0), np.where(zero, 0.0, 1.0)


def _unary(op: str, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    if op == "ASSIGN":
        return lo, hi
    if op == "NEG":
        return -hi, -lo
    if op == "TWICE":
        return _out(2 * lo, 2 * hi)
    if op == "SQ":
        return _sq(lo, hi)
    if op == "INV":
        return _inv(lo, hi)
    if op == "FABS":
        return _abs(lo, hi)
    if op == "SQRT":
        return _increasing(np.sqrt, lo, hi, 0.0)
    if op == "EXP":
        return _increasing(np.exp, lo, hi)
    if op == "LOG":
        return _increasing(np.log, lo, hi, 0.0)
    if op == "LOG1P":
        return _increasing(np.log1p, lo, hi, -1.0)
    if op == "EXPM1":
        return _increasing(np.expm1, lo, hi)
    if op == "SIN":
        return _periodic(lo, hi, np.sin, math.pi / 2, -math.pi / 2)
    if op == "COS":
        return _periodic(lo, hi, np.cos, 0.0, math.pi)
    if op == "TAN":
        return _tan(lo, hi)
    if op == "ASIN":
        return _increasing(np.arcsin, lo, hi, -1.0, 1.0)
    if op == "ACOS":  # decreasing
        with np.errstate(all="ignore"):
            a, b = np.arccos(hi), np.arccos(lo)
        bad = (lo < -1) | (hi > 1)
        return _out(np.where(bad, -_INF, a), np.where(bad, _INF, b))
    if op == "ATAN":
        return _increasing(np.arctan, lo, hi)
    if op == "SINH":
        return _increasing(np.sinh, lo, hi)
    if op == "COSH":
        return _cosh(lo, hi)
    if op == "TANH":
        return _increasing(np.tanh, lo, hi)
    if op == "ASINH":
        return _increasing(np.arcsinh, lo, hi)
    if op == "ACOSH":
        return _increasing(np.arccosh, lo, hi, 1.0)
    if op == "ATANH":
        return _increasing(np.arctanh, lo, hi, -1.0, 1.0)
    if op == "ERF":
        from scipy.special import erf

        return _increasing(erf, lo, hi)
    if op == "SIGN":
        return np.sign(lo), np.sign(hi)
    if op == "FLOOR":
        return np.floor(lo), np.floor(hi)
    if op == "CEIL":
        return np.ceil(lo), np.ceil(hi)
    if op == "NOT":
        t_lo, t_hi = _logic(lo, hi)
        return 1.0 - t_hi, 1.0 - t_lo
    raise UnsupportedTape(op)


def _atan2(yl, yh, xl, xh):
    """atan2(y, x) over a box: continuous where the box holds neither the origin nor a point of its branch cut (y = 0,
    x < 0), and then its extremes are at corners (its level sets are rays from the origin, and a ray that only touches
    a box touches a corner); elsewhere [-pi, pi]."""
    with np.errstate(all="ignore"):
        corners = [np.arctan2(y, x) for y in (yl, yh) for x in (xl, xh)]
    lo, hi = _out(np.minimum.reduce(corners), np.maximum.reduce(corners))
    whole = (yl <= 0) & (yh >= 0) & (xl <= 0)  # the cut, or the origin (y = 0, x = 0): the angle may jump
    whole |= np.isnan(yl) | np.isnan(yh) | np.isnan(xl) | np.isnan(xh)
    return np.where(whole, -math.pi, np.maximum(lo, -math.pi)), np.where(whole, math.pi, np.minimum(hi, math.pi))


def _binary(op: str, al, ah, bl, bh) -> tuple[np.ndarray, np.ndarray]:
    if op == "ADD":
        return _out(al + bl, ah + bh)
    if op == "SUB":
        return _out(al - bh, ah - bl)
    if op == "MUL":
        return _mul(al, ah, bl, bh)
    if op == "DIV":
        il, ih = _inv(bl, bh)
        return _mul(al, ah, il, ih)
    if op in ("POW", "CONSTPOW"):
        return _pow(al, ah, bl, bh)
    if op == "FMIN":
        return np.minimum(al, bl), np.minimum(ah, bh)
    if op == "FMAX":
        return np.maximum(al, bl), np.maximum(ah, bh)
    if op == "HYPOT":
        sl, sh = _sq(al, ah)
        tl, th = _sq(bl, bh)
        low, high = _out(sl + tl, sh + th)
        return _increasing(np.sqrt, np.maximum(low, 0.0), high)
    if op == "ATAN2":
        return _atan2(al, ah, bl, bh)
    if op in ("LT", "LE"):
        strict = op == "LT"
        true = (ah < bl) if strict else (ah <= bl)
        false = (al >= bh) if strict else (al > bh)
        return np.where(true, 1.0, 0.0), np.where(false, 0.0, 1.0)
    if op in ("EQ", "NE"):
        disjoint = (ah < bl) | (bh < al)
        same = (al == ah) & (bl == bh) & (al == bl)
        lo, hi = np.where(same, 1.0, 0.0), np.where(disjoint, 0.0, 1.0)
        return (lo, hi) if op == "EQ" else (1.0 - hi, 1.0 - lo)
    if op in ("AND", "OR"):
        xl, xh = _logic(al, ah)
        yl, yh = _logic(bl, bh)
        return (np.minimum(xl, yl), np.minimum(xh, yh)) if op == "AND" else (np.maximum(xl, yl), np.maximum(xh, yh))
    if op == "IF_ELSE_ZERO":
        tl, th = _logic(al, ah)
        lo = np.where(th == 0, 0.0, np.where(tl == 1, bl, np.minimum(bl, 0.0)))
        hi = np.where(th == 0, 0.0, np.where(tl == 1, bh, np.maximum(bh, 0.0)))
        return lo, hi
    if op in ("COPYSIGN", "FMOD", "REMAINDER"):
        m = np.maximum(np.abs(al), np.abs(ah)) if op == "COPYSIGN" else np.maximum(np.abs(bl), np.abs(bh))
        return -m, m
    raise UnsupportedTape(op)
