"""What a Dask cluster costs on this machine, against the local process pool, for many short cases.

Every configuration runs the same batch through ``optim.batch.run_cases``: ``--cases`` cases that each burn
``--ms`` milliseconds of CPU in Python (no model work, so nothing but the executor differs), on 2 workers.
Configurations, interleaved round by round (``--repeats``), each on a fresh executor:

- ``pool``: flexopt's local process pool;
- ``dask defaults``: a ``LocalCluster`` as Dask makes it (single-threaded worker processes, Dask's
  configuration) and ``client.get_executor()``: one task per case, every case at once;
- ``dask chunks``: the same cluster with flexopt's executor (``optim.batch.dask_executor``: one task per worker
  thread in flight, short cases in chunks);
- ``quiet cluster``: ``optim.batch.dask_local_cluster`` (Dask's polling slowed and the workers' profiler
  removed by ``optim.dask_preload``) with ``client.get_executor()``: one task per case, every case at once;
- ``flexopt cluster``: that cluster with flexopt's executor (both remedies).

Printed per configuration: the batch's wall time (median, min, max), its excess over the ideal (cases x ms / 2
workers), the CPU seconds of the workers, of this process (the client, and a LocalCluster's scheduler and
nannies), and the load before and after. Run from the repository root: ``python bench/bench_dask_overhead.py
[--cases 400] [--ms 50] [--repeats 3]``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import time

import psutil
from _common import cpu_seconds


def burn(case: dict) -> dict:
    """The case: ``ms`` milliseconds of this thread's CPU in a Python loop (it holds the GIL, as model code does
    between its compiled calls)."""
    t0, x = time.thread_time(), 0
    while time.thread_time() - t0 < case["ms"] / 1e3:
        for i in range(500):
            x += i
    return {"k": case["k"], "x": x}


def _load() -> str:
    return (
        subprocess.run(["uptime"], capture_output=True, text=True, check=False)
        .stdout.split("load average: ")[-1]
        .strip()
    )


def _one(how: str, cases: list[dict]) -> tuple[float, float, float]:
    """(wall, workers' CPU, this process's CPU) of one batch on a fresh executor of kind ``how``."""
    from distributed import Client, LocalCluster
    from flexopt.optim.batch import dask_executor, dask_local_cluster, process_pool, run_cases

    me = psutil.Process()
    fn = "bench_dask_overhead:burn"
    if how == "pool":
        ex = process_pool(2)
        try:
            run_cases(cases[:2], fn, executor=ex)  # the workers are started (as a cluster is) before the clock
            pids = list(ex._processes)  # type: ignore[attr-defined]
            c0, m0, t0 = cpu_seconds(pids), cpu_seconds([me.pid]), time.perf_counter()
            run_cases(cases, fn, executor=ex)
            return time.perf_counter() - t0, cpu_seconds(pids) - c0, cpu_seconds([me.pid]) - m0
        finally:
            ex.shutdown()
    if how in ("quiet cluster", "flexopt cluster"):
        cluster = dask_local_cluster(2)
    else:
        cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
    with cluster:
        if how in ("dask defaults", "quiet cluster"):
            client = Client(cluster)
            ex = client.get_executor()
        else:
            ex = dask_executor(cluster.scheduler_address)
            client = ex._client  # type: ignore[attr-defined]
        try:
            pids = list(client.run(os.getpid).values())
            c0, m0, t0 = cpu_seconds(pids), cpu_seconds([me.pid]), time.perf_counter()
            run_cases(cases, fn, executor=ex)
            return time.perf_counter() - t0, cpu_seconds(pids) - c0, cpu_seconds([me.pid]) - m0
        finally:
            ex.shutdown()
            client.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=400)
    ap.add_argument("--ms", type=float, default=50.0)
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args()
    hows = ["pool", "dask defaults", "dask chunks", "quiet cluster", "flexopt cluster"]
    got: dict[str, list[tuple[float, float, float]]] = {h: [] for h in hows}
    l0 = _load()
    for r in range(a.repeats):
        for h in hows:  # interleaved: load drifts hit every configuration alike
            cases = [{"k": k, "ms": a.ms, "round": r} for k in range(a.cases)]  # fresh ids: no store, no reuse
            got[h].append(_one(h, cases))
    ideal = a.cases * a.ms / 1e3 / 2
    print(f"{a.cases} cases of {a.ms:g} ms CPU on 2 workers (ideal {ideal:.1f} s), {a.repeats} interleaved rounds")
    print("| executor | wall median [s] (min-max) | over the ideal | workers' CPU [s] | this process's CPU [s] |")
    print("|---|---|---|---|---|")
    for h in hows:
        w = [x[0] for x in got[h]]
        med = statistics.median(w)
        print(
            f"| {h} | {med:.2f} ({min(w):.2f}-{max(w):.2f}) | {100 * (med / ideal - 1):+.0f} % | "
            f"{statistics.median(x[1] for x in got[h]):.1f} | {statistics.median(x[2] for x in got[h]):.1f} |"
        )
    print(f"load before: {l0}; after: {_load()}")


if __name__ == "__main__":
    main()
