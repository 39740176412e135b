"""The fenced code blocks of README.md and docs/pages/*.md, for the tests that run them (test_readme.py: the
README's blocks and every block that talks to a server; test_docs.py: the pages' other blocks, page by page).

A block opts out only with a marker comment on the line before its fence:
``<!-- readme-test: skip: REASONS -->`` with reasons from :data:`OPT_OUT`, or ``<!-- readme-test: ci -->`` for the
test suite's own command (checked against ``.ci/run`` instead of run). A shell command whose comment says
``# exit N`` must exit with N.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
PAGES = ROOT / "docs" / "pages"
#: the reasons a block may give after "skip: " (one or more, comma-separated)
OPT_OUT = {"starts a server", "long run", "installs the package"}
_FENCE = re.compile(
    r"^(?:<!-- readme-test: (?P<mark>[^>]*?) -->\n)?```(?P<lang>[a-z]*)\n(?P<body>.*?)^```$", re.M | re.S
)


@dataclass(frozen=True)
class Block:
    path: Path
    line: int  # the fence's line (1-based)
    lang: str
    body: str
    mark: str | None

    def __str__(self) -> str:
        return f"{self.path.relative_to(ROOT)}:{self.line} ({self.lang})"

    @property
    def skipped(self) -> bool:
        return self.mark is not None and self.mark.startswith("skip")


def blocks(path: Path) -> list[Block]:
    text = path.read_text()
    return [
        Block(path, text.count("\n", 0, m.start("lang")) + 1, m["lang"], m["body"], m["mark"])
        for m in _FENCE.finditer(text)
    ]


def pages() -> list[Path]:
    return sorted(PAGES.glob("*.md"))


def commands(body: str) -> list[str]:
    """Shell commands of a block: continuation lines joined, a here-document kept whole with its command."""
    out, cur, heredoc = [], "", None
    for line in body.splitlines():
        if heredoc is not None:
            cur += "\n" + line
            if line.strip() == heredoc:
                out.append(cur)
                cur, heredoc = "", None
            continue
        cur += line
        if cur.endswith("\\"):
            cur = cur[:-1] + " "
            continue
        m = re.search(r"<<-?\s*['\"]?(\w+)['\"]?", cur)
        if m:
            heredoc = m[1]
            continue
        if cur.strip():
            out.append(cur.strip())
        cur = ""
    if cur.strip():
        out.append(cur.strip())
    return out


def expected_exit(command: str) -> int:
    m = re.search(r"#\s*exit (\d+)", command.splitlines()[0])
    return int(m[1]) if m else 0


def uses_server(block: Block) -> bool:
    """A block that talks to a running service: it names its address, or it is one of the README's Python
    blocks (the client examples)."""
    return (
        "localhost:8000" in block.body
        or "127.0.0.1:8000" in block.body
        or (block.lang == "python" and block.path == README)
    )
