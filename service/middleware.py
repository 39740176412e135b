"""ASGI middleware of the service: one JSON log line per request, 415 for bodies that are not JSON.

``RequestLog`` is the outermost layer (inside Starlette's own error middleware): it gives each request an id
(the client's ``X-Request-ID`` when it is a short token, else a new one), echoes it in the response, and logs
``{"event": "request", "request_id", "method", "route", "path", "status", "duration_ms"}``. An exception
that escapes the application is logged here and answered with a 500 problem body *without* being raised
again, so the server keeps the connection open (a raised exception makes uvicorn close it, and the
client's next request on that connection fails too).

``JsonLogFormatter`` writes every log record of the process as one JSON object per line; ``flexopt serve``
installs it for the ``flexopt`` and ``uvicorn`` loggers.
"""

from __future__ import annotations

import json
import logging
import re
import time
import uuid
from typing import Any

from starlette.types import ASGIApp, Message, Receive, Scope, Send

from . import errors_http

__all__ = ["JsonLogFormatter", "JsonOnly", "RequestLog", "log_config"]

log = logging.getLogger("flexopt.service.access")
_TOKEN = re.compile(r"^[A-Za-z0-9._:-]{1,100}$")
_JSON = re.compile(r"^application/([a-z0-9.+-]*\+)?json$")


class RequestLog:
    """Request id, structured access log, and no exception ever escaping to the server."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        given = dict(scope["headers"]).get(b"x-request-id", b"").decode("latin-1")
        rid = given if _TOKEN.match(given) else uuid.uuid4().hex
        scope.setdefault("state", {})["request_id"] = rid
        status, started, t0 = 500, False, time.perf_counter()

        async def send_with_id(msg: Message) -> None:
            nonlocal status, started
            if msg["type"] == "http.response.start":
                status, started = msg["status"], True
                msg["headers"] = [*msg.get("headers", []), (b"x-request-id", rid.encode())]
            await send(msg)

        try:
            await self.app(scope, receive, send_with_id)
        except Exception:  # noqa: BLE001 - logged with its traceback; the client gets a problem body
            log.exception("unhandled error", extra={"request_id": rid})
            if not started:
                await errors_http.problem(500, "internal error; the server log has the details "
                                               f"(request id {rid})")(scope, receive, send_with_id)
        finally:
            route = scope.get("route")
            log.info("request", extra={"event": "request", "request_id": rid, "method": scope["method"],
                                       "route": getattr(route, "path", None), "path": scope["path"],
                                       "status": status,
                                       "duration_ms": round(1000 * (time.perf_counter() - t0), 2)})


class JsonOnly:
    """415 for a POST/PUT/PATCH with a body whose Content-Type is not JSON (``application/json`` or ``+json``)."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["method"] not in ("POST", "PUT", "PATCH"):
            await self.app(scope, receive, send)
            return
        headers = dict(scope["headers"])
        media = headers.get(b"content-type", b"").decode("latin-1").split(";")[0].strip().lower()
        length = headers.get(b"content-length")
        has_body = b"transfer-encoding" in headers or (length is not None and length.strip() not in (b"", b"0"))
        if has_body and not _JSON.match(media):
            shown = media or "none"
            await errors_http.problem(415, f"Content-Type '{shown}' is not accepted: send the body as JSON with "
                                           "'Content-Type: application/json'")(scope, receive, send)
            return
        await self.app(scope, receive, send)


_STANDARD = set(logging.makeLogRecord({}).__dict__) | {"message", "asctime", "color_message"}


class JsonLogFormatter(logging.Formatter):
    """One JSON object per record: time, level, logger, message, the record's extra fields, the traceback."""

    def format(self, record: logging.LogRecord) -> str:
        out: dict[str, Any] = {"time": self.formatTime(record, "%Y-%m-%dT%H:%M:%S%z"), "level": record.levelname,
                               "logger": record.name, "message": record.getMessage()}
        out.update({k: v for k, v in record.__dict__.items() if k not in _STANDARD and not k.startswith("_")})
        if record.exc_info:
            out["traceback"] = self.formatException(record.exc_info)
        return json.dumps(out, default=str)


def log_config(level: str = "info") -> dict[str, Any]:
    """``logging.config.dictConfig`` form: JSON lines on stderr for flexopt and uvicorn (its access log off:
    :class:`RequestLog` writes a richer one)."""
    lvl = level.upper()
    handler = {"class": "logging.StreamHandler", "formatter": "json", "stream": "ext://sys.stderr"}
    return {"version": 1, "disable_existing_loggers": False,
            "formatters": {"json": {"()": f"{__name__}.JsonLogFormatter"}},
            "handlers": {"stderr": handler},
            "loggers": {"flexopt": {"handlers": ["stderr"], "level": lvl, "propagate": False},
                        "uvicorn": {"handlers": ["stderr"], "level": lvl, "propagate": False},
                        "uvicorn.access": {"handlers": [], "level": "WARNING", "propagate": False}}}
