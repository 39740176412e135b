"""The compiled fill and scatter of the assembly (model/cassembly.py) against the numpy code they replace.

Reference: the same System with the compiled helpers switched off (``_c = None``), i.e. numpy gathers and
``bincount``. The compiled loops sum in bincount's order, so the results must be *bitwise* equal; a
state away from the reference (after Newton updates with rotations) exercises the node offsets and the
rotations of bodies.
"""

from __future__ import annotations

import numpy as np
import pytest

from flexopt.model import Analysis, cassembly, scene_from_dict, template

pytestmark = pytest.mark.skipif(cassembly.library() is None, reason="needs a C compiler")


def _leaf_with_truss():
    """The leaf with a truss from its tip to a supported anchor (beams and trusses in one model)."""
    d = template("leaf-spring").model_dump(mode="json")
    d["nodes"].append({"name": "anchor", "position": [0.1, 0.0, 0.05]})
    d["elements"].append({"kind": "truss", "name": "bar", "nodes": ["tip", "anchor"], "material": "steel",
                          "area": 1e-6})
    d["supports"].append({"node": "anchor"})
    return scene_from_dict(d)


@pytest.mark.parametrize("name", ["leaf-spring", "cross-spring-pivot", "leaf+truss", "wire-guide-5",
                                  "folded-sheet-guide-5", "three-fold-cross-hinge"])
def test_compiled_assembly_bitwise_equal_to_numpy(name: str) -> None:
    an = Analysis(_leaf_with_truss() if name == "leaf+truss" else template(name))
    sys = an.system
    st = sys.reference_state()
    rng = np.random.default_rng(3)
    for _ in range(2):  # a deformed, rotated state: random increments on every active DOF
        st = sys.update(st, 1e-2 * rng.standard_normal(sys.n) * sys.scale,
                        1e-3 * rng.standard_normal(sys.n_con) if sys.n_con else None)
    a = sys.evaluate(st)
    Ma = sys.mass(st)
    c, sys._c = sys._c, None
    try:
        b = sys.evaluate(st)
        Mb = sys.mass(st)
    finally:
        sys._c = c
    worst = 0.0
    for x, y in ((a.g, b.g), (a.H, b.H), (a.G, b.G), (a.c, b.c), (a.chart, b.chart), (a.e_beam, b.e_beam),
                 (a.e_truss, b.e_truss), (Ma, Mb)):
        if not np.array_equal(x, y):
            worst = max(worst, float(np.abs(x - y).max() / np.abs(y).max()))
    # bitwise equal where nodes sit on their masters; a node offset from its master (the bodies' attachment
    # points) is R r in the compiled loop and numpy.einsum's own summation order, one rounding apart, which
    # the kernels pass on: measured 2e-16 of each array's largest entry
    assert worst < 1e-14, worst
    if name in ("leaf-spring", "leaf+truss"):
        assert worst == 0.0
