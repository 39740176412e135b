"""Wire models of the HTTP API, shared by the server and the client.

Only pydantic here (no model/ import): ``model/__init__`` loads CasADi, and the client must stay light. The
scene therefore travels as a JSON object (``SceneDocument``); the server validates it against
``model.scene.Scene`` and its full JSON schema is served at ``GET /v1/scene-schema``. A client may pass a
``model.Scene`` instance anyway: it is dumped to JSON first.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, FiniteFloat, PositiveFloat

from .._methods import METHODS, Method  # the one list of method names (imports nothing)
from ..optim.problem import Problem as OptimisationProblem  # pydantic only (no CasADi)

__all__ = [
    "API_VERSION",
    "METHODS",
    "Method",
    "SceneDocument",
    "Health",
    "ParameterInfo",
    "TemplateInfo",
    "TemplateSceneRequest",
    "FrequencyCurveRequest",
    "FailureOut",
    "FrequencyCurveOut",
    "DiagnosisRequest",
    "ModesRequest",
    "ModeShapeOut",
    "ModesOut",
    "FieldError",
    "Problem",
    "OptimisationProblem",
    "Job",
    "JobPage",
]

API_VERSION = "1"

SceneDocument = Annotated[
    dict[str, Any],
    Field(
        description="a flexopt scene (SI units); schema at GET /v1/scene-schema, examples from "
        "POST /v1/templates/{name}/scene"
    ),
]


class _Wire(BaseModel):
    model_config = ConfigDict(extra="forbid")


class Health(_Wire):
    """Liveness and version."""

    status: Literal["ok"] = "ok"
    version: str = Field(description="flexopt package version")
    api_version: str = API_VERSION
    methods: list[str] = Field(description="frequency-curve methods this server offers")


class ParameterInfo(_Wire):
    """One template parameter: its default and what values are accepted."""

    name: str
    type: Literal["number", "integer", "string"]
    default: float | int | str
    bounds: str = Field(
        description="accepted values, derived from the parameter's kind (the templates declare "
        "no numeric ranges; the scene validator has the final word)"
    )
    unit: str | None = Field(
        None,
        description="the SI unit of the default and of a plain number (None for counts, "
        "words and ratios); a string with any unit of this dimension is "
        "converted, e.g. '0.3 mm'",
    )


class TemplateInfo(_Wire):
    """A parametric template scene."""

    name: str
    parameters: list[ParameterInfo]


class TemplateSceneRequest(_Wire):
    """Parameter overrides for a template (omitted parameters keep their defaults)."""

    parameters: dict[str, float | int | str] = Field(
        default_factory=dict,
        description="numbers in the parameter's SI unit (a rotation stroke in deg), or "
        'strings with a unit, e.g. {"thickness": "0.3 mm"}; the scene returned is SI',
    )


class FrequencyCurveRequest(_Wire):
    """A scene, optionally a stroke grid, and the method."""

    scene: SceneDocument
    stroke: list[FiniteFloat] | None = Field(
        None,
        description="stroke values in the result's stroke unit: deg or rad, m for translations (SI even when "
        "the scene has a units block); default: the scene's own grid",
    )
    method: Method = Field(
        "exact",
        description="exact (continuation + eigen), fd1, fd2, manifold, reduced, hermite (exact samples + exact stroke derivatives, cubic Hermite) or auto",
    )
    tolerance: PositiveFloat = Field(
        0.01, description="relative error allowed on the first parasitic frequency (method auto)"
    )
    shapes: bool = Field(
        False,
        description="add the deflected configuration at every stroke point (`shapes`: "
        "member chains, body boxes and per point node positions [m], "
        "orientations as rotation vectors [rad], stresses)",
    )


class FailureOut(_Wire):
    """Where and why the curve stops before the requested range ends."""

    reason: str
    stroke: float
    last_converged: float
    message: str


class WarningOut(_Wire):
    """Something the user of a result must know (``model.results.ResultWarning``)."""

    kind: Literal["stress", "validity", "mesh", "units", "notice"] = Field(
        description="stress: a limit broken; validity: outside beam theory; mesh: discretisation not "
        "converged; units: input whose units look wrong; notice: anything else"
    )
    message: str = Field(description="one line: what, where and what to do")
    element: str | None = Field(None, description="the scene element it applies to, if one")
    stroke_range: list[float] | None = Field(None, description="[from, to] in the result's stroke unit, if limited")
    value: float | None = Field(None, description="the figure behind it (e.g. peak stress utilisation)")


class FrequencyCurveOut(_Wire):
    """Stroke-dependent natural frequencies (``model.FrequencyCurve.to_dict``); NaN travels as null."""

    scene: str
    method: str
    stroke: list[float | None]
    stroke_unit: str
    stroke_kind: str
    parasitic_hz: list[float | None] = Field(description="first parasitic frequency [Hz] per stroke point")
    modes_hz: list[list[float | None]] = Field(description="tracked modes [Hz], one row per stroke point")
    mode_labels: list[list[str]]
    drive_reaction: list[float | None]
    drive_reaction_unit: str
    max_von_mises: dict[str, list[float | None]] = Field(description="member -> largest von Mises stress [Pa]")
    allowable_stress: dict[str, float] = Field(description="member -> allowable stress [Pa]")
    status: Literal["complete", "truncated"]
    failures: list[FailureOut]
    conventions: dict[str, str]
    solver: dict[str, float | int | str | bool | None] = Field(
        description="how the curve was computed: numbers (seconds, tolerances, exact points, estimates; null for "
        "NaN) and notes (auto_method: the method auto chose; auto_rejected; mirrored: which half of the "
        "stroke was mirrored by symmetry)"
    )
    warnings: list[WarningOut] = Field(default_factory=list, description="limits broken, validity, mesh, units")
    mesh_error: float | None = Field(None, description="estimated relative discretisation error of parasitic_hz")
    provenance: dict[str, Any] = Field(
        default_factory=dict, description="flexopt version, scene hash, method, solver settings"
    )
    shapes: dict[str, Any] | None = Field(
        None, description="with shapes=true: {members, bodies, points: one deflected configuration per stroke point}"
    )


class SpacarImportRequest(_Wire):
    """A SPACAR ``.dat`` model as text (model.spacar: what is mapped, and every line that is not, is an error)."""

    text: str = Field(max_length=2_000_000, description="the .dat file's contents")
    name: str = Field("spacar", max_length=100, description="name of the scene made from it")


class SpacarImportResult(_Wire):
    """The scene made from a ``.dat`` model and what the importer did."""

    scene: dict[str, Any] = Field(description="the scene (SI), ready for /v1/frequency-curve or /v1/diagnosis")
    mapped: dict[str, int] = Field(description="lines mapped, per keyword")
    notes: list[str] = Field(description="what was read in a way worth knowing (conversions, defaults, left-outs)")
    numbering: str = Field(description="how the file's X and R node numbers pair up")
    spacar_dof: int = Field(description="SPACAR's degrees of freedom: inputs and dynamic (DYNE) deformations")
    released: dict[str, list[int]] = Field(
        default_factory=dict,
        description="released (RLSE) deformations of beams and trusses, e.g. {'BEAM 4': [3, 5]}: calculated by "
        "SPACAR, read as elastic with their ESTIFF stiffness (docs: SPACAR models)",
    )
    spacar: dict[str, Any] = Field(
        description="SPACAR's own D_cc of the file (model.spacar_dcc; docs: SPACAR models): m, n, rank, "
        "condition_number (null: rank deficient), verdict, dof and the definition used"
    )


class SpacarExportRequest(_Wire):
    """A scene to write as a SPACAR ``.dat`` model."""

    scene: SceneDocument
    numbering: Literal[2, 3] = Field(2, description="SPACAR nodes per point: 2 (X 2i-1, R 2i) or 3 (X 3i-2, R 3i-1)")
    warping: Literal["factor", "beamw"] = Field(
        "factor",
        description="constrained warping as BEAM with GJ times the member's Vlasov factor (factor) or as BEAMW "
        "with warping nodes, EIw and the clamped ends' warping nodes fixed (beamw: three-node numbering)",
    )


class StateSpaceRequest(_Wire):
    """A scene, a stroke point, inputs and outputs for the linearised model (model.linear)."""

    scene: SceneDocument
    at_stroke: FiniteFloat = Field(0.0, description="stroke value (stroke unit)")
    inputs: list[str] = Field(
        min_length=1,
        max_length=50,
        description="forces or moments on nodes or bodies, "
        "e.g. ['tip.fz', 'stage.my'] (fx fy fz mx my mz, global axes)",
    )
    outputs: list[str] = Field(
        min_length=1,
        max_length=50,
        description="positions, rotations or rates, e.g. "
        "['tip.z', 'tip.ry', 'tip.vz'] (x y z rx ry rz vx vy vz wx wy wz)",
    )
    damping: float = Field(0.01, ge=0, lt=1, description="modal damping ratio of every mode")
    modes: int | None = Field(None, ge=1, le=3000, description="keep the lowest N modes (default all)")
    frequencies_hz: list[FiniteFloat] | None = Field(
        None, max_length=2000, description="frequencies of a frequency response (Bode) table"
    )


class DiagnosisRequest(_Wire):
    """A scene to diagnose, at the reference or at a stroke value."""

    scene: SceneDocument
    at_stroke: FiniteFloat | None = Field(
        None, description="stroke value (stroke unit); null = reference configuration"
    )
    kinematic: bool | None = Field(
        None,
        description="kinematic diagnosis (null: the scene's own setting, or the kinematic idealisation "
        "when the scene declares no rigid or generalised deformation; the result's notes say so)",
    )


class ModesRequest(_Wire):
    """A scene and a stroke value at which to compute the deflected structure and mode shapes."""

    scene: SceneDocument
    at_stroke: FiniteFloat = Field(0.0, description="stroke value in the scene's stroke unit")
    mode: int | None = Field(
        None,
        ge=0,
        description="0-based mode drawn with Accept: image/png or image/gif (default: the first parasitic mode)",
    )


class ModeShapeOut(_Wire):
    """One mode shape, mass normalised (phi^T M phi = 1, M in kg and kg m^2)."""

    hz: float | None = Field(description="natural frequency [Hz]")
    label: str = Field(description="parasitic | intended | drive")
    translation: dict[str, list[float]] = Field(description="node -> translation [m] per unit modal coordinate")
    rotation: dict[str, list[float]] = Field(description="node -> rotation vector [rad] per unit modal coordinate")


class ModesOut(_Wire):
    """The deflected structure and its mode shapes at one stroke value (``model.shapes.Shapes.to_dict``)."""

    scene: str
    stroke: float = Field(description="stroke value (stroke_unit)")
    stroke_unit: str
    stroke_kind: str
    nodes: dict[str, list[float]] = Field(
        description="node -> deflected position [m] (scene and segment-internal nodes 'member#i')"
    )
    orientations: dict[str, list[float]] = Field(description="node -> rotation vector from the reference [rad]")
    bodies: dict[str, dict[str, Any]] = Field(
        description="body -> position (centre of mass) [m], orientation "
        "[rad], nodes, drawn box size and centre offset [m]"
    )
    members: dict[str, dict[str, Any]] = Field(
        description="member -> node chain, width and thickness [m] (plates), unit width direction in the reference"
    )
    drive_reaction: float | None = Field(description="actuator moment [N m] or force [N]")
    stress: dict[str, dict[str, float | None]] = Field(
        description="member -> von_mises [Pa], allowable [Pa], utilisation [-]"
    )
    modes: list[ModeShapeOut]
    warnings: list[WarningOut] = Field(default_factory=list)
    conventions: dict[str, str]
    provenance: dict[str, Any] = Field(
        default_factory=dict, description="flexopt version, scene hash, settings, the units the scene was read in"
    )


class FieldError(_Wire):
    """One invalid input: where (path) and why."""

    loc: list[str | int]
    msg: str


class Problem(BaseModel):
    """RFC 9457 problem details: every error body of the API."""

    type: str = "about:blank"
    title: str
    status: int
    detail: str
    errors: list[FieldError] = Field(default_factory=list)


class Job(_Wire):
    """An optimisation job: status, progress, finished cases so far and the final result."""

    id: str
    kind: Literal["optimisation", "frequency-curve", "topology-search", "pareto-front"] = Field(
        "optimisation",
        description="an optimisation, a frequency curve too costly for a request, a topology search or a Pareto front",
    )
    status: Literal["queued", "running", "cancelling", "succeeded", "failed", "cancelled"]
    progress: dict[str, Any] = Field(
        description="{'done': cases finished, 'total': cases} of the running batch; "
        "a topology search adds 'phase' (screen, first pass, full pass, refine), "
        "'counts' (generated, screened, passed, first_pass, optimised, verified) "
        "and 'best' (the best verified worst case so far); a Pareto front adds 'phase' "
        "(optima, levels, strokes, check, check verification)"
    )
    partial: list[dict[str, Any]] = Field(
        description="summary of every finished case (family, start, verified worst-case frequency, design; "
        "a search's or a front's 'phase'; a front's point also 'kind', 'level' and its verified "
        "'drive_stiffness' or 'stroke')"
    )
    result: dict[str, Any] | None = Field(
        description="optim.optimise's result once succeeded: per family the best "
        "verified design, curves before and after, the ranking (a "
        "topology search: run_topology_search's candidates, ranking "
        "and best; a Pareto front: optim.pareto.pareto's points)"
    )
    error: str | None = None
    attempts: int = Field(description="runs started (a server restart resumes a running job)")
    created: str
    updated: str
    estimate: dict[str, Any] | None = Field(
        default=None,
        description="the cost estimate made at submission: 'seconds' (CPU seconds on one core, a budget: "
        "every start spends its iteration budget; most jobs take less), 'cases', 'what' drives it, "
        "'drivers' (the fields that reduce it, largest share first) and this server's 'limit'",
    )


class JobPage(_Wire):
    """A page of jobs, newest first."""

    items: list[Job]
    total: int
    offset: int
    limit: int
