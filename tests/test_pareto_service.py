"""Pareto fronts over HTTP: ``/v1/pareto-fronts`` as jobs in the job store (a real uvicorn on 127.0.0.1, the real
front), validation at submission naming the field under ``problem``, the case store."""

from __future__ import annotations

from pathlib import Path

import httpx
import pytest

pytest.importorskip("fastapi")
pytest.importorskip("sqlalchemy")

from flexopt.optim.pareto import ParetoSpec, example_spec  # noqa: E402

from tests.test_jobs import _cases, _server, _until  # noqa: E402

# one leaf's thickness, the two single-objective optima only: a few seconds
TINY = {
    "problem": {
        "families": [{"template": "leaf-spring", "design": {"thickness": [3e-4, 6e-4]}, "fixed": {"segments": 4}}],
        "stroke": 20,
        "samples": 5,
        "starts": 1,
        "verify_points": 31,
        "max_iterations": 10,
    },
    "points": 2,
}


@pytest.mark.slow
def test_pareto_front_job_over_http(tmp_path: Path) -> None:
    srv = _server(tmp_path)
    http = httpx.Client(base_url=srv.url, timeout=60)  # the first check imports the model on a loaded machine
    try:
        ex = http.get("/v1/pareto-fronts/example")
        assert ex.status_code == 200 and ex.json() == ParetoSpec.model_validate(example_spec()).model_dump(mode="json")
        bad = {**TINY, "problem": {**TINY["problem"], "families": [{"template": "no-such", "design": {"x": [0, 1]}}]}}
        r = http.post("/v1/pareto-fronts", json=bad)
        assert r.status_code == 422 and r.json()["errors"][0]["loc"][:4] == ["body", "problem", "families", 0], r.text
        r = http.post("/v1/pareto-fronts", json={**TINY, "points": 1})
        assert r.status_code == 422 and r.json()["errors"][0]["loc"][:2] == ["body", "points"], r.text
        assert http.get("/v1/pareto-fronts").json()["total"] == 0

        r = http.post("/v1/pareto-fronts", json=TINY)
        assert r.status_code == 202 and r.json()["kind"] == "pareto-front"
        job_id = r.json()["id"]
        job = _until(
            lambda: (
                (j := http.get(f"/v1/pareto-fronts/{job_id}").json())["status"] in ("succeeded", "failed", "cancelled")
                and j
            ),
            timeout=180,
        )
        assert job["status"] == "succeeded", job
        pts = sorted(job["result"]["points"], key=lambda p: p["drive_stiffness"])
        assert len(pts) == 2 and pts[0]["worst_hz"] < pts[1]["worst_hz"]
        assert job["result"]["drive_stiffness_unit"] == "N m/rad"
        assert http.get("/v1/pareto-fronts").json()["total"] == 1
        # the progress names the phase (the two optima are the whole front of 2 points), and each finished case's
        # summary carries its kind and verified drive stiffness: the result's two ends
        assert job["progress"]["phase"] == "optima", job["progress"]
        ends = {"max_frequency": job["result"]["max_frequency"], "min_drive": job["result"]["min_drive_stiffness"]}
        assert sorted(p["kind"] for p in job["partial"]) == sorted(ends)
        for p in job["partial"]:
            assert p["phase"] == "optima" and p["status"] == "optimal"
            assert (p["drive_stiffness"], p["worst_hz"]) == (
                ends[p["kind"]]["drive_stiffness"],
                ends[p["kind"]]["worst_hz"],
            )
        ids = {p["id"] for p in job["partial"]}
        assert len(ids) == 2 and {f"{i}.json" for i in ids} <= set(_cases(tmp_path)), "both optima, recorded"
        assert http.delete(f"/v1/pareto-fronts/{job_id}").json()["status"] == "succeeded"
        assert http.get(f"/v1/pareto-fronts/{job_id}").status_code == 404
        assert not {f"{i}.json" for i in ids} & set(_cases(tmp_path)), "and removed with the job"
    finally:
        http.close()
        srv.__exit__()
