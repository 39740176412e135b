"""Trade-offs: the Pareto front of worst-case first parasitic frequency against drive stiffness for one family.

Objectives
----------
*Worst case* ``f``: the lowest first parasitic frequency over the stroke (maximised), as in :mod:`optim.search`.
*Drive stiffness* ``K = max_s |R(s)| / S``: the largest actuation moment [N m] (force [N]) ``R`` over the
stroke ``-S..S`` divided by the stroke's half range ``S`` in SI units [rad] ([m]); the secant stiffness the
actuator must overcome at the worst point (minimised: a stiffer drive is worse). Units ``N m/rad`` for a
rotation, ``N/m`` for a translation.

Method (epsilon-constraint)
---------------------------
1. The two single-objective optima: the maximum of ``f`` (:func:`optim.search.run_case` unchanged) and the
   minimum of ``K`` (:func:`_min_drive`: SLSQP on the epigraph ``minimise u`` subject to
   ``u >= (R_j / R_0)^2`` at every stroke sample, the stress and envelope rows of the search, with the exact
   gradients ``dR/dp`` of :func:`model.design.point_sensitivity`, the implicit-function derivative of the
   drive reaction along the equilibrium's move).
2. Between them, ``points - 2`` levels ``K_i`` evenly spaced; each is the search of step 1 with the drive
   limit ``max_drive = K_i S`` (the search's smooth rows ``1 - (R_j / max_drive)^2 >= 0`` with exact gradients).
3. Every point is verified by the search's verification: the exact curve on ``verify_points`` stroke points,
   stress within allowable / safety_factor; its worst case and drive stiffness are the *verified* ones, and a
   point whose verified drive exceeds its level by more than ``tolerance`` is not feasible.
Each level runs ``starts`` starts (the search's start sequence) and keeps its best feasible one; every case
goes through :func:`optim.batch.run_cases`, so any ``concurrent.futures.Executor`` runs them.

Gradient-free check
-------------------
With ``check``, pymoo's NSGA-II (optional extra ``pareto``) searches the same box for both objectives with
exact curves on ``2 samples - 1`` stroke points (stress and envelope as constraints), evaluating each
generation through the same executor; its non-dominated points are verified like the front's. The check
passes when no NSGA-II point *dominates an epsilon-constraint point by more than* ``check.tolerance``:
better than it by more than that fraction in one objective and no worse in the other.
"""

from __future__ import annotations

import concurrent.futures as cf
import math
import time
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from .problem import Problem

__all__ = [
    "PHASES",
    "ParetoCheck",
    "ParetoSpec",
    "dominates",
    "drive_stiffness",
    "evaluate_design",
    "pareto",
    "run_point",
]


#: The phases of a front's computation, in order, as its progress events name them: the two single-objective
#: optima, the epsilon-constraint levels between them (or, against stroke, one optimum per stroke), NSGA-II's
#: generations and the verification of its non-dominated points.
PHASES = ("optima", "levels", "strokes", "check", "check verification")


class ParetoCheck(BaseModel):
    """The gradient-free check by pymoo's NSGA-II."""

    model_config = ConfigDict(extra="forbid")

    population: int = Field(default=16, ge=4, le=200, description="NSGA-II population size")
    generations: int = Field(default=8, ge=1, le=200, description="NSGA-II generations")
    tolerance: float = Field(
        default=0.02,
        gt=0,
        lt=0.5,
        description="an NSGA-II point beating a front point "
        "by more than this fraction in one objective, and no worse in the other, fails "
        "the check",
    )
    seed: int = Field(default=0, ge=0, description="NSGA-II's random seed (deterministic)")


class ParetoSpec(BaseModel):
    """A Pareto front of worst-case parasitic frequency against drive stiffness for one family."""

    model_config = ConfigDict(extra="forbid")

    format: Literal["flexopt-pareto"] = "flexopt-pareto"
    version: Literal[1] = 1
    problem: Problem = Field(
        description="the optimisation problem (flexopt-problem, one family); its "
        "max_drive, if any, is replaced by each level's limit"
    )
    points: int = Field(default=5, ge=2, le=25, description="front points, the two single-objective optima included")
    against: Literal["drive_stiffness", "stroke"] = Field(
        default="drive_stiffness",
        description="the second objective: 'drive_stiffness' (minimised) or 'stroke' "
        "(maximised: the frequency optimum at each of ``points`` strokes evenly spaced over ``strokes``)",
    )
    strokes: tuple[float, float] | None = Field(
        default=None,
        description="with against 'stroke': the smallest and largest half range of the stroke, in the "
        "template's stroke unit (deg for rotations, m for translations)",
    )
    check: ParetoCheck | None = Field(default=None, description="gradient-free check by NSGA-II (pymoo; optional)")

    @model_validator(mode="after")
    def _one_family(self) -> ParetoSpec:
        if len(self.problem.families) != 1:
            raise ValueError(
                f"problem.families: a front is drawn for one family, got {len(self.problem.families)}; keep one"
            )
        if self.against == "stroke":
            if self.strokes is None or not 0 < self.strokes[0] < self.strokes[1] < math.inf:
                raise ValueError(
                    "strokes: with against 'stroke' give [smallest, largest] half ranges, 0 < smallest < largest"
                )
            if self.check is not None:
                raise ValueError(
                    "check: the NSGA-II check covers the drive-stiffness front; remove it or set "
                    "against 'drive_stiffness'"
                )
        elif self.strokes is not None:
            raise ValueError("strokes: only with against 'stroke'; remove it")
        return self


# ----------------------------------------------------------------------------------------- units
def _stroke_si(prob: Problem) -> tuple[float, str, str]:
    """The stroke's half range in SI units, the drive stiffness unit and the drive unit of the family."""
    from ..model.templates import TEMPLATES, template

    fam = prob.families[0]
    defaults = TEMPLATES[fam.template][1] if fam.template in TEMPLATES else {}
    stroke = float(prob.stroke if prob.stroke is not None else defaults.get("stroke", 45.0))
    params = {k: v for k, v in fam.fixed.items()}
    params.update({k: 0.5 * (lo + hi) for k, (lo, hi) in fam.design.items()})
    params["stroke"] = stroke
    st = template(fam.template, **params).stroke
    assert st is not None  # a family is a stroked template (search.FamilyEvaluator refuses others)
    kind = st.kind
    if kind == "rotation":
        return math.radians(stroke), "N m/rad", "N m"
    return stroke, "N/m", "N"


def drive_stiffness(problem: Problem | dict, design: dict[str, float]) -> tuple[float, dict[str, float]]:
    """The drive stiffness ``K = max_j |R(s_j)| / S`` of ``design`` over the problem's stroke samples and its
    exact gradient ``dK/dp`` per design parameter [K's unit per parameter unit]: ``dR/dp`` of the sample of the
    peak from :func:`model.design.point_sensitivity` (the implicit-function derivative of the reaction along the
    equilibrium's move), through the search's drive rows. One-sided where two samples tie for the peak."""
    from .search import FamilyEvaluator

    prob = Problem.model_validate(problem).model_copy(update={"max_drive": 1.0})
    fam = FamilyEvaluator(prob, prob.families[0])
    x = np.array([(float(design[k]) - lo) / (hi - lo) for k, lo, hi in zip(fam.names, fam.lo, fam.hi)])
    ev = fam.evaluate(x)
    if not ev.ok:
        raise ValueError(f"design: the curve of {design} fails: {ev.message}")
    assert ev.kinds is not None
    rows = np.flatnonzero(ev.kinds == "drive")
    r2 = 1.0 - ev.con[rows]  # rows 1 - (R / 1)^2
    j = rows[int(np.argmax(r2))]
    r = math.sqrt(max(float(r2.max()), 0.0))
    s_si = _stroke_si(prob)[0]
    dr2 = -ev.jac[j, : len(x)] / (fam.hi - fam.lo)  # d(R^2)/dp, per parameter unit
    return r / s_si, {k: float(v) / (2.0 * r * s_si) for k, v in zip(fam.names, dr2)}


# ---------------------------------------------------------------------------------- one front point
def _point(r: dict, level: float | None, s_si: float, tol: float) -> dict:
    """A front point from a case record of the search (or of :func:`_min_drive`)."""
    v = r.get("verified") or {}
    status, message = r.get("status", "failed"), r.get("message") or r.get("error") or ""
    k = v["max_drive"] / s_si if v.get("max_drive") is not None else None
    if status == "optimal" and level is not None and k is not None and k > level * (1 + tol):
        status, message = (
            "infeasible",
            (f"the verified drive stiffness {k:.6g} exceeds the level {level:.6g} by {k / level - 1:.3g}"),
        )
    return {
        "status": status,
        "message": message,
        "design": r.get("design"),
        "worst_hz": v.get("worst_hz"),
        "zero_stroke_hz": v.get("zero_stroke_hz"),
        "stroke_at_worst": v.get("stroke_at_worst"),
        "drive_stiffness": k,
        "max_drive": v.get("max_drive"),
        "stress_ratio": v.get("stress_ratio"),
        "level": level,
        "start": r.get("start"),
        "kkt_residual": (r.get("optimality") or {}).get("kkt_residual"),
        "warnings": r.get("warnings", []),
    }


def run_point(case: dict) -> dict:
    """One start of one level (the unit of work of a batch; JSON in and out): ``kind`` ``"max_frequency"``
    (the search unchanged), ``"epsilon"`` (the search with ``max_drive = level * stroke``) or
    ``"min_drive"`` (:func:`_min_drive`)."""
    from .search import run_case

    prob = Problem.model_validate(case["problem"])
    s_si = _stroke_si(prob)[0]
    kind, start = case["kind"], int(case["start"])
    if kind == "min_drive":
        return {"kind": kind, **_point(_min_drive(prob, start), None, s_si, prob.tolerance)}
    if kind == "stroke":  # the frequency optimum over +-level (its own drive stiffness over that stroke)
        prob = prob.model_copy(update={"stroke": float(case["level"])})
        r = run_case({"problem": prob.model_dump(mode="json"), "family": 0, "start": start})
        return {"kind": kind, **_point(r, None, _stroke_si(prob)[0], prob.tolerance), "stroke": prob.stroke}
    level = None
    if kind == "epsilon":
        level = float(case["level"])
        prob = prob.model_copy(update={"max_drive": level * s_si})
    elif kind != "max_frequency":
        raise ValueError(f"unknown kind {kind!r}")
    r = run_case({"problem": prob.model_dump(mode="json"), "family": 0, "start": start})
    return {"kind": kind, **_point(r, level, s_si, prob.tolerance)}


def _min_drive(prob: Problem, start: int) -> dict:
    """The minimum drive stiffness of the family, a case record in the search's form (status, design,
    verified, optimality).

    ``minimise u`` subject to ``u - (R_j / R_0)^2 >= 0`` at every stroke sample ``j`` (``R_0`` the start's peak),
    the stress rows ``1 - (sigma / sigma_allow)^2 >= 0`` and the envelope rows of :mod:`optim.search`, in the unit
    box, by SLSQP with the exact gradients of :func:`model.design.point_sensitivity` (its ``dreaction``). The
    rows are the search's own (its drive rows with a unit limit, ``1 - R_j^2``), each distinct row once.
    """
    from scipy.optimize import minimize, nnls

    from .search import FamilyEvaluator, start_point, verify

    p1 = prob.model_copy(update={"max_drive": 1.0})
    fam = FamilyEvaluator(p1, p1.families[0])
    x0 = start_point(fam, p1, 0, start)
    ev = fam.evaluate(x0)
    names = fam.names
    base = {"start": start, "family": fam.fam.template, "design": fam.params(x0)}
    if not ev.ok:
        return {**base, "status": "failed", "message": f"the start design fails: {ev.message}", "verified": {}}
    fam.select(ev)
    assert fam.keep is not None and ev.kinds is not None
    keep = fam.keep
    drive = keep[ev.kinds[keep] == "drive"]
    other = keep[np.isin(ev.kinds[keep], ["stress", "envelope"])]
    r0 = float(np.max(1.0 - ev.con[drive]))
    nx = len(x0)
    failed: list[str] = []

    def at(z: np.ndarray):
        e = fam.evaluate(np.clip(z[:nx], 0.0, 1.0))
        if not e.ok:
            failed.append(e.message)
            raise RuntimeError(e.message)
        return e

    def con(z: np.ndarray) -> np.ndarray:
        e = at(z)
        return np.concatenate([z[-1] - (1.0 - e.con[drive]) / r0, e.con[other]])

    def jac(z: np.ndarray) -> np.ndarray:
        e = at(z)
        jd = np.column_stack([e.jac[drive, :nx] / r0, np.ones(len(drive))])
        jo = np.column_stack([e.jac[other, :nx], np.zeros(len(other))])
        return np.vstack([jd, jo])

    z0 = np.concatenate([x0, [1.0]])
    try:
        res = minimize(
            lambda z: z[-1],
            z0,
            jac=lambda z: np.eye(nx + 1)[-1],
            method="SLSQP",
            bounds=[(0.0, 1.0)] * nx + [(None, None)],
            constraints=[{"type": "ineq", "fun": con, "jac": jac}],
            options={"maxiter": prob.max_iterations, "ftol": prob.tolerance * 1e-2},
        )
    except RuntimeError:
        return {**base, "status": "failed", "message": f"an evaluation failed: {failed[-1]}", "verified": {}}
    x = np.clip(res.x[:nx], 0.0, 1.0)
    z = np.concatenate([x, [float(np.max((1.0 - fam.evaluate(x).con[drive]) / r0))]])
    c, J = con(z), jac(z)
    # KKT residual of the scaled problem, as optim.search._optimality: min_{mu>=0} |grad u - J_A^T mu| over the
    # rows and bounds active within the tolerance
    tol = prob.tolerance
    cols = [J[i] for i in np.flatnonzero(c <= tol)]
    active_bounds = {}
    for j, k in enumerate(names):
        if x[j] <= tol or x[j] >= 1 - tol:
            e = np.zeros(nx + 1)
            e[j] = 1.0 if x[j] <= tol else -1.0
            cols.append(e)
            active_bounds[k] = "lower" if x[j] <= tol else "upper"
    g = np.eye(nx + 1)[-1]
    kkt = float(nnls(np.array(cols).T, g)[1]) if cols else 1.0
    verified = verify(fam, x, prob.verify_points)
    searched = float(np.sqrt(z[-1] * r0))
    status, message = "optimal", ""
    if verified.get("status") != "complete" or "worst_hz" not in verified:
        status, message = "failed", "; ".join(verified.get("failures", [])) or "the verification failed"
    elif verified["stress_ratio"] > 1 + tol:
        status, message = "infeasible", "the verified stress exceeds allowable / safety_factor"
    elif float(np.min(c)) < -tol:
        status, message = "infeasible", f"a constraint is violated by {-float(np.min(c)):.3g} (scaled)"
    elif verified["max_drive"] > searched * (1 + tol):
        status, message = (
            "unconverged",
            (
                f"the verified peak drive {verified['max_drive']:.6g} exceeds the "
                f"searched one {searched:.6g} (a peak between the samples)"
            ),
        )
    elif res.status != 0:
        status, message = "unconverged", f"the solver stopped: {res.message}"
    elif kkt > prob.kkt_tolerance:
        status, message = "unconverged", f"KKT residual {kkt:.3g} above kkt_tolerance {prob.kkt_tolerance:g}"
    params = fam.params(x)
    return {
        **base,
        "status": status,
        "message": message,
        "design": {k: params[k] for k in names},
        "verified": verified,
        "optimality": {"kkt_residual": kkt, "active_bounds": active_bounds},
        "warnings": [],
    }


# ------------------------------------------------------------------------------------- dominance
def dominates(a: dict, b: dict, tol: float = 0.0, against: str = "drive_stiffness") -> bool:
    """Whether point ``a`` dominates ``b`` by more than ``tol``: better by more than that fraction in one
    objective (higher ``worst_hz``; lower ``drive_stiffness``, or higher ``stroke``) and no worse in the other."""
    fa, fb = a["worst_hz"], b["worst_hz"]
    ka, kb = (a[against], b[against]) if against == "drive_stiffness" else (-a[against], -b[against])
    return bool((fa > fb * (1 + tol) and ka <= kb) or (ka < kb - tol * abs(kb) and fa >= fb))


def _best(records: list[dict], by_drive: bool = False) -> dict:
    ok = [r for r in records if r["status"] == "optimal" and r["worst_hz"] is not None]
    if not ok:
        return (
            records[0]
            if len(records) == 1
            else {
                **records[0],
                "status": "failed",
                "message": "; ".join(f"start {r['start']}: {r['status']} ({r['message']})" for r in records),
            }
        )
    return (
        min(ok, key=lambda r: (r["drive_stiffness"], -r["worst_hz"]))
        if by_drive
        else max(ok, key=lambda r: r["worst_hz"])
    )


# --------------------------------------------------------------------------- gradient-free check
def evaluate_design(case: dict) -> dict:
    """Both objectives and the constraints of one design from an exact curve (no gradients), for NSGA-II:
    ``{"worst_hz", "drive_stiffness", "stress_ratio", "envelope", "ok"}`` (a unit of work of a batch)."""
    from ..model.curve import Analysis
    from ..model.errors import FlexoptError
    from ..model.templates import TEMPLATES, template
    from .search import FamilyEvaluator

    prob = Problem.model_validate(case["problem"])
    fam = FamilyEvaluator(prob, prob.families[0])
    x = np.asarray(case["x"], float)
    params = fam.params(x)
    s_si = _stroke_si(prob)[0]
    grid = np.linspace(-fam.stroke, fam.stroke, int(case["points"]))
    try:
        scene = template(fam.fam.template, **params)
        curve = Analysis(scene).frequency_curve(stroke=grid)
    except FlexoptError as exc:
        return {"ok": False, "message": str(exc)}
    if curve.status != "complete":
        return {"ok": False, "message": curve.failures[0].message if curve.failures else "incomplete"}
    allow = min(m.allowable_stress for m in scene.materials) / prob.safety_factor
    vm = np.nan_to_num(np.array([curve.max_von_mises[m] for m in curve.max_von_mises]), nan=0.0)
    env = 0.0
    if prob.envelope is not None:
        fn, defaults = TEMPLATES[fam.fam.template]
        pts = _envelope_positions(fn({**defaults, **params}))
        if isinstance(prob.envelope, float):
            env = max(float(p @ p) / prob.envelope**2 for p in pts) - 1.0
        else:
            assert scene.stroke is not None  # a family is a stroked template
            axis = np.asarray(scene.stroke.axis, float)
            axis = axis / np.linalg.norm(axis)
            env = max((float(p @ p) - float(p @ axis) ** 2) / prob.envelope.radius**2 for p in pts) - 1.0
            if prob.envelope.half_height is not None:
                env = max(env, max(float(p @ axis) ** 2 / prob.envelope.half_height**2 for p in pts) - 1.0)
    return {
        "ok": True,
        "x": x.tolist(),
        "design": {k: params[k] for k in fam.names},
        "worst_hz": float(np.min(curve.parasitic_hz)),
        "drive_stiffness": float(np.max(np.abs(curve.drive_reaction))) / s_si,
        "stress_ratio": float(np.max(vm)) / allow,
        "envelope": env,
    }


def _envelope_positions(scene: dict) -> list[np.ndarray]:
    """The points of :func:`optim.search.envelope_points` (nodes and leaf edges), without derivatives."""
    from .search import envelope_points

    empty = {
        "nodes": [{"position": [0.0, 0.0, 0.0]} for _ in scene["nodes"]],
        "elements": [{"y_axis": [0.0, 0.0, 0.0], "section": {"width": 0.0}} for _ in scene["elements"]],
    }
    return [p for p, _, _ in envelope_points(scene, (empty,))]


def _nsga(spec: ParetoSpec, run: Any, lo: np.ndarray, hi: np.ndarray) -> dict:
    """NSGA-II (pymoo) on the family's unit box; each generation evaluated through ``run`` (the batch)."""
    try:
        from pymoo.algorithms.moo.nsga2 import NSGA2
        from pymoo.core.problem import Problem as MooProblem
        from pymoo.optimize import minimize as moo_minimize
    except ImportError as exc:  # pragma: no cover - the optional extra is missing
        raise ImportError("the NSGA-II check needs pymoo: pip install 'flexopt[pareto]'") from exc
    prob = spec.problem
    pj = prob.model_dump(mode="json")
    points = 2 * prob.samples - 1
    check = spec.check
    assert check is not None
    seen: list[dict] = []

    class _Moo(MooProblem):
        def __init__(self) -> None:
            super().__init__(n_var=len(lo), n_obj=2, n_ieq_constr=2, xl=0.0, xu=1.0)

        def _evaluate(self, X, out, *args, **kwargs):
            recs = run(
                [{"problem": pj, "x": [float(v) for v in x], "points": points} for x in X],
                "check",
                "flexopt.optim.pareto:evaluate_design",
            )
            F, G = [], []
            for r in recs:
                if r.get("ok"):
                    seen.append(r)
                    F.append([-r["worst_hz"], r["drive_stiffness"]])
                    G.append([r["stress_ratio"] - 1.0, r["envelope"]])
                else:  # a design whose curve fails is infeasible, never a value
                    F.append([0.0, 1e30])
                    G.append([1e30, 1e30])
            out["F"], out["G"] = np.array(F), np.array(G)

    res = moo_minimize(
        _Moo(), NSGA2(pop_size=check.population), ("n_gen", check.generations), seed=check.seed, verbose=False
    )
    X = np.atleast_2d(res.X) if res.X is not None else np.zeros((0, len(lo)))
    return {"front_x": X.tolist(), "evaluated": len(seen)}


def example_spec() -> dict:
    """A small front (cross-spring pivot, length and thickness, +-30 deg): what ``flexopt pareto --example``
    prints."""
    return {
        "format": "flexopt-pareto",
        "version": 1,
        "points": 5,
        "problem": {
            "families": [
                {"template": "cross-spring-pivot", "design": {"length": [0.03, 0.07], "thickness": [2e-4, 4e-4]}}
            ],
            "stroke": 30,
            "samples": 5,
            "starts": 1,
            "verify_points": 61,
        },
        "check": {"population": 12, "generations": 6, "tolerance": 0.02, "seed": 0},
    }


# ---------------------------------------------------------------------------------------- driver
def pareto(
    spec: ParetoSpec | dict,
    *,
    executor: cf.Executor | None = None,
    workers: int | None = None,
    store: Any = None,
    progress: Any = None,
    cancel: Any = None,
) -> dict:
    """The front of ``spec`` (module docstring): JSON with its points (design, verified worst case [Hz],
    drive stiffness with its unit, stress ratio, status), the single-objective optima, the NSGA-II check
    and warnings. ``executor``: any ``concurrent.futures.Executor`` (default: a local process pool of
    ``workers``, shared by every phase); ``store``: a directory of finished cases, as
    :func:`optim.batch.run_cases`'s (a rerun resumes); ``progress`` and ``cancel`` (a ``threading.Event``) as
    there, per phase, each event with its ``phase`` (:data:`PHASES`); an event's record is the case's point
    (its ``kind``, ``level``, verified ``worst_hz`` and ``drive_stiffness``, or ``stroke``) or, in the check,
    an evaluated design."""
    from ..model.threads import limited
    from .batch import run_cases
    from .search import FamilyEvaluator

    spec = ParetoSpec.model_validate(spec)
    prob = spec.problem.model_copy(update={"max_drive": None})
    FamilyEvaluator(prob, prob.families[0])  # fail fast, in the caller, on a bad family
    s_si, k_unit, _ = _stroke_si(prob)
    pj = prob.model_dump(mode="json")
    t0 = time.perf_counter()
    own = executor is None
    ex: cf.Executor = cf.ProcessPoolExecutor(max_workers=workers) if executor is None else executor

    def run(cs: list[dict], phase: str, fn: str = "flexopt.optim.pareto:run_point") -> list[dict]:
        def told(event: dict) -> None:  # every event names its phase (PHASES: the job's status, the web page)
            progress({**event, "phase": phase})

        return run_cases(cs, fn, executor=ex, store=store, progress=told if progress else None, cancel=cancel)

    def level_cases(kind: str, level: float | None = None) -> list[dict]:
        return [
            {"problem": pj, "kind": kind, "start": s, **({} if level is None else {"level": level})}
            for s in range(prob.starts)
        ]

    if spec.against == "stroke":
        try:
            with limited():
                return _stroke_front(spec, prob, run, level_cases, k_unit, t0)
        finally:
            if own:
                ex.shutdown()
    try:
        with limited():
            ends = run(level_cases("max_frequency") + level_cases("min_drive"), "optima")
            top = _best(ends[: prob.starts])
            bottom = _best(ends[prob.starts :], by_drive=True)
            notes: list[dict] = []
            points = [bottom]
            if top["status"] == "optimal" and bottom["status"] == "optimal":
                k_lo, k_hi = bottom["drive_stiffness"], top["drive_stiffness"]
                levels = [k_lo + (k_hi - k_lo) * i / (spec.points - 1) for i in range(1, spec.points - 1)]
                flat = [c for lv in levels for c in level_cases("epsilon", lv)]
                recs = run(flat, "levels") if flat else []
                for i in range(len(levels)):
                    points.append(_best(recs[i * prob.starts : (i + 1) * prob.starts]))
            else:
                notes.append(
                    {
                        "kind": "notice",
                        "message": "a single-objective optimum failed (max frequency: "
                        f"{top['status']} {top['message']}; min drive stiffness: {bottom['status']} "
                        f"{bottom['message']}); no front between them",
                    }
                )
            points.append(top)
            front = [p for p in points if p["status"] == "optimal"]
            for p in points:
                if p["status"] != "optimal":
                    notes.append(
                        {
                            "kind": "notice",
                            "message": f"the point at level {p['level']} is not on the "
                            f"front: {p['status']} ({p['message']})",
                        }
                    )
            for p in front:
                p["dominated_by"] = [j for j, q in enumerate(front) if q is not p and dominates(q, p)]
                if p["dominated_by"]:
                    notes.append(
                        {
                            "kind": "notice",
                            "message": f"the point of drive stiffness "
                            f"{p['drive_stiffness']:.6g} {k_unit} is dominated by another point of the front",
                        }
                    )
            check = None
            if spec.check is not None:
                check = _check(spec, prob, front, run, s_si)
                if not check["passed"]:
                    notes.append({"kind": "notice", "message": check["summary"]})
    finally:
        if own:
            ex.shutdown()
    return {
        "format": "flexopt-pareto-result",
        "template": prob.families[0].template,
        "against": "drive_stiffness",
        "objectives": {"worst_hz": "maximised, Hz", "drive_stiffness": f"minimised, {k_unit}"},
        "drive_stiffness_unit": k_unit,
        "stroke_si": s_si,
        "points": front,
        "rejected": [p for p in points if p not in front],
        "max_frequency": top,
        "min_drive_stiffness": bottom,
        "check": check,
        "seconds": time.perf_counter() - t0,
        "warnings": notes,
        "spec": spec.model_dump(mode="json"),
    }


def _stroke_front(spec: ParetoSpec, prob: Problem, run: Any, level_cases: Any, k_unit: str, t0: float) -> dict:
    """Worst case against stroke: the frequency optimum at each stroke (the search with ``stroke`` set)."""
    assert spec.strokes is not None
    lo, hi = spec.strokes
    levels = [lo + (hi - lo) * i / (spec.points - 1) for i in range(spec.points)]
    recs = run([c for lv in levels for c in level_cases("stroke", lv)], "strokes")
    points = [_best(recs[i * prob.starts : (i + 1) * prob.starts]) for i in range(len(levels))]
    for p, lv in zip(points, levels):
        p["stroke"] = lv
    front = [p for p in points if p["status"] == "optimal"]
    notes = [
        {
            "kind": "notice",
            "message": f"the point at stroke {p['stroke']:.6g} is not on the front: {p['status']} ({p['message']})",
        }
        for p in points
        if p["status"] != "optimal"
    ]
    for p in front:
        p["dominated_by"] = [j for j, q in enumerate(front) if q is not p and dominates(q, p, against="stroke")]
        if p["dominated_by"]:
            notes.append(
                {
                    "kind": "notice",
                    "message": f"the point at stroke {p['stroke']:.6g} is dominated by another "
                    "point of the front (a longer stroke reaches at least its worst case)",
                }
            )
    unit = "deg" if k_unit == "N m/rad" else "m"
    return {
        "format": "flexopt-pareto-result",
        "template": prob.families[0].template,
        "against": "stroke",
        "objectives": {"worst_hz": "maximised, Hz", "stroke": f"maximised, {unit}"},
        "stroke_unit": unit,
        "drive_stiffness_unit": k_unit,
        "points": front,
        "rejected": [p for p in points if p not in front],
        "max_frequency": None,
        "min_drive_stiffness": None,
        "check": None,
        "seconds": time.perf_counter() - t0,
        "warnings": notes,
        "spec": spec.model_dump(mode="json"),
    }


def _check(spec: ParetoSpec, prob: Problem, front: list[dict], run: Any, s_si: float) -> dict:
    """NSGA-II's non-dominated points, verified on ``verify_points`` like the front's, against the front."""
    from .search import FamilyEvaluator

    assert spec.check is not None
    fam = FamilyEvaluator(prob, prob.families[0])
    t0 = time.perf_counter()
    res = _nsga(spec, run, fam.lo, fam.hi)
    pj = prob.model_dump(mode="json")
    ver = run(
        [{"problem": pj, "x": x, "points": prob.verify_points} for x in res["front_x"]],
        "check verification",
        "flexopt.optim.pareto:evaluate_design",
    )
    tol = spec.check.tolerance
    pts = [
        r for r in ver if r.get("ok") and r["stress_ratio"] <= 1 + prob.tolerance and r["envelope"] <= prob.tolerance
    ]
    beats = [
        {
            "nsga": q["design"],
            "nsga_worst_hz": q["worst_hz"],
            "nsga_drive_stiffness": q["drive_stiffness"],
            "front_worst_hz": p["worst_hz"],
            "front_drive_stiffness": p["drive_stiffness"],
        }
        for q in pts
        for p in front
        if dominates(q, p, tol)
    ]
    margin = max(
        (
            max(q["worst_hz"] / p["worst_hz"] - 1, 1 - q["drive_stiffness"] / p["drive_stiffness"])
            for q in pts
            for p in front
            if q["worst_hz"] >= p["worst_hz"] and q["drive_stiffness"] <= p["drive_stiffness"]
        ),
        default=0.0,
    )
    passed = not beats
    summary = (
        f"NSGA-II ({spec.check.population} x {spec.check.generations}, {res['evaluated']} exact curves): "
        f"{len(pts)} verified non-dominated points, "
        + (
            "none dominates a front point by more than "
            if passed
            else f"{len(beats)} dominate front points by more than "
        )
        + f"{tol:g} (largest margin of a dominating NSGA-II point: {margin:.3g})"
    )
    return {
        "passed": passed,
        "tolerance": tol,
        "points": pts,
        "dominating": beats,
        "largest_margin": margin,
        "evaluations": res["evaluated"],
        "seconds": time.perf_counter() - t0,
        "summary": summary,
    }
