"""The web page at ``/``: a single page for engineers who will not write code, calling the same ``/v1`` API.

Every asset is served from this package (``static/``; vendored JavaScript with its licence in
``static/vendor/``), so the page works without internet. :func:`install` adds ``GET /`` and the static mount.

The page and its assets carry a Content-Security-Policy (scripts and connections to this origin only, no inline
script, no plugins, no framing) and ``X-Frame-Options: DENY``: the page keeps an API key in localStorage, so a
script injected through server text, or a page framing it (clickjacking), must find nothing to run or to click.
Inline styles stay allowed: plotly.js sets style attributes on the SVG it draws.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from fastapi import FastAPI
from fastapi.responses import FileResponse
from fastapi.staticfiles import StaticFiles
from starlette.responses import Response

__all__ = ["CSP", "SECURITY_HEADERS", "STATIC", "install"]

STATIC = Path(__file__).parent / "static"

#: The page's policy: everything from this origin; data:/blob: images for plotly's exports; no inline script.
CSP = (
    "default-src 'self'; script-src 'self'; style-src 'self' 'unsafe-inline'; img-src 'self' data: blob:; "
    "font-src 'self' data:; connect-src 'self'; worker-src 'self' blob:; object-src 'none'; base-uri 'none'; "
    "form-action 'self'; frame-ancestors 'none'"
)

#: Headers on the page and on every static asset.
SECURITY_HEADERS = {
    "Content-Security-Policy": CSP,
    "X-Frame-Options": "DENY",
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
}


class _Static(StaticFiles):
    """Static files with :data:`SECURITY_HEADERS` (a licence page under /static is a document too)."""

    async def get_response(self, path: str, scope: Any) -> Response:
        response = await super().get_response(path, scope)
        response.headers.update(SECURITY_HEADERS)
        return response


def install(app: FastAPI) -> None:
    """Serve the page at ``/`` and its assets under ``/static``."""
    app.mount("/static", _Static(directory=STATIC), name="static")

    @app.get("/", include_in_schema=False)
    async def index() -> FileResponse:
        return FileResponse(STATIC / "index.html", media_type="text/html", headers=SECURITY_HEADERS)
