"""The heavy work of the service, as plain functions of a JSON spec (run in a worker process or thread).

Workers get a JSON string and return ``(True, bytes)`` or ``(False, error dict)``: nothing user-supplied is
ever pickled, and model exceptions (whose constructors take keyword-shaped arguments) cross the process
boundary as data and are rebuilt by :func:`raise_error` in the server.
"""

from __future__ import annotations

import io
import json
import math
from typing import Any

__all__ = ["curve", "diagnosis", "raise_error", "warm_up"]

Outcome = tuple[bool, Any]


def _finite(obj: Any) -> Any:
    """JSON-safe copy: non-finite floats become null, numpy scalars plain numbers."""
    if isinstance(obj, dict):
        return {str(k): _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    if isinstance(obj, bool) or obj is None or isinstance(obj, (str, int)):
        return obj
    try:
        v = float(obj)
    except (TypeError, ValueError):
        return str(obj)
    return v if math.isfinite(v) else None


def _png(curve: Any) -> bytes:
    """Frequency against stroke as a PNG (matplotlib's object API: thread-safe, no pyplot state)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7, 4.5))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    for j in range(curve.modes_hz.shape[1]):
        ax.plot(curve.stroke, curve.modes_hz[:, j], color="0.75", lw=1, label="tracked modes" if j == 0 else None)
    ax.plot(curve.stroke, curve.parasitic_hz, color="C3", lw=2, label="first parasitic")
    ax.set_xlabel(f"stroke [{curve.stroke_unit}]")
    ax.set_ylabel("natural frequency [Hz]")
    ax.set_title(f"{curve.scene} ({curve.method})")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    return buf.getvalue()


def _error(exc: Exception) -> Outcome:
    return False, {"kind": type(exc).__name__, "field": getattr(exc, "field", ""),
                   "message": getattr(exc, "message", str(exc))}


#: Magnitudes outside [TINY, HUGE] are reported as the likely cause when a computation breaks: far beyond
#: any flexure in SI units (nanometre films to kilometre frames, E of steel 2.1e11 Pa), and where squares,
#: cubes and products of such numbers leave double precision (1e308) or its useful relative range.
TINY, HUGE = 1e-12, 1e15


def _extreme_fields(doc: Any, path: str = "") -> list[str]:
    """Dotted paths (``elements[0].section.thickness``) of the scene's numbers outside [TINY, HUGE]."""
    out: list[str] = []
    if isinstance(doc, dict):
        for k, v in doc.items():
            out += _extreme_fields(v, f"{path}.{k}" if path else str(k))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            out += _extreme_fields(v, f"{path}[{i}]")
    elif isinstance(doc, (int, float)) and not isinstance(doc, bool) and doc != 0:
        if not TINY <= abs(doc) <= HUGE:
            out.append(path)
    return out


def _broken(exc: Exception, scene: dict) -> Outcome:
    """A computation that broke on a valid scene (overflow, division by zero, a failed solve): name the
    scene's extreme numbers as the likely cause, or the scene as a whole."""
    fields = _extreme_fields(scene)
    where = (f"; check {', '.join(fields[:5])}: outside the range [{TINY:g}, {HUGE:g}] in SI units"
             if fields else "; check that the scene's sizes, materials and stroke are physically plausible")
    first = (str(exc).strip().splitlines() or [""])[-1][:200]
    return False, {"kind": "ComputationError", "field": fields[:5],
                   "message": f"the scene could not be computed ({type(exc).__name__}: {first}){where}"}


def raise_error(err: dict[str, Any]) -> None:
    """Rebuild and raise a model error reported by a worker."""
    from ..model.errors import FlexoptError, KernelBuildError, ModelSizeError, SceneError

    kind, field, message = err["kind"], err["field"], err["message"]
    if kind == "ComputationError":
        from .errors_http import ComputationFailed

        raise ComputationFailed(list(field), message)
    if kind in ("SceneError", "ModelSizeError"):
        raise (ModelSizeError if kind == "ModelSizeError" else SceneError)(field, message)
    if kind == "KernelBuildError":
        raise KernelBuildError(message)
    raise FlexoptError(message)


def curve(spec: str) -> Outcome:
    """Frequency curve of ``{"scene", "stroke", "method", "tolerance", "media"}`` as JSON, CSV or PNG bytes."""
    import numpy as np

    from ..model import Analysis
    from ..model.errors import FlexoptError
    from ..model.scene import Scene

    s = json.loads(spec)
    try:
        an = Analysis(Scene.model_validate(s["scene"]))
        stroke = None if s["stroke"] is None else np.asarray(s["stroke"], dtype=float)
        if s["method"] == "exact":
            result = an.frequency_curve(stroke)
        else:
            from ..model.derivatives import curve_with_method

            result = curve_with_method(an, s["method"], s["tolerance"], stroke)
        if s["media"] == "text/csv":
            return True, result.to_csv().encode()
        if s["media"] == "image/png":
            return True, _png(result)
        return True, json.dumps(_finite(result.to_dict()), allow_nan=False).encode()
    except FlexoptError as exc:
        return _error(exc)
    except Exception as exc:  # noqa: BLE001 - overflow, zero division, a failed solve: named, never a 500
        return _broken(exc, s["scene"])


def diagnosis(spec: str) -> Outcome:
    """Exact-constraint diagnosis of ``{"scene", "at_stroke", "kinematic"}`` as JSON bytes."""
    from ..model.constraints import diagnose
    from ..model.errors import FlexoptError
    from ..model.scene import Scene

    s = json.loads(spec)
    try:
        d = diagnose(Scene.model_validate(s["scene"]), at_stroke=s["at_stroke"], kinematic=s["kinematic"])
        return True, json.dumps(_finite(d.to_dict()), allow_nan=False).encode()
    except FlexoptError as exc:
        return _error(exc)
    except Exception as exc:  # noqa: BLE001 - overflow, zero division, a failed solve: named, never a 500
        return _broken(exc, s["scene"])


def warm_up() -> None:
    """Import the model in a fresh worker process (so the first request does not pay for it)."""
    from .. import model  # noqa: F401
