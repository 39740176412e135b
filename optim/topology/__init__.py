"""flexopt.optim.topology: generate hinge topologies, keep the well-constrained ones, optimise and rank them.

:mod:`.grammar` names topologies (descriptors, canonical forms, the enumeration), :mod:`.screen` applies the
exact-constraint filter (seed 002's kinematic diagnosis), :mod:`.rank` optimises the survivors under one
problem and ranks them (:func:`run_topology_search`, the unit a job runs), :mod:`.spec` is the JSON spec.
Only the spec imports eagerly (pydantic); the rest (and CasADi) loads on first use, as in :mod:`optim`.
"""

from __future__ import annotations

import importlib
from typing import Any

from .spec import TopologySpec, example_spec

__all__ = [
    "FAMILIES",
    "Leaf",
    "Stage",
    "Topology",
    "canonical",
    "design_parameters",
    "enumerate_topologies",
    "family_of",
    "parse",
    "screen_scene",
    "screen_topology",
    "TopologySpec",
    "example_spec",
    "run_topology_search",
]

_LAZY = {
    "FAMILIES": "grammar",
    "Leaf": "grammar",
    "Stage": "grammar",
    "Topology": "grammar",
    "canonical": "grammar",
    "design_parameters": "grammar",
    "enumerate_topologies": "grammar",
    "family_of": "grammar",
    "parse": "grammar",
    "screen_scene": "screen",
    "screen_topology": "screen",
    "run_topology_search": "rank",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(f".{_LAZY[name]}", __package__), name)
    raise AttributeError(f"module 'flexopt.optim.topology' has no attribute {name!r}")
