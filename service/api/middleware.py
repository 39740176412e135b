"""ASGI middleware of the service: one JSON log line per request, 413 for bodies too large, 415 for bodies that
are not JSON.

``RequestLog`` is the outermost layer (inside Starlette's own error middleware): it gives each request an id
(the client's ``X-Request-ID`` when it is a short token, else a new one), echoes it in the response, and logs
``{"event": "request", "request_id", "method", "route", "path", "status", "duration_ms"}``. An exception
that escapes the application is logged here and answered with a 500 problem body *without* being raised
again, so the server keeps the connection open (a raised exception makes uvicorn close it, and the
client's next request on that connection fails too).

``AllowedHosts`` answers 400 for a Host header not in the settings' allow-list (default the loopback names):
a page from another origin whose name an attacker re-points at 127.0.0.1 (DNS rebinding) sends its own
name as Host, so it cannot reach a local server, keyless or not.

``FrameBlock`` forbids framing every response (``X-Frame-Options: DENY`` and, where the response sets no
policy of its own, ``Content-Security-Policy: frame-ancestors 'none'``), the API docs pages included; the web
page sets its full policy itself (:mod:`service.web`).

``BodyLimit`` answers 413 for a body larger than the limit, declared or streamed. The JSON log lines
themselves are written by :mod:`service.logs`.
"""

from __future__ import annotations

import asyncio
import logging
import re
import time
import uuid

from starlette.types import ASGIApp, Message, Receive, Scope, Send

from . import errors

__all__ = ["AllowedHosts", "BodyLimit", "FrameBlock", "JsonOnly", "RequestLog", "host_name"]

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
                await errors.problem(500, f"internal error; the server log has the details (request id {rid})")(
                    scope, receive, send_with_id
                )
        finally:
            route = scope.get("route")
            log.info(
                "request",
                extra={
                    "event": "request",
                    "request_id": rid,
                    "method": scope["method"],
                    "route": getattr(route, "path", None),
                    "path": scope["path"],
                    "status": status,
                    "duration_ms": round(1000 * (time.perf_counter() - t0), 2),
                },
            )


def host_name(header: str) -> str:
    """The host of a Host header without its port, lower case (``[::1]:8000`` -> ``[::1]``)."""
    h = header.strip().lower()
    if h.startswith("["):
        return h[: h.find("]") + 1] if "]" in h else h
    return h.rsplit(":", 1)[0] if h.count(":") == 1 else h


class AllowedHosts:
    """400 for a request whose Host header names a host not in ``hosts`` (``*.domain`` matches subdomains,
    ``*`` anything); lifespan and websocket scopes of allowed hosts pass unchanged."""

    def __init__(self, app: ASGIApp, hosts: tuple[str, ...]) -> None:
        self.app = app
        self.any = "*" in hosts
        self.exact = frozenset(h for h in hosts if not h.startswith("*"))
        self.suffixes = tuple(h[1:] for h in hosts if h.startswith("*."))
        self.shown = ", ".join(hosts)

    def allows(self, host: str) -> bool:
        return self.any or host in self.exact or (bool(host) and host.endswith(self.suffixes))

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket") or self.any:
            await self.app(scope, receive, send)
            return
        raw = dict(scope["headers"]).get(b"host", b"").decode("latin-1")
        host = host_name(raw)
        if self.allows(host):
            await self.app(scope, receive, send)
            return
        shown = (raw[:100] + "...") if len(raw) > 100 else raw
        what = f"host '{shown}' is not served here" if raw else "the request has no Host header"
        await errors.problem(
            400,
            f"{what}: this server answers to {self.shown}; add the name clients use to "
            "FLEXOPT_ALLOWED_HOSTS (comma-separated) to serve it",
        )(scope, receive, send)


class FrameBlock:
    """No page of this server in a frame (clickjacking); ``nosniff`` so no response is read as another type."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def send_blocked(msg: Message) -> None:
            if msg["type"] == "http.response.start":
                headers = list(msg.get("headers", []))
                names = {k.lower() for k, _ in headers}
                for name, value in (
                    (b"x-frame-options", b"DENY"),
                    (b"x-content-type-options", b"nosniff"),
                    (b"content-security-policy", b"frame-ancestors 'none'"),
                ):
                    if name not in names:
                        headers.append((name, value))
                msg = {**msg, "headers": headers}
            await send(msg)

        await self.app(scope, receive, send_blocked)


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
            await errors.problem(
                415,
                f"Content-Type '{shown}' is not accepted: send the body as JSON with 'Content-Type: application/json'",
            )(scope, receive, send)
            return
        await self.app(scope, receive, send)


class BodyLimit:
    """ASGI middleware: 413 for request bodies larger than ``limit`` bytes (declared or streamed), 408 for a
    body not received within ``timeout`` seconds. Both close the connection (``Connection: close``): before
    (issue 29 item 8), a 50 MB chunked upload was read to its end (145 s) behind its 413, and a client that
    sent its body slowly, or never, held its connection open for good."""

    def __init__(self, app: ASGIApp, limit: int, timeout: float = 30.0) -> None:
        self.app = app
        self.limit = limit
        self.timeout = timeout

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        close = {"Connection": "close"}
        too_large = errors.problem(413, f"request body larger than the limit of {self.limit} bytes", headers=close)
        declared = dict(scope["headers"]).get(b"content-length")
        if declared is not None and declared.isdigit() and int(declared) > self.limit:
            await too_large(scope, receive, send)
            return
        body = bytearray()
        deadline = asyncio.get_running_loop().time() + self.timeout
        while True:
            try:
                msg = await asyncio.wait_for(receive(), max(0.0, deadline - asyncio.get_running_loop().time()))
            except TimeoutError:
                await errors.problem(
                    408, f"the request body was not received within {self.timeout:g} s; send it at once", headers=close
                )(scope, receive, send)
                return
            if msg["type"] == "http.disconnect":
                return
            body += msg.get("body", b"")
            if len(body) > self.limit:
                await too_large(scope, receive, send)
                return
            if not msg.get("more_body", False):
                break
        replayed = False

        async def replay() -> Message:
            nonlocal replayed
            if not replayed:
                replayed = True
                return {"type": "http.request", "body": bytes(body), "more_body": False}
            return await receive()

        await self.app(scope, replay, send)
