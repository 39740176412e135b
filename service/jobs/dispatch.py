"""The job dispatcher: runs queued jobs in their own process groups, retries lost runs, survives the database.

One thread per server. Each tick it (1) collects job processes that ended: a run that ended without a
verdict (killed, out of memory, a pool worker lost) is requeued, and after ``MAX_CRASHES`` such crashes failed
with its reason (a run stopped by a stopping server is requeued and never counted); the rest of the process group (the pool workers) is killed with it; (2) requeues jobs whose
lease expired (a job process of a server that was killed and whose process then died too); (3) starts
queued jobs up to ``max_jobs``. A database error in a tick is logged and the tick retried with exponential
backoff (0.5 s doubling to 30 s): the thread never dies of it, and ``healthy()`` reports it for ``/ready``.

Job processes are started in their own session (``start_new_session``), so a job process and its pool
workers form one process group that can be ended together; a stopping server sends SIGTERM to each group,
waits ``stop_timeout`` seconds for the job to store its cases in progress, then SIGKILLs what is left. Only
processes that carry the run's token (:data:`RUN_TOKEN`) in their environment are ever signalled
(:func:`end_run`).
Lifecycle events (``job.started``, ``job.ended``, ``job.requeued``, ``job.failed``) are logged as JSON fields.
"""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

from .store import HOST, JobStore, StoreUnavailable

__all__ = ["RUN_TOKEN", "Dispatcher", "end_run"]

log = logging.getLogger("flexopt.service.jobs")


#: The environment variable that marks every process of one job run: ``"<job id>:<attempt>"``, set on the job
#: process and inherited by its pool workers (spawn and forkserver copy the environment). A process is
#: signalled only if its environment carries the run's token: a pid alone proves nothing once the process
#: is gone (issue 29 item 6: a restarted server killed an unrelated process-group leader that had taken
#: the pid of a stale lease).
RUN_TOKEN = "FLEXOPT_JOB_RUN"


def _pgid(pid: int) -> int | None:
    """The process group of ``pid`` from ``/proc/<pid>/stat`` (field 5, after the parenthesised name)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return int(stat[stat.rindex(")") + 2 :].split()[2])


def _token(pid: int) -> str | None:
    """The run token in the environment of ``pid`` (readable only for our own user's processes), or None."""
    try:
        env = Path(f"/proc/{pid}/environ").read_bytes()
    except OSError:
        return None
    prefix = f"{RUN_TOKEN}=".encode()
    return next((v[len(prefix) :].decode(errors="replace") for v in env.split(b"\0") if v.startswith(prefix)), None)


def end_run(pgid: int, token: str, sig: int = signal.SIGKILL) -> int:
    """Signal the processes of group ``pgid`` (a job process and its pool workers) that prove to be the run
    ``token``; how many were signalled.

    Each candidate is pinned with a pidfd before its environment is read, so the signal reaches the process
    that was checked even if it dies and its pid is reused in between. Where this cannot be proven (no
    ``/proc``, no pidfd, another user's process), nothing is signalled.
    """
    if not hasattr(os, "pidfd_open") or not Path("/proc/self/environ").exists():  # pragma: no cover - not Linux
        return 0
    sent = 0
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit() or _pgid(pid := int(entry.name)) != pgid:
            continue
        try:
            fd = os.pidfd_open(pid)
        except OSError:  # gone already
            continue
        try:
            if _token(pid) == token:
                signal.pidfd_send_signal(fd, sig)
                sent += 1
        except OSError:
            pass
        finally:
            os.close(fd)
    return sent


class Dispatcher:
    """Runs queued jobs, at most ``max_jobs`` at a time, each in its own process group."""

    def __init__(self, store: JobStore, max_jobs: int, workers: int | None, stop_timeout: float = 5.0) -> None:
        self.store, self.max_jobs, self.workers, self.stop_timeout = store, max_jobs, workers, stop_timeout
        self.procs: dict[str, tuple[subprocess.Popen, int]] = {}  # job id -> (its process, attempt)
        self.holder = f"{HOST}:{os.getpid()}"
        self.last_error: str | None = None  # the last tick's database error (None: the last tick was fine)
        self.last_tick = 0.0  # time.monotonic() of the last completed tick
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="flexopt-jobs", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def healthy(self) -> str | None:
        """None when dispatching works; otherwise why not (for ``/ready``)."""
        if not self._thread.is_alive():
            return "the job dispatcher thread is not running"
        if self.last_error is not None:
            return f"the job dispatcher cannot reach the job store: {self.last_error}"
        return None

    def stop(self) -> None:
        """Stop dispatching and the job processes: their jobs are requeued and resume at the next start."""
        self._stop.set()
        self._thread.join(5)
        for jid, (p, attempt) in self.procs.items():
            end_run(p.pid, f"{jid}:{attempt}", signal.SIGTERM)
        deadline = time.monotonic() + self.stop_timeout
        for jid, (p, attempt) in self.procs.items():
            try:  # the job stops its batch (cases in progress end or are dropped), then exits
                p.wait(max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
            end_run(p.pid, f"{jid}:{attempt}")
            try:
                self.store.requeue(jid, attempt, "interrupted by a stopping server", crash=False)
            except StoreUnavailable:  # recovered from the expired lease at the next start
                pass
        self.procs.clear()

    def _loop(self) -> None:
        backoff = 0.5
        while not self._stop.is_set():
            try:
                self._tick()
            except Exception as exc:  # noqa: BLE001 - a busy or unreachable database: log, back off, retry
                self.last_error = str(exc).splitlines()[0][:300] if str(exc) else type(exc).__name__
                log.warning(
                    "job dispatcher: %s; retrying in %.1f s",
                    self.last_error,
                    backoff,
                    extra={"event": "dispatcher.error"},
                )
                self._stop.wait(backoff)
                backoff = min(30.0, backoff * 2)
                continue
            self.last_error, self.last_tick, backoff = None, time.monotonic(), 0.5
            self._stop.wait(0.2)

    def _tick(self) -> None:
        for jid, (p, attempt) in list(self.procs.items()):
            code = p.poll()
            if code is None:
                if not self._started(jid):  # until the job process beats, the dispatcher holds its lease
                    self.store.heartbeat(jid, attempt, self.holder)
                continue
            end_run(p.pid, f"{jid}:{attempt}")  # a job process killed outright leaves its worker pool behind
            new = self.store.requeue(jid, attempt, f"the job process ended without a result (exit code {code})")
            del self.procs[jid]
            if new is None:  # the job process wrote its verdict
                job = self.store.get(jid) or {}
                level = logging.WARNING if job.get("status") == "failed" else logging.INFO
                log.log(
                    level,
                    "job ended",
                    extra={
                        "event": f"job.{job.get('status', 'ended')}",
                        "job_id": jid,
                        "attempt": attempt,
                        "exit_code": code,
                        "error": job.get("error"),
                    },
                )
            else:
                log.warning(
                    "job run lost",
                    extra={
                        "event": f"job.{'requeued' if new == 'queued' else new}",
                        "job_id": jid,
                        "attempt": attempt,
                        "exit_code": code,
                    },
                )
        for job in self.store.expired():
            if job["id"] in self.procs:
                continue
            host, _, rest = (job["lease_holder"] or "").partition(":")
            pid, _, kind = rest.partition(":")
            if host == HOST and kind == "job" and pid.isdigit():  # its job process is gone, its pool may not be:
                end_run(int(pid), f"{job['id']}:{job['attempts']}")  # only processes proven to be that run
            new = self.store.requeue(job["id"], job["attempts"], "the job's lease expired (its process is gone)")
            if new is not None:
                log.warning(
                    "job lease expired",
                    extra={
                        "event": f"job.{'requeued' if new == 'queued' else new}",
                        "job_id": job["id"],
                        "attempt": job["attempts"],
                    },
                )
        while len(self.procs) < self.max_jobs and not self._stop.is_set():
            queued = self.store.next_queued(self.holder)
            if queued is None:
                break
            job = queued
            env: dict[str, Any] = dict(
                os.environ,
                **{RUN_TOKEN: f"{job['id']}:{job['attempts']}"},
                FLEXOPT_DATABASE_URL=self.store.url,
                FLEXOPT_DATA_DIR=str(self.store.data_dir),
                FLEXOPT_LEASE_SECONDS=str(self.store.lease_seconds),
            )
            if self.workers:
                env["FLEXOPT_JOB_WORKERS"] = str(self.workers)
            p = subprocess.Popen(
                [sys.executable, "-m", "flexopt.service.jobs", "run", job["id"], str(job["attempts"])],
                env=env,
                start_new_session=True,
            )
            self.procs[job["id"]] = (p, job["attempts"])
            log.info(
                "job started",
                extra={"event": "job.started", "job_id": job["id"], "attempt": job["attempts"], "pid": p.pid},
            )

    def _started(self, jid: str) -> bool:
        """Whether the job process has taken the lease over (until then the dispatcher keeps it alive)."""
        row = self.store.row(jid)
        return row is not None and row["lease_holder"] not in (None, self.holder)
