"""What the bench scripts share: the template sets they time, a ``flexopt`` package of a checkout or a commit,
the fresh-process runner, the load line and interleaved timing.

A script imports it as ``from _common import ...``: ``python bench/<script>.py`` puts bench/ first on
``sys.path``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, TypeVar

K = TypeVar("K")

ROOT = Path(__file__).resolve().parents[1]

#: The three classic flexures and the optimiser's three hinge families, in the order the tables print them.
HINGES = (
    "leaf-spring",
    "parallel-leaf-spring",
    "cross-spring-pivot",
    "cartwheel-hinge",
    "three-fold-cross-hinge",
    "double-cross-hinge",
)
#: The templates with a stroke whose default mesh the tables report: the hinges, the topology hinge and the guides.
DEFAULT_TEMPLATES = (
    *HINGES,
    "topology-hinge",
    "wire-guide-5",
    "wire-guide-parallel",
    "folded-sheet-guide-5",
    "folded-sheet-guide-6",
)

#: The console script's entry, for either layout (service/cli.py, or the package service/cli/ with main.py), so
#: that two versions start alike.
LAUNCH = "import sys; from flexopt.service.cli import main; sys.exit(getattr(main, 'main', main)())"


def package(src: Path, dest: Path) -> Path:
    """``dest`` with a ``flexopt`` package made of checkout ``src`` (the layout pyproject.toml maps)."""
    pkg = dest / "flexopt"
    pkg.mkdir(parents=True)
    for f in (src / "service" / "_root").glob("*.py"):
        shutil.copy(f, pkg / f.name)
    for d in ("model", "optim", "service"):
        (pkg / d).symlink_to(src / d)
    return dest


def from_commit(commit: str, dest: Path) -> Path:
    """``dest/pkg`` with a ``flexopt`` package of ``commit`` of this repository (``git archive`` into ``dest/src``)."""
    src = dest / "src"
    src.mkdir(parents=True)
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", commit], check=True, capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(src)], input=archive, check=True)
    return package(src, dest / "pkg")


def run_cli(args: Sequence[str], env: Mapping[str, str]) -> tuple[float, subprocess.CompletedProcess[str]]:
    """``flexopt <args>`` in a fresh process through :data:`LAUNCH` with ``env``: its wall seconds, start-up
    included, and the finished process (its exit code is the caller's to judge)."""
    t = time.perf_counter()
    out = subprocess.run(
        [sys.executable, "-c", LAUNCH, *args], env=dict(env), capture_output=True, text=True, check=False
    )
    return time.perf_counter() - t, out


def add_base_arguments(p: argparse.ArgumentParser, required: bool = True) -> None:
    """The 'before' version of a before/after benchmark: ``--base DIR`` or ``--base-commit REV`` (one of them;
    ``required=False``: at most one, for a script with a mode that needs none)."""
    g = p.add_mutually_exclusive_group(required=required)
    g.add_argument("--base", type=Path, help="directory holding the 'before' flexopt package (PYTHONPATH)")
    g.add_argument("--base-commit", help="commit of this repository to build the 'before' package from")


def base_package(args: argparse.Namespace, tmp: Path) -> Path:
    """The directory to put on ``PYTHONPATH`` for the 'before' version (:func:`add_base_arguments`), made under
    ``tmp`` from ``--base-commit``."""
    return args.base if args.base is not None else from_commit(args.base_commit, tmp / "before")


def bench_env(pythonpath: Path | str, **extra: str) -> dict[str, str]:
    """This process's environment with ``PYTHONPATH`` the version to run and one BLAS thread (the benchmarks'
    default; bench_blas.py is the one that measures BLAS threads)."""
    return dict(os.environ, PYTHONPATH=str(pythonpath), OPENBLAS_NUM_THREADS="1", **extra)


def run_fresh(code: str, pythonpath: Path | str, env: Mapping[str, str] | None = None) -> Any:
    """Run ``code`` in a fresh Python process (``env``, default :func:`bench_env` of ``pythonpath``) and return
    the JSON its last line of output prints; its error output is raised with a failing exit."""
    out = subprocess.run(
        [sys.executable, "-c", code],
        env=dict(env) if env is not None else bench_env(pythonpath),
        capture_output=True,
        text=True,
        check=False,
    )
    if out.returncode:
        raise RuntimeError(f"a fresh process exited {out.returncode}: {out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def cpu_seconds(pids: Sequence[int]) -> float:
    """CPU seconds (user + system) the processes ``pids`` have used so far (psutil; 0 for one that is gone)."""
    import psutil

    out = 0.0
    for pid in pids:
        try:
            t = psutil.Process(pid).cpu_times()
        except psutil.Error:
            continue
        out += t.user + t.system
    return out


def load_line(when: str) -> str:
    """``load average L <when>; N CPUs``: the 1-minute load ``uptime`` shows, for a table's header."""
    return f"load average {os.getloadavg()[0]:.2f} {when}; {os.cpu_count()} CPUs"


def interleave(rounds: int, calls: Mapping[K, Callable[[], Any]]) -> tuple[dict[K, list[float]], dict[K, Any]]:
    """Seconds of each call over ``rounds`` rounds, the calls in turn within a round (A B C A B C ...), so a drift
    of the machine's load falls on all alike; and each call's last result."""
    seconds: dict[K, list[float]] = {k: [] for k in calls}
    last: dict[K, Any] = {}
    for _ in range(rounds):
        for k, f in calls.items():
            t0 = time.perf_counter()
            last[k] = f()
            seconds[k].append(time.perf_counter() - t0)
    return seconds, last


def median_ratio(a: Sequence[float], b: Sequence[float]) -> float:
    """The median of the per-pair ratios a / b (of interleaved runs)."""
    return statistics.median([x / y for x, y in zip(a, b)])
