"""BLAS threads as users meet them: the README's CLI command and a server request on a busy machine, before/after.

Issue 26 item 2: every other benchmark sets ``OPENBLAS_NUM_THREADS=1``, which users do not. This one runs
flexopt as a user does -- no ``*_NUM_THREADS`` variable -- while ``--busy`` other processes (default 2) do
numpy matrix products with their default BLAS threads, as other work on a shared machine does. Two
versions are timed side by side, interleaved (A B A B ...), each in fresh processes:

* the README's command, ``flexopt curve --template double-cross-hinge``: the whole process, start-up
  included (wall time from start to exit);
* one server request: ``flexopt serve`` on 127.0.0.1 with a free port per version, then ``POST
  /v1/frequency-curve`` with the double cross's scene, each request a new scene name so that the server's
  result cache never answers (wall time of the request, after one warm-up request per server).

It prints each version's median and range and the median of the per-pair ratios (before / after), with the
load average (``os.getloadavg``, as ``uptime`` shows it) before and after. Version A is this checkout; B
(``--base``) is a directory on ``PYTHONPATH`` holding a ``flexopt`` package, or ``--base-commit`` makes one
from a commit of this repository (``git archive``, as bench_ab.py describes). Both run through the same
launcher (``python -c 'from flexopt.service.cli import main; ...'``), so they start alike::

    python bench/bench_blas.py --base-commit main --pairs 7 --requests 7
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

from _common import LAUNCH, ROOT, add_base_arguments, base_package, package, run_cli
from flexopt.model.threads import VARIABLES

#: every variable through which a BLAS/OpenMP library or flexopt reads its thread count: none is set, as a
#: user's shell sets none
THREAD_VARS = (*VARIABLES, "FLEXOPT_BLAS_THREADS")
BUSY = (
    "import numpy as np\n"
    "a = np.random.default_rng(0).random((1200, 1200))\n"
    "while True:\n"
    "    a = a @ a; a /= np.abs(a).max()\n"
)


def user_env(pythonpath: Path, data_dir: Path | None = None) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in THREAD_VARS}
    env["PYTHONPATH"] = str(pythonpath)
    if data_dir is not None:  # a server: its own job store, and time limits that a slow request does not hit
        env["FLEXOPT_DATA_DIR"] = str(data_dir)
        env["FLEXOPT_REQUEST_TIMEOUT"] = env["FLEXOPT_QUEUE_TIMEOUT"] = "3000"
    return env


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def cli_once(pythonpath: Path) -> tuple[float, int]:
    dt, out = run_cli(["curve", "--template", "double-cross-hinge"], user_env(pythonpath))
    return dt, out.returncode


class Server:
    """``flexopt serve`` of one version on a free port (stopped by :meth:`stop`, by its own pid)."""

    def __init__(self, pythonpath: Path, data_dir: Path) -> None:
        self.port = free_port()
        self.proc = subprocess.Popen(
            [sys.executable, "-c", LAUNCH, "serve", "--port", str(self.port), "--log-level", "warning"],
            env=user_env(pythonpath, data_dir),
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        deadline = time.time() + 120
        while True:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{self.port}/health", timeout=5):
                    return
            except OSError:
                if self.proc.poll() is not None or time.time() > deadline:
                    raise RuntimeError(f"flexopt serve ({pythonpath}) did not start") from None
                time.sleep(0.3)

    def curve(self, scene: dict, n: int) -> float:
        body = json.dumps({"scene": {**scene, "name": f"double-cross-hinge-{n}"}}).encode()
        req = urllib.request.Request(
            f"http://127.0.0.1:{self.port}/v1/frequency-curve", data=body, headers={"Content-Type": "application/json"}
        )
        t = time.perf_counter()
        with urllib.request.urlopen(req, timeout=3000) as r:
            data = json.loads(r.read())
        dt = time.perf_counter() - t
        assert data["status"] == "complete", data["status"]
        return dt

    def stop(self) -> None:
        self.proc.terminate()
        try:
            self.proc.wait(20)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


def summary(label: str, a: list[float], b: list[float]) -> str:
    ratio = statistics.median([y / x for x, y in zip(a, b)])
    return (
        f"| {label} | {statistics.median(b):.2f} ({min(b):.2f}-{max(b):.2f}) | "
        f"{statistics.median(a):.2f} ({min(a):.2f}-{max(a):.2f}) | {ratio:.1f}x |"
    )


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_base_arguments(p)
    p.add_argument("--pairs", type=int, default=5, help="CLI runs per version (interleaved; 0: none)")
    p.add_argument("--requests", type=int, default=5, help="server requests per version (interleaved; 0: none)")
    p.add_argument("--busy", type=int, default=2, help="other busy processes (numpy matmuls, default threads)")
    args = p.parse_args()

    tmp = Path(tempfile.mkdtemp(prefix="bench_blas_"))
    busy: list[subprocess.Popen] = []
    servers: list[Server] = []
    try:
        after = package(ROOT, tmp / "after")
        before = base_package(args, tmp)
        label = args.base_commit or str(args.base)
        scene = json.loads(
            subprocess.run(
                [sys.executable, "-c", LAUNCH, "template", "double-cross-hinge"],
                env=user_env(after),
                capture_output=True,
                text=True,
                check=True,
            ).stdout
        )
        for path in (after, before):  # warm the kernel caches (compiled once, shared by both versions)
            cli_once(path)
        clean = {k: v for k, v in os.environ.items() if k not in THREAD_VARS}
        busy = [subprocess.Popen([sys.executable, "-c", BUSY], env=clean) for _ in range(args.busy)]
        time.sleep(2)
        load0 = os.getloadavg()
        cli_a, cli_b, codes = [], [], set()
        for _ in range(args.pairs):
            for path, out, name in ((before, cli_b, "before"), (after, cli_a, "after")):
                dt, code = cli_once(path)
                out.append(dt)
                codes.add(code)
                print(f"cli {name} {dt:.2f} s (load {os.getloadavg()[0]:.1f})", file=sys.stderr, flush=True)
        if args.requests:
            servers = [Server(before, tmp / "data_before"), Server(after, tmp / "data_after")]
        for s in servers:
            s.curve(scene, -1)  # warm-up: imports and kernels
        req_a, req_b = [], []
        for i in range(args.requests):
            req_b.append(servers[0].curve(scene, i))
            req_a.append(servers[1].curve(scene, i))
            print(f"server before {req_b[-1]:.2f} s, after {req_a[-1]:.2f} s", file=sys.stderr, flush=True)
        load1 = os.getloadavg()
    finally:
        for s in servers:
            s.stop()
        for b in busy:
            b.terminate()
            b.wait()
        shutil.rmtree(tmp, ignore_errors=True)
    print(
        f"# no *_NUM_THREADS set; {args.busy} busy numpy processes with default threads; "
        f"{os.cpu_count()} CPUs; load average {load0[0]:.2f} before, {load1[0]:.2f} after; "
        f"CLI exit codes {sorted(codes)}"
    )
    print(f"| double cross, wall s | before ({label}) | after | before / after |")
    print("|---|---|---|---|")
    if cli_a:
        print(
            summary(
                f"`flexopt curve --template double-cross-hinge` (whole process, {args.pairs} runs each)", cli_a, cli_b
            )
        )
    if req_a:
        print(summary(f"server: one POST /v1/frequency-curve ({args.requests} requests each)", req_a, req_b))
    return 0


if __name__ == "__main__":
    sys.exit(main())
