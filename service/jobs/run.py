"""Optimisation jobs that are never lost nor run twice: the job process, on top of ``store`` and ``dispatch``.

Each job runs ``optim.optimise`` in its own OS process (``python -m flexopt.service.jobs run ID ATTEMPT``),
started by :class:`~flexopt.service.jobs.dispatch.Dispatcher` in its own process group, never in the server's
event loop. The process holds the job's lease (heartbeat with ``host:pid``) and writes progress and its
verdict only while the row carries its attempt number (the fencing token, :mod:`.store`).

Finished cases are kept in one case store shared by all jobs (``DATA_DIR/cases/<case id>.json``, the id a
hash of the case's content, ``optim.batch``): a retried run and an identical resubmission find them there
and never compute them again.

Life cycle: ``queued -> running -> succeeded | failed | cancelled``. A run that ends without a verdict (the
process or one of its pool workers killed, the server stopping) is requeued and resumes from its finished
cases; after ``MAX_CRASHES`` crashed runs the job fails with that reason (a graceful stop of the server is
not a crash: such a job resumes however often the server restarts). A job whose every case failed is
``failed`` with the reasons. The job process keeps running if its server is killed (its lease stays alive,
so a restarted server does not start it a second time) and writes its own verdict. Cancellation is
cooperative: the process reads ``cancelling`` from its row and stops the batch.
"""

from __future__ import annotations

import concurrent.futures as cf
import json
import logging
import os
import signal
import sys
import threading
import time
from pathlib import Path

from . import worker
from .store import HOST, JobStore, StoreUnavailable
from .worker import finite

__all__ = ["RETRY", "main", "run_job"]

log = logging.getLogger("flexopt.service.jobs")

#: Exit code of a run that ended without a verdict (interrupted, lost its lease, a pool worker died): the
#: dispatcher requeues it (EX_TEMPFAIL).
RETRY = 75


#: What a Pareto front's case adds to its summary when it has it: the point's kind and level, its verified
#: drive stiffness (or stroke), so that the page can draw the front while it runs
_FRONT_FIELDS = ("kind", "level", "drive_stiffness", "stroke", "ok")


def _summary(case: dict, phase: str | None = None) -> dict:
    v = case.get("verified", {})
    out = {
        "id": case.get("id"),
        "family": case.get("family"),
        "start": case.get("start"),
        "status": case.get("status", "failed" if "error" in case else None),
        "worst_hz": v.get("worst_hz", case.get("worst_hz")),
        "ratio": v.get("ratio"),
        "design": case.get("design"),
        "error": case.get("error"),
    }
    out.update({k: case[k] for k in _FRONT_FIELDS if k in case})
    if phase is not None:  # a topology search's or a front's phase the case belongs to
        out["phase"] = phase
    return out


def _family_forms(result: dict) -> dict:
    """A topology search's result with each candidate's ``family_form`` (``optim.topology.grammar.family_form``)."""
    from ...optim.topology.grammar import family_form

    for c in result.get("candidates", []):
        if isinstance(c.get("topology"), str) and c["topology"].startswith("R:"):
            c["family_form"] = family_form(c["topology"])
    return result


def _all_failed(result: dict) -> str | None:
    """The reasons, when no family of ``result`` has a verified design (every case failed); else None."""
    fams = result.get("families", [])
    if not fams or any(f.get("best") is not None for f in fams):
        return None
    reasons = [
        f"{f.get('template')} start {x.get('start')}: {x.get('message') or x.get('status')}"
        for f in fams
        for x in f.get("failed", [])
    ]
    return "every case failed: " + "; ".join(reasons[:5]) + (" ..." if len(reasons) > 5 else "")


def run_job(job_id: str, attempt: int, *, handle_signals: bool = True) -> int:
    """Body of a job process (run ``attempt`` of the job). Returns the process's exit code: 0 with a
    verdict written (or nothing to do), :data:`RETRY` without one (the dispatcher requeues), 1 on failure."""
    from ...optim import optimise
    from ...optim.batch import BatchCancelled

    store = JobStore(
        os.environ["FLEXOPT_DATABASE_URL"],
        Path(os.environ["FLEXOPT_DATA_DIR"]),
        float(os.environ.get("FLEXOPT_LEASE_SECONDS", "15")),
    )
    holder = f"{HOST}:{os.getpid()}:job"  # a job process leads its own process group (its pool workers)
    job = store.row(job_id)
    if job is None or job["attempts"] != attempt:
        return 0
    if job["status"] == "cancelling":  # cancelled before this process started
        store.update(job_id, attempt, status="cancelled")
        return 0
    if job["status"] != "running" or not store.heartbeat(job_id, attempt, holder):
        return 0
    spec = json.loads(job["spec"])
    cancel, interrupted = threading.Event(), threading.Event()
    partial: list[dict] = []
    latest: dict = {}  # the last progress written ({done, total} and a search's phase, counts, best), again with the verdict
    cases = store.case_dir()

    def stop_outside() -> None:
        """Stopped from outside (SIGTERM from a stopping server, or a newer run owns the job): stop the batch,
        write no verdict."""
        interrupted.set()
        cancel.set()

    def watch() -> None:
        beat = max(0.5, store.lease_seconds / 4)
        last = 0.0
        while not cancel.is_set():
            try:
                if time.monotonic() - last >= beat:
                    if not store.heartbeat(job_id, attempt, holder):
                        stop_outside()  # recovered and handed to a newer run, or deleted
                        break
                    last = time.monotonic()
                row = store.get(job_id)
                if row is not None and row["status"] == "cancelling":
                    cancel.set()
            except StoreUnavailable as exc:  # a busy or unreachable database: keep going, look again
                log.warning("job %s: %s", job_id, exc)
            time.sleep(0.3)

    def progress(event: dict) -> None:
        # a topology search adds its phase, its counts (screened, passed, ...) and the best so far
        shown = {
            "done": event["done"],
            "total": event["total"],
            **{k: event[k] for k in ("phase", "counts", "best") if k in event},
        }
        latest.update(shown)
        try:
            partial.append(_summary(json.loads((cases / f"{event['id']}.json").read_text()), event.get("phase")))
        except (OSError, json.JSONDecodeError):
            pass
        try:  # best effort: a database busy for longer than its timeout must not fail the optimisation
            store.update(
                job_id,
                attempt,
                progress=json.dumps(finite(shown), allow_nan=False),
                partial=json.dumps(finite(partial), allow_nan=False),
            )
        except StoreUnavailable:  # the next case's progress writes it again
            log.warning("job %s: progress not written", job_id)

    if spec.get("kind") == "frequency-curve":  # a curve too costly for a request: one computation
        return _curve_job(store, job_id, attempt, spec, holder)
    if handle_signals:
        signal.signal(signal.SIGTERM, lambda signum, frame: stop_outside())
        signal.signal(signal.SIGINT, lambda signum, frame: stop_outside())
    threading.Thread(target=watch, daemon=True, name="flexopt-lease").start()
    workers = int(os.environ["FLEXOPT_JOB_WORKERS"]) if os.environ.get("FLEXOPT_JOB_WORKERS") else None
    try:
        if spec.get("kind") == "topology-search":  # same batch machinery, same case store: a rerun resumes
            from ...optim.topology import run_topology_search

            search = {k: v for k, v in spec.items() if k != "kind"}
            result = _family_forms(
                run_topology_search(search, workers=workers, store=cases, progress=progress, cancel=cancel)
            )
        elif spec.get("kind") == "pareto-front":  # its phases run on the same batch machinery and case store
            from ...optim.pareto import pareto

            front = {k: v for k, v in spec.items() if k != "kind"}
            result = pareto(front, workers=workers, store=cases, progress=progress, cancel=cancel)
        else:
            result = optimise(spec, workers=workers, store=cases, progress=progress, cancel=cancel)
        blob = json.dumps(finite(result), allow_nan=False)
    except BatchCancelled:
        if interrupted.is_set():
            return RETRY
        store.update(job_id, attempt, status="cancelled")
        return 0
    except RuntimeError as exc:
        if isinstance(exc.__cause__, cf.BrokenExecutor) or interrupted.is_set():
            log.warning(
                "job %s: run %d lost a worker process; finished cases are stored, the job is retried", job_id, attempt
            )
            return RETRY
        store.update(job_id, attempt, status="failed", error=f"{type(exc).__name__}: {exc}")
        return 1
    except Exception as exc:  # noqa: BLE001 - any failure is recorded on the job with its message
        if interrupted.is_set():
            return RETRY
        store.update(job_id, attempt, status="failed", error=f"{type(exc).__name__}: {exc}")
        return 1
    finally:
        cancel.set()
    # a topology search whose candidates were all rejected or failed is still an answer: each says why
    reasons = None if spec.get("kind") == "topology-search" else _all_failed(result)
    if spec.get("kind") == "pareto-front" and not result.get("points"):  # no verified point: say why
        reasons = "no verified point: " + "; ".join(w["message"] for w in result.get("warnings", []))[:2000]
    verdict = {"status": "failed", "error": reasons} if reasons is not None else {"status": "succeeded"}
    if latest:  # progress writes are best effort: one lost in an outage at the end is written with the verdict
        verdict.update(
            progress=json.dumps(finite(latest), allow_nan=False), partial=json.dumps(finite(partial), allow_nan=False)
        )
    for wait in (0.5, 1, 2, 4, 8, 16, 30):  # the verdict outlasts a busy or briefly unreachable database
        try:
            store.update(job_id, attempt, result=blob, **verdict)
            break
        except StoreUnavailable as exc:
            log.warning("job %s: verdict not written (%s); retrying in %g s", job_id, exc, wait)
            time.sleep(wait)
    else:
        return RETRY  # every case is stored: the retry only summarises them
    return 1 if reasons is not None else 0


def _curve_job(store: JobStore, job_id: str, attempt: int, spec: dict, holder: str) -> int:
    """Compute a frequency curve (``worker.curve``) while a thread renews the lease; store it as the result.
    SIGTERM ends the process (default action): the dispatcher requeues the run, which starts again."""
    done = threading.Event()

    def beat() -> None:
        while not done.wait(max(0.5, store.lease_seconds / 4)):
            try:
                store.heartbeat(job_id, attempt, holder)
            except StoreUnavailable as exc:
                log.warning("job %s: %s", job_id, exc)

    threading.Thread(target=beat, daemon=True, name="flexopt-lease").start()
    try:
        ok, payload = worker.curve(json.dumps(spec))
    finally:
        done.set()
    if ok:
        store.update(job_id, attempt, status="succeeded", result=payload.decode(), progress='{"done": 1, "total": 1}')
        return 0
    store.update(job_id, attempt, status="failed", error=f"{payload['kind']}: {payload['message']}")
    return 1


def main(argv: list[str]) -> int:
    """``run JOB_ID ATTEMPT``: the job process's command line (``python -m flexopt.service.jobs``)."""
    if len(argv) == 3 and argv[0] == "run" and argv[2].isdigit():
        import logging.config

        from ..logs import log_config

        logging.config.dictConfig(log_config(os.environ.get("FLEXOPT_LOG_LEVEL", "info")))
        from ...model.threads import limit_process

        limit_process()  # one BLAS thread in the job process and its pool (model.threads)
        return run_job(argv[1], int(argv[2]))
    print("usage: python -m flexopt.service.jobs run JOB_ID ATTEMPT", file=sys.stderr)
    return 2
