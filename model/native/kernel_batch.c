/* The batch entry of one compiled element kernel (model/kernels.py, CompiledKernel): out[k] = f(in[k]) for every
   row k of a contiguous batch, one call per element type per assembly. Appended to the kernel's CasADi-generated
   C code; model.kernels defines before this source:
     KERNEL   the CasADi function's name        BATCH   the name of this entry (KERNEL_batch)
     N_IN     inputs per row                    N_OUT   outputs per row
     SZ_ARG, SZ_RES, SZ_IW, SZ_W                the CasADi function's work sizes (sz_arg, sz_res, sz_iw, sz_w)
   Returns 0, or 1 when the kernel reported an evaluation error. */
#include <stdlib.h>

/* the CasADi-generated function (casadi_int = long long, casadi_real = double) */
int KERNEL(const double** arg, double** res, long long* iw, double* w, int mem);

int BATCH(long long n, const double* in, double* out) {
  const double* arg[SZ_ARG]; double* res[SZ_RES];
  long long* iw = (long long*) malloc(sizeof(long long) * (SZ_IW + 1));
  double* w = (double*) malloc(sizeof(double) * (SZ_W + 1));
  int flag = 0;
  for (long long k = 0; k < n; ++k) {
    arg[0] = in + k * N_IN;
    res[0] = out + k * N_OUT;
    if (KERNEL(arg, res, iw, w, 0)) { flag = 1; break; }
  }
  free(iw); free(w);
  return flag;
}
