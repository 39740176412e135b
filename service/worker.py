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


def raise_error(err: dict[str, Any]) -> None:
    """Rebuild and raise a model error reported by a worker."""
    from ..model.errors import FlexoptError, KernelBuildError, MassUnderflowError, ModelSizeError, SceneError

    kind, field, message = err["kind"], err["field"], err["message"]
    scene_errors = {c.__name__: c for c in (SceneError, ModelSizeError, MassUnderflowError)}
    if kind in scene_errors:
        raise scene_errors[kind](field, message)
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
    except FlexoptError as exc:
        return _error(exc)
    if s["media"] == "text/csv":
        return True, result.to_csv().encode()
    if s["media"] == "image/png":
        return True, _png(result)
    return True, json.dumps(_finite(result.to_dict()), allow_nan=False).encode()


def diagnosis(spec: str) -> Outcome:
    """Exact-constraint diagnosis of ``{"scene", "at_stroke", "kinematic"}`` as JSON bytes."""
    from ..model.constraints import diagnose
    from ..model.errors import FlexoptError
    from ..model.scene import Scene

    s = json.loads(spec)
    try:
        d = diagnose(Scene.model_validate(s["scene"]), at_stroke=s["at_stroke"], kinematic=s["kinematic"])
    except FlexoptError as exc:
        return _error(exc)
    return True, json.dumps(_finite(d.to_dict()), allow_nan=False).encode()


def warm_up() -> None:
    """Import the model in a fresh worker process (so the first request does not pay for it)."""
    from .. import model  # noqa: F401
