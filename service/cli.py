"""The ``flexopt`` command line. Imports lazily, so ``flexopt curve`` never loads the web stack.

Exit codes: 0 success, 1 the analysis ran but could not finish the stroke (truncated curve), 2 bad input,
3 (``curve --strict``) the result carries a warning of kind stress or validity (takes precedence over 1).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

__all__ = ["main", "parse_sets", "scene_from_args", "add_scene_arguments"]


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
    p.add_argument("scene", nargs="?", help="scene JSON file" + (
        f" (default: the built-in {default_template} template)" if default_template else ""))
    p.add_argument("--template", metavar="NAME", help="use a built-in template instead of a file")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a template parameter; numbers in SI (stroke in deg) or with a unit, "
                   "e.g. --set thickness=0.3mm")


def scene_from_args(args: argparse.Namespace, default_template: str | None = None):  # noqa: ANN201 - Scene
    """The scene a command's arguments name (see :func:`add_scene_arguments`)."""
    from ..model import load_scene, template

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


def _cmd_template(args: argparse.Namespace) -> int:
    from ..model import template, template_parameters
    from ..model.templates import TEMPLATES, parameter_unit

    if args.name is None or args.list:
        for name in sorted(TEMPLATES):
            params = ", ".join((f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}")
                               + (f" {parameter_unit(name, k)}" if parameter_unit(name, k) else "")
                               for k, v in template_parameters(name).items())
            print(f"{name}: {params}")
        return 0
    scene = template(args.name, **parse_sets(args.set))
    print(scene.model_dump_json(indent=2))
    return 0


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
    from . import plots

    plots.save(plots.curve_figure(curve, None if scene is None else scene.model_dump(mode="json"), log), path)


def _cmd_curve(args: argparse.Namespace) -> int:
    from ..model import Analysis
    from ..model.checks import STRICT_KINDS

    scene = scene_from_args(args, "leaf-spring")
    progress = _Progress(args.progress or sys.stderr.isatty())
    if args.method == "exact":
        curve = Analysis(scene).frequency_curve(progress=progress)
    else:
        from ..model.curve import curve_with_method

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


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="flexopt", description="Large-stroke flexure design: frequency curves "
                                "over the stroke of SPACAR-style flexure models.")
    sub = p.add_subparsers(dest="command", required=True)
    t = sub.add_parser("template", help="print a template scene as JSON (or list templates)")
    t.add_argument("name", nargs="?", help="template name; omit to list templates and their parameters")
    t.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a parameter")
    t.add_argument("--list", action="store_true", help="list templates and parameters")
    t.set_defaults(func=_cmd_template)
    c = sub.add_parser("curve", help="stroke-dependent natural frequencies of a scene")
    add_scene_arguments(c, "leaf-spring")
    fmt = c.add_mutually_exclusive_group()
    fmt.add_argument("--json", action="store_true", help="print a JSON object")
    fmt.add_argument("--csv", action="store_true", help="print CSV")
    c.add_argument("--plot", metavar="FILE.png", help="draw frequency against stroke")
    c.add_argument("--log-frequency", action="store_true",
                   help="logarithmic frequency axis in --plot (default: chosen when modes span > 8x)")
    c.add_argument("--progress", action="store_true", help="show progress on stderr even when not a terminal")
    c.add_argument("--method", choices=["exact", "fd1", "fd2", "manifold", "reduced", "hermite", "auto"], default="exact",
                   help="exact (continuation + eigen), Taylor fd1/fd2, quadratic manifold, reduced, hermite, or auto")
    c.add_argument("--tolerance", type=float, default=0.01,
                   help="relative error allowed on the first parasitic frequency (for --method hermite and auto)")
    c.add_argument("--strict", action="store_true",
                   help="exit 3 when the result has a warning of kind stress or validity")
    c.set_defaults(func=_cmd_curve)
    from .cli_diagnose import add_parser as _add_diagnose  # exact-constraint diagnosis
    _add_diagnose(sub)
    from .cli_modes import add_parser as _add_modes  # deflected structure and mode shapes, plots, VTK
    _add_modes(sub)
    from .cli_serve import add_parser as _add_serve  # HTTP service; uvicorn loads only on run
    _add_serve(sub)
    from .cli_optimise import add_parser as _add_optimise  # optimisation batch; optim loads only on run
    _add_optimise(sub)
    from .cli_topology import add_parser as _add_topology  # topology search; optim loads only on run
    _add_topology(sub)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit code."""
    parser = _parser()
    args = parser.parse_args(argv)
    from ..model.errors import FlexoptError

    try:
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


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
