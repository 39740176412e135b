"""The curve methods as a user runs them -- one fresh process per curve -- beside the warm figures, before/after.

Issue 26 item 2: as a one-off command ``flexopt curve --method auto`` was slower than exact on the double cross
(0.5-0.6x from the curves' own ``solver.seconds``) while the in-process benchmark (bench_methods.py) claimed
3.3-5x: the first fast-method curve of a process paid imports (``scipy.optimize`` for the mode matching,
``scipy.linalg`` for the Taylor module and a banded solve) that a warm process had paid already.

For each template and each of exact, hermite and auto, interleaved (E H A per round, each version in turn):

* cold: ``flexopt curve --template T --method M --json`` in a fresh process; the curve's own
  ``solver.seconds`` (the compute, imports made inside it included) and the whole process's wall time;
* warm: in one process per version, the median ``solver.seconds`` of ``--warm`` further curves after the
  first (the figure bench_methods.py reports).

Speed-ups are exact / method per pair (median). Both versions run with ``OPENBLAS_NUM_THREADS=1`` (the
BLAS threads are bench_blas.py's subject), through the same launcher. Version B as in bench_blas.py::

    python bench/bench_cold.py --base-commit main --rounds 3
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import sys
import tempfile
from pathlib import Path

from _common import HINGES as TEMPLATES
from _common import ROOT, add_base_arguments, base_package, bench_env, package, run_cli, run_fresh

METHODS = ("exact", "hermite", "auto")
WARM = """
import json, statistics, sys
from flexopt.model import Analysis, template
from flexopt.model.methods import frequency_curve
out = {}
for name in TEMPLATES:
    for m in METHODS:
        frequency_curve(Analysis(template(name)), m)
        out[name + "/" + m] = statistics.median(
            frequency_curve(Analysis(template(name)), m).solver["seconds"] for _ in range(WARM))
print(json.dumps(out))
"""


def cold(pythonpath: Path, name: str, method: str) -> tuple[float, float]:
    """(solver.seconds, whole-process wall seconds) of one fresh ``flexopt curve``."""
    wall, out = run_cli(["curve", "--template", name, "--method", method, "--json"], bench_env(pythonpath))
    if out.returncode not in (0, 3):
        raise RuntimeError(f"{name} {method}: exit {out.returncode}: {out.stderr[-500:]}")
    return json.loads(out.stdout)["solver"]["seconds"], wall


def warm(pythonpath: Path, n: int) -> dict[str, float]:
    code = f"TEMPLATES = {TEMPLATES!r}\nMETHODS = {METHODS!r}\nWARM = {n}\n" + WARM
    return run_fresh(code, pythonpath)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_base_arguments(p)
    p.add_argument("--rounds", type=int, default=3, help="cold runs per template, method and version")
    p.add_argument("--warm", type=int, default=3, help="warm curves per template and method (after one)")
    p.add_argument("--only", default=None, help="comma-separated templates (default: all six)")
    args = p.parse_args()
    names = tuple(args.only.split(",")) if args.only else TEMPLATES
    tmp = Path(tempfile.mkdtemp(prefix="bench_cold_"))
    try:
        versions = {
            "before": base_package(args, tmp),
            "after": package(ROOT, tmp / "a"),
        }
        for v in versions.values():  # kernels compiled once (shared cache), not inside a timed run
            for name in names:
                cold(v, name, "auto")
        load0 = os.getloadavg()[0]
        runs: dict[tuple[str, str, str], list[tuple[float, float]]] = {}
        for _ in range(args.rounds):
            for name in names:
                for vname, path in versions.items():
                    for m in METHODS:
                        runs.setdefault((vname, name, m), []).append(cold(path, name, m))
        warms = {vname: warm(path, args.warm) for vname, path in versions.items()}
        load1 = os.getloadavg()[0]
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(
        f"# OPENBLAS_NUM_THREADS=1; {args.rounds} cold runs per cell, interleaved; warm: median of {args.warm} "
        f"after one; load average {load0:.2f} before, {load1:.2f} after"
    )
    print(
        "| template | version | cold exact s | cold hermite s (x) | cold auto s (x) | process wall exact / auto s "
        "| warm hermite x | warm auto x |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for name in names:
        for vname in versions:
            e = runs[(vname, name, "exact")]
            cells = []
            for m in ("hermite", "auto"):
                r = runs[(vname, name, m)]
                x = statistics.median([a[0] / b[0] for a, b in zip(e, r)])
                cells.append(f"{statistics.median(s for s, _ in r):.3f} ({x:.1f}x)")
            wall = (
                f"{statistics.median(w for _, w in e):.2f} / "
                f"{statistics.median(w for _, w in runs[(vname, name, 'auto')]):.2f}"
            )
            w = warms[vname]
            wx = [w[f"{name}/exact"] / w[f"{name}/{m}"] for m in ("hermite", "auto")]
            print(
                f"| {name} | {vname} | {statistics.median(s for s, _ in e):.3f} | {cells[0]} | {cells[1]} | {wall} "
                f"| {wx[0]:.1f}x | {wx[1]:.1f}x |"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
