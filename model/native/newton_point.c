/* One whole Newton solve of model.statics in one C call (newton_point): per iteration the evaluation (assemble.c's
   assemble through its pointer, the rotated node offsets of model.assembly.rotate and the chart entries of
   System._chart_correction), the Newton system (linalg.c's newton through its pointer), the convergence tests
   of model.statics.solve_point in its order and the update (assemble.c's update_state), with the predictor of
   model.statics.predict in front when asked. The same operations in the same order as the Python loop over the
   compiled steps, so the same numbers to the bit (tests/test_linalg.py).

   ctx: one int64 slot per entry of model.statics.LOOP_SLOTS, whose names model.statics defines before this
   source as an enum (slot ASSEMBLE is LOOP_SLOTS' "assemble", and so on), with LOOP_MAX_ITER (the most
   iterations whose increments are kept): the table is written once, in Python. */
#include <math.h>
#include <stdint.h>
#include <string.h>
typedef int (*assemble_t)(void*, long long, long long, long long, const double*, const double*, const long long*,
                          const long long*, const double*, double*, double*, const long long*, const long long*,
                          const long long*, long long, long long, double*, double*, double*, long long, long long);
typedef int (*update_t)(void*, long long, const double*, const double*, const double*, const long long*,
                        const long long*, long long, double*, double*, double*, double*);
typedef int (*batch_t)(long long, const double*, double*);
typedef long long (*newton_t)(long long*, double*, const double*, const double*, const double*, const double*,
                              double*, double*, void*, void*, double*, double*, double*);
#define PTR(T, slot) ((T*) (intptr_t) ctx[slot])

static int evaluate(const long long* ctx, const double* X, const double* R, double* buf) {
  long long nn = ctx[NODES], ne = ctx[NE], n_out = ctx[N_OUT], N = ctx[N_EXT], n_full = ctx[N_FULL];
  const long long* nm = PTR(const long long, NODE_MASTER);
  const double* off = PTR(const double, NODE_OFFSET);
  double* r = PTR(double, OFFSETS);
  for (long long i = 0; i < nn; ++i) {  /* model.assembly.rotate */
    const double *Rm = R + 9 * nm[i], *o = off + 3 * i;
    for (int a = 0; a < 3; ++a) r[3 * i + a] = Rm[3 * a] * o[0] + Rm[3 * a + 1] * o[1] + Rm[3 * a + 2] * o[2];
  }
  double *g = buf + ne * n_out, *gf = g + N, *H = gf + n_full;
  if (((assemble_t) (intptr_t) ctx[ASSEMBLE])(PTR(void, KERNEL), ne, ctx[N_IN], n_out, X, R,
        PTR(const long long, END_MASTER), PTR(const long long, END_NODE), r, PTR(double, KERNEL_IN), buf,
        PTR(const long long, DOFS), PTR(const long long, DOFS_FULL), PTR(const long long, FLAT), N, n_full, g, gf,
        H, 0, 12))
    return 1;
  double* C = PTR(double, CHART);  /* System._chart_correction: its fixed entries; the rest stays 0 */
  const long long *cf = PTR(const long long, CHART_FLAT), *cs = PTR(const long long, CHART_SRC);
  const double* sg = PTR(const double, CHART_SIGN);
  for (long long c = 0; c < ctx[NCHART]; ++c) C[cf[c]] = sg[c] * gf[cs[c]];
  return 0;
}

static int update(const long long* ctx, const double* X, const double* R, const double* xi, double* Xn, double* Rn) {
  return ((update_t) (intptr_t) ctx[UPDATE])(PTR(void, ROT_UPDATE), ctx[MASTERS], X, R, xi, PTR(const long long, ACT),
                                             PTR(const long long, MOVING), ctx[NMOV], PTR(double, RIN),
                                             PTR(double, ROUT), Xn, Rn);
}

/* model.statics.predict: step = t1 ds (+ 0.5 ds^2 curvature, first step), + a ds^2 + b ds^3 with the cubic
   through the previous point (System.difference: translations X - Xp, rotations log(R Rp^T) by the compiled
   kernel, mapped to active numbering by act). opt: ..., ds, ds^2, ds^3, h, h^2 (powers taken in Python, as
   predict takes them). pred: t1, curvature, Xp, Rp, t0 (0 when absent). Returns 9 when a relative rotation is
   near pi (the quaternion route of System.difference is in Python). */
static int predictor(const long long* ctx, const double* opt, const long long* pred, const double* X,
                     const double* R, double* step) {
  long long n = ctx[N_ACT], nm = ctx[MASTERS], nmov = ctx[NMOV], i, j;
  double ds = opt[7], ds2 = opt[8], ds3 = opt[9], h = opt[10], h2 = opt[11];
  const double *t1 = (const double*) (intptr_t) pred[0], *cv = (const double*) (intptr_t) pred[1];
  for (i = 0; i < n; ++i) step[i] = t1[i] * ds;
  if (pred[2] == 0) {
    if (cv)
      for (i = 0; i < n; ++i) step[i] = step[i] + 0.5 * ds2 * cv[i];
    return 0;
  }
  const double *Xp = (const double*) (intptr_t) pred[2], *Rp = (const double*) (intptr_t) pred[3],
               *t0 = (const double*) (intptr_t) pred[4];
  const long long *act = PTR(const long long, ACT), *mov = PTR(const long long, MOVING);
  double *delta = PTR(double, DXI), *in = PTR(double, LOG_IN), *lo = PTR(double, LOG_OUT);
  for (i = 0; i < n; ++i) delta[i] = 0.0;
  for (long long m = 0; m < nm; ++m)
    for (int a = 0; a < 3; ++a)
      if (act[6 * m + a] >= 0) delta[act[6 * m + a]] = X[3 * m + a] - Xp[3 * m + a];
  for (j = 0; j < nmov; ++j) {  /* column-major R and Rp */
    long long m = mov[j];
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) {
        in[18 * j + a + 3 * b] = R[9 * m + 3 * a + b];
        in[18 * j + 9 + a + 3 * b] = Rp[9 * m + 3 * a + b];
      }
  }
  if (nmov && ((batch_t) (intptr_t) ctx[ROT_LOG])(nmov, in, lo)) return 9;
  for (j = 0; j < nmov; ++j) {
    long long m = mov[j];
    if (lo[4 * j + 3] > M_PI - 1e-3) return 9;
    for (int a = 0; a < 3; ++a)
      if (act[6 * m + 3 + a] >= 0) delta[act[6 * m + 3 + a]] = lo[4 * j + a];
  }
  for (i = 0; i < n; ++i) {
    double b = (t0[i] + t1[i] - 2.0 * delta[i] / h) / h2;
    double a = (t1[i] * h - delta[i]) / h2 + b * h;
    step[i] = step[i] + a * ds2 + b * ds3;
  }
  return 0;
}

long long newton_point(const long long* ctx, const double* opt, const double* X0, const double* R0,
                       const long long* pred, double* out) {
  long long nm = ctx[MASTERS], n = ctx[N_ACT], N = ctx[N_EXT], dm = ctx[DRIVE_MASTER], kind = ctx[KIND];
  long long max_iter = (long long) opt[4], it;
  double s_target = opt[0], near = opt[1], tol = opt[2], polish = opt[3], contraction = opt[5];
  double *Xo = out, *Ro = Xo + 3 * nm, *tan = Ro + 9 * nm, *info = tan + n, *buf = info + 8;
  double *g = buf + ctx[NE] * ctx[N_OUT], *H = g + N + ctx[N_FULL];
  double *Xc = PTR(double, X_WORK), *Rc = PTR(double, R_WORK), *Xn = Xc + 3 * nm, *Rn = Rc + 9 * nm, *t;
  double *dxi = PTR(double, DXI), *sc = PTR(double, SC), *dp = PTR(double, DP), incs[LOOP_MAX_ITER + 1];
  long long* ip = PTR(long long, IP);
  const double *axis = PTR(const double, AXIS), *mpos = PTR(const double, MASTER_POS);
  newton_t newton = (newton_t) (intptr_t) ctx[NEWTON];
  for (int q = 0; q < 8; ++q) info[q] = 0.0;
  if (max_iter > LOOP_MAX_ITER) { info[0] = 10; return 10; }  /* the caller checks first (_point_loop) */
  if (pred) {
    double* step = PTR(double, STEP);
    if (predictor(ctx, opt, pred, X0, R0, step)) { info[0] = 9; return 9; }
    if (update(ctx, X0, R0, step, Xc, Rc)) { info[0] = 2; return 2; }
  } else {
    memcpy(Xc, X0, sizeof(double) * 3 * nm);
    memcpy(Rc, R0, sizeof(double) * 9 * nm);
  }
  double inc = NAN, res = NAN;
  for (it = 0; it <= max_iter; ++it) {
    info[1] = (double) it;
    if (evaluate(ctx, Xc, Rc, buf)) { info[0] = 1; return 1; }
    double dval = 0.0;
    if (kind != 0) {  /* System.drive_value of a translation */
      double d0 = Xc[3 * dm] - mpos[3 * dm], d1 = Xc[3 * dm + 1] - mpos[3 * dm + 1], d2 = Xc[3 * dm + 2] - mpos[3 * dm + 2];
      dval = d0 * axis[0] + d1 * axis[1] + d2 * axis[2];
    }
    dp[3] = near;
    dp[4] = s_target;
    dp[5] = dval;
    ip[1] = N;
    newton(ip, dp, H, PTR(double, CHART), g, kind == 0 ? Rc + 9 * dm : PTR(double, EYE), PTR(double, J_WORK),
           PTR(double, B_WORK), PTR(void, IPIV), PTR(void, FP), dxi, tan, sc);
    if (sc[3] != 1.0) { info[0] = 3; return 3; }
    if (sc[4] > 0) { info[0] = 4; info[5] = sc[4]; info[6] = sc[5]; return 4; }
    dval = sc[0];
    inc = sc[1];
    res = sc[2];
    info[2] = dval;
    info[3] = inc;
    info[4] = res;
    if (!isfinite(inc)) { info[0] = 5; return 5; }
    int stalled = it > 0 && inc > 0.25 * incs[it - 1];
    if (res <= tol && (inc <= polish || (inc <= tol && stalled))) {
      memcpy(Xo, Xc, sizeof(double) * 3 * nm);
      memcpy(Ro, Rc, sizeof(double) * 9 * nm);
      return 0;
    }
    if (it > 2 && inc > 1e3 * tol && inc > 0.5) { info[0] = 6; return 6; }
    if (it >= 2 && inc > 1e3 * tol && inc > contraction * incs[it - 2]) {
      info[0] = 7;
      info[5] = incs[it - 2];
      return 7;
    }
    incs[it] = inc;
    if (update(ctx, Xc, Rc, dxi, Xn, Rn)) { info[0] = 2; return 2; }
    t = Xc; Xc = Xn; Xn = t;
    t = Rc; Rc = Rn; Rn = t;
  }
  info[0] = 8;
  return 8;
}
