"""Shape optimisation of the screened topologies under one problem, and their ranking.

Every accepted candidate is optimised with the existing worst-case formulation (:mod:`optim.search`: the
epigraph of the lowest parasitic frequencies at the stroke samples, per-end squared stress rows, the
common cylinder envelope, exact design gradients, verification on a dense exact grid) as a one-family
:class:`optim.problem.Problem` of the ``topology-hinge`` template with the same envelope, stress limit,
material, moving-body mass and inertia for every candidate, so that the ranking is fair.

Schedule (:func:`run_topology_search`; every phase a batch on one executor, :func:`optim.batch.run_cases`:
a local process pool or any executor such as a Dask cluster's, resumable from one store, with progress)
-----------------------------------------------------------------------------------------------------------
1. *Generate* (:func:`.grammar.enumerate_topologies`, with ``prune`` no designed crossing on a stage that
   crosses nothing) and *screen* (:mod:`.screen`, the exact-constraint filter; candidates that differ only
   by '@' or 'r' share one verdict, :func:`.screen.screen_key`). A candidate whose pass finds no optimum is
   checked for exact design gradients (:func:`.screen.traceable`) and, if its scene cannot be traced,
   marked ``untraceable`` (tracing every survivor in the screen cost more than half of its time).
2. *First pass* (``schedule="multi-fidelity"`` and more survivors than ``promote_min``): every survivor one
   start on a coarse mesh (``first_pass_segments``), few samples (``first_pass_samples``), no refinement,
   no mesh estimate, in the smallest design space (``first_pass_dimensions``, default shared dimensions:
   measured, a case of ``R:+-|-+|+-`` takes 14 s shared and 41 s per stage on the loaded 2-core machine).
   In two tiers: first every candidate without a designed crossing ('@'; or whose midpoint variant is no
   candidate), from its own start; then every designed-crossing variant warm-started at its midpoint
   variant's first-pass design with the crossing at 0.5 (a point of its own design space, so it starts
   where its midpoint variant ended: measured, a third of a cold case's time when the midpoint is
   stationary, as it is for 355 of the default space's 399 variants).
   A designed crossing that ends at the midpoint (within :data:`_SAME_CROSSING`) while its midpoint
   variant is a candidate too is pruned: it reduces to that variant, which inherits its score.
3. *Full pass*: the best ``max(promote_min, promote x scored)`` by the first pass's verified worst case
   (every survivor with ``"exhaustive"``) get ``starts`` starts on the search's mesh; start 0 begins at the
   candidate's first-pass design (per-stage dimensions inherit its shared values), the others at their own
   points. No mesh estimate on the search's mesh: the refined verification gives it.
4. *Refined verification* of every optimum (``refine_segments``, "auto": the mesh that meets
   ``refine_tolerance``, :mod:`model.mesh`): worst case, zero-stroke frequency, stress and the mesh error
   there; the ranking is by the refined worst case, feasible (refined stress within the limit) first.
Cases are keyed by their content only (the problem without ``starts``, :func:`optim.search.cases`), so a
rerun with more starts or more candidates reuses every finished case of the store.

Design space of a candidate (:func:`design_space`, with :func:`bound_origins` saying where each bound comes
from): its continuous parameters (:func:`.grammar.design_parameters` under the spec's ``dimensions``) with
bounds inside the common envelope: length 20 mm up to twice the envelope's radius (a leaf crossing the axis
at its midpoint reaches a radius of half its length; the envelope rows bound the rest), width up to what
lets the candidate's stack of layers fit the envelope's height with its gaps (per stage: with the other
stages at their smallest width), thickness from the problem's minimum to 1 mm, angle 30-150 degrees,
crossing fraction 0.15-0.85, rigid fraction 0.1-0.6; with ``taper`` k each tapered leaf's zone thicknesses
(:func:`.grammar.zone_names`) have its thickness's bounds, and neighbouring zones are within ``max_taper`` of
each other (ratio rows both ways). Optional validity constraints (``min_length_over_width``,
``min_length_over_thickness``) bound every leaf's slenderness (:class:`optim.problem.Ratio`).
"""

from __future__ import annotations

import itertools
import math
import sys
import time
from collections.abc import Callable
from typing import Any

from ...model.threads import limited
from ..problem import Family, Problem, Ratio
from ..search import best_start, no_optimum_reason
from .grammar import Topology, candidate_topologies, canonical, design_parameters, family_of, parse, zone_names
from .spec import TopologySpec, example_spec, schedule_counts

__all__ = [
    "TopologySpec",
    "example_spec",
    "run_topology_search",
    "design_space",
    "bound_origins",
    "candidate_problem",
    "family_problem",
    "refine_case",
]

_GAP = 0.002  # the template's gap between layers [m]
_SAME_CROSSING = 0.02  # a first-pass crossing this close to 0.5 reduces to the midpoint variant
_SCREEN_CHUNK = 16  # descriptors per screening case (a verdict takes tens of milliseconds)


def _stage_width_sums(t: Topology) -> list[int]:
    """Per stage, the sum of the width multiples over its layers (an in-plane crossing is one layer)."""
    return [max(lf.width for lf in s.leaves) if s.inplane else sum(lf.width for lf in s.leaves) for s in t.stages]


def _layers(t: Topology) -> tuple[int, int]:
    """(layers, sum of width multiples over the layers) of a topology's stack."""
    return sum(s.layers for s in t.stages), sum(_stage_width_sums(t))


def _boxes(t: Topology, spec: TopologySpec) -> dict[str, tuple[float, float, str, str]]:
    """Every parameter's (lower, upper, origin of the lower, origin of the upper)."""
    env = spec.envelope
    n, wsum = _layers(t)
    height = 2 * env.half_height if env.half_height is not None else 0.1
    h_origin = (
        "the envelope's height" if env.half_height is not None else "0.1 m (no envelope height: the search's own)"
    ) + f" shared by the stack's {n} layer{'s' * (n > 1)} and {n - 1} gap{'s' * (n != 2)}"
    w_hi = (height - (n - 1) * _GAP) / wsum
    w_lo = min(0.005, 0.5 * w_hi)
    w_lo_origin = "5 mm, the search's smallest width" if w_lo == 0.005 else "half the width the envelope allows"
    t_lo = max(spec.min_thickness, 5e-5)
    box: dict[str, tuple[float, float, str, str]] = {
        "length": (
            0.02,
            2 * env.radius,
            "20 mm, the search's shortest leaf",
            "twice the envelope's radius (a leaf across the axis)",
        ),
        "thickness": (
            t_lo,
            1e-3,
            "the minimum manufacturable thickness (min_thickness)"
            if t_lo == spec.min_thickness
            else "50 um, the search's thinnest leaf",
            "1 mm, the search's thickest leaf",
        ),
        "width": (w_lo, w_hi, w_lo_origin, h_origin),
        "angle": (30.0, 150.0, "30 deg, the search's range of plane angles", "150 deg, the search's range"),
        "crossing": (0.15, 0.85, "0.15, the search's range of crossing fractions", "0.85, the search's range"),
        "rigid_fraction": (0.1, 0.6, "0.1, the search's range of rigid fractions", "0.6, the search's range"),
    }
    sums = _stage_width_sums(t)
    for k in range(1, len(t.stages)):
        box[f"length_s{k + 1}"] = box["length"]
        box[f"thickness_s{k + 1}"] = box["thickness"]
        box[f"angle_s{k + 1}"] = box["angle"]
    if spec.dimensions != "shared":  # each stage's width: the height left by the others at their smallest
        for k in range(len(t.stages)):
            hi = (height - (n - 1) * _GAP - (wsum - sums[k]) * w_lo) / sums[k]
            key = "width" if k == 0 else f"width_s{k + 1}"
            box[key] = (
                w_lo,
                hi,
                w_lo_origin,
                h_origin + (", the other stages at their smallest width" if len(t.stages) > 1 else ""),
            )
    for k, st in enumerate(t.stages):
        for i in range(len(st.leaves)):
            box[f"thickness_s{k + 1}l{i + 1}"] = box["thickness"]
    for name in [n for n in box if n.startswith("thickness")]:  # a tapered leaf's zones: as its thickness
        for z in zone_names(name, spec.taper, spec.taper_symmetric):
            box.setdefault(z, box[name])
    return box


def _names(t: Topology, spec: TopologySpec) -> list[str]:
    return design_parameters(t, spec.dimensions, spec.taper, spec.taper_symmetric)


def design_space(t: Topology, spec: TopologySpec) -> dict[str, tuple[float, float]]:
    """The candidate's continuous parameters with bounds inside the common envelope (module docstring)."""
    box = _boxes(t, spec)
    return {k: box[k][:2] for k in _names(t, spec)}


def bound_origins(t: Topology, spec: TopologySpec) -> dict[str, tuple[str, str]]:
    """Where each bound of :func:`design_space` comes from, (lower, upper) in words."""
    box = _boxes(t, spec)
    return {k: box[k][2:] for k in _names(t, spec)}


def _ratios(t: Topology, spec: TopologySpec) -> list[Ratio]:
    """The validity constraints of the spec on every stage's leaves (length over width times the widest
    multiple, length over thickness of each leaf's thickness parameter or zone), and a tapered leaf's bounded
    taper: each zone thickness at least 1 / ``max_taper`` times its neighbour's, both ways."""
    names = set(_names(t, spec))
    out: dict[tuple, Ratio] = {}
    for k, st in enumerate(t.stages):
        tag = "" if k == 0 or spec.dimensions == "shared" else f"_s{k + 1}"
        length, width = "length" + tag, "width" + tag
        if spec.min_length_over_width is not None:
            m = max(lf.width for lf in st.leaves)
            out[(length, width, m)] = Ratio(
                numerator=length,
                denominator=width,
                minimum=spec.min_length_over_width,
                factor=float(m),
                reason="leaves longer than wide: beams, not plates",
            )
        if spec.min_length_over_thickness is not None:
            th = (
                [f"thickness_s{k + 1}l{i + 1}" for i in range(len(st.leaves))]
                if spec.dimensions == "leaf"
                else ["thickness" + tag]
            )
            for name in [z for b in th for z in [b, *zone_names(b, spec.taper, spec.taper_symmetric)]]:
                if name in names:
                    out[(length, name, 1)] = Ratio(
                        numerator=length,
                        denominator=name,
                        minimum=spec.min_length_over_thickness,
                        reason="leaves longer than thick",
                    )
    if spec.taper > 1:
        for name in sorted({n.rsplit("_z", 1)[0] for n in names if "_z" in n}):
            zs = zone_names(name, spec.taper, spec.taper_symmetric)
            for a, b in itertools.pairwise(zs):
                for num, den in ((a, b), (b, a)):
                    out[(num, den, "taper")] = Ratio(
                        numerator=num,
                        denominator=den,
                        minimum=1.0 / spec.max_taper,
                        reason=f"neighbouring zones within max_taper {spec.max_taper:g}",
                    )
    return list(out.values())


def candidate_problem(t: Topology, spec: TopologySpec, first_pass: bool = False) -> Problem:
    """The one-family optimisation problem of a candidate (the same for every candidate but its family); with
    ``first_pass`` the schedule's cheap pass (one start, coarse mesh, few samples, no refinement)."""
    r = (2 * spec.body_inertia / spec.body_mass) ** 0.5  # the template's inertia m r^2 / 2
    if first_pass and spec.first_pass_dimensions != "same":  # the cheapest space: no zones either
        spec = spec.model_copy(update={"dimensions": spec.first_pass_dimensions, "taper": 1})
    taper = {"taper": spec.taper, "taper_symmetric": int(spec.taper_symmetric)} if spec.taper > 1 else {}
    fam = Family(
        template="topology-hinge",
        design=design_space(t, spec),
        origins=bound_origins(t, spec),
        ratios=_ratios(t, spec),
        fixed={
            "topology": str(t),
            "segments": spec.first_pass_segments if first_pass else spec.segments,
            "body_radius": r,
            "mid_mass": spec.intermediate_mass,
            "gap": _GAP,
            **taper,
        },
    )
    if first_pass:
        return Problem(
            families=[fam],
            stroke=spec.stroke,
            samples=spec.first_pass_samples,
            safety_factor=spec.safety_factor,
            min_thickness=spec.min_thickness,
            envelope=spec.envelope,
            body_mass=spec.body_mass,
            solver=spec.solver,
            starts=1,
            seed=spec.seed,
            max_iterations=spec.first_pass_iterations,
            refine_rounds=0,
            verify_points=31,
            preview=False,
        )
    return Problem(
        families=[fam],
        stroke=spec.stroke,
        samples=spec.samples,
        safety_factor=spec.safety_factor,
        min_thickness=spec.min_thickness,
        envelope=spec.envelope,
        body_mass=spec.body_mass,
        solver=spec.solver,
        starts=spec.starts,
        seed=spec.seed,
        max_iterations=spec.max_iterations,
        refine_rounds=spec.refine_rounds,
        verify_points=spec.verify_points,
        preview=False,  # the start's curve is for `flexopt optimise --plot`; measured 9 % of a full-pass case
    )


def family_problem(name: str, descriptor: str, spec: TopologySpec) -> dict:
    """The problem of candidate ``descriptor`` with the hand-made family ``name``'s own template in place of
    ``topology-hinge`` (same design bounds, envelope, mass and limits; shared dimensions, the families' own):
    the reference a search restricted to that family must reproduce (tests/test_topology.py,
    bench/bench_topology.py)."""
    spec = spec.model_copy(update={"dimensions": "shared", "taper": 1})  # the family templates have no zones
    prob = candidate_problem(parse(descriptor), spec).model_dump(mode="json")
    fam = prob["families"][0]
    fam["template"] = name
    fam["fixed"] = {k: v for k, v in fam["fixed"].items() if k != "topology"}
    if name in ("cross-spring-pivot", "three-fold-cross-hinge", "cartwheel-hinge"):
        fam["fixed"].pop("mid_mass", None)  # no intermediate body
    if name == "cartwheel-hinge":
        fam["fixed"].pop("gap", None)  # the leaves cross in one plane
    return prob


def _candidates(spec: TopologySpec) -> list[Topology]:
    return candidate_topologies(
        spec.topologies,
        spec.max_flexures,
        spec.max_stages,
        planes=spec.planes,
        inplane=spec.inplane,
        free_crossing=spec.free_crossing,
        reinforce=spec.reinforcement,
        prune=spec.prune,
    )


def refine_case(case: dict) -> dict:
    """A batch case of the refined verification: the exact curve of one optimum on the mesh ``segments``
    ("auto": every leaf's segments refined until the estimated error of the first parasitic frequency is
    within ``tolerance``, :func:`model.mesh.resolve_auto_segments`) at ``points`` stroke points and the
    ``extra`` strokes (the search's verified minimum), with its stress, and the mesh error estimated there
    (:func:`model.mesh.mesh_error`).

    ``case``: ``{"params", "stroke", "points", "extra", "segments", "tolerance", "safety_factor"}``.
    """
    import numpy as np

    from ...model.curve import Analysis
    from ...model.scene import Beam
    from ...model.templates import template
    from ..search import _curve_summary

    seg = case["segments"]
    scene = template("topology-hinge", **{**case["params"], "segments": 4 if seg == "auto" else int(seg)})
    if seg == "auto":
        els = tuple(e.model_copy(update={"segments": "auto"}) if isinstance(e, Beam) else e for e in scene.elements)
        scene = scene.model_copy(update={"elements": els, "mesh_tolerance": float(case["tolerance"])})
    an = Analysis(scene)
    s = float(case["stroke"])
    grid = np.unique(np.concatenate([np.linspace(-s, s, int(case["points"])), np.asarray(case["extra"], float)]))
    curve = an.frequency_curve(stroke=grid, mesh_error=True)
    out = _curve_summary(curve, len(grid))
    used = sorted({e.segments for e in an.scene.elements if isinstance(e, Beam)})
    out.update(
        segments=seg,
        segments_used=used,
        auto_note=an.auto_note,
        mesh_error=curve.mesh_error,
        tolerance=case["tolerance"] if seg == "auto" else None,
        warnings=[w.to_dict() for w in curve.warnings],
    )
    if "worst_hz" in out:
        mats = {m.name: m for m in an.scene.materials}
        allow = min(mats[e.material].allowable_stress for e in an.scene.elements)
        peak = np.nan_to_num(np.array([curve.max_von_mises[m] for m in curve.max_von_mises]), nan=-np.inf)
        im, ip = np.unravel_index(int(np.argmax(peak)), peak.shape)
        out.update(
            stress_ratio=float(peak[im, ip]) * float(case["safety_factor"]) / allow,
            member_at_max_stress=list(curve.max_von_mises)[im],
            stroke_at_max_stress=float(curve.stroke[ip]),
        )
    return out


class _Tracker:
    """Progress of a search: counts (generated, screened, passed, first pass, optimised, verified) and the best
    so far, given to the caller's callback with every batch event and written as one line per event to
    stderr when it is not a terminal (logs), one line per phase when it is (the batch draws its own bar)."""

    def __init__(self, progress: Callable[[dict], None] | None, generated: int, echo: bool) -> None:
        self.progress, self.echo, self.tty = progress, echo, sys.stderr.isatty()
        self.counts = {
            "generated": generated,
            "screened": 0,
            "passed": 0,
            "first_pass": 0,
            "optimised": 0,
            "verified": 0,
        }
        self.best: dict | None = None
        self.t0 = time.perf_counter()

    def offer(self, descriptor: str, hz: float | None, phase: str) -> None:
        if hz is not None and (self.best is None or hz > self.best["worst_hz"]):
            self.best = {"topology": descriptor, "worst_hz": hz, "phase": phase}

    def line(self, phase: str, done: int | None = None, total: int | None = None) -> str:
        c = self.counts
        best = (
            f", best {self.best['topology']} {self.best['worst_hz']:.2f} Hz ({self.best['phase']})" if self.best else ""
        )
        where = f" {done}/{total}" if total is not None else ""
        return (
            f"topology search {time.perf_counter() - self.t0:.0f} s: {phase}{where}: generated {c['generated']}, "
            f"screened {c['screened']}, passed {c['passed']}, first pass {c['first_pass']}, optimised "
            f"{c['optimised']}, verified {c['verified']}{best}"
        )

    def event(self, phase: str, ev: dict) -> None:
        out = {k: v for k, v in ev.items() if k != "record"}
        out.update(phase=phase, counts=dict(self.counts), best=self.best)
        if self.progress is not None:
            self.progress(out)
        if self.echo and not self.tty:
            print(self.line(phase, ev.get("done"), ev.get("total")), file=sys.stderr, flush=True)

    def phase_end(self, phase: str) -> None:
        if self.echo and self.tty:
            print(self.line(phase + " done"), file=sys.stderr, flush=True)


def _best_hz(results: list[dict]) -> float | None:
    ok = [
        r["verified"]["worst_hz"]
        for r in results
        if r.get("status") == "optimal" and (r.get("verified") or {}).get("worst_hz") is not None
    ]
    return max(ok) if ok else None


def _first_pass_score(r: dict, tol: float = 1e-3) -> float | None:
    """The first pass's verdict on a candidate: its verified worst case when the start ended optimal or
    unconverged and within the stress limit; divided by the stress ratio when above it (a thinner leaf
    would bring it down: a heuristic for promotion only); None when it failed."""
    v = r.get("verified") or {}
    if r.get("status") not in ("optimal", "unconverged", "infeasible") or v.get("worst_hz") is None:
        return None
    sr = v.get("stress_ratio") or 0.0
    return v["worst_hz"] / sr if sr > 1 + tol else v["worst_hz"]


@limited()  # one BLAS thread while it computes (model.threads)
def run_topology_search(
    spec: TopologySpec | dict,
    *,
    executor: Any = None,
    workers: int | None = None,
    store: Any = None,
    progress: Callable[[dict], None] | None = None,
    cancel: Any = None,
    echo: bool = True,
) -> dict:
    """Generate, screen, optimise, verify and rank hinge topologies (the unit of work a service job calls;
    the schedule is the module docstring's).

    Parameters
    ----------
    spec
        A :class:`TopologySpec` or its JSON.
    executor, workers, store, cancel
        As :func:`optim.batch.run_cases`: any ``concurrent.futures.Executor`` (default a local process pool
        of ``workers``, shared by every phase), a directory of finished cases (a rerun resumes) and a
        ``threading.Event`` that stops the batch.
    progress
        Called after each case of each phase with the batch's event (``{"done", "total", "id", "status"}``)
        and ``phase`` ("screen", "first pass", "full pass", "refine"), ``counts`` (generated, screened,
        passed, first_pass, optimised, verified) and ``best`` (the best verified worst case so far).
    echo
        Write the progress to stderr (one line per event when it is not a terminal).

    Returns
    -------
    dict
        JSON-serialisable: ``spec``, ``counts`` (generated, rejected by reason kind, untraceable, pruned,
        first_pass, promoted, optimised, failed), ``candidates`` (each ``topology``, ``family``, ``dof``,
        ``intended_dof``, ``overconstraints``, ``self_stress``, ``release``, ``status`` (``rejected`` with
        ``reason``, ``pruned`` with ``same_design_as``, ``first pass`` (not promoted, with ``first_pass``),
        ``optimised``, ``untraceable`` or ``failed`` with ``reason``), ``same_design_as``, ``first_pass``
        (the cheap pass's verified worst case and design), ``worst_case_hz``, ``zero_stroke_hz``, ``ratio``
        (verified on the search's mesh), ``refined`` (on the refined mesh: ``worst_hz``, ``zero_stroke_hz``,
        ``ratio``, ``stress_ratio``, ``mesh_error``, ``segments_used``), ``design``, ``stress_ratio``,
        ``kkt_residual``, ``active_bounds``, ``bound_origins``, ``warnings``, ``starts``), ``ranking``
        (descriptors of the optimised candidates, best refined worst case first, those within the stress
        limit on the refined mesh before those beyond it), ``best``, ``seconds`` (per phase).
    """
    from ..batch import process_pool, run_cases
    from ..search import cases as problem_cases
    from .screen import screen_key

    spec = TopologySpec.model_validate(spec)
    if spec.motion == "translation":
        return _guide_search(spec, executor=executor, workers=workers, store=store, cancel=cancel)
    t0 = time.perf_counter()
    seconds: dict[str, float] = {}
    tops = _candidates(spec)
    track = _Tracker(progress, len(tops), echo)
    own = executor is None
    ex = process_pool(workers) if own else executor

    def batch(
        phase: str, cases: list[dict], fn: str, on_record: Callable[[int, dict], None] | None = None
    ) -> list[dict]:
        pos: dict[str, list[int]] = {}
        if not cases:
            return []
        from ..batch import case_id

        for i, c in enumerate(cases):
            pos.setdefault(case_id(c), []).append(i)

        def ev(e: dict) -> None:
            if on_record is not None and "record" in e:
                for i in pos.get(e["id"], []):
                    on_record(i, e["record"])
            track.event(phase, e)

        out = run_cases(cases, fn, executor=ex, store=store, progress=ev, cancel=cancel)
        track.phase_end(phase)
        return out

    try:
        # 1. screen: one verdict per screen key, in chunks, on the executor
        members: dict[str, list[str]] = {}
        for t in tops:
            members.setdefault(screen_key(t), []).append(str(t))
        keys = sorted(members)
        chunks = [keys[i : i + _SCREEN_CHUNK] for i in range(0, len(keys), _SCREEN_CHUNK)]
        verdicts: dict[str, dict] = {}

        def screened(i: int, rec: dict) -> None:
            if "verdicts" in rec:
                verdicts.update(rec["verdicts"])
                track.counts["screened"] = sum(1 for t in tops if screen_key(t) in verdicts)
                track.counts["passed"] = sum(
                    1 for t in tops if verdicts.get(screen_key(t), {}).get("status") == "accepted"
                )

        res = batch(
            "screen",
            [
                {
                    "descriptors": c,
                    "allow_overconstraints": spec.allow_overconstraints,
                }
                for c in chunks
            ],
            "flexopt.optim.topology.screen:screen_case",
            screened,
        )
        for r in res:
            if "verdicts" not in r:
                raise RuntimeError(f"the screen failed: {r.get('kind')}: {r.get('error')}")
            verdicts.update(r["verdicts"])
        records: list[dict] = []
        pending: list[int] = []
        for t in tops:
            sc = verdicts[screen_key(t)]
            rec = {
                "topology": str(t),
                "family": family_of(t),
                "flexures": t.flexures,
                "stages": len(t.stages),
                "dof": sc["dof"],
                "intended_dof": 1 + sc["intended_motions"],
                "overconstraints": sc["overconstraints"],
                "self_stress": sc["self_stress"],
                "release": sc["release"],
                "free_motions": sc["free_motions"],
                "status": "rejected" if sc["status"] == "rejected" else "pending",
                "reason": sc["reason"],
                "worst_case_hz": None,
                "zero_stroke_hz": None,
                "ratio": None,
                "design": None,
                "same_design_as": None,
                "first_pass": None,
                "refined": None,
            }
            if rec["status"] == "pending":
                pending.append(len(records))
            records.append(rec)
        seconds["screen"] = time.perf_counter() - t0
        # 2. first pass (multi-fidelity), pruning of the designed crossings that reduce to the midpoint
        t1 = time.perf_counter()
        promoted = list(pending)
        first = schedule_counts(spec, len(pending)).first_pass > 0
        if first:
            # tier 1: every candidate without a designed crossing (or whose midpoint variant is no candidate),
            # cold; tier 2: each designed-crossing variant warm-started at its midpoint variant's first-pass
            # design (crossing 0.5), a point of its own design space: it starts where tier 1 ended
            by_name = {records[i]["topology"]: i for i in pending}
            base_of = {i: by_name.get(str(canonical(records[i]["topology"].replace("@", "")))) for i in pending}
            tier2 = [i for i in pending if base_of[i] is not None and base_of[i] != i]
            tier1 = [i for i in pending if i not in set(tier2)]
            score: dict[int, float] = {}

            def first_pass(phase: str, idx: list[int], warm: dict[int, dict]) -> None:
                cs = []
                for i in idx:
                    c = problem_cases(candidate_problem(parse(records[i]["topology"]), spec, first_pass=True))[0]
                    c["mesh_estimate"] = False  # ranked on the refined mesh, which estimates its own
                    if i in warm:
                        c.update(x0=warm[i], stop_if_stationary=True)  # stationary at 0.5: pruned below
                    cs.append(c)

                def cheap(k: int, rec: dict) -> None:
                    track.counts["first_pass"] += 1
                    track.offer(records[idx[k]]["topology"], _best_hz([rec]), "first pass")

                for i, r in zip(idx, batch(phase, cs, "flexopt.optim.search:run_case", cheap)):
                    fs = _first_pass_score(r)
                    records[i]["first_pass"] = {
                        "status": r.get("status", "failed"),
                        "score_hz": fs,
                        "worst_hz": (r.get("verified") or {}).get("worst_hz"),
                        "stress_ratio": (r.get("verified") or {}).get("stress_ratio"),
                        "design": r.get("design"),
                        "message": r.get("message") or r.get("error"),
                        "warm_start": i in warm,
                    }
                    if fs is not None:
                        score[i] = fs

            first_pass("first pass", tier1, {})
            warm = {}
            for i in tier2:
                d = records[base_of[i]]["first_pass"]["design"]  # type: ignore[index]
                if d:
                    warm[i] = {**d, "crossing": 0.5}
            first_pass("first pass", tier2, warm)
            fp_dims = spec.dimensions if spec.first_pass_dimensions == "same" else spec.first_pass_dimensions
            _mark_untraceable([records[i] for i in pending if records[i]["first_pass"]["status"] == "failed"], fp_dims)
            if spec.prune:
                by_name = {records[i]["topology"]: i for i in pending}
                for i in pending:
                    d = records[i]["first_pass"]["design"] or {}
                    if "crossing" not in d or abs(d["crossing"] - 0.5) > _SAME_CROSSING:
                        continue
                    base = str(canonical(records[i]["topology"].replace("@", "")))
                    j = by_name.get(base)
                    if j is None or j == i:
                        continue
                    records[i].update(
                        status="pruned",
                        same_design_as=base,
                        reason=f"its first pass crosses at {d['crossing']:.3f}, the midpoint: it reduces to {base}",
                    )
                    if i in score:
                        score[j] = max(score.get(j, -math.inf), score.pop(i))
            ranked_first = sorted(score, key=lambda i: -score[i])
            n_full = schedule_counts(spec, len(pending), len(ranked_first)).promoted
            promoted = ranked_first[:n_full]
            for i in pending:
                if records[i]["status"] == "pending" and i not in promoted:
                    fp = records[i]["first_pass"]
                    records[i].update(
                        status="first pass",
                        reason=f"not promoted: its first pass ranks below the best {n_full}"
                        if fp["score_hz"] is not None
                        else f"not promoted: its first pass failed ({fp['message']})",
                    )
        seconds["first_pass"] = time.perf_counter() - t1
        # 3. full pass
        t2 = time.perf_counter()
        full_probs = {i: candidate_problem(parse(records[i]["topology"]), spec) for i in promoted}
        full_cases: list[dict] = []
        owner: list[int] = []
        for i in promoted:
            cs = problem_cases(full_probs[i])
            fp = records[i]["first_pass"]
            for c in cs:
                c["mesh_estimate"] = False  # the refined verification estimates it
            if fp is not None and fp["design"]:
                cs[0]["x0"] = fp["design"]  # start 0 where the first pass ended (per-stage values inherited)
            full_cases += cs
            owner += [i] * len(cs)
        results_of: dict[int, list[dict]] = {i: [] for i in promoted}

        def full(k: int, rec: dict) -> None:
            i = owner[k]
            results_of[i].append(rec)
            if len(results_of[i]) == full_probs[i].starts:
                track.counts["optimised"] += 1
            track.offer(records[i]["topology"], _best_hz([rec]), "full pass")

        res = batch("full pass", full_cases, "flexopt.optim.search:run_case", full)
        for i in promoted:
            _fill(records[i], [r for r, o in zip(res, owner) if o == i])
            records[i]["bound_origins"] = {k: list(v) for k, v in full_probs[i].families[0].origins.items()}
        _mark_untraceable([records[i] for i in promoted if records[i]["status"] == "failed"], spec.dimensions)
        _mark_same_designs(records)
        seconds["optimise"] = time.perf_counter() - t2
        # 4. refined verification of every optimum
        t3 = time.perf_counter()
        done = [i for i in promoted if records[i]["status"] == "optimised"]
        if spec.refine_segments is not None and done:
            ref_cases = []
            for i in done:
                r = records[i]
                params = {
                    **full_probs[i].families[0].fixed,
                    **r["design"],
                    "body_mass": spec.body_mass,
                    "stroke": spec.stroke,
                }
                ref_cases.append(
                    {
                        "params": params,
                        "stroke": spec.stroke,
                        "points": spec.refine_points,
                        "extra": [r["stroke_at_worst"]],
                        "segments": spec.refine_segments,
                        "tolerance": spec.refine_tolerance,
                        "safety_factor": spec.safety_factor,
                    }
                )

            def refined(k: int, rec: dict) -> None:
                track.counts["verified"] += 1

            res = batch("refine", ref_cases, "flexopt.optim.topology.rank:refine_case", refined)
            for i, r in zip(done, res):
                _refined(records[i], r, spec)
        seconds["refine"] = time.perf_counter() - t3
    finally:
        if own:
            ex.shutdown(wait=True, cancel_futures=True)
    ranked = sorted((r for r in records if r["status"] == "optimised"), key=_rank_key)
    counts = {
        "generated": len(records),
        "rejected": sum(r["status"] == "rejected" for r in records),
        "untraceable": sum(r["status"] == "untraceable" for r in records),
        "pruned": sum(r["status"] == "pruned" for r in records),
        "first_pass": sum(r["first_pass"] is not None for r in records),
        "promoted": len(promoted),
        "optimised": len(ranked),
        "failed": sum(r["status"] == "failed" for r in records),
    }
    seconds["total"] = time.perf_counter() - t0
    return _result(spec, records, ranked, counts, seconds)


def _rank_key(r: dict) -> tuple:
    """Feasible on the refined mesh first, then by the refined worst case (the search mesh's without one)."""
    ref = r.get("refined") or {}
    hz: Any = ref.get("worst_hz") if ref.get("worst_hz") is not None else r["worst_case_hz"]
    return (not ref.get("feasible", True), -float(hz))


def _refined(rec: dict, r: dict, spec: TopologySpec, tol: float = 1e-3) -> None:
    """A candidate's refined verification, and a warning for what it finds (stress beyond the limit, a mesh
    error above the tolerance, a refined worst case that differs from the search's)."""
    if "worst_hz" not in r:
        why = r.get("error") or "; ".join(r.get("failures", [])) or "incomplete curve"
        rec["refined"] = {"status": "failed", "reason": why, "feasible": False, "worst_hz": None}
        rec.setdefault("warnings", []).append(
            {
                "kind": "notice",
                "message": f"{rec['topology']}: the refined verification failed ({why}); it is ranked last",
            }
        )
        return
    feasible = r["stress_ratio"] <= 1 + tol
    rec["refined"] = {
        "status": "complete",
        "worst_hz": r["worst_hz"],
        "zero_stroke_hz": r["zero_stroke_hz"],
        "ratio": r["ratio"],
        "stroke_at_worst": r["stroke_at_worst"],
        "stress_ratio": r["stress_ratio"],
        "member_at_max_stress": r["member_at_max_stress"],
        "feasible": feasible,
        "mesh_error": r["mesh_error"],
        "segments": r["segments"],
        "segments_used": r["segments_used"],
        "tolerance": r["tolerance"],
        "points": r["points"],
        "change": r["worst_hz"] / rec["worst_case_hz"] - 1,
    }
    notes = rec.setdefault("warnings", [])
    if not feasible:
        notes.append(
            {
                "kind": "stress",
                "message": f"{rec['topology']}: on the refined mesh the peak stress is "
                f"{r['stress_ratio']:.3f} times allowable / safety_factor in {r['member_at_max_stress']}: "
                "beyond the limit; ranked after the feasible candidates",
                "value": r["stress_ratio"],
            }
        )
    if r["mesh_error"] is not None and r["tolerance"] is not None and r["mesh_error"] > r["tolerance"]:
        notes.append(
            {
                "kind": "mesh",
                "message": f"{rec['topology']}: the refined mesh's estimated error "
                f"{r['mesh_error']:.2g} is above the tolerance {r['tolerance']:g}",
                "value": r["mesh_error"],
            }
        )
    for w in r.get("warnings", []):
        if w.get("kind") not in ("stress", "mesh"):
            notes.append(dict(w, message=f"{rec['topology']} (refined): {w['message']}"))


def _mark_untraceable(records: list[dict], dimensions: str) -> None:
    """Status ``untraceable`` (with the reason) for the candidates among ``records`` (each one whose pass found
    no optimum) whose scene cannot be traced for exact design gradients under ``dimensions``
    (:func:`.screen.traceable`). Checked only where a pass failed: a trace of every survivor in the screen
    cost more than half of the screen's time, and every pass traces its candidate anyway."""
    from .screen import traceable

    for r in records:
        why = traceable(r["topology"], dimensions)
        if why:
            r.update(status="untraceable", reason=why)


def _mark_same_designs(records: list[dict], tol: float = 1e-3) -> None:
    """``same_design_as``: for a candidate with a designed crossing ('@') whose optimum crosses at the midpoint
    (within ``tol``), the candidate without '@', whose scene is then the same; None otherwise."""
    by_name = {r["topology"]: r for r in records}
    for r in records:
        if r["status"] == "pruned":  # already the same design as another (first pass)
            continue
        r["same_design_as"] = None
        if r["status"] != "optimised" or "crossing" not in r["design"] or abs(r["design"]["crossing"] - 0.5) > tol:
            continue
        base = str(canonical(r["topology"].replace("@", "")))
        if base != r["topology"] and base in by_name:
            r["same_design_as"] = base


def _fill(rec: dict, starts: list[dict]) -> None:
    """A candidate's record from its starts' results: the best start that is optimal (converged, verified,
    feasible), else the reason none is."""
    rec["starts"] = [
        {
            "start": r.get("start"),
            "status": r.get("status", "failed"),
            "message": r.get("message") or r.get("error"),
            "worst_hz": (r.get("verified") or {}).get("worst_hz"),
            "seconds": r.get("seconds"),
        }
        for r in starts
    ]
    b = best_start(starts)
    if b is None:
        rec.update(status="failed", reason=no_optimum_reason(starts))
        return
    v = b["verified"]
    rec.update(
        status="optimised",
        reason=None,
        worst_case_hz=v["worst_hz"],
        zero_stroke_hz=v["zero_stroke_hz"],
        stroke_at_worst=v["stroke_at_worst"],
        ratio=v["ratio"],
        design=b["design"],
        stress_ratio=v["stress_ratio"],
        kkt_residual=b["optimality"]["kkt_residual"],
        active_bounds=b["optimality"]["active_bounds"],
        moving_mass=b.get("moving_mass"),
        scene=v.get("scene"),
        curve={"stroke": v.get("stroke"), "parasitic_hz": v.get("parasitic_hz")},
        warnings=b.get("warnings", []),
    )


#: A guide's design space: the wires' side and length, and where each bound comes from.
GUIDE_DESIGN = {"wire_diameter": (5e-4, 2e-3), "wire_length": (0.02, 0.06)}
GUIDE_ORIGINS = {
    "wire_diameter": ("0.5 mm, the search's thinnest wire", "2 mm, the search's thickest wire"),
    "wire_length": ("20 mm, the search's shortest wire", "60 mm, the search's longest wire"),
}


def guide_problem(descriptor: str, spec: TopologySpec) -> Problem:
    """The one-family problem of a guide (template ``wire-guide-topology``, :func:`optim.guides.guide_problem`):
    its worst-case parasitic frequency over +-``guide_stroke`` under the stress limit, wire side and length
    designed in the search's box (:data:`GUIDE_DESIGN`)."""
    from ..guides import guide_problem as problem_of

    return problem_of(
        descriptor,
        GUIDE_DESIGN,
        {"segments": spec.segments},
        GUIDE_ORIGINS,
        stroke=spec.guide_stroke,
        samples=spec.samples,
        safety_factor=spec.safety_factor,
        min_thickness=spec.min_thickness,
        solver=spec.solver,
        starts=spec.starts,
        seed=spec.seed,
        max_iterations=spec.max_iterations,
        refine_rounds=spec.refine_rounds,
        verify_points=spec.verify_points,
    )


def _guide_search(
    spec: TopologySpec, executor: Any = None, workers: int | None = None, store: Any = None, cancel: Any = None
) -> dict:
    """Straight guides: every arrangement of up to ``max_flexures`` wires (or the listed descriptors) screened;
    the accepted ones ranked by the condition number of their scaled D_cc (smaller: further from a singular,
    compliant arrangement). With ``optimise_guides`` N, the best N by conditioning are shape-optimised like
    hinges (:func:`guide_problem`: the worst-case parasitic frequency over the translation stroke) and ranked
    by it first."""
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
        records.append(
            {
                "topology": str(g),
                "family": None,
                "flexures": g.flexures,
                "stages": 1,
                "dof": sc["dof"],
                "intended_dof": 1,
                "overconstraints": sc["overconstraints"],
                "self_stress": sc["self_stress"],
                "release": sc["release"],
                "free_motions": sc["free_motions"],
                "condition_number": sc["condition_number"],
                "status": "accepted" if sc["status"] == "accepted" else "rejected",
                "reason": sc["reason"],
                "worst_case_hz": None,
                "zero_stroke_hz": None,
                "ratio": None,
                "design": None,
            }
        )
    ranked = sorted((r for r in records if r["status"] == "accepted"), key=lambda r: r["condition_number"])
    t1 = time.perf_counter()
    chosen = ranked[: spec.optimise_guides]
    if chosen:
        from ..guides import run_guides

        probs = [guide_problem(r["topology"], spec) for r in chosen]
        res = run_guides(probs, executor=executor, workers=workers, store=store, cancel=cancel)
        for r, starts in zip(chosen, res):
            _fill(r, starts)
            r["bound_origins"] = {n: list(v) for n, v in GUIDE_ORIGINS.items()}
            if r["status"] == "optimised":
                r["status"] = "accepted"  # the screen's verdict; 'optimised' below says it was optimised too
                r["optimised"] = True
        done = sorted((r for r in chosen if r.get("optimised")), key=lambda r: -r["worst_case_hz"])
        ranked = done + [r for r in ranked if not r.get("optimised")]
    counts = {
        "generated": len(records),
        "rejected": len(records) - len(ranked),
        "untraceable": 0,
        "optimised": sum(bool(r.get("optimised")) for r in records),
        "accepted": len(ranked),
        "failed": sum(r["status"] == "failed" for r in records),
    }
    return _result(spec, records, ranked, counts, {"screen": t1 - t0, "optimise": time.perf_counter() - t1})


def _result(
    spec: TopologySpec, records: list[dict], ranked: list[dict], counts: dict[str, int], seconds: dict[str, float]
) -> dict:
    """The search's JSON answer (hinges and guides alike): counts with the rejections by reason, every
    candidate, the ranking and the best."""
    rejected_by: dict[str, int] = {}
    for r in records:
        if r["status"] == "rejected":
            kind = r["reason"].split(":", 1)[0]
            rejected_by[kind] = rejected_by.get(kind, 0) + 1
    counts_out: dict[str, Any] = {
        "generated": counts["generated"],
        "rejected": counts["rejected"],
        "rejected_by": rejected_by,
        **{k: v for k, v in counts.items() if k not in ("generated", "rejected")},
    }
    return {
        "format": "flexopt-topology-result",
        "version": 1,
        "spec": spec.model_dump(mode="json"),
        "counts": counts_out,
        "candidates": records,
        "ranking": [r["topology"] for r in ranked],
        "best": ranked[0] if ranked else None,
        "seconds": seconds,
    }
