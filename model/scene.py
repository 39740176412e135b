"""The scene: a flexure design as JSON (pydantic v2 schema only; no CasADi here).

Units are SI (m, kg, s, N, Pa) in every description. A scene written in other units says so in an optional
``units`` block (e.g. ``{"length": "mm", "mass": "tonne", "stress": "MPa"}``): its numbers are converted to SI
when the scene is validated (model.units, with pint) and the block is left out of every dump, so a loaded
scene, its hash and every result are SI.

A scene holds materials, nodes, rigid bodies, flexible elements (spatial beams and trusses), supports,
the stroke (the driven coordinate and its range) and, optionally, the support directions used to label
parasitic modes. Cross-references are names (strings), checked in one after-validator so that an error
names the field and the fix.
"""

from __future__ import annotations

import difflib
import math
from typing import Annotated, Any, Final, Literal

import numpy as np
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    field_validator,
    model_serializer,
    model_validator,
)

__all__ = [
    "SCENE_FORMAT",
    "AUTO_START",
    "SCENE_VERSION",
    "MODE_NAMES",
    "Material",
    "Node",
    "RectangularSection",
    "GeneralSection",
    "Section",
    "Beam",
    "Truss",
    "Element",
    "RigidBody",
    "Support",
    "Stroke",
    "SupportDirections",
    "Units",
    "Load",
    "LoadRamp",
    "LoadTable",
    "Joint",
    "Scene",
    "expand_modes",
    "did_you_mean",
]

#: First mesh of a ``segments: "auto"`` beam (model.mesh refines it; model.structure compiles an unresolved
#: "auto" beam at it).
AUTO_START = 4

SCENE_FORMAT: Final = "flexopt.scene"  # Final: read as the Literal the Scene field declares
SCENE_VERSION: Final = 1

#: Names of the six deformation parameters of the spatial beam (seed 002, eq. 2), and groups of them.
MODE_NAMES: dict[str, tuple[int, ...]] = {
    "elongation": (0,),
    "torsion": (1,),
    "bending_y": (2, 3),  # eps3, eps4: bending about local y (deflection along local z), EI_y
    "bending_z": (4, 5),  # eps5, eps6: bending about local z (deflection along local y), EI_z
    "eps1": (0,),
    "eps2": (1,),
    "eps3": (2,),
    "eps4": (3,),
    "eps5": (4,),
    "eps6": (5,),
}

DeformationName = Literal[
    "elongation", "torsion", "bending_y", "bending_z", "eps1", "eps2", "eps3", "eps4", "eps5", "eps6"
]

Pos = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNeg = Annotated[float, Field(ge=0, allow_inf_nan=False)]
Real = Annotated[float, Field(allow_inf_nan=False)]
Vec3 = Annotated[tuple[Real, Real, Real], Field(description="a 3-vector (x, y, z)")]
Name = Annotated[str, Field(min_length=1, max_length=100, pattern=r"^[^#\s]+$")]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class Material(_Strict):
    """An isotropic linear-elastic material."""

    name: Name
    E: Pos = Field(description="Young's modulus [Pa]")
    G: Pos = Field(description="shear modulus [Pa]")
    density: Pos = Field(description="mass density [kg/m^3]")
    allowable_stress: Pos = Field(description="allowable von Mises stress [Pa]")


class Node(_Strict):
    """A nodal point. Its orientation at the reference configuration is the global frame."""

    name: Name
    position: Vec3 = Field(description="reference position [m]")


class RectangularSection(_Strict):
    """A solid rectangle: ``width`` along the local y axis, ``thickness`` along the local z axis.

    For a leaf spring the thickness is the small dimension, so bending about local y (eps3, eps4) is the
    weak, compliant bending.
    """

    kind: Literal["rectangular"] = "rectangular"
    width: Pos = Field(description="extent along local y [m]")
    thickness: Pos = Field(description="extent along local z [m]")
    warping: Literal["free", "one_end", "both_ends"] = Field(
        "free",
        description="torsion assumption: free warping (St Venant, default) or warping constrained at one "
        "or both clamped ends of the element (Vlasov correction on GJ, see model.sections)",
    )


class GeneralSection(_Strict):
    """A section given by its properties. Fibre distances are needed only for stresses."""

    kind: Literal["general"] = "general"
    A: Pos = Field(description="area [m^2]")
    Iy: Pos = Field(description="second moment about local y [m^4] (resists deflection along local z)")
    Iz: Pos = Field(description="second moment about local z [m^4] (resists deflection along local y)")
    J: Pos = Field(description="St Venant torsion constant [m^4]")
    cy: Pos | None = Field(None, description="largest fibre distance along local y [m] (for stress)")
    cz: Pos | None = Field(None, description="largest fibre distance along local z [m] (for stress)")
    torsion_stress_factor: Pos | None = Field(
        None, description="max shear stress per unit torque [1/m^3] (for stress); thin rectangle: t/J"
    )
    shear_y: NonNeg = Field(
        0.0,
        description="SPACAR's shear flexibility S_y = E Iy / (k G A) [m^2] of bending about local y (eps3, "
        "eps4): Timoshenko shear deformation; 0 = none (Euler-Bernoulli)",
    )
    shear_z: NonNeg = Field(
        0.0, description="SPACAR's shear flexibility S_z = E Iz / (k G A) [m^2] of bending about local z (eps5, eps6)"
    )
    Iw: NonNeg = Field(
        0.0,
        description="warping constant [m^6] (thin rectangle t^3 w^3 / 144; SPACAR's EIw / E); used only with "
        "'warping' constrained at an end",
    )
    warping: Literal["free", "one_end", "both_ends"] = Field(
        "free",
        description="torsion assumption: free warping (St Venant, default) or warping constrained at one or both "
        "ends of the member (Vlasov factor on GJ with this section's Iw, see model.sections)",
    )

    @model_validator(mode="after")
    def _warping_constant(self) -> GeneralSection:
        if self.warping != "free" and not self.Iw > 0:
            raise ValueError(
                f"warping '{self.warping}' needs the section's warping constant: give Iw > 0 (thin rectangle "
                "t^3 w^3 / 144), or warping 'free'"
            )
        return self


Section = Annotated[RectangularSection | GeneralSection, Field(discriminator="kind")]


class Beam(_Strict):
    """A SPACAR spatial beam (seed 002, eq. 2) between two nodes, meshed into ``segments`` elements."""

    kind: Literal["beam"] = "beam"
    name: Name
    nodes: tuple[Name, Name] = Field(description="end nodes (p, q)")
    material: Name
    section: Section
    y_axis: Vec3 = Field(
        description="direction of the section's local y axis (the width direction of a rectangle); "
        "its part perpendicular to the beam axis is used, so it must not be parallel to the beam"
    )
    segments: Annotated[int, Field(ge=1, le=1000)] | Literal["auto"] = Field(
        1,
        description="number of beam elements along the member, or 'auto': refined until the estimated "
        "discretisation error of the curve is within the scene's mesh_tolerance (model.mesh)",
    )

    @field_validator("segments", mode="before")
    @classmethod
    def _segments(cls, v: object) -> object:
        # one message for both members of the union (pydantic would report a clause per member)
        if v == "auto" or (isinstance(v, int) and not isinstance(v, bool) and 1 <= v <= 1000):
            return v
        if isinstance(v, float) and v.is_integer() and 1 <= v <= 1000:
            return int(v)
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            raise ValueError(
                f"segments must be greater than or equal to 1 and less than or equal to 1000 "
                f"(a whole number) or 'auto', got {v!r}"
            )
        raise ValueError(f"segments must be a whole number from 1 to 1000 or 'auto', got {v!r}")

    rigid: tuple[DeformationName, ...] = Field(
        (),
        description="deformation modes held rigid (zero), e.g. ['elongation'] for a wire flexure, "
        "['elongation', 'bending_z'] for a sheet whose in-plane bending is rigid",
    )
    generalised: tuple[DeformationName, ...] = Field(
        (),
        description="deformation modes taken as generalised (independent) coordinates e(m) in the "
        "exact-constraint diagnosis (seed 002, eq. 4), e.g. ['eps5'] for one sheet of a folded sheet "
        "flexure (section 4.2); a beam of several segments is diagnosed as one flexure",
    )
    kinematic_rigid: tuple[DeformationName, ...] | None = Field(
        None,
        description="deformation modes held rigid in a *kinematic* diagnosis (Scene.kinematic); default "
        "derived from the section: a sheet (rectangle with width >= 2 thickness, or Iz >= 4 Iy) keeps "
        "elongation and in-plane bending (bending_z) rigid, a wire only its elongation",
    )


class Truss(_Strict):
    """A truss (elongation only) between two nodes."""

    kind: Literal["truss"] = "truss"
    name: Name
    nodes: tuple[Name, Name]
    material: Name
    area: Pos = Field(description="cross-section area [m^2]")
    segments: int = Field(
        1,
        ge=1,
        le=1,
        description="always 1: a truss has no bending stiffness, so interior nodes would be free mechanisms",
    )
    rigid: tuple[Literal["elongation", "eps1"], ...] = Field((), description="['elongation'] for a rigid bar")
    generalised: tuple[Literal["elongation", "eps1"], ...] = Field(
        (),
        description="['elongation'] to take the elongation as a generalised coordinate e(m) in the "
        "exact-constraint diagnosis",
    )
    kinematic_rigid: tuple[Literal["elongation", "eps1"], ...] | None = Field(
        None, description="rigid deformations in a kinematic diagnosis (default: the elongation is rigid)"
    )


Element = Annotated[Beam | Truss, Field(discriminator="kind")]


class RigidBody(_Strict):
    """A rigid body that carries nodes; its mass properties are given about its centre of mass."""

    name: Name
    mass: NonNeg = Field(0.0, description="mass [kg]")
    center_of_mass: Vec3 = Field(description="centre of mass at the reference configuration [m]")
    inertia: tuple[Vec3, Vec3, Vec3] = Field(
        ((0.0, 0.0, 0.0),) * 3, description="inertia tensor about the centre of mass, global axes [kg m^2]"
    )
    nodes: tuple[Name, ...] = Field((), description="nodes rigidly attached to the body")

    @field_validator("inertia")
    @classmethod
    def _inertia_physical(cls, v: tuple[Vec3, Vec3, Vec3]) -> tuple[Vec3, Vec3, Vec3]:
        J = np.array(v, dtype=float)
        if not np.allclose(J, J.T, rtol=1e-9, atol=1e-300 + 1e-12 * np.abs(J).max()):
            raise ValueError("inertia tensor must be symmetric; fix: set inertia[i][j] == inertia[j][i]")
        w = np.linalg.eigvalsh(J)
        tol = 1e-12 * max(abs(w).max(), 1e-300)
        if w.min() < -tol:
            raise ValueError("inertia tensor must be positive semidefinite; fix the principal moments")
        a, b, c = sorted(w)
        if c > a + b + tol * 10:
            raise ValueError("inertia tensor violates the triangle inequality (I1 <= I2 + I3); no real body has it")
        return v


DofName = Literal["x", "y", "z", "rx", "ry", "rz"]


class Support(_Strict):
    """A support: fixes coordinates of a node, or grounds a whole body."""

    node: Name | None = Field(None, description="supported node")
    body: Name | None = Field(None, description="grounded body (all six coordinates fixed)")
    dofs: tuple[DofName, ...] = Field(
        ("x", "y", "z", "rx", "ry", "rz"), description="fixed coordinates of the node (default: all)"
    )

    @model_validator(mode="after")
    def _one_target(self) -> Support:
        if (self.node is None) == (self.body is None):
            raise ValueError("give exactly one of 'node' or 'body'")
        if not self.dofs:
            raise ValueError("'dofs' is empty; list the fixed coordinates or remove the support")
        return self


class Stroke(_Strict):
    """The driven coordinate and its range.

    A rotation stroke is a spin about the fixed ``axis``: the stroke value is the twist angle about that
    axis of the target's orientation (swing-twist decomposition), the actuator exerts a moment about the
    axis only, and locking the drive in the eigen analysis removes only the incremental spin about it
    (delta_omega . axis = 0); see model.statics. A translation stroke is the displacement along ``axis``.
    """

    kind: Literal["rotation", "translation"] = "rotation"
    node: Name | None = Field(None, description="driven node")
    body: Name | None = Field(None, description="driven body")
    axis: Vec3 = Field(description="fixed drive axis (normalised internally)")
    start: Real | None = Field(None, description="first stroke value (default -45 deg for rotations)")
    stop: Real | None = Field(None, description="last stroke value (default +45 deg for rotations)")
    points: int = Field(91, ge=2, le=100001, description="number of stroke points")
    unit: Literal["deg", "rad", "m"] | None = Field(
        None,
        description="stroke unit: deg (default) or rad for rotations, m for translations (written in the "
        "units block's length unit, if any, and converted to m)",
    )
    drive: Literal["locked", "free"] = Field(
        "locked", description="eigen analysis with the actuator holding the drive (locked) or not (free)"
    )

    @model_validator(mode="after")
    def _consistent(self) -> Stroke:
        if (self.node is None) == (self.body is None):
            raise ValueError("give exactly one of 'node' or 'body' as the driven target")
        if not np.linalg.norm(self.axis) > 0:
            raise ValueError("axis is the zero vector; give the drive direction, e.g. [0, 0, 1]")
        if self.kind == "rotation" and self.unit == "m":
            raise ValueError("a rotation stroke has unit 'deg' or 'rad', not 'm'")
        if self.kind == "translation":
            if self.unit in ("deg", "rad"):
                raise ValueError("a translation stroke has unit 'm' (the scene's length unit)")
            if self.start is None or self.stop is None:
                raise ValueError("a translation stroke needs 'start' and 'stop' (in the scene's length unit)")
        if self.start is not None and self.stop is not None and not self.stop > self.start:
            raise ValueError(f"stop ({self.stop}) must be greater than start ({self.start})")
        return self

    @property
    def resolved_unit(self) -> str:
        """The unit of the stroke values."""
        return self.unit or ("deg" if self.kind == "rotation" else "m")

    def values(self) -> np.ndarray:
        """The stroke values in ``resolved_unit`` (linearly spaced, ``points`` of them)."""
        default = 45.0 if self.resolved_unit == "deg" else math.radians(45.0)
        start = self.start if self.start is not None else -default
        stop = self.stop if self.stop is not None else default
        if not stop > start:
            raise ValueError(f"stroke stop ({stop}) must be greater than start ({start})")
        return np.linspace(start, stop, self.points)

    def to_internal(self, s: np.ndarray | float) -> np.ndarray:
        """Stroke values in radians (rotations) or length units (translations)."""
        return np.radians(s) if self.resolved_unit == "deg" else np.asarray(s, dtype=float)


class Joint(_Strict):
    """An ideal joint between two nodes (a kinematic pair, SPACAR's HINGE): ``hinge`` (revolute) leaves only the
    rotation of ``nodes[1]`` relative to ``nodes[0]`` about ``axis`` free, ``slider`` (prismatic) only their
    relative translation along ``axis``; the other five relative coordinates are exact constraints (rigid, with
    multipliers; model.elements.joint_spec). The nodes usually coincide (a hinge's two sides); they must not
    be carried by the same body. Joints have no mass and no stiffness."""

    kind: Literal["hinge", "slider"] = "hinge"
    name: Name
    nodes: tuple[Name, Name] = Field(description="the two nodes the joint connects (p, q)")
    axis: Vec3 = Field(description="joint axis in global axes at the reference (normalised internally)")

    @model_validator(mode="after")
    def _axis(self) -> Joint:
        if not np.linalg.norm(self.axis) > 0:
            raise ValueError("axis is the zero vector; give the joint's axis, e.g. [0, 0, 1]")
        if self.nodes[0] == self.nodes[1]:
            raise ValueError(
                f"joint '{self.name}' connects node '{self.nodes[0]}' to itself; give two nodes "
                "(they may share a position)"
            )
        return self


class LoadRamp(_Strict):
    """A force (or moment, with the load's ``kind``) varying linearly with the stroke: ``start`` at the stroke's
    first value, ``stop`` at its last (extrapolated linearly beyond them, e.g. to stroke 0, where continuation
    starts)."""

    start: Vec3 = Field(description="force [N] (or moment [N m]) at the stroke's first value")
    stop: Vec3 = Field(description="force [N] (or moment [N m]) at the stroke's last value")


class LoadTable(_Strict):
    """A force (or a moment) given at stroke values (the stroke's unit), linear between them; the table must
    cover the stroke range and stroke 0 (where continuation starts)."""

    stroke: tuple[Real, ...] = Field(min_length=2, description="stroke values, increasing (stroke unit)")
    force: tuple[Vec3, ...] | None = Field(None, min_length=2, description="force at each stroke value [N]")
    moment: tuple[Vec3, ...] | None = Field(None, min_length=2, description="moment at each stroke value [N m]")

    @model_validator(mode="after")
    def _consistent(self) -> LoadTable:
        if (self.force is None) == (self.moment is None):
            raise ValueError("give exactly one of 'force' or 'moment' in a load table")
        vals, what = (self.force, "force") if self.force is not None else (self.moment, "moment")
        assert vals is not None
        if len(self.stroke) != len(vals):
            raise ValueError(
                f"the table has {len(self.stroke)} stroke values and {len(vals)} {what}s; "
                f"give one {what} per stroke value"
            )
        if not all(b > a for a, b in zip(self.stroke[:-1], self.stroke[1:])):
            raise ValueError("table stroke values must increase strictly; sort them")
        return self

    @model_serializer(mode="wrap")
    def _dump(self, handler: Any) -> Any:
        out = handler(self)  # the absent one of force and moment is left out
        if isinstance(out, dict):
            for key in ("force", "moment"):
                if out.get(key, 0) is None:
                    out.pop(key)
        return out

    @property
    def values(self) -> tuple[Vec3, ...]:
        """The table's vectors (forces or moments)."""
        out = self.force if self.force is not None else self.moment
        assert out is not None
        return out


class Load(_Strict):
    """An external force or moment on a node or a body (SPACAR's XF/DELXF on a position or a rotation node).

    The vector is either constant (``force`` or ``moment``), a linear ramp over the stroke (``ramp``, a force
    unless ``kind`` is ``"moment"``) or a table over the stroke (``table``, with ``force`` or ``moment``
    rows). By default the load is dead: its direction is fixed in space. With ``follower: true`` it turns with
    the loaded node (or body): the value given is its direction at the reference configuration.

    A dead force enters the total energy as the potential ``-F . x`` of its point of application (for a body,
    ``point``; default its centre of mass), so its stiffness is symmetric. A follower force, and a moment
    (dead or follower) under finite 3D rotations, has no potential: it is non-conservative, its load
    stiffness is unsymmetric and the eigen analysis solves the general eigenproblem, whose eigenvalues may
    be complex (flutter); see model.loads.
    """

    name: Name | None = Field(None, description="optional label")
    node: Name | None = Field(None, description="loaded node")
    body: Name | None = Field(None, description="loaded body")
    point: Vec3 | None = Field(
        None,
        description="point of application on the body at the reference "
        "configuration [m] (default: its centre of mass); body loads only",
    )
    force: Vec3 | None = Field(None, description="constant force [N], global axes (at the reference, if follower)")
    moment: Vec3 | None = Field(None, description="constant moment [N m], global axes (at the reference, if follower)")
    ramp: LoadRamp | None = Field(None, description="force (or moment, kind 'moment') varying linearly with the stroke")
    table: LoadTable | None = Field(None, description="force or moment given per stroke value")
    kind: Literal["force", "moment"] | None = Field(
        None, description="what a ramp gives: 'force' (default) or 'moment'; implied by 'force', 'moment' or a table"
    )
    follower: bool = Field(
        False,
        description="the load turns with the loaded node or body (non-conservative); default: dead (fixed in space)",
    )

    @model_serializer(mode="wrap")
    def _dump(self, handler: Any) -> Any:
        # the fields added with moments are left out at their defaults, so a scene with dead forces only
        # dumps (and hashes, model.checks.scene_hash) as before they existed
        out = handler(self)
        if isinstance(out, dict):
            for key in ("moment", "kind"):
                if out.get(key, 0) is None:
                    out.pop(key)
            if out.get("follower") is False:
                out.pop("follower")
        return out

    @model_validator(mode="after")
    def _one(self) -> Load:
        if (self.node is None) == (self.body is None):
            raise ValueError("give exactly one of 'node' or 'body' as the loaded target")
        if self.point is not None and self.body is None:
            raise ValueError("'point' is for body loads; a node load acts at the node (remove 'point')")
        given = [k for k in ("force", "moment", "ramp", "table") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError(f"give exactly one of 'force', 'moment', 'ramp' or 'table' (got {given or 'none'})")
        implied = (
            "moment"
            if (self.moment is not None or (self.table is not None and self.table.moment is not None))
            else ("force" if self.ramp is None else None)
        )
        if self.kind is not None and implied is not None and self.kind != implied:
            raise ValueError(f"kind '{self.kind}' contradicts the {implied} given; remove 'kind' or give a {self.kind}")
        return self

    @property
    def is_moment(self) -> bool:
        """Whether the load is a moment (else a force)."""
        if self.kind is not None:
            return self.kind == "moment"
        return self.moment is not None or (self.table is not None and self.table.moment is not None)

    @property
    def conservative(self) -> bool:
        """Whether the load has a potential: a dead force (a moment or a follower load has none in 3D)."""
        return not (self.follower or self.is_moment)

    def describe(self, index: int) -> str:
        """``"loads[i] ('name': follower force on node 'B')"``, for messages."""
        what = ("follower " if self.follower else "dead ") + ("moment" if self.is_moment else "force")
        on = f"node '{self.node}'" if self.node is not None else f"body '{self.body}'"
        return f"loads[{index}]" + (f" '{self.name}'" if self.name else "") + f" ({what} on {on})"

    def value(self, stroke: float, first: float, last: float) -> np.ndarray:
        """The force [N] or moment [N m] at ``stroke`` (stroke unit) of a stroke running from ``first`` to
        ``last``."""
        const = self.force if self.force is not None else self.moment
        if const is not None:
            return np.array(const, dtype=float)
        if self.ramp is not None:
            t = (stroke - first) / (last - first)
            return (1.0 - t) * np.array(self.ramp.start) + t * np.array(self.ramp.stop)
        assert self.table is not None
        F = np.array(self.table.values, dtype=float)
        return np.array([np.interp(stroke, self.table.stroke, F[:, k]) for k in range(3)])

    def rate(self, stroke: float, first: float, last: float) -> np.ndarray:
        """d value / d stroke [N or N m per stroke unit] at ``stroke`` (the table's slope on the segment
        holding it)."""
        if self.force is not None or self.moment is not None:
            return np.zeros(3)
        if self.ramp is not None:
            return (np.array(self.ramp.stop) - np.array(self.ramp.start)) / (last - first)
        assert self.table is not None
        s = np.array(self.table.stroke)
        F = np.array(self.table.values, dtype=float)
        i = int(np.clip(np.searchsorted(s, stroke, side="right") - 1, 0, len(s) - 2))
        return (F[i + 1] - F[i]) / (s[i + 1] - s[i])


class SupportDirections(_Strict):
    """Directions that count as *support* (parasitic) motion, for labelling modes by participation.

    A mode is parasitic when more than half of its kinetic energy lies in these translation directions
    and rotation axes (global frame). Without them, every mode with the drive locked is parasitic.
    """

    translations: tuple[Vec3, ...] = ()
    rotations: tuple[Vec3, ...] = ()

    @field_validator("translations", "rotations")
    @classmethod
    def _not_zero(cls, dirs: tuple[Vec3, ...]) -> tuple[Vec3, ...]:
        """A zero vector names no direction (it was accepted, and every mode then read as non-parasitic)."""
        for i, d in enumerate(dirs):
            if not math.hypot(*d) > 0:
                raise ValueError(
                    f"direction {i} is the zero vector, which names no direction: give a direction "
                    "such as [0, 1, 0], or remove it"
                )
        return dirs


class Units(_Strict):
    """The units a scene's numbers are written in (each a pint unit string; omitted kinds are SI).

    Converted to SI when the scene is validated (:func:`model.units.scene_to_si`); results are always SI.
    """

    length: str | None = Field(
        None, description="unit of lengths, e.g. 'mm' (positions, sections, a translation stroke); default m"
    )
    mass: str | None = Field(
        None, description="unit of masses, e.g. 'tonne' or 'g' (inertia: mass length^2); default kg"
    )
    force: str | None = Field(
        None, description="unit of force, e.g. 'N'; only sets the default stress unit (force / length^2); default N"
    )
    stress: str | None = Field(
        None, description="unit of E, G and the allowable stress, e.g. 'MPa' or 'GPa'; default force / length^2"
    )
    density: str | None = Field(None, description="unit of density, e.g. 'kg/m^3' or 'g/cm^3'; default mass / length^3")

    @model_validator(mode="after")
    def _readable(self) -> Units:
        from .units import UnitsError, check_unit

        errors = []
        for kind in ("length", "mass", "force", "stress", "density"):
            u = getattr(self, kind)
            if u is not None:
                try:
                    check_unit(kind, u)
                except UnitsError as exc:
                    errors.append(f"units.{kind}: {exc}")
        if errors:
            raise ValueError("; ".join(errors))
        return self


class Scene(_Strict):
    """A flexure design: the whole input of an analysis."""

    format: Literal["flexopt.scene"] = SCENE_FORMAT
    version: Literal[1] = SCENE_VERSION
    name: str = "scene"
    materials: tuple[Material, ...] = Field(min_length=1)
    nodes: tuple[Node, ...] = Field(min_length=2)
    bodies: tuple[RigidBody, ...] = ()
    elements: tuple[Element, ...] = Field(min_length=1)
    supports: tuple[Support, ...] = Field(min_length=1)
    stroke: Stroke | None = Field(
        ...,
        description="the driven coordinate; null only for a structure without drive (exact-constraint "
        "diagnosis); a frequency curve needs a stroke",
    )
    kinematic: bool = Field(
        False,
        description="exact-constraint diagnosis with the kinematic idealisation: every flexure keeps only "
        "its compliant deformations (see Beam.kinematic_rigid); dynamic analyses ignore it",
    )
    mesh_tolerance: float = Field(
        1e-3,
        gt=0,
        le=0.5,
        allow_inf_nan=False,
        description="relative discretisation error of the first parasitic frequency aimed at by beams with "
        "segments 'auto' (model.mesh)",
    )
    support_directions: SupportDirections | None = None
    modes: int = Field(6, ge=1, le=50, description="number of modes reported per stroke point")
    gravity: Vec3 | None = Field(
        None,
        description="gravitational acceleration [m/s^2] acting on the mass of every element and body, "
        "e.g. [0, 0, -9.81]; default none",
    )
    loads: tuple[Load, ...] = Field((), description="external forces and moments on nodes or bodies (model.loads)")
    joints: tuple[Joint, ...] = Field((), description="ideal joints (hinges, sliders) between nodes")
    units: Units | None = Field(
        None,
        exclude=True,
        description="units the numbers above are written in (default SI); converted to SI on reading, so the "
        "validated scene, its dumps and every result are SI",
    )

    @model_serializer(mode="wrap")
    def _dump(self, handler: Any) -> Any:
        # gravity and loads are left out of a dump when absent, so a scene without them dumps (and hashes,
        # model.checks.scene_hash) exactly as before they existed
        out = handler(self)
        if isinstance(out, dict):
            if out.get("gravity", 0) is None:
                out.pop("gravity")
            for key in ("loads", "joints"):
                if key in out and not out[key]:
                    out.pop(key)
        return out

    @model_validator(mode="before")
    @classmethod
    def _to_si(cls, data: Any) -> Any:
        if isinstance(data, dict) and isinstance(data.get("units"), dict):
            from .units import UnitsError, scene_to_si

            try:
                return scene_to_si(data)
            except UnitsError:
                return data  # the Units validator names the bad unit; nothing is analysed
        return data

    @model_validator(mode="after")
    def _references(self) -> Scene:
        """Cross-references and geometry, one table of checks (:class:`_ReferenceCheck`): every error found,
        joined in one message."""
        errors = _ReferenceCheck(self).errors()
        if errors:
            raise ValueError("; ".join(errors))
        return self


class _ReferenceCheck:
    """The checks of :meth:`Scene._references`, read top to bottom: unique names, bodies, elements, supports
    and the stroke; each appends its messages to ``self.out``."""

    def __init__(self, scene: Scene) -> None:
        self.scene = scene
        self.out: list[str] = []
        self.names_of = {
            "node": [n.name for n in scene.nodes],
            "body": [b.name for b in scene.bodies],
            "material": [m.name for m in scene.materials],
        }
        self.carrier: dict[str, str] = {}
        self.supported: dict[str, set[str]] = {}
        self.grounded: set[str] = set()
        self.budget = SUGGEST_BUDGET  # work left for suggestions (character pairs)

    def unknown(self, kind: str, name: str) -> str:
        close, spent = closest(name, self.names_of[kind], self.budget)  # one budget for the whole scene
        self.budget -= spent
        return f"unknown {kind} '{name}'" + (f" (did you mean '{close}'?)" if close else "")

    def unique(self, kind: str, names: list[str]) -> set[str]:
        seen: set[str] = set()
        for i, n in enumerate(names):
            if n in seen:
                self.out.append(f"{kind}[{i}].name: duplicate name '{n}'; names must be unique")
            seen.add(n)
        return seen

    def errors(self) -> list[str]:
        sc = self.scene
        self.mats = self.unique("materials", [m.name for m in sc.materials])
        self.nodes = self.unique("nodes", [n.name for n in sc.nodes])
        self.bodies = self.unique("bodies", [b.name for b in sc.bodies])
        self.unique("elements", [e.name for e in sc.elements])
        self.pos = {n.name: np.array(n.position) for n in sc.nodes}
        self.extent = max(float(np.ptp(np.array([n.position for n in sc.nodes]), axis=0).max()), 1e-300)
        self.check_bodies()
        for i, e in enumerate(sc.elements):
            self.check_element(i, e)
        self.check_supports()
        self.check_stroke()
        self.check_loads()
        self.check_joints()
        return self.out

    def check_bodies(self) -> None:
        for i, b in enumerate(self.scene.bodies):
            for n in b.nodes:
                if n not in self.nodes:
                    self.out.append(f"bodies[{i}].nodes: {self.unknown('node', n)}; define it under 'nodes'")
                elif n in self.carrier:
                    self.out.append(
                        f"bodies[{i}].nodes: node '{n}' is already carried by body '{self.carrier[n]}'; "
                        "a node belongs to at most one body"
                    )
                else:
                    self.carrier[n] = b.name

    def check_element(self, i: int, e: Beam | Truss) -> None:
        where = f"elements[{i}]"
        errors = self.out
        for n in e.nodes:
            if n not in self.nodes:
                errors.append(f"{where}.nodes: {self.unknown('node', n)}; define it under 'nodes' or fix the name")
        if e.material not in self.mats:
            errors.append(f"{where}.material: {self.unknown('material', e.material)}; define it under 'materials'")
        if all(n in self.pos for n in e.nodes):
            self.check_geometry(where, e)
        both = set(expand_modes(e.rigid)) & set(expand_modes(e.generalised))
        if both:
            errors.append(
                f"{where}.generalised: deformations {sorted(both)} (0-based) of '{e.name}' are both rigid "
                "and generalised; remove them from one of 'rigid' and 'generalised'"
            )
        if isinstance(e, Beam) and len(set(i for r in e.rigid for i in MODE_NAMES[r])) == 6:
            errors.append(
                f"{where}.rigid: all six deformations of beam '{e.name}' are rigid; "
                "model a rigid connection as a rigid body instead"
            )

    def check_geometry(self, where: str, e: Beam | Truss) -> None:
        p, q = self.pos[e.nodes[0]], self.pos[e.nodes[1]]
        length = float(np.linalg.norm(q - p))
        if e.nodes[0] == e.nodes[1] or length <= 1e-9 * self.extent:
            self.out.append(
                f"{where}.nodes: element '{e.name}' has zero length: nodes '{e.nodes[0]}' and "
                f"'{e.nodes[1]}' coincide; move one node or remove the element"
            )
        elif isinstance(e, Beam):
            ex = (q - p) / length
            y = np.array(e.y_axis, dtype=float)
            ny = float(np.linalg.norm(y))
            if ny == 0 or float(np.linalg.norm(np.cross(ex, y / ny))) < 1e-6:
                self.out.append(
                    f"{where}.y_axis: section orientation {tuple(e.y_axis)} is parallel to the axis "
                    f"of beam '{e.name}'; give a direction across the beam (the width direction)"
                )

    def check_supports(self) -> None:
        for i, s in enumerate(self.scene.supports):
            if s.node is not None:
                if s.node not in self.nodes:
                    self.out.append(f"supports[{i}].node: {self.unknown('node', s.node)}")
                elif s.node in self.carrier:
                    if set(s.dofs) != {"x", "y", "z", "rx", "ry", "rz"}:
                        self.out.append(
                            f"supports[{i}].dofs: node '{s.node}' is carried by body '{self.carrier[s.node]}'; "
                            "support it fully or ground the body"
                        )
                    self.grounded.add(self.carrier[s.node])
                else:
                    self.supported.setdefault(s.node, set()).update(s.dofs)
            if s.body is not None:
                if s.body not in self.bodies:
                    self.out.append(f"supports[{i}].body: {self.unknown('body', s.body)}")
                self.grounded.add(s.body)

    def check_stroke(self) -> None:
        st = self.scene.stroke
        errors = self.out
        if st is None:
            return
        if st.node is not None:
            if st.node not in self.nodes:
                errors.append(f"stroke.node: {self.unknown('node', st.node)}")
            elif st.node in self.carrier:
                errors.append(
                    f"stroke.node: node '{st.node}' is carried by body '{self.carrier[st.node]}'; "
                    f"drive the body instead (stroke.body = '{self.carrier[st.node]}')"
                )
            else:
                fixed = self.supported.get(st.node, set())
                axis = np.array(st.axis) / np.linalg.norm(st.axis)
                names = ("rx", "ry", "rz") if st.kind == "rotation" else ("x", "y", "z")
                blocked = [names[k] for k in range(3) if names[k] in fixed and abs(axis[k]) > 1e-12]
                if blocked:
                    errors.append(
                        f"stroke.node: the stroke drives node '{st.node}' along {blocked}, which a support "
                        "fixes; drive an unsupported node or remove that support"
                    )
        if st.body is not None:
            if st.body not in self.bodies:
                errors.append(f"stroke.body: {self.unknown('body', st.body)}")
            elif st.body in self.grounded:
                errors.append(f"stroke.body: body '{st.body}' is grounded by a support; drive a moving body instead")

    def check_joints(self) -> None:
        names = {e.name for e in self.scene.elements}
        for i, j in enumerate(self.scene.joints):
            for n in j.nodes:
                if n not in self.nodes:
                    self.out.append(f"joints[{i}].nodes: {self.unknown('node', n)}")
            if j.name in names:
                self.out.append(f"joints[{i}].name: '{j.name}' is also an element's name; names must be unique")
            names.add(j.name)
            a, b = (self.carrier.get(n) for n in j.nodes)
            if a is not None and a == b:
                self.out.append(
                    f"joints[{i}].nodes: both nodes of joint '{j.name}' are carried by body '{a}', "
                    "which holds them rigidly; join nodes of different parts"
                )

    def check_loads(self) -> None:
        st = self.scene.stroke
        for i, ld in enumerate(self.scene.loads):
            if ld.node is not None and ld.node not in self.nodes:
                self.out.append(f"loads[{i}].node: {self.unknown('node', ld.node)}")
            if ld.body is not None and ld.body not in self.bodies:
                self.out.append(f"loads[{i}].body: {self.unknown('body', ld.body)}")
            if ld.table is not None and st is not None:
                lo, hi = sorted((0.0, *(float(v) for v in st.values()[[0, -1]])))[::2]
                if ld.table.stroke[0] > lo or ld.table.stroke[-1] < hi:
                    self.out.append(
                        f"loads[{i}].table.stroke: the table covers {ld.table.stroke[0]:g} to "
                        f"{ld.table.stroke[-1]:g} but the analysis visits {lo:g} to {hi:g} (the stroke range "
                        "and 0, where continuation starts); extend the table"
                    )
            if (ld.ramp is not None or ld.table is not None) and st is None:
                self.out.append(f"loads[{i}]: a ramp or table load needs a stroke; give a constant 'force' or 'moment'")


#: the work one scene's "did you mean" suggestions may do, in character pairs compared (difflib's ratio costs
#: about a microsecond per pair of characters, up to ~10 ms for two 100-character names, plus ~0.1 ms a name):
#: about 0.2 s at most, however many unknown names a scene has. Before (issue 29 item 3) every unknown name
#: was compared with every node name on the request thread: a 43 kB scene held the server 18 s.
SUGGEST_BUDGET = 200_000
_PAIR_COST = 100  # the fixed cost of comparing two names, in character pairs


def closest(name: str, choices: list[str] | tuple[str, ...], budget: int = SUGGEST_BUDGET) -> tuple[str | None, int]:
    """The closest of ``choices`` to ``name`` (difflib's ratio at least 0.6), or None, and the work spent.

    Names are compared in order until ``budget`` (character pairs) is spent; only names whose lengths allow
    the cutoff (``2M/(a+b) >= 0.6`` needs the shorter at least 3/7 of the longer) are compared.
    """
    n, spent, best, found = len(name), 0, 0.6, None
    if budget < _PAIR_COST:
        return None, 0
    m = difflib.SequenceMatcher()
    m.set_seq2(name)
    for c in map(str, choices):
        if 3 * max(n, len(c)) > 7 * min(n, len(c)):
            continue
        cost = n * len(c) + _PAIR_COST
        if spent + cost > budget:
            break
        spent += cost
        m.set_seq1(c)
        if m.real_quick_ratio() >= best and m.quick_ratio() >= best and (r := m.ratio()) >= best:
            best, found = r, c
            if r == 1.0:
                break
    return found, spent


def did_you_mean(name: str, choices: list[str] | tuple[str, ...], budget: int = SUGGEST_BUDGET) -> str:
    """``" (did you mean 'x'?)"`` for the closest of ``choices`` to a misspelt ``name`` (:func:`closest`,
    bounded by ``budget``), else ``""``."""
    close, _ = closest(name, choices, budget)
    return f" (did you mean '{close}'?)" if close else ""


def expand_modes(names: tuple[str, ...]) -> tuple[int, ...]:
    """Indices (0-based, eps1 = 0) of the deformation parameters named in ``names``."""
    return tuple(sorted({i for n in names for i in MODE_NAMES[n]}))
