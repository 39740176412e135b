"""The heavy work of the service, as plain functions of a JSON spec (run in a worker process or thread).

Workers get a JSON string and return ``(True, bytes)`` or ``(False, error dict)``: nothing user-supplied is
ever pickled, and model exceptions (whose constructors take keyword-shaped arguments) cross the process
boundary as data and are rebuilt by :func:`raise_error` in the server.
"""

from __future__ import annotations

import json
import math
from typing import Any

__all__ = ["ComputationFailed", "broken", "curve", "diagnosis", "finite", "modes", "raise_error", "warm_up"]

Outcome = tuple[bool, Any]


class ComputationFailed(Exception):
    """A valid scene whose numbers broke the computation (overflow, division by zero, a failed solve)."""

    def __init__(self, fields: list[str], message: str) -> None:
        super().__init__(message)
        self.fields = fields


def finite(obj: Any) -> Any:
    """JSON-safe copy (the service's one sanitiser; the wire has no NaN): non-finite floats become null, numpy
    scalars plain numbers, tuples lists, keys strings."""
    if isinstance(obj, dict):
        return {str(k): finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [finite(v) for v in obj]
    if isinstance(obj, bool) or obj is None or isinstance(obj, (str, int)):
        return obj
    try:
        v = float(obj)
    except (TypeError, ValueError):
        return str(obj)
    return v if math.isfinite(v) else None


def _png(curve: Any, scene: dict | None = None) -> bytes:
    """The curve plot (service.plots, matplotlib's object API: thread-safe, no pyplot state) as PNG."""
    from ..plots import curve_png

    return curve_png(curve, scene)


def _error(exc: Exception) -> Outcome:
    return False, {
        "kind": type(exc).__name__,
        "field": getattr(exc, "field", ""),
        "message": getattr(exc, "message", str(exc)),
    }


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


def _model_error(exc: Exception, scene: dict) -> Outcome:
    """A model error of a valid scene: as it is when it names its field; when it names none (e.g. a singular
    reference equilibrium) and the scene holds extreme numbers, those numbers are the likely cause, named."""
    if not getattr(exc, "field", "") and _extreme_fields(scene):
        return broken(exc, scene)
    return _error(exc)


def broken(exc: Exception, scene: dict) -> Outcome:
    """A computation that broke on a valid scene (overflow, division by zero, a failed solve): name the
    scene's extreme numbers as the likely cause, or the scene as a whole."""
    fields = _extreme_fields(scene)
    where = (
        f"; check {', '.join(fields[:5])}: outside the range [{TINY:g}, {HUGE:g}] in SI units"
        if fields
        else "; check that the scene's sizes, materials and stroke are physically plausible"
    )
    return False, {
        "kind": "ComputationError",
        "field": fields[:5],
        "message": f"the scene could not be computed ({_in_words(exc)}){where}",
    }


#: what Python's arithmetic errors mean for a scene, in words (their own texts, e.g. "(34, 'Numerical result out
#: of range')", and their class names say nothing to a user)
_ARITHMETIC = (
    (OverflowError, "a number grew beyond double precision"),
    (ZeroDivisionError, "a division by zero"),
    (FloatingPointError, "a floating-point operation failed"),
    (RecursionError, "the input is nested too deeply"),
)


def _in_words(exc: Exception) -> str:
    """Why a computation broke, without exception class names: Python's arithmetic errors by what they mean,
    anything else by the first line of its own message (the model's messages are written for users)."""
    for kind, words in _ARITHMETIC:
        if isinstance(exc, kind):
            return words
    first = (str(exc).strip().splitlines() or [""])[0][:200]
    return first or "the computation failed"


def raise_error(err: dict[str, Any]) -> None:
    """Rebuild and raise a model error reported by a worker."""
    from ...model.errors import FlexoptError, KernelBuildError, MassUnderflowError, ModelSizeError, SceneError

    kind, field, message = err["kind"], err["field"], err["message"]
    if kind == "ComputationError":
        raise ComputationFailed(list(field), message)
    scene_errors = {c.__name__: c for c in (SceneError, ModelSizeError, MassUnderflowError)}
    if kind in scene_errors:
        raise scene_errors[kind](field, message)
    if kind == "KernelBuildError":
        raise KernelBuildError(message)
    raise FlexoptError(message)


def curve(spec: str) -> Outcome:
    """Frequency curve of ``{"scene", "stroke", "method", "tolerance", "media"}`` as JSON, CSV or PNG bytes."""
    import numpy as np

    from ...model import Analysis
    from ...model.errors import FlexoptError
    from ...model.scene import Scene
    from ..schemas import FrequencyCurveOut

    s = json.loads(spec)
    shapes = None
    try:
        an = Analysis(Scene.model_validate(s["scene"]))
        stroke = None if s["stroke"] is None else np.asarray(s["stroke"], dtype=float)
        if s["method"] == "exact":
            result = an.frequency_curve(stroke)
        else:
            from ...model.curve import curve_with_method

            result = curve_with_method(an, s["method"], s["tolerance"], stroke)
        if s.get("shapes"):
            shapes = _configurations(an, result.stroke)
        if s["media"] == "text/csv":
            return True, result.to_csv().encode()
        if s["media"] == "image/png":
            return True, _png(result, s["scene"])
        out = result.to_dict()
        if shapes is not None:
            out["shapes"] = shapes
    except FlexoptError as exc:
        return _model_error(exc, s["scene"])
    except Exception as exc:  # noqa: BLE001 - overflow, zero division, a failed solve: named, never a 500
        return broken(exc, s["scene"])
    # through the wire model the client validates with (schemas.FrequencyCurveOut), so that server and client
    # cannot disagree on the shape of a curve (a mismatch is the server's bug: raised, never blamed on the scene)
    wire = FrequencyCurveOut.model_validate(finite(out)).model_dump(mode="json", exclude_unset=True)
    return True, json.dumps(wire, allow_nan=False).encode()


def _configurations(an: Any, stroke: Any) -> dict:
    """The deflected configuration at every stroke point of a curve, with the drawing geometry once."""
    from ...model.shapes import configuration_dict, shapes_along

    found = shapes_along(an, stroke, modes=False, strict=False)
    if not found:
        return {"members": {}, "bodies": {}, "points": []}
    first = found[0]
    return {
        "members": first.members,
        "bodies": first.bodies,
        "points": [
            configuration_dict(sh.node_names, list(sh.bodies), sh.members, sh.allowable_stress, sh.configuration)
            for sh in found
        ],
    }


def modes(spec: str) -> Outcome:
    """Deflected structure and mode shapes of ``{"scene", "at_stroke", "media"}`` as JSON, PNG or GIF bytes
    (``mode``: the 0-based mode drawn in a picture; default the first parasitic)."""
    s = json.loads(spec)
    try:
        return _modes(s)
    except Exception as exc:  # noqa: BLE001 - overflow, zero division, a failed solve: named, never a 500
        from ...model.errors import FlexoptError

        if isinstance(exc, FlexoptError):
            return _model_error(exc, s["scene"])
        return broken(exc, s["scene"])


def _modes(s: dict) -> Outcome:
    import os
    import tempfile

    from ...model import Analysis
    from ...model.errors import FlexoptError
    from ...model.scene import Scene
    from ...model.shapes import shapes_at

    d = shapes_at(Analysis(Scene.model_validate(s["scene"])), s["at_stroke"]).to_dict()
    if s["media"] in ("image/png", "image/gif"):
        from .. import plots

        k = s.get("mode")
        if k is None:
            par = [i for i, m in enumerate(d["modes"]) if m["label"] == "parasitic"]
            k = min(par, key=lambda i: d["modes"][i]["hz"]) if par else 0
        if not 0 <= k < len(d["modes"]):
            return _error(FlexoptError(f"mode {k} does not exist; give 0 to {len(d['modes']) - 1}"))
        if s["media"] == "image/png":
            return True, plots.figure_bytes(plots.shapes_figure(d, k))
        fd, path = tempfile.mkstemp(suffix=".gif")
        os.close(fd)
        try:
            plots.animate_mode(d, k, path)
            with open(path, "rb") as fh:
                return True, fh.read()
        finally:
            os.unlink(path)
    return True, json.dumps(finite(d), allow_nan=False).encode()


def diagnosis(spec: str) -> Outcome:
    """Exact-constraint diagnosis of ``{"scene", "at_stroke", "kinematic"}`` as JSON bytes."""
    from ...model.diagnosis import diagnose
    from ...model.errors import FlexoptError
    from ...model.scene import Scene

    s = json.loads(spec)
    try:
        d = diagnose(Scene.model_validate(s["scene"]), at_stroke=s["at_stroke"], kinematic=s["kinematic"])
        return True, json.dumps(finite(d.to_dict()), allow_nan=False).encode()
    except FlexoptError as exc:
        return _model_error(exc, s["scene"])
    except Exception as exc:  # noqa: BLE001 - overflow, zero division, a failed solve: named, never a 500
        return broken(exc, s["scene"])


def state_space(spec: str) -> Outcome:
    """The linearised model (model.linear) of ``{"scene", "at_stroke", "inputs", "outputs", "damping", "modes",
    "frequencies_hz"}`` as JSON bytes: the matrices, the static gain and, if asked, the frequency response."""
    from ...model.errors import FlexoptError
    from ...model.linear import frequency_response
    from ...model.linear import state_space as linearise
    from ...model.scene import Scene

    s = json.loads(spec)
    try:
        ss = linearise(
            Scene.model_validate(s["scene"]), s["at_stroke"], s["inputs"], s["outputs"], s["damping"], s["modes"]
        )
        out = {**ss.to_dict(), "static_gain": ss.static_gain().tolist()}
        if s.get("frequencies_hz"):
            mag, ph = frequency_response(ss, s["frequencies_hz"])
            out["bode"] = {"frequency_hz": s["frequencies_hz"], "magnitude": mag.tolist(), "phase_deg": ph.tolist()}
        return True, json.dumps(finite(out), allow_nan=False).encode()
    except FlexoptError as exc:
        return _model_error(exc, s["scene"])
    except Exception as exc:  # noqa: BLE001 - overflow, zero division, a failed solve: named, never a 500
        return broken(exc, s["scene"])


def warm_up() -> None:
    """Import the model in a fresh worker process (so the first request does not pay for it) and limit the
    process to one BLAS thread (model.threads)."""
    from ...model.threads import limit_process

    limit_process()
