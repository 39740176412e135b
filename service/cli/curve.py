"""``flexopt curve``: stroke-dependent natural frequencies of a scene (table, JSON, CSV, plot).

Exit codes: 0 complete, 1 truncated (the analysis could not finish the stroke), 3 with ``--strict`` when the
result carries a warning of a strict kind (takes precedence over 1).
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from ..._methods import METHODS
from .scene_args import add_scene_arguments, scene_from_args

__all__ = ["add_parser"]


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add the ``curve`` subcommand to an argparse subparsers object."""
    c = subparsers.add_parser("curve", help="stroke-dependent natural frequencies of a scene")
    add_scene_arguments(c, "leaf-spring")
    fmt = c.add_mutually_exclusive_group()
    fmt.add_argument("--json", action="store_true", help="print a JSON object")
    fmt.add_argument("--csv", action="store_true", help="print CSV")
    c.add_argument("--plot", metavar="FILE.png", help="draw frequency against stroke")
    c.add_argument(
        "--log-frequency",
        action="store_true",
        help="logarithmic frequency axis in --plot (default: chosen when modes span > 8x)",
    )
    c.add_argument("--progress", action="store_true", help="show progress on stderr even when not a terminal")
    c.add_argument(
        "--method",
        choices=METHODS,
        default="exact",
        help="exact (continuation + eigen), Taylor fd1/fd2, quadratic manifold, reduced, hermite, or auto",
    )
    c.add_argument(
        "--tolerance",
        type=float,
        default=0.01,
        help="relative error allowed on the first parasitic frequency (for --method hermite and auto)",
    )
    c.add_argument(
        "--strict", action="store_true", help="exit 3 when the result has a warning of kind stress, validity or units"
    )
    c.set_defaults(func=_cmd_curve)
    return c


class _Progress:
    """A one-line progress indication on stderr for runs longer than a second."""

    def __init__(self, enabled: bool) -> None:
        import time

        self.enabled = enabled
        self.t0 = time.perf_counter()
        self.shown = False

    def __call__(self, done: int, total: int) -> None:
        import time

        if self.enabled and (self.shown or time.perf_counter() - self.t0 > 1.0):
            self.shown = True
            print(f"\rcurve: {done}/{total} stroke points", end="", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.shown:
            print(file=sys.stderr)


def _plot(curve, path: str, scene=None, log: bool | None = None) -> None:
    from .. import plots

    plots.save(plots.curve_figure(curve, None if scene is None else scene.model_dump(mode="json"), log), path)


def _cmd_curve(args: argparse.Namespace) -> int:
    from ...model import Analysis
    from ...model.checks import STRICT_KINDS

    scene = scene_from_args(args, "leaf-spring")
    progress = _Progress(args.progress or sys.stderr.isatty())
    if args.method == "exact":
        curve = Analysis(scene).frequency_curve(progress=progress)
    else:
        from ...model.curve import curve_with_method

        curve = curve_with_method(Analysis(scene), args.method, args.tolerance)
    progress.close()
    if args.json:
        print(curve.to_json())
    elif args.csv:
        print(curve.to_csv(), end="")
    else:
        print(curve.table())
    if args.plot:
        _plot(curve, args.plot, scene, True if args.log_frequency else None)
        print(f"plot written to {args.plot}", file=sys.stderr)
    for f in curve.failures:
        print(f"warning: curve truncated: {f.message}", file=sys.stderr)
    if args.json or args.csv:  # the table shows them; JSON carries them too, CSV cannot
        for w in curve.warnings:
            print(f"warning [{w.kind}]: {w.message}", file=sys.stderr)
    if args.strict and any(w.kind in STRICT_KINDS for w in curve.warnings):
        return 3
    return 0 if curve.status == "complete" else 1
