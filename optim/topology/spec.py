"""The topology search's spec as JSON (pydantic only: the service and the client can share it without CasADi;
the descriptors are checked by the grammar, loaded on first use)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, PositiveFloat, ValidationInfo, field_validator

from ..problem import Envelope

__all__ = ["TopologySpec", "example_spec"]


class TopologySpec(BaseModel):
    """A topology search: what to generate, how to screen it and the one problem every survivor is optimised
    under (JSON, ``"format": "flexopt-topology"``)."""

    model_config = ConfigDict(extra="forbid")

    format: Literal["flexopt-topology"] = "flexopt-topology"
    version: Literal[1] = 1
    motion: Literal["rotation", "translation"] = Field(
        default="rotation", description="the intended motion: 'rotation' about the z axis through the origin "
        "(hinges of leaf flexures, screened, optimised and ranked) or 'translation' along x (straight guides of "
        "wire flexures: screened and ranked by the condition number of their constraints; no shape "
        "optimisation yet)")
    stroke: PositiveFloat = Field(default=45.0, le=180.0, description="half range of the rotation [deg] "
                                  "(rotation only)")
    envelope: Envelope = Field(default_factory=lambda: Envelope(radius=0.035, half_height=0.02),
                               description="the cylinder around the axis every candidate must fit in [m]")
    safety_factor: float = Field(default=1.5, ge=1.0, le=20.0, description="von Mises stress below allowable / "
                                 "safety_factor (steel: 600 MPa allowable)")
    body_mass: PositiveFloat = Field(default=0.1, description="moving-body (rotor) mass [kg]")
    body_inertia: PositiveFloat = Field(default=2e-5, description="rotor inertia about each axis through its "
                                        "centre of mass [kg m^2] (the families' 0.1 kg x (20 mm)^2 / 2)")
    intermediate_mass: PositiveFloat = Field(default=0.02, description="mass of each intermediate body [kg] "
                                             "(inertia as the rotor's per unit mass)")
    max_flexures: int = Field(default=4, ge=1, le=6, description="at most this many leaf flexures")
    max_stages: int = Field(default=2, ge=1, le=3, description="at most this many stages in series")
    planes: str = Field(default="+-", description="leaf planes to place: a subset of '+-0' ('+' and '-' at "
                        "+-angle/2 about the axis, '0' radial)")
    inplane: bool = Field(default=True, description="also generate leaves crossing in one plane (joined)")
    free_crossing: bool = Field(default=True, description="also generate designed crossing fractions ('@')")
    reinforcement: bool = Field(default=False, description="also generate stages of leaves with a rigid middle")
    allow_overconstraints: bool = Field(default=True, description="accept candidates with self-stress states "
                                        "(monolithic hinges live with them); false rejects them")
    topologies: list[str] | None = Field(default=None, max_length=256, description="search only these "
                                         "descriptors (e.g. ['R:+-@']) instead of the enumeration")
    starts: int = Field(default=2, ge=1, le=16, description="optimiser starts per candidate (the first from the "
                        "template's defaults clipped into the bounds, then a scrambled Halton sequence)")
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


def example_spec() -> dict:
    """The default spec as JSON (``flexopt topology --example``)."""
    return TopologySpec().model_dump(mode="json")
