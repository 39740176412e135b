"""The job store on SQLite and on a real PostgreSQL server: owners, idempotency, leases, fencing, retries.

PostgreSQL is started by the ``pg_url`` fixture from the ``pgserver`` package (a PostgreSQL build on PyPI,
run as a throw-away server in a temporary directory) and reached through the pure-Python ``pg8000`` driver;
those tests skip, saying why, only where neither can be had.
"""

from __future__ import annotations

import itertools
import sqlite3
import threading
import time
import warnings
from collections.abc import Iterator
from pathlib import Path

import pytest

pytest.importorskip("sqlalchemy")

from flexopt.service.jobs.store import (  # noqa: E402
    MAX_ATTEMPTS,
    MAX_CRASHES,
    JobStore,
    KeyReused,
    StoreCorrupt,
    StoreUnavailable,
    TooManyJobs,
    owner_of,
)

SPEC = {"families": [{"template": "leaf-spring", "design": {"thickness": [3e-4, 6e-4]}}], "starts": 1}
_dbs = itertools.count()


@pytest.fixture(scope="session")
def pg_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[object, Path]]:
    """A PostgreSQL server for the session (pgserver), or a skip with the reason."""
    try:
        import pg8000  # noqa: F401
    except ImportError:
        pytest.skip("PostgreSQL tests need the pg8000 driver (pip install '.[test]')")
    with warnings.catch_warnings():  # platformdirs warns about XDG_RUNTIME_DIR on import
        warnings.simplefilter("ignore")
        try:
            import pgserver
        except ImportError:
            pytest.skip("PostgreSQL tests need the pgserver package (pip install '.[test]')")
        where = tmp_path_factory.mktemp("pg")
        try:
            srv = pgserver.get_server(where, cleanup_mode="stop")
        except Exception as exc:  # noqa: BLE001 - the reason is the skip message
            pytest.skip(f"pgserver could not start PostgreSQL here: {exc}")
    yield srv, where
    srv.cleanup()


@pytest.fixture
def pg_url(pg_server: tuple[object, Path]) -> str:
    """A fresh, empty PostgreSQL database for one test."""
    srv, where = pg_server
    name = f"t{next(_dbs)}"
    srv.psql(f"CREATE DATABASE {name};")  # type: ignore[attr-defined]
    return f"postgresql+pg8000://postgres@/{name}?unix_sock={where}/.s.PGSQL.5432"


@pytest.fixture(params=["sqlite", "postgresql"])
def store(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[JobStore]:
    url = f"sqlite:///{tmp_path / 'jobs.sqlite'}" if request.param == "sqlite" else request.getfixturevalue("pg_url")
    s = JobStore(url, tmp_path, lease_seconds=0.5)
    yield s
    s.engine.dispose()


def test_submit_idempotency_and_owners(store: JobStore) -> None:
    a, b = owner_of("key-a"), owner_of("key-b")
    job, created = store.submit(SPEC, "k1", a)
    assert created and store.submit(SPEC, "k1", a) == (job, False), "a retried submission returns the job"
    with pytest.raises(KeyReused, match="different problem"):
        store.submit({**SPEC, "starts": 2}, "k1", a)
    other, created = store.submit({**SPEC, "starts": 2}, "k1", b)  # the same key of another client
    assert created and other["id"] != job["id"]
    assert store.get(job["id"], b) is None and store.get(job["id"], a)["id"] == job["id"]
    assert [j["id"] for j in store.page(0, 10, a)[0]] == [job["id"]] and store.page(0, 10, b)[1] == 1
    assert store.cancel(job["id"], b) is None and store.delete(job["id"], b) is None, "not b's job"
    assert store.get(job["id"])["status"] == "queued"
    assert store.submit(SPEC, None, b, max_active=2)[1], "b's second unfinished job"
    with pytest.raises(TooManyJobs, match="limit 2"):
        store.submit(SPEC, None, b, max_active=2)
    assert store.submit(SPEC, None, a, max_active=2)[1], "the cap is per key"


def test_claim_heartbeat_lease_expiry_and_fencing(store: JobStore) -> None:
    job, _ = store.submit(SPEC, None)
    claimed = store.next_queued("host:1")
    assert claimed["id"] == job["id"] and claimed["status"] == "running" and claimed["attempts"] == 1
    assert store.next_queued("host:1") is None, "claimed once"
    assert store.heartbeat(job["id"], 1, "host:2") and store.expired() == []
    assert store.update(job["id"], 1, progress='{"done": 1, "total": 4}')
    time.sleep(0.7)  # the lease (0.5 s) runs out without a heartbeat
    assert [j["id"] for j in store.expired()] == [job["id"]]
    assert store.requeue(job["id"], 1, "lease expired") == "queued"
    assert store.next_queued("host:1")["attempts"] == 2
    # run 1 is a leftover (fencing token 1): it can neither beat nor write a verdict over run 2
    assert not store.heartbeat(job["id"], 1, "host:2")
    assert not store.update(job["id"], 1, status="succeeded")
    assert store.requeue(job["id"], 1, "late") is None
    assert store.get(job["id"])["status"] == "running"
    assert store.update(job["id"], 2, status="succeeded", result='{"ranking": []}')
    assert store.get(job["id"])["progress"] == {"done": 1, "total": 4}, "progress survived the retry"


def test_retries_end_in_failure_with_the_reason(store: JobStore) -> None:
    job, _ = store.submit(SPEC, None)
    for attempt in range(1, MAX_ATTEMPTS + 1):
        assert store.next_queued("h:1")["attempts"] == attempt
        new = store.requeue(job["id"], attempt, "the job process ended without a result (exit code -9)")
        assert new == ("failed" if attempt == MAX_ATTEMPTS else "queued")
    final = store.get(job["id"])
    assert final["status"] == "failed" and "exit code -9" in final["error"] and "3 times" in final["error"]


def test_graceful_stops_never_fail_a_job_and_crashes_do_by_policy(store: JobStore) -> None:
    """Issue 29 item 5: a rolling deploy (five graceful stops of the server during one job) requeues it each
    time without counting; three crashes then fail it, the error naming the policy. It failed before: the
    third graceful stop failed the job."""
    job, _ = store.submit(SPEC, None)
    for attempt in range(1, 6):
        assert store.next_queued("h:1")["attempts"] == attempt
        assert store.requeue(job["id"], attempt, "interrupted by a stopping server", crash=False) == "queued"
    for attempt in range(6, 6 + MAX_CRASHES):
        store.next_queued("h:1")
        new = store.requeue(job["id"], attempt, "the job process ended without a result (exit code -9)")
        assert new == ("failed" if attempt == 5 + MAX_CRASHES else "queued")
    error = store.get(job["id"])["error"]
    assert "(exit code -9), 3 times" in error and "policy" in error and "restarts are not counted" in error


def test_cancel_and_delete(store: JobStore, tmp_path: Path) -> None:
    queued, _ = store.submit(SPEC, None)
    running, _ = store.submit({**SPEC, "starts": 2}, None)
    assert store.next_queued("h:1")["id"] == queued["id"]  # oldest first
    assert store.cancel(running["id"])["status"] == "cancelled", "queued: cancelled at once"
    assert store.delete(queued["id"])["status"] == "cancelling", "running: DELETE only asks it to stop"
    assert store.requeue(queued["id"], 1, "ended") == "cancelled"
    files = store.job_dir(queued["id"])
    files.mkdir(parents=True)
    (files / "x.json").write_text("{}")
    assert store.delete(queued["id"])["status"] == "cancelled"
    assert store.get(queued["id"]) is None and not files.exists(), "a finished job and its files are removed"
    assert store.delete(queued["id"]) is None


def test_locked_sqlite_is_unavailable_then_recovers(tmp_path: Path) -> None:
    """Another process holding the write lock: writes raise StoreUnavailable (503), never a raw error."""
    path = tmp_path / "jobs.sqlite"
    store = JobStore(f"sqlite:///{path}", tmp_path)
    store.engine.pool.dispose()
    lock = sqlite3.connect(path, timeout=1)
    lock.execute("BEGIN EXCLUSIVE")
    try:
        with pytest.raises(StoreUnavailable, match="locked.*retry"):
            store.submit(SPEC, None)
    finally:
        lock.rollback()
        lock.close()
    assert store.submit(SPEC, None)[1]


def test_corrupt_sqlite_refused_with_one_line(tmp_path: Path) -> None:
    path = tmp_path / "jobs.sqlite"
    path.write_bytes(b"this is not a database" * 100)
    with pytest.raises(StoreCorrupt) as info:
        JobStore(f"sqlite:///{path}", tmp_path)
    msg = str(info.value)
    assert "\n" not in msg and str(path) in msg and "move it aside" in msg


def test_old_database_gets_the_new_columns(tmp_path: Path) -> None:
    """A job table of the previous release (no owner, no lease) is upgraded in place; its jobs stay."""
    path = tmp_path / "jobs.sqlite"
    con = sqlite3.connect(path)
    con.execute(
        "CREATE TABLE jobs (id VARCHAR(36) PRIMARY KEY, status VARCHAR(16), spec TEXT, idempotency_key "
        "VARCHAR(200) UNIQUE, progress TEXT, partial TEXT, result TEXT, error TEXT, attempts INTEGER, "
        "created VARCHAR(40), updated VARCHAR(40))"
    )
    con.execute("INSERT INTO jobs VALUES ('j1', 'running', '{}', NULL, '{}', '[]', NULL, NULL, 1, 'a', 'a')")
    con.commit()
    con.close()
    store = JobStore(f"sqlite:///{path}", tmp_path)
    assert store.get("j1", "")["status"] == "running"
    assert [j["id"] for j in store.expired()] == ["j1"], "a run of the old server has no lease: expired"


def test_concurrent_claims_give_each_job_once(store: JobStore) -> None:
    ids = {store.submit({**SPEC, "starts": k}, None)[0]["id"] for k in range(1, 7)}
    got: list[str] = []

    def claim() -> None:
        while (j := store.next_queued(f"h:{threading.get_ident()}")) is not None:
            got.append(j["id"])

    threads = [threading.Thread(target=claim) for _ in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(30)
    assert sorted(got) == sorted(ids), "every job claimed exactly once"


def test_dispatcher_survives_database_errors(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The audit: one database error (a lock held for 40 s) ended the dispatch thread for good, while /health
    said 200. Now each failing tick is logged and retried with backoff, and ``healthy()`` tells /ready."""
    from flexopt.service.jobs.dispatch import Dispatcher

    store = JobStore(f"sqlite:///{tmp_path / 'jobs.sqlite'}", tmp_path)
    real, calls = store.expired, []

    def flaky(now: float | None = None) -> list[dict]:
        calls.append(time.monotonic())
        if len(calls) <= 3:
            raise StoreUnavailable(RuntimeError("database is locked"))
        return real(now)

    monkeypatch.setattr(store, "expired", flaky)
    d = Dispatcher(store, max_jobs=1, workers=1)
    d.start()
    try:
        deadline = time.monotonic() + 2
        while d.last_error is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert d.healthy() is not None and "locked" in d.healthy()
        deadline = time.monotonic() + 20
        while len(calls) < 5 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert d.healthy() is None and d._thread.is_alive(), "back to work after the errors"
        gaps = [b - a for a, b in zip(calls, calls[1:4])]
        assert gaps[1] > gaps[0] > 0.4, f"exponential backoff between retries: {gaps}"
    finally:
        d.stop()


def test_fair_share_between_owners(store: JobStore) -> None:
    """Issue 29 item 8: key A submits three jobs, then key B one. B's job is claimed second (A has one running),
    and after A's first job ends, before A's second (A was served last): it failed before, B's job waited
    behind all of A's (one first-in-first-out queue)."""
    a, b = owner_of("key-a"), owner_of("key-b")
    jobs_a = [store.submit({**SPEC, "starts": n}, None, a)[0]["id"] for n in (1, 2, 3)]
    job_b = store.submit(SPEC, None, b)[0]["id"]
    assert store.next_queued("h:1")["id"] == jobs_a[0], "nothing running: the oldest"
    assert store.next_queued("h:1")["id"] == job_b, "A has a job running, B none"
    store.update(jobs_a[0], 1, status="succeeded")
    store.update(job_b, 1, status="succeeded")
    assert store.next_queued("h:1")["id"] == jobs_a[1], "B has no job left: A's next"
    job_b2 = store.submit({**SPEC, "starts": 4}, None, b)[0]["id"]
    store.update(jobs_a[1], 1, status="succeeded")
    assert store.next_queued("h:1")["id"] == job_b2, "none running: B, served less recently than A"
