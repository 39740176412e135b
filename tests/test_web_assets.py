"""The page's assets ship in a non-editable wheel (package data), and the page loads nothing from a CDN."""

from __future__ import annotations

import re
import subprocess
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
STATIC = ROOT / "service" / "web" / "static"


def test_page_references_only_served_assets() -> None:
    html = (STATIC / "index.html").read_text()
    for src in re.findall(r'(?:src|href)="([^"]+)"', html):
        assert src.startswith("/"), f"index.html refers to {src}: every asset must be served by the package"
        if src.startswith("/static/"):
            assert (STATIC / src.removeprefix("/static/")).exists(), src
    for vendored in (STATIC / "vendor").iterdir():
        assert (vendored / "LICENSE").exists(), f"vendored {vendored.name} without its licence"


def test_wheel_contains_the_page_and_its_assets(tmp_path: Path) -> None:
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(tmp_path), str(ROOT)],
        check=True,
        capture_output=True,
    )
    wheel = next(tmp_path.glob("flexopt-*.whl"))
    names = set(zipfile.ZipFile(wheel).namelist())
    for f in STATIC.rglob("*"):
        if f.is_file():
            rel = "flexopt/service/web/static/" + f.relative_to(STATIC).as_posix()
            assert rel in names, f"{rel} is missing from the wheel: add it to pyproject's package-data"
    assert "flexopt/service/web/__init__.py" in names and "flexopt/service/plots.py" in names
