"""Design sensitivities: exact derivatives of stroke-point frequencies and stresses with respect to the
named parameters of a template.

Chain of exact derivatives (no finite differences anywhere):

1. *Template -> scene numbers.* The template function is called with CasADi symbols for the design
   parameters (templates use casadi's scalar maths, which also accepts floats), and every number of the
   scene dictionary is differentiated by ``ca.jacobian``: ``dS/dp``, one scene-shaped dictionary per
   parameter.
2. *Scene -> structure arrays.* Each beam segment's constants, mass and rotary inertia come from
   :func:`model.elements.beam_segment_design`, the same formulas ``compile_scene`` evaluates, with their
   exact Jacobian; node positions are linear in the scene's (interior mesh nodes ``p + (q - p) i/n``).
3. *Structure -> equilibrium.* At an equilibrium ``g(xi, p) = 0`` with the drive prescribed, the implicit
   function theorem gives ``(H + C)_ff dxi_f = -dg_f/dp`` (``C`` the chart term of the exact Newton
   Jacobian, :meth:`model.assembly.System.chart_correction`), where ``dg/dp`` at a fixed state is the
   derivative of the element gradients along the change of their packed inputs (constants, reference
   offsets, supported positions), from :func:`model.elements.beam_input_jvp`.
4. *Equilibrium -> eigenvalues.* The kernels' inputs are absolute (positions, rotation matrices) and their
   Hessian is taken in the chart at that state, so ``dK/dp`` is one directional derivative of the
   element Hessians along the *total* input change (design plus the equilibrium's move ``dxi``: node
   ``dx = u + psi x r``, ``dR = [psi] R``), and ``dM/dp`` differentiates the mass formulas of
   :meth:`model.assembly.System.mass` term by term. For a mass-normalised mode,
   ``d lambda = phi^T (dK - lambda dM) phi``. A (nearly) repeated eigenvalue (relative gap below
   ``cluster_gap``) gets the derivative of the cluster's mean, ``trace(Phi^T (dK - lambda dM) Phi)/k``:
   exact for the mean, and exact for every member while the pair stays degenerate, as it does by
   symmetry in the symmetric hinges; never a division by the gap.
5. *Stresses.* ``d sigma = dS eps + S d eps`` with ``d eps`` from the same directional derivative, through
   the square of the von Mises bound, :func:`model.elements.beam_von_mises_squared`, and its CasADi
   Jacobian: finite everywhere, also where the stress vanishes (the root's gradient is ``0/0`` there).
   ``d vm = d(vm^2) / (2 vm)`` where ``vm > 0``.

6. *Loads.* Dead forces and gravity (model.loads) enter the same way: their generalised gradient changes with
   the design at a fixed state (a body's weight with its mass, a beam segment's with its mass and length, a
   force with its point's offset and its value) and their Hessian along the total input change; both are
   CasADi directional derivatives of the load kernels (:func:`model.elements.load_jvp_spec`).

Scope: beams with rectangular sections and rigid bodies (what the hinge families are made of), without
rigid deformations (no multipliers), with dead forces and gravity; follower loads and moments
(non-conservative: an unsymmetric stiffness, whose eigenvalue derivatives need left eigenvectors) are not
covered. Other scenes get a clear error.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, overload

import casadi as ca
import numpy as np
import scipy.linalg as sla

from . import elements as _el
from .analysis import beam_sigma
from .assembly import System
from .errors import FlexoptError
from .kernels import compiled
from .loads import LoadSet
from .modal import Modes
from .rotations import skew
from .scene import Beam, RectangularSection, Scene
from .statics import Equilibrium
from .structure import Structure
from .templates import TEMPLATES, template

__all__ = [
    "DesignScene",
    "trace_template",
    "StructureDerivative",
    "structure_derivative",
    "structure_derivatives",
    "PointSensitivity",
    "point_sensitivity",
]


# ----------------------------------------------------------------------------- 1. template -> scene
@dataclass(frozen=True)
class DesignScene:
    """A template evaluated at a design, with the derivative of its scene numbers."""

    name: str
    design: tuple[str, ...]  # design parameter names, in gradient order
    values: np.ndarray  # (np,) their values
    params: dict  # all template parameters
    scene: Scene
    scene_dict: dict  # the template's scene dictionary (numbers)
    dscene: tuple[dict, ...]  # per design parameter: the scene dictionary's derivative (same shape)


def _leaves(obj, out: list) -> None:
    if isinstance(obj, dict):
        for v in obj.values():
            _leaves(v, out)
    elif isinstance(obj, (list, tuple)):
        for v in obj:
            _leaves(v, out)
    elif isinstance(obj, ca.SX) or (isinstance(obj, (int, float)) and not isinstance(obj, bool)):
        out.append(obj)


def _rebuild(obj, it):
    if isinstance(obj, dict):
        return {k: _rebuild(v, it) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_rebuild(v, it) for v in obj]
    if isinstance(obj, ca.SX) or (isinstance(obj, (int, float)) and not isinstance(obj, bool)):
        return float(next(it))
    return obj


def _rebuild_many(obj, rows, n: int) -> list:
    """``n`` copies of ``obj`` with its numbers (:func:`_leaves` order) replaced: copy ``j`` takes column ``j`` of
    the row each number draws from ``rows`` (the same as ``n`` calls of :func:`_rebuild`, one per column, in
    one walk of the nested dictionary instead of ``n``)."""
    if isinstance(obj, dict):
        parts = [(k, _rebuild_many(v, rows, n)) for k, v in obj.items()]
        return [{k: p[j] for k, p in parts} for j in range(n)]
    if isinstance(obj, (list, tuple)):
        items = [_rebuild_many(v, rows, n) for v in obj]
        return [[p[j] for p in items] for j in range(n)]
    if isinstance(obj, ca.SX) or (isinstance(obj, (int, float)) and not isinstance(obj, bool)):
        return next(rows).tolist()
    return [obj] * n


def trace_template(name: str, params: dict, design: Sequence[str], extra: dict | None = None) -> DesignScene:
    """Evaluate template ``name`` at ``params`` and differentiate its scene with respect to ``design``.

    ``extra``: scene fields added to the template's scene, constant in the design (e.g. ``{"gravity": [0, 0,
    -9.81], "loads": [...]}``: a payload's weight or a preload; their derivatives are zero).

    Raises
    ------
    SceneError
        Unknown template or parameter, or an invalid scene.
    """
    fn, defaults = TEMPLATES[name] if name in TEMPLATES else (None, None)
    scene = template(name, **params)  # validates names and values with the template's own errors
    assert fn is not None and defaults is not None
    full = dict(defaults)
    full.update(params)
    for k in design:
        if k not in full:
            raise FlexoptError(
                f"design.{k}: template '{name}' has no parameter '{k}'; its parameters are {sorted(full)}"
            )
    values = np.array([float(full[k]) for k in design])
    jac = _scene_jacobian(name, fn, full, tuple(design))
    numeric = fn(full)
    J = jac(values).full()
    dscene = tuple(_rebuild_many(numeric, iter(J), len(design))) if len(design) else ()
    if extra:
        from .io import scene_from_dict

        numeric = {**numeric, **extra}
        scene = scene_from_dict(numeric)
        zeros = _zeros(extra)
        dscene = tuple({**d, **zeros} for d in dscene)
    return DesignScene(name, tuple(design), values, full, scene, numeric, dscene)


#: the traced scene Jacobians kept (least recently used dropped past it): one per template, fixed parameters and
#: design names, so that the evaluations of one candidate (a search's case: tens of designs of one topology)
#: trace its template once; a process that meets many candidates (a topology search's worker) keeps this many
SCENE_JAC_ENTRIES = 32
_SCENE_JAC: OrderedDict[tuple, ca.Function] = OrderedDict()


def _scene_jacobian(name: str, fn, full: dict, design: tuple[str, ...]) -> ca.Function:
    """The Jacobian of template ``name``'s scene numbers (in :func:`_leaves` order) with respect to ``design``,
    as a function of the design values: the template traced with CasADi symbols for the design parameters
    and the other parameters at ``full``'s values. The trace is the same expression whatever the design values
    (a template cannot branch on a symbol), so it is kept per (template, other parameters, design names) and
    evaluated at each design: the same numbers as tracing again (measured: 11 of a trace's 16-19 ms on the
    3-stage hinges)."""
    key = (name, design, repr(sorted((k, v) for k, v in full.items() if k not in design)))
    jac = _SCENE_JAC.get(key)
    if jac is not None:
        _SCENE_JAC.move_to_end(key)
        return jac
    sym = ca.SX.sym("p", len(design))
    traced = dict(full)
    for i, k in enumerate(design):
        traced[k] = sym[i]
    leaves: list = []
    _leaves(fn(traced), leaves)
    jac = _SCENE_JAC[key] = ca.Function("dscene", [sym], [ca.jacobian(ca.vertcat(*[ca.SX(v) for v in leaves]), sym)])
    while len(_SCENE_JAC) > SCENE_JAC_ENTRIES:
        _SCENE_JAC.popitem(last=False)
    return jac


def _zeros(obj):
    """``obj`` with every number replaced by 0.0 (the derivative of constants)."""
    if isinstance(obj, dict):
        return {k: _zeros(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_zeros(v) for v in obj]
    return 0.0 if isinstance(obj, (int, float)) and not isinstance(obj, bool) else obj


# ------------------------------------------------------------------------- 2. scene -> structure
@dataclass(frozen=True)
class StructureDerivative:
    """Derivative of the design-dependent arrays of a :class:`Structure` along one design direction."""

    beam_const: np.ndarray  # (nb, 23); the mask entries are 0
    beam_mass: np.ndarray  # (nb,)
    beam_stress: np.ndarray  # (nb, 7)
    node_rot_inertia: np.ndarray  # (nn, 3, 3)
    node_offset: np.ndarray  # (nn, 3) reference offsets from the masters
    master_pos: np.ndarray  # (nm, 3) reference positions of the masters
    master_mass: np.ndarray  # (nm,)
    master_inertia: np.ndarray  # (nm, 3, 3)
    loads: tuple[dict, ...] = ()  # the scene loads' derivative dictionaries (model.loads), in scene order
    gravity: np.ndarray | None = None  # (3,) derivative of the gravity vector


def _check_scope(s: Structure) -> None:
    bad = [e.name for e in s.scene.elements if not (isinstance(e, Beam) and isinstance(e.section, RectangularSection))]
    if bad or len(s.constraints):
        what = (
            f"elements {bad} are not beams with rectangular sections"
            if bad
            else "some deformations are rigid (multipliers)"
        )
        raise FlexoptError(
            f"design sensitivities cover beams with rectangular sections and rigid bodies "
            f"without rigid deformations; in scene '{s.scene.name}' {what}: optimise a "
            "family built from rectangular leaves and bodies"
        )
    bad_loads = [ld.describe(i) for i, ld in enumerate(s.scene.loads) if not ld.conservative]
    if bad_loads:
        # an unsymmetric stiffness: eigenvalue derivatives need left eigenvectors, and complex pairs have none
        raise FlexoptError(
            f"design sensitivities cover dead forces and gravity; scene '{s.scene.name}' has the "
            f"non-conservative load(s) {', '.join(bad_loads)}: optimise without them, or check the design by "
            "frequency curves"
        )


def _segment_input(scene_dict: dict, ie: int, pos: dict, mats: dict) -> tuple[np.ndarray, float, str]:
    el = scene_dict["elements"][ie]
    sec = el["section"]
    m = mats[el["material"]]
    p, q = el["nodes"]
    x = np.concatenate(
        [
            pos[p],
            pos[q],
            np.asarray(el["y_axis"], float),
            [sec["width"], sec["thickness"], m["E"], m["G"], m["density"]],
        ]
    ).astype(float)
    return x, float(el.get("segments", 1)), sec.get("warping", "free")


def _segment_jacobians(s: Structure, scene_dict: dict) -> dict[int, np.ndarray]:
    """Per beam element of ``scene_dict``: the Jacobian of its segments' formulas
    (:func:`model.elements.beam_segment_design`) at the element's inputs, the same for every design direction."""
    pos = {n["name"]: np.asarray(n["position"], float) for n in scene_dict["nodes"]}
    mats = {m["name"]: m for m in scene_dict["materials"]}
    out = {}
    for ie in np.unique(s.beam_member):
        x, n, warping = _segment_input(scene_dict, int(ie), pos, mats)
        out[int(ie)] = np.asarray(_el.beam_segment_design(warping)(x, n)[1])
    return out


def structure_derivatives(s: Structure, scene_dict: dict, dscenes: Sequence[dict]) -> list[StructureDerivative]:
    """:func:`structure_derivative` along each of ``dscenes`` (a :class:`DesignScene`'s ``dscene``), the segment
    formulas' Jacobians evaluated once for all of them instead of once per direction."""
    _check_scope(s)
    jacobians = _segment_jacobians(s, scene_dict)
    plan = _node_plan(s, scene_dict)
    return [structure_derivative(s, scene_dict, d, jacobians, plan) for d in dscenes]


def _node_plan(s: Structure, scene_dict: dict) -> tuple[np.ndarray, ...]:
    """Where each structure node's position derivative comes from, the same for every design direction: the
    nodes that are scene nodes (``at``, their scene index ``src``) and the interior mesh nodes ``element#i``
    (``mid``) at ``p + (q - p) i / n`` (scene indices ``a``, ``b``; ``i`` and ``n`` as floats)."""
    index = {n["name"]: j for j, n in enumerate(scene_dict["nodes"])}
    el_index = {e["name"]: i for i, e in enumerate(scene_dict["elements"])}
    at, src, mid, a, b, i, n = [], [], [], [], [], [], []
    for k, name in enumerate(s.node_names):
        if name in index:
            at.append(k)
            src.append(index[name])
        else:
            el_name, seg = name.rsplit("#", 1)
            el = scene_dict["elements"][el_index[el_name]]
            mid.append(k)
            a.append(index[el["nodes"][0]])
            b.append(index[el["nodes"][1]])
            i.append(float(int(seg)))
            n.append(float(int(el["segments"])))
    ints = [np.array(v, dtype=np.int64) for v in (at, src, mid, a, b)]
    return (*ints, np.array(i, dtype=float)[:, None], np.array(n, dtype=float)[:, None])


def structure_derivative(
    s: Structure,
    scene_dict: dict,
    dscene: dict,
    jacobians: dict[int, np.ndarray] | None = None,
    plan: tuple[np.ndarray, ...] | None = None,
) -> StructureDerivative:
    """Derivative of the structure arrays of ``scene_dict`` along ``dscene`` (see :class:`DesignScene`);
    ``jacobians``: :func:`_segment_jacobians` and ``plan``: :func:`_node_plan` of ``scene_dict`` when the caller
    has them."""
    _check_scope(s)
    if jacobians is None:
        jacobians = _segment_jacobians(s, scene_dict)
    if plan is None:
        plan = _node_plan(s, scene_dict)
    dpos = {n["name"]: np.asarray(d["position"], float) for n, d in zip(scene_dict["nodes"], dscene["nodes"])}
    dmats = {m["name"]: d for m, d in zip(scene_dict["materials"], dscene["materials"])}
    nb, nn, nm = s.n_beams, len(s.node_names), len(s.master_names)

    # node positions: scene nodes, then interior mesh nodes "element#i" at p + (q - p) i / n (the same
    # arithmetic, row by row, as one node at a time)
    dnode = np.zeros((nn, 3))
    at, src, mid, ia, ib, seg, nseg = plan
    P = np.array([d["position"] for d in dscene["nodes"]], dtype=float).reshape(-1, 3)
    dnode[at] = P[src]
    dnode[mid] = P[ia] + (P[ib] - P[ia]) * seg / nseg
    bodies = scene_dict.get("bodies", []) or []
    dbodies = dscene.get("bodies", []) or []
    dmaster = np.zeros((nm, 3))
    dmass = np.zeros(nm)
    dJ = np.zeros((nm, 3, 3))
    for i, db in enumerate(dbodies[: len(bodies)]):
        dmaster[i] = np.asarray(db["center_of_mass"], float)
        dmass[i] = float(db["mass"])
        dJ[i] = np.asarray(db["inertia"], float)
    own = s.node_master >= len(bodies)
    dmaster[s.node_master[own]] = dnode[own]
    doffset = dnode - dmaster[s.node_master]

    dconst = np.zeros((nb, _el.BEAM_CONST))
    dbmass = np.zeros(nb)
    dstress = np.zeros((nb, 7))
    drot = np.zeros((nb, 3, 3))
    for ie in np.unique(s.beam_member):
        rows = np.flatnonzero(s.beam_member == ie)
        el = dscene["elements"][ie]
        p, q = scene_dict["elements"][ie]["nodes"]
        dm = dmats[scene_dict["elements"][ie]["material"]]
        dx = np.concatenate(
            [
                dpos[p],
                dpos[q],
                np.asarray(el["y_axis"], float),
                [el["section"]["width"], el["section"]["thickness"], dm["E"], dm["G"], dm["density"]],
            ]
        ).astype(float)
        d = jacobians[int(ie)] @ dx
        dconst[rows, :15] = d[:15]
        dbmass[rows] = d[15]
        drot[rows] = d[16:25].reshape(3, 3, order="F")
        dstress[rows] = d[25:32]
    dnrot = np.zeros((nn, 3, 3))
    np.add.at(dnrot, s.beam_nodes[:, 0], drot)
    np.add.at(dnrot, s.beam_nodes[:, 1], drot)
    dloads = tuple(dscene.get("loads", []) or [])
    dgrav = np.asarray(dscene["gravity"], float) if dscene.get("gravity") is not None else np.zeros(3)
    return StructureDerivative(dconst, dbmass, dstress, dnrot, doffset, dmaster, dmass, dJ, dloads, dgrav)


# --------------------------------------------------------------------- 3-5. equilibrium, modes, stress
@dataclass(frozen=True)
class PointSensitivity:
    """Derivatives at one equilibrium along each design direction."""

    dlam: np.ndarray  # (np, k) d lambda_i / dp of the given modes [1/s^2 per parameter unit]
    dvm: np.ndarray  # (np, nb, 2) d(von Mises at each segment end) / dp [Pa per parameter unit]; NaN where vm = 0
    vm: np.ndarray  # (nb, 2) von Mises at each segment end [Pa]
    dvm2: np.ndarray  # (np, nb, 2) d(vm^2) / dp [Pa^2 per parameter unit]: finite everywhere
    dxi: np.ndarray  # (np, n) move of the equilibrium (drive basis)
    dreaction: np.ndarray  # (np,) derivative of the actuator's force or moment along the drive


class _Frame:
    """What every design direction at one equilibrium shares: the masters' rotations and offsets per node and
    the beam kernels' inputs at the state, computed once per point instead of once per direction."""

    def __init__(self, sys: System, st) -> None:
        s = sys.s
        self.sys, self.st = sys, st
        self.m = s.node_master
        _, self.Rm, self.r = sys.node_states(st)
        self.p, self.q = s.beam_nodes[:, 0], s.beam_nodes[:, 1]
        sys.fill_inputs(st)
        self.beam_in = sys.beam_in.copy()


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise ``a x b`` of (n, 3) arrays, the same products and differences as ``np.cross`` (so the same
    rounding) without its axis handling, which costs more than the arithmetic at these sizes."""
    out = np.empty(a.shape)
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return out


def _beam_inputs_change(fr: _Frame, u: np.ndarray, psi: np.ndarray, dr0: np.ndarray) -> np.ndarray:
    """Change of the beams' state inputs for master moves ``u``, rotations ``psi`` (nm, 3) and reference
    offset changes ``dr0`` (nn, 3); positions of prescribed masters are in ``u``."""
    m, Rm, p, q = fr.m, fr.Rm, fr.p, fr.q
    pm = psi[m]
    dr = _cross(pm, fr.r) + np.einsum("nij,nj->ni", Rm, dr0)
    dx = u[m] + dr
    dR = skew(pm) @ Rm
    out = np.zeros((len(p), _el.BEAM_STATE))
    out[:, 0:3], out[:, 12:15], out[:, 15:18], out[:, 27:30] = dx[p], dr[p], dx[q], dr[q]
    out[:, 3:12] = dR[p].transpose(0, 2, 1).reshape(-1, 9)
    out[:, 18:27] = dR[q].transpose(0, 2, 1).reshape(-1, 9)
    return out


def _beam_inputs_change_many(fr: _Frame, u: np.ndarray, psi: np.ndarray, dr0: np.ndarray) -> np.ndarray:
    """:func:`_beam_inputs_change` for D directions at once: ``u``, ``psi`` (D, nm, 3), ``dr0`` (D, nn, 3) ->
    (D, nb, BEAM_STATE)."""
    m, Rm, p, q, r = fr.m, fr.Rm, fr.p, fr.q, fr.r
    pm = psi[:, m]
    dr = np.empty(pm.shape)
    dr[..., 0] = pm[..., 1] * r[:, 2] - pm[..., 2] * r[:, 1]
    dr[..., 1] = pm[..., 2] * r[:, 0] - pm[..., 0] * r[:, 2]
    dr[..., 2] = pm[..., 0] * r[:, 1] - pm[..., 1] * r[:, 0]
    dr += np.einsum("nij,dnj->dni", Rm, dr0)
    dx = u[:, m] + dr
    dR = skew(pm) @ Rm
    D = len(psi)
    out = np.zeros((D, len(p), _el.BEAM_STATE))
    out[..., 0:3], out[..., 12:15], out[..., 15:18], out[..., 27:30] = dx[:, p], dr[:, p], dx[:, q], dr[:, q]
    out[..., 3:12] = dR[:, p].transpose(0, 1, 3, 2).reshape(D, -1, 9)
    out[..., 18:27] = dR[:, q].transpose(0, 1, 3, 2).reshape(D, -1, 9)
    return out


def _jvp_kernel_many(fr: _Frame, da_state: np.ndarray, dconst: np.ndarray, hessian: bool) -> np.ndarray:
    """:func:`_jvp_kernel` for D directions in one call: ``da_state`` (D, nb, BEAM_STATE), ``dconst`` (D, nb,
    BEAM_CONST) -> (D, nb, outputs)."""
    a = fr.beam_in
    D, nb = da_state.shape[:2]
    x = np.zeros((D, nb, 2 * a.shape[1]))
    x[:, :, : a.shape[1]] = a
    x[:, :, a.shape[1] : a.shape[1] + _el.BEAM_STATE] = da_state
    x[:, :, a.shape[1] + _el.BEAM_STATE : a.shape[1] + _el.BEAM_STATE + _el.BEAM_CONST] = dconst
    spec = _el.beam_jvp_spec() if hessian else _el.beam_jvp_gradient_spec()
    return compiled(spec)(x.reshape(D * nb, -1)).reshape(D, nb, -1)


@overload
def _jvp(
    fr: _Frame, da_state: np.ndarray, dconst: np.ndarray, hessian: Literal[True] = ...
) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...
@overload
def _jvp(
    fr: _Frame, da_state: np.ndarray, dconst: np.ndarray, hessian: Literal[False]
) -> tuple[np.ndarray, None, None]: ...
def _jvp(
    fr: _Frame, da_state: np.ndarray, dconst: np.ndarray, hessian: bool = True
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Assembled ``dg`` (n), ``dH`` (n, n) and per-beam ``de`` (nb, 6) along a change of the beam inputs;
    with ``hessian=False`` only ``dg`` (the cheaper kernel), ``None`` for the others."""
    sys = fr.sys
    N = sys.N
    out = _jvp_kernel(fr, da_state, dconst, hessian)
    g = sys.reduce_vector(np.bincount(sys.beam_dofs.ravel(), out[:, :12].ravel(), minlength=N))
    if not hessian:
        return g, None, None
    H = np.bincount(sys.beam_flat, out[:, 12:156].ravel(), minlength=N * N).reshape(N, N)
    return g, sys.reduce_matrix(H), out[:, 156:162]


def _jvp_kernel(fr: _Frame, da_state: np.ndarray, dconst: np.ndarray, hessian: bool) -> np.ndarray:
    """The beam kernel's directional derivative along a change of the beam inputs, per beam: ``dg`` (12, at
    ``sys.beam_dofs``), with ``hessian`` then ``dH`` (144, at ``sys.beam_flat``) and ``de`` (6)."""
    a = fr.beam_in
    da = np.zeros_like(a)
    da[:, : _el.BEAM_STATE] = da_state
    da[:, _el.BEAM_STATE : _el.BEAM_STATE + _el.BEAM_CONST] = dconst
    spec = _el.beam_jvp_spec() if hessian else _el.beam_jvp_gradient_spec()
    return compiled(spec)(np.hstack([a, da]))


def _mass_derivative(fr: _Frame, psi: np.ndarray, d: StructureDerivative) -> np.ndarray:
    """``dM`` for master rotations ``psi`` (nm, 3) and the design change ``d`` (terms of System.mass)."""
    sys = fr.sys
    N = sys.N
    blocks, masses, dJm = _mass_derivative_terms(fr, psi, d)
    out = np.zeros(N * N)
    if blocks is not None:
        out += np.bincount(sys.beam_flat, blocks.ravel(), minlength=N * N)
    np.add.at(out, _mass_diag(sys) * (N + 1), masses)
    np.add.at(out, sys.rot_flat, dJm.ravel())
    out[(N - 1) * (N + 1)] = 0.0
    return sys.reduce_matrix(out.reshape(N, N))


def _mass_diag(sys: System) -> np.ndarray:
    """Extended indices of every master's three translational DOFs, masters in order (System.mass's)."""
    nm = len(sys.s.master_names)
    return sys.pos[(6 * np.arange(nm)[:, None] + np.arange(3)).ravel()]


def _mass_derivative_terms(
    fr: _Frame, psi: np.ndarray, d: StructureDerivative
) -> tuple[np.ndarray | None, np.ndarray, np.ndarray]:
    """The terms of ``dM`` (:func:`_mass_derivative`) before assembly: the beams' 12 x 12 blocks (nb, 144) at
    ``sys.beam_flat`` (None without beams), the masters' translational masses (3 nm) on the diagonal at
    :func:`_mass_diag` and their rotary inertias (nm, 3, 3) at ``sys.rot_flat``."""
    sys, st = fr.sys, fr.st
    s = sys.s
    m, Rm = fr.m, fr.Rm
    nm = len(s.master_names)
    blocks = None
    if s.n_beams:  # the cubic consistent mass (model.elements.beam_mass_spec), differentiated by CasADi
        da = np.hstack(
            [_beam_inputs_change(fr, np.zeros((nm, 3)), psi, d.node_offset), d.beam_const, d.beam_mass[:, None]]
        )
        nc = _el.BEAM_STATE + _el.BEAM_CONST
        a = np.hstack([fr.beam_in[:, :nc], s.beam_mass[:, None]])
        blocks = compiled(_el.beam_mass_jvp_spec())(np.hstack([a, da]))
    dRn = skew(psi[m]) @ Rm
    dJn = (
        dRn @ s.node_rot_inertia @ Rm.transpose(0, 2, 1)
        + Rm @ d.node_rot_inertia @ Rm.transpose(0, 2, 1)
        + Rm @ s.node_rot_inertia @ dRn.transpose(0, 2, 1)
    )
    dJm = np.zeros((nm, 3, 3))
    np.add.at(dJm, m, dJn)
    dRb = skew(psi) @ st.R
    dJm += (
        dRb @ s.master_inertia @ st.R.transpose(0, 2, 1)
        + st.R @ d.master_inertia @ st.R.transpose(0, 2, 1)
        + st.R @ s.master_inertia @ dRb.transpose(0, 2, 1)
    )
    return blocks, np.repeat(d.master_mass, 3), dJm


class _LoadFrame:
    """The loads (model.loads) of one equilibrium for the design sensitivities: their kernels' inputs at the
    state, once per point, and their directional derivatives along a design direction (:meth:`jvp`)."""

    def __init__(self, fr: _Frame, ls: LoadSet, stroke: float) -> None:
        sys = fr.sys
        self.fr, self.ls = fr, ls  # sys.loads, which the caller found not None
        ls = self.ls
        self.value_at = ls.stroke_value(stroke)
        self.vec = sys.load_scale * ls.forces(stroke)
        self.Rm = fr.st.R[ls.masters]
        self.a_point = ls.kernel_input(fr.st.R, self.vec) if ls.point_kernel is not None else None
        if ls.beam_gravity:
            s = sys.s
            nc = _el.BEAM_STATE + _el.BEAM_CONST
            self.a_beam = np.hstack(
                [fr.beam_in[:, :nc], s.beam_mass[:, None], np.tile(sys.load_scale * ls.gravity, (s.n_beams, 1))]
            )
        self.dvec = self.doff = np.zeros((len(ls.loads), 3))

    def direction(self, d: StructureDerivative) -> None:
        """Set the design direction ``d``: each load's change of value ``dvec`` and of reference offset from its
        master ``doff``."""
        ls, s = self.ls, self.fr.sys.s
        g = ls.gravity
        dg = d.gravity if d.gravity is not None else np.zeros(3)
        self.dvec = np.zeros((len(ls.loads), 3))
        self.doff = np.zeros((len(ls.loads), 3))
        for k, (kind, i) in enumerate(ls.source):
            if kind == "weight":
                self.dvec[k] = d.master_mass[i] * g + s.master_mass[i] * dg
                continue
            if kind == "truss":  # outside the scope (trusses are refused by _check_scope)
                raise FlexoptError("design sensitivities do not cover trusses")
            ld = ls.loads[k]
            dld = d.loads[k] if k < len(d.loads) else {}
            self.dvec[k] = _load_value_derivative(ld, dld, *self.value_at)
            if kind == "node":
                self.doff[k] = d.node_offset[i]
            elif ld.point is not None:
                self.doff[k] = np.asarray(dld.get("point", (0.0, 0.0, 0.0)), float) - d.master_pos[i]
        self.dvec *= self.fr.sys.load_scale

    def jvp(self, da_state: np.ndarray, psi: np.ndarray, d: StructureDerivative, gradient: bool) -> np.ndarray:
        """The loads' ``dg`` (``gradient``: active numbering, n) or ``dH`` (n, n) along the beams' state input
        change ``da_state`` with the masters' rotations ``psi`` (nm, 3) and the direction of :meth:`direction`."""
        sys, ls = self.fr.sys, self.ls
        N = sys.N
        out = np.zeros(N if gradient else N * N)
        if self.a_point is not None:
            r = self.a_point[:, 0:3]
            dr = np.einsum("kij,kj->ki", self.Rm, self.doff) + _cross(psi[ls.masters], r)
            da = np.zeros_like(self.a_point)
            da[:, 0:3], da[:, 3:6] = dr, self.dvec  # dead forces only (moments and followers are refused)
            o = compiled(_el.load_jvp_spec("point"))(np.hstack([self.a_point, da]))
            if gradient:
                out += np.bincount(ls.dofs.ravel(), o[:, :6].ravel(), minlength=N)
            else:
                out += np.bincount(ls.flat, o[:, 6:].ravel(), minlength=N * N)
        if ls.beam_gravity:
            da = np.zeros_like(self.a_beam)
            da[:, : _el.BEAM_STATE] = da_state
            da[:, _el.BEAM_STATE : _el.BEAM_STATE + _el.BEAM_CONST] = d.beam_const
            da[:, _el.BEAM_STATE + _el.BEAM_CONST] = d.beam_mass
            dg = d.gravity if d.gravity is not None else np.zeros(3)
            da[:, _el.BEAM_STATE + _el.BEAM_CONST + 1 :] = sys.load_scale * dg
            o = compiled(_el.load_jvp_spec("beam_gravity"))(np.hstack([self.a_beam, da]))
            if gradient:
                out += np.bincount(sys.beam_dofs.ravel(), o[:, :12].ravel(), minlength=N)
            else:
                out += np.bincount(sys.beam_flat, o[:, 12:].ravel(), minlength=N * N)
        return sys.reduce_vector(out) if gradient else sys.reduce_matrix(out.reshape(N, N))


def _load_value_derivative(ld, dld: dict, v: float, first: float, last: float) -> np.ndarray:
    """The derivative of a scene load's value (model.scene.Load.value at ``v``, the stroke unit) from its
    derivative dictionary ``dld`` (the same keys, derivatives of the numbers; the stroke grid is taken as
    independent of the design)."""
    if ld.force is not None:
        return np.asarray(dld.get("force", (0.0, 0.0, 0.0)), float)
    if ld.ramp is not None:
        dr = dld.get("ramp") or {}
        t = (v - first) / (last - first)
        return (1 - t) * np.asarray(dr.get("start", (0.0,) * 3), float) + t * np.asarray(
            dr.get("stop", (0.0,) * 3), float
        )
    dt = (dld.get("table") or {}).get("force")
    if dt is None:
        return np.zeros(3)
    F = np.asarray(dt, float)
    return np.array([np.interp(v, ld.table.stroke, F[:, k]) for k in range(3)])


def _stiffness(k: np.ndarray) -> np.ndarray:
    """Constitutive matrices (nb, 6, 6) from the stiffness constants ``k1, k2, ky, kz`` (nb, 4)."""
    S = np.zeros((len(k), 6, 6))
    S[:, 0, 0], S[:, 1, 1] = k[:, 0], k[:, 1]
    B = np.array([[4.0, -2.0], [-2.0, 4.0]])
    S[:, 2:4, 2:4] = k[:, 2, None, None] * B
    S[:, 4:6, 4:6] = k[:, 3, None, None] * B
    return S


def _bordered_lu(sys: System, eq: Equilibrium, A: np.ndarray) -> tuple:
    """LU factors of the locked tangent stiffness bordered by the drive's gradient (rows: the free DOFs'
    rows of ``A``, then the drive constraint); :class:`FlexoptError` at a limit point (singular)."""
    f = sys.free
    Jb = np.zeros((len(f) + 1, sys.n))
    Jb[: len(f)] = A[f]
    Jb[len(f)] = sys.drive_gradient(eq.state)
    try:
        lu = sla.lu_factor(Jb, check_finite=False)
        if not np.all(np.isfinite(lu[0])) or np.min(np.abs(np.diag(lu[0]))) == 0.0:
            raise np.linalg.LinAlgError("singular")
    except np.linalg.LinAlgError as exc:
        raise FlexoptError(
            f"the tangent stiffness is singular at stroke {eq.stroke:.6g}: the equilibrium is at "
            "a limit point, where design derivatives do not exist; shorten the stroke"
        ) from exc
    return lu


def _eigen_clusters(lam: np.ndarray, cluster_gap: float) -> list[list[int]]:
    """Indices of ``lam`` grouped into clusters of (nearly) repeated eigenvalues, in ascending order."""
    groups: list[list[int]] = []
    for i in np.argsort(lam):
        if groups and abs(lam[i] - lam[groups[-1][-1]]) <= cluster_gap * max(abs(lam[i]), 1e-300):
            groups[-1].append(int(i))
        else:
            groups.append([int(i)])
    return groups


def point_sensitivity(
    sys: System,
    eq: Equilibrium,
    modes: Modes,
    which: Sequence[int] | np.ndarray,
    dstructs: Sequence[StructureDerivative],
    cluster_gap: float = 1e-6,
) -> PointSensitivity:
    """Exact derivatives of the eigenvalues ``modes.omega2[which]`` (drive locked or free, as the scene says) and of the segment-end
    von Mises stresses at ``eq`` along each design direction (module docstring, steps 3-5).

    Raises
    ------
    FlexoptError
        When the locked tangent stiffness is singular (the equilibrium is at a limit point).
    """
    s = sys.s
    _check_scope(s)
    st, ev = eq.state, eq.ev
    n, f = sys.n, sys.free
    nm = len(s.master_names)
    A = ev.H if ev.chart is None else ev.H + ev.chart
    lu = _bordered_lu(sys, eq, A)
    which = np.asarray(which, dtype=int)
    locked = sys.stroke.drive == "locked"  # the eigenproblem of model.modal.modes_at
    dofs = f if locked else np.arange(n)
    lam = modes.omega2[which]
    phi = modes.phi[:, which]
    groups = _eigen_clusters(lam, cluster_gap)
    act = np.zeros((nm, 6), dtype=bool)
    act.reshape(-1)[sys.act_full] = True
    sig = beam_sigma(s, sys, eq)
    fr = _Frame(sys, st)
    lf = _LoadFrame(fr, sys.loads, eq.stroke) if sys.loads is not None else None
    z = np.hstack([sig, s.beam_stress])
    vm_out = _von_mises_jac(len(z))(z.T)
    vm2 = vm_out[0].full().T
    vm = np.sqrt(vm2)
    Jvm = vm_out[1].full().T.reshape(len(z), 13, 2).transpose(0, 2, 1)  # (nb, 2, 13): d(vm^2)/dz
    pf = phi[dofs]
    # Without loads, each eigenvalue derivative needs only the quadratic forms phi^T dK phi and phi^T dM phi of the
    # tracked modes: summed entry by entry over the assembled terms (the element blocks at their flat indices in
    # the extended numbering, with the modes carried there: y = E phi, reduce_matrix's congruence, zero on the
    # DOFs free_block leaves out), instead of assembling, reducing and cutting two N x N matrices per direction
    # (measured: half of a full-pass case of the 3-stage default spec). The same sums in another order.
    quad = lf is None
    if quad:
        N = sys.N
        Y = np.zeros((N, len(which)))
        Y[dofs] = pf
        if not sys.direct:
            Y[n : n + 3] = sys.Qa @ Y[sys.block_pos]
        r_, c_ = np.divmod(sys.beam_flat, N)
        w_beam = Y[r_] * Y[c_]
        w_diag = Y[_mass_diag(sys)] ** 2
        r_, c_ = np.divmod(sys.rot_flat, N)
        w_rot = Y[r_] * Y[c_]
    if quad and len(dstructs):
        return _directions_at_once(sys, eq, A, lu, lam, groups, act, fr, dstructs, vm, Jvm, (w_beam, w_diag, w_rot))
    dlam = np.zeros((len(dstructs), len(which)))
    dvm2 = np.zeros((len(dstructs), s.n_beams, 2))
    dxis = np.zeros((len(dstructs), n))
    dreac = np.zeros(len(dstructs))
    for j, d in enumerate(dstructs):
        # prescribed master positions move with the reference (supports; a translation drive below)
        u_pres = np.where(act[:, :3], 0.0, d.master_pos)
        da_design = _beam_inputs_change(fr, u_pres, np.zeros((nm, 3)), d.node_offset)
        dg, _, _ = _jvp(fr, da_design, d.beam_const, hessian=False)
        if lf is not None:
            lf.direction(d)
            dg = dg + lf.jvp(da_design, np.zeros((nm, 3)), d, gradient=True)
        rhs = np.zeros(len(f) + 1)
        rhs[: len(f)] = -dg[f]
        if s.drive_kind == "translation":
            rhs[-1] = float(d.master_pos[s.drive_master] @ s.drive_axis)
        dxi = sla.lu_solve(lu, rhs, check_finite=False)
        v = sys.to_global(dxi).reshape(nm, 6)
        da_total = da_design + _beam_inputs_change(fr, v[:, :3], v[:, 3:], np.zeros_like(d.node_offset))
        _, dH, de = _jvp(fr, da_total, d.beam_const)
        if lf is not None:
            dH = dH + lf.jvp(da_total, v[:, 3:], d, gradient=False)
        dM = _mass_derivative(fr, v[:, 3:], d)
        dK, dMf = sys.free_block(dH, locked), sys.free_block(dM, locked)
        for g_ in groups:
            P = pf[:, g_]
            if len(g_) == 1:
                i = g_[0]
                dlam[j, i] = P[:, 0] @ (dK - lam[i] * dMf) @ P[:, 0]
            else:
                lc = float(np.mean(lam[g_]))
                dlam[j, g_] = np.trace(P.T @ (dK - lc * dMf) @ P) / len(g_)
        dS = _stiffness(d.beam_const[:, 10:14])
        e_m = ev.e_beam * s.beam_mask
        dsig = np.einsum("eij,ej->ei", dS, e_m) + np.einsum("eij,ej->ei", s.beam_stiff, de * s.beam_mask)
        dz = np.hstack([dsig, d.beam_stress])
        dvm2[j] = np.einsum("ekz,ez->ek", Jvm, dz)
        dxis[j] = dxi
        # reaction = g at the drive DOF: its change at fixed state plus along the equilibrium's move
        dreac[j] = dg[sys.drive] + A[sys.drive] @ dxi
    with np.errstate(divide="ignore", invalid="ignore"):
        dvm = np.where(vm > 0, dvm2 / (2 * vm), np.nan)
    return PointSensitivity(dlam, dvm, vm, dvm2, dxis, dreac)


def _directions_at_once(
    sys: System,
    eq: Equilibrium,
    A: np.ndarray,
    lu: tuple,
    lam: np.ndarray,
    groups: list[list[int]],
    act: np.ndarray,
    fr: _Frame,
    dstructs: Sequence[StructureDerivative],
    vm: np.ndarray,
    Jvm: np.ndarray,
    weights: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> PointSensitivity:
    """:func:`point_sensitivity` of a scene without loads, every design direction at once: the same steps as its
    loop (the implicit-function move, the element derivatives along the total input change, the eigenvalue
    derivatives as quadratic forms with ``weights``: the products of the carried modes at the beams' flat
    indices, the masters' translational diagonal and their rotation blocks), each a single batched kernel
    call, solve or product over the D directions instead of D small ones (measured: a quarter of
    point_sensitivity's time on the 3-stage hinges at 8 segments was the loop's per-call overhead)."""
    s, st, ev = sys.s, eq.state, eq.ev
    n, f, N = sys.n, sys.free, sys.N
    nm, nb, D = len(s.master_names), s.n_beams, len(dstructs)
    w_beam, w_diag, w_rot = weights
    master_pos = np.stack([d.master_pos for d in dstructs])
    dr0 = np.stack([d.node_offset for d in dstructs])
    dconst = np.stack([d.beam_const for d in dstructs])
    zero = np.zeros((D, nm, 3))
    # prescribed master positions move with the reference (supports; a translation drive below)
    da_design = _beam_inputs_change_many(fr, np.where(act[None, :, :3], 0.0, master_pos), zero, dr0)
    og = _jvp_kernel_many(fr, da_design, dconst, hessian=False)[:, :, :12]
    dofs = sys.beam_dofs.ravel()
    ext = np.bincount((dofs[None, :] + N * np.arange(D)[:, None]).ravel(), og.reshape(D, -1).ravel(), minlength=D * N)
    ext = ext.reshape(D, N)
    dg = ext[:, :n].copy()
    if not sys.direct:
        dg[:, sys.block_pos] += ext[:, n : n + 3] @ sys.Qa  # reduce_vector, row by row
    rhs = np.zeros((len(f) + 1, D))
    rhs[: len(f)] = -dg[:, f].T
    if s.drive_kind == "translation":
        rhs[-1] = master_pos[:, s.drive_master] @ s.drive_axis
    dxi = sla.lu_solve(lu, rhs, check_finite=False)  # (n, D)
    v = sys.to_global(dxi).T.reshape(D, nm, 6)
    psi = v[:, :, 3:]
    da_total = da_design + _beam_inputs_change_many(fr, v[:, :, :3], psi, np.zeros_like(dr0))
    out = _jvp_kernel_many(fr, da_total, dconst, hessian=True)
    de = out[:, :, 156:162]
    qK = out[:, :, 12:156].reshape(D, -1) @ w_beam
    # dM's terms (_mass_derivative_terms), every direction at once
    m, Rm = fr.m, fr.Rm
    qM = np.repeat(np.stack([d.master_mass for d in dstructs]), 3, axis=1) @ w_diag
    if nb:
        nc = _el.BEAM_STATE + _el.BEAM_CONST
        a = np.hstack([fr.beam_in[:, :nc], s.beam_mass[:, None]])
        x = np.empty((D, nb, 2 * a.shape[1]))
        x[:, :, : a.shape[1]] = a
        x[:, :, a.shape[1] : a.shape[1] + _el.BEAM_STATE] = _beam_inputs_change_many(fr, zero, psi, dr0)
        x[:, :, a.shape[1] + _el.BEAM_STATE : a.shape[1] + nc] = dconst
        x[:, :, a.shape[1] + nc] = np.stack([d.beam_mass for d in dstructs])
        blocks = compiled(_el.beam_mass_jvp_spec())(x.reshape(D * nb, -1))
        qM = qM + blocks.reshape(D, -1) @ w_beam
    dRn = skew(psi[:, m]) @ Rm
    RmT = Rm.transpose(0, 2, 1)
    dJn = (
        dRn @ s.node_rot_inertia @ RmT
        + Rm @ np.stack([d.node_rot_inertia for d in dstructs]) @ RmT
        + Rm @ s.node_rot_inertia @ dRn.transpose(0, 1, 3, 2)
    )
    dJm = np.zeros((nm, D, 3, 3))
    np.add.at(dJm, m, dJn.transpose(1, 0, 2, 3))
    dJm = dJm.transpose(1, 0, 2, 3)
    dRb = skew(psi) @ st.R
    RT = st.R.transpose(0, 2, 1)
    dJm = dJm + (
        dRb @ s.master_inertia @ RT
        + st.R @ np.stack([d.master_inertia for d in dstructs]) @ RT
        + st.R @ s.master_inertia @ dRb.transpose(0, 1, 3, 2)
    )
    qM = qM + dJm.reshape(D, -1) @ w_rot
    dlam = np.zeros((D, len(lam)))
    for g_ in groups:
        if len(g_) == 1:
            i = g_[0]
            dlam[:, i] = qK[:, i] - lam[i] * qM[:, i]
        else:
            lc = float(np.mean(lam[g_]))
            dlam[:, g_] = (np.sum(qK[:, g_] - lc * qM[:, g_], axis=1) / len(g_))[:, None]
    dS = _stiffness(dconst[:, :, 10:14].reshape(D * nb, 4)).reshape(D, nb, 6, 6)
    e_m = ev.e_beam * s.beam_mask
    dsig = np.einsum("deij,ej->dei", dS, e_m) + np.einsum("eij,dej->dei", s.beam_stiff, de * s.beam_mask)
    dz = np.concatenate([dsig, np.stack([d.beam_stress for d in dstructs])], axis=2)
    dvm2 = np.einsum("ekz,dez->dek", Jvm, dz)
    # reaction = g at the drive DOF: its change at fixed state plus along the equilibrium's move
    dreac = dg[:, sys.drive] + A[sys.drive] @ dxi
    with np.errstate(divide="ignore", invalid="ignore"):
        dvm = np.where(vm > 0, dvm2 / (2 * vm), np.nan)
    return PointSensitivity(dlam, dvm, vm, dvm2, dxi.T.copy(), dreac)


#: the mapped von Mises Jacobians kept, one per beam count (least recently used dropped past it): a process
#: that meets many distinct models (a topology search's pool worker) keeps at most this many (issue 29 item 2)
VM_JAC_ENTRIES = 32
_VM_JAC: OrderedDict[int, ca.Function] = OrderedDict()


def _von_mises_jac(n: int) -> ca.Function:
    if n in _VM_JAC:
        _VM_JAC.move_to_end(n)
        return _VM_JAC[n]
    fn = _VM_JAC[n] = _el.beam_von_mises_squared().map(n)
    while len(_VM_JAC) > VM_JAC_ENTRIES:
        _VM_JAC.popitem(last=False)
    return fn
