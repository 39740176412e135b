"""Optimisation jobs that are never lost: a SQLAlchemy store and a dispatcher of job processes.

Store: one ``jobs`` table (SQLite file by default, any SQLAlchemy URL such as PostgreSQL through
``FLEXOPT_DATABASE_URL``). Each job runs ``optim.search`` in its own OS process (``python -m
service.jobs run ID``), never in the server's event loop; that process writes progress to the store as
cases finish, and keeps every finished case in the job's directory (``optim.batch`` store), so a job that
is started again resumes without redoing finished cases.

Life cycle: ``queued -> running -> succeeded | failed | cancelled``. At start-up the dispatcher puts every
job left ``running`` by a stopped server back in the queue (it resumes from its case store) or, after
``MAX_ATTEMPTS`` interrupted runs, marks it failed with that reason: no job stays ``running`` forever.
Cancellation is cooperative: the job process watches its row and stops the batch when it reads
``cancelling``. An ``Idempotency-Key`` is unique: a retried submission returns the first job.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
import uuid
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from sqlalchemy import Integer, String, Text, create_engine, func, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import DeclarativeBase, Mapped, Session, mapped_column

__all__ = ["Job", "JobStore", "Dispatcher", "MAX_ATTEMPTS"]

#: Runs of a job interrupted by a stopped server before it is marked failed.
MAX_ATTEMPTS = 3
ACTIVE = ("queued", "running", "cancelling")


class _Base(DeclarativeBase):
    pass


class Job(_Base):
    """One optimisation job."""

    __tablename__ = "jobs"
    id: Mapped[str] = mapped_column(String(36), primary_key=True)
    status: Mapped[str] = mapped_column(String(16), index=True)
    spec: Mapped[str] = mapped_column(Text)
    idempotency_key: Mapped[str | None] = mapped_column(String(200), unique=True, nullable=True)
    progress: Mapped[str] = mapped_column(Text, default="{}")
    partial: Mapped[str] = mapped_column(Text, default="[]")  # finished cases so far (summaries)
    result: Mapped[str | None] = mapped_column(Text, nullable=True)
    error: Mapped[str | None] = mapped_column(Text, nullable=True)
    attempts: Mapped[int] = mapped_column(Integer, default=0)
    created: Mapped[str] = mapped_column(String(40))
    updated: Mapped[str] = mapped_column(String(40))

    def to_dict(self) -> dict[str, Any]:
        return {"id": self.id, "status": self.status, "progress": json.loads(self.progress or "{}"),
                "partial": json.loads(self.partial or "[]"),
                "result": json.loads(self.result) if self.result else None, "error": self.error,
                "attempts": self.attempts, "created": self.created, "updated": self.updated}


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")


class JobStore:
    """The job table behind a SQLAlchemy engine."""

    def __init__(self, url: str, data_dir: Path) -> None:
        self.url, self.data_dir = url, Path(data_dir)
        self.data_dir.mkdir(parents=True, exist_ok=True)
        args = {"check_same_thread": False, "timeout": 30} if url.startswith("sqlite") else {}
        self.engine = create_engine(url, connect_args=args)
        _Base.metadata.create_all(self.engine)

    def case_dir(self, job_id: str) -> Path:
        return self.data_dir / "jobs" / job_id

    def submit(self, spec: dict, idempotency_key: str | None) -> tuple[dict, bool]:
        """Store a new queued job; with a known idempotency key return that job instead. (job, created)"""
        with Session(self.engine) as s:
            if idempotency_key:
                old = s.scalar(select(Job).where(Job.idempotency_key == idempotency_key))
                if old is not None:
                    return old.to_dict(), False
            now = _now()
            job = Job(id=str(uuid.uuid4()), status="queued", spec=json.dumps(spec), idempotency_key=idempotency_key,
                      progress="{}", partial="[]", attempts=0, created=now, updated=now)
            s.add(job)
            try:
                s.commit()
            except IntegrityError:  # a concurrent retry with the same key won the race
                s.rollback()
                old = s.scalar(select(Job).where(Job.idempotency_key == idempotency_key))
                assert old is not None
                return old.to_dict(), False
            return job.to_dict(), True

    def get(self, job_id: str) -> dict | None:
        with Session(self.engine) as s:
            job = s.get(Job, job_id)
            return job.to_dict() if job is not None else None

    def page(self, offset: int, limit: int) -> tuple[list[dict], int]:
        with Session(self.engine) as s:
            total = s.scalar(select(func.count()).select_from(Job)) or 0
            rows = s.scalars(select(Job).order_by(Job.created.desc(), Job.id).offset(offset).limit(limit)).all()
            return [r.to_dict() for r in rows], int(total)

    def update(self, job_id: str, **fields: Any) -> dict | None:
        with Session(self.engine) as s:
            job = s.get(Job, job_id)
            if job is None:
                return None
            for k, v in fields.items():
                setattr(job, k, v)
            job.updated = _now()
            s.commit()
            return job.to_dict()

    def cancel(self, job_id: str) -> dict | None:
        """Queued jobs are cancelled at once; running ones are asked to stop (``cancelling``)."""
        with Session(self.engine) as s:
            job = s.get(Job, job_id)
            if job is None:
                return None
            if job.status == "queued":
                job.status = "cancelled"
            elif job.status == "running":
                job.status = "cancelling"
            job.updated = _now()
            s.commit()
            return job.to_dict()

    def next_queued(self) -> dict | None:
        """Claim the oldest queued job (mark it running)."""
        with Session(self.engine) as s:
            job = s.scalar(select(Job).where(Job.status == "queued").order_by(Job.created, Job.id).limit(1))
            if job is None:
                return None
            job.status, job.attempts, job.updated = "running", job.attempts + 1, _now()
            s.commit()
            return job.to_dict()

    def recover(self) -> list[str]:
        """Jobs left running (or cancelling) by a stopped server: back to the queue, or failed/cancelled."""
        touched = []
        with Session(self.engine) as s:
            for job in s.scalars(select(Job).where(Job.status.in_(("running", "cancelling")))).all():
                if job.status == "cancelling":
                    job.status = "cancelled"
                elif job.attempts >= MAX_ATTEMPTS:
                    job.status = "failed"
                    job.error = (f"interrupted {job.attempts} times by a stopped server; resubmit it (finished cases "
                                 "are kept and will not be recomputed)")
                else:
                    job.status = "queued"
                job.updated = _now()
                touched.append(job.id)
            s.commit()
        return touched


class Dispatcher:
    """Runs queued jobs, at most ``max_jobs`` at a time, each in its own process."""

    def __init__(self, store: JobStore, max_jobs: int, workers: int | None) -> None:
        self.store, self.max_jobs, self.workers = store, max_jobs, workers
        self.procs: dict[str, subprocess.Popen] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="flexopt-jobs", daemon=True)

    def start(self) -> None:
        self.store.recover()
        self._thread.start()

    def stop(self) -> None:
        """Stop dispatching and terminate running job processes: their jobs resume at the next start."""
        self._stop.set()
        self._thread.join(5)
        for p in self.procs.values():
            p.terminate()
        for p in self.procs.values():
            try:  # the job finishes the cases in progress (a few seconds each), then exits
                p.wait(30)
            except subprocess.TimeoutExpired:
                p.kill()
        self.procs.clear()

    def _loop(self) -> None:
        while not self._stop.is_set():
            for jid, p in list(self.procs.items()):
                if p.poll() is not None:
                    del self.procs[jid]
                    job = self.store.get(jid)
                    if job is not None and job["status"] == "cancelling":
                        self.store.update(jid, status="cancelled")
                    elif job is not None and job["status"] in ACTIVE:  # the process died without a verdict
                        self.store.update(jid, status="failed",
                                          error=f"the job process ended unexpectedly (exit code {p.returncode})")
            while len(self.procs) < self.max_jobs and not self._stop.is_set():
                job = self.store.next_queued()
                if job is None:
                    break
                env = dict(os.environ, FLEXOPT_DATABASE_URL=self.store.url, FLEXOPT_DATA_DIR=str(self.store.data_dir))
                if self.workers:
                    env["FLEXOPT_JOB_WORKERS"] = str(self.workers)
                self.procs[job["id"]] = subprocess.Popen([sys.executable, "-m", "flexopt.service.jobs", "run", job["id"]],
                                                         env=env)
            self._stop.wait(0.2)


def _summary(case: dict) -> dict:
    v = case.get("verified", {})
    return {"id": case.get("id"), "family": case.get("family"), "start": case.get("start"),
            "status": case.get("status", "failed" if "error" in case else None),
            "worst_hz": v.get("worst_hz"), "ratio": v.get("ratio"), "design": case.get("design"),
            "error": case.get("error")}


def run_job(job_id: str) -> int:
    """Body of a job process: run the optimisation, writing progress and the result to the store."""
    from ..optim import optimise
    from ..optim.batch import BatchCancelled

    store = JobStore(os.environ["FLEXOPT_DATABASE_URL"], Path(os.environ["FLEXOPT_DATA_DIR"]))
    job = store.get(job_id)
    if job is not None and job["status"] == "cancelling":  # cancelled before this process started
        store.update(job_id, status="cancelled")
    if job is None or job["status"] != "running":
        return 0
    spec = json.loads(_spec(store, job_id))
    cancel = threading.Event()
    partial: list[dict] = []
    case_dir = store.case_dir(job_id)

    def watch() -> None:
        while not cancel.is_set():
            j = store.get(job_id)
            if j is None or j["status"] == "cancelling":
                cancel.set()
            time.sleep(0.3)

    def progress(event: dict) -> None:
        path = case_dir / f"{event['id']}.json"
        try:
            partial.append(_summary(json.loads(path.read_text())))
        except (OSError, json.JSONDecodeError):
            pass
        store.update(job_id, progress=json.dumps({"done": event["done"], "total": event["total"]}),
                     partial=json.dumps(partial))

    # a stopping server sends SIGTERM: stop the batch cleanly (the worker pool shuts down with this process
    # instead of being orphaned) and leave the job 'running', so that the next start requeues and resumes it
    interrupted = threading.Event()

    def on_term(signum: int, frame: Any) -> None:
        interrupted.set()
        cancel.set()

    signal.signal(signal.SIGTERM, on_term)
    threading.Thread(target=watch, daemon=True).start()
    workers = int(os.environ["FLEXOPT_JOB_WORKERS"]) if os.environ.get("FLEXOPT_JOB_WORKERS") else None
    try:
        result = optimise(spec, workers=workers, store=case_dir, progress=progress, cancel=cancel)
    except BatchCancelled:
        if not interrupted.is_set():
            store.update(job_id, status="cancelled")
        return 0
    except Exception as exc:  # noqa: BLE001 - any failure is recorded on the job with its message
        store.update(job_id, status="failed", error=f"{type(exc).__name__}: {exc}")
        return 1
    finally:
        cancel.set()
    store.update(job_id, status="succeeded", result=json.dumps(_finite(result)))
    return 0


def _spec(store: JobStore, job_id: str) -> str:
    with Session(store.engine) as s:
        job = s.get(Job, job_id)
        assert job is not None
        return job.spec


def _finite(obj: Any) -> Any:
    """JSON-safe: non-finite floats become null (the wire format has no NaN)."""
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_finite(v) for v in obj]
    if isinstance(obj, float) and obj != obj or obj in (float("inf"), float("-inf")):
        return None
    return obj


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "run":
        sys.exit(run_job(sys.argv[2]))
    print("usage: python -m flexopt.service.jobs run JOB_ID", file=sys.stderr)
    sys.exit(2)
