"""Helpers shared by the fast methods: the curve record, Hz conversion, the cluster gap."""

from __future__ import annotations

import numpy as np

from ..analysis import MeshAnalysis
from ..results import FrequencyCurve

#: Relative eigenvalue gap below which modes are treated as one (quasi-)degenerate cluster.
CLUSTER_GAP = 2e-2


def _curve_from(
    an: MeshAnalysis,
    method: str,
    stroke_user: np.ndarray,
    hz: np.ndarray,
    labels: np.ndarray,
    par: np.ndarray,
    seconds: float,
    extra: dict,
    conventions: dict | None = None,
) -> FrequencyCurve:
    spec = an.stroke
    nan = np.full(len(stroke_user), np.nan)
    return FrequencyCurve(
        scene=an.scene.name,
        method=method,
        stroke=np.asarray(stroke_user, dtype=float),
        stroke_unit=spec.resolved_unit,
        stroke_kind=spec.kind,
        modes_hz=hz,
        mode_labels=labels,
        parasitic_hz=par,
        drive_reaction=nan,
        drive_reaction_unit="N m" if spec.kind == "rotation" else "N",
        max_von_mises={},
        allowable_stress={},
        status="complete",
        conventions=conventions
        or {
            "stroke_map": "eta_j = stroke (rad or length): the driving mode is the static mode "
            "with drive entry 1 and the modal derivatives have no drive entry",
            "method": method,
            "drive_reaction": "not computed by this method (NaN)",
        },
        solver={"seconds": seconds, **extra},
    )


def _hz(lam: np.ndarray) -> np.ndarray:
    return np.sign(lam) * np.sqrt(np.abs(lam)) / (2 * np.pi)


def _first_parasitic(hz: np.ndarray, labels) -> float:
    vals = [h for h, lab in zip(hz, labels) if lab == "parasitic"]
    return min(vals) if vals else float("nan")
