"""Discretisation error of an exact curve, and ``segments: "auto"`` meshes refined to a tolerance.

Estimate (:func:`mesh_error`)
-----------------------------
The same analysis on a coarser mesh (every beam of ``n >= 2`` segments at ``n // 2``, refinement ratio
``r = n / (n // 2)``, the smallest over the beams) at a few stroke points: the ends of the converged range
on each side and up to :data:`ESTIMATE_POINTS` - 1 of the curve's own points per side in between
(continuation needs them), so the fine mesh's values are the curve's. With ``f`` and ``f_2`` the first
parasitic frequency (the lowest mode where none is parasitic) on the fine and the coarse mesh at a point,
Richardson extrapolation at order ``p`` puts the fine mesh's error at ``|f - f_2| / (r^p - 1)``
(Richardson 1911; Roache, Verification and Validation in Computational Science and Engineering, 1998,
ch. 5); the largest relative value over the points is ``FrequencyCurve.mesh_error``.

``p = 2``, the rate measured along the stroke: the element's nonlinear terms converge at O(h^2)
(Meijaard 2022; the cross-spring pivot's parasitic frequency at 15 deg differs by 2.48, 0.59, 0.146 Hz
between 4/8/16/32 segments, ratio 4.0), while zero-stroke modes with the cubic mass converge at O(h^4)
(tests/test_mesh.py), where the estimate is conservative. A rate measured from three meshes was tried
and dropped: from 8/4/2 segments the pivot reads an order of 4.5 (coarse meshes are outside the
asymptotic range) and the estimate fell 4 times short; at ``p = 2`` the estimates of the default
templates are within 10 % of the error against 80 segments (leaf 7.7e-4 vs 7.4e-4, guide 8.3e-5 vs
8.5e-5, pivot 8.3e-3 vs 7.7e-3).

Cost: the coarse model holds half the fine model's degrees of freedom and is solved at ``2
ESTIMATE_POINTS + 1`` stroke points instead of the curve's ``points`` (continuation over the longer steps
may halve them a few times), plus compiling the coarse structure (once per :class:`model.curve.Analysis`, reused by every
curve it computes): measured on the default 91-point
templates (medians of 4 interleaved runs, 2 shared cores at load 5-7, ``python bench/bench_mesh.py``)
between -25 % and +27 % of the curve's time, i.e. below the noise of that machine. Curves computed with a ``visit`` callback (the optimiser's inner loop) skip it unless
asked.

Refinement (:func:`resolve_auto_segments`)
------------------------------------------
Beams with ``segments: "auto"`` start at :data:`AUTO_START` segments; the mesh of those beams is doubled
until the estimate of the finer of two meshes (the same Richardson estimate, at the reference and up to :data:`ESTIMATE_POINTS` stroke points per side) is within ``Scene.mesh_tolerance``,
or :data:`AUTO_MAX` segments, or the model would exceed ``MAX_DOFS``.
"""

from __future__ import annotations

import numpy as np

from .analysis import MeshAnalysis
from .modal import modes_at
from .scene import AUTO_START, Beam, Scene
from .statics import NewtonOptions, WalkFailure, solve_point, walk
from .structure import MAX_DOFS

__all__ = ["mesh_error", "coarsened", "resolve_auto_segments", "AUTO_START", "AUTO_MAX", "ESTIMATE_POINTS", "ORDER"]

#: Stroke points per side (besides the reference) at which the coarse meshes are solved.
ESTIMATE_POINTS = 4
#: Convergence order used for the Richardson estimate (see the module docstring).
ORDER = 2.0
#: The most a ``segments: "auto"`` beam is refined to (it starts at :data:`model.scene.AUTO_START`).
AUTO_MAX = 128


def coarsened(scene: Scene, factor: int) -> Scene | None:
    """``scene`` with every beam of at least ``factor`` segments at ``segments // factor``; None if no beam
    changes."""
    changed = False
    els = []
    for e in scene.elements:
        if isinstance(e, Beam) and isinstance(e.segments, int) and e.segments >= factor:
            els.append(e.model_copy(update={"segments": e.segments // factor}))
            changed = True
        else:
            els.append(e)
    return scene.model_copy(update={"elements": tuple(els)}) if changed else None


def _first_parasitic(an: MeshAnalysis, targets: np.ndarray) -> dict[float, float]:
    """First parasitic frequency (lowest mode where none is parasitic) at each converged, stable target
    (internal units, one side, monotone away from 0), by continuation on ``an``'s model."""
    sys = an.system
    drive = an.structure.scene.stroke.drive
    k = an.structure.scene.modes + 2
    out: dict[float, float] = {}
    opts: NewtonOptions = an.options
    last: list = [None]  # the previous point's modes: where its eigen solve starts (modal.modes_at's near)

    def accept(eq) -> WalkFailure | None:  # noqa: ANN001 - statics callback
        modes = last[0] = modes_at(sys, eq, k, drive, last[0])
        if not len(modes.omega2) or not modes.omega2[0] > 0:
            return WalkFailure("unstable", eq.stroke, eq.stroke, "")
        labels, par = an.label_modes(modes, eq.tangent)
        out[float(eq.stroke)] = par if np.isfinite(par) else float(modes.hz[0])
        return None

    eq0 = solve_point(sys, sys.reference_state(), 0.0, opts, 0.0)
    if accept(eq0) is None and len(targets):
        walk(sys, targets, opts, accept, start=eq0)
    return out


def _estimate_points(strokes: np.ndarray) -> list[np.ndarray]:
    """Per side, up to ESTIMATE_POINTS of the given stroke values (internal units), evenly spread by
    index and ending at the side's last one, ordered away from 0."""
    out = []
    for side in (np.sort(strokes[strokes > 0]), np.sort(strokes[strokes < 0])[::-1]):
        if len(side):
            idx = np.unique(np.round(np.linspace(len(side) - 1, 0, ESTIMATE_POINTS, endpoint=False)).astype(int))
            out.append(side[np.sort(idx)])
        else:
            out.append(np.zeros(0))
    return out


def mesh_error(an: MeshAnalysis, coarse: MeshAnalysis, strokes: np.ndarray, fine: dict[float, float]
               ) -> float | None:
    """Estimated relative discretisation error of the first parasitic frequency of ``an``'s curve (see the
    module docstring). ``coarse`` is the same analysis on :func:`coarsened` ``(an.scene, 2)`` (the caller
    builds it once and reuses it: model.curve); ``strokes`` are the curve's converged stroke values
    (internal units); ``fine`` maps stroke values to the fine mesh's first parasitic frequency there (points
    missing from it are skipped)."""
    ns = [e.segments for e in an.scene.elements if isinstance(e, Beam) and isinstance(e.segments, int)
          and e.segments >= 2]
    r = min(n / (n // 2) for n in ns)  # refinement ratio (2 for even counts; the smallest is conservative)
    sides = _estimate_points(np.asarray(strokes, dtype=float))
    sub = coarse
    f2: dict[float, float] = {}
    for side in sides:
        f2.update(_first_parasitic(sub, side))
    f = {float(k): float(v) for k, v in fine.items() if np.isfinite(v)}
    common = sorted(set(f) & set(f2))
    if not common:
        return None
    d2 = np.array([f[s] - f2[s] for s in common])
    fv = np.array([f[s] for s in common])
    p = ORDER
    return float(np.max(np.abs(d2) / (r**p - 1.0) / np.abs(fv)))


def resolve_auto_segments(scene: Scene, options: NewtonOptions | None = None) -> tuple[Scene, str | None]:
    """``scene`` with every ``segments: "auto"`` beam given the segments that meet ``scene.mesh_tolerance``
    (see the module docstring), and a one-line note of what was chosen (None when nothing was "auto")."""

    auto = [i for i, e in enumerate(scene.elements) if isinstance(e, Beam) and e.segments == "auto"]
    if not auto:
        return scene, None

    def with_n(n: int) -> Scene:
        els = list(scene.elements)
        for i in auto:
            els[i] = els[i].model_copy(update={"segments": n})
        return scene.model_copy(update={"elements": tuple(els)})

    tol = scene.mesh_tolerance
    st = scene.stroke
    grid = st.to_internal(st.values()) if st is not None else np.zeros(1)
    sides = _estimate_points(np.asarray(grid, dtype=float))
    n, chosen = AUTO_START, None
    prev = None
    est = float("nan")
    while n <= AUTO_MAX:
        sc = with_n(n)
        an = MeshAnalysis(sc, options)
        if int(an.structure.active.sum()) > MAX_DOFS:
            break
        chosen = (sc, n)
        vals: dict[float, float] = {}
        for side in sides:
            vals.update(_first_parasitic(an, side))
        if prev is not None:
            common = sorted(set(vals) & set(prev))
            if common:
                est = max(abs(vals[s] - prev[s]) / (2.0**ORDER - 1.0) / abs(vals[s]) for s in common)
                if est <= tol:
                    break
        prev, n = vals, 2 * n
    if chosen is None:
        chosen = (with_n(AUTO_START), AUTO_START)
    sc, n = chosen
    names = ", ".join(scene.elements[i].name for i in auto)
    met = "within" if est <= tol else "NOT within"
    return sc, (f"segments 'auto': {n} per beam for {names} (estimated discretisation error {est:.2g}, {met} "
                f"mesh_tolerance {tol:g})")
