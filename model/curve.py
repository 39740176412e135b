"""The curve pipeline: a scene's mesh resolved, its curve computed, its discretisation error estimated.

:class:`Analysis` (``flexopt.model.Analysis``) sits one floor above :class:`model.analysis.MeshAnalysis`,
which solves one given mesh: it resolves ``segments: "auto"`` beams to a mesh that meets the scene's
``mesh_tolerance`` (:func:`model.mesh.resolve_auto_segments`), builds the analysis of that mesh and
attaches ``FrequencyCurve.mesh_error`` (:func:`model.mesh.mesh_error`, from the same analysis on a second
mesh, half or twice the segments: :func:`model.mesh.second_mesh`, built once per analysis) to every curve
it computes, before the checks read it (:func:`model.checks.annotate_curve`: the ``mesh`` warning). A
curve by a fast method (:func:`curve_with_method`) carries the estimate of the exact curve of its mesh:
the same points solved exactly on both meshes.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from .analysis import MeshAnalysis
from .checks import annotate_curve
from .errors import ModelSizeError
from .mesh import SecondMesh, resolve_auto_segments, second_mesh
from .mesh import mesh_error as estimate_mesh_error
from .modal import Modes
from .results import FrequencyCurve
from .scene import Beam, Scene
from .statics import Equilibrium, NewtonOptions
from .symmetry import one_side
from .threads import limited

__all__ = ["Analysis", "frequency_curve", "curve_with_method"]


class Analysis(MeshAnalysis):
    """A scene's curve pipeline, ready to compute curves (reuse it for repeated calls): ``segments: "auto"``
    resolved (:attr:`auto_note` says to what), the analysis of the resulting mesh (:class:`MeshAnalysis`,
    whose members it has) and the mesh estimate of every curve (:meth:`frequency_curve`,
    :meth:`method_curve`)."""

    @limited()  # one BLAS thread while it computes (model.threads): 'auto' segments solve curves
    def __init__(self, scene: Scene, options: NewtonOptions | None = None) -> None:
        #: What segments 'auto' resolved to (model.mesh); None when no beam had 'auto'.
        self.auto_note: str | None = None
        if any(getattr(e, "segments", 1) == "auto" for e in scene.elements):
            scene, self.auto_note = resolve_auto_segments(scene, options)
        super().__init__(scene, options)
        #: The mesh estimate's second analysis (half or twice the segments per beam), built on first use and
        #: reused by every curve this analysis computes (:meth:`second_mesh`).
        self.second: SecondMesh | None = None
        #: Why the estimate is missing, when it is (no beam; a refined mesh beyond MAX_DOFS).
        self.no_estimate: str | None = None

    def second_mesh(self) -> SecondMesh | None:
        """The estimate's second mesh (:func:`model.mesh.second_mesh`), compiled once and reused; None (and
        :attr:`no_estimate` says why) when there is none."""
        if self.second is not None and self.second.analysis.options is self.options:
            return self.second
        if not any(isinstance(e, Beam) for e in self.scene.elements):
            self.no_estimate = "no beam to mesh (trusses are exact bars)"
            return None
        try:
            self.second = second_mesh(self.scene, self.options)
        except ModelSizeError as exc:
            self.no_estimate = f"not estimated: the second mesh is too large ({exc})"
            return None
        return self.second

    def _with_estimate(
        self, curve: FrequencyCurve, strokes: np.ndarray, fine: dict[float, float] | None, estimate: bool, how: str
    ) -> FrequencyCurve:
        """``curve`` with its mesh estimate (when ``estimate``), the mesh convention and its checks."""
        t0 = time.perf_counter()
        err = None
        second = self.second_mesh() if estimate and len(curve.stroke) else None
        if second is not None:
            err = estimate_mesh_error(self, second, strokes, fine)
        if second is not None:
            other = f"{second.ratio:g} times" if second.refined else "half"
            mesh = (
                f"mesh_error: Richardson estimate (order 2) from the same analysis on a mesh with {other} the "
                f"segments per beam, at a few stroke points (model.mesh){how}"
            )
        else:
            mesh = "mesh_error: " + ((self.no_estimate or "") if estimate else "not estimated (asked not to)")
        mesh += f"; {self.auto_note}" if self.auto_note else ""
        seconds = float(curve.solver.get("seconds", 0.0)) + time.perf_counter() - t0  # the curve's time includes it
        curve = replace(
            curve,
            mesh_error=err,
            conventions={**curve.conventions, "mesh": mesh},
            solver={**curve.solver, "seconds": seconds},
        )
        return annotate_curve(curve, self.scene, self.options)  # warnings and provenance (model.checks)

    @limited()  # one BLAS thread while it computes (model.threads)
    def frequency_curve(
        self,
        stroke: np.ndarray | None = None,
        progress: Callable[[int, int], None] | None = None,
        visit: Callable[[Equilibrium, Modes, list[str]], None] | None = None,
        mirror: bool = True,
        *,
        mesh_error: bool | None = None,
    ) -> FrequencyCurve:
        """The exact frequency curve at ``stroke`` (stroke unit; default: the scene's stroke grid) with its
        mesh estimate, its checks' warnings and its provenance.

        ``stroke``, ``progress``, ``visit`` and ``mirror`` as :meth:`MeshAnalysis.exact_curve`.
        ``mesh_error``: estimate the discretisation error (:func:`model.mesh.mesh_error`, about a tenth of
        the curve's time) into ``FrequencyCurve.mesh_error``; None = unless ``visit`` is given (the
        optimiser's inner loop). On a symmetric design the other side's estimate is the same: it is
        estimated on the solved side only.
        """
        curve, solved = self.exact_curve(stroke, progress, visit, mirror)
        want = mesh_error if mesh_error is not None else visit is None
        return self._with_estimate(curve, np.array(sorted(solved)), solved, want, "")

    def method_curve(self, method: str, tolerance: float = 0.01, stroke: np.ndarray | None = None) -> FrequencyCurve:
        """The curve by ``method`` (:func:`model.methods.frequency_curve`) with the mesh estimate of the
        exact curve of this mesh: the estimate's points solved exactly on both meshes, so it is the exact
        curve's (to the Newton tolerance) whatever the method's own error. An exact curve (``exact``, or a
        fast method that fell back to it) has its estimate already."""
        from .methods import frequency_curve as by_method  # lazily: `import flexopt.model` stays as light

        curve = by_method(self, method, tolerance, stroke)
        if curve.method == "exact" and "mesh_error:" in curve.conventions.get("mesh", ""):
            return curve
        spec = self.stroke
        values = np.asarray(spec.values() if stroke is None else stroke, dtype=float)
        internal = np.asarray(spec.to_internal(values), dtype=float)
        # on a symmetric design the estimate of the exact curve reads the positive side only (as exact does)
        strokes = one_side(internal) if self.symmetry is not None else internal
        return self._with_estimate(curve, strokes, None, True, ", the points solved exactly on both meshes")


@limited()
def frequency_curve(
    scene: Scene, stroke: np.ndarray | None = None, progress: Callable[[int, int], None] | None = None
) -> FrequencyCurve:
    """Exact stroke-dependent natural frequencies of ``scene`` (see :class:`Analysis`)."""
    return Analysis(scene).frequency_curve(stroke, progress)


@limited()
def curve_with_method(
    analysis: Analysis | Scene, method: str, tolerance: float = 0.01, stroke: np.ndarray | None = None
) -> FrequencyCurve:
    """The curve of ``analysis`` (or of a scene, through :class:`Analysis`) by ``method`` (one of
    :data:`model.methods.METHODS`) with the exact mesh's estimate (:meth:`Analysis.method_curve`)."""
    an = analysis if isinstance(analysis, Analysis) else Analysis(analysis)
    return an.method_curve(method, tolerance, stroke)
