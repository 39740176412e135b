"""Every store that grows with the distinct scenes a server meets stays within its bound (issue 29 item 2).

A stream of distinct scenes (each a different mesh and thickness, so every request is a cache miss and a new
model) through a real server whose computations run in its own process (``executor: thread``), so that the
model's per-process stores are the test's to read: the response cache (entries and bytes), the scene hashes
of ``model.checks``, the compiled kernels (one per element kind, whatever the scenes), the mapped von Mises
Jacobians of ``model.design`` (one per beam count) and the cost estimator's topology counts. Resident memory
is measured by ``bench/bench_soak.py`` (not here: it depends on the machine).
"""

from __future__ import annotations

from pathlib import Path

import httpx
import pytest

pytest.importorskip("fastapi")

from flexopt.model import checks, design, kernels  # noqa: E402
from flexopt.service.api import cost  # noqa: E402
from flexopt.service.api.settings import Settings  # noqa: E402

from tests.test_service import _Server  # noqa: E402

ENTRIES, BYTES = 6, 40_000


@pytest.mark.slow
def test_stores_stay_within_their_bounds_over_distinct_scenes(tmp_path: Path) -> None:
    settings = Settings(executor="thread", cache_size=ENTRIES, cache_bytes=BYTES, data_dir=tmp_path)
    with _Server(settings) as srv, httpx.Client(base_url=srv.url, timeout=120) as c:
        rt = srv.server.config.app.state.runtime
        base = c.post("/v1/templates/leaf-spring/scene").json()
        base["stroke"]["points"] = 2
        kinds_after_first: int | None = None
        n_scenes = 30
        for i in range(n_scenes):
            scene = {
                **base,
                "elements": [
                    {**e, "segments": 2 + i, "section": {**e["section"], "thickness": 4e-4 * (1 + 1e-3 * i)}}
                    if "section" in e
                    else e
                    for e in base["elements"]
                ],
            }
            body = {"scene": scene, **({"shapes": True} if i % 3 == 0 else {})}
            r = c.post("/v1/frequency-curve", json=body)
            assert r.status_code == 200, r.text
            if kinds_after_first is None:
                kinds_after_first = len(kernels._CACHE)
            # the response cache: its bounds in entries and in bytes, and its byte count true
            assert len(rt.cache) <= ENTRIES and rt.cached_bytes <= BYTES, (len(rt.cache), rt.cached_bytes)
            assert rt.cached_bytes == sum(len(v) for v in rt.cache.values())
        assert len(rt.cache) >= 1, "the cache was used"
        # the scene hashes: the last 16 scenes; the kernels: one per element kind, none per scene
        assert len(checks._HASHES) <= 16
        assert kinds_after_first is not None and len(kernels._CACHE) == kinds_after_first
    # the von Mises Jacobians, one per beam count: the most recent VM_JAC_ENTRIES
    for n in range(1, design.VM_JAC_ENTRIES + 11):
        design._von_mises_jac(n)
    assert len(design._VM_JAC) == design.VM_JAC_ENTRIES
    assert list(design._VM_JAC)[-1] == design.VM_JAC_ENTRIES + 10
    # the estimator's topology counts: 16 specs
    from flexopt.optim.topology.spec import TopologySpec

    for k in range(20):
        cost.topology_estimate(TopologySpec(topologies=["R:+-", "R:++", "R:-+"][: 1 + k % 3], seed=k, starts=1 + k % 4))
        cost.topology_estimate(TopologySpec(topologies=["R:+-"] * (1 + k)))
    assert cost._candidate_shapes.cache_info().currsize <= 16
