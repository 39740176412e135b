"""Compiled helpers of model/assembly.py: the element inputs from the masters' state, and the scatter of
the element outputs into the gradient and Hessian.

Each is a few loops over precomputed index arrays that numpy would run as a dozen small array operations
(node states, gathers, ``bincount`` scatters), whose per-call overhead dominated the assembly of small
models. The arithmetic is the same: node position ``x_n = X_m + R_m r_n`` and rotation ``R_n = R_m`` of each
node from its master ``m`` and reference offset ``r_n``; element inputs laid out as the kernels expect
(model/elements.py); sums in the same order as ``numpy.bincount`` (element by element, entry by entry), so
the results are those of the numpy code they replace: bitwise for nodes on their masters, within a rounding
where ``R r`` of an offset node is summed in another order than numpy.einsum's (tests/test_assembly_compiled.py).

Compiled and cached like the element kernels (:func:`model.kernels.shared_library`); without a C compiler
:func:`library` is None and model/assembly.py keeps its numpy code.
"""

from __future__ import annotations

import ctypes

import numpy as np

from .errors import KernelBuildError
from .kernels import shared_library

__all__ = ["library", "ptr"]

_SOURCE = r"""
typedef long long I;

/* Node state of node k: position x (3), rotation R (row-major 3x3, = its master's), offset r = R_m r0 (3). */
static void node_state(I k, const I* master, const double* off, const double* X, const double* R, double* x,
                       const double** Rn, double* r) {
  I m = master[k];
  const double* Rm = R + 9 * m;
  const double* o = off + 3 * k;
  for (int i = 0; i < 3; ++i) {
    r[i] = Rm[3 * i] * o[0] + Rm[3 * i + 1] * o[1] + Rm[3 * i + 2] * o[2];
    x[i] = X[3 * m + i] + r[i];
  }
  *Rn = Rm;
}

/* Beam kernel inputs, row e of `in` (stride columns): per end (p at 0, q at 15) position (3), rotation
   column-major (9), offset (3). */
void fill_beams(I nb, const I* nodes, const I* master, const double* off, const double* X, const double* R,
                double* in, I stride) {
  for (I e = 0; e < nb; ++e) {
    for (int end = 0; end < 2; ++end) {
      double x[3], r[3];
      const double* Rn;
      node_state(nodes[2 * e + end], master, off, X, R, x, &Rn, r);
      double* b = in + e * stride + 15 * end;
      for (int i = 0; i < 3; ++i) { b[i] = x[i]; b[12 + i] = r[i]; }
      for (int j = 0; j < 3; ++j)
        for (int i = 0; i < 3; ++i) b[3 + 3 * j + i] = Rn[3 * i + j];
    }
  }
}

/* Truss kernel inputs: x_p (3), r_p (3), x_q (3), r_q (3). */
void fill_trusses(I nt, const I* nodes, const I* master, const double* off, const double* X, const double* R,
                  double* in, I stride) {
  for (I e = 0; e < nt; ++e) {
    for (int end = 0; end < 2; ++end) {
      double x[3], r[3];
      const double* Rn;
      node_state(nodes[2 * e + end], master, off, X, R, x, &Rn, r);
      double* b = in + e * stride + 6 * end;
      for (int i = 0; i < 3; ++i) { b[i] = x[i]; b[3 + i] = r[i]; }
    }
  }
}

/* g[dofs[e, i]] += out[e, i] (i < 12), gfull[dofs_full[e, i]] += out[e, i],
   H[flat[e, j]] += out[e, 12 + j] (j < 144): element by element, as numpy.bincount sums. */
void scatter(I ne, const double* out, I n_out, const I* dofs, const I* dofs_full, const I* flat, double* g,
             double* gfull, double* H) {
  for (I e = 0; e < ne; ++e) {
    const double* o = out + e * n_out;
    for (int i = 0; i < 12; ++i) {
      g[dofs[12 * e + i]] += o[i];
      gfull[dofs_full[12 * e + i]] += o[i];
    }
  }
  for (I e = 0; e < ne; ++e) {
    const double* o = out + e * n_out + 12;
    const I* f = flat + 144 * e;
    for (int j = 0; j < 144; ++j) H[f[j]] += o[j];
  }
}

/* H[flat[e, j]] += blocks[e, j] (j < 144). */
void scatter_blocks(I ne, const double* blocks, const I* flat, double* H) {
  for (I e = 0; e < ne; ++e)
    for (int j = 0; j < 144; ++j) H[flat[144 * e + j]] += blocks[144 * e + j];
}
"""

_LIB: list = []


def library():
    """The compiled helpers (a ctypes library with argument types set), or None without a C compiler."""
    if not _LIB:
        try:
            lib = shared_library("flexopt_assembly", (_SOURCE,), lambda: _SOURCE)
        except KernelBuildError:
            lib = None
        if lib is not None:
            L, P = ctypes.c_longlong, ctypes.c_void_p
            for name in ("fill_beams", "fill_trusses"):
                getattr(lib, name).restype = None
                getattr(lib, name).argtypes = [L, P, P, P, P, P, P, L]
            lib.scatter.restype = None
            lib.scatter.argtypes = [L, P, L, P, P, P, P, P, P]
            lib.scatter_blocks.restype = None
            lib.scatter_blocks.argtypes = [L, P, P, P]
        _LIB.append(lib)
    return _LIB[0]


def ptr(a: np.ndarray) -> int:
    """The data address of a C-contiguous array (checked: a strided view would be misread)."""
    if not a.flags.c_contiguous:
        raise ValueError("compiled assembly needs C-contiguous arrays")
    return a.ctypes.data
