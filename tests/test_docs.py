"""The documentation site builds with warnings as errors, and every code block in it runs.

A fenced block in ``docs/pages/*.md`` is run unless the line before it is ``<!-- not run: REASON -->`` (a block that
starts a server, installs the package or runs the whole test suite); the reason is required, so a skipped block
says why. ``python`` blocks run in a fresh interpreter, ``sh`` blocks in bash (``-euo pipefail``), a page's blocks
in order in one temporary directory (with the repository's ``examples/`` beside them), so a tutorial's later steps
see the files its earlier ones wrote; other languages (json, text) are data, not run.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs" / "pages"
FENCE = re.compile(r"(?P<before>[^\n]*)\n```(?P<lang>[a-z]*)[^\n]*\n(?P<body>.*?)\n```", re.S)
SKIP = re.compile(r"<!--\s*not run:\s*(?P<why>.+?)\s*-->")
RUN = {"python", "sh", "bash"}


def blocks(path: Path) -> list[tuple[str, str, str | None, int]]:
    """(language, body, skip reason or None, line) of every fenced block of ``path``."""
    text = "\n" + path.read_text()
    out = []
    for m in FENCE.finditer(text):
        skip = SKIP.search(m.group("before"))
        line = text.count("\n", 0, m.start("lang"))
        out.append((m.group("lang"), m.group("body"), skip.group("why") if skip else None, line))
    return out


def _pages() -> list:
    """One case per page that has blocks to run: a page's blocks run in order, in one directory, so a
    tutorial's later steps see the files its earlier steps wrote."""
    cases = []
    for page in sorted(DOCS.glob("*.md")):
        if any(lang in RUN and not why for lang, _, why, _ in blocks(page)):
            cases.append(pytest.param(page, id=page.name))
    return cases


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env.setdefault("MPLBACKEND", "Agg")
    return env


@pytest.mark.slow
def test_site_builds_with_warnings_as_errors(tmp_path: Path) -> None:
    pytest.importorskip("mkdocs", reason="the docs extra (mkdocs, mkdocstrings) is part of the test extra")
    run = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(ROOT / "docs" / "mkdocs.yml"), "-d",
         str(tmp_path / "site")], capture_output=True, text=True, cwd=ROOT, env=_env(), timeout=600,
    )
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    assert (tmp_path / "site" / "index.html").exists()
    assert (tmp_path / "site" / "reference" / "model" / "index.html").exists()


@pytest.mark.slow
@pytest.mark.parametrize("page", _pages())
def test_code_blocks_run(page: Path, tmp_path: Path) -> None:
    shutil.copytree(ROOT / "examples", tmp_path / "examples")
    for lang, body, why, line in blocks(page):
        if lang not in RUN or why:
            continue
        cmd = [sys.executable, "-c", body] if lang == "python" else ["bash", "-euo", "pipefail", "-c", body]
        run = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp_path, env=_env(), timeout=900)
        assert run.returncode == 0, f"{page.name}:{line}: exit {run.returncode}\n--- block ---\n{body}\n" \
            f"--- stdout ---\n{run.stdout[-2000:]}\n--- stderr ---\n{run.stderr[-2000:]}"


def test_every_skipped_block_says_why() -> None:
    """A block marked not run carries a reason, and the marker is spelled so the runner sees it."""
    for page in sorted(DOCS.glob("*.md")):
        for line_no, line in enumerate(page.read_text().splitlines(), 1):
            if "not run" in line and line.strip().startswith("<!--"):
                assert SKIP.search(line), f"{page.name}:{line_no}: write '<!-- not run: REASON -->'"
