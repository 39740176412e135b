"""Executor-agnostic batch runner: one whole case per task, JSON in and out, resumable from a store.

Any ``concurrent.futures.Executor`` runs the cases: a local process pool by default, a Dask cluster's
executor (:func:`dask_executor`) for scale-out. Workers receive a JSON string and the importable name of
the case function (``"module:function"``), never pickled CasADi objects; each worker imports the function
itself and builds (or loads from the disk cache, ``model/kernels.py``, ``$FLEXOPT_CACHE_DIR``) its compiled
kernels. Nothing here imports a scheduler at import time: ``distributed`` loads only in
:func:`dask_executor` and :func:`dask_local_cluster`. On an executor that reports its worker threads
(``slots()``, as :func:`dask_executor`'s does) one or two tasks per thread are in flight (:func:`_in_flight`)
and short cases travel in chunks (:func:`_chunk_size`); each case keeps its own record, store file and progress
event.

Store layout (``store=DIR``): one file ``DIR/<case id>.json`` per finished case, written as the case
completes (temporary file, ``fsync``, atomic rename), so a crash never leaves a half-written record and an
interrupted batch resumes without redoing finished work. A record is either the case function's dictionary
with ``"id"`` added, or a failure record with exactly the keys ``{"id", "error", "kind"}``. One store holds
the cases of one case function: the case id does not include ``fn``.

What is stored: the result of every case the function returned or raised from. What is not: a case the
executor could not run (a lost Dask worker, ``KilledWorker``): it is returned as a failure record but not
stored, so the next run tries it again. A process pool whose worker dies is broken for every case; the
batch stops with a ``RuntimeError`` (finished cases are stored; rerun to resume). A Dask cluster left
without workers would wait forever (its scheduler keeps the cases queued for workers that may come back):
after ``no_worker_timeout`` seconds without any worker the batch stops with :class:`NoWorkers`
(finished cases are stored and carried by the exception).
"""

from __future__ import annotations

import concurrent.futures as cf
import hashlib
import importlib
import json
import math
import multiprocessing
import os
import sys
import tempfile
import threading
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

__all__ = [
    "BatchCancelled",
    "NoWorkers",
    "case_id",
    "case_seed",
    "dask_executor",
    "dask_local_cluster",
    "process_pool",
    "run_cases",
]

_FAILURE_KEYS = frozenset({"id", "error", "kind"})
_POLL = 0.2  # seconds between looks at the cancel event while cases run
_WORKER_POLL = 1.0  # seconds between asks for the executor's worker count (an RPC to a Dask scheduler)
NO_WORKER_TIMEOUT = 60.0  # default: seconds a batch waits for a cluster without workers before it stops
_CHUNK_SECONDS = 1.0  # work per task on a chunking executor (_chunk_size): a task's ~7 ms is then under 1 %
_CHUNK_MAX = 32  # cases per task at most (progress, cancel and a lost worker's rerun stay fine-grained)
_CHUNK_WINDOW = 16  # finished cases whose median time sizes the next chunk


class BatchCancelled(Exception):
    """The batch was cancelled.

    Attributes
    ----------
    results
        One entry per case, in the order of ``cases``: the record of every finished case (stored ones
        included), ``None`` for a case that did not run.
    """

    def __init__(self, results: list[dict | None]) -> None:
        super().__init__(
            f"cancelled after {sum(r is not None for r in results)} of {len(results)} cases; "
            "rerun with the same store to resume"
        )
        self.results = results


class NoWorkers(RuntimeError):
    """The executor had no workers for longer than the timeout: the batch stopped.

    Attributes
    ----------
    results
        As :class:`BatchCancelled`: the record of every finished case (stored ones included), ``None``
        for a case that did not finish.
    """

    def __init__(self, results: list[dict | None], timeout: float) -> None:
        done = sum(r is not None for r in results)
        super().__init__(
            f"the cluster had no workers for {timeout:g} s: stopped after {done} of {len(results)} "
            "cases (the finished ones are kept in the store); start workers (`dask worker "
            "SCHEDULER_ADDRESS`) and rerun with the same store to resume"
        )
        self.results = results


def case_id(case: dict) -> str:
    """Deterministic id of a case: SHA-256 of its canonical JSON (sorted keys, no spaces), 20 hex digits.

    Key order does not matter; value types do (``1`` and ``1.0`` are different cases). Raises
    ``ValueError`` for a case that is not strict JSON (NaN, numpy scalars, tuples as keys, ...).
    """
    try:
        blob = json.dumps(case, sort_keys=True, separators=(",", ":"), allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise ValueError(
            f"a case must be strict JSON ({exc}): convert numpy values with float() or "
            ".tolist() and replace NaN or infinity by null"
        ) from None
    return hashlib.sha256(blob.encode()).hexdigest()[:20]


def case_seed(case: dict, base_seed: int = 0) -> int:
    """A 32-bit random seed for one case, the same on any worker, in any order, on any rerun.

    ``numpy.random.SeedSequence([base_seed, int(case_id(case), 16)]).generate_state(1)[0]``: the case id
    (80 bits) is mixed with ``base_seed`` by numpy's SeedSequence hash, so different cases (or base seeds)
    get independent streams. Use it as ``numpy.random.default_rng(case_seed(case, base_seed))``.
    """
    import numpy as np

    if not isinstance(base_seed, int) or base_seed < 0:
        raise ValueError(f"base_seed must be a non-negative integer, got {base_seed!r}")
    return int(np.random.SeedSequence([base_seed, int(case_id(case), 16)]).generate_state(1)[0])


def _split(fn: str) -> tuple[str, str]:
    mod, sep, name = fn.partition(":")
    if not (sep and mod and name and all(p.isidentifier() for p in mod.split(".")) and name.isidentifier()):
        raise ValueError(
            f"fn must name an importable function as 'module:function' (e.g. "
            f"'flexopt.optim.search:run_case'), got {fn!r}"
        )
    return mod, name


def _message(exc: BaseException) -> str:
    # the message only: FlexoptError and ValueError messages already say what is wrong and how to fix it
    return str(exc) or type(exc).__name__


def _import_fn(fn: str) -> Callable[[dict], Any] | str:
    """Worker side: the case function ``fn`` names, or, when it cannot be imported, the failure envelope (JSON,
    ``"setup": True``) that stops the batch."""
    mod, name = _split(fn)
    try:
        return getattr(importlib.import_module(mod), name)
    except (ImportError, AttributeError) as exc:
        return json.dumps({"ok": False, "setup": True, "error": _message(exc), "kind": type(exc).__name__})


def _run_one(func: Callable[[dict], Any], fn: str, case_json: str) -> str:
    """Worker side: ``func`` (named ``fn``) on one case; the envelope ``{"ok", "result" | "error", "kind",
    "seconds"}`` as JSON, the result serialised once (``seconds``: the case's own wall time)."""
    t0 = time.perf_counter()
    try:
        from ..model.threads import limited  # lazily: flexopt.model loads CasADi

        with limited():  # one BLAS thread (model.threads); a no-op in a pool worker limited at its start
            out = func(json.loads(case_json))
        if not isinstance(out, dict):
            raise TypeError(f"{fn} returned a {type(out).__name__}: a case function must return a dict")
        try:  # NaN is kept (Python's JSON reads it back)
            return json.dumps({"ok": True, "result": out, "seconds": time.perf_counter() - t0})
        except (TypeError, ValueError) as exc:
            raise type(exc)(
                f"the result of {fn} is not JSON ({exc}): return floats, lists and dicts "
                "(numpy values through float() or .tolist())"
            ) from None
    except Exception as exc:  # noqa: BLE001 - every failure of a case becomes its record: type and message
        return json.dumps(
            {"ok": False, "error": _message(exc), "kind": type(exc).__name__, "seconds": time.perf_counter() - t0}
        )


def _call(fn: str, case_json: str) -> str:
    """Worker side: import ``fn``, run it on one case, its envelope (:func:`_run_one`) as JSON."""
    func = _import_fn(fn)
    return func if isinstance(func, str) else _run_one(func, fn, case_json)


def _call_many(fn: str, cases_json: list[str]) -> str:
    """Worker side: several cases in turn (one task on a cluster: see :func:`_chunk_size`), their envelopes as a
    JSON list; only the import's failure when ``fn`` cannot be imported (every case would fail alike)."""
    func = _import_fn(fn)
    if isinstance(func, str):
        return f"[{func}]"
    return "[" + ",".join(_run_one(func, fn, c) for c in cases_json) + "]"


def _median(seconds: list[float]) -> float | None:
    """The median time of the last :data:`_CHUNK_WINDOW` finished cases (None before the first)."""
    if not seconds:
        return None
    recent = sorted(seconds[-_CHUNK_WINDOW:])
    return recent[len(recent) // 2]


def _chunk_size(median: float | None, waiting: int, slots: int) -> int:
    """Cases per task on an executor that reports its worker threads (a Dask cluster: :func:`dask_executor`).

    One Dask task costs the cluster a few ms of CPU in its scheduler, nanny and worker event loops, and a round
    trip before a worker starts the next: measured (``python bench/bench_dask_overhead.py``, 400 cases of 50 ms
    on 2 single-threaded workers, ideal 10 s, 27 Nov 2026), one task per case took 14.5 s on a LocalCluster
    against 12.3 s in chunks and 10.4 s on the process pool (10.5 s in chunks on ``dask_local_cluster``). A topology
    search's first pass has hundreds of 0.1-0.3 s cases. So cases are sent in chunks of about
    :data:`_CHUNK_SECONDS` of work, the size from ``median``, the median time of the last finished cases (1
    until one has finished: nothing is known), at most :data:`_CHUNK_MAX`, and at most ``waiting / (2 slots)``
    so that the last cases still spread over every worker thread instead of queueing behind one."""
    if median is None:
        return 1
    size = int(_CHUNK_SECONDS / max(median, 1e-3))
    return max(1, min(size, _CHUNK_MAX, waiting // (2 * max(slots, 1))))


def _in_flight(median: float | None, slots: int) -> int:
    """Tasks in flight on an executor that reports its worker threads: one per thread, the next task going to
    the first thread free as on the pool (a Dask scheduler queues what it is given on its workers, and at a
    batch's end one worker's queue waits while another idles: measured, two per thread made the quick
    search's full pass of 1-5 s cases slower than the pool's). With short cases (median under
    :data:`_CHUNK_SECONDS`) two per thread: a thread then starts its next task without waiting for a round
    trip through the scheduler and the client, and a task waiting behind another holds at most about a
    second of work (``python bench/bench_topology.py --runs quick default --dask``, docs/pages/optimisation.md)."""
    return slots * (2 if median is not None and median < _CHUNK_SECONDS else 1)


def _cpu_count() -> int:
    try:
        return len(os.sched_getaffinity(0))  # the CPUs this process may use (containers, taskset)
    except AttributeError:  # pragma: no cover - not on Linux
        return os.cpu_count() or 1


def _default_executor(workers: int) -> cf.Executor:
    # Start method: forkserver, else spawn. Plain fork copies the parent at an arbitrary moment; the callers
    # run threads (the HTTP service, the job process's cancel watcher, a Dask client, BLAS pools), and a
    # lock held by one of them at fork time stays locked forever in the child. A forkserver child is
    # forked from a separate single-threaded server process that was itself started fresh, so that hazard
    # is gone, and starting a child costs a fork instead of a new interpreter (spawn).
    # One BLAS thread per worker (model.threads, FLEXOPT_BLAS_THREADS): the workers already use every core,
    # and nested BLAS threads on top of them oversubscribe the machine (measured: a 2-worker topology search
    # ran several times slower). Each worker limits itself at its start; the caller's process is untouched.
    from ..model.threads import limit_process

    # The fork server imports CasADi, scipy and the case functions once (optim._preload), so a worker forked
    # from it starts with them loaded (measured: a 2-worker pool's first cases 5-6 s sooner at load 11).
    methods = multiprocessing.get_all_start_methods()
    ctx = multiprocessing.get_context("forkserver" if "forkserver" in methods else "spawn")
    if ctx.get_start_method() == "forkserver":
        ctx.set_forkserver_preload(["flexopt.optim._preload"])  # no effect once the server runs
    return cf.ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=limit_process)


def process_pool(workers: int | None = None) -> cf.Executor:
    """The local process pool :func:`run_cases` uses by default (``workers`` processes, default the CPUs this
    process may use; one BLAS thread each), for a caller that runs several batches on one pool (a topology
    search's screen, passes and verification); the caller shuts it down."""
    if workers is not None and workers < 1:
        raise ValueError(f"workers must be at least 1, got {workers}")
    return _default_executor(workers or _cpu_count())


def dask_executor(address: str, **client_kwargs: object) -> cf.Executor:
    """A ``concurrent.futures`` executor on the Dask cluster at ``address`` (``Client(address).get_executor()``).

    ``client_kwargs`` go to ``distributed.Client`` (e.g. ``timeout="10s"``). Shutting the executor down
    (``with dask_executor(addr) as ex: ...``) also closes its client; the cluster itself keeps running.
    The workers need flexopt installed (they import ``optim.batch`` and the case function); started with
    ``--nthreads 1 --preload flexopt.optim._preload`` they load CasADi and the case functions once at start,
    as the local pool's workers do.
    """
    try:
        from distributed import Client
        from distributed.cfexecutor import ClientExecutor
    except ImportError as exc:  # pragma: no cover - depends on the installation
        raise ValueError(
            "running on a Dask cluster needs the 'distributed' package: pip install 'flexopt[cluster]'"
        ) from exc

    class _OwningClientExecutor(ClientExecutor):
        def worker_count(self) -> int:
            """Workers the scheduler knows now (run_cases stops a batch left without any)."""
            return len(self._client.scheduler_info(n_workers=-1).get("workers", {}))

        def slots(self) -> int:
            """Worker threads the scheduler knows now (run_cases keeps one or two tasks per thread in flight)."""
            return sum(self._client.nthreads().values())

        # ClientExecutor.shutdown waits for (or cancels) the futures but leaves the client connected
        def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
            try:
                super().shutdown(wait=wait and not cancel_futures)
            finally:
                self._client.close()

    try:
        client = Client(address, **client_kwargs)
    except OSError as exc:
        raise ValueError(
            f"cannot reach the Dask scheduler at {address!r} ({exc}): check the address, or "
            "start one with `dask scheduler` and workers with `dask worker ADDRESS`"
        ) from exc
    return _OwningClientExecutor(client)


def dask_local_cluster(workers: int | None = None, **cluster_kwargs: Any) -> Any:
    """A Dask ``LocalCluster`` on this machine, set up as flexopt's cases run best on it: ``workers``
    single-threaded worker processes (default: the CPUs this process may use), each preloaded with
    ``optim._preload`` (CasADi and the case functions imported once, glibc's large-block reuse, one BLAS
    thread), the scheduler and the nannies with ``optim.dask_preload`` (Dask's polling slowed, the workers'
    profiler off), no dashboard. ``cluster_kwargs`` go to ``LocalCluster`` and win. Use it with
    :func:`dask_executor` on its ``scheduler_address``; close it (``with``) when done."""
    try:
        from distributed import LocalCluster
    except ImportError as exc:  # pragma: no cover - depends on the installation
        raise ValueError(
            "a local Dask cluster needs the 'distributed' package: pip install 'flexopt[cluster]'"
        ) from exc
    if workers is not None and workers < 1:
        raise ValueError(f"workers must be at least 1, got {workers}")
    options: dict[str, Any] = {
        "n_workers": workers or _cpu_count(),
        "threads_per_worker": 1,
        "processes": True,
        "preload": ["flexopt.optim._preload"],
        "preload_nanny": ["flexopt.optim.dask_preload"],
        "scheduler_kwargs": {"preload": ["flexopt.optim.dask_preload"]},
        "dashboard_address": None,
    }
    return LocalCluster(**{**options, **cluster_kwargs})


def _write(store: Path, cid: str, record: dict) -> None:
    fd, tmp = tempfile.mkstemp(dir=store, prefix=f".{cid}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as fh:
            json.dump(record, fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, store / f"{cid}.json")
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _load(store: Path | None, cid: str) -> dict | None:
    """The stored record of a case, or None (not stored, unreadable, or someone else's file)."""
    if store is None:
        return None
    try:
        record = json.loads((store / f"{cid}.json").read_text())
    except (OSError, ValueError):
        return None
    return record if isinstance(record, dict) and record.get("id") == cid else None


def _is_failure(record: dict) -> bool:
    return set(record) == _FAILURE_KEYS


class _Bar:
    """A one-line text progress bar on stderr, drawn only when stderr is a terminal."""

    def __init__(self, total: int) -> None:
        self.total, self.failed, self.on = total, 0, sys.stderr.isatty()

    def __call__(self, done: int, status: str) -> None:
        self.failed += status == "failed"
        if self.on:
            n = int(30 * done / max(self.total, 1))
            tail = f", {self.failed} failed" if self.failed else ""
            sys.stderr.write(f"\r[{'#' * n}{'.' * (30 - n)}] {done}/{self.total} cases{tail}")
            sys.stderr.flush()

    def close(self) -> None:
        if self.on:
            sys.stderr.write("\n")
            sys.stderr.flush()


def run_cases(
    cases: list[dict],
    fn: str,
    *,
    executor: cf.Executor | None = None,
    workers: int | None = None,
    store: str | os.PathLike | None = None,
    progress: Callable[[dict], None] | None = None,
    cancel: threading.Event | None = None,
    retry_failed: bool = False,
    no_worker_timeout: float = NO_WORKER_TIMEOUT,
) -> list[dict]:
    """Run ``fn`` on every case, in parallel; results in the order of ``cases``.

    Parameters
    ----------
    cases
        JSON dictionaries; equal cases (same :func:`case_id`) run once and share their record.
    fn
        ``"module:function"`` importable on every worker; it takes one case dictionary and returns a JSON
        dictionary.
    executor
        Any ``concurrent.futures.Executor`` (e.g. :func:`dask_executor`); it is not shut down here. Default:
        a local process pool, shut down on return.
    workers
        Processes of the default pool (default: the CPUs this process may use); ignored with ``executor``.
    store
        Directory of finished cases (see the module docstring); cases found there are not run again.
    progress
        Called in this process after each case with ``{"done", "total", "id", "status", "record"}``, status
        one of ``"done"``, ``"failed"``, ``"skipped"`` (found in the store), record the case's record.
    cancel
        When set, no new case starts; queued ones are cancelled; cases already running on a process pool
        cannot be stopped: they finish and are stored, then :class:`BatchCancelled` is raised.
    retry_failed
        Run the cases whose stored record is a failure again (by default it is returned as it is).
    no_worker_timeout
        Seconds an executor that reports its workers (``executor.worker_count()``, as :func:`dask_executor`'s
        does) may have none while cases wait, before the batch stops with :class:`NoWorkers`.

    Returns
    -------
    list of dict
        The function's dictionary with ``"id"`` added, or a failure record ``{"id", "error", "kind"}``:
        the exception's message (no traceback) and its class name (e.g. ``"EquilibriumError"``).

    Raises
    ------
    BatchCancelled
        ``cancel`` was set (or the executor cancelled cases); carries the results finished so far.
    ValueError
        ``fn`` is not ``"module:function"``, cannot be imported on a worker, or a case is not strict JSON.
    RuntimeError
        The executor broke (a worker process died): finished cases are stored, rerun to resume.
    NoWorkers
        A cluster had no workers for ``no_worker_timeout`` seconds (a ``RuntimeError``; carries the results).
    """
    _split(fn)
    if workers is not None and workers < 1:
        raise ValueError(f"workers must be at least 1, got {workers}")
    if not no_worker_timeout > 0:
        raise ValueError(f"no_worker_timeout must be a positive number of seconds, got {no_worker_timeout!r}")
    root = Path(store) if store is not None else None
    if root is not None:
        root.mkdir(parents=True, exist_ok=True)
    ids = [case_id(c) for c in cases]
    results: list[dict | None] = [None] * len(cases)
    total, done = len(cases), 0
    bar = _Bar(total)

    def report(cid: str, status: str, record: dict) -> None:
        bar(done, status)
        if progress is not None:
            progress({"done": done, "total": total, "id": cid, "status": status, "record": record})

    todo: dict[str, list[int]] = {}  # case id -> its positions in `cases`
    for i, cid in enumerate(ids):
        if cid in todo:
            todo[cid].append(i)
            continue
        old = _load(root, cid)
        if old is not None and not (retry_failed and _is_failure(old)):
            results[i] = old
            done += 1
            report(cid, "skipped", old)
        else:
            todo[cid] = [i]
    if not todo:
        bar.close()
        return results  # type: ignore[return-value]

    own = executor is None
    n_workers = min(workers or _cpu_count(), len(todo))
    ex: cf.Executor = _default_executor(n_workers) if executor is None else executor
    # Own pool: keep exactly one case per worker in flight, so a cancel stops every case not yet started
    # (a process pool hands queued calls to its workers early and cannot take them back). An executor that
    # reports its worker threads (``slots()``, as dask_executor's does) gets one or two tasks per thread in
    # flight (_in_flight), each a chunk of cases (_chunk_size); any other executor gets every case at once.
    limit = n_workers if own else None
    slots_of = None if own else getattr(ex, "slots", None)
    queue = deque(todo.items())
    running: dict[cf.Future, list[str]] = {}
    seconds: list[float] = []  # the finished cases' own times, which size the chunks
    stopped = False
    count = None if own else getattr(ex, "worker_count", None)
    looked, idle_since = time.monotonic(), None
    n_slots, slots_looked = 1, -math.inf

    def starved() -> bool:
        """True once the executor has had no workers for ``no_worker_timeout`` seconds."""
        nonlocal looked, idle_since
        now = time.monotonic()
        if count is None or now - looked < _WORKER_POLL:
            return False
        looked = now
        if count() > 0:
            idle_since = None
            return False
        idle_since = now if idle_since is None else idle_since
        return now - idle_since >= no_worker_timeout

    def cancelled() -> bool:
        return cancel is not None and cancel.is_set()

    def slots() -> int:
        nonlocal n_slots, slots_looked
        now = time.monotonic()
        if slots_of is not None and now - slots_looked >= _WORKER_POLL:
            n_slots, slots_looked = max(int(slots_of()), 1), now
        return n_slots

    def fill() -> None:
        while queue and not cancelled():
            if slots_of is None:
                if limit is not None and len(running) >= limit:
                    return
                cid, idx = queue.popleft()
                running[ex.submit(_call, fn, json.dumps(cases[idx[0]]))] = [cid]
                continue
            n, median = slots(), _median(seconds)
            if len(running) >= _in_flight(median, n):
                return
            size = _chunk_size(median, len(queue), n)
            group = [queue.popleft() for _ in range(min(size, len(queue)))]
            blobs = [json.dumps(cases[idx[0]]) for _, idx in group]
            running[ex.submit(_call_many, fn, blobs)] = [cid for cid, _ in group]

    def finish(f: cf.Future, cids: list[str]) -> None:
        nonlocal done
        try:
            raw = json.loads(f.result())
        except cf.CancelledError:
            return  # cancelled by someone else (e.g. the executor shut down): not finished, not stored
        except cf.BrokenExecutor as exc:
            raise RuntimeError(
                "a worker process died (out of memory, killed, a crash in compiled code, or a script that "
                "starts the batch without an `if __name__ == '__main__':` guard); finished cases are in the "
                "store: rerun to resume"
            ) from exc
        except Exception as exc:  # noqa: BLE001 - the executor could not run these cases: report, do not store
            raw = [{"ok": False, "error": _message(exc), "kind": type(exc).__name__, "lost": True}] * len(cids)
        # a chunk whose function could not be imported holds that one envelope: it stops the batch here
        for cid, out in zip(cids, raw if isinstance(raw, list) else [raw]):
            if out.get("setup"):
                raise ValueError(
                    f"cannot import {fn!r} on a worker ({out['kind']}: {out['error']}): check the "
                    "name, and that the workers have flexopt (and the module) installed"
                )
            if "seconds" in out:
                seconds.append(float(out["seconds"]))
            if out["ok"]:
                record = dict(out["result"], id=cid)
            else:
                record = {"id": cid, "error": out["error"], "kind": out["kind"]}
            if root is not None and not out.get("lost"):
                _write(root, cid, record)
            for i in todo[cid]:
                results[i] = record
                done += 1
            report(cid, "failed" if _is_failure(record) else "done", record)

    try:
        fill()
        while running:
            if cancelled() and not stopped:
                stopped = True
                for f in list(running):
                    if f.cancel():  # queued: dropped; running (cancel() is False): finishes below
                        del running[f]
                continue
            finished, _ = cf.wait(running, timeout=_POLL, return_when=cf.FIRST_COMPLETED)
            for f in finished:
                finish(f, running.pop(f))
            fill()
            if running and starved():
                for f in running:
                    f.cancel()
                raise NoWorkers(results, no_worker_timeout)
    finally:
        bar.close()
        if own:
            ex.shutdown(wait=True, cancel_futures=True)
    if any(r is None for r in results):  # cancelled, by `cancel` or by the executor
        raise BatchCancelled(results)
    return results  # type: ignore[return-value]
