"""The job store: one ``jobs`` table behind SQLAlchemy (a SQLite file by default, PostgreSQL by URL).

Every state change is a conditional ``UPDATE ... WHERE`` so that a cancellation, the dispatcher claiming a
job and a job process writing its verdict can never overwrite each other. Three ideas carry the rest:

- **Owner.** A job belongs to the API key that submitted it (``owner``: a SHA-256 prefix of the key, ``""``
  when the server has no keys); every read, list, cancel and delete is filtered by it. The
  ``Idempotency-Key`` is stored prefixed by the owner, so keys of different clients never meet, and a key
  reused with a different problem raises :class:`KeyReused`.
- **Lease and fencing token.** A run of a job holds a lease: ``lease_holder`` (``host:pid``) and
  ``lease_until`` (epoch seconds), renewed by the job process's heartbeat. ``attempts`` numbers the runs and
  is the fencing token: a job process writes only while the row still carries its number, so a process
  left over from an earlier run can never overwrite a newer one. A (restarted) server requeues only jobs
  whose lease has expired; a job whose lease is alive is left to the process that holds it.
- **Unavailable store.** Any database error is raised as :class:`StoreUnavailable` (503 at the HTTP
  layer), a file that is not a database as :class:`StoreCorrupt` (refused at start with one line).
"""

from __future__ import annotations

import functools
import hashlib
import json
import shutil
import socket
import time
import uuid
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, TypeVar

from sqlalchemy import Float, Integer, String, Text, create_engine, event, func, inspect, select, text
from sqlalchemy import delete as sql_delete
from sqlalchemy import update as sql_update
from sqlalchemy.exc import DatabaseError, IntegrityError, SQLAlchemyError
from sqlalchemy.orm import DeclarativeBase, Mapped, Session, mapped_column

__all__ = [
    "ACTIVE",
    "MAX_ATTEMPTS",
    "JOB_AGING",
    "MAX_CRASHES",
    "STATUSES",
    "Job",
    "JobStore",
    "KeyReused",
    "StoreCorrupt",
    "StoreUnavailable",
    "TooManyJobs",
    "owner_of",
]

#: Crashed runs of a job (its job process or a pool worker killed, out of memory, its lease expired) before
#: it is failed: the stated policy, named in the job's error. A run interrupted by a graceful server stop
#: (SIGTERM, a rolling deploy) is not counted: such a job resumes from its finished cases however often the
#: server restarts (issue 29 item 5: three SIGTERMs during one long job failed it).
MAX_CRASHES = 3
MAX_ATTEMPTS = MAX_CRASHES  # the former name
ACTIVE = ("queued", "running", "cancelling")
FINISHED = ("succeeded", "failed", "cancelled")
STATUSES = (*ACTIVE, *FINISHED)
HOST = socket.gethostname()

T = TypeVar("T")


class StoreUnavailable(Exception):
    """The job database cannot be reached or is locked; the request can be retried later (HTTP 503)."""

    def __init__(self, cause: BaseException) -> None:
        first = str(cause).strip().splitlines()[0] if str(cause).strip() else type(cause).__name__
        super().__init__(f"the job store is unavailable ({first[:200]}); retry in a few seconds")


class StoreCorrupt(Exception):
    """The job database file exists but is not a readable database."""


class TooManyJobs(Exception):
    """The owner already has the allowed number of unfinished jobs (HTTP 429)."""


class KeyReused(Exception):
    """An ``Idempotency-Key`` already names a job of this owner with a different problem."""

    def __init__(self, key: str, job_id: str) -> None:
        super().__init__(
            f"Idempotency-Key '{key}' was already used for job {job_id} with a different problem; "
            "use a new key for a new problem"
        )
        self.job_id = job_id


def owner_of(api_key: str | None) -> str:
    """The owner recorded on a job: a SHA-256 prefix of the API key (never the key itself), ``""`` for none."""
    return hashlib.sha256(api_key.encode()).hexdigest()[:16] if api_key else ""


def _guarded(fn: Callable[..., T]) -> Callable[..., T]:
    """Database errors (locked, unreachable, broken) leave the store as :class:`StoreUnavailable`."""

    @functools.wraps(fn)
    def call(*args: Any, **kwargs: Any) -> T:
        try:
            return fn(*args, **kwargs)
        except (KeyReused, StoreUnavailable, TooManyJobs):
            raise
        except SQLAlchemyError as exc:
            raise StoreUnavailable(getattr(exc, "orig", None) or exc) from exc

    return call


class _Base(DeclarativeBase):
    pass


class Job(_Base):
    """One optimisation job."""

    __tablename__ = "jobs"
    id: Mapped[str] = mapped_column(String(36), primary_key=True)
    status: Mapped[str] = mapped_column(String(16), index=True)
    spec: Mapped[str] = mapped_column(Text)
    idempotency_key: Mapped[str | None] = mapped_column(String(300), unique=True, nullable=True)
    progress: Mapped[str] = mapped_column(Text, default="{}")
    partial: Mapped[str] = mapped_column(Text, default="[]")  # finished cases so far (summaries)
    result: Mapped[str | None] = mapped_column(Text, nullable=True)
    error: Mapped[str | None] = mapped_column(Text, nullable=True)
    attempts: Mapped[int] = mapped_column(Integer, default=0)  # runs started; the fencing token
    created: Mapped[str] = mapped_column(String(40))
    updated: Mapped[str] = mapped_column(String(40))
    owner: Mapped[str] = mapped_column(String(64), default="", index=True)
    lease_holder: Mapped[str | None] = mapped_column(String(300), nullable=True)  # host:pid of the run
    lease_until: Mapped[float | None] = mapped_column(Float, nullable=True)  # epoch seconds
    crashes: Mapped[int] = mapped_column(Integer, default=0)  # runs that crashed (graceful stops not counted)
    started: Mapped[float | None] = mapped_column(Float, nullable=True)  # epoch seconds of the latest claim
    estimate: Mapped[str | None] = mapped_column(Text, nullable=True)  # the cost estimate at submission (JSON)
    cost: Mapped[float | None] = mapped_column(Float, nullable=True)  # its seconds (the queue's order in a key)

    def to_dict(self) -> dict[str, Any]:
        kind = next((k for k in KINDS if f'"kind": "{k}"' in (self.spec or "")), "optimisation")
        return {
            "id": self.id,
            "kind": kind,
            "status": self.status,
            "progress": json.loads(self.progress or "{}"),
            "partial": json.loads(self.partial or "[]"),
            "result": json.loads(self.result) if self.result else None,
            "error": self.error,
            "attempts": self.attempts,
            "created": self.created,
            "updated": self.updated,
            "estimate": json.loads(self.estimate) if self.estimate else None,
        }


#: kinds of job besides an optimisation, marked by a ``"kind"`` key in the stored spec
KINDS = ("frequency-curve", "topology-search", "pareto-front")

# columns added after the first release: added to an older database at start (all nullable or defaulted)
_ADDED = {
    "owner": "VARCHAR(64) NOT NULL DEFAULT ''",
    "lease_holder": "VARCHAR(300)",
    "lease_until": "FLOAT",
    "crashes": "INTEGER NOT NULL DEFAULT 0",
    "started": "FLOAT",
    "estimate": "TEXT",
    "cost": "FLOAT",
}

#: Seconds of estimate a queued job sheds for each second it has waited (the queue's order within one key:
#: smallest ``cost - JOB_AGING x waited`` first): a small job overtakes a large one of the same key, and a
#: job of estimate E is overtaken by newer jobs for at most E / JOB_AGING seconds, so none starves.
JOB_AGING = 10.0


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")


def _sqlite_pragmas(conn: Any, record: Any) -> None:
    cur = conn.cursor()
    cur.execute("PRAGMA journal_mode=WAL")  # server, dispatcher and job processes share the file
    cur.execute("PRAGMA busy_timeout=5000")
    cur.close()


class JobStore:
    """The job table behind a SQLAlchemy engine; ``data_dir`` holds the shared case store."""

    def __init__(self, url: str, data_dir: Path, lease_seconds: float = 15.0) -> None:
        self.url, self.data_dir, self.lease_seconds = url, Path(data_dir), lease_seconds
        self.data_dir.mkdir(parents=True, exist_ok=True)
        sqlite = url.startswith("sqlite")
        self.engine = create_engine(
            url, connect_args={"check_same_thread": False, "timeout": 5} if sqlite else {}, pool_pre_ping=not sqlite
        )
        if sqlite:
            event.listen(self.engine, "connect", _sqlite_pragmas)
        try:
            _Base.metadata.create_all(self.engine)
            self._add_columns()
            self._file = self._identity()  # the SQLite file opened: ping() checks it is still the one in place
        except DatabaseError as exc:
            where = url.removeprefix("sqlite:///") if sqlite else url.split("@")[-1]
            if sqlite and "not a database" in str(exc) or "malformed" in str(exc):
                raise StoreCorrupt(
                    f"the job store {where} is not a readable database ({str(exc.orig)[:80]}); "
                    "move it aside (jobs are lost, finished cases in cases/ are kept) or restore "
                    "a backup, then start again"
                ) from None
            raise StoreCorrupt(
                f"the job store {where} cannot be opened ({str(getattr(exc, 'orig', exc))[:120]});"
                " check FLEXOPT_DATABASE_URL and that the database is running"
            ) from None

    def _add_columns(self) -> None:
        have = {c["name"] for c in inspect(self.engine).get_columns("jobs")}
        with self.engine.begin() as conn:
            for name, ddl in _ADDED.items():
                if name not in have:
                    conn.execute(text(f"ALTER TABLE jobs ADD COLUMN {name} {ddl}"))

    # -- where a job's files are ------------------------------------------------------------------------------
    def case_dir(self) -> Path:
        """The case store shared by all jobs: one file per case, named by the case's content (its id)."""
        return self.data_dir / "cases"

    def job_dir(self, job_id: str) -> Path:
        """Files of one job (none today besides the database row; removed with the job)."""
        return self.data_dir / "jobs" / job_id

    # -- reads and writes -------------------------------------------------------------------------------------
    def _identity(self) -> tuple[int, int] | None:
        """(device, inode) of the SQLite file, or None (not SQLite, or no file)."""
        if not self.url.startswith("sqlite:///"):
            return None
        try:
            st = Path(self.url.removeprefix("sqlite:///")).stat()
        except OSError:
            return None
        return st.st_dev, st.st_ino

    def _same_file(self) -> None:
        """:class:`StoreUnavailable` when the SQLite file opened at start is no longer the one in place."""
        if self.url.startswith("sqlite:///") and self._identity() != self._file:
            raise StoreUnavailable(
                OSError(
                    f"the database file {self.url.removeprefix('sqlite:///')} was deleted "
                    "or replaced under the running server; restore it and restart the "
                    "server"
                )
            )

    @_guarded
    def ping(self) -> None:
        """Raise :class:`StoreUnavailable` unless the store can be written: a write transaction begins (SQLite:
        readers go on while another process holds the write lock, so a read proves nothing) or a query
        answers (a server database). A SQLite file deleted or replaced under the running server is
        unavailable too: the server would go on writing to the deleted file while its job processes open a
        new one (issue 29 item 8: /ready said 200 and every later job failed after three lost runs)."""
        self._same_file()
        with self.engine.connect() as conn:
            if self.url.startswith("sqlite"):
                conn.exec_driver_sql("BEGIN IMMEDIATE")
                conn.exec_driver_sql("ROLLBACK")
            else:
                conn.execute(select(func.count()).select_from(Job).where(Job.id == ""))

    @_guarded
    def submit(
        self,
        spec: dict,
        idempotency_key: str | None,
        owner: str = "",
        max_active: int | None = None,
        estimate: dict | None = None,
    ) -> tuple[dict, bool]:
        """Store a new queued job (with its cost ``estimate``, whose ``seconds`` order the owner's queue); with a
        known idempotency key (of this owner) return that job instead.

        Returns ``(job, created)``. Raises :class:`KeyReused` when the key names a job with a different spec,
        and :class:`TooManyJobs` when the owner already has ``max_active`` unfinished jobs.
        """
        self._same_file()  # a job stored in a deleted file would be lost
        scoped = f"{owner}/{idempotency_key}" if idempotency_key else None

        def same(old: Job) -> tuple[dict, bool]:
            if json.loads(old.spec) != spec:
                raise KeyReused(str(idempotency_key), old.id)
            return old.to_dict(), False

        with Session(self.engine) as s:
            if scoped:
                old = s.scalar(select(Job).where(Job.idempotency_key == scoped))
                if old is not None:
                    return same(old)
            if max_active is not None:
                n = (
                    s.scalar(select(func.count()).select_from(Job).where(Job.owner == owner, Job.status.in_(ACTIVE)))
                    or 0
                )
                if n >= max_active:
                    raise TooManyJobs(
                        f"{n} jobs of this API key are queued or running (limit {max_active}); "
                        "wait for one to finish or cancel one"
                    )
            now = _now()
            job = Job(
                id=str(uuid.uuid4()),
                status="queued",
                spec=json.dumps(spec),
                idempotency_key=scoped,
                progress="{}",
                partial="[]",
                attempts=0,
                created=now,
                updated=now,
                owner=owner,
                estimate=json.dumps(estimate) if estimate is not None else None,
                cost=float(estimate["seconds"]) if estimate is not None else None,
            )
            s.add(job)
            try:
                s.commit()
            except IntegrityError:  # a concurrent retry with the same key won the race
                s.rollback()
                old = s.scalar(select(Job).where(Job.idempotency_key == scoped))
                if old is None:  # pragma: no cover - not a key clash: a real integrity problem
                    raise
                return same(old)
            return job.to_dict(), True

    @_guarded
    def get(self, job_id: str, owner: str | None = None) -> dict | None:
        """The job (only if it belongs to ``owner``, when given), or None."""
        with Session(self.engine) as s:
            job = s.get(Job, job_id)
            if job is None or (owner is not None and job.owner != owner):
                return None
            return job.to_dict()

    @_guarded
    def row(self, job_id: str) -> dict | None:
        """The job with its spec and lease (for the dispatcher and the job process)."""
        with Session(self.engine) as s:
            job = s.get(Job, job_id)
            if job is None:
                return None
            return {
                **job.to_dict(),
                "spec": job.spec,
                "owner": job.owner,
                "lease_holder": job.lease_holder,
                "lease_until": job.lease_until,
            }

    @_guarded
    def page(
        self, offset: int, limit: int, owner: str | None = None, status: str | None = None, kind: str | None = None
    ) -> tuple[list[dict], int]:
        """Jobs newest first (of ``owner``, with ``status``, of ``kind`` (one of :data:`KINDS`), when given) and
        how many there are in all."""
        where = [
            w
            for w in (
                Job.owner == owner if owner is not None else None,
                Job.status == status if status else None,
                Job.spec.contains(f'"kind": "{kind}"') if kind else None,
            )
            if w is not None
        ]
        with Session(self.engine) as s:
            total = s.scalar(select(func.count()).select_from(Job).where(*where)) or 0
            rows = s.scalars(
                select(Job).where(*where).order_by(Job.created.desc(), Job.id.desc()).offset(offset).limit(limit)
            ).all()
            return [r.to_dict() for r in rows], int(total)

    def _set(self, job_id: str, where: tuple, **fields: Any) -> bool:
        """``UPDATE jobs SET fields WHERE id = job_id AND where``: whether a row changed."""
        with Session(self.engine) as s:
            res: Any = s.execute(sql_update(Job).where(Job.id == job_id, *where).values(**fields, updated=_now()))
            n = res.rowcount  # a CursorResult's (SQLAlchemy types execute() as the general Result)
            s.commit()
            return bool(n)

    @_guarded
    def update(self, job_id: str, attempt: int | None = None, **fields: Any) -> bool:
        """Set ``fields``; with ``attempt`` (the fencing token) only while that run still owns the job (it is
        running or cancelling with that attempt number). Whether the row was written."""
        where = () if attempt is None else (Job.attempts == attempt, Job.status.in_(("running", "cancelling")))
        return self._set(job_id, where, **fields)

    @_guarded
    def heartbeat(self, job_id: str, attempt: int, holder: str) -> bool:
        """Renew the lease of run ``attempt``; False when that run no longer owns the job."""
        return self._set(
            job_id,
            (Job.attempts == attempt, Job.status.in_(("running", "cancelling"))),
            lease_holder=holder,
            lease_until=time.time() + self.lease_seconds,
        )

    @_guarded
    def cancel(self, job_id: str, owner: str | None = None) -> dict | None:
        """Queued jobs are cancelled at once; running ones are asked to stop (``cancelling``); finished ones
        are left as they are. The job afterwards, or None if there is no such job (of ``owner``)."""
        if self.get(job_id, owner) is None:
            return None
        if not self._set(job_id, (Job.status == "queued",), status="cancelled"):
            self._set(job_id, (Job.status == "running",), status="cancelling")
        return self.get(job_id)

    @_guarded
    def delete(self, job_id: str, owner: str | None = None) -> dict | None:
        """Remove a finished job and its files; an unfinished one is only cancelled (as :meth:`cancel`).

        Returns the job as it was (``status`` tells which happened), or None if there is no such job."""
        job = self.get(job_id, owner)
        if job is None:
            return None
        if job["status"] not in FINISHED:
            return self.cancel(job_id, owner)
        with Session(self.engine) as s:
            spec = s.scalar(select(Job.spec).where(Job.id == job_id))
            s.execute(sql_delete(Job).where(Job.id == job_id, Job.status.in_(FINISHED)))
            shared = s.scalar(select(func.count()).select_from(Job).where(Job.spec == spec)) if spec else 0
            s.commit()
        shutil.rmtree(self.job_dir(job_id), ignore_errors=True)
        if spec and not shared and job["kind"] in ("topology-search", "pareto-front"):
            # its cases are those its progress recorded; two searches can share a candidate's case, so a case
            # another job recorded stays
            with Session(self.engine) as s:
                for cid in {p.get("id") for p in job["partial"] if isinstance(p.get("id"), str)}:
                    if cid.isalnum() and not s.scalar(
                        select(func.count()).select_from(Job).where(Job.partial.contains(f'"{cid}"'))
                    ):
                        (self.case_dir() / f"{cid}.json").unlink(missing_ok=True)
        elif spec and not shared:  # its cases are no other job's (a case's id covers the whole problem)
            for path in self.case_files(json.loads(spec)):
                path.unlink(missing_ok=True)
        return job

    def case_files(self, spec: dict) -> list[Path]:
        """Where the finished cases of a job with ``spec`` are (or will be) stored."""
        from ...optim.batch import case_id
        from ...optim.search import cases

        try:
            return [self.case_dir() / f"{case_id(c)}.json" for c in cases(spec)]
        except ValueError:  # pragma: no cover - a spec the optimiser no longer reads: nothing to find
            return []

    @_guarded
    def next_queued(self, holder: str) -> dict | None:
        """Claim the next queued job: running, one more attempt, a lease held by ``holder`` (the dispatcher)
        until the job process takes it over.

        Fair share between owners (API keys): the owner with the fewest running jobs, ties going to the owner
        served least recently (before, issue 29 item 8, one first-in-first-out queue: key B's small job waited
        72 s behind key A's three). Within that owner, the job with the smallest estimate less
        :data:`JOB_AGING` x the seconds it has waited (shortest first, with aging: one huge job neither holds
        the owner's small ones behind it nor waits for ever); jobs without an estimate count as 0 s.
        """
        while True:
            with Session(self.engine) as s:
                queued = s.execute(
                    select(Job.id, Job.owner, Job.attempts, Job.cost, Job.created)
                    .where(Job.status == "queued")
                    .order_by(Job.created, Job.id)
                    .limit(500)
                ).all()
                if not queued:
                    return None
                owners = {q.owner for q in queued}
                running = dict(
                    s.execute(
                        select(Job.owner, func.count())
                        .where(Job.status.in_(("running", "cancelling")), Job.owner.in_(owners))
                        .group_by(Job.owner)
                    ).all()
                )
                served = dict(
                    s.execute(
                        select(Job.owner, func.max(Job.started)).where(Job.owner.in_(owners)).group_by(Job.owner)
                    ).all()
                )
            owner = min(queued, key=lambda q: (running.get(q.owner, 0), served.get(q.owner) or 0.0)).owner
            now = time.time()
            mine = [q for q in queued if q.owner == owner]
            ranks = [(q.cost or 0.0) - JOB_AGING * (now - datetime.fromisoformat(q.created).timestamp()) for q in mine]
            job_id, _, attempts, _, _ = mine[ranks.index(min(ranks))]
            if self._set(
                job_id,
                (Job.status == "queued", Job.attempts == attempts),
                status="running",
                attempts=attempts + 1,
                lease_holder=holder,
                lease_until=now + self.lease_seconds,
                started=now,
            ):
                return self.row(job_id)
            # cancelled (or claimed by another server) in the meantime: look again

    @_guarded
    def requeue(self, job_id: str, attempt: int, reason: str, crash: bool = True) -> str | None:
        """Run ``attempt`` ended without a verdict: back to the queue, or cancelled if it was being cancelled.

        ``crash`` (the job process or a pool worker killed, its lease expired) counts towards
        :data:`MAX_CRASHES`, after which the job fails with ``reason`` and the policy; a graceful stop of the
        server (``crash=False``) never fails a job. The new status, or None if that run no longer owned the job.
        """
        with Session(self.engine) as s:
            job = s.get(Job, job_id)
            if job is None or job.attempts != attempt or job.status not in ("running", "cancelling"):
                return None
            status, crashes = job.status, (job.crashes or 0) + crash
        if status == "cancelling":
            new, extra = "cancelled", {}
        elif crashes >= MAX_CRASHES:
            new, extra = (
                "failed",
                {
                    "error": f"{reason}, {crashes} times: a job whose run crashes {MAX_CRASHES} "
                    "times is failed (the policy; graceful server restarts are not "
                    "counted); finished cases are kept: resubmit to resume from them"
                },
            )
        else:
            new, extra = "queued", {}
        ok = self._set(
            job_id,
            (Job.attempts == attempt, Job.status == status),
            status=new,
            crashes=crashes,
            lease_holder=None,
            lease_until=None,
            **extra,
        )
        return new if ok else None

    @_guarded
    def expired(self, now: float | None = None) -> list[dict]:
        """Running or cancelling jobs whose lease has run out (their run is gone)."""
        now = time.time() if now is None else now
        with Session(self.engine) as s:
            rows = s.scalars(
                select(Job).where(
                    Job.status.in_(("running", "cancelling")), (Job.lease_until.is_(None)) | (Job.lease_until < now)
                )
            ).all()
            return [{"id": j.id, "attempts": j.attempts, "lease_holder": j.lease_holder} for j in rows]
