"""Signals reach only the processes of a job run that prove to be it (issue 29 item 6).

A restarted server ends what is left of a job whose lease expired (its job process and pool workers). Before,
it sent SIGKILL to the process group named by the lease's pid: with that pid reused by an unrelated process
group leader, that process was killed. Now only processes whose environment carries the run's token
(``dispatch.RUN_TOKEN``) are signalled.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from flexopt.service.jobs.dispatch import RUN_TOKEN, Dispatcher
from flexopt.service.jobs.store import HOST, MAX_CRASHES, JobStore

pytestmark = pytest.mark.skipif(
    not Path("/proc/self/environ").exists() or not hasattr(os, "pidfd_open"),
    reason="identity is proven from /proc and pidfds (Linux)",
)

SPEC = {"families": [{"template": "leaf-spring", "design": {"thickness": [3e-4, 6e-4]}}], "starts": 1}
# a process-group leader with one child in its group, both sleeping
_GROUP = (
    "import subprocess, sys, time; subprocess.Popen([sys.executable, '-c', 'import time; time.sleep(60)']); "
    "print('ready', flush=True); time.sleep(60)"
)


def _expired_job(tmp_path: Path, pid: int) -> tuple[JobStore, str]:
    """A running job (attempt 1) whose lease, held by ``pid`` on this host, has run out."""
    store = JobStore(f"sqlite:///{tmp_path / 'jobs.sqlite'}", tmp_path, lease_seconds=0.2)
    job, _ = store.submit(SPEC, None)
    store.next_queued("dispatcher")
    assert store.heartbeat(job["id"], 1, f"{HOST}:{pid}:job")
    time.sleep(0.3)
    return store, job["id"]


def _group(env: dict | None = None) -> tuple[subprocess.Popen, list[int]]:
    p = subprocess.Popen(
        [sys.executable, "-c", _GROUP], start_new_session=True, env=env, stdout=subprocess.PIPE, text=True
    )
    assert p.stdout is not None
    ready = p.stdout.readline().strip()
    p.stdout.close()
    assert ready == "ready"
    members = [
        int(d)
        for d in os.listdir("/proc")
        if d.isdigit() and os.path.exists(f"/proc/{d}/stat") and _pgid(int(d)) == p.pid
    ]
    return p, members


def _pgid(pid: int) -> int | None:
    try:
        return os.getpgid(pid)
    except ProcessLookupError:
        return None


def _alive(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat[stat.rindex(")") + 2] != "Z"  # a killed child not yet reaped is a zombie


def test_stale_lease_never_signals_an_unrelated_process(tmp_path: Path) -> None:
    """The lease's pid now leads an unrelated process group: it and its child live on, and the job is
    requeued (it failed before: both killed by signal 9)."""
    stranger, members = _group()
    try:
        store, jid = _expired_job(tmp_path, stranger.pid)
        Dispatcher(store, max_jobs=0, workers=1)._tick()  # max_jobs 0: requeue only, start nothing
        assert store.get(jid)["status"] == "queued"
        time.sleep(0.2)
        assert len(members) == 2 and all(_alive(m) for m in members), "an unrelated process was signalled"
    finally:
        os.killpg(stranger.pid, 9)
        stranger.wait()


def test_stale_lease_ends_the_processes_of_its_own_run(tmp_path: Path) -> None:
    """The job process (and its pool worker) of the expired run carry its token: both are ended; a process of
    another run of the same job (another attempt's token) is not."""
    store = JobStore(f"sqlite:///{tmp_path / 'jobs.sqlite'}", tmp_path, lease_seconds=0.2)
    job, _ = store.submit(SPEC, None)
    ours, members = _group(dict(os.environ, **{RUN_TOKEN: f"{job['id']}:1"}))
    other, others = _group(dict(os.environ, **{RUN_TOKEN: f"{job['id']}:2"}))
    try:
        store.next_queued("dispatcher")
        assert store.heartbeat(job["id"], 1, f"{HOST}:{ours.pid}:job")
        time.sleep(0.3)
        Dispatcher(store, max_jobs=0, workers=1)._tick()
        ours.wait(5)
        deadline = time.monotonic() + 5
        while any(_alive(m) for m in members) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not any(_alive(m) for m in members), "the run's pool worker outlived it"
        assert ours.returncode == -9 and store.get(job["id"])["status"] == "queued"
        assert all(_alive(m) for m in others)
    finally:
        for p in (ours, other):
            try:
                os.killpg(p.pid, 9)
            except ProcessLookupError:
                pass
            p.wait()


def test_stopping_server_requeues_its_job_without_counting_a_crash(tmp_path: Path) -> None:
    """Issue 29 item 5: each graceful stop (SIGTERM to the run, then requeued) leaves the job queued with no
    crash counted, however many there are (it failed before: failed at the third stop)."""
    store = JobStore(f"sqlite:///{tmp_path / 'jobs.sqlite'}", tmp_path, lease_seconds=5)
    job, _ = store.submit(SPEC, None)
    for attempt in range(1, MAX_CRASHES + 2):
        assert store.next_queued("dispatcher")["attempts"] == attempt
        run, _ = _group(dict(os.environ, **{RUN_TOKEN: f"{job['id']}:{attempt}"}))
        d = Dispatcher(store, max_jobs=0, workers=1, stop_timeout=5)
        d.procs[job["id"]] = (run, attempt)
        d.start()
        d.stop()  # SIGTERM to the run (the sleeping stand-in ends on it), then requeued
        assert run.returncode == -15
        assert store.get(job["id"])["status"] == "queued"
        assert store.row(job["id"])["lease_holder"] is None
