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
from typing import Any, Literal, Self

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

    def health(self) -> Health:
        """Liveness, version and the methods the server offers."""
        return Health.model_validate(self._request("GET", "/health").json())

    def templates(self) -> list[TemplateInfo]:
        """Every template with its parameters, defaults and bounds."""
        return [TemplateInfo.model_validate(t) for t in self._request("GET", "/v1/templates").json()]

    def template(self, name: str) -> TemplateInfo:
        """One template."""
        return TemplateInfo.model_validate(self._request("GET", f"/v1/templates/{name}").json())

    def template_scene(self, name: str, **params: Any) -> dict[str, Any]:
        """The scene JSON of template ``name`` with parameters overridden."""
        return self._request("POST", f"/v1/templates/{name}/scene", json={"parameters": params}).json()

    def frequency_curve(
        self,
        scene: Any,
        stroke: Any = None,
        method: str = "exact",
        tolerance: float | None = None,
        format: Format = "json",
    ) -> FrequencyCurveOut | str | bytes:
        """The frequency curve: a FrequencyCurveOut (``format="json"``), CSV text or PNG bytes."""
        r = self._request(
            "POST",
            "/v1/frequency-curve",
            json=_curve_body(scene, stroke, method, tolerance),
            headers={"Accept": _ACCEPT[format]},
        )
        return (
            FrequencyCurveOut.model_validate_json(r.content)
            if format == "json"
            else (r.text if format == "csv" else r.content)
        )

    def diagnose(self, scene: Any, at_stroke: float | None = None, kinematic: bool | None = None) -> dict[str, Any]:
        """The exact-constraint diagnosis (``model.constraints.ConstraintDiagnosis.to_dict`` form)."""
        return self._request(
            "POST", "/v1/diagnosis", json={"scene": _scene_json(scene), "at_stroke": at_stroke, "kinematic": kinematic}
        ).json()

    def modes(
        self,
        scene: Any,
        at_stroke: float = 0.0,
        format: Literal["json", "png", "gif"] = "json",
        mode: int | None = None,
    ) -> dict[str, Any] | bytes:
        """Deflected structure and mode shapes at ``at_stroke`` (``ModesOut`` dict, for
        ``flexopt.service.plots``), or a PNG 3D view / GIF animation of ``mode`` (0-based)."""
        r = self._request(
            "POST",
            "/v1/modes",
            json={"scene": _scene_json(scene), "at_stroke": at_stroke, "mode": mode},
            headers={"Accept": {"json": "application/json", "png": "image/png", "gif": "image/gif"}[format]},
        )
        return r.json() if format == "json" else r.content

    def submit_optimisation(self, spec: Any, idempotency_key: str | None = None) -> JobHandle:
        """Submit an optimisation (an ``optim.Problem`` or its JSON); one idempotency key for all retries, so
        a retried submission returns the same job."""
        key = idempotency_key or str(uuid.uuid4())
        r = self._request("POST", "/v1/optimisations", json=_spec_json(spec), headers={"Idempotency-Key": key})
        return JobHandle(self, Job.model_validate(r.json()))

    def submit_topology_search(self, spec: Any = None, idempotency_key: str | None = None) -> JobHandle:
        """Submit a topology search (a ``TopologySpec``, its JSON, or None for the defaults) as a job; retries
        and idempotency as :meth:`submit_optimisation`. ``.wait()`` returns ``run_topology_search``'s dict."""
        key = idempotency_key or str(uuid.uuid4())
        r = self._request(
            "POST",
            "/v1/topology-searches",
            json=_spec_json(spec if spec is not None else {}),
            headers={"Idempotency-Key": key},
        )
        return JobHandle(self, Job.model_validate(r.json()))

    def topology_searches(self, offset: int = 0, limit: int = 20) -> JobPage:
        """A page of topology searches, newest first."""
        return JobPage.model_validate(
            self._request("GET", "/v1/topology-searches", params={"offset": offset, "limit": limit}).json()
        )

    def optimisation(self, job_id: str) -> Job:
        """The current state of a job."""
        return Job.model_validate(self._request("GET", f"/v1/optimisations/{job_id}").json())

    def optimisations(self, offset: int = 0, limit: int = 20) -> JobPage:
        """A page of jobs, newest first."""
        return JobPage.model_validate(
            self._request("GET", "/v1/optimisations", params={"offset": offset, "limit": limit}).json()
        )

    def cancel_optimisation(self, job_id: str) -> Job:
        """``DELETE``: an unfinished job is cancelled (queued: at once; running: after the cases in progress);
        a finished one is removed with its files. The job as it was answered."""
        return Job.model_validate(self._request("DELETE", f"/v1/optimisations/{job_id}").json())


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

    async def health(self) -> Health:
        """Liveness, version and the methods the server offers."""
        return Health.model_validate((await self._request("GET", "/health")).json())

    async def templates(self) -> list[TemplateInfo]:
        """Every template with its parameters, defaults and bounds."""
        return [TemplateInfo.model_validate(t) for t in (await self._request("GET", "/v1/templates")).json()]

    async def template(self, name: str) -> TemplateInfo:
        """One template."""
        return TemplateInfo.model_validate((await self._request("GET", f"/v1/templates/{name}")).json())

    async def template_scene(self, name: str, **params: Any) -> dict[str, Any]:
        """The scene JSON of template ``name`` with parameters overridden."""
        return (await self._request("POST", f"/v1/templates/{name}/scene", json={"parameters": params})).json()

    async def frequency_curve(
        self,
        scene: Any,
        stroke: Any = None,
        method: str = "exact",
        tolerance: float | None = None,
        format: Format = "json",
    ) -> FrequencyCurveOut | str | bytes:
        """The frequency curve: a FrequencyCurveOut (``format="json"``), CSV text or PNG bytes."""
        r = await self._request(
            "POST",
            "/v1/frequency-curve",
            json=_curve_body(scene, stroke, method, tolerance),
            headers={"Accept": _ACCEPT[format]},
        )
        return (
            FrequencyCurveOut.model_validate_json(r.content)
            if format == "json"
            else (r.text if format == "csv" else r.content)
        )

    async def diagnose(
        self, scene: Any, at_stroke: float | None = None, kinematic: bool | None = None
    ) -> dict[str, Any]:
        """The exact-constraint diagnosis (``ConstraintDiagnosis.to_dict`` form)."""
        r = await self._request(
            "POST", "/v1/diagnosis", json={"scene": _scene_json(scene), "at_stroke": at_stroke, "kinematic": kinematic}
        )
        return r.json()

    async def modes(
        self,
        scene: Any,
        at_stroke: float = 0.0,
        format: Literal["json", "png", "gif"] = "json",
        mode: int | None = None,
    ) -> dict[str, Any] | bytes:
        """Deflected structure and mode shapes; see :meth:`Client.modes`."""
        r = await self._request(
            "POST",
            "/v1/modes",
            json={"scene": _scene_json(scene), "at_stroke": at_stroke, "mode": mode},
            headers={"Accept": {"json": "application/json", "png": "image/png", "gif": "image/gif"}[format]},
        )
        return r.json() if format == "json" else r.content

    async def submit_optimisation(self, spec: Any, idempotency_key: str | None = None) -> AsyncJobHandle:
        """Submit an optimisation; see :meth:`Client.submit_optimisation`."""
        key = idempotency_key or str(uuid.uuid4())
        r = await self._request("POST", "/v1/optimisations", json=_spec_json(spec), headers={"Idempotency-Key": key})
        return AsyncJobHandle(self, Job.model_validate(r.json()))

    async def submit_topology_search(self, spec: Any = None, idempotency_key: str | None = None) -> AsyncJobHandle:
        """Submit a topology search; see :meth:`Client.submit_topology_search`."""
        key = idempotency_key or str(uuid.uuid4())
        r = await self._request(
            "POST",
            "/v1/topology-searches",
            json=_spec_json(spec if spec is not None else {}),
            headers={"Idempotency-Key": key},
        )
        return AsyncJobHandle(self, Job.model_validate(r.json()))

    async def optimisation(self, job_id: str) -> Job:
        """The current state of a job."""
        return Job.model_validate((await self._request("GET", f"/v1/optimisations/{job_id}")).json())

    async def cancel_optimisation(self, job_id: str) -> Job:
        """``DELETE``: an unfinished job is cancelled (queued: at once; running: after the cases in progress);
        a finished one is removed with its files. The job as it was answered."""
        return Job.model_validate((await self._request("DELETE", f"/v1/optimisations/{job_id}")).json())


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
            if job.status in _DONE:
                if job.status != "succeeded" or job.result is None:
                    raise JobFailed(job)
                return job.result
            if deadline is not None and time.monotonic() > deadline:
                raise TimeoutError(f"job {self.id} still {job.status} after {timeout} s")
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
            if job.status in _DONE:
                if job.status != "succeeded" or job.result is None:
                    raise JobFailed(job)
                return job.result
            if deadline is not None and time.monotonic() > deadline:
                raise TimeoutError(f"job {self.id} still {job.status} after {timeout} s")
            await asyncio.sleep(poll)
