"""Tapered leaves (issue 30 item 1): hinges optimised with and without thickness zones under identical constraints.

For each descriptor (default: the double cross hinge ``R:+-|-+`` and the default search's winner ``R:+-|-+|+-``)
the topology search is run on that descriptor alone twice, interleaved: ``taper`` 1 (uniform leaves, today's)
and ``taper`` k (default 3: k zones per stacked leaf, symmetric about its middle, neighbours within
``max_taper``), everything else the default spec's (envelope, stress limit, masses, each stage its own
dimensions, 2 starts, the refined verification on the mesh that meets 0.2 %). Printed per run: the refined
worst-case first parasitic frequency over +-45 deg, the zero-stroke frequency and the fraction kept, the mesh
error and segments there, the refined stress ratio, the zone thicknesses, the active bounds and the wall time,
with ``uptime``'s load before and after (the machine is shared: times under load are upper bounds).

Run from the repository root: ``python bench/bench_taper.py [--workers 2] [--taper 3] [--topologies ...]
[--store DIR] [--json out.json]``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from flexopt.optim.topology import run_topology_search  # noqa: E402


def _load() -> str:
    return subprocess.run(["uptime"], capture_output=True, text=True, check=False).stdout.strip().split("load ")[-1]


def _zones(design: dict) -> str:
    """The thickness parameters of a design in mm, zones grouped by their leaf or stage."""
    th = {k: v for k, v in design.items() if k.startswith("thickness")}
    return ", ".join(f"{k} {1e3 * v:.3f}" for k, v in th.items())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--taper", type=int, default=3)
    ap.add_argument("--topologies", nargs="+", default=["R:+-|-+", "R:+-|-+|+-"])
    ap.add_argument("--store", default=None, help="case store (a rerun reuses its cases: times then mean nothing)")
    ap.add_argument("--json", default=None, help="write every run's result here")
    args = ap.parse_args()
    rows, results = [], {}
    for d in args.topologies:
        for k in (1, args.taper):
            spec = {"topologies": [d], "taper": k}
            before = _load()
            t0 = time.perf_counter()
            res = run_topology_search(spec, workers=args.workers, store=args.store, echo=False)
            wall = time.perf_counter() - t0
            after = _load()
            results[f"{d} taper {k}"] = res
            b = res["best"]
            if b is None:
                rows.append(
                    f"| `{d}` | {k} | failed: {res['candidates'][0].get('reason')} | | | | | | {wall:.0f} | {before} / {after} |"
                )
                continue
            ref = b.get("refined") or {}
            rows.append(
                f"| `{d}` | {k} | {ref.get('worst_hz', float('nan')):.2f} | {ref.get('zero_stroke_hz', float('nan')):.2f} "
                f"| {ref.get('ratio', float('nan')):.3f} | {ref.get('mesh_error', float('nan')):.1e} "
                f"({max(ref.get('segments_used') or [0])}) | {ref.get('stress_ratio', float('nan')):.3f} "
                f"| {_zones(b['design'])} | {', '.join(f'{n} ({s})' for n, s in (b.get('active_bounds') or {}).items())} "
                f"| {wall:.0f} | {before} / {after} |"
            )
            print(rows[-1], flush=True)
    print()
    print(
        "| topology | taper | worst-case [Hz] refined | zero-stroke [Hz] | worst / zero | mesh error (segments per "
        "beam) | stress ratio | thicknesses [mm] | active bounds | time [s] | load before / after |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(r)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=1, default=str)


if __name__ == "__main__":
    main()
