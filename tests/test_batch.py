"""The batch runner (optim/batch.py) and the optimiser's batch entry point, on real model work."""

from __future__ import annotations

import threading

import pytest

from optim import optimise
from optim.batch import BatchCancelled, case_id, case_seed, run_cases
from tests.batch_cases import leaf_torsion_hz

FN = "tests.batch_cases:leaf_torsion_hz"


def _cases(tmp_path=None, n=4):
    marker = str(tmp_path) if tmp_path is not None else None
    return [{"thickness": 3e-4 + 1e-4 * i, "marker_dir": marker} for i in range(n)]


def test_pool_results_equal_the_serial_computation_in_order():
    cases = _cases()
    out = run_cases(cases, FN, workers=2)
    for c, r in zip(cases, out):
        assert r["hz"] == leaf_torsion_hz(c)["hz"], "a worker process computes exactly what the caller does"
        assert r["id"] == case_id(c)


def test_interrupted_batch_resumes_without_redoing_finished_cases(tmp_path):
    marks = tmp_path / "marks"
    marks.mkdir()
    store = tmp_path / "store"
    cases = _cases(marks)
    first = run_cases(cases[:2], FN, workers=2, store=store)  # the "interrupted" batch finished two cases
    events = []
    full = run_cases(cases, FN, workers=2, store=store, progress=events.append)
    assert len(list(marks.iterdir())) == 4, "each case ran exactly once over both batches"
    assert [e["status"] for e in events].count("skipped") == 2
    assert full[:2] == first
    assert events[-1]["done"] == events[-1]["total"] == 4


def test_failures_are_records_retried_only_on_request(tmp_path):
    marks = tmp_path / "marks"
    marks.mkdir()
    cases = [{"thickness": -1.0, "marker_dir": str(marks)}]
    out = run_cases(cases, FN, workers=1, store=tmp_path / "s")
    assert out[0]["kind"] == "ValueError" and "thickness must be positive" in out[0]["error"]
    run_cases(cases, FN, workers=1, store=tmp_path / "s")
    assert len(list(marks.iterdir())) == 1, "a stored failure is not retried by default"
    run_cases(cases, FN, workers=1, store=tmp_path / "s", retry_failed=True)
    assert len(list(marks.iterdir())) == 2


def test_case_ids_and_seeds_are_deterministic():
    a, b = {"x": 1, "y": [1, 2]}, {"y": [1, 2], "x": 1}
    assert case_id(a) == case_id(b) and case_seed(a, 7) == case_seed(b, 7)
    assert case_seed(a, 7) != case_seed(a, 8) and case_id(a) != case_id({"x": 2, "y": [1, 2]})


def test_cancel_stops_the_batch_and_keeps_finished_results():
    cancel = threading.Event()
    cancel.set()
    with pytest.raises(BatchCancelled) as info:
        run_cases(_cases(n=3), FN, workers=1, cancel=cancel)
    assert len(info.value.results) == 3


TINY = {"families": [{"template": "leaf-spring", "design": {"thickness": [3e-4, 6e-4]}}], "stroke": 20,
        "samples": 5, "starts": 2, "max_iterations": 5}


def test_optimise_runs_families_as_a_batch_and_resumes(tmp_path):
    events = []
    res = optimise(TINY, workers=2, store=tmp_path, progress=events.append)
    best = res["families"][0]["best"]
    assert best["verified"]["points"] == 181 and res["ranking"][0]["template"] == "leaf-spring"
    again = optimise(TINY, workers=2, store=tmp_path)
    assert again["ranking"] == res["ranking"], "the resumed batch reads the same stored cases"
    assert {e["status"] for e in events} == {"done"}


@pytest.mark.slow
def test_dask_local_cluster_gives_the_pool_results():
    distributed = pytest.importorskip("distributed")
    cases = _cases(n=3)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        out = run_cases(cases, FN, executor=client.get_executor())
    assert [r["hz"] for r in out] == [r["hz"] for r in run_cases(cases, FN, workers=2)]
