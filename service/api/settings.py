"""Service settings: one BaseSettings read from the environment (prefix ``FLEXOPT_``)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Literal

from pydantic import AliasChoices, Field, PositiveFloat, PositiveInt
from pydantic_settings import BaseSettings, SettingsConfigDict

__all__ = ["Settings"]


def _default_data_dir() -> Path:
    """``$XDG_DATA_HOME/flexopt`` (``~/.local/share/flexopt``): a per-user place, not the working directory."""
    return Path(os.environ.get("XDG_DATA_HOME") or Path.home() / ".local" / "share") / "flexopt"


class Settings(BaseSettings):
    """Limits and options of the HTTP service; every field can be set as ``FLEXOPT_<NAME>``."""

    model_config = SettingsConfigDict(env_prefix="FLEXOPT_", extra="ignore")

    max_body_bytes: PositiveInt = Field(1_000_000, description="largest accepted request body [bytes] (413 past it)")
    head_timeout: PositiveFloat = Field(
        10.0,
        description="time allowed to send a request's line and headers [s], "
        "from the connection's opening or its last response (the connection is "
        "closed past it; flexopt serve)",
    )
    body_timeout: PositiveFloat = Field(
        30.0, description="time allowed to receive a request body [s] (408 past it, and the connection is closed)"
    )
    request_timeout: PositiveFloat = Field(
        30.0, description="time limit of a synchronous computation [s] (504 past it)"
    )
    max_concurrent: PositiveInt = Field(2, description="heavy computations running at once (429 past it)")
    executor: Literal["process", "thread"] = Field(
        "process", description="where computations run: worker processes (parallel on all cores) or threads"
    )
    max_queued: int = Field(64, ge=0, description="heavy requests waiting for a slot (429 past it)")
    queue_timeout: float = Field(10.0, ge=0, description="longest wait for a computation slot [s] (429 past it)")
    retry_after: PositiveInt = Field(1, description="Retry-After sent with 429 [s]")
    max_stroke_points: PositiveInt = Field(
        1001,
        description="largest stroke grid accepted: the explicit list or the scene's own stroke.points (422 past it)",
    )
    max_cost: PositiveFloat = Field(
        30.0,
        description="largest estimated cost of a synchronous computation [s], estimated before any work "
        "as guards.seconds_per_point(DOFs) x stroke points (413 past it, or a job with "
        "'Prefer: respond-async')",
    )
    max_job_cost: PositiveFloat = Field(
        3600.0, description="largest estimated cost of a frequency curve run as a job [s] (413 past it)"
    )
    max_batch_cost: PositiveFloat = Field(
        500_000.0,
        description="largest estimated cost of an optimisation, topology-search or Pareto-front job [CPU s on "
        "one core], estimated at submission as a budget (service.api.cost; 413 past it, naming the fields "
        "to reduce); the default admits the default topology search (about 390,000 s)",
    )
    cache_size: int = Field(256, ge=0, description="entries of the LRU response cache for identical requests (0 = off)")
    cache_bytes: int = Field(
        32_000_000,
        ge=0,
        description="bytes the LRU response cache may hold in all [bytes] (a response larger "
        "than an eighth of it is not cached): bounds the server's memory whatever the responses' size",
    )
    worker_tasks: PositiveInt = Field(
        200,
        description="computations a worker process serves before it is replaced by a fresh one: bounds what a "
        "worker retains of the distinct scenes it met (compiled functions, caches, its heap's fragmentation)",
    )
    api_keys: str = Field("", description="comma-separated API keys; empty = no authentication")
    api_key_header: str = Field("X-API-Key", description="header carrying the API key")
    allowed_hosts: str = Field(
        "localhost,127.0.0.1,[::1]",
        description="comma-separated host names this server answers to (the Host "
        "header, port ignored; '*.example.com' matches its subdomains, '*' any host): others get 400, so a web "
        "page on another name resolved to this address (DNS rebinding) cannot call a local keyless server; add "
        "the name clients use, e.g. 'localhost,127.0.0.1,[::1],flexopt.example.com'",
    )

    data_dir: Path = Field(
        default_factory=lambda: _default_data_dir(),
        description="where the job database (SQLite) and the jobs' "
        "finished cases are kept; mount it as a volume in a container",
    )
    database_url: str = Field(
        "",
        validation_alias=AliasChoices("FLEXOPT_DATABASE_URL", "DATABASE_URL"),
        description="SQLAlchemy URL of the job store (e.g. postgresql+psycopg://...); empty = SQLite file in data_dir",
    )
    max_jobs: PositiveInt = Field(1, description="optimisation jobs running at once (each uses job_workers processes)")
    job_workers: int = Field(0, ge=0, description="worker processes per optimisation job (0 = CPU count)")
    max_active_jobs: PositiveInt = Field(8, description="queued or running jobs per API key (429 past it)")
    lease_seconds: PositiveFloat = Field(
        15.0, description="a job run's lease [s]: renewed by its heartbeat; a job whose lease ran out is requeued"
    )
    job_stop_timeout: PositiveFloat = Field(
        5.0,
        description="how long a stopping server waits for its job "
        "processes [s] before killing them (with the 3 s given to requests, "
        "keep the sum below the container's stop grace, 10 s in Docker)",
    )

    def job_store_url(self) -> str:
        """The job store's SQLAlchemy URL."""
        return self.database_url or f"sqlite:///{(self.data_dir / 'jobs.sqlite').resolve()}"

    def hosts(self) -> tuple[str, ...]:
        """The allowed host names, lower case (see ``allowed_hosts``)."""
        return tuple(h.strip().lower() for h in self.allowed_hosts.split(",") if h.strip())

    def keys(self) -> frozenset[str]:
        """The configured API keys (empty: authentication off)."""
        return frozenset(k.strip() for k in self.api_keys.split(",") if k.strip())
