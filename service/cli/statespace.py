"""``flexopt statespace``: the linearised input-output model at a stroke point (model.linear), as JSON."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from .scene_args import add_scene_arguments, scene_from_args

__all__ = ["add_parser"]


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add the ``statespace`` subcommand to an argparse subparsers object."""
    p = subparsers.add_parser("statespace", help="state-space model (A, B, C, D) about the equilibrium at a stroke")
    add_scene_arguments(p)
    p.add_argument("--at-stroke", type=float, default=0.0, metavar="VALUE", help="stroke value (stroke unit)")
    p.add_argument(
        "--input",
        action="append",
        required=True,
        metavar="NAME.fx",
        help="a force (fx, fy, fz) or moment (mx, my, mz) on a node or body; repeat for more",
    )
    p.add_argument(
        "--output",
        action="append",
        required=True,
        metavar="NAME.z",
        help="a position (x, y, z), rotation (rx, ry, rz) or rate (vx.., wx..) of a node or body",
    )
    p.add_argument("--damping", type=float, default=0.01, help="modal damping ratio of every mode (default 0.01)")
    p.add_argument("--modes", type=int, default=None, help="keep the lowest N modes (default: all)")
    p.add_argument("--bode", metavar="FMIN:FMAX:N", help="also a frequency response table (Hz, log spaced)")
    p.set_defaults(func=_cmd_statespace)
    return p


def _cmd_statespace(args: argparse.Namespace) -> int:
    import numpy as np

    from ...model.linear import frequency_response, state_space

    ss = state_space(scene_from_args(args), args.at_stroke, args.input, args.output, args.damping, args.modes)
    out = ss.to_dict()
    out["static_gain"] = ss.static_gain().tolist()
    if args.bode:
        try:
            lo, hi, n = args.bode.split(":")
            f = np.geomspace(float(lo), float(hi), int(n))
        except ValueError:
            raise ValueError(f"--bode expects FMIN:FMAX:N with 0 < FMIN < FMAX, got '{args.bode}'") from None
        mag, ph = frequency_response(ss, f)
        out["bode"] = {"frequency_hz": f.tolist(), "magnitude": mag.tolist(), "phase_deg": ph.tolist()}
    json.dump(out, sys.stdout)
    sys.stdout.write("\n")
    return 0
