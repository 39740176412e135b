"""The documentation site builds with warnings as errors, and every code block of its pages runs.

The pages' blocks that talk to a server (``localhost:8000``) run in test_readme.py against a server it starts;
the others run here, a page's blocks in order in one temporary directory (with the repository's ``examples/``
beside them), so a tutorial's later steps see the files its earlier steps wrote: ``sh`` blocks command by
command in bash (each must exit 0, or the ``# exit N`` its comment announces), ``python`` blocks in a fresh
interpreter. A block opts out only with the marker of tests/doc_blocks.py (``<!-- readme-test: skip: REASON
-->``); ``json`` blocks are validated in test_readme.py.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from .doc_blocks import ROOT, Block, blocks, commands, expected_exit, pages, uses_server

RUN = {"python", "sh"}


def _local(page: Path) -> list[Block]:
    return [b for b in blocks(page) if b.lang in RUN and not b.skipped and not uses_server(b)]


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env.setdefault("MPLBACKEND", "Agg")
    return env


@pytest.mark.slow
def test_site_builds_with_warnings_as_errors(tmp_path: Path) -> None:
    pytest.importorskip("mkdocs", reason="the docs extra (mkdocs, mkdocstrings) is part of the test extra")
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "mkdocs",
            "build",
            "--strict",
            "-f",
            str(ROOT / "docs" / "mkdocs.yml"),
            "-d",
            str(tmp_path / "site"),
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=_env(),
        timeout=600,
    )
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    assert (tmp_path / "site" / "index.html").exists()
    assert (tmp_path / "site" / "reference" / "model" / "index.html").exists()


@pytest.mark.slow
@pytest.mark.parametrize("page", [p for p in pages() if _local(p)], ids=lambda p: p.name)
def test_code_blocks_run(page: Path, tmp_path: Path) -> None:
    shutil.copytree(ROOT / "examples", tmp_path / "examples")
    for b in _local(page):
        steps = (
            [[sys.executable, "-c", b.body]] if b.lang == "python" else [["bash", "-c", c] for c in commands(b.body)]
        )
        for cmd in steps:
            want = 0 if b.lang == "python" else expected_exit(cmd[-1])
            run = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp_path, env=_env(), timeout=900)
            assert run.returncode == want, (
                f"{b}: exit {run.returncode}, expected {want}\n--- run ---\n{cmd[-1]}\n--- stdout ---\n"
                f"{run.stdout[-2000:]}\n--- stderr ---\n{run.stderr[-2000:]}"
            )


def test_pages_have_blocks_to_run() -> None:
    """The pattern still finds the pages' blocks (a changed fence syntax would silently run nothing)."""
    assert sum(len(_local(p)) for p in pages()) >= 8
