"""The web page at ``/``: a single page for engineers who will not write code, calling the same ``/v1`` API.

Every asset is served from this package (``static/``; vendored JavaScript with its licence in
``static/vendor/``), so the page works without internet. :func:`install` adds ``GET /`` and the static mount.
"""

from __future__ import annotations

from pathlib import Path

from fastapi import FastAPI
from fastapi.responses import FileResponse
from fastapi.staticfiles import StaticFiles

__all__ = ["install", "STATIC"]

STATIC = Path(__file__).parent / "static"


def install(app: FastAPI) -> None:
    """Serve the page at ``/`` and its assets under ``/static``."""
    app.mount("/static", StaticFiles(directory=STATIC), name="static")

    @app.get("/", include_in_schema=False)
    async def index() -> FileResponse:
        return FileResponse(STATIC / "index.html", media_type="text/html")
