"""Exact-constraint diagnosis: D_cc, its SVD and the Table-1 classification (seed 002, section 3).

Partitioning (seed 002, eq. 4)
------------------------------
Nodal coordinates ``x``: the six increments ``(u, psi)`` of every master (rigid body or free node, see
model.structure), in global axes. ``x(o)`` are the supported coordinates (and the rotations of masters that
only trusses join, which nothing can measure), ``x(m)`` the stroke coordinate (the drive-basis direction of
the driven master; none for a scene with ``stroke: null``) and ``x(c)`` all the others. Rigid bodies carry
their nodes exactly, so unlike SPACAR (section 4.2, last paragraph) they need no constraint deformations:
both the extra nodal coordinates and the extra rows are absent, which leaves ``D_cc`` square if it was.

Deformations ``e``: ``e(o)`` the rigid ones, ``e(m)`` the generalised ones (``Beam.generalised``), ``e(c)``
the rest. In a *kinematic* diagnosis (``Scene.kinematic`` or ``model.diagnosis.diagnose(kinematic=True)``) the rigid set
of each element is its ``kinematic_rigid`` field, or else derived from its section: a sheet keeps its
elongation and in-plane bending rigid, a wire its elongation, a truss is a rigid bar (section 4.2).

Jacobian and scaling
--------------------
``D_cc`` (eq. 9) holds the rows ``[e(o); e(m)]`` and the columns ``x(c)`` of ``D_x D``, the exact
derivative of the deformations from the CasADi element kernels (model.elements), at the reference or at an
equilibrium on the stroke. Rotations are spatial rotation increments, so a rotation column is the
deformation rate per unit angular velocity (SPACAR's velocity form).

All deformations have the dimension of length (eps_2..eps_6 are l0 times an angle). A translation column
is therefore dimensionless and a rotation column has the dimension of length. To make the singular values
comparable and unit-free we factor ``D_cc = L_c D^ C^-1`` with the characteristic length ``L_c`` (the
largest distance between two nodes: invariant under rigid motion, proportional to the length unit) and
``C = diag(L_c for translations, 1 for rotations)``; the SVD (eq. 11) is taken of
``D^ = D_cc C / L_c``. Its singular values are dimensionless, do not change under a change of units or a
rigid motion, and its null vectors map back exactly (``x_dot = C v``, ``sigma = u``).

Rank tolerance: ``sigma_i > RANK_RTOL sigma_max`` with ``RANK_RTOL = 1e-8``. At the reference the
Jacobian is exact to round-off (about 1e-15 relative), and at a stroke point the equilibrium satisfies the
rigid deformations to the Newton tolerance (1e-10 scaled), which perturbs an exact zero by about that
much; 1e-8 leaves two orders of margin on either side. A design with ``sigma_min / sigma_max <
NEAR_RTOL = 1e-4`` is reported as *almost singular*: a geometric imperfection of that relative size could
make it over- or underconstrained, and its constraint forces grow as 1/sigma_min.

Modes: the columns of V beyond the rank (zero singular values and excess columns, section 3.1) and of U
beyond the rank (section 3.2), each a unit vector with its largest entry made positive. With more than
one mode of a kind, the modes span the right space but the basis is LAPACK's (any rotation of it is as
valid), so compare spaces, not individual vectors, between designs.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .elements import beam_spec, joint_spec, truss_spec
from .errors import SceneError
from .kernels import compiled
from .results import ResultWarning
from .scene import Beam, GeneralSection, RectangularSection, Truss, expand_modes
from .structure import Structure

__all__ = [
    "ConstraintDiagnosis",
    "kinematic_rigid_set",
    "partition",
    "split_label",
    "columns",
    "jacobian_rows",
    "sign_fix",
    "deformation_label",
    "RANK_RTOL",
    "NEAR_RTOL",
    "numerical_rank",
    "DEFORMATION_NAMES",
]

RANK_RTOL = 1e-8
NEAR_RTOL = 1e-4
_AXES = ("x", "y", "z", "rx", "ry", "rz")


def numerical_rank(sv: np.ndarray) -> int:
    """The rank the singular values ``sv`` (largest first) give: how many exceed ``RANK_RTOL`` times the
    largest (0 for none, or for a zero matrix)."""
    return int(np.sum(sv > RANK_RTOL * sv[0])) if sv.size and sv[0] > 0 else 0


def kinematic_rigid_set(element: Beam | Truss) -> tuple[str, ...]:
    """The deformations an element keeps rigid in a kinematic analysis (seed 002, section 4.2).

    ``kinematic_rigid`` when given; otherwise a truss is a rigid bar, a sheet (rectangle with width at
    least twice the thickness, or a general section with one second moment at least four times the other)
    keeps its elongation and its in-plane (stiff) bending rigid, and any other beam is a wire: only its
    elongation is rigid.
    """
    if element.kinematic_rigid is not None:
        return tuple(element.kinematic_rigid)
    if isinstance(element, Truss):
        return ("elongation",)
    sec = element.section
    if isinstance(sec, RectangularSection):
        iy, iz = sec.width * sec.thickness**3, sec.thickness * sec.width**3  # proportional to Iy, Iz
    else:
        assert isinstance(sec, GeneralSection)
        iy, iz = sec.Iy, sec.Iz
    if iz >= 4.0 * iy:
        return ("elongation", "bending_z")  # stiff bending about local z: in-plane deflection along y
    if iy >= 4.0 * iz:
        return ("elongation", "bending_y")
    return ("elongation",)


@dataclass(frozen=True)
class ConstraintDiagnosis:
    """D_cc of a scene, its SVD and the indeterminate modes (seed 002, eqs. 9, 11, 15 and Table 1).

    Shapes: m rows ``[e(o); e(m)]``, n columns ``x(c)``.
    """

    scene: str
    stroke: float | None  # stroke value (stroke unit) of the configuration, None = reference
    kinematic: bool
    rows: tuple[str, ...]  # (m,) "element.eps_k" (element "member[i]" for meshed segments)
    row_kind: tuple[str, ...]  # (m,) "rigid" | "generalised"
    columns: tuple[str, ...]  # (n,) "master.x" ... "master.rz" (or a drive-basis direction)
    column_master: tuple[str, ...]  # (n,) master (node or body) of each column
    column_direction: np.ndarray  # (n, 6) unit direction of each column in its master's (u, psi) block
    D_cc: np.ndarray  # (m, n) eq. 9, physical units (translations in length units, rotations in rad)
    D_scaled: np.ndarray  # (m, n) D^ = D_cc C / L_c, dimensionless
    characteristic_length: float  # L_c
    singular_values: np.ndarray  # (min(m, n),) of D^, descending
    U: np.ndarray  # (m, m)
    V: np.ndarray  # (n, n)
    rank: int
    n_generalised_coordinates: int  # x(m): 1 with a stroke, 0 without
    n_rigid: int  # rows of e(o)
    notes: tuple[str, ...] = field(default=())  # what the diagnosis chose for the user (idealisation, condensing)
    kinematic_modes: tuple[dict[str, dict[str, list[float]]], ...] = field(default=())
    static_modes: tuple[dict[str, dict[str, float]], ...] = field(default=())
    release_candidates: tuple[tuple[str, ...], ...] = field(default=())
    warnings: tuple[ResultWarning, ...] = field(default=())  # scene checks (model.checks): validity, units
    provenance: dict[str, Any] = field(default_factory=dict)  # flexopt version, scene hash, method, settings
    #: SPACAR's own count and D_cc (model.spacar_dcc.SpacarDcc.to_dict), or {"available": False, "why": ...}
    spacar: dict[str, Any] | None = None

    @property
    def spacar_dof(self) -> int | None:
        """SPACAR's degrees of freedom (inputs and dynamic deformations; model.spacar_dcc), None if not computed."""
        return self.spacar.get("dof") if self.spacar else None

    @property
    def spacar_condition_number(self) -> float | None:
        """Condition number of D_cc by SPACAR's definition (model.spacar_dcc; None: not computed, or D_cc
        rank deficient: then ``spacar['verdict']`` says how)."""
        return self.spacar.get("condition_number") if self.spacar else None

    @property
    def m(self) -> int:
        """Number of rows of D_cc (rigid plus generalised deformations)."""
        return len(self.rows)

    @property
    def n(self) -> int:
        """Number of columns of D_cc (dependent nodal coordinates)."""
        return len(self.columns)

    @property
    def n_dof(self) -> int:
        """Nominal degrees of freedom (section 3.1): coordinates minus x(o) minus e(o)."""
        return self.n + self.n_generalised_coordinates - self.n_rigid

    @property
    def statically_indeterminate(self) -> int:
        """Number of self-stress states (m - rank; Table 1)."""
        return self.m - self.rank

    @property
    def kinematically_indeterminate(self) -> int:
        """Number of free motions with e(o), e(m), x(m) held (n - rank; Table 1)."""
        return self.n - self.rank

    @property
    def exact_constraint(self) -> bool:
        """Both statically and kinematically determinate: m = n = rank (section 4)."""
        return self.statically_indeterminate == 0 and self.kinematically_indeterminate == 0

    @property
    def smallest_nonzero_singular_value(self) -> float:
        """The smallest singular value above the rank tolerance (nan if the rank is 0)."""
        return float(self.singular_values[self.rank - 1]) if self.rank else float("nan")

    @property
    def condition_number(self) -> float:
        """sigma_max / smallest non-zero sigma of the scaled D_cc."""
        return float(self.singular_values[0] / self.smallest_nonzero_singular_value) if self.rank else float("inf")

    @property
    def almost_singular(self) -> bool:
        """True when the smallest non-zero singular value is below NEAR_RTOL sigma_max."""
        return bool(self.rank and self.smallest_nonzero_singular_value < NEAR_RTOL * self.singular_values[0])

    @property
    def classification(self) -> str:
        """The Table-1 verdict in words."""
        st = "statically indeterminate" if self.statically_indeterminate else "statically determinate"
        kin = "kinematically indeterminate" if self.kinematically_indeterminate else "kinematically determinate"
        shape = "m = n" if self.m == self.n else ("m > n" if self.m > self.n else "m < n")
        return f"{shape}, rank {self.rank}: {st}, {kin}" + (" (exact constraint)" if self.exact_constraint else "")

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready form (plain lists and numbers)."""
        sv = [float(v) for v in self.singular_values]
        return {
            "scene": self.scene,
            "stroke": self.stroke,
            "kinematic": self.kinematic,
            "rows": list(self.rows),
            "row_kind": list(self.row_kind),
            "columns": list(self.columns),
            "m": self.m,
            "n": self.n,
            "rank": self.rank,
            "n_dof": self.n_dof,
            "singular_values": sv,
            "characteristic_length": self.characteristic_length,
            "rank_tolerance": RANK_RTOL * (sv[0] if sv else 0.0),
            "smallest_nonzero_singular_value": self.smallest_nonzero_singular_value if self.rank else None,
            "condition_number": self.condition_number if self.rank else None,
            "almost_singular": self.almost_singular,
            "statically_indeterminate": self.statically_indeterminate,
            "kinematically_indeterminate": self.kinematically_indeterminate,
            "exact_constraint": self.exact_constraint,
            "classification": self.classification,
            "notes": list(self.notes),
            "kinematic_modes": [dict(k) for k in self.kinematic_modes],
            "static_modes": [dict(s) for s in self.static_modes],
            "release_candidates": [list(r) for r in self.release_candidates],
            "warnings": [w.to_dict() for w in self.warnings],
            "provenance": dict(self.provenance),
            "spacar_dof": self.spacar_dof,
            "spacar_condition_number": self.spacar_condition_number,
            "spacar": dict(self.spacar) if self.spacar else None,
            "conventions": {
                "scaling": "SVD of D_cc C / L_c with C = diag(L_c translations, 1 rotations): singular values "
                "dimensionless; kinematic modes are unit vectors of that scaled problem (translations in L_c "
                "per unit time, rotations in rad per unit time), static modes unit vectors of generalised "
                "stresses; sign: largest entry positive",
                "rank_rtol": RANK_RTOL,
                "almost_singular_rtol": NEAR_RTOL,
            },
        }

    def report(self) -> str:
        """A readable report: counts, Table-1 verdict, free motions, self-stresses and what to release."""
        lines = [
            f"scene '{self.scene}'"
            + (f" at stroke {self.stroke:g}" if self.stroke is not None else " at the reference")
            + (" (kinematic idealisation)" if self.kinematic else ""),
            f"D_cc: m = {self.m} rows (e(o) {self.n_rigid}, e(m) {self.m - self.n_rigid}), n = {self.n} columns "
            f"x(c), rank {self.rank}; nominal degrees of freedom n_dof = {self.n_dof}",
            f"Table 1: {self.classification}",
        ]
        lines += [f"note: {n}" for n in self.notes]
        if self.rank:
            lines.append(
                f"smallest non-zero singular value {self.smallest_nonzero_singular_value:.4g}, "
                f"condition number {self.condition_number:.4g} (L_c = {self.characteristic_length:.4g})"
            )
            if self.almost_singular:
                lines.append(
                    "warning: almost singular: a small imperfection could make the design over- or "
                    "underconstrained; constraint forces grow as 1/sigma_min"
                )
        for i, mode in enumerate(self.kinematic_modes):
            lines.append(f"kinematic mode {i + 1} (free motion):")
            for name, vel in mode.items():
                lines.append(f"  {name}: translation {_fmt(vel['translation'])}, rotation {_fmt(vel['rotation'])}")
        for i, (mode, rel) in enumerate(zip(self.static_modes, self.release_candidates)):
            lines.append(f"static mode {i + 1} (self-stress, deformations that fight each other):")
            for name, comps in mode.items():
                lines.append("  " + name + ": " + ", ".join(f"{k} {v:+.4f}" for k, v in comps.items()))
            lines.append("  release one of these to remove it: " + ", ".join(rel))
        lines += [f"warning [{w.kind}]: {w.message}" for w in self.warnings]
        sp = self.spacar
        if sp and sp.get("available", True):
            cond = sp["condition_number"]
            lines.append(
                f"SPACAR's count (its variables, SI, at the reference): degrees of freedom {sp['dof']}, D_cc "
                f"{sp['m']} x {sp['n']} of rank {sp['rank']} ({sp.get('released', 0)} deformations released, RLSE), "
                "condition number " + (f"{cond:.6g}" if cond is not None else "infinite") + f": {sp['verdict']}"
            )
            lines += [f"  SPACAR note: {n}" for n in sp.get("notes", [])]
        elif sp:
            lines.append(f"SPACAR's count not available: {sp['why']}")
        return "\n".join(lines)


#: Names of the six deformations as scenes write them (model.scene.MODE_NAMES): eps3/eps5 belong to the
#: element's first end p, eps4/eps6 to its second end q (seed 002, eq. 2).
DEFORMATION_NAMES = ("elongation", "torsion", "bending_y", "bending_y", "bending_z", "bending_z")


#: Names of a joint's six coordinates (model.elements.joint_spec): relative translation along and rotation
#: about the joint basis a (the axis), b1, b2.
JOINT_COORDINATES = ("along_axis", "along_b1", "along_b2", "about_axis", "about_b1", "about_b2")


def deformation_label(k: int, p: str, q: str) -> str:
    """Readable name of deformation ``k`` (0-based) of an element from node ``p`` to ``q``: ``elongation``,
    ``torsion``, or ``bending_y@p`` / ``bending_z@q`` (the bending deformations are the end rotations
    relative to the chord at that end node)."""
    name = DEFORMATION_NAMES[k]
    return name if k < 2 else f"{name}@{p if k in (2, 4) else q}"


def _fmt(v: list[float]) -> str:
    return "(" + ", ".join(f"{x:+.4f}" for x in v) + ")"


def sign_fix(v: np.ndarray) -> np.ndarray:
    """Deterministic sign: the first entry within 1e-9 of the largest magnitude is made positive."""
    a = np.abs(v)
    if not a.size or a.max() == 0:
        return v
    k = int(np.flatnonzero(a >= a.max() * (1 - 1e-9))[0])
    return v if v[k] > 0 else -v


def partition(s: Structure, kinematic: bool) -> tuple[list[tuple[int, int, int]], list[str], list[str], int]:
    """Rows [e(o); e(m)] as (kind 0 beam / 1 truss / 2 joint, element, deformation), their labels and kinds;
    a joint's constrained coordinates are rigid rows in either partition (kinematic pairs)."""
    scene = s.scene
    rigid_rows: list[tuple[int, int, int]] = []
    gen_rows: list[tuple[int, int, int]] = []
    for kind, member_of in ((0, s.beam_member), (1, s.truss_member)):
        for i, ie in enumerate(member_of):
            el = scene.elements[int(ie)]
            rig = set(expand_modes(kinematic_rigid_set(el) if kinematic else el.rigid))
            gen = set(expand_modes(el.generalised))
            both = rig & gen
            if both:
                raise SceneError(
                    f"elements[{ie}].generalised",
                    f"deformations {sorted(f'eps{k + 1}' for k in both)} of '{el.name}' are rigid in the "
                    f"{'kinematic' if kinematic else 'declared'} partition and also generalised; set "
                    "'kinematic_rigid' (or 'rigid') so they are not rigid, or drop them from 'generalised'",
                )
            rigid_rows += [(kind, i, k) for k in sorted(rig)]
            gen_rows += [(kind, i, k) for k in sorted(gen)]
    # ideal joints: kinematic pairs, rigid in both partitions (their five constrained coordinates)
    rigid_rows += [(2, int(i), int(k)) for kind_, i, k in s.constraints if kind_ == 2]
    labels: list[str] = []
    index: dict[tuple[int, int], str] = {}
    ends: dict[tuple[int, int], tuple[str, str]] = {}
    for kind, member_of in ((0, s.beam_member), (1, s.truss_member)):
        per: dict[int, int] = {}
        tot = np.bincount(member_of, minlength=len(scene.elements)) if len(member_of) else []
        for i, ie in enumerate(member_of):
            j = per.get(int(ie), 0)
            per[int(ie)] = j + 1
            name = scene.elements[int(ie)].name
            index[(kind, i)] = name if tot[int(ie)] == 1 else f"{name}[{j}]"
            nodes = s.beam_nodes[i] if kind == 0 else s.truss_nodes[i]
            ends[(kind, i)] = (s.node_names[nodes[0]], s.node_names[nodes[1]])
    for kind, i, k in rigid_rows + gen_rows:
        if kind == 2:
            labels.append(f"{s.joint_names[i]}.{JOINT_COORDINATES[k]}")
            continue
        labels.append(f"{index[(kind, i)]}.{deformation_label(k, *ends[(kind, i)])}")
    kinds = ["rigid"] * len(rigid_rows) + ["generalised"] * len(gen_rows)
    return rigid_rows + gen_rows, labels, kinds, len(rigid_rows)


def split_label(s: Structure, row: tuple[int, int, int], label: str) -> tuple[str, str]:
    """(element label, deformation name) of a row label built by :func:`partition`."""
    kind, i, k = row
    if kind == 2:
        return s.joint_names[i], JOINT_COORDINATES[k]
    nodes = s.beam_nodes[i] if kind == 0 else s.truss_nodes[i]
    d = deformation_label(k, s.node_names[nodes[0]], s.node_names[nodes[1]])
    return label[: -len(d) - 1], d


def columns(s: Structure) -> tuple[np.ndarray, list[str], list[str], np.ndarray]:
    """Columns x(c): (6 nm, n) map T from column velocities to all masters' (u, psi), labels, masters,
    and a flag per column (True = translation)."""
    nm = len(s.master_names)
    cols: list[np.ndarray] = []
    labels: list[str] = []
    masters: list[str] = []
    trans: list[bool] = []
    drive_blk = s.drive_dof if s.drive_kind != "none" else -10
    for mi in range(nm):
        for b in (0, 3):
            start = 6 * mi + b
            for k in range(3):
                dof = start + k
                if not s.active[dof]:
                    continue
                t = np.zeros(6 * nm)
                if start == drive_blk:
                    if k == 0:
                        continue  # x(m): the stroke coordinate
                    d = s.drive_basis[:, k]
                    t[start : start + 3] = d
                    ax = [j for j in range(3) if abs(abs(d[j]) - 1.0) < 1e-14]
                    lab = (
                        ("-" if ax and d[ax[0]] < 0 else "") + _AXES[b + ax[0]]
                        if ax
                        else ("u" if b == 0 else "r") + "(" + ",".join(f"{c:.3g}" for c in d) + ")"
                    )
                else:
                    t[dof] = 1.0
                    lab = _AXES[b + k]
                cols.append(t)
                labels.append(f"{s.master_names[mi]}.{lab}")
                masters.append(s.master_names[mi])
                trans.append(b == 0)
    T = np.array(cols).T if cols else np.zeros((6 * nm, 0))
    return T, labels, masters, np.array(trans, dtype=bool)


def jacobian_rows(s: Structure, X: np.ndarray, R: np.ndarray, rows: list[tuple[int, int, int]]) -> np.ndarray:
    """Rows of D_x D (all masters' (u, psi), global axes) for the chosen deformations, from the kernels."""
    nm = len(s.master_names)
    m = s.node_master
    r = np.einsum("nij,nj->ni", R[m], s.node_offset)
    xn, Rn = X[m] + r, R[m]
    D = np.zeros((len(rows), 6 * nm))
    blocks = np.arange(6)
    De_b = De_t = None
    if s.n_beams:
        p, q = s.beam_nodes[:, 0], s.beam_nodes[:, 1]
        a = np.hstack(
            [
                xn[p],
                Rn[p].transpose(0, 2, 1).reshape(-1, 9),
                r[p],
                xn[q],
                Rn[q].transpose(0, 2, 1).reshape(-1, 9),
                r[q],
                s.beam_const,
                np.zeros((s.n_beams, 6)),
            ]
        )
        out = np.asarray(compiled(beam_spec()[0])(a))
        De_b = out[:, 162:234].reshape(-1, 12, 6)  # [elem, col, row] (column-major 6 x 12)
    if len(s.truss_nodes):
        p, q = s.truss_nodes[:, 0], s.truss_nodes[:, 1]
        a = np.hstack([xn[p], r[p], xn[q], r[q], s.truss_const, np.zeros((len(p), 1))])
        out = np.asarray(compiled(truss_spec()[0])(a))
        De_t = out[:, 157:169]
    De_j = None
    if len(s.joint_nodes):
        p, q = s.joint_nodes[:, 0], s.joint_nodes[:, 1]
        a = np.hstack(
            [
                xn[p],
                Rn[p].transpose(0, 2, 1).reshape(-1, 9),
                r[p],
                xn[q],
                Rn[q].transpose(0, 2, 1).reshape(-1, 9),
                r[q],
                s.joint_const,
                np.zeros((len(p), 6)),
            ]
        )
        De_j = np.asarray(compiled(joint_spec()[0])(a))[:, 162:234].reshape(-1, 12, 6)
    # every row's 12 entries scattered in one np.add.at per kind (a row whose two nodes share a master adds twice
    # into its columns, in the same order as one call per row: the same sums)
    if not rows:
        return D
    rk = np.array(rows, dtype=np.int64).reshape(-1, 3)
    for kind, nodes_of in enumerate((s.beam_nodes, s.truss_nodes, s.joint_nodes)):
        sel = np.flatnonzero(rk[:, 0] == kind)
        if not len(sel):
            continue
        el, k = rk[sel, 1], rk[sel, 2]
        dofs = (6 * m[nodes_of[el]][:, :, None] + blocks).reshape(len(sel), 12)
        vals = De_b[el, :, k] if kind == 0 else (De_t[el] if kind == 1 else De_j[el, :, k])  # type: ignore[index]
        np.add.at(D, (np.repeat(sel, 12).reshape(-1, 12), dofs), vals)
    return D
