"""Regenerate tests/data/exact_pins.json: REGRESSION PINS of the exact frequency curves.

These numbers are what this code produced when they were written (not references): they guard the exact
path against unintended changes while it is optimised (issue 12). A deliberate model change (e.g. the
element mass) regenerates them with::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python tests/make_pins.py

and says why in the commit.

History: first made with the LAPACK dsygvx eigen route; regenerated once when the eigen solve moved to the
route through K (issue 12 item 2): the old values carried the old solver's error (up to 6e-8 relative,
e.g. the 40-element leaf's lowest mode: 2.7e-8 against an extended-precision reference, now 2.3e-10;
tests/test_eigen_accuracy.py) and one different branch order in the degenerate pair of the three-fold cross;
regenerated again when the beam's translational mass became the consistent cubic (Hermite) mass (issue 11
item 6; frequencies move by up to about 1 %, towards the converged values).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

#: (template, overrides): 13 points over the full stroke each. The meshes are stated: those that were the
#: templates' defaults when the pins were made (the defaults became finer with issue 26 item 4). The 64-segment pivot is left out on purpose:
#: its eigenvalues carry up to 4e-4 relative LAPACK noise today (issue 12 item 2), which that item removes.
CASES = [
    ("leaf-spring", {}),
    ("leaf-spring", {"segments": 40}),
    ("parallel-leaf-spring", {}),
    ("cross-spring-pivot", {"segments": 8}),
    ("wire-guide-5", {"segments": 1}),
    ("wire-guide-parallel", {"segments": 1}),
    ("folded-sheet-guide-5", {"segments": 1}),
    ("folded-sheet-guide-6", {"segments": 1}),
    ("cartwheel-hinge", {"segments": 8}),
    ("three-fold-cross-hinge", {"segments": 8}),
    ("double-cross-hinge", {"segments": 8}),
]
#: Per-case relative tolerance where the float64 data itself is not reproducible to 1e-9: replacing only the
#: rounding of the rotation update (scipy's exponential map by our Rodrigues formula, same maths) moved the
#: 40-element leaf's second mode by 2.0e-8 with an exact eigen solve: that mode's sensitivity to round-off
#: in the equilibrium (its float64 Rayleigh quotient errs by 2.4e-8, tests/test_eigen_accuracy.py).
RTOL = {("leaf-spring", 40): 1e-7}
PATH = Path(__file__).parent / "data" / "exact_pins.json"


def strokes(scene) -> np.ndarray:
    """13 stroke values spanning the scene's stroke range (both ends included)."""
    v = np.asarray(scene.stroke.values(), dtype=float)
    return np.linspace(v.min(), v.max(), 13)


def compute() -> list[dict]:
    """The pinned curves computed by the current code."""
    from flexopt.model import Analysis, template

    out = []
    for name, over in CASES:
        sc = template(name, **over)
        c = Analysis(sc).frequency_curve(strokes(sc))
        out.append(
            {
                "template": name,
                "overrides": over,
                "stroke": c.stroke.tolist(),
                "modes_hz": c.modes_hz.tolist(),
                "parasitic_hz": c.parasitic_hz.tolist(),
                "status": c.status,
            }
        )
    return out


if __name__ == "__main__":
    PATH.parent.mkdir(exist_ok=True)
    PATH.write_text(
        json.dumps({"note": "REGRESSION PINS (not references): tests/make_pins.py", "cases": compute()}, indent=1)
        + "\n"
    )
    print(f"wrote {PATH}")
