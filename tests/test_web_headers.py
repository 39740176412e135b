"""The page's security headers and the Host allow-list (issue 29 item 9), over HTTP without a browser.

The page keeps an API key in localStorage: its responses carry a Content-Security-Policy that runs only
scripts from this origin (no inline script, no eval) and forbids framing (clickjacking), with
``X-Frame-Options: DENY`` for browsers without CSP level 2. That the page works under this policy is checked
in a real browser (tests/test_web.py: no ``securitypolicyviolation`` while it draws curves and 3D views).
"""

from __future__ import annotations

import asyncio
from pathlib import Path

import httpx
import pytest
from flexopt.service.api.app import create_app
from flexopt.service.api.settings import Settings


def _get(app: object, path: str, host: str = "127.0.0.1") -> httpx.Response:
    async def go() -> httpx.Response:
        async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://127.0.0.1") as c:
            return await c.get(path, headers={"Host": host})

    return asyncio.run(go())


@pytest.fixture(scope="module")
def app(tmp_path_factory: pytest.TempPathFactory) -> object:
    return create_app(Settings(executor="thread", api_keys="", data_dir=tmp_path_factory.mktemp("data")))


def _directives(csp: str) -> dict[str, list[str]]:
    out = {}
    for part in csp.split(";"):
        words = part.split()
        if words:
            out[words[0]] = words[1:]
    return out


@pytest.mark.parametrize("path", ["/", "/static/app.js", "/static/vendor/plotly/LICENSE"])
def test_page_and_assets_carry_csp_and_frame_blocking(app: object, path: str) -> None:
    r = _get(app, path)
    assert r.status_code == 200
    csp = _directives(r.headers["content-security-policy"])
    assert csp["frame-ancestors"] == ["'none'"], "the page can be framed"
    assert csp["script-src"] == ["'self'"], "inline or foreign scripts would run"
    assert csp["object-src"] == ["'none'"] and csp["base-uri"] == ["'none'"]
    assert csp["default-src"] == ["'self'"] and csp["connect-src"] == ["'self'"]
    assert r.headers["x-frame-options"] == "DENY"
    assert r.headers["x-content-type-options"] == "nosniff"


def test_page_has_no_inline_script() -> None:
    """script-src 'self' blocks inline script: the page must not need any (its script is /static/app.js)."""
    from flexopt.service.web import STATIC

    html = (Path(STATIC) / "index.html").read_text()
    low = html.lower()
    assert low.count("<script") == low.count("<script src=") == 2, "an inline <script> or one without src"
    for attr in ("onclick=", "onload=", "onerror=", "onchange=", "javascript:"):
        assert attr not in low, f"inline handler {attr}"


@pytest.mark.parametrize("host", ["localhost", "localhost:8000", "127.0.0.1:8000", "[::1]:8000", "LOCALHOST"])
def test_loopback_hosts_are_served_by_default(app: object, host: str) -> None:
    assert _get(app, "/health", host).status_code == 200


@pytest.mark.parametrize(
    "host",
    [
        "attacker.example",
        "attacker.example:8000",
        "127.0.0.1.attacker.example",
        "localhost.attacker.example:80",
        "",
        "[::2]:8000",
    ],
)
def test_other_hosts_get_400_naming_the_setting(app: object, host: str) -> None:
    """DNS rebinding: a page on attacker.example, its name re-pointed at 127.0.0.1, sends Host attacker.example."""
    for path in ("/", "/health", "/v1/templates", "/static/app.js"):
        r = _get(app, path, host)
        assert r.status_code == 400, (path, host, r.status_code)
        assert r.headers["content-type"] == "application/problem+json"
        assert "FLEXOPT_ALLOWED_HOSTS" in r.json()["detail"]


def test_allowed_hosts_setting(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("FLEXOPT_ALLOWED_HOSTS", "flexopt.example.com, *.lab.example")
    app = create_app(Settings(executor="thread", api_keys="", data_dir=tmp_path))
    assert _get(app, "/health", "flexopt.example.com:8000").status_code == 200
    assert _get(app, "/health", "node3.lab.example").status_code == 200
    assert _get(app, "/health", "lab.example.evil").status_code == 400
    assert _get(app, "/health", "localhost").status_code == 400, "the setting replaces the default"
    anyhost = create_app(Settings(executor="thread", api_keys="", data_dir=tmp_path, allowed_hosts="*"))
    assert _get(anyhost, "/health", "whatever.example").status_code == 200


def test_host_name() -> None:
    from flexopt.service.api.middleware import host_name

    assert host_name("[::1]:8000") == "[::1]" and host_name("[::1]") == "[::1]"
    assert host_name("Example.COM:443") == "example.com" and host_name("example.com") == "example.com"


@pytest.mark.parametrize("path", ["/docs", "/redoc", "/health", "/openapi.json", "/v1/templates"])
def test_every_answer_forbids_framing(app: object, path: str) -> None:
    """The API docs pages run inline scripts (no strict policy there) but are not framed either."""
    r = _get(app, path)
    assert r.status_code == 200
    assert r.headers["x-frame-options"] == "DENY"
    assert _directives(r.headers["content-security-policy"])["frame-ancestors"] == ["'none'"]
    assert r.headers["x-content-type-options"] == "nosniff"
    assert _get(app, path, "attacker.example").headers["x-frame-options"] == "DENY"
