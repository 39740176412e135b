"""``flexopt diagnose``: exact-constraint diagnosis of a scene (D_cc, its SVD, Table 1 of seed 002).

Registered by service.cli.main through :func:`add_parser`; imports the model lazily.
"""

from __future__ import annotations

import argparse
import json
from typing import Any

__all__ = ["add_parser", "plot_diagnosis"]


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add the ``diagnose`` subcommand to an argparse subparsers object."""
    d = subparsers.add_parser("diagnose", help="exact-constraint diagnosis: D_cc rank, free motions, self-stresses")
    from .scene_args import add_scene_arguments

    add_scene_arguments(d)
    d.add_argument(
        "--at-stroke",
        type=float,
        default=None,
        metavar="VALUE",
        help="diagnose the equilibrium at this stroke value (stroke unit); default: the reference",
    )
    d.add_argument(
        "--kinematic",
        dest="kinematic",
        action="store_true",
        default=None,
        help="kinematic idealisation (flexures keep only compliant deformations)",
    )
    d.add_argument(
        "--declared",
        dest="kinematic",
        action="store_false",
        help="use the scene's declared rigid deformations, not the kinematic idealisation",
    )
    d.add_argument("--json", action="store_true", help="print a JSON object")
    d.add_argument("--plot", metavar="FILE.png", help="draw the structure, free motions and self-stresses")
    d.set_defaults(func=_cmd_diagnose)
    return d


def _cmd_diagnose(args: argparse.Namespace) -> int:
    import sys

    from ...model.diagnosis import diagnose
    from .scene_args import scene_from_args

    imported = None
    if args.scene is not None and str(args.scene).lower().endswith(".dat"):  # a SPACAR model: its own counts too
        from ...model.io import load_dat

        scene, imported = load_dat(args.scene)
    else:
        scene = scene_from_args(args)
    text = imported.text if imported is not None else None
    diag = diagnose(scene, at_stroke=args.at_stroke, kinematic=args.kinematic, spacar_text=text)
    if args.json:
        print(json.dumps(diag.to_dict(), indent=2))
    else:
        print(diag.report())
    if args.plot:
        plot_diagnosis(scene, diag, args.plot)
        print(f"plot written to {args.plot}", file=sys.stderr)
    return 0


def plot_diagnosis(scene: Any, diag: Any, path: str) -> None:
    """Draw the structure, its free motions (translations and rotations) and the first self-stress (colour
    bar): :func:`service.plots.diagnosis_figure`."""
    from .. import plots

    plots.save(plots.diagnosis_figure(scene.model_dump(mode="json"), diag.to_dict()), path, dpi=110)
