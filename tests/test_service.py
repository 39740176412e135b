"""The HTTP service end to end: a real uvicorn on 127.0.0.1 driven by service.client."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Self

import httpx
import pytest

pytest.importorskip("fastapi")
pytest.importorskip("uvicorn")

import uvicorn  # noqa: E402
from flexopt.service.api.app import create_app, openapi_json  # noqa: E402
from flexopt.service.api.settings import Settings  # noqa: E402
from flexopt.service.client import (  # noqa: E402
    Client,
    InvalidInput,
    NotFound,
    PayloadTooLarge,
    TooManyRequests,
    Unauthorized,
)
from flexopt.service.client import ComputeTimeout as ClientTimeout  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class _Server:
    """uvicorn in a background thread on a free loopback port."""

    def __init__(self, settings: Settings) -> None:
        self.port = _free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        config = uvicorn.Config(
            create_app(settings), host="127.0.0.1", port=self.port, log_level="warning", lifespan="on", ws="none"
        )
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self.server.run, daemon=True)

    def __enter__(self) -> Self:
        self.thread.start()
        deadline = time.monotonic() + 10
        while not self.server.started:
            if time.monotonic() > deadline or not self.thread.is_alive():
                raise RuntimeError("uvicorn did not start")
            time.sleep(0.02)
        return self

    def __exit__(self, *exc: object) -> None:
        self.server.should_exit = True
        self.thread.join(10)


@pytest.fixture(scope="module")
def start(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Callable[..., _Server]]:
    """Start a server with the given settings (stopped at the end of the module); jobs in a temporary dir."""
    servers: list[_Server] = []

    def _start(**kw: object) -> _Server:
        kw.setdefault("data_dir", tmp_path_factory.mktemp("data"))
        s = _Server(Settings(**kw)).__enter__()
        servers.append(s)
        return s

    yield _start
    for s in servers:
        s.__exit__()


@pytest.fixture(scope="module")
def server(start: Callable[..., _Server]) -> _Server:
    return start()


@pytest.fixture
def client(server: _Server) -> Iterator[Client]:
    with Client(server.url, max_retries=0) as c:
        yield c


# --- endpoints ---------------------------------------------------------------------------------------------


def test_health(client: Client) -> None:
    h = client.health()
    assert h.status == "ok" and "exact" in h.methods


def test_templates(client: Client) -> None:
    names = [t.name for t in client.templates()]
    assert "leaf-spring" in names
    leaf = client.template("leaf-spring")
    p = {q.name: q for q in leaf.parameters}
    assert p["length"].default == 0.1 and p["length"].bounds.startswith("positive")
    assert p["points"].type == "integer" and "free" in p["warping"].bounds


def test_template_scene_and_curve(client: Client) -> None:
    scene = client.template_scene("leaf-spring", points=11, stroke=20.0)
    assert scene["stroke"]["points"] == 11
    curve = client.frequency_curve(scene)
    assert curve.status == "complete" and len(curve.stroke) == 11 and curve.method == "exact"
    assert all(f is not None and f > 0 for f in curve.parasitic_hz)
    # An explicit grid overrides the scene's; a second identical request is served from the LRU cache.
    curve2 = client.frequency_curve(scene, stroke=[0.0, 5.0, 10.0])
    assert curve2.stroke == [0.0, 5.0, 10.0]


def test_csv_and_png(client: Client) -> None:
    scene = client.template_scene("leaf-spring", points=5)
    csv = client.frequency_curve(scene, format="csv")
    lines = csv.strip().splitlines()
    assert lines[0].startswith("stroke_deg,parasitic_hz") and len(lines) == 6
    png = client.frequency_curve(scene, format="png")
    assert isinstance(png, bytes) and png.startswith(b"\x89PNG\r\n\x1a\n")


def test_approximate_method(client: Client) -> None:
    if "fd1" not in client.health().methods:
        pytest.skip("model.derivatives not available")
    scene = client.template_scene("leaf-spring", points=5, stroke=10.0)
    assert client.frequency_curve(scene, method="fd1").method == "fd1"


def test_diagnosis(client: Client, server: _Server) -> None:
    paths = httpx.get(f"{server.url}/openapi.json").json()["paths"]
    if "/v1/diagnosis" not in paths:
        pytest.skip("model.constraints not available")
    scene = client.template_scene("leaf-spring")
    d = client.diagnose(scene, kinematic=True)
    assert "classification" in d and d["rank"] >= 0
    with pytest.raises(InvalidInput, match="rigid") as err:  # a model error keeps its field path
        client.diagnose(scene, kinematic=False)
    assert err.value.errors[0].loc[:3] == ["body", "scene", "elements"]


# --- errors ------------------------------------------------------------------------------------------------


def test_invalid_scene_names_field(client: Client) -> None:
    scene = client.template_scene("leaf-spring")
    scene["materials"][0]["E"] = -1.0
    with pytest.raises(InvalidInput) as err:
        client.frequency_curve(scene)
    locs = [e.loc for e in err.value.errors]
    assert ["body", "scene", "materials", 0, "E"] in locs, locs
    assert "materials[0].E" in err.value.detail


def test_unknown_template_and_parameter(client: Client) -> None:
    with pytest.raises(NotFound, match="unknown template 'nope'"):
        client.template("nope")
    with pytest.raises(InvalidInput) as err:
        client.template_scene("leaf-spring", lenght=0.1)
    assert err.value.errors[0].loc == ["body", "parameters", "lenght"] and "no parameter" in err.value.detail


def test_model_too_large(client: Client) -> None:
    scene = client.template_scene("leaf-spring", segments=1000)
    with pytest.raises(InvalidInput, match="degrees of freedom"):
        client.frequency_curve(scene)


def test_method_and_stroke_checked(client: Client) -> None:
    scene = client.template_scene("leaf-spring", points=3)
    with pytest.raises(InvalidInput) as err:
        client.frequency_curve(scene, method="magic")
    assert err.value.errors[0].loc == ["body", "method"]
    with pytest.raises(InvalidInput, match="stroke"):
        client.frequency_curve(scene, stroke=[0.0] * 5000)


def test_body_too_large(start: Callable[..., _Server]) -> None:
    srv = start(max_body_bytes=2000)
    with Client(srv.url, max_retries=0) as c:
        with pytest.raises(PayloadTooLarge, match="2000 bytes"):
            c.frequency_curve({"padding": "x" * 5000})
        with pytest.raises(PayloadTooLarge):  # chunked upload without Content-Length
            c._request("POST", "/v1/frequency-curve", content=iter([b"{" + b" " * 3000, b"}"]))


def test_api_key(start: Callable[..., _Server]) -> None:
    srv = start(api_keys="k1, k2")
    with Client(srv.url, max_retries=0) as c:
        assert c.health().status == "ok"  # liveness stays open
        with pytest.raises(Unauthorized, match="X-API-Key"):
            c.templates()
    with Client(srv.url, api_key="wrong", max_retries=0) as c, pytest.raises(Unauthorized):
        c.templates()
    with Client(srv.url, api_key="k2") as c:
        assert c.templates()


def test_time_limit(start: Callable[..., _Server]) -> None:
    srv = start(request_timeout=0.02, cache_size=0)
    with Client(srv.url, max_retries=0) as c, pytest.raises(ClientTimeout, match="time limit of 0.02 s"):
        c.frequency_curve(c.template_scene("cross-spring-pivot"))


def test_concurrency_limit_429_and_retry(start: Callable[..., _Server]) -> None:
    srv = start(max_concurrent=1, max_queued=0, cache_size=0, retry_after=1)
    with Client(srv.url) as c:
        slow = c.template_scene("cross-spring-pivot", points=1001)
        fast = c.template_scene("leaf-spring", points=3)
    errors: list[BaseException] = []

    def hold() -> None:
        try:
            with Client(srv.url, max_retries=0) as c:
                c.frequency_curve(slow)
        except BaseException as exc:  # noqa: BLE001 - reported by the assertion below
            errors.append(exc)

    t = threading.Thread(target=hold)
    t.start()
    time.sleep(0.3)
    r = httpx.post(f"{srv.url}/v1/frequency-curve", json={"scene": fast})
    assert r.status_code == 429 and r.headers["retry-after"] == "1"
    assert "limit of 1 concurrent" in r.json()["detail"]
    with Client(srv.url, max_retries=0) as c, pytest.raises(TooManyRequests) as err:
        c.frequency_curve(fast)
    assert err.value.retry_after == 1.0
    # the client waits Retry-After and gets through once the slow request ends; enough retries to outlast it on
    # a loaded machine (the 1001-point pivot took 5.6 s at load 6.5 on 2 cores, where 5 retries ran out)
    with Client(srv.url, max_retries=60) as c:
        assert c.frequency_curve(fast).status == "complete"
    t.join(30)
    assert not errors


def test_queue_waits_for_a_slot(start: Callable[..., _Server]) -> None:
    srv = start(max_concurrent=1, max_queued=8, queue_timeout=20, cache_size=0)
    with Client(srv.url, max_retries=0) as c:
        scenes = [c.template_scene("leaf-spring", points=n) for n in (21, 22, 23)]
    out: list[object] = []

    def call(scene: dict) -> None:
        with Client(srv.url, max_retries=0) as c:
            out.append(c.frequency_curve(scene).status)

    threads = [threading.Thread(target=call, args=(sc,)) for sc in scenes]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert out == ["complete"] * 3  # queued behind the running one, none refused


def test_problem_details_shape(server: _Server) -> None:
    r = httpx.post(
        f"{server.url}/v1/frequency-curve", content=b"{not json", headers={"content-type": "application/json"}
    )
    assert r.status_code == 422 and r.headers["content-type"] == "application/problem+json"
    body = r.json()
    assert set(body) == {"type", "title", "status", "detail", "errors"} and body["detail"]


# --- client and schema -------------------------------------------------------------------------------------


def test_client_import_is_light() -> None:
    code = (
        "import sys, flexopt.client; "
        "bad = [m for m in ('casadi', 'fastapi', 'uvicorn', 'model', 'starlette') if m in sys.modules]; "
        "print(bad); sys.exit(1 if bad else 0)"
    )
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60, check=False)
    assert r.returncode == 0, f"importing flexopt.client loaded {r.stdout.strip()} {r.stderr}"


def test_openapi_committed_and_current() -> None:
    committed = (ROOT / "service" / "openapi.json").read_text()
    assert json.loads(committed) == json.loads(openapi_json()), (
        "service/openapi.json is stale: regenerate with `python -m flexopt.service.api.app > service/openapi.json`"
    )


def test_cli_registers_serve() -> None:
    from flexopt.service.cli.main import _parser

    args = _parser().parse_args(["serve", "--port", "8123"])
    assert args.port == 8123 and args.host == "127.0.0.1"


def test_async_client(server: _Server) -> None:
    import asyncio

    from flexopt.service.client import AsyncClient

    async def go() -> tuple[str, str]:
        async with AsyncClient(server.url) as c:
            scene = await c.template_scene("leaf-spring", points=4)
            curve = await c.frequency_curve(scene)
            with pytest.raises(NotFound):
                await c.template("nope")
            return (await c.health()).status, curve.status

    assert asyncio.run(go()) == ("ok", "complete")


def test_response_cache_is_bounded_lru() -> None:
    from flexopt.service.api.runtime import Runtime

    rt = Runtime(Settings(cache_size=2))
    for k in "abc":
        rt.store(k, k.upper())
    assert rt.cached("a") is None and rt.cached("b") == "B"  # "a" evicted; "b" now most recent
    rt.store("d", "D")
    assert list(rt.cache) == ["b", "d"]
    off = Runtime(Settings(cache_size=0))
    off.store("a", 1)
    assert off.cached("a") is None


def test_retry_honours_retry_after() -> None:
    calls: list[float] = []

    def handler(request: httpx.Request) -> httpx.Response:
        calls.append(time.monotonic())
        if len(calls) == 1:
            return httpx.Response(
                503,
                headers={"Retry-After": "0"},
                json={"title": "Service unavailable", "status": 503, "detail": "busy"},
            )
        return httpx.Response(200, json={"status": "ok", "version": "x", "api_version": "1", "methods": ["exact"]})

    with Client("http://test", transport=httpx.MockTransport(handler), backoff=5.0) as c:
        assert c.health().status == "ok"
    assert len(calls) == 2 and calls[1] - calls[0] < 1.0  # waited Retry-After (0 s), not the 5 s backoff


def test_flexopt_serve_subprocess() -> None:
    port = _free_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "flexopt.service.cli", "serve", "--port", str(port), "--log-level", "warning"], cwd=ROOT
    )
    try:
        deadline = time.monotonic() + 30
        while True:
            try:
                with Client(f"http://127.0.0.1:{port}", max_retries=0) as c:
                    assert c.health().status == "ok"
                break
            except Exception:
                if time.monotonic() > deadline or proc.poll() is not None:
                    raise
                time.sleep(0.2)
    finally:
        proc.terminate()
        proc.wait(10)


def test_units_warnings_and_provenance_over_http(client: Client, server: _Server) -> None:
    """Issue 11: unit-bearing template parameters, and warnings and provenance in HTTP answers."""
    scene = client.template_scene("cross-spring-pivot", points=3, segments=4, thickness="0.3 mm")
    assert scene["elements"][0]["section"]["thickness"] == pytest.approx(0.3e-3, rel=1e-15)
    curve = client.frequency_curve(scene)
    kinds = {w.kind for w in curve.warnings}
    assert "stress" in kinds and curve.provenance["method"] == "exact"
    assert len(curve.provenance["scene_sha256"]) == 64
    with pytest.raises(InvalidInput) as err:
        client.template_scene("leaf-spring", density=-1.0)
    assert err.value.errors[0].loc == ["body", "parameters", "density"]
    assert "template parameter 'density'" in err.value.detail and "materials" not in err.value.detail
    bad = dict(scene, materials=[dict(scene["materials"][0], density=-1.0)])
    with pytest.raises(InvalidInput) as err:
        client.frequency_curve(bad)
    assert "at least 1 item" not in err.value.detail, err.value.detail
    r = httpx.get(f"{server.url}/v1/templates/leaf-sprng")
    assert r.status_code == 404 and "did you mean 'leaf-spring'" in r.json()["detail"]
