"""One BLAS/LAPACK thread for flexopt's compute, wherever it runs, without the user setting anything.

flexopt's matrices have a few hundred rows: BLAS threads buy nothing on them, and on a machine with other
work running a threaded OpenBLAS spins and waits for cores it does not get (issue 26 item 2, measured: the
double cross's curve from the command line 6.7-9.3 s with the default threads against 1.2-2.2 s with one,
a server request 2.5-6.9 s against 0.19-0.26 s). So flexopt limits the BLAS/LAPACK pools it computes on to
:func:`threads` threads (``FLEXOPT_BLAS_THREADS``, default 1) through threadpoolctl, in two forms:

- :func:`limit_process`, once, in the processes flexopt owns: the command line, the server's lifespan, each
  pool worker's initializer and each job process. It writes the limit into the ``*_NUM_THREADS`` variables
  (read by a BLAS library when it loads: scipy's own OpenBLAS loads only when ``scipy.linalg`` is first
  imported, and child processes inherit them) and sets it on the libraries already loaded. It is never
  undone: the process is flexopt's.
- :func:`limited`, around the Python API's calls (``frequency_curve``, ``diagnose``, a batch case on a Dask
  worker, ...), in a process that is the user's. threadpoolctl's limits are process-global, so a context
  entered and left by two threads at once could restore the wrong value (thread A leaves and restores the
  user's threads while thread B still computes; B then "restores" A's limit of one for good). The
  contexts therefore share one count under a lock: the first to enter saves the libraries' settings and
  limits them, the nested and concurrent ones only count, and the last to leave restores what the first
  saved. While any flexopt call runs, other threads of the process see the limit too (the limit is the
  library's, not the thread's). In a process under :func:`limit_process` the context does nothing.

numpy's and scipy's wheels ship OpenBLAS built with pthreads, whose thread count is the library's; an
OpenMP-built BLAS keeps its count per thread, and only the calling thread's is set (threadpoolctl's
documented limit).
"""

from __future__ import annotations

import contextlib
import os
import sys
import threading
from collections.abc import Iterator
from typing import Any

__all__ = ["VARIABLES", "limit_process", "limited", "threads"]

#: The variables through which BLAS/LAPACK/OpenMP libraries read their thread count when they load.
VARIABLES = (
    "OPENBLAS_NUM_THREADS",
    "OMP_NUM_THREADS",
    "MKL_NUM_THREADS",
    "BLIS_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "NUMEXPR_NUM_THREADS",
)

_LOCK = threading.Lock()
_state: dict[str, Any] = {"process": False, "held": 0, "saved": None}


def threads() -> int:
    """BLAS threads for flexopt's compute: ``FLEXOPT_BLAS_THREADS`` (a positive integer), else 1."""
    raw = os.environ.get("FLEXOPT_BLAS_THREADS", "").strip()
    if not raw:
        return 1
    try:
        n = int(raw)
    except ValueError:
        n = 0
    if n < 1:
        raise ValueError(
            f"FLEXOPT_BLAS_THREADS={raw!r} is not a positive integer: set it to e.g. 1 (the default) or unset it"
        )
    return n


def limit_process() -> None:
    """Limit this whole process, for good, to :func:`threads` BLAS threads (flexopt's own processes only).

    Idempotent. The variables cover libraries loaded later and child processes; threadpoolctl covers the
    libraries already loaded (nothing to do, and threadpoolctl not even imported, before numpy loads)."""
    n = threads()
    with _LOCK:
        for var in VARIABLES:
            os.environ[var] = str(n)
        if "numpy" in sys.modules or _state["held"]:
            from threadpoolctl import threadpool_limits

            _take_control()
            threadpool_limits(limits=n)
        _state["process"] = True


def _preload() -> None:
    """Load the BLAS libraries flexopt may load in the middle of a call, so that a call's limit covers them.

    scipy's wheel ships its own OpenBLAS (``scipy.libs``), loaded when ``scipy.linalg`` is first imported,
    which flexopt's compute does lazily (null spaces of constrained scenes, the fast methods): a library
    loaded inside a call would miss the limit set at its start. Loading it (dlopen, ~10 ms, once; not the
    0.2-1 s import of ``scipy.linalg``) lets the limit cover it; the later import finds it loaded."""
    if _state.get("preloaded"):
        return
    _state["preloaded"] = True
    import ctypes
    import glob
    import importlib.util

    try:
        spec = importlib.util.find_spec("scipy")
    except (ImportError, ValueError):  # pragma: no cover - scipy is a dependency
        return
    if spec is None or spec.origin is None:  # pragma: no cover
        return
    for path in sorted(
        glob.glob(os.path.join(os.path.dirname(os.path.dirname(spec.origin)), "scipy.libs", "*openblas*.so*"))
    ):
        try:
            ctypes.CDLL(path)
        except OSError:  # pragma: no cover - another platform's wheel layout: the limit covers what is loaded
            pass


def _take_control() -> None:
    """Let this thread set OpenBLAS's limit. threadpoolctl (3.8) lets only the first thread that sets a
    pthreads OpenBLAS's limit set it again, and silently ignores every other thread ("controlling thread"):
    a user's ``threadpool_limits(2)`` on the main thread would make a server thread's or a worker thread's
    limit a no-op. The calls here are serialised by this module's lock, so taking control is safe; after a
    restore control is released again (the user's next setting takes it back)."""
    try:
        from threadpoolctl import OpenBLASController
    except ImportError:  # pragma: no cover - threadpoolctl without per-thread control (< 3.6): nothing to take
        return
    clear = getattr(OpenBLASController, "clear_controlling_thread", None)
    if clear is not None:
        clear(force=True)


def _controller() -> Any:
    """threadpoolctl's controller of the loaded libraries, kept while no module has been imported since.

    Making one scans every loaded shared library (5-50 ms, a quarter to all of a warm curve); setting and
    restoring limits through a kept one costs about 0.1-0.7 ms. A BLAS library loads with an import (numpy,
    scipy.linalg, ...), so the controller is made again whenever ``sys.modules`` has grown or shrunk."""
    from threadpoolctl import ThreadpoolController

    n = len(sys.modules)
    kept = _state.get("controller")
    if kept is None or kept[1] != n:
        kept = _state["controller"] = (ThreadpoolController(), len(sys.modules))
    return kept[0]


def _enter() -> bool:
    """Count a call in; the first saves the libraries' settings and limits them. False: not counted."""
    with _LOCK:
        if _state["process"]:
            return False
        if _state["held"] == 0:
            _preload()
            _take_control()
            _state["saved"] = _controller().limit(limits=threads())
        _state["held"] += 1
        return True


def _leave(counted: bool) -> None:
    """Count a call out; the last restores what the first saved (unless the process is now limited)."""
    if not counted:
        return
    with _LOCK:
        _state["held"] -= 1
        if _state["held"] == 0:
            saved, _state["saved"] = _state["saved"], None
            if not _state["process"]:
                _take_control()
                saved.restore_original_limits()
                _take_control()


@contextlib.contextmanager
def limited() -> Iterator[None]:
    """A context (and decorator: ``@limited()``) for Python API calls: :func:`threads` BLAS threads inside,
    the user's setting after.

    Safe when nested and when entered by several threads at once (one count under a lock, see the module's
    docstring); does nothing in a process under :func:`limit_process`."""
    counted = _enter()
    try:
        yield
    finally:
        _leave(counted)
