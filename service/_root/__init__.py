"""flexopt: design of large-stroke flexure hinges.

Installed, the repository's top-level folders form this one package (``pyproject.toml`` maps them):
``flexopt.model`` (``model/``: the nonlinear beam model, frequency curves, exact-constraint diagnosis),
``flexopt.optim`` (``optim/``: worst-case optimisation across hinge families), ``flexopt.service``
(``service/``: command line, HTTP service) and ``flexopt.client`` (the typed HTTP client; imports httpx and
pydantic only). This file lives in ``service/_root/`` because the repository's top level is fixed.

Subpackages load on first attribute access, so ``import flexopt`` stays cheap (no CasADi, no FastAPI).
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = ["__version__", "model", "optim", "service", "client"]


def __getattr__(name: str) -> Any:
    if name in ("model", "optim", "service", "client"):
        return importlib.import_module(f".{name}", __name__)
    if name == "__version__":  # looked up on first use: importlib.metadata costs about 35 ms at start-up
        from importlib.metadata import PackageNotFoundError, version

        try:
            return version("flexopt")
        except PackageNotFoundError:  # pragma: no cover - a checkout that is not installed
            return "0+unknown"
    raise AttributeError(f"module 'flexopt' has no attribute {name!r}")
