"""mkdocs hook: lay the installed package's shape out for the API reference.

The repository's top-level folders become one package, ``flexopt``, only when installed (pyproject.toml
maps ``service/_root`` to ``flexopt``, ``model/`` to ``flexopt.model``, ...). mkdocstrings reads source files
statically, so this hook builds that tree from symbolic links under ``build/apistage`` before the pages are
rendered; the same reference then builds from a checkout, an editable install or a wheel install.
"""

from __future__ import annotations

import os
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
STAGE = ROOT / "build" / "apistage" / "flexopt"
LINKS = {
    "__init__.py": "service/_root/__init__.py",
    "client.py": "service/_root/client.py",
    "model": "model",
    "optim": "optim",
    "service": "service",
}


def on_startup(command, dirty):  # noqa: ANN001, ANN201 - mkdocs' hook signature
    """Create (or refresh) the staged package tree that mkdocs.yml's ``paths`` points at, before any
    plugin's ``on_config`` (mkdocstrings resolves its paths there)."""
    STAGE.mkdir(parents=True, exist_ok=True)
    for name, target in LINKS.items():
        link = STAGE / name
        if link.is_symlink() or link.exists():
            link.unlink()
        os.symlink(ROOT / target, link)
