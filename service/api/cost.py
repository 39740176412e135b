"""Cost estimates of jobs at submission (issue 29 item 8): optimisations, topology searches and Pareto fronts.

A job is a batch of cases (one start of one family; a topology candidate's starts; a Pareto level's starts), so
its cost is the sum of its cases' costs, in CPU seconds on one core (the job's pool spreads them over its
workers; the estimate does not depend on how many). A case's cost is a *budget*: every round of the search
uses its whole iteration budget and every verification round runs. Most searches converge sooner (the
default problem in a tenth to a third of its budget, ``bench/bench_job_cost.py``), so a job usually takes less
than its estimate; what the estimate bounds is what a spec may ask for.

One case of a family whose model has ``n`` degrees of freedom and ``d`` design parameters, searched on ``S``
stroke samples::

    evaluation(n, d, S) = EVAL_BASE + S n (EVAL_DOF + EVAL_DOF_PARAM d)          (exact, with gradients)
    curve(n, P)         = CURVE_BASE + P curve_point(n)                          (exact, no gradients)
    case = screen x FAST x curve(n, 2S - 1) + preview x FAST x curve(n, V)
         + (R + 1) [(I x EVALS_PER_ITERATION + 1) evaluation(n, d, S + 2R) + curve(n, V)]

with ``I`` the iteration budget (``max_iterations``; ten times that for trust-constr, whose iterations cost a
tenth), ``R`` the refinement rounds (each may add two samples), ``V`` the verification points. The constants
are fitted by ``bench/bench_job_cost.py`` (medians of interleaved runs; the fit it printed is copied here).

A topology search's candidates after screening cannot be known at submission: the estimate assumes every
generated candidate passes (the bound), each with its own leaf count (``n = 6 (leaves x segments + stages)``,
within 12 % of the compiled model on the hinge topologies) and design parameters; then the schedule's first
pass (every candidate, cheap) and full pass (the promoted fraction, all starts), and the refined
verification of the ranked candidates at the finest mesh 'auto' may reach.
"""

from __future__ import annotations

import functools
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

__all__ = ["CALIBRATION", "Estimate", "case_seconds", "curve_seconds", "estimate_job"]

#: Fitted by ``OPENBLAS_NUM_THREADS=1 python bench/bench_job_cost.py`` (3 interleaved rounds, medians; load
#: average 6 to 10 on the shared 2 cores, so they err on the slow side): whole cases whose budget is spent
#: measured at 0.9 to 1.2 times these estimates; cases that converge early at a third to a fiftieth.
CALIBRATION: dict[str, float] = {
    "EVAL_BASE": 0.0,  # s per evaluation besides its points (fitted as 0: within the points' share)
    "EVAL_DOF": 9.8e-5,  # s per stroke sample and DOF
    "EVAL_DOF_PARAM": 5.1e-5,  # s per stroke sample, DOF and design parameter (the gradients)
    "CURVE_BASE": 0.026,  # s per exact curve
    "CURVE_DOF": 1.7e-5,  # s per stroke point and DOF of an exact curve
    "EVALS_PER_ITERATION": 1.5,  # evaluations per solver iteration (line searches), the budget spent
    "FAST": 0.55,  # a fast-method ('auto') curve's time over the exact one's (preview, screening)
    "SCREEN_CANDIDATE": 0.05,  # s per topology candidate's screening verdict (not fitted: tens of ms each)
}

#: segments per leaf of the finest mesh a topology search's 'auto' refinement may reach (model.mesh.AUTO_MAX)
_AUTO_SEGMENTS = 128


@dataclass
class Estimate:
    """A job's estimated cost: CPU seconds, its cases, and what drives it (the fields to reduce, largest
    share first)."""

    seconds: float
    cases: int
    what: str
    drivers: list[str] = field(default_factory=list)

    def to_dict(self, limit: float | None = None) -> dict[str, Any]:
        out: dict[str, Any] = {
            "seconds": round(self.seconds, 1),
            "cases": self.cases,
            "what": self.what,
            "drivers": self.drivers,
        }
        if limit is not None:
            out["limit"] = limit
        return out


def _n(k: int, word: str) -> str:
    """``k`` and ``word``, plural unless ``k`` is 1 ("1 start", "4 starts"; "family" -> "families")."""
    if k == 1:
        return f"{k} {word}"
    return f"{k} {word[:-1]}ies" if word.endswith("y") else f"{k} {word}s"


def _c(name: str, cal: dict[str, float] | None) -> float:
    return (cal or CALIBRATION)[name]


def curve_seconds(n: int, points: int, cal: dict[str, float] | None = None) -> float:
    """An exact curve of ``points`` stroke points of a model of ``n`` DOFs: the fitted linear cost, or the
    request limit's dense model (``guards.seconds_per_point``) where that is larger (large models)."""
    from .guards import seconds_per_point

    per_point = max(_c("CURVE_DOF", cal) * n, seconds_per_point(n) if n > 1000 else 0.0)
    return _c("CURVE_BASE", cal) + points * per_point


def evaluation_seconds(n: int, d: int, samples: int, cal: dict[str, float] | None = None) -> float:
    """One evaluation of the search (the exact curve on ``samples`` points with gradients in ``d`` parameters)."""
    return _c("EVAL_BASE", cal) + samples * n * (_c("EVAL_DOF", cal) + _c("EVAL_DOF_PARAM", cal) * d)


def case_seconds(
    n: int,
    d: int,
    samples: int,
    iterations: int,
    rounds: int,
    verify_points: int,
    screen: int = 0,
    preview: bool = False,
    cal: dict[str, float] | None = None,
) -> dict[str, float]:
    """The budget of one case, split by what drives it: ``search`` (the solver's evaluations), ``verify``,
    ``screen`` and ``preview`` [s] (module docstring)."""
    fast = _c("FAST", cal)
    evals = iterations * _c("EVALS_PER_ITERATION", cal) + 1
    search = sum(evals * evaluation_seconds(n, d, samples + 2 * r, cal) for r in range(rounds + 1))
    return {
        "search": search,
        "verify": (rounds + 1) * curve_seconds(n, verify_points, cal),
        "screen": screen * fast * curve_seconds(n, 2 * samples - 1, cal),
        "preview": fast * curve_seconds(n, verify_points, cal) if preview else 0.0,
    }


def _iterations(max_iterations: int, solver: str) -> int:
    """The solver's iteration budget: ``max_iterations``, ten times that for trust-constr (optim.search)."""
    return max_iterations * (10 if solver == "trust-constr" else 1)


def _family_dofs(fam: Any) -> int:
    """DOFs of a family's model: the larger of its design box's corners (``compile_scene``, tables only)."""
    import numpy as np

    from ...model import template
    from ...model.structure import compile_scene
    from ...optim.problem import Problem
    from ...optim.search import FamilyEvaluator

    built = FamilyEvaluator(Problem(families=[fam]), fam)
    return max(
        compile_scene(template(fam.template, **built.params(np.full(len(built.names), c)))).n_dof for c in (0.0, 1.0)
    )


_FIELDS = {
    "search": "max_iterations or samples",
    "verify": "verify_points",
    "screen": "screen",
    "preview": "preview",
    "check": "check.population or check.generations",
}


def _problem_cases(prob: Any, starts: int, cal: dict[str, float] | None) -> tuple[float, dict[str, float], list[int]]:
    """Total seconds of ``starts`` cases of each family of ``prob``, the shares by driver, the DOFs."""
    total, shares, dofs = 0.0, dict.fromkeys(_FIELDS, 0.0), []
    for fam in prob.families:
        n = _family_dofs(fam)
        dofs.append(n)
        parts = case_seconds(
            n,
            len(fam.design),
            prob.samples,
            _iterations(prob.max_iterations, prob.solver),
            prob.refine_rounds,
            prob.verify_points,
            prob.screen,
            prob.preview,
            cal,
        )
        for k, v in parts.items():
            shares[k] += starts * v
        total += starts * sum(parts.values())
    return total, shares, dofs


def _drivers(shares: dict[str, float], *first: str) -> list[str]:
    ranked = [_FIELDS[k] for k, v in sorted(shares.items(), key=lambda kv: -kv[1]) if v > 0]
    return [*first, *ranked]


def optimisation_estimate(spec: Any, cal: dict[str, float] | None = None) -> Estimate:
    """An optimisation (``optim.Problem``): families x starts cases."""
    total, shares, dofs = _problem_cases(spec, spec.starts, cal)
    cases = len(spec.families) * spec.starts
    what = (
        f"{_n(cases, 'case')} ({_n(len(spec.families), 'family')} x {_n(spec.starts, 'start')}; "
        f"{max(dofs)} DOFs, {spec.samples} samples, {spec.max_iterations} iterations x "
        f"{_n(spec.refine_rounds + 1, 'round')}, {spec.verify_points} verification points)"
    )
    return Estimate(total, cases, what, _drivers(shares, "starts"))


def pareto_estimate(spec: Any, cal: dict[str, float] | None = None) -> Estimate:
    """A Pareto front: its levels' cases (``points`` x ``problem.starts``, each an optimisation case), plus
    the NSGA-II check's exact curves (population x generations on 2 samples - 1 points, then the verification
    of at most a population on ``verify_points``)."""
    prob = spec.problem
    total, shares, dofs = _problem_cases(prob, prob.starts * spec.points, cal)
    cases = spec.points * prob.starts
    what = f"{_n(cases, 'case')} ({spec.points} points x {_n(prob.starts, 'start')}; {dofs[0]} DOFs)"
    if spec.check is not None:
        c = spec.check
        check = c.population * c.generations * curve_seconds(dofs[0], 2 * prob.samples - 1, cal)
        check += c.population * curve_seconds(dofs[0], prob.verify_points, cal)
        total += check
        shares["check"] = check
        what += f" and {c.population * c.generations} NSGA-II curves"
    return Estimate(total, cases, what, _drivers(shares, "points", "problem.starts"))


def topology_estimate(spec: Any, cal: dict[str, float] | None = None) -> Estimate:
    """A topology search (rotation): every generated candidate assumed to pass the screening (the bound);
    the first pass on every candidate and the full pass on the promoted ones (``promote``, at least
    ``promote_min``; every candidate with ``schedule: exhaustive`` or when they are no more than
    ``promote_min``), then the refined verification of each optimised candidate. A translation search screens
    and ranks guides by their conditioning: its cost is the screening, plus ``optimise_guides`` cases."""
    if spec.motion == "translation":
        from ...optim.topology.rank import guide_problem

        n_guides, widest = _guide_count(
            tuple(spec.topologies) if spec.topologies is not None else None, spec.max_flexures
        )
        chosen = min(spec.optimise_guides, n_guides)
        total, shares = n_guides * _c("SCREEN_CANDIDATE", cal), dict.fromkeys(_FIELDS, 0.0)
        if chosen:  # the guides optimised are known only after the screening: the most wires, for a bound
            more, shares, _ = _problem_cases(guide_problem(widest, spec), chosen * spec.starts, cal)
            total += more
        return Estimate(
            total,
            chosen * spec.starts,
            f"{_n(n_guides, 'guide')} screened, {chosen} x {_n(spec.starts, 'start')} optimised",
            _drivers(shares, "optimise_guides", "starts"),
        )
    first_dims = spec.dimensions if spec.first_pass_dimensions == "same" else spec.first_pass_dimensions
    shapes = _candidate_shapes(
        tuple(spec.topologies) if spec.topologies is not None else None,
        spec.max_flexures,
        spec.max_stages,
        spec.planes,
        spec.inplane,
        spec.free_crossing,
        spec.reinforcement,
        spec.prune,
        first_dims,
        spec.dimensions,
    )
    from ...optim.topology.spec import schedule_counts

    n_all = sum(shapes.values())
    plan = schedule_counts(spec, n_all)  # the search's own rule: every candidate assumed scored (the bound)
    two_pass, promoted = plan.first_pass > 0, plan.promoted

    def dofs(leaves: int, stages: int, segments: int) -> int:
        return 6 * (leaves * segments + stages)

    first, full, refine = 0.0, [], []
    for (leaves, stages, d_first, d_full), count in shapes.items():
        if two_pass:
            first += count * sum(
                case_seconds(
                    dofs(leaves, stages, spec.first_pass_segments),
                    d_first,
                    spec.first_pass_samples,
                    _iterations(spec.first_pass_iterations, spec.solver),
                    0,
                    31,
                    cal=cal,
                ).values()
            )
        one = sum(
            case_seconds(
                dofs(leaves, stages, spec.segments),
                d_full,
                spec.samples,
                _iterations(spec.max_iterations, spec.solver),
                spec.refine_rounds,
                spec.verify_points,
                cal=cal,
            ).values()
        )
        full += [spec.starts * one] * count
        if spec.refine_segments is not None:
            meshes = (
                [s for s in (4, 8, 16, 32, 64, _AUTO_SEGMENTS)]
                if spec.refine_segments == "auto"
                else [spec.refine_segments]
            )
            refine += [sum(curve_seconds(dofs(leaves, stages, s), spec.refine_points, cal) for s in meshes)] * count
    full.sort(reverse=True)  # the promoted are not known: the costliest, for a bound
    refine.sort(reverse=True)
    screen = n_all * _c("SCREEN_CANDIDATE", cal)
    total = screen + first + sum(full[:promoted]) + sum(refine[: plan.refined])
    what = (
        f"{n_all} candidates generated (all assumed to pass the screening): "
        + (f"a first pass of each, then {promoted} promoted" if two_pass else f"{promoted} optimised")
        + f" x {_n(spec.starts, 'start')}"
    )
    drivers = ["max_flexures or max_stages (or list topologies)", "starts", "max_iterations or samples"]
    if two_pass:
        drivers.insert(1, "promote or promote_min")
    if spec.refine_segments == "auto":
        drivers.append("refine_segments (a number instead of 'auto')")
    return Estimate(total, promoted * spec.starts + plan.first_pass, what, drivers)


@functools.lru_cache(maxsize=16)  # bounded: 16 specs' counts
def _guide_count(topologies: tuple[str, ...] | None, max_flexures: int) -> tuple[int, str]:
    """How many guides a translation search screens, and the descriptor of one with the most wires."""
    from ...optim.topology.grammar import canonical_guide, enumerate_guides

    if topologies is not None:
        guides = list({str(canonical_guide(d)): canonical_guide(d) for d in topologies}.values())
    else:
        guides = [g for k in range(1, max_flexures + 1) for g in enumerate_guides(k)]
    return len(guides), str(max(guides, key=lambda g: g.flexures))


@functools.lru_cache(maxsize=16)  # bounded: 16 specs' counts, a few hundred bytes each
def _candidate_shapes(
    topologies: tuple[str, ...] | None,
    max_flexures: int,
    max_stages: int,
    planes: str,
    inplane: bool,
    free_crossing: bool,
    reinforcement: bool,
    prune: bool,
    first_dims: str,
    dims: str,
) -> Counter[tuple[int, int, int, int]]:
    """How many candidates of each (leaves, stages, design parameters of the first pass, of the full pass)."""
    from ...optim.topology.grammar import candidate_topologies, design_parameters

    tops = candidate_topologies(
        topologies,
        max_flexures,
        max_stages,
        planes=planes,
        inplane=inplane,
        free_crossing=free_crossing,
        reinforce=reinforcement,
        prune=prune,
    )
    return Counter(
        (t.flexures, len(t.stages), len(design_parameters(t, first_dims)), len(design_parameters(t, dims)))
        for t in tops
    )


def estimate_job(kind: str, spec: Any, cal: dict[str, float] | None = None) -> Estimate:
    """The estimate of a job of ``kind`` ('optimisation', 'topology-search', 'pareto-front') for its validated
    spec model."""
    if kind == "topology-search":
        return topology_estimate(spec, cal)
    if kind == "pareto-front":
        return pareto_estimate(spec, cal)
    return optimisation_estimate(spec, cal)
