"""The topology search's spec as JSON (pydantic only: the service and the client can share it without CasADi;
the descriptors are checked by the grammar, loaded on first use)."""

from __future__ import annotations

import math
from typing import Literal, NamedTuple

from pydantic import BaseModel, ConfigDict, Field, PositiveFloat, ValidationInfo, field_validator

from ..problem import Envelope

__all__ = ["TopologySpec", "example_spec", "QUICK", "Schedule", "schedule_counts"]


class TopologySpec(BaseModel):
    """A topology search: what to generate, how to screen it and the one problem every survivor is optimised
    under (JSON, ``"format": "flexopt-topology"``)."""

    model_config = ConfigDict(extra="forbid")

    format: Literal["flexopt-topology"] = "flexopt-topology"
    version: Literal[1] = 1
    motion: Literal["rotation", "translation"] = Field(
        default="rotation",
        description="the intended motion: 'rotation' about the z axis through the origin "
        "(hinges of leaf flexures, screened, optimised and ranked) or 'translation' along x (straight guides of "
        "wire flexures: screened and ranked by the condition number of their constraints; no shape "
        "optimisation yet)",
    )
    stroke: PositiveFloat = Field(
        default=45.0, le=180.0, description="half range of the rotation [deg] (rotation only)"
    )
    envelope: Envelope = Field(
        default_factory=lambda: Envelope(radius=0.035, half_height=0.02),
        description="the cylinder around the axis every candidate must fit in [m]",
    )
    safety_factor: float = Field(
        default=1.5,
        ge=1.0,
        le=20.0,
        description="von Mises stress below allowable / safety_factor (steel: 600 MPa allowable)",
    )
    body_mass: PositiveFloat = Field(default=0.1, description="moving-body (rotor) mass [kg]")
    body_inertia: PositiveFloat = Field(
        default=2e-5,
        description="rotor inertia about each axis through its "
        "centre of mass [kg m^2] (the families' 0.1 kg x (20 mm)^2 / 2)",
    )
    intermediate_mass: PositiveFloat = Field(
        default=0.02, description="mass of each intermediate body [kg] (inertia as the rotor's per unit mass)"
    )
    max_flexures: int = Field(default=6, ge=1, le=6, description="at most this many leaf flexures")
    max_stages: int = Field(default=3, ge=1, le=3, description="at most this many stages in series")
    dimensions: Literal["shared", "stage", "leaf"] = Field(
        default="stage",
        description="how each candidate's dimensions are designed: 'shared' (one length, "
        "thickness, width and plane angle for every stage), 'stage' (each stage its own) or 'leaf' (each stage "
        "its own, and each leaf its own thickness)",
    )
    taper: int = Field(
        default=1,
        ge=1,
        le=5,
        description="thickness zones per leaf: 1 a uniform leaf; k >= 2 every stacked leaf "
        "without a rigid middle is k zones of equal length, each its own designed thickness (at least "
        "min_thickness, at most 1 mm), neighbouring zones within max_taper of each other",
    )
    taper_symmetric: bool = Field(
        default=True,
        description="zones mirrored about the leaf's middle share one thickness (ceil(taper / 2) per "
        "leaf): a leaf crossing the axis at its midpoint is bent by the stroke with the same moment along its "
        "length, so its load is symmetric about its middle; false: every zone its own (for designed crossings)",
    )
    max_taper: float = Field(
        default=2.0,
        gt=1.0,
        le=10.0,
        description="largest thickness ratio between neighbouring zones of a tapered leaf: the "
        "beam model has no stress concentration at a step in thickness, so keep steps that a rounded "
        "shoulder makes harmless",
    )
    prune: bool = Field(
        default=True,
        description="leave out duplicates before optimising: a designed crossing "
        "('@') on a stage whose leaves cross nothing, and (after the first pass) a designed "
        "crossing that ends at the midpoint when its midpoint variant is a candidate too",
    )
    schedule: Literal["multi-fidelity", "exhaustive"] = Field(
        default="multi-fidelity",
        description="'multi-fidelity': every survivor gets one cheap pass (one start, "
        "first_pass_samples, first_pass_segments, no refinement) and only the most promising (promote) get "
        "the full starts; 'exhaustive': every survivor gets the full starts",
    )
    first_pass_segments: int = Field(default=4, ge=2, le=40, description="beam elements per leaf of the first pass")
    first_pass_samples: int = Field(
        default=3,
        ge=3,
        le=61,
        description="stroke samples of the first pass (3: the stroke's ends and zero, two after the mirror symmetry)",
    )
    first_pass_dimensions: Literal["shared", "stage", "leaf", "same"] = Field(
        default="shared",
        description="the design space of the first pass: 'shared' (the fewest parameters, "
        "the cheapest: it ranks topologies, the full pass then designs them under 'dimensions') or 'same' "
        "(the full pass's)",
    )
    first_pass_iterations: int = Field(default=15, ge=1, le=500, description="solver iterations of the first pass")
    promote: float = Field(
        default=0.04,
        gt=0,
        le=1,
        description="fraction of the first pass's candidates (best first) given the full starts",
    )
    promote_min: int = Field(
        default=8,
        ge=1,
        le=10000,
        description="at least this many are given the full "
        "starts (a search with this many survivors or fewer skips the first pass)",
    )
    refine_segments: int | Literal["auto"] | None = Field(
        default="auto",
        description="the mesh every ranked optimum is verified on before it is ranked: 'auto' "
        "(refined until the estimated discretisation error of the first parasitic frequency is within "
        "refine_tolerance), a number of beam elements per leaf, or null (ranked on the search's mesh)",
    )
    refine_tolerance: float = Field(
        default=2e-3, gt=0, le=0.1, description="discretisation error aimed at by refine_segments 'auto' (relative)"
    )
    refine_points: int = Field(
        default=31,
        ge=5,
        le=2001,
        description="stroke points of the refined verification (and the stroke of the search's verified minimum)",
    )
    min_length_over_width: float | None = Field(
        default=None,
        gt=0,
        le=100,
        description="validity constraint: every leaf at least this many times as "
        "long as it is wide (beam theory; e.g. 2 excludes plate-like leaves); null: no constraint",
    )
    min_length_over_thickness: float | None = Field(
        default=None,
        gt=0,
        le=10000,
        description="validity constraint: every leaf at least this many times as "
        "long as it is thick; null: no constraint",
    )
    optimise_guides: int = Field(
        default=0,
        ge=0,
        le=256,
        description="translation only: shape-optimise the "
        "best this many accepted guides (by the condition number of D_cc) for their "
        "worst-case parasitic frequency over guide_stroke, and rank them by it before "
        "the others; 0: rank by conditioning only",
    )
    guide_stroke: PositiveFloat = Field(
        default=0.002, le=0.05, description="half range of a guide's translation [m] (translation only)"
    )
    planes: str = Field(
        default="+-",
        description="leaf planes to place: a subset of '+-0' ('+' and '-' at +-angle/2 about the axis, '0' radial)",
    )
    inplane: bool = Field(default=True, description="also generate leaves crossing in one plane (joined)")
    free_crossing: bool = Field(default=True, description="also generate designed crossing fractions ('@')")
    reinforcement: bool = Field(default=False, description="also generate stages of leaves with a rigid middle")
    allow_overconstraints: bool = Field(
        default=True,
        description="accept candidates with self-stress states (monolithic hinges live with them); false rejects them",
    )
    topologies: list[str] | None = Field(
        default=None,
        max_length=256,
        description="search only these descriptors (e.g. ['R:+-@']) instead of the enumeration",
    )
    starts: int = Field(
        default=2,
        ge=1,
        le=16,
        description="optimiser starts per candidate (the first from the "
        "template's defaults clipped into the bounds, then a scrambled Halton sequence)",
    )
    seed: int = Field(default=0, ge=0, description="seed of the starts (deterministic)")
    segments: int = Field(default=8, ge=2, le=40, description="beam elements per leaf in the optimisation")
    samples: int = Field(default=9, ge=3, le=61, description="stroke samples of the search")
    verify_points: int = Field(default=121, ge=31, le=2001, description="exact stroke points of the verification")
    refine_rounds: int = Field(default=1, ge=0, le=10, description="verification rounds (optim.Problem)")
    max_iterations: int = Field(default=30, ge=1, le=500, description="solver iterations per start and round")
    min_thickness: float = Field(default=50e-6, gt=0, description="smallest manufacturable thickness [m]")
    solver: Literal["slsqp", "trust-constr"] = "slsqp"

    @field_validator("planes")
    @classmethod
    def _planes(cls, v: str) -> str:
        if not v or not set(v) <= set("+-0") or len(set(v)) != len(v):
            raise ValueError(f"planes must be distinct characters from '+-0', e.g. '+-', got {v!r}")
        return v

    @field_validator("topologies")
    @classmethod
    def _descriptors(cls, v: list[str] | None, info: ValidationInfo) -> list[str] | None:
        if v is not None:
            from ...model.errors import SceneError
            from .grammar import parse, parse_guide

            read = parse_guide if info.data.get("motion") == "translation" else parse
            for d in v:
                try:
                    read(d)
                except SceneError as exc:
                    raise ValueError(str(exc).removeprefix("template.topology: ")) from None
        return v


class Schedule(NamedTuple):
    """How many candidates each phase of a search's schedule takes (:func:`schedule_counts`)."""

    first_pass: int  #: given the cheap first pass (0: the schedule skips it)
    promoted: int  #: given the full pass (all ``starts``)
    refined: int  #: at most this many optimised candidates get the refined verification (0: none)


def schedule_counts(spec: TopologySpec, candidates: int, scored: int | None = None) -> Schedule:
    """The schedule's counts (:mod:`.rank`, phases 2-4) for ``candidates`` survivors of the screening: a
    first pass of every one when the schedule is 'multi-fidelity' and they are more than ``promote_min``;
    then the best ``max(promote_min, ceil(promote x scored))`` of the ``scored`` ones (those whose first pass
    gave a score and were not pruned; by default all of them, the bound a cost estimate uses) promoted, else
    every one; the promoted verified on the refined mesh unless ``refine_segments`` is None. The one rule
    the search (:func:`.rank.run_topology_search`) and the job's cost estimate (``service.api.cost``) follow."""
    if spec.schedule != "multi-fidelity" or candidates <= spec.promote_min:
        first, promoted = 0, candidates
    else:
        n = candidates if scored is None else scored
        first, promoted = candidates, min(n, max(spec.promote_min, math.ceil(spec.promote * n)))
    return Schedule(first, promoted, promoted if spec.refine_segments is not None else 0)


#: The quick spec: today's 4-leaf, 2-stage space with shared dimensions (``flexopt topology --example quick``).
QUICK: dict[str, object] = {"max_flexures": 4, "max_stages": 2, "dimensions": "shared"}


def example_spec(kind: str = "default") -> dict:
    """The default spec as JSON (``flexopt topology --example``): the broad space (6 leaves, 3 stages, each
    stage its own dimensions); ``kind="quick"`` the quick one (:data:`QUICK`)."""
    if kind not in ("default", "quick"):
        raise ValueError(f"example kind must be 'default' or 'quick', got {kind!r}")
    return TopologySpec.model_validate(QUICK if kind == "quick" else {}).model_dump(mode="json")
