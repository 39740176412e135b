"""The README's examples run as tests, so the README cannot drift from the code (issue 26, item 1); so do the
documentation pages' blocks that talk to a server (their other blocks run in test_docs.py, page by page).

Every fenced block of README.md is a case: ``json`` blocks are validated as the spec their ``format`` names;
``sh`` blocks run command by command in a temporary directory (exit status 0, or the ``# exit N`` their
comment announces); blocks that talk to ``localhost:8000`` and the ``python`` blocks run against a real
server this test starts (its address substituted; ``JOB_ID`` becomes the id of the job the block submitted
last). A block opts out only with a marker comment on the line before its fence, for one of the reasons in
:data:`OPT_OUT` (the test reports each skipped block and its reason):

- ``<!-- readme-test: skip: starts a server -->`` (``flexopt serve``: it would not return);
- ``<!-- readme-test: skip: long run -->`` (a benchmark, an optimisation or a search of minutes; its spec is
  checked where the README shows it as a ``json`` block);
- ``<!-- readme-test: ci -->``: the block is the test suite's own command; the test checks that ``.ci/run`` runs
  exactly that command instead of running the suite inside itself.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from .doc_blocks import OPT_OUT, README, ROOT, Block, blocks, pages
from .doc_blocks import commands as _commands
from .doc_blocks import expected_exit as _expected_exit
from .doc_blocks import uses_server as _uses_server


def _all() -> list[Block]:
    return [b for path in (README, *pages()) for b in blocks(path)]


def test_every_block_is_run_or_opts_out_for_a_listed_reason() -> None:
    assert len(blocks(README)) >= 5, "the README's fenced blocks were not found: the pattern no longer matches"
    for b in _all():
        assert b.lang in ("sh", "python", "json"), f"{b}: a fenced block without a language this test runs"
        if b.mark is None or b.mark == "ci":
            continue
        reasons = b.mark.removeprefix("skip: ").split(", ")
        assert b.mark.startswith("skip: ") and set(reasons) <= OPT_OUT, (
            f"{b}: marker '{b.mark}' is neither 'ci' nor 'skip: ' with reasons from {sorted(OPT_OUT)}"
        )


def _case(b: Block) -> None:
    if b.mark is not None and b.mark.startswith("skip"):
        pytest.skip(f"{b}: {b.mark.removeprefix('skip: ')} (marked in the page)")


@pytest.mark.parametrize("block", [b for b in _all() if b.lang == "json"], ids=str)
def test_json_block_is_a_valid_spec(block: Block) -> None:
    from flexopt.optim import Problem
    from flexopt.optim.topology.spec import TopologySpec

    _case(block)
    doc = json.loads(block.body)
    model = {"flexopt-problem": Problem, "flexopt-topology": TopologySpec}[doc["format"]]
    model.model_validate(doc)


def test_ci_block_is_what_ci_runs() -> None:
    ci = [b for b in blocks(README) if b.mark == "ci"]
    assert ci, "the README shows no test command marked '<!-- readme-test: ci -->'"
    script = (ROOT / ".ci" / "run").read_text()
    for b in ci:
        for command in _commands(b.body):
            assert command in script, f"{b}: .ci/run does not run `{command}`"


@pytest.mark.slow
@pytest.mark.parametrize(
    "block", [b for b in blocks(README) if b.lang == "sh" and b.mark != "ci" and not _uses_server(b)], ids=str
)
def test_shell_block_runs(block: Block, tmp_path: Path) -> None:
    _case(block)
    env = {
        **os.environ,
        "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
        "MPLBACKEND": "Agg",
    }
    for command in _commands(block.body):
        r = subprocess.run(
            ["bash", "-c", command], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900, check=False
        )
        assert r.returncode == _expected_exit(command), (
            f"{block}: `{command}` exited {r.returncode}, expected {_expected_exit(command)}\n{r.stderr[-2000:]}"
        )


# --- blocks that talk to a server ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def server_url(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    pytest.importorskip("uvicorn")
    from flexopt.service.api.settings import Settings

    from .test_service import _Server

    settings = Settings(
        data_dir=tmp_path_factory.mktemp("data"), max_concurrent=1, max_jobs=1, job_workers=1, request_timeout=300
    )
    with _Server(settings) as server:
        yield server.url


def _job_id(output: str) -> str | None:
    m = re.search(r"^location: /v1/[a-z-]+/([0-9a-f-]+)", output, re.M | re.I) or re.search(
        r'"id":\s*"([0-9a-f-]+)"', output
    )
    return m[1] if m else None


def _cancel_jobs(url: str) -> None:
    """Cancel what a block submitted, so that the next block's job does not queue behind it."""
    import httpx

    for collection in ("optimisations", "topology-searches"):
        for job in httpx.get(f"{url}/v1/{collection}").json()["items"]:
            httpx.delete(f"{url}/v1/{collection}/{job['id']}")


@pytest.mark.slow
@pytest.mark.parametrize("block", [b for b in _all() if b.lang == "sh" and _uses_server(b)], ids=str)
def test_curl_block_runs_against_a_server(block: Block, server_url: str, tmp_path: Path) -> None:
    _case(block)
    job = None
    try:
        for command in _commands(block.body):
            command = re.sub(r"\s+#[^'\"]*$", "", command)  # a trailing comment would swallow the -w below
            command = command.replace("localhost:8000", server_url.removeprefix("http://"))
            if "JOB_ID" in command:
                assert job is not None, f"{block}: `{command}` names JOB_ID before any job was submitted"
                command = command.replace("JOB_ID", job)
            # the HTTP status on a line of its own after the body (-w), so that every answer is checked
            r = subprocess.run(
                ["bash", "-c", command + " -w '\\n%{http_code}\\n'" if "> " not in command else command],
                cwd=tmp_path,
                capture_output=True,
                text=True,
                timeout=300,
                check=False,
            )
            assert r.returncode == 0, f"{block}: `{command}` exited {r.returncode}: {r.stderr}"
            if "> " not in command:
                body, status = r.stdout.rstrip("\n").rsplit("\n", 1)
                assert status.startswith("2"), f"{block}: `{command}` answered {status}: {body[-1000:]}"
                job = _job_id(body) or job
            else:  # redirected to a file: the file is the answer
                target = shlex.split(command.split("> ")[-1])[0]
                assert (tmp_path / target).stat().st_size > 0, f"{block}: `{command}` wrote nothing"
    finally:
        _cancel_jobs(server_url)


@pytest.mark.slow
@pytest.mark.parametrize("block", [b for b in _all() if b.lang == "python" and _uses_server(b)], ids=str)
def test_python_block_runs_against_a_server(block: Block, server_url: str, tmp_path: Path) -> None:
    _case(block)
    code = block.body.replace("http://127.0.0.1:8000", server_url).replace(
        "localhost:8000", server_url.removeprefix("http://")
    )
    r = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=900, check=False
    )
    try:
        assert r.returncode == 0, f"{block} failed:\n{r.stderr[-3000:]}"
    finally:
        _cancel_jobs(server_url)
