"""The speed-accuracy ladder of the frequency-curve methods (issue 4), as markdown tables.

For every template: warm time of a 91-point curve (median of ``--repeat`` runs; for the expansions fd1, fd2,
manifold and reduced with their exact check points, model/methods/accuracy.py) and its speed-up over the
exact curve in the same run, build time (modal and
frequency derivatives, for the fast methods), max and RMS relative error of the first parasitic frequency
(for the expansions: at every requested point, before the accuracy rule keeps those within the tolerance)
against the exact curve over a third, two thirds and all of the stroke (+-15, +-30, +-45 deg for
rotations), and the stroke range over which each method stays within 1 % and 5 %.

    python bench/bench_methods.py [--repeat 5] [--plot methods.png] [--only-interleaved]
    python bench/bench_methods.py --auto-tolerances 1e-2,1e-3,1e-4,1e-5 [--repeat 3]

The last table times exact, hermite and auto interleaved (E H A per round), the ratio that holds on a
shared machine. ``--auto-tolerances`` prints only auto against exact at those tolerances (what auto ran,
its cost relative to exact, its estimate and its true error).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from _common import HINGES, interleave, load_line, median_ratio  # noqa: E402
from flexopt.model import Analysis, template  # noqa: E402
from flexopt.model.methods import expansion_curve, frequency_curve  # noqa: E402

TEMPLATES = HINGES[:3]  # the classic flexures (plotted); then the optimiser's other families
METHODS = ("exact", "fd1", "fd2", "manifold", "reduced", "hermite", "auto")
FAST = ("fd1", "fd2", "manifold", "reduced")  # the expansions about stroke 0 (model/methods/accuracy.py)


def _range_within(stroke: np.ndarray, err: np.ndarray, tol: float) -> float:
    """Largest |s| such that every point with |stroke| <= |s| has error <= tol."""
    order = np.argsort(np.abs(stroke))
    good = 0.0
    for i in order:
        if not (err[i] <= tol):
            break
        good = abs(stroke[i])
    return good


def bench_template(name: str, repeat: int) -> tuple[list[str], dict]:
    """Rows of the markdown table for one template, and the curves (for the plot)."""
    curves = {}
    rows = []
    an = Analysis(template(name))
    values = an.scene.stroke.values()
    exact = None
    for m in METHODS:
        an_m = Analysis(template(name))
        t0 = time.perf_counter()
        c = frequency_curve(an_m, m, stroke=values)  # first call: builds derivatives (and kernels)
        build = c.solver.get("build_seconds", float("nan"))
        times = []
        for _ in range(repeat):
            if an_m.expansion is not None:  # the expansions' exact check points are paid on every curve
                an_m.expansion.checks.clear()
            t0 = time.perf_counter()
            c = frequency_curve(an_m, m, stroke=values)
            times.append(time.perf_counter() - t0)
        if m in FAST:  # every point of the expansion (its curve keeps only those within 1 %: accuracy.py)
            c = expansion_curve(an_m, m, values)[0]
        curves[m] = c
        if m == "exact":
            exact, exact_median = c, statistics.median(times)
        err = np.abs(c.parasitic_hz / exact.parasitic_hz - 1.0)
        smax = np.abs(values).max()
        cols = []
        for frac in (1 / 3, 2 / 3, 1.0):
            sel = np.abs(values) <= frac * smax + 1e-12
            e = err[sel]
            cols.append(f"{e.max():.2e} / {np.sqrt(np.mean(e**2)):.2e}")
        unit = c.stroke_unit
        r1, r5 = _range_within(values, err, 0.01), _range_within(values, err, 0.05)
        label = m if m != "auto" else f"auto ({c.method})"
        speed = statistics.median(times) / exact_median if m != "exact" else 1.0
        rows.append(
            f"| {label} | {statistics.median(times) * 1e3:.2f} | {1 / speed:.1f}x | "
            f"{'-' if not np.isfinite(build) else f'{build * 1e3:.1f}'} | "
            + " | ".join(cols)
            + f" | +-{r1:.4g} {unit} | +-{r5:.4g} {unit} |"
        )
    return rows, curves


def auto_table(tolerances: list[float], repeat: int) -> None:
    """auto against exact at several tolerances: what auto ran, its cost relative to the exact curve
    (median of per-round ratios, the two interleaved on one ``Analysis``), its estimate and true error."""
    print(f"{load_line('at start')}; {repeat} rounds of exact, auto")
    print("\n| template | tolerance | auto ran | samples | exact points | auto / exact time | estimate | true error |")
    print("|---|---|---|---|---|---|---|---|")
    for name in HINGES:
        an = Analysis(template(name))
        ex = frequency_curve(an, "exact")
        frequency_curve(an, "hermite")
        for tol in tolerances:
            t, last = interleave(
                repeat,
                {
                    "exact": lambda an=an: frequency_curve(an, "exact"),
                    "auto": lambda an=an, tol=tol: frequency_curve(an, "auto", tolerance=tol),
                },
            )
            a = last["auto"]
            err = float(np.max(np.abs(a.parasitic_hz / ex.parasitic_hz - 1)))
            print(
                f"| {name} | {tol:g} | {a.solver['auto_method']} | {a.solver.get('samples', '-')} | "
                f"{a.solver.get('exact_points', '-')} | {median_ratio(t['auto'], t['exact']):.2f} | "
                f"{a.solver['auto_estimate']:.1e} | {err:.1e} |"
            )
    print(f"\nload average {os.getloadavg()[0]:.2f} at the end")


def main(argv: list[str] | None = None) -> int:
    """Print one markdown table per template."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--plot", default=None, help="write a PNG of the first parasitic frequency per method")
    p.add_argument("--only-interleaved", action="store_true", help="print only the exact/hermite/auto table")
    p.add_argument(
        "--auto-tolerances",
        default=None,
        metavar="T1,T2,...",
        help="only the table of auto against exact at these tolerances (e.g. 1e-2,1e-3,1e-4,1e-5)",
    )
    args = p.parse_args(argv)
    if args.auto_tolerances:
        auto_table([float(t) for t in args.auto_tolerances.split(",")], args.repeat)
        return 0

    print(f"{load_line('at start')}; medians of {args.repeat} warm runs")
    all_curves = {}
    for name in () if args.only_interleaved else HINGES:
        rows, curves = bench_template(name, args.repeat)
        all_curves[name] = curves
        unit = curves["exact"].stroke_unit
        smax = float(np.abs(curves["exact"].stroke).max())
        thirds = ", ".join(f"+-{f * smax:.3g}" for f in (1 / 3, 2 / 3, 1.0))
        print(
            f"\n### {name} (first parasitic at 0: {curves['exact'].parasitic_hz[len(curves['exact'].stroke) // 2]:.2f} Hz)\n"
        )
        print(
            f"| method | warm 91-pt [ms] | speed-up vs exact | build [ms] | max / RMS rel. error over {thirds} {unit} "
            "(three columns) | | | within 1 % | within 5 % |"
        )
        print("|---|---|---|---|---|---|---|---|---|")
        for r in rows:
            print(r)
    print(
        f"\n### exact, hermite and auto interleaved (tolerance 1 %; {args.repeat} rounds of E H A; load average "
        f"{os.getloadavg()[0]:.2f})\n"
    )
    print(
        "| template | exact median [ms] | hermite median [ms] | hermite speed-up (median of rounds) | auto ran "
        "| auto speed-up | hermite samples | hermite max error | hermite estimate |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for name in HINGES:
        an = Analysis(template(name))
        ex = frequency_curve(an, "exact")
        frequency_curve(an, "hermite")
        t, last = interleave(
            args.repeat,
            {m: lambda an=an, m=m: frequency_curve(an, m, tolerance=0.01) for m in ("exact", "hermite", "auto")},
        )
        (te, th, ta), h, a = (t[m] for m in ("exact", "hermite", "auto")), last["hermite"], last["auto"]
        err = float(np.max(np.abs(h.parasitic_hz / ex.parasitic_hz - 1)))
        sh, sa = median_ratio(te, th), median_ratio(te, ta)
        print(
            f"| {name} | {statistics.median(te) * 1e3:.1f} | {statistics.median(th) * 1e3:.1f} | {sh:.1f}x | "
            f"{a.method} | {sa:.1f}x | {h.solver['samples']} | {err:.2e} | {h.solver['estimated_error']:.2e} |"
        )
    if args.plot and all_curves:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(1, len(TEMPLATES), figsize=(5 * len(TEMPLATES), 4))
        for ax, name in zip(axes, TEMPLATES):
            ex = all_curves[name]["exact"]
            scale, unit = (1e3, "mm") if ex.stroke_unit == "m" else (1.0, ex.stroke_unit)  # readable ticks
            for m, c in all_curves[name].items():
                ax.plot(c.stroke * scale, c.parasitic_hz, label=m, lw=2 if m == "exact" else 1)
            lo, hi = np.nanmin(ex.parasitic_hz), np.nanmax(ex.parasitic_hz)
            ax.set_ylim(0.5 * lo, 1.3 * hi)
            ax.set_title(name)
            ax.set_xlabel(f"stroke [{unit}]")
            ax.set_ylabel("first parasitic [Hz]")
            ax.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(args.plot, dpi=120)
        print(f"\nplot written to {args.plot}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
