"""``diagnose(scene)``: the exact-constraint diagnosis of a scene (seed 002, section 3), one floor above the
rows, columns and SVD conventions of :mod:`model.constraints` (see its docstring) and, for a diagnosis at a
stroke value, the equilibrium of the curve pipeline (:class:`model.curve.Analysis`).
"""

from __future__ import annotations

import numpy as np

from .checks import annotate_diagnosis
from .constraints import (
    NEAR_RTOL,
    RANK_RTOL,
    ConstraintDiagnosis,
    columns,
    jacobian_rows,
    numerical_rank,
    partition,
    sign_fix,
    split_label,
)
from .curve import Analysis
from .errors import EquilibriumError, SceneError
from .scene import Beam, Scene
from .statics import walk
from .structure import Structure, compile_scene
from .threads import limited

__all__ = ["diagnose"]


def _state_at(scene: Scene, at_stroke: float) -> tuple[np.ndarray, np.ndarray]:
    """Master positions and rotations of the equilibrium at ``at_stroke`` (stroke unit)."""
    if scene.stroke is None:
        raise SceneError(
            "stroke",
            "a diagnosis at a stroke value needs a 'stroke' in the scene; omit "
            "--at-stroke to diagnose the reference configuration",
        )
    an = Analysis(scene)
    target = float(scene.stroke.to_internal(at_stroke))
    got: list = []
    targets = np.linspace(0.0, target, 9)[1:] if target != 0 else np.array([0.0])

    def accept(eq):  # noqa: ANN001, ANN202 - statics callback
        got.append(eq)
        return None

    fail = walk(an.system, targets, an.options, accept)
    if fail is not None or not got:
        raise EquilibriumError(
            f"no equilibrium at stroke {at_stroke:g}: {fail.message if fail else ''}",
            stroke=at_stroke,
            last_converged=float("nan"),
            reason=fail.reason if fail else "divergence",
        )
    st = got[-1].state
    return st.X, st.R


def _kinematic(scene: Scene, kinematic: bool | None) -> tuple[bool, list[str]]:
    """Whether the diagnosis is kinematic (section 4.2), and the note that says why when it was chosen for
    the scene."""
    kin = scene.kinematic if kinematic is None else bool(kinematic)
    if kinematic is None and not kin and not any(e.rigid or e.generalised for e in scene.elements):
        return True, [
            "kinematic idealisation used: the scene declares no rigid or generalised deformation, so "
            "each flexure keeps only its compliant deformations (kinematic_rigid; seed 002 sec. 4.2); "
            "--declared (kinematic=false) diagnoses the declared partition instead"
        ]
    return kin, []


def _one_flexure_per_beam(scene: Scene, full: Structure) -> tuple[Structure, list[str]]:
    """The structure with every meshed beam as one segment (``full`` when none is meshed), and the note."""
    flex = scene.model_copy(
        update={
            "elements": tuple(
                e.model_copy(update={"segments": 1}) if isinstance(e, Beam) and e.segments != 1 else e
                for e in scene.elements
            )
        }
    )
    if flex.elements == scene.elements:
        return full, []
    s = compile_scene(flex)
    n_inner = len(full.master_names) - len(s.master_names)
    return s, [
        f"each meshed beam is diagnosed as one flexure: {n_inner} segment-internal nodes condensed, "
        "so motions are those of bodies and flexure ends"
    ]


def _kinematic_modes(s: Structure, V: np.ndarray, T: np.ndarray, rank: int, col_masters: list[str]) -> list[dict]:
    """Kinematic modes (eq. 15): the columns of V beyond the rank, as each master's translation and rotation."""
    ncount = V.shape[1]
    out = []
    dirs = T.T.reshape(ncount, -1, 6)  # (n, nm, 6)
    for j in range(rank, ncount):
        v = sign_fix(V[:, j])
        blk = np.einsum("c,cmk->mk", v, dirs)
        mode: dict[str, dict[str, list[float]]] = {}
        for mi, name in enumerate(s.master_names):
            if name in col_masters:
                b = np.where(np.abs(blk[mi]) < 1e-12, 0.0, blk[mi])
                mode[name] = {"translation": [float(x) for x in b[:3]], "rotation": [float(x) for x in b[3:]]}
        out.append(mode)
    return out


def _static_modes(
    U: np.ndarray, rank: int, row_parts: list[tuple[str, str]], row_labels: list[str]
) -> tuple[list[dict], list[tuple[str, ...]]]:
    """Static modes (eq. 15): the columns of U beyond the rank per element and deformation, and for each the
    rows that carry at least half its largest entry (release candidates, at most 12)."""
    stat_modes = []
    releases = []
    for j in range(rank, U.shape[0]):
        u = sign_fix(U[:, j])
        mode2: dict[str, dict[str, float]] = {}
        for (el, dname), val in zip(row_parts, u):
            if abs(val) >= 1e-12:
                mode2.setdefault(el, {})[dname] = float(val)
        stat_modes.append(mode2)
        order = np.argsort(-np.abs(u), kind="stable")
        # at least half the largest entry; a tie at exactly half (a geometric ratio of 1/2, as in
        # wire-guide-parallel) counts, within round-off, rather than falling either way by the last bit
        big = [row_labels[i] for i in order if abs(u[i]) >= 0.5 * abs(u[order[0]]) * (1 - 1e-9)]
        releases.append(tuple(big[:12]))
    return stat_modes, releases


def _configuration(
    scene: Scene, s: Structure, full: Structure, at_stroke: float | None
) -> tuple[np.ndarray, np.ndarray]:
    """Positions and rotations of ``s``'s masters: the reference configuration, or the equilibrium at
    ``at_stroke`` (solved on the ``full`` structure, its masters that ``s`` keeps)."""
    if at_stroke is None:
        return s.master_pos.copy(), np.tile(np.eye(3), (len(s.master_names), 1, 1))
    Xf, Rf = _state_at(scene, at_stroke)
    keep = [full.master_names.index(m) for m in s.master_names]
    return Xf[keep], Rf[keep]


def _scaled_svd(
    scene: Scene, D: np.ndarray, trans: np.ndarray
) -> tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """The characteristic length (the largest distance between scene nodes), D scaled by it (eq. 11), its SVD
    (U, singular values, V) and rank."""
    pos = np.array([n.position for n in scene.nodes], dtype=float)
    Lc = float(np.sqrt(((pos[:, None, :] - pos[None, :, :]) ** 2).sum(-1).max()))
    c = np.where(trans, Lc, 1.0)
    Dh = D * c / Lc
    U, sv, Vt = np.linalg.svd(Dh)
    rank = numerical_rank(sv)
    return Lc, Dh, U, sv, Vt.T, rank


def _spacar(scene: Scene, spacar_text: str | None) -> dict:
    """SPACAR's own count and D_cc (:mod:`model.spacar_dcc`): of ``spacar_text`` (the imported file) or of the
    scene's SPACAR model with one beam element per member; what stops it, said."""
    from .spacar import spacar_dcc_of_scene
    from .spacar_dcc import spacar_dcc

    try:
        if spacar_text is not None:
            got = spacar_dcc(spacar_text).to_dict()
            got["model"] = "the imported .dat file"
            return got
        one = scene.model_copy(
            update={
                "elements": tuple(
                    e.model_copy(update={"segments": 1}) if isinstance(e, Beam) else e for e in scene.elements
                )
            }
        )
        got = spacar_dcc_of_scene(one).to_dict()
        got["model"] = (
            "the scene as model.spacar.write_dat writes it, each member one beam element, the surplus dynamic "
            "deformations released (RLSE, still elastic) as write_dat does (flexopt export --to dat writes the "
            "members' segments: the same verdict, its own size and condition number)"
        )
        return got
    except SceneError as exc:
        return {"available": False, "why": str(exc)}


@limited()  # one BLAS thread while it computes (model.threads)
def diagnose(
    scene: Scene,
    at_stroke: float | None = None,
    kinematic: bool | None = None,
    spacar: bool = True,
    spacar_text: str | None = None,
) -> ConstraintDiagnosis:
    """Exact-constraint diagnosis of a scene (seed 002, section 3).

    Parameters
    ----------
    scene
        A validated scene (``stroke`` may be null: then no x(m)).
    at_stroke
        Stroke value (stroke unit) of the equilibrium to diagnose; None = the reference configuration.
    kinematic
        Use the kinematic idealisation (section 4.2); None = the scene's ``kinematic`` flag.
    spacar
        Also report SPACAR's degrees of freedom and the condition number of D_cc by SPACAR's definition
        (:mod:`model.spacar_dcc`; at the reference configuration, whatever ``at_stroke``).
    spacar_text
        The ``.dat`` text the scene was imported from: SPACAR's count is then that file's.

    Returns
    -------
    ConstraintDiagnosis
        D_cc (eq. 9), the SVD of its scaled form (eq. 11), the Table-1 counts, kinematic modes from V and
        static modes from U (eq. 15).

    Raises
    ------
    SceneError
        When the partition has no rows (every deformation released and none generalised) or no columns
        (every coordinate supported or driven), or a deformation is both rigid and generalised.
    """
    kin, notes = _kinematic(scene, kinematic)
    full = compile_scene(scene)
    s, note = _one_flexure_per_beam(scene, full)
    notes += note
    rows, row_labels, row_kind, n_rigid = partition(s, kin)
    row_parts = [split_label(s, r, lab) for r, lab in zip(rows, row_labels)]
    if not rows:
        raise SceneError(
            "elements[].rigid",
            "no rigid and no generalised deformations: D_cc has no rows, so "
            "nothing constrains the structure; declare rigid deformations (e.g. "
            "rigid: ['elongation'] for a wire) or set 'kinematic': true",
        )
    T, col_labels, col_masters, trans = columns(s)
    if T.shape[1] == 0:
        raise SceneError(
            "supports",
            "every nodal coordinate is supported or driven: D_cc has no columns; remove supports from the moving parts",
        )
    X, R = _configuration(scene, s, full, at_stroke)
    Dfull = jacobian_rows(s, X, R, rows)
    D = Dfull @ T
    Lc, Dh, U, sv, V, rank = _scaled_svd(scene, D, trans)
    mcount, ncount = D.shape
    kin_modes = _kinematic_modes(s, V, T, rank, col_masters)
    stat_modes, releases = _static_modes(U, rank, row_parts, row_labels)
    diag = ConstraintDiagnosis(
        scene=scene.name,
        stroke=at_stroke,
        kinematic=kin,
        rows=tuple(row_labels),
        row_kind=tuple(row_kind),
        columns=tuple(col_labels),
        column_master=tuple(col_masters),
        column_direction=np.array(
            [T[6 * s.master_names.index(mn) : 6 * s.master_names.index(mn) + 6, k] for k, mn in enumerate(col_masters)]
        ).reshape(ncount, 6),
        D_cc=D,
        D_scaled=Dh,
        characteristic_length=Lc,
        singular_values=sv,
        U=U,
        V=V,
        rank=rank,
        n_generalised_coordinates=0 if s.drive_kind == "none" else 1,
        n_rigid=n_rigid,
        kinematic_modes=tuple(kin_modes),
        static_modes=tuple(stat_modes),
        release_candidates=tuple(releases),
        notes=tuple(notes),
        spacar=_spacar(scene, spacar_text) if spacar else None,
    )
    settings = {"at_stroke": at_stroke, "kinematic": kin, "rank_rtol": RANK_RTOL, "almost_singular_rtol": NEAR_RTOL}
    return annotate_diagnosis(diag, scene, settings)  # scene checks and provenance (model.checks)
