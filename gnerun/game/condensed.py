"""The condensed KKT function compiled to C: what a condensed semismooth Newton solve evaluates at every iterate (L, c
and their derivatives, ``CompiledGame._kkt``; L and c alone at a line search's trial points, ``_residual``), generated
as C, compiled and cached like the sparse system's stage kernels (gnerun.game.kernels: the same cache folder, one
shared library per generated source, named by its hash, the CasADi version, the compiler and its flags).

The function is generated with sparse outputs: its derivatives' nonzeros alone. Densified outputs write every
structural zero too; on the paper's game that is 4,963 operations instead of 1,706, 167 KB of C instead of 57 KB, and
the 5-7 s that gcc -O2 took on it. It is compiled at -O1: on these long straight-line functions -O2 costs 2-4x the
compile time for no faster code (measured: the two-vehicle game's 25,572 operations, gcc -O1 6.1 s and 11.6 us per
evaluation, -O2 24 s and 17.6 us; interpreted 120 us).

``solver.compile: compiled`` compiles it for a condensed ``ssn`` solve, up to ``COMPILE_UP_TO`` operations (beyond,
one function of straight-line code takes gcc minutes: the 20-knot merge's 628,000 operations more than 6 minutes; its
sparse formulation compiles per stage). ``auto`` keeps it interpreted: an evaluation saves 20-110 us against 0.4-6 s
of gcc, which a solve or a closed loop does not win back. Both give the same iterates up to rounding.
"""

from __future__ import annotations

import casadi as ca

from ..errors import one_line
from ..language.config import Config
from .building import stoppable
from .compile import CompiledGame
from .evaluator import DenseOutputs, Evaluator
from .kernels import KernelReport, build_library, compiler

FLAGS = ("-O1", "-fPIC", "-shared")
COMPILE_UP_TO = 100_000  # operations of the condensed KKT function (the overtaking game's 170,000: 36 s of gcc -O1)


@stoppable  # gcc may take seconds: Ctrl-C stops the wait
def condensed_kernels(cfg: Config, game: CompiledGame) -> KernelReport:
    """Evaluate ``game``'s condensed KKT function as ``cfg.solver.compile`` asks (compiled C or CasADi's interpreter)
    from now on; the report is kept in ``game.derived["condensed"]`` (gnerun.game.kernels.kernel_report). A game asked
    again in the same mode is left as it is; in another mode, it is switched."""
    mode = cfg.solver.compile
    report = game.derived.get("condensed")
    if report is not None and game.derived.get("condensed_mode") == mode:
        return report
    interpreted = game.derived.get("condensed_interpreted")
    if interpreted is not None:  # compiled before in another mode: back to the interpreter first
        game._derivatives["kkt"], game.__dict__["_residual"] = interpreted
    why = _why_interpreted(mode, cfg.solver.kind)
    if why:
        # the default (auto) keeps a condensed function interpreted: said in summary.json, not on the terminal
        report = KernelReport("interpreted", reason=why, form="condensed", quiet=mode == "auto")
    else:
        report = _compile(game)
    game.derived["condensed"] = report
    game.derived["condensed_mode"] = mode
    return report


def _why_interpreted(mode: str, kind: str) -> str:
    """Why the condensed KKT function stays interpreted before anything is built ('': it is compiled if it is not
    too long)."""
    if mode == "interpreted":
        return "solver.compile: interpreted"
    if kind != "ssn":
        return f"solver.kind: {kind} (the condensed KKT function is compiled for ssn)"
    if mode == "auto":
        return "auto: the condensed KKT function is compiled with solver.compile: compiled"
    if compiler() is None:
        return "no C compiler found (gcc, cc or $CC)"
    return ""


def _compile(game: CompiledGame) -> KernelReport:
    """The game's KKT function and residual function compiled (or found in the cache) and put in place of the
    interpreted ones; the interpreted ones are kept (``game.derived["condensed_interpreted"]``)."""
    kkt = game._derivatives["kkt"]
    residual = game._residual
    operations = kkt.function.n_instructions()
    constant = ""
    if game.affine:  # evaluated for the constant matrices, and for the offsets of each state unless they are affine
        constant = "; constant derivatives, evaluated once" + ("" if game.lq.offset_map is not None else " per state")
    if operations > COMPILE_UP_TO:
        return KernelReport("interpreted", form="condensed", operations=operations,
                            reason=f"condensed KKT function of {operations:,} operations, compiled up to "
                                   f"{COMPILE_UP_TO:,}: use solver.formulation: sparse")
    try:
        library, hit, seconds = build_library([kkt.function, residual.function], f"condensed_kkt_{game.n}", FLAGS,
                                             all_outputs=True)
        compiled = (DenseOutputs(ca.external(kkt.function.name(), str(library))),
                    Evaluator(ca.external(residual.function.name(), str(library))))
    except (RuntimeError, ValueError) as why:  # a compiler's or CasADi's failure: the interpreted path stays
        return KernelReport("interpreted", reason=one_line(str(why)), form="condensed", operations=operations)
    game.derived["condensed_interpreted"] = (kkt, residual)
    game._derivatives["kkt"], game.__dict__["_residual"] = compiled
    return KernelReport("compiled", path=str(library), cache_hit=hit, compile_s=seconds, form="condensed",
                        operations=operations, note=constant)
