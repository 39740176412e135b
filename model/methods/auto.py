"""One registry of frequency-curve methods, ``frequency_curve(obj, method)`` and ``auto``.

Methods: ``exact`` (continuation + eigen at every point, model.analysis), ``fd1``/``fd2`` (Taylor,
:mod:`.taylor`), ``manifold``/``reduced`` (:mod:`.manifold`), ``hermite`` (exact samples and exact
stroke derivatives joined by cubic Hermite interpolation, :mod:`.hermite`) and ``auto``.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from ..._methods import METHODS  # the one list of method names (imports nothing)
from ..analysis import MeshAnalysis
from ..checks import annotate_curve
from ..errors import FlexoptError
from ..results import FrequencyCurve
from ..scene import Scene
from ..threads import limited
from .accuracy import check_strokes, estimates, limit
from .common import _curve_from
from .hermite import hermite_frequency_curve
from .manifold import eigen_curve
from .taylor import _prepare, taylor_curve

__all__ = ["METHODS", "AUTO_ORDER", "frequency_curve", "estimate_error", "curve_with_method", "expansion_curve"]

#: Cheapest first: the fast methods :func:`estimate_error` rates.
AUTO_ORDER = ("fd1", "fd2", "reduced", "manifold", "exact")  # candidates of estimate_error (auto: _auto)


@limited()  # one BLAS thread while it computes (model.threads)
def frequency_curve(
    obj: Scene | MeshAnalysis, method: str = "auto", tolerance: float = 0.01, stroke: np.ndarray | None = None
) -> FrequencyCurve:
    """Stroke-dependent frequencies by ``method`` (one of :data:`METHODS`).

    ``exact``: continuation + eigen at every point. ``fd1``: eq. 10 (first order). ``fd2``: second-order
    Taylor in eta with degenerate perturbation. ``manifold``: one-shot configuration on the quadratic
    manifold, full eigen solve, no Newton. ``reduced``: the same configuration, eigenproblem in the basis
    of the first modes, their modal derivatives and the driving mode (Wu and Tiso 2015). ``hermite``:
    exact samples with exact stroke derivatives, cubic Hermite along tracked branches, samples added until
    the estimated error of the first parasitic frequency meets ``tolerance`` (:mod:`.hermite`). ``auto``:
    ``hermite`` when it meets ``tolerance`` within a sample budget, otherwise ``exact`` (:func:`_auto`).
    The fast methods' estimator for the Taylor and manifold methods is :func:`estimate_error`.
    """
    an = obj if isinstance(obj, MeshAnalysis) else MeshAnalysis(obj)
    curve = _frequency_curve(an, method, tolerance, stroke)
    if method == "exact":  # MeshAnalysis.frequency_curve has attached the checks and the provenance already
        return curve
    # every other method's curve leaves with the model's checks (warnings) and its provenance (model.checks)
    return annotate_curve(curve, an.scene, an.options)


def _frequency_curve(an: MeshAnalysis, method: str, tolerance: float, stroke: np.ndarray | None) -> FrequencyCurve:
    if method not in METHODS:
        raise FlexoptError(f"unknown method '{method}': choose one of {', '.join(METHODS)}")
    if not (tolerance > 0):
        raise FlexoptError(f"tolerance must be positive (a relative error, e.g. 0.01), got {tolerance}")
    spec = an.stroke
    values = np.asarray(spec.values() if stroke is None else stroke, dtype=float)
    if method == "exact":
        return an.frequency_curve(values)
    if an.system.loads is not None:
        # the fast methods expand about a stress-free reference at stroke 0 (model.methods.taylor, hermite's
        # first step); under loads or gravity it is not stress-free, so only the exact curve applies
        if method == "auto":
            curve = an.frequency_curve(values)
            return replace(
                curve,
                solver={
                    **curve.solver,
                    "auto_method": "exact",
                    "auto_estimate": 0.0,
                    "auto_tolerance": tolerance,
                    "auto_rejected": "fast methods (the scene has loads or gravity)",
                },
            )
        raise FlexoptError(
            f"method '{method}' expands about a stress-free reference, but scene '{an.scene.name}' "
            "has loads or gravity: use method 'exact' or 'auto'"
        )
    if method == "hermite":
        return hermite_frequency_curve(an, values, tolerance)[0]
    if method == "auto":
        return _auto(an, values, tolerance)
    if spec.drive == "free":
        # the Taylor and manifold methods analyse modes with the drive locked (model.methods.taylor): on a
        # scene whose eigen analysis keeps the drive free they would answer a different question
        raise FlexoptError(
            f"method '{method}' computes modes with the drive locked, but scene '{an.scene.name}' "
            "asks for the drive free in its eigen analysis (stroke.drive: free): use method "
            "'exact', 'hermite' or 'auto', or set stroke.drive to 'locked'"
        )
    curve, est = expansion_curve(an, method, values)
    return limit(curve, est, tolerance)


def expansion_curve(an: MeshAnalysis, method: str, values: np.ndarray) -> tuple[FrequencyCurve, np.ndarray]:
    """The curve of an expansion about stroke 0 (fd1, fd2, manifold, reduced) at every requested stroke, and
    its estimated relative error per point (:mod:`.accuracy`: from exact check points, cached on the
    analysis's expansion)."""
    t0 = time.perf_counter()
    prep = _prepare(an)
    checks = check_strokes(values)
    f_exact, check_seconds = _exact_checks(an, prep, checks)
    both = np.concatenate([values, checks])
    eta = np.asarray(an.stroke.to_internal(both), dtype=float)
    # a structure with fewer locked DOFs than requested modes has only that many (wire guides: 5 of 6)
    n_rep = min(an.scene.modes, len(an.system.free) - an.system.n_con)
    extra: dict = {"build_seconds": prep.md.build_seconds, "exact_checks": len(checks), "check_seconds": check_seconds}
    if method in ("fd1", "fd2"):
        hz, labels, par = taylor_curve(prep, eta, 1 if method == "fd1" else 2, n_rep)
    else:
        hz, labels, par, dev = eigen_curve(prep, eta, method == "reduced", n_rep)
        extra["max_drive_deviation"] = dev
    p = len(values)
    est = estimates(values, par[:p], checks, par[p:], f_exact)
    curve = _curve_from(an, method, values, hz[:p], labels[:p], par[:p], time.perf_counter() - t0, extra)
    return curve, est


def _exact_checks(an: MeshAnalysis, prep, checks: np.ndarray) -> tuple[np.ndarray, float]:
    """The exact first parasitic frequency at the ``checks`` (NaN where the exact curve stops before them)
    and the seconds it took (0 when cached on ``prep``)."""
    key = checks.tobytes()
    if key not in prep.checks:
        t0 = time.perf_counter()
        f = np.full(len(checks), np.nan)
        if len(checks):
            ref = an.exact_curve(checks)[0]
            for i, c in enumerate(checks):
                hit = np.flatnonzero(np.isclose(ref.stroke, c, rtol=1e-9, atol=1e-12 * np.abs(checks).max()))
                if len(hit):
                    f[i] = ref.parasitic_hz[hit[0]]
        prep.checks[key] = (f, time.perf_counter() - t0)
        return prep.checks[key]
    return prep.checks[key][0], 0.0


#: Fewest requested stroke points on one side of 0 for which ``auto`` tries ``hermite`` (it solves four exact
#: points per side, samples or probes, before it can estimate anything; below this the exact curve is as cheap).
AUTO_MIN_POINTS = 12
#: Below this relative tolerance ``auto`` computes the exact curve directly: hermite's samples no longer pay
#: (measured on the hinge templates at 1e-5: most requested points end up filled exactly and the samples
#: come on top, 1.1 to 1.3 times the exact curve; at 1e-4 0.22 to 0.92 of it), and its error estimate is
#: validated down to 1e-4 only (tests/test_hermite.py).
AUTO_MIN_TOLERANCE = 1e-4


def _auto(an: MeshAnalysis, values: np.ndarray, tolerance: float) -> FrequencyCurve:
    """``auto``: on curves with at least ``AUTO_MIN_POINTS`` points per side and a tolerance of at least
    ``AUTO_MIN_TOLERANCE``, ``hermite`` within a sample budget; on shorter curves (an optimiser's screening
    grid) the cheapest Taylor or manifold method whose :func:`estimate_error` meets ``tolerance``; otherwise
    (or when neither qualifies) the exact curve.

    Budget: a third of the requested points per side as samples. When the samples stop with intervals whose
    estimate misses ``tolerance``, the requested points inside those intervals are computed exactly
    (walked from the interval's left sample, as the exact method walks) and the rest is interpolated, so
    every interpolated interval's estimate meets the tolerance and the rest is exact
    (``solver.exact_points``; ``auto_method`` ``hermite+exact``). Cost: the samples plus those exact points; a sample costs one to three exact points
    (its continuation step, one eigen solve and the slopes). Measured: a fifth to a third of the exact
    curve at 1 % on the templates, 0.2-0.7 of it at 1e-4 (no points filled since the midpoint probes of
    :mod:`.hermite`; before them the pivot needed ten and cost 0.96-1.05 of exact); below 1e-4, where
    the hinges' samples stopped paying, the exact curve directly; the exact curve alone when a sample's
    equilibrium cannot be computed (``hermite`` falls back and says so). Short curves: as below; nothing
    more for a drive-free scene, where the locked-drive methods do not apply. The curve's ``solver`` says
    which method ran (``auto_method``), its estimated error (``auto_estimate``; 0 for exact) and the tolerance;
    ``solver.seconds`` covers everything auto did.
    """
    t0 = time.perf_counter()
    internal = np.asarray(an.stroke.to_internal(values), dtype=float)
    per_side = max(int(np.sum(internal > 0)), int(np.sum(internal < 0)))
    tried: dict = {}
    if per_side >= AUTO_MIN_POINTS and tolerance < AUTO_MIN_TOLERANCE:
        tried = {
            "auto_rejected": f"hermite (tolerance {tolerance:g} below {AUTO_MIN_TOLERANCE:g}: the exact curve "
            "is cheaper there)"
        }
    elif per_side >= AUTO_MIN_POINTS:
        curve, tried = _auto_hermite(an, values, tolerance, per_side, t0)
        if curve is not None:
            return curve
    elif an.stroke.drive == "locked" and not an.system.n_con:
        curve, tried = _auto_expansion(an, values, tolerance, t0)
        if curve is not None:
            return curve
    return _stamped(an.frequency_curve(values), t0, "exact", 0.0, tolerance, tried)


def _stamped(
    curve: FrequencyCurve, t0: float, method: str, estimate: float, tolerance: float, tried: dict | None = None
) -> FrequencyCurve:
    """``curve`` with auto's entries in its ``solver``: the seconds since ``t0``, the method that ran, its
    estimated error, the tolerance and what was tried and rejected before it."""
    return replace(
        curve,
        solver={
            **curve.solver,
            "seconds": time.perf_counter() - t0,
            "auto_method": method,
            "auto_estimate": estimate,
            "auto_tolerance": tolerance,
            **(tried or {}),
        },
    )


def _auto_hermite(
    an: MeshAnalysis, values: np.ndarray, tolerance: float, per_side: int, t0: float
) -> tuple[FrequencyCurve | None, dict]:
    """:func:`_auto`'s long curves: ``hermite`` within its sample budget (a third of the points per side, exact
    points filled where an interval misses ``tolerance``), or None and why it was rejected."""
    curve, extra = hermite_frequency_curve(an, values, tolerance, max_samples=max(4, per_side // 3), fill=True)
    if curve.method == "hermite" and extra["converged"] and extra["estimated_error"] <= tolerance:
        how = "hermite" + ("+exact" if extra["exact_points"] else "")
        return _stamped(curve, t0, how, extra["estimated_error"], tolerance), {}
    return None, {
        "auto_rejected": f"hermite (estimated error {extra.get('estimated_error', float('nan')):.3g}, "
        f"{extra.get('samples', 0)} samples)"
    }


def _auto_expansion(
    an: MeshAnalysis, values: np.ndarray, tolerance: float, t0: float
) -> tuple[FrequencyCurve | None, dict]:
    """:func:`_auto`'s short curves (e.g. an optimiser's screening grid): the cheapest Taylor or manifold method
    whose estimated error (:mod:`.accuracy`, from exact check points) meets ``tolerance`` at every point, or None
    and the estimates of those rejected."""
    est: dict[str, float] = {}
    for m in AUTO_ORDER[:-1]:
        try:
            cur, e = expansion_curve(an, m, values)
        except FlexoptError:
            est[m] = float("inf")
            continue
        est[m] = float(e.max()) if len(e) else 0.0
        if est[m] <= tolerance:
            return _stamped(limit(cur, e, tolerance), t0, m, est[m], tolerance), {}
    return None, {
        "auto_rejected": "fd1, fd2, reduced, manifold (estimated errors "
        + ", ".join(f"{est[m]:.3g}" for m in AUTO_ORDER[:-1])
        + ")"
    }


def estimate_error(an: MeshAnalysis, values: np.ndarray) -> dict[str, float]:
    """Estimated max relative error of the first parasitic frequency at the strokes ``values`` for each
    expansion about stroke 0 (fd1, fd2, reduced, manifold; ``exact``: 0): the largest of the per-point
    estimates of :mod:`.accuracy` (exact check points per side, shared by the methods), infinite where a
    method gives a negative or non-finite frequency, where the exact check curve stops, or where the
    method does not apply (drive free, rigid deformations)."""
    values = np.asarray(values, dtype=float)
    est = {"exact": 0.0}
    for m in AUTO_ORDER[:-1]:
        if an.stroke.drive == "free":
            est[m] = float("inf")
            continue
        try:
            e = expansion_curve(an, m, values)[1]
        except FlexoptError:
            est[m] = float("inf")
            continue
        est[m] = float(e.max()) if len(e) else 0.0
    return est


def curve_with_method(
    analysis: MeshAnalysis, method: str, tolerance: float = 0.01, stroke: np.ndarray | None = None
) -> FrequencyCurve:
    """CLI entry point: :func:`frequency_curve` on a ready :class:`MeshAnalysis` (result has ``.method`` set)."""
    return frequency_curve(analysis, method, tolerance, stroke)
