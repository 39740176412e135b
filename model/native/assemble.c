/* Gather, element kernel and scatter of model.assembly.System.evaluate in one C call (beams only, no rigid
   deformations): the kernel inputs (from the masters' states and the nodes' rotated offsets,
   model.assembly.rotate), the batched kernel (kernel_batch.c) through its function pointer, and the sums into g,
   g_full and H in the order numpy.bincount adds them, so the numbers are the same to the last bit
   (tests/test_linalg.py compares both routes). The beams' consistent mass (mass_matrix) and the Hessian's
   directional derivative go the same way (no gradient, g_off < 0; their 144 outputs from h_off = 0);
   update_state is System.update. model.assembly defines before this source the enum of MASS_SLOTS, the slots of
   mass_matrix's context c (slot KERNEL is MASS_SLOTS' "kernel", and so on). */
#include <string.h>
typedef int (*batch_t)(long long, const double*, double*);
int assemble(void* kernel, long long ne, long long n_in, long long n_out, const double* X, const double* R,
             const long long* end_master, const long long* end_node, const double* r, double* in,
             double* out, const long long* dofs, const long long* dofs_full, const long long* flat,
             long long N, long long n_full, double* g, double* g_full, double* H, long long g_off,
             long long h_off) {
  for (long long e = 0; e < ne; ++e)
    for (int end = 0; end < 2; ++end) {
      long long m = end_master[2 * e + end];
      const double* rn = r + 3 * end_node[2 * e + end];
      const double* Rm = R + 9 * m;
      double* a = in + e * n_in + 15 * end;
      for (int i = 0; i < 3; ++i) {
        a[i] = X[3 * m + i] + rn[i];
        a[12 + i] = rn[i];
        for (int j = 0; j < 3; ++j) a[3 + i + 3 * j] = Rm[3 * i + j];
      }
    }
  if (((batch_t) kernel)(ne, in, out)) return 1;
  if (g_off >= 0) {
    memset(g, 0, sizeof(double) * N);
    memset(g_full, 0, sizeof(double) * n_full);
    for (long long e = 0; e < ne; ++e)
      for (int k = 0; k < 12; ++k) g[dofs[12 * e + k]] += out[e * n_out + g_off + k];
    for (long long e = 0; e < ne; ++e)
      for (int k = 0; k < 12; ++k) g_full[dofs_full[12 * e + k]] += out[e * n_out + g_off + k];
  }
  memset(H, 0, sizeof(double) * N * N);
  for (long long e = 0; e < ne; ++e)
    for (int k = 0; k < 144; ++k) H[flat[144 * e + k]] += out[e * n_out + h_off + k];
  return 0;
}

/* R J R^T of a row-major rotation R and tensor J, as model.assembly.rjrt sums it: A = R J, then A R^T, each
   entry a sum of products left to right */
static void rjrt(const double* R, const double* J, double* B) {
  double A[9];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) A[3 * i + j] = R[3 * i] * J[j] + R[3 * i + 1] * J[3 + j] + R[3 * i + 2] * J[6 + j];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      B[3 * i + j] = A[3 * i] * R[3 * j] + A[3 * i + 1] * R[3 * j + 1] + A[3 * i + 2] * R[3 * j + 2];
}

/* System.mass in one call (beams only, no rigid deformations; c: one int64 per entry of
   model.assembly.MASS_SLOTS): the beams' consistent mass scattered by assemble (no gradient), plus the constant
   part (const + scatter, as numpy adds them), then each node's and body's rotary inertia R J R^T summed per
   master in node order (np.add.at's) and added to the masters' rotation blocks at rot_flat in that order. out:
   the layout of NativeRoute.call, the matrix last. The same numbers as the numpy route. */
int mass_matrix(const long long* c, const double* X, const double* R, double* out) {
  long long ne = c[NE], n_out = c[N_OUT], N = c[N_EXT], n_full = c[N_FULL], nn = c[NODES], nm = c[MASTERS], i, e;
  const long long* node_master = (const long long*) c[NODE_MASTER];
  const double *off = (const double*) c[NODE_OFFSET], *Mc = (const double*) c[MASS_CONST],
               *Jn = (const double*) c[NODE_INERTIA], *Jb = (const double*) c[BODY_INERTIA];
  const long long* rot_flat = (const long long*) c[ROT_FLAT];
  double *r = (double*) c[OFFSETS], *Jm = (double*) c[INERTIA_WORK], B[9];
  for (i = 0; i < nn; ++i) {  /* model.assembly.rotate */
    const double *Rm = R + 9 * node_master[i], *o = off + 3 * i;
    for (int a = 0; a < 3; ++a) r[3 * i + a] = Rm[3 * a] * o[0] + Rm[3 * a + 1] * o[1] + Rm[3 * a + 2] * o[2];
  }
  double *g = out + ne * n_out, *M = g + N + n_full;
  if (assemble((void*) c[KERNEL], ne, c[N_IN], n_out, X, R, (const long long*) c[END_MASTER],
               (const long long*) c[END_NODE], r, (double*) c[KERNEL_IN], out, (const long long*) c[DOFS],
               (const long long*) c[DOFS_FULL], (const long long*) c[FLAT], N, n_full, g, g + N, M, -1, 0))
    return 1;
  for (i = 0; i < N * N; ++i) M[i] = Mc[i] + M[i];
  for (i = 0; i < 9 * nm; ++i) Jm[i] = 0.0;
  for (i = 0; i < nn; ++i) {
    long long m = node_master[i];
    rjrt(R + 9 * m, Jn + 9 * i, B);
    for (e = 0; e < 9; ++e) Jm[9 * m + e] = Jm[9 * m + e] + B[e];
  }
  if (Jb)
    for (long long m = 0; m < nm; ++m) {
      rjrt(R + 9 * m, Jb + 9 * m, B);
      for (e = 0; e < 9; ++e) Jm[9 * m + e] = Jm[9 * m + e] + B[e];
    }
  for (i = 0; i < 9 * nm; ++i) M[rot_flat[i]] = M[rot_flat[i]] + Jm[i];
  return 0;
}

/* System.update for a drive basis of global axes: x += u, R <- expm(psi) R through the compiled Rodrigues
   kernel (its batch entry), the same arithmetic as the numpy route. act: the active index of each of the
   6 nm global DOFs (-1: not active, increment 0). */
int update_state(void* kernel, long long nm, const double* X, const double* R, const double* xi,
                 const long long* act, const long long* moving, long long nmov, double* rin, double* rout,
                 double* Xn, double* Rn) {
  for (long long m = 0; m < nm; ++m)
    for (int i = 0; i < 3; ++i) {
      long long a = act[6 * m + i];
      Xn[3 * m + i] = X[3 * m + i] + (a >= 0 ? xi[a] : 0.0);
    }
  memcpy(Rn, R, sizeof(double) * 9 * nm);
  for (long long j = 0; j < nmov; ++j) {
    long long m = moving[j];
    for (int i = 0; i < 3; ++i) {
      long long a = act[6 * m + 3 + i];
      rin[12 * j + i] = a >= 0 ? xi[a] : 0.0;
      for (int k = 0; k < 3; ++k) rin[12 * j + 3 + i + 3 * k] = R[9 * m + 3 * i + k];
    }
  }
  if (nmov && ((batch_t) kernel)(nmov, rin, rout)) return 1;
  for (long long j = 0; j < nmov; ++j) {
    long long m = moving[j];
    for (int i = 0; i < 3; ++i)
      for (int k = 0; k < 3; ++k) Rn[9 * m + 3 * i + k] = rout[9 * j + i + 3 * k];
  }
  return 0;
}
