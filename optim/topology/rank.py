"""Shape optimisation of the screened topologies under one problem, and their ranking.

Every accepted candidate is optimised with the existing worst-case formulation (:mod:`optim.search`: the
epigraph of the lowest parasitic frequencies at the stroke samples, per-end squared stress rows, the
common cylinder envelope, exact design gradients, verification on a dense exact grid) as a one-family
:class:`optim.problem.Problem` of the ``topology-hinge`` template with the same envelope, stress limit,
material, moving-body mass and inertia for every candidate, so that the ranking is fair. All starts of all
candidates run as one batch (:func:`optim.batch.run_cases`: a local process pool, or any executor such as a
Dask cluster's), resumable from a store, with progress.

Design space of a candidate (:func:`design_space`): its continuous parameters
(:func:`.grammar.design_parameters`) with bounds inside the common envelope: length up to twice the
envelope's radius (a leaf crossing the axis at its midpoint reaches a radius of half its length; the
envelope rows bound the rest), width up to what lets the candidate's stack of layers fit the envelope's
height with its gaps, thickness from the problem's minimum, angle 30-150 degrees, crossing fraction
0.15-0.85, rigid fraction 0.1-0.6.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from ..problem import Family, Problem
from .grammar import Topology, canonical, design_parameters, enumerate_topologies, family_of, parse
from .spec import TopologySpec, example_spec
from ...model.threads import limited

__all__ = ["TopologySpec", "example_spec", "run_topology_search", "design_space", "candidate_problem",
           "family_problem"]


def _layers(t: Topology) -> tuple[int, int]:
    """(layers, sum of width multiples over the layers) of a topology's stack."""
    n = sum(s.layers for s in t.stages)
    w = sum(max(lf.width for lf in s.leaves) if s.inplane else sum(lf.width for lf in s.leaves) for s in t.stages)
    return n, w


_GAP = 0.002  # the template's gap between layers [m]


def design_space(t: Topology, spec: TopologySpec) -> dict[str, tuple[float, float]]:
    """The candidate's continuous parameters with bounds inside the common envelope (module docstring)."""
    env = spec.envelope
    n, wsum = _layers(t)
    height = 2 * env.half_height if env.half_height is not None else 0.1
    w_hi = (height - (n - 1) * _GAP) / wsum
    box = {"length": (0.02, 2 * env.radius), "thickness": (max(spec.min_thickness, 5e-5), 1e-3),
           "width": (min(0.005, 0.5 * w_hi), w_hi), "angle": (30.0, 150.0), "crossing": (0.15, 0.85),
           "rigid_fraction": (0.1, 0.6)}
    return {k: box[k] for k in design_parameters(t)}


def candidate_problem(t: Topology, spec: TopologySpec) -> Problem:
    """The one-family optimisation problem of a candidate (the same for every candidate but its family)."""
    r = (2 * spec.body_inertia / spec.body_mass) ** 0.5  # the template's inertia m r^2 / 2
    fam = Family(template="topology-hinge", design=design_space(t, spec),
                 fixed={"topology": str(t), "segments": spec.segments, "body_radius": r,
                        "mid_mass": spec.intermediate_mass, "gap": _GAP})
    return Problem(families=[fam], stroke=spec.stroke, samples=spec.samples, safety_factor=spec.safety_factor,
                   min_thickness=spec.min_thickness, envelope=spec.envelope, body_mass=spec.body_mass,
                   solver=spec.solver, starts=spec.starts, seed=spec.seed, max_iterations=spec.max_iterations,
                   refine_rounds=spec.refine_rounds, verify_points=spec.verify_points)


def family_problem(name: str, descriptor: str, spec: TopologySpec) -> dict:
    """The problem of candidate ``descriptor`` with the hand-made family ``name``'s own template in place of
    ``topology-hinge`` (same design bounds, envelope, mass and limits): the reference a search restricted to
    that family must reproduce (tests/test_topology.py, bench/bench_topology.py)."""
    prob = candidate_problem(parse(descriptor), spec).model_dump(mode="json")
    fam = prob["families"][0]
    fam["template"] = name
    fam["fixed"] = {k: v for k, v in fam["fixed"].items() if k != "topology"}
    if name in ("cross-spring-pivot", "three-fold-cross-hinge", "cartwheel-hinge"):
        fam["fixed"].pop("mid_mass", None)  # no intermediate body
    if name == "cartwheel-hinge":
        fam["fixed"].pop("gap", None)  # the leaves cross in one plane
    return prob


def _traceable(t: Topology, prob: Problem) -> str | None:
    """None when the candidate's scene can be traced with CasADi symbols at its start, else why not."""
    from ...model.design import trace_template
    from ...model.errors import FlexoptError
    from ..search import _Family

    try:
        fam = _Family(prob, prob.families[0])
        trace_template("topology-hinge", fam.params(fam.default_x()), fam.names)
    except (FlexoptError, ValueError, RuntimeError) as exc:  # casadi raises RuntimeError
        return f"cannot be traced for exact design gradients: {exc}"
    return None


def _candidates(spec: TopologySpec) -> list[Topology]:
    if spec.topologies is not None:
        seen: dict[str, Topology] = {}
        for d in spec.topologies:
            c = canonical(d)
            seen.setdefault(str(c), c)
        return list(seen.values())
    return enumerate_topologies(spec.max_flexures, spec.max_stages, spec.planes, spec.inplane, spec.free_crossing,
                                spec.reinforcement)


@limited()  # one BLAS thread while it computes (model.threads)
def run_topology_search(spec: TopologySpec | dict, *, executor: Any = None, workers: int | None = None,
                        store: Any = None, progress: Callable[[dict], None] | None = None, cancel: Any = None) -> dict:
    """Generate, screen, optimise and rank hinge topologies (the unit of work a service job calls).

    Parameters
    ----------
    spec
        A :class:`TopologySpec` or its JSON.
    executor, workers, store, progress, cancel
        As :func:`optim.batch.run_cases`: any ``concurrent.futures.Executor`` (default a local process pool
        of ``workers``), a directory of finished cases (a rerun resumes), a callback per finished case
        (``{"done", "total", "id", "status"}``) and a ``threading.Event`` that stops the batch.

    Returns
    -------
    dict
        JSON-serialisable: ``spec``, ``counts`` (generated, rejected by reason kind, untraceable, optimised,
        failed), ``candidates`` (each ``topology``, ``family``, ``dof``, ``intended_dof``,
        ``overconstraints``, ``self_stress``, ``release``, ``status`` (``rejected`` with ``reason``,
        ``optimised``, ``untraceable`` or ``failed`` with ``reason``), ``same_design_as`` (a designed
        crossing that ends at the midpoint: the descriptor without '@'), ``worst_case_hz``,
        ``zero_stroke_hz``, ``ratio``, ``design``, ``stress_ratio``, ``kkt_residual``, ``active_bounds``,
        ``starts``), ``ranking`` (descriptors of the optimised candidates, best first), ``best`` (the first
        candidate of the ranking, or None), ``seconds`` (``screen``, ``optimise``).
    """
    from ..batch import run_cases
    from ..search import cases as problem_cases
    from .screen import screen_topology

    spec = TopologySpec.model_validate(spec)
    if spec.motion == "translation":
        return _guide_search(spec)
    t0 = time.perf_counter()
    tops = _candidates(spec)
    records: list[dict] = []
    jobs: list[tuple[int, Problem]] = []
    for t in tops:
        sc = screen_topology(t, spec.allow_overconstraints)
        rec = {"topology": str(t), "family": family_of(t), "flexures": t.flexures, "stages": len(t.stages),
               "dof": sc["dof"], "intended_dof": 1 + sc["intended_motions"], "overconstraints": sc["overconstraints"],
               "self_stress": sc["self_stress"], "release": sc["release"], "free_motions": sc["free_motions"],
               "status": "rejected" if sc["status"] == "rejected" else "pending", "reason": sc["reason"],
               "worst_case_hz": None, "zero_stroke_hz": None, "ratio": None, "design": None}
        if rec["status"] == "pending":
            prob = candidate_problem(t, spec)
            why = _traceable(t, prob)
            if why:
                rec.update(status="untraceable", reason=why)
            else:
                jobs.append((len(records), prob))
        records.append(rec)
    t_screen = time.perf_counter() - t0
    batch = [c for _, prob in jobs for c in problem_cases(prob)]
    results = run_cases(batch, "flexopt.optim.search:run_case", executor=executor, workers=workers, store=store,
                        progress=progress, cancel=cancel) if batch else []
    k = 0
    for i, prob in jobs:
        rs = results[k:k + prob.starts]
        k += prob.starts
        _fill(records[i], rs)
    _mark_same_designs(records)
    ranked = sorted((r for r in records if r["status"] == "optimised"), key=lambda r: -r["worst_case_hz"])
    counts = {"generated": len(records), "rejected": sum(r["status"] == "rejected" for r in records),
              "untraceable": sum(r["status"] == "untraceable" for r in records),
              "optimised": len(ranked), "failed": sum(r["status"] == "failed" for r in records)}
    return _result(spec, records, ranked, counts,
                   {"screen": t_screen, "optimise": time.perf_counter() - t0 - t_screen})


def _mark_same_designs(records: list[dict], tol: float = 1e-3) -> None:
    """``same_design_as``: for a candidate with a designed crossing ('@') whose optimum crosses at the midpoint
    (within ``tol``), the candidate without '@', whose scene is then the same; None otherwise."""
    by_name = {r["topology"]: r for r in records}
    for r in records:
        r["same_design_as"] = None
        if r["status"] != "optimised" or "crossing" not in r["design"] or abs(r["design"]["crossing"] - 0.5) > tol:
            continue
        base = str(canonical(r["topology"].replace("@", "")))
        if base != r["topology"] and base in by_name:
            r["same_design_as"] = base


def _fill(rec: dict, starts: list[dict]) -> None:
    """A candidate's record from its starts' results: the best start that is optimal (converged, verified,
    feasible), else the reason none is."""
    ok = [r for r in starts if r.get("status") == "optimal" and (r.get("verified") or {}).get("worst_hz") is not None]
    rec["starts"] = [{"start": r.get("start"), "status": r.get("status", "failed"),
                      "message": r.get("message") or r.get("error"),
                      "worst_hz": (r.get("verified") or {}).get("worst_hz"), "seconds": r.get("seconds")}
                     for r in starts]
    if not ok:
        why = "; ".join(f"start {s['start']}: {s['status']} ({s['message']})" for s in rec["starts"])
        rec.update(status="failed", reason=f"no start reached a converged, verified, feasible optimum: {why}")
        return
    b = max(ok, key=lambda r: r["verified"]["worst_hz"])
    v = b["verified"]
    rec.update(status="optimised", reason=None, worst_case_hz=v["worst_hz"], zero_stroke_hz=v["zero_stroke_hz"],
               ratio=v["ratio"], design=b["design"], stress_ratio=v["stress_ratio"],
               kkt_residual=b["optimality"]["kkt_residual"], active_bounds=b["optimality"]["active_bounds"],
               moving_mass=b.get("moving_mass"), scene=v.get("scene"), curve={"stroke": v.get("stroke"),
                                                                              "parasitic_hz": v.get("parasitic_hz")},
               warnings=b.get("warnings", []))


def _guide_search(spec: TopologySpec) -> dict:
    """Straight guides: every arrangement of up to ``max_flexures`` wires (or the listed descriptors) screened;
    the accepted ones ranked by the condition number of their scaled D_cc (smaller: further from a singular,
    compliant arrangement). No shape optimisation (the optimiser's families are hinges)."""
    from .grammar import canonical_guide, enumerate_guides
    from .screen import screen_guide

    t0 = time.perf_counter()
    if spec.topologies is not None:
        guides = list({str(canonical_guide(d)): canonical_guide(d) for d in spec.topologies}.values())
    else:
        guides = [g for n in range(1, spec.max_flexures + 1) for g in enumerate_guides(n)]
    records = []
    for g in guides:
        sc = screen_guide(g, spec.allow_overconstraints)
        records.append({"topology": str(g), "family": None, "flexures": g.flexures, "stages": 1, "dof": sc["dof"],
                        "intended_dof": 1, "overconstraints": sc["overconstraints"], "self_stress": sc["self_stress"],
                        "release": sc["release"], "free_motions": sc["free_motions"],
                        "condition_number": sc["condition_number"],
                        "status": "accepted" if sc["status"] == "accepted" else "rejected", "reason": sc["reason"],
                        "worst_case_hz": None, "zero_stroke_hz": None, "ratio": None, "design": None})
    ranked = sorted((r for r in records if r["status"] == "accepted"), key=lambda r: r["condition_number"])
    counts = {"generated": len(records), "rejected": len(records) - len(ranked), "untraceable": 0, "optimised": 0,
              "accepted": len(ranked), "failed": 0}
    return _result(spec, records, ranked, counts, {"screen": time.perf_counter() - t0, "optimise": 0.0})


def _result(spec: TopologySpec, records: list[dict], ranked: list[dict], counts: dict[str, int],
            seconds: dict[str, float]) -> dict:
    """The search's JSON answer (hinges and guides alike): counts with the rejections by reason, every
    candidate, the ranking and the best."""
    rejected_by: dict[str, int] = {}
    for r in records:
        if r["status"] == "rejected":
            kind = r["reason"].split(":", 1)[0]
            rejected_by[kind] = rejected_by.get(kind, 0) + 1
    counts_out: dict[str, Any] = {"generated": counts["generated"], "rejected": counts["rejected"],
                                  "rejected_by": rejected_by,
                                  **{k: v for k, v in counts.items() if k not in ("generated", "rejected")}}
    return {"format": "flexopt-topology-result", "version": 1, "spec": spec.model_dump(mode="json"),
            "counts": counts_out, "candidates": records, "ranking": [r["topology"] for r in ranked],
            "best": ranked[0] if ranked else None, "seconds": seconds}
