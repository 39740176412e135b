"""Executor-agnostic batch runner: one whole case per task, JSON in and out, resumable from a store.

Any ``concurrent.futures.Executor`` runs the cases: a local process pool by default, a Dask cluster's
executor (:func:`dask_executor`) for scale-out. Workers receive a JSON string and the importable name of
the case function, never pickled CasADi objects; each worker builds (or loads from the disk cache,
``model/kernels.py``) its compiled kernels itself. With a ``store`` directory every finished case is
written there as it completes (temporary file, then an atomic rename), so an interrupted batch resumes
without redoing finished work. Nothing here imports a scheduler at import time.
"""

from __future__ import annotations

import concurrent.futures as cf
import hashlib
import importlib
import json
import multiprocessing
import os
import sys
import tempfile
import threading
from collections.abc import Callable
from pathlib import Path

import numpy as np

__all__ = ["run_cases", "case_id", "case_seed", "dask_executor", "BatchCancelled"]


class BatchCancelled(Exception):
    """The batch was cancelled; ``results`` holds the finished cases (None for the others)."""

    def __init__(self, results: list[dict | None]) -> None:
        super().__init__(f"cancelled after {sum(r is not None for r in results)} of {len(results)} cases")
        self.results = results


def case_id(case: dict) -> str:
    """Deterministic id of a case: the SHA-256 of its canonical JSON (sorted keys), 20 hex digits."""
    blob = json.dumps(case, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(blob.encode()).hexdigest()[:20]


def case_seed(case: dict, base_seed: int = 0) -> int:
    """A 32-bit seed derived from ``base_seed`` and the case id (numpy ``SeedSequence``): the same case gets
    the same seed on any worker, in any order, on a rerun."""
    return int(np.random.SeedSequence([base_seed, int(case_id(case), 16)]).generate_state(1)[0])


def _call(fn: str, case_json: str) -> str:
    """Worker side: run ``fn`` ("module:function") on the case; exceptions become a failure record."""
    mod, _, name = fn.partition(":")
    try:
        out = getattr(importlib.import_module(mod), name)(json.loads(case_json))
        return json.dumps({"ok": True, "result": out}, allow_nan=True)
    except Exception as exc:  # noqa: BLE001 - every failure is reported as a record, with its type and message
        return json.dumps({"ok": False, "error": str(exc) or type(exc).__name__, "kind": type(exc).__name__})


def _default_executor(workers: int | None) -> cf.Executor:
    # forkserver: children start from a clean single-threaded server process, so a parent that runs threads
    # (the HTTP service, Dask's client) cannot leave a lock held in a forked child; spawn where unavailable
    # one BLAS thread per worker: the workers already use every core, and nested BLAS threads on top of
    # them oversubscribe the machine (measured: a 2-worker topology search ran several times slower)
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")
    methods = multiprocessing.get_all_start_methods()
    ctx = multiprocessing.get_context("forkserver" if "forkserver" in methods else "spawn")
    return cf.ProcessPoolExecutor(max_workers=workers or os.cpu_count() or 1, mp_context=ctx)


def dask_executor(address: str) -> cf.Executor:
    """A ``concurrent.futures`` executor on the Dask cluster at ``address`` (``Client.get_executor``)."""
    try:
        from distributed import Client
    except ImportError as exc:  # pragma: no cover - depends on the installation
        raise ValueError("running on a Dask cluster needs the 'distributed' package: pip install "
                         "'flexopt[cluster]'") from exc
    return Client(address).get_executor()


def _write(store: Path, cid: str, record: dict) -> None:
    store.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=store, prefix=f".{cid}.", suffix=".tmp")
    with os.fdopen(fd, "w") as fh:
        json.dump(record, fh)
    os.replace(tmp, store / f"{cid}.json")


def _load(store: Path | None, cid: str) -> dict | None:
    if store is None:
        return None
    path = store / f"{cid}.json"
    try:
        return json.loads(path.read_text())
    except (OSError, json.JSONDecodeError):
        return None


class _Bar:
    def __init__(self, total: int) -> None:
        self.total, self.on = total, sys.stderr.isatty()

    def __call__(self, done: int) -> None:
        if self.on:
            n = int(30 * done / max(self.total, 1))
            sys.stderr.write(f"\r[{'#' * n}{'.' * (30 - n)}] {done}/{self.total} cases")
            sys.stderr.flush()

    def close(self) -> None:
        if self.on:
            sys.stderr.write("\n")


def run_cases(cases: list[dict], fn: str, *, executor: cf.Executor | None = None, workers: int | None = None,
              store: str | os.PathLike | None = None, progress: Callable[[dict], None] | None = None,
              cancel: threading.Event | None = None, retry_failed: bool = False) -> list[dict]:
    """Run ``fn`` on every case; results in the order of ``cases``.

    Each result is the function's dictionary with ``"id"`` added, or a failure record ``{"id", "error",
    "kind"}``. Cases already in ``store`` are not run again (failures only with ``retry_failed``).
    ``progress(event)`` is called in the caller's process after each case with ``{"done", "total", "id",
    "status": "done" | "failed" | "skipped"}``.

    Raises
    ------
    BatchCancelled
        When ``cancel`` is set: no new case starts, queued ones are cancelled.
    """
    root = Path(store) if store is not None else None
    ids = [case_id(c) for c in cases]
    results: list[dict | None] = [None] * len(cases)
    total, done = len(cases), 0
    bar = _Bar(total)

    def report(cid: str, status: str) -> None:
        if progress is not None:
            progress({"done": done, "total": total, "id": cid, "status": status})
        bar(done)

    todo: dict[str, list[int]] = {}
    for i, cid in enumerate(ids):
        old = _load(root, cid)
        if old is not None and ("error" not in old or not retry_failed):
            results[i] = old
            done += 1
            report(cid, "skipped")
        else:
            todo.setdefault(cid, []).append(i)
    if not todo:
        bar.close()
        return results  # type: ignore[return-value]
    own = executor is None
    ex = _default_executor(min(workers or os.cpu_count() or 1, len(todo))) if own else executor
    futures = {ex.submit(_call, fn, json.dumps(cases[idx[0]])): cid for cid, idx in todo.items()}
    try:
        pending = set(futures)
        while pending:
            if cancel is not None and cancel.is_set():
                for f in pending:
                    f.cancel()
                raise BatchCancelled(results)
            finished, pending = cf.wait(pending, timeout=0.2, return_when=cf.FIRST_COMPLETED)
            for f in finished:
                cid = futures[f]
                try:
                    raw = f.result()
                except cf.process.BrokenProcessPool as exc:
                    raise RuntimeError(
                        "a worker process died (out of memory, killed, or a script that starts the batch "
                        "without an `if __name__ == '__main__':` guard); finished cases are in the store, "
                        "rerun to resume") from exc
                out = json.loads(raw)
                record = dict(out["result"], id=cid) if out["ok"] else {"id": cid, "error": out["error"],
                                                                        "kind": out["kind"]}
                if root is not None:
                    _write(root, cid, record)
                for i in todo[cid]:
                    results[i] = record
                    done += 1
                report(cid, "done" if out["ok"] else "failed")
    finally:
        bar.close()
        if own:
            ex.shutdown(wait=True, cancel_futures=True)
    return results  # type: ignore[return-value]
