"""Triangular solves with a banded lower-triangular matrix and many right-hand sides, L Y = B and L^T Y = B, in
place: compiled C that does the arithmetic of LAPACK's dtbtrs (the OpenBLAS that scipy ships) in the same order, so
that its results are the same to the bit, but on all right-hand sides at once.

dtbtrs solves one right-hand side after the other (dtbsv), and OpenBLAS's dtbsv calls a level-1 kernel per row: an
axpy (no transpose: row i is divided by its diagonal entry, then -y_i times the column below the diagonal is added to
the rows below, one fused multiply-add each) or a dot product (transpose: the dot product of the entries below the
diagonal with the rows below, accumulated by fused multiply-adds from 0 in the order of the rows, is subtracted from
row i, which is then divided by its diagonal entry). On the players' blocks of the interior step (band width 5, 240
to 480 rows, 40 to 80 right-hand sides) those calls cost more than the arithmetic. The C code below makes the same
operations on each right-hand side, row after row, with the right-hand sides side by side in a row (a C-ordered
array), where the compiler vectorises them; a vector operation rounds each of its lanes as the scalar one does.

It is compiled once per machine by the system's C compiler into the kernels' cache (gnerun.game.kernels) and used
when three things hold: the library builds and loads, the processor has fused multiply-add (the library's code for
it is compiled for AVX2 and FMA and checks the processor before it runs), and its results on a test band equal
LAPACK's bit for bit (another BLAS, or OpenBLAS's kernels for a processor without FMA, round differently). Otherwise
the solves are LAPACK's. Only the payload of a NaN can differ (which of two NaN operands an instruction passes on
depends on the instruction's form): where LAPACK's result is NaN, so is this one's.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import subprocess
import tempfile
from pathlib import Path

import numpy as np
from scipy.linalg import lapack

from ..game.kernels import cache_dir, compiler

FLAGS = ("-O3", "-fPIC", "-shared", "-ffp-contract=off")  # no contraction: the fused multiply-adds are LAPACK's only

_SOURCE = r"""
#include <stddef.h>

#define CHUNK 64 /* right-hand sides per pass of the transposed solve's dot products */

/* band: n rows of k + 1, band[i][0] the diagonal entry L[i][i], band[i][r] = L[i + r][i];
   b: n rows of m right-hand sides (C order), overwritten by the solution */

static int first_zero(int n, int k, const double *band) {
    for (int i = 0; i < n; i++)
        if (band[(size_t)i * (k + 1)] == 0.0) return i + 1;
    return 0;
}

/* L y = b (OpenBLAS's dtbsv_NLN, driver/level2/tbsv_L.c, with daxpy's scalar loop: y[i] += alpha * x[i] as one
   fused multiply-add, alpha = -y_i) */
__attribute__((target("avx2,fma")))
static void lower(int n, int k, const double *restrict band, int m, double *restrict b) {
    for (int i = 0; i < n; i++) {
        double *restrict bi = b + (size_t)i * m;
        const double *a = band + (size_t)i * (k + 1);
        double d = a[0];
        for (int j = 0; j < m; j++) bi[j] = bi[j] / d;
        int len = n - i - 1 < k ? n - i - 1 : k;
        for (int j0 = 0; j0 < m && len > 0; j0 += CHUNK) {
            int j1 = m - j0 < CHUNK ? m : j0 + CHUNK;
            double alpha[CHUNK];
            for (int j = j0; j < j1; j++) alpha[j - j0] = -bi[j];
            for (int r = 1; r <= len; r++) {
                double *restrict br = bi + (size_t)r * m;
                double ar = a[r];
                for (int j = j0; j < j1; j++) br[j] = __builtin_fma(ar, alpha[j - j0], br[j]);
            }
        }
    }
}

/* L^T y = b (OpenBLAS's dtbsv_TLN, driver/level2/tbsv_U.c with TRANSA, with ddot's scalar loop: dot = 0, then
   dot += y[i] * x[i] as one fused multiply-add each) */
__attribute__((target("avx2,fma")))
static void upper(int n, int k, const double *restrict band, int m, double *restrict b) {
    for (int i = n - 1; i >= 0; i--) {
        double *restrict bi = b + (size_t)i * m;
        const double *a = band + (size_t)i * (k + 1);
        int len = n - i - 1 < k ? n - i - 1 : k;
        for (int j0 = 0; j0 < m && len > 0; j0 += CHUNK) {
            int j1 = m - j0 < CHUNK ? m : j0 + CHUNK;
            double dot[CHUNK];
            for (int j = j0; j < j1; j++) dot[j - j0] = 0.0;
            for (int r = 1; r <= len; r++) {
                const double *br = bi + (size_t)r * m;
                double ar = a[r];
                for (int j = j0; j < j1; j++) dot[j - j0] = __builtin_fma(ar, br[j], dot[j - j0]);
            }
            for (int j = j0; j < j1; j++) bi[j] = bi[j] - dot[j - j0];
        }
        double d = a[0];
        for (int j = 0; j < m; j++) bi[j] = bi[j] / d;
    }
}

int banded_supported(void) {
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
}

/* 0, or (as dtbtrs's info) the first row whose diagonal entry is zero, b untouched */
int banded_solve(int n, int k, const double *band, int m, double *b, int transpose) {
    int info = first_zero(n, k, band);
    if (info) return info;
    if (transpose) upper(n, k, band, m, b); else lower(n, k, band, m, b);
    return 0;
}
"""


def solve(band: np.ndarray, b: np.ndarray, transpose: bool = False) -> int:
    """Solve L Y = B (or L^T Y = B) in place of ``b`` (n x m, C-ordered, float64), L lower triangular with ``k`` =
    ``band.shape[1] - 1`` diagonals below its own, given as ``band`` (n x (k + 1), C-ordered): ``band[i, 0]`` =
    L[i, i], ``band[i, r]`` = L[i + r, i] (entries beyond the last row: any value, never read). Returns 0, or
    LAPACK's info: the first row (from 1) whose diagonal entry is zero, with ``b`` left as it was."""
    kernel = _kernel()
    if kernel is None:
        y, info = lapack.dtbtrs(band.T, b, uplo="L", trans="T" if transpose else "N")
        if info == 0:
            b[...] = y
        return int(info)
    if not (band.flags.c_contiguous and b.flags.c_contiguous and band.dtype == b.dtype == np.float64):
        raise ValueError("the band and the right-hand sides must be C-ordered arrays of float64")
    n, width = band.shape
    if b.shape[0] != n:
        raise ValueError(f"{b.shape[0]} rows of right-hand sides for a band of {n} rows")
    return kernel(n, width - 1, band.ctypes.data, b.shape[1] if b.ndim == 2 else 1, b.ctypes.data, int(transpose))


def status() -> str:
    """Which solves :func:`solve` makes: "compiled", or "lapack (why)"."""
    _kernel()
    return _STATE["status"]


_STATE: dict = {}  # the loaded kernel (None: LAPACK's solves) and its status, once per process


def _kernel():
    if "kernel" not in _STATE:
        _STATE["kernel"], _STATE["status"] = _load()
    return _STATE["kernel"]


def _load():
    """The compiled solve (built if the cache has none) and "compiled", or None and why not."""
    cc = compiler()
    if cc is None:
        return None, "lapack (no C compiler found: gcc, cc or $CC)"
    key = hashlib.sha256("\n".join([_SOURCE, cc, *FLAGS]).encode()).hexdigest()[:24]
    folder = cache_dir()
    path = folder / f"banded-{key}.so"
    if not path.exists():
        try:
            folder.mkdir(parents=True, exist_ok=True)
            with tempfile.TemporaryDirectory(dir=folder) as tmp:
                src = Path(tmp) / "banded.c"
                src.write_text(_SOURCE)
                out = Path(tmp) / path.name
                run = subprocess.run([cc, *FLAGS, str(src), "-o", str(out)], capture_output=True, text=True)
                if run.returncode != 0:
                    return None, f"lapack ({Path(cc).name} failed: {run.stderr.strip()[:200]})"
                os.replace(out, path)  # atomic: a concurrent process sees the whole library or none
        except OSError as e:
            return None, f"lapack (cannot build in {folder}: {e})"
    try:
        lib = ctypes.CDLL(str(path))
    except OSError as e:
        return None, f"lapack (cannot load {path}: {e})"
    if not lib.banded_supported():
        return None, "lapack (the processor has no AVX2 and FMA)"
    kernel = lib.banded_solve
    kernel.restype = ctypes.c_int
    kernel.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_void_p, ctypes.c_int, ctypes.c_void_p, ctypes.c_int]
    if not _agrees(kernel):
        return None, "lapack (the compiled solves round differently from this LAPACK's)"
    return kernel, "compiled"


def _agrees(kernel) -> bool:
    """Whether ``kernel`` gives LAPACK's results bit for bit on a test band (both directions, right-hand sides of
    several lengths, a short band and one wider than the rows)."""
    rng = np.random.default_rng(0)
    for n, k, m in ((37, 4, 71), (3, 5, 2), (25, 1, 1)):
        band = np.ascontiguousarray(rng.standard_normal((n, k + 1)))
        b = rng.standard_normal((n, m))
        for transpose in (False, True):
            ref, info = lapack.dtbtrs(band.T, b, uplo="L", trans="T" if transpose else "N")
            got = b.copy()
            if info != 0 or kernel(n, k, band.ctypes.data, m, got.ctypes.data, int(transpose)) != 0:
                return False
            if not np.array_equal(ref.view(np.int64), got.view(np.int64)):
                return False
    return True
