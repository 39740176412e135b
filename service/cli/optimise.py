"""``flexopt optimise``: maximise the worst-case first parasitic frequency over the stroke (optim/).

Registered by service.cli.main through :func:`add_parser`; imports optim lazily.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

__all__ = ["SCHEDULER_HELP", "add_parser", "plot_result"]

#: The ``--scheduler`` option's help, for every subcommand that runs a batch on Dask: how to start a cluster whose
#: servers and workers are set up for flexopt's cases (docs/pages/optimisation.md, Batch).
SCHEDULER_HELP = (
    "run on a Dask cluster, e.g. tcp://host:8786; start it for flexopt with `dask scheduler --preload "
    "flexopt.optim.dask_preload` and `dask worker ADDRESS --nthreads 1 --preload flexopt.optim._preload "
    "--preload-nanny flexopt.optim.dask_preload`"
)


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add the ``optimise`` subcommand to an argparse subparsers object."""
    o = subparsers.add_parser("optimise", help="optimise hinge families for the worst-case parasitic frequency")
    o.add_argument("spec", help="problem JSON (format flexopt-problem, see optim/problem.py)")
    o.add_argument("--workers", type=int, default=None, help="local worker processes (default: CPU count)")
    o.add_argument("--scheduler", metavar="ADDRESS", help=SCHEDULER_HELP)
    o.add_argument("--store", metavar="DIR", help="write each finished case here; rerun to resume")
    o.add_argument(
        "--no-worker-timeout",
        type=float,
        default=60.0,
        metavar="SECONDS",
        help="with --scheduler: stop when the cluster has had no workers this long (default 60)",
    )
    o.add_argument("--json", action="store_true", help="print the whole result as JSON")
    o.add_argument("--plot", metavar="FILE.png", help="frequency against stroke before and after, per family")
    o.add_argument("--scenes", metavar="DIR", help="write the scene JSON of each family's optimum here")
    o.set_defaults(func=_cmd_optimise)
    return o


def _first_error(exc: Exception) -> str:
    errs = getattr(exc, "errors", None)
    if callable(errs):
        e = errs()[0]
        loc = ".".join(str(p) for p in e.get("loc", ()))
        return f"{loc or 'spec'}: {str(e.get('msg')).removeprefix('Value error, ')}"
    return str(exc)


def read_spec(path: str, model: Any) -> Any:
    """The JSON file ``path`` validated as the pydantic ``model``; one-line ValueError naming the field."""
    from pydantic import ValidationError

    try:
        raw = json.loads(Path(path).read_text())
    except OSError as exc:
        raise ValueError(f"cannot read '{path}': {exc.strerror}") from exc
    except json.JSONDecodeError as exc:
        raise ValueError(f"'{path}' is not JSON: {exc.msg} at line {exc.lineno}") from exc
    try:
        return model.model_validate(raw)
    except ValidationError as exc:
        raise ValueError(f"spec.{_first_error(exc)}") from None


def case_lines(command: str) -> Any:
    """A batch progress callback writing one line per finished case on stderr when stderr is not a terminal
    (redirected to a log: the batch's own bar is drawn on terminals only); None on a terminal."""
    if sys.stderr.isatty():
        return None

    def line(event: dict) -> None:
        print(f"{command}: case {event['done']}/{event['total']} {event['status']}", file=sys.stderr, flush=True)

    return line


def executor_for(scheduler: str | None) -> Any:
    """A Dask client's executor for ``scheduler`` (an address), or None for the local process pool."""
    if not scheduler:
        return None
    from ...optim.batch import dask_executor

    return dask_executor(scheduler)


def _cmd_optimise(args: argparse.Namespace) -> int:
    from ...optim import Problem, optimise
    from ...optim.batch import NoWorkers

    prob = read_spec(args.spec, Problem)
    executor = executor_for(args.scheduler)
    try:
        result = optimise(
            prob,
            executor=executor,
            workers=args.workers,
            store=args.store,
            no_worker_timeout=args.no_worker_timeout,
            progress=case_lines("optimise"),
        )
    except NoWorkers as exc:  # exit code 4: the cluster, not the input (2) nor a warning (3, curve --strict)
        print(f"error: {exc}", file=sys.stderr)
        return 4
    finally:
        if executor is not None:
            executor.shutdown()  # also closes the Dask client
    if args.scenes:
        out = Path(args.scenes)
        out.mkdir(parents=True, exist_ok=True)
        for fam in result["families"]:
            if fam["best"] is not None and "scene" in fam["best"]["verified"]:
                (out / f"{fam['template']}.json").write_text(json.dumps(fam["best"]["verified"]["scene"], indent=2))
    if args.plot:
        plot_result(result, args.plot)
    if args.json:
        print(json.dumps(result))
    else:
        print(_table(result))
    return 0 if result["ranking"] else 1


def quantity(value: float, unit: str | None) -> str:
    """A design value with its unit, in the unit a flexure engineer reads: lengths in mm, stresses and moduli
    in MPa or GPa, masses in g below 1 kg (``0.0004, "m"`` -> ``"0.4 mm"``)."""
    if unit == "m":
        return f"{value * 1e3:.4g} mm"
    if unit == "Pa":
        return f"{value / 1e9:.4g} GPa" if abs(value) >= 1e9 else f"{value / 1e6:.4g} MPa"
    if unit == "kg" and abs(value) < 1:
        return f"{value * 1e3:.4g} g"
    return f"{value:.4g}" + (f" {unit}" if unit else "")


def design_text(design: dict[str, float], template: str, box: dict[str, list[float]] | None = None) -> str:
    """``thickness=0.4 mm (upper bound), length=52.1 mm``: each value with its unit, and the bound of the design
    box it sits on (within 1e-6 of the box's width), if any."""
    from ...model.templates import parameter_unit

    parts = []
    for k, v in design.items():
        text = f"{k}={quantity(v, parameter_unit(template, k))}"
        if box and k in box:
            lo, hi = box[k]
            tol = 1e-6 * abs(hi - lo)
            text += " (lower bound)" if abs(v - lo) <= tol else " (upper bound)" if abs(v - hi) <= tol else ""
        parts.append(text)
    return ", ".join(parts)


def _table(result: dict) -> str:
    lines = ["rank  family                    worst [Hz]  zero [Hz]  worst/zero  stress/limit  status      design"]
    ranked = {r["template"]: i + 1 for i, r in enumerate(result["ranking"])}
    boxes = {f["template"]: f.get("design", {}) for f in result["problem"].get("families", [])}
    for fam in sorted(result["families"], key=lambda f: ranked.get(f["template"], 99)):
        b = fam["best"]
        if b is None:
            why = "; ".join(f"start {f['start']}: {f['status']} {f['message'] or ''}".strip() for f in fam["failed"])
            lines.append(f"  -   {fam['template']:<25} no verified design ({why})")
            continue
        v = b["verified"]
        design = design_text(b["design"], fam["template"], boxes.get(fam["template"]))
        lines.append(
            f"{ranked[fam['template']]:>4}  {fam['template']:<25} {v['worst_hz']:>10.2f} {v['zero_stroke_hz']:>10.2f}"
            f"  {v['ratio']:>10.3f}  {v['stress_ratio']:>12.3f}  {b['status']:<10}  {design}"
        )
    lines.append(
        f"verified on {result['problem']['verify_points']} exact stroke points per family; stress limit = "
        f"allowable / {result['problem']['safety_factor']}"
    )
    lines += [f"warning ({w['kind']}): {w['message']}" for w in result.get("warnings", [])]
    return "\n".join(lines)


def plot_result(result: dict, path: str) -> None:
    """Frequency against stroke of each family's best start: the starting design and the optimum."""
    import matplotlib.pyplot as plt

    fig = result_figure(result)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    print(f"plot written to {path}", file=sys.stderr)


def result_figure(result: dict) -> Any:
    """The figure of :func:`plot_result` (a matplotlib Figure)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ...model.templates import parameter_unit

    fams = [f for f in result["families"] if f["best"] is not None]
    tol = result["problem"].get("tolerance", 1e-3)
    fig, axes = plt.subplots(1, max(len(fams), 1), figsize=(4.2 * max(len(fams), 1), 3.4), squeeze=False)
    for ax, fam in zip(axes[0], fams):
        b = fam["best"]
        for key, label, style in (("initial", "start", "--"), ("verified", "optimum", "-")):
            c = b[key]
            if not c.get("stroke"):
                continue
            how = c.get("method", "exact")  # the start's curve is method auto's (optim.search._preview)
            if how != "exact":  # a start above the optimum is usually one that breaks the stress limit
                label += f" ({how}; stress not checked)"
            elif c.get("stress_ratio", 0.0) >= 1 - tol:
                label += " (at the stress limit)"
            ax.plot(c["stroke"], c["parasitic_hz"], style, label=label)
        ax.set_ylim(0, 1.4 * ax.get_ylim()[1])  # room above the curves for the legend's long labels
        ax.set_title(fam["template"], fontsize=9)
        ax.set_xlabel(f"stroke [{parameter_unit(fam['template'], 'stroke')}]")
        ax.set_ylabel("first parasitic frequency [Hz]")
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    return fig
