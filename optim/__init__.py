"""flexopt.optim: maximise the worst-case first parasitic frequency over the stroke, across hinge families.

``optimise(problem)`` runs every start of every family as a batch (a local process pool, or a Dask cluster)
and returns the verified optimum of each family and their ranking; ``Problem`` is the JSON problem.
The problem schema imports only pydantic; the optimiser (and CasADi) loads on first use, so the HTTP
client can share the schema without the model.
"""

from __future__ import annotations

from typing import Any

from .problem import Family, Problem

__all__ = ["optimise", "run_case", "cases", "summarise", "Problem", "Family"]


_LAZY = ("optimise", "run_case", "cases", "summarise")


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(".search", __package__), name)
    raise AttributeError(f"module 'flexopt.optim' has no attribute {name!r}")
