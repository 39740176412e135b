"""Fault injection on loopback (issue 13): real processes are killed, the store is locked or corrupt.

Checked each time: no finished case is lost or computed again (a case computed again is written again, so its
file gets a new inode), no job runs twice at once, no pool worker is left behind, and the service answers
(503 while the store is locked, never a 500), then carries on by itself.
"""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import threading
import time
from pathlib import Path

import httpx
import pytest

pytest.importorskip("uvicorn")
if not sys.platform.startswith("linux"):
    pytest.skip("reads /proc and uses process groups", allow_module_level=True)

from flexopt.service.client import Client  # noqa: E402

from tests.test_jobs import LONG, TINY, _cases, _server, _until  # noqa: E402
from tests.test_service import ROOT, _free_port  # noqa: E402


def _procs() -> dict[int, tuple[int, int, str]]:
    """Live processes: pid -> (parent pid, process group, command line)."""
    out = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
            cmd = (stat.parent / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
        except OSError:
            continue
        if fields[0] != "Z":
            out[int(stat.parent.name)] = (int(fields[1]), int(fields[2]), cmd)
    return out


def _job_processes(job_id: str) -> list[int]:
    return [pid for pid, (_, _, cmd) in _procs().items() if f"flexopt.service.jobs run {job_id}" in cmd]


def _group(pgid: int) -> set[int]:
    return {pid for pid, (_, g, _) in _procs().items() if g == pgid}


def _pool_workers(job_pid: int) -> list[int]:
    """The pool workers of a job process (forkserver children: the job's grandchildren)."""
    procs = _procs()
    servers = {pid for pid, (pp, _, _) in procs.items() if pp == job_pid}
    return [pid for pid, (pp, _, cmd) in procs.items() if pp in servers and "resource_tracker" not in cmd]


def _pool_worker(job_pid: int) -> int | None:
    """A pool worker of a job process, or None yet."""
    workers = _pool_workers(job_pid)
    return workers[0] if workers else None


@pytest.mark.slow
def test_killed_job_process_and_pool_worker_are_retried_from_finished_cases(tmp_path: Path) -> None:
    srv = _server(tmp_path, lease_seconds=3.0)
    try:
        with Client(srv.url, max_retries=0) as c:
            h = c.submit_optimisation(LONG)
            _until(lambda: h.status().progress.get("done", 0) >= 1)
            [job_pid] = _job_processes(h.id)
            group = _group(job_pid)
            assert len(group) >= 3, "the job process, its forkserver and pool worker form one group"
            before = _cases(tmp_path)
            os.kill(job_pid, signal.SIGKILL)  # 1. the job process dies (out of memory, killed)
            _until(lambda: not (_group(job_pid) & group), timeout=20)  # its pool workers die with it
            _until(lambda: h.status().attempts == 2 and h.status().status == "running", timeout=30)
            _until(
                lambda: (w := _job_processes(h.id)) and _pool_worker(w[0]) and len(_cases(tmp_path)) > len(before),
                timeout=90,
            )
            assert all(_cases(tmp_path)[k] == v for k, v in before.items()), "finished cases kept, not redone"
            before = _cases(tmp_path)
            [job_pid] = _job_processes(h.id)
            worker = _pool_worker(job_pid)
            assert worker is not None
            os.kill(worker, signal.SIGKILL)  # 2. a pool worker dies in the middle of a case
            job = _until(lambda: (j := h.status()).status in ("succeeded", "failed") and j, timeout=150)
            assert job.status == "succeeded", job.error
            assert job.attempts == 3, "each lost run was retried once"
            after = _cases(tmp_path)
            assert len(after) == 4 and all(after[k] == v for k, v in before.items())
            _until(lambda: not _job_processes(h.id), timeout=20)  # the last run exits after its verdict
    finally:
        srv.__exit__()


LEASE = 8  # seconds; the job process beats every 2 s, often enough under load


def _serve(tmp_path: Path, port: int) -> subprocess.Popen:
    env = {
        **os.environ,
        "FLEXOPT_DATA_DIR": str(tmp_path),
        "FLEXOPT_EXECUTOR": "thread",
        "FLEXOPT_JOB_WORKERS": "1",
        "FLEXOPT_LEASE_SECONDS": str(LEASE),
    }
    p = subprocess.Popen(
        [sys.executable, "-m", "flexopt.service.cli", "serve", "--port", str(port), "--log-level", "warning"],
        cwd=ROOT,
        env=env,
    )

    def up() -> bool:
        try:
            return httpx.get(f"http://127.0.0.1:{port}/ready", timeout=2).status_code == 200
        except httpx.TransportError:
            assert p.poll() is None, "the server exited"
            return False

    _until(up, timeout=60)
    return p


@pytest.mark.slow
def test_killed_server_leaves_its_job_to_the_live_lease(tmp_path: Path) -> None:
    """kill -9 of the server: its job process keeps running and holds the lease; the restarted server
    does not start a second process for the job, and the job finishes once, from its own run.

    The orphan's pool workers are paused (SIGSTOP) across the restart, so the job cannot finish before the
    new server is up (it did once the cases got fast: the test then checked nothing), and the pause outlasts
    the lease: a second run is then held off by the orphan's heartbeats, not by a lease not yet expired."""
    port = _free_port()
    url = f"http://127.0.0.1:{port}"
    server = _serve(tmp_path, port)
    try:
        with Client(url, max_retries=0) as c:
            h = c.submit_optimisation(LONG)
            _until(lambda: h.status().progress.get("done", 0) >= 1)
        [orphan] = _job_processes(h.id)
        workers = _pool_workers(orphan)
        assert workers, "the job computes its cases in pool workers"
        for w in workers:
            os.kill(w, signal.SIGSTOP)
        before = _cases(tmp_path)
    finally:
        server.send_signal(signal.SIGKILL)
        server.wait(10)
    killed = time.monotonic()
    seen: set[int] = set()
    try:
        server = _serve(tmp_path, port)
        with Client(url, max_retries=3) as c:
            while time.monotonic() - killed < LEASE + 4:  # past the lease and two of its heartbeats
                seen.update(_job_processes(h.id))
                j = c.optimisation(h.id)
                assert j.status == "running" and j.attempts == 1, (j.status, j.attempts)
                time.sleep(0.1)
            for w in workers:
                os.kill(w, signal.SIGCONT)
            workers = []

            def done() -> object:
                seen.update(_job_processes(h.id))
                j = c.optimisation(h.id)
                return j.status in ("succeeded", "failed") and j

            job = _until(done, timeout=150, poll=0.1)
        assert job.status == "succeeded", job.error
        assert seen == {orphan} and job.attempts == 1, "one run only: the orphan with the live lease finished it"
        after = _cases(tmp_path)
        assert len(after) == 4 and all(after[k] == v for k, v in before.items())
        _until(lambda: orphan not in _procs(), timeout=20)
    finally:
        for w in workers:
            os.kill(w, signal.SIGCONT)
        server.send_signal(signal.SIGTERM)
        server.wait(30)


@pytest.mark.slow
def test_locked_store_answers_503_and_dispatching_carries_on(tmp_path: Path) -> None:
    """Another process holds the SQLite write lock longer than the busy timeout (the audit: 40 s killed the
    dispatch thread for good and /health said 200)."""
    srv = _server(tmp_path)
    try:
        assert httpx.get(f"{srv.url}/v1/optimisations").status_code == 200
        lock = sqlite3.connect(tmp_path / "jobs.sqlite", timeout=1, check_same_thread=False)
        lock.execute("BEGIN EXCLUSIVE")
        release = threading.Timer(12.0, lock.rollback)  # the store waits 5 s for a lock, twice below
        release.start()
        try:
            r = httpx.post(f"{srv.url}/v1/optimisations", json=TINY, timeout=30)
            assert r.status_code == 503 and r.headers["retry-after"] and "job store" in r.json()["detail"], r.text
            assert httpx.get(f"{srv.url}/ready", timeout=30).status_code == 503
            assert httpx.get(f"{srv.url}/health").status_code == 200, "liveness: the process answers"
        finally:
            release.join()
            lock.close()
        _until(lambda: httpx.get(f"{srv.url}/ready").status_code == 200, timeout=60)
        with Client(srv.url, max_retries=0) as c:  # the dispatcher survived: a new job runs
            assert c.submit_optimisation(TINY).wait(poll=0.2, timeout=120)["ranking"]
    finally:
        srv.__exit__()


def test_corrupt_store_refused_at_start_with_one_line(tmp_path: Path) -> None:
    (tmp_path / "jobs.sqlite").write_bytes(b"garbage " * 1000)
    env = {**os.environ, "FLEXOPT_DATA_DIR": str(tmp_path)}
    r = subprocess.run(
        [sys.executable, "-m", "flexopt.service.cli", "serve", "--port", str(_free_port())],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and str(tmp_path / "jobs.sqlite") in lines[0] and "move it aside" in lines[0], r.stderr
