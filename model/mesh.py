"""Discretisation error of an exact curve, and ``segments: "auto"`` meshes refined to a tolerance.

Estimate (:func:`mesh_error`)
-----------------------------
The same analysis on a second mesh (:func:`second_mesh`) at a few stroke points: the ends of the converged
range on each side and up to :data:`ESTIMATE_POINTS` - 1 of the curve's own points per side in between
(continuation needs them), so the curve's mesh's values are the curve's (a fast method's curve: those
points solved exactly). With ``f`` and ``f_2`` the first parasitic frequency (the lowest mode where none
is parasitic) on the curve's and the second mesh at a point, Richardson extrapolation at order ``p``
(Richardson 1911; Roache, Verification and Validation in Computational Science and Engineering, 1998,
ch. 5) puts the error of the curve's mesh at

* ``|f - f_2| / (r^p - 1)`` when the second mesh is the coarser: every beam of ``n`` segments at ``n // 2``
  (refinement ratio ``r = n / (n // 2)``, the smallest over the beams), used when every beam keeps at least
  :data:`COARSE_MIN` (= 2) segments at half;
* ``|f - f_2| r^p / (r^p - 1)``, relative to ``f_2``, when the mesh is too coarse to halve: every beam at
  :data:`REFINE` (= 4) times its segments (``r = 4``). A half mesh of 1 segment per member reads 4-100x low
  (the double cross hinge at 2 segments: 1.1 % against 14.3 % true), and so does a mesh of twice the
  segments, still outside the asymptotic range from 1 segment (the folded-sheet guide at 1 segment: 17.6 %
  from 2 segments, 46 % from 4, 55.7 % true; ``python bench/bench_mesh_estimate.py``);

the largest relative value over the points is ``FrequencyCurve.mesh_error``. Every curve of a scene with
a beam has one, whatever its mesh (none: a scene of trusses only, which are exact bars).

``p = 2``, the rate measured along the stroke: the element's nonlinear terms converge at O(h^2)
(Meijaard 2022; the cross-spring pivot's parasitic frequency at 15 deg differs by 2.48, 0.59, 0.146 Hz
between 4/8/16/32 segments, ratio 4.0), while zero-stroke modes with the cubic mass converge at O(h^4)
(tests/test_mesh.py), where the estimate is conservative. A rate measured from three meshes was tried
and dropped: from 8/4/2 segments the pivot reads an order of 4.5 (coarse meshes are outside the
asymptotic range) and the estimate fell 4 times short; at ``p = 2`` the estimates of the default
templates are within 10 % of the error against 80 segments (leaf 7.7e-4 vs 7.4e-4, guide 8.3e-5 vs
8.5e-5, pivot 8.3e-3 vs 7.7e-3).

Cost (of the usual half mesh; the refined one is four times a mesh of 1-3 segments per beam, small): the coarse model holds half the fine model's degrees of freedom and is solved at ``2
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

from dataclasses import dataclass

import numpy as np

from .analysis import MeshAnalysis
from .modal import modes_at
from .scene import AUTO_START, Beam, Scene, Truss
from .statics import NewtonOptions, WalkFailure, reference_equilibrium, walk
from .structure import MAX_DOFS

__all__ = [
    "mesh_error",
    "coarsened",
    "refined",
    "second_mesh",
    "SecondMesh",
    "resolve_auto_segments",
    "AUTO_START",
    "AUTO_MAX",
    "ESTIMATE_POINTS",
    "ORDER",
    "COARSE_MIN",
]

#: Stroke points per side (besides the reference) at which the coarse meshes are solved.
ESTIMATE_POINTS = 4
#: Convergence order used for the Richardson estimate (see the module docstring).
ORDER = 2.0
#: The estimate halves the mesh only when every beam keeps at least this many segments at half; a coarser
#: mesh is compared with twice its segments instead (a half mesh of 1 segment per member reads 4-100x low).
COARSE_MIN = 2
#: ... and with this many times its segments per beam (see the module docstring for why not twice).
REFINE = 4
#: The most a ``segments: "auto"`` beam is refined to (it starts at :data:`model.scene.AUTO_START`).
AUTO_MAX = 128


def coarsened(scene: Scene, factor: int) -> Scene | None:
    """``scene`` with every beam of at least ``factor`` segments at ``segments // factor``; None if no beam
    changes."""
    changed = False
    els: list[Beam | Truss] = []
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
    drive = an.stroke.drive
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

    eq0 = reference_equilibrium(sys, opts)  # under loads: applied in steps, as the curve's own reference
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


def refined(scene: Scene, factor: int) -> Scene:
    """``scene`` with every beam at ``factor`` times its segments (an unvalidated copy, as
    :func:`coarsened`)."""
    els = [e.model_copy(update={"segments": e.segments * factor}) if isinstance(e, Beam) else e for e in scene.elements]
    return scene.model_copy(update={"elements": tuple(els)})


@dataclass(frozen=True)
class SecondMesh:
    """The estimate's second analysis (:func:`second_mesh`): the same scene on another mesh."""

    analysis: MeshAnalysis
    ratio: float  # refinement ratio r between the two meshes (> 1)
    refined: bool  # True: twice the curve's segments (the curve's mesh is the coarse one); False: half


def second_mesh(scene: Scene, options: NewtonOptions | None) -> SecondMesh | None:
    """The mesh the estimate compares the curve's with: half the segments per beam when every beam keeps
    at least :data:`COARSE_MIN` at half (refinement ratio the smallest ``n / (n // 2)``), otherwise twice
    the segments of every beam (ratio 2); None when the scene has no beam (trusses are exact bars)."""
    ns = [e.segments for e in scene.elements if isinstance(e, Beam) and isinstance(e.segments, int)]
    if not ns:
        return None
    if min(ns) // 2 >= COARSE_MIN:
        half = coarsened(scene, 2)
        assert half is not None
        return SecondMesh(MeshAnalysis(half, options), min(n / (n // 2) for n in ns), False)
    return SecondMesh(MeshAnalysis(refined(scene, REFINE), options), float(REFINE), True)


def mesh_error(
    an: MeshAnalysis, second: SecondMesh, strokes: np.ndarray, fine: dict[float, float] | None = None
) -> float | None:
    """Estimated relative discretisation error of the first parasitic frequency of ``an``'s curve (see the
    module docstring). ``second`` is the same analysis on the other mesh (:func:`second_mesh`; the caller
    builds it once and reuses it: model.curve); ``strokes`` are the curve's stroke values (internal
    units; those the curve reached); ``fine`` maps stroke values to ``an``'s first parasitic frequency
    there (points missing from it are skipped); None = solve ``an`` exactly at the estimate's points (a
    curve by a fast method: its own values carry its interpolation error)."""
    sides = _estimate_points(np.asarray(strokes, dtype=float))
    if fine is None:
        fine = {}
        for side in sides:
            fine.update(_first_parasitic(an, side))
    f2: dict[float, float] = {}
    for side in sides:
        f2.update(_first_parasitic(second.analysis, side))
    f = {float(k): float(v) for k, v in fine.items() if np.isfinite(v)}
    common = sorted(set(f) & set(f2))
    if not common:
        return None
    fv = np.array([f[s] for s in common])  # the curve's mesh
    f2v = np.array([f2[s] for s in common])  # the other mesh
    rp = second.ratio**ORDER
    if not second.refined:  # the curve's mesh is the finer: its error |f - f_2| / (r^p - 1)
        return float(np.max(np.abs(fv - f2v) / (rp - 1.0) / np.abs(fv)))
    # the curve's mesh is the coarser: its error |f - f_2| r^p / (r^p - 1) (Richardson's extrapolated value
    # f_2 + (f_2 - f) / (r^p - 1) is the reference), relative to the finer mesh's value
    return float(np.max(np.abs(fv - f2v) * rp / (rp - 1.0) / np.abs(f2v)))


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
    return sc, (
        f"segments 'auto': {n} per beam for {names} (estimated discretisation error {est:.2g}, {met} "
        f"mesh_tolerance {tol:g})"
    )
