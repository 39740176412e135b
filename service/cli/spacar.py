"""``flexopt import MODEL.dat`` and ``flexopt export SCENE --to dat``: SPACAR models in and out (model.spacar)."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from .scene_args import add_scene_arguments, scene_from_args

__all__ = ["add_parser"]


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add the ``import`` and ``export`` subcommands to an argparse subparsers object."""
    i = subparsers.add_parser("import", help="read a SPACAR .dat model and print it as a scene JSON")
    i.add_argument("model", help="SPACAR .dat file")
    i.add_argument("--name", help="scene name (default: the file's stem)")
    i.add_argument("--quiet", action="store_true", help="no import report on stderr")
    i.set_defaults(func=_cmd_import)
    e = subparsers.add_parser("export", help="write a scene as a SPACAR .dat model (stdout)")
    add_scene_arguments(e)
    e.add_argument("--to", choices=["dat"], default="dat", help="the format (dat: SPACAR input file)")
    e.add_argument(
        "--numbering",
        type=int,
        choices=[2, 3],
        default=2,
        help="SPACAR nodes per point: 2 (X 2i-1, R 2i) or 3 (X 3i-2, R 3i-1, as SPACAR Light)",
    )
    e.add_argument(
        "--warping",
        choices=["factor", "beamw"],
        default="factor",
        help="constrained warping as BEAM with GJ times the member's Vlasov factor (factor: SPACAR computes "
        "flexopt's model) or as BEAMW with warping nodes, EIw and the clamped ends' warping nodes fixed (beamw: "
        "three-node numbering; docs: SPACAR models)",
    )
    e.set_defaults(func=_cmd_export)
    return i


def _cmd_import(args: argparse.Namespace) -> int:
    from ...model.io import load_dat

    scene, imp = load_dat(args.model, args.name)
    print(scene.model_dump_json(indent=2))
    if not args.quiet:
        mapped = ", ".join(f"{k} {v}" for k, v in sorted(imp.mapped.items()))
        print(
            f"# imported {args.model}: {mapped}; node numbering: {imp.numbering}; SPACAR degrees of freedom "
            f"(inputs and dynamic deformations): {imp.spacar_dof}",
            file=sys.stderr,
        )
        for note in imp.notes:
            print(f"# note: {note}", file=sys.stderr)
        from ...model.spacar_dcc import spacar_dcc

        d = spacar_dcc(imp.text)
        cond = d.condition_number
        print(
            f"# SPACAR's D_cc (its variables, SI, at the reference; docs: SPACAR models): {d.m} x {d.n}, rank "
            f"{d.rank}, condition number {cond:.6g}: {d.verdict}",
            file=sys.stderr,
        )
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    from ...model.spacar import write_dat

    sys.stdout.write(write_dat(scene_from_args(args), numbering=args.numbering, warping=args.warping))
    return 0
