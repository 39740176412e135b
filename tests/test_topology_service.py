"""Topology searches over HTTP: ``/v1/topology-searches`` as jobs in the job store (a real uvicorn on
127.0.0.1, the typed client, the real search), validation at submission, API-key ownership, the case store."""

from __future__ import annotations

import asyncio
from pathlib import Path

import httpx
import pytest

pytest.importorskip("fastapi")
pytest.importorskip("sqlalchemy")

from flexopt.optim.topology.spec import TopologySpec  # noqa: E402
from flexopt.service.client import AsyncClient, Client, InvalidInput, NotFound  # noqa: E402
from flexopt.service.schemas import Job  # noqa: E402

from tests.test_jobs import _cases, _server, _until  # noqa: E402

# one hinge that survives the filter (the cross-spring pivot's leaves, optimised) and one the filter rejects
# (both leaves in one plane: a mechanism); a few seconds in all
TINY = {
    "topologies": ["R:+-", "R:++"],
    "segments": 4,
    "samples": 5,
    "verify_points": 31,
    "refine_rounds": 1,
    "starts": 1,
    "refine_segments": None,
}  # no refined verification: the cases are the screen's and the search's


def test_topology_search_job_over_http(tmp_path: Path) -> None:
    srv = _server(tmp_path, api_keys="key-a,key-b")
    try:
        a_hdr, b_hdr = {"X-API-Key": "key-a"}, {"X-API-Key": "key-b"}
        ex = httpx.get(f"{srv.url}/v1/topology-searches/example", headers=a_hdr)
        assert ex.status_code == 200 and ex.json() == TopologySpec().model_dump(mode="json")
        # a bad field: 422 naming it, and no job created
        for body, field in (
            ({**TINY, "max_flexure": 3}, "max_flexure"),
            ({**TINY, "planes": "+x"}, "planes"),
            ({**TINY, "topologies": ["R:+*"]}, "topologies"),
        ):
            r = httpx.post(f"{srv.url}/v1/topology-searches", json=body, headers=a_hdr)
            assert r.status_code == 422, r.text
            assert r.json()["errors"][0]["loc"][:2] == ["body", field], r.json()
        r = httpx.post(
            f"{srv.url}/v1/topology-searches",
            content='{"stroke": Infinity}',
            headers={**a_hdr, "Content-Type": "application/json"},
        )
        assert r.status_code == 422 and r.json()["errors"][0]["loc"][:2] == ["body", "stroke"], r.text
        assert httpx.get(f"{srv.url}/v1/topology-searches", headers=a_hdr).json()["total"] == 0

        r = httpx.post(f"{srv.url}/v1/topology-searches", json=TINY, headers={**a_hdr, "Idempotency-Key": "t-1"})
        assert r.status_code == 202 and r.headers["Location"] == f"/v1/topology-searches/{r.json()['id']}"
        job_id = r.json()["id"]
        assert r.json()["kind"] == "topology-search"
        again = httpx.post(f"{srv.url}/v1/topology-searches", json=TINY, headers={**a_hdr, "Idempotency-Key": "t-1"})
        assert again.json()["id"] == job_id, "a retried submission is the same job"
        # another API key sees nothing of it
        assert httpx.get(f"{srv.url}/v1/topology-searches/{job_id}", headers=b_hdr).status_code == 404
        assert httpx.delete(f"{srv.url}/v1/topology-searches/{job_id}", headers=b_hdr).status_code == 404
        assert httpx.get(f"{srv.url}/v1/topology-searches", headers=b_hdr).json()["total"] == 0

        job = _until(
            lambda: (
                (j := httpx.get(f"{srv.url}/v1/topology-searches/{job_id}", headers=a_hdr).json())["status"]
                in ("succeeded", "failed", "cancelled")
                and j
            ),
            timeout=180,
        )
        assert job["status"] == "succeeded", job
        res = job["result"]
        assert job["progress"]["done"] == job["progress"]["total"] == 1, "one optimised case: one start of 'R:+-'"
        by = {c["topology"]: c for c in res["candidates"]}
        assert set(by) == {"R:+-", "R:++"}
        assert by["R:++"]["status"] == "rejected" and by["R:++"]["reason"].startswith("underconstrained")
        assert res["ranking"] == ["R:+-"] and res["best"]["topology"] == "R:+-"
        assert res["best"]["worst_case_hz"] > 0 and res["best"]["scene"]["elements"], "a scene to draw"
        page = httpx.get(f"{srv.url}/v1/topology-searches", headers=a_hdr).json()
        assert page["total"] == 1 and page["items"][0]["id"] == job_id
        # an optimisation job is not a topology search
        opt = httpx.post(
            f"{srv.url}/v1/optimisations",
            headers=a_hdr,
            json={
                "families": [{"template": "leaf-spring", "design": {"thickness": [3e-4, 6e-4]}}],
                "samples": 5,
                "starts": 1,
                "max_iterations": 3,
            },
        ).json()
        assert httpx.get(f"{srv.url}/v1/topology-searches/{opt['id']}", headers=a_hdr).status_code == 404
        assert httpx.get(f"{srv.url}/v1/topology-searches", headers=a_hdr).json()["total"] == 1
        httpx.delete(f"{srv.url}/v1/optimisations/{opt['id']}", headers=a_hdr)

        # the typed client: the same search again finds its case in the shared case store (nothing recomputed)
        before = _cases(tmp_path)
        with Client(srv.url, api_key="key-a", max_retries=0) as c:
            h = c.submit_topology_search(TINY)
            assert h.id != job_id and c.topology_searches().total == 2
            out = h.wait(poll=0.2, timeout=180)
            assert out["ranking"] == res["ranking"] and out["best"]["worst_case_hz"] == res["best"]["worst_case_hz"]
            with pytest.raises(InvalidInput) as info:
                c.submit_topology_search({"samples": 2})
            assert info.value.errors[0].loc[:2] == ["body", "samples"]
            assert c.cancel_optimisation(h.id).status == "succeeded"  # the generic job routes serve every kind
            with pytest.raises(NotFound):
                c.optimisation(h.id)
        assert _cases(tmp_path) == before
        ids = {p["id"] for p in job["partial"]}
        assert len(ids) == 2 and {f"{i}.json" for i in ids} <= set(before), "the screen's and the search's case"
        assert httpx.delete(f"{srv.url}/v1/topology-searches/{job_id}", headers=a_hdr).json()["status"] == "succeeded"
        assert httpx.get(f"{srv.url}/v1/topology-searches/{job_id}", headers=a_hdr).status_code == 404
        assert not {f"{i}.json" for i in ids} & set(_cases(tmp_path)), "and removed with the last job using it"
    finally:
        srv.__exit__()


def test_async_client_submits_and_cancels_a_topology_search(tmp_path: Path) -> None:
    srv = _server(tmp_path)

    async def go() -> Job:
        async with AsyncClient(srv.url, max_retries=0) as c:
            spec = TopologySpec(starts=4)  # 40 survivors x 4 starts: cancelled long before the end
            h = await c.submit_topology_search(spec, idempotency_key="k")
            assert (await c.submit_topology_search(spec, idempotency_key="k")).id == h.id
            await h.cancel()
            return await h.status()

    try:
        job = asyncio.run(go())
        assert job.kind == "topology-search" and job.status in ("cancelling", "cancelled"), job
        _until(lambda: httpx.get(f"{srv.url}/v1/topology-searches/{job.id}").json()["status"] == "cancelled", 120)
    finally:
        srv.__exit__()


@pytest.mark.slow
def test_restarted_topology_search_resumes_from_its_finished_cases(tmp_path: Path) -> None:
    from flexopt.service.api.settings import Settings
    from flexopt.service.jobs.store import JobStore

    spec = {**TINY, "topologies": ["R:+-", "R:+-@"], "starts": 4}  # 8 cases of a second or two each
    srv = _server(tmp_path)
    with Client(srv.url, max_retries=0) as c:
        h = c.submit_topology_search(spec)
        _until(lambda: h.status().progress.get("done", 0) >= 1)
    srv.__exit__()  # the server stops mid-search: its job process is stopped and the job requeued
    store = JobStore(Settings(data_dir=tmp_path).job_store_url(), tmp_path)
    assert store.get(h.id)["status"] == "queued", "requeued by the stopping server"
    before = _cases(tmp_path)
    assert 1 <= len(before) < 9
    srv = _server(tmp_path)
    try:
        with Client(srv.url, max_retries=0) as c:
            job = _until(lambda: (j := c.optimisation(h.id)).status in ("succeeded", "failed") and j, timeout=240)
            assert job.status == "succeeded" and job.attempts == 2, job.error
            after = _cases(tmp_path)
            # 8 search cases and the screen's (one case for both descriptors)
            assert len(after) == 9 and all(after[k] == v for k, v in before.items()), "finished cases kept"
            assert (job.progress["done"], job.progress["total"], job.progress["phase"]) == (8, 8, "full pass")
            assert job.progress["counts"]["optimised"] == 2 and job.progress["best"]["topology"] in ("R:+-", "R:+-@")
            assert job.result["best"] is not None
    finally:
        srv.__exit__()
        store.engine.dispose()
