"""``flexopt template``: print a template scene as JSON, or list the templates and their parameters."""

from __future__ import annotations

import argparse
from typing import Any

from .scene_args import parse_sets

__all__ = ["add_parser"]


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add the ``template`` subcommand to an argparse subparsers object."""
    t = subparsers.add_parser("template", help="print a template scene as JSON (or list templates)")
    t.add_argument("name", nargs="?", help="template name; omit to list templates and their parameters")
    t.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a parameter")
    t.add_argument("--list", action="store_true", help="list templates and parameters")
    t.set_defaults(func=_cmd_template)
    return t


def _cmd_template(args: argparse.Namespace) -> int:
    from ...model import template, template_parameters
    from ...model.templates import TEMPLATES, parameter_unit

    if args.name is None or args.list:
        for name in sorted(TEMPLATES):
            params = ", ".join(
                (f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}")
                + (f" {parameter_unit(name, k)}" if parameter_unit(name, k) else "")
                for k, v in template_parameters(name).items()
            )
            print(f"{name}: {params}")
        return 0
    scene = template(args.name, **parse_sets(args.set))
    print(scene.model_dump_json(indent=2))
    return 0
