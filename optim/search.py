"""Maximise the worst-case first parasitic frequency over the stroke.

Formulation (epigraph)
----------------------
With the design scaled to the unit box, ``x = (p - lower) / (upper - lower)``, the search solves

    maximise t   subject to   f_k(s_j; x) / f_ref >= t      for the ``modes`` lowest parasitic modes k
                                                            at every stroke sample s_j,
                              sigma_j(x) <= sigma_allow / safety_factor,   |F_j(x)| <= max_drive,
                              0 <= x <= 1,

by SLSQP with exact gradients (:mod:`model.design`: the implicit function theorem through each sampled
equilibrium, ``d lambda = phi^T (dK - lambda dM) phi``, cluster means for repeated eigenvalues). The
minimum over the stroke is not differentiable where the worst sample or the lowest mode switches; the
epigraph keeps every sample and several modes as smooth constraints, so a switch changes which
constraints are active but never hides the minimum (a KS aggregate would smooth it at the price of a
bias that depends on its parameter). ``f_ref`` is the starting design's worst case (scaling only).

Fidelity ladder
---------------
The search sees ``samples`` exact stroke points; the result is then *verified* with the exact method on
``verify_points`` (181 by default) points. If the verified minimum lies between samples and is lower than
the searched one by more than ``tolerance``, its stroke is added to the samples and the search resumes
from the current design (``refine_rounds`` times at most). Both figures are reported; a result whose
final verification failed (lost equilibrium, violated stress) is reported as such, never as an optimum.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize
from scipy.stats import qmc

from ..model.analysis import Analysis
from ..model.design import point_sensitivity, structure_derivative, trace_template
from ..model.errors import FlexoptError
from ..model.templates import TEMPLATES

from .problem import Family, Problem

__all__ = ["run_case", "cases", "optimise", "summarise"]


@dataclass
class _Eval:
    x: np.ndarray
    con: np.ndarray  # constraint values (>= 0 feasible), scaled
    jac: np.ndarray  # (n_con, n_x + 1)
    worst_hz: float
    stroke_at_worst: float
    max_stress: float
    ok: bool
    message: str = ""
    strokes: np.ndarray | None = None  # stroke (user unit) of each constraint row; nan for the envelope


def _bounds(fam: Family, prob: Problem) -> tuple[list[str], np.ndarray, np.ndarray]:
    names = list(fam.design)
    lo = np.array([fam.design[k][0] for k in names], dtype=float)
    hi = np.array([fam.design[k][1] for k in names], dtype=float)
    for i, k in enumerate(names):
        if "thickness" in k:
            lo[i] = max(lo[i], prob.min_thickness)
            if not lo[i] < hi[i]:
                raise FlexoptError(f"families[].design.{k}: the upper bound {hi[i]:g} m is below the minimum "
                                   f"manufacturable thickness {prob.min_thickness:g} m; raise it")
    return names, lo, hi


class _Family:
    """Evaluations of one family at scaled designs (cached on x)."""

    def __init__(self, prob: Problem, fam: Family) -> None:
        if fam.template not in TEMPLATES:
            raise FlexoptError(f"families[].template: unknown template '{fam.template}'; choose one of "
                               f"{sorted(TEMPLATES)}")
        self.prob, self.fam = prob, fam
        self.names, self.lo, self.hi = _bounds(fam, prob)
        defaults = TEMPLATES[fam.template][1]
        unknown = sorted(set(self.names) - set(defaults))
        if unknown:
            raise FlexoptError(f"families[].design: template '{fam.template}' has no parameters {unknown}; "
                               f"its parameters are {sorted(defaults)}")
        self.stroke = float(prob.stroke if prob.stroke is not None else defaults.get("stroke", 45.0))
        self.samples = np.linspace(-self.stroke, self.stroke, prob.samples)
        self.f_ref: float | None = None
        self.keep: np.ndarray | None = None  # constraint rows passed to SLSQP (see dedupe)
        self._last: _Eval | None = None
        self._good: _Eval | None = None  # the last successful evaluation
        self.evaluations = 0

    def params(self, x: np.ndarray) -> dict:
        p = dict(self.fam.fixed)
        p.update({k: float(v) for k, v in zip(self.names, self.lo + np.clip(x, 0, 1) * (self.hi - self.lo))})
        p["stroke"] = self.stroke
        return p

    def default_x(self) -> np.ndarray:
        d = TEMPLATES[self.fam.template][1]
        return np.clip((np.array([float(d[k]) for k in self.names]) - self.lo) / (self.hi - self.lo), 0, 1)

    def evaluate(self, x: np.ndarray) -> _Eval:
        x = np.asarray(x, dtype=float)
        if self._last is not None and np.array_equal(self._last.x, x):
            return self._last
        self.evaluations += 1
        try:
            ev = self._evaluate(x)
        except FlexoptError as exc:
            ev = self._failed(x, str(exc))
        self._last = ev
        if ev.ok:
            self._good = ev
        return ev

    def _failed(self, x: np.ndarray, message: str) -> _Eval:
        # an infeasible point: every frequency constraint violated; the gradient of the last good point
        # (if any) steers SLSQP's line search back
        good = self._good
        if good is None:  # only the start design can fail without a previous good point: run_case stops
            n = len(self.samples) * self.prob.modes
            return _Eval(x.copy(), -np.ones(n), np.zeros((n, len(x) + 1)), float("nan"), float("nan"),
                         float("nan"), False, message)
        return _Eval(x.copy(), -np.ones(len(good.con)), good.jac, float("nan"), float("nan"), float("nan"), False,
                     message, good.strokes)

    def _evaluate(self, x: np.ndarray) -> _Eval:
        prob = self.prob
        ds = trace_template(self.fam.template, self.params(x), self.names)
        an = Analysis(ds.scene)
        scale = self.hi - self.lo
        dstructs = [structure_derivative(an.structure, ds.scene_dict, d) for d in ds.dscene]
        rows_f: list[tuple[float, np.ndarray, float]] = []
        rows_g: list[tuple[float, np.ndarray, float]] = []
        unit = ds.scene.stroke.resolved_unit
        to_user = (lambda v: float(np.degrees(v))) if unit == "deg" else float
        pts: dict[float, tuple[float, float]] = {}
        mats = {m.name: m for m in ds.scene.materials}
        allow = min(mats[e.material].allowable_stress for e in ds.scene.elements) / prob.safety_factor

        def visit(eq, modes, labels):
            par = [i for i in np.argsort(modes.omega2) if labels[i] == "parasitic"][: prob.modes]
            if len(par) < prob.modes:
                raise FlexoptError(f"only {len(par)} parasitic modes are tracked; lower 'modes' or raise the "
                                   "template's 'modes'")
            ps = point_sensitivity(an.system, eq, modes, par, dstructs)
            lam = modes.omega2[par]
            hz = np.sqrt(np.maximum(lam, 0)) / (2 * np.pi)
            for k in range(len(par)):
                dhz = ps.dlam[:, k] / (8 * np.pi**2 * max(hz[k], 1e-300)) * scale
                rows_f.append((hz[k], dhz, to_user(eq.stroke)))
            i = np.unravel_index(np.argmax(ps.vm), ps.vm.shape)
            vm = float(ps.vm[i])
            rows_g.append((1.0 - vm / allow, -ps.dvm[:, i[0], i[1]] * scale / allow, to_user(eq.stroke)))
            if prob.max_drive is not None:
                r = eq.drive_reaction
                rows_g.append((1.0 - abs(r) / prob.max_drive, -np.sign(r) * ps.dreaction * scale / prob.max_drive,
                               to_user(eq.stroke)))
            pts[eq.stroke] = (float(hz[0]), vm)

        if prob.envelope is not None:  # every scene node within a sphere of radius envelope
            R2 = prob.envelope**2
            for k, node in enumerate(ds.scene_dict["nodes"]):
                pos = np.asarray(node["position"], float)
                dpos = np.array([d["nodes"][k]["position"] for d in ds.dscene], float)  # (np, 3)
                rows_g.append((1.0 - float(pos @ pos) / R2, -2.0 * (dpos @ pos) * scale / R2, float("nan")))
        curve = an.frequency_curve(stroke=self.samples, visit=visit)
        if curve.status != "complete":
            raise FlexoptError(curve.failures[0].message if curve.failures else "the stroke was not completed")
        f = np.array([r[0] for r in rows_f])
        if self.f_ref is None:
            self.f_ref = float(f.min())
        nx = len(x)
        con, jac = [], []
        for hz, d, _ in rows_f:  # f / f_ref - t >= 0
            con.append(hz / self.f_ref)
            jac.append(np.concatenate([d / self.f_ref, [-1.0]]))
        for v, d, _ in rows_g:
            con.append(v)
            jac.append(np.concatenate([d, [0.0]]))
        k = int(np.argmin(f))
        strokes = np.array([r[2] for r in rows_f] + [r[2] for r in rows_g])
        return _Eval(x.copy(), np.array(con), np.array(jac).reshape(len(con), nx + 1), float(f.min()),
                     rows_f[k][2], max(v[1] for v in pts.values()), True, strokes=strokes)

    def reduce_symmetric(self, ev: _Eval) -> bool:
        """Keep only the non-negative samples when every constraint row at ``-s`` equals the one at ``s``
        (values and gradients to 1e-6 of their scale: the mirrored equilibria agree to the
        Newton tolerance, about 1e-8): a design space symmetric in the stroke (a mirror or
        a 180-degree turn that maps the stroke to its negative) would otherwise give SLSQP pairs of
        identical constraints, whose linear dependence breaks its least-squares subproblem. The dense
        verification still covers the whole stroke, so a design that breaks the symmetry is caught."""
        if not ev.ok or ev.strokes is None or not np.any(self.samples < 0):
            return False
        rows = np.column_stack([ev.con, ev.jac])
        tol = 1e-6 * max(float(np.abs(rows).max()), 1e-300)
        for s_ in self.samples[self.samples < 0]:
            a, b = rows[ev.strokes == s_], rows[ev.strokes == -s_]
            if a.shape != b.shape or np.abs(a - b).max(initial=0.0) > tol:
                return False
        self.samples = self.samples[self.samples >= 0]
        self._last = self._good = None
        return True

    def dedupe(self, ev: _Eval) -> None:
        """Pass SLSQP each distinct constraint once: rows equal to an earlier one (value and gradient to 1e-9
        of the scale) at the start design, such as the envelope rows of mirrored nodes, are the same
        function of the design in a symmetric family, and duplicates make its subproblem singular."""
        if not ev.ok:
            return
        rows = np.column_stack([ev.con, ev.jac])
        tol = 1e-9 * max(float(np.abs(rows).max()), 1e-300)
        keep: list[int] = []
        for i in range(len(rows)):
            if all(np.abs(rows[i] - rows[j]).max() > tol for j in keep):
                keep.append(i)
        self.keep = np.array(keep)

    # the epigraph's frequency constraints are relative to t, the last variable
    def constraints(self):
        def fun(z):
            ev = self.evaluate(z[:-1])
            c = ev.con.copy()
            nf = len(self.samples) * self.prob.modes
            c[:nf] -= z[-1]
            return c if self.keep is None else c[self.keep]

        def jac(z):
            j = self.evaluate(z[:-1]).jac
            return j if self.keep is None else j[self.keep]

        return [{"type": "ineq", "fun": fun, "jac": jac}]


def _verify(fam: _Family, x: np.ndarray, points: int) -> dict:
    """The exact curve of design ``x`` on ``points`` stroke points: worst and zero-stroke frequency."""
    from ..model.templates import template

    params = fam.params(x)
    scene = template(fam.fam.template, **params)
    an = Analysis(scene)
    grid = np.linspace(-fam.stroke, fam.stroke, points)
    curve = an.frequency_curve(stroke=grid)
    mats = {m.name: m for m in scene.materials}
    allow = min(mats[e.material].allowable_stress for e in scene.elements)
    out = {"points": points, "status": curve.status,
           "failures": [f.message for f in curve.failures],
           "stroke": curve.stroke.tolist(), "parasitic_hz": curve.parasitic_hz.tolist()}
    if curve.status != "complete":
        return out
    ph = curve.parasitic_hz
    i = int(np.argmin(ph))
    zero = float(ph[int(np.argmin(np.abs(curve.stroke)))])
    per_point = np.nanmax(np.array(list(curve.max_von_mises.values())), axis=0)
    stress = float(per_point.max())
    out.update(worst_hz=float(ph[i]), stroke_at_worst=float(curve.stroke[i]), zero_stroke_hz=zero,
               ratio=float(ph[i] / zero), max_stress=stress, allowable_stress=allow,
               stress_ratio=stress * fam.prob.safety_factor / allow,
               stroke_at_max_stress=float(curve.stroke[int(np.argmax(per_point))]),
               max_drive=float(np.max(np.abs(curve.drive_reaction))), drive_unit=curve.drive_reaction_unit,
               scene=scene.model_dump(mode="json"))
    return out


def _start_points(fam: _Family, prob: Problem, family_index: int) -> np.ndarray:
    pts = [fam.default_x()]
    if prob.starts > 1:
        sampler = qmc.LatinHypercube(d=len(fam.names), seed=np.random.default_rng([prob.seed, family_index]))
        pts += list(sampler.random(prob.starts - 1))
    return np.array(pts)


def _screen(fam: _Family, prob: Problem, family_index: int, start: int, x0: np.ndarray) -> tuple[np.ndarray, dict]:
    """Fast first rung of the ladder: rank ``prob.screen`` candidates (the start point and its own slice of a
    seeded Latin hypercube) by their worst-case first parasitic frequency from ``model.derivatives`` with
    method 'auto' (each candidate's error estimate decides whether a Taylor estimate is good enough or the
    exact curve is needed). Candidates whose curve cannot be computed are skipped. Returns the best point
    and a record of the screening."""
    from ..model.derivatives import frequency_curve as fast_curve
    from ..model.templates import template

    sampler = qmc.LatinHypercube(d=len(fam.names), seed=np.random.default_rng([prob.seed, family_index, start, 1]))
    cands = [x0] + list(sampler.random(prob.screen - 1)) if prob.screen > 1 else [x0]
    grid = np.linspace(-fam.stroke, fam.stroke, 2 * prob.samples - 1)
    best, best_f, methods, scored = x0, -np.inf, {}, 0
    for x in cands:
        try:
            c = fast_curve(Analysis(template(fam.fam.template, **fam.params(x))), "auto", prob.screen_tolerance, grid)
        except FlexoptError:
            continue
        f = float(np.min(c.parasitic_hz))
        scored += 1
        methods[c.method] = methods.get(c.method, 0) + 1
        if np.isfinite(f) and f > best_f:
            best, best_f = np.asarray(x, dtype=float), f
    return best, {"candidates": len(cands), "scored": scored, "methods": methods, "best_estimate_hz": best_f}


def run_case(case: dict) -> dict:
    """One start of one family: search, verify, refine (the unit of work of a batch; JSON in and out)."""
    t0 = time.perf_counter()
    prob = Problem.model_validate(case["problem"])
    fi, si = int(case["family"]), int(case["start"])
    fam_spec = prob.families[fi]
    fam = _Family(prob, fam_spec)
    x0 = _start_points(fam, prob, fi)[si]
    screening = None
    if prob.screen:
        x0, screening = _screen(fam, prob, fi, si, x0)
    initial = _verify(fam, x0, prob.verify_points)
    x = x0.copy()
    history = []
    status, message = "optimal", ""
    verified: dict = {}
    searched = fam.evaluate(x)
    symmetric = fam.reduce_symmetric(searched)
    rounds = prob.refine_rounds + 1
    res = None
    if not searched.ok:
        status, message, rounds = "failed", f"the start design fails: {searched.message}", 0
    for rnd in range(rounds):
        ev0 = fam.evaluate(x)
        fam.dedupe(ev0)
        t_start = ev0.worst_hz / fam.f_ref if ev0.ok else 0.0
        res = minimize(
            lambda z: -z[-1], np.concatenate([x, [t_start]]),
            jac=lambda z: np.concatenate([np.zeros(len(x)), [-1.0]]),
            method="SLSQP", bounds=[(0.0, 1.0)] * len(x) + [(None, None)],
            constraints=fam.constraints(), options={"maxiter": prob.max_iterations, "ftol": prob.tolerance * 1e-2},
        )
        x = np.clip(res.x[:-1], 0, 1)
        searched = fam.evaluate(x)
        history.append({"round": rnd, "samples": fam.samples.tolist(), "slsqp_status": int(res.status),
                        "slsqp_message": str(res.message), "iterations": int(res.nit),
                        "searched_worst_hz": searched.worst_hz})
        if not searched.ok:
            status, message = "failed", searched.message
            break
        verified = _verify(fam, x, prob.verify_points)
        if verified["status"] != "complete":
            status, message = "failed", "; ".join(verified["failures"])
            break
        low = verified["worst_hz"] < searched.worst_hz * (1 - prob.tolerance)
        stressed = verified["stress_ratio"] > 1 + prob.tolerance
        if not (low or stressed) or rnd == prob.refine_rounds:
            if low:
                status = "unconverged"
                message = (f"the verified minimum ({verified['worst_hz']:.5g} Hz) is still below the searched one "
                           f"({searched.worst_hz:.5g} Hz) after {prob.refine_rounds} refinement rounds")
            break
        # the verified minimum (or the stress peak) lies between the samples: add its stroke and resume
        new = [s_ for s_, bad in ((verified["stroke_at_worst"], low), (verified["stroke_at_max_stress"], stressed))
               if bad]
        new = [abs(s_) for s_ in new] if symmetric else new + [-s_ for s_ in new]
        fam.samples = np.unique(np.concatenate([fam.samples, new]))
        fam._last = fam._good = None
    if status == "optimal":
        if verified.get("stress_ratio", 0) > 1 + prob.tolerance:
            status, message = "infeasible", "the verified stress exceeds allowable / safety_factor"
        elif res.status not in (0,):
            status, message = "iteration limit" if res.status == 9 else "stopped", str(res.message)
    params = fam.params(x)
    return {
        "family": fam_spec.template, "family_index": fi, "start": si, "status": status, "message": message,
        "design": {k: params[k] for k in fam.names},
        "bounds": {k: [float(lo), float(hi)] for k, lo, hi in zip(fam.names, fam.lo, fam.hi)},
        "x0": {k: float(fam.lo[i] + x0[i] * (fam.hi[i] - fam.lo[i])) for i, k in enumerate(fam.names)},
        "searched": {"worst_hz": searched.worst_hz, "stroke_at_worst": searched.stroke_at_worst,
                     "samples": len(fam.samples), "mirror_symmetric": symmetric,
                     "max_stress": searched.max_stress},
        "verified": verified, "initial": initial, "history": history, "screening": screening,
        "evaluations": fam.evaluations, "seconds": time.perf_counter() - t0,
    }


def cases(problem: Problem | dict) -> list[dict]:
    """The batch's units of work: one per (family, start)."""
    prob = Problem.model_validate(problem)
    pj = prob.model_dump(mode="json")
    return [{"problem": pj, "family": i, "start": k} for i in range(len(prob.families)) for k in range(prob.starts)]


def summarise(prob: Problem, results: list[dict]) -> dict:
    """Best verified start per family and the ranking of families by verified worst-case frequency."""
    fams = []
    for i, fam in enumerate(prob.families):
        rs = [r for r in results if r.get("family_index") == i]
        ok = [r for r in rs if r.get("status") in ("optimal", "iteration limit", "stopped")
              and r["verified"].get("worst_hz") is not None]
        best = max(ok, key=lambda r: r["verified"]["worst_hz"]) if ok else None
        fams.append({"template": fam.template, "best": best, "starts": len(rs),
                     "failed": [{"start": r.get("start"), "status": r.get("status"),
                                 "message": r.get("message") or r.get("error")} for r in rs if r not in ok]})
    ranking = sorted((f for f in fams if f["best"] is not None), key=lambda f: -f["best"]["verified"]["worst_hz"])
    return {"problem": prob.model_dump(mode="json"), "families": fams,
            "ranking": [{"template": f["template"], "worst_hz": f["best"]["verified"]["worst_hz"],
                         "zero_stroke_hz": f["best"]["verified"]["zero_stroke_hz"],
                         "ratio": f["best"]["verified"]["ratio"], "design": f["best"]["design"]}
                        for f in ranking]}


def optimise(problem: Problem | dict, *, executor=None, workers: int | None = None, store=None, progress=None,
             cancel=None) -> dict:
    """Optimise every family of ``problem`` (multi-start), in parallel, resumable through ``store``.

    ``executor``: any ``concurrent.futures.Executor`` (default: a local process pool of ``workers``; a
    Dask cluster through :func:`optim.batch.dask_executor`). Returns :func:`summarise`'s dictionary.
    """
    from .batch import run_cases

    prob = Problem.model_validate(problem)
    for fam in prob.families:  # fail fast, in the caller, on a bad family
        _Family(prob, fam)
    results = run_cases(cases(prob), "flexopt.optim.search:run_case", executor=executor, workers=workers, store=store,
                        progress=progress, cancel=cancel)
    return summarise(prob, results)


