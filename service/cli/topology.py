"""``flexopt topology``: generate hinge topologies, screen them by exact constraint, optimise and rank them.

Registered by service.cli.main through :func:`add_parser`; imports optim lazily.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from .optimise import SCHEDULER_HELP, design_text

__all__ = ["add_parser", "plot_ranking"]


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add the ``topology`` subcommand to an argparse subparsers object."""
    o = subparsers.add_parser("topology", help="topology search: generate, screen, optimise and rank hinges")
    o.add_argument("spec", nargs="?", help="search spec JSON (format flexopt-topology; see --example)")
    o.add_argument(
        "--example",
        nargs="?",
        const="default",
        choices=["default", "quick"],
        default=None,
        help="print the default spec (the broad space: 6 leaves, 3 stages, each stage its own "
        "dimensions) or, with 'quick', the quick one (4 leaves, 2 stages, shared dimensions) and exit",
    )
    o.add_argument("--workers", type=int, default=None, help="local worker processes (default: CPU count)")
    o.add_argument("--scheduler", metavar="ADDRESS", help=SCHEDULER_HELP)
    o.add_argument("--store", metavar="DIR", help="write each finished case here; rerun to resume")
    o.add_argument("--json", action="store_true", help="print the whole result as JSON")
    o.add_argument("--plot", metavar="FILE.png", help="bar chart of the ranking (worst case and zero stroke)")
    o.add_argument("--scenes", metavar="DIR", help="write the scene JSON of each optimised candidate here")
    o.set_defaults(func=_cmd_topology)
    return o


def _file_name(descriptor: str) -> str:
    """A file name for a descriptor: 'R:+-@|-+' -> 'R_pmc_mp' (+ p, - m, 0 o, @ c, : and | _)."""
    table = {"+": "p", "-": "m", "0": "o", "|": "_", "@": "c", ":": "_"}
    return "".join(table.get(c, c) for c in descriptor)


def _cmd_topology(args: argparse.Namespace) -> int:
    from ...optim.topology.spec import TopologySpec, example_spec
    from .optimise import case_lines, executor_for, read_spec

    if args.example:
        print(json.dumps(example_spec(args.example), indent=2))
        return 0
    if args.spec is None:
        raise ValueError("give a spec file (flexopt topology --example > spec.json) or --example")
    spec = read_spec(args.spec, TopologySpec)
    from ...optim.batch import NoWorkers
    from ...optim.topology import run_topology_search

    executor = executor_for(args.scheduler)
    try:
        result = run_topology_search(
            spec, executor=executor, workers=args.workers, store=args.store, progress=case_lines("topology")
        )
    except NoWorkers as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 3
    finally:
        if executor is not None:
            executor.shutdown()
    if args.scenes:
        out = Path(args.scenes)
        out.mkdir(parents=True, exist_ok=True)
        for c in result["candidates"]:
            if c.get("scene"):
                (out / f"{_file_name(c['topology'])}.json").write_text(json.dumps(c["scene"], indent=2))
        print(f"scenes written to {out}/", file=sys.stderr)
    if args.plot:
        plot_ranking(result, args.plot)
    if args.json:
        print(json.dumps({k: v for k, v in result.items()}))
    else:
        print(table(result))
    return 0 if result["best"] is not None else 1


def table(result: dict) -> str:
    """The ranking and the rejected candidates as text."""
    c = result["counts"]
    by = ", ".join(f"{n} {k}" for k, n in sorted(c["rejected_by"].items()))
    sec = result["seconds"]
    passes = (
        f", first pass {c['first_pass']}, pruned {c['pruned']}, full pass {c['promoted']}" if "first_pass" in c else ""
    )
    head = (
        f"{c['generated']} topologies generated, {c['rejected']} rejected ({by or 'none'}), "
        f"{c['untraceable']} untraceable{passes}, {c['optimised']} optimised, {c['failed']} failed "
        f"(screen {sec['screen']:.1f} s, first pass {sec.get('first_pass', 0.0):.1f} s, optimisation "
        f"{sec['optimise']:.1f} s, refined verification {sec.get('refine', 0.0):.1f} s)"
    )
    lines = [head]
    by_name = {r["topology"]: r for r in result["candidates"]}
    if result["spec"]["motion"] == "translation":
        lines[0] += f", {c['accepted']} accepted (guides: screened, not optimised)"
        lines.append("rank  guide                          self-stress  condition number of D_cc")
        lines += [
            f"{i:>4}  {n:<30} {by_name[n]['overconstraints']:>11}  {by_name[n]['condition_number']:.4g}"
            for i, n in enumerate(result["ranking"][:50], start=1)
        ]
        if len(result["ranking"]) > 50:
            lines.append(f"      ... {len(result['ranking']) - 50} more (--json lists every candidate)")
        rej = [r for r in result["candidates"] if r["status"] == "rejected"]
        if rej:
            lines.append("rejected by the exact-constraint filter:")
            lines += [f"      {r['topology']:<30} {r['reason']}" for r in rej[:50]]
            if len(rej) > 50:
                lines.append(f"      ... {len(rej) - 50} more (--json lists every candidate)")
        return "\n".join(lines)
    from ...optim.topology.grammar import family_form

    # a designed crossing ('@') whose optimum crosses at the midpoint is the design of the topology without '@':
    # shown once, on that topology's row, with its '@' variants named
    variants: dict[str, list[str]] = {}
    for name in result["ranking"]:
        base = by_name[name].get("same_design_as")
        if base and base in result["ranking"]:
            variants.setdefault(base, []).append(name)
    shown = [n for n in result["ranking"] if not any(n in v for v in variants.values())]
    unfinished = [r["topology"] for r in result["candidates"] if r["status"] in ("failed", "untraceable")]
    # the family in words (optim.topology.grammar.family_form: "R:+-" is the cross-spring pivot crossing at the
    # midpoint), for the rows printed with it, in a column as wide as its longest entry there
    families = {n: family_form(n) or "-" for n in shown + unfinished}
    fw = max([len("family"), *(len(f) for f in families.values())])
    lines.append(
        f"rank  topology          {'family':<{fw}} dof  self-stress  worst [Hz]  zero [Hz]  worst/zero  "
        "stress  mesh error  KKT      design (bound: origin)"
    )
    for i, name in enumerate(shown, start=1):
        r = by_name[name]
        design = design_text(r["design"], r["family"] or "topology-hinge")
        bounds = r.get("active_bounds") or {}
        origins = r.get("bound_origins") or {}
        told = [f"{k} {side}: {origins[k][side == 'upper']}" for k, side in bounds.items() if k in origins]
        if told:
            design += f" (on bounds: {'; '.join(told)})"
        if r.get("same_design_as"):
            design += f" (crossing at the midpoint: the design of {r['same_design_as']})"
        if name in variants:
            design += f"; also {', '.join(variants[name])} (their optimum crosses at the midpoint: this design)"
        ref = r.get("refined") or {}
        worst = ref.get("worst_hz") if ref.get("worst_hz") is not None else r["worst_case_hz"]
        zero = ref.get("zero_stroke_hz", r["zero_stroke_hz"])
        ratio = ref.get("ratio", r["ratio"])
        stress = ref.get("stress_ratio", r.get("stress_ratio"))
        stress_text = "-" if stress is None else f"{stress:.3f}"  # a result without a stress check shows '-'
        kkt = r.get("kkt_residual")
        kkt_text = "-" if kkt is None else f"{kkt:.1e}"
        me = f"{ref['mesh_error']:.1e}" if ref.get("mesh_error") is not None else "-"
        lines.append(
            f"{i:>4}  {name:<17} {families[name]:<{fw}} {r['dof']:>3}  {r['overconstraints']:>11}  "
            f"{worst:>10.2f} {zero:>10.2f}  {ratio:>10.3f}  {stress_text:>6}  {me:>10}  "
            f"{kkt_text}  {design}"
        )
        lines += [f"      ! {w['message']}" for w in r.get("warnings", []) if w.get("kind") in ("stress", "mesh")]
    if any(by_name[n].get("refined") for n in result["ranking"]):
        lines.append(
            "      (worst, zero, worst/zero and stress on the refined mesh: refine_segments, refine_tolerance)"
        )
    for r in result["candidates"]:
        if r["status"] in ("failed", "untraceable"):
            lines.append(f"   -  {r['topology']:<17} {families[r['topology']]:<{fw}} {r['status']}: {r['reason']}")
    rej = [r for r in result["candidates"] if r["status"] == "rejected"]
    if rej:
        lines.append("rejected by the exact-constraint filter:")
        lines += [f"      {r['topology']:<17} {r['reason']}" for r in rej]
    return "\n".join(lines)


def plot_ranking(result: dict, path: str) -> None:
    """Worst-case and zero-stroke first parasitic frequency of every optimised candidate, best first; the
    hand-made families labelled."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    by_name = {r["topology"]: r for r in result["candidates"]}
    rows = [by_name[n] for n in result["ranking"] if by_name[n]["worst_case_hz"] is not None]
    if not rows:
        print("no optimised candidate to plot", file=sys.stderr)
        return
    fig, ax = plt.subplots(figsize=(max(6.0, 0.35 * len(rows) + 2), 4.2))
    xs = range(len(rows))
    ax.bar(xs, [r["zero_stroke_hz"] for r in rows], color="0.85", label="zero stroke")
    ax.bar(
        xs,
        [r["worst_case_hz"] for r in rows],
        color=["C3" if r["family"] else "C0" for r in rows],
        label="worst case over the stroke (red: a hand-made family)",
    )
    ax.set_xticks(
        list(xs), [r["topology"] + (f"\n{r['family']}" if r["family"] else "") for r in rows], rotation=90, fontsize=7
    )
    ax.set_ylabel("first parasitic frequency [Hz]")
    ax.set_yscale("log")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, axis="y")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    print(f"plot written to {path}", file=sys.stderr)
