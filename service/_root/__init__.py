"""flexopt: design of large-stroke flexure hinges.

The everyday calls are at the top: :func:`curve`, :func:`modes`, :func:`diagnose`, :func:`optimise`,
:func:`template` and :func:`load` (see :mod:`flexopt.api`). Installed, the repository's top-level folders
form this one package (``pyproject.toml`` maps them): ``flexopt.model`` (``model/``: the nonlinear beam model,
frequency curves, exact-constraint diagnosis), ``flexopt.optim`` (``optim/``: worst-case optimisation and the
topology search), ``flexopt.service`` (``service/``: command line, HTTP service) and ``flexopt.client`` (the
typed HTTP client; imports httpx and pydantic only). This file lives in ``service/_root/`` because the
repository's top level is fixed.

Everything loads on first use, so ``import flexopt`` stays cheap (no CasADi, no FastAPI) and tab completion
shows the package's own names only.
"""

from __future__ import annotations

__all__ = [
    "__version__",
    "curve",
    "modes",
    "diagnose",
    "optimise",
    "template",
    "load",
    "model",
    "optim",
    "service",
    "client",
    "api",
]

_API = ("curve", "modes", "diagnose", "optimise", "template", "load")
_SUBPACKAGES = ("model", "optim", "service", "client", "api")


def __getattr__(name: str):  # noqa: ANN202 - a module, a function or the version string
    import importlib

    if name in _SUBPACKAGES:
        return importlib.import_module(f".{name}", __name__)
    if name in _API:
        return getattr(importlib.import_module(".api", __name__), name)
    if name == "__version__":  # looked up on first use: importlib.metadata costs about 35 ms at start-up
        from importlib.metadata import PackageNotFoundError, version

        try:
            return version("flexopt")
        except PackageNotFoundError:  # pragma: no cover - a checkout that is not installed
            return "0+unknown"
    raise AttributeError(f"module 'flexopt' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)
