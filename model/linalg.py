"""Compiled dense linear algebra of the hot path: the lowest eigenpairs and the Newton solve, one C call each.

**Eigen solve** (:func:`lowest_pairs`). The algorithm is the one :func:`model.modal._lowest_pairs`
documents (Jacobi scaling ``D = diag(K)^(-1/2)``, Cholesky ``K_s = L L^T``, the standard problem ``C y = mu y``
with ``C = L^-1 M_s L^-T`` and ``mu = 1/lambda``, vectors ``phi = D L^-T y / sqrt(mu)``); only the symmetric
eigen solver differs. LAPACK's expert driver dsyevx (and dsyevr, for a subset of the spectrum) finds the
wanted pairs by bisection and inverse iteration, which costs several times the Householder
tridiagonalisation at a flexure model's sizes (241 us against 47 us at n = 59). Here the tridiagonal
problem is solved by the MRRR algorithm for the ``k`` wanted pairs only (dstemr: Dhillon, Parlett and
Voemel, ACM TOMS 32(4), 2006) and the vectors are transformed back by dormtr. Each eigenvalue is then
replaced by the Rayleigh quotient of its vector accumulated in extended precision (``long double``), which
takes the relative error of thin, finely meshed leaves from a few 1e-8 (cancellation in ``K x``) to about
1e-11 (issue 12 item 2; tests/test_eigen_accuracy.py).

**Newton solve** (:func:`solve`): LU with partial pivoting (dgetrf, dgetrs) of a row-major matrix, read as
its transpose by LAPACK and solved with ``trans = 'T'``, so nothing is copied.

The routines come from :func:`model.lapack.routines` (numpy's OpenBLAS, else scipy's), so this path never
imports ``scipy.linalg``. The C code is compiled once and cached like the element kernels
(:func:`model.kernels.shared_library`); without a C compiler or a usable LAPACK :func:`available` is False
and the callers use scipy's Python wrappers.
"""

from __future__ import annotations

import ctypes
import threading

import numpy as np

from .errors import KernelBuildError
from .kernels import shared_library
from .lapack import routines

__all__ = ["lowest_pairs", "solve", "available", "build"]

#: Up to this order ``C = L^-1 M_s L^-T`` is formed by two triangular solves (BLAS dtrsm), above it by
#: LAPACK dsygst (half the flops): whole eigen solve measured 324 vs 384 us at n = 59, even at n = 89-119
#: (scipy route, model.modal); the compiled driver takes the same switch.
TRSM_MAX = 80

_SOURCE = r"""
#include <math.h>

/* FINT: the LAPACK integer, defined before this source ("long long" for ILP64, "int" for LP64) */
typedef void (*potrf_t)(char*, FINT*, double*, FINT*, FINT*);
typedef void (*trsm_t)(char*, char*, char*, char*, FINT*, FINT*, double*, double*, FINT*, double*, FINT*);
typedef void (*sygst_t)(FINT*, char*, FINT*, double*, FINT*, double*, FINT*, FINT*);
typedef void (*sytrd_t)(char*, FINT*, double*, FINT*, double*, double*, double*, double*, FINT*, FINT*);
typedef void (*stemr_t)(char*, char*, FINT*, double*, double*, double*, double*, FINT*, FINT*, FINT*, double*,
                        double*, FINT*, FINT*, FINT*, FINT*, double*, FINT*, FINT*, FINT*, FINT*);
typedef void (*ormtr_t)(char*, char*, char*, FINT*, FINT*, double*, FINT*, double*, double*, FINT*, double*,
                        FINT*, FINT*);
typedef void (*trtrs_t)(char*, char*, char*, FINT*, FINT*, double*, FINT*, double*, FINT*, FINT*);
typedef void (*getrf_t)(FINT*, FINT*, double*, FINT*, FINT*, FINT*);
typedef void (*getrs_t)(char*, FINT*, FINT*, double*, FINT*, FINT*, double*, FINT*, FINT*);

/* Solve A X = B in place: A (n x n, row-major, overwritten by the LU factors of A^T), B (n x nrhs,
   column-major, overwritten by X), ipiv (n). Returns LAPACK's info (> 0: A is singular). */
long long solve(long long n_, long long nrhs_, double* A, double* B, FINT* ipiv, void** fp) {
  getrf_t getrf = (getrf_t) fp[7];
  getrs_t getrs = (getrs_t) fp[8];
  FINT n = (FINT) n_, nrhs = (FINT) nrhs_, info = 0;
  char T = 'T';
  getrf(&n, &n, A, &n, ipiv, &info);
  if (info != 0) return (long long) info;
  getrs(&T, &n, &nrhs, A, &n, ipiv, B, &n, &info);
  return (long long) info;
}

/* Rayleigh quotients lam_j = (x^T K x) / (x^T M x) of the computed vectors, accumulated in extended
   precision (long double) over the nonzero entries of the lower triangles. A float64 eigen solver is
   backward stable in the scaled norm only: cancellation in K x leaves the eigenvalue of a thin, finely
   meshed leaf with relative errors of a few 1e-8; the Rayleigh quotient's error is second order in the
   vector's, so from these vectors it is exact to about 1e-12. iw (>= n (n + 1) ints) holds the nonzero
   pattern, collected once per call. */
static void rayleigh(FINT n, FINT k, const double* K, const double* M, double* lam, const double* X, FINT* iw) {
  FINT i, j, p, nz = 0;
  FINT *rows = iw, *cols = iw + (n * (n + 1)) / 2;
  for (i = 0; i < n; ++i)
    for (j = 0; j <= i; ++j)
      if (K[i * n + j] != 0.0 || M[i * n + j] != 0.0) {
        rows[nz] = i;
        cols[nz] = j;
        ++nz;
      }
  for (p = 0; p < k; ++p) {
    long double a = 0.0L, b = 0.0L;
    for (FINT q = 0; q < nz; ++q) {
      FINT r = rows[q], c = cols[q];
      long double xx = (long double) X[r * k + p] * (long double) X[c * k + p];
      if (r != c) xx *= 2.0L;
      a += (long double) K[r * n + c] * xx;
      b += (long double) M[r * n + c] * xx;
    }
    if (b > 0.0L) lam[p] = (double) (a / b);
  }
}

/* Doubles and ints of workspace lowest_pairs needs for order n. */
long long work_doubles(int n) { return 3LL * n * n + 6LL * n + 82LL * n; }
long long work_ints(int n) { return 12LL * n + (long long) n * (n + 1); }

/* The k lowest eigenpairs of K x = lambda M x. K, M: n x n, row-major; only their lower triangles are
   read: a row-major lower triangle is the column-major *upper* triangle of the same buffer, so LAPACK is
   called with uplo 'U' on the scaled buffers (A = U^T U, C = U^-T M U^-T, x = U^-1 y), no transposition.
   Output: lam (k, ascending), X (n x k, row-major, mass-normalised). Returns 0 on success, 1 if K or M
   has a non-positive diagonal or K is not positive definite (the caller's route through M takes over),
   2 if LAPACK failed otherwise. */
long long lowest_pairs(long long n_, long long k_, long long trsm_max, const double* K, const double* M,
                       double* lam, double* X, void** fp, double* buf, FINT* iw, long long refine) {
  FINT n = (FINT) n_, k = (FINT) k_;
  potrf_t potrf = (potrf_t) fp[0];
  trsm_t trsm = (trsm_t) fp[1];
  sygst_t sygst = (sygst_t) fp[2];
  sytrd_t sytrd = (sytrd_t) fp[3];
  stemr_t stemr = (stemr_t) fp[4];
  ormtr_t ormtr = (ormtr_t) fp[5];
  trtrs_t trtrs = (trtrs_t) fp[6];
  char U = 'U', L = 'L', R = 'R', N = 'N', T = 'T', V = 'V', I = 'I';
  FINT info = 0, one = 1, i, j;
  FINT lwork = 82 * n, liwork = 10 * n, ldz = n, nzc = k, m = 0, tryrac = 1;
  FINT il = n - k + 1, iu = n;
  double alpha = 1.0, vl = 0.0, vu = 0.0;
  double *Ks = buf, *Ms = Ks + n * n, *Z = Ms + n * n, *D = Z + n * n, *d = D + n, *e = d + n,
         *tau = e + n, *w = tau + n, *work = w + n;  /* dstemr writes W(1:N) */
  FINT* isuppz = iw + liwork;
  for (i = 0; i < n; ++i) {
    if (!(K[i * n + i] > 0.0) || !(M[i * n + i] > 0.0)) return 1;
    D[i] = 1.0 / sqrt(K[i * n + i]);
  }
  /* Jacobi scaling of the row-major lower triangles (= column-major upper ones) */
  for (i = 0; i < n; ++i)
    for (j = 0; j <= i; ++j) {
      Ks[i * n + j] = D[i] * K[i * n + j] * D[j];
      Ms[i * n + j] = D[i] * M[i * n + j] * D[j];
    }
  potrf(&U, &n, Ks, &n, &info);
  if (info != 0) return 1;
  if (n <= trsm_max) {
    for (i = 0; i < n; ++i)  /* the full symmetric Ms for the triangular solves */
      for (j = 0; j < i; ++j) Ms[j * n + i] = Ms[i * n + j];
    trsm(&L, &U, &T, &N, &n, &n, &alpha, Ks, &n, Ms, &n);
    trsm(&R, &U, &N, &N, &n, &n, &alpha, Ks, &n, Ms, &n);
  } else {
    sygst(&one, &U, &n, Ms, &n, Ks, &n, &info);
    if (info != 0) return 2;
  }
  sytrd(&U, &n, Ms, &n, d, e, tau, work, &lwork, &info);  /* C = Q T Q^T */
  if (info != 0) return 2;
  e[n - 1] = 0.0;
  stemr(&V, &I, &n, d, e, &vl, &vu, &il, &iu, &m, w, Z, &ldz, &nzc, isuppz, &tryrac, work, &lwork, iw, &liwork,
        &info);
  if (info != 0 || m != k) return 2;
  for (j = 0; j < k; ++j)
    if (!(w[j] > 0.0)) return 1;
  ormtr(&L, &U, &N, &n, &k, Ms, &n, tau, Z, &n, work, &lwork, &info);
  if (info != 0) return 2;
  trtrs(&U, &N, &N, &n, &k, Ks, &n, Z, &n, &info);
  if (info != 0) return 2;
  /* largest mu first = lowest lambda first; phi = D x / sqrt(mu) */
  for (j = 0; j < k; ++j) {
    FINT src = k - 1 - j;
    double mu = w[src], s = 1.0 / sqrt(mu);
    lam[j] = 1.0 / mu;
    for (i = 0; i < n; ++i) X[i * k + j] = D[i] * Z[i + src * n] * s;
  }
  if (refine) rayleigh(n, k, K, M, lam, X, iw);
  return 0;
}
"""

_LOCAL = threading.local()  # workspace per thread (ctypes releases the GIL during the call) and per order
_DRIVER: list = []  # [(library, routines)] once loaded, [None] when unavailable


def build(table) -> tuple | None:
    """Compile (or load from the cache) the driver for one LAPACK pointer table (model.lapack.Routines);
    ``(library, table, integer dtype)``, or None without a working C compiler."""
    source = f"#define FINT {table.int_type}\n" + _SOURCE
    try:
        lib = shared_library("flexopt_linalg", (source,), lambda: source)
    except KernelBuildError:
        return None
    L, P = ctypes.c_longlong, ctypes.c_void_p
    lib.lowest_pairs.restype = L
    lib.lowest_pairs.argtypes = [L, L, L, P, P, P, P, P, P, P, L]
    lib.solve.restype = L
    lib.solve.argtypes = [L, L, P, P, P, P]
    for name in ("work_doubles", "work_ints"):
        getattr(lib, name).restype = L
        getattr(lib, name).argtypes = [L]
    return lib, table, (np.int64 if table.int_type == "long long" else np.intc)


def _driver():
    if not _DRIVER:
        table = routines()
        _DRIVER.append(build(table) if table is not None else None)
    return _DRIVER[0]


def available() -> bool:
    """Whether the compiled drivers could be built (a C compiler and a LAPACK, see model.lapack)."""
    return _driver() is not None


def _workspace(n: int, drv: tuple) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    cache = getattr(_LOCAL, "work", None)
    if cache is None:
        cache = _LOCAL.work = {}
    key = (n, drv[2])
    ws = cache.get(key)
    if ws is None:  # kept per order: no allocation (nor page faults) per call
        lib, _, int_dtype = drv
        ws = cache[key] = (np.empty(lib.work_doubles(n)), np.empty(lib.work_ints(n), dtype=int_dtype),
                         np.empty(max(n, 1), dtype=int_dtype))
    return ws


def lowest_pairs(K: np.ndarray, M: np.ndarray, k: int, refine: bool = True,
                 driver: tuple | None = None) -> tuple[np.ndarray, np.ndarray] | None | bool:
    """The ``k`` lowest eigenpairs ``(lambda, phi)`` of ``K phi = lambda M phi`` through ``K``.

    Returns ``None`` when the driver is not available (no C compiler), ``False`` when ``K`` is not positive
    definite or a diagonal entry of ``M`` is not positive (the caller's route through ``M`` applies), the
    eigenvalues ascending and the mass-normalised vectors otherwise. ``refine``: eigenvalues as Rayleigh
    quotients in extended precision (see the module docstring). ``driver``: one from :func:`build` instead
    of the process's own (tests compare the LAPACK sources).
    """
    drv = driver or _driver()
    if drv is None:
        return None
    lib, table, _ = drv
    n = K.shape[0]
    K = np.ascontiguousarray(K, dtype=np.float64)
    M = np.ascontiguousarray(M, dtype=np.float64)
    lam = np.empty(k)
    X = np.empty((n, k))
    work, iwork, _ = _workspace(n, drv)
    status = lib.lowest_pairs(n, k, TRSM_MAX, K.ctypes.data, M.ctypes.data, lam.ctypes.data, X.ctypes.data,
                              table.table, work.ctypes.data, iwork.ctypes.data, int(refine))
    if status == 0:
        return lam, X
    if status == 1:
        return False
    return None  # a LAPACK failure: the scipy route decides (and reports) what is wrong


def solve(A: np.ndarray, B: np.ndarray) -> int | None:
    """Solve ``A X = B`` in place: ``A`` square, C-contiguous float64 (destroyed), ``B`` Fortran-ordered
    float64 (overwritten by ``X``). Returns LAPACK's info (0: solved; > 0: ``A`` is singular), ``None``
    without the compiled driver (the caller solves another way; nothing was touched)."""
    drv = _driver()
    if drv is None:
        return None
    lib, table, _ = drv
    n = A.shape[0]
    if not (A.flags.c_contiguous and A.dtype == np.float64 and B.dtype == np.float64
            and (B.flags.f_contiguous or B.ndim == 1) and B.shape[0] == n):
        raise ValueError("solve needs a C-contiguous float64 A and a Fortran-ordered float64 B of matching rows")
    if n == 0:
        return 0
    _, _, ipiv = _workspace(n, drv)
    nrhs = B.shape[1] if B.ndim == 2 else 1
    return int(lib.solve(n, nrhs, A.ctypes.data, B.ctypes.data, ipiv.ctypes.data, table.table))
