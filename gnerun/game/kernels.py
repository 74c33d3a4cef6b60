"""Compiled stage kernels: the sparse formulation's KKT function built from per-stage CasADi Functions, generated as
C, compiled once by the system's C compiler and kept in an on-disk cache.

The sparse system of a dynamic game (gnerun.game.sparse) is a sum over stages: the stage-tau part of agent i's
Lagrangian,

    l_i(xi(tau+1), u(tau)) + lambda(tau)^T c(tau) + p_i(tau)^T d(tau)[R_i],   d(tau) = f(xi(tau), u(tau)) - xi(tau+1),

touches only the stage's unknowns (xi(tau), u(tau), xi(tau+1), lambda(tau), p(tau)), and so does each row of F and
each nonzero of dF/dw. One small Function per stage gives the stage's rows and their Jacobian; stages whose
Functions are the same expression (most of them: a stage differs only when its data do, e.g. a reference that
depends on tau) share one, so the C code holds each distinct stage once however long the horizon. The whole-horizon
function (roll-out of the states, costates by the backward recursion, the stage calls, their sums into F and the
nonzeros of dF/dw in the interpreted system's pattern) is a CasADi MX graph of calls to these, generated into the
same C file.

The interpreted path (``solver.compile: interpreted``, or no C compiler) evaluates the SX function of
gnerun.game.sparse; both give the same values up to rounding (the sums are taken in another order).

The cache: ``$GNERUN_CACHE_DIR`` or ``$XDG_CACHE_HOME/gnerun`` (``~/.cache/gnerun``), folder ``kernels``, one shared
library per generated source, named by a hash of the source, the CasADi version, the compiler and its flags.
Beside each library, the system's pattern and layout under a hash of the game, the code that builds it and the same
versions: a second run of the same game (any x0 or runtime values) loads both and builds nothing. Deleting the
folder clears it.
"""

from __future__ import annotations

import hashlib
import os
import re
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np

FLAGS = ("-O2", "-fPIC", "-shared")


@dataclass
class KernelReport:
    """What became of the compiled kernels of one game: used or not (why), cache hit or compile time, where."""

    mode: str  # "compiled" or "interpreted"
    reason: str = ""  # why interpreted
    path: str = ""  # the shared library
    cache_hit: bool = False
    compile_s: float = 0.0  # gcc's time (0 on a cache hit)
    stages: int = 0  # stage Functions in the C code (distinct stages)
    horizon: int = 0
    form: str = "stages"  # "stages": the sparse system's stage kernels; "condensed": the condensed KKT function
    operations: int = 0  # the condensed KKT function's
    note: str = ""  # after the line's parenthesis (a condensed function evaluated once)
    quiet: bool = False  # the default's choice that needs no line on the terminal (summary.json still has it)

    def as_dict(self) -> dict:
        """For summary.json."""
        out: dict = {"mode": self.mode}
        if self.form == "condensed":
            out["function"] = "condensed"
            if self.operations:
                out["operations"] = self.operations
        if self.mode == "compiled" and self.form == "condensed":
            out.update(cache_hit=self.cache_hit, compile_s=self.compile_s, library=self.path)
        elif self.mode == "compiled":
            out.update(cache_hit=self.cache_hit, compile_s=self.compile_s, library=self.path,
                       stage_functions=self.stages, stages=self.horizon)
        elif self.reason:
            out["reason"] = self.reason
        return out

    def line(self) -> str:
        if self.mode != "compiled":
            return f"kernels: interpreted ({self.reason})" if self.reason else "kernels: interpreted"
        how = "cache hit" if self.cache_hit else f"compiled in {self.compile_s:.1f} s"
        if self.form == "condensed":
            return (f"kernels: compiled C, the condensed KKT function of {self.operations:,} operations ({how}; "
                    f"{self.path}){self.note}")
        return (f"kernels: compiled C, {self.stages} stage function{'s' if self.stages != 1 else ''} for "
                f"{self.horizon} stages ({how}; {self.path})")


def cache_dir() -> Path:
    """Where compiled kernels are kept."""
    root = os.environ.get("GNERUN_CACHE_DIR")
    if root:
        return Path(root) / "kernels"
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "gnerun" / "kernels"


def compiler() -> str | None:
    """The C compiler: ``$CC``, else gcc or cc on the PATH (None: none)."""
    cc = os.environ.get("CC")
    if cc:
        return shutil.which(cc)
    return shutil.which("gcc") or shutil.which("cc")


def sources_digest() -> str:
    """A hash of the code that turns a config into a compiled system (gnerun.game, gnerun.language): a cached system
    built by other code is not used."""
    global _SOURCES
    if _SOURCES is None:
        h = hashlib.sha256()
        root = Path(__file__).resolve().parents[1]
        for path in sorted([*root.glob("game/*.py"), *root.glob("language/*.py")]):
            h.update(path.name.encode())
            h.update(path.read_bytes())
        _SOURCES = h.hexdigest()
    return _SOURCES


_SOURCES: str | None = None


def entry_key(game_key: str) -> str:
    """The cache's name for a game's compiled system: the game (gnerun.game.compile.compile_key), the code that
    builds it, CasADi's version, the compiler and its flags."""
    cc = compiler() or ""
    return hashlib.sha256("\n".join([game_key, sources_digest(), ca.__version__, cc, *FLAGS]).encode()).hexdigest()[:24]


def save_entry(key: str, library: Path, arrays: dict[str, np.ndarray]) -> None:
    """What a cache hit needs besides the library (the system's pattern and layout), next to it."""
    folder = cache_dir()
    with tempfile.NamedTemporaryFile(dir=folder, suffix=".npz", delete=False) as f:
        np.savez(f, library=np.array(library.name), **arrays)
    os.replace(f.name, folder / f"system-{key}.npz")


def load_entry(key: str) -> tuple[Path, dict[str, np.ndarray]] | None:
    """The library and arrays saved for ``key``, if both are in the cache and readable."""
    path = cache_dir() / f"system-{key}.npz"
    try:
        with np.load(path) as data:
            arrays = {k: data[k] for k in data.files}
    except (OSError, ValueError, EOFError):
        return None
    library = cache_dir() / str(arrays.pop("library"))
    return (library, arrays) if library.exists() else None


# CasADi's C code checks an output's pointer before every entry it writes: one branch per output nonzero
_GUARD = re.compile(r"if \(res\[\d+\]!=0\) ")


def build_library(functions: list[ca.Function], name: str, flags: tuple[str, ...] = FLAGS, *,
                  all_outputs: bool = False) -> tuple[Path, bool, float]:
    """C code for ``functions`` (and every Function they call), compiled with ``flags`` into a shared library in the
    cache unless one built from the same source, CasADi version, compiler and flags is there. Returns its path,
    whether it was a cache hit, and the compile time in seconds. Raises RuntimeError when the compiler fails.

    ``all_outputs``: the library's functions are always called with every output buffer (gnerun.game.evaluator does),
    so the check of an output's pointer before each entry written is left out of the C code: thousands of branches
    in one function, half of gcc's time on the condensed KKT functions of the FK library (A.9b: 7.3 s of gcc -O1 CPU
    time with them, 3.9 s without). Functions called by the MX graph of another (the stage kernels) must keep them."""
    gen = ca.CodeGenerator(f"{name}.c", {"with_header": False})
    for f in functions:
        gen.add(f)
    source = gen.dump()
    if all_outputs:
        source = _GUARD.sub("", source)
    return build_source(source, name, flags, (ca.__version__,))


def build_source(source: str, name: str, flags: tuple[str, ...], versions: tuple[str, ...] = ()) -> tuple[Path, bool,
                                                                                                        float]:
    """C ``source`` compiled with ``flags`` into the shared library ``name-<hash>.so`` in the cache, unless one built
    from the same source, ``versions`` (of what generated it), compiler and flags is there. Returns its path, whether
    it was a cache hit, and the compile time in seconds. Raises RuntimeError when there is no compiler or it fails
    (OSError where the cache cannot be written)."""
    cc = compiler()
    if cc is None:
        raise RuntimeError("no C compiler found (gcc, cc or $CC)")
    key = hashlib.sha256("\n".join([source, *versions, cc, *flags]).encode()).hexdigest()[:24]
    folder = cache_dir()
    lib = folder / f"{name}-{key}.so"
    if lib.exists():
        return lib, True, 0.0
    folder.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(dir=folder) as tmp:
        src = Path(tmp) / f"{name}.c"
        src.write_text(source)
        out = Path(tmp) / lib.name
        run = subprocess.run([cc, *flags, str(src), "-o", str(out), "-lm"], capture_output=True, text=True)
        if run.returncode != 0:
            raise RuntimeError(f"{Path(cc).name} failed: {run.stderr.strip()[:300]}")
        os.replace(out, lib)  # atomic: a concurrent run sees the whole library or none
    return lib, False, time.perf_counter() - t0


class Stages:
    """The per-stage Functions of a sparse system, deduplicated, and where their rows and nonzeros go.

    Built by gnerun.game.sparse.compile_sparse from the same expressions as the interpreted system."""

    def __init__(self) -> None:
        self.groups: dict[str, tuple[ca.Function, ...]] = {}  # serialization -> (rows, rows and Jacobian, c rows)
        self.calls: list[tuple[ca.Function, ...]] = []  # per stage
        self.row_maps: list[np.ndarray] = []  # per stage: global row of each local row (-1: none)
        self.col_maps: list[np.ndarray] = []  # per stage: global column of each local unknown (-1: a given value)
        self.jac_entries: list[tuple[np.ndarray, np.ndarray]] = []  # per stage: local (row, col) of each nonzero
        self.gxn: list[list[slice]] = []  # per stage, per agent: its grad_{xi(tau+1)} rows among the local rows

    def add(self, inputs: list[ca.SX], rows: ca.SX, unknowns: ca.SX, row_map: np.ndarray, col_map: np.ndarray,
            gxn: list[slice], constraints: int = 0) -> None:
        """One stage: its Function of ``inputs`` (xi(tau), u(tau), xi(tau+1), lambda(tau), p(tau), runtime
        values), the local rows ``rows``, their Jacobian in ``unknowns`` (a vertcat of some inputs); the last
        ``constraints`` rows are constraint values c (a Function of their own computes them alone)."""
        J = ca.jacobian(rows, unknowns)
        r, c = J.sparsity().get_triplet()
        raw = ca.Function("raw", inputs, [rows, ca.vertcat(*J.nonzeros())])
        fresh = [ca.SX.sym(f"v{k}", raw.sparsity_in(k)) for k in range(raw.n_in())]
        out = raw(*fresh)
        both = ca.Function("stage", fresh, out)
        key = both.serialize()
        if key not in self.groups:
            g = len(self.groups)
            self.groups[key] = (ca.Function(f"stage{g}_f", fresh, [out[0]]), ca.Function(f"stage{g}_fj", fresh, out),
                                ca.Function(f"stage{g}_c", fresh, [out[0][rows.numel() - constraints:]]))
        self.calls.append(self.groups[key])
        self.row_maps.append(row_map)
        self.col_maps.append(col_map)
        self.jac_entries.append((np.asarray(r, dtype=int), np.asarray(c, dtype=int)))
        self.gxn.append(gxn)


def scatter(n_out: int, targets: list[np.ndarray]) -> ca.DM:
    """The 0/1 matrix that sums the concatenated local values into ``n_out`` global ones (target -1: dropped)."""
    t = np.concatenate(targets) if targets else np.zeros(0, dtype=int)
    cols = np.flatnonzero(t >= 0)
    rows = t[cols]
    order = np.lexsort((rows, cols))  # column-major, as CasADi stores
    cols, rows = cols[order], rows[order]
    colind = np.searchsorted(cols, np.arange(t.size + 1))
    sparsity = ca.Sparsity(n_out, t.size, colind.tolist(), rows.tolist())
    return ca.DM(sparsity, np.ones(rows.size))


def pattern_positions(pattern: ca.Sparsity, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Positions of the entries (rows, cols) among the nonzeros of ``pattern`` (-1 where rows or cols is -1).
    Raises ValueError for an entry outside the pattern."""
    colind = np.asarray(pattern.colind())
    prow = np.asarray(pattern.row())
    out = np.full(rows.size, -1, dtype=int)
    keep = (rows >= 0) & (cols >= 0)
    for k in np.flatnonzero(keep):
        lo, hi = colind[cols[k]], colind[cols[k] + 1]
        pos = lo + np.searchsorted(prow[lo:hi], rows[k])
        if pos >= hi or prow[pos] != rows[k]:
            raise ValueError(f"stage entry ({rows[k]}, {cols[k]}) is not in the system's pattern")
        out[k] = pos
    return out


def kernel_report(game) -> KernelReport | None:
    """How ``game``'s KKT system is evaluated: its sparse system, if one was built, else its condensed KKT function
    (gnerun.game.condensed), if a solver asked for it (None: neither)."""
    system = game.derived.get("sparse")
    if system is not None:
        return system.kernels
    return game.derived.get("condensed")
