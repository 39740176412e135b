"""Benchmark: the exact 91-point frequency curve (continuation + eigen solve at every point).

For each case it reports, side by side in one run:

- ``cold``: a fresh process with an *empty* kernel cache (CasADi code generation and C compilation
  included), from ``import model`` to the finished curve;
- ``new process``: a fresh process with the disk cache filled (what a worker or a CLI call pays);
- ``first call``: build (compile_scene, kernels loaded) plus the first curve, in a warm process;
- ``warm``: the median of repeated curves on one ``Analysis`` (the cost inside an optimisation loop),
  with the spread (min, max) beside it.

Times are wall clock on whatever else the machine is doing: quote medians, compare within one run.

``--split`` prints instead where a warm curve's time goes (eigen solves, Newton solves, mass matrices, the
rest), the per-point floor the README's speed section discusses.

Usage::

    python bench/bench_curve.py [--repeat 15] [--markdown] [--split]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

# measure this checkout, not an installed copy (the children inherit it through PYTHONPATH)
ROOT = str(Path(__file__).resolve().parents[1])
sys.path.insert(0, ROOT)
os.environ["PYTHONPATH"] = os.pathsep.join([ROOT, os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep)

CASES = [
    ("leaf-spring, 10 elements", "leaf-spring", {"segments": 10}),
    ("leaf-spring, 40 elements", "leaf-spring", {"segments": 40}),
    ("cross-spring-pivot, 2 x 8 elements", "cross-spring-pivot", {}),
    ("parallel-leaf-spring, 2 x 10 elements", "parallel-leaf-spring", {}),
]

_CHILD = """
import time, sys
t0 = time.perf_counter()
from flexopt.model import Analysis, template
c = Analysis(template({name!r}, **{params!r})).frequency_curve()
assert c.status == "complete" and len(c.stroke) == 91
print(time.perf_counter() - t0)
"""


def _child_seconds(name: str, params: dict, cache: str) -> float:
    env = dict(os.environ, FLEXOPT_CACHE_DIR=cache)
    out = subprocess.run(
        [sys.executable, "-c", _CHILD.format(name=name, params=params)],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    return float(out.stdout.strip().splitlines()[-1])


def split(repeat: int) -> None:
    """Where a warm curve's time goes: the eigen solves (the banded Lanczos pencil or the dense driver; a Lanczos
    solve that declines and the dense one after it count as two), the Newton solves (model.statics' compiled
    loop: predictor, kernel evaluations, Newton systems and updates of a point in one call), the mass matrices
    and the rest, timed by wrapping those functions over ``repeat`` curves; the rest is the continuation's
    Python (tracking, labels, stresses, mesh estimate bookkeeping)."""
    import statistics as st

    from flexopt.model import Analysis, assembly, linalg, statics, template

    acc: dict[str, list[float]] = {}

    def timed(owner, name: str, key: str):
        f = getattr(owner, name)

        def g(*a, **k):
            t = time.perf_counter()
            try:
                return f(*a, **k)
            finally:
                rec = acc.setdefault(key, [0.0, 0])
                rec[0] += time.perf_counter() - t
                rec[1] += 1

        setattr(owner, name, g)
        return f

    print(
        f"where the warm exact 91-point curve's time goes ({repeat} curves per case, medians of the whole "
        f"curve; parts summed over the curves); load average {os.getloadavg()[0]:.2f}; {os.cpu_count()} CPUs"
    )
    print(
        "| case | curve [ms] | eigen solves / curve | eigen [ms] | per eigen solve [us] | Newton solves / curve "
        "| Newton solves [ms] | per Newton solve [us] | mass matrices [ms] | rest [ms] |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for label, name, params in CASES:
        an = Analysis(template(name, **params))
        an.frequency_curve()
        acc.clear()
        originals = [
            (linalg, "lowest_pairs", timed(linalg, "lowest_pairs", "eigen")),
            (linalg.BandedPencil, "solve", timed(linalg.BandedPencil, "solve", "eigen")),
            (statics._PointLoop, "solve", timed(statics._PointLoop, "solve", "newton")),
            (assembly.System, "mass", timed(assembly.System, "mass", "mass")),
        ]
        try:
            ts = []
            for _ in range(repeat):
                t = time.perf_counter()
                an.frequency_curve()
                ts.append(time.perf_counter() - t)
        finally:
            for owner, attr, f in originals:
                setattr(owner, attr, f)
        per = {k: (v[0] / repeat, v[1] / repeat) for k, v in acc.items()}
        total = sum(ts) / repeat
        eig, newton, mass = per.get("eigen", (0, 0)), per.get("newton", (0, 0)), per.get("mass", (0, 0))
        rest = total - eig[0] - newton[0] - mass[0]
        print(
            f"| {label} | {st.median(ts) * 1e3:.1f} | {eig[1]:.0f} | {eig[0] * 1e3:.1f} | "
            f"{eig[0] / max(eig[1], 1) * 1e6:.0f} | {newton[1]:.0f} | {newton[0] * 1e3:.1f} | "
            f"{newton[0] / max(newton[1], 1) * 1e6:.0f} | {mass[0] * 1e3:.1f} | {rest * 1e3:.1f} |"
        )


def main(argv: list[str] | None = None) -> None:
    """Run the benchmark and print one table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=15, help="warm repetitions per case (median reported)")
    ap.add_argument("--markdown", action="store_true", help="print a markdown table")
    ap.add_argument(
        "--split",
        action="store_true",
        help="instead: where a warm curve's time goes (eigen, Newton solves, mass, the rest)",
    )
    args = ap.parse_args(argv)
    if args.split:
        split(args.repeat)
        return

    from flexopt.model import Analysis, template

    rows = []
    with tempfile.TemporaryDirectory() as cold_root:
        for label, name, params in CASES:
            cold = _child_seconds(name, params, os.path.join(cold_root, label.replace(" ", "_")))
            fresh = _child_seconds(name, params, os.path.join(cold_root, label.replace(" ", "_")))
            t0 = time.perf_counter()
            an = Analysis(template(name, **params))
            curve = an.frequency_curve()
            first = time.perf_counter() - t0
            warm = []
            for _ in range(args.repeat):
                t = time.perf_counter()
                an.frequency_curve()
                warm.append(time.perf_counter() - t)
            rows.append(
                (
                    label,
                    an.system.n,
                    cold,
                    fresh,
                    first,
                    statistics.median(warm),
                    min(warm),
                    max(warm),
                    curve.solver["mean_newton_iterations"],
                )
            )

    head = (
        "case",
        "DOFs",
        "cold [s]",
        "new process [s]",
        "first call [ms]",
        "warm median [ms]",
        "warm min-max [ms]",
        "Newton it./point",
    )
    fmt = [
        lambda r: r[0],
        lambda r: f"{r[1]}",
        lambda r: f"{r[2]:.2f}",
        lambda r: f"{r[3]:.2f}",
        lambda r: f"{r[4] * 1e3:.0f}",
        lambda r: f"{r[5] * 1e3:.1f}",
        lambda r: f"{r[6] * 1e3:.0f}-{r[7] * 1e3:.0f}",
        lambda r: f"{r[8]:.2f}",
    ]
    table = [[f(r) for f in fmt] for r in rows]
    print(
        f"exact 91-point curve over the template's full stroke; {args.repeat} warm repetitions; "
        f"{os.cpu_count()} CPUs; Python {sys.version.split()[0]}"
    )
    if args.markdown:
        print("| " + " | ".join(head) + " |")
        print("|" + "|".join("---" for _ in head) + "|")
        for r in table:
            print("| " + " | ".join(r) + " |")
    else:
        widths = [max(len(h), *(len(r[i]) for r in table)) for i, h in enumerate(head)]
        print("  ".join(h.ljust(w) for h, w in zip(head, widths)))
        for r in table:
            print("  ".join(c.ljust(w) for c, w in zip(r, widths)))


if __name__ == "__main__":
    main()
