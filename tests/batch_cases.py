"""Case functions for tests/test_batch.py, importable by worker processes as ``tests.batch_cases``.

With ``marker_dir`` in a case every call leaves a file there, so a test can count how often cases really ran.
"""

from __future__ import annotations

import os
import time
from pathlib import Path


def _mark(case: dict) -> None:
    if case.get("marker_dir"):
        Path(case["marker_dir"], f"{os.getpid()}.{os.urandom(6).hex()}").touch()


def leaf_torsion_hz(case: dict) -> dict:
    """Zero-stroke first parasitic frequency of the leaf-spring template at a thickness (real model work).

    A non-positive thickness makes the model raise its own ``SceneError`` (a FlexoptError and ValueError).
    """
    from flexopt.model import Analysis, template

    _mark(case)
    c = Analysis(template("leaf-spring", thickness=case["thickness"], stroke=1.0, points=3)).frequency_curve()
    return {"thickness": case["thickness"], "hz": float(c.parasitic_hz[1])}


def seeded(case: dict) -> dict:
    """The case's seed as a worker computes it, and the first draw of the generator it seeds.

    ``hold`` (seconds) keeps the case running that long, so a test can cancel while it runs.
    """
    import numpy as np
    from flexopt.optim.batch import case_seed

    _mark(case)
    time.sleep(case.get("hold", 0.0))
    seed = case_seed(case, case["base_seed"])
    return {"seed": seed, "draw": float(np.random.default_rng(seed).random())}


def misbehave(case: dict) -> dict:
    """Fails in the way ``case["how"]`` names: an ordinary exception, or a result that is not JSON."""
    _mark(case)
    how = case["how"]
    if how == "lookup":
        return {"value": {"a": 1}["missing-key"]}
    if how == "divide":
        return {"value": 1 / 0}
    if how == "not-a-dict":
        return [1, 2]  # type: ignore[return-value]
    if how == "not-json":
        return {"value": {1, 2}}
    return {"value": how}
