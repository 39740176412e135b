"""Mesh convergence, the mesh-error estimate and its cost (issue 11, item 6), as markdown tables.

1. Zero-stroke modes of the guide, the pivot and the seed leaf at 5, 10, 20, 40 segments per beam,
   relative to 80 segments (the cubic consistent mass converges at O(h^4)).
2. ``FrequencyCurve.mesh_error`` of the default templates against the largest relative error of the first
   parasitic frequency with respect to 80 segments at every 15th stroke point.
3. The estimate's cost: warm 91-point curves with and without it, medians of ``--repeat`` interleaved runs.
4. The stiff-axis leaf's located stability limit per mesh against the lateral-torsional buckling theory.

    python bench/bench_mesh.py [--repeat 4]
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from _common import interleave  # noqa: E402
from flexopt.model import Analysis, template  # noqa: E402

TEMPLATES = ("parallel-leaf-spring", "cross-spring-pivot", "leaf-spring")


def zero_stroke(name: str, n: int) -> np.ndarray:
    return Analysis(template(name, segments=n, points=2)).frequency_curve(np.array([0.0]), mesh_error=False).modes_hz[0]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=4)
    args = ap.parse_args()

    print("## Zero-stroke modes: largest relative difference from 80 segments\n")
    print("| template | 5 | 10 | 20 | 40 |\n|---|---|---|---|---|")
    for name in TEMPLATES:
        fine = zero_stroke(name, 80)
        row = [np.max(np.abs(zero_stroke(name, n) / fine - 1)) for n in (5, 10, 20, 40)]
        print(f"| {name} | " + " | ".join(f"{v:.1e}" for v in row) + " |")

    print("\n## mesh_error of the default curves against 80 segments\n")
    print("| template | segments | mesh_error | error vs 80 segments | ratio |\n|---|---|---|---|---|")
    for name in TEMPLATES:
        sc = template(name)
        c = Analysis(sc).frequency_curve()
        sub = c.stroke[::15]
        fine = Analysis(template(name, segments=80)).frequency_curve(stroke=sub, mesh_error=False)
        sel = [int(np.argmin(np.abs(c.stroke - s))) for s in fine.stroke]
        true = float(np.max(np.abs(c.parasitic_hz[sel] / fine.parasitic_hz - 1)))
        print(f"| {name} | {sc.elements[0].segments} | {c.mesh_error:.2e} | {true:.2e} | {c.mesh_error / true:.2f} |")

    print(f"\n## Cost of the estimate (91-point curves, medians of {args.repeat} interleaved runs)\n")
    print("| template | without [s] | with [s] | extra |\n|---|---|---|---|")
    for name in TEMPLATES:
        an = Analysis(template(name))
        an.frequency_curve()
        t, _ = interleave(
            args.repeat, {me: lambda an=an, me=me: an.frequency_curve(mesh_error=me) for me in (False, True)}
        )
        a, b = statistics.median(t[False]), statistics.median(t[True])
        print(f"| {name} | {a:.3f} | {b:.3f} | {100 * (b / a - 1):+.0f} % |")

    print("\n## Stiff-axis leaf (width and thickness swapped): located loss of stability\n")
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from references import stiff_axis_leaf_loss_deg  # noqa: E402

    theory = stiff_axis_leaf_loss_deg()
    print(f"theory (pi/L) sqrt(E I_w G J): {theory:.6f} deg\n")
    print("| segments | located [deg] | vs theory |\n|---|---|---|")
    for n in (10, 20, 40):
        sc = template("leaf-spring", width=0.5e-3, thickness=0.04, segments=n, points=3, stroke=1.0)
        f = max(Analysis(sc).frequency_curve(mesh_error=False).failures, key=lambda x: x.stroke)
        print(f"| {n} | {f.stroke:.6f} | {100 * (f.stroke / theory - 1):+.3f} % |")


if __name__ == "__main__":
    main()
