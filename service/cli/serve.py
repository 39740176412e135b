"""``flexopt serve``: run the HTTP service with uvicorn (imported only when this subcommand runs)."""

from __future__ import annotations

import argparse

__all__ = ["add_parser", "head_timeout_protocol"]


def head_timeout_protocol(seconds: float) -> type:
    """uvicorn's h11 protocol with a deadline for each request's head: a connection that has not sent a
    complete request line and headers ``seconds`` after it opened (or after its last response) is closed.
    uvicorn itself closes idle keep-alive connections but never one that trickles its headers or sends
    nothing at all (issue 29 item 8: 350 slow connections stayed open). Request bodies have their own
    deadline (``FLEXOPT_BODY_TIMEOUT``, ``api.middleware.BodyLimit``)."""
    from uvicorn.protocols.http.h11_impl import H11Protocol

    class HeadTimeoutProtocol(H11Protocol):
        _head_timer = None

        def connection_made(self, transport):  # type: ignore[no-untyped-def]
            super().connection_made(transport)
            self._arm()

        def on_response_complete(self) -> None:
            super().on_response_complete()
            self._arm()

        def connection_lost(self, exc: Exception | None) -> None:
            if self._head_timer is not None:
                self._head_timer.cancel()
            super().connection_lost(exc)

        def _arm(self) -> None:
            if self._head_timer is not None:
                self._head_timer.cancel()
            self._head_timer = self.loop.call_later(seconds, self._expired)

        def _expired(self) -> None:
            if self.cycle is None or self.cycle.response_complete:  # no request in progress: its head is late
                self.transport.close()

    return HeadTimeoutProtocol


def _cmd_serve(args: argparse.Namespace) -> int:
    import sys

    import uvicorn

    from ..api.app import create_app
    from ..api.settings import Settings
    from ..jobs.store import JobStore, StoreCorrupt
    from ..logs import log_config

    settings = Settings()
    if args.host not in ("0.0.0.0", "::", "") and args.host.lower() not in settings.hosts():  # a named interface
        settings.allowed_hosts += f",{f'[{args.host}]' if ':' in args.host else args.host}"  # answers to its name
    try:  # refuse a corrupt or unreachable job store before listening, with one line naming it and the fix
        JobStore(settings.job_store_url(), settings.data_dir, settings.lease_seconds).engine.dispose()
    except StoreCorrupt as exc:
        print(f"flexopt serve: {exc}", file=sys.stderr)
        return 2
    # JSON log lines (request id, route, status, duration; job events). A stopping server gives requests
    # 3 s to end; job processes get settings.job_stop_timeout more (see Dockerfile's stop grace).
    shown = "127.0.0.1" if args.host in ("0.0.0.0", "::") else args.host
    shown = f"[{shown}]" if ":" in shown else shown
    print(
        f"flexopt serve: the page at http://{shown}:{args.port}/ (API documentation at /docs); Ctrl+C stops",
        file=sys.stderr,
        flush=True,
    )
    uvicorn.run(
        create_app(settings),
        host=args.host,
        port=args.port,
        log_level=args.log_level,
        log_config=log_config(args.log_level),
        access_log=False,
        timeout_graceful_shutdown=3,
        http=head_timeout_protocol(settings.head_timeout),
    )
    return 0


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """Register the ``serve`` subcommand."""
    s = subparsers.add_parser("serve", help="run the HTTP service (settings from FLEXOPT_* environment variables)")
    s.add_argument(
        "--host",
        default="127.0.0.1",
        help="interface to listen on (0.0.0.0 in a container; the "
        "Host names the server answers to are FLEXOPT_ALLOWED_HOSTS, default the loopback names, plus "
        "this address when it is a specific one)",
    )
    s.add_argument("--port", type=int, default=8000, help="TCP port")
    s.add_argument("--log-level", default="info", choices=["critical", "error", "warning", "info", "debug"])
    s.set_defaults(func=_cmd_serve)
