"""Optimisation jobs over HTTP: a real uvicorn on 127.0.0.1, the typed client, the real optimiser.

Owners (API keys), idempotency, the per-key cap, deletion, validation at submission, cancellation and a
restart that resumes from the shared case store, on SQLite and on a real PostgreSQL server.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import httpx
import pytest

pytest.importorskip("fastapi")
pytest.importorskip("sqlalchemy")

from flexopt.service.api.settings import Settings  # noqa: E402
from flexopt.service.client import Client, InvalidInput, JobFailed, NotFound  # noqa: E402
from flexopt.service.jobs.run import run_job
from flexopt.service.jobs.store import JobStore  # noqa: E402

from tests.test_job_store import pg_server, pg_url  # noqa: E402,F401 - fixtures
from tests.test_service import _Server  # noqa: E402

TINY = {
    "families": [{"template": "leaf-spring", "design": {"thickness": [3e-4, 6e-4]}}],
    "stroke": 20,
    "samples": 5,
    "starts": 1,
    "max_iterations": 3,
}
# four cases of a few seconds each: long enough to interrupt, short enough for CI
LONG = {
    "families": [{"template": "cross-spring-pivot", "design": {"length": [0.03, 0.07], "thickness": [1.5e-4, 4e-4]}}],
    "starts": 4,
}


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


def _cases(store_dir: Path) -> dict[str, tuple[int, int]]:
    """Finished case files -> (inode, mtime): a case computed again is written again (new inode)."""
    return {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in (store_dir / "cases").glob("*.json")}


def test_job_completes_with_progress_and_idempotency(tmp_path: Path) -> None:
    srv = _server(tmp_path)
    try:
        with Client(srv.url, max_retries=0) as c:
            seen = []
            h = c.submit_optimisation(TINY, idempotency_key="k-1")
            assert c.submit_optimisation(TINY, idempotency_key="k-1").id == h.id, "a retried submission"
            with pytest.raises(InvalidInput, match="different problem") as info:  # same key, other problem
                c.submit_optimisation({**TINY, "samples": 7}, idempotency_key="k-1")
            assert info.value.errors[0].loc == ["header", "Idempotency-Key"]
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
            # an identical resubmission finds every case in the case store: nothing is computed again
            before = _cases(tmp_path)
            again = c.submit_optimisation(TINY)
            assert again.id != h.id and again.wait(poll=0.2, timeout=120)["ranking"] == result["ranking"]
            assert _cases(tmp_path) == before
    finally:
        srv.__exit__()


def test_keys_isolate_jobs_cap_and_delete(tmp_path: Path) -> None:
    srv = _server(tmp_path, api_keys="key-a,key-b", max_active_jobs=1)
    try:
        with Client(srv.url, api_key="key-a", max_retries=0) as a, Client(srv.url, api_key="key-b", max_retries=0) as b:
            h = a.submit_optimisation(TINY, idempotency_key="same")
            r = httpx.post(f"{srv.url}/v1/optimisations", json=TINY, headers={"X-API-Key": "key-a"})
            assert r.status_code == 429 and "limit 1" in r.json()["detail"], "one unfinished job per key here"
            assert b.optimisations().total == 0, "b lists only its own jobs"
            for call in (b.optimisation, b.cancel_optimisation):
                with pytest.raises(NotFound):
                    call(h.id)
            hb = b.submit_optimisation({**TINY, "samples": 7}, idempotency_key="same")  # keys scoped by API key
            assert hb.id != h.id
            h.wait(poll=0.2, timeout=120)
            store = JobStore(Settings(data_dir=tmp_path).job_store_url(), tmp_path)
            files = store.case_files(TINY)
            assert files and all(f.exists() for f in files)
            assert a.cancel_optimisation(h.id).status == "succeeded", "DELETE of a finished job removes it"
            assert not any(f.exists() for f in files), "and its files"
            with pytest.raises(NotFound):
                a.optimisation(h.id)
            assert a.optimisations().total == 0 and b.optimisations().total == 1
            b.cancel_optimisation(hb.id)
    finally:
        srv.__exit__()


# each: the body, the field path expected in the 422, words of the message
BAD_SPECS = [
    (
        '{"families": [{"template": "leaf-spring", "design": {"thickness": [3e-4, 6e-4]}}], "stroke": Infinity}',
        ["body", "stroke"],
        "finite",
    ),
    (
        '{"families": [{"template": "leaf-spring", "design": {"thickness": [3e-4, 6e-4]}}], "max_drive": Infinity}',
        ["body", "max_drive"],
        "finite",
    ),
    (
        json.dumps(
            {
                "families": [
                    {"template": "leaf-spring", "design": {"thickness": [3e-4, 6e-4]}, "fixed": {"segments": 100000}}
                ]
            }
        ),
        ["body", "families", 0, "fixed", "segments"],
        "",
    ),
    (
        json.dumps(
            {
                "families": [
                    {"template": "leaf-spring", "design": {"thickness": [3e-4, 6e-4]}, "fixed": {"warping": "bogus"}}
                ]
            }
        ),
        ["body", "families", 0, "fixed", "warping"],
        "",
    ),
    (
        json.dumps(
            {"families": [{"template": "leaf-spring", "design": {"thickness": [3e-4, 6e-4], "segments": [4, 12]}}]}
        ),
        ["body", "families", 0, "design", "segments"],
        "set it in 'fixed'",
    ),
    (
        json.dumps({"families": [{"template": "nope", "design": {"t": [1, 2]}}]}),
        ["body", "families", 0, "template"],
        "unknown template",
    ),
]


def test_job_specs_validated_completely_at_submission(tmp_path: Path) -> None:
    srv = _server(tmp_path)
    try:
        for body, loc, words in BAD_SPECS:
            r = httpx.post(f"{srv.url}/v1/optimisations", content=body, headers={"Content-Type": "application/json"})
            assert r.status_code == 422, (body, r.text)
            err = r.json()["errors"]
            assert err and err[0]["loc"][: len(loc)] == loc and words in err[0]["msg"], (body, err)
        assert httpx.get(f"{srv.url}/v1/optimisations").json()["total"] == 0, "no job was created"
    finally:
        srv.__exit__()


def test_job_whose_every_case_failed_is_failed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The case runner's failure records (as optim.batch returns them) summarised as the job's verdict."""
    import flexopt.optim as optim
    from flexopt.optim.problem import Problem
    from flexopt.optim.search import summarise

    def all_fail(spec, **kw):  # every case raised in its worker: the batch returns failure records
        prob = Problem.model_validate(spec)
        return summarise(
            prob,
            [
                {
                    "id": "x",
                    "family_index": 0,
                    "start": 0,
                    "status": "failed",
                    "error": "EquilibriumError: no equilibrium at stroke 3 deg",
                    "verified": {},
                }
            ],
        )

    monkeypatch.setattr(optim, "optimise", all_fail)
    url = f"sqlite:///{tmp_path / 'jobs.sqlite'}"
    monkeypatch.setenv("FLEXOPT_DATABASE_URL", url)
    monkeypatch.setenv("FLEXOPT_DATA_DIR", str(tmp_path))
    store = JobStore(url, tmp_path)
    job, _ = store.submit(TINY, None)
    store.next_queued("test:1")
    assert run_job(job["id"], 1, handle_signals=False) == 1
    final = store.get(job["id"])
    assert final["status"] == "failed" and "every case failed" in final["error"]
    assert "no equilibrium at stroke 3 deg" in final["error"]


def test_progress_lost_in_an_outage_is_written_with_the_verdict(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Issue 29 item 8: with the database out for every progress write (here: all of them, as at the very
    end of a job), the job once succeeded listed 3 of 12 cases and progress 3/12. The verdict now carries
    the final progress and every case (it failed before: progress {} and no cases listed)."""
    from flexopt.service.jobs.store import StoreUnavailable

    real = JobStore.update

    def outage(self: JobStore, job_id: str, attempt: int | None = None, **fields: object) -> bool:
        if "progress" in fields and "status" not in fields:
            raise StoreUnavailable(OSError("database is unreachable"))
        return real(self, job_id, attempt, **fields)

    monkeypatch.setattr(JobStore, "update", outage)
    url = f"sqlite:///{tmp_path / 'jobs.sqlite'}"
    monkeypatch.setenv("FLEXOPT_DATABASE_URL", url)
    monkeypatch.setenv("FLEXOPT_DATA_DIR", str(tmp_path))
    monkeypatch.setenv("FLEXOPT_JOB_WORKERS", "1")
    store = JobStore(url, tmp_path)
    job, _ = store.submit({**TINY, "starts": 2}, None)
    store.next_queued("test:1")
    assert run_job(job["id"], 1, handle_signals=False) == 0
    final = store.get(job["id"])
    assert final["status"] == "succeeded"
    assert final["progress"] == {"done": 2, "total": 2} and len(final["partial"]) == 2, final["progress"]


def test_job_cancelled(tmp_path: Path) -> None:
    srv = _server(tmp_path)  # one job at a time: the second one waits in the queue
    try:
        with Client(srv.url, max_retries=0) as c:
            h = c.submit_optimisation(LONG)
            _until(lambda: h.status().status == "running")
            # submitted once LONG runs: the queue runs the smallest estimate of a key first, so a TINY
            # submitted beside LONG would start (and finish) before it
            queued = c.submit_optimisation(TINY)
            assert queued.cancel().status == "cancelled", "a queued job is cancelled at once"
            h.cancel()
            with pytest.raises(JobFailed) as info:
                h.wait(poll=0.2, timeout=120)
            assert info.value.job.status == "cancelled"
    finally:
        srv.__exit__()


@pytest.mark.slow
@pytest.mark.parametrize("db", ["sqlite", "postgresql"])
def test_restart_resumes_a_running_job_without_redoing_finished_cases(
    tmp_path: Path, db: str, request: pytest.FixtureRequest
) -> None:
    url = request.getfixturevalue("pg_url") if db == "postgresql" else ""
    srv = _server(tmp_path, database_url=url)
    with Client(srv.url, max_retries=0) as c:
        h = c.submit_optimisation(LONG)
        _until(lambda: h.status().progress.get("done", 0) >= 1)
    srv.__exit__()  # the server stops mid-job: its job process is stopped and the job requeued
    store = JobStore(Settings(data_dir=tmp_path, database_url=url).job_store_url(), tmp_path)
    assert store.get(h.id)["status"] == "queued", "requeued by the stopping server"
    before = _cases(tmp_path)
    assert len(before) >= 1
    srv = _server(tmp_path, database_url=url)  # the next start runs it again; it resumes from its cases
    try:
        with Client(srv.url, max_retries=0) as c:
            job = _until(lambda: (j := c.optimisation(h.id)).status in ("succeeded", "failed") and j, timeout=180)
            assert job.status == "succeeded", job.error
            assert job.attempts == 2
            after = _cases(tmp_path)
            assert len(after) == 4 and all(after[k] == v for k, v in before.items()), "finished cases kept"
    finally:
        srv.__exit__()
        store.engine.dispose()


def test_costly_curve_runs_as_a_job_when_asked(tmp_path: Path) -> None:
    """Large models leave the request path: 413 naming the way out, or a job with 'Prefer: respond-async'."""
    import numpy as np
    from flexopt.model import Analysis
    from flexopt.model.scene import Scene

    srv = _server(tmp_path, max_cost=1e-4)  # every curve is "too costly" for a request here
    try:
        with Client(srv.url, max_retries=0) as c:
            scene = c.template_scene("leaf-spring", points=5)
            r = httpx.post(f"{srv.url}/v1/frequency-curve", json={"scene": scene})
            assert r.status_code == 413 and "Prefer: respond-async" in r.json()["detail"]
            r = httpx.post(f"{srv.url}/v1/frequency-curve", json={"scene": scene}, headers={"Prefer": "respond-async"})
            assert r.status_code == 202 and r.headers["preference-applied"] == "respond-async", r.text
            assert r.json()["kind"] == "frequency-curve"
            job = _until(lambda: (j := c.optimisation(r.json()["id"])).status in ("succeeded", "failed") and j)
            assert job.status == "succeeded", job.error
        direct = Analysis(Scene.model_validate(scene)).frequency_curve()  # the same computation in-process
        np.testing.assert_allclose(job.result["parasitic_hz"], direct.parasitic_hz, rtol=1e-9)
    finally:
        srv.__exit__()


def test_family_form_recognises_every_form_of_a_family() -> None:
    """The web page's family column (a topology search's ``family_form``): a family's own descriptor and its
    mirror images by the grammar's canonical form, and the family's descriptor without its designed crossing
    (the family at crossing 0.5) named so; the grammar's own ``family`` stays None there (its crossing is not
    designed), and a topology of no family is None. Each expected name read off FAMILIES' table by hand."""
    from flexopt.optim.topology.grammar import family_form

    assert family_form("R:+-@") == family_form("R:-+@") == "cross-spring-pivot"
    assert family_form("R:+-") == family_form("R:-+") == "cross-spring-pivot (crossing at the midpoint)"
    assert family_form("R:-+2-") == family_form("R:+-2+") == "three-fold-cross-hinge (crossing at the midpoint)"
    assert family_form("R:x+-") == "cartwheel-hinge"
    assert family_form("R:+-|-+") == "double-cross-hinge"
    assert family_form("R:++") is None and family_form("R:+-@|-+") is None  # a double cross with a designed crossing
