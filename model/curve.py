"""The curve pipeline: a scene's mesh resolved, its exact curve solved, its discretisation error estimated.

:class:`Analysis` (``flexopt.model.Analysis``) sits one floor above :class:`model.analysis.MeshAnalysis`,
which solves one given mesh: it resolves ``segments: "auto"`` beams to a mesh that meets the scene's
``mesh_tolerance`` (:func:`model.mesh.resolve_auto_segments`), builds the analysis of that mesh and
attaches ``FrequencyCurve.mesh_error`` (:func:`model.mesh.mesh_error`, from the same analysis on a mesh of
half the segments, built once per analysis) to every curve it computes, before the checks read it
(:func:`model.checks.annotate_curve`: the ``mesh`` warning).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from .analysis import MeshAnalysis
from .checks import annotate_curve
from .mesh import coarsened
from .mesh import mesh_error as estimate_mesh_error
from .mesh import resolve_auto_segments
from .modal import Modes
from .results import FrequencyCurve
from .scene import Scene
from .statics import Equilibrium, NewtonOptions
from .threads import limited

__all__ = ["Analysis", "frequency_curve", "curve_with_method", "MESH_ESTIMATE"]

#: What ``conventions["mesh"]`` says of a curve whose mesh error is estimated.
MESH_ESTIMATE = ("mesh_error: Richardson estimate (order 2) from the same analysis on a mesh with half the "
                 "segments per beam, at a few stroke points (model.mesh)")


class Analysis(MeshAnalysis):
    """A scene's curve pipeline, ready to compute curves (reuse it for repeated calls): ``segments: "auto"``
    resolved (:attr:`auto_note` says to what), the analysis of the resulting mesh (:class:`MeshAnalysis`,
    whose members it has) and the mesh estimate of every curve (:meth:`frequency_curve`)."""

    @limited()  # one BLAS thread while it computes (model.threads): 'auto' segments solve curves
    def __init__(self, scene: Scene, options: NewtonOptions | None = None) -> None:
        #: What segments 'auto' resolved to (model.mesh); None when no beam had 'auto'.
        self.auto_note: str | None = None
        if any(getattr(e, "segments", 1) == "auto" for e in scene.elements):
            scene, self.auto_note = resolve_auto_segments(scene, options)
        super().__init__(scene, options)
        #: The mesh estimate's coarse analysis (half the segments per beam), built on first use and reused
        #: by every curve this analysis computes (:meth:`coarse_analysis`).
        self.coarse: MeshAnalysis | None = None

    def coarse_analysis(self) -> MeshAnalysis | None:
        """The analysis of the scene on half the segments per beam (:func:`model.mesh.coarsened`), compiled
        once and reused; None when no beam can be coarsened (every beam has one segment)."""
        if self.coarse is not None and self.coarse.options is self.options:
            return self.coarse
        half = coarsened(self.scene, 2)
        if half is None:
            return None
        self.coarse = MeshAnalysis(half, self.options)
        return self.coarse

    @limited()  # one BLAS thread while it computes (model.threads)
    def frequency_curve(
        self, stroke: np.ndarray | None = None, progress: Callable[[int, int], None] | None = None,
        visit: Callable[[Equilibrium, Modes, list[str]], None] | None = None,
        mesh_error: bool | None = None, mirror: bool = True,
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
        t0 = time.perf_counter()
        err = None
        if (mesh_error if mesh_error is not None else visit is None) and len(curve.stroke):
            coarse = self.coarse_analysis()
            if coarse is not None:
                err = estimate_mesh_error(self, coarse, np.array(sorted(solved)), solved)
        mesh = MESH_ESTIMATE + (f"; {self.auto_note}" if self.auto_note else "")
        seconds = curve.solver["seconds"] + time.perf_counter() - t0  # the curve's time includes its estimate
        curve = replace(curve, mesh_error=err, conventions={**curve.conventions, "mesh": mesh},
                        solver={**curve.solver, "seconds": seconds})
        return annotate_curve(curve, self.scene, self.options)  # warnings and provenance (model.checks)


@limited()
def frequency_curve(scene: Scene, stroke: np.ndarray | None = None,
                    progress: Callable[[int, int], None] | None = None) -> FrequencyCurve:
    """Exact stroke-dependent natural frequencies of ``scene`` (see :class:`Analysis`)."""
    return Analysis(scene).frequency_curve(stroke, progress)


@limited()
def curve_with_method(analysis: Analysis | Scene, method: str, tolerance: float = 0.01,
                      stroke: np.ndarray | None = None) -> FrequencyCurve:
    """The curve of ``analysis`` (or of a scene, through :class:`Analysis`) by ``method`` (one of
    :data:`model.methods.METHODS`, :func:`model.methods.frequency_curve`)."""
    from .methods import curve_with_method as method_curve  # lazily: `import flexopt.model` stays as light

    an = analysis if isinstance(analysis, Analysis) else Analysis(analysis)
    return method_curve(an, method, tolerance, stroke)
