"""Compiled element kernels, cached on disk, evaluated for a whole batch of elements in one call.

Small models are dominated by Python-to-CasADi call overhead, so each element kernel is generated to C
once, wrapped in a loop over elements, compiled to a shared library and called through ``ctypes`` on
contiguous numpy buffers: one call per element type per assembly, no copies.

Cache (after PyBaMM's ahead-of-time compile): the key is a SHA-256 of the kernel's serialised CasADi
function, the wrapper source, the compiler command and the CasADi version; the library is written to a
temporary file and renamed atomically, so concurrent processes never see half a file. The directory is
``$FLEXOPT_CACHE_DIR`` or ``~/.cache/flexopt/kernels``. Without a C compiler the kernel falls back to
CasADi's own virtual machine (``Function.map``) with a ``KernelPerformanceWarning``: same numbers, slower.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import tempfile
import warnings
from pathlib import Path

import casadi as ca
import numpy as np

from .elements import KernelSpec
from .errors import KernelBuildError

__all__ = ["CompiledKernel", "compiled", "cache_dir", "shared_library", "KernelPerformanceWarning"]

_WRAPPER = r"""
#include <stdlib.h>
int {batch}(long long n, const double* in, double* out) {{
  const double* arg[{sz_arg}]; double* res[{sz_res}];
  long long* iw = (long long*) malloc(sizeof(long long) * ({sz_iw} + 1));
  double* w = (double*) malloc(sizeof(double) * ({sz_w} + 1));
  int flag = 0;
  for (long long k = 0; k < n; ++k) {{
    arg[0] = in + k * {n_in};
    res[0] = out + k * {n_out};
    if ({name}(arg, res, iw, w, 0)) {{ flag = 1; break; }}
  }}
  free(iw); free(w);
  return flag;
}}
"""


class KernelPerformanceWarning(UserWarning):
    """A kernel runs in CasADi's virtual machine because no C compiler was found."""


def cache_dir() -> Path:
    """Directory of the compiled-kernel cache."""
    env = os.environ.get("FLEXOPT_CACHE_DIR")
    return Path(env) if env else Path.home() / ".cache" / "flexopt" / "kernels"


def _compiler() -> str | None:
    return os.environ.get("CC") or shutil.which("gcc") or shutil.which("cc")


_FLAGS = ("-O2", "-shared", "-fPIC", "-fno-math-errno")


def shared_library(name: str, key_parts: tuple[str, ...], source, cc: str | None = None) -> ctypes.CDLL:
    """Compile C code to a shared library once and load it from the disk cache afterwards.

    ``key_parts`` identify the code (hashed with the compiler and its flags: the library is rebuilt when
    any of them changes); ``source()`` returns the C source and is called only on a cache miss, so code
    generation costs nothing once cached. The library is written to a temporary file and renamed
    atomically, so concurrent processes never load half a file. Raises KernelBuildError when the compiler
    fails or no compiler is found.
    """
    cc = cc or _compiler()
    if cc is None:
        raise KernelBuildError(f"no C compiler found to build '{name}'; install gcc or set CC")
    key = hashlib.sha256()
    for part in (*key_parts, cc, " ".join(_FLAGS)):
        key.update(part.encode())
    directory = cache_dir()
    lib_path = directory / f"{name}-{key.hexdigest()[:24]}.so"
    if not lib_path.exists():
        directory.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=directory) as tmp:
            src = Path(tmp) / (name + ".c")
            src.write_text(source())
            tmp_lib = Path(tmp) / "lib.so"
            proc = subprocess.run([cc, *_FLAGS, str(src), "-o", str(tmp_lib), "-lm"], capture_output=True, text=True)
            if proc.returncode != 0:
                raise KernelBuildError(
                    f"compiling '{name}' failed ({cc}): {proc.stderr[-2000:]}; check the C compiler or unset CC"
                )
            os.replace(tmp_lib, lib_path)
    try:
        return ctypes.CDLL(str(lib_path))
    except OSError as exc:  # a corrupt cache entry: rebuild once
        lib_path.unlink(missing_ok=True)
        raise KernelBuildError(f"loading '{name}' from {lib_path} failed: {exc}; retry") from exc


class CompiledKernel:
    """A batch evaluator of one element kernel: ``out[k] = f(in[k])`` for every row ``k``."""

    def __init__(self, spec: KernelSpec) -> None:
        self.spec = spec
        self.n_in = spec.n_in
        self.n_out = spec.n_out
        self._lib = None
        self._fn = None
        self._address: int | None = None
        cc = _compiler()
        if cc is None:
            warnings.warn(
                f"no C compiler found: kernel '{spec.name}' runs in CasADi's virtual machine (slower); "
                "install gcc to compile it",
                KernelPerformanceWarning,
                stacklevel=2,
            )
            self._vm = spec.function
        else:
            self._vm = None
            self._load(cc)

    def _load(self, cc: str) -> None:
        f = self.spec.function
        name = f.name()
        wrapper = _WRAPPER.format(
            batch=name + "_batch", name=name, n_in=self.n_in, n_out=self.n_out,
            sz_arg=max(f.sz_arg(), 1), sz_res=max(f.sz_res(), 1), sz_iw=f.sz_iw(), sz_w=f.sz_w(),
        )

        def source() -> str:
            with tempfile.TemporaryDirectory() as tmp:
                cg = ca.CodeGenerator(name + ".c", {"with_header": False, "casadi_int": "long long"})
                cg.add(f)
                cg.generate(tmp + os.sep)
                return (Path(tmp) / (name + ".c")).read_text() + wrapper

        lib = shared_library(name, (f.serialize(), wrapper, ca.__version__), source, cc)
        fn = getattr(lib, name + "_batch")
        fn.restype = ctypes.c_int
        fn.argtypes = [ctypes.c_longlong, ctypes.c_void_p, ctypes.c_void_p]
        self._lib, self._fn = lib, fn
        self._address = ctypes.cast(fn, ctypes.c_void_p).value

    @property
    def address(self) -> int | None:
        """Address of the compiled batch entry ``int f(long long n, const double* in, double* out)`` (C code
        calls it through a pointer, model/assembly.py), or None when the kernel runs in CasADi's VM."""
        return self._address

    def __call__(self, inputs: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Evaluate on ``inputs`` of shape (n, n_in); returns (n, n_out)."""
        inputs = np.ascontiguousarray(inputs, dtype=np.float64)
        n = inputs.shape[0]
        if inputs.shape[1] != self.n_in:
            raise ValueError(f"kernel '{self.spec.name}' expects {self.n_in} inputs, got {inputs.shape[1]}")
        if out is None:
            out = np.empty((n, self.n_out))
        if n == 0:
            return out
        if self._fn is not None:
            if self._fn(n, inputs.ctypes.data, out.ctypes.data):
                raise KernelBuildError(f"kernel '{self.spec.name}' reported an evaluation error")
            return out
        res = self._vm.map(n)(inputs.T)
        out[:] = np.asarray(res).T
        return out


_CACHE: dict[str, CompiledKernel] = {}


def compiled(spec: KernelSpec) -> CompiledKernel:
    """The compiled kernel of ``spec``, built (or loaded from the disk cache) once per process."""
    k = _CACHE.get(spec.name)
    if k is None:
        k = _CACHE[spec.name] = CompiledKernel(spec)
    return k
