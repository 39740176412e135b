"""A Dask preload for the scheduler, the nannies and the workers of a cluster that runs flexopt's cases:
Dask's servers poll less often, and the workers' statistical profiler is off.

Dask's defaults suit an interactive dashboard: every server (scheduler, nanny, worker) wakes every 20 ms to
check that its event loop is not blocked (``tick``), every 500 ms to sample its CPU, memory, network and
disk (``monitor``), and every worker and nanny every 100 ms to read its memory (``memory_monitor``); a
worker samples its running task's stack every 10 ms (``profile``). On a machine whose cores all run cases,
each wake-up takes a core from a case. Measured on this 2-core machine (``python bench/bench_dask_overhead.py``:
400 cases of 50 ms of CPU on 2 single-threaded workers, ideal 10 s, interleaved medians, 27 Nov 2026): 14.5 s
on a LocalCluster as Dask makes it, 13.4 s with this preload, one task per case either way; with flexopt's
executor (short cases in chunks, ``optim.batch.run_cases``) 12.3 s without the preload and 10.5 s with it,
against 10.4 s on the local process pool.

:func:`dask_setup` (the hook Dask calls on a preload) slows them to :data:`INTERVALS` (never faster than
configured) and removes the worker's profiler. What stays: the event loop's watchdog still reports a loop
blocked for longer than ``distributed.admin.tick.limit`` (3 s), the memory limits are still enforced (read
every second), and the dashboard still has its figures, every two seconds.

Use: ``dask scheduler --preload flexopt.optim.dask_preload``, ``dask worker ADDRESS --nthreads 1 --preload
flexopt.optim._preload --preload-nanny flexopt.optim.dask_preload`` (``optim._preload`` calls it for the
worker too), or :func:`optim.batch.dask_local_cluster`. It imports nothing but the standard library, so a
scheduler's start does not load CasADi."""

from __future__ import annotations

from typing import Any

__all__ = ["INTERVALS", "PROFILER", "dask_setup"]

#: Dask's periodic callbacks slowed, and their period here in milliseconds (Dask's defaults: 20, 500, 100)
INTERVALS = {"tick": 1000.0, "monitor": 2000.0, "memory_monitor": 1000.0}
#: the worker's statistical profiler's callbacks (sampling, and the cycling of its history), removed
PROFILER = ("profile", "profile-cycle")


def dask_setup(server: Any) -> None:
    """Slow a Dask server's polling (:data:`INTERVALS`) and remove a worker's profiler (:data:`PROFILER`).

    Dask calls it on the scheduler, nanny or worker the module is a preload of, before the server starts its
    periodic callbacks; a callback already running takes the new period at its next call."""
    callbacks = getattr(server, "periodic_callbacks", None)
    if not isinstance(callbacks, dict):
        return
    for name in PROFILER:
        pc = callbacks.pop(name, None)
        if pc is not None:
            pc.stop()
    for name, ms in INTERVALS.items():
        pc = callbacks.get(name)
        if pc is not None and float(pc.callback_time) < ms:
            pc.callback_time = ms
