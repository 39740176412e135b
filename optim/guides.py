"""Straight guides shape-optimised: the worst-case first parasitic frequency over a translation stroke, as hinges.

The optimiser (:mod:`optim.search`) takes translation templates unchanged: the stroke is in metres (the
template's ``stroke``, 2 mm for the guides), the drive a prescribed translation whose design derivative is
the reference position's move along the drive axis (:func:`model.design.point_sensitivity`), and the
verification, stress limit, KKT check and warnings are the hinges'. This module gives a wire-guide
topology (``T:<wire>,...``, template ``wire-guide-topology``, :func:`model.templates.guide_layout`) its problem
and optimises a list of them, or the leaders of a topology search of guides (which ranks them by the
condition number of their constraints only), ranking them by their verified worst case.

Design box (default :data:`DEFAULT_DESIGN`): the wires' length and square side. Where they come from: the
length from 30 mm (a wire of 1.5 mm side stays slender, L/w >= 20) to 80 mm (the block's 100 mm length); the
side from 0.5 mm (a machinable wire) to 1.5 mm.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from .problem import Problem
from .search import best_start, cases, no_optimum_reason

__all__ = ["DEFAULT_DESIGN", "guide_problem", "optimise_guides", "run_guides"]

DEFAULT_DESIGN: dict[str, tuple[float, float]] = {"wire_length": (0.03, 0.08), "wire_diameter": (5e-4, 1.5e-3)}


def guide_problem(
    descriptor: str,
    design: dict[str, tuple[float, float]] | None = None,
    fixed: dict[str, Any] | None = None,
    origins: dict[str, tuple[str, str]] | None = None,
    **problem: Any,
) -> Problem:
    """The problem of one wire guide ``descriptor``: template ``wire-guide-topology`` with ``topology`` fixed,
    the ``design`` box (default :data:`DEFAULT_DESIGN`), other ``fixed`` parameters, where the bounds come
    from (``origins``, :class:`optim.problem.Family`) and the remaining :class:`optim.problem.Problem` fields
    (``stroke`` in metres, ``samples``, ...)."""
    fam = {
        "template": "wire-guide-topology",
        "design": {k: list(v) for k, v in (design or DEFAULT_DESIGN).items()},
        "fixed": {**(fixed or {}), "topology": descriptor},
        "origins": {k: list(v) for k, v in (origins or {}).items()},
    }
    return Problem.model_validate({**problem, "families": [fam]})


def run_guides(
    problems: Sequence[Problem],
    *,
    executor: Any = None,
    workers: int | None = None,
    store: Any = None,
    progress: Any = None,
    cancel: Any = None,
) -> list[list[dict]]:
    """Every start of every guide problem (:func:`guide_problem`) as one case of :func:`optim.batch.run_cases`
    (any executor, resumable through ``store``): per problem, its starts' records (:func:`optim.search.run_case`)."""
    from .batch import run_cases

    batch = [c for p in problems for c in cases(p)]
    results = run_cases(
        batch,
        "flexopt.optim.search:run_case",
        executor=executor,
        workers=workers,
        store=store,
        progress=progress,
        cancel=cancel,
    )
    out, k = [], 0
    for p in problems:
        out.append(results[k : k + p.starts])
        k += p.starts
    return out


def optimise_guides(
    guides: Sequence[str] | dict,
    *,
    top: int = 5,
    design: dict[str, tuple[float, float]] | None = None,
    fixed: dict[str, Any] | None = None,
    problem: dict[str, Any] | None = None,
    executor: Any = None,
    workers: int | None = None,
    store: Any = None,
    progress: Any = None,
    cancel: Any = None,
) -> dict:
    """Shape-optimise wire guides for their worst-case first parasitic frequency over the translation stroke.

    ``guides``: descriptors, or a topology search's result for ``motion: "translation"`` (its first ``top``
    ranked guides, with their condition numbers). Every start of every guide is one case of
    :func:`optim.batch.run_cases` (any executor, resumable through ``store``). Returns ``{"guides": [...],
    "ranking": [...]}``: per guide its descriptor (canonical), condition number (if given), status, verified
    worst case, zero-stroke frequency and their ratio [Hz], stress ratio, design, KKT residual, active bounds
    and warnings; the ranking orders the optimal ones by verified worst case, highest first.
    """
    from .topology.grammar import canonical_guide

    cond: dict[str, float | None] = {}
    if isinstance(guides, dict):
        by_name = {c["topology"]: c for c in guides.get("candidates", [])}
        names = list(guides.get("ranking", []))[:top]
        cond = {d: by_name.get(d, {}).get("condition_number") for d in names}
    else:
        names = [str(canonical_guide(d)) for d in guides]
    names = list(dict.fromkeys(names))  # each guide once
    probs = [guide_problem(d, design, fixed, **(problem or {})) for d in names]
    per_guide = run_guides(probs, executor=executor, workers=workers, store=store, progress=progress, cancel=cancel)
    out = []
    for d, rs in zip(names, per_guide):
        rec: dict[str, Any] = {
            "topology": d,
            "condition_number": cond.get(d),
            "starts": [
                {
                    "start": r.get("start"),
                    "status": r.get("status", "failed"),
                    "message": r.get("message") or r.get("error"),
                }
                for r in rs
            ],
        }
        b = best_start(rs)
        if b is None:
            rec.update(status="failed", reason=no_optimum_reason(rs))
        else:
            v = b["verified"]
            rec.update(
                status="optimised",
                reason=None,
                worst_case_hz=v["worst_hz"],
                zero_stroke_hz=v["zero_stroke_hz"],
                ratio=v["ratio"],
                stress_ratio=v["stress_ratio"],
                design=b["design"],
                kkt_residual=b["optimality"]["kkt_residual"],
                active_bounds=b["optimality"]["active_bounds"],
                max_drive=v.get("max_drive"),
                drive_unit=v.get("drive_unit"),
                warnings=b.get("warnings", []),
            )
        out.append(rec)
    ranking = [
        r["topology"] for r in sorted((r for r in out if r["status"] == "optimised"), key=lambda r: -r["worst_case_hz"])
    ]
    return {"guides": out, "ranking": ranking, "problem": probs[0].model_dump(mode="json") if probs else None}
