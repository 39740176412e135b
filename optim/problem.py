"""The optimisation problem as JSON (pydantic v2): what the CLI reads and the service accepts unchanged.

Maximise the worst-case first parasitic frequency over the stroke of one or more hinge families, under a
stress limit (allowable stress of the material divided by a safety factor), a minimum manufacturable
thickness, an optional maximum actuation force or moment, and the design bounds.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, PositiveFloat, field_validator, model_validator

__all__ = ["Envelope", "Family", "Problem", "Ratio"]


class Envelope(BaseModel):
    """The space every family must fit in: a cylinder around the stroke's axis (through the origin, the hinge
    centre of the templates), the same for every family so that they are compared in one space."""

    model_config = ConfigDict(extra="forbid")

    shape: Literal["cylinder"] = "cylinder"
    radius: PositiveFloat = Field(
        description="largest distance of any scene node or leaf edge (node +- "
        "width/2 across the leaf) from the stroke axis [m]"
    )
    half_height: PositiveFloat | None = Field(
        default=None,
        description="largest distance of any scene node or "
        "leaf edge along the axis from the origin's plane [m] (default: "
        "unbounded)",
    )


class Ratio(BaseModel):
    """A validity constraint of a family: ``numerator >= minimum x factor x denominator`` on two template
    parameters (designed or fixed), e.g. ``length >= 2 width`` so that a leaf stays a beam, not a plate."""

    model_config = ConfigDict(extra="forbid")

    numerator: str = Field(description="template parameter above, e.g. 'length'")
    denominator: str = Field(description="template parameter below, e.g. 'width'")
    minimum: PositiveFloat = Field(description="smallest allowed numerator / (factor x denominator)")
    factor: PositiveFloat = Field(default=1.0, description="multiple of the denominator (a leaf of double width: 2)")
    reason: str = Field(default="", max_length=200, description="why, in words (shown when it is active)")


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
    origins: dict[str, tuple[str, str]] = Field(
        default_factory=dict,
        description="where each design bound comes from, (lower, upper) in words (e.g. "
        "'the envelope's height shared by 2 layers'): a warning for an optimum on a bound names it (optional; "
        "bounds without an origin are the family's design box)",
    )
    ratios: list[Ratio] = Field(
        default_factory=list,
        max_length=32,
        description="validity constraints numerator / (factor x "
        "denominator) >= minimum on template parameters, e.g. a leaf's length over its width within beam "
        "theory (optional)",
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
    def _disjoint(self) -> Family:
        both = sorted(set(self.design) & set(self.fixed))
        if both:
            raise ValueError(f"parameters {both} are both designed and fixed; keep each in one of the two")
        stray = sorted(set(self.origins) - set(self.design))
        if stray:
            raise ValueError(f"origins names {stray}, which are not designed; give origins of design parameters only")
        return self


class Problem(BaseModel):
    """An optimisation of the worst-case first parasitic frequency over the stroke."""

    model_config = ConfigDict(extra="forbid")

    format: Literal["flexopt-problem"] = "flexopt-problem"
    version: Literal[1] = 1
    families: list[Family] = Field(min_length=1, max_length=16, description="the candidate topologies")
    stroke: float | None = Field(
        default=None,
        gt=0,
        description="half range of the stroke, in the template's stroke unit (deg for "
        "rotations, m for translations); default: the template's own 'stroke' parameter (45 deg for hinges)",
    )
    samples: int = Field(default=9, ge=3, le=61, description="stroke samples of the search, over -stroke..stroke")
    modes: int = Field(
        default=2,
        ge=1,
        le=6,
        description="lowest parasitic modes bounded at every sample "
        "(more than one, so a mode switch cannot hide the minimum)",
    )
    safety_factor: float = Field(
        default=1.5, ge=1.0, le=20.0, description="von Mises stress must stay below allowable / safety_factor"
    )
    min_thickness: float = Field(
        default=50e-6,
        gt=0,
        description="smallest manufacturable thickness [m]; "
        "raises the lower bound of every parameter named '*thickness*'",
    )
    max_drive: float | None = Field(
        default=None, gt=0, description="largest actuation moment [N m] or force [N] along the stroke (optional)"
    )
    envelope: PositiveFloat | Envelope | None = Field(
        default=None,
        description="the space every family must fit in, the same for all: a cylinder around "
        'the stroke axis ({"radius", "half_height"} [m]), or a number: a sphere of that radius [m] about '
        "the origin (the hinge centre of the templates); scene nodes and leaf edges are constrained, rigid "
        "bodies are not (optional)",
    )
    body_mass: PositiveFloat | None = Field(
        default=None,
        description="moving-body mass [kg] given to every family (the templates' 'body_mass'), so "
        "that they are compared with the same payload; default: each template's own (0.1 kg for every hinge "
        "family); the result reports each family's mass and warns when they differ",
    )
    gravity: tuple[float, float, float] | None = Field(
        default=None,
        description="gravitational acceleration [m/s^2] on every family's masses (its moving body, the payload, "
        "and its leaves), e.g. [0, 0, -9.81] in the templates' axes; default none. Frequencies, stresses and "
        "their exact gradients include the weight (model.loads); the fast methods do not, so screening and the "
        "preview then run exact curves",
    )
    solver: Literal["slsqp", "trust-constr"] = Field(
        default="slsqp",
        description="'slsqp' (scipy SLSQP, active set) or 'trust-constr' (scipy's "
        "interior-point / trust-region method, with BFGS Hessians of the constraints)",
    )
    kkt_tolerance: float = Field(
        default=1e-2,
        gt=0,
        lt=1,
        description="largest first-order optimality "
        "residual (KKT, relative to the objective's gradient) of a converged start",
    )
    starts: int = Field(
        default=4,
        ge=1,
        le=64,
        description="multi-start: starts per family (the first is the "
        "template's defaults clipped into the bounds, start k >= 1 the k-th point of a scrambled "
        "Halton sequence seeded by (seed, family): adding starts keeps the earlier ones)",
    )
    screen: int = Field(
        default=0,
        ge=0,
        le=256,
        description="fast-method screening: each start first "
        "evaluates this many Latin-hypercube candidates of its own with the modal-derivative "
        "'auto' method (the cheapest method whose estimated error meets screen_tolerance; exact "
        "where none does) and starts from the one with the highest estimated worst case",
    )
    screen_tolerance: float = Field(default=0.02, gt=0, lt=0.5, description="error tolerance of the screening")
    seed: int = Field(default=0, ge=0, description="base seed of the start sequence and the screening (deterministic)")
    max_iterations: int = Field(
        default=30,
        ge=1,
        le=500,
        description="SLSQP iterations per start and "
        "round (trust-constr: ten times as many, its iterations being cheaper)",
    )
    refine_rounds: int = Field(
        default=3,
        ge=0,
        le=10,
        description="verification rounds: what the "
        "verification found (the stroke of the verified minimum or stress peak, or the "
        "stressed member's constraints) is added to the search and the search resumed; "
        "a round that would add nothing stops with the reason",
    )
    verify_points: int = Field(default=181, ge=31, le=2001, description="exact stroke points of the verification")
    preview: bool = Field(
        default=True,
        description="compute the start design's curve (method 'auto') for the "
        "plot of start against optimum; a topology search's first pass leaves it out",
    )
    tolerance: float = Field(
        default=1e-3,
        gt=0,
        lt=0.1,
        description="relative tolerance of the search (SLSQP ftol) and of the verified-versus-searched worst case",
    )
