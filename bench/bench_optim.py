"""Optimiser benchmark: correctness against a grid search, the coarse-then-verify ladder against an exact-only
dense search, and per hinge family the optimum, its status, KKT residual, active bounds and time, for SLSQP
and scipy's trust-constr on the same problems, in the families' own boxes and in one common envelope.

Run from the repository root: ``python bench/bench_optim.py [--grid 11] [--workers 2] [--starts 4]
[--skip-grid] [--skip-speed] [--solvers slsqp,trust-constr]``. Prints markdown tables for the README, then the
four families in one ``optimise`` call (SLSQP), as the topology search runs them.
Wall-clock times of single runs (an optimisation is seconds long); the two solvers run interleaved, family by
family, so that a change of the machine's load affects both alike.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ["PYTHONPATH"] = str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")

from flexopt.model import Analysis, template  # noqa: E402
from flexopt.model.templates import DESIGN_SPACES, TEMPLATES  # noqa: E402
from flexopt.optim import optimise  # noqa: E402

PIVOT = {"template": "cross-spring-pivot", "design": {"length": [0.03, 0.07], "thickness": [1.5e-4, 4e-4]}}

# One space for every family: a cylinder around the hinge axis (radius 35 mm, height 40 mm) bounding every
# node and leaf edge, the same 0.1 kg moving body, and boxes wide enough that the envelope (not the box)
# limits the size: length 20-140 mm, width 5-60 mm, thickness 0.05-1 mm, crossing angle 30-150 deg.
ENVELOPE = {"radius": 0.035, "half_height": 0.02}
WIDE = {"length": (0.02, 0.14), "thickness": (5e-5, 1e-3), "width": (0.005, 0.06), "angle": (30.0, 150.0)}


def _families(wide: bool) -> list[dict]:
    fams = []
    for name, box in DESIGN_SPACES.items():
        if name in TEMPLATES and TEMPLATES[name][1].get("stroke", 0) == 45.0:
            fams.append(
                {"template": name, "design": {k: list(WIDE[k] if wide and k in WIDE else v) for k, v in box.items()}}
            )
    return fams


def _timed(spec: dict, workers: int) -> tuple[dict, float]:
    t = time.perf_counter()
    res = optimise(spec, workers=workers)
    return res, time.perf_counter() - t


def grid_check(n: int, workers: int) -> None:
    res, _ = _timed({"families": [PIVOT], "starts": 4}, workers)
    opt = res["ranking"][0]["worst_hz"] if res["ranking"] else float("nan")
    allow = 600e6 / 1.5
    best, arg = 0.0, None
    t = time.perf_counter()
    for L in np.linspace(*PIVOT["design"]["length"], n):
        for th in np.linspace(*PIVOT["design"]["thickness"], n):
            c = Analysis(
                template("cross-spring-pivot", length=float(L), thickness=float(th), points=61)
            ).frequency_curve()
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
    print(
        f"| optimiser (4 starts) | {opt:.3f} | L {d.get('length', 0) * 1e3:.2f} mm, t {d.get('thickness', 0) * 1e6:.1f} um | |"
    )
    print(
        f"| grid {n} x {n} (61-point curves, best re-verified) | {best181:.3f} | L {arg[0] * 1e3:.2f} mm, "
        f"t {arg[1] * 1e6:.1f} um | {grid_s:.1f} |"
    )
    print(f"\noptimiser / grid = {opt / best181:.4f} (criterion: >= 0.995)")


def speed(workers: int) -> None:
    one = {"families": [PIVOT], "starts": 4}
    dense = dict(one, samples=61, refine_rounds=0)
    rows = []
    for label, spec in (
        ("ladder (9 samples + 181-point verification)", one),
        ("exact-only dense search (61 samples)", dense),
    ):
        res, t = _timed(spec, workers)
        rows.append((label, t, res["ranking"][0]["worst_hz"] if res["ranking"] else float("nan")))
    print(f"\n### Time, cross-spring pivot, 1 family x 4 starts ({workers} worker processes, {os.cpu_count()} CPUs)\n")
    print("| run | wall time [s] | verified worst [Hz] |")
    print("|---|---|---|")
    for label, t, w in rows:
        print(f"| {label} | {t:.1f} | {w:.3f} |")
    print(f"\nladder speed-up over the dense exact search: {rows[1][1] / rows[0][1]:.1f}x")


def _design(d: dict) -> str:
    unit = {
        "length": (1e3, "mm"),
        "thickness": (1e3, "mm"),
        "width": (1e3, "mm"),
        "angle": (1, "deg"),
        "crossing": (1, ""),
    }
    return ", ".join(
        f"{k} {v * unit.get(k, (1, ''))[0]:.4g}{(' ' + unit[k][1]) if unit.get(k, (1, ''))[1] else ''}"
        for k, v in d.items()
    )


def families(workers: int, starts: int, solvers: list[str], fair: bool) -> None:
    base = {"starts": starts}
    if fair:
        base.update(envelope=ENVELOPE, body_mass=0.1)
    title = (
        "one envelope (cylinder r 35 mm, half-height 20 mm, nodes and leaf edges), 0.1 kg moving body, wide boxes"
        if fair
        else "each family in its own box (DESIGN_SPACES), no envelope"
    )
    print(f"\n### Hinge families, +-45 deg, {starts} starts each: {title}\n")
    print(
        "| family | solver | worst [Hz] | worst / zero | optimal starts | spread of optimal starts | KKT residual "
        "(best) | active bounds | active constraints | time [s] | design |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    summary, notes = [], []
    for fam in _families(wide=fair):
        for solver in solvers:
            res, t = _timed(dict(base, families=[fam], solver=solver), workers)
            f = res["families"][0]
            b = f["best"]
            others = ", ".join(f"{x['status']}" for x in f["failed"])
            starts_col = f"{f['optimal_starts']}/{f['starts']}" + (f" ({others})" if others else "")
            notes += [
                f"- {fam['template']}, {solver}, start {x['start']}: {x['status']}: {x['message']}" for x in f["failed"]
            ]
            if b is None:
                print(f"| {fam['template']} | {solver} | - | - | {starts_col} | - | - | - | - | {t:.1f} | |")
                continue
            v, o = b["verified"], b["optimality"]
            bounds = ", ".join(f"{k} {side}" for k, side in o["active_bounds"].items()) or "none"
            print(
                f"| {fam['template']} | {solver} | {v['worst_hz']:.2f} | {v['ratio']:.3f} | {starts_col} | "
                f"{f['spread'] * 100:.2f} % | {o['kkt_residual']:.1e} | {bounds} | {', '.join(o['active_kinds'])} | "
                f"{t:.1f} | {_design(b['design'])} |"
            )
            summary.append((solver, fam["template"], v["worst_hz"], t))
    print("\n" + "\n".join(notes) if notes else "")
    for solver in solvers:
        rank = sorted((s for s in summary if s[0] == solver), key=lambda s: -s[2])
        print(
            f"\n{solver}: ranking {' > '.join(f'{s[1]} ({s[2]:.2f} Hz)' for s in rank)}; total "
            f"{sum(s[3] for s in summary if s[0] == solver):.1f} s"
        )


def combined(workers: int, starts: int) -> None:
    """The four hinge families in one ``optimise`` call (one process pool, the cases of all families queued
    together), as a topology search runs them; the per-family tables above start a pool per family."""
    fams = _families(wide=False)
    res, t = _timed({"families": fams, "starts": starts}, workers)
    print(
        f"\n### All {len(fams)} families in one optimise call ({starts} starts each, {workers} worker processes, "
        f"each family in its own box)\n"
    )
    print(
        f"wall time {t:.1f} s; ranking "
        + " > ".join(f"{f['template']} ({f['worst_hz']:.2f} Hz)" for f in res["ranking"])
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--grid", type=int, default=11)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--starts", type=int, default=4)
    ap.add_argument("--solvers", default="slsqp,trust-constr")
    ap.add_argument("--skip-grid", action="store_true")
    ap.add_argument("--skip-speed", action="store_true")
    args = ap.parse_args()
    print(f"load before: {os.getloadavg()}")
    if not args.skip_grid:
        grid_check(args.grid, args.workers)
    if not args.skip_speed:
        speed(args.workers)
    solvers = args.solvers.split(",")
    families(args.workers, args.starts, solvers, fair=False)
    families(args.workers, args.starts, solvers, fair=True)
    combined(args.workers, args.starts)
    print(f"\nload after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
