"""The exact-constraint filter: the kinematic diagnosis of each candidate before any expensive analysis.

For each candidate, seed 002's kinematic diagnosis (section 4.2; :func:`model.constraints.diagnose` with
``kinematic=True``): every flexure's compliant deformations released, a sheet keeping its elongation and
in-plane bending rigid, a wire its elongation; each leaf is one segment between its ends (the flexure
level: a reinforced middle and the halves of an in-plane crossing are condensed into the flexure,
``flexure_level=1`` of the ``topology-hinge`` template). With the drive held (the stroke coordinate is
x(m)), the null space of D_cc holds the free motions and the left null space the self-stress states.

Intended free motions: none for a single-stage hinge or a guide (the stroke is the only motion); for
stages in series, the rotation about the stroke axis of every intermediate body and in-plane joint (each
stage a hinge about the same axis: a double cross hinge turns its intermediate body by about half the
stroke). A candidate is accepted when its free motions are exactly these (their span, to the rank
tolerance), otherwise rejected with every other free motion named by its largest motion. Self-stress
states (overconstraints) are counted and named by the flexures that fight; by the spec they are allowed
(monolithic hinges live with them: the cross-spring pivot has one, both leaves fixing the axial
translation) or reject the candidate. The release advice (which deformations to free to remove each
self-stress) is kept with the candidate.
"""

from __future__ import annotations

import numpy as np

from ...model.constraints import RANK_RTOL, ConstraintDiagnosis
from ...model.diagnosis import diagnose
from ...model.scene import Scene
from ...model.structure import compile_scene
from ...model.templates import template
from .grammar import GuideTopology, Topology

__all__ = ["screen_scene", "screen_topology", "screen_guide", "name_motion", "screen_key", "screen_case", "traceable"]


def _master_motion(d: ConstraintDiagnosis, v: np.ndarray) -> dict[str, np.ndarray]:
    """Column-space velocity ``v`` (of D_cc's columns, physical units) as (u, psi) per master."""
    out: dict[str, np.ndarray] = {}
    for k, m in enumerate(d.column_master):
        out.setdefault(m, np.zeros(6))
        out[m] += v[k] * d.column_direction[k]
    return out


def name_motion(d: ConstraintDiagnosis, v: np.ndarray) -> str:
    """A free motion in words: the part that moves most and how (a translation along, or rotation about,
    a unit direction), with the other parts that move."""
    blocks = _master_motion(d, v)
    L = d.characteristic_length
    size = {m: max(np.linalg.norm(b[:3]) / L, np.linalg.norm(b[3:])) for m, b in blocks.items()}
    moving = sorted((m for m in size if size[m] > 1e-6 * max(size.values())), key=lambda m: -size[m])
    m = moving[0]
    b = blocks[m]
    rot = np.linalg.norm(b[3:]) >= np.linalg.norm(b[:3]) / L
    u = b[3:] if rot else b[:3]
    u = u / np.linalg.norm(u)
    u = np.where(np.abs(u) < 1e-9, 0.0, u)
    what = "rotates about" if rot else "translates along"
    others = f" (with {', '.join(moving[1:4])}{', ...' if len(moving) > 4 else ''})" if len(moving) > 1 else ""
    return f"{m} {what} ({u[0]:+.3g}, {u[1]:+.3g}, {u[2]:+.3g}){others}"


def _allowed(d: ConstraintDiagnosis, scene: Scene, masters: list[str]) -> np.ndarray:
    """Column-space vectors (scaled like D^'s columns) of the intended motions: each master's rotation
    about the stroke axis (through the origin)."""
    if not masters or scene.stroke is None or scene.stroke.kind != "rotation":
        return np.zeros((d.n, 0))
    s = compile_scene(scene)
    axis = np.asarray(scene.stroke.axis, float)
    axis = axis / np.linalg.norm(axis)
    trans = np.array([np.linalg.norm(cd[:3]) > 0 for cd in d.column_direction])
    scale = np.where(trans, d.characteristic_length, 1.0)
    cols = []
    for m in masters:
        if m not in s.master_names:
            continue
        p = s.master_pos[s.master_names.index(m)]
        motion = np.concatenate([np.cross(axis, p), axis])  # (u, psi) of a rotation about the axis
        x = np.array([cd @ motion if cm == m else 0.0 for cd, cm in zip(d.column_direction, d.column_master)])
        cols.append(x / scale)  # x_dot = C v  ->  v = C^-1 x_dot
    return np.array(cols).T if cols else np.zeros((d.n, 0))


def screen_scene(scene: Scene, intended: list[str] | None = None, allow_overconstraints: bool = True) -> dict:
    """The exact-constraint verdict of one scene (kinematic diagnosis at the reference configuration).

    Parameters
    ----------
    scene
        The candidate (its stroke is the intended motion, held as x(m)).
    intended
        Masters (bodies or nodes) whose rotation about the stroke axis is an intended free motion (stages in
        series).
    allow_overconstraints
        Accept candidates with self-stress states.

    Returns
    -------
    dict
        ``status`` ("accepted" or "rejected"), ``reason`` (None when accepted), ``dof`` (free motions with
        the drive free: 1 + intended + unintended), ``free_motions`` (the unintended ones, named),
        ``intended_motions``, ``overconstraints`` (count), ``self_stress`` (per state: the flexures that
        fight), ``release`` (per state: deformations to release), ``classification`` (Table 1), ``m``,
        ``n``, ``rank``, ``almost_singular``, ``condition_number`` (of the scaled D_cc: how far from singular
        the constraint arrangement is; seed 002 sec. 3).
    """
    d = diagnose(scene, kinematic=True, spacar=False)  # SPACAR's own count: not needed to screen
    A = _allowed(d, scene, intended or [])
    null = d.V[:, d.rank :]  # free motions, scaled columns
    if A.shape[1]:
        Q, _ = np.linalg.qr(A)
        rest = null - Q @ (Q.T @ null)
        n_intended = int(np.linalg.matrix_rank(A, tol=1e-9))
    else:
        rest, n_intended = null, 0
    if rest.shape[1]:
        U, sv, _ = np.linalg.svd(rest, full_matrices=False)
        extra = U[:, sv > np.sqrt(RANK_RTOL)]
    else:
        extra = rest
    scale = np.where([np.linalg.norm(cd[:3]) > 0 for cd in d.column_direction], d.characteristic_length, 1.0)
    free = [name_motion(d, extra[:, j] * scale) for j in range(extra.shape[1])]
    n_free = extra.shape[1]
    missing = max(n_intended - (null.shape[1] - n_free), 0)  # an intended motion that is locked
    stress = [sorted(mode) for mode in d.static_modes]
    out = {
        "dof": 1 + null.shape[1],
        "free_motions": free,
        "intended_motions": null.shape[1] - n_free,
        "overconstraints": d.statically_indeterminate,
        "self_stress": [f"self-stress among {', '.join(els)}" for els in stress],
        "release": [list(r) for r in d.release_candidates],
        "classification": d.classification,
        "m": d.m,
        "n": d.n,
        "rank": d.rank,
        "almost_singular": d.almost_singular,
        "condition_number": d.condition_number if d.rank else None,
    }
    reason = None
    if free:
        reason = f"underconstrained: {n_free} free motion{'s' * (n_free > 1)}: " + "; ".join(free)
    elif missing:
        reason = f"{missing} intended rotation{'s' * (missing > 1)} of the intermediate parts locked"
    elif d.statically_indeterminate and not allow_overconstraints:
        reason = (
            f"overconstrained: {d.statically_indeterminate} self-stress state"
            f"{'s' * (d.statically_indeterminate > 1)} ({'; '.join(out['self_stress'])}) and the spec "
            "rejects overconstraints"
        )
    out.update(status="rejected" if reason else "accepted", reason=reason)
    return out


def screen_topology(t: Topology, allow_overconstraints: bool = True) -> dict:
    """:func:`screen_scene` of a hinge topology at its flexure level (one segment per leaf, template
    defaults for the shape: the verdict is generic in the continuous parameters)."""
    scene = template("topology-hinge", topology=str(t), flexure_level=1, segments=1)
    return screen_scene(scene, t.intermediate_masters, allow_overconstraints)


def screen_guide(g: GuideTopology, allow_overconstraints: bool = True) -> dict:
    """:func:`screen_scene` of a wire guide (template ``wire-guide-topology``, one segment per wire). A guide
    of fewer than five wires is rejected by counting, without a diagnosis: each wire fixes at most one of the
    five motions besides the stroke."""
    if g.flexures < 5:
        n = 5 - g.flexures
        return {
            "dof": 1 + n,
            "free_motions": [],
            "intended_motions": 0,
            "overconstraints": None,
            "self_stress": [],
            "release": [],
            "classification": None,
            "m": None,
            "n": None,
            "rank": None,
            "almost_singular": None,
            "condition_number": None,
            "status": "rejected",
            "reason": f"underconstrained: {g.flexures} wires fix at most {g.flexures} of "
            f"the 5 motions besides the stroke (at least {n} free)",
        }
    scene = template("wire-guide-topology", topology=str(g), segments=1)
    return screen_scene(scene, [], allow_overconstraints)


def screen_key(t: Topology) -> str:
    """The descriptor whose verdict ``t`` shares: ``t`` without its designed crossing ('@') and reinforcement
    ('r'). At the flexure level the screen sees (one segment per leaf at the template's defaults) these give
    the same scene: the default crossing fraction is the midpoint, and a reinforced leaf is condensed into
    its flexure."""
    return "R:" + str(t)[2:].replace("@", "").replace("r", "")


def traceable(descriptor: str, dimensions: str) -> str | None:
    """None when the candidate's scene can be traced with CasADi symbols in its design parameters (under
    ``dimensions``), else why not. Traced at the template's defaults, a per-stage or per-leaf parameter at
    its stage 1 counterpart's default (its own default 0 means "inherited")."""
    from ...model.design import trace_template
    from ...model.errors import FlexoptError
    from ...model.templates import TEMPLATES
    from .grammar import design_parameters, parse

    defaults = TEMPLATES["topology-hinge"][1]
    names = design_parameters(parse(descriptor), dimensions)
    params: dict = {"topology": descriptor, "segments": 2}
    for k in names:
        if defaults[k] == 0:
            params[k] = defaults[k.split("_s")[0]]
    try:
        trace_template("topology-hinge", params, names)
    except (FlexoptError, ValueError, RuntimeError) as exc:  # casadi raises RuntimeError
        return f"cannot be traced for exact design gradients: {exc}"
    return None


def screen_case(case: dict) -> dict:
    """A batch case of the screen (:func:`optim.batch.run_cases`): ``{"descriptors": [...],
    "allow_overconstraints": bool}`` -> ``{"verdicts": {descriptor: screen_topology's dict}}``; with
    ``"members": {descriptor: [candidates sharing its verdict]}`` and ``"dimensions"``, also
    ``"untraceable": {candidate: reason}`` for the members of accepted descriptors that cannot be traced
    (:func:`traceable`)."""
    from .grammar import parse

    allow = bool(case.get("allow_overconstraints", True))
    verdicts = {d: screen_topology(parse(d), allow) for d in case["descriptors"]}
    out: dict = {"verdicts": verdicts}
    if "members" in case:
        out["untraceable"] = {}
        for d, members in case["members"].items():
            if verdicts[d]["status"] == "accepted":
                for m in members:
                    why = traceable(m, case["dimensions"])
                    if why:
                        out["untraceable"][m] = why
    return out
