"""Optimiser benchmark: correctness against a grid search, time per family and per topology search, the
coarse-then-verify ladder against an exact-only dense search, and the best hinge's flatness.

Run from the repository root: ``python bench/bench_optim.py [--grid 15] [--workers 2] [--skip-grid]``.
Prints markdown tables for the README. Wall-clock times of single runs on this machine (an optimisation
is seconds long; the spread between repeated runs is reported by ``--repeat``).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ["PYTHONPATH"] = str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")

from flexopt.model import Analysis, template  # noqa: E402
from flexopt.model.templates import TEMPLATES  # noqa: E402
from flexopt.optim import optimise  # noqa: E402

PIVOT = {"template": "cross-spring-pivot", "design": {"length": [0.03, 0.07], "thickness": [1.5e-4, 4e-4]}}


def _hinge_families() -> list[dict]:
    try:
        from flexopt.model.templates import DESIGN_SPACES
    except ImportError:
        return [PIVOT]
    fams = []
    for name, box in DESIGN_SPACES.items():
        if name in TEMPLATES and TEMPLATES[name][1].get("stroke", 0) == 45.0:
            fams.append({"template": name, "design": {k: list(v) for k, v in box.items()}})
    return fams or [PIVOT]


def _timed(spec: dict, workers: int, repeat: int) -> tuple[dict, list[float]]:
    times, res = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        res = optimise(spec, workers=workers)
        times.append(time.perf_counter() - t)
    assert res is not None
    return res, times


def grid_check(n: int, workers: int) -> None:
    spec = {"families": [PIVOT], "starts": 4}
    res, _ = _timed(spec, workers, 1)
    opt = res["ranking"][0]["worst_hz"] if res["ranking"] else float("nan")
    allow = 600e6 / 1.5
    best, arg = 0.0, None
    t = time.perf_counter()
    for L in np.linspace(*PIVOT["design"]["length"], n):
        for th in np.linspace(*PIVOT["design"]["thickness"], n):
            c = Analysis(template("cross-spring-pivot", length=float(L), thickness=float(th), points=61)).frequency_curve()
            stress = max(float(np.max(v)) for v in c.max_von_mises.values())
            if c.status == "complete" and stress <= allow and float(np.min(c.parasitic_hz)) > best:
                best, arg = float(np.min(c.parasitic_hz)), (float(L), float(th))
    grid_s = time.perf_counter() - t
    assert arg is not None
    c = Analysis(template("cross-spring-pivot", length=arg[0], thickness=arg[1], points=181)).frequency_curve()
    best181 = float(np.min(c.parasitic_hz))
    print("\n### Correctness: cross-spring pivot, length x thickness, +-45 deg, stress <= 400 MPa\n")
    print("| method | worst-case first parasitic [Hz] (181 exact points) | design | time [s] |")
    print("|---|---|---|---|")
    d = res["ranking"][0]["design"] if res["ranking"] else {}
    print(f"| optimiser (4 starts) | {opt:.3f} | L {d.get('length', 0) * 1e3:.2f} mm, t {d.get('thickness', 0) * 1e6:.1f} um | |")
    print(f"| grid {n} x {n} (61-point curves, best re-verified) | {best181:.3f} | L {arg[0] * 1e3:.2f} mm, "
          f"t {arg[1] * 1e6:.1f} um | {grid_s:.1f} |")
    print(f"\noptimiser / grid = {opt / best181:.4f} (criterion: >= 0.995)")


def speed(workers: int, repeat: int) -> None:
    print(f"\n### Time ({workers} worker processes, {os.cpu_count()} CPUs; median of {repeat} runs)\n")
    print("| run | families x starts | wall time [s] | verified worst [Hz] |")
    print("|---|---|---|---|")
    one = {"families": [PIVOT], "starts": 4}
    res, t = _timed(one, workers, repeat)
    print(f"| cross-spring pivot, ladder (9 samples + 181-point verification) | 1 x 4 | {statistics.median(t):.1f} | "
          f"{res['ranking'][0]['worst_hz']:.3f} |")
    dense = dict(one, samples=61, refine_rounds=0)
    res_d, t_d = _timed(dense, workers, repeat)
    print(f"| cross-spring pivot, exact-only dense search (61 samples) | 1 x 4 | {statistics.median(t_d):.1f} | "
          f"{res_d['ranking'][0]['worst_hz']:.3f} |")
    print(f"\nladder speed-up over the dense exact search: {statistics.median(t_d) / statistics.median(t):.1f}x")
    fams = _hinge_families()
    search = {"families": fams, "starts": 4}
    res_s, t_s = _timed(search, workers, 1)
    print(f"\n### Topology search: {len(fams)} families x 4 starts, +-45 deg: {t_s[0]:.1f} s\n")
    print("| rank | family | worst [Hz] | zero-stroke [Hz] | worst / zero | design |")
    print("|---|---|---|---|---|---|")
    for i, r in enumerate(res_s["ranking"], 1):
        design = ", ".join(f"{k} {v:.4g}" for k, v in r["design"].items())
        print(f"| {i} | {r['template']} | {r['worst_hz']:.2f} | {r['zero_stroke_hz']:.2f} | {r['ratio']:.3f} | {design} |")
    for f in res_s["families"]:
        if f["best"] is None:
            print(f"| - | {f['template']} | no verified design | | | {f['failed'][:1]} |")
    if res_s["ranking"]:
        flat = max(res_s["ranking"], key=lambda r: r["ratio"])
        print(f"\nflattest verified hinge: {flat['template']}, worst / zero-stroke = {flat['ratio']:.3f} "
              f"(published optimised large-stroke hinges: about 0.75)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grid", type=int, default=15)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--skip-grid", action="store_true")
    args = ap.parse_args()
    if not args.skip_grid:
        grid_check(args.grid, args.workers)
    speed(args.workers, args.repeat)


if __name__ == "__main__":
    main()
