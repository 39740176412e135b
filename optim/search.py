"""Maximise the worst-case first parasitic frequency over the stroke.

Formulation (epigraph)
----------------------
With the design scaled to the unit box, ``x = (p - lower) / (upper - lower)``, the search solves

    maximise t   subject to   f_k(s_j; x) / f_ref >= t        for the ``modes`` lowest parasitic modes k
                                                              at every stroke sample s_j,
                              (sigma_e(s_j; x) / sigma_allow)^2 <= 1   at every segment end e,
                              (F_j(x) / max_drive)^2 <= 1,   every node inside the envelope,
                              0 <= x <= 1,

by SLSQP (or scipy's ``trust-constr``) with exact gradients (:mod:`model.design`: the implicit function
theorem through each sampled equilibrium, ``d lambda = phi^T (dK - lambda dM) phi``, cluster means for
repeated eigenvalues). The minimum over the stroke is not differentiable where the worst sample or the
lowest mode switches; the epigraph keeps every sample and several modes as smooth constraints, so a switch
changes which constraints are active but never hides the minimum. The stress limit is treated the same
way: one constraint per segment end and sample (never the maximum over the segments, whose kinks stall
SLSQP), squared so that its gradient is finite where the stress vanishes (the root's gradient is 0/0 at
the stroke's zero of an unstressed hinge). Every segment end's row is passed to the solver (a subset
chosen at the round's start, e.g. the ends above half the peak stress, was measured to miss the ends a
moving crossing point makes critical); rows that duplicate another (mirrored leaves, mirrored nodes) are
passed once. ``f_ref`` is the start's worst case (scaling only).

Fidelity ladder
---------------
The search sees ``samples`` exact stroke points; the result is then *verified* with the exact method on
``verify_points`` (181 by default) points. If the verified minimum (or stress peak) lies between samples,
its stroke is added and the search resumes (``refine_rounds`` times at most). A round that would add
nothing (the violation lies at a stroke already sampled) stops with the reason: never an identical rerun.

Optimality and status
---------------------
Every start reports the solver's exit and a first-order optimality measure: the KKT residual
``min_{mu >= 0} || grad f - sum mu_i grad c_i ||`` over the constraints and bounds active within
``tolerance`` (non-negative least squares; ``grad f`` has unit norm), with the largest violation and the
active bounds. ``status`` is "optimal" (solver converged, KKT residual within ``kkt_tolerance``, verified
and feasible), "unconverged" (verified and feasible, but the solver stopped or the residual is large),
"infeasible" (the verification violates the stress limit) or "failed" (an evaluation or the verification
failed). The ranking uses "optimal" starts only; the others are listed with their status.

A design whose evaluation fails (equilibrium lost along the stroke) is never given to the solver as a
value: the solver stops, and the search steps back to the last good design and resumes inside a box
around it half as wide as the failed step (a trust region), at most ``_STEP_BACKS`` times per round. A
start design that fails (e.g. unstable at zero stroke) steps toward start 0, the template's own design,
along the segment between them (``_START_STEPS``), and says so in its warnings.
"""

from __future__ import annotations

import hashlib
import json
import re
import time
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import BFGS, Bounds, NonlinearConstraint, minimize, nnls

from ..model.curve import Analysis
from ..model.design import point_sensitivity, structure_derivatives, trace_template
from ..model.errors import FlexoptError
from ..model.results import ResultWarning
from ..model.templates import TEMPLATES, start_value
from ..model.threads import limited
from .problem import Envelope, Family, Problem

__all__ = [
    "run_case",
    "cases",
    "optimise",
    "summarise",
    "start_point",
    "warm_point",
    "FamilyEvaluator",
    "verify",
    "envelope_points",
]

_STEP_BACKS = 4  # failed evaluations per round before the start is reported as failed
_BOUND_TOL = 1e-6  # a scaled design variable this close to 0 or 1 is on its bound
_START_STEPS = (0.25, 0.5, 0.75, 1.0)  # a failing start steps this far toward start 0 (the template's design)


class _EvaluationFailed(Exception):
    """An evaluation failed: the solver must not see a value there (see the module docstring)."""

    def __init__(self, x: np.ndarray, message: str) -> None:
        super().__init__(message)
        self.x = x


@dataclass
class _Eval:
    x: np.ndarray
    con: np.ndarray  # constraint values (>= 0 feasible), scaled; frequency rows without the epigraph's t
    jac: np.ndarray  # (n_con, n_x + 1)
    worst_hz: float
    stroke_at_worst: float
    max_stress: float
    ok: bool
    message: str = ""
    strokes: np.ndarray | None = None  # stroke (user unit) of each constraint row; nan for the envelope
    kinds: np.ndarray | None = None  # "frequency", "stress", "drive", "envelope" per row
    labels: list[str] = field(default_factory=list)  # what each row bounds, for the report
    hz: np.ndarray | None = None  # the frequency rows' frequencies [Hz] (unscaled)
    peaks: dict[float, float] | None = None  # per stroke sample (user unit): the largest von Mises stress there


def _bounds(fam: Family, prob: Problem) -> tuple[list[str], np.ndarray, np.ndarray]:
    names = list(fam.design)
    lo = np.array([fam.design[k][0] for k in names], dtype=float)
    hi = np.array([fam.design[k][1] for k in names], dtype=float)
    for i, k in enumerate(names):
        if "thickness" in k:
            lo[i] = max(lo[i], prob.min_thickness)
            if not lo[i] < hi[i]:
                raise FlexoptError(
                    f"families[].design.{k}: the upper bound {hi[i]:g} m is below the minimum "
                    f"manufacturable thickness {prob.min_thickness:g} m; raise it"
                )
    return names, lo, hi


class FamilyEvaluator:
    """Evaluations of one family at scaled designs (cached on x)."""

    def __init__(self, prob: Problem, fam: Family) -> None:
        if fam.template not in TEMPLATES:
            raise FlexoptError(
                f"families[].template: unknown template '{fam.template}'; choose one of {sorted(TEMPLATES)}"
            )
        self.prob, self.fam = prob, fam
        self.names, self.lo, self.hi = _bounds(fam, prob)
        defaults = TEMPLATES[fam.template][1]
        unknown = sorted(set(self.names) - set(defaults))
        if unknown:
            raise FlexoptError(
                f"families[].design: template '{fam.template}' has no parameters {unknown}; "
                f"its parameters are {sorted(defaults)}"
            )
        if prob.body_mass is not None:
            if "body_mass" not in defaults:
                raise FlexoptError(
                    f"body_mass: template '{fam.template}' has no moving body ('body_mass'); "
                    "remove body_mass from the problem or this family"
                )
            if "body_mass" in fam.design or fam.fixed.get("body_mass", prob.body_mass) != prob.body_mass:
                raise FlexoptError(
                    f"families[].{fam.template}: body_mass is set by the problem "
                    f"({prob.body_mass:g} kg, the same for every family); remove it from the family"
                )
        self.stroke = float(prob.stroke if prob.stroke is not None else defaults.get("stroke", 45.0))
        self.samples = np.linspace(-self.stroke, self.stroke, prob.samples)
        self.f_ref: float | None = None
        self.keep: np.ndarray | None = None  # constraint rows passed to the solver (see select)
        self._last: _Eval | None = None
        self._good: _Eval | None = None  # the last successful evaluation
        self.evaluations = 0

    def params(self, x: np.ndarray) -> dict:
        p = dict(self.fam.fixed)
        if self.prob.body_mass is not None:
            p["body_mass"] = self.prob.body_mass
        p.update({k: float(v) for k, v in zip(self.names, self.lo + np.clip(x, 0, 1) * (self.hi - self.lo))})
        p["stroke"] = self.stroke
        return p

    def extra(self) -> dict | None:
        """The scene fields the problem adds to every family's template scene (its ``gravity``), or None."""
        return {"gravity": [float(v) for v in self.prob.gravity]} if self.prob.gravity is not None else None

    def scene(self, x: np.ndarray) -> Any:
        """The template's scene at design ``x``, with the problem's additions (:meth:`extra`)."""
        from ..model.templates import template

        scene = template(self.fam.template, **self.params(x))
        extra = self.extra()
        if extra is None:
            return scene
        from ..model.io import scene_from_dict

        return scene_from_dict({**scene.model_dump(mode="json"), **extra})

    def moving_mass(self) -> float | None:
        """The moving body's (payload's) mass of this family [kg]: the template's 'body_mass'; None if it has
        none or designs it."""
        d = TEMPLATES[self.fam.template][1]
        if "body_mass" not in d or "body_mass" in self.names:
            return None
        return float(self.params(np.zeros(len(self.names))).get("body_mass", d["body_mass"]))

    def default_x(self) -> np.ndarray:
        start = [start_value(self.fam.template, k) for k in self.names]
        return np.clip((np.array(start) - self.lo) / (self.hi - self.lo), 0, 1)

    def evaluate(self, x: np.ndarray) -> _Eval:
        x = np.asarray(x, dtype=float)
        if self._last is not None and np.array_equal(self._last.x, x):
            return self._last
        self.evaluations += 1
        try:
            ev = self._evaluate(x)
        except FlexoptError as exc:
            ev = _Eval(
                x.copy(),
                np.empty(0),
                np.empty((0, len(x) + 1)),
                float("nan"),
                float("nan"),
                float("nan"),
                False,
                str(exc),
            )
        self._last = ev
        if ev.ok:
            self._good = ev
        return ev

    def _evaluate(self, x: np.ndarray) -> _Eval:
        prob = self.prob
        ds = trace_template(self.fam.template, self.params(x), self.names, self.extra())
        an = Analysis(ds.scene)
        s = an.structure
        scale = self.hi - self.lo
        dstructs = structure_derivatives(s, ds.scene_dict, ds.dscene)
        rows_f: list[tuple[float, np.ndarray, float, str]] = []
        rows_g: list[tuple[float, np.ndarray, float, str, str]] = []  # value, gradient, stroke, kind, label
        stroke = ds.scene.stroke
        assert stroke is not None  # every family is a stroked template (FamilyEvaluator refuses others)
        unit = stroke.resolved_unit
        to_user = (lambda v: float(np.degrees(v))) if unit == "deg" else float
        pts: dict[float, tuple[float, float]] = {}
        peaks: dict[float, float] = {}
        mats = {m.name: m for m in ds.scene.materials}
        allow = min(mats[e.material].allowable_stress for e in ds.scene.elements) / prob.safety_factor
        member = [s.member_names[i] for i in s.beam_member]

        def visit(eq, modes, labels):
            par = [i for i in np.argsort(modes.omega2) if labels[i] == "parasitic"][: prob.modes]
            if len(par) < prob.modes:
                raise FlexoptError(
                    f"only {len(par)} parasitic modes are tracked; lower 'modes' or raise the template's 'modes'"
                )
            ps = point_sensitivity(an.system, eq, modes, par, dstructs)
            lam = modes.omega2[par]
            hz = np.sqrt(np.maximum(lam, 0)) / (2 * np.pi)
            su = to_user(eq.stroke)
            for k in range(len(par)):
                dhz = ps.dlam[:, k] / (8 * np.pi**2 * max(hz[k], 1e-300)) * scale
                rows_f.append((hz[k], dhz, su, f"parasitic mode {k + 1} at stroke {su:.6g}"))
            # one smooth row per segment end: 1 - (sigma / allow)^2 >= 0
            for b in range(s.n_beams):
                for end in range(2):
                    r = float(ps.vm[b, end]) / allow
                    rows_g.append(
                        (
                            1.0 - r * r,
                            -ps.dvm2[:, b, end] * scale / allow**2,
                            su,
                            "stress",
                            f"stress in {member[b]} (segment {b}, end {end}) at stroke {su:.6g}",
                        )
                    )
            if prob.max_drive is not None:
                r = eq.drive_reaction / prob.max_drive
                rows_g.append(
                    (
                        1.0 - r * r,
                        -2.0 * r * ps.dreaction * scale / prob.max_drive,
                        su,
                        "drive",
                        f"drive force or moment at stroke {su:.6g}",
                    )
                )
            pts[eq.stroke] = (float(hz[0]), float(np.max(ps.vm)))
            peaks[su] = float(np.max(ps.vm))

        if prob.envelope is not None:
            for pos, dpos, name in envelope_points(ds.scene_dict, ds.dscene):
                if not isinstance(prob.envelope, Envelope):  # a sphere about the origin
                    R2 = prob.envelope**2
                    rows_g.append(
                        (
                            1.0 - float(pos @ pos) / R2,
                            -2.0 * (dpos @ pos) * scale / R2,
                            float("nan"),
                            "envelope",
                            f"{name} on the envelope (sphere)",
                        )
                    )
                    continue
                axis = np.asarray(stroke.axis, float)
                axis = axis / float(np.linalg.norm(axis))
                a, da = float(pos @ axis), dpos @ axis
                R2 = prob.envelope.radius**2
                rows_g.append(
                    (
                        1.0 - (float(pos @ pos) - a * a) / R2,
                        -2.0 * (dpos @ pos - a * da) * scale / R2,
                        float("nan"),
                        "envelope",
                        f"{name} on the envelope's radius",
                    )
                )
                if prob.envelope.half_height is not None:
                    H2 = prob.envelope.half_height**2
                    rows_g.append(
                        (
                            1.0 - a * a / H2,
                            -2.0 * a * da * scale / H2,
                            float("nan"),
                            "envelope",
                            f"{name} on the envelope's end",
                        )
                    )
        if self.fam.ratios:
            full = {**TEMPLATES[self.fam.template][1], **self.params(x)}
            for rt in self.fam.ratios:
                num, den = float(full[rt.numerator]), float(full[rt.denominator])
                k = rt.minimum * rt.factor
                g = np.zeros(len(x))
                for i, name in enumerate(self.names):  # d(1 - k den / num) along the scaled design
                    if name == rt.numerator:
                        g[i] += k * den / num**2 * scale[i]
                    if name == rt.denominator:
                        g[i] -= k / num * scale[i]
                rows_g.append(
                    (
                        1.0 - k * den / num,
                        g,
                        float("nan"),
                        "validity",
                        f"{rt.numerator} / ({rt.factor:g} {rt.denominator}) >= {rt.minimum:g}"
                        + (f" ({rt.reason})" if rt.reason else ""),
                    )
                )
        # the curve before its checks and provenance (model.checks.annotate_curve ran the scene and stress checks
        # and hashed the scene at every evaluation: about 5 % of a first-pass case, measured): only its status
        # and failures are read here
        with limited():  # one BLAS thread while it computes (model.threads)
            curve, _ = an.exact_curve(self.samples, visit=visit)
        if curve.status != "complete":
            raise FlexoptError(curve.failures[0].message if curve.failures else "the stroke was not completed")
        f = np.array([r[0] for r in rows_f])
        if self.f_ref is None:
            self.f_ref = float(f.min())
        nx = len(x)
        con = [hz / self.f_ref for hz, *_ in rows_f] + [r[0] for r in rows_g]
        jac = [np.concatenate([d / self.f_ref, [-1.0]]) for _, d, *_ in rows_f] + [
            np.concatenate([r[1], [0.0]]) for r in rows_g
        ]
        k = int(np.argmin(f))
        nf = len(rows_f)
        return _Eval(
            x.copy(),
            np.array(con),
            np.array(jac).reshape(len(con), nx + 1),
            float(f.min()),
            rows_f[k][2],
            max(v[1] for v in pts.values()),
            True,
            strokes=np.array([r[2] for r in rows_f] + [r[2] for r in rows_g]),
            kinds=np.array(["frequency"] * nf + [r[3] for r in rows_g]),
            labels=[r[3] for r in rows_f] + [r[4] for r in rows_g],
            hz=f,
            peaks=peaks,
        )

    def n_frequency(self) -> int:
        return len(self.samples) * self.prob.modes

    def reduce_symmetric(self, ev: _Eval) -> bool:
        """Keep only the non-negative samples when the constraint rows at ``-s`` are those at ``s`` (as a set:
        a mirror maps one leaf's segment ends onto the other's; values and gradients to 1e-6 of their scale,
        the mirrored equilibria agree to the Newton tolerance, about 1e-8): a design space symmetric in the
        stroke would otherwise give the solver pairs of identical constraints, whose linear dependence breaks
        SLSQP's least-squares subproblem. The dense verification still covers the whole stroke, so a
        design that breaks the symmetry is caught."""
        if not ev.ok or ev.strokes is None or not np.any(self.samples < 0):
            return False
        rows = np.column_stack([ev.con, ev.jac])
        tol = 1e-6 * max(float(np.abs(rows).max()), 1e-300)
        for s_ in self.samples[self.samples < 0]:
            a, b = rows[ev.strokes == s_], rows[ev.strokes == -s_]
            if a.shape != b.shape:
                return False
            used = np.zeros(len(b), dtype=bool)
            for r in a:  # pair each row at -s with an unused equal row at +s
                d = np.abs(b - r).max(axis=1, initial=0.0)
                d[used] = np.inf
                j = int(np.argmin(d)) if len(d) else -1
                if j < 0 or d[j] > tol:
                    return False
                used[j] = True
        self.samples = self.samples[self.samples >= 0]
        self._last = self._good = self._restricted(ev)
        return True

    def _restricted(self, ev: _Eval) -> _Eval | None:
        """``ev`` restricted to the non-negative samples (with the rows of no sample: envelope, validity): what
        an evaluation at ``ev.x`` on :meth:`reduce_symmetric`'s samples gives, without computing it again. The
        walk to each side of zero starts at the same reference equilibrium, so the rows of the non-negative side
        are the same numbers (measured bitwise on the 2- and 3-stage hinges at 4 and 8 segments); the worst case,
        its stroke and the peak stress are taken over those rows and samples as that evaluation takes them.
        None (evaluate again) for an evaluation without the per-row frequencies and per-sample peaks."""
        if ev.strokes is None or ev.hz is None or ev.peaks is None or ev.kinds is None:
            return None
        keep = np.isnan(ev.strokes) | (ev.strokes >= 0)
        nf = len(ev.hz)
        hz = ev.hz[keep[:nf]]
        strokes = ev.strokes[keep]
        peaks = {s_: v for s_, v in ev.peaks.items() if s_ >= 0}
        if not len(hz) or not peaks:
            return None
        k = int(np.argmin(hz))
        return _Eval(
            ev.x.copy(),
            ev.con[keep],
            ev.jac[keep],
            float(hz.min()),
            float(strokes[k]),
            max(peaks.values()),
            True,
            strokes=strokes,
            kinds=ev.kinds[keep],
            labels=[lab for lab, kp in zip(ev.labels, keep) if kp],
            hz=hz,
            peaks=peaks,
        )

    def select(self, ev: _Eval) -> None:
        """Choose the rows passed to the solver at the start of a round: each distinct row once. Rows equal to
        an earlier one (value and gradient to 1e-9 of the scale), such as the envelope rows of mirrored nodes
        or the mirrored leaves' stresses, are the same function of the design in a symmetric family, and
        duplicates make SLSQP's subproblem singular.

        Raises
        ------
        FlexoptError
            When a row is not finite (a NaN would make every comparison false and drop all rows but one).
        """
        assert ev.ok
        rows = np.column_stack([ev.con, ev.jac])
        bad = np.flatnonzero(~np.all(np.isfinite(rows), axis=1))
        if len(bad):
            raise FlexoptError(
                f"constraint rows {[ev.labels[i] for i in bad[:3]]} are not finite at design "
                f"{self.params(ev.x)}: a gradient is undefined there (report this as a bug)"
            )
        tol = 1e-9 * max(float(np.abs(rows).max()), 1e-300)
        keep: list[int] = []
        for i in range(len(rows)):
            if not keep or np.abs(rows[keep] - rows[i]).max(axis=1).min() > tol:
                keep.append(int(i))
        self.keep = np.array(keep, dtype=int)

    def _checked(self, z: np.ndarray) -> _Eval:
        ev = self.evaluate(z[:-1])
        if not ev.ok:
            raise _EvaluationFailed(np.asarray(z[:-1], float).copy(), ev.message)
        return ev

    def fun(self, z: np.ndarray) -> np.ndarray:
        """The solver's constraint values (>= 0) at ``z = (x, t)``: the epigraph's frequency rows minus t."""
        c = self._checked(z).con.copy()
        c[: self.n_frequency()] -= z[-1]
        return c if self.keep is None else c[self.keep]

    def jac(self, z: np.ndarray) -> np.ndarray:
        j = self._checked(z).jac
        return j if self.keep is None else j[self.keep]


def envelope_points(scene: dict, dscene: tuple[dict, ...]) -> list[tuple[np.ndarray, np.ndarray, str]]:
    """Points that must lie in the envelope, with their derivatives ``(np, 3)`` along the design: every scene
    node, and both edges of every rectangular leaf at its end nodes (node +- width/2 along the section's
    width direction ``y_axis``), so that the leaves' width counts. Rigid bodies are mass properties without a
    shape here and are not bounded; the thickness (t/2, well below a millimetre) is neglected."""
    pos = {
        n["name"]: (np.asarray(n["position"], float), np.array([d["nodes"][k]["position"] for d in dscene], float))
        for k, n in enumerate(scene["nodes"])
    }
    out = [(p, dp, f"node {name}") for name, (p, dp) in pos.items()]
    for k, el in enumerate(scene["elements"]):
        sec = el.get("section") or {}
        if el.get("kind") != "beam" or sec.get("kind") != "rectangular":
            continue
        y = np.asarray(el["y_axis"], float)
        dy = np.array([d["elements"][k]["y_axis"] for d in dscene], float)
        ny = float(np.linalg.norm(y))
        u = y / ny
        du = (dy - np.outer(dy @ u, u)) / ny  # derivative of the unit vector y / |y|
        w = float(sec["width"])
        dw = np.array([float(d["elements"][k]["section"]["width"]) for d in dscene])
        for node in el["nodes"]:
            p, dp = pos[node]
            for sign, side in ((1.0, "+"), (-1.0, "-")):
                out.append(
                    (
                        p + sign * 0.5 * w * u,
                        dp + sign * 0.5 * (np.outer(dw, u) + w * du),
                        f"edge {side} of {el['name']} at node {node}",
                    )
                )
    return out


def start_point(fam: FamilyEvaluator, prob: Problem, family_index: int, start: int) -> np.ndarray:
    """Start ``start`` of a family in the unit box: 0 the template's defaults clipped into the bounds, k >= 1
    the k-th point of a scrambled Halton sequence seeded by ``(seed, family_index)`` (Owen scrambling,
    scipy.stats.qmc). Each start depends only on its own index, so adding starts keeps the earlier ones,
    and the sequence fills the box evenly however many starts are drawn."""
    if start == 0:
        return fam.default_x()
    from scipy.stats import qmc  # here, not at the top: 0.8 s of this module's import in every job process

    seq = qmc.Halton(d=len(fam.names), scramble=True, seed=np.random.default_rng([prob.seed, family_index]))
    seq.fast_forward(start - 1)
    return seq.random(1)[0]


def _trust_constr_options(prob: Problem) -> dict:
    # measured (bench/bench_optim.py): with scipy's defaults (barrier 0.1, gtol 1e-8 loosened to the search's
    # tolerance) the interior point stops about 0.6 % inside an active bound; a small initial barrier and
    # tight barrier and gradient tolerances let it reach the bound in a few iterations more
    return {
        "maxiter": prob.max_iterations * 10,
        "gtol": prob.tolerance * 1e-5,
        "xtol": prob.tolerance * 1e-7,
        "barrier_tol": prob.tolerance * 1e-7,
        "initial_barrier_parameter": prob.tolerance,
    }


def _solve(fam: FamilyEvaluator, prob: Problem, x: np.ndarray, t0: float, lo: np.ndarray, hi: np.ndarray) -> dict:
    """One solver run from ``(x, t0)`` inside the box ``[lo, hi]``; raises _EvaluationFailed."""
    n = len(x)
    z0 = np.concatenate([np.clip(x, lo, hi), [t0]])
    obj = lambda z: -z[-1]
    grad = lambda z: np.concatenate([np.zeros(n), [-1.0]])
    if prob.solver == "slsqp":
        res = minimize(
            obj,
            z0,
            jac=grad,
            method="SLSQP",
            bounds=list(zip(lo, hi)) + [(None, None)],
            constraints=[{"type": "ineq", "fun": fam.fun, "jac": fam.jac}],
            options={"maxiter": prob.max_iterations, "ftol": prob.tolerance * 1e-2},
        )
        return {
            "z": res.x,
            "success": bool(res.status == 0),
            "code": int(res.status),
            "message": str(res.message),
            "iterations": int(res.nit),
        }
    con = NonlinearConstraint(fam.fun, 0.0, np.inf, jac=fam.jac, hess=BFGS())
    bounds = Bounds(np.concatenate([lo, [-np.inf]]), np.concatenate([hi, [np.inf]]))
    with warnings.catch_warnings():
        # BFGS skips its update where a constraint is linear in the step (the envelope, the epigraph's t)
        warnings.filterwarnings("ignore", message="delta_grad == 0.0", category=UserWarning)
        res = minimize(
            obj,
            z0,
            jac=grad,
            hess=lambda z: np.zeros((n + 1, n + 1)),
            method="trust-constr",
            bounds=bounds,
            constraints=[con],
            options=_trust_constr_options(prob),
        )
    return {
        "z": res.x,
        "success": bool(res.status in (1, 2)),
        "code": int(res.status),
        "message": str(res.message),
        "iterations": int(res.nit),
    }


def _optimality(fam: FamilyEvaluator, ev: _Eval, tol: float) -> dict:
    """First-order optimality at ``ev`` (all constraint rows, not only those passed to the solver):
    the KKT residual ``min_{mu >= 0} || grad f - J_A^T mu ||`` over the constraints and bounds active within
    ``tol`` (scipy.optimize.nnls; a scaled variable within ``tol`` of 0 or 1 is on its bound, which an
    interior-point solver approaches without touching), the largest violation, and what is active."""
    nf = fam.n_frequency()
    n = len(ev.x)
    t = float(ev.con[:nf].min())
    c = ev.con.copy()
    c[:nf] -= t
    act = np.flatnonzero(c <= tol)
    cols = [ev.jac[i] for i in act]
    names = [ev.labels[i] for i in act]
    bounds = {}
    for j, k in enumerate(fam.names):
        e = np.zeros(n + 1)
        if ev.x[j] <= tol:
            e[j] = 1.0
            cols.append(e)
            names.append(f"{k} at its lower bound")
            bounds[k] = "lower"
        elif ev.x[j] >= 1 - tol:
            e[j] = -1.0
            cols.append(e)
            names.append(f"{k} at its upper bound")
            bounds[k] = "upper"
    g = np.zeros(n + 1)
    g[-1] = -1.0  # gradient of the objective -t
    A = np.array(cols).T if cols else np.zeros((n + 1, 0))
    if A.shape[1]:
        mu, resid = nnls(A, g)
    else:
        mu, resid = np.zeros(0), float(np.linalg.norm(g))
    active = [nm for nm, m in zip(names, mu) if m > 1e-9]
    kinds = ev.kinds if ev.kinds is not None else np.array([], dtype=object)
    return {
        "kkt_residual": float(resid),
        "max_violation": float(max(0.0, -float(c.min()))),
        "active": active,
        "active_bounds": bounds,
        "active_kinds": sorted({str(kinds[i]) for i, m in zip(act, mu) if m > 1e-9}),
    }


def _curve_summary(curve, points: int) -> dict:
    """What a case records of a curve on ``points`` stroke points: status, failures, the curve, and (when
    complete) the worst first parasitic frequency, where it is, the zero-stroke one and their ratio."""
    out = {
        "points": points,
        "status": curve.status,
        "failures": [f.message for f in curve.failures],
        "stroke": curve.stroke.tolist(),
        "parasitic_hz": curve.parasitic_hz.tolist(),
    }
    if curve.status == "complete" and len(curve.stroke):
        ph = curve.parasitic_hz
        i = int(np.argmin(ph))
        zero = float(ph[int(np.argmin(np.abs(curve.stroke)))])
        out.update(
            worst_hz=float(ph[i]),
            stroke_at_worst=float(curve.stroke[i]),
            zero_stroke_hz=zero,
            ratio=float(ph[i] / zero),
        )
    return out


def verify(fam: FamilyEvaluator, x: np.ndarray, points: int, mesh_error: bool = True) -> dict:
    """The exact curve of design ``x`` on ``points`` stroke points: worst and zero-stroke frequency, stress;
    with ``mesh_error`` its mesh estimate (:func:`model.mesh.mesh_error`) too."""
    scene = fam.scene(x)
    an = Analysis(scene)
    grid = np.linspace(-fam.stroke, fam.stroke, points)
    curve = an.frequency_curve(stroke=grid, mesh_error=mesh_error)
    mats = {m.name: m for m in scene.materials}
    allow = min(mats[e.material].allowable_stress for e in scene.elements)
    out = _curve_summary(curve, points)
    out["warnings"] = [w.to_dict() for w in curve.warnings]  # the model's checks of the verified curve
    if "worst_hz" not in out:
        return out
    members = list(curve.max_von_mises)
    per_member = np.nan_to_num(np.array([curve.max_von_mises[m] for m in members]), nan=-np.inf)
    im, ip = np.unravel_index(int(np.argmax(per_member)), per_member.shape)
    stress = float(per_member[im, ip])
    out.update(
        max_stress=stress,
        allowable_stress=allow,
        stress_ratio=stress * fam.prob.safety_factor / allow,
        stroke_at_max_stress=float(curve.stroke[ip]),
        member_at_max_stress=members[im],
        max_drive=float(np.max(np.abs(curve.drive_reaction))),
        drive_unit=curve.drive_reaction_unit,
        scene=scene.model_dump(mode="json"),
    )
    return out


def _preview(fam: FamilyEvaluator, x: np.ndarray, points: int, tolerance: float) -> dict:
    """The start design's curve on ``points`` stroke points, for comparison with the optimum (``initial`` of a
    case; plotted by ``flexopt optimise --plot``). Nothing is decided on it, so it is computed with method
    'auto' at the search's ``tolerance`` (hermite where its estimate meets it: a quarter to a fifth of the
    exact curve's time on the hinge templates) and says so (``method``, ``estimated_error``); stresses are
    not computed. The optimum's curve (``verified``) stays exact."""
    from ..model.methods import frequency_curve as fast_curve

    grid = np.linspace(-fam.stroke, fam.stroke, points)
    try:
        curve = fast_curve(Analysis(fam.scene(x)), "auto", tolerance, grid)
    except FlexoptError as exc:
        return {"points": points, "status": "failed", "failures": [str(exc)], "stroke": [], "parasitic_hz": []}
    return {
        **_curve_summary(curve, points),
        "method": curve.solver.get("auto_method", curve.method),
        "estimated_error": curve.solver.get("auto_estimate", 0.0),
    }


def _screen(
    fam: FamilyEvaluator, prob: Problem, family_index: int, start: int, x0: np.ndarray
) -> tuple[np.ndarray, dict]:
    """Fast first rung of the ladder: rank ``prob.screen`` candidates (the start point and its own slice of a
    seeded Latin hypercube) by their worst-case first parasitic frequency from ``model.methods`` with
    method 'auto' (each candidate's error estimate decides whether a Taylor estimate is good enough or the
    exact curve is needed). Candidates whose curve cannot be computed are skipped. Returns the best point
    and a record of the screening."""
    from scipy.stats import qmc

    from ..model.methods import frequency_curve as fast_curve

    sampler = qmc.LatinHypercube(d=len(fam.names), seed=np.random.default_rng([prob.seed, family_index, start, 1]))
    cands = [x0] + list(sampler.random(prob.screen - 1)) if prob.screen > 1 else [x0]
    grid = np.linspace(-fam.stroke, fam.stroke, 2 * prob.samples - 1)
    best, best_f, scored = x0, -np.inf, 0
    methods: dict[str, Any] = {}
    for x in cands:
        try:
            c = fast_curve(Analysis(fam.scene(x)), "auto", prob.screen_tolerance, grid)
        except FlexoptError:
            continue
        f = float(np.min(c.parasitic_hz))
        scored += 1
        methods[c.method] = methods.get(c.method, 0) + 1
        if np.isfinite(f) and f > best_f:
            best, best_f = np.asarray(x, dtype=float), f
    return best, {"candidates": len(cands), "scored": scored, "methods": methods, "best_estimate_hz": best_f}


def _search(fam: FamilyEvaluator, prob: Problem, x: np.ndarray) -> dict:
    """One round of the search from the good design ``x``, stepping back after a failed evaluation.

    A failed evaluation stops the solver (it never sees a value there); the search resumes from the last
    good design inside a box around it of half the failed step's size (a trust region), and once a run
    ends inside such a box on its edge, from there in the whole box again. ``_STEP_BACKS`` failures at most.
    """
    n = len(x)
    lo, hi = np.zeros(n), np.ones(n)
    backs, resumes, iterations = 0, 0, 0
    steps: list[dict] = []
    while True:
        good = fam.evaluate(x)
        if not good.ok:
            return {
                "x": x,
                "success": False,
                "code": -1,
                "iterations": iterations,
                "steps": steps,
                "failed": good.message,
                "message": "evaluation failed",
            }
        assert fam.f_ref is not None  # set by the first evaluation
        t0 = good.worst_hz / fam.f_ref
        try:
            out = _solve(fam, prob, x, t0, lo, hi)
        except _EvaluationFailed as exc:
            backs += 1
            last = fam._good
            assert last is not None
            good = last
            steps.append({"failed_at": fam.params(exc.x), "message": str(exc)})
            if backs > _STEP_BACKS:
                return {
                    "x": good.x,
                    "success": False,
                    "code": -1,
                    "iterations": iterations,
                    "steps": steps,
                    "failed": f"{backs} evaluations failed (last: {exc}); stopped at the last good design",
                    "message": "evaluations failed",
                }
            r = 0.5 * max(float(np.abs(exc.x - good.x).max()), 1e-6)
            x, lo, hi = good.x.copy(), np.maximum(good.x - r, 0.0), np.minimum(good.x + r, 1.0)
            continue
        iterations += out["iterations"]
        x = np.clip(out["z"][:-1], 0.0, 1.0)
        edge = np.any((x <= lo + _BOUND_TOL) & (lo > 0)) or np.any((x >= hi - _BOUND_TOL) & (hi < 1))
        if edge and resumes < _STEP_BACKS:
            resumes += 1
            lo, hi = np.zeros(n), np.ones(n)
            continue
        out.update(x=x, iterations=iterations, steps=steps, failed=None)
        return out


def _refine(fam: FamilyEvaluator, verified: dict, low: bool, stressed: bool, symmetric: bool) -> tuple[list[str], str]:
    """What the verification found that the search did not see, added to the search; or why nothing can be."""
    added: list[str] = []
    why: list[str] = []
    tol = 1e-9 * max(fam.stroke, 1.0)

    def sampled(s_: float) -> bool:
        return bool(np.any(np.abs(fam.samples - (abs(s_) if symmetric else s_)) <= tol))

    def add(s_: float) -> None:
        new = [abs(s_)] if symmetric else [s_, -s_]
        fam.samples = np.unique(np.concatenate([fam.samples, new]))

    if low:
        s_ = verified["stroke_at_worst"]
        if not sampled(s_):
            add(s_)
            added.append(f"stroke {s_:.6g} (verified minimum)")
        else:
            why.append(
                f"the verified minimum ({verified['worst_hz']:.6g} Hz) lies at the sampled stroke {s_:.6g}: "
                "the searched modes miss it (raise 'modes')"
            )
    if stressed:
        s_, m = verified["stroke_at_max_stress"], verified["member_at_max_stress"]
        if not sampled(s_):
            add(s_)
            added.append(f"stroke {s_:.6g} (verified stress peak)")
        else:
            why.append(
                f"the stress limit is exceeded at the sampled stroke {s_:.6g} in {m}, whose constraints the "
                "solver had: it stopped at an infeasible design"
            )
    if added:
        fam._last = fam._good = None
    return added, "; ".join(why)


def _provenance(prob: Problem, one_start: bool = False) -> dict:
    """Where a result comes from: flexopt's version, the problem's SHA-256 (canonical JSON; with ``one_start``,
    a case's, without ``starts``, as :func:`cases` gives it) and the solver."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        ver = version("flexopt")
    except PackageNotFoundError:  # pragma: no cover - running from a source tree without installing
        ver = "0+unknown"
    blob = json.dumps(
        prob.model_dump(mode="json", exclude={"starts"} if one_start else None), sort_keys=True, separators=(",", ":")
    )
    settings = {
        "method": prob.solver,
        "max_iterations": prob.max_iterations,
        "tolerance": prob.tolerance,
        "kkt_tolerance": prob.kkt_tolerance,
        "refine_rounds": prob.refine_rounds,
        "stress_rows": "every segment end at every sample",
        "step_backs": _STEP_BACKS,
        "starts": "template defaults, then a scrambled Halton sequence seeded by (seed, family)",
    }
    if prob.solver == "slsqp":
        settings["ftol"] = prob.tolerance * 1e-2
    else:
        settings.update(_trust_constr_options(prob), hessian="BFGS")
    return {"flexopt": ver, "problem_sha256": hashlib.sha256(blob.encode()).hexdigest(), "solver": settings}


def warm_point(fam: FamilyEvaluator, design: dict) -> np.ndarray:
    """A design (template units) in the unit box, clipped into it; a parameter it lacks takes the value of the
    one it inherits from (``length_s2`` from ``length``, ``thickness_s1l2`` from ``thickness``: the
    ``topology-hinge`` template's per-stage and per-leaf parameters), else the template's default."""
    d = TEMPLATES[fam.fam.template][1]
    vals = []
    for k in fam.names:
        chain = [k, re.sub(r"l\d+$", "", k), k.split("_s")[0]]  # thickness_s2l1 -> thickness_s2 -> thickness
        v = next((design[c] for c in chain if c in design), None)
        if v is None:
            v = next(d[c] for c in chain if c in d and (d[c] != 0 or c == chain[-1]))
        vals.append(float(v))
    return np.clip((np.array(vals) - fam.lo) / (fam.hi - fam.lo), 0, 1)


def run_case(case: dict) -> dict:
    """One start of one family: search, verify, refine (the unit of work of a batch; JSON in and out).

    ``case``: ``{"problem", "family", "start"}`` (:func:`cases`) and optionally ``"x0"``, a design (template
    units) the start begins at instead of its own point (a warm start, :func:`warm_point`; a failing one steps
    toward the template's design like a failing Halton start), ``"stop_if_stationary": true`` to return a warm
    start that already meets the first-order conditions (KKT residual within ``kkt_tolerance``, every
    constraint within ``tolerance``) with status ``"stationary"``, unsearched and unverified (a topology
    search's designed-crossing variant started at its midpoint variant's optimum), and ``"mesh_estimate":
    false`` to leave the verification's mesh estimate out (a topology search estimates it on its refined mesh
    instead)."""
    t0 = time.perf_counter()
    prob = Problem.model_validate(case["problem"])
    fi, si = int(case["family"]), int(case["start"])
    fam_spec = prob.families[fi]
    fam = FamilyEvaluator(prob, fam_spec)
    warm = case.get("x0")
    x0 = warm_point(fam, warm) if warm else start_point(fam, prob, fi, si)
    estimate = bool(case.get("mesh_estimate", True))
    screening = None
    if prob.screen:
        x0, screening = _screen(fam, prob, fi, si, x0)
    initial = (
        _preview(fam, x0, prob.verify_points, prob.tolerance)
        if prob.preview
        else {"points": 0, "status": "skipped", "failures": [], "stroke": [], "parasitic_hz": []}
    )
    x = x0.copy()
    history: list[dict] = []
    status, message = "optimal", ""
    verified: dict = {}
    searched = fam.evaluate(x)
    moved = None
    if not searched.ok and (si > 0 or warm):  # step back toward the template's design along the segment
        xd = fam.default_x()
        for frac in _START_STEPS:
            ev = fam.evaluate(x0 + frac * (xd - x0))
            if ev.ok:
                moved = {
                    "fraction_toward_defaults": frac,
                    "reason": searched.message,
                    "design": {k: v for k, v in fam.params(ev.x).items() if k in fam.names},
                }
                x, searched = ev.x.copy(), ev
                break
    symmetric = fam.reduce_symmetric(searched)
    run: dict | None = None
    low = False
    stationary = None
    if searched.ok and warm and case.get("stop_if_stationary"):
        ev0 = fam.evaluate(x)  # on the samples left by the mirror symmetry
        stationary = _optimality(fam, ev0, prob.tolerance) if ev0.ok else None
        if stationary and not (
            stationary["kkt_residual"] <= prob.kkt_tolerance and stationary["max_violation"] <= prob.tolerance
        ):
            stationary = None
    if not searched.ok:
        status, message = "failed", f"the start design fails: {searched.message}"
    elif stationary is not None:
        status = "stationary"
        message = (
            f"the warm start meets the first-order conditions (KKT residual {stationary['kkt_residual']:.3g} "
            f"within kkt_tolerance {prob.kkt_tolerance:g}, feasible): not searched, not verified"
        )
        searched = fam.evaluate(x)
    else:
        for rnd in range(prob.refine_rounds + 1):
            ev0 = fam.evaluate(x)
            if not ev0.ok:
                status, message = "failed", ev0.message
                break
            fam.select(ev0)
            run = _search(fam, prob, x)
            x = run["x"]
            searched = fam.evaluate(x)
            history.append(
                {
                    "round": rnd,
                    "samples": fam.samples.tolist(),
                    "solver_status": run["code"],
                    "solver_message": run["message"],
                    "iterations": run["iterations"],
                    "constraints": 0 if fam.keep is None else int(len(fam.keep)),
                    "step_backs": run["steps"],
                    "searched_worst_hz": searched.worst_hz,
                }
            )
            if run["failed"] or not searched.ok:
                status, message = "failed", run["failed"] or searched.message
                break
            verified = verify(fam, x, prob.verify_points, estimate)
            if verified["status"] != "complete":
                status, message = "failed", "; ".join(verified["failures"])
                break
            low = verified["worst_hz"] < searched.worst_hz * (1 - prob.tolerance)
            stressed = verified["stress_ratio"] > 1 + prob.tolerance
            if not (low or stressed):
                break
            if rnd == prob.refine_rounds:
                message = f"the verification still differs from the search after {prob.refine_rounds} refinement rounds"
                break
            added, why = _refine(fam, verified, low, stressed, symmetric)
            history[-1]["added"] = added
            if not added:
                message = why
                break
    opt = _optimality(fam, searched, prob.tolerance) if searched.ok else None
    if status == "optimal":
        assert run is not None and opt is not None
        if verified["stress_ratio"] > 1 + prob.tolerance:
            status = "infeasible"
            message = message or "the verified stress exceeds allowable / safety_factor"
        elif opt["max_violation"] > prob.tolerance:
            status, message = "infeasible", f"a constraint is violated by {opt['max_violation']:.3g} (scaled)"
        elif low:
            status = "unconverged"
            message = message or (
                f"the verified minimum ({verified['worst_hz']:.5g} Hz) is below the searched one "
                f"({searched.worst_hz:.5g} Hz)"
            )
        elif not run["success"]:
            status, message = "unconverged", f"the solver stopped: {run['message']}"
        elif opt["kkt_residual"] > prob.kkt_tolerance:
            status, message = (
                "unconverged",
                (f"KKT residual {opt['kkt_residual']:.3g} above kkt_tolerance {prob.kkt_tolerance:g}"),
            )
    params = fam.params(x)
    notes = _case_warnings(fam, si, status, message, verified, opt)
    if moved is not None:
        notes.append(
            ResultWarning(
                "notice",
                f"{fam_spec.template} start {si}: the start design fails "
                f"({moved['reason']}); the search started {moved['fraction_toward_defaults']:g} of "
                "the way toward the template's design instead",
            )
        )
    return {
        "family": fam_spec.template,
        "family_index": fi,
        "start": si,
        "status": status,
        "message": message,
        "design": {k: params[k] for k in fam.names},
        "bounds": {k: [float(lo), float(hi)] for k, lo, hi in zip(fam.names, fam.lo, fam.hi)},
        "x0": {k: float(fam.lo[i] + x0[i] * (fam.hi[i] - fam.lo[i])) for i, k in enumerate(fam.names)},
        "searched": {
            "worst_hz": searched.worst_hz,
            "stroke_at_worst": searched.stroke_at_worst,
            "samples": len(fam.samples),
            "mirror_symmetric": symmetric,
            "max_stress": searched.max_stress,
        },
        "solver": {
            "method": prob.solver,
            "status": run["code"] if run else None,
            "message": run["message"] if run else None,
            "converged": bool(run and run["success"]),
        },
        "optimality": opt,
        "moving_mass": fam.moving_mass(),
        "start_moved": moved,
        "verified": verified,
        "initial": initial,
        "history": history,
        "screening": screening,
        "evaluations": fam.evaluations,
        "seconds": time.perf_counter() - t0,
        "warnings": [w.to_dict() for w in notes],
        "provenance": _provenance(prob, one_start=True),
    }


def _case_warnings(
    fam: FamilyEvaluator, start: int, status: str, message: str, verified: dict, opt: dict | None
) -> list[ResultWarning]:
    out: list[ResultWarning] = []
    name = fam.fam.template
    for w in verified.get("warnings", []):  # the model's own checks (validity, mesh, units); stress is below
        if w["kind"] != "stress":
            rng = w.get("stroke_range")
            out.append(
                ResultWarning(
                    w["kind"],
                    f"{name} start {start}: {w['message']}",
                    w.get("element"),
                    None if rng is None else (rng[0], rng[1]),
                    w.get("value"),
                )
            )
    if verified.get("stress_ratio", 0.0) > 1 + fam.prob.tolerance:
        out.append(
            ResultWarning(
                "stress",
                f"{name} start {start}: the verified peak stress is "
                f"{verified['stress_ratio']:.3f} times allowable / safety_factor in "
                f"{verified['member_at_max_stress']} at stroke {verified['stroke_at_max_stress']:.4g}; "
                "this design is not an optimum",
                element=verified["member_at_max_stress"],
                value=verified["stress_ratio"],
            )
        )
    if status in ("unconverged", "failed"):
        out.append(
            ResultWarning(
                "notice",
                f"{name} start {start}: {status} ({message}); it is not ranked",
                value=None if opt is None else opt["kkt_residual"],
            )
        )
    if opt is not None and opt["active_bounds"]:
        origins = fam.fam.origins
        plain = {k: side for k, side in opt["active_bounds"].items() if k not in origins}
        told = {k: side for k, side in opt["active_bounds"].items() if k in origins}
        if plain:
            which = ", ".join(f"{k} ({side})" for k, side in plain.items())
            out.append(
                ResultWarning(
                    "notice",
                    f"{name} start {start}: stopped by the design bounds {which}: the "
                    "design is the bounds' result, not the family's; widen them (or bound the "
                    "family by an envelope) to compare families fairly",
                )
            )
        for k, side in told.items():  # the bound's origin says whether widening it is the user's choice
            why = origins[k][0 if side == "lower" else 1]
            out.append(
                ResultWarning(
                    "notice",
                    f"{name} start {start}: {k} is on its {side} bound, which is {why}: the optimum is limited by it",
                    value=fam.params(np.zeros(len(fam.names)) if side == "lower" else np.ones(len(fam.names)))[k],
                )
            )
    if opt is not None and "validity" in opt.get("active_kinds", []):
        act = [a for a in opt["active"] if " / (" in a]
        out.append(
            ResultWarning(
                "notice",
                f"{name} start {start}: the validity constraint is active "
                f"({'; '.join(act)}): the optimum is limited by it",
            )
        )
    return out


def cases(problem: Problem | dict) -> list[dict]:
    """The batch's units of work: one per (family, start). A case's problem leaves out ``starts`` (a case is
    one start, and start k does not depend on how many there are: :func:`start_point`), so that a case's id
    (:func:`optim.batch.case_id`) is the same whatever the number of starts, and adding starts to a stored
    run reuses every finished case."""
    prob = Problem.model_validate(problem)
    pj = prob.model_dump(mode="json")
    del pj["starts"]
    return [{"problem": pj, "family": i, "start": k} for i in range(len(prob.families)) for k in range(prob.starts)]


def optimal_starts(starts: list[dict]) -> list[dict]:
    """The starts whose optimum is *optimal*: converged, verified (a worst case) and feasible."""
    return [r for r in starts if r.get("status") == "optimal" and (r.get("verified") or {}).get("worst_hz") is not None]


def best_start(starts: list[dict]) -> dict | None:
    """The optimal start (:func:`optimal_starts`) with the highest verified worst case, or None."""
    ok = optimal_starts(starts)
    return max(ok, key=lambda r: r["verified"]["worst_hz"]) if ok else None


def no_optimum_reason(starts: list[dict]) -> str:
    """Why no start is optimal: each start's status and message, in one line."""
    why = "; ".join(
        f"start {r.get('start')}: {r.get('status', 'failed')} ({r.get('message') or r.get('error')})" for r in starts
    )
    return f"no start reached a converged, verified, feasible optimum: {why}"


def summarise(prob: Problem, results: list[dict]) -> dict:
    """Best *optimal* start per family (converged, verified, feasible) and the ranking of families by verified
    worst-case frequency; every other start is listed with its status and message."""
    fams: list[dict[str, Any]] = []
    notes: list[dict] = []
    for i, fam in enumerate(prob.families):
        rs = [r for r in results if r.get("family_index") == i]
        ok = optimal_starts(rs)
        best = best_start(ok)
        table = [
            {
                "start": r.get("start"),
                "status": r.get("status", "failed"),
                "message": r.get("message") or r.get("error"),
                "worst_hz": (r.get("verified") or {}).get("worst_hz"),
                "stress_ratio": (r.get("verified") or {}).get("stress_ratio"),
                "kkt_residual": (r.get("optimality") or {}).get("kkt_residual"),
                "active_bounds": (r.get("optimality") or {}).get("active_bounds"),
                "seconds": r.get("seconds"),
            }
            for r in rs
        ]
        worst = [r["verified"]["worst_hz"] for r in ok]
        fams.append(
            {
                "template": fam.template,
                "best": best,
                "starts": len(rs),
                "optimal_starts": len(ok),
                "spread": (max(worst) - min(worst)) / max(worst) if worst else None,
                "moving_mass": next((r.get("moving_mass") for r in rs if "moving_mass" in r), None),
                "start_table": table,
                "failed": [
                    {"start": t["start"], "status": t["status"], "message": t["message"]}
                    for t, r in zip(table, rs)
                    if r not in ok
                ],
            }
        )
        if best is not None:
            notes += list(best.get("warnings", []))
        elif rs:
            notes.append(
                ResultWarning(
                    "notice",
                    f"{fam.template}: no start reached a converged, verified, "
                    "feasible optimum; the family is not ranked",
                ).to_dict()
            )
    masses = {f["template"]: f["moving_mass"] for f in fams if f["moving_mass"] is not None}
    if len(set(masses.values())) > 1:
        notes.append(
            ResultWarning(
                "notice",
                f"the families move different masses ({masses} kg): they are not "
                "compared with the same payload; set the problem's body_mass",
            ).to_dict()
        )
    if prob.envelope is None and len(prob.families) > 1:
        notes.append(
            ResultWarning(
                "notice",
                "no envelope: each family is bounded only by its own design box, "
                "so the ranking compares boxes as much as topologies; set 'envelope'",
            ).to_dict()
        )
    ranking = sorted((f for f in fams if f["best"] is not None), key=lambda f: -f["best"]["verified"]["worst_hz"])
    return {
        "problem": prob.model_dump(mode="json"),
        "families": fams,
        "ranking": [
            {
                "template": f["template"],
                "worst_hz": f["best"]["verified"]["worst_hz"],
                "zero_stroke_hz": f["best"]["verified"]["zero_stroke_hz"],
                "ratio": f["best"]["verified"]["ratio"],
                "design": f["best"]["design"],
                "status": f["best"]["status"],
                "kkt_residual": f["best"]["optimality"]["kkt_residual"],
                "active_bounds": f["best"]["optimality"]["active_bounds"],
                "active": f["best"]["optimality"]["active"],
            }
            for f in ranking
        ],
        "warnings": notes,
        "provenance": _provenance(prob),
    }


@limited()  # one BLAS thread while it computes (model.threads)
def optimise(
    problem: Problem | dict,
    *,
    executor: Any = None,
    workers: int | None = None,
    store: Any = None,
    progress: Any = None,
    cancel: Any = None,
    no_worker_timeout: float | None = None,
) -> dict:
    """Optimise every family of ``problem`` (multi-start), in parallel, resumable through ``store``.

    ``executor``: any ``concurrent.futures.Executor`` (default: a local process pool of ``workers``; a
    Dask cluster through :func:`optim.batch.dask_executor`, whose lack of workers for longer than
    ``no_worker_timeout`` seconds ends the run, see :func:`optim.batch.run_cases`). Returns
    :func:`summarise`'s dictionary.
    """
    from .batch import run_cases

    prob = Problem.model_validate(problem)
    for fam in prob.families:  # fail fast, in the caller, on a bad family
        FamilyEvaluator(prob, fam)
    kw: dict[str, Any] = {} if no_worker_timeout is None else {"no_worker_timeout": no_worker_timeout}
    results = run_cases(
        cases(prob),
        "flexopt.optim.search:run_case",
        executor=executor,
        workers=workers,
        store=store,
        progress=progress,
        cancel=cancel,
        **kw,
    )
    return summarise(prob, results)
