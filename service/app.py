"""The flexopt HTTP service: ``create_app(settings=None)`` builds the FastAPI application.

Routes are thin: validate, run the model in the worker pool (never on the event loop), return wire models.
The lifespan owns the runtime state: the worker process pool (service.worker functions of a JSON spec), the
slots bounding concurrent heavy computations and the bounded LRU cache of identical frequency-curve requests. Exceptions become problem-details bodies in errors_http only.

Regenerate the committed schema with ``python -m flexopt.service.app > service/openapi.json``.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import hashlib
import hmac
import json
import multiprocessing
import threading
from collections import OrderedDict
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from dataclasses import dataclass, field
from importlib.metadata import PackageNotFoundError, version
from typing import Any

from fastapi import APIRouter, Depends, FastAPI, Header, Query, Request, Security
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, Response
from fastapi.security import APIKeyHeader
from fastapi_offline import FastAPIOffline
from pydantic import ValidationError
from starlette.exceptions import HTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from . import errors_http, worker
from .errors_http import Busy, ComputeTimeout
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

__all__ = ["Runtime", "create_app"]

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
    jobs: Any = None  # service.jobs.JobStore, opened by start()
    dispatcher: Any = None  # service.jobs.Dispatcher

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
            future = self.pool.submit(fn, spec)
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
        if not ok:
            worker.raise_error(payload)
        return payload

    def start(self) -> None:
        """Start the worker pool (process executor)."""
        if self.settings.executor == "process":
            ctx = multiprocessing.get_context("spawn")  # never fork the threaded server
            self.pool = concurrent.futures.ProcessPoolExecutor(self.settings.max_concurrent, mp_context=ctx,
                                                               initializer=worker.warm_up)
        from .jobs import Dispatcher, JobStore

        self.jobs = JobStore(self.settings.job_store_url(), self.settings.data_dir)
        self.dispatcher = Dispatcher(self.jobs, self.settings.max_jobs, self.settings.job_workers or None)
        self.dispatcher.start()  # jobs left running by a stopped server are requeued (or failed) first

    def stop(self) -> None:
        """Stop the job dispatcher (running jobs resume at the next start), the pool, and drop the cache."""
        if self.dispatcher is not None:
            self.dispatcher.stop()
            self.dispatcher = None
        if self.pool is not None:
            # Queued work is dropped; running computations (bounded by the time limit) end, then the workers.
            self.pool.shutdown(wait=True, cancel_futures=True)
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

    def require_key(given: str | None = Security(header)) -> None:
        keys = settings.keys()
        if not keys:
            return
        if not any(hmac.compare_digest((given or "").encode(), k.encode()) for k in keys):
            raise HTTPException(401, f"missing or invalid API key: send it in the '{settings.api_key_header}' "
                                     "header", headers={"WWW-Authenticate": "ApiKey"})

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
        from ..model import derivatives

        return list(getattr(derivatives, "METHODS", ("exact",)))
    except ImportError:  # pragma: no cover - before model.derivatives lands
        return ["exact"]


def _diagnosis_available() -> bool:
    try:
        from ..model.constraints import diagnose  # noqa: F401
    except ImportError:  # pragma: no cover - before model.constraints lands
        return False
    return True


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
            hit = await rt.run(worker.curve, json.dumps(spec))
            rt.store(key, hit)
        return Response(hit, media_type=media)

    if _diagnosis_available():
        @v1.post("/diagnosis", summary="Exact-constraint diagnosis of a scene (D_cc, SVD, Table-1 class)",
                 response_model=dict[str, Any], responses=_HEAVY)
        async def diagnosis(req: DiagnosisRequest, request: Request) -> Response:
            rt = _runtime(request)
            scene = _scene(req.scene)
            spec = {"scene": scene.model_dump(mode="json"), "at_stroke": req.at_stroke, "kinematic": req.kinematic}
            return Response(await rt.run(worker.diagnosis, json.dumps(spec)), media_type="application/json")

    def _store(request: Request) -> Any:
        store = _runtime(request).jobs
        if store is None:  # pragma: no cover - only before the lifespan started
            raise HTTPException(503, "the job store is not open yet; retry")
        return store

    @v1.post("/optimisations", status_code=202, response_model=Job, summary="Submit an optimisation job",
             responses={422: {"model": Problem}})
    async def submit_optimisation(spec: OptimisationProblem, request: Request, response: Response,
                                  idempotency_key: str | None = Header(default=None, max_length=200)) -> Job:
        from ..model.errors import FlexoptError
        from ..optim.search import _Family

        for i, fam in enumerate(spec.families):  # fail now, not in the job, on a family that cannot run
            try:
                _Family(spec, fam)
            except FlexoptError as exc:
                raise RequestValidationError([{"loc": ("body", "families", i), "type": "value_error",
                                               "msg": str(exc)}]) from None
        job, _ = await asyncio.to_thread(_store(request).submit, spec.model_dump(mode="json"), idempotency_key)
        response.headers["Location"] = f"/v1/optimisations/{job['id']}"
        return Job(**job)

    @v1.get("/optimisations/{job_id}", response_model=Job, summary="Status, progress, partial and final results",
            responses={404: {"model": Problem}})
    async def get_optimisation(job_id: str, request: Request) -> Job:
        job = await asyncio.to_thread(_store(request).get, job_id)
        if job is None:
            raise HTTPException(404, f"no optimisation job '{job_id}'")
        return Job(**job)

    @v1.get("/optimisations", response_model=JobPage, summary="Optimisation jobs, newest first")
    async def list_optimisations(request: Request, offset: int = Query(0, ge=0, le=1_000_000_000),
                                 limit: int = Query(20, ge=1, le=100)) -> JobPage:
        items, total = await asyncio.to_thread(_store(request).page, offset, limit)
        return JobPage(items=[Job(**j) for j in items], total=total, offset=offset, limit=limit)

    @v1.delete("/optimisations/{job_id}", response_model=Job, summary="Cancel a job (queued: at once; running: "
               "it stops after the cases in progress)", responses={404: {"model": Problem}})
    async def cancel_optimisation(job_id: str, request: Request) -> Job:
        job = await asyncio.to_thread(_store(request).cancel, job_id)
        if job is None:
            raise HTTPException(404, f"no optimisation job '{job_id}'")
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

    @app.get("/health", response_model=Health, summary="Liveness, version and available methods")
    async def health() -> Health:
        return Health(version=_package_version(), methods=_methods())

    app.include_router(_router(settings))
    from . import routes_shapes, web  # POST /v1/modes; the page at / and its static assets

    app.include_router(routes_shapes.router(), prefix="/v1", dependencies=[Depends(_key_checker(settings))],
                       responses={401: _ERRORS[401]})
    web.install(app)
    app.add_middleware(BodyLimit, limit=settings.max_body_bytes)
    return app


def openapi_json() -> str:
    """The OpenAPI document as committed in service/openapi.json (default settings)."""
    return json.dumps(create_app(Settings(api_keys="")).openapi(), indent=2, sort_keys=True) + "\n"


if __name__ == "__main__":  # pragma: no cover
    print(openapi_json(), end="")
