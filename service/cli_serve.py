"""``flexopt serve``: run the HTTP service with uvicorn (imported only when this subcommand runs)."""

from __future__ import annotations

import argparse

__all__ = ["add_parser"]


def _cmd_serve(args: argparse.Namespace) -> int:
    import uvicorn

    from .app import create_app

    uvicorn.run(create_app(), host=args.host, port=args.port, log_level=args.log_level)
    return 0


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """Register the ``serve`` subcommand."""
    s = subparsers.add_parser("serve", help="run the HTTP service (settings from FLEXOPT_* environment variables)")
    s.add_argument("--host", default="127.0.0.1", help="interface to listen on (0.0.0.0 in a container)")
    s.add_argument("--port", type=int, default=8000, help="TCP port")
    s.add_argument("--log-level", default="info", choices=["critical", "error", "warning", "info", "debug"])
    s.set_defaults(func=_cmd_serve)
