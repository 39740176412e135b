"""Style gates (issue 27 item 7): ruff's formatter and linter over the repository, mypy over service/ and
optim/ (and model/ as far as CasADi's untyped API allows), all configured in pyproject.toml.

mypy reads the package as it is installed (``flexopt.model`` = model/, ...): the test lays that tree out with
symbolic links under a temporary directory, so the same check runs on a checkout, an editable install or a wheel
install.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _tool(name: str) -> list[str]:
    pytest.importorskip(name, reason=f"{name} is part of the test extra")
    return [sys.executable, "-m", name]


def _run(cmd: list[str], cwd: Path, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=900, env=env)


def test_ruff_format() -> None:
    run = _run([*_tool("ruff"), "format", "--check", "."], ROOT)
    assert run.returncode == 0, "run `ruff format .`:\n" + run.stdout[-3000:] + run.stderr[-2000:]


def test_ruff_lint() -> None:
    run = _run([*_tool("ruff"), "check", "--output-format", "concise", "."], ROOT)
    assert run.returncode == 0, run.stdout[-4000:] + run.stderr[-2000:]


def _mypy_home() -> Path:
    """A folder per checkout for mypy's staged tree and its incremental cache, beside the compiled kernels
    (``$FLEXOPT_CACHE_DIR`` or ``~/.cache/flexopt``): a rerun checks only what changed (mypy validates every
    cached module by its path, size and content hash, so a stale entry is re-checked, never trusted). A cold
    cache checks everything (65 s on CI's two cores); a warm one about a tenth of that."""
    import hashlib

    env = os.environ.get("FLEXOPT_CACHE_DIR")
    base = Path(env) if env else Path.home() / ".cache" / "flexopt"
    return base / "mypy" / hashlib.sha1(str(ROOT).encode()).hexdigest()[:12]


@pytest.mark.slow
def test_mypy() -> None:
    cmd = _tool("mypy")
    tmp_path = _mypy_home()
    stage = tmp_path / "flexopt"
    if stage.exists():
        shutil.rmtree(stage)  # symbolic links only: rmtree unlinks them, never follows them
    stage.mkdir(parents=True)
    for f in (ROOT / "service" / "_root").glob("*.py"):
        os.symlink(f, stage / f.name)
    for sub in ("model", "optim", "service"):
        os.symlink(ROOT / sub, stage / sub)
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    env = {**os.environ, "MYPYPATH": str(tmp_path)}
    run = _run(
        [
            *cmd,
            "--config-file",
            str(tmp_path / "pyproject.toml"),
            "--cache-dir",
            str(tmp_path / ".mypy"),
            "-p",
            "flexopt.service",
            "-p",
            "flexopt.optim",
            "-p",
            "flexopt.model",
        ],
        tmp_path,
        env,
    )
    assert run.returncode == 0, run.stdout[-5000:] + run.stderr[-2000:]
