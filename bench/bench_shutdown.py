"""How long ``flexopt serve`` takes to stop on SIGTERM with a job and a synchronous curve running.

Starts the server (process pool), submits a four-case optimisation job, waits for its first finished case,
starts a 1001-point cross-spring-pivot curve, then sends SIGTERM and times the exit; checks that no job process
is left. The container's stop grace (Docker: 10 s by default) must be longer. Not a test: prints one line.

Usage::

    python bench/bench_shutdown.py
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx

JOB = {
    "families": [{"template": "cross-spring-pivot", "design": {"length": [0.03, 0.07], "thickness": [1.5e-4, 4e-4]}}],
    "starts": 4,
}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _job_processes(job_id: str) -> list[int]:
    out = []
    for cmd in Path("/proc").glob("[0-9]*/cmdline"):
        try:
            if f"flexopt.service.jobs run {job_id}" in cmd.read_bytes().replace(b"\0", b" ").decode():
                out.append(int(cmd.parent.name))
        except OSError:
            pass
    return out


def main() -> None:
    port = _free_port()
    url = f"http://127.0.0.1:{port}"
    env = {**os.environ, "FLEXOPT_DATA_DIR": tempfile.mkdtemp(), "FLEXOPT_JOB_WORKERS": "1"}
    p = subprocess.Popen(
        [sys.executable, "-m", "flexopt.service.cli", "serve", "--port", str(port), "--log-level", "warning"],
        env=env,
        stderr=subprocess.DEVNULL,
    )
    while True:
        try:
            if httpx.get(url + "/ready").status_code == 200:
                break
        except httpx.TransportError:
            pass
        time.sleep(0.2)
    jid = httpx.post(url + "/v1/optimisations", json=JOB).json()["id"]
    while httpx.get(f"{url}/v1/optimisations/{jid}").json()["progress"].get("done", 0) < 1:
        time.sleep(0.2)
    scene = httpx.post(url + "/v1/templates/cross-spring-pivot/scene", json={"parameters": {"points": 1001}}).json()

    def curve() -> None:
        try:
            httpx.post(url + "/v1/frequency-curve", json={"scene": scene}, timeout=60)
        except httpx.TransportError:
            pass  # cut by the stopping server

    threading.Thread(target=curve, daemon=True).start()
    time.sleep(1.0)
    t0 = time.perf_counter()
    p.send_signal(signal.SIGTERM)
    p.wait(60)
    print(
        f"server exited {time.perf_counter() - t0:.1f} s after SIGTERM (exit {p.returncode}); "
        f"job processes left: {len(_job_processes(jid))}"
    )


if __name__ == "__main__":
    main()
