"""flexopt.optim.topology: generate hinge topologies, keep the well-constrained ones, optimise and rank them.

:mod:`.grammar` names topologies (descriptors, canonical forms, the enumeration), :mod:`.screen` applies the
exact-constraint filter (seed 002's kinematic diagnosis), :mod:`.rank` optimises the survivors under one
problem and ranks them (:func:`run_topology_search`, the unit a job runs).
"""

from __future__ import annotations

from .grammar import (FAMILIES, Leaf, Stage, Topology, canonical, design_parameters, enumerate_topologies,
                      family_of, parse)
from .rank import TopologySpec, example_spec, run_topology_search
from .screen import screen_scene, screen_topology

__all__ = ["FAMILIES", "Leaf", "Stage", "Topology", "canonical", "design_parameters", "enumerate_topologies",
           "family_of", "parse", "screen_scene", "screen_topology", "TopologySpec", "example_spec",
           "run_topology_search"]
