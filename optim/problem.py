"""The optimisation problem as JSON (pydantic v2): what the CLI reads and the service accepts unchanged.

Maximise the worst-case first parasitic frequency over the stroke of one or more hinge families, under a
stress limit (allowable stress of the material divided by a safety factor), a minimum manufacturable
thickness, an optional maximum actuation force or moment, and the design bounds.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

__all__ = ["Family", "Problem"]


class Family(BaseModel):
    """One parametric family (a template) and its design space."""

    model_config = ConfigDict(extra="forbid")

    template: str = Field(description="template name, e.g. 'cross-spring-pivot' (GET /v1/templates)")
    design: dict[str, tuple[float, float]] = Field(
        min_length=1,
        description="design parameters with (lower, upper) bounds in the template's SI units [m, kg, deg]",
    )
    fixed: dict[str, float | int | str] = Field(
        default_factory=dict, description="other template parameters held at these values (default: the template's)"
    )

    @field_validator("design")
    @classmethod
    def _bounds(cls, v: dict[str, tuple[float, float]]) -> dict[str, tuple[float, float]]:
        for k, (lo, hi) in v.items():
            if not (lo == lo and hi == hi and abs(lo) < float("inf") and abs(hi) < float("inf")):
                raise ValueError(f"bounds of '{k}' must be finite numbers")
            if not lo < hi:
                raise ValueError(f"bounds of '{k}' must satisfy lower < upper (got {lo}, {hi})")
        return v

    @model_validator(mode="after")
    def _disjoint(self) -> "Family":
        both = sorted(set(self.design) & set(self.fixed))
        if both:
            raise ValueError(f"parameters {both} are both designed and fixed; keep each in one of the two")
        return self


class Problem(BaseModel):
    """An optimisation of the worst-case first parasitic frequency over the stroke."""

    model_config = ConfigDict(extra="forbid")

    format: Literal["flexopt-problem"] = "flexopt-problem"
    version: Literal[1] = 1
    families: list[Family] = Field(min_length=1, max_length=16, description="the candidate topologies")
    stroke: float | None = Field(
        default=None, gt=0, description="half range of the stroke, in the template's stroke unit (deg for "
        "rotations, m for translations); default: the template's own 'stroke' parameter (45 deg for hinges)",
    )
    samples: int = Field(default=9, ge=3, le=61, description="stroke samples of the search, over -stroke..stroke")
    modes: int = Field(default=2, ge=1, le=6, description="lowest parasitic modes bounded at every sample "
                       "(more than one, so a mode switch cannot hide the minimum)")
    safety_factor: float = Field(default=1.5, ge=1.0, le=20.0,
                                 description="von Mises stress must stay below allowable / safety_factor")
    min_thickness: float = Field(default=50e-6, gt=0, description="smallest manufacturable thickness [m]; "
                                 "raises the lower bound of every parameter named '*thickness*'")
    max_drive: float | None = Field(default=None, gt=0, description="largest actuation moment [N m] or "
                                    "force [N] along the stroke (optional)")
    envelope: float | None = Field(default=None, gt=0, description="largest distance of any scene node from "
                                   "the origin (the hinge centre of the templates) [m] (optional)")
    starts: int = Field(default=4, ge=1, le=64, description="multi-start: starts per family (the first is the "
                        "template's defaults clipped into the bounds, the others a Latin hypercube)")
    screen: int = Field(default=0, ge=0, le=256, description="fast-method screening: each start first "
                        "evaluates this many Latin-hypercube candidates of its own with the modal-derivative "
                        "'auto' method (the cheapest method whose estimated error meets screen_tolerance; exact "
                        "where none does) and starts from the one with the highest estimated worst case")
    screen_tolerance: float = Field(default=0.02, gt=0, lt=0.5, description="error tolerance of the screening")
    seed: int = Field(default=0, ge=0, description="base seed of the Latin hypercube (deterministic)")
    max_iterations: int = Field(default=30, ge=1, le=500, description="SLSQP iterations per start and round")
    refine_rounds: int = Field(default=3, ge=0, le=10, description="verification rounds: the stroke of the "
                               "verified minimum is added to the samples and the search resumed")
    verify_points: int = Field(default=181, ge=31, le=2001, description="exact stroke points of the verification")
    tolerance: float = Field(default=1e-3, gt=0, lt=0.1, description="relative tolerance of the search "
                             "(SLSQP ftol) and of the verified-versus-searched worst case")
