"""Memory of ``flexopt serve`` over a stream of distinct scenes (issue 29 item 2).

Starts the server (process pool, default settings but for the data directory), then sends distinct leaf-spring
scenes (each a different thickness, so no response is a cache hit) to ``/v1/frequency-curve`` (JSON, with and
without ``shapes``, and PNG) and ``/v1/modes``, plus scenes naming unknown nodes (422s). Every ``--every``
requests it prints the resident memory (RSS, from ``/proc``) of the server process and of its worker processes.
Memory should level off: the response cache is bounded in bytes (``FLEXOPT_CACHE_BYTES``) and each worker
process is replaced after ``runtime.WORKER_TASKS`` computations. Not a test: prints a table.

``--fuzz``: the requests are the test fuzzer's instead (``tests/fuzz_requests.py``: every POST route's example
and every template's scene, mutated structurally and semantically, each scene distinct; jobs it manages to
submit are cancelled at once). ``--trace`` (with ``--fuzz``) runs the server in this process instead of a
subprocess, and prints what the server's heap gained between the first sample and the last (tracemalloc
snapshots diffed, by line) and the object counts by type that grew (gc), to find what is retained.

Usage::

    python bench/bench_soak.py [--requests 400] [--every 40] [--points 5] [--kinds json,shapes,png,modes,bad]
    python bench/bench_soak.py --fuzz [--requests 3000] [--every 250] [--trace]
"""

from __future__ import annotations

import argparse
import gc
import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _rss_mb(pid: int) -> float:
    try:
        pages = int(Path(f"/proc/{pid}/statm").read_text().split()[1])
    except (OSError, IndexError):
        return 0.0
    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20


def _children(pid: int) -> list[int]:
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            text = stat.read_text()
        except OSError:
            continue
        if int(text[text.rindex(")") + 2 :].split()[1]) == pid:
            out.append(int(stat.parent.name))
    return out


def _wait(c: httpx.Client, seconds: float = 180.0) -> None:
    """Until the server answers /health (a loaded machine starts it in tens of seconds)."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        try:
            if c.get("/health").status_code == 200:
                return
        except httpx.TransportError:
            time.sleep(0.2)
    raise SystemExit(f"the server did not answer /health within {seconds:.0f} s")


def _types() -> dict[str, int]:
    counts: dict[str, int] = {}
    for o in gc.get_objects():
        t = type(o).__qualname__
        counts[t] = counts.get(t, 0) + 1
    return counts


def _fuzz(args: argparse.Namespace) -> None:
    """Memory over a stream of the test fuzzer's requests (module docstring)."""
    import threading
    import tracemalloc

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from tests.fuzz_requests import bases, mutated

    port = _free_port()
    with tempfile.TemporaryDirectory() as data:
        env = dict(os.environ, FLEXOPT_DATA_DIR=data, OPENBLAS_NUM_THREADS="1")
        srv: subprocess.Popen | None = None
        server = None
        if args.trace:  # in this process: its heap can be snapshotted
            import uvicorn
            from flexopt.service.api.app import create_app
            from flexopt.service.api.settings import Settings

            os.environ.update(env)
            server = uvicorn.Server(
                uvicorn.Config(create_app(Settings()), host="127.0.0.1", port=port, log_level="warning", ws="none")
            )
            threading.Thread(target=server.run, daemon=True).start()
            pid = os.getpid()
        else:
            srv = subprocess.Popen(
                [sys.executable, "-m", "flexopt.service.cli", "serve", "--port", str(port), "--log-level", "warning"],
                env=env,
            )
            pid = srv.pid
        try:
            with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=120) as c:
                _wait(c)
                bodies, scenes = bases(lambda p: c.get(p).json(), lambda p: c.post(p).json())
                stream = mutated(bodies, scenes, c.get("/health").json()["methods"], seed=args.seed)
                print(f"load: {os.getloadavg()[0]:.1f}  requests  seconds  server_MB  workers_MB  statuses")
                start, seen, first = time.monotonic(), {}, None
                for i in range(args.requests):
                    method, path, body, headers = next(stream)
                    try:
                        r = c.request(method, path, json=body, headers=headers)
                        status = r.status_code
                        if status == 202 and "json" in r.headers.get("content-type", ""):
                            c.delete(r.headers.get("location") or f"{path}/{r.json()['id']}")
                    except httpx.TransportError as exc:
                        status = type(exc).__name__
                    except ValueError:  # a body nested too deeply to send: not a request
                        continue
                    seen[status] = seen.get(status, 0) + 1
                    if (i + 1) % args.every == 0:
                        workers = sum(_rss_mb(p) for p in _children(pid))
                        print(
                            f"{'':13}{i + 1:8d}  {time.monotonic() - start:7.0f}  {_rss_mb(pid):9.0f}  "
                            f"{workers:10.0f}  {dict(sorted(seen.items(), key=str))}",
                            flush=True,
                        )
                        if args.trace and first is None:
                            gc.collect()
                            tracemalloc.start(8)
                            first = (tracemalloc.take_snapshot(), _types())
                if args.trace and first is not None:
                    gc.collect()
                    last, types = tracemalloc.take_snapshot(), _types()
                    skip = [
                        tracemalloc.Filter(False, f"*{m}*") for m in ("httpx", "h11", "fuzz_requests", "tracemalloc")
                    ]
                    print("heap gained since the first sample, by line (top 25):")
                    for d in last.filter_traces(skip).compare_to(first[0].filter_traces(skip), "lineno")[:25]:
                        print(f"  {d.size_diff / 2**20:+8.2f} MB {d.count_diff:+8d} blocks  {d.traceback}")
                    grew = sorted(((n - first[1].get(t, 0), t) for t, n in types.items()), reverse=True)[:15]
                    print("objects by type that grew:", ", ".join(f"{t} {n:+d}" for n, t in grew))
        finally:
            if srv is not None:
                srv.terminate()
                srv.wait(30)
            if server is not None:
                server.should_exit = True
                time.sleep(2)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--requests", type=int, default=400)
    ap.add_argument("--every", type=int, default=40)
    ap.add_argument("--fuzz", action="store_true", help="the test fuzzer's requests over every POST route")
    ap.add_argument("--trace", action="store_true", help="with --fuzz: the server in this process, heap diffed")
    ap.add_argument("--seed", type=int, default=29)
    ap.add_argument("--points", type=int, default=5, help="stroke points of each scene (large answers: 201)")
    ap.add_argument("--kinds", default="json,shapes,png,modes,bad", help="the requests sent, in turn")
    args = ap.parse_args()
    if args.fuzz:
        _fuzz(args)
        return
    port = _free_port()
    with tempfile.TemporaryDirectory() as data:
        env = dict(os.environ, FLEXOPT_DATA_DIR=data, OPENBLAS_NUM_THREADS="1")
        srv = subprocess.Popen(
            [sys.executable, "-m", "flexopt.service.cli", "serve", "--port", str(port), "--log-level", "warning"],
            env=env,
        )
        try:
            url = f"http://127.0.0.1:{port}"
            with httpx.Client(base_url=url, timeout=120) as c:
                _wait(c)
                base = c.post("/v1/templates/leaf-spring/scene").json()
                base["stroke"]["points"] = args.points
                kinds = args.kinds.split(",")
                print(f"load: {os.getloadavg()[0]:.1f}  requests  seconds  server_MB  workers_MB  statuses")
                start, seen = time.monotonic(), {}
                for i in range(args.requests):
                    scene = {
                        **base,
                        "elements": [
                            {**e, "section": {**e["section"], "thickness": 4e-4 * (1 + 1e-4 * i)}}
                            if "section" in e
                            else e
                            for e in base["elements"]
                        ],
                    }
                    kind = ("json", "shapes", "png", "modes", "bad").index(kinds[i % len(kinds)])
                    if kind == 0:
                        r = c.post("/v1/frequency-curve", json={"scene": scene})
                    elif kind == 1:
                        r = c.post("/v1/frequency-curve", json={"scene": scene, "shapes": True})
                    elif kind == 2:
                        r = c.post("/v1/frequency-curve", json={"scene": scene}, headers={"Accept": "image/png"})
                    elif kind == 3:
                        r = c.post("/v1/modes", json={"scene": scene, "at_stroke": 0.0})
                    elif i % 2 == 0:  # a large body (about 600 kB) of misspelt fields: a 422 listing 100 of them
                        bad = {
                            **scene,
                            "nodes": [
                                {**scene["nodes"][0], **{f"positon{i}_{k}": k for k in range(30_000)}},
                                *scene["nodes"][1:],
                            ],
                        }
                        r = c.post("/v1/frequency-curve", json={"scene": bad})
                    else:  # elements naming unknown nodes: a 422 with suggestions
                        bad = {**scene, "elements": [{**e, "nodes": [f"n{i}a", f"n{i}b"]} for e in scene["elements"]]}
                        r = c.post("/v1/frequency-curve", json={"scene": bad})
                    seen[r.status_code] = seen.get(r.status_code, 0) + 1
                    if (i + 1) % args.every == 0:
                        workers = sum(_rss_mb(p) for p in _children(srv.pid))
                        print(
                            f"{'':13}{i + 1:8d}  {time.monotonic() - start:7.0f}  {_rss_mb(srv.pid):9.0f}  "
                            f"{workers:10.0f}  {dict(sorted(seen.items()))}",
                            flush=True,
                        )
        finally:
            srv.terminate()
            srv.wait(30)


if __name__ == "__main__":
    main()
