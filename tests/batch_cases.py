"""Case functions for tests/test_batch.py (importable by worker processes as tests.batch_cases)."""

from __future__ import annotations

import os
from pathlib import Path


def leaf_torsion_hz(case: dict) -> dict:
    """Zero-stroke first parasitic frequency of the leaf-spring template at a thickness (real model work).

    With ``marker_dir`` each call also leaves a file, so a test can count how often a case really ran.
    """
    from model import Analysis, template

    if case.get("marker_dir"):
        Path(case["marker_dir"], f"{case['thickness']:.6e}.{os.getpid()}.{os.urandom(4).hex()}").touch()
    if case["thickness"] <= 0:
        raise ValueError("thickness must be positive")
    c = Analysis(template("leaf-spring", thickness=case["thickness"], stroke=1.0, points=3)).frequency_curve()
    return {"thickness": case["thickness"], "hz": float(c.parasitic_hz[1])}
