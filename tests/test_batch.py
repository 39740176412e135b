"""The batch runner (optim/batch.py) and the optimiser's batch entry point, on real model work.

Case functions live in tests/batch_cases.py so worker processes can import them; a marker file per call
counts how often cases really ran.
"""

from __future__ import annotations

import concurrent.futures as cf
import io
import json
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from flexopt.optim import optimise
from flexopt.optim.batch import BatchCancelled, case_id, case_seed, run_cases

from tests.batch_cases import leaf_torsion_hz

LEAF = "tests.batch_cases:leaf_torsion_hz"
SEEDED = "tests.batch_cases:seeded"
MISBEHAVE = "tests.batch_cases:misbehave"


def _leaf_cases(marks: Path | None = None, n: int = 4) -> list[dict]:
    return [{"thickness": 3e-4 + 1e-4 * i, "marker_dir": str(marks) if marks else None} for i in range(n)]


def _runs(marks: Path) -> int:
    return len(list(marks.iterdir()))


@pytest.fixture
def marks(tmp_path: Path) -> Path:
    d = tmp_path / "marks"
    d.mkdir()
    return d


def test_pool_results_equal_the_serial_computation_in_order(marks: Path) -> None:
    cases = _leaf_cases(marks)[::-1]
    cases.append(cases[0])  # any order, and a repeated case
    out = run_cases(cases, LEAF, workers=2)
    assert _runs(marks) == 4, "the repeated case ran once"
    for c, r in zip(cases, out, strict=True):
        assert r == dict(leaf_torsion_hz(c), id=case_id(c)), "a worker process computes exactly what the caller does"
    assert out[0] is out[-1]


def test_cancel_after_the_first_case_then_resume_runs_each_case_once(tmp_path: Path, marks: Path) -> None:
    store, cancel, events = tmp_path / "store", threading.Event(), []
    cases = _leaf_cases(marks, n=5)

    def stop_after_first(event: dict) -> None:
        events.append(event)
        cancel.set()

    with pytest.raises(BatchCancelled) as info:
        run_cases(cases, LEAF, workers=2, store=store, progress=stop_after_first, cancel=cancel)
    # the pool holds one case per worker: the other running case finishes and is stored, none starts
    assert _runs(marks) == 2 and len(events) == 2
    finished = [r for r in info.value.results if r is not None]
    assert len(finished) == 2 and len(list(store.glob("*.json"))) == 2
    assert not list(store.glob(".*")), "no temporary file is left in the store"

    events.clear()
    full = run_cases(cases, LEAF, workers=2, store=store, progress=events.append)
    assert _runs(marks) == 5, "each case ran exactly once over both batches"
    assert sorted(e["status"] for e in events) == ["done"] * 3 + ["skipped"] * 2
    assert [e["done"] for e in events] == [1, 2, 3, 4, 5] and events[-1]["total"] == 5
    assert [r for r in full if r in finished] == finished, "resumed results are the stored ones"
    assert [r["hz"] for r in full] == [leaf_torsion_hz(c)["hz"] for c in cases]


def test_a_subset_run_then_the_whole_list_resumes(tmp_path: Path, marks: Path) -> None:
    store = tmp_path / "store"
    cases = _leaf_cases(marks, n=3)
    first = run_cases(cases[:2], LEAF, workers=2, store=store)
    full = run_cases(cases, LEAF, workers=2, store=store)
    assert _runs(marks) == 3 and full[:2] == first
    for r in full:
        assert json.loads((store / f"{r['id']}.json").read_text()) == r, "one JSON file per case id"


def test_cancel_on_a_foreign_executor_drops_queued_cases(tmp_path: Path, marks: Path) -> None:
    store, cancel = tmp_path / "store", threading.Event()
    # the second case holds its thread for 0.5 s: the cancel (at the first case's event) lands while it runs
    cases = [{"base_seed": 0, "k": k, "hold": 0.5 * (k == 1), "marker_dir": str(marks)} for k in range(3)]
    with cf.ThreadPoolExecutor(1) as ex:
        with pytest.raises(BatchCancelled) as info:
            run_cases(cases, SEEDED, executor=ex, store=store, progress=lambda e: cancel.set(), cancel=cancel)
        ran = _runs(marks)
        assert 1 <= ran <= 2, "the queued case never started; the one running when cancelled may finish"
        assert info.value.results[2] is None and sum(r is not None for r in info.value.results) == ran
        assert len(list(store.glob("*.json"))) == ran, "a case that finished after the cancel is stored too"
        run_cases(cases, SEEDED, executor=ex, store=store)
    assert _runs(marks) == 3


def test_cancel_set_before_the_start_runs_nothing(marks: Path) -> None:
    cancel = threading.Event()
    cancel.set()
    with pytest.raises(BatchCancelled, match="after 0 of 3 cases") as info:
        run_cases(_leaf_cases(marks, n=3), LEAF, workers=1, cancel=cancel)
    assert info.value.results == [None, None, None] and _runs(marks) == 0


def test_failures_are_records_kept_and_retried_only_on_request(tmp_path: Path, marks: Path) -> None:
    store = tmp_path / "store"
    m = str(marks)
    cases = [{"how": how, "marker_dir": m} for how in ("lookup", "divide", "not-a-dict", "not-json", "fine")]
    cases.append({"thickness": -1e-3, "marker_dir": m})
    with cf.ThreadPoolExecutor(2) as ex:  # in-process threads: the same worker code, no process start-up
        out = run_cases(cases[:5], MISBEHAVE, executor=ex, store=store)
    out += run_cases(cases[5:], LEAF, workers=1, store=store)  # the model's own error, in a worker process
    expected = [  # kind, words in the message
        ("KeyError", "missing-key"),
        ("ZeroDivisionError", "division by zero"),
        ("TypeError", "must return a dict"),
        ("TypeError", "not JSON"),
        (None, None),
        ("SceneError", "template parameter 'thickness' = -0.001 m: must be greater than 0"),  # FlexoptError: whole
    ]
    for case, r, (kind, words) in zip(cases, out, expected, strict=True):
        if kind is None:
            assert r == {"value": "fine", "id": case_id(case)}
            continue
        assert set(r) == {"id", "error", "kind"} and r["kind"] == kind and words in r["error"], r
        assert "Traceback" not in r["error"]
        assert json.loads((store / f"{r['id']}.json").read_text()) == r, "a failure is stored like a result"
    assert _runs(marks) == 6

    events = []
    with cf.ThreadPoolExecutor(2) as ex:
        again = run_cases(cases[:5], MISBEHAVE, executor=ex, store=store, progress=events.append)
        assert again == out[:5] and _runs(marks) == 6, "a stored failure is not retried by default"
        assert {e["status"] for e in events} == {"skipped"}
        events.clear()
        run_cases(cases[:5], MISBEHAVE, executor=ex, store=store, retry_failed=True, progress=events.append)
    assert _runs(marks) == 10, "retry_failed runs the four failures again, not the finished case"
    assert sorted(e["status"] for e in events) == ["failed"] * 4 + ["skipped"]


class _LosesFirstCase(cf.ThreadPoolExecutor):
    """A thread pool that loses its first task, as a Dask cluster does when a worker dies."""

    def __init__(self) -> None:
        super().__init__(1)
        self.lost = False

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> cf.Future:
        if self.lost:
            return super().submit(fn, *args, **kwargs)
        self.lost = True
        f: cf.Future = cf.Future()
        f.set_exception(OSError("connection to worker tcp://10.0.0.7:40000 lost"))
        return f


def test_a_case_the_executor_lost_is_reported_not_stored(tmp_path: Path, marks: Path) -> None:
    cases = [{"base_seed": 1, "k": k, "marker_dir": str(marks)} for k in range(2)]
    with _LosesFirstCase() as ex:
        out = run_cases(cases, SEEDED, executor=ex, store=tmp_path)
    assert out[0] == {
        "id": case_id(cases[0]),
        "error": "connection to worker tcp://10.0.0.7:40000 lost",
        "kind": "OSError",
    }
    assert not (tmp_path / f"{case_id(cases[0])}.json").exists() and _runs(marks) == 1
    with cf.ThreadPoolExecutor(1) as ex:
        again = run_cases(cases, SEEDED, executor=ex, store=tmp_path)
    assert "seed" in again[0] and again[1] == out[1] and _runs(marks) == 2, "only the lost case ran again"


class _Slots(cf.ThreadPoolExecutor):
    """A thread pool that reports its threads as a Dask executor does (``slots()``), records how many cases each
    task carried and the most tasks it ever had in flight, and loses the tasks listed in ``lose`` (by order)."""

    def __init__(self, threads: int = 2, lose: tuple[int, ...] = ()) -> None:
        super().__init__(threads)
        self.threads, self.lose = threads, lose
        self.sizes: list[int] = []
        self.in_flight = self.most = 0
        self.lock = threading.Lock()

    def slots(self) -> int:
        return self.threads

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> cf.Future:
        self.sizes.append(len(args[1]) if isinstance(args[1], list) else 1)
        if len(self.sizes) - 1 in self.lose:
            f: cf.Future = cf.Future()
            f.set_exception(OSError("connection to worker tcp://10.0.0.7:40000 lost"))
            return f
        with self.lock:
            self.in_flight += 1
            self.most = max(self.most, self.in_flight)
        fut = super().submit(fn, *args, **kwargs)
        fut.add_done_callback(lambda _: self._done())
        return fut

    def _done(self) -> None:
        with self.lock:
            self.in_flight -= 1


def test_chunk_size_and_tasks_in_flight_by_hand() -> None:
    """optim.batch: about 1 s of work per task (_CHUNK_SECONDS) from the median of the last 16 finished cases,
    at most 32 cases, and at most waiting / (2 slots) so the last cases spread over every thread; two tasks in
    flight per thread while the cases are shorter than 1 s, else one. Each expected value is that rule worked
    by hand."""
    from flexopt.optim.batch import _chunk_size, _in_flight, _median

    assert _median([]) is None and _chunk_size(None, 100, 2) == 1, "nothing finished yet: nothing is known"
    assert _median([0.3, 0.1, 0.2]) == 0.2 and _median([5.0] * 16 + [0.1] * 17) == 0.1, "the last 16 cases"
    assert _chunk_size(0.1, 100, 2) == 10  # 1 s / 0.1 s
    assert _chunk_size(0.2, 100, 2) == 5
    assert _chunk_size(0.001, 100, 2) == 25  # 1000 by time, 32 at most, 100 // 4 = 25 by the tail
    assert _chunk_size(0.001, 1000, 2) == 32
    assert _chunk_size(0.01, 3, 2) == 1, "3 waiting on 2 threads: one each, not a chunk"
    assert _chunk_size(2.0, 100, 2) == 1, "a case longer than the target goes alone"
    assert _in_flight(None, 2) == 2 and _in_flight(2.0, 2) == 2, "unknown or long cases: one task per thread"
    assert _in_flight(0.2, 2) == 4 and _in_flight(0.2, 3) == 6, "short cases: one running, one ready per thread"


def test_an_executor_with_slots_gets_chunks_and_the_same_records(tmp_path: Path) -> None:
    """Short cases on an executor that reports its threads (as dask_executor's does) travel in chunks, at most
    two tasks per thread in flight; every case still gets its own record, progress event and store file, in
    order."""
    cases = [{"base_seed": 3, "k": k} for k in range(60)]
    with cf.ThreadPoolExecutor(2) as ex:
        plain = run_cases(cases, SEEDED, executor=ex)  # no slots(): one case per task, every case at once
    events: list[dict] = []
    with _Slots(2) as ex:
        out = run_cases(cases, SEEDED, executor=ex, store=tmp_path, progress=events.append)
    assert out == plain
    assert ex.sizes[0] == 1 and max(ex.sizes) > 1 and sum(ex.sizes) == len(cases), ex.sizes
    assert len(ex.sizes) < len(cases) / 2, "the short cases went in chunks"
    assert ex.most <= 4, "at most two tasks per thread in flight"
    assert [e["done"] for e in events] == list(range(1, 61)) and {e["status"] for e in events} == {"done"}
    assert sorted(p.name for p in tmp_path.glob("*.json")) == sorted(f"{r['id']}.json" for r in out)


def test_a_lost_chunk_reports_each_of_its_cases_and_stores_none(tmp_path: Path, marks: Path) -> None:
    """A chunk the executor could not run (a lost Dask worker): each of its cases gets the failure record, none
    is stored, and a rerun runs exactly those again."""
    cases = [{"base_seed": 5, "k": k, "marker_dir": str(marks)} for k in range(40)]
    with _Slots(2, lose=(3,)) as ex:
        out = run_cases(cases, SEEDED, executor=ex, store=tmp_path)
    lost_n = ex.sizes[3]
    assert lost_n > 1, ex.sizes
    lost = [r for r in out if r.get("kind") == "OSError"]
    assert len(lost) == lost_n and all(r["error"] == "connection to worker tcp://10.0.0.7:40000 lost" for r in lost)
    assert len(list(tmp_path.glob("*.json"))) == 40 - lost_n and _runs(marks) == 40 - lost_n
    with _Slots(2) as ex:
        again = run_cases(cases, SEEDED, executor=ex, store=tmp_path)
    assert _runs(marks) == 40 and all("seed" in r for r in again)


def test_a_chunk_whose_function_cannot_be_imported_stops_the_batch() -> None:
    with _Slots(2) as ex, pytest.raises(ValueError, match="cannot import 'tests.batch_cases:nope'"):
        run_cases([{"base_seed": 0, "k": k} for k in range(5)], "tests.batch_cases:nope", executor=ex)


def test_the_dask_preload_slows_the_polling_and_removes_the_profiler() -> None:
    """optim.dask_preload.dask_setup on a server's periodic callbacks (tornado's, as Dask's servers keep them):
    Dask's default periods (tick 20 ms, monitor 500 ms, memory monitor 100 ms) become 1 s, 2 s and 1 s, one
    configured slower is kept, the profiler's two callbacks are stopped and removed, the others untouched."""
    from flexopt.optim.dask_preload import dask_setup
    from tornado.ioloop import PeriodicCallback

    class Server:
        def __init__(self) -> None:
            ms = {"tick": 20, "monitor": 10_000, "memory_monitor": 100, "profile": 10, "profile-cycle": 1000}
            self.periodic_callbacks = {k: PeriodicCallback(lambda: None, v) for k, v in ms.items()}
            self.periodic_callbacks["heartbeat"] = PeriodicCallback(lambda: None, 500)

    srv = Server()
    prof = srv.periodic_callbacks["profile"]
    dask_setup(srv)
    got = {k: pc.callback_time for k, pc in srv.periodic_callbacks.items()}
    assert got == {"tick": 1000.0, "monitor": 10_000, "memory_monitor": 1000.0, "heartbeat": 500}
    assert not prof.is_running()
    dask_setup(object())  # not a Dask server (no periodic callbacks): nothing to do, no error


def test_case_ids_and_seeds_are_deterministic_across_workers() -> None:
    a, b = {"x": 1, "y": [1, 2]}, {"y": [1, 2], "x": 1}
    assert case_id(a) == case_id(b) and case_seed(a, 7) == case_seed(b, 7), "key order does not matter"
    assert case_id(a) != case_id({"x": 2, "y": [1, 2]}) and case_id({"x": 1}) != case_id({"x": 1.0})
    assert case_seed(a, 7) != case_seed(a, 8)
    # regression pin (this code's value, no outside source): a change re-seeds every stored batch
    assert case_seed({"x": 1}, 0) == 1581472773 and case_id({"x": 1}) == "5041bf1f713df2047843"
    cases = [{"base_seed": 3, "k": k} for k in range(4)]
    out = run_cases(cases, SEEDED, workers=2)
    assert [r["seed"] for r in out] == [case_seed(c, 3) for c in cases], "a worker derives the caller's seed"
    assert len({r["draw"] for r in out}) == 4, "different cases draw different random streams"


@pytest.mark.parametrize(
    ("call", "words"),
    [
        (lambda: run_cases([{}], "tests.batch_cases.seeded"), "'module:function'"),
        (lambda: run_cases([{}], "tests.batch_cases:"), "'module:function'"),
        (lambda: run_cases([{"x": float("nan")}], SEEDED), "strict JSON"),
        (lambda: run_cases([{"x": {1, 2}}], SEEDED), "strict JSON"),
        (lambda: run_cases([{}], SEEDED, workers=0), "workers must be at least 1"),
        (lambda: case_seed({}, -1), "non-negative"),
    ],
)
def test_bad_inputs_fail_fast_with_a_fix(call: Callable[[], object], words: str) -> None:
    with pytest.raises(ValueError, match=words):
        call()


def test_a_case_function_workers_cannot_import_stops_the_batch() -> None:
    with cf.ThreadPoolExecutor(1) as ex, pytest.raises(ValueError, match="cannot import 'tests.batch_cases:nope'"):
        run_cases([{"base_seed": 0}], "tests.batch_cases:nope", executor=ex)


def test_progress_bar_on_a_terminal(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    class Tty(io.StringIO):
        def isatty(self) -> bool:
            return True

    err = Tty()
    monkeypatch.setattr(sys, "stderr", err)
    cases = [{"base_seed": 0, "k": k} for k in range(2)] + [{"how": "divide"}]
    with cf.ThreadPoolExecutor(1) as ex:
        run_cases(cases[:2], SEEDED, executor=ex, store=tmp_path)
        run_cases(cases[2:], MISBEHAVE, executor=ex)
    lines = err.getvalue().split("\n")
    assert lines[0].endswith("] 2/2 cases") and lines[1].endswith("] 1/1 cases, 1 failed")


TINY = {
    "families": [{"template": "leaf-spring", "design": {"thickness": [3e-4, 6e-4]}}],
    "stroke": 20,
    "samples": 5,
    "starts": 2,
    "max_iterations": 5,
}


def test_optimise_runs_families_as_a_batch_and_resumes(tmp_path: Path) -> None:
    events = []
    res = optimise(TINY, workers=2, store=tmp_path, progress=events.append)
    best = res["families"][0]["best"]
    assert best["verified"]["points"] == 181 and res["ranking"][0]["template"] == "leaf-spring"
    again = optimise(TINY, workers=2, store=tmp_path)
    assert again["ranking"] == res["ranking"], "the resumed batch reads the same stored cases"
    assert {e["status"] for e in events} == {"done"}


@pytest.mark.slow
def test_dask_local_cluster_gives_the_pool_results() -> None:
    distributed = pytest.importorskip("distributed")
    from flexopt.optim.batch import dask_executor

    cases = _leaf_cases(n=3)
    pool = run_cases(cases, LEAF, workers=2)
    cancel = threading.Event()
    deadline = threading.Timer(120.0, cancel.set)  # bound: a hung cluster ends as BatchCancelled, not a hang
    deadline.start()
    t0 = time.perf_counter()
    try:
        # close order: the executor closes its client first, then the cluster stops its workers
        with distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
        ) as cluster:  # a free port: 8787 may be taken
            with dask_executor(cluster.scheduler_address, timeout="30s") as ex:
                out = run_cases(cases, LEAF, executor=ex, cancel=cancel)
                assert ex._client.status == "running"
            assert ex._client.status == "closed", "shutting the executor down closes its client"
    finally:
        deadline.cancel()
    assert time.perf_counter() - t0 < 120
    assert out == pool, "a Dask cluster computes exactly what the local process pool does"


@pytest.mark.slow  # a real cluster whose workers import the preload (CasADi, scipy, the case functions)
def test_flexopts_local_cluster_is_quiet_and_gives_the_pool_results() -> None:
    """optim.batch.dask_local_cluster: single-threaded workers, every server's polling slowed by
    optim.dask_preload (the scheduler's, the nannies' and the workers'), no worker profiler; flexopt's executor
    on it reports its threads (so cases travel in chunks) and computes exactly what the process pool does."""
    pytest.importorskip("distributed")
    from flexopt.optim.batch import dask_executor, dask_local_cluster

    def periods(dask_worker: Any = None, dask_scheduler: Any = None) -> dict:
        server = dask_worker if dask_worker is not None else dask_scheduler
        return {k: pc.callback_time for k, pc in server.periodic_callbacks.items()}

    cases = [{"base_seed": 9, "k": k} for k in range(12)]
    pool = run_cases(cases, SEEDED, workers=2)
    with dask_local_cluster(2) as cluster, dask_executor(cluster.scheduler_address, timeout="30s") as ex:
        assert ex.slots() == 2 and ex.worker_count() == 2
        servers = [*ex._client.run(periods).values(), *ex._client.run(periods, nanny=True).values()]
        servers.append(ex._client.run_on_scheduler(periods))
        for pcs in servers:
            assert pcs["tick"] >= 1000 and pcs["monitor"] >= 2000 and pcs.get("memory_monitor", 1000) >= 1000, pcs
            assert "profile" not in pcs and "profile-cycle" not in pcs
        out = run_cases(cases, SEEDED, executor=ex)
    assert out == pool


def test_an_unreachable_scheduler_says_how_to_fix_it() -> None:
    pytest.importorskip("distributed")
    from flexopt.optim.batch import dask_executor

    with pytest.raises(ValueError, match="cannot reach the Dask scheduler at 'tcp://127.0.0.1:9'.*dask scheduler"):
        dask_executor("tcp://127.0.0.1:9", timeout="1s")


@pytest.mark.slow
def test_a_dask_cluster_survives_a_lost_worker_and_stops_when_it_has_none(tmp_path: Path, marks: Path) -> None:
    """A real LocalCluster of two worker processes. Killing one while both run a case: the scheduler reruns
    that case on the other (it ran twice), the batch completes and stores each case once. Then every worker
    is closed while a case is waiting for one: the batch stops with NoWorkers after the stated timeout (it
    used to wait forever), keeping the case that finished."""
    import os
    import signal

    distributed = pytest.importorskip("distributed")
    from flexopt.optim.batch import NoWorkers, dask_executor

    hold = [{"base_seed": 1, "k": k, "hold": 2.0, "marker_dir": str(marks)} for k in range(2)]
    tail = [
        {"base_seed": 1, "k": 2, "marker_dir": str(marks)},
        {"base_seed": 1, "k": 3, "hold": 120.0, "marker_dir": str(marks)},
    ]
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
    ) as cluster:  # a free port: 8787 may be taken
        with dask_executor(cluster.scheduler_address, timeout="30s") as ex:

            def kill_one() -> None:
                while _runs(marks) < 2:  # both cases are running
                    time.sleep(0.05)
                pid = next(iter(ex._client.run(os.getpid).values()))
                os.kill(pid, signal.SIGKILL)

            killer = threading.Thread(target=kill_one, daemon=True)
            killer.start()
            out = run_cases(hold, SEEDED, executor=ex, store=tmp_path)
            killer.join(5)
            assert _runs(marks) == 3, "the case of the killed worker ran again"
            assert [r["id"] for r in out] == [case_id(c) for c in hold]
            assert sorted(p.name for p in tmp_path.glob("*.json")) == sorted(f"{case_id(c)}.json" for c in hold)

            def close_all(event: dict) -> None:
                if event["status"] == "done":  # the quick case finished: no worker is left for the other
                    cluster.scale(0)

            t0 = time.perf_counter()
            with pytest.raises(NoWorkers, match="no workers for 2 s.*1 of 2 cases") as err:
                run_cases(tail, SEEDED, executor=ex, store=tmp_path, progress=close_all, no_worker_timeout=2.0)
            assert time.perf_counter() - t0 < 30
    assert err.value.results[0]["id"] == case_id(tail[0]) and err.value.results[1] is None
    assert (tmp_path / f"{case_id(tail[0])}.json").exists() and not (tmp_path / f"{case_id(tail[1])}.json").exists()


_FAULTS = """
import resource, sys
import numpy as np
if sys.argv[1] == "1":
    import flexopt.optim._preload  # noqa: F401
n = (1 << 20) // 8  # a 1 MiB block, above glibc's fixed 128 KiB mmap threshold
np.ones(n)  # a first one: glibc's dynamic threshold, when it is on, rises to it here
f0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(200):
    a = np.ones(n)
    del a
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f0)
"""


@pytest.mark.slow  # a subprocess imports the preload (CasADi, scipy, the case functions): 3-9 s
@pytest.mark.skipif(
    not sys.platform.startswith("linux") or __import__("platform").libc_ver()[0] != "glibc", reason="glibc's mallopt"
)
def test_the_worker_preload_undoes_the_dask_nannys_allocator_setting() -> None:
    """A Dask nanny starts its workers with MALLOC_TRIM_THRESHOLD_=65536 (distributed.nanny.pre-spawn-environ),
    which switches glibc's dynamic mmap threshold off: every freed 1 MiB block goes back to the system and the
    next one faults its pages in again (a full-pass case took 1.5x the CPU: optim/_preload.py). The preload gives
    the large-block reuse back. Counted in page faults, not timed: each of the 200 blocks faults in all of its
    pages without the fix, and about none with it (the pages of a reused block are mapped already)."""
    import os
    import resource
    import subprocess

    env = {**os.environ, "MALLOC_TRIM_THRESHOLD_": "65536", "OPENBLAS_NUM_THREADS": "1"}
    pages = (1 << 20) // resource.getpagesize()

    def faults(preload: str) -> int:
        out = subprocess.run(
            [sys.executable, "-c", _FAULTS, preload], env=env, capture_output=True, text=True, check=True
        )
        return int(out.stdout.split()[-1])

    assert faults("0") >= 200 * pages * 0.9, "the nanny's setting no longer costs faults: the test sees nothing"
    assert faults("1") <= 200 * pages * 0.05
