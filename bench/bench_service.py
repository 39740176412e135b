"""Load benchmark of the HTTP service: N concurrent clients on loopback calling POST /v1/frequency-curve.

The leaf-spring template, exact method, 91 stroke points. Two server configurations in one run:

- ``cached``: default settings; identical requests are answered from the bounded LRU response cache
  (FLEXOPT_CACHE_SIZE entries, keyed by the canonical request JSON), so only the first one computes;
- ``uncached``: FLEXOPT_CACHE_SIZE=0, every request computes (~0.1 s of CPU each); past FLEXOPT_MAX_CONCURRENT
  running computations the server answers 429 and the client waits Retry-After, as service.client does.

Latency is per successful request, from the first attempt to the answer (retries included). The server runs
in a separate process (``flexopt serve``) so that client and server do not share an event loop; they do
share the machine's cores. Not a test: it prints a markdown table.

Usage::

    python bench/bench_service.py [--clients 32] [--seconds 10] [--modes cached,uncached]
"""

from __future__ import annotations

import argparse
import asyncio
import os
import socket
import statistics
import subprocess
import sys
import time
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parents[1]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _start(env_extra: dict[str, str]) -> tuple[subprocess.Popen, str]:
    port = _free_port()
    env = {**os.environ, "PYTHONPATH": str(ROOT), **env_extra}
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "flexopt.service.cli",
            "serve",
            "--host",
            "127.0.0.1",
            "--port",
            str(port),
            "--log-level",
            "warning",
        ],
        env=env,
        cwd=ROOT,
    )
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        try:
            if httpx.get(f"{url}/health", timeout=1).status_code == 200:
                return proc, url
        except httpx.TransportError:
            time.sleep(0.1)
    proc.terminate()
    raise RuntimeError("server did not start")


async def _run(url: str, clients: int, seconds: float) -> dict[str, float]:
    async with httpx.AsyncClient(base_url=url, timeout=120, limits=httpx.Limits(max_connections=clients)) as http:
        scene = (await http.post("/v1/templates/leaf-spring/scene", json={"parameters": {"points": 91}})).json()
        body = {"scene": scene, "method": "exact"}
        assert (await http.post("/v1/frequency-curve", json=body)).status_code == 200  # warm-up: kernels loaded
        latencies: list[float] = []
        counts = {"429": 0, "errors": 0}
        stop = time.monotonic() + seconds

        async def worker() -> None:
            while time.monotonic() < stop:
                t0 = time.perf_counter()
                while True:
                    r = await http.post("/v1/frequency-curve", json=body)
                    if r.status_code == 429:
                        counts["429"] += 1
                        await asyncio.sleep(float(r.headers.get("retry-after", "1")))
                        continue
                    break
                if r.status_code == 200:
                    latencies.append(time.perf_counter() - t0)
                else:
                    counts["errors"] += 1

        t0 = time.perf_counter()
        await asyncio.gather(*(worker() for _ in range(clients)))
        wall = time.perf_counter() - t0
    lat = sorted(latencies)
    q = statistics.quantiles(lat, n=100) if len(lat) > 1 else [lat[0] if lat else float("nan")] * 99
    return {
        "n": len(lat),
        "p50": q[49] * 1e3,
        "p99": q[98] * 1e3,
        "rps": len(lat) / wall,
        "r429": counts["429"],
        "errors": counts["errors"],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clients", type=int, default=32)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--modes", default="cached,uncached")
    args = ap.parse_args()
    envs = {"cached": {}, "uncached": {"FLEXOPT_CACHE_SIZE": "0"}}
    rows = []
    for mode in args.modes.split(","):
        proc, url = _start(envs[mode])
        try:
            res = asyncio.run(_run(url, args.clients, args.seconds))
        finally:
            proc.terminate()
            proc.wait(10)
        rows.append((mode, res))
    print(
        f"POST /v1/frequency-curve, leaf-spring, exact, 91 points, {args.clients} concurrent clients, "
        f"{args.seconds:g} s per mode, {os.cpu_count()} cores\n"
    )
    print("| server | requests ok | p50 [ms] | p99 [ms] | throughput [req/s] | 429 answers (retried) | errors |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for mode, r in rows:
        print(f"| {mode} | {r['n']} | {r['p50']:.1f} | {r['p99']:.1f} | {r['rps']:.1f} | {r['r429']} | {r['errors']} |")


if __name__ == "__main__":
    main()
