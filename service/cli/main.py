"""The ``flexopt`` command line: the parser and :func:`main`; one module per subcommand, each registering
itself with ``add_parser(subparsers)`` and importing the model, optim or the web stack only when it runs, so
``flexopt curve`` never loads FastAPI.

Exit codes: 0 success, 1 the analysis ran but could not finish the stroke (truncated curve), 2 bad input,
3 (``curve --strict``) the result carries a warning of kind stress, validity or units (takes precedence over 1),
4 (``optimise --scheduler``) the cluster has no workers.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from . import curve, diagnose, modes, optimise, pareto, serve, spacar, statespace, template, topology

__all__ = ["main"]

#: the subcommands, in the order ``flexopt --help`` lists them
COMMANDS = (template, curve, diagnose, modes, statespace, serve, optimise, topology, pareto, spacar)


class _Version(argparse.Action):
    """``--version``: the installed package's version, looked up only when asked (importlib.metadata costs
    about 35 ms)."""

    def __init__(self, option_strings: Sequence[str], dest: str, **kw: object) -> None:
        super().__init__(option_strings, dest, nargs=0, help="print flexopt's version and exit")

    def __call__(self, parser: argparse.ArgumentParser, *_: object) -> None:
        import flexopt

        print(f"flexopt {flexopt.__version__}")
        parser.exit()


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="flexopt",
        description="Large-stroke flexure design: frequency curves over the stroke of SPACAR-style flexure models.",
    )
    p.add_argument("--version", action=_Version)
    sub = p.add_subparsers(dest="command", required=True)
    for command in COMMANDS:
        command.add_parser(sub)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit code."""
    parser = _parser()
    args = parser.parse_args(argv)
    from ...model.errors import FlexoptError
    from ...model.threads import limit_process

    try:
        limit_process()  # one BLAS thread for this whole command and its children (model.threads)
        return int(args.func(args))
    except BrokenPipeError:  # the reader went away (e.g. `| head`): no traceback
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except FlexoptError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
