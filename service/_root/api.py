"""The everyday calls, at the top of the package: ``flexopt.curve``, ``flexopt.modes``, ``flexopt.diagnose``,
``flexopt.optimise``, ``flexopt.template``, ``flexopt.load``.

Each takes a scene as a :class:`flexopt.model.Scene`, a scene dict (the JSON format), a path to a scene file,
or a template's name (with template parameters as keywords), so a notebook needs no sub-module::

    import flexopt
    curve = flexopt.curve("cross-spring-pivot", method="hermite", thickness="0.3 mm")
    curve.plot()
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # pragma: no cover - names for annotations only; nothing heavy loads at import
    from .model import ConstraintDiagnosis, FrequencyCurve, Scene
    from .model.shapes import Shapes

__all__ = ["curve", "modes", "diagnose", "optimise", "template", "load"]


def template(name: str, **params: Any) -> Scene:
    """The scene of a built-in template; parameters as keywords, numbers in SI or strings with a unit
    (``thickness="0.3 mm"``). ``flexopt.model.TEMPLATES`` lists the names."""
    from .model import template as _template

    return _template(name, **params)


def load(scene: Scene | dict | str | Path, **params: Any) -> Scene:
    """A scene from any of the forms the top-level calls accept: a Scene (returned as it is), a dict in the
    scene format, a path to a scene file, or a template's name (``params`` are its parameters)."""
    from .model import TEMPLATES, load_scene, scene_from_dict
    from .model import Scene as _Scene

    if isinstance(scene, _Scene):
        if params:
            raise TypeError("template parameters apply to a template's name, not to a Scene")
        return scene
    if isinstance(scene, dict):
        if params:
            raise TypeError("template parameters apply to a template's name, not to a scene dict")
        return scene_from_dict(scene)
    if isinstance(scene, str) and scene in TEMPLATES:
        return template(scene, **params)
    path = Path(scene)
    if not path.exists():
        raise FileNotFoundError(
            f"no scene file '{scene}' and no template of that name; templates: {', '.join(sorted(TEMPLATES))}"
        )
    if params:
        raise TypeError("template parameters apply to a template's name, not to a scene file")
    return load_scene(path)


def curve(
    scene: Scene | dict | str | Path, method: str = "exact", tolerance: float = 0.01, stroke: Any = None, **params: Any
) -> FrequencyCurve:
    """The stroke-dependent frequency curve of ``scene`` by ``method`` (``exact``, ``hermite``, ``auto``,
    ``fd1``, ``fd2``, ``manifold``, ``reduced``; see the methods page), with its warnings and mesh estimate.

    ``stroke``: stroke values in the scene's stroke unit (default: the scene's own range and points).
    """
    import numpy as np

    from .model.curve import curve_with_method  # the curve pipeline: segments 'auto', mesh_error, warnings

    values = None if stroke is None else np.asarray(stroke, dtype=float)
    return curve_with_method(load(scene, **params), method, tolerance, values)


def modes(scene: Scene | dict | str | Path, at_stroke: float = 0.0, **params: Any) -> Shapes:
    """The equilibrium and the mode shapes at one stroke value (stroke unit), as ``flexopt modes`` shows."""
    from .model import Analysis
    from .model.shapes import shapes_at

    return shapes_at(Analysis(load(scene, **params)), at_stroke)


def diagnose(
    scene: Scene | dict | str | Path, at_stroke: float | None = None, kinematic: bool | None = None, **params: Any
) -> ConstraintDiagnosis:
    """The exact-constraint diagnosis (D_cc, its SVD, free motions and self-stresses) of ``scene``."""
    from .model import diagnose as _diagnose

    return _diagnose(load(scene, **params), at_stroke=at_stroke, kinematic=kinematic)


def optimise(problem: Any, **options: Any) -> dict:
    """Maximise the worst-case first parasitic frequency over the stroke (a problem dict, JSON path or
    :class:`flexopt.optim.Problem`); ``options`` as :func:`flexopt.optim.optimise` (``executor``,
    ``workers``, ``store``, ``progress``)."""
    import json

    from .optim import optimise as _optimise

    if isinstance(problem, (str, Path)):
        problem = json.loads(Path(problem).read_text())
    return _optimise(problem, **options)
