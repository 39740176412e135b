/* The compiled linear algebra of the hot path (model/linalg.py, whose docstring describes the algorithms): the
   lowest eigenpairs (lowest_pairs: dense; lanczos_pairs: banded), the Newton solve (solve) and one whole Newton
   system of model.statics (newton). LAPACK and BLAS are called through the pointer table fp of model.lapack
   whose slots model.linalg defines before this source as an enum from model.lapack.NAMES (fp[DGETRF] is
   dgetrf), with FINT, the LAPACK integer ("long long" for ILP64, "int" for LP64). */
#include <math.h>

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
typedef void (*gbtrf_t)(FINT*, FINT*, FINT*, FINT*, double*, FINT*, FINT*, FINT*);
typedef void (*gbtrs_t)(char*, FINT*, FINT*, FINT*, FINT*, double*, FINT*, FINT*, double*, FINT*, FINT*);

/* Solve A X = B in place: A (n x n, row-major, overwritten by the LU factors of A^T), B (n x nrhs,
   column-major, overwritten by X), ipiv (n). Returns LAPACK's info (> 0: A is singular). */
long long solve(long long n_, long long nrhs_, double* A, double* B, FINT* ipiv, void** fp) {
  getrf_t getrf = (getrf_t) fp[DGETRF];
  getrs_t getrs = (getrs_t) fp[DGETRS];
  FINT n = (FINT) n_, nrhs = (FINT) nrhs_, info = 0;
  char T = 'T';
  getrf(&n, &n, A, &n, ipiv, &info);
  if (info != 0) return (long long) info;
  getrs(&T, &n, &nrhs, A, &n, ipiv, B, &n, &info);
  return (long long) info;
}

/* One Newton system of model.statics (its _newton_step, _scaled_residual and the twist drive of
   model.rotations), for a drive basis of global axes and no rigid deformations, in the same operations
   and order as the numpy code, so the same numbers (tests/test_linalg.py compares both routes).
   ip: n, N (row stride of H and C, set per call), drive index d, drive kind (0 rotation, 1 translation), number of
   active drive-block coordinates nba, then free (n - 1), block_pos (nba), block component (nba: the
   global axis of each basis column). dp: axis (3), near, s_target, dval (translation: given), then
   scale (n), scale_free (n - 1). H, C: n x n views with row stride N (C may be NULL); g (n); Rd: the
   driven master's rotation (row-major). Work: J (n x n, or the band storage), b (5 n). Out: dxi, tan (n), sc =
   [dval, inc, res, finite (1/0), info, reduced (1/0)]. Returns 0. With band orders (ip after the block
   components, see NewtonSystem) the system is solved by a banded LU in that order instead of a dense one:
   the same system, other rounding. */
static void quaternion(const double* R, double* q) {
  double r00 = R[0], r01 = R[1], r02 = R[2], r10 = R[3], r11 = R[4], r12 = R[5], r20 = R[6], r21 = R[7],
         r22 = R[8];
  double t = r00 + r11 + r22, c[4] = {t, r00, r11, r22};
  int k = 0;
  for (int i = 1; i < 4; ++i)
    if (c[i] > c[k]) k = i;
  if (k == 0) {
    double w = 0.5 * sqrt(1.0 + t), f = 0.25 / w;
    q[0] = w; q[1] = (r21 - r12) * f; q[2] = (r02 - r20) * f; q[3] = (r10 - r01) * f;
  } else if (k == 1) {
    double x = 0.5 * sqrt(1.0 + 2 * r00 - t), f = 0.25 / x;
    q[0] = (r21 - r12) * f; q[1] = x; q[2] = (r10 + r01) * f; q[3] = (r20 + r02) * f;
  } else if (k == 2) {
    double y = 0.5 * sqrt(1.0 + 2 * r11 - t), f = 0.25 / y;
    q[0] = (r02 - r20) * f; q[1] = (r10 + r01) * f; q[2] = y; q[3] = (r21 + r12) * f;
  } else {
    double z = 0.5 * sqrt(1.0 + 2 * r22 - t), f = 0.25 / z;
    q[0] = (r10 - r01) * f; q[1] = (r20 + r02) * f; q[2] = (r21 + r12) * f; q[3] = z;
  }
  if (!(q[0] >= 0)) for (int i = 0; i < 4; ++i) q[i] = -q[i];
}

/* The Newton matrix in "DOF order": reduced, entry (i, j) of the free block (H + C)[f_i, f_j]; bordered,
   row a of H + C for every DOF a but the drive's, whose row is the drive gradient dd. */
typedef struct {
  const double *H, *C, *dd;
  const long long* f;
  long long N, d, bordered;
} newton_matrix;

static inline double entry(const newton_matrix* s, long long i, long long j) {
  if (s->bordered) {
    if (i == s->d) return s->dd[j];
    return s->H[i * s->N + j] + (s->C ? s->C[i * s->N + j] : 0.0);
  }
  long long fi = s->f[i], fj = s->f[j];
  return s->H[fi * s->N + fj] + (s->C ? s->C[fi * s->N + fj] : 0.0);
}

/* Solve the m x m Newton matrix for two right-hand sides x (2 m, DOF order, overwritten by the solutions) by
   a banded LU with partial pivoting (dgbtrf/dgbtrs) in the order perm (position p holds DOF-order index
   perm[p]; with it the matrix has kl sub- and ku superdiagonals, model.linalg.band_order). AB: (2 kl + ku + 1)
   x m column-major band storage, t: 2 m. Entries outside the band are zero by the band order's pattern, so
   only the band is read, and checked finite (*finite = 0 if not). Returns LAPACK's info. */
static FINT band_solve(const newton_matrix* s, long long m_, long long kl_, long long ku_, const long long* perm,
                       double* AB, double* x, double* t, FINT* ipiv, void** fp, double* finite) {
  FINT m = (FINT) m_, kl = (FINT) kl_, ku = (FINT) ku_, ld = 2 * kl + ku + 1, two = 2, info = 0;
  char N = 'N';
  for (long long q = 0; q < m_; ++q) {
    double* col = AB + q * ld;
    long long lo = q - ku_ > 0 ? q - ku_ : 0, hi = q + kl_ < m_ - 1 ? q + kl_ : m_ - 1, pq = perm[q];
    for (long long r = 0; r < ld; ++r) col[r] = 0.0;
    for (long long p = lo; p <= hi; ++p) {
      double v = entry(s, perm[p], pq);
      if (!isfinite(v)) *finite = 0.0;
      col[kl_ + ku_ + p - q] = v;
    }
  }
  if (*finite == 0.0) return 0;  /* the caller raises on it; LAPACK is not given NaN */
  for (long long p = 0; p < m_; ++p) {
    t[p] = x[perm[p]];
    t[m_ + p] = x[m_ + perm[p]];
  }
  ((gbtrf_t) fp[DGBTRF])(&m, &m, &kl, &ku, AB, &ld, ipiv, &info);
  if (info == 0) ((gbtrs_t) fp[DGBTRS])(&N, &m, &kl, &ku, &two, AB, &ld, ipiv, t, &m, &info);
  for (long long p = 0; p < m_; ++p) {
    x[perm[p]] = t[p];
    x[m_ + perm[p]] = t[m_ + p];
  }
  return info;
}

long long newton(const long long* ip, const double* dp, const double* H, const double* C, const double* g,
                 const double* Rd, double* J, double* b, FINT* ipiv, void** fp, double* dxi, double* tan,
                 double* sc) {
  long long n = ip[0], N = ip[1], d = ip[2], kind = ip[3], nba = ip[4];
  const long long *f = ip + 5, *bpos = f + (n - 1), *bcomp = bpos + nba;
  /* band orders: reduced (kl, ku, perm over the n - 1 free DOFs), bordered (kl, ku, perm over all n); kl < 0:
     dense LU */
  const long long *band_r = bcomp + nba, *band_b = band_r + 2 + (n - 1);
  long long nf = n - 1;
  const double *axis = dp, *scale = dp + 6, *scale_free = dp + 6 + n;
  double near = dp[3], s_target = dp[4], dval = dp[5];
  double* dd = b + 2 * n;  /* b (5 n): two right-hand sides, the drive gradient, the banded solve's copies */
  long long i, j;
  sc[3] = 1.0;
  for (i = 0; i < n; ++i)
    if (!isfinite(g[i])) sc[3] = 0.0;
  if (band_r[0] < 0 || band_b[0] < 0)  /* a dense form may be solved: all of H (the banded one checks its band) */
    for (i = 0; i < n; ++i)
      for (j = 0; j < n; ++j)
        if (!isfinite(H[i * N + j])) sc[3] = 0.0;
  for (i = 0; i < n; ++i) dd[i] = 0.0;
  if (kind == 0) {
    double q[4], a0 = axis[0], a1 = axis[1], a2 = axis[2];
    quaternion(Rd, q);
    double w = q[0], x = q[1], y = q[2], z = q[3];
    double th = 2.0 * atan2(x * a0 + y * a1 + z * a2, w);
    dval = th + 2 * M_PI * nearbyint((near - th) / (2 * M_PI));
    double va = x * a0 + y * a1 + z * a2, den = w * w + va * va, tg[3];
    tg[0] = (w * (w * a0 + y * a2 - z * a1) + va * x) / den;
    tg[1] = (w * (w * a1 + z * a0 - x * a2) + va * y) / den;
    tg[2] = (w * (w * a2 + x * a1 - y * a0) + va * z) / den;
    for (i = 0; i < nba; ++i) dd[bpos[i]] = tg[bcomp[i]];
  } else {
    dd[d] = 1.0;
  }
  sc[0] = dval;
  double rhs_drive = dval - s_target, dd_d = dd[d], other = 0.0;
  for (i = 0; i < n; ++i) other += fabs(dd[i]);
  other -= fabs(dd_d);
  FINT info = 0;
  if (other <= 1e-14 * fabs(dd_d)) {
    /* reduced: the free block (row-major, read transposed by LAPACK), two right-hand sides */
    double dxd = -rhs_drive / dd_d;
    for (i = 0; i < nf; ++i) {
      long long fi = f[i];
      double Afd = H[fi * N + d] + (C ? C[fi * N + d] : 0.0);
      b[i] = -g[fi] - Afd * dxd;
      b[nf + i] = -Afd / dd_d;
      if (band_r[0] < 0)
        for (j = 0; j < nf; ++j) J[i * nf + j] = H[fi * N + f[j]] + (C ? C[fi * N + f[j]] : 0.0);
    }
    if (nf > 0 && band_r[0] >= 0) {
      newton_matrix s = {H, C, dd, f, N, d, 0};
      info = band_solve(&s, nf, band_r[0], band_r[1], band_r + 2, J, b, b + 3 * n, ipiv, fp, sc + 3);
    } else if (nf > 0) {
      FINT nn = (FINT) nf, two = 2;
      char T = 'T';
      ((getrf_t) fp[DGETRF])(&nn, &nn, J, &nn, ipiv, &info);
      if (info == 0) ((getrs_t) fp[DGETRS])(&T, &nn, &two, J, &nn, ipiv, b, &nn, &info);
    }
    for (i = 0; i < nf; ++i) {
      dxi[f[i]] = b[i];
      tan[f[i]] = b[nf + i];
    }
    dxi[d] = dxd;
    tan[d] = 1.0 / dd_d;
  } else {
    if (band_b[0] >= 0) {
      /* bordered, banded: each DOF's row (the drive's: its gradient), so the solution is in DOF order */
      newton_matrix s = {H, C, dd, f, N, d, 1};
      for (i = 0; i < n; ++i) {
        b[i] = -g[i];
        b[n + i] = 0.0;
      }
      b[d] = -rhs_drive;
      b[n + d] = 1.0;
      info = band_solve(&s, n, band_b[0], band_b[1], band_b + 2, J, b, b + 3 * n, ipiv, fp, sc + 3);
    } else {
      /* bordered: free rows of H + C, then the drive gradient row */
      for (i = 0; i < nf; ++i)
        for (j = 0; j < n; ++j) J[i * n + j] = H[f[i] * N + j] + (C ? C[f[i] * N + j] : 0.0);
      for (j = 0; j < n; ++j) J[nf * n + j] = dd[j];
      for (i = 0; i < nf; ++i) {
        b[i] = -g[f[i]];
        b[n + i] = 0.0;
      }
      b[nf] = -rhs_drive;
      b[n + nf] = 1.0;
      FINT nn = (FINT) n, two = 2;
      char T = 'T';
      ((getrf_t) fp[DGETRF])(&nn, &nn, J, &nn, ipiv, &info);
      if (info == 0) ((getrs_t) fp[DGETRS])(&T, &nn, &two, J, &nn, ipiv, b, &nn, &info);
    }
    for (i = 0; i < n; ++i) {
      dxi[i] = b[i];
      tan[i] = b[n + i];
    }
  }
  sc[4] = (double) info;
  sc[5] = other <= 1e-14 * fabs(dd_d) ? 1.0 : 0.0;
  /* scaled increment and residual (model.statics._scaled_residual) */
  double inc = 0.0, dmax = 0.0, res = 0.0;
  for (i = 0; i < n; ++i) {
    double v = fabs(dxi[i] / scale[i]);
    if (!(v <= inc)) inc = v;  /* a NaN stays */
    if (isnan(inc)) break;
  }
  for (i = 0; i < nf; ++i) {
    double v = fabs(H[f[i] * N + f[i]]);
    if (v > dmax) dmax = v;
  }
  double floor_ = 1e-12 * (dmax > 1e-300 ? dmax : 1e-300);
  for (i = 0; i < nf; ++i) {
    double v = fabs(H[f[i] * N + f[i]]), ds = v > floor_ ? v : floor_;
    double r = fabs(g[f[i]]) / (ds * scale_free[i]);
    if (r > res) res = r;
  }
  double rd = fabs(dval - s_target) / scale[d];
  if (rd > res) res = rd;
  sc[1] = inc;
  sc[2] = res;
  return 0;
}

/* Jacobi scaling D = diag(K)^-1/2 of both eigen drivers; 0 (the route through M) if a diagonal entry of K or
   M is not positive. */
static int jacobi(long long n, const double* K, const double* M, double* D) {
  for (long long i = 0; i < n; ++i) {
    if (!(K[i * n + i] > 0.0) || !(M[i * n + i] > 0.0)) return 0;
    D[i] = 1.0 / sqrt(K[i * n + i]);
  }
  return 1;
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
  potrf_t potrf = (potrf_t) fp[DPOTRF];
  trsm_t trsm = (trsm_t) fp[DTRSM];
  sygst_t sygst = (sygst_t) fp[DSYGST];
  sytrd_t sytrd = (sytrd_t) fp[DSYTRD];
  stemr_t stemr = (stemr_t) fp[DSTEMR];
  ormtr_t ormtr = (ormtr_t) fp[DORMTR];
  trtrs_t trtrs = (trtrs_t) fp[DTRTRS];
  char U = 'U', L = 'L', R = 'R', N = 'N', T = 'T', V = 'V', I = 'I';
  FINT info = 0, one = 1, i, j;
  FINT lwork = 82 * n, liwork = 10 * n, ldz = n, nzc = k, m = 0, tryrac = 1;
  FINT il = n - k + 1, iu = n;
  double alpha = 1.0, vl = 0.0, vu = 0.0;
  double *Ks = buf, *Ms = Ks + n * n, *Z = Ms + n * n, *D = Z + n * n, *d = D + n, *e = d + n,
         *tau = e + n, *w = tau + n, *work = w + n;  /* dstemr writes W(1:N) */
  FINT* isuppz = iw + liwork;
  if (!jacobi(n, K, M, D)) return 1;
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

/* ---- the lowest eigenpairs of a banded pencil by Lanczos (lanczos_pairs) ---- */
typedef void (*pbtrf_t)(char*, FINT*, FINT*, double*, FINT*, FINT*);
typedef void (*gemv_t)(char*, FINT*, FINT*, double*, double*, FINT*, double*, FINT*, double*, double*, FINT*);

/* w -= Q (Q^T w), twice (classical Gram-Schmidt against the m orthonormal columns of Q, n x m column-major;
   BLAS dgemv: the plain loops' serial sums were most of a solve at n = 89); h: m doubles */
static void reorth(long long n_, long long m_, const double* Q, double* w, double* h, void** fp) {
  FINT n = (FINT) n_, m = (FINT) m_, one = 1;
  double p1 = 1.0, m1 = -1.0, z = 0.0;
  char T = 'T', N = 'N';
  if (m == 0) return;
  for (int pass = 0; pass < 2; ++pass) {
    ((gemv_t) fp[DGEMV])(&T, &n, &m, &p1, (double*) Q, &n, w, &one, &z, h, &one);
    ((gemv_t) fp[DGEMV])(&N, &n, &m, &m1, (double*) Q, &n, h, &one, &p1, w, &one);
  }
}

/* Upper band storage (LAPACK 'U', ld = kd + 1): entry (i, j), i <= j <= i + kd, at B[kd + i - j + j * ld]. */
#define BAND(B, i, j) (B)[kd + (i) - (j) + (j) * ld]

/* w = U^-1 v (U upper band, from dpbtrf), by columns: each solved w[j] is subtracted from the rows above it
   along column j of the band, which is contiguous in memory (the row-wise sums read the band with stride kd
   and cost twice as much) */
static void band_back(long long n, long long kd, const double* U, const double* v, double* w) {
  long long ld = kd + 1;
  for (long long i = 0; i < n; ++i) w[i] = v[i];
  for (long long j = n - 1; j >= 0; --j) {
    double wj = w[j] / BAND(U, j, j);
    long long lo = j - kd > 0 ? j - kd : 0;
    w[j] = wj;
    for (long long i = lo; i < j; ++i) w[i] -= BAND(U, i, j) * wj;
  }
}

/* z = U^-T v */
static void band_fwd(long long n, long long kd, const double* U, const double* v, double* z) {
  long long ld = kd + 1;
  for (long long j = 0; j < n; ++j) {
    double s = v[j];
    long long lo = j - kd > 0 ? j - kd : 0;
    for (long long i = lo; i < j; ++i) s -= BAND(U, i, j) * z[i];
    z[j] = s / BAND(U, j, j);
  }
}

/* y = A v, A symmetric in upper band storage. Column j adds its upper part to y[lo..j-1] and its row part
   (the same entries, by symmetry) to y[j], which no earlier column touched. */
static void band_mv(long long n, long long kd, const double* restrict A, const double* restrict v,
                    double* restrict y) {
  long long ld = kd + 1;
  for (long long j = 0; j < n; ++j) {
    long long lo = j - kd > 0 ? j - kd : 0;
    double vj = v[j], s = BAND(A, j, j) * vj;
    for (long long i = lo; i < j; ++i) {
      double a = BAND(A, i, j);
      y[i] += a * vj;
      s += a * v[i];
    }
    y[j] = s;
  }
}

/* The number of negative pivots of W = A - sigma B (upper band, overwritten) by a symmetric LDL^T without
   pivoting: the number of eigenvalues of A x = lambda B x below sigma (Sylvester's law of inertia; the Sturm
   sequence check of Bathe, Finite Element Procedures, 1996, sec. 11.4.3). -1 when a pivot is tiny against
   its row (no pivoting: the count is then not trusted and the caller takes the dense route). */
static long long band_inertia(long long n, long long kd, double* W) {
  long long ld = kd + 1, neg = 0;
  for (long long j = 0; j < n; ++j) {
    double d = BAND(W, j, j), size = 0.0;
    long long hi = j + kd < n - 1 ? j + kd : n - 1;
    for (long long l = j; l <= hi; ++l) size += fabs(BAND(W, j, l));
    if (!(fabs(d) > 1e-12 * size)) return -1;
    if (d < 0.0) ++neg;
    for (long long l = j + 1; l <= hi; ++l) {
      double t = BAND(W, j, l) / d;
      for (long long m = l; m <= hi; ++m) BAND(W, l, m) -= t * BAND(W, j, m);
    }
  }
  return neg;
}

/* Column m of Q (n x m+1, column-major): a fixed pseudo-random vector (a 64-bit LCG from *seed) orthogonalised
   against the first m columns and normalised. Returns 0 if nothing is left of it. h: m doubles. */
static int random_column(long long n, long long m, double* Q, double* h, unsigned long long* seed, void** fp) {
  double *q = Q + m * n, r = 0.0;
  for (long long i = 0; i < n; ++i) {
    *seed = *seed * 6364136223846793005ULL + 1442695040888963407ULL;
    q[i] = (double) (*seed >> 11) / 9007199254740992.0 - 0.5;
  }
  reorth(n, m, Q, q, h, fp);
  for (long long i = 0; i < n; ++i) r += q[i] * q[i];
  r = sqrt(r);
  if (!(r > 0.0)) return 0;
  for (long long i = 0; i < n; ++i) q[i] /= r;
  return 1;
}

/* Doubles of workspace lanczos_pairs needs (order n, half bandwidth kd, at most mmax Lanczos vectors). */
long long lanczos_doubles(long long n, long long kd, long long mmax) {
  return 4 * (kd + 1) * n + n * (mmax + 1) + 5 * n + 4 * mmax + mmax * mmax + 18 * mmax + (mmax + 1) + mmax;
}

/* The Rayleigh quotients of rayleigh() over the band: the entries (perm[p], perm[q]), |p - q| <= kd, which
   hold every nonzero of the pencil, instead of a scan of the whole triangle. A(r, c) = A[ro[r] + co[c]]. */
static void rayleigh_band(long long n, long long kd, long long k, const long long* perm, const long long* ro,
                          const long long* co, const double* K, const double* M, double* lam, const double* X,
                          long long xs, const long long* xo) {
  for (long long c = 0; c < k; ++c) {
    long double a = 0.0L, b = 0.0L;
    for (long long p = 0; p < n; ++p) {
      long long lo = p - kd > 0 ? p - kd : 0, pp = perm[p];
      long double xp = (long double) X[xo[pp] * xs + c];
      for (long long q = lo; q <= p; ++q) {
        long long pq = perm[q], r = pp > pq ? pp : pq, cc = pp > pq ? pq : pp;  /* lower triangle */
        long double xx = xp * (long double) X[xo[pq] * xs + c];
        if (q != p) xx *= 2.0L;
        a += (long double) K[ro[r] + co[cc]] * xx;
        b += (long double) M[ro[r] + co[cc]] * xx;
      }
    }
    if (b > 0.0L) lam[c] = (double) (a / b);
  }
}

/* The k lowest eigenpairs of K x = lambda M x whose nonzeros lie within kd of the diagonal in the order perm
   (position p holds row perm[p]). The pencil is read through index maps, entry (r, c) of K at
   K[ro[r] + co[c]] (the free block of the whole matrices without a copy: ro[r] = f_r N, co[c] = f_c; r >= c,
   the lower triangle, read), and each vector written to row xo[r] of X (k columns, rows not written stay as
   they are). Jacobi scaling and the Cholesky factor of K as in lowest_pairs, then Lanczos with full
   reorthogonalisation (twice) on the standard problem U^-T M_s U^-1 y = mu y (the largest mu are the lowest
   lambda; Parlett, The Symmetric Eigenvalue Problem, ch. 13), from a fixed pseudo-random start, until each of
   the k largest Ritz values' residual beta_m |s_mi| is at most tol mu_max; then the Sturm count at
   sigma = lambda_k (1 + gap) must be k (no eigenvalue below was missed). The Ritz pairs (one MRRR solve of T,
   the largest part of a small solve) are first computed at step ip[5] (lanczos_first_check: where the solve of
   a neighbouring problem stopped), then every two steps.
   ip: n, k, kd, mmax, refine, first check, (out) steps taken. dp: tol, gap. Output as lowest_pairs. Returns 0,
   1 (K not positive definite or a diagonal of M not positive: the route through M), 2 (not converged in mmax
   steps, a tiny pivot in the Sturm count, or a count other than k: the caller takes the dense route). */
long long lanczos_pairs(long long* ip, const double* dp, const long long* perm, const long long* ro,
                        const long long* co, const long long* xo, const double* K, const double* M, double* lam,
                        double* X, void** fp, double* buf, FINT* iw) {
  long long n = ip[0], k = ip[1], kd = ip[2], mmax = ip[3], refine = ip[4], first = ip[5];
  double tol = dp[0], gap = dp[1];
  long long ld = kd + 1, i, j, p;
  double *Kb = buf, *Mb = Kb + ld * n, *W = Mb + ld * n, *T = W + ld * n, *Q = T + ld * n, *D = Q + n * (mmax + 1),
         *w = D + n, *u = w + n, *z = u + n, *x = z + n, *al = x + n, *be = al + mmax, *dd = be + mmax,
         *ee = dd + mmax, *S = ee + mmax, *wk = S + mmax * mmax, *hw = wk + 18 * mmax, *tw = hw + mmax + 1;
  ip[6] = 0;
  for (i = 0; i < n; ++i) {  /* Jacobi scaling (as jacobi() does on a plain matrix) */
    double kii = K[ro[i] + co[i]];
    if (!(kii > 0.0) || !(M[ro[i] + co[i]] > 0.0)) return 1;
    D[i] = 1.0 / sqrt(kii);
  }
  for (j = 0; j < n; ++j) {  /* scaled bands in the order perm */
    long long lo = j - kd > 0 ? j - kd : 0, pj = perm[j];
    for (p = lo; p <= j; ++p) {
      long long pi = perm[p], r = pi > pj ? pi : pj, c = pi > pj ? pj : pi;  /* lower triangle */
      BAND(Kb, p, j) = D[pi] * K[ro[r] + co[c]] * D[pj];
      BAND(Mb, p, j) = D[pi] * M[ro[r] + co[c]] * D[pj];
    }
  }
  FINT nn = (FINT) n, kk = (FINT) kd, ldd = (FINT) ld, info = 0;
  char U = 'U', V = 'V';
  for (i = 0; i < ld * n; ++i) W[i] = Kb[i];
  ((pbtrf_t) fp[DPBTRF])(&U, &nn, &kk, W, &ldd, &info);
  if (info != 0) return 1;
  unsigned long long seed = 0x9E3779B97F4A7C15ULL;
  random_column(n, 0, Q, hw, &seed, fp);  /* the start */
  long long m = 0, done = 0, mlim = mmax < n ? mmax : n;
  if (first < k) first = k;
  while (m < mlim) {
    double* q = Q + m * n;
    band_back(n, kd, W, q, u);  /* w = U^-T M U^-1 q */
    band_mv(n, kd, Mb, u, z);
    band_fwd(n, kd, W, z, w);
    double a = 0.0, wn = 0.0;
    for (i = 0; i < n; ++i) a += q[i] * w[i];
    al[m] = a;
    for (i = 0; i < n; ++i) wn += w[i] * w[i];
    reorth(n, m + 1, Q, w, hw, fp);  /* full reorthogonalisation */
    double b = 0.0;
    for (i = 0; i < n; ++i) b += w[i] * w[i];
    b = sqrt(b);
    ++m;
    if ((m >= first && (m - first) % 2 == 0) || m == mlim) {
      /* the k largest Ritz values (tw, ascending) and their vectors of T (S, m x k) by MRRR, as in
         lowest_pairs: a full dsteqr of T cost a sixth of a solve */
      FINT mm = (FINT) m, il = (FINT) (m - k + 1), iu = (FINT) m, nf = 0, nzc = (FINT) k, tryrac = 1;
      FINT lw = (FINT) (18 * mmax), liw = (FINT) (10 * mlim);
      double vl = 0.0, vu = 0.0;
      char I = 'I';
      for (j = 0; j < m; ++j) dd[j] = al[j];
      for (j = 0; j + 1 < m; ++j) ee[j] = be[j];
      ee[m - 1] = 0.0;
      ((stemr_t) fp[DSTEMR])(&V, &I, &mm, dd, ee, &vl, &vu, &il, &iu, &nf, tw, S, &mm, &nzc, iw, &tryrac, wk, &lw,
                        iw + 2 * mlim, &liw, &info);
      if (info != 0 || nf != k) return 2;
      int ok = 1;
      for (j = 0; j < k; ++j)
        if (!(fabs(b * S[(m - 1) + j * m]) <= tol * tw[k - 1])) ok = 0;
      if (ok) {
        done = 1;
        break;
      }
    }
    if (m == mlim) break;
    if (!(b > 1e-10 * sqrt(wn))) {  /* an invariant subspace: go on from a new vector orthogonal to it */
      b = 0.0;
      if (!random_column(n, m, Q, hw, &seed, fp)) return 2;
    } else {
      for (i = 0; i < n; ++i) Q[m * n + i] = w[i] / b;
    }
    be[m - 1] = b;
  }
  ip[6] = m;
  if (!done) return 2;
  /* Sturm count below sigma: exactly the k found */
  double mu_k = tw[0];
  if (!(mu_k > 0.0)) return 2;
  double sigma = (1.0 / mu_k) * (1.0 + gap);
  for (i = 0; i < ld * n; ++i) T[i] = Kb[i] - sigma * Mb[i];
  if (band_inertia(n, kd, T) != k) return 2;
  for (j = 0; j < k; ++j) {  /* Ritz vectors y = Q s, x = U^-1 y, phi = D x / sqrt(mu), lowest lambda first */
    long long c = k - 1 - j;
    double mu = tw[c], s = 1.0 / sqrt(mu);
    for (i = 0; i < n; ++i) {
      double y = 0.0;
      for (p = 0; p < m; ++p) y += Q[p * n + i] * S[p + c * m];
      z[i] = y;
    }
    band_back(n, kd, W, z, x);
    lam[j] = 1.0 / mu;
    for (p = 0; p < n; ++p) X[xo[perm[p]] * k + j] = D[perm[p]] * x[p] * s;
  }
  if (refine) rayleigh_band(n, kd, k, perm, ro, co, K, M, lam, X, k, xo);
  return 0;
}

/* band_inertia of A - sigma B (upper bands, ld = kd + 1; W: ld n of work), for the tests. */
long long sturm_count(long long n, long long kd, const double* A, const double* B, double sigma, double* W) {
  for (long long i = 0; i < (kd + 1) * n; ++i) W[i] = A[i] - sigma * B[i];
  return band_inertia(n, kd, W);
}
