"""The error estimate of the expansions about stroke 0 (fd1, fd2, manifold, reduced) and the one rule that
limits every such curve to the stroke where its estimate meets the tolerance.

The Taylor and manifold methods are expansions about stroke 0: exact there, and wrong by any amount far from
it (the cross-spring pivot's first parasitic frequency falls from 426 to 39 Hz over 45 deg; the manifold
gives -130,145 Hz there). Their own terms do not bound their error (the fd2 - fd1 difference, the last
retained term of the Taylor series, reads 8 deg for fd2 on the leaf, which holds to 34 deg, and 34 deg for
fd1 on the double cross hinge, which fails at 30 deg). So the estimate rests on **exact check points**: per
side of stroke 0 the exact curve (model.analysis, the same solves as the exact method) at
``CHECKS`` strokes ``s_max / 2^k`` (k = 0 .. CHECKS - 1), and the method's relative error of the first
parasitic frequency there, ``e_k``. Between two checks ``c_k+1 < |s| <= c_k``

    est(s) = max(e_k+1, e_k |s| / c_k, e_k-1 |s| / c_k-1),

the larger of the error at the check below and the errors of the two checks beyond scaled linearly
(below the smallest check, the last two terms). The expansions' errors grow at least quadratically from 0
while they hold, so the linear scaling overstates them; the check two octaves out is there because they do
not hold monotonically where they break down: the three-fold hinge's manifold error is 1.7 % at -5 deg but
1.4 % at the check -5.6 deg (it changes sign on the way to -209 Hz at -7 deg), which the nearest check
alone scales to 0.97 % at -4 deg (true 1.2 %); the check at -11.25 deg (negative) rejects that octave. A point where the method gives a
negative, zero or non-finite frequency, or where the exact check curve stops, has an infinite estimate.
Measured against the exact curve at every point on the six templates (tests/test_methods_accuracy.py,
bench/bench_methods.py): see the README's methods table.

The rule (:func:`limit`, applied by :func:`model.methods.auto.frequency_curve` to every one of these methods):
on each side of stroke 0 the curve keeps the points from 0 outwards up to the first whose estimate exceeds
the tolerance; the rest are left out and the curve is ``truncated`` with one ``Failure`` (reason
``accuracy``) per side naming the stroke where the estimate fails, the estimate there, and the methods that
hold further out (``hermite``, ``exact``). ``solver.estimated_error`` is the largest estimate of the points
kept.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..results import Failure, FrequencyCurve

__all__ = ["CHECKS", "check_strokes", "estimates", "limit"]

#: Exact check strokes per side of stroke 0: ``s_max / 2^k``, k = 0 .. CHECKS - 1 (45, 22.5, ... 1.4 deg on
#: the templates' +-45 deg); the curve's points closer to 0 than the last scale linearly from it.
CHECKS = 6


def check_strokes(values: np.ndarray) -> np.ndarray:
    """The exact check strokes (stroke unit, ascending) for the requested ``values``: per side with a
    non-zero stroke, ``s_max / 2^k`` for k = 0 .. ``CHECKS`` - 1, none closer to 0 than half the side's
    smallest non-zero requested stroke."""
    values = np.asarray(values, dtype=float)
    out: list[float] = []
    for side in (values[values > 0], values[values < 0]):
        if not len(side):
            continue
        far, near = side[np.argmax(np.abs(side))], float(np.abs(side).min())
        for k in range(CHECKS):
            c = far / 2.0**k
            out.append(float(c))
            if abs(c) <= near:
                break
    return np.array(sorted(set(out)))


def estimates(
    stroke: np.ndarray, f_method: np.ndarray, checks: np.ndarray, f_checks: np.ndarray, f_exact: np.ndarray
) -> np.ndarray:
    """The estimated relative error (p,) of the first parasitic frequencies ``f_method`` at ``stroke`` (see the
    module docstring), from the method's ``f_checks`` and the exact ``f_exact`` at the ``checks`` (NaN where
    the exact curve has no point)."""
    stroke = np.asarray(stroke, dtype=float)
    e_all = np.abs(f_checks / f_exact - 1.0)
    bad = ~(np.isfinite(f_checks) & (f_checks > 0) & np.isfinite(f_exact) & (f_exact > 0))
    e_all = np.where(bad, np.inf, e_all)
    est = np.zeros(len(stroke))
    for sign in (1.0, -1.0):
        sel = np.flatnonzero(np.sign(stroke) == sign)
        on = np.sign(checks) == sign
        if not len(sel):
            continue
        if not on.any():
            est[sel] = np.inf
            continue
        order = np.argsort(-np.abs(checks[on]))  # descending |stroke|
        c, e = np.abs(checks[on])[order], e_all[on][order]
        est[sel] = [_between(abs(s), c, e) for s in stroke[sel]]
    ok = np.isfinite(f_method) & (f_method > 0)
    return np.where(ok, est, np.inf)


def _between(s: float, c: np.ndarray, e: np.ndarray) -> float:
    """The estimate at ``|s|`` from the checks ``c`` (descending) and their errors ``e`` (module docstring)."""
    if s > c[0] * (1 + 1e-12):
        return float("inf")
    k = int(np.searchsorted(-c, -s, side="right")) - 1  # c[k] >= s > c[k + 1] (k = len(c) - 1: below them all)
    out = float(e[k + 1]) if k + 1 < len(c) else 0.0
    for j in (k, k - 1):  # the two checks at or beyond s, scaled linearly
        if j >= 0:
            out = max(out, float(e[j]) * s / c[j])
    return out


def limit(curve: FrequencyCurve, est: np.ndarray, tolerance: float) -> FrequencyCurve:
    """The one rule for the expansions about stroke 0: ``curve`` up to, per side, the first point from 0
    outwards whose estimate ``est`` exceeds ``tolerance``; the points beyond it left out, each side cut
    named in a ``Failure`` (reason ``accuracy``), ``solver.estimated_error`` and ``solver.tolerance`` set."""
    s = np.asarray(curve.stroke, dtype=float)
    keep = np.ones(len(s), dtype=bool)
    failures = list(curve.failures)
    unit = curve.stroke_unit
    for sign in (1.0, -1.0):
        idx = np.flatnonzero(np.sign(s) == sign)
        idx = idx[np.argsort(np.abs(s[idx]))]
        over = np.flatnonzero(~(est[idx] <= tolerance))
        if not len(over):
            continue
        first = idx[over[0]]
        keep[idx[over[0] :]] = False
        last = float(s[idx[over[0] - 1]]) if over[0] > 0 else 0.0
        e = est[first]
        why = (
            "a negative or non-finite frequency"
            if not np.isfinite(curve.parasitic_hz[first]) or curve.parasitic_hz[first] <= 0
            else f"an estimated error of {e:.3g}"
            if np.isfinite(e)
            else "no bound on its error (at a check stroke beyond it the method's frequency is negative or "
            "not finite, or the exact curve has no point)"
        )
        failures.append(
            Failure(
                reason="accuracy",
                stroke=float(s[first]),
                last_converged=last,
                message=f"method '{curve.method}' is an expansion about stroke 0 and holds to the tolerance "
                f"{tolerance:g} only up to {last:g} {unit}: at {float(s[first]):g} {unit} it has {why}; "
                f"the points from there on are left out (use method 'hermite' or 'exact' for them)",
            )
        )
    kept = est[keep]
    solver = {**curve.solver, "estimated_error": float(kept.max()) if len(kept) else 0.0, "tolerance": tolerance}
    if keep.all():
        return replace(curve, solver=solver)
    return replace(
        curve,
        stroke=s[keep],
        modes_hz=curve.modes_hz[keep],
        mode_labels=curve.mode_labels[keep],
        parasitic_hz=curve.parasitic_hz[keep],
        drive_reaction=curve.drive_reaction[keep],
        max_von_mises={k: v[keep] for k, v in curve.max_von_mises.items()},
        status="truncated",
        failures=tuple(failures),
        solver=solver,
    )
