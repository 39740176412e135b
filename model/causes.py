"""The right cause: checks run before continuation, and the named reasons behind a loss of stability.

A frequency curve that stops at stroke 0 or at a tiny stroke usually has a cause the solver cannot see
from its own numbers: a part that nothing holds, a mechanism, a mass too small for double precision, or a
flexure that the drive bends about its stiff axis. Each is detected here from the structure itself, so the
error names the part and the fix instead of reporting "buckling".

- :func:`check_mass`: segment masses and rotary inertias that underflow (``rho A l0`` below
  :data:`MASS_FLOOR`, or stiffness-to-mass ratios ``E / (rho l0^2)`` beyond :data:`OMEGA2_CEILING` so that
  ``omega^2`` overflows): raises :class:`MassUnderflowError`.
- :func:`free_motions`: the exact-constraint machinery of :mod:`model.constraints` with *every* deformation
  of every element held rigid. Its kinematic modes (null vectors of ``D_cc``, seed 002 eq. 11) are the
  motions that deform nothing: rigid motions of parts not connected to a support or the drive, and
  mechanisms. At the stress-free reference these are exactly the zero-stiffness motions of the tangent
  stiffness (``K = D^T S D`` with ``S`` positive definite), which make the reference equilibrium singular.
- :func:`stiff_axis_drives`: beams whose bending by the drive is about their stiff section axis (a leaf
  driven about its stiff axis buckles laterally at a tiny stroke; Timoshenko and Gere, Theory of Elastic
  Stability, ch. 6), with the ``y_axis`` that makes it the weak one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .constraints import columns, jacobian_rows, numerical_rank
from .errors import MassUnderflowError, SceneError
from .scene import Beam, RectangularSection
from .structure import Structure

__all__ = [
    "MassUnderflowError",
    "check_mass",
    "FreeMotion",
    "free_motions",
    "check_free_motions",
    "stiff_axis_drives",
    "member_of_master",
    "MASS_FLOOR",
    "OMEGA2_CEILING",
    "MECHANISM_MAX_COLUMNS",
]

#: Smallest segment mass or rotary inertia accepted: a thousand times the smallest normal double
#: (2.2e-308); below it the Cholesky factor of the mass matrix loses every significant digit.
MASS_FLOOR = 1e3 * float(np.finfo(float).tiny)
#: Largest number of coordinates for which :func:`free_motions` looks for mechanisms (a dense SVD of
#: ``D_cc``, measured on the 2-core machine under load: 0.2 s at 500 columns, 6.5 s at 1500); larger models
#: get the connectivity check only, and a mechanism there shows as an unstable reference equilibrium.
MECHANISM_MAX_COLUMNS = 600
#: Largest ``omega^2`` scale ``E / (rho l0^2)`` of a segment accepted [1/s^2]: 1e200 is a frequency of
#: 1e99 Hz, beyond any structure, and still 1e108 below the overflow of a double.
OMEGA2_CEILING = 1e200
#: Densities of real solids [kg/m^3] (aerogels about 1 to osmium 22590, with margin): a mass underflow with
#: a density in this range comes from the section or the length, and is reported there.
DENSITY_PLAUSIBLE = (0.1, 1e5)


def check_mass(structure: Structure) -> None:
    """Raise :class:`MassUnderflowError` when a material's density or a body's mass underflows.

    Raises
    ------
    MassUnderflowError
        Naming ``materials[i].density`` (or ``bodies[i].mass``) and the fix.
    """
    s = structure
    scene = s.scene
    mat_index = {m.name: i for i, m in enumerate(scene.materials)}
    for ie, el in enumerate(scene.elements):
        mat = scene.materials[mat_index[el.material]]
        if isinstance(el, Beam):
            rows = np.flatnonzero(s.beam_member == ie)
            if not len(rows):
                continue
            l0 = float(s.beam_stress[rows[0], 6])
            A, Iy, Iz = (float(s.beam_stress[rows[0], k]) for k in range(3))
            small = min(mat.density * A * l0, mat.density * l0 * min(Iy, Iz))
        else:
            rows = np.flatnonzero(s.truss_member == ie)
            l0 = float(s.truss_const[rows[0], 0]) if len(rows) else 1.0
            small = float(s.truss_mass[rows[0]]) if len(rows) else 1.0
        w2 = mat.E / (mat.density * l0**2) if mat.density * l0**2 > 0 else float("inf")
        if small < MASS_FLOOR and DENSITY_PLAUSIBLE[0] <= mat.density <= DENSITY_PLAUSIBLE[1]:
            # a density of a real solid: the section (or the length) is what underflows, e.g. a thickness of
            # 1e-103 m (rotary inertia ~ t^3); name the dimension, not the material
            sec = getattr(el, "section", None)
            if isinstance(sec, RectangularSection):
                dim = "thickness" if sec.thickness <= sec.width else "width"
                where, value = f"elements[{ie}].section.{dim}", getattr(sec, dim)
                what = f"its section {dim} {value:.3g} m"
            else:
                where, what = f"elements[{ie}].section", "its section constants"
            raise MassUnderflowError(
                where,
                f"mass underflow: element '{el.name}' has a segment mass or rotary inertia of {small:.3g} "
                f"(double precision ends near 2.2e-308) from {what} with density {mat.density:.3g} kg/m^3; give "
                "the section dimensions in metres (a leaf is typically 1e-5 to 1e-2 m thick)",
            )
        if (
            not w2 < OMEGA2_CEILING
            and small >= MASS_FLOOR
            and DENSITY_PLAUSIBLE[0] <= mat.density <= DENSITY_PLAUSIBLE[1]
        ):
            # a real solid's density and a resolvable mass: the modulus is what makes omega^2 overflow
            i = mat_index[mat.name]
            raise MassUnderflowError(
                f"materials[{i}].E",
                f"omega^2 overflow: Young's modulus {mat.E:.3g} of material '{mat.name}' over its density "
                f"{mat.density:.3g} kg/m^3 gives element '{el.name}' an omega^2 of order {w2:.3g} 1/s^2, beyond "
                "what a double holds; give E in Pa (steel: 2.1e11 Pa)",
            )
        if small < MASS_FLOOR or not w2 < OMEGA2_CEILING:
            i = mat_index[mat.name]
            raise MassUnderflowError(
                f"materials[{i}].density",
                f"mass underflow: density {mat.density:.3g} of material '{mat.name}' gives element '{el.name}' "
                f"a segment mass or rotary inertia of {small:.3g} (double precision ends near 2.2e-308) and "
                + (f"omega^2 of order {w2:.3g} 1/s^2" if np.isfinite(w2) else "an omega^2 that overflows")
                + ", beyond what a double holds; give the density in the scene's mass unit per length unit "
                "cubed (steel: 7800 kg/m^3)",
            )
    for i, b in enumerate(scene.bodies):
        if b.mass < MASS_FLOOR:
            raise MassUnderflowError(
                f"bodies[{i}].mass",
                f"mass underflow: body '{b.name}' has mass "
                f"{b.mass:.3g}, below what double precision resolves; give it in kg",
            )


def member_of_master(structure: Structure, master: str) -> str:
    """The scene name of a master: a body or scene node as is, a segment-internal node ``leaf#3`` as
    ``leaf (inside)``."""
    return master.split("#")[0] + " (inside)" if "#" in master else master


@dataclass(frozen=True)
class FreeMotion:
    """A motion that deforms no element: of a part held by nothing, or of a mechanism."""

    kind: str  # "unconnected" (a part joined to no support and no drive) | "mechanism"
    elements: tuple[str, ...]  # scene elements involved
    nodes: tuple[str, ...]  # scene nodes and bodies that move (segment-internal nodes condensed)
    count: int  # number of independent motions


def _components(s: Structure) -> list[set[int]]:
    """Connected components of masters joined by elements or joints (sets of master indices)."""
    nm = len(s.master_names)
    parent = list(range(nm))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for nodes in (s.beam_nodes, s.truss_nodes, s.joint_nodes):
        for a, b in s.node_master[nodes] if len(nodes) else []:
            parent[find(int(a))] = find(int(b))
    groups: dict[int, set[int]] = {}
    for i in range(nm):
        groups.setdefault(find(i), set()).add(i)
    return list(groups.values())


def free_motions(structure: Structure) -> list[FreeMotion]:
    """Motions that deform no element with the drive held (see the module docstring).

    Parts joined to no supported coordinate and not driven are reported as ``unconnected``; any other
    null vector of ``D_cc`` (every deformation rigid) as a ``mechanism``, naming the masters it moves.
    """
    s = structure
    nm = len(s.master_names)
    anchored = np.zeros(nm, dtype=bool)  # supported (any coordinate) or driven
    node_index = {n: i for i, n in enumerate(s.node_names)}
    for sup in s.scene.supports:
        if sup.body is not None:
            anchored[s.master_names.index(sup.body)] = True
        elif sup.node is not None:  # a support names a body or a node (the scene's validator)
            anchored[s.node_master[node_index[sup.node]]] = True
    if s.drive_master >= 0:
        anchored[s.drive_master] = True
    out: list[FreeMotion] = []
    loose: set[int] = set()
    member_names = s.member_names
    for comp in _components(s):
        if any(anchored[i] for i in comp):
            continue
        loose |= comp
        els = sorted(
            {member_names[int(e)] for e, nd in zip(s.beam_member, s.beam_nodes) if s.node_master[nd[0]] in comp}
            | {member_names[int(e)] for e, nd in zip(s.truss_member, s.truss_nodes) if s.node_master[nd[0]] in comp}
        )
        names = sorted({member_of_master(s, s.master_names[i]) for i in comp if "#" not in s.master_names[i]})
        out.append(FreeMotion("unconnected", tuple(els), tuple(names), 6))
    rows = [(0, i, k) for i in range(s.n_beams) for k in range(6)] + [(1, i, 0) for i in range(len(s.truss_nodes))]
    rows += [(2, int(i), int(k)) for kind, i, k in s.constraints if kind == 2]  # joints: their constraints
    T, _, col_masters, trans = columns(s)
    if not rows or T.shape[1] == 0 or T.shape[1] > MECHANISM_MAX_COLUMNS:
        return out
    X, R = s.master_pos.copy(), np.tile(np.eye(3), (nm, 1, 1))
    D = jacobian_rows(s, X, R, rows) @ T
    c = np.where(trans, s.length_scale, 1.0)
    Dh = D * c / s.length_scale
    keep = np.array([s.master_names.index(m) not in loose for m in col_masters])
    Dh = Dh[:, keep]
    if Dh.shape[1] == 0:
        return out
    # the singular values alone decide the rank; the motions (V) only when some are null: a full-rank D_cc
    # (every optimiser evaluation of an exactly constrained design) skips half the SVD's work
    sv = np.linalg.svd(Dh, compute_uv=False)
    rank = numerical_rank(sv)
    if rank == Dh.shape[1]:
        return out
    _, sv, Vt = np.linalg.svd(Dh)
    rank = numerical_rank(sv)
    null = Vt[rank:].T  # (n_kept, k) unit motions
    if null.shape[1] == 0:
        return out
    cm = np.array(col_masters)[keep]
    size = np.zeros(nm)
    for j, m in enumerate(cm):
        size[s.master_names.index(m)] = max(size[s.master_names.index(m)], float(np.abs(null[j]).max()))
    moving = [i for i in range(nm) if size[i] > 1e-6]
    names = sorted({member_of_master(s, s.master_names[i]) for i in moving})
    els = sorted(
        {
            member_names[int(e)]
            for e, nd in zip(s.beam_member, s.beam_nodes)
            if {int(s.node_master[nd[0]]), int(s.node_master[nd[1]])} & set(moving)
        }
        | {
            member_names[int(e)]
            for e, nd in zip(s.truss_member, s.truss_nodes)
            if {int(s.node_master[nd[0]]), int(s.node_master[nd[1]])} & set(moving)
        }
    )
    out.append(FreeMotion("mechanism", tuple(els), tuple(names), int(null.shape[1])))
    return out


def check_free_motions(structure: Structure) -> None:
    """Raise a :class:`SceneError` naming parts not connected to anything and mechanisms (free motions
    beyond the drive), from :func:`free_motions`."""
    s = structure
    found = free_motions(s)
    if not found:
        return
    idx = {e.name: i for i, e in enumerate(s.scene.elements)}
    f = found[0]
    field = f"elements[{idx[f.elements[0]]}].nodes" if f.elements else "supports"
    if not f.elements and f.nodes and f.nodes[0] in [b.name for b in s.scene.bodies]:
        field = f"bodies[{[b.name for b in s.scene.bodies].index(f.nodes[0])}]"
    msgs = []
    for f in found:
        if f.kind == "unconnected":
            part = (
                f"element{'s' if len(f.elements) > 1 else ''} {', '.join(repr(e) for e in f.elements)} "
                f"(nodes {', '.join(repr(n) for n in f.nodes)})"
                if f.elements
                else ", ".join(repr(n) for n in f.nodes)
            )
            msgs.append(
                f"{part} {'are' if len(f.elements) > 1 else 'is'} not connected to any support or to the driven "
                "part: nothing holds it (6 free rigid-body motions); connect it to the structure, support it, "
                "or remove it"
            )
        else:
            msgs.append(
                f"{f.count} free motion{'s' if f.count > 1 else ''} beyond the drive (a mechanism: "
                f"{', '.join(repr(n) for n in f.nodes)} move{'s' if len(f.nodes) == 1 else ''} without deforming "
                f"any element{' of ' + ', '.join(repr(e) for e in f.elements) if f.elements else ''}); support "
                "the moving parts or add elements that hold them ('flexopt diagnose' lists the motions)"
            )
    raise SceneError(field, "; ".join(msgs))


def stiff_axis_drives(structure: Structure) -> list[str]:
    """Beams the drive bends about their stiff section axis, each as one sentence naming the fix.

    The drive bends a beam along ``ex`` about ``b``: the drive axis for a rotation, ``ex x axis`` for a
    translation (its part across the beam). The bending stiffness about ``b`` is ``E (Iy (b.ey)^2 +
    Iz (b.ez)^2)``; when it is at least four times the stiffness about the other transverse axis (the
    sheet criterion of :func:`model.constraints.kinematic_rigid_set`), the drive works against the stiff
    axis and the beam buckles laterally (lateral-torsional buckling, Timoshenko and Gere ch. 6) long before
    any useful stroke. The fix is the ``y_axis`` that puts the weak axis along ``b``.
    """
    s = structure
    if s.drive_kind not in ("rotation", "translation"):
        return []
    a = s.drive_axis
    out: list[str] = []
    for ie, el in enumerate(s.scene.elements):
        if not isinstance(el, Beam):
            continue
        rows = np.flatnonzero(s.beam_member == ie)
        if not len(rows):
            continue
        E0 = s.beam_const[rows[0], 1:10].reshape(3, 3, order="F")
        ex, ey, ez = E0[:, 0], E0[:, 1], E0[:, 2]
        b = a if s.drive_kind == "rotation" else np.cross(ex, a)
        b = b - (b @ ex) * ex
        if np.linalg.norm(b) < 0.5 * np.linalg.norm(a):
            continue  # the drive twists or stretches this beam rather than bending it
        b = b / np.linalg.norm(b)
        bp = np.cross(ex, b)
        Iy, Iz = float(s.beam_stress[rows[0], 1]), float(s.beam_stress[rows[0], 2])
        k_b = Iy * (b @ ey) ** 2 + Iz * (b @ ez) ** 2
        k_p = Iy * (bp @ ey) ** 2 + Iz * (bp @ ez) ** 2
        if k_b < 4.0 * k_p:
            continue
        # weak bending about local y when Iy < Iz: y along b; otherwise z along b, i.e. y = b x ex
        y_new = b if Iy < Iz else np.cross(b, ex)
        y_new = np.where(np.abs(y_new) < 1e-12, 0.0, y_new)
        y_new = (y_new if y_new[np.argmax(np.abs(y_new))] > 0 else -y_new) + 0.0  # + 0.0: no "-0"
        fmt = "(" + ", ".join(f"{v:.4g}" for v in y_new) + ")"
        swap = " or swap its width and thickness" if isinstance(el.section, RectangularSection) else ""
        out.append(
            f"the drive bends beam '{el.name}' about its stiff section axis (bending stiffness "
            f"{k_b / k_p:.3g} times that about the other axis), so it buckles laterally "
            f"(lateral-torsional buckling); set elements[{ie}].y_axis to {fmt}{swap}"
        )
    return out
