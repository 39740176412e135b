"""The page's security headers (issue 29 item 9), over HTTP without a browser.

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

from flexopt.service.app import create_app
from flexopt.service.settings import Settings


def _get(app: object, path: str, host: str = "127.0.0.1") -> httpx.Response:
    async def go() -> httpx.Response:
        async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url=f"http://{host}") as c:
            return await c.get(path)

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
