"""Banded linear algebra in compiled C that does the arithmetic of LAPACK's routines (the OpenBLAS that scipy ships)
in the same order, so that its results are the same to the bit, without their calls per column into small kernels:
triangular solves with a banded lower-triangular matrix and many right-hand sides (dtbtrs), and banded LU with
partial pivoting (dgbtrf) with its solves (dgbtrs).

dtbtrs solves one right-hand side after the other (dtbsv), and OpenBLAS's dtbsv calls a level-1 kernel per row: an
axpy (no transpose: row i is divided by its diagonal entry, then -y_i times the column below the diagonal is added to
the rows below, one fused multiply-add each) or a dot product (transpose: the dot product of the entries below the
diagonal with the rows below, accumulated by fused multiply-adds from 0 in the order of the rows, is subtracted from
row i, which is then divided by its diagonal entry). On the players' blocks of the interior step (band width 5, 240
to 480 rows, 40 to 80 right-hand sides) those calls cost more than the arithmetic. The C code below makes the same
operations on each right-hand side, row after row, with the right-hand sides side by side in a row (a C-ordered
array), where the compiler vectorises them; a vector operation rounds each of its lanes as the scalar one does.

dgbtrf is reference LAPACK (Fortran) calling OpenBLAS's BLAS; with LAPACK's block size (32, and 1 where ku <= 64) it
is unblocked (dgbtf2) wherever kl < 32 or ku <= 64, as on every band the solvers factorise (kl = 6..18): per column
idamax, a row swap, the multipliers scaled by the reciprocal of the pivot (dscal: one division, then products), and
dger, which OpenBLAS makes as one daxpy per column (y += (-1 * u) x, fused multiply-adds). dgbtrs applies the
swaps and multipliers (dger, or dgemv_t for the transpose: its SSE2 kernel for the rows in fours, products rounded
and added in 2 x 2 lanes, then the last rows in fused multiply-adds) and solves with U by dtbsv (axpy, or a dot
product: ddot's 16 lanes of fused multiply-adds for the first n & -16 terms, then one at a time). The C code makes
the same operations on each entry in the same order; only where they are independent does it order them otherwise.
It leaves out the operations that add a zero, which the stage-ordered KKT bands are mostly made of (91% of the
merge's band is zero inside it): dger's columns whose entry in the pivot's row is zero and its rows whose multiplier
is zero, and a solve's axpy of a zero multiple. Adding a zero leaves a finite number as it was, so the values are
LAPACK's to the bit; only a zero's sign can differ (LAPACK's -0 + 0 is +0; nothing downstream tells them apart). A
zero times a value that is not finite is NaN, so such values go back to LAPACK (below).

The same library holds the rest of the interior step's players' blocks of the Schur complement
(:class:`PlayersComplement`: numpy's gathers and divisions and scipy.sparse's products, csr_matvecs, in their order,
without fused multiply-adds as those are compiled, less the additions of zeros: the dynamics' solve and the
multipliers' rows are zero beyond a column that grows with the stage) and the players' convexifying shifts (with the
dpotrf that scipy.linalg.lapack calls, its address taken from scipy.linalg.cython_lapack); the caller compares a
system's first result with its numpy code, value for value, and keeps the numpy code where they differ.

It is compiled once per machine by the system's C compiler into the kernels' cache (gnerun.game.kernels) and used
when three things hold: the library builds and loads, the processor has fused multiply-add (the library's code for
it is compiled for AVX2 and FMA and checks the processor before it runs), and its results on test bands equal
LAPACK's bit for bit (another BLAS, or OpenBLAS's kernels for a processor without FMA, round differently). Otherwise
all of it is LAPACK's. Only the payload of a NaN can differ (which of two NaN operands an instruction passes on
depends on the instruction's form): where LAPACK's result is NaN, so is this one's. A column to pivot on, a
multiplier or an entry of U that is not finite (idamax and dscal treat those their own way, and dger would spread
them as NaNs where the compiled update adds nothing) goes back to LAPACK, as does dgbtrf's blocked path and a
transposed solve of several right-hand sides (dgemv_t sums two and four columns otherwise).
"""

from __future__ import annotations

import ctypes

import numpy as np
from scipy.linalg import lapack

from .kernels import build_source, cache_dir, compiler

FLAGS = ("-O3", "-fPIC", "-shared", "-ffp-contract=off")  # no contraction: the fused multiply-adds are LAPACK's only

_SOURCE = r"""
#include <immintrin.h>
#include <math.h>
#include <stddef.h>
#include <stdlib.h>

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

/* ---- banded LU with partial pivoting (dgbtf2) and its solves (dgbtrs) ---- */

/* ab: LAPACK's band storage, column-major, column j at ab + j * ld, entry (i, j) at ab[j * ld + kl + ku + i - j];
   ld = 2 kl + ku + 1; ipiv: from 0, as scipy returns them */

/* OpenBLAS's daxpy (kernel/x86_64/daxpy.c): y[i] += da * x[i], one fused multiply-add each (the vector loops too) */
__attribute__((target("avx2,fma")))
static void axpy(int n, double da, const double *restrict x, double *restrict y) {
    for (int i = 0; i < n; i++) y[i] = __builtin_fma(da, x[i], y[i]);
}

/* OpenBLAS's ddot (kernel/x86_64/ddot.c, ddot_microk_skylakex-2.c as compiled for SkylakeX): the first n & -16
   terms in 16 lanes of fused multiply-adds (4 x 8 lanes over blocks of 32, folded to 4 x 4, then 4 x 4 over a block
   of 16), the lanes summed (((a0 + a1) + a2) + a3, then the halves, then the pair), then the rest one fused
   multiply-add at a time */
__attribute__((target("avx2,fma")))
static double dot(int n, const double *x, const double *y) {
    int n1 = n & -16, n32 = n1 & -32, i = 0;
    double d = 0.0;
    if (n1) {
        __m256d a0 = _mm256_setzero_pd(), a1 = a0, a2 = a0, a3 = a0;
        if (n32) {  /* 4 x 8 lanes: the low and high halves of each */
            __m256d w0 = a0, w1 = a0, w2 = a0, w3 = a0, w4 = a0, w5 = a0, w6 = a0, w7 = a0;
            for (; i < n32; i += 32) {
                w0 = _mm256_fmadd_pd(_mm256_loadu_pd(x + i), _mm256_loadu_pd(y + i), w0);
                w1 = _mm256_fmadd_pd(_mm256_loadu_pd(x + i + 4), _mm256_loadu_pd(y + i + 4), w1);
                w2 = _mm256_fmadd_pd(_mm256_loadu_pd(x + i + 8), _mm256_loadu_pd(y + i + 8), w2);
                w3 = _mm256_fmadd_pd(_mm256_loadu_pd(x + i + 12), _mm256_loadu_pd(y + i + 12), w3);
                w4 = _mm256_fmadd_pd(_mm256_loadu_pd(x + i + 16), _mm256_loadu_pd(y + i + 16), w4);
                w5 = _mm256_fmadd_pd(_mm256_loadu_pd(x + i + 20), _mm256_loadu_pd(y + i + 20), w5);
                w6 = _mm256_fmadd_pd(_mm256_loadu_pd(x + i + 24), _mm256_loadu_pd(y + i + 24), w6);
                w7 = _mm256_fmadd_pd(_mm256_loadu_pd(x + i + 28), _mm256_loadu_pd(y + i + 28), w7);
            }
            a0 = _mm256_add_pd(w0, w1);
            a1 = _mm256_add_pd(w2, w3);
            a2 = _mm256_add_pd(w4, w5);
            a3 = _mm256_add_pd(w6, w7);
        }
        for (; i < n1; i += 16) {
            a0 = _mm256_fmadd_pd(_mm256_loadu_pd(x + i), _mm256_loadu_pd(y + i), a0);
            a1 = _mm256_fmadd_pd(_mm256_loadu_pd(x + i + 4), _mm256_loadu_pd(y + i + 4), a1);
            a2 = _mm256_fmadd_pd(_mm256_loadu_pd(x + i + 8), _mm256_loadu_pd(y + i + 8), a2);
            a3 = _mm256_fmadd_pd(_mm256_loadu_pd(x + i + 12), _mm256_loadu_pd(y + i + 12), a3);
        }
        __m256d sum = _mm256_add_pd(_mm256_add_pd(_mm256_add_pd(a0, a1), a2), a3);
        __m128d half = _mm_add_pd(_mm256_castpd256_pd128(sum), _mm256_extractf128_pd(sum, 1));
        d = _mm_cvtsd_f64(half) + _mm_cvtsd_f64(_mm_unpackhi_pd(half, half));
    }
    for (; i < n; i++) d = __builtin_fma(y[i], x[i], d);
    return d;
}

/* y - (a^T x) for one column as OpenBLAS's dgemv_t (kernel/x86_64/dgemv_t_4.c, alpha = -1, one column): the first
   m & -4 rows by dgemv_kernel_4x1 (SSE2: products rounded, then added into 2 x 2 lanes), y -= their sum; the last
   m & 3 rows as the compiled C, x negated: y += ((a1 x1 fused a0 x0) fused a2 x2), or y += fma(a0, x0, y) */
__attribute__((target("avx2,fma")))
static inline double gemv_t1(int m, const double *a, const double *x, double y) {
    int m3 = m & 3, m4 = m - m3;
    if (m4) {
        __m128d p = _mm_setzero_pd(), q = p;
        for (int i = 0; i < m4; i += 4) {
            p = _mm_add_pd(p, _mm_mul_pd(_mm_loadu_pd(a + i), _mm_loadu_pd(x + i)));
            q = _mm_add_pd(q, _mm_mul_pd(_mm_loadu_pd(a + i + 2), _mm_loadu_pd(x + i + 2)));
        }
        __m128d v = _mm_add_pd(p, q);
        double t = _mm_cvtsd_f64(v) + _mm_cvtsd_f64(_mm_unpackhi_pd(v, v));
        y = __builtin_fma(t, -1.0, y);
    }
    a += m4;
    x += m4;
    if (m3 == 3) {
        double x0 = x[0] * -1.0, x1 = x[1] * -1.0, x2 = x[2] * -1.0;
        double t = a[1] * x1;
        t = __builtin_fma(a[0], x0, t);
        t = __builtin_fma(a[2], x2, t);
        y = y + t;
    } else if (m3 == 2) {
        double x0 = x[0] * -1.0, x1 = x[1] * -1.0;
        double t = a[1] * x1;
        t = __builtin_fma(a[0], x0, t);
        y = y + t;
    } else if (m3 == 1) {
        y = __builtin_fma(a[0], x[0] * -1.0, y);
    }
    return y;
}

/* OpenBLAS's idamax: the first entry of largest magnitude (from 0), or -1 where one is not finite; the largest
   found in four lanes at a time */
__attribute__((target("avx2,fma")))
static int first_largest(int n, const double *x) {
    const __m256d sign = _mm256_set1_pd(-0.0), top = _mm256_set1_pd(__DBL_MAX__);
    __m256d big = _mm256_setzero_pd(), finite = _mm256_castsi256_pd(_mm256_set1_epi64x(-1));
    int i = 0;
    for (; i + 4 <= n; i += 4) {
        __m256d v = _mm256_andnot_pd(sign, _mm256_loadu_pd(x + i));
        finite = _mm256_and_pd(finite, _mm256_cmp_pd(v, top, _CMP_LE_OQ));
        big = _mm256_max_pd(big, v);
    }
    if (_mm256_movemask_pd(finite) != 15) return -1;
    double lanes[4], best;
    _mm256_storeu_pd(lanes, big);
    best = lanes[0] > lanes[1] ? lanes[0] : lanes[1];
    if (lanes[2] > best) best = lanes[2];
    if (lanes[3] > best) best = lanes[3];
    for (int k = i; k < n; k++) {
        double v = __builtin_fabs(x[k]);
        if (!(v <= __DBL_MAX__)) return -1;
        if (v > best) best = v;
    }
    for (int k = 0; k < n; k++)
        if (__builtin_fabs(x[k]) == best) return k;
    return 0;
}

/* dger as OpenBLAS makes it (kernel/generic/ger.c: one daxpy per column, alpha_c = -1 * y_c): column c = 1 .. cols
   of a (at a step of `step` from a; its entry 0 is y_c, entries 1 .. m are updated) += alpha_c x, one fused
   multiply-add per entry as daxpy's; nothing where that adds a zero: a column whose y_c is zero, the rows outside
   lo .. hi - 1 (x is finite and zero there; no rows where lo = hi, every y_c still checked). So the same values as
   dger's, a zero's sign aside (-0 + 0 is +0). Band KKT matrices are mostly zero inside their band: on the merge's,
   86% of the columns and 77% of the multipliers. Returns 1 where a y_c is not finite (dger's NaNs would reach the
   rows skipped: the caller asks LAPACK), else 0. */
__attribute__((target("avx2,fma")))
static int rank_one(int cols, const double *restrict x, double *restrict a, size_t step, int lo, int hi) {
    for (int c = 1; c <= cols; c++) {
        double alpha = -1.0 * a[c * step];
        if (alpha == 0.0) continue;
        if (!(__builtin_fabs(alpha) <= __DBL_MAX__)) return 1;
        double *u = a + c * step + 1;
        int r = lo;
        __m256d al = _mm256_set1_pd(alpha);
        for (; r + 4 <= hi; r += 4)
            _mm256_storeu_pd(u + r, _mm256_fmadd_pd(al, _mm256_loadu_pd(x + r), _mm256_loadu_pd(u + r)));
        for (; r < hi; r++) u[r] = __builtin_fma(alpha, x[r], u[r]);
    }
    return 0;
}

/* dgbtf2: 0, LAPACK's info (the first zero pivot, from 1; the factorisation goes on as LAPACK's does), or -1 where
   a column to pivot on, a multiplier or an entry of U is not finite (OpenBLAS's idamax and dscal treat those their
   own way, and dger's NaNs reach where rank_one adds nothing: the caller factorises with LAPACK). So factors that
   come back are finite, and a solve may skip a multiple of zero. */
__attribute__((target("avx2,fma")))
int band_lu(int n, int kl, int ku, double *ab, int ld, int *ipiv) {
    int kv = ku + kl, info = 0, ju = 0;
    for (int j = ku + 1; j < (kv < n ? kv : n); j++)  /* the fill of columns ku + 2 .. kv (from 1) */
        for (int i = kv - j; i < kl; i++) ab[(size_t)j * ld + i] = 0.0;
    for (int j = 0; j < n; j++) {
        if (j + kv < n)
            for (int i = 0; i < kl; i++) ab[(size_t)(j + kv) * ld + i] = 0.0;
        int km = kl < n - 1 - j ? kl : n - 1 - j;
        double *col = ab + (size_t)j * ld + kv;  /* the diagonal entry (j, j); (j + r, j) at col[r] */
        int jp = first_largest(km + 1, col);
        if (jp < 0) return -1;
        ipiv[j] = jp + j;
        if (col[jp] != 0.0) {
            int last = j + ku + jp < n - 1 ? j + ku + jp : n - 1;
            if (last > ju) ju = last;
            if (jp != 0)  /* rows j and j + jp in columns j .. ju: a step of ld - 1 along a row */
                for (int c = 0; c <= ju - j; c++) {
                    double *u = col + (size_t)c * (ld - 1), t = u[0];
                    u[0] = u[jp];
                    u[jp] = t;
                }
            if (km > 0) {
                double r = 1.0 / col[0];
                if (!(__builtin_fabs(r) <= __DBL_MAX__)) return -1;  /* a pivot whose reciprocal overflows */
                for (int i = 1; i <= km; i++) col[i] *= r;  /* finite: |col[i]| <= |col[0]| */
                int lo = 0, hi = km;  /* the multipliers' nonzero rows: lo .. hi - 1 */
                while (lo < km && col[1 + lo] == 0.0) lo++;
                while (hi > lo && col[hi] == 0.0) hi--;
                if (ju > j && rank_one(ju - j, col + 1, col, (size_t)ld - 1, lo, hi)) return -1;  /* row j of U */
            }
        } else if (!info) {
            info = j + 1;
        }
    }
    return info;
}

/* dgbtrs, for the m right-hand sides in the columns of b (n rows, column-major): no transpose, or the transpose of
   one right-hand side (with more, dgemv_t's kernels for 2 and 4 columns sum otherwise: the caller asks LAPACK) */
__attribute__((target("avx2,fma")))
int band_lu_solve(int n, int kl, int ku, const double *ab, int ld, const int *ipiv, int m, double *b,
                  int transpose) {
    int kv = kl + ku;
    if (transpose && m != 1) return -1;
    for (int c = 0; c < m; c++) {
        double *x = b + (size_t)c * n;
        if (!transpose) {
            if (kl > 0)
                for (int j = 0; j < n - 1; j++) {
                    int lm = kl < n - 1 - j ? kl : n - 1 - j, l = ipiv[j];
                    if (l != j) { double t = x[l]; x[l] = x[j]; x[j] = t; }
                    if (x[j] != 0.0) axpy(lm, -1.0 * x[j], ab + (size_t)j * ld + kv + 1, x + j + 1);
                }
            for (int i = n - 1; i >= 0; i--) {  /* dtbsv, upper, no transpose (driver/level2/tbsv_U.c) */
                const double *a = ab + (size_t)i * ld;
                x[i] /= a[kv];
                int len = i < kv ? i : kv;
                if (len > 0 && x[i] != 0.0) axpy(len, -x[i], a + kv - len, x + i - len);
            }
        } else {
            for (int i = 0; i < n; i++) {  /* dtbsv, upper, transpose (driver/level2/tbsv_L.c with TRANSA) */
                const double *a = ab + (size_t)i * ld;
                int len = i < kv ? i : kv;
                if (len > 0) x[i] -= dot(len, a + kv - len, x + i - len);
                x[i] /= a[kv];
            }
            if (kl > 0)
                for (int j = n - 2; j >= 0; j--) {
                    int lm = kl < n - 1 - j ? kl : n - 1 - j, l = ipiv[j];
                    x[j] = gemv_t1(lm, x + j + 1, ab + (size_t)j * ld + kv + 1, x[j]);
                    if (l != j) { double t = x[l]; x[l] = x[j]; x[j] = t; }
                }
        }
    }
    return 0;
}

/* numpy's sum (DOUBLE_pairwise_sum: from zero, blocks of at most 128 in 8 accumulators, halves above) of TERM(x[i]):
   abs_sum of |x|, plain_sum of x */
#define PAIRWISE_SUM(name, TERM)                                                                       \
    static double name(const double *x, long n) {                                                      \
        if (n < 8) {                                                                                   \
            double res = 0.0;                                                                          \
            for (long i = 0; i < n; i++) res += TERM(x[i]);                                            \
            return res;                                                                                \
        }                                                                                              \
        if (n <= 128) {                                                                                \
            double r[8];                                                                               \
            long i;                                                                                    \
            for (int k = 0; k < 8; k++) r[k] = TERM(x[k]);                                             \
            for (i = 8; i < n - (n % 8); i += 8)                                                       \
                for (int k = 0; k < 8; k++) r[k] += TERM(x[i + k]);                                    \
            double res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));            \
            for (; i < n; i++) res += TERM(x[i]);                                                      \
            return res;                                                                                \
        }                                                                                              \
        long n2 = n / 2;                                                                               \
        n2 -= n2 % 8;                                                                                  \
        return name(x, n2) + name(x + n2, n - n2);                                                     \
    }
#define SAME(v) (v)
PAIRWISE_SUM(abs_sum, __builtin_fabs)
PAIRWISE_SUM(plain_sum, SAME)

/* numpy's argmax of |x|: the first NaN, or the first largest */
static int abs_argmax(const double *x, int n) {
    int j = 0;
    double best = __builtin_fabs(x[0]);
    if (best != best) return 0;
    for (int i = 1; i < n; i++) {
        double v = __builtin_fabs(x[i]);
        if (v != v) return i;
        if (v > best) { best = v; j = i; }
    }
    return j;
}

/* 1 where the signs of x (x >= 0: 1, else -1; NaN: -1) are those in s */
static int same_signs(const double *x, double *s, int n) {
    for (int i = 0; i < n; i++)
        if ((x[i] >= 0 ? 1.0 : -1.0) != s[i]) return 0;
    return 1;
}

static void signs_of(const double *x, double *s, int n) {
    for (int i = 0; i < n; i++) s[i] = x[i] >= 0 ? 1.0 : -1.0;
}

/* numpy's np.abs(ab).sum(axis=0).max() of a Fortran-ordered (ld, n) array: the 1-norm of the band's matrix */
double band_one_norm(int n, const double *ab, int ld) {
    double norm = 0.0;
    for (int j = 0; j < n; j++) {
        double s = abs_sum(ab + (size_t)j * ld, ld);
        if (s != s) return s;
        if (j == 0 || s > norm) norm = s;
    }
    return norm;
}

static void lu_solve1(int n, int kl, int ku, const double *ab, int ld, const int *ipiv, double *x, int transpose) {
    band_lu_solve(n, kl, ku, ab, ld, ipiv, 1, x, transpose);
}

/* gnerun.game.sparse.EliminatedLU._solve with banded factors of the complement: numpy's operations in their order
   (np.bincount adds its weights, each a rounded product, entry by entry from zeros), so the same values to the bit.
   x_e' = b_e / E; r = b_r - K_re x_e' (bincount); x_r = the complement's solution of r (BandLU.solve: r permuted to
   the band's rows, dgbtrs, back to the kept order); x_e = x_e' - (K_er x_r) / E. dims: n_rest, n_out, n_re, n_er, kl,
   ku, ld; ix: rest, out, K_re's rows and columns, K_er's rows and columns, the band's row and column orders; work:
   2 n_rest + 2 n_out doubles. */
__attribute__((target("avx2,fma")))
void eliminated_solve(const long long *dims, const long long *const *ix, const double *diag, const double *re,
                      const double *er, const double *ab, const int *ipiv, const double *b, double *x, double *work) {
    long long n_rest = dims[0], n_out = dims[1], n_re = dims[2], n_er = dims[3];
    int kl = (int)dims[4], ku = (int)dims[5], ld = (int)dims[6];
    const long long *rest = ix[0], *out = ix[1], *re_row = ix[2], *re_col = ix[3], *er_row = ix[4], *er_col = ix[5];
    const long long *row_order = ix[6], *col_order = ix[7];
    double *acc = work, *y = acc + n_rest, *b_out = y + n_rest, *acc_out = b_out + n_out;
    for (long long j = 0; j < n_out; j++) b_out[j] = b[out[j]] / diag[j];
    for (long long i = 0; i < n_rest; i++) acc[i] = 0.0;
    for (long long k = 0; k < n_re; k++) acc[re_row[k]] += re[k] * b_out[re_col[k]];
    for (long long i = 0; i < n_rest; i++) acc[i] = b[rest[i]] - acc[i];
    for (long long i = 0; i < n_rest; i++) y[i] = acc[row_order[i]];
    if (n_rest) band_lu_solve((int)n_rest, kl, ku, ab, ld, ipiv, 1, y, 0);
    for (long long i = 0; i < n_rest; i++) acc[col_order[i]] = y[i];  /* x_r */
    for (long long i = 0; i < n_rest; i++) x[rest[i]] = acc[i];
    for (long long j = 0; j < n_out; j++) acc_out[j] = 0.0;
    for (long long k = 0; k < n_er; k++) acc_out[er_row[k]] += er[k] * acc[er_col[k]];
    for (long long j = 0; j < n_out; j++) x[out[j]] = b_out[j] - acc_out[j] / diag[j];
}

/* gnerun.game.sparse.inverse_norm with the solves above: the same operations in the same order (numpy's sums and
   argmax included), so the same estimate of ||A^-1||_1 to the bit; work: 2 n doubles */
double band_lu_inverse_norm(int n, int kl, int ku, const double *ab, int ld, const int *ipiv, double *work) {
    double *x = work, *signs = work + n;
    for (int i = 0; i < n; i++) x[i] = 1.0 / n;
    lu_solve1(n, kl, ku, ab, ld, ipiv, x, 0);
    if (n == 1) return __builtin_fabs(x[0]);
    double est = abs_sum(x, n);
    if (!(est - est == 0.0)) return est;  /* not finite */
    signs_of(x, signs, n);
    for (int i = 0; i < n; i++) x[i] = signs[i];
    lu_solve1(n, kl, ku, ab, ld, ipiv, x, 1);
    int j = abs_argmax(x, n);
    for (int iteration = 2; iteration < 6; iteration++) {
        for (int i = 0; i < n; i++) x[i] = 0.0;
        x[j] = 1.0;
        lu_solve1(n, kl, ku, ab, ld, ipiv, x, 0);
        double previous = est;
        est = abs_sum(x, n);
        if (same_signs(x, signs, n) || est <= previous) break;
        signs_of(x, signs, n);
        for (int i = 0; i < n; i++) x[i] = signs[i];
        lu_solve1(n, kl, ku, ab, ld, ipiv, x, 1);
        int last = j;
        j = abs_argmax(x, n);
        if (x[last] == __builtin_fabs(x[j]) || iteration == 5) break;
    }
    for (int i = 0; i < n; i++) x[i] = (i % 2 == 0 ? 1.0 : -1.0) * (1.0 + (double)i / (double)(n - 1));
    lu_solve1(n, kl, ku, ab, ld, ipiv, x, 0);
    double alternating = 2.0 * abs_sum(x, n) / (3.0 * n);
    return alternating > est ? alternating : est;
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

/* ---- the players' blocks of the interior step's Schur complement (gnerun.solvers.interior_point._AgentBlocks) ---- */

/* y (rows x m, C order) = A x for A in CSR form with values data[pos]: scipy's csr_matvecs (y_i += a_ij x_j from
   zeros, row by row, entry by entry, a product then a sum: no fused multiply-add), with nothing added where it adds a
   zero: a row's first product is its start (0 + p is p), a row of x is read up to its length xlen[j] (NULL: m; zero
   beyond), and a row without entries is zeros. So the same values, a zero's sign aside (0 + -0 is +0). ylen (NULL:
   not asked): each row of y's length, the longest of the rows of x it reads. Returns 1 where a value that is not
   finite meets a zero it skips (the product would be NaN: the caller computes with numpy), else 0. */
__attribute__((target("avx2")))
static int csr_times(long long rows, const long long *indptr, const long long *indices, const long long *pos,
                     const double *data, int m, const double *x, const int *xlen, double *y, int *ylen) {
    for (long long i = 0; i < rows; i++) {
        double *restrict yi = y + (size_t)i * m;
        int len = 0;
        for (long long jj = indptr[i]; jj < indptr[i + 1]; jj++) {
            const double a = data[pos[jj]];
            const double *restrict xj = x + (size_t)indices[jj] * m;
            int lj = xlen ? xlen[indices[jj]] : m;
            if (lj < m && !(__builtin_fabs(a) <= __DBL_MAX__)) return 1;
            int k = 0;
            for (; k < (lj < len ? lj : len); k++) yi[k] += a * xj[k];
            for (; k < lj; k++) yi[k] = a * xj[k];  /* beyond the row's length so far: its start */
            if (lj > len) len = lj;
        }
        for (int k = len; k < m; k++) yi[k] = 0.0;
        if (ylen) ylen[i] = len;
    }
    return 0;
}

/* lower's solve of L Y = B where each row of B is zero beyond some column: row i read up to its last nonzero (its
   length, into len), and nothing added where it adds a zero (the same values, a zero's sign aside; lower itself
   stays LAPACK's to the bit, zeros' signs included, for banded_solve). Returns 1 where a value that is not finite
   meets a zero it skips, else 0. */
__attribute__((target("avx2,fma")))
static int lower_rows(int n, int k, const double *restrict band, int m, double *restrict b, int *len) {
    for (int i = 0; i < n; i++) {
        double *restrict bi = b + (size_t)i * m;
        const double *a = band + (size_t)i * (k + 1);
        int l = m;
        while (l > 0 && bi[l - 1] == 0.0) l--;
        len[i] = l;
        double d = a[0];
        int below = n - i - 1 < k ? n - i - 1 : k;
        if (l < m)
            for (int r = 0; r <= below; r++)
                if (!(__builtin_fabs(a[r]) <= __DBL_MAX__)) return 1;
        for (int j = 0; j < l; j++) bi[j] = bi[j] / d;
        for (int j0 = 0; j0 < l && below > 0; j0 += CHUNK) {
            int j1 = l - j0 < CHUNK ? l : j0 + CHUNK;
            double alpha[CHUNK];
            for (int j = j0; j < j1; j++) alpha[j - j0] = -bi[j];
            for (int r = 1; r <= below; r++) {
                double *restrict br = bi + (size_t)r * m;
                double ar = a[r];
                for (int j = j0; j < j1; j++) br[j] = __builtin_fma(ar, alpha[j - j0], br[j]);
            }
        }
    }
    return 0;
}

/* _AgentBlocks.complement's numpy and scipy.sparse operations, in their order, on its gathers and products, with
   nothing added where it adds a zero (the dynamics' solve Y_x and the multipliers' rows Y_lambda are zero beyond a
   column that grows with the stage: half of them): the same values, a zero's sign aside.
   dims: ng (states), m (columns), width (the band's), nI, na (rows of C and of A), and the gathers' lengths n_da,
   n_band, n_ka; ix: da (flat, pos), band (flat, pos), Kx (indptr, indices, pos), Ka (flat, pos), touched,
   Kl (indptr, indices, pos), Ap (indptr, indices, pos); work: ng m + ng (width + 1) + (ng + na) m + na m doubles
   and ng + nI + ng + na ints; K: (nI + ng + na) m, the result (its last na rows the blocks). 0, or 1 where a diagonal
   entry of D_x is zero, or 2 where a value that is not finite (or D's zero) meets a zero the code skips: the caller
   computes that call with numpy. */
__attribute__((target("avx2")))
int players_complement(const long long *dims, const long long *const *ix, const double *data, const double *D,
                       double *work, double *K) {
    long long ng = dims[0], nI = dims[3], na = dims[4];
    int m = (int)dims[1], width = (int)dims[2];
    double *Yx = work, *band = Yx + ng * m, *LY = band + ng * (width + 1), *tmp = LY + (ng + na) * m;
    int *xlen = (int *)(tmp + na * m), *klen = xlen + ng;
    for (long long i = 0; i < ng * m; i++) Yx[i] = 0.0;
    for (long long t = 0; t < dims[5]; t++) Yx[ix[0][t]] = -1.0 * data[ix[1][t]];
    if (ng) {
        for (long long i = 0; i < ng * (width + 1); i++) band[i] = 0.0;
        for (long long t = 0; t < dims[6]; t++) band[ix[2][t]] = data[ix[3][t]];
        if (first_zero((int)ng, width, band)) return 1;
        if (lower_rows((int)ng, width, band, m, Yx, xlen)) return 2;
    }
    long long rows = nI + ng + na;
    if (csr_times(rows, ix[4], ix[5], ix[6], data, m, Yx, ng ? xlen : NULL, K, klen)) return 2;
    for (long long t = 0; t < dims[7]; t++) {
        long long at = ix[7][t], row = at / m;
        int col = (int)(at - row * m) + 1;
        K[at] += data[ix[8][t]];
        if (col > klen[row]) klen[row] = col;  /* a row's length: beyond it, zeros */
    }
    for (long long i = 0; i < nI; i++) {  /* Y_lambda */
        double d = D[ix[9][i]];
        if (klen[i] < m && !(d != 0.0 && __builtin_fabs(d) <= __DBL_MAX__)) return 2;
        for (int k = 0; k < klen[i]; k++) K[i * m + k] = K[i * m + k] / d;
    }
    if (csr_times(ng + na, ix[10], ix[11], ix[12], data, m, K, klen, LY, NULL)) return 2;
    double *G = K + nI * m;
    for (long long i = 0; i < ng * m; i++) G[i] = -(G[i] + LY[i]);
    if (ng) upper((int)ng, width, band, m, G);
    csr_times(na, ix[13], ix[14], ix[15], data, m, G, NULL, tmp, NULL);  /* G's rows whole: nothing skipped */
    double *S = G + ng * m;
    for (long long i = 0; i < na * m; i++) S[i] = (S[i] + tmp[i]) + LY[ng * m + i];
    return 0;
}

/* ---- whether every player's block is positive definite, by a recursion over its stages ---- */

/* Cholesky factor (lower, in place) of the k x k matrix a (row-major); 0 where a pivot is not positive (dpotrf's
   test: not > 0, NaN included) */
static int cholesky(int k, double *a) {
    for (int j = 0; j < k; j++) {
        double d = a[j * k + j];
        for (int p = 0; p < j; p++) d -= a[j * k + p] * a[j * k + p];
        if (!(d > 0.0)) return 0;
        d = __builtin_sqrt(d);
        a[j * k + j] = d;
        for (int i = j + 1; i < k; i++) {
            double v = a[i * k + j];
            for (int p = 0; p < j; p++) v -= a[i * k + p] * a[j * k + p];
            a[i * k + j] = v / d;
        }
    }
    return 1;
}

/* gnerun.solvers.interior_point._StageRecursion: each player's block of the interior step's Schur complement is
   the reduced Hessian of its barrier Lagrangian on its dynamics x(t+1) = A_t x(t) + B_t u(t). Stage t's group of
   unknowns is z = (u(t), x(t), y = x(t+1)) (m = nu + 2 nx; x(0) is no unknown), its Hessian H_t the symmetric part of
   the entries K assigns it plus C' D^-1 C over the multipliers it carries. From P_T = 0, with W = H_yy + P_{t+1}:
     uu = H_uu + B' W B + H_uy B + B' H_uy',  ux = H_ux + B' W A + H_uy A + B' H_xy',
     P_t = H_xx + A' W A + H_xy A + A' H_xy' - ux' uu^-1 ux;
   the block is positive definite exactly when every uu is. dims: per player T, nu, nx and its multiplier terms; ix
   (positions in data, -1: zero): per player and stage the number of H's entries (m x m), then those entries' places
   in H and positions, B (nx x nu), A (nx x nx), the dynamics' diagonal on x(t+1) (nx: -1 there), then per term its
   stage (terms listed by stage), its multiplier (in D), its column over the group's rows (m) and its row over the
   group's columns (m). Returns 1 where every player's block is positive definite, 0 where one is not, -1 where the
   recursion cannot tell (a dynamics diagonal other than -1, a value not finite). */
static double at_(const double *data, long long k) { return k >= 0 ? data[k] : 0.0; }

/* out = A B (row-major, r x k times k x c), each entry summed from zero in the order of k */
static void product(int r, int k, int c, const double *A, const double *B, double *out) {
    for (int i = 0; i < r; i++)
        for (int j = 0; j < c; j++) {
            double v = 0.0;
            for (int p = 0; p < k; p++) v += A[i * k + p] * B[p * c + j];
            out[i * c + j] = v;
        }
}

int players_definite(int agents, const long long *dims, const long long *const *ix, const double *data,
                     const double *D, double *work) {
    const long long *hn = ix[0], *hi = ix[1], *hp = ix[2], *bp = ix[3], *ap = ix[4], *dp = ix[5], *tg = ix[6],
                    *td = ix[7], *tc = ix[8], *tr = ix[9];
    for (int g = 0; g < agents; g++) {
        int T = (int)dims[4 * g], nu = (int)dims[4 * g + 1], nx = (int)dims[4 * g + 2];
        long long terms = dims[4 * g + 3];
        int m = nu + 2 * nx, X = nu, Yo = nu + nx;  /* the group's x(t) and y = x(t+1) from these columns */
        double *P = work, *W = P + nx * nx, *H = W + nx * nx, *uu = H + m * m, *ux = uu + nu * nu, *Y = ux + nu * nx,
               *WB = Y + nu * nx, *WA = WB + nx * nu, *Bm = WA + nx * nx, *Am = Bm + nx * nu;
        for (int i = 0; i < nx * nx; i++) P[i] = 0.0;
        long long end = terms;
        long long entries = 0;  /* H's entries of this player, all stages */
        for (int t = 0; t < T; t++) entries += hn[t];
        long long h_end = entries;
        for (int t = T - 1; t >= 0; t--) {
            const long long *b = bp + (long long)t * nx * nu, *a = ap + (long long)t * nx * nx,
                            *d = dp + (long long)t * nx;
            long long h_start = h_end - hn[t];
            for (int i = 0; i < nx; i++)
                if (d[i] < 0 || data[d[i]] != -1.0) return -1;
            for (int i = 0; i < nx * nu; i++) Bm[i] = at_(data, b[i]);
            for (int i = 0; i < nx * nx; i++) Am[i] = at_(data, a[i]);
            for (int i = 0; i < m * m; i++) H[i] = 0.0;
            for (long long e = h_start; e < h_end; e++) H[hi[e]] = data[hp[e]];
            h_end = h_start;
            long long k = end;
            while (k > 0 && tg[k - 1] == t) {  /* + col D^-1 row, over the entries there are */
                k--;
                double inv = 1.0 / D[td[k]], cv[m], rv[m];
                int ci[m], ri[m], nc = 0, nr = 0;
                const long long *col = tc + k * m, *row = tr + k * m;
                for (int i = 0; i < m; i++) {
                    if (col[i] >= 0) { ci[nc] = i; cv[nc++] = data[col[i]] * inv; }
                    if (row[i] >= 0) { ri[nr] = i; rv[nr++] = data[row[i]]; }
                }
                for (int a = 0; a < nc; a++)
                    for (int b = 0; b < nr; b++) H[ci[a] * m + ri[b]] += cv[a] * rv[b];
            }
            end = k;
            for (int i = 0; i < m; i++)  /* the symmetric part, in place */
                for (int j = i + 1; j < m; j++) {
                    double v = 0.5 * (H[i * m + j] + H[j * m + i]);
                    H[i * m + j] = H[j * m + i] = v;
                }
#define HH(i, j) H[(i) * m + (j)]
            for (int i = 0; i < nx; i++)
                for (int j = 0; j < nx; j++) W[i * nx + j] = HH(Yo + i, Yo + j) + P[i * nx + j];
            product(nx, nx, nu, W, Bm, WB);
            for (int i = 0; i < nu; i++)  /* uu = H_uu + B' W B + H_uy B + B' H_uy' */
                for (int j = 0; j < nu; j++) {
                    double v = HH(i, j);
                    for (int p = 0; p < nx; p++)
                        v += Bm[p * nu + i] * WB[p * nu + j] + HH(i, Yo + p) * Bm[p * nu + j]
                             + Bm[p * nu + i] * HH(j, Yo + p);
                    uu[i * nu + j] = v;
                }
            for (int i = 0; i < nu * nu; i++)
                if (!(__builtin_fabs(uu[i]) <= __DBL_MAX__)) return -1;
            if (!cholesky(nu, uu)) return 0;
            if (t == 0) break;
            product(nx, nx, nx, W, Am, WA);
            for (int i = 0; i < nu; i++)  /* ux = H_ux + B' W A + H_uy A + B' H_xy' */
                for (int j = 0; j < nx; j++) {
                    double v = HH(i, X + j);
                    for (int p = 0; p < nx; p++)
                        v += Bm[p * nu + i] * WA[p * nx + j] + HH(i, Yo + p) * Am[p * nx + j]
                             + Bm[p * nu + i] * HH(X + j, Yo + p);
                    ux[i * nx + j] = v;
                }
            for (int j = 0; j < nx; j++) {  /* Y = uu^-1 ux by the Cholesky factor */
                for (int i = 0; i < nu; i++) {
                    double v = ux[i * nx + j];
                    for (int p = 0; p < i; p++) v -= uu[i * nu + p] * Y[p * nx + j];
                    Y[i * nx + j] = v / uu[i * nu + i];
                }
                for (int i = nu - 1; i >= 0; i--) {
                    double v = Y[i * nx + j];
                    for (int p = i + 1; p < nu; p++) v -= uu[p * nu + i] * Y[p * nx + j];
                    Y[i * nx + j] = v / uu[i * nu + i];
                }
            }
            for (int i = 0; i < nx; i++)  /* P = H_xx + A' W A + H_xy A + A' H_xy' - ux' Y */
                for (int j = 0; j < nx; j++) {
                    double v = HH(X + i, X + j);
                    for (int p = 0; p < nx; p++)
                        v += Am[p * nx + i] * WA[p * nx + j] + HH(X + i, Yo + p) * Am[p * nx + j]
                             + Am[p * nx + i] * HH(X + j, Yo + p);
                    for (int p = 0; p < nu; p++) v -= ux[p * nx + i] * Y[p * nx + j];
                    P[i * nx + j] = v;
                }
#undef HH
            for (int i = 0; i < nx * nx; i++)
                if (!(__builtin_fabs(P[i]) <= __DBL_MAX__)) return -1;
        }
        hn += T; hi += entries; hp += entries;
        bp += (long long)T * nx * nu; ap += (long long)T * nx * nx; dp += (long long)T * nx;
        tg += terms; td += terms; tc += terms * m; tr += terms * m;
    }
    return 1;
}

/* ---- the players' convexifying shifts (gnerun.solvers.interior_point.convexifying_shift) ---- */

typedef void (*potrf_t)(char *, int *, double *, int *, int *);

/* whether LAPACK's dpotrf (lower; scipy's own, passed in) factorises sym + delta I (with shifted), as
   interior_point._positive_definite asks it of the same array: sym is symmetric, so its row-major copy is the
   column-major one */
static int definite(potrf_t potrf, int k, const double *sym, double delta, int shifted, double *a) {
    for (int i = 0; i < k; i++)
        for (int j = 0; j < k; j++)
            a[(size_t)i * k + j] = shifted ? sym[(size_t)i * k + j] + delta * (i == j ? 1.0 : 0.0)
                                           : sym[(size_t)i * k + j];
    char uplo = 'L';
    int n = k, lda = k, info = 0;
    potrf(&uplo, &n, a, &lda, &info);
    return info == 0;
}

/* numpy's np.max(np.abs(v), initial=0.0) folded into Python's max(1.0, .): a NaN makes numpy's maximum NaN, and
   max(1.0, NaN) is 1.0 */
static double scale_of(int nan, double largest) { return nan ? 1.0 : (largest > 1.0 ? largest : 1.0); }

/* convexifying_shift of the k x k block at b (row stride m): 0 where its symmetric part is positive definite, else
   the first of 1e-8 scale, 1e-7 scale, ... (scale: the largest diagonal entry, at least 1) that makes it so */
static double shift_of(potrf_t potrf, int k, const double *b, int m, double *sym, double *a) {
    if (k == 0) return 0.0; /* an empty block is positive definite (dpotrf of order 0 succeeds) */
    for (int i = 0; i < k; i++)
        for (int j = 0; j < k; j++) sym[(size_t)i * k + j] = 0.5 * (b[(size_t)i * m + j] + b[(size_t)j * m + i]);
    if (definite(potrf, k, sym, 0.0, 0, a)) return 0.0;
    int nan = 0;
    double largest = 0.0;
    for (int i = 0; i < k; i++) {
        double v = __builtin_fabs(sym[(size_t)i * k + i]);
        if (v != v) nan = 1; else if (v > largest) largest = v;
    }
    double scale = scale_of(nan, largest), delta = 1e-8 * scale;
    while (delta < 1e12 * scale && !definite(potrf, k, sym, delta, 1, a)) delta *= 10.0;
    return delta;
}

/* SparseBarrier._shifts on the stacked blocks S (agents blocks of decisions[i] rows from row rows[i], m columns):
   each block's shift into deltas, and the largest |diagonal entry + shift|, at least 1, returned; work: 2 m m */
double players_shifts(int agents, const long long *rows, const long long *decisions, int m, const double *S,
                      void *potrf, double *work, double *deltas) {
    int nan = 0;
    double largest = 0.0;
    for (int i = 0; i < agents; i++) {
        int k = (int)decisions[i];
        const double *b = S + (size_t)rows[i] * m;
        deltas[i] = shift_of((potrf_t)potrf, k, b, m, work, work + (size_t)m * m);
        for (int j = 0; j < k; j++) {
            double v = __builtin_fabs(b[(size_t)j * m + j] + deltas[i]);
            if (v != v) nan = 1; else if (v > largest) largest = v;
        }
    }
    return scale_of(nan, largest);
}

/* ---- the interior phase's bookkeeping (gnerun.solvers.interior_point.InteriorPoint.measure and reset_slacks) ---- */

/* one step of linalg.largest (numpy's max of |v|: a NaN wins, 0 for an empty v) over v_k = a: 1 once it is NaN */
static int fold_largest(double a, long long k, double *best) {
    a = __builtin_fabs(a);
    if (a != a) { *best = a; return 1; }
    if (k == 0 || a > *best) *best = a;
    return 0;
}

/* Python's max(a, b): b where b > a (a NaN first stays) */
static double py_max(double a, double b) { return b > a ? b : a; }

/* InteriorPoint.measure's error of H_eps at (z, w) given L and c: max(largest(L), largest(c_I + w), largest(c_E),
   largest(lambda_I w - eps)), the same number. dims: n, nI, nE; ix: I, E. */
double barrier_error(const long long *dims, const long long *const *ix, const double *L, const double *c,
                     const double *z, const double *w, double eps) {
    long long n = dims[0], nI = dims[1], nE = dims[2];
    const long long *I = ix[0], *E = ix[1];
    double part[4] = {0.0, 0.0, 0.0, 0.0};
    for (long long k = 0; k < n && !fold_largest(L[k], k, &part[0]); k++) {}
    for (long long k = 0; k < nI && !fold_largest(c[I[k]] + w[k], k, &part[1]); k++) {}
    for (long long k = 0; k < nE && !fold_largest(c[E[k]], k, &part[2]); k++) {}
    for (long long k = 0; k < nI && !fold_largest(z[n + I[k]] * w[k] - eps, k, &part[3]); k++) {}
    return py_max(py_max(py_max(part[0], part[1]), part[2]), part[3]);
}

/* InteriorPoint.reset_slacks: the rows guessed inactive (lambda_j <= w_j) whose constraint lies further inside than
   the slack (-c_j > w_j, finite) get w_j = -c_j, their multiplier times the old slack over the new. Returns 0 where no
   row is reset (z_new and w_new not written), else 1 with the new z and w. dims: n, nI, z's size; ix: I. */
int slack_reset(const long long *dims, const long long *const *ix, const double *c, const double *z, const double *w,
                double *z_new, double *w_new) {
    long long n = dims[0], nI = dims[1], nz = dims[2];
    const long long *I = ix[0];
#define RESETS(k) (-c[I[k]] > w[k] && z[n + I[k]] <= w[k] && -c[I[k]] - -c[I[k]] == 0.0)
    long long first = 0;
    while (first < nI && !RESETS(first)) first++;
    if (first == nI) return 0;
    for (long long j = 0; j < nz; j++) z_new[j] = z[j];
    for (long long k = 0; k < nI; k++) {
        w_new[k] = w[k];
        if (k >= first && RESETS(k)) {
            double inside = -c[I[k]];
            z_new[n + I[k]] = z[n + I[k]] * (w[k] / inside);
            w_new[k] = inside;
        }
    }
#undef RESETS
    return 1;
}

/* ---- where a kept matrix's nonzeros go (gnerun.game.sparse.KeptLayout, without an elimination) ---- */

/* KeptLayout's index arithmetic for the rows and columns keep of the full system (integers: the same numbers): which
   of the pattern's nonzeros are in the kept matrix (in data order), the band's row and column orders (the kept rows
   sorted stably by their stage keys, by counting), every entry's band row i and column j (the nonzeros', then the
   diagonal additions' at), the band (kl, ku), whether it is factorised banded, and then each entry's place in the
   band's storage. dims: the full size, nk, the pattern's nonzeros, the additions, banded (1, 0, or -1: where the
   band is at most a fraction of the size), that fraction times 2^20; fixed: the pattern's rows and columns, the row
   and column keys (of the full system: >= 0); varying: keep, at; out: kl, ku, banded, then nonzeros (the pattern's
   count), i (or the places) and j (as many and the additions), row_order, col_order (nk each). Returns the number
   of nonzeros kept, or -1 (no memory). */
long long kept_layout(const long long *dims, const long long *const *fixed, const long long *const *varying,
                      long long *out) {
    long long size = dims[0], nk = dims[1], nnz = dims[2], n_at = dims[3];
    const long long *rows = fixed[0], *cols = fixed[1], *row_key = fixed[2], *col_key = fixed[3];
    const long long *keep = varying[0], *at = varying[1];
    long long *band = out, *nonzeros = out + 3, *iv = nonzeros + nnz, *jv = iv + nnz + n_at;
    long long *row_order = jv + nnz + n_at, *col_order = row_order + nk;
    long long top = 0;
    for (long long k = 0; k < nk; k++) {
        if (row_key[keep[k]] > top) top = row_key[keep[k]];
        if (col_key[keep[k]] > top) top = col_key[keep[k]];
    }
    long long *where = (long long *)malloc(sizeof(long long) * (size_t)(size + 2 * nk + top + 2));
    if (!where) return -1;
    long long *ir = where + size, *ic = ir + nk, *count = ic + nk;
    for (long long g = 0; g < size; g++) where[g] = -1;
    for (long long k = 0; k < nk; k++) where[keep[k]] = k;
    for (int pass = 0; pass < 2; pass++) {  /* a stable counting sort of the kept keys; the inverse */
        const long long *key = pass ? col_key : row_key;
        long long *order = pass ? col_order : row_order, *inverse = pass ? ic : ir;
        for (long long v = 0; v <= top + 1; v++) count[v] = 0;
        for (long long k = 0; k < nk; k++) count[key[keep[k]] + 1]++;
        for (long long v = 0; v <= top; v++) count[v + 1] += count[v];
        for (long long k = 0; k < nk; k++) order[count[key[keep[k]]]++] = k;
        for (long long b = 0; b < nk; b++) inverse[order[b]] = b;
    }
    long long kept = 0, lo = 0, hi = 0;
    for (long long k = 0; k < nnz; k++) {
        long long r = where[rows[k]], c = where[cols[k]];
        if (r < 0 || c < 0) continue;
        nonzeros[kept] = k;
        iv[kept] = ir[r];
        jv[kept] = ic[c];
        kept++;
    }
    for (long long k = 0; k < n_at; k++) {
        iv[kept + k] = ir[at[k]];
        jv[kept + k] = ic[at[k]];
    }
    for (long long k = 0; k < kept + n_at; k++) {
        long long d = iv[k] - jv[k];
        if (d > hi) hi = d;
        if (d < lo) lo = d;
    }
    band[0] = hi;
    band[1] = -lo;
    free(where);
    /* banded: dims[4] = 1, or dims[4] = -1 and the band at most dims[5] / 2^20 of the size (sparse.banded_wins); then
       each entry's place in the band's storage, j ld + kl + ku + (i - j) (ld = 2 kl + ku + 1), in i's place */
    double fraction = (double)dims[5] / 1048576.0;
    int banded = dims[4] == 1 || (dims[4] == -1 && (double)(hi - lo + 1) <= fraction * (double)nk);
    if (banded)
        for (long long k = 0; k < kept + n_at; k++)
            iv[k] = jv[k] * (2 * hi - lo + 1) + (hi - lo) + (iv[k] - jv[k]);
    band[2] = banded;
    return kept;
}

/* ---- the min-map Newton point of the reduced system, whole (gnerun.solvers.reduced.SparseReduced.point) ---- */

/* SparseReduced.point on a nonlinear game's banded kept matrix (KeptLayout.factor without diagonal additions or an
   elimination, then BandLU.solve and SparseKKT.new_iterate): the band zeroed and the pattern's values scattered into
   it, its 1-norm where the estimate is made, dgbtrf, the estimate, the solve of -F0 over keep, z^+. The same
   operations in the same order, so the same values to the bit. Returns 0 with ab and ipiv (the factors), rcond[0]
   (NaN without the estimate) and z_new; or 1 where the factorisation met a value that is not finite or a zero
   pivot (the numpy code then makes the point). dims: n, z's size, nk (keep's size), the layout's nonzeros, kl, ku,
   ld, lam0 (where keep's multipliers begin), estimate; ix: keep, the layout's nonzeros and flat positions, the
   band's row and column orders; work: 3 nk doubles. */
__attribute__((target("avx2,fma")))
int reduced_point(const long long *dims, const long long *const *ix, const double *data, const double *F0,
                  const double *z, double *ab, int *ipiv, double *work, double *z_new, double *rcond) {
    long long n = dims[0], nz = dims[1], nk = dims[2], nnz = dims[3], lam0 = dims[7];
    int kl = (int)dims[4], ku = (int)dims[5], ld = (int)dims[6], estimate = (int)dims[8];
    const long long *keep = ix[0], *nonzeros = ix[1], *flat = ix[2], *row_order = ix[3], *col_order = ix[4];
    double *y = work, *x = work + nk, *scratch = work + nk;  /* (the estimate's 2 nk before x is needed) */
    for (size_t k = 0; k < (size_t)nk * ld; k++) ab[k] = 0.0;
    for (long long k = 0; k < nnz; k++) ab[flat[k]] = data[nonzeros[k]];
    double norm = estimate ? band_one_norm((int)nk, ab, ld) : 0.0;
    if (band_lu((int)nk, kl, ku, ab, ld, ipiv) != 0) return 1;
    rcond[0] = NAN;
    if (estimate) {
        double inverse = band_lu_inverse_norm((int)nk, kl, ku, ab, ld, ipiv, scratch);
        rcond[0] = (inverse - inverse == 0.0 && inverse > 0) ? 1.0 / (norm * inverse) : 0.0;
    }
    for (long long i = 0; i < nk; i++) y[i] = -F0[keep[row_order[i]]];
    band_lu_solve((int)nk, kl, ku, ab, ld, ipiv, 1, y, 0);
    for (long long i = 0; i < nk; i++) x[col_order[i]] = y[i];
    for (long long j = 0; j < nz; j++) z_new[j] = 0.0;
    for (long long j = 0; j < n; j++) z_new[j] = z[j] + x[j];
    for (long long k = lam0; k < nk; k++) z_new[n + keep[k] - lam0] = x[k];
    return 0;
}

/* ---- one interior-point step of the sparse barrier, whole (gnerun.solvers.interior_point.InteriorPoint.step) ---- */

/* interior_point._to_boundary: fraction times the least -v_i / dv_i over dv_i < 0 (numpy's min: a NaN wins), and
   Python's min(1.0, .); 1 where no dv_i < 0 */
static double to_boundary(const double *v, const double *dv, long n, double fraction) {
    int any = 0;
    double least = 0.0;
    for (long i = 0; i < n; i++) {
        if (!(dv[i] < 0)) continue;
        double r = -v[i] / dv[i];
        if (!any) { least = r; any = 1; } else if (r != r) least = r; else if (r < least) least = r;
    }
    if (!any) return 1.0;
    double y = fraction * least;
    return y < 1.0 ? y : 1.0;
}

typedef struct {
    long long n, size, lam0, nk, nI, nE, n_rest, n_out;
    const long long *keep, *I, *E, *edims, *const *eix;
    const double *F, *c, *diag, *re, *er, *ab;
    const int *ipiv;
    double *rhs, *b, *x, *work;
} step_t;

/* SparseBarrier.direction's solve at delta = 0 for the inequality rows' right-hand side rhs_I: rhs = -F, rhs_I and
   -c_E on the multipliers' rows, over keep; the eliminated solve; the solution over the whole system (zeros where not
   kept). 0, or 1 where it is not finite. */
static int barrier_direction(const step_t *s, const double *rhs_I, double *sol) {
    for (long long i = 0; i < s->size; i++) s->rhs[i] = -s->F[i];
    for (long long i = 0; i < s->nI; i++) s->rhs[s->lam0 + s->I[i]] = rhs_I[i];
    for (long long i = 0; i < s->nE; i++) s->rhs[s->lam0 + s->E[i]] = -s->c[s->E[i]];
    for (long long k = 0; k < s->nk; k++) s->b[k] = s->rhs[s->keep[k]];
    eliminated_solve(s->edims, s->eix, s->diag, s->re, s->er, s->ab, s->ipiv, s->b, s->x, s->work);
    for (long long i = 0; i < s->size; i++) sol[i] = 0.0;
    for (long long k = 0; k < s->nk; k++) {
        if (!(s->x[k] - s->x[k] == 0.0)) return 1;
        sol[s->keep[k]] = s->x[k];
    }
    return 0;
}

/* InteriorPoint.step where the sparse barrier's common case holds: every player's block positive definite by the
   stage recursion (no shift), the band of the complement (the inequality multipliers eliminated) factorised at
   delta = 0 with no refinement, finite solutions. The same operations in the same order as the numpy code (its
   band, the elimination's bincount, Mehrotra's target with numpy's means, the steps to the boundary), so the same
   values to the bit. Returns 0 with z_new, w_new and t_out[0] (the step length), or where the numpy code must take
   the step: 1 (a block not positive definite, or the recursion cannot tell), 2 (the factorisation failed or met a
   value that is not finite), 3 (the solve would be refined), 4 (a direction is not finite), 5 (no memory).
   dims: n, size, lam0, nk, nI, nE, the layout's nonzeros, diagonal additions and fill entries, the elimination's
   pairs, n_out, n_re, n_er, n_rest, kl, ku, ld, the players (recursion), its work, predict, n + nI, m; ix: keep, I,
   E, the layout's nonzeros, flat, flat_at, flat_fill, add_kept, diagonal_at, pair_re, pair_er, pair_out, pair_entry,
   K_re's and K_er's data positions, rest, out, K_re's rows and columns, K_er's rows and columns, the band's row and
   column orders; scal: eps, BOUNDARY, PREDICTED, CENTERING, REFINE_FROM. */
__attribute__((target("avx2,fma")))
int interior_step(const long long *dims, const long long *const *ix, const long long *def_dims,
                  const long long *const *def_ix, const double *scal, const double *data, const double *F,
                  const double *c, const double *z, const double *w, const double *lam, const double *D,
                  double *z_new, double *w_new, double *t_out) {
    long long n = dims[0], size = dims[1], lam0 = dims[2], nk = dims[3], nI = dims[4], nE = dims[5], nnz = dims[6],
              n_at = dims[7], nfill = dims[8], npairs = dims[9], n_out = dims[10], n_re = dims[11], n_er = dims[12],
              n_rest = dims[13], def_work = dims[18], n_add = dims[20], m = dims[21];
    int kl = (int)dims[14], ku = (int)dims[15], ld = (int)dims[16], agents = (int)dims[17], predict = (int)dims[19];
    const long long *keep = ix[0], *I = ix[1], *E = ix[2], *nonzeros = ix[3], *flat = ix[4], *flat_at = ix[5],
                    *flat_fill = ix[6], *add_kept = ix[7], *diagonal_at = ix[8], *pair_re = ix[9], *pair_er = ix[10],
                    *pair_out = ix[11], *pair_entry = ix[12], *re0 = ix[13], *er0 = ix[14];
    double eps = scal[0], boundary = scal[1], predicted = scal[2], centering = scal[3], refine_from = scal[4];
    long long edims[7] = {n_rest, n_out, n_re, n_er, kl, ku, ld};
    const long long *eix[8] = {ix[15], ix[16], ix[17], ix[18], ix[19], ix[20], ix[21], ix[22]};
    size_t doubles = (size_t)n_rest * ld + (size_t)def_work + n_add + nfill + n_out + n_re + n_er + 2 * size
                     + 4 * nk + 5 * nI + n_out;  /* as laid out below */
    double *mem = (double *)calloc(doubles, sizeof(double));
    int *ipiv = (int *)malloc((size_t)(n_rest > 0 ? n_rest : 1) * sizeof(int));
    if (!mem || !ipiv) { free(mem); free(ipiv); return 5; }
    double *ab = mem, *def = ab + (size_t)n_rest * ld, *add = def + def_work, *fill = add + n_add, *diag = fill + nfill,
           *re = diag + n_out, *er = re + n_re, *rhs = er + n_er, *sol = rhs + size, *b = sol + size, *x = b + nk,
           *work = x + nk, *rhs_I = work + 2 * nk, *dw = rhs_I + nI, *comp = dw + nI, *tmp = comp + nI,
           *dlam = tmp + nI, *inverse = dlam + nI;
    int code = 0, target = 0;
    if (players_definite(agents, def_dims, def_ix, data, D, def) != 1) { code = 1; goto done; }
    /* the matrix: the shifts (zeros) and -D added to the diagonal; its band as KeptLayout.band fills it */
    for (long long i = 0; i < n; i++) add[i] = 0.0;
    for (long long i = 0; i < nI; i++) add[n + i] = -D[i];
    for (long long k = 0; k < nnz; k++) ab[flat[k]] = data[nonzeros[k]];
    for (long long e = 0; e < n_out; e++) inverse[e] = -1.0 / add[diagonal_at[e]];
    for (long long p = 0; p < npairs; p++)
        fill[pair_entry[p]] += data[pair_re[p]] * data[pair_er[p]] * inverse[pair_out[p]];
    for (long long k = 0; k < nfill; k++) ab[flat_fill[k]] += fill[k];
    for (long long k = 0; k < n_at; k++) ab[flat_at[k]] += add[add_kept[k]];
    if (band_lu((int)n_rest, kl, ku, ab, ld, ipiv) != 0) { code = 2; goto done; }
    for (long long e = 0; e < n_out; e++) {
        diag[e] = add[diagonal_at[e]];
        if (__builtin_fabs(diag[e]) * refine_from <= 1.0) { code = 3; goto done; }
    }
    for (long long k = 0; k < n_re; k++) re[k] = data[re0[k]];
    for (long long k = 0; k < n_er; k++) er[k] = data[er0[k]];
    step_t s = {n, size, lam0, nk, nI, nE, n_rest, n_out, keep, I, E, edims, eix, F, c, diag, re, er, ab, ipiv,
                rhs, b, x, work};
    if (predict) {  /* InteriorPoint._target: Mehrotra's predictor */
        for (long long i = 0; i < nI; i++) rhs_I[i] = -c[I[i]];
        if (barrier_direction(&s, rhs_I, sol)) { code = 4; goto done; }
        for (long long i = 0; i < nI; i++) {
            dlam[i] = sol[lam0 + I[i]];
            dw[i] = -w[i] - D[i] * dlam[i];
        }
        double t_p = to_boundary(w, dw, nI, 1.0), t_d = to_boundary(lam, dlam, nI, 1.0);
        if (!((t_d < t_p ? t_d : t_p) < predicted)) {
            for (long long i = 0; i < nI; i++) tmp[i] = lam[i] * w[i];
            double mu = plain_sum(tmp, nI) / (double)nI;
            for (long long i = 0; i < nI; i++) tmp[i] = (w[i] + t_p * dw[i]) * (lam[i] + t_d * dlam[i]);
            double mu_aff = plain_sum(tmp, nI) / (double)nI;
            double cube = pow(mu_aff / mu, 3.0);
            double sigma = cube > centering ? cube : centering;
            sigma = sigma < 1.0 ? sigma : 1.0;
            for (long long i = 0; i < nI; i++) comp[i] = sigma * mu - dlam[i] * dw[i];
            target = 1;
        }
    }
    for (long long i = 0; i < nI; i++) rhs_I[i] = -(c[I[i]] + (target ? comp[i] : eps) / lam[i]);
    if (barrier_direction(&s, rhs_I, sol)) { code = 4; goto done; }
    for (long long i = 0; i < nI; i++) {
        dlam[i] = sol[lam0 + I[i]];
        dw[i] = (target ? comp[i] : eps) / lam[i] - w[i] - D[i] * dlam[i];
    }
    double t_p = to_boundary(w, dw, nI, boundary), t_d = to_boundary(lam, dlam, nI, boundary);
    for (long long j = 0; j < n + m; j++) z_new[j] = z[j];
    for (long long j = 0; j < n; j++) z_new[j] += t_p * sol[j];
    for (long long i = 0; i < nI; i++) z_new[n + I[i]] += t_d * dlam[i];
    for (long long i = 0; i < nE; i++) z_new[n + E[i]] += t_d * sol[lam0 + E[i]];
    for (long long i = 0; i < nI; i++) w_new[i] = w[i] + t_p * dw[i];
    t_out[0] = t_d < t_p ? t_d : t_p;
done:
    free(mem);
    free(ipiv);
    return code;
}
"""


_buffer, _address = ctypes.c_char.from_buffer, ctypes.addressof


def _at(a: np.ndarray) -> int:
    """The address of an array's data, for a call into the compiled code: ctypes' view of a writable C-ordered array's
    buffer, or of a Fortran-ordered one's transpose (a third of the time of ``a.ctypes.data``, which builds an object
    per call; these calls pass a dozen arrays each), else ``a.ctypes.data`` (a read-only or empty array)."""
    try:
        return _address(_buffer(a))
    except (TypeError, ValueError, BufferError):
        pass
    try:
        return _address(_buffer(a.T))
    except (TypeError, ValueError, BufferError):
        return a.ctypes.data


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
    return kernel(n, width - 1, _at(band), b.shape[1] if b.ndim == 2 else 1, _at(b), int(transpose))


def lu_factor(ab: np.ndarray, kl: int, ku: int) -> tuple[np.ndarray, np.ndarray, int] | None:
    """LAPACK's dgbtrf of the band matrix ``ab`` (LAPACK's band storage with room for the fill: Fortran-ordered,
    2 ``kl`` + ``ku`` + 1 rows, one column per column of the matrix) in place, as scipy's
    ``lapack.dgbtrf(ab, kl, ku, overwrite_ab=1)`` returns it (the same values, a zero's sign aside): the factors
    (``ab``), the pivots (from 0) and info (0, or the first zero pivot, from 1). Compiled, or LAPACK's where nothing
    is compiled or dgbtrf takes its blocked path (``kl`` >= 32 and ``ku`` > 64: LAPACK's block size). None where the
    compiled factorisation met a value that is not finite (in a column to pivot on, among the multipliers or in U):
    ``ab`` is then half factorised; factorise the matrix again with LAPACK."""
    kernels = _lu_kernels()
    if kernels is None or (kl >= 32 and ku > 64):
        lu, piv, info = lapack.dgbtrf(ab, kl, ku, overwrite_ab=1)
        return lu, piv, int(info)
    n = ab.shape[1]
    if not (ab.flags.f_contiguous and ab.dtype == np.float64 and ab.shape[0] == 2 * kl + ku + 1):
        raise ValueError("the band must be a Fortran-ordered array of float64 with 2 kl + ku + 1 rows")
    piv = np.empty(n, dtype=np.int32)
    info = kernels[0](n, kl, ku, _at(ab), ab.shape[0], _at(piv))
    return None if info < 0 else (ab, piv, info)


def lu_solve(lu: np.ndarray, kl: int, ku: int, piv: np.ndarray, b: np.ndarray, trans: int = 0) -> np.ndarray:
    """The solution of A X = B (``trans`` = 1: A^T X = B) from A's factors (:func:`lu_factor`, or scipy's
    ``lapack.dgbtrf``), as LAPACK's dgbtrs computes it; ``b`` is left as it was. A transposed solve with more than
    one right-hand side is LAPACK's (dgemv's kernels sum two and four columns in other orders)."""
    kernels = _lu_kernels()
    m = 1 if b.ndim == 1 else b.shape[1]
    if kernels is None or (trans and m != 1) or lu.shape[1] == 0:
        return lapack.dgbtrs(lu, kl, ku, b, piv, trans=trans)[0]
    if not (lu.flags.f_contiguous and lu.dtype == np.float64 and piv.dtype == np.int32 and piv.flags.c_contiguous):
        raise ValueError("the factors must be a Fortran-ordered array of float64 and the pivots of int32")
    n = lu.shape[1]
    if b.shape[0] != n:
        raise ValueError(f"{b.shape[0]} rows of right-hand sides for a matrix of {n} rows")
    x = np.array(b, dtype=np.float64, order="F")
    kernels[1](n, kl, ku, _at(lu), lu.shape[0], _at(piv), m, _at(x), int(bool(trans)))
    return x


def lu_inverse_norm(lu: np.ndarray, kl: int, ku: int, piv: np.ndarray) -> float | None:
    """:func:`gnerun.game.sparse.inverse_norm` of the matrix whose factors are ``lu`` and ``piv`` (:func:`lu_factor`),
    with :func:`lu_solve`'s solves, the whole estimate in C: the same operations in the same order, numpy's sums
    and argmax included, so the same number to the bit. None where the solves are LAPACK's."""
    kernels = _lu_kernels()
    n = lu.shape[1]
    if kernels is None or n == 0:
        return None
    if not (lu.flags.f_contiguous and lu.dtype == np.float64 and piv.dtype == np.int32 and piv.flags.c_contiguous):
        raise ValueError("the factors must be a Fortran-ordered array of float64 and the pivots of int32")
    work = np.empty(2 * n)
    return kernels[2](n, kl, ku, _at(lu), lu.shape[0], _at(piv), _at(work))


class EliminatedSolve:
    """The compiled form of :meth:`gnerun.game.sparse.EliminatedLU._solve` for one elimination and the band layout of
    its complement (``ix``: rest, out, K_re's rows and columns, K_er's rows and columns, the band's row and column
    orders, as :class:`~gnerun.game.sparse.Elimination` and :class:`~gnerun.game.sparse.KeptLayout` hold them;
    ``kl``, ``ku``: the band's): the same operations in the same order, one call instead of some fifteen of numpy's."""

    def __init__(self, function, ix: list[np.ndarray], kl: int, ku: int) -> None:
        self._function = function
        self._ix = [np.ascontiguousarray(v, dtype=np.int64) for v in ix]  # held: the pointers point into them
        self._pointers = (ctypes.c_void_p * len(self._ix))(*[v.ctypes.data for v in self._ix])
        self._size = self._ix[0].size + self._ix[1].size  # the kept system's
        self._dims = np.array([self._ix[0].size, self._ix[1].size, self._ix[2].size, self._ix[4].size, kl, ku,
                               2 * kl + ku + 1], dtype=np.int64)
        self._fixed = (self._dims.ctypes.data, ctypes.addressof(self._pointers))  # the held arrays' addresses

    def __call__(self, lu: np.ndarray, piv: np.ndarray, diagonal: np.ndarray, re: np.ndarray, er: np.ndarray,
                 b: np.ndarray) -> np.ndarray:
        """x with K x = b, from the complement's band factors (``lu``, ``piv``: dgbtrf's), E's diagonal and the
        gathered entries of K_re and K_er."""
        if not (lu.flags.f_contiguous and lu.dtype == np.float64 and lu.shape[0] == self._dims[6]
                and piv.dtype == np.int32 and piv.flags.c_contiguous and b.size == self._size):
            raise ValueError("the factors or the right-hand side do not fit this elimination")
        b = np.ascontiguousarray(b, dtype=np.float64)
        diagonal, re, er = (np.ascontiguousarray(v, dtype=np.float64) for v in (diagonal, re, er))
        x = np.empty(self._size)
        work = np.empty(2 * self._size)
        self._function(*self._fixed, _at(diagonal), _at(re), _at(er), _at(lu),
                       _at(piv), _at(b), _at(x), _at(work))
        return x


def eliminated_solve(ix: list[np.ndarray], kl: int, ku: int) -> EliminatedSolve | None:
    """The compiled eliminated solve for these indices and band, or None where nothing is compiled."""
    kernels = _lu_kernels()
    if kernels is None:
        return None
    return EliminatedSolve(kernels[6], ix, kl, ku)


class PlayersDefinite:
    """The compiled recursion of :class:`gnerun.solvers.interior_point._StageRecursion` (``dims``: per player T, nu,
    nx and its multiplier terms; ``ix``: the position arrays in ``players_definite``'s order)."""

    def __init__(self, function, dims: np.ndarray, ix: list[np.ndarray], work: int) -> None:
        self._function = function
        self._dims = np.ascontiguousarray(dims, dtype=np.int64)
        self._ix = [np.ascontiguousarray(v, dtype=np.int64) for v in ix]  # held: the pointers point into them
        self._pointers = (ctypes.c_void_p * len(self._ix))(*[v.ctypes.data for v in self._ix])
        self._work = work
        self._agents = self._dims.size // 4
        self._fixed = (self._agents, self._dims.ctypes.data, ctypes.addressof(self._pointers))  # (held arrays)

    def __call__(self, data: np.ndarray, D: np.ndarray) -> int:
        """1 where every player's block is positive definite, 0 where one is not, -1 where it cannot tell."""
        data = np.ascontiguousarray(data, dtype=np.float64)
        D = np.ascontiguousarray(D, dtype=np.float64)
        work = np.empty(self._work)  # per call: ctypes lets go of the GIL, and two threads may share a system
        return self._function(*self._fixed, _at(data), _at(D), _at(work))


def players_definite(dims: np.ndarray, ix: list[np.ndarray], work: int) -> PlayersDefinite | None:
    """The compiled stage recursion for these positions, or None where nothing is compiled."""
    kernels = _lu_kernels()
    if kernels is None:
        return None
    return PlayersDefinite(kernels[7], dims, ix, work)


class InteriorStep:
    """The compiled form of :meth:`gnerun.solvers.interior_point.InteriorPoint.step` on a sparse barrier's common case
    (C's ``interior_step``): the stage recursion finds every player's block positive definite, the complement's band
    (the inequality multipliers eliminated) factorises at delta = 0 without refinement, and the directions are finite.
    The same operations in the same order as the numpy code, so the same step to the bit; where the case does not
    hold, a code that says why (the numpy code then takes the step, from the start). ``dims`` and ``ix`` as
    ``interior_step`` reads them (the predictor's flag left 0), ``definite``: the barrier's :class:`PlayersDefinite`,
    ``constants``: BOUNDARY, PREDICTED, CENTERING, REFINE_FROM."""

    def __init__(self, function, dims: list[int], ix: list[np.ndarray], definite: PlayersDefinite,
                 constants: tuple[float, ...]) -> None:
        self._function = function
        self._dims = np.array(dims, dtype=np.int64)
        self._predict = self._dims.copy()
        self._predict[19] = 1
        self._ix = [np.ascontiguousarray(v, dtype=np.int64) for v in ix]  # held: the pointers point into them
        self._pointers = (ctypes.c_void_p * len(self._ix))(*[v.ctypes.data for v in self._ix])
        self._definite = definite  # held: its arrays are read
        self._constants = constants
        self._sizes = (int(dims[0]) + int(dims[21]), int(dims[4]))  # z's and w's
        self._fixed = (ctypes.addressof(self._pointers), definite._dims.ctypes.data,
                       ctypes.addressof(definite._pointers))

    def __call__(self, data: np.ndarray, F: np.ndarray, c: np.ndarray, z: np.ndarray, w: np.ndarray,
                 lam: np.ndarray, D: np.ndarray, eps: float,
                 predict: bool) -> tuple[np.ndarray, np.ndarray, float] | int:
        """(z, w, t) after the step from (z, w) (lambda_I = ``lam``, D = w / lambda_I), J's nonzeros ``data``, F, c;
        with Mehrotra's predictor where ``predict``; or, where the numpy code must take it, why (``interior_step``'s
        code: 1 where the stage recursion does not find every block positive definite)."""
        data, F, c, z, w, lam, D = (np.ascontiguousarray(v, dtype=np.float64) for v in (data, F, c, z, w, lam, D))
        z_new, w_new = np.empty(self._sizes[0]), np.empty(self._sizes[1])
        scal = np.array([eps, *self._constants])
        t = np.empty(1)
        dims = self._predict if predict else self._dims
        code = self._function(_at(dims), *self._fixed, _at(scal), _at(data), _at(F),
                              _at(c), _at(z), _at(w), _at(lam), _at(D),
                              _at(z_new), _at(w_new), _at(t))
        return (z_new, w_new, float(t[0])) if code == 0 else code


def interior_step(dims: list[int], ix: list[np.ndarray], definite, constants: tuple[float, ...]) -> InteriorStep | None:
    """The compiled interior step for these positions, or None where nothing is compiled (or no recursion)."""
    kernels = _lu_kernels()
    if kernels is None or not isinstance(definite, PlayersDefinite):
        return None
    return InteriorStep(kernels[8], dims, ix, definite, constants)


class ReducedPoint:
    """The compiled form of :meth:`gnerun.solvers.reduced.SparseReduced.point` for one banded kept matrix of a
    nonlinear game (C's ``reduced_point``: the band, its norm, dgbtrf, the estimate, the solve, z^+; the same values to
    the bit). ``keep``: the rows and columns kept (the unknowns but the multipliers, then from ``lam0`` on the
    multipliers of the rows kept); ``layout``: their :class:`~gnerun.game.sparse.KeptLayout` (banded, no diagonal
    additions, no elimination); ``n``: the decisions; ``nz``: the iterate's size."""

    def __init__(self, function, layout, keep: np.ndarray, n: int, nz: int, lam0: int) -> None:
        self._function, self.layout = function, layout
        self._ix = [np.ascontiguousarray(v, dtype=np.int64) for v in (keep, layout.nonzeros, layout.flat,
                                                                       layout.row_order, layout.col_order)]
        self._pointers = (ctypes.c_void_p * len(self._ix))(*[v.ctypes.data for v in self._ix])  # (held arrays)
        dims = [n, nz, layout.size, layout.nonzeros.size, layout.lower, layout.upper, layout.ld, lam0]
        self._dims = (np.array([*dims, 0], dtype=np.int64), np.array([*dims, 1], dtype=np.int64))
        self._shape, self._nz = (layout.size, layout.ld), nz

    def __call__(self, data: np.ndarray, F0: np.ndarray, z: np.ndarray,
                 estimate: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, float] | None:
        """(z^+, the factors' band (Fortran-ordered, as dgbtrf leaves it), the pivots, rcond: NaN without
        ``estimate``), or None where the numpy code must make the point (a value that is not finite, a zero pivot)."""
        data, F0, z = (np.ascontiguousarray(v, dtype=np.float64) for v in (data, F0, z))
        ab = np.empty(self._shape)  # C's zeros; the transpose of the Fortran-ordered band
        piv = np.empty(self._shape[0], dtype=np.int32)
        work, z_new, rcond = np.empty(3 * self._shape[0]), np.empty(self._nz), np.empty(1)
        code = self._function(_at(self._dims[estimate]), ctypes.addressof(self._pointers), _at(data),
                              _at(F0), _at(z), _at(ab), _at(piv), _at(work),
                              _at(z_new), _at(rcond))
        return (z_new, ab.T, piv, float(rcond[0])) if code == 0 else None


def reduced_point(layout, keep: np.ndarray, n: int, nz: int, lam0: int) -> ReducedPoint | None:
    """The compiled reduced point for this layout, or None where nothing is compiled or it does not apply (SuperLU's
    layout, an elimination, an empty matrix, dgbtrf's blocked path)."""
    kernels = _lu_kernels()
    if (kernels is None or not layout.banded or layout.elimination is not None or not layout.size or layout.at.size
            or (layout.lower >= 32 and layout.upper > 64)):
        return None
    return ReducedPoint(kernels[9], layout, keep, n, nz, lam0)


class KeptLayouts:
    """:class:`gnerun.game.sparse.KeptLayout`'s indices without an elimination, compiled (C's ``kept_layout``: the same
    integers), for one full system's pattern (``rows``, ``cols``: its nonzeros' rows and columns, in data order) and
    stage keys (``row_key``, ``col_key``), whose addresses are taken once."""

    def __init__(self, function, size: int, rows: np.ndarray, cols: np.ndarray, row_key: np.ndarray,
                 col_key: np.ndarray, fraction: float) -> None:
        self._function, self._size = function, size
        self._fraction = int(round(fraction * 2 ** 20))  # (sparse.BAND_FRACTION, exactly: 0.25)
        if self._fraction != fraction * 2 ** 20:
            raise ValueError("the band's fraction must be a multiple of 2^-20")
        self._held = [np.ascontiguousarray(v, dtype=np.int64) for v in (rows, cols, row_key, col_key)]
        self._fixed = (ctypes.c_void_p * 4)(*[v.ctypes.data for v in self._held])  # (held arrays)
        self._nnz = self._held[0].size

    def __call__(self, keep: np.ndarray, at: np.ndarray, banded: bool | None) -> tuple | None:
        """For the rows and columns ``keep`` and the diagonal additions at ``at`` (positions in ``keep``): the pattern's
        nonzeros in the kept matrix, each entry's place in the band's storage (the nonzeros', then the additions'),
        the band's row and column orders, kl, ku, and whether the matrix is factorised banded (``banded``, or where
        :func:`gnerun.game.sparse.banded_wins`; without, the places are not made); None where memory ran out."""
        keep, at = (np.ascontiguousarray(v, dtype=np.int64) for v in (keep, at))
        nk, n_at, nnz = keep.size, at.size, self._nnz
        out = np.empty(3 + 3 * nnz + 2 * n_at + 2 * nk, dtype=np.int64)
        dims = np.array([self._size, nk, nnz, n_at, -1 if banded is None else int(banded), self._fraction],
                        dtype=np.int64)
        varying = (ctypes.c_void_p * 2)(_at(keep), _at(at))
        kept = self._function(_at(dims), ctypes.addressof(self._fixed), ctypes.addressof(varying),
                              _at(out))
        if kept < 0:
            return None
        i0 = 3 + nnz
        r0 = i0 + 2 * (nnz + n_at)
        return (out[3:3 + kept], out[i0:i0 + kept + n_at], out[r0:r0 + nk], out[r0 + nk:r0 + 2 * nk], int(out[0]),
                int(out[1]), bool(out[2]))


def kept_layouts(size: int, rows: np.ndarray, cols: np.ndarray, row_key: np.ndarray, col_key: np.ndarray,
                 fraction: float) -> KeptLayouts | None:
    """The compiled layout arithmetic for this pattern and these keys (``fraction``: sparse.BAND_FRACTION), or None
    where nothing is compiled."""
    kernels = _lu_kernels()
    if kernels is None:
        return None
    return KeptLayouts(kernels[10], size, rows, cols, row_key, col_key, fraction)


class Barrier:
    """The interior phase's bookkeeping for one set of inequality rows ``I`` and equality rows ``E`` of a game with
    ``n`` decisions and iterates of ``size`` entries, compiled (C's ``barrier_error`` and ``slack_reset``: the same
    numbers as :meth:`gnerun.solvers.interior_point.InteriorPoint.measure` and ``reset_slacks``)."""

    def __init__(self, functions, n: int, I: np.ndarray, E: np.ndarray, size: int) -> None:
        self._error, self._reset = functions
        self._ix = [np.ascontiguousarray(v, dtype=np.int64) for v in (I, E)]
        self._pointers = (ctypes.c_void_p * 2)(*[v.ctypes.data for v in self._ix])  # (held arrays)
        self._dims = np.array([n, self._ix[0].size, self._ix[1].size], dtype=np.int64)
        self._reset_dims = np.array([n, self._ix[0].size, size], dtype=np.int64)
        self._fixed = (self._dims.ctypes.data, ctypes.addressof(self._pointers))
        self._reset_fixed = (self._reset_dims.ctypes.data, ctypes.addressof(self._pointers))
        self._size = size

    def error(self, L: np.ndarray, c: np.ndarray, z: np.ndarray, w: np.ndarray, eps: float) -> float:
        """max(largest(L), largest(c_I + w), largest(c_E), largest(lambda_I w - eps))."""
        L, c, z, w = (np.ascontiguousarray(v, dtype=np.float64) for v in (L, c, z, w))
        return self._error(*self._fixed, _at(L), _at(c), _at(z), _at(w), eps)

    def reset(self, c: np.ndarray, z: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(z, w) after the slack reset: new arrays where a row is reset, else ``z`` and ``w`` themselves."""
        c, zc, wc = (np.ascontiguousarray(v, dtype=np.float64) for v in (c, z, w))
        if zc.size != self._size or wc.size != self._dims[1]:
            raise ValueError("the iterate does not fit these rows")
        z_new, w_new = np.empty(self._size), np.empty(wc.size)
        if not self._reset(*self._reset_fixed, _at(c), _at(zc), _at(wc), _at(z_new), _at(w_new)):
            return z, w
        return z_new, w_new


def barrier(n: int, I: np.ndarray, E: np.ndarray, size: int) -> Barrier | None:
    """The compiled bookkeeping of an interior phase, or None where nothing is compiled."""
    kernels = _lu_kernels()
    if kernels is None:
        return None
    return Barrier(kernels[11], n, I, E, size)


def one_norm(ab: np.ndarray) -> float | None:
    """``float(np.abs(ab).sum(axis=0).max())`` of a Fortran-ordered band (numpy's pairwise sums, the same number),
    without its temporary arrays; None where nothing is compiled."""
    kernels = _lu_kernels()
    if kernels is None or ab.shape[1] == 0:
        return None
    if not (ab.flags.f_contiguous and ab.dtype == np.float64):
        raise ValueError("the band must be a Fortran-ordered array of float64")
    return kernels[3](ab.shape[1], _at(ab), ab.shape[0])


class PlayersComplement:
    """The compiled form of :meth:`gnerun.solvers.interior_point._AgentBlocks.complement` for one set of its gathers
    and products (``parts``: the index arrays in the order of ``players_complement``'s ``ix``; ``dims``: ng, m,
    width, nI, na; the players' blocks: ``decisions[i]`` rows of the last na from row ``rows[i]`` of them): the same
    operations in the same order, less those that add a zero, so the same values to the bit, a zero's sign aside
    (checked on the first call against the numpy and scipy.sparse code by the caller)."""

    def __init__(self, function, dims: tuple[int, ...], parts: list[np.ndarray], rows: np.ndarray,
                 decisions: np.ndarray, shifts=(None, None)) -> None:
        self._function, self._shifts = function, shifts
        self._parts = [np.ascontiguousarray(p, dtype=np.int64) for p in parts]  # held: the pointers point into them
        ng, m, width, nI, na = dims
        self._dims = np.array([*dims, self._parts[0].size, self._parts[2].size, self._parts[7].size], dtype=np.int64)
        self._pointers = (ctypes.c_void_p * len(self._parts))(*[p.ctypes.data for p in self._parts])
        self._fixed = (self._dims.ctypes.data, ctypes.addressof(self._pointers))  # the held arrays' addresses
        # doubles, then ints for the rows' lengths (ng + nI + ng + na), in doubles' room
        self._work = ng * m + ng * (width + 1) + (ng + na) * m + na * m + (2 * ng + nI + na + 1) // 2 + 1
        self._shape = (nI + ng + na, m)
        self._rows = np.ascontiguousarray(rows, dtype=np.int64)
        self._decisions = np.ascontiguousarray(decisions, dtype=np.int64)

    def __call__(self, data: np.ndarray, D: np.ndarray) -> np.ndarray | bool | None:
        """K = [Y_lambda; Y_p; S] (S: the players' blocks stacked), None where D_x has a zero on its diagonal, or False
        where a value that is not finite meets a zero the code skips (numpy's product would be NaN there: compute this
        call with numpy)."""
        data = np.ascontiguousarray(data, dtype=np.float64)
        D = np.ascontiguousarray(D, dtype=np.float64)
        work = np.empty(self._work)  # per call: a system's blocks may serve several solves at once
        K = np.empty(self._shape)
        code = self._function(*self._fixed, _at(data), _at(D), _at(work), _at(K))
        return K if code == 0 else (None if code == 1 else False)

    def shifts(self, K: np.ndarray) -> tuple[list[float], float] | None:
        """The players' convexifying shifts (:func:`gnerun.solvers.interior_point.convexifying_shift` of each block
        of K, a result of this object) and the largest |diagonal entry + shift|, at least 1, as
        :meth:`~gnerun.solvers.interior_point.SparseBarrier._shifts` finds them, with the same LAPACK dpotrf; None
        where that dpotrf is not at hand."""
        function, potrf = self._shifts
        if potrf is None:
            return None
        m, players = self._shape[1], self._decisions.size
        S = K[self._shape[0] - int(self._decisions.sum()):]
        deltas, work = np.empty(players), np.empty(2 * m * m)
        scale = function(players, _at(self._rows), _at(self._decisions), m, _at(S), potrf,
                         _at(work), _at(deltas))
        return deltas.tolist(), float(scale)


def players_complement(dims: tuple[int, ...], parts: list[np.ndarray], rows: np.ndarray,
                       decisions: np.ndarray) -> PlayersComplement | None:
    """The compiled players' complement for these gathers and products, or None where nothing is compiled."""
    kernels = _lu_kernels()
    if kernels is None:
        return None
    return PlayersComplement(kernels[4], dims, parts, rows, decisions, kernels[5])


def status() -> str:
    """Which solves and factorisations this module makes: "compiled", or "lapack (why)"."""
    _kernel()
    return _STATE["status"]


_STATE: dict = {}  # the loaded kernels (None: LAPACK's) and their status, once per process


def _kernel():
    if "kernel" not in _STATE:
        _STATE["kernel"], _STATE["lu"], _STATE["status"] = _load()
    return _STATE["kernel"]


def _lu_kernels():
    _kernel()
    return _STATE.get("lu")


def _load():
    """The compiled triangular solve, the banded LU's factorisation and solve (built if the cache has none) and
    "compiled", or None, None and why not."""
    if compiler() is None:
        return None, None, "lapack (no C compiler found: gcc, cc or $CC)"
    try:
        path, _, _ = build_source(_SOURCE, "banded", FLAGS)
    except RuntimeError as e:
        return None, None, f"lapack ({e})"
    except OSError as e:
        return None, None, f"lapack (cannot build in {cache_dir()}: {e})"
    try:
        lib = ctypes.CDLL(str(path))
    except OSError as e:
        return None, None, f"lapack (cannot load {path}: {e})"
    if not lib.banded_supported():
        return None, None, "lapack (the processor has no AVX2 and FMA)"
    kernel = lib.banded_solve
    kernel.restype = ctypes.c_int
    kernel.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_void_p, ctypes.c_int, ctypes.c_void_p, ctypes.c_int]
    factor, solve_lu, inverse_norm = lib.band_lu, lib.band_lu_solve, lib.band_lu_inverse_norm
    norm = lib.band_one_norm
    factor.restype = solve_lu.restype = ctypes.c_int
    inverse_norm.restype = norm.restype = ctypes.c_double
    norm.argtypes = [ctypes.c_int, ctypes.c_void_p, ctypes.c_int]
    inverse_norm.argtypes = [ctypes.c_int] * 3 + [ctypes.c_void_p, ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p]
    factor.argtypes = [ctypes.c_int] * 3 + [ctypes.c_void_p, ctypes.c_int, ctypes.c_void_p]
    solve_lu.argtypes = [ctypes.c_int] * 3 + [ctypes.c_void_p, ctypes.c_int, ctypes.c_void_p, ctypes.c_int,
                                              ctypes.c_void_p, ctypes.c_int]
    if not (_agrees(kernel) and _lu_agrees(factor, solve_lu)):
        return None, None, "lapack (the compiled solves round differently from this LAPACK's)"
    complement = lib.players_complement
    complement.restype = ctypes.c_int
    complement.argtypes = [ctypes.c_void_p] * 6
    shifts = lib.players_shifts
    shifts.restype = ctypes.c_double
    shifts.argtypes = [ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int] + [ctypes.c_void_p] * 4
    eliminated = lib.eliminated_solve
    eliminated.restype = None
    eliminated.argtypes = [ctypes.c_void_p] * 10
    definite = lib.players_definite
    definite.restype = ctypes.c_int
    definite.argtypes = [ctypes.c_int] + [ctypes.c_void_p] * 5
    step = lib.interior_step
    step.restype = ctypes.c_int
    step.argtypes = [ctypes.c_void_p] * 15
    point = lib.reduced_point
    point.restype = ctypes.c_int
    point.argtypes = [ctypes.c_void_p] * 10
    layout = lib.kept_layout
    layout.restype = ctypes.c_longlong
    layout.argtypes = [ctypes.c_void_p] * 4
    error, reset = lib.barrier_error, lib.slack_reset
    error.restype, reset.restype = ctypes.c_double, ctypes.c_int
    error.argtypes = [ctypes.c_void_p] * 6 + [ctypes.c_double]
    reset.argtypes = [ctypes.c_void_p] * 7
    return kernel, (factor, solve_lu, inverse_norm, norm, complement, (shifts, _potrf()), eliminated,
                    definite, step, point, layout, (error, reset)), "compiled"


def _potrf() -> int | None:
    """The address of the dpotrf that scipy.linalg.lapack calls (scipy.linalg.cython_lapack's), or None."""
    try:
        from scipy.linalg import cython_lapack

        capsule = cython_lapack.__pyx_capi__["dpotrf"]
        api = ctypes.pythonapi
        api.PyCapsule_GetName.restype = ctypes.c_char_p
        api.PyCapsule_GetName.argtypes = [ctypes.py_object]
        api.PyCapsule_GetPointer.restype = ctypes.c_void_p
        api.PyCapsule_GetPointer.argtypes = [ctypes.py_object, ctypes.c_char_p]
        return api.PyCapsule_GetPointer(capsule, api.PyCapsule_GetName(capsule)) or None
    except (ImportError, AttributeError, KeyError, ValueError):
        return None


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


def _lu_agrees(factor, solve_lu) -> bool:
    """Whether the compiled banded LU gives LAPACK's factors, pivots and solutions on test bands, the same values bit
    for bit (a zero's sign aside: the factorisation skips the updates that add zeros): with pivoting and without,
    solves of both kinds (dot products and dgemv's sums of every length the band holds: ``kl`` + ``ku`` beyond 32,
    ``kl`` of every residue mod 4), a band with a zero pivot, several right-hand sides, a band mostly zero inside."""
    rng = np.random.default_rng(1)
    for n, kl, ku, m, zeros in ((60, 19, 27, 1, 0.3), (41, 6, 40, 3, 0.3), (9, 3, 1, 2, 0.3), (30, 2, 0, 1, 0.3),
                                (25, 0, 3, 1, 0.3), (90, 18, 18, 2, 0.85)):
        ld = 2 * kl + ku + 1
        ab = np.zeros((ld, n), order="F")
        ab[kl:] = rng.standard_normal((kl + ku + 1, n)) * 10.0 ** rng.integers(-2, 3, (kl + ku + 1, n))
        ab[kl:][rng.random((kl + ku + 1, n)) < zeros] = 0.0
        ab[kl + ku][ab[kl + ku] == 0.0] = 1.0  # no zero pivot without pivoting (kl = 0) ...
        if n == 30:  # ... but one here
            ab[kl + ku, 7] = ab[kl + ku + 1, 7] = ab[kl + ku + 2, 7] = 0.0  # column 8: its pivot is zero
        ref, piv, info = lapack.dgbtrf(ab.copy(order="F"), kl, ku)
        got, gpiv = ab.copy(order="F"), np.zeros(n, dtype=np.int32)
        if factor(n, kl, ku, got.ctypes.data, ld, gpiv.ctypes.data) != info or not (
                _same_values(ref, got) and np.array_equal(piv, gpiv)):
            return False
        if info:
            continue
        b = np.asfortranarray(rng.standard_normal((n, m)))
        for trans in (0, 1) if m == 1 else (0,):
            x = b.copy(order="F")
            solve_lu(n, kl, ku, got.ctypes.data, ld, gpiv.ctypes.data, m, x.ctypes.data, trans)
            if not _same_values(lapack.dgbtrs(ref, kl, ku, b, piv, trans=trans)[0], x):
                return False
    return True


def _same_values(a: np.ndarray, b: np.ndarray) -> bool:
    """The same numbers bit for bit, NaN for NaN; +0 and -0 alike."""
    return a.shape == b.shape and np.array_equal(a, b, equal_nan=True)
