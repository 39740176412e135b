"""``flexopt pareto``: the Pareto front of worst-case parasitic frequency against drive stiffness (optim/pareto.py).

Registered by service.cli.main through :func:`add_parser`; imports optim lazily.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from .optimise import SCHEDULER_HELP

__all__ = ["add_parser"]


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add the ``pareto`` subcommand to an argparse subparsers object."""
    o = subparsers.add_parser("pareto", help="Pareto front: worst-case parasitic frequency against drive stiffness")
    o.add_argument("spec", nargs="?", help="front spec JSON (format flexopt-pareto; see --example)")
    o.add_argument("--example", action="store_true", help="print a small spec and exit")
    o.add_argument("--workers", type=int, default=None, help="local worker processes (default: CPU count)")
    o.add_argument("--scheduler", metavar="ADDRESS", help=SCHEDULER_HELP)
    o.add_argument("--store", metavar="DIR", help="write each finished case here; rerun to resume")
    o.add_argument("--json", action="store_true", help="print the whole result as JSON")
    o.add_argument("--plot", metavar="FILE.png", help="the front: worst case against drive stiffness")
    o.set_defaults(func=_cmd_pareto)
    return o


def _cmd_pareto(args: argparse.Namespace) -> int:
    from ...optim.pareto import ParetoSpec, example_spec
    from .optimise import executor_for, read_spec

    if args.example:
        print(json.dumps(example_spec(), indent=2))
        return 0
    if args.spec is None:
        raise ValueError("give a spec file (flexopt pareto --example > spec.json) or --example")
    spec = read_spec(args.spec, ParetoSpec)
    from ...optim.batch import NoWorkers
    from ...optim.pareto import pareto

    executor = executor_for(args.scheduler)
    try:
        result = pareto(spec, executor=executor, workers=args.workers, store=args.store)
    except NoWorkers as exc:  # exit code 4, as optimise --scheduler
        print(f"error: {exc}", file=sys.stderr)
        return 4
    finally:
        if executor is not None:
            executor.shutdown()
    if args.plot:
        from ..plots import pareto_figure, save

        save(pareto_figure(result), args.plot)
        print(f"plot written to {args.plot}", file=sys.stderr)
    print(json.dumps(result) if args.json else _table(result))
    return 0 if result["points"] else 1


def _table(result: dict) -> str:
    unit = result["drive_stiffness_unit"]
    stroke = result.get("against") == "stroke"
    first = f"stroke [{result.get('stroke_unit')}]" if stroke else f"drive stiffness [{unit}]"
    lines = [f"{first:>26}  worst [Hz]  zero [Hz]  stress/limit  point              design"]
    ends = {id(result["max_frequency"]): "max frequency", id(result["min_drive_stiffness"]): "min drive stiffness"}
    for p in sorted(result["points"], key=lambda p: p["stroke" if stroke else "drive_stiffness"]):
        design = ", ".join(f"{k}={v:.4g}" for k, v in p["design"].items())
        what = ends.get(id(p), f"level {p['level']:.4g}" if p["level"] is not None else "")
        what = f"K {p['drive_stiffness']:.4g} {unit}" if stroke else what
        lines.append(
            f"{p['stroke' if stroke else 'drive_stiffness']:>26.5g}  {p['worst_hz']:>10.3f} {p['zero_stroke_hz']:>10.3f}  "
            f"{p['stress_ratio']:>12.3f}  {what:<18} {design}"
        )
    prob = result["spec"]["problem"]
    lines.append(
        f"{len(result['points'])} verified points on {prob['verify_points']} exact stroke points each; "
        + (
            "the frequency optimum at each stroke"
            if stroke
            else "drive stiffness = peak drive over the stroke / its half range"
        )
        + f"; {result['seconds']:.1f} s"
    )
    if result.get("check"):
        lines.append(result["check"]["summary"])
    lines += [f"warning ({w['kind']}): {w['message']}" for w in result.get("warnings", [])]
    return "\n".join(lines)
