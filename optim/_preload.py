"""What the local process pool's fork server imports once (:func:`optim.batch.process_pool`), so that each worker
forked from it starts with CasADi, scipy and the case functions loaded instead of importing them itself
(measured: 2-4 s per worker on the shared 2-core machine, paid again by every pool of a topology search).
One BLAS thread is set first (model.threads), before numpy loads its BLAS.

A Dask worker started with this module as its preload (``dask worker ADDRESS --nthreads 1 --preload
flexopt.optim._preload``, or ``LocalCluster(preload=[...])``) gets the same, and :func:`malloc_defaults`
undoes the allocator setting Dask's nanny gives its workers (``MALLOC_TRIM_THRESHOLD_=65536``, Dask's
``distributed.nanny.pre-spawn-environ``); its ``dask_setup`` (:func:`optim.dask_preload.dask_setup`) slows the
worker's polling and removes its statistical profiler."""

from __future__ import annotations

import os

from ..model.threads import limit_process
from .dask_preload import dask_setup  # noqa: F401  (Dask calls a preload's dask_setup on its worker)

#: glibc's mallopt parameters (malloc.h) and the values set in place of Dask's: the largest mmap threshold
#: glibc's own dynamic threshold reaches on a 64-bit machine (DEFAULT_MMAP_THRESHOLD_MAX, 32 MiB) and, as that
#: dynamic rule sets, a trim threshold of twice it
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
MMAP_THRESHOLD = 32 << 20
TRIM_THRESHOLD = 2 * MMAP_THRESHOLD
_VARIABLES = ("MALLOC_TRIM_THRESHOLD_", "MALLOC_MMAP_THRESHOLD_", "MALLOC_TOP_PAD_", "MALLOC_MMAP_MAX_")


def malloc_defaults() -> bool:
    """Give glibc's allocator back the large-block behaviour its defaults have, in a process started with one of
    its tuning variables set (a Dask nanny's worker: ``MALLOC_TRIM_THRESHOLD_=65536``); True if it did.

    Any such variable switches glibc's dynamic mmap threshold off, so every block above 128 KiB (a stiffness or
    mass matrix of a hinge at 8 segments per leaf, its factors, the design Jacobians) is a fresh ``mmap``
    whose pages fault in one by one and go back with ``munmap`` when it is freed: measured, one full-pass
    case of the quick spec took 2.3-2.4 CPU-s under Dask's setting against 1.55-1.65 without it (one
    process), and the quick search's full pass on a 2-worker Dask cluster 2.4x the process pool's
    (``bench/bench_topology.py --dask``). ``mallopt`` sets the thresholds the dynamic rule would reach, so
    freed blocks are reused; the worker keeps up to :data:`TRIM_THRESHOLD` of freed memory for reuse
    instead of returning it at once (Dask's reason for the variable: its memory reports count less
    unmanaged memory). Not glibc (musl, macOS) or no variable set: nothing is done."""
    if not any(v in os.environ for v in _VARIABLES):
        return False
    import ctypes
    import platform

    if platform.libc_ver()[0] != "glibc":
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # pragma: no cover - a glibc without mallopt
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD))


limit_process()
malloc_defaults()

from . import search  # noqa: E402, F401  (imported for its side effect: loaded in the fork server)
from .topology import rank, screen  # noqa: E402, F401
