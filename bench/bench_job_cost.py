"""Cost of optimisation cases: the data behind ``service.api.cost.CALIBRATION`` (issue 29 item 8).

1. Unit costs, interleaved over three rounds (medians): one search evaluation (exact curve with gradients) of
   the cross-spring pivot meshed with 6, 12 and 24 segments per leaf, 2 and 4 design parameters, 5 and 9
   stroke samples; one exact curve of 31 and 121 points of the same meshes; the 'auto' curve against the exact
   one (preview, screening). Fitted by non-negative least squares to the model of ``service/api/cost.py``.
2. Evaluations per solver iteration when the budget is spent: cases with ``max_iterations`` 2 and 4, no
   refinement, a tolerance the solver cannot meet.
3. Whole cases (``optim.search.run_case``, the unit a job runs): several templates, meshes, samples, budgets,
   and one topology candidate's first-pass and full-pass case: measured seconds against the estimate with the
   fitted constants (the estimate is a budget: a case that converges early takes less).

Prints the fitted constants (to copy into ``CALIBRATION``) and the table. The load average (``uptime``) is
printed before and after: on the shared 2 cores the constants err on the slow side. Not a test.

Usage::

    OPENBLAS_NUM_THREADS=1 python bench/bench_job_cost.py [--rounds 3]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import time

import numpy as np
from flexopt.model import Analysis, template
from flexopt.model.methods import frequency_curve as fast_curve
from flexopt.model.structure import compile_scene
from flexopt.optim.problem import Problem
from flexopt.optim.search import FamilyEvaluator, cases, run_case
from flexopt.optim.topology.grammar import parse
from flexopt.optim.topology.rank import candidate_problem
from flexopt.optim.topology.spec import TopologySpec
from flexopt.service.api.cost import CALIBRATION, case_seconds, optimisation_estimate
from scipy.optimize import nnls

CROSS = {"length": (0.03, 0.07), "thickness": (1.5e-4, 4e-4)}
CROSS4 = {**CROSS, "width": (0.005, 0.02), "angle": (60.0, 120.0)}


def _uptime() -> str:
    return subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()


def _problem(design: dict, segments: int, **kw: object) -> Problem:
    return Problem.model_validate(
        {"families": [{"template": "cross-spring-pivot", "design": design, "fixed": {"segments": segments}}], **kw}
    )


def _units(rounds: int) -> tuple[list, list, list]:
    """(n, d, S, seconds) of evaluations, (n, P, seconds) of exact curves, auto/exact time ratios."""
    rng = np.random.default_rng(0)
    evals: dict[tuple, list[float]] = {}
    curves: dict[tuple, list[float]] = {}
    fast: list[float] = []
    setups = [(seg, design, s) for seg in (6, 12, 24) for design in (CROSS, CROSS4) for s in (5, 9)]
    for r in range(rounds):
        for seg, design, s in setups[r % len(setups) :] + setups[: r % len(setups)]:  # rotate: interleaved
            fam = FamilyEvaluator(p := _problem(design, seg, samples=s), p.families[0])
            n = compile_scene(template("cross-spring-pivot", segments=seg)).n_dof
            fam.evaluate(rng.random(len(fam.names)))  # kernels compiled outside the timing
            t = time.perf_counter()
            fam.evaluate(rng.random(len(fam.names)))
            evals.setdefault((n, len(design), s), []).append(time.perf_counter() - t)
        for seg in (6, 12, 24):
            an = Analysis(template("cross-spring-pivot", segments=seg))
            n = an.structure.n_dof
            for pts in (31, 121):
                t = time.perf_counter()
                an.frequency_curve(np.linspace(-45, 45, pts))
                curves.setdefault((n, pts), []).append(time.perf_counter() - t)
            an = Analysis(template("cross-spring-pivot", segments=seg))
            t = time.perf_counter()
            fast_curve(an, "auto", 1e-3, np.linspace(-45, 45, 61))
            ta = time.perf_counter() - t
            an = Analysis(template("cross-spring-pivot", segments=seg))
            t = time.perf_counter()
            an.frequency_curve(np.linspace(-45, 45, 61))
            fast.append(ta / (time.perf_counter() - t))
    return (
        [(*k, statistics.median(v)) for k, v in evals.items()],
        [(*k, statistics.median(v)) for k, v in curves.items()],
        fast,
    )


def _evals_per_iteration() -> float:
    out = []
    for budget in (2, 4):
        prob = _problem(CROSS4, 8, samples=5, max_iterations=budget, refine_rounds=0, preview=False, tolerance=1e-9)
        rec = run_case(cases(prob)[0])
        out.append((rec["evaluations"] - 1) / budget)
        print(f"  max_iterations {budget}: {rec['evaluations']} evaluations ({rec['status']})")
    return max(out)


def _whole_cases(cal: dict[str, float], rounds: int) -> None:
    topo = TopologySpec.model_validate({"topologies": ["R:+-"], "starts": 1, "segments": 6, "samples": 5})
    t = parse("R:+-")
    specs = [
        (
            "cross-spring-pivot 8 seg, 2 param, S 5, budget 3, R 0",
            _problem(CROSS, 8, samples=5, max_iterations=3, refine_rounds=0, verify_points=31, tolerance=1e-9),
        ),
        (
            "cross-spring-pivot 12 seg, 4 param, S 5, budget 3, R 0",
            _problem(CROSS4, 12, samples=5, max_iterations=3, refine_rounds=0, verify_points=61, tolerance=1e-9),
        ),
        ("cross-spring-pivot 12 seg, defaults but S 5, V 61", _problem(CROSS, 12, samples=5, verify_points=61)),
        (
            "cartwheel-hinge defaults, S 5, V 61",
            Problem.model_validate(
                {"families": [{"template": "cartwheel-hinge", "design": CROSS}], "samples": 5, "verify_points": 61}
            ),
        ),
        ("topology R:+- first pass", candidate_problem(t, topo, first_pass=True)),
        ("topology R:+- full pass (6 seg, S 5)", candidate_problem(t, topo)),
    ]
    measured: dict[str, list[float]] = {}
    for r in range(rounds):
        for name, prob in specs[r % len(specs) :] + specs[: r % len(specs)]:
            case = cases(prob.model_copy(update={"starts": 1}))[0]
            t0 = time.perf_counter()
            rec = run_case(case)
            measured.setdefault(name, []).append(time.perf_counter() - t0)
            measured.setdefault(name + " evaluations", []).append(rec["evaluations"])
    print("| case | measured [s] | evaluations | estimate (budget) [s] | estimate / measured |")
    print("|---|---:|---:|---:|---:|")
    for name, prob in specs:
        est = optimisation_estimate(prob.model_copy(update={"starts": 1}), cal).seconds
        m = statistics.median(measured[name])
        ev = statistics.median(measured[name + " evaluations"])
        print(f"| {name} | {m:.2f} | {ev:.0f} | {est:.2f} | {est / m:.1f} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    print("load before:", _uptime(), f"(OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS')})")
    # compile the kernels once, outside every timing
    Analysis(template("cross-spring-pivot")).frequency_curve(np.linspace(-45, 45, 3))
    evals, curves, fast = _units(args.rounds)
    a = np.array([[1.0, s * n, s * n * d] for n, d, s, _ in evals])
    (e0, e1, e2), _ = nnls(a, np.array([v for *_, v in evals]))
    b = np.array([[1.0, p * n] for n, p, _ in curves])
    (c0, c1), _ = nnls(b, np.array([v for *_, v in curves]))
    print("| n | d | S | evaluation [s] | fitted [s] |\n|---:|---:|---:|---:|---:|")
    for n, d, s, v in sorted(evals):
        print(f"| {n} | {d} | {s} | {v:.3f} | {e0 + s * n * (e1 + e2 * d):.3f} |")
    print("| n | points | exact curve [s] | fitted [s] |\n|---:|---:|---:|---:|")
    for n, p, v in sorted(curves):
        print(f"| {n} | {p} | {v:.3f} | {c0 + p * n * c1:.3f} |")
    print("evaluations per iteration, the budget spent:")
    k = _evals_per_iteration()
    cal = {
        **CALIBRATION,
        "EVAL_BASE": round(float(e0), 3),
        "EVAL_DOF": float(f"{e1:.2g}"),
        "EVAL_DOF_PARAM": float(f"{e2:.2g}"),
        "CURVE_BASE": round(float(c0), 3),
        "CURVE_DOF": float(f"{c1:.2g}"),
        "EVALS_PER_ITERATION": round(k, 2),
        "FAST": round(statistics.median(fast), 2),
    }
    print("fitted CALIBRATION:", cal)
    _whole_cases(cal, args.rounds)
    print("one default case (cross-spring-pivot, 12 segments, 9 samples, 30 iterations x 4 rounds, 181 points):")
    print("  budget split [s]:", {k: round(v, 1) for k, v in case_seconds(150, 2, 9, 30, 3, 181, 0, True, cal).items()})
    print("load after:", _uptime())


if __name__ == "__main__":
    main()
