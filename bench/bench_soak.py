"""Memory of ``flexopt serve`` over a stream of distinct scenes (issue 29 item 2).

Starts the server (process pool, default settings but for the data directory), then sends distinct leaf-spring
scenes (each a different thickness, so no response is a cache hit) to ``/v1/frequency-curve`` (JSON, with and
without ``shapes``, and PNG) and ``/v1/modes``, plus scenes naming unknown nodes (422s). Every ``--every``
requests it prints the resident memory (RSS, from ``/proc``) of the server process and of its worker processes.
Memory should level off: the response cache is bounded in bytes (``FLEXOPT_CACHE_BYTES``) and each worker
process is replaced after ``runtime.WORKER_TASKS`` computations. Not a test: prints a table.

Usage::

    python bench/bench_soak.py [--requests 400] [--every 40]
"""

from __future__ import annotations

import argparse
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--requests", type=int, default=400)
    ap.add_argument("--every", type=int, default=40)
    args = ap.parse_args()
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
                for _ in range(200):
                    try:
                        if c.get("/health").status_code == 200:
                            break
                    except httpx.TransportError:
                        time.sleep(0.1)
                base = c.post("/v1/templates/leaf-spring/scene").json()
                base["stroke"]["points"] = 5
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
                    kind = i % 5
                    if kind == 0:
                        r = c.post("/v1/frequency-curve", json={"scene": scene})
                    elif kind == 1:
                        r = c.post("/v1/frequency-curve", json={"scene": scene, "shapes": True})
                    elif kind == 2:
                        r = c.post("/v1/frequency-curve", json={"scene": scene}, headers={"Accept": "image/png"})
                    elif kind == 3:
                        r = c.post("/v1/modes", json={"scene": scene, "at_stroke": 0.0})
                    elif i % 10 == 4:  # a large body (about 600 kB) of misspelt fields: a 422 listing 100 of them
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
