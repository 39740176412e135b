"""A/B benchmark of the warm exact curve: this checkout against another flexopt (e.g. the base commit).

On a shared machine absolute times drift; what holds is a ratio measured side by side. This script runs
the two versions in alternating child processes (A B A B ...), each child timing ``--inner`` warm 91-point
curves per case after one warm-up, and prints the medians and the median of the per-pair ratios.

Version A is this checkout's ``flexopt`` package (bench/_common.package: the layout pyproject.toml maps, not
whatever flexopt is installed); version B a directory holding a ``flexopt`` package (``--base``) or one built
from a commit of this repository (``--base-commit``). Each child reports the model directory it imported,
printed above the table::

    python bench/bench_ab.py --base-commit 84035ae

``--routes`` instead compares, in one process and curve by curve, this checkout's compiled and banded per-point
routes with the numpy routes and dense eigen solve they replace (frequencies within 3e-8, asserted).
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import ROOT, add_base_arguments, base_package, package, run_fresh  # noqa: E402
from bench_curve import CASES  # noqa: E402  (the cases of the README's speed table, so the rows match)

_CHILD = """
import json, os, statistics, time
import flexopt.model
from flexopt.model import Analysis, template
out = {}
for label, name, params in CASES:
    an = Analysis(template(name, **params))
    an.frequency_curve()
    ts = []
    for _ in range(INNER):
        t = time.perf_counter()
        c = an.frequency_curve()
        ts.append(time.perf_counter() - t)
    assert c.status == "complete" and len(c.stroke) == 91
    out[label] = statistics.median(ts)
print(json.dumps({"model": os.path.realpath(os.path.dirname(flexopt.model.__file__)), "seconds": out}))
"""


def _run(pythonpath: Path, inner: int) -> tuple[str, dict[str, float]]:
    """The model directory the child imported and its median seconds per case."""
    out = run_fresh(f"CASES = {CASES!r}\nINNER = {inner}\n" + _CHILD, pythonpath)
    return out["model"], out["seconds"]


def _systems(an) -> list:
    """The analysis's System and that of its mesh estimate's coarse model (both solve every curve)."""
    subs = [an.system]
    if an.second is not None:
        subs.append(an.second.analysis.system)
    return subs


def _set_routes(systems: list, saved: list | None) -> list:
    """Switch the compiled per-point routes and the banded ones off (``saved`` None: returns what to restore)
    or back on."""
    if saved is None:
        for s in systems:
            s.eigen_band(True), s.eigen_band(False)  # found before they are switched off
        saved = [(s.native.switch_off(), dict(s.eigen_bands)) for s in systems]
        for s in systems:
            s.eigen_bands.update({True: None, False: None})
        return saved
    for s, (native, band) in zip(systems, saved):
        s.native.restore(native)
        s.eigen_bands.update(band)
    return saved


def routes(pairs: int, tmp: Path) -> int:
    """In one process, on one Analysis per case: warm curves with the compiled per-point routes (model/assembly.py's
    one-call evaluate, mass, Hessian derivative and update; model.linalg.newton with its banded LU; the banded
    Lanczos eigen solve) against the numpy routes and the dense compiled eigen solve, alternating curve by
    curve. The frequencies agree to 3e-8 relative (checked here; see the comment there; the dense-only
    routes were bit-identical to the numpy ones, the banded ones round differently)."""
    sys.path.insert(0, str(package(ROOT, tmp / "a")))
    import flexopt.model
    import numpy as np
    from flexopt.model import Analysis, template

    load0 = os.getloadavg()[0]
    rows = []
    for label, name, params in CASES:
        an = Analysis(template(name, **params))
        ref = an.frequency_curve()
        systems = _systems(an)
        on, off = [], []
        for _ in range(pairs):
            t = time.perf_counter()
            a = an.frequency_curve()
            on.append(time.perf_counter() - t)
            saved = _set_routes(systems, None)
            try:
                t = time.perf_counter()
                b = an.frequency_curve()
                off.append(time.perf_counter() - t)
            finally:
                _set_routes(systems, saved)
            assert np.array_equal(a.modes_hz, ref.modes_hz)  # deterministic
            # 3e-8: the 40-element leaf's equilibria are fixed only to their rounding floor (Newton stalls
            # there), which moves one of its frequencies by 1.1e-8 between the routes; the numpy route's
            # own value moves by 2.6e-8 when its polish tolerance goes from 1e-12 to 1e-14. The default
            # templates agree to 1e-10.
            np.testing.assert_allclose(b.modes_hz, ref.modes_hz, rtol=3e-8, atol=0)
        ratio = statistics.median([y / x for x, y in zip(on, off)])
        rows.append((label, statistics.median(on), statistics.median(off), ratio))
    print(
        f"{pairs} alternating pairs of warm curves in one process; load average {load0:.2f} at start, "
        f"{os.getloadavg()[0]:.2f} at end; {os.cpu_count()} CPUs; frequencies within 3e-8 on both routes"
    )
    print(f"imports {Path(flexopt.model.__file__).resolve().parent}")
    print("| case | compiled routes, median [ms] | numpy routes, median [ms] | speed-up (median of pairs) |")
    print("|---|---|---|---|")
    for label, a, b, r in rows:
        print(f"| {label} | {a * 1e3:.1f} | {b * 1e3:.1f} | {r:.2f} |")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Alternate A (this checkout) and B (``--base``) and print one markdown table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_base_arguments(ap, required=False)
    ap.add_argument(
        "--routes",
        action="store_true",
        help="instead: this checkout's compiled per-point routes against its numpy routes, in process",
    )
    ap.add_argument("--pairs", type=int, default=5, help="A B pairs of child processes (or of curves, --routes)")
    ap.add_argument("--inner", type=int, default=5, help="warm curves per case and child (median taken)")
    args = ap.parse_args(argv)
    tmp = Path(tempfile.mkdtemp(prefix="bench_ab_"))
    try:
        if args.routes:
            return routes(args.pairs, tmp)
        if args.base is None and args.base_commit is None:
            ap.error("one of --base DIR or --base-commit REV is required (or --routes)")
        return compare(args, tmp)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def compare(args: argparse.Namespace, tmp: Path) -> int:
    """A (this checkout) against B (``--base``/``--base-commit``) in alternating child processes."""
    a_path, b_path = package(ROOT, tmp / "a"), base_package(args, tmp)
    load0 = os.getloadavg()[0]
    a_runs, b_runs = [], []
    for _ in range(args.pairs):
        a_model, a = _run(a_path, args.inner)
        b_model, b = _run(b_path, args.inner)
        a_runs.append(a)
        b_runs.append(b)
    print(
        f"{args.pairs} interleaved A/B pairs x {args.inner} warm curves; load average {load0:.2f} at start, "
        f"{os.getloadavg()[0]:.2f} at end; {os.cpu_count()} CPUs"
    )
    print(f"A imports {a_model}; B imports {b_model}")
    print("| case | A: this checkout, median [ms] | B: base, median [ms] | speed-up B/A (median of pairs) |")
    print("|---|---|---|---|")
    for label, _, _ in CASES:
        a = [r[label] for r in a_runs]
        b = [r[label] for r in b_runs]
        ratio = statistics.median([y / x for x, y in zip(a, b)])
        print(f"| {label} | {statistics.median(a) * 1e3:.1f} | {statistics.median(b) * 1e3:.1f} | {ratio:.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
