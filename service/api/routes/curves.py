"""``POST /v1/frequency-curve``: stroke-dependent natural frequencies of a scene (JSON, CSV or PNG).

Identical requests are answered from the runtime's LRU cache; a request too costly for the request path
becomes a job when the client sends ``Prefer: respond-async``.
"""

from __future__ import annotations

import asyncio
import hashlib
import json

from fastapi import APIRouter, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, Response
from starlette.exceptions import HTTPException

from ...jobs import worker
from ...schemas import FrequencyCurveOut, FrequencyCurveRequest, Job
from ..errors import HEAVY
from ..guards import TooCostly, check_cost, scene_from
from ..runtime import job_store, runtime

__all__ = ["router"]


def _accepted(request: Request) -> str:
    accept = request.headers.get("accept", "")
    for media in ("text/csv", "image/png"):
        if media in accept:
            return media
    return "application/json"


def router(prefix: str) -> APIRouter:
    """The frequency-curve route (under ``prefix``, ``/v1``)."""
    r = APIRouter(prefix=prefix)

    @r.post(
        "/frequency-curve",
        summary="Stroke-dependent natural frequencies of a scene",
        response_model=FrequencyCurveOut,
        responses={
            200: {
                "content": {
                    "text/csv": {"schema": {"type": "string"}},
                    "image/png": {"schema": {"type": "string", "format": "binary"}},
                },
                "description": "JSON by default; CSV with Accept: text/csv; PNG with Accept: image/png",
            },
            202: {
                "model": Job,
                "description": "too costly for a request and 'Prefer: respond-async' sent: "
                "run as a job (Location; its result is the curve's JSON)",
            },
            **HEAVY,
        },
    )
    async def frequency_curve(req: FrequencyCurveRequest, request: Request) -> Response:
        rt = runtime(request)
        if req.stroke is not None and not 1 <= len(req.stroke) <= rt.settings.max_stroke_points:
            raise RequestValidationError(
                [
                    {
                        "loc": ("body", "stroke"),
                        "type": "value_error",
                        "msg": f"give 1 to {rt.settings.max_stroke_points} stroke values",
                    }
                ]
            )
        media = _accepted(request)
        # one cache per API key: a hit is never another key's computation, whose speed would tell that key's
        # scenes to this one (issue 29 item 9)
        try:
            key = hashlib.sha256(
                json.dumps([request.state.owner, req.model_dump(mode="json"), media], sort_keys=True).encode()
            ).hexdigest()
        except (ValueError, RecursionError):  # nested too deeply to serialise: the scene's validation says where
            await asyncio.to_thread(scene_from, req.scene)
            raise RequestValidationError(
                [
                    {
                        "loc": ("body", "scene"),
                        "type": "value_error",
                        "msg": "nested too deeply; a scene is a few levels deep",
                    }
                ]
            ) from None
        hit = rt.cached(key)  # only validated scenes are ever stored, so a hit needs no re-validation
        if hit is None:
            scene = await asyncio.to_thread(scene_from, req.scene)  # off the event loop (issue 29 item 3)
            spec = {
                "scene": scene.model_dump(mode="json"),
                "stroke": req.stroke,
                "method": req.method,
                "tolerance": req.tolerance,
                "media": media,
                "shapes": req.shapes,
            }
            try:
                await asyncio.to_thread(check_cost, scene, req.stroke, rt.settings)
            except TooCostly as exc:  # large models go to a job when the client accepts an asynchronous answer
                if "respond-async" not in request.headers.get("prefer", "") or exc.seconds > rt.settings.max_job_cost:
                    raise HTTPException(413, str(exc)) from None
                estimate = {
                    "seconds": round(exc.seconds, 1),
                    "cases": 1,
                    "what": "one frequency curve",
                    "drivers": ["stroke points", "segments"],
                    "limit": rt.settings.max_job_cost,
                }
                job, _ = await asyncio.to_thread(
                    job_store(request).submit,
                    {**spec, "kind": "frequency-curve", "media": "application/json"},
                    None,
                    request.state.owner,
                    rt.settings.max_active_jobs,
                    estimate,
                )
                return JSONResponse(
                    Job(**job).model_dump(mode="json"),
                    status_code=202,
                    headers={"Location": f"/v1/optimisations/{job['id']}", "Preference-Applied": "respond-async"},
                )
            hit = await rt.run(worker.curve, json.dumps(spec))
            rt.store(key, hit)
        return Response(hit, media_type=media)

    return r
