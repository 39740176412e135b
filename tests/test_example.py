"""examples/leaf_spring.py runs and says what the physics says (kept small: about 10 s)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np

from tests import references as ref

ROOT = Path(__file__).resolve().parents[1]


def test_leaf_spring_example(tmp_path: Path) -> None:
    spec = importlib.util.spec_from_file_location("leaf_spring_example", ROOT / "examples" / "leaf_spring.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    out = mod.main(str(tmp_path))
    for name in ("curve.png", "mode_stroke0.png", "mode_stroke0.gif", "mode_stroke45.png", "diagnosis.png"):
        assert (tmp_path / name).stat().st_size > 10_000, name
    mode = out["shapes0"]["modes"][out["first_parasitic"]]
    ref.TORSION_FREE_WARPING.check(mode["hz"])
    rot = np.array(list(mode["rotation"].values()))
    assert (rot[:, 0] ** 2).sum() > 0.999 * (rot**2).sum(), "the first parasitic mode at stroke 0 is torsion (about x)"
    # a sheet (kinematic idealisation) leaves the tip two free motions besides the drive: z and rx (seed 002)
    motions = out["diagnosis"].kinematic_modes
    assert len(motions) == 2
    assert {tuple(np.nonzero(np.r_[m["tip"]["translation"], m["tip"]["rotation"]])[0]) for m in motions} == {(2,), (3,)}
    # the optimiser starts from the template's design (t 0.5 mm, w 40 mm) and must not end below it
    curve = out["curve"]
    inside = np.abs(curve.stroke) <= 20.0 + 1e-9
    start_worst = float(curve.parasitic_hz[inside].min())
    best = out["optimisation"]["ranking"][0]
    assert best["worst_hz"] >= start_worst * (1 - 1e-3), (best, start_worst)
