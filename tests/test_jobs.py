"""Optimisation jobs over HTTP: a real uvicorn on 127.0.0.1, the typed client, the real optimiser."""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest

pytest.importorskip("fastapi")
pytest.importorskip("sqlalchemy")

from flexopt.service.client import Client, InvalidInput, JobFailed, NotFound  # noqa: E402
from flexopt.service.jobs import MAX_ATTEMPTS, JobStore  # noqa: E402
from flexopt.service.settings import Settings  # noqa: E402
from tests.test_service import _Server  # noqa: E402

TINY = {"families": [{"template": "leaf-spring", "design": {"thickness": [3e-4, 6e-4]}}], "stroke": 20,
        "samples": 5, "starts": 1, "max_iterations": 3}
# eight cases of a few seconds each: long enough to interrupt, short enough for CI
LONG = {"families": [{"template": "cross-spring-pivot",
                      "design": {"length": [0.03, 0.07], "thickness": [1.5e-4, 4e-4]}}], "starts": 8}


def _server(tmp_path: Path, **kw: object) -> _Server:
    return _Server(Settings(data_dir=tmp_path, executor="thread", job_workers=1, **kw)).__enter__()


def _until(pred, timeout: float = 120.0, poll: float = 0.2):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        out = pred()
        if out:
            return out
        time.sleep(poll)
    raise AssertionError("condition not reached in time")


def test_job_completes_with_progress_and_idempotency(tmp_path):
    srv = _server(tmp_path)
    try:
        with Client(srv.url, max_retries=0) as c:
            seen = []
            h = c.submit_optimisation(TINY, idempotency_key="k-1")
            assert c.submit_optimisation(TINY, idempotency_key="k-1").id == h.id, "a retried submission"
            result = h.wait(progress=lambda j: seen.append(j.status), poll=0.2, timeout=120)
            assert result["ranking"][0]["template"] == "leaf-spring"
            assert result["families"][0]["best"]["verified"]["points"] == 181
            job = h.status()
            assert job.status == "succeeded" and job.progress == {"done": 1, "total": 1} and len(job.partial) == 1
            page = c.optimisations(limit=1)
            assert page.total == 1 and page.items[0].id == h.id
            with pytest.raises(NotFound):
                c.optimisation("no-such-job")
            with pytest.raises(InvalidInput) as info:
                c.submit_optimisation({**TINY, "samples": 1})
            assert any("samples" in ".".join(map(str, e.loc)) for e in info.value.errors)
    finally:
        srv.__exit__()


def test_job_cancelled(tmp_path):
    srv = _server(tmp_path)
    try:
        with Client(srv.url, max_retries=0) as c:
            h = c.submit_optimisation(LONG)
            _until(lambda: h.status().status == "running")
            h.cancel()
            with pytest.raises(JobFailed) as info:
                h.wait(poll=0.2, timeout=120)
            assert info.value.job.status == "cancelled"
    finally:
        srv.__exit__()


def test_restart_resumes_a_running_job_without_redoing_finished_cases(tmp_path):
    srv = _server(tmp_path)
    with Client(srv.url, max_retries=0) as c:
        h = c.submit_optimisation(LONG)
        _until(lambda: h.status().progress.get("done", 0) >= 2)
    srv.__exit__()  # the server stops mid-job: its job process is terminated
    store = JobStore(Settings(data_dir=tmp_path).job_store_url(), tmp_path)
    assert store.get(h.id)["status"] == "running", "left running by the stopped server"
    before = {p.name: p.stat().st_mtime_ns for p in store.case_dir(h.id).glob("*.json")}
    assert len(before) >= 2
    srv = _server(tmp_path)  # the next start requeues it; it resumes from its finished cases
    try:
        with Client(srv.url, max_retries=0) as c:
            job = _until(lambda: (j := c.optimisation(h.id)).status in ("succeeded", "failed") and j, timeout=180)
            assert job.status == "succeeded", job.error
            assert job.attempts == 2
            after = {p.name: p.stat().st_mtime_ns for p in store.case_dir(h.id).glob("*.json")}
            assert len(after) == 8 and all(after[k] == v for k, v in before.items()), "finished cases kept"
    finally:
        srv.__exit__()


def test_repeatedly_interrupted_job_is_failed_with_its_reason(tmp_path):
    store = JobStore(f"sqlite:///{tmp_path / 'j.sqlite'}", tmp_path)
    job, created = store.submit(TINY, None)
    assert created
    for _ in range(MAX_ATTEMPTS):
        assert store.next_queued()["id"] == job["id"]
        store.recover()  # the server stopped while it ran
    final = store.get(job["id"])
    assert final["status"] == "failed" and "interrupted" in final["error"]
    assert json.loads(json.dumps(final))["attempts"] == MAX_ATTEMPTS
