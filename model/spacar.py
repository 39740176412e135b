"""SPACAR ``.dat`` models: read one into a Scene, write a Scene as one (issue 28, items 3 and 5).

The format as far as public sources show (the SPACAR manual's element descriptions, seed 002; every line
here written for flexopt). A file is lines of a keyword and numbers, ``#`` starts a comment, ``END`` closes a
section and ``HALT`` the file. Nodes are numbered: translational nodes are declared (``X n x y z``), rotational
nodes are not (they appear in element lists, orientation the identity, Euler parameters (1, 0, 0, 0)). A
flexopt node is a pair of one X node and the R node the beams attach to it, inferred from the connectivity,
so both numberings SPACAR Light writes (user node i as X 2i-1, R 2i, or X 3i-2, R 3i-1, W 3i) read alike.

Mapped keywords (reader and writer):

- ``BEAM Ne Xp Rp Xq Rq Oy_x Oy_y Oy_z`` a spatial beam (Oy: the section's local y axis); ``TRUSS Ne Xp Xq``;
- ``BEAMW Ne Xp Rp Wp Xq Rq Wq Oy_x Oy_y Oy_z`` the same beam with warping nodes (``W``; ``FIX W``: warping
  clamped there): flexopt has no warping coordinate, so a member of BEAMW elements (a chain through shared,
  unfixed warping nodes; a fixed interior one splits it) gets the general section's ``Iw = EIw / E`` and a
  ``warping`` end condition (``FIX``ed end: clamped; an end's W node no other element uses: free), i.e. the
  member-level Vlasov factor on GJ of :func:`model.sections.warping_factor` (static, prismatic: exact under end
  torques), not SPACAR's element-level warping coordinates; the report says so per member. In a vibration
  this reads low against Vlasov's exact solution (seed leaf: -0.55 % with both ends' warping clamped, -5.6 %
  with the root's only, -13.5 % with the twist clamped at both ends; tests/test_spacar_warping.py);
- ``DYNE Ne k...`` its dynamic deformations (1 elongation, 2 torsion, 3-4 bending about y, 5-6 about z) and
  ``RLSE Ne k...`` its released ones (calculated, e(c)), both flexible with the stiffness ESTIFF gives them
  (this reader's interpretation of RLSE, with its reasons on the docs' SPACAR page: being calculated says
  nothing about stiffness; SPACAR Light writes ESTIFF for the elements it releases); the others rigid; a beam
  with none flexible is rigid: the nodes it joins become one rigid body;
- ``ESTIFF Ne EA GJ EIy EIz [Sy Sz [EIw]]`` (EIw: a BEAMW's warping stiffness; on a BEAM, with no warping
  coordinate, it has no effect and the report says so) (a truss: ``EA``; the shear flexibilities ``Sy = EIy / (k G A)``,
  ``Sz`` as the general section's ``shear_y``, ``shear_z``: Timoshenko bending, model.elements) and ``EM Ne rhoA [rho(Iy+Iz) rhoIy rhoIz
  [rhoIyz [rhoIw]]]`` (``rhoIw`` not modelled: its estimated effect on the torsion frequency, ``rho Iw
  (pi/L)^2 / (rho Ip) / 2``, in the report, an error above 1 %): each element gets a general section and its own material whose products are SPACAR's
  numbers exactly (E nominal, A = EA / E, ...; with ``CROSSDIM Ne w t`` in the VISUALIZATION block, A = w t
  and the fibre distances for stresses, else stresses are not available);
- ``FIX n [k...]`` (X node: coordinates 1-3 = x, y, z; R node: Euler parameters 2-4 = rx, ry, rz, all when
  none listed); ``INPUTX n k...`` and ``DELINPX n k v`` (the one input with an increment is the stroke: an X
  coordinate a translation by ``v``, an R component ``k`` a rotation about axis ``k - 1`` to ``2 asin v``;
  inputs without an increment are held, i.e. supported);
- ``XF n fx fy fz`` / ``DELXF``: a force on an X node, constant or ramped over the stroke; on an R node a
  dead moment (3 values, or 4 Euler-parameter values of older files: :func:`_moment`); ``XM n m`` (X node)
  and ``XM n Ixx Ixy Ixz Iyy Iyz Izz`` (R node): lumped mass, as a rigid body; ``GRAVITY gx gy gz``;
- ``ITERSTEP s ...``: ``s`` load steps, ``s + 1`` stroke points (its other numbers: flexopt's own Newton);
- ``HINGE Ne Rp Rq ax ay az`` with ``RLSE Ne 1`` (or ``DYNE Ne 1``, no stiffness): an ideal revolute joint
  (``Scene.joints``) between the two rotational nodes, which share one translational node (where a second R
  node sits at an X node, it becomes a flexopt node of its own at that point);
- ``DYNX n k`` on the input coordinate: the drive free in the eigen analysis.

``HALT`` and ``END`` end sections; reading goes on after ``HALT`` (SPACAR Light writes stiffness, mass and
loads after it), and SPACAR Light's ``BEAMPROPS``/``CROSSTYPE RECT``/``CROSSDIM w t`` give CROSSDIM.
:func:`write_dat` releases (RLSE) the dynamic deformations beyond a maximal independent set so the file's
SPACAR D_cc has independent rows (:func:`model.spacar_dcc.surplus_dynamic_rows`).

Not mapped (each an error naming the line, the keyword and why): a free warping node shared by two members'
elements (warping coupled across members), any line but FIX on a warping node, a released beam deformation or truss without ESTIFF (free), a locked ``HINGE`` or one with ESTIFF (a torsion
spring), two R nodes at
an X node without a HINGE (a spherical joint), a moment of neither 3 nor 4 values, ``ESIG``, several
inputs with increments, and any keyword not listed. Lines of the
VISUALIZATION block other than ``CROSSDIM`` change nothing in the model and are listed in the report.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .errors import SceneError
from .spacar_dcc import SpacarDcc, spacar_dcc, surplus_dynamic_rows
from .spacar_format import _MODE, SpacarError, _parse, _Reader

__all__ = [
    "NOMINAL_E",
    "NOMINAL_G",
    "SpacarError",
    "SpacarImport",
    "read_dat",
    "spacar_dcc_of_scene",
    "spacar_light",
    "write_dat",
]

#: Nominal material constants of an imported element (the products EA, GJ, EIy, EIz are SPACAR's exactly).
NOMINAL_E, NOMINAL_G = 210e9, 80e9
#: Allowable stress of an imported material as a fraction of its E: SPACAR files carry none (E / 200 is
#: 1.05 GPa for steel); the report says so, and the scene is where to set the real one.
ALLOWABLE_PER_E = 1 / 200


@dataclass
class SpacarImport:
    """What :func:`read_dat` made of a file: the scene (a dict, validated by the caller) and a report."""

    scene: dict
    mapped: dict[str, int] = field(default_factory=dict)  # keyword -> lines mapped
    notes: list[str] = field(default_factory=list)
    numbering: str = ""  # how X and R node numbers pair up
    #: SPACAR's count of degrees of freedom: inputs plus flexible (dynamic) deformations
    spacar_dof: int = 0
    #: the .dat text read (SPACAR Light tables: the model written from them), for SPACAR's own D_cc
    text: str = ""
    #: released (RLSE) deformations of beams and trusses, e.g. {"BEAM 4": [3, 5]}: elastic in flexopt
    released: dict[str, list[int]] = field(default_factory=dict)


# --- the assembly of the scene from what was read, step by step (each on the reader; errors collected)


def _pair_nodes(r: _Reader) -> None:
    """Roles of node numbers: X declared, R from the beams; a flexopt node per X node; the numbering found."""
    err, X, r_of, x_of, extra = r.err, r.X, r.r_of, r.x_of, r.extra
    for ne, xp, rp, xq, rq, _oy, ln in r.beams:
        for xn, rn in ((xp, rp), (xq, rq)):
            if xn not in X:
                err.add(
                    ln,
                    r.bkw(ne),
                    f"element {ne}: node {xn} is used as a translational node but never declared with 'X {xn} x y z'",
                )
            if rn in X:
                err.add(
                    ln,
                    r.bkw(ne),
                    f"element {ne}: node {rn} is used as a rotational node but is declared as a "
                    "translational node (X); check the node order Xp Rp Xq Rq",
                )
            if r_of.setdefault(xn, rn) != rn:
                extra.setdefault(rn, (xn, ne, ln))
            if x_of.setdefault(rn, xn) != xn:
                err.add(
                    ln,
                    r.bkw(ne),
                    f"element {ne}: rotational node {rn} belongs to two translational nodes "
                    f"({x_of[rn]} and {xn}); give each point its own rotational node",
                )
    for ne, xp, xq, ln in r.trusses:
        for xn in (xp, xq):
            if xn not in X:
                err.add(ln, "TRUSS", f"element {ne}: node {xn} is used but never declared with 'X {xn} x y z'")
    w_at = _warping_nodes(r)
    if r_of:
        pairs = sorted(r_of.items())
        if all(rn == x + 1 for x, rn in pairs) and all(x % 2 == 1 for x, _ in pairs) and not w_at:
            r.numbering = "X 2i-1, R 2i (two SPACAR nodes per point)"
        elif all(rn == x + 1 for x, rn in pairs) and all(x % 3 == 1 for x, _ in pairs):
            w3 = all(w == x + 2 for w, x in w_at.items())
            r.numbering = f"X 3i-2, R 3i-1{', W 3i' if w_at and w3 else ''} (three SPACAR nodes per point)"
        else:
            r.numbering = "X and R paired by the beams' connectivity"
    else:
        r.numbering = "translational nodes only"


def _warping_nodes(r: _Reader) -> dict[int, int]:
    """The warping (W) nodes of the BEAMW lines: each W node's X node (a W node is one point's warping
    coordinate); a W node that is also an X or R node, or serves two points, is an error."""
    w_at: dict[int, int] = {}
    for ne, xp, _rp, xq, _rq, _oy, ln in r.beams:
        if ne not in r.warp:
            continue
        wp, wq, _ = r.warp[ne]
        for xn, wn in ((xp, wp), (xq, wq)):
            if wn in r.X or wn in r.x_of:
                r.err.add(
                    ln,
                    "BEAMW",
                    f"element {ne}: node {wn} is used as a warping node but is also a "
                    f"{'translational' if wn in r.X else 'rotational'} node; check the node order Xp Rp Wp Xq Rq Wq",
                )
                continue
            if w_at.setdefault(wn, xn) != xn:
                r.err.add(
                    ln,
                    "BEAMW",
                    f"element {ne}: warping node {wn} belongs to two points (translational nodes {w_at[wn]} and "
                    f"{xn}); a warping node is one point's warping coordinate: give each point its own",
                )
                continue
            users = r.w_nodes.setdefault(wn, [])
            if ne not in users:
                users.append(ne)
    return w_at


def _warping_lines(r: _Reader) -> None:
    """Lines other than FIX that name a warping node (a bimoment, a mass, an input on the warping coordinate):
    one error each, and left out of what follows; FIX on a warping node: warping clamped there."""

    def refused(kw: str, n: int, ln: int) -> bool:
        if r.role(n) != "W":
            return False
        r.err.add(
            ln,
            kw,
            f"node {n} is a warping node (BEAMW): {kw} on a warping coordinate is not mapped (flexopt takes "
            f"warping per member, from its end conditions); only 'FIX {n}' (warping clamped there) is read",
        )
        return True

    for table, kw in ((r.xf, "XF"), (r.delxf, "DELXF"), (r.xm, "XM")):
        for n in [n for n, (_v, ln) in table.items() if refused(kw, n, ln)]:
            del table[n]
    r.inputs = [i for i in r.inputs if not refused("INPUTX", i[0], i[2])]
    r.dynx = [i for i in r.dynx if not refused("DYNX", i[0], i[2])]
    r.delinp = [i for i in r.delinp if not refused("DELINPX", i[0], i[3])]
    keep = []
    for n, ks, ln in r.fixes:
        if r.role(n) != "W":
            keep.append((n, ks, ln))
        elif ks and ks != [1]:
            r.err.add(ln, "FIX", f"node {n} is a warping node: it has one coordinate; write 'FIX {n}'")
        else:
            r.w_fixed.setdefault(n, ln)
    r.fixes = keep


def _hinge_joints(r: _Reader) -> None:
    """HINGE lines as ideal revolute joints; a second R node no hinge joins and RLSE of beams are errors."""
    err, X, x_of, dyne = r.err, r.X, r.x_of, r.dyne
    for ne, rp, rq, axis, ln in r.hinges:
        if rp not in x_of or rq not in x_of:
            bad = [n for n in (rp, rq) if n not in x_of]
            err.add(ln, "HINGE", f"element {ne}: nodes {bad} are not rotational nodes of any beam")
            continue
        pa, pb = np.array(X[x_of[rp]][0]), np.array(X[x_of[rq]][0])
        if np.linalg.norm(pa - pb) > 1e-12 * max(1.0, float(np.abs(pa).max())):
            err.add(
                ln,
                "HINGE",
                f"element {ne}: rotational nodes {rp} and {rq} sit at different points; a hinge "
                "joins two rotations at one point (one X node)",
            )
            continue
        flex = set(dyne.get(ne, set())) | r.released(ne)
        if flex != {1}:
            err.add(
                ln,
                "HINGE",
                f"element {ne}: free deformations {sorted(flex) or 'none'}; flexopt maps a hinge "
                f"whose rotation (deformation 1) is free: 'RLSE {ne} 1' or 'DYNE {ne} 1' (a locked hinge welds the "
                "rotations: use one R node)",
            )
            continue
        if ne in r.estiff:
            err.add(
                r.estiff[ne][1],
                "ESTIFF",
                f"element {ne}: a hinge with ESTIFF is a torsion spring (its free rotation keeps the stiffness "
                "ESTIFF gives it), which is not mapped (flexopt's joints are ideal); model it as a short flexible "
                "beam, or remove ESTIFF for a free revolute joint",
            )
            continue
        if not np.linalg.norm(axis) > 0:
            err.add(ln, "HINGE", f"element {ne}: the axis is the zero vector")
            continue
        r.joints.append({"kind": "hinge", "name": f"h{ne}", "nodes": [r.rname(rp), r.rname(rq)], "axis": list(axis)})
        r.hinged.update((rp, rq))
        if ne in dyne:
            r.notes.append(
                f"element {ne}: HINGE with DYNE 1: its rotation is free (a dynamic coordinate, no stiffness)"
            )
        else:
            r.notes.append(
                f"element {ne}: HINGE with RLSE 1: its rotation is free (released: calculated, no ESTIFF, so no "
                "stiffness)"
            )
    for rn, (xn, ne, ln) in r.extra.items():
        if rn not in r.hinged:
            err.add(
                ln,
                r.bkw(ne),
                f"element {ne}: translational node {xn} carries two rotational nodes ({r.r_of[xn]} and "
                f"{rn}) that no HINGE joins: a joint between beams (spherical) that flexopt does not model; join "
                "them with a HINGE or use one rotational node",
            )


def _releases(r: _Reader) -> None:
    """RLSE lines checked: of an element that exists, not also DYNE; the released beam and truss deformations
    are reported (flexopt reads them as elastic with their ESTIFF stiffness: see the module docstring)."""
    kinds = (
        {b[0]: r.bkw(b[0]) for b in r.beams} | {t[0]: "TRUSS" for t in r.trusses} | {h[0]: "HINGE" for h in r.hinges}
    )
    for ne, items in sorted(r.rlse.items()):
        for ks, ln in items:
            if ne not in kinds:
                r.err.add(ln, "RLSE", f"element {ne} is no BEAM, TRUSS or HINGE of the file")
                continue
            both = sorted(set(ks) & r.dyne.get(ne, set()))
            if both:
                r.err.add(
                    ln,
                    "RLSE",
                    f"element {ne}: deformations {both} are listed in DYNE too; a deformation is either dynamic "
                    "(DYNE) or released (RLSE)",
                )
        if ne in kinds and kinds[ne] != "HINGE":
            r.released_report[f"{kinds[ne]} {ne}"] = sorted(r.released(ne))


def _unique_elements(r: _Reader) -> None:
    seen_e: set[int] = set()
    for ne, ln, kw_e in sorted(
        [(b[0], b[-1], r.bkw(b[0])) for b in r.beams] + [(t[0], t[-1], "TRUSS") for t in r.trusses],
        key=lambda row: row[1],
    ):
        if ne in seen_e:
            r.err.add(ln, kw_e, f"element number {ne} is used twice; number elements uniquely")
        seen_e.add(ne)


def _beam_stiffness(r: _Reader, ne: int, ln: int, flex: list[int]) -> tuple[list[float], list[float], int] | None:
    """A flexible beam's ESTIFF products (EA, GJ, EIy, EIz), its EM numbers and the EM line; None after an error."""
    err, estiff, em = r.err, r.estiff, r.em
    if ne not in estiff:
        rel = sorted(r.released(ne))
        why = (
            f" (released {rel} without stiffness are free deformations of a beam, which flexopt does not model)"
            if rel
            else ""
        )
        err.add(
            ln,
            r.bkw(ne),
            f"element {ne} has flexible deformations {flex} but no ESTIFF line{why}; add 'ESTIFF {ne} EA GJ EIy EIz'",
        )
        return None
    k, kln = estiff[ne]
    if len(k) < 4:
        err.add(kln, "ESTIFF", f"element {ne} is a beam: give EA GJ EIy EIz (got {len(k)} numbers)")
        return None
    if any(s < 0 for s in k[4:6]):
        err.add(kln, "ESTIFF", f"element {ne}: shear flexibilities Sy, Sz = {k[4:6]} must be 0 or positive")
        return None
    if len(k) > 7:
        err.add(kln, "ESTIFF", f"element {ne}: at most 7 numbers (EA GJ EIy EIz Sy Sz EIw), got {len(k)}")
        return None
    if len(k) > 6 and k[6] < 0:
        err.add(kln, "ESTIFF", f"element {ne}: warping stiffness EIw = {k[6]} must be 0 or positive")
        return None
    if len(k) > 6 and k[6] > 0 and ne not in r.warp:
        r.notes.append(
            f"line {kln}: ESTIFF {ne}: EIw = {k[6]:g} on a BEAM (no warping nodes): SPACAR then has no warping "
            "coordinate, so warping is free; EIw has no effect"
        )
    EA, GJ, EIy, EIz = k[:4]
    if min(EA, GJ, EIy, EIz) <= 0:
        err.add(kln, "ESTIFF", f"element {ne}: EA, GJ, EIy, EIz must be positive, got {k[:4]}")
        return None
    if ne not in em:
        err.add(ln, r.bkw(ne), f"element {ne} has no EM line: flexopt's beams carry their mass; add 'EM {ne} rhoA'")
        return None
    m, mln = em[ne]
    rhoA = m[0]
    if rhoA <= 0:
        err.add(mln, "EM", f"element {ne}: rhoA must be positive, got {rhoA}")
        return None
    if len(m) >= 4:
        # flexopt's rotary inertia is rho (Iy, Iz) of the section: it must be SPACAR's numbers
        for got, want, what in (
            (m[2], rhoA * EIy / EA, "rhoIy"),
            (m[3], rhoA * EIz / EA, "rhoIz"),
            (m[1], m[2] + m[3], "rho(Iy+Iz)"),
        ):
            if abs(got - want) > 1e-6 * max(abs(want), 1e-300):
                err.add(
                    mln,
                    "EM",
                    f"element {ne}: {what} = {got:.6g} is not that of the section ({want:.6g} "
                    "from rhoA and ESTIFF): flexopt derives rotary inertia from the section (a homogeneous "
                    "material); give consistent numbers",
                )
                break
        if len(m) >= 5 and abs(m[4]) > 0:
            err.add(mln, "EM", f"element {ne}: a product of inertia rhoIyz = {m[4]} is not modelled; set 0")
        if len(m) > 6:
            err.add(mln, "EM", f"element {ne}: at most 6 numbers (rhoA rho(Iy+Iz) rhoIy rhoIz rhoIyz rhoIw)")
            return None
        if len(m) >= 6 and m[5] < 0:
            err.add(mln, "EM", f"element {ne}: warping inertia rhoIw = {m[5]} must be 0 or positive")
            return None
        if len(m) >= 6 and m[5] > 0 and ne not in r.warp:
            r.notes.append(
                f"line {mln}: EM {ne}: rhoIw = {m[5]:g} on a BEAM (no warping nodes): no warping coordinate, so "
                "no warping inertia; it has no effect"
            )
    return k, m, mln


def _beam(r: _Reader, ne: int, xp: int, rp: int, xq: int, rq: int, oy: list[float], ln: int) -> None:
    """One BEAM line as a flexopt beam with its general section and own material, or a rigid link."""
    err, X = r.err, r.X
    if xp in X and xq in X:
        d = np.array(X[xq][0]) - np.array(X[xp][0])
        y = np.array(oy, dtype=float)
        if np.linalg.norm(d) == 0:
            err.add(ln, r.bkw(ne), f"element {ne} has zero length: nodes {xp} and {xq} coincide")
            return
        if np.linalg.norm(y) == 0 or np.linalg.norm(np.cross(d / np.linalg.norm(d), y / np.linalg.norm(y))) < 1e-6:
            err.add(
                ln,
                r.bkw(ne),
                f"element {ne}: Oy = {tuple(oy)} is parallel to the beam's axis; give the section's "
                "y direction across the beam",
            )
            return
    dyne = r.dyne.get(ne, set())
    r.spacar_dof += len(dyne)  # released deformations are calculated: not degrees of freedom
    flex = sorted(dyne | r.released(ne))  # both elastic, with the stiffness ESTIFF gives them
    if not flex:
        r.rigid_links.append((ne, xp, xq))
        if ne in r.estiff or ne in r.em:
            r.notes.append(f"element {ne}: rigid (no DYNE): its ESTIFF is unused; its EM mass goes to the body")
        return
    got = _beam_stiffness(r, ne, ln, flex)
    if got is None:
        return
    k, m, _ = got
    EA, GJ, EIy, EIz = k[:4]
    rhoA = m[0]
    if ne in r.crossdim:
        w, t = r.crossdim[ne]
        A = w * t
        E = EA / A
        Jg = w * t**3 / 3 * (1 - 0.63 * min(w, t) / max(w, t)) if w >= t else t * w**3 / 3 * (1 - 0.63 * w / t)
        G = GJ / Jg
        fibres = {"cy": w / 2, "cz": t / 2, "torsion_stress_factor": min(w, t) / Jg}
    else:
        E, G = NOMINAL_E, NOMINAL_G
        A = EA / E
        fibres = {}
    section = {"kind": "general", "A": A, "Iy": EIy / E, "Iz": EIz / E, "J": GJ / G, **fibres}
    if ne in r.warp and len(k) > 6 and k[6] > 0:  # the end conditions follow from the W nodes (_warping)
        section["Iw"] = k[6] / E
    if len(k) >= 6 and (k[4] > 0 or k[5] > 0):  # SPACAR's shear flexibilities E I / (k G A): Timoshenko bending
        section.update(shear_y=k[4], shear_z=k[5])
    mat = f"m{ne}"
    r.materials.append({"name": mat, "E": E, "G": G, "density": rhoA / A, "allowable_stress": E * ALLOWABLE_PER_E})
    rigid = [_MODE[i] for i in range(1, 7) if i not in flex]
    r.elements.append(
        {
            "kind": "beam",
            "name": f"b{ne}",
            "nodes": [r.rname(rp), r.rname(rq)],
            "material": mat,
            "section": section,
            "y_axis": list(oy),
            "segments": 1,
            "rigid": rigid,
        }
    )


def _truss(r: _Reader, ne: int, xp: int, xq: int, ln: int) -> None:
    """One TRUSS line as a flexopt truss (a rigid one without ESTIFF/EM: a nominal section)."""
    err, estiff, em = r.err, r.estiff, r.em
    dyne, rel = sorted(r.dyne.get(ne, set())), sorted(r.released(ne))
    flex = sorted(set(dyne) | set(rel))
    if flex and flex != [1]:
        err.add(ln, "TRUSS", f"element {ne}: a truss has only deformation 1 (elongation), DYNE/RLSE list {flex}")
        return
    r.spacar_dof += len(dyne)
    if rel and ne not in estiff:
        err.add(
            ln,
            "TRUSS",
            f"element {ne}: released (RLSE) without ESTIFF: a free elongation (no stiffness), which flexopt does "
            f"not model; give 'ESTIFF {ne} EA' (a released elongation keeps its stiffness) or remove the truss",
        )
        return
    if not flex and (ne not in estiff or ne not in em):
        # a rigid truss needs no stiffness; flexopt's trusses carry a section and mass: nominal ones
        estiff.setdefault(ne, ([NOMINAL_E * 1e-6], ln))
        em.setdefault(ne, ([7800 * 1e-6], ln))
        r.notes.append(
            f"element {ne}: rigid truss without ESTIFF/EM: a nominal steel section of 1 mm^2 (EA "
            f"{NOMINAL_E * 1e-6:g} N, unused: rigid; mass 7.8e-3 kg/m: for a dynamic analysis give its EM)"
        )
    if ne not in estiff or ne not in em:
        err.add(ln, "TRUSS", f"element {ne} needs 'ESTIFF {ne} EA' and 'EM {ne} rhoA'")
        return
    EA, rhoA = estiff[ne][0][0], em[ne][0][0]
    if EA <= 0 or rhoA <= 0:
        err.add(ln, "TRUSS", f"element {ne}: EA and rhoA must be positive")
        return
    mat = f"m{ne}"
    r.materials.append(
        {
            "name": mat,
            "E": NOMINAL_E,
            "G": NOMINAL_G,
            "density": rhoA * NOMINAL_E / EA,
            "allowable_stress": NOMINAL_E * ALLOWABLE_PER_E,
        }
    )
    r.elements.append(
        {
            "kind": "truss",
            "name": f"t{ne}",
            "nodes": [r.nname(xp), r.nname(xq)],
            "material": mat,
            "area": EA / NOMINAL_E,
            "rigid": [] if flex else ["elongation"],
        }
    )


def _lumped_masses(r: _Reader) -> tuple[dict[int, float], dict[int, np.ndarray]]:
    """XM lines: the point mass per X node and the inertia (global axes) of its R node; each joins a body."""
    point_mass: dict[int, float] = {}  # X node -> mass
    point_inertia: dict[int, np.ndarray] = {}  # X node -> inertia of its R node's XM (global axes)
    for n, (vals, ln) in r.xm.items():
        if r.role(n) == "X":
            if len(vals) != 1:
                r.err.add(ln, "XM", f"node {n} is translational: give its mass (1 number), got {len(vals)}")
            else:
                point_mass[n] = vals[0]
                r.find(n)
        elif r.role(n) == "R":
            if len(vals) != 6:
                r.err.add(
                    ln, "XM", f"node {n} is rotational: give Ixx Ixy Ixz Iyy Iyz Izz (6 numbers), got {len(vals)}"
                )
            else:
                a, b, c, d, e, f = vals
                point_inertia[r.x_of[n]] = np.array([[a, b, c], [b, d, e], [c, e, f]])
                r.find(r.x_of[n])
        else:
            r.err.add(ln, "XM", f"node {n} is used by no element")
    return point_mass, point_inertia


def _bodies(r: _Reader) -> None:
    """Rigid bodies: nodes joined by rigid beams (union-find), plus nodes carrying lumped mass."""
    X = r.X
    for _, xp, xq in r.rigid_links:
        r.parent[r.find(xp)] = r.find(xq)
    point_mass, point_inertia = _lumped_masses(r)
    clusters: dict[int, list[int]] = {}
    for n in r.parent:
        clusters.setdefault(r.find(n), []).append(n)
    for members in clusters.values():
        members = sorted(members)
        # point masses (lumped XM) and the rigid beams' own mass (EM: a rod, rhoA L at its middle)
        pts: list[tuple[float, np.ndarray, np.ndarray]] = []
        for n in members:
            if n in X:
                pts.append((point_mass.get(n, 0.0), np.array(X[n][0]), point_inertia.get(n, np.zeros((3, 3)))))
        for ne, xp, xq in r.rigid_links:
            if r.find(xp) == r.find(members[0]) and ne in r.em and xp in X and xq in X:
                p, q = np.array(X[xp][0]), np.array(X[xq][0])
                L = float(np.linalg.norm(q - p))
                mass = r.em[ne][0][0] * L
                ex = (q - p) / L
                pts.append((mass, (p + q) / 2, mass * L**2 / 12 * (np.eye(3) - np.outer(ex, ex))))
        mtot = sum(m for m, _, _ in pts)
        com = sum(m * c for m, c, _ in pts) / mtot if mtot > 0 else np.array(X[members[0]][0])
        J = np.zeros((3, 3))
        for m, c, Jc in pts:
            rr = c - com
            J += Jc + m * (float(rr @ rr) * np.eye(3) - np.outer(rr, rr))
        bname = f"body{members[0]}"
        r.bodies.append(
            {
                "name": bname,
                "mass": mtot,
                "center_of_mass": list(com),
                "inertia": J.tolist(),
                "nodes": [r.nname(n) for n in members],
            }
        )
        for n in members:
            r.carrier[n] = bname
    for rn in r.extra:
        if r.x_of[rn] in r.carrier:
            r.err.add(
                r.extra[rn][2],
                r.bkw(r.extra[rn][1]),
                f"node {r.x_of[rn]} is part of a rigid body and carries a hinge: not "
                "mapped; hinge a flexible element's node instead",
            )


def _fixes(r: _Reader) -> None:
    """FIX lines as the supported coordinates per X node (and per hinged point's second R node)."""
    for n, ks, ln in r.fixes:
        role = r.role(n)
        xn = n if role == "X" else r.x_of.get(n)
        if role == "?":
            r.err.add(ln, "FIX", f"node {n} is used by no element")
            continue
        if role == "X":
            bad = [k for k in ks if k not in (1, 2, 3)]
            dofs = {("x", "y", "z")[k - 1] for k in ks if k in (1, 2, 3)} if ks else {"x", "y", "z"}
        else:
            bad = [k for k in ks if k not in (1, 2, 3, 4)]
            if ks == [1]:
                r.err.add(
                    ln,
                    "FIX",
                    f"node {n}: fixing only the Euler parameter lambda0 fixes no rotation direction; "
                    "fix components 2-4 (rx, ry, rz)",
                )
                continue
            dofs = {("rx", "ry", "rz")[k - 2] for k in ks if k in (2, 3, 4)} if ks else {"rx", "ry", "rz"}
        if bad:
            r.err.add(ln, "FIX", f"node {n} ({role}): coordinates {bad} do not exist")
            continue
        if role == "R" and n in r.extra:
            r.fixed_extra.setdefault(r.rname(n), set()).update(dofs)
            continue
        r.fixed.setdefault(xn, set()).update(dofs)
        r.fix_line.setdefault(xn, ln)


def _stroke(r: _Reader, moving: list, held_inputs: set) -> None:
    """The one DELINPX with an increment as the stroke (drive free where DYNX lists it)."""
    for n, k, val, ln in moving[:1]:
        if (n, k) not in held_inputs:
            r.err.add(ln, "DELINPX", f"node {n} coordinate {k} is not declared with INPUTX {n} {k}")
            continue
        role = r.role(n)
        xn = n if role == "X" else r.x_of.get(n)
        pts = (r.steps or 10) + 1
        target = {"body": r.carrier[xn]} if xn in r.carrier else {"node": r.rname(n) if role == "R" else r.nname(xn)}
        if role == "X" and k in (1, 2, 3):
            lo, hi = sorted((0.0, val))
            r.stroke = {
                "kind": "translation",
                **target,
                "axis": list(np.eye(3)[k - 1]),
                "start": lo,
                "stop": hi,
                "points": pts,
                "unit": "m",
            }
        elif role == "R" and k in (2, 3, 4):
            if abs(val) >= 1:
                r.err.add(ln, "DELINPX", f"Euler parameter increment {val}: |value| must be below 1 (sin(angle/2))")
                continue
            ang = math.degrees(2 * math.asin(val))
            lo, hi = sorted((0.0, ang))
            r.stroke = {
                "kind": "rotation",
                **target,
                "axis": list(np.eye(3)[k - 2]),
                "start": lo,
                "stop": hi,
                "points": pts,
                "unit": "deg",
            }
            r.notes.append(
                f"line {ln}: DELINPX {n} {k} {val}: rotation about {'xyz'[k - 2]} to {ang:.6g} deg "
                "(2 asin of the Euler parameter)"
            )
        else:
            r.err.add(
                ln,
                "DELINPX",
                f"node {n} ({role}) coordinate {k}: a stroke drives an X coordinate 1-3 or an R Euler parameter 2-4",
            )
            continue
        held_inputs.discard((n, k))
        if role == "R":
            held_inputs.discard((n, 1))  # lambda0 follows from the others (normalisation)
        if r.stroke is not None:
            r.stroke["drive"] = "locked"
            for dn, dks, _dln in r.dynx:
                if dn == n and k in dks:
                    r.stroke["drive"] = "free"  # the input is a dynamic degree of freedom: not locked in the eigen


def _inputs(r: _Reader) -> None:
    """INPUTX/DELINPX/DYNX: the stroke, and the inputs without an increment held (supported)."""
    moving = [d for d in r.delinp if abs(d[2]) > 0]
    if len(moving) > 1:
        for _n, _k, _val, ln in moving[1:]:
            r.err.add(ln, "DELINPX", "a second input with an increment: flexopt drives one coordinate; keep one")
    held_inputs = {(n, k) for n, ks, _ in r.inputs for k in ks}
    input_line = {(n, k): ln for n, ks, ln in r.inputs for k in ks}
    _stroke(r, moving, held_inputs)
    stroke = r.stroke
    for dn, dks, dln in r.dynx:
        if not (stroke is not None and moving and dn == moving[0][0] and moving[0][1] in dks and len(dks) == 1):
            r.err.add(
                dln,
                "DYNX",
                "only the input coordinate may be dynamic (the drive free in the eigen analysis); "
                "other dynamic coordinates are not mapped",
            )
    for n, k in sorted(held_inputs):
        role = r.role(n)
        xn = n if role == "X" else r.x_of.get(n)
        if xn is None or role == "?":
            r.err.add(input_line[(n, k)], "INPUTX", f"node {n} is used by no element")
            continue
        if role == "R" and k == 1:
            continue
        name_k = ("x", "y", "z")[k - 1] if role == "X" else ("rx", "ry", "rz")[k - 2]
        r.fixed.setdefault(xn, set()).add(name_k)
        r.notes.append(f"INPUTX {n} {k}: an input without increment is held: supported ({name_k})")


def _supports(r: _Reader) -> None:
    """The supported coordinates as scene supports (a body's all or none; the driven coordinate left free)."""
    grounded: set[str] = set()
    stroke, carrier = r.stroke, r.carrier
    for xn, dofs in sorted(r.fixed.items()):
        if xn in carrier:
            if dofs != {"x", "y", "z", "rx", "ry", "rz"}:
                r.err.add(
                    r.fix_line.get(xn, 0),
                    "FIX",
                    f"node {xn} is part of a rigid body ({carrier[xn]}): fix all its coordinates (X and R) or none",
                )
            elif carrier[xn] not in grounded:
                grounded.add(carrier[xn])
                r.supports.append({"body": carrier[xn]})
            continue
        if stroke is not None and stroke.get("node") == r.nname(xn):
            drive_dofs = ("rx", "ry", "rz") if stroke["kind"] == "rotation" else ("x", "y", "z")
            dofs = dofs - {drive_dofs[int(np.argmax(np.abs(stroke["axis"])))]}
        if dofs:
            order = ("x", "y", "z", "rx", "ry", "rz")
            r.supports.append({"node": r.nname(xn), "dofs": [d for d in order if d in dofs]})
    for nd, dofs in sorted(r.fixed_extra.items()):
        if stroke is not None and stroke.get("node") == nd:
            dofs = dofs - {("rx", "ry", "rz")[int(np.argmax(np.abs(stroke["axis"])))]}
        if dofs:
            r.supports.append({"node": nd, "dofs": [d for d in ("rx", "ry", "rz") if d in dofs]})


def _merge(r: _Reader) -> None:
    """Chains of equal collinear beams through free interior nodes: one member with that many segments."""
    x_of = r.x_of
    special = (
        set(r.fixed)
        | set(r.carrier)
        | {x_of.get(n, n) for n in r.xf}
        | {x_of.get(n, n) for n in r.delxf}
        | {n for n, _, _ in r.inputs}
        | {x_of.get(n, n) for n, _, _ in r.inputs}
        | {x_of.get(n, n) for n, _, _ in r.fixes}
        | {x_of[rn] for rn in r.hinged}
        | _warping_breaks(r)
    )
    r.elements, merged, chains = _merge_chains(r.elements, r.materials, r.X, special)
    r.chain_of = chains
    for e in r.elements:
        for name in chains.get(e["name"], [e["name"]]):
            r.member_of[int(name[1:])] = e["name"]
    if merged:
        r.notes.append(f"{merged} chains of equal collinear beams read as members with segments (one member each)")


def _warping_breaks(r: _Reader) -> set[int]:
    """X nodes a member does not run through for warping's sake: where a BEAMW meets a BEAM, where BEAMW elements
    meet with different warping nodes (each free there), and where the warping node is FIXed (warping clamped at
    an interior point: two members, each clamped at that end; Vlasov's equation decouples there, theta' = 0)."""
    at: dict[int, set[int | None]] = {}
    for ne, xp, _rp, xq, _rq, _oy, _ln in r.beams:
        for xn, end in ((xp, 0), (xq, 1)):
            at.setdefault(xn, set()).add(r.warp[ne][end] if ne in r.warp else None)
    out = set()
    for xn, ws in at.items():
        if len(ws) > 1:
            out.add(xn)
        elif ws != {None} and next(iter(ws)) in r.w_fixed:
            out.add(xn)
    return out


def _warping(r: _Reader) -> None:
    """Each member made of BEAMW elements gets its warping end conditions: clamped where its end's warping node is
    FIXed, free where no other element uses it; a free warping node shared with another member's element is an
    error (warping coupled across members, which a member's factor cannot represent). Warping inertia (EM's
    rhoIw) is not modelled: its estimated effect on the torsion frequency is reported (an error above 1 %)."""
    X = r.X
    lines = {b[0]: b for b in r.beams}
    for e in r.elements:
        if e["kind"] != "beam":
            continue
        chain = [int(n[1:]) for n in r.chain_of.get(e["name"], [e["name"]])]
        if not any(ne in r.warp for ne in chain):
            continue
        first, last = chain[0], chain[-1]
        ends = [(r.warp[first][0], lines[first][1]), (r.warp[last][1], lines[last][3])]
        clamped, bad = [], False
        for wn, xn in ends:
            if wn in r.w_fixed:
                clamped.append(True)
                continue
            others = sorted(ne for ne in r.w_nodes.get(wn, []) if r.member_of.get(ne) != e["name"])
            if others:
                ln = r.warp[first][2] if wn == ends[0][0] else r.warp[last][2]
                r.err.add(
                    ln,
                    "BEAMW",
                    f"element {first if wn == ends[0][0] else last}: warping node {wn} (at node {xn}) is shared "
                    f"with element(s) {others} of another member and not fixed: warping coupled across members at "
                    f"a joint, which flexopt's per-member warping cannot represent; write 'FIX {wn}' (warping "
                    "clamped there) or give each element its own warping node (free there)",
                )
                bad = True
            clamped.append(False)
        if bad:
            continue
        sec = e["section"]
        L = float(np.linalg.norm(np.array(X[lines[last][3]][0]) - np.array(X[lines[first][1]][0])))
        cond = {0: "free", 1: "one_end", 2: "both_ends"}[sum(clamped)]
        where = ", ".join(
            f"W {wn} at node {xn} {'fixed (clamped)' if c else 'free'}"
            for (wn, xn), c in zip(ends, clamped, strict=True)
        )
        label = f"member {e['name']} (BEAMW {', '.join(map(str, chain))})"
        if "Iw" not in sec:
            r.notes.append(f"{label}: {where}; EIw is 0 or not given, so no warping stiffness: free warping")
        elif "eps2" in e.get("rigid", []):
            r.notes.append(f"{label}: torsion rigid (no DYNE 2), so warping has no effect")
        else:
            sec["warping"] = cond
            mat = next(m for m in r.materials if m["name"] == e["material"])
            aL = math.sqrt(mat["G"] * sec["J"] / (mat["E"] * sec["Iw"])) * L
            fac = {"free": 1.0, "one_end": aL / (aL - math.tanh(aL)), "both_ends": aL / (aL - 2 * math.tanh(aL / 2))}
            r.notes.append(
                f"{label}: {where}: warping '{cond}', read as flexopt's member-level Vlasov factor on GJ (static, "
                f"prismatic bar under end torques: alpha L = {aL:.4g}, GJ x {fac[cond]:.6g}), not SPACAR's "
                "element-level warping coordinates (docs: SPACAR models, for what that costs in a vibration)"
            )
        _warping_inertia(r, e, chain, L)


def _warping_inertia(r: _Reader, e: dict, chain: list[int], L: float) -> None:
    """EM's rhoIw of a BEAMW member: not modelled; its estimated effect on the first torsion frequency, the
    warping kinetic energy against the rotary one for a twist varying as sin(pi x / L): rho Iw (pi/L)^2 /
    (rho Ip), half of that on the frequency; a note, or an error when above 1 %."""
    for ne in chain:
        m, mln = r.em.get(ne, ([], 0))
        if len(m) < 6 or m[5] <= 0:
            continue
        ratio = m[5] * (math.pi / L) ** 2 / m[1]
        if ratio / 2 > 0.01:
            r.err.add(
                mln,
                "EM",
                f"element {ne}: warping inertia rhoIw = {m[5]:g} is not modelled and would lower the torsion "
                f"frequency of member {e['name']} by about {100 * ratio / 2:.2f} % (rho Iw (pi/L)^2 / (rho Ip) / 2): "
                "flexopt has no warping inertia, so its torsion frequencies would read that much high; set rhoIw "
                "to 0 to accept the model without it",
            )
        else:
            r.notes.append(
                f"line {mln}: EM {ne}: warping inertia rhoIw = {m[5]:g} not modelled (flexopt has none): it would "
                f"lower the torsion frequency of member {e['name']} by about {ratio / 2:.2g} (relative; rho Iw "
                "(pi/L)^2 / (rho Ip) / 2)"
            )
        return


def _moment(r: _Reader, kw: str, n: int, vals: list[float], ln: int) -> list[float] | None:
    """The moment [N m, global axes] of XF/DELXF on rotational node ``n`` (a note says which form was read),
    or None after the one-line error: 3 values ``mx my mz`` (the form since 2017, and what SPACAR Light writes)
    are the moment; 4 values (the form before 2017) are the generalised forces ``Q0..Q3`` dual to the node's
    Euler parameters, whose virtual work ``Q . dlambda`` equals ``m . dtheta`` with ``dtheta = 2 dlambda_v``
    at the reference (lambda = (1, 0, 0, 0)), so ``m = (Q1, Q2, Q3) / 2`` there (``Q0`` does no work there
    and must be 0); read as a dead moment, which equals the generalised force at the reference only."""
    if len(vals) == 3:
        r.notes.append(f"line {ln}: {kw} {n}: a moment, 3 values (mx my mz, the form since 2017) read")
        return list(vals)
    if len(vals) == 4:
        if vals[0] != 0:
            r.err.add(
                ln,
                kw,
                f"node {n} is rotational: of 4 Euler-parameter values (the form before 2017) the first, on lambda0, "
                f"must be 0 (it does no work at the reference), got {vals[0]}; give 3 values mx my mz",
            )
            return None
        m = [v / 2 for v in vals[1:]]
        r.notes.append(
            f"line {ln}: {kw} {n}: 4 Euler-parameter values (the form before 2017) read as the dead moment "
            f"{m} N m (half their last three: the generalised force on the Euler parameters at the reference; "
            "the two differ once the node has turned); write 3 values (mx my mz) to give the moment itself"
        )
        return m
    r.err.add(
        ln,
        kw,
        f"node {n} is rotational: a moment takes 3 values (mx my mz, since 2017) or 4 Euler-parameter "
        f"values (older files), got {len(vals)}; give 3",
    )
    return None


def _forces(r: _Reader) -> dict[tuple[str, int], tuple[np.ndarray, np.ndarray]]:
    """XF and DELXF lines checked: per (kind, X or R node) the constant value (XF) and the increment (DELXF);
    forces on X nodes, moments on R nodes (:func:`_moment`)."""
    out: dict[tuple[str, int], tuple[np.ndarray, np.ndarray]] = {}
    for kw, table in (("XF", r.xf), ("DELXF", r.delxf)):
        for n, (vals, ln) in table.items():
            role = r.role(n)
            if role == "R":
                v = _moment(r, kw, n, vals, ln)
                key = ("moment", n)
            elif role == "X" and len(vals) == 3:
                v, key = list(vals), ("force", n)
            else:
                form = "XF n fx fy fz" if kw == "XF" else "DELXF n dfx dfy dfz"
                r.err.add(ln, kw, f"node {n}: give a force '{form}' on a translational node")
                continue
            if v is None:
                continue
            f0, df = out.get(key, (np.zeros(3), np.zeros(3)))
            out[key] = (np.array(v, dtype=float), df) if kw == "XF" else (f0, np.array(v, dtype=float))
    return out


def _loads(r: _Reader) -> None:
    """Loads: XF constant, XF + DELXF ramped with the stroke (in full without one); forces on X nodes, moments
    on R nodes."""
    stroke = r.stroke
    for (kind, n), (f0, df) in sorted(_forces(r).items(), key=lambda item: (item[0][1], item[0][0])):
        xn = n if kind == "force" else r.x_of[n]
        if xn in r.carrier:
            target: dict = {"body": r.carrier[xn]}
            if kind == "force":
                target["point"] = list(r.X[xn][0])
        else:
            target = {"node": r.nname(n) if kind == "force" else r.rname(n)}
        if not np.any(df):
            r.loads.append({**target, kind: list(f0)})
        elif stroke is None:
            r.loads.append({**target, kind: list(f0 + df)})
            r.notes.append(f"DELXF {n}: no input to ramp it over; applied in full (XF + DELXF) in load steps")
        else:
            # the increment runs with the input, from 0 (XF) to its final value (XF + DELXF)
            start, stop = stroke["start"], stroke["stop"]
            s_end = stop if stop != 0 else start
            ramp = {"start": list(f0 + df * (start / s_end)), "stop": list(f0 + df * (stop / s_end))}
            r.loads.append({**target, "ramp": ramp, **({"kind": "moment"} if kind == "moment" else {})})


def _scene(r: _Reader, name: str) -> dict:
    """The scene dict: the nodes the kept elements, bodies and joints use, and every part assembled."""
    X, x_of = r.X, r.x_of
    node_list = sorted(
        {xp for _, xp, _, _, _, _, _ in r.beams}
        | {xq for _, _, _, xq, _, _, _ in r.beams}
        | {xp for _, xp, _, _ in r.trusses}
        | {xq for _, _, xq, _ in r.trusses}
    )
    for xn in X:
        if xn not in node_list:
            r.notes.append(f"node {xn} is declared but used by no element: left out")
    kept = (
        {n for e in r.elements for n in e["nodes"]}
        | {n for b in r.bodies for n in b["nodes"]}
        | {n for j in r.joints for n in j["nodes"]}
    )
    node_list = [xn for xn in node_list if r.nname(xn) in kept]
    r.materials = [m for m in r.materials if m["name"] in {e["material"] for e in r.elements}]
    scene = {
        "name": name,
        "materials": r.materials
        or [
            {
                "name": "none",
                "E": NOMINAL_E,
                "G": NOMINAL_G,
                "density": 7800.0,
                "allowable_stress": NOMINAL_E * ALLOWABLE_PER_E,
            }
        ],
        "nodes": [{"name": r.nname(xn), "position": list(X[xn][0])} for xn in node_list if xn in X]
        + [{"name": r.rname(rn), "position": list(X[x_of[rn]][0])} for rn in sorted(r.extra) if rn in r.hinged],
        "bodies": r.bodies,
        "elements": r.elements,
        "supports": r.supports,
        "stroke": r.stroke,
        "loads": r.loads,
        "joints": r.joints,
    }
    if r.gravity is not None and any(r.gravity):
        scene["gravity"] = r.gravity
    return scene


def read_dat(text: str, name: str = "spacar") -> SpacarImport:
    """Read a SPACAR ``.dat`` model (see the module docstring) into a scene dict and a report.

    Raises
    ------
    SceneError
        Listing every line that cannot be mapped, each with its number, keyword and why.
    """
    r = _parse(text)
    _pair_nodes(r)
    _hinge_joints(r)
    _releases(r)
    _unique_elements(r)
    for b in r.beams:
        _beam(r, *b)
    for t in r.trusses:
        _truss(r, *t)
    _warping_lines(r)
    _bodies(r)
    _fixes(r)
    _inputs(r)
    _supports(r)
    _merge(r)
    _warping(r)
    _loads(r)
    scene = _scene(r, name)
    if r.err.items:
        raise SpacarError(sorted(r.err.items, key=lambda m: int(m.split(":", 1)[0].split()[1])))
    if not any(e for e in r.elements):
        raise SceneError("spacar", "the file has no flexible element (every beam is rigid); nothing to analyse")
    if r.materials:
        r.notes.append(
            f"allowable stress: not in SPACAR files; set to E/{round(1 / ALLOWABLE_PER_E)} per element "
            "material (edit 'allowable_stress' in the scene)"
        )
    if not any(c for c in r.crossdim) and r.elements:
        r.notes.append("no CROSSDIM: the file gives stiffness only, so stresses are not available (NaN)")
    if r.released_report:
        r.notes.append(
            "released (RLSE: calculated by SPACAR, not degrees of freedom; elastic with the stiffness ESTIFF "
            "gives them, docs: SPACAR models): "
            + "; ".join(f"{el} {' '.join(map(str, ks))}" for el, ks in r.released_report.items())
        )
    spacar_dof = r.spacar_dof
    spacar_dof += len({(n, k) for n, ks, _ in r.inputs for k in ks if not (r.role(n) == "R" and k == 1)})
    spacar_dof += sum(1 for h in r.hinges if h[0] in r.dyne)
    return SpacarImport(
        scene=scene,
        mapped=r.mapped,
        notes=r.notes,
        numbering=r.numbering,
        spacar_dof=spacar_dof,
        text=text,
        released=dict(r.released_report),
    )


def _merge_chains(
    elements: list[dict], materials: list[dict], X: dict, special: set[int]
) -> tuple[list[dict], int, dict[str, list[str]]]:
    """Beams that continue each other (same section, material, flexible set and Oy, collinear, equal lengths)
    through an interior X node that nothing else uses become one member with ``segments``: flexopt meshes a
    member into equal segments at the same positions, so the model is the same, read as the user drew it.
    Returns the elements, the count of merged chains and each merged member's elements in order (by name)."""
    mats = {m["name"]: {k: v for k, v in m.items() if k != "name"} for m in materials}
    use: dict[str, list[int]] = {}
    for i, e in enumerate(elements):
        for n in e["nodes"]:
            use.setdefault(n, []).append(i)

    def key(e: dict) -> tuple:
        return (
            e["kind"],
            repr(sorted(e.get("section", {}).items())),
            repr(sorted(mats[e["material"]].items())),
            tuple(e.get("rigid", ())),
            tuple(
                np.round(
                    np.array(e.get("y_axis", (0, 0, 0))) / max(np.linalg.norm(e.get("y_axis", (1, 0, 0))), 1e-300), 15
                )
            ),
        )

    def pos(name: str) -> np.ndarray:
        return np.array(X[int(name[1:])][0], dtype=float)

    nxt: dict[int, int] = {}  # element i continues into element j through node q of i == node p of j
    for name, idx in use.items():
        if len(idx) != 2 or int(name[1:]) in special:
            continue
        i, j = idx
        a, b = elements[i], elements[j]
        if a["kind"] != "beam" or key(a) != key(b):
            continue
        if a["nodes"][1] == name and b["nodes"][0] == name:
            first, second = i, j
        elif b["nodes"][1] == name and a["nodes"][0] == name:
            first, second = j, i
        else:
            continue
        p, m, q = pos(elements[first]["nodes"][0]), pos(name), pos(elements[second]["nodes"][1])
        d1, d2 = m - p, q - m
        if np.linalg.norm(d1 - d2) <= 1e-12 * np.linalg.norm(d1):
            nxt[first] = second
    starts = [i for i in nxt if i not in set(nxt.values())]
    out, gone, merged = [], set(), 0
    chains: dict[str, list[str]] = {}
    for i in starts:
        chain = [i]
        while chain[-1] in nxt:
            chain.append(nxt[chain[-1]])
        e = dict(elements[i])
        e["nodes"] = [elements[i]["nodes"][0], elements[chain[-1]]["nodes"][1]]
        e["segments"] = len(chain)
        gone.update(chain)
        out.append(e)
        chains[e["name"]] = [elements[k]["name"] for k in chain]
        merged += 1
    return [e for k, e in enumerate(elements) if k not in gone] + out, merged, chains


def _fmt(x: float) -> str:
    return repr(float(x))  # shortest text that reads back to the same double


@dataclass
class _Writer:
    """The points :func:`write_dat` numbers (scene nodes, then mesh nodes, then bodies' centres of mass) and the
    SPACAR node numbers of each."""

    numbering: int
    pos: dict[str, np.ndarray]
    order: list[str]
    chains: dict[str, list[str]] = field(default_factory=dict)  # element -> its nodes along the mesh
    carrier: dict[str, str] = field(default_factory=dict)  # node -> its body
    center: dict[str, str] = field(default_factory=dict)  # body -> the node that carries its mass
    idx: dict[str, int] = field(default_factory=dict)
    share: dict[str, str] = field(default_factory=dict)  # a hinge's second node -> the node whose X it shares
    beamw: bool = False  # members with constrained warping as BEAMW with warping nodes (three-node numbering)
    extra_w: int = 0  # the last warping node number handed out beyond the points' 3i
    w_fixed: set[int] = field(default_factory=set)

    def add_point(self, name: str, p: np.ndarray) -> None:
        self.pos[name] = p
        self.order.append(name)

    def xnum(self, i: int) -> int:
        return self.numbering * i - self.numbering + 1

    def X(self, name: str) -> int:
        return self.xnum(self.idx[self.share.get(name, name)])

    def R(self, name: str) -> int:
        return self.xnum(self.idx[name]) + 1

    def W(self, name: str) -> int:
        """The warping node of point ``name`` (three-node numbering: 3i)."""
        return self.xnum(self.idx[name]) + 2


def _write_points(scene, w: _Writer) -> None:
    """Mesh nodes of multi-segment beams, bodies' centres of mass, the numbering and the hinges' shared X."""
    for e in scene.elements:
        seg = getattr(e, "segments", 1)
        if seg == "auto":
            raise SceneError(f"elements.{e.name}.segments", "'auto' segments: resolve the mesh first (give a number)")
        p, q = w.pos[e.nodes[0]], w.pos[e.nodes[1]]
        chain = [e.nodes[0]]
        for k in range(1, seg):
            w.add_point(f"{e.name}#{k}", p + (q - p) * k / seg)
            chain.append(f"{e.name}#{k}")
        w.chains[e.name] = chain + [e.nodes[1]]
    w.carrier.update({n: b.name for b in scene.bodies for n in b.nodes})
    for b in scene.bodies:  # a node at its centre of mass carries its mass, or a new one
        com = np.array(b.center_of_mass, dtype=float)
        tol = 1e-12 * max(1.0, float(np.abs(com).max()))
        at = [n for n in b.nodes if float(np.linalg.norm(w.pos[n] - com)) <= tol]
        w.center[b.name] = at[0] if at else f"{b.name}@com"
        if not at:
            w.add_point(w.center[b.name], com)
    w.idx.update({name: i + 1 for i, name in enumerate(w.order)})
    # a hinge's two nodes share SPACAR's translational node (HINGE joins rotations at one point)
    pos = w.pos
    for j in scene.joints:
        if j.kind != "hinge":
            raise SceneError(f"joints.{j.name}", f"a {j.kind} has no SPACAR element mapped here; export hinges only")
        p_, q_ = j.nodes
        if float(np.linalg.norm(pos[p_] - pos[q_])) > 1e-12 * max(1.0, float(np.abs(pos[p_]).max())):
            raise SceneError(
                f"joints.{j.name}", "a SPACAR HINGE joins two rotations at one point: its nodes must coincide to export"
            )
        if p_ in w.carrier or q_ in w.carrier:
            raise SceneError(
                f"joints.{j.name}", "a hinge at a body's node is not exported; hinge flexible elements' nodes"
            )
        w.share[q_] = w.share.get(p_, p_)


def _write_elements(scene, w: _Writer, lines: list[str], props_lines: list[str], vis: list[str]) -> int:
    """TRUSS and BEAM lines (a beam per segment) with their ESTIFF, EM, DYNE and CROSSDIM; the elements' count."""
    from .sections import section_properties, warping_factor

    X, R = w.X, w.R
    mats = {m.name: m for m in scene.materials}
    ne = 0
    modes = {"elongation": (1,), "torsion": (2,), "bending_y": (3, 4), "bending_z": (5, 6)}
    modes.update({f"eps{i}": (i,) for i in range(1, 7)})
    for e in scene.elements:
        mat = mats[e.material]
        rigid = {k for r in e.rigid for k in modes[r]}
        flex = [k for k in range(1, 7 if e.kind == "beam" else 2) if k not in rigid]
        chain = w.chains[e.name]
        if e.kind == "truss":
            ne += 1
            lines.append(f"TRUSS {ne} {X(chain[0])} {X(chain[1])}  # {e.name}")
            props_lines += [f"ESTIFF {ne} {_fmt(mat.E * e.area)}", f"EM {ne} {_fmt(mat.density * e.area)}"]
            if flex:
                props_lines.append(f"DYNE {ne} 1")
            continue
        pr = section_properties(e.section)
        L = float(np.linalg.norm(w.pos[e.nodes[1]] - w.pos[e.nodes[0]]))
        beamw = w.beamw and pr.warping != "free" and float(pr.Iw) > 0 and not {"torsion", "eps2"} & set(e.rigid)
        factor = float(warping_factor(mat.E, mat.G, pr, L, pr.warping))
        GJ = float(mat.G * pr.J * (1.0 if beamw else factor))
        if pr.warping != "free" and not beamw:
            lines.append(
                f"# {e.name}: warping '{pr.warping}' written as GJ x {factor:.9g} (flexopt's member-level factor); "
                "write_dat(..., warping='beamw') writes BEAMW with warping nodes instead"
            )
        ends = _warping_ends(scene, e, w, pr.warping) if beamw else {}
        for a, b in itertools.pairwise(chain):
            ne += 1
            y = e.y_axis
            oy = f"{_fmt(y[0])} {_fmt(y[1])} {_fmt(y[2])}"
            if beamw:
                wa, wb = ends.get(a, (w.W(a), False))[0], ends.get(b, (w.W(b), False))[0]
                lines.append(f"BEAMW {ne} {X(a)} {R(a)} {wa} {X(b)} {R(b)} {wb} {oy}  # {e.name}")
            else:
                lines.append(f"BEAM {ne} {X(a)} {R(a)} {X(b)} {R(b)} {oy}  # {e.name}")
            rho = mat.density
            props_lines += [
                f"ESTIFF {ne} {_fmt(mat.E * pr.A)} {_fmt(GJ)} {_fmt(mat.E * pr.Iy)} {_fmt(mat.E * pr.Iz)} "
                f"{_fmt(pr.Sy)} {_fmt(pr.Sz)}" + (f" {_fmt(mat.E * float(pr.Iw))}" if beamw else ""),
                f"EM {ne} {_fmt(rho * pr.A)} {_fmt(rho * (pr.Iy + pr.Iz))} {_fmt(rho * pr.Iy)} {_fmt(rho * pr.Iz)} 0"
                + (" 0" if beamw else ""),
            ]
            if flex:
                props_lines.append(f"DYNE {ne} " + " ".join(str(k) for k in flex))
            if e.section.kind == "rectangular":
                vis.append(f"CROSSDIM {ne} {_fmt(e.section.width)} {_fmt(e.section.thickness)}")
        for wn, fixed in sorted(set(ends.values())):
            if fixed and wn not in w.w_fixed:
                w.w_fixed.add(wn)
                props_lines.append(f"FIX {wn}  # {e.name}: warping clamped")
    return ne


def _warping_ends(scene, e, w: _Writer, warping: str) -> dict[str, tuple[int, bool]]:
    """The warping nodes of member ``e``'s two end points and whether each is fixed: both for 'both_ends'; for
    'one_end' (the factor does not say which end) the end whose node has the most supported rotations (a
    clamp), else the first node. A free end shared with another member gets a warping node of its own (a
    shared free one would couple the members' warping, which the reader refuses)."""
    p, q = e.nodes
    if warping == "both_ends":
        clamped = {p, q}
    else:
        rot = {s.node: sum(d in ("rx", "ry", "rz") for d in s.dofs) for s in scene.supports if s.node is not None}
        clamped = {q} if rot.get(q, 0) > rot.get(p, 0) else {p}
    shared = {n for n in (p, q) if sum(n in f.nodes for f in scene.elements if f.kind == "beam") > 1}
    out = {}
    for n in (p, q):
        if n in clamped or n not in shared:
            out[n] = (w.W(n), n in clamped)
        else:
            w.extra_w += 1
            out[n] = (w.extra_w, False)
    return out


def _write_bodies(scene, w: _Writer, lines: list[str], props_lines: list[str], ne: int) -> int:
    """A body as rigid beams from its centre-of-mass node to its other nodes, and its XM; the elements' count."""
    X, R, pos = w.X, w.R, w.pos
    for b in scene.bodies:
        c = w.center[b.name]
        for n in b.nodes:
            if n == c:
                continue
            ne += 1
            d = pos[n] - pos[c]
            if np.linalg.norm(d) <= 1e-12 * max(1.0, float(np.abs(pos[c]).max())):
                raise SceneError(
                    f"bodies.{b.name}",
                    f"nodes '{n}' and '{c}' of body '{b.name}' coincide: SPACAR "
                    "needs a rigid beam of nonzero length between them; merge them",
                )
            t = np.eye(3)[int(np.argmin(np.abs(d)))]
            y = t - (t @ d) * d / (d @ d)
            lines.append(
                f"BEAM {ne} {X(c)} {R(c)} {X(n)} {R(n)} {_fmt(y[0])} {_fmt(y[1])} {_fmt(y[2])}  "
                f"# rigid link of body {b.name}"
            )
        props_lines.append(f"XM {X(c)} {_fmt(b.mass)}")
        J = np.array(b.inertia, dtype=float)
        props_lines.append(
            f"XM {R(c)} " + " ".join(_fmt(v) for v in (J[0, 0], J[0, 1], J[0, 2], J[1, 1], J[1, 2], J[2, 2]))
        )
    return ne


def _write_supports(scene, w: _Writer, lines: list[str]) -> None:
    """FIX lines: a body's centre node fixed whole, a node's X and R coordinates as listed."""
    X, R = w.X, w.R
    comps = {"x": ("X", 1), "y": ("X", 2), "z": ("X", 3), "rx": ("R", 2), "ry": ("R", 3), "rz": ("R", 4)}
    for s in scene.supports:
        if s.body is not None or s.node in w.carrier:
            c = w.center[s.body or w.carrier[s.node]]
            lines += [f"FIX {X(c)}", f"FIX {R(c)}"]
            continue
        xs = [comps[d][1] for d in s.dofs if comps[d][0] == "X"]
        rs = [comps[d][1] for d in s.dofs if comps[d][0] == "R"]
        if xs:
            lines.append(f"FIX {X(s.node)}" + ("" if len(xs) == 3 else " " + " ".join(map(str, xs))))
        if rs:
            lines.append(f"FIX {R(s.node)}" + ("" if len(rs) == 3 else " " + " ".join(map(str, rs))))


def _write_stroke(st, w: _Writer, lines: list[str]) -> None:
    """The stroke as INPUTX and DELINPX (and DYNX for a free drive) on one coordinate, with ITERSTEP."""
    X, R = w.X, w.R
    axis = np.array(st.axis, dtype=float) / np.linalg.norm(st.axis)
    k = int(np.argmax(np.abs(axis)))
    if abs(abs(axis[k]) - 1) > 1e-12:
        raise SceneError(
            "stroke.axis", "SPACAR inputs are coordinates: the drive axis must be a coordinate axis to export"
        )
    vals = st.values()
    if vals[0] != 0 and vals[-1] != 0:
        raise SceneError(
            "stroke.start",
            f"a SPACAR input runs from the reference (0) to its increment; the "
            f"stroke runs {vals[0]:g} to {vals[-1]:g}: set start or stop to 0 to export",
        )
    end = float(vals[-1] if vals[-1] != 0 else vals[0]) * float(np.sign(axis[k]))
    target = w.center[st.body] if st.body is not None else st.node
    if st.kind == "rotation":
        ang = math.radians(end) if st.resolved_unit == "deg" else end
        lines += [f"INPUTX {R(target)} {k + 2}", f"DELINPX {R(target)} {k + 2} {_fmt(math.sin(ang / 2))}"]
    else:
        lines += [f"INPUTX {X(target)} {k + 1}", f"DELINPX {X(target)} {k + 1} {_fmt(end)}"]
    if st.drive == "free":  # the input is a dynamic coordinate: free in the eigen analysis
        lines.append(lines[-2].replace("INPUTX", "DYNX", 1))
    lines.append(f"ITERSTEP {st.points - 1}")


def _write_loads(scene, w: _Writer, lines: list[str]) -> None:
    """Forces on X nodes and moments on R nodes (3 values, the form since 2017) as XF (a ramp: XF at the
    stroke's start and DELXF to its end), and GRAVITY."""
    st = scene.stroke
    for i, ld in enumerate(scene.loads):
        if ld.table is not None:
            raise SceneError("loads.table", "a load table has no SPACAR form (XF + DELXF is linear); use a ramp")
        if ld.follower:
            raise SceneError(
                f"loads[{i}].follower",
                "a follower load has no SPACAR form mapped here (XF is read as dead); export dead loads",
            )
        if ld.is_moment:  # a moment on a rigid body acts alike at any of its points: its centre node's R
            carrier = ld.body or w.carrier.get(ld.node or "")
            at = w.R(w.center[carrier]) if carrier else w.R(ld.node)
        else:
            if ld.body is not None or ld.point is not None:
                raise SceneError(
                    "loads.body",
                    "a force on a body has no node in the exported file; load one of the body's nodes instead",
                )
            if ld.node in w.carrier:
                raise SceneError(
                    "loads.node", f"node '{ld.node}' is carried by a body; load it through a node of a flexible element"
                )
            at = w.X(ld.node)
        const = ld.force if ld.force is not None else ld.moment
        if const is not None:
            lines.append(f"XF {at} " + " ".join(_fmt(v) for v in const))
        else:
            vals = st.values()
            s0, s1 = float(vals[0]), float(vals[-1])
            F0 = ld.value(0.0, s0, s1)
            Fend = ld.value(s1 if s1 != 0 else s0, s0, s1)
            lines.append(f"XF {at} " + " ".join(_fmt(v) for v in F0))
            lines.append(f"DELXF {at} " + " ".join(_fmt(v) for v in Fend - F0))
    if scene.gravity is not None and any(scene.gravity):
        lines.append("GRAVITY " + " ".join(_fmt(v) for v in scene.gravity))


def write_dat(scene, numbering: int = 2, warping: str = "factor") -> str:
    """A ``.dat`` text of ``scene`` (see the module docstring) that :func:`read_dat` reads back to the same model.

    Each scene node ``i`` (1-based, in order; then each beam's interior mesh nodes, then each body's centre of
    mass) becomes X node ``2i - 1`` and R node ``2i`` (``numbering=3``: ``3i - 2`` and ``3i - 1``). Beams are
    written per segment with their stiffness (ESTIFF: E A, G J (times the member's warping factor), E Iy,
    E Iz) and mass (EM: rho A, rho (Iy + Iz), rho Iy, rho Iz); a rectangular section also as CROSSDIM. A rigid
    body is its centre-of-mass node with its mass and inertia (XM), joined to each of its nodes by a rigid beam.

    Constrained warping (a section's ``warping`` 'one_end' or 'both_ends'): ``warping="factor"`` (default)
    writes BEAM with GJ times the member's factor, so SPACAR computes flexopt's model; ``warping="beamw"``
    writes BEAMW with warping nodes (three-node numbering, W 3i), EIw = E Iw and the warping nodes of the
    clamped ends FIXed ('one_end': the end with the most supported rotations, else the first node), so a
    SPACAR user's BEAMW file round-trips; SPACAR then models warping per element (its warping coordinates),
    which differs from flexopt's factor in a vibration (docs: SPACAR models). rhoIw is written 0 (flexopt
    has no warping inertia).

    Raises
    ------
    SceneError
        For what the format (as mapped here) cannot hold: a beam with segments 'auto', a drive axis that is not
        a coordinate axis, a load given as a table, a stroke not starting or ending at 0.
    """
    if numbering not in (2, 3):
        raise SceneError("numbering", f"numbering must be 2 or 3 SPACAR nodes per point, got {numbering}")
    if warping not in ("factor", "beamw"):
        raise SceneError("warping", f"warping must be 'factor' or 'beamw', got {warping!r}")
    if warping == "beamw":
        numbering = 3  # a warping node per point: X 3i-2, R 3i-1, W 3i
    lines = [f"# {scene.name}: written by flexopt (model.spacar.write_dat); SI units", ""]
    w = _Writer(
        numbering, {n.name: np.array(n.position, dtype=float) for n in scene.nodes}, [n.name for n in scene.nodes]
    )
    w.beamw = warping == "beamw"
    _write_points(scene, w)
    w.extra_w = w.xnum(len(w.order)) + 2
    for name in w.order:
        if name in w.share:
            continue  # its hinge partner's X
        p = w.pos[name]
        lines.append(f"X {w.X(name)} {_fmt(p[0])} {_fmt(p[1])} {_fmt(p[2])}  # {name}")
    lines.append("")
    props_lines: list[str] = []
    vis: list[str] = []
    ne = _write_elements(scene, w, lines, props_lines, vis)
    ne = _write_bodies(scene, w, lines, props_lines, ne)
    for j in scene.joints:
        ne += 1
        a = np.array(j.axis, dtype=float)
        lines.append(
            f"HINGE {ne} {w.R(j.nodes[0])} {w.R(j.nodes[1])} {_fmt(a[0])} {_fmt(a[1])} {_fmt(a[2])}  # {j.name}"
        )
        props_lines.append(f"RLSE {ne} 1")
    lines += [""] + props_lines + [""]
    _write_supports(scene, w, lines)
    if scene.stroke is not None:
        _write_stroke(scene.stroke, w, lines)
    _write_loads(scene, w, lines)
    lines += ["END", ""]
    if vis:
        lines += ["VISUALIZATION"] + vis + ["END", ""]
    lines.append("HALT")
    return _release_surplus(lines)


def _release_surplus(lines: list[str]) -> str:
    """The text of ``lines`` with the surplus dynamic deformations released (RLSE), so that SPACAR's D_cc
    (rows rigid + DYNE, seed 002 eq. 9) has independent rows (:func:`model.spacar_dcc.surplus_dynamic_rows`);
    a released deformation keeps its ESTIFF stiffness (module docstring), so the model is the same. The second
    line says how many were released and SPACAR's D_cc afterwards."""
    text = "\n".join(lines) + "\n"
    try:
        d = spacar_dcc(text, singular_values=False)
        surplus = surplus_dynamic_rows(d)
    except SceneError as exc:  # no SPACAR D_cc of this model: written as it is, and the file says why
        why = "; ".join(getattr(exc, "lines", None) or [str(exc)])
        lines.insert(1, f"# SPACAR's D_cc not computed ({why}): no deformation released")
        return "\n".join(lines) + "\n"
    rel: dict[int, set[int]] = {}
    for label in surplus:  # e.g. "BEAM 3 eps5"
        _, ne, eps = label.split()
        rel.setdefault(int(ne), set()).add(int(eps[3:]))
    out = []
    for line in lines:
        tok = line.split()
        if tok[:1] == ["DYNE"] and int(tok[1]) in rel:
            ne = int(tok[1])
            ks = [int(k) for k in tok[2:]]
            kept, freed = [k for k in ks if k not in rel[ne]], [k for k in ks if k in rel[ne]]
            if kept:
                out.append(f"DYNE {ne} " + " ".join(map(str, kept)))
            out.append(f"RLSE {ne} " + " ".join(map(str, freed)))
        else:
            out.append(line)
    out.insert(
        1,
        f"# SPACAR's D_cc (rows rigid + DYNE): {len(surplus)} dynamic deformations released (RLSE: calculated, "
        f"elastic with their ESTIFF stiffness), the surplus over the independent ones; D_cc now "
        f"{d.m - len(surplus)} x {d.D_cc.shape[1]}",
    )
    return "\n".join(out) + "\n"


# ------------------------------------------------------------------------------- SPACAR Light tables (item 4)
#: nprops fields mapped by :func:`spacar_light` (SPACAR Light's names; supports, inputs, loads, masses).
NPROPS_FIELDS = (
    "fix",
    "fix_pos",
    "fix_orien",
    "fix_x",
    "fix_y",
    "fix_z",
    "displ_x",
    "displ_y",
    "displ_z",
    "rot_x",
    "rot_y",
    "rot_z",
    "force",
    "mass",
    "mominertia",
    "fix_w",
)
#: eprops fields mapped by :func:`spacar_light`.
EPROPS_FIELDS = (
    "elems",
    "emod",
    "smod",
    "dens",
    "cshape",
    "dim",
    "orien",
    "nbeams",
    "flex",
    "color",
    "name",
    "hide",
    "opacity",
    "enable_warping",
    "cw",
)


def _light_elements(
    P: np.ndarray,
    E_: np.ndarray,
    eprops,
    new_point,
    lines: list[str],
    props: list[str],
    vis: list[str],
    errors: list[str],
    rls: list[dict] | None = None,
    per_point: int = 2,
) -> tuple[set[int], list[str]]:
    """SPACAR Light's elements and eprops as BEAM lines (``nbeams`` per element, interior points from
    ``new_point``) with ESTIFF, EM, DYNE and CROSSDIM; BEAMW lines with EIw and rhoIw for a set with
    ``enable_warping`` (``per_point`` 3: X, R, W), GJ times the both-ends warping factor for ``cw``. Returns the
    user nodes a BEAMW ends at and notes for the report."""
    xn = lambda i: per_point * i - per_point + 1
    warped: set[int] = set()
    notes: list[str] = []
    set_of: dict[int, dict] = {}
    for k, es in enumerate(eprops or [], start=1):
        bad = sorted(set(es) - set(EPROPS_FIELDS))
        if bad:
            errors.append(f"eprops({k}): fields {bad} are not mapped (mapped: {', '.join(EPROPS_FIELDS)})")
        for e in np.atleast_1d(es.get("elems", [])):
            set_of[int(e)] = es
    ne = 0
    for e, (a, b) in enumerate(E_, start=1):
        es = set_of.get(e)
        if es is None:
            errors.append(f"elements({e}): no eprops set lists it in 'elems'; every element needs properties")
            continue
        if es.get("cshape", "rect") != "rect":
            errors.append(f"eprops: cshape '{es.get('cshape')}' of element {e} is not mapped; use 'rect'")
            continue
        try:
            w, t = (float(v) for v in es["dim"])
            Em, G, rho = float(es["emod"]), float(es["smod"]), float(es["dens"])
        except (KeyError, TypeError, ValueError):
            errors.append(f"eprops: element {e} needs emod, smod, dens and dim = [width, thickness]")
            continue
        orien = [float(v) for v in es.get("orien", (0.0, 0.0, 1.0))]
        n = int(es.get("nbeams", 1))
        flex = [int(v) for v in np.atleast_1d(es.get("flex", []))]
        A, Iy, Iz = w * t, w * t**3 / 12, t * w**3 / 12
        lo, hi = min(w, t), max(w, t)
        J = hi * lo**3 * (1 / 3 - 0.21 * (lo / hi) * (1 - lo**4 / (12 * hi**4)))
        Iw = w**3 * t**3 / 144  # Vlasov, thin rectangle (as SPACAR Light's and flexopt's rectangles)
        warp = bool(es.get("enable_warping", False))
        GJ = G * J
        if es.get("cw") and not warp:  # SPACAR Light: cw on a plain BEAM only (BEAMW models warping itself)
            from .sections import rectangular_properties, warping_factor

            L = float(np.linalg.norm(P[b - 1] - P[a - 1]))
            f = float(warping_factor(Em, G, rectangular_properties(w, t), L, "both_ends"))
            GJ *= f
            notes.append(
                f"eprops: element {e} with cw: GJ x {f:.6g}, the both-ends warping factor of the whole element "
                f"(L = {L:g} m; flexopt's rectangle: J by Roark's series, Iw = t^3 w^3/144), written into ESTIFF"
            )
        chain = [a] + [new_point(P[a - 1] + (P[b - 1] - P[a - 1]) * k / n) for k in range(1, n)] + [b]
        if warp:
            warped.update((a, b))
        for p_, q_ in itertools.pairwise(chain):
            ne += 1
            y_ = f"{_fmt(orien[0])} {_fmt(orien[1])} {_fmt(orien[2])}"
            if warp:
                lines.append(f"BEAMW {ne} {xn(p_)} {xn(p_) + 1} {xn(p_) + 2} {xn(q_)} {xn(q_) + 1} {xn(q_) + 2} {y_}")
            else:
                lines.append(f"BEAM {ne} {xn(p_)} {xn(p_) + 1} {xn(q_)} {xn(q_) + 1} {y_}")
            props += [
                f"ESTIFF {ne} {_fmt(Em * A)} {_fmt(GJ)} {_fmt(Em * Iy)} {_fmt(Em * Iz)} 0 0"
                + (f" {_fmt(Em * Iw)}" if warp else ""),
                f"EM {ne} {_fmt(rho * A)} {_fmt(rho * (Iy + Iz))} {_fmt(rho * Iy)} {_fmt(rho * Iz)} 0"
                + (f" {_fmt(rho * Iw)}" if warp else ""),
            ]
            # SPACAR Light releases on the element's last beam only (spacarlight.m): DYNE the rest there
            rel = (
                [int(v) for v in np.atleast_1d(rls[e - 1].get("def", []))] if rls and q_ == b and e <= len(rls) else []
            )
            dyne = [k for k in flex if k not in rel]
            if dyne:
                props.append(f"DYNE {ne} " + " ".join(map(str, dyne)))
            if rel:
                props.append(f"RLSE {ne} " + " ".join(map(str, rel)))
            vis.append(f"CROSSDIM {ne} {_fmt(w)} {_fmt(t)}")
    return warped, notes


def _light_nodes(
    nprops: list, props: list[str], errors: list[str], per_point: int = 2, warped: set[int] | None = None
) -> None:
    """SPACAR Light's nprops as FIX, INPUTX/DELINPX, XF and XM lines (user node i: X 2i-1, R 2i; with warping
    X 3i-2, R 3i-1, W 3i, and ``fix_w`` as FIX of W 3i where a BEAMW ends at node i)."""
    xn = lambda i: per_point * i - per_point + 1
    inputs = 0
    for i, npr in enumerate(nprops, start=1):
        if not npr:
            continue
        bad = sorted(set(npr) - set(NPROPS_FIELDS))
        if bad:
            errors.append(f"nprops({i}): fields {bad} are not mapped (mapped: {', '.join(NPROPS_FIELDS)})")
        X_, R_ = xn(i), xn(i) + 1
        if npr.get("fix"):
            props += [f"FIX {X_}", f"FIX {R_}"]
        if npr.get("fix_pos"):
            props.append(f"FIX {X_}")
        if npr.get("fix_orien"):
            props.append(f"FIX {R_}")
        if npr.get("fix_w"):
            if i in (warped or set()):
                props.append(f"FIX {R_ + 1}")
            else:
                errors.append(
                    f"nprops({i}).fix_w: no element with enable_warping ends at node {i}, so it has no warping "
                    "coordinate to fix; enable warping on its element set or remove fix_w"
                )
        for k, ax in enumerate("xyz"):
            if npr.get(f"fix_{ax}"):
                props.append(f"FIX {X_} {k + 1}")
            if f"displ_{ax}" in npr:
                inputs += 1
                props += [f"INPUTX {X_} {k + 1}", f"DELINPX {X_} {k + 1} {_fmt(float(npr[f'displ_{ax}']))}"]
            if f"rot_{ax}" in npr:
                inputs += 1
                props += [f"INPUTX {R_} {k + 2}", f"DELINPX {R_} {k + 2} {_fmt(math.sin(float(npr[f'rot_{ax}']) / 2))}"]
        if "force" in npr:
            props.append(f"XF {X_} " + " ".join(_fmt(float(v)) for v in npr["force"]))
        if "mass" in npr:
            props.append(f"XM {X_} {_fmt(float(npr['mass']))}")
        if "mominertia" in npr:
            props.append(f"XM {R_} " + " ".join(_fmt(float(v)) for v in npr["mominertia"]))
    if inputs > 1:
        errors.append(f"nprops: {inputs} inputs (displ_*/rot_*); flexopt drives one coordinate")


def spacar_light(nodes, elements, nprops, eprops, opt: dict | None = None, name: str = "spacar-light") -> SpacarImport:
    """A scene from SPACAR Light's four tables, so a script ports line by line: ``nodes`` (n x 3 positions),
    ``elements`` (ne x 2 node numbers, 1-based), ``nprops`` (a list, one dict per node, or a dict {node: dict})
    and ``eprops`` (a list of element sets), and ``opt`` (``gravity``, ``loadsteps``, ``rls``: per element
    ``{"def": [k...]}``, a list or a dict {element: ...}, released on the element's last beam as SPACAR Light
    writes them, and read as elastic: :func:`read_dat`).

    The tables are written as the equivalent ``.dat`` model (user node i as X 2i-1, R 2i; each element as
    ``nbeams`` beams with ESTIFF/EM from a rectangle ``dim = [w, t]`` with ``w`` along ``orien``, J by Roark's
    series as flexopt's rectangles, not SPACAR Light's own torsion formula) and read by :func:`read_dat`, so both
    routes map alike. nprops: ``fix``, ``fix_pos``, ``fix_orien``, ``fix_x/y/z`` supports; ``displ_x/y/z`` [m]
    and ``rot_x/y/z`` [rad] the input (one, with its final value); ``force`` [N]; ``mass`` [kg] and
    ``mominertia`` (Ixx Ixy Ixz Iyy Iyz Izz) [kg m^2]. eprops: ``elems``, ``emod``, ``smod``, ``dens``,
    ``cshape`` ('rect'), ``dim``, ``orien``, ``nbeams``, ``flex`` (flexible deformations; none: rigid).
    Warping as SPACAR Light 2.01 "beamw" writes it: ``enable_warping`` (eprops) writes BEAMW elements with
    ``EIw = E t^3 w^3 / 144`` and ``rhoIw`` (every point numbered X 3i-2, R 3i-1, W 3i) and ``fix_w`` (nprops)
    FIXes node i's warping coordinate, read as :func:`read_dat` reads BEAMW (the member-level Vlasov factor);
    ``cw`` (eprops, without ``enable_warping``) multiplies GJ of a plain BEAM by the both-ends factor of the
    whole element, as SPACAR Light does (with flexopt's rectangle's J and Iw, so it equals a native
    rectangular section with ``warping: both_ends``; a note in the report says so).
    Anything else (moments, circular sections, ...) is an error naming the table, entry and field.
    """
    errors: list[str] = []
    P = np.asarray(nodes, dtype=float).reshape(-1, 3)
    E_ = np.asarray(elements, dtype=int).reshape(-1, 2)
    if isinstance(nprops, dict):
        nprops = [nprops.get(i + 1, nprops.get(str(i + 1), {})) or {} for i in range(len(P))]
    nprops = list(nprops or [])
    opt = dict(opt or {})
    lines = [f"# {name}: SPACAR Light tables written as a .dat model by flexopt"]
    # SPACAR Light 2.01 "beamw" numbers a point as X 3i-2, R 3i-1, W 3i; without warping two nodes suffice
    per_point = 3 if any(es.get("enable_warping") for es in eprops or []) else 2
    xn = lambda i: per_point * i - per_point + 1
    count = len(P)

    def new_point(p: np.ndarray) -> int:
        nonlocal count
        count += 1
        lines.append(f"X {xn(count)} {_fmt(p[0])} {_fmt(p[1])} {_fmt(p[2])}")
        return count

    for i, p in enumerate(P, start=1):
        lines.append(f"X {xn(i)} {_fmt(p[0])} {_fmt(p[1])} {_fmt(p[2])}")
    props: list[str] = []
    vis: list[str] = ["VISUALIZATION"]
    rls = opt.get("rls") or []
    rls = [rls.get(i + 1, rls.get(str(i + 1), {})) or {} for i in range(len(E_))] if isinstance(rls, dict) else rls
    warped, notes = _light_elements(
        P, E_, eprops, new_point, lines, props, vis, errors, [dict(x or {}) for x in rls], per_point
    )
    _light_nodes(nprops, props, errors, per_point, warped)
    if "gravity" in opt:
        props.append("GRAVITY " + " ".join(_fmt(float(v)) for v in opt["gravity"]))
    if "loadsteps" in opt:
        props.append(f"ITERSTEP {int(opt['loadsteps'])}")
    bad = sorted(set(opt) - {"gravity", "loadsteps", "rls", "filename", "silent", "showinputonly"})
    if bad:
        errors.append(
            f"opt: fields {bad} are not mapped (mapped: gravity, loadsteps, rls; filename, silent, "
            "showinputonly are ignored)"
        )
    if errors:
        raise SpacarError(errors)
    text = "\n".join(lines + props + ["END"] + vis + ["END", "HALT"]) + "\n"
    imp = read_dat(text, name)
    imp.notes.extend(notes)
    return imp


def spacar_dcc_of_scene(scene: Any) -> SpacarDcc:
    """SPACAR's D_cc of a native scene: of the model :func:`model.spacar.write_dat` writes for it (loads and
    gravity left out: they do not enter D_cc; a beam meshed 'auto' as one beam element; a stroke from the
    reference: only which coordinate is the input enters D_cc).

    Raises
    ------
    SceneError
        When the scene has no SPACAR form (:func:`model.spacar.write_dat`'s errors, e.g. a drive axis that
        is not a coordinate axis).
    """
    from .scene import Beam

    elements = tuple(
        e.model_copy(update={"segments": 1}) if isinstance(e, Beam) and e.segments == "auto" else e
        for e in scene.elements
    )
    update: dict[str, Any] = {"loads": (), "gravity": None, "elements": elements}
    st = scene.stroke
    if st is not None and st.start != 0 and st.stop != 0:  # only which coordinate is the input matters here
        update["stroke"] = st.model_copy(update={"start": 0.0})
    return spacar_dcc(write_dat(scene.model_copy(update=update)))
