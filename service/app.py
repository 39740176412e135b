"""The flexopt HTTP service: ``create_app(settings=None)`` builds the FastAPI application.

Routes are thin: validate, run the model in the worker pool (never on the event loop), return wire models.
The lifespan owns the runtime state: the worker process pool (service.worker functions of a JSON spec), the
slots bounding concurrent heavy computations and the bounded LRU cache of identical frequency-curve requests. Exceptions become problem-details bodies in errors_http only.

Jobs: ``store`` (SQLAlchemy table, owners, leases), ``dispatch`` (job processes, retries), ``jobs`` (the job
process). Request ids, JSON access logs and 415: ``middleware``.

Regenerate the committed schema with ``python -m flexopt.service.app > service/openapi.json``.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import hashlib
import hmac
import json
import math
import multiprocessing
import re
import threading
from collections import OrderedDict
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from importlib.metadata import PackageNotFoundError, version
from typing import Any

import numpy as np
from fastapi import APIRouter, Depends, FastAPI, Header, Query, Request, Security
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, Response
from fastapi.security import APIKeyHeader
from fastapi_offline import FastAPIOffline
from pydantic import ValidationError
from starlette.exceptions import HTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from ..optim.topology.spec import TopologySpec, example_spec  # pydantic only (no CasADi)
from . import errors_http, worker
from .errors_http import Busy, ComputationFailed, ComputeTimeout
from .middleware import JsonOnly, RequestLog
from .schemas import (
    DiagnosisRequest,
    FrequencyCurveOut,
    FrequencyCurveRequest,
    Health,
    Job,
    JobPage,
    OptimisationProblem,
    ParameterInfo,
    Problem,
    TemplateInfo,
    TemplateSceneRequest,
)
from .settings import Settings

__all__ = ["Runtime", "create_app", "seconds_per_point"]


def seconds_per_point(dofs: int) -> float:
    """Estimated seconds per stroke point of the exact method for a model with ``dofs`` degrees of freedom,
    checked before a synchronous computation starts: ``1e-9 n^3 + 1e-4 n`` (dense eigen-analysis, plus a
    per-DOF overhead). Fitted to one measured series (leaf spring, 10 to 320 segments, 66 to 1926 DOFs, 5 points:
    0.011, 0.044, 1.0, 6.3 s per point at load average 7 on 2 cores, ``bench/bench_request_cost.py``), so
    it errs on the slow side on a quiet machine; it only has to keep requests that cannot finish in time off
    the request path."""
    return 1e-9 * dofs**3 + 1e-4 * dofs

def _package_version() -> str:
    try:
        return version("flexopt")
    except PackageNotFoundError:  # pragma: no cover - running from a source tree without install
        return "0+unknown"


@dataclass
class Runtime:
    """Per-application state owned by the lifespan.

    Heavy computations: at most ``max_concurrent`` run at once (one worker process, or thread, each); up to ``max_queued``
    more wait at most ``queue_timeout`` seconds for a slot; anything past that gets 429 with Retry-After.
    A slot is given back when the computation really ends, also for a computation abandoned at the time
    limit (the computation is not interrupted), so the CPU is never oversubscribed.
    """

    settings: Settings
    waiting: int = 0  # requests queued for a slot
    lock: threading.Lock = field(default_factory=threading.Lock)
    cache: OrderedDict[str, Any] = field(default_factory=OrderedDict)  # canonical request -> result (LRU)
    _slots: asyncio.Semaphore | None = None
    pool: concurrent.futures.ProcessPoolExecutor | None = None
    jobs: Any = None  # service.store.JobStore, opened by start()
    dispatcher: Any = None  # service.dispatch.Dispatcher

    def slots(self) -> asyncio.Semaphore:
        """The slot semaphore, created on first use inside the server's event loop."""
        if self._slots is None:
            self._slots = asyncio.Semaphore(self.settings.max_concurrent)
        return self._slots

    def cached(self, key: str) -> Any | None:
        """The cached result for ``key`` (marking it recently used), or None."""
        with self.lock:
            if key in self.cache:
                self.cache.move_to_end(key)
                return self.cache[key]
        return None

    def store(self, key: str, value: Any) -> None:
        """Cache ``value``; the least recently used entry goes once the cache is full."""
        if self.settings.cache_size <= 0:
            return
        with self.lock:
            self.cache[key] = value
            self.cache.move_to_end(key)
            while len(self.cache) > self.settings.cache_size:
                self.cache.popitem(last=False)

    async def _acquire(self) -> None:
        s = self.settings
        slots = self.slots()
        if not slots.locked():
            await slots.acquire()
            return
        busy = Busy(s.retry_after, s.max_concurrent)
        if self.waiting >= s.max_queued or s.queue_timeout <= 0:
            raise busy
        self.waiting += 1
        try:
            await asyncio.wait_for(slots.acquire(), s.queue_timeout)
        except TimeoutError:
            raise busy from None
        finally:
            self.waiting -= 1

    async def run(self, fn: Callable[[str], tuple[bool, Any]], spec: str) -> Any:
        """``fn(spec)`` in the worker pool within the slot limit (429) and the time limit (504).

        ``fn`` is a :mod:`service.worker` function; a model error it reports is raised here again.
        """
        s = self.settings
        await self._acquire()
        loop = asyncio.get_running_loop()
        release = self.slots().release
        if self.pool is not None:
            try:
                future = self.pool.submit(fn, spec)
            except concurrent.futures.BrokenExecutor:  # a worker died: replace the pool, once
                self.slots().release()
                self._new_pool()
                return await self.run(fn, spec)
        else:
            future = concurrent.futures.Future()

            def in_thread() -> None:
                try:
                    future.set_result(fn(spec))
                except BaseException as exc:  # noqa: BLE001 - handed to the awaiting request
                    future.set_exception(exc)

            threading.Thread(target=in_thread, daemon=True, name="flexopt-compute").start()
        # The slot is released when the work really ends (not when the request gives up at the time limit).
        future.add_done_callback(lambda _: loop.call_soon_threadsafe(release))
        try:
            ok, payload = await asyncio.wait_for(asyncio.shield(asyncio.wrap_future(future)), s.request_timeout)
        except TimeoutError:
            future.cancel()  # drops it if still queued in the pool; a running computation finishes on its own
            raise ComputeTimeout(s.request_timeout) from None
        except concurrent.futures.BrokenExecutor:  # the worker running it died (killed, out of memory)
            self._new_pool()
            raise ComputationFailed([], "the worker process computing this request died (out of memory or "
                                        "killed); retry, or use fewer stroke points or a smaller model") from None
        if not ok:
            worker.raise_error(payload)
        return payload

    def _new_pool(self) -> None:
        old, self.pool = self.pool, None
        if old is not None:
            old.shutdown(wait=False, cancel_futures=True)
        ctx = multiprocessing.get_context("spawn")  # never fork the threaded server
        self.pool = concurrent.futures.ProcessPoolExecutor(self.settings.max_concurrent, mp_context=ctx,
                                                           initializer=worker.warm_up)

    def start(self) -> None:
        """Open the job store (a corrupt one raises ``store.StoreCorrupt``), start the pool and the dispatcher."""
        from .dispatch import Dispatcher
        from .store import JobStore

        s = self.settings
        self.jobs = JobStore(s.job_store_url(), s.data_dir, s.lease_seconds)
        if s.executor == "process":
            self._new_pool()
        self.dispatcher = Dispatcher(self.jobs, s.max_jobs, s.job_workers or None, s.job_stop_timeout)
        self.dispatcher.start()  # jobs whose lease expired (their server and process gone) are requeued

    def not_ready(self) -> list[str]:
        """Why the service cannot take work now (empty: ready): the store, the dispatcher, the pool."""
        from .store import StoreUnavailable

        out = []
        if self.jobs is None:
            out.append("the job store is not open")
        else:
            try:
                self.jobs.ping()
            except StoreUnavailable as exc:
                out.append(str(exc))
        if self.dispatcher is not None and (why := self.dispatcher.healthy()):
            out.append(why)
        if self.settings.executor == "process" and self.pool is None:
            out.append("the worker pool is not running")
        return out

    def stop(self) -> None:
        """Stop the job dispatcher (running jobs resume at the next start), the pool, and drop the cache."""
        if self.dispatcher is not None:
            self.dispatcher.stop()
            self.dispatcher = None
        if self.pool is not None:
            # Queued work is dropped and running computations are ended: their requests were answered or cut
            # when the server stopped listening, and waiting for them would outlast a container's stop grace.
            workers = list(getattr(self.pool, "_processes", {}).values())
            self.pool.shutdown(wait=False, cancel_futures=True)
            for p in workers:
                p.terminate()
            for p in workers:
                p.join(5)
            self.pool.shutdown(wait=True)  # the pool's manager sees its workers gone and frees its queues
            self.pool = None
        self.cache.clear()


class BodyLimit:
    """ASGI middleware: 413 for request bodies larger than ``limit`` bytes (declared or streamed)."""

    def __init__(self, app: ASGIApp, limit: int) -> None:
        self.app = app
        self.limit = limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        too_large = errors_http.problem(413, f"request body larger than the limit of {self.limit} bytes")
        declared = dict(scope["headers"]).get(b"content-length")
        if declared is not None and declared.isdigit() and int(declared) > self.limit:
            await too_large(scope, receive, send)
            return
        body = bytearray()
        while True:
            msg = await receive()
            if msg["type"] == "http.disconnect":
                return
            body += msg.get("body", b"")
            if len(body) > self.limit:
                await too_large(scope, receive, send)
                return
            if not msg.get("more_body", False):
                break
        replayed = False

        async def replay() -> Message:
            nonlocal replayed
            if not replayed:
                replayed = True
                return {"type": "http.request", "body": bytes(body), "more_body": False}
            return await receive()

        await self.app(scope, replay, send)


def _runtime(request: Request) -> Runtime:
    return request.app.state.runtime


def _key_checker(settings: Settings) -> Callable[..., None]:
    """A dependency checking the API key header when keys are configured (constant-time comparison).

    Declared through ``APIKeyHeader`` so the OpenAPI document shows the security scheme.
    """
    header = APIKeyHeader(name=settings.api_key_header, auto_error=False,
                          description="API key; required only when the server has FLEXOPT_API_KEYS set")

    def require_key(request: Request, given: str | None = Security(header)) -> None:
        keys = settings.keys()
        if not keys:
            request.state.owner = ""
            return
        if not any(hmac.compare_digest((given or "").encode(), k.encode()) for k in keys):
            raise HTTPException(401, f"missing or invalid API key: send it in the '{settings.api_key_header}' "
                                     "header", headers={"WWW-Authenticate": "ApiKey"})
        from .store import owner_of

        request.state.owner = owner_of(given)  # jobs belong to the key that submitted them

    return require_key


_ERRORS: dict[int | str, dict[str, Any]] = {
    422: {"model": Problem, "description": "invalid input (field path and reason in errors)"},
    401: {"model": Problem, "description": "API key missing or invalid (when keys are configured)"},
    413: {"model": Problem, "description": "request body too large"},
}
_HEAVY: dict[int | str, dict[str, Any]] = {
    **_ERRORS,
    429: {"model": Problem, "description": "too many concurrent computations; see Retry-After"},
    504: {"model": Problem, "description": "the computation exceeded the time limit"},
}


def _scene(data: dict[str, Any]) -> Any:
    """Validate a scene document; errors are located inside the request's ``scene`` field."""
    from ..model.io import clean_errors
    from ..model.scene import Scene

    try:
        return Scene.model_validate(data)
    except ValidationError as exc:
        errs = [{**e, "loc": ("body", "scene", *e["loc"])} for e in clean_errors(exc.errors(include_url=False))]
        raise RequestValidationError(errs) from None
    except Exception as exc:  # noqa: BLE001 - a validator's arithmetic broke on extreme numbers: named, not a 500
        ok, err = worker._broken(exc, data)
        raise ComputationFailed(err["field"], err["message"]) from None


def _dofs(scene: Any) -> int:
    """Degrees of freedom of the meshed scene (``compile_scene``: numeric tables only, about a millisecond);
    the model-size limit (422) is checked here, and numbers that break the tables are named (422)."""
    from ..model.errors import FlexoptError
    from ..model.structure import compile_scene

    try:
        return compile_scene(scene).n_dof
    except FlexoptError:
        raise
    except Exception as exc:  # noqa: BLE001 - overflow and the like on extreme numbers: named, never a 500
        ok, err = worker._broken(exc, scene.model_dump(mode="json"))
        raise ComputationFailed(err["field"], err["message"]) from None


class TooCostly(Exception):
    """A synchronous computation estimated to exceed ``max_cost`` (413, or a job when the client asks)."""

    def __init__(self, seconds: float, message: str) -> None:
        super().__init__(message)
        self.seconds = seconds


def _check_cost(scene: Any, stroke: list[float] | None, settings: Settings) -> None:
    """422 for more stroke points than allowed, :class:`TooCostly` for a computation estimated to exceed
    ``max_cost``."""
    points, loc = (len(stroke), ("body", "stroke")) if stroke is not None else (
        scene.stroke.points, ("body", "scene", "stroke", "points"))
    if not 1 <= points <= settings.max_stroke_points:
        raise RequestValidationError([{"loc": loc, "type": "value_error",
                                       "msg": f"{points} stroke points; give 1 to {settings.max_stroke_points}"}])
    dofs = _dofs(scene)
    seconds = seconds_per_point(dofs) * points
    if seconds > settings.max_cost:
        raise TooCostly(seconds, f"estimated cost {seconds:.0f} s ({dofs} degrees of freedom x {points} stroke "
                                 f"points) exceeds this server's limit of {settings.max_cost:g} s for a request; "
                                 "send 'Prefer: respond-async' to run it as a job, or use fewer stroke points or "
                                 "fewer segments")


def _accepted(request: Request) -> str:
    accept = request.headers.get("accept", "")
    for media in ("text/csv", "image/png"):
        if media in accept:
            return media
    return "application/json"


def _parameter_info(name: str, default: Any, unit: str | None = None) -> ParameterInfo:
    if isinstance(default, str):
        from typing import get_args

        from ..model.scene import RectangularSection

        choices = get_args(RectangularSection.model_fields[name].annotation) if (
            name in RectangularSection.model_fields) else ()
        bounds = f"one of {', '.join(choices)}" if choices else "string"
        return ParameterInfo(name=name, type="string", default=default, bounds=bounds)
    if isinstance(default, int):
        return ParameterInfo(name=name, type="integer", default=default, bounds="integer >= 1 (a count)")
    bounds = "any real number (signed offset)" if "offset" in name else "positive (> 0)"
    if unit:
        bounds += f"; a number in {unit} or a string with a unit, e.g. '{default:g} {unit}'"
    return ParameterInfo(name=name, type="number", default=float(default), bounds=bounds)


def _unknown_template(name: str) -> str:
    from ..model.errors import SceneError
    from ..model.templates import template_parameters

    try:
        template_parameters(name)
    except SceneError as exc:
        return exc.message  # "unknown template 'x' (did you mean 'y'?); choose one of ..."
    return f"unknown template '{name}'"  # pragma: no cover - only called for unknown names


def _template_info(name: str) -> TemplateInfo:
    from ..model import template_parameters

    from ..model.templates import parameter_unit

    params = template_parameters(name)
    return TemplateInfo(name=name, parameters=[_parameter_info(k, v, parameter_unit(name, k))
                                               for k, v in params.items()])


def _methods() -> list[str]:
    try:
        from ..model import methods

        return list(getattr(methods, "METHODS", ("exact",)))
    except ImportError:  # pragma: no cover - before model.methods lands
        return ["exact"]


def _diagnosis_available() -> bool:
    try:
        from ..model.diagnosis import diagnose  # noqa: F401
    except ImportError:  # pragma: no cover - before model.constraints lands
        return False
    return True


def _nonfinite(obj: Any, loc: tuple = ()) -> tuple | None:
    """The location of the first NaN or infinite number in a JSON-like value, or None."""
    if isinstance(obj, dict):
        return next((r for k, v in obj.items() if (r := _nonfinite(v, (*loc, k))) is not None), None)
    if isinstance(obj, (list, tuple)):
        return next((r for i, v in enumerate(obj) if (r := _nonfinite(v, (*loc, i))) is not None), None)
    if isinstance(obj, float) and not math.isfinite(obj):
        return loc
    return None


def _check_problem(spec: OptimisationProblem) -> None:
    """Everything the job's cases would check, done at submission (422 naming the field): finite numbers,
    each family as the optimiser builds it (``optim.search._Family``), design parameters that are real
    numbers, and the scene of every family at both corners of its design box (template, scene validation,
    model size)."""
    from ..model import TEMPLATES, template
    from ..model.errors import FlexoptError, SceneError
    from ..model.structure import compile_scene
    from ..optim.search import _Family

    def bad(loc: tuple, msg: str) -> RequestValidationError:
        return RequestValidationError([{"loc": ("body", *loc), "type": "value_error", "msg": msg}])

    where = _nonfinite(spec.model_dump())
    if where is not None:
        raise bad(where, "must be a finite number (Infinity and NaN are not accepted)")
    for i, fam in enumerate(spec.families):
        try:
            built = _Family(spec, fam)
        except FlexoptError as exc:
            path = str(exc).split(":")[0].removeprefix("families[].").split(".")  # e.g. design.thickness
            raise bad(("families", i, *path) if path[0] in ("template", "design") else ("families", i),
                      str(exc)) from None
        defaults = TEMPLATES[fam.template][1]
        for k in fam.design:
            if not isinstance(defaults[k], float):
                raise bad(("families", i, "design", k), f"'{k}' is not a real-valued parameter of template "
                          f"'{fam.template}' (default {defaults[k]!r}); set it in 'fixed' instead")
        for corner in (0.0, 1.0):
            params = built.params(np.full(len(built.names), corner))
            try:
                compile_scene(template(fam.template, **params))
            except SceneError as exc:
                # the scene's field (elements[0].beam.segments) named by the template parameter it comes from
                path = exc.field or exc.message.split(":")[0]  # a pydantic error's path leads the message
                key = [p for p in re.split(r"[.\[\]]", path.removeprefix("template.")) if p][-1:]
                key = key[0] if key else ""
                loc = ("families", i, "fixed", key) if key in fam.fixed else (
                    ("families", i, "design", key) if key in fam.design else ("families", i))
                raise bad(loc, f"{exc.message} (at the {'lower' if corner == 0 else 'upper'} corner of the design "
                               "box)") from None
            except FlexoptError as exc:
                raise bad(("families", i), str(exc)) from None


def _router(settings: Settings) -> APIRouter:
    v1 = APIRouter(prefix="/v1", dependencies=[Depends(_key_checker(settings))], responses={401: _ERRORS[401]})

    @v1.get("/templates", response_model=list[TemplateInfo], summary="List parametric templates")
    async def list_templates() -> list[TemplateInfo]:
        from ..model import TEMPLATES

        return [_template_info(n) for n in sorted(TEMPLATES)]

    @v1.get("/templates/{name}", response_model=TemplateInfo, summary="One template: parameters, defaults, bounds",
            responses={404: {"model": Problem}})
    async def get_template(name: str) -> TemplateInfo:
        from ..model import TEMPLATES

        if name not in TEMPLATES:
            raise HTTPException(404, _unknown_template(name))
        return _template_info(name)

    @v1.post("/templates/{name}/scene", summary="The scene of a template with parameters overridden",
             response_model=dict[str, Any], responses={404: {"model": Problem}, **_ERRORS})
    async def template_scene(name: str, body: TemplateSceneRequest | None = None) -> JSONResponse:
        from ..model import TEMPLATES, template
        from ..model.errors import SceneError

        if name not in TEMPLATES:
            raise HTTPException(404, _unknown_template(name))
        params = body.parameters if body is not None else {}
        try:
            scene = template(name, **params)
        except SceneError as exc:
            key = exc.field.removeprefix("template.")
            loc = ("body", "parameters", key) if exc.field.startswith("template.") else ("body", "parameters")
            raise RequestValidationError([{"loc": loc, "msg": exc.message, "type": "value_error"}]) from None
        return JSONResponse(scene.model_dump(mode="json"))

    @v1.get("/scene-schema", summary="JSON schema of a scene", response_model=dict[str, Any])
    async def scene_schema() -> dict[str, Any]:
        from ..model.scene import Scene

        return Scene.model_json_schema()

    @v1.post(
        "/frequency-curve",
        summary="Stroke-dependent natural frequencies of a scene",
        response_model=FrequencyCurveOut,
        responses={200: {"content": {"text/csv": {"schema": {"type": "string"}},
                                     "image/png": {"schema": {"type": "string", "format": "binary"}}},
                         "description": "JSON by default; CSV with Accept: text/csv; PNG with Accept: image/png"},
                   202: {"model": Job, "description": "too costly for a request and 'Prefer: respond-async' sent: "
                                                      "run as a job (Location; its result is the curve's JSON)"},
                   **_HEAVY},
    )
    async def frequency_curve(req: FrequencyCurveRequest, request: Request) -> Response:
        rt = _runtime(request)
        if req.stroke is not None and not 1 <= len(req.stroke) <= rt.settings.max_stroke_points:
            raise RequestValidationError([{"loc": ("body", "stroke"), "type": "value_error",
                                           "msg": f"give 1 to {rt.settings.max_stroke_points} stroke values"}])
        available = _methods()
        if req.method not in available:
            raise RequestValidationError([{"loc": ("body", "method"), "type": "value_error",
                                           "msg": f"method '{req.method}' is not available on this server; "
                                                  f"choose one of {', '.join(available)}"}])
        media = _accepted(request)
        key = hashlib.sha256(json.dumps([req.model_dump(mode="json"), media], sort_keys=True).encode()).hexdigest()
        hit = rt.cached(key)  # only validated scenes are ever stored, so a hit needs no re-validation
        if hit is None:
            scene = _scene(req.scene)
            spec = {"scene": scene.model_dump(mode="json"), "stroke": req.stroke, "method": req.method,
                    "tolerance": req.tolerance, "media": media, "shapes": req.shapes}
            try:
                _check_cost(scene, req.stroke, rt.settings)
            except TooCostly as exc:  # large models go to a job when the client accepts an asynchronous answer
                if "respond-async" not in request.headers.get("prefer", "") or exc.seconds > rt.settings.max_job_cost:
                    raise HTTPException(413, str(exc)) from None
                job, _ = await asyncio.to_thread(_store(request).submit,
                                                 {**spec, "kind": "frequency-curve", "media": "application/json"},
                                                 None, request.state.owner, rt.settings.max_active_jobs)
                return JSONResponse(Job(**job).model_dump(mode="json"), status_code=202,
                                    headers={"Location": f"/v1/optimisations/{job['id']}",
                                             "Preference-Applied": "respond-async"})
            hit = await rt.run(worker.curve, json.dumps(spec))
            rt.store(key, hit)
        return Response(hit, media_type=media)

    if _diagnosis_available():
        @v1.post("/diagnosis", summary="Exact-constraint diagnosis of a scene (D_cc, SVD, Table-1 class)",
                 response_model=dict[str, Any], responses=_HEAVY)
        async def diagnosis(req: DiagnosisRequest, request: Request) -> Response:
            rt = _runtime(request)
            scene = _scene(req.scene)
            _check_cost(scene, [0.0], rt.settings)
            spec = {"scene": scene.model_dump(mode="json"), "at_stroke": req.at_stroke, "kinematic": req.kinematic}
            return Response(await rt.run(worker.diagnosis, json.dumps(spec)), media_type="application/json")

    def _store(request: Request) -> Any:
        store = _runtime(request).jobs
        if store is None:  # pragma: no cover - only before the lifespan started
            raise HTTPException(503, "the job store is not open yet; retry")
        return store

    async def _submit(request: Request, response: Response, body: dict, idempotency_key: str | None,
                      collection: str) -> Job:
        """Store a job (or find the one this idempotency key made), point Location at it, log a new one."""
        job, created = await asyncio.to_thread(_store(request).submit, body, idempotency_key, request.state.owner,
                                               _runtime(request).settings.max_active_jobs)
        response.headers["Location"] = f"/v1/{collection}/{job['id']}"
        if created:
            errors_http.log.info("job submitted", extra={"event": "job.submitted", "job_id": job["id"],
                                                         "request_id": request.state.request_id})
        return Job(**job)

    _JOBS = {503: {"model": Problem, "description": "the job store is unavailable; see Retry-After"}}

    @v1.post("/optimisations", status_code=202, response_model=Job, summary="Submit an optimisation job",
             responses={**_ERRORS, **_JOBS, 429: {"model": Problem, "description": "too many unfinished jobs "
                                                                                   "of this API key"}})
    async def submit_optimisation(spec: OptimisationProblem, request: Request, response: Response,
                                  idempotency_key: str | None = Header(default=None, max_length=200)) -> Job:
        await asyncio.to_thread(_check_problem, spec)  # fail now, not in the job
        return await _submit(request, response, spec.model_dump(mode="json"), idempotency_key, "optimisations")

    @v1.get("/optimisations/{job_id}", response_model=Job, summary="Status, progress, partial and final results",
            responses={404: {"model": Problem}, **_JOBS})
    async def get_optimisation(job_id: str, request: Request) -> Job:
        job = await asyncio.to_thread(_store(request).get, job_id, request.state.owner)
        if job is None:
            raise HTTPException(404, f"no optimisation job '{job_id}'")
        return Job(**job)

    @v1.get("/optimisations", response_model=JobPage, summary="Optimisation jobs of this API key, newest first",
            responses=_JOBS)
    async def list_optimisations(request: Request, offset: int = Query(0, ge=0, le=1_000_000_000),
                                 limit: int = Query(20, ge=1, le=100)) -> JobPage:
        items, total = await asyncio.to_thread(_store(request).page, offset, limit, request.state.owner)
        return JobPage(items=[Job(**j) for j in items], total=total, offset=offset, limit=limit)

    @v1.delete("/optimisations/{job_id}", response_model=Job,
               summary="Cancel an unfinished job (queued: at once; running: after the cases in progress), or "
                       "remove a finished one and its files", responses={404: {"model": Problem}, **_JOBS})
    async def cancel_optimisation(job_id: str, request: Request) -> Job:
        job = await asyncio.to_thread(_store(request).delete, job_id, request.state.owner)
        if job is None:
            raise HTTPException(404, f"no optimisation job '{job_id}'")
        errors_http.log.info("job deleted or cancelled", extra={"event": "job.delete", "job_id": job_id,
                                                                "status": job["status"],
                                                                "request_id": request.state.request_id})
        return Job(**job)

    # ------------------------------------------------------------------ topology searches (jobs of their own kind)
    _TOPO = "topology-search"

    def _topology_job(job: dict | None, job_id: str) -> Job:
        if job is None or job["kind"] != _TOPO:
            raise HTTPException(404, f"no topology search '{job_id}'")
        return Job(**job)

    @v1.get("/topology-searches/example", response_model=TopologySpec,
            summary="The default topology-search spec (TopologySpec defaults), to edit and submit")
    async def topology_example() -> dict[str, Any]:
        return example_spec()

    @v1.post("/topology-searches", status_code=202, response_model=Job,
             summary="Submit a topology search: generate, screen, optimise and rank hinge topologies as a job",
             responses={**_ERRORS, **_JOBS, 429: {"model": Problem, "description": "too many unfinished jobs "
                                                                                   "of this API key"}})
    async def submit_topology_search(spec: TopologySpec, request: Request, response: Response,
                                     idempotency_key: str | None = Header(default=None, max_length=200)) -> Job:
        body = spec.model_dump(mode="json")
        where = _nonfinite(spec.model_dump())  # the rest (bounds, descriptors) was checked by TopologySpec itself
        if where is not None:
            raise RequestValidationError([{"loc": ("body", *where), "type": "value_error",
                                           "msg": "must be a finite number (Infinity and NaN are not accepted)"}])
        return await _submit(request, response, {**body, "kind": _TOPO}, idempotency_key, "topology-searches")

    @v1.get("/topology-searches/{job_id}", response_model=Job, responses={404: {"model": Problem}, **_JOBS},
            summary="Status, progress {done, total} of the optimised cases, and the result once succeeded")
    async def get_topology_search(job_id: str, request: Request) -> Job:
        return _topology_job(await asyncio.to_thread(_store(request).get, job_id, request.state.owner), job_id)

    @v1.get("/topology-searches", response_model=JobPage, responses=_JOBS,
            summary="Topology searches of this API key, newest first")
    async def list_topology_searches(request: Request, offset: int = Query(0, ge=0, le=1_000_000_000),
                                     limit: int = Query(20, ge=1, le=100)) -> JobPage:
        items, total = await asyncio.to_thread(_store(request).page, offset, limit, request.state.owner, None, _TOPO)
        return JobPage(items=[Job(**j) for j in items], total=total, offset=offset, limit=limit)

    @v1.delete("/topology-searches/{job_id}", response_model=Job, responses={404: {"model": Problem}, **_JOBS},
               summary="Cancel an unfinished topology search (running: after the cases in progress), or remove "
                       "a finished one")
    async def cancel_topology_search(job_id: str, request: Request) -> Job:
        _topology_job(await asyncio.to_thread(_store(request).get, job_id, request.state.owner), job_id)
        job = await asyncio.to_thread(_store(request).delete, job_id, request.state.owner)
        if job is None:  # removed in between
            raise HTTPException(404, f"no topology search '{job_id}'")
        errors_http.log.info("job deleted or cancelled", extra={"event": "job.delete", "job_id": job_id,
                                                                "status": job["status"],
                                                                "request_id": request.state.request_id})
        return Job(**job)

    return v1


def create_app(settings: Settings | None = None) -> FastAPI:
    """The FastAPI application (settings from the environment unless given)."""
    settings = settings or Settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        rt = Runtime(settings)
        rt.start()
        app.state.runtime = rt
        try:
            yield
        finally:
            rt.stop()

    app = FastAPIOffline(title="flexopt", version=_package_version(), lifespan=lifespan,
                  description="Large-stroke flexure hinges: templates, scenes, stroke-dependent natural "
                              "frequencies and exact-constraint diagnosis. Errors are RFC 9457 problem details.")
    # The runtime also exists before startup so that in-process tools (schema export) work without a lifespan.
    app.state.runtime = Runtime(settings)
    errors_http.install(app)

    @app.get("/health", response_model=Health, summary="Liveness (the process answers), version and methods")
    async def health() -> Health:
        return Health(version=_package_version(), methods=_methods())

    @app.head("/health", summary="Liveness, without a body", operation_id="health_head")
    async def health_head() -> Response:
        return Response()

    _NOT_READY = {503: {"model": Problem, "description": "not ready; detail says what is missing"}}

    @app.get("/ready", response_model=Health, responses=_NOT_READY,
             summary="Readiness: the job store answers, the job dispatcher runs, the worker pool is up")
    async def ready(request: Request) -> Health:
        why = await asyncio.to_thread(_runtime(request).not_ready)
        if why:
            raise HTTPException(503, "not ready: " + "; ".join(why), headers={"Retry-After": "5"})
        return Health(version=_package_version(), methods=_methods())

    @app.head("/ready", summary="Readiness, without a body", operation_id="ready_head", responses=_NOT_READY)
    async def ready_head(request: Request) -> Response:
        await ready(request)
        return Response()

    app.include_router(_router(settings))
    from . import routes_shapes, web  # POST /v1/modes; the page at / and its static assets

    app.include_router(routes_shapes.router(), prefix="/v1", dependencies=[Depends(_key_checker(settings))],
                       responses={401: _ERRORS[401]})
    web.install(app)
    app.add_middleware(JsonOnly)  # inside BodyLimit: a body too large is 413 whatever its type
    app.add_middleware(BodyLimit, limit=settings.max_body_bytes)
    app.add_middleware(RequestLog)  # added last: the outermost layer, sees every request and exception
    app.openapi = lambda: _openapi(app)  # type: ignore[method-assign]
    return app


def _openapi(app: FastAPI) -> dict[str, Any]:
    """FastAPI's document, corrected to describe what the service really does (built once, then cached):
    error bodies are ``application/problem+json`` (RFC 9457) and every 422 is a :class:`Problem`; bodies that
    are not JSON get 415 and bodies that are not UTF-8 or not JSON get 400 (or 422); the API key is optional
    (only servers with keys configured ask for it); the ``scene`` of a request is the full scene schema, so
    that a client or a fuzzer can build valid scenes from the document alone."""
    if app.openapi_schema:
        return app.openapi_schema
    from fastapi.openapi.utils import get_openapi

    from ..model.scene import Scene

    doc = get_openapi(title=app.title, version=app.version, description=app.description, routes=app.routes)
    comps = doc.setdefault("components", {}).setdefault("schemas", {})
    scene = Scene.model_json_schema(ref_template="#/components/schemas/{model}")
    for name, sub in scene.pop("$defs", {}).items():
        if name in comps:  # pragma: no cover - a name clash would silently change another schema
            raise RuntimeError(f"scene schema part '{name}' clashes with an API schema")
        comps[name] = sub
    comps["Scene"] = scene
    for req in ("FrequencyCurveRequest", "DiagnosisRequest", "ModesRequest"):
        props = comps.get(req, {}).get("properties", {})
        if "scene" in props:
            props["scene"] = {"$ref": "#/components/schemas/Scene", "description": props["scene"].get("description", "")}
    comps.pop("HTTPValidationError", None)
    comps.pop("ValidationError", None)
    # two models are called Problem (the error body and optim's problem): pydantic names them Problem-Input
    # and Problem-Output by accident of use; give each its own name
    renames = {}
    for name in [k for k in comps if k.split("-")[0] == "Problem"]:
        is_error = {"detail", "errors", "status"} <= set(comps[name].get("properties", {}))
        renames[name] = "ProblemDetails" if is_error else "OptimisationProblem"
    text = json.dumps(doc)
    for old, new in renames.items():
        text = text.replace(f'"#/components/schemas/{old}"', f'"#/components/schemas/{new}"')
    doc = json.loads(text)
    comps = doc["components"]["schemas"]
    for old, new in renames.items():
        comps[new] = comps.pop(old)
    problem_ref = {"$ref": "#/components/schemas/ProblemDetails"}
    schemes = doc.get("components", {}).get("securitySchemes", {})
    for path_item in doc.get("paths", {}).values():
        for method, op in path_item.items():
            responses = op.setdefault("responses", {})
            if method in ("post", "put", "patch") and "requestBody" in op:
                responses.setdefault("400", {"description": "the body is not UTF-8 or not JSON"})
                responses.setdefault("415", {"description": "the body's Content-Type is not JSON"})
            for code, resp in responses.items():
                if code.isdigit() and int(code) >= 400:
                    resp["content"] = {"application/problem+json": {"schema": problem_ref}}
            if op.get("security") and schemes:  # keys are optional: no key is fine on a server without keys
                op["security"] = [*op["security"], {}]
    submit = doc["paths"].get("/v1/optimisations", {}).get("post")
    if submit is not None:  # the job id of a submission feeds the job's own operations (OpenAPI links)
        by_id = {op["operationId"]: op for op in doc["paths"].get("/v1/optimisations/{job_id}", {}).values()}
        submit["responses"]["202"]["links"] = {
            op_id.split("_v1_")[0]: {"operationId": op_id, "parameters": {"job_id": "$response.body#/id"}}
            for op_id in sorted(by_id)}
    app.openapi_schema = doc
    return doc


def openapi_json() -> str:
    """The OpenAPI document as committed in service/openapi.json (default settings)."""
    return json.dumps(create_app(Settings(api_keys="")).openapi(), indent=2, sort_keys=True) + "\n"


if __name__ == "__main__":  # pragma: no cover
    print(openapi_json(), end="")
