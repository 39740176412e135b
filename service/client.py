"""Python client of the flexopt HTTP service (httpx; sync ``Client`` and ``AsyncClient``).

Imports only httpx, pydantic and service.schemas, never CasADi or FastAPI. Scenes are JSON objects (dicts);
a ``model.Scene`` instance is accepted too and dumped to JSON. Results come back as the server's wire models.

Exceptions (one tree)::

    FlexoptClientError              base
    ├── ConnectionFailed            the server could not be reached
    └── APIError                    the server answered with an error (problem details: .status, .detail, .errors)
        ├── BadRequest              400
        ├── Unauthorized            401
        ├── NotFound                404
        ├── PayloadTooLarge         413
        ├── InvalidInput            422 (.errors: field paths and reasons)
        ├── TooManyRequests         429 (.retry_after), raised once the retries are spent
        ├── ServerError             500
        ├── ServiceUnavailable      503
        └── ComputeTimeout          504
"""

from __future__ import annotations

import asyncio
import time
import uuid
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import Any, Generic, Literal, Self, TypeVar

import httpx

from .schemas import FieldError, FrequencyCurveOut, Health, Job, JobPage, Problem, TemplateInfo

__all__ = [
    "Client",
    "AsyncClient",
    "JobHandle",
    "AsyncJobHandle",
    "JobFailed",
    "FlexoptClientError",
    "ConnectionFailed",
    "APIError",
    "BadRequest",
    "Unauthorized",
    "NotFound",
    "PayloadTooLarge",
    "InvalidInput",
    "TooManyRequests",
    "ServerError",
    "ServiceUnavailable",
    "ComputeTimeout",
]

_DONE = frozenset({"succeeded", "failed", "cancelled"})
T = TypeVar("T")


def _spec_json(spec: Any) -> dict[str, Any]:
    return spec.model_dump(mode="json") if hasattr(spec, "model_dump") else dict(spec)  # a pydantic spec or its JSON


Format = Literal["json", "csv", "png"]
_ACCEPT = {"json": "application/json", "csv": "text/csv", "png": "image/png"}
_RETRY_STATUS = frozenset({429, 503})


class FlexoptClientError(Exception):
    """Base of every error the client raises."""


class ConnectionFailed(FlexoptClientError):
    """The server could not be reached (after the retries)."""


class APIError(FlexoptClientError):
    """The server answered with an error status; carries its problem-details message."""

    status: int = 0

    def __init__(
        self, status: int, detail: str, errors: list[FieldError] | None = None, retry_after: float | None = None
    ) -> None:
        self.status = status
        self.detail = detail
        self.errors = errors or []
        self.retry_after = retry_after
        super().__init__(f"HTTP {status}: {detail}")


class BadRequest(APIError):
    """400."""


class Unauthorized(APIError):
    """401: API key missing or wrong."""


class NotFound(APIError):
    """404."""


class PayloadTooLarge(APIError):
    """413: the request body is over the server's limit."""


class InvalidInput(APIError):
    """422: invalid scene or parameters; ``errors`` holds the field paths and reasons."""


class TooManyRequests(APIError):
    """429: the server is at its concurrency limit (``retry_after`` seconds)."""


class ServerError(APIError):
    """500."""


class ServiceUnavailable(APIError):
    """503."""


class JobFailed(FlexoptClientError):
    """An optimisation job ended failed or cancelled (``.job`` holds its last state and error)."""

    def __init__(self, job: Job) -> None:
        super().__init__(f"optimisation job {job.id} {job.status}: {job.error or 'no result'}")
        self.job = job


class ComputeTimeout(APIError):
    """504: the computation exceeded the server's time limit."""


_BY_STATUS: dict[int, type[APIError]] = {
    400: BadRequest,
    401: Unauthorized,
    404: NotFound,
    413: PayloadTooLarge,
    422: InvalidInput,
    429: TooManyRequests,
    500: ServerError,
    503: ServiceUnavailable,
    504: ComputeTimeout,
}


def _retry_after(response: httpx.Response) -> float | None:
    value = response.headers.get("retry-after")
    try:
        return max(0.0, float(value)) if value is not None else None
    except ValueError:
        return None


def _raise_for(response: httpx.Response) -> None:
    if response.status_code < 400:
        return
    try:
        p = Problem.model_validate(response.json())
        detail, errors = p.detail, p.errors
    except ValueError:
        detail, errors = response.text.strip() or response.reason_phrase, []
    cls = _BY_STATUS.get(response.status_code, ServerError if response.status_code >= 500 else APIError)
    raise cls(response.status_code, detail, errors, _retry_after(response))


def _scene_json(scene: Any) -> dict[str, Any]:
    if hasattr(scene, "model_dump"):
        return scene.model_dump(mode="json")
    if not isinstance(scene, dict):
        raise TypeError("scene must be a dict (scene JSON) or a model.Scene")
    return scene


def _curve_body(scene: Any, stroke: Any, method: str, tolerance: float | None) -> dict[str, Any]:
    body: dict[str, Any] = {"scene": _scene_json(scene), "method": method}
    if stroke is not None:
        body["stroke"] = [float(v) for v in stroke]
    if tolerance is not None:
        body["tolerance"] = float(tolerance)
    return body


@dataclass(frozen=True)
class _Call(Generic[T]):
    """One API call as data: the request (method, path, httpx keywords) and how its response is read. Built
    once by :class:`_Calls` for both clients, which only send it (:meth:`Client._do`, :meth:`AsyncClient._do`)."""

    method: str
    path: str
    read: Callable[[httpx.Response], T]
    kw: dict[str, Any] = field(default_factory=dict)


def _job(r: httpx.Response) -> Job:
    return Job.model_validate(r.json())


def _page(r: httpx.Response) -> JobPage:
    return JobPage.model_validate(r.json())


def _json(r: httpx.Response) -> Any:
    return r.json()


class _Calls:
    """The request builders of the API, one per call, shared by :class:`Client` and :class:`AsyncClient`."""

    @staticmethod
    def health() -> _Call[Health]:
        return _Call("GET", "/health", lambda r: Health.model_validate(r.json()))

    @staticmethod
    def templates() -> _Call[list[TemplateInfo]]:
        return _Call("GET", "/v1/templates", lambda r: [TemplateInfo.model_validate(t) for t in r.json()])

    @staticmethod
    def template(name: str) -> _Call[TemplateInfo]:
        return _Call("GET", f"/v1/templates/{name}", lambda r: TemplateInfo.model_validate(r.json()))

    @staticmethod
    def template_scene(name: str, params: dict[str, Any]) -> _Call[dict[str, Any]]:
        return _Call("POST", f"/v1/templates/{name}/scene", _json, {"json": {"parameters": params}})

    @staticmethod
    def frequency_curve(
        scene: Any, stroke: Any, method: str, tolerance: float | None, format: Format
    ) -> _Call[FrequencyCurveOut | str | bytes]:
        def read(r: httpx.Response) -> FrequencyCurveOut | str | bytes:
            if format == "json":
                return FrequencyCurveOut.model_validate_json(r.content)
            return r.text if format == "csv" else r.content

        body = _curve_body(scene, stroke, method, tolerance)
        return _Call("POST", "/v1/frequency-curve", read, {"json": body, "headers": {"Accept": _ACCEPT[format]}})

    @staticmethod
    def diagnose(scene: Any, at_stroke: float | None, kinematic: bool | None) -> _Call[dict[str, Any]]:
        body = {"scene": _scene_json(scene), "at_stroke": at_stroke, "kinematic": kinematic}
        return _Call("POST", "/v1/diagnosis", _json, {"json": body})

    @staticmethod
    def modes(scene: Any, at_stroke: float, format: str, mode: int | None) -> _Call[dict[str, Any] | bytes]:
        accept = {"json": "application/json", "png": "image/png", "gif": "image/gif"}[format]
        return _Call(
            "POST",
            "/v1/modes",
            lambda r: r.json() if format == "json" else r.content,
            {
                "json": {"scene": _scene_json(scene), "at_stroke": at_stroke, "mode": mode},
                "headers": {"Accept": accept},
            },
        )

    @staticmethod
    def submit(collection: str, spec: Any, idempotency_key: str | None) -> _Call[Job]:
        """A job submission; one idempotency key for all retries, so a retried submission returns the same job."""
        key = idempotency_key or str(uuid.uuid4())
        return _Call("POST", f"/v1/{collection}", _job, {"json": _spec_json(spec), "headers": {"Idempotency-Key": key}})

    @staticmethod
    def job(collection: str, job_id: str) -> _Call[Job]:
        return _Call("GET", f"/v1/{collection}/{job_id}", _job)

    @staticmethod
    def jobs(collection: str, offset: int, limit: int) -> _Call[JobPage]:
        return _Call("GET", f"/v1/{collection}", _page, {"params": {"offset": offset, "limit": limit}})

    @staticmethod
    def cancel(collection: str, job_id: str) -> _Call[Job]:
        return _Call("DELETE", f"/v1/{collection}/{job_id}", _job)


class _Base:
    def __init__(
        self, base_url: str, api_key: str | None, timeout: float, max_retries: int, backoff: float, api_key_header: str
    ) -> None:
        self.base_url = base_url.rstrip("/")
        self.headers = {api_key_header: api_key} if api_key else {}
        self.timeout = timeout
        self.max_retries = max_retries
        self.backoff = backoff

    def _delay(self, attempt: int, response: httpx.Response | None) -> float:
        after = _retry_after(response) if response is not None else None
        return after if after is not None else min(self.backoff * 2**attempt, 30.0)


class Client(_Base):
    """Synchronous client: ``Client("http://127.0.0.1:8000", api_key=None)``; use as a context manager."""

    def __init__(
        self,
        base_url: str,
        api_key: str | None = None,
        *,
        timeout: float = 60.0,
        max_retries: int = 3,
        backoff: float = 0.5,
        api_key_header: str = "X-API-Key",
        transport: httpx.BaseTransport | None = None,
    ) -> None:
        super().__init__(base_url, api_key, timeout, max_retries, backoff, api_key_header)
        self._http = httpx.Client(base_url=self.base_url, headers=self.headers, timeout=timeout, transport=transport)

    def close(self) -> None:
        """Close the connection pool."""
        self._http.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _request(self, method: str, path: str, **kw: Any) -> httpx.Response:
        for attempt in range(self.max_retries + 1):
            try:
                r = self._http.request(method, path, **kw)
            except httpx.TransportError as exc:
                if attempt == self.max_retries:
                    raise ConnectionFailed(f"cannot reach {self.base_url}: {exc}") from exc
                time.sleep(self._delay(attempt, None))
                continue
            if r.status_code in _RETRY_STATUS and attempt < self.max_retries:
                time.sleep(self._delay(attempt, r))
                continue
            _raise_for(r)
            return r
        raise AssertionError("unreachable")  # pragma: no cover

    def _do(self, call: _Call[T]) -> T:
        return call.read(self._request(call.method, call.path, **call.kw))

    def health(self) -> Health:
        """Liveness, version and the methods the server offers."""
        return self._do(_Calls.health())

    def templates(self) -> list[TemplateInfo]:
        """Every template with its parameters, defaults and bounds."""
        return self._do(_Calls.templates())

    def template(self, name: str) -> TemplateInfo:
        """One template."""
        return self._do(_Calls.template(name))

    def template_scene(self, name: str, **params: Any) -> dict[str, Any]:
        """The scene JSON of template ``name`` with parameters overridden."""
        return self._do(_Calls.template_scene(name, params))

    def frequency_curve(
        self,
        scene: Any,
        stroke: Any = None,
        method: str = "exact",
        tolerance: float | None = None,
        format: Format = "json",
    ) -> FrequencyCurveOut | str | bytes:
        """The frequency curve: a FrequencyCurveOut (``format="json"``), CSV text or PNG bytes."""
        return self._do(_Calls.frequency_curve(scene, stroke, method, tolerance, format))

    def diagnose(self, scene: Any, at_stroke: float | None = None, kinematic: bool | None = None) -> dict[str, Any]:
        """The exact-constraint diagnosis (``model.constraints.ConstraintDiagnosis.to_dict`` form)."""
        return self._do(_Calls.diagnose(scene, at_stroke, kinematic))

    def modes(
        self,
        scene: Any,
        at_stroke: float = 0.0,
        format: Literal["json", "png", "gif"] = "json",
        mode: int | None = None,
    ) -> dict[str, Any] | bytes:
        """Deflected structure and mode shapes at ``at_stroke`` (``ModesOut`` dict, for
        ``flexopt.service.plots``), or a PNG 3D view / GIF animation of ``mode`` (0-based)."""
        return self._do(_Calls.modes(scene, at_stroke, format, mode))

    def submit_optimisation(self, spec: Any, idempotency_key: str | None = None) -> JobHandle:
        """Submit an optimisation (an ``optim.Problem`` or its JSON); one idempotency key for all retries, so
        a retried submission returns the same job."""
        return JobHandle(self, self._do(_Calls.submit("optimisations", spec, idempotency_key)))

    def submit_topology_search(self, spec: Any = None, idempotency_key: str | None = None) -> JobHandle:
        """Submit a topology search (a ``TopologySpec``, its JSON, or None for the defaults) as a job; retries
        and idempotency as :meth:`submit_optimisation`. ``.wait()`` returns ``run_topology_search``'s dict."""
        return JobHandle(
            self, self._do(_Calls.submit("topology-searches", spec if spec is not None else {}, idempotency_key))
        )

    def topology_searches(self, offset: int = 0, limit: int = 20) -> JobPage:
        """A page of topology searches, newest first."""
        return self._do(_Calls.jobs("topology-searches", offset, limit))

    def optimisation(self, job_id: str) -> Job:
        """The current state of a job."""
        return self._do(_Calls.job("optimisations", job_id))

    def optimisations(self, offset: int = 0, limit: int = 20) -> JobPage:
        """A page of jobs, newest first."""
        return self._do(_Calls.jobs("optimisations", offset, limit))

    def cancel_optimisation(self, job_id: str) -> Job:
        """``DELETE``: an unfinished job is cancelled (queued: at once; running: after the cases in progress);
        a finished one is removed with its files. The job as it was answered."""
        return self._do(_Calls.cancel("optimisations", job_id))


class AsyncClient(_Base):
    """Asynchronous client with the same methods as :class:`Client` (``await``-ed)."""

    def __init__(
        self,
        base_url: str,
        api_key: str | None = None,
        *,
        timeout: float = 60.0,
        max_retries: int = 3,
        backoff: float = 0.5,
        api_key_header: str = "X-API-Key",
        transport: httpx.AsyncBaseTransport | None = None,
    ) -> None:
        super().__init__(base_url, api_key, timeout, max_retries, backoff, api_key_header)
        self._http = httpx.AsyncClient(
            base_url=self.base_url, headers=self.headers, timeout=timeout, transport=transport
        )

    async def aclose(self) -> None:
        """Close the connection pool."""
        await self._http.aclose()

    async def __aenter__(self) -> Self:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.aclose()

    async def _request(self, method: str, path: str, **kw: Any) -> httpx.Response:
        for attempt in range(self.max_retries + 1):
            try:
                r = await self._http.request(method, path, **kw)
            except httpx.TransportError as exc:
                if attempt == self.max_retries:
                    raise ConnectionFailed(f"cannot reach {self.base_url}: {exc}") from exc
                await asyncio.sleep(self._delay(attempt, None))
                continue
            if r.status_code in _RETRY_STATUS and attempt < self.max_retries:
                await asyncio.sleep(self._delay(attempt, r))
                continue
            _raise_for(r)
            return r
        raise AssertionError("unreachable")  # pragma: no cover

    async def _do(self, call: _Call[T]) -> T:
        return call.read(await self._request(call.method, call.path, **call.kw))

    async def health(self) -> Health:
        """Liveness, version and the methods the server offers."""
        return await self._do(_Calls.health())

    async def templates(self) -> list[TemplateInfo]:
        """Every template with its parameters, defaults and bounds."""
        return await self._do(_Calls.templates())

    async def template(self, name: str) -> TemplateInfo:
        """One template."""
        return await self._do(_Calls.template(name))

    async def template_scene(self, name: str, **params: Any) -> dict[str, Any]:
        """The scene JSON of template ``name`` with parameters overridden."""
        return await self._do(_Calls.template_scene(name, params))

    async def frequency_curve(
        self,
        scene: Any,
        stroke: Any = None,
        method: str = "exact",
        tolerance: float | None = None,
        format: Format = "json",
    ) -> FrequencyCurveOut | str | bytes:
        """The frequency curve: a FrequencyCurveOut (``format="json"``), CSV text or PNG bytes."""
        return await self._do(_Calls.frequency_curve(scene, stroke, method, tolerance, format))

    async def diagnose(
        self, scene: Any, at_stroke: float | None = None, kinematic: bool | None = None
    ) -> dict[str, Any]:
        """The exact-constraint diagnosis (``ConstraintDiagnosis.to_dict`` form)."""
        return await self._do(_Calls.diagnose(scene, at_stroke, kinematic))

    async def modes(
        self,
        scene: Any,
        at_stroke: float = 0.0,
        format: Literal["json", "png", "gif"] = "json",
        mode: int | None = None,
    ) -> dict[str, Any] | bytes:
        """Deflected structure and mode shapes; see :meth:`Client.modes`."""
        return await self._do(_Calls.modes(scene, at_stroke, format, mode))

    async def submit_optimisation(self, spec: Any, idempotency_key: str | None = None) -> AsyncJobHandle:
        """Submit an optimisation; see :meth:`Client.submit_optimisation`."""
        return AsyncJobHandle(self, await self._do(_Calls.submit("optimisations", spec, idempotency_key)))

    async def submit_topology_search(self, spec: Any = None, idempotency_key: str | None = None) -> AsyncJobHandle:
        """Submit a topology search; see :meth:`Client.submit_topology_search`."""
        return AsyncJobHandle(
            self, await self._do(_Calls.submit("topology-searches", spec if spec is not None else {}, idempotency_key))
        )

    async def topology_searches(self, offset: int = 0, limit: int = 20) -> JobPage:
        """A page of topology searches, newest first."""
        return await self._do(_Calls.jobs("topology-searches", offset, limit))

    async def optimisation(self, job_id: str) -> Job:
        """The current state of a job."""
        return await self._do(_Calls.job("optimisations", job_id))

    async def optimisations(self, offset: int = 0, limit: int = 20) -> JobPage:
        """A page of jobs, newest first."""
        return await self._do(_Calls.jobs("optimisations", offset, limit))

    async def cancel_optimisation(self, job_id: str) -> Job:
        """``DELETE``: an unfinished job is cancelled (queued: at once; running: after the cases in progress);
        a finished one is removed with its files. The job as it was answered."""
        return await self._do(_Calls.cancel("optimisations", job_id))


def _ended(job: Job, deadline: float | None, timeout: float | None) -> bool:
    """Whether a polled job has its result; :class:`JobFailed` if it ended without one, ``TimeoutError`` past
    the deadline (both handles' ``wait``)."""
    if job.status in _DONE:
        if job.status != "succeeded" or job.result is None:
            raise JobFailed(job)
        return True
    if deadline is not None and time.monotonic() > deadline:
        raise TimeoutError(f"job {job.id} still {job.status} after {timeout} s")
    return False


class JobHandle:
    """A submitted job: ``.status()``, ``.wait(progress=callback)``, ``.cancel()``."""

    def __init__(self, client: Client, job: Job) -> None:
        self.client, self.job, self.id = client, job, job.id

    def status(self) -> Job:
        """Refresh and return the job's state."""
        self.job = self.client.optimisation(self.id)
        return self.job

    def cancel(self) -> Job:
        """Ask the job to stop."""
        self.job = self.client.cancel_optimisation(self.id)
        return self.job

    def wait(
        self, progress: Callable[[Job], None] | None = None, poll: float = 0.5, timeout: float | None = None
    ) -> dict[str, Any]:
        """Poll until the job ends; returns the result, raises :class:`JobFailed` if it failed or was cancelled
        and ``TimeoutError`` past ``timeout`` seconds. ``progress(job)`` sees every polled state."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            job = self.status()
            if progress is not None:
                progress(job)
            if _ended(job, deadline, timeout):
                assert job.result is not None  # checked by _ended
                return job.result
            time.sleep(poll)


class AsyncJobHandle:
    """The asynchronous counterpart of :class:`JobHandle`."""

    def __init__(self, client: AsyncClient, job: Job) -> None:
        self.client, self.job, self.id = client, job, job.id

    async def status(self) -> Job:
        self.job = await self.client.optimisation(self.id)
        return self.job

    async def cancel(self) -> Job:
        self.job = await self.client.cancel_optimisation(self.id)
        return self.job

    async def wait(
        self,
        progress: Callable[[Job], Awaitable[None] | None] | None = None,
        poll: float = 0.5,
        timeout: float | None = None,
    ) -> dict[str, Any]:
        """See :meth:`JobHandle.wait`; ``progress`` may be a coroutine function."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            job = await self.status()
            if progress is not None:
                out = progress(job)
                if asyncio.iscoroutine(out):
                    await out
            if _ended(job, deadline, timeout):
                assert job.result is not None  # checked by _ended
                return job.result
            await asyncio.sleep(poll)
