"""LAPACK and BLAS function pointers for compiled drivers, found without importing ``scipy.linalg``.

The hot path (Newton steps, eigen solves) calls LAPACK from C (model/native/linalg.c, built by model/linalg.py),
so it needs the routines' addresses, not Python wrappers. ``import scipy.linalg`` costs 0.17-0.3 s of a command-line call's start-up
(issue 12 item 5), so the first source is the OpenBLAS that numpy's wheel already loaded (``numpy.libs``:
64-bit integers, symbols ``scipy_<name>64_``); the second is scipy's own (``scipy.linalg.cython_lapack`` and
``cython_blas`` export their routines' pointers, 32-bit integers). Each source is accepted only after a
2 x 2 solve through it returns the right answer, so a library with another integer width or naming is never
called with the wrong ABI. ``routines()`` returns ``None`` when neither source works (the callers then use
scipy's Python wrappers).
"""

from __future__ import annotations

import ctypes
import glob
import os
from collections.abc import Callable

__all__ = ["Routines", "routines", "NAMES"]

#: The routines the compiled drivers call, in the order of their pointer table (model/native/linalg.c indexes it
#: by an enum of these names, :func:`model.linalg.source_definitions`).
NAMES = (
    "dpotrf",
    "dtrsm",
    "dsygst",
    "dsytrd",
    "dstemr",
    "dormtr",
    "dtrtrs",
    "dgetrf",
    "dgetrs",
    "dgbtrf",
    "dgbtrs",
    "dpbtrf",
    "dgemv",
)
_BLAS = {"dtrsm", "dgemv"}


class Routines:
    """Addresses of :data:`NAMES` in one library and the C type of its integers."""

    def __init__(
        self,
        source: str,
        int_type: str,
        addresses: list[int | None],
        lookup: Callable[[str], int | None] | None = None,
    ) -> None:
        self.source = source  # where the routines come from (said in provenance and tests)
        self.int_type = int_type  # "long long" (ILP64) or "int" (LP64)
        self.table = (ctypes.c_void_p * len(addresses))(*addresses)  # None: a NULL entry
        self._lookup = lookup  # name -> address in the same library (routines outside the table)

    def address(self, name: str) -> int | None:
        """The address of another LAPACK routine of the same library (e.g. ``"dpbsv"``), or None."""
        try:
            return None if self._lookup is None else self._lookup(name)
        except (AttributeError, KeyError, ValueError):
            return None


def _works(dgesv: int, int_c: type[ctypes.c_int] | type[ctypes.c_longlong]) -> bool:
    """Solve [[2, 1], [1, 3]] x = [3, 5] (x = [0.8, 1.4]) through the pointer with integer type ``int_c``."""
    fn = ctypes.CFUNCTYPE(None, *([ctypes.c_void_p] * 8))(dgesv)
    A = (ctypes.c_double * 4)(2.0, 1.0, 1.0, 3.0)
    b = (ctypes.c_double * 2)(3.0, 5.0)
    n, nrhs = int_c(2), int_c(1)
    ipiv = (int_c * 2)()
    info = int_c(-99)
    fn(ctypes.byref(n), ctypes.byref(nrhs), A, ctypes.byref(n), ipiv, b, ctypes.byref(n), ctypes.byref(info))
    return info.value == 0 and abs(b[0] - 0.8) < 1e-12 and abs(b[1] - 1.4) < 1e-12


def _from_numpy() -> Routines | None:
    import numpy

    root = os.path.dirname(os.path.dirname(numpy.__file__))
    for path in sorted(glob.glob(os.path.join(root, "numpy.libs", "*openblas*.so*"))):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for pattern in ("scipy_{}_64_", "{}_64_", "{}64_"):
            try:
                addr = [ctypes.cast(getattr(lib, pattern.format(nm)), ctypes.c_void_p).value for nm in NAMES]
                gesv = ctypes.cast(getattr(lib, pattern.format("dgesv")), ctypes.c_void_p).value
            except AttributeError:
                continue
            if gesv is not None and _works(gesv, ctypes.c_longlong):

                def lookup(nm: str, lib: ctypes.CDLL = lib, pattern: str = pattern) -> int | None:
                    return ctypes.cast(getattr(lib, pattern.format(nm)), ctypes.c_void_p).value

                return Routines(f"numpy's OpenBLAS ({os.path.basename(path)})", "long long", addr, lookup)
    return None


def _from_scipy() -> Routines | None:
    try:
        from scipy.linalg import cython_blas, cython_lapack
    except ImportError:
        return None
    get_name = ctypes.pythonapi.PyCapsule_GetName
    get_name.restype, get_name.argtypes = ctypes.c_char_p, [ctypes.py_object]
    get_ptr = ctypes.pythonapi.PyCapsule_GetPointer
    get_ptr.restype, get_ptr.argtypes = ctypes.c_void_p, [ctypes.py_object, ctypes.c_char_p]

    def address(name: str) -> int | None:
        cap = (cython_blas if name in _BLAS else cython_lapack).__pyx_capi__[name]
        return get_ptr(cap, get_name(cap))

    try:
        addr = [address(nm) for nm in NAMES]
        gesv = address("dgesv")
    except (KeyError, ValueError):
        return None
    if gesv is None or not _works(gesv, ctypes.c_int):
        return None
    return Routines("scipy.linalg.cython_lapack", "int", addr, address)


_FOUND: list = []


def routines() -> Routines | None:
    """The LAPACK/BLAS pointer table (found once per process), or ``None``."""
    if not _FOUND:
        _FOUND.append(_from_numpy() or _from_scipy())
    return _FOUND[0]
