"""The runtime state of one application, owned by its lifespan: the worker pool, the computation slots, the
response cache, the job store and the job dispatcher."""

from __future__ import annotations

import asyncio
import concurrent.futures
import multiprocessing
import os
import threading
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fastapi import Request, Response
from starlette.exceptions import HTTPException

from ..jobs import worker
from ..jobs.worker import ComputationFailed
from ..schemas import Job
from .errors import Busy, ComputeTimeout, log
from .settings import Settings

__all__ = ["WORKER_TASKS", "Runtime", "job_store", "runtime", "submit_job"]

#: computations a worker process serves before it is replaced by a fresh one (bounds what it retains): the
#: default of the ``worker_tasks`` setting (FLEXOPT_WORKER_TASKS)
WORKER_TASKS = 200


@dataclass
class Runtime:
    """Per-application state owned by the lifespan.

    Heavy computations: at most ``max_concurrent`` run at once (one worker process, or thread, each); up to ``max_queued``
    more wait at most ``queue_timeout`` seconds for a slot; anything past that gets 429 with Retry-After.
    Each slot has its own worker process; a computation past the time limit is ended with its process, so
    its slot is free at once and the CPU is never oversubscribed (with the thread executor, which cannot end
    a computation, the slot is given back when the computation really ends).
    """

    settings: Settings
    waiting: int = 0  # requests queued for a slot
    lock: threading.Lock = field(default_factory=threading.Lock)
    cache: OrderedDict[str, Any] = field(default_factory=OrderedDict)  # canonical request -> result (LRU)
    cached_bytes: int = 0  # bytes held by the cache's values
    _slots: asyncio.Semaphore | None = None
    pools: list[Any] = field(default_factory=list)  # one single-process pool per slot (executor "process")
    idle: list[int] = field(default_factory=list)  # slots whose process is free
    jobs: Any = None  # service.jobs.store.JobStore, opened by start()
    dispatcher: Any = None  # service.jobs.dispatch.Dispatcher

    def slots(self) -> asyncio.Semaphore:
        """The slot semaphore, created on first use inside the server's event loop."""
        if self._slots is None:
            self._slots = asyncio.Semaphore(self.settings.max_concurrent)
        return self._slots

    def cached(self, key: str) -> Any | None:
        """The cached result for ``key`` (marking it recently used), or None."""
        with self.lock:
            if key in self.cache:
                self.cache.move_to_end(key)
                return self.cache[key]
        return None

    def store(self, key: str, value: Any) -> None:
        """Cache ``value`` (bytes); the least recently used entries go while the cache holds more than
        ``cache_size`` entries or ``cache_bytes`` bytes. Before the byte bound (issue 29 item 2), 256 entries of
        curves with shapes, PNGs and GIFs of distinct scenes took the server from 129 MB to 601 MB."""
        s = self.settings
        if s.cache_size <= 0:
            return
        size = len(value)
        if size > s.cache_bytes // 8:
            return
        with self.lock:
            if key in self.cache:
                self.cached_bytes -= len(self.cache[key])
            self.cache[key] = value
            self.cached_bytes += size
            self.cache.move_to_end(key)
            while len(self.cache) > s.cache_size or self.cached_bytes > s.cache_bytes:
                _, old = self.cache.popitem(last=False)
                self.cached_bytes -= len(old)

    async def _acquire(self) -> None:
        s = self.settings
        slots = self.slots()
        if not slots.locked():
            await slots.acquire()
            return
        busy = Busy(s.retry_after, s.max_concurrent)
        if self.waiting >= s.max_queued or s.queue_timeout <= 0:
            raise busy
        self.waiting += 1
        try:
            await asyncio.wait_for(slots.acquire(), s.queue_timeout)
        except TimeoutError:
            raise busy from None
        finally:
            self.waiting -= 1

    async def run(self, fn: Callable[[str], tuple[bool, Any]], spec: str) -> Any:
        """``fn(spec)`` in a worker process within the slot limit (429) and the time limit (504).

        ``fn`` is a :mod:`service.jobs.worker` function; a model error it reports is raised here again. Each
        slot has its own worker process: a computation past the time limit is ended with its process and the
        slot is free at once (issue 29 item 4: two abandoned computations held both slots for minutes). With
        the thread executor a computation cannot be ended; its slot is given back when it ends.
        """
        s = self.settings
        await self._acquire()
        loop = asyncio.get_running_loop()
        freed = threading.Event()
        slot = self.idle.pop() if self.pools else -1

        def free() -> None:  # once, whichever comes first: the work ends, or it is ended at the time limit
            if not freed.is_set():
                freed.set()
                if slot >= 0:
                    self.idle.append(slot)
                self.slots().release()

        pool = self.pools[slot] if slot >= 0 else None
        if pool is not None:
            try:
                future = pool.submit(fn, spec)
            except concurrent.futures.BrokenExecutor:  # its worker died: replace it, once
                self._new_pool(slot)
                free()
                return await self.run(fn, spec)
        else:
            future = concurrent.futures.Future()

            def in_thread() -> None:
                try:
                    future.set_result(fn(spec))
                except BaseException as exc:  # noqa: BLE001 - handed to the awaiting request
                    future.set_exception(exc)

            threading.Thread(target=in_thread, daemon=True, name="flexopt-compute").start()
        future.add_done_callback(lambda _: loop.call_soon_threadsafe(free))
        try:
            ok, payload = await asyncio.wait_for(asyncio.shield(asyncio.wrap_future(future)), s.request_timeout)
        except TimeoutError:
            if slot >= 0:  # end the computation with its process; the slot gets a fresh one
                self._new_pool(slot)
                free()
            raise ComputeTimeout(s.request_timeout) from None
        except concurrent.futures.BrokenExecutor:  # the worker running it died (killed, out of memory)
            if self.pools and self.pools[slot] is pool:  # not yet replaced by the next user of the slot
                self._new_pool(slot)
            raise ComputationFailed(
                [],
                "the worker process computing this request died (out of memory or "
                "killed); retry, or use fewer stroke points or a smaller model",
            ) from None
        if not ok:
            worker.raise_error(payload)
        return payload

    def _new_pool(self, slot: int) -> None:
        """A fresh one-process pool for ``slot``; the old one's process (if any) is ended."""
        old = self.pools[slot]
        if old is not None:
            procs = list(getattr(old, "_processes", {}).values())
            old.shutdown(wait=False, cancel_futures=True)
            for p in procs:
                p.kill()
        ctx = multiprocessing.get_context("spawn")  # never fork the threaded server
        # A worker is replaced after worker_tasks computations: the compiled kernels and caches of the
        # distinct scenes it met go with it (issue 29 item 2: memory grew over a fuzzing run).
        self.pools[slot] = concurrent.futures.ProcessPoolExecutor(
            1, mp_context=ctx, initializer=worker.warm_up, max_tasks_per_child=self.settings.worker_tasks
        )

    def start(self) -> None:
        """Open the job store (a corrupt one raises ``store.StoreCorrupt``), start the pool and the dispatcher."""
        from ..jobs.dispatch import Dispatcher
        from ..jobs.store import JobStore

        s = self.settings
        # The server validates scenes, checks costs and checks optimisation problems itself: load the model and
        # the optimiser's search (scipy.optimize) in the background from the start, so that the first request
        # does not pay all of those seconds of imports (the model used to load at the first /health, which read
        # the method names from it), while the server starts answering at once.
        threading.Thread(target=_warm_up, daemon=True, name="flexopt-warm-up").start()
        self.jobs = JobStore(s.job_store_url(), s.data_dir, s.lease_seconds)
        if s.executor == "process":
            self.pools = [None] * s.max_concurrent
            for slot in range(s.max_concurrent):
                self._new_pool(slot)
            self.idle = list(range(s.max_concurrent))
        self.dispatcher = Dispatcher(self.jobs, s.max_jobs, s.job_workers or None, s.job_stop_timeout)
        self.dispatcher.start()  # jobs whose lease expired (their server and process gone) are requeued

    def not_ready(self) -> list[str]:
        """Why the service cannot take work now (empty: ready): the store, the dispatcher, the pool."""
        from ..jobs.store import StoreUnavailable

        out = []
        if self.jobs is None:
            out.append("the job store is not open")
        else:
            try:
                self.jobs.ping()
            except StoreUnavailable as exc:
                out.append(str(exc))
        if (why := _unwritable(self.settings.data_dir)) is not None:
            out.append(why)
        if self.dispatcher is not None and (why := self.dispatcher.healthy()):
            out.append(why)
        if self.settings.executor == "process" and not self.pools:
            out.append("the worker pool is not running")
        return out

    def stop(self) -> None:
        """Stop the job dispatcher (running jobs resume at the next start), the pool, and drop the cache."""
        if self.dispatcher is not None:
            self.dispatcher.stop()
            self.dispatcher = None
        if self.pools:
            # Queued work is dropped and running computations are ended: their requests were answered or cut
            # when the server stopped listening, and waiting for them would outlast a container's stop grace.
            workers = [p for pool in self.pools for p in getattr(pool, "_processes", {}).values()]
            for pool in self.pools:
                pool.shutdown(wait=False, cancel_futures=True)
            for p in workers:
                p.terminate()
            for p in workers:
                p.join(5)
            for pool in self.pools:
                pool.shutdown(wait=True)  # the pool's manager sees its workers gone and frees its queues
            self.pools, self.idle = [], []
        self.cache.clear()
        self.cached_bytes = 0


def _warm_up() -> None:
    """Import what the routes' guards use (the model, optim.search); a failure here is the request's to report."""
    try:
        worker.warm_up()
        from ...optim import search  # noqa: F401 - guards.check_problem's import
    except Exception:  # noqa: BLE001 - the request that needs the import raises it again, with its context
        log.warning("warm-up import failed", exc_info=True)


def _unwritable(data_dir: Path) -> str | None:
    """Why ``data_dir`` (finished cases, the SQLite file) cannot take a write now, or None: a 64 kB probe file
    written, flushed to disk and removed. On a full disk /ready said 200 while submissions got 503 (issue 29
    item 8)."""
    probe = data_dir / f".ready-{os.getpid()}"
    try:
        with open(probe, "wb") as f:
            f.write(bytes(65536))
            f.flush()
            os.fsync(f.fileno())
    except OSError as exc:
        return f"the data directory {data_dir} cannot be written ({exc.strerror or exc}); free space or fix it"
    finally:
        probe.unlink(missing_ok=True)
    return None


def runtime(request: Request) -> Runtime:
    """The runtime of the application serving ``request``."""
    return request.app.state.runtime


def job_store(request: Request) -> Any:
    """The job store (``service.jobs.store.JobStore``) of the application serving ``request``."""
    store = runtime(request).jobs
    if store is None:  # pragma: no cover - only before the lifespan started
        raise HTTPException(503, "the job store is not open yet; retry")
    return store


async def submit_job(
    request: Request,
    response: Response,
    body: dict,
    idempotency_key: str | None,
    collection: str,
    estimate: dict | None = None,
) -> Job:
    """Store a job with its cost ``estimate`` (or find the one this idempotency key made), point Location at
    it, log a new one."""
    job, created = await asyncio.to_thread(
        job_store(request).submit,
        body,
        idempotency_key,
        request.state.owner,
        runtime(request).settings.max_active_jobs,
        estimate,
    )
    response.headers["Location"] = f"/v1/{collection}/{job['id']}"
    if created:
        log.info(
            "job submitted",
            extra={
                "event": "job.submitted",
                "job_id": job["id"],
                "request_id": request.state.request_id,
                "estimate_seconds": (estimate or {}).get("seconds"),
            },
        )
    return Job(**job)
