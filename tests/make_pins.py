"""Regenerate tests/data/exact_pins.json: REGRESSION PINS of the exact frequency curves.

These numbers are what this code produced when they were written (not references): they guard the exact
path against unintended changes while it is optimised (issue 12). A deliberate model change (e.g. the
element mass) regenerates them with::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python tests/make_pins.py

and says why in the commit.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

#: (template, overrides): 13 points over the full stroke each. The 64-segment pivot is left out on purpose:
#: its eigenvalues carry up to 4e-4 relative LAPACK noise today (issue 12 item 2), which that item removes.
CASES = [
    ("leaf-spring", {}), ("leaf-spring", {"segments": 40}), ("parallel-leaf-spring", {}),
    ("cross-spring-pivot", {}), ("wire-guide-5", {}),
    ("wire-guide-parallel", {}), ("folded-sheet-guide-5", {}), ("folded-sheet-guide-6", {}),
    ("cartwheel-hinge", {}), ("three-fold-cross-hinge", {}), ("double-cross-hinge", {}),
]
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
        out.append({"template": name, "overrides": over, "stroke": c.stroke.tolist(),
                    "modes_hz": c.modes_hz.tolist(), "parasitic_hz": c.parasitic_hz.tolist(),
                    "status": c.status})
    return out


if __name__ == "__main__":
    PATH.parent.mkdir(exist_ok=True)
    PATH.write_text(json.dumps({"note": "REGRESSION PINS (not references): tests/make_pins.py", "cases": compute()},
                               indent=1) + "\n")
    print(f"wrote {PATH}")
