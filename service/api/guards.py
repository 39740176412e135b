"""What a request must pass before any work starts: the API key, a valid scene, the model-size and cost limits,
an optimisation problem that its cases will accept, finite numbers.

Each guard raises what :mod:`.errors` turns into a problem body: 401 (key), 422 (``RequestValidationError``
naming the field, or ``ComputationFailed`` for numbers that break the tables), :class:`TooCostly` (413, or a
job when the client accepts an asynchronous answer).
"""

from __future__ import annotations

import asyncio
import hmac
import math
import re
from collections.abc import Callable
from typing import Any

import numpy as np
from fastapi import Request, Security
from fastapi.exceptions import RequestValidationError
from fastapi.security import APIKeyHeader
from pydantic import ValidationError
from starlette.exceptions import HTTPException

from ..jobs import worker
from ..jobs.worker import ComputationFailed
from ..schemas import OptimisationProblem
from .settings import Settings

__all__ = [
    "TooCostly",
    "admit",
    "check_cost",
    "check_problem",
    "key_checker",
    "nonfinite",
    "scene_from",
    "seconds_per_point",
]


def seconds_per_point(dofs: int) -> float:
    """Estimated seconds per stroke point of the exact method for a model with ``dofs`` degrees of freedom,
    checked before a synchronous computation starts: ``1e-9 n^3 + 1e-4 n`` (dense eigen-analysis, plus a
    per-DOF overhead). Fitted to one measured series (leaf spring, 10 to 320 segments, 66 to 1926 DOFs, 5 points:
    0.011, 0.044, 1.0, 6.3 s per point at load average 7 on 2 cores, ``bench/bench_request_cost.py``), so
    it errs on the slow side on a quiet machine; it only has to keep requests that cannot finish in time off
    the request path."""
    return 1e-9 * dofs**3 + 1e-4 * dofs


def key_checker(settings: Settings) -> Callable[..., None]:
    """A dependency checking the API key header when keys are configured (constant-time comparison).

    Declared through ``APIKeyHeader`` so the OpenAPI document shows the security scheme.
    """
    header = APIKeyHeader(
        name=settings.api_key_header,
        auto_error=False,
        description="API key; required only when the server has FLEXOPT_API_KEYS set",
    )

    def require_key(request: Request, given: str | None = Security(header)) -> None:
        keys = settings.keys()
        if not keys:
            request.state.owner = ""
            return
        if not any(hmac.compare_digest((given or "").encode(), k.encode()) for k in keys):
            raise HTTPException(
                401,
                f"missing or invalid API key: send it in the '{settings.api_key_header}' header",
                headers={"WWW-Authenticate": "ApiKey"},
            )
        from ..jobs.store import owner_of

        request.state.owner = owner_of(given)  # jobs belong to the key that submitted them

    return require_key


#: the most field errors one 422 lists (the rest are counted)
MAX_ERRORS = 100


def scene_from(data: dict[str, Any]) -> Any:
    """Validate a scene document; errors are located inside the request's ``scene`` field."""
    from ...model.io import clean_errors
    from ...model.scene import Scene

    try:
        return Scene.model_validate(data)
    except ValidationError as exc:
        found = exc.errors(include_url=False)
        errs = [{**e, "loc": ("body", "scene", *e["loc"])} for e in clean_errors(found[:MAX_ERRORS])]
        if len(found) > MAX_ERRORS:  # a body of 40,000 unknown fields answers in 0.1 s, not 10 s of messages
            errs.append(
                {
                    "loc": ("body", "scene"),
                    "type": "value_error",
                    "msg": f"{len(found) - MAX_ERRORS} more errors not listed; fix the ones above first",
                }
            )
        raise RequestValidationError(errs) from None
    except Exception as exc:  # noqa: BLE001 - a validator's arithmetic broke on extreme numbers: named, not a 500
        _, err = worker.broken(exc, data)
        raise ComputationFailed(err["field"], err["message"]) from None


def _dofs(scene: Any) -> int:
    """Degrees of freedom of the meshed scene (``compile_scene``: numeric tables only, about a millisecond);
    the model-size limit (422) is checked here, and numbers that break the tables are named (422)."""
    from ...model.errors import FlexoptError
    from ...model.structure import compile_scene

    try:
        return compile_scene(scene).n_dof
    except FlexoptError:
        raise
    except Exception as exc:  # noqa: BLE001 - overflow and the like on extreme numbers: named, never a 500
        _, err = worker.broken(exc, scene.model_dump(mode="json"))
        raise ComputationFailed(err["field"], err["message"]) from None


def _auto_meshes(scene: Any) -> list[tuple[int, int]]:
    """``(segments, DOFs)`` of every mesh that ``segments: "auto"`` beams may be refined through
    (``model.mesh.resolve_auto_segments``: AUTO_START doubling to AUTO_MAX, while the model stays within
    MAX_DOFS); empty when no beam is "auto"."""
    from ...model.mesh import AUTO_MAX
    from ...model.scene import AUTO_START, Beam
    from ...model.structure import MAX_DOFS, compile_scene

    auto = [i for i, e in enumerate(scene.elements) if isinstance(e, Beam) and e.segments == "auto"]
    out: list[tuple[int, int]] = []
    n = AUTO_START
    while auto and n <= AUTO_MAX:
        els = list(scene.elements)
        for i in auto:
            els[i] = els[i].model_copy(update={"segments": n})
        st = compile_scene(scene.model_copy(update={"elements": tuple(els)}))
        if int(st.active.sum()) > MAX_DOFS:
            break
        out.append((n, st.n_dof))
        n *= 2
    return out


class TooCostly(Exception):
    """A synchronous computation estimated to exceed ``max_cost`` (413, or a job when the client asks)."""

    def __init__(self, seconds: float, message: str) -> None:
        super().__init__(message)
        self.seconds = seconds


def check_cost(scene: Any, stroke: list[float] | None, settings: Settings) -> None:
    """422 for more stroke points than allowed, :class:`TooCostly` for a computation estimated to exceed
    ``max_cost``."""
    loc: tuple[str, ...]
    if stroke is not None:
        points, loc = len(stroke), ("body", "stroke")
    elif scene.stroke is not None:
        points, loc = scene.stroke.points, ("body", "scene", "stroke", "points")
    else:  # no stroke (a scene for the diagnosis only): the model names the field (422), costed as one point
        points, loc = 1, ("body", "scene", "stroke")
    if not 1 <= points <= settings.max_stroke_points:
        raise RequestValidationError(
            [
                {
                    "loc": loc,
                    "type": "value_error",
                    "msg": f"{points} stroke points; give 1 to {settings.max_stroke_points}",
                }
            ]
        )
    dofs = _dofs(scene)
    seconds = seconds_per_point(dofs) * points
    what = f"{dofs} degrees of freedom x {points} stroke points"
    meshes = _auto_meshes(scene)
    if meshes:  # the worst mesh 'auto' may reach, plus the refinement's own solves (issue 29 item 4: a tiny
        # mesh_tolerance bypassed the limit, estimated at the 4-segment start mesh)
        from ...model.mesh import ESTIMATE_POINTS

        n, dofs = meshes[-1]
        refine = sum(seconds_per_point(d) for _, d in meshes) * (2 * ESTIMATE_POINTS + 1)
        seconds = seconds_per_point(dofs) * points + refine
        what = (
            f"segments 'auto' may refine to {n} per beam: {dofs} degrees of freedom x {points} stroke points, "
            f"plus {refine:.0f} s of refinement"
        )
    if seconds > settings.max_cost:
        raise TooCostly(
            seconds,
            f"estimated cost {seconds:.0f} s ({what}) exceeds this server's limit of "
            f"{settings.max_cost:g} s for a request; send 'Prefer: respond-async' to run it "
            "as a job, or use fewer stroke points or fewer (explicit) segments",
        )


async def admit(data: dict[str, Any], stroke: list[float] | None, settings: Settings) -> Any:
    """The validated scene of a request whose cost :func:`check_cost` accepts, both checked in a worker thread:
    validation is pure Python whose time grows with the body (up to about a second for 1 MB), and on the event
    loop it held every route, ``/health`` included (issue 29 item 3)."""

    def both() -> Any:
        scene = scene_from(data)
        check_cost(scene, stroke, settings)
        return scene

    return await asyncio.to_thread(both)


def nonfinite(obj: Any, loc: tuple = ()) -> tuple | None:
    """The location of the first NaN or infinite number in a JSON-like value, or None."""
    if isinstance(obj, dict):
        return next((r for k, v in obj.items() if (r := nonfinite(v, (*loc, k))) is not None), None)
    if isinstance(obj, (list, tuple)):
        return next((r for i, v in enumerate(obj) if (r := nonfinite(v, (*loc, i))) is not None), None)
    if isinstance(obj, float) and not math.isfinite(obj):
        return loc
    return None


def check_problem(spec: OptimisationProblem) -> None:
    """Everything the job's cases would check, done at submission (422 naming the field): finite numbers,
    each family as the optimiser builds it (``optim.search.FamilyEvaluator``), design parameters that are real
    numbers, and the scene of every family at both corners of its design box (template, scene validation,
    model size)."""
    from ...model import TEMPLATES, template
    from ...model.errors import FlexoptError, SceneError
    from ...model.structure import compile_scene
    from ...optim.search import FamilyEvaluator

    def bad(loc: tuple, msg: str) -> RequestValidationError:
        return RequestValidationError([{"loc": ("body", *loc), "type": "value_error", "msg": msg}])

    where = nonfinite(spec.model_dump())
    if where is not None:
        raise bad(where, "must be a finite number (Infinity and NaN are not accepted)")
    for i, fam in enumerate(spec.families):
        try:
            built = FamilyEvaluator(spec, fam)
        except FlexoptError as exc:
            path = str(exc).split(":")[0].removeprefix("families[].").split(".")  # e.g. design.thickness
            raise bad(
                ("families", i, *path) if path[0] in ("template", "design") else ("families", i), str(exc)
            ) from None
        defaults = TEMPLATES[fam.template][1]
        for k in fam.design:
            if not isinstance(defaults[k], float):
                raise bad(
                    ("families", i, "design", k),
                    f"'{k}' is not a real-valued parameter of template "
                    f"'{fam.template}' (default {defaults[k]!r}); set it in 'fixed' instead",
                )
        for corner in (0.0, 1.0):
            params = built.params(np.full(len(built.names), corner))
            try:
                compile_scene(template(fam.template, **params))
            except SceneError as exc:
                # the scene's field (elements[0].beam.segments) named by the template parameter it comes from
                field = exc.field or exc.message.split(":")[0]  # a pydantic error's path leads the message
                parts = [p for p in re.split(r"[.\[\]]", field.removeprefix("template.")) if p][-1:]
                key = parts[0] if parts else ""
                loc = (
                    ("families", i, "fixed", key)
                    if key in fam.fixed
                    else (("families", i, "design", key) if key in fam.design else ("families", i))
                )
                raise bad(
                    loc, f"{exc.message} (at the {'lower' if corner == 0 else 'upper'} corner of the design box)"
                ) from None
            except FlexoptError as exc:
                raise bad(("families", i), str(exc)) from None
            except (ArithmeticError, ValueError) as exc:  # a bound such as 1e308 overflows the section's
                # arithmetic: named, not a 500 (issue 29 item 8)
                side = "lower" if corner == 0 else "upper"
                values = ", ".join(f"{k} = {params[k]:g}" for k in fam.design)
                raise bad(
                    ("families", i, "design"),
                    f"the scene at the {side} corner of the design box ({values}) "
                    f"cannot be computed ({type(exc).__name__}: numbers out of range); narrow the bounds "
                    "to physical values",
                ) from None
