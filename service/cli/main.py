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

from . import curve, diagnose, modes, optimise, serve, spacar, statespace, template, topology

__all__ = ["main"]

#: the subcommands, in the order ``flexopt --help`` lists them
COMMANDS = (template, curve, diagnose, modes, statespace, serve, optimise, topology, spacar)


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="flexopt", description="Large-stroke flexure design: frequency curves "
                                "over the stroke of SPACAR-style flexure models.")
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
