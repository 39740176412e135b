"""Deflected configurations and mode shapes at stroke points: what the structure looks like and how it vibrates.

Numeric only: everything here is read off a converged :class:`~model.statics.Equilibrium` and its
:class:`~model.modal.Modes`, obtained through the public :meth:`model.analysis.MeshAnalysis.frequency_curve`
(its ``visit`` hook sees every converged stroke point with its tracked modes and labels), so a shape is
always the one behind the frequencies of the curve at the same stroke.

Conventions
-----------
- Node ``n`` carried by master ``m`` (a body or the node itself) with current offset ``r = R_m r_0``:
  position ``x_n = X_m + r``, orientation ``R_n = R_m`` (nodes are oriented as the global frame in the
  reference), incremental translation ``u_n = u_m + psi_m x r`` and rotation ``psi_n = psi_m`` (the
  spatial rotation vector of the exponential chart, model.assembly).
- Mode shapes are mass normalised over the model's DOFs: ``phi^T M phi = 1`` with the mass matrix ``M`` at
  the deflected state in SI units (kg for translations, kg m^2 for rotations), so a nodal translation is in
  m and a rotation in rad per unit modal coordinate (kg^1/2 m). Their sign is arbitrary (an eigenvector).
- Modes appear in the curve's branch order (the frequency order at stroke 0, followed by mass-weighted MAC
  tracking), so mode ``i`` here is column ``i`` of ``FrequencyCurve.modes_hz``.
- Orientations on the wire are rotation vectors (axis times angle, rad) of the rotation from the reference.
- Bodies carry no geometry in a scene: each is drawn as the box bounding its nodes and centre of mass (at
  least ``BODY_MIN_SIZE`` times the structure's length scale thick), a drawing aid only.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from .analysis import MeshAnalysis, von_mises
from .errors import FlexoptError
from .modal import Modes
from .results import ResultWarning
from .rotations import log_so3
from .scene import Beam, RectangularSection
from .statics import Equilibrium

__all__ = ["ModeShape", "Configuration", "Shapes", "shapes_at", "shapes_along", "BODY_MIN_SIZE"]

#: Smallest drawn box edge of a body, relative to the structure's length scale.
BODY_MIN_SIZE = 0.06

STRESS_CONVENTION = (
    "largest von Mises stress of each member at this stroke [Pa] (ends of every beam segment, "
    "the bound of model.elements.beam_von_mises); utilisation = stress / allowable"
)


@dataclass(frozen=True)
class ModeShape:
    """One natural mode at a stroke point (nn nodes)."""

    hz: float  # natural frequency [Hz]
    label: str  # "parasitic" | "intended" | "drive"
    translation: np.ndarray  # (nn, 3) nodal translation per unit modal coordinate [m]
    rotation: np.ndarray  # (nn, 3) nodal rotation vector per unit modal coordinate [rad]


@dataclass(frozen=True)
class Configuration:
    """The deflected structure at one stroke point (nn nodes, nbd bodies)."""

    stroke: float  # stroke unit
    positions: np.ndarray  # (nn, 3) node positions [m]
    orientations: np.ndarray  # (nn, 3, 3) node rotation matrices (from the reference, global axes)
    body_positions: np.ndarray  # (nbd, 3) centres of mass [m]
    body_orientations: np.ndarray  # (nbd, 3, 3)
    drive_reaction: float  # actuator moment [N m] or force [N] along the drive axis
    von_mises: np.ndarray  # (n_members,) largest von Mises stress [Pa]


@dataclass(frozen=True)
class Shapes:
    """Deflected configuration and mode shapes of a scene at one stroke point, with the geometry needed to
    draw it (member chains and widths, body boxes)."""

    scene: str
    stroke_unit: str
    stroke_kind: str
    node_names: tuple[str, ...]  # (nn,) scene nodes and segment-internal nodes ("member#i")
    members: dict[str, dict]  # name -> {"kind", "nodes" (chain), "width", "thickness", "y_axis" (unit width
    #                           direction across the member in the reference; it turns with the nodes)}
    bodies: dict[str, dict]  # name -> {"nodes", "size" (3,), "center_offset" (3,)} in the reference
    allowable_stress: dict[str, float]  # member -> [Pa]
    configuration: Configuration
    modes: tuple[ModeShape, ...]
    warnings: tuple[ResultWarning, ...] = ()
    conventions: dict[str, str] = field(default_factory=dict)
    provenance: dict = field(default_factory=dict)  # flexopt version, scene hash, method, solver settings

    @property
    def stroke(self) -> float:
        """The stroke value (stroke unit)."""
        return self.configuration.stroke

    def to_dict(self) -> dict:
        """A JSON-ready dict: ``stroke``, ``nodes`` (name -> position [m]), ``modes`` (list of ``hz``,
        ``label``, ``translation`` and ``rotation``: node -> [3]) and the drawing data."""
        out = configuration_dict(
            self.node_names, list(self.bodies), self.members, self.allowable_stress, self.configuration
        )
        names = self.node_names
        out = {
            "scene": self.scene,
            "stroke_unit": self.stroke_unit,
            "stroke_kind": self.stroke_kind,
            **out,
            "members": {k: dict(v) for k, v in self.members.items()},
            "bodies": {k: {**v, **out["bodies"][k]} for k, v in self.bodies.items()},
            "modes": [
                {
                    "hz": _f(m.hz),
                    "label": m.label,
                    "translation": {n: _vec(v) for n, v in zip(names, m.translation)},
                    "rotation": {n: _vec(v) for n, v in zip(names, m.rotation)},
                }
                for m in self.modes
            ],
            "warnings": [w.to_dict() for w in self.warnings],
            "conventions": dict(self.conventions),
            "provenance": dict(self.provenance),
        }
        return out


def _f(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None


def _vec(v: np.ndarray) -> list[float]:
    return [float(x) for x in v]


def configuration_dict(
    node_names: Sequence[str],
    body_names: Sequence[str],
    members: dict[str, dict],
    allowable: dict[str, float],
    c: Configuration,
) -> dict:
    """The wire form of one deflected configuration (also one entry of a curve's ``shapes``)."""
    util = {}
    for i, name in enumerate(members):
        vm = float(c.von_mises[i])
        a = allowable.get(name)
        util[name] = {"von_mises": _f(vm), "allowable": a, "utilisation": _f(vm / a) if a else None}
    return {
        "stroke": float(c.stroke),
        "nodes": {n: _vec(p) for n, p in zip(node_names, c.positions)},
        "orientations": {n: _vec(v) for n, v in zip(node_names, log_so3(c.orientations))},
        "bodies": {
            b: {"position": _vec(c.body_positions[i]), "orientation": _vec(log_so3(c.body_orientations[i]))}
            for i, b in enumerate(body_names)
        },
        "drive_reaction": _f(c.drive_reaction),
        "stress": util,
    }


def _geometry(an: MeshAnalysis) -> tuple[dict[str, dict], dict[str, dict]]:
    """Member chains (scene and segment-internal nodes, in order) with section sizes, and body boxes."""
    s = an.structure
    scene = s.scene
    members: dict[str, dict] = {}
    pos = {n.name: np.array(n.position, dtype=float) for n in scene.nodes}
    for el in scene.elements:
        p, q = el.nodes
        n = el.segments
        assert isinstance(n, int)  # a MeshAnalysis refuses segments "auto" (model.curve resolves them)
        chain = [p, *(f"{el.name}#{i}" for i in range(1, n)), q]
        width = thickness = None
        y_axis = None
        if isinstance(el, Beam):  # the width direction: y_axis's part across the beam, reference
            t = (pos[q] - pos[p]) / np.linalg.norm(pos[q] - pos[p])
            y = np.array(el.y_axis, dtype=float)
            y = y - (y @ t) * t
            y_axis = _vec(y / np.linalg.norm(y))
            if isinstance(el.section, RectangularSection):
                width, thickness = float(el.section.width), float(el.section.thickness)
        members[el.name] = {"kind": el.kind, "nodes": chain, "width": width, "thickness": thickness, "y_axis": y_axis}
    bodies: dict[str, dict] = {}
    for b in scene.bodies:
        com = np.array(b.center_of_mass, dtype=float)
        pts = np.array([pos[n] for n in b.nodes] + [com])
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        size = np.maximum(hi - lo, BODY_MIN_SIZE * s.length_scale)
        centre = (lo + hi) / 2
        bodies[b.name] = {"nodes": list(b.nodes), "size": _vec(size), "center_offset": _vec(centre - com)}
    return members, bodies


def _configuration(an: MeshAnalysis, eq: Equilibrium, stroke: float) -> Configuration:
    s, sys = an.structure, an.system
    x, R, _ = sys.node_states(eq.state)
    nbd = len(s.scene.bodies)  # bodies are the first masters (model.structure)
    return Configuration(
        stroke=stroke,
        positions=x,
        orientations=R,
        body_positions=eq.state.X[:nbd].copy(),
        body_orientations=eq.state.R[:nbd].copy(),
        drive_reaction=eq.drive_reaction,
        von_mises=von_mises(s, sys, eq),
    )


def _mode_shapes(an: MeshAnalysis, eq: Equilibrium, modes: Modes, labels: list[str], k: int) -> tuple[ModeShape, ...]:
    s, sys = an.structure, an.system
    _, _, r = sys.node_states(eq.state)
    m = s.node_master
    out = []
    hz = modes.hz
    for j in range(min(k, modes.phi.shape[1])):
        v = sys.to_global(modes.phi[:, j]).reshape(-1, 6)  # (nm, 6) master (u, psi), global axes
        u, psi = v[m, :3], v[m, 3:]
        out.append(
            ModeShape(hz=float(hz[j]), label=str(labels[j]), translation=u + np.cross(psi, r), rotation=psi.copy())
        )
    return tuple(out)


def shapes_along(an: MeshAnalysis, stroke: Sequence[float], modes: bool = True, strict: bool = True) -> list[Shapes]:
    """Deflected configurations (and, with ``modes``, mode shapes) at the stroke values ``stroke``
    (stroke unit), in ascending stroke order, computed by the exact continuation of
    :meth:`~model.analysis.MeshAnalysis.frequency_curve`. With ``strict=False`` the stroke values past a loss
    of equilibrium are left out instead.

    The modes are the curve's modes at that stroke, in its branch order and with its labels: the
    continuation passes through the scene's stroke grid (the curve's points) between 0 and each requested
    value, tracking the modes from point to point as the curve does. (Tracked in one jump from stroke 0,
    the branches that come down from above the reported ones were taken for others: the cartwheel's
    sixth mode at 45 deg, 352 Hz, was shown as a 2,116 Hz mode.)

    Raises
    ------
    FlexoptError
        When a requested stroke value lies beyond the loss of a stable equilibrium.
    """
    s = an.structure
    spec = an.stroke
    values = np.unique(np.asarray(stroke, dtype=float).ravel())  # sorted: the continuation walks outwards
    if not np.all(np.isfinite(values)):
        raise FlexoptError("stroke values must be finite numbers")
    n_rep = s.scene.modes
    to_unit = (lambda v: float(np.degrees(v))) if spec.resolved_unit == "deg" else float
    found: dict[float, tuple[Configuration, tuple[ModeShape, ...]]] = {}

    requested = {float(spec.to_internal(v)): float(v) for v in values}  # report the values as given

    def visit(eq: Equilibrium, md: Modes, labels: list[str]) -> None:
        if eq.stroke not in requested:  # a point of the curve's grid passed on the way
            return
        st = requested.get(eq.stroke, to_unit(eq.stroke))
        c = _configuration(an, eq, st)
        found[eq.stroke] = (c, _mode_shapes(an, eq, md, labels, n_rep) if modes else ())

    grid = np.asarray(spec.values(), dtype=float)  # the curve's points passed on the way (tracking)
    grid = grid[((grid > 0) & (grid < values.max())) | ((grid < 0) & (grid > values.min()))]
    curve = an.frequency_curve(np.union1d(values, grid), visit=visit)
    missing = [v for v in values if float(spec.to_internal(v)) not in found]
    if missing and strict:
        why = "; ".join(f.message for f in curve.failures) or "no equilibrium found"
        raise FlexoptError(
            f"no stable equilibrium at stroke {missing[0]:.6g} {spec.resolved_unit}: {why}; "
            "choose a stroke inside the curve's range"
        )
    members, bodies = _geometry(an)
    mats = {mt.name: mt for mt in s.scene.materials}
    allow = {e.name: float(mats[e.material].allowable_stress) for e in s.scene.elements}
    conventions = {
        "positions": "node positions and body centres of mass at the deflected equilibrium [m], global axes",
        "orientations": "rotation vectors (axis times angle) [rad] from the reference orientation",
        "modes": "mass normalised over the model's DOFs, phi^T M phi = 1 with M in kg and kg m^2 at the "
        "deflected state; translation in m, rotation (spatial rotation vector) in rad per unit modal "
        "coordinate; sign arbitrary; branch order of the frequency curve",
        "bodies": "drawn as the box bounding the body's nodes and centre of mass (a drawing aid)",
        "stress": STRESS_CONVENTION,
        **{k: v for k, v in curve.conventions.items() if k in ("drive", "drive_in_eigen_analysis", "parasitic")},
    }

    # every check comes with the curve (model.checks, one stress check for curves and shapes alike): each
    # point keeps the scene-wide warnings and the stress ranges it lies in
    def applies(w: ResultWarning, stroke: float) -> bool:
        return w.stroke_range is None or min(w.stroke_range) <= stroke <= max(w.stroke_range)

    out = []
    for key in sorted(found):
        c, ms = found[key]
        out.append(
            Shapes(
                scene=s.scene.name,
                stroke_unit=spec.resolved_unit,
                stroke_kind=spec.kind,
                node_names=s.node_names,
                members=members,
                bodies=bodies,
                allowable_stress=allow,
                configuration=c,
                modes=ms,
                warnings=tuple(w for w in curve.warnings if applies(w, c.stroke)),
                conventions=conventions,
                provenance=dict(curve.provenance),
            )
        )
    return out


def shapes_at(an: MeshAnalysis, stroke: float = 0.0) -> Shapes:
    """Deflected configuration and mode shapes at one stroke value (stroke unit); see :func:`shapes_along`."""
    return shapes_along(an, [stroke])[0]
