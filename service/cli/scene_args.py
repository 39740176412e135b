"""The scene arguments every command that analyses a scene shares: a scene file, or ``--template NAME`` with
``--set KEY=VALUE`` overrides (numbers in SI, or quantities with a unit)."""

from __future__ import annotations

import argparse
from collections.abc import Sequence

__all__ = ["add_scene_arguments", "parse_sets", "scene_from_args"]


def parse_sets(items: Sequence[str]) -> dict[str, str]:
    """``["thickness=0.3mm", ...]`` -> ``{"thickness": "0.3mm"}`` (values stay strings: the template reads
    numbers and quantities with units)."""
    out = {}
    for item in items:
        if "=" not in item:
            raise ValueError(f"--set expects key=value (e.g. --set thickness=0.3mm), got '{item}'")
        k, v = item.split("=", 1)
        out[k.strip()] = v.strip()
    return out


def add_scene_arguments(p: argparse.ArgumentParser, default_template: str | None = None) -> None:
    """The scene arguments of every command that analyses one: a file, or ``--template`` with ``--set``."""
    p.add_argument(
        "scene",
        nargs="?",
        help="scene JSON file or SPACAR .dat model"
        + (f" (default: the built-in {default_template} template)" if default_template else ""),
    )
    p.add_argument("--template", metavar="NAME", help="use a built-in template instead of a file")
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a template parameter; numbers in SI (stroke in deg) or with a unit, e.g. --set thickness=0.3mm",
    )


def scene_from_args(args: argparse.Namespace, default_template: str | None = None):  # noqa: ANN201 - Scene
    """The scene a command's arguments name (see :func:`add_scene_arguments`)."""
    from ...model import load_scene, template

    if args.scene is not None and args.template is not None:
        raise ValueError("give a scene file or --template, not both")
    sets = parse_sets(args.set)
    if args.scene is not None:
        if sets:
            raise ValueError("--set applies to --template only (edit the scene file, or use --template NAME)")
        return load_scene(args.scene)
    name = args.template or default_template
    if name is None:
        raise ValueError("give a scene file or --template NAME (one of them)")
    return template(name, **sets)
