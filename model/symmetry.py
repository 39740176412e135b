"""Symmetry of a design that reverses the stroke: a mirror plane or a half-turn axis.

An isometry ``x -> c + S (x - c)`` with ``S`` a reflection ``I - 2 n n^T`` (about the plane through ``c``
with normal ``n``) or a half-turn ``2 u u^T - I`` (rotation by 180 deg about the axis through ``c`` along
``u``) that maps the whole scene onto itself -- every node onto a node, every element onto an element of the
same kind, material, section, segments and mapped section orientation, every body onto a body of the same
mass, mapped centre of mass and inertia ``S J S``, every support onto an equivalent support, the declared
support directions onto themselves, and the driven node or body onto itself -- maps each equilibrium of the
scene onto an equilibrium of the same scene (the strain energy is invariant: every element goes to an
identical element in the mapped configuration). A rotation ``R(theta, a)`` becomes ``S R S^T =
R(det(S) theta, S a)``: the stroke is reversed by a reflection whose plane contains the drive axis
(``n . a = 0``) and by a half-turn about an axis perpendicular to it (``S a = -a``); a translation along
``a`` by a reflection with ``n`` parallel to ``a`` or a half-turn with ``u`` perpendicular to it. The image
of the equilibrium at ``s`` is then the equilibrium at ``-s`` (the continuation's branch from the
symmetric reference), with the mass matrix congruent under ``S``: the same natural frequencies, the same
shares of kinetic energy in the (mapped) support directions, the drive reaction with the opposite sign and
each member's stresses those of its image member. The frequency curve is even in the stroke, and one side
gives the other (:meth:`model.analysis.MeshAnalysis.exact_curve`, ``hermite``).

Every comparison is exact up to a relative tolerance of :data:`TOL` (positions: of the design's size), and
any doubt -- an end-specific rigid deformation (eps3..eps6) or warping condition on an element whose image
runs the other way, a partial support whose image is another set of directions, a body without a partner
-- means "no symmetry". The fixed point ``c`` is the centroid of the nodes (any symmetry of the node set
fixes it). Candidate reflection normals are the differences of node pairs (an image pair's difference is
parallel to ``n``) and, when the nodes and the drive axis span only a plane, that plane's normal; candidate
half-turn axes the directions of node-pair midpoints and of nodes from ``c`` (they lie on the axis) and,
the cross products of the drive axis with the differences of node pairs (a pair whose midpoint is ``c``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .scene import Beam, Element, RectangularSection, Scene, Stroke, Truss

__all__ = ["StrokeSymmetry", "stroke_symmetry", "one_side", "image_indices", "mirror_tol", "TOL"]

#: Relative tolerance (of the largest node distance from the centroid) for positions, and relative tolerance
#: of every compared number (masses, inertias, section data).
TOL = 1e-9
_DOF = {"x": 0, "y": 1, "z": 2, "rx": 3, "ry": 4, "rz": 5}
_END_SPECIFIC = {"eps3", "eps4", "eps5", "eps6"}


@dataclass(frozen=True)
class StrokeSymmetry:
    """A symmetry of the design that reverses the stroke: a reflection or a half-turn."""

    kind: str  # "reflection" (about a plane) | "half-turn" (rotation by 180 deg about an axis)
    point: tuple[float, float, float]  # a fixed point (on the plane or the axis) [m]
    vector: tuple[float, float, float]  # unit normal of the plane, or direction of the axis
    node_map: dict[str, str]  # each node's image
    element_map: dict[str, str]  # each element's image (the member whose stresses it has at -s)

    def describe(self) -> str:
        v, c = np.round(self.vector, 6) + 0.0, np.round(self.point, 6) + 0.0
        where = f"({c[0]:g}, {c[1]:g}, {c[2]:g}) m"
        if self.kind == "reflection":
            return f"mirror plane through {where} with normal ({v[0]:g}, {v[1]:g}, {v[2]:g})"
        return f"half-turn about the axis through {where} along ({v[0]:g}, {v[1]:g}, {v[2]:g})"


def _close(a: float, b: float) -> bool:
    return abs(a - b) <= TOL * max(abs(a), abs(b), 1e-300)


def _perp_unit(v: np.ndarray, t: np.ndarray) -> np.ndarray | None:
    w = v - (v @ t) * t
    nw = np.linalg.norm(w)
    return None if nw == 0 else w / nw


def _projector(vectors: list[np.ndarray]) -> np.ndarray:
    if not vectors:
        return np.zeros((3, 3))
    A = np.array(vectors, dtype=float).T
    U, sv, _ = np.linalg.svd(A, full_matrices=False)
    U = U[:, sv > 1e-12 * sv.max()]
    return U @ U.T


def _node_map(c: np.ndarray, S: np.ndarray, X: dict[str, np.ndarray], scale: float) -> dict[str, str] | None:
    """Each node's image under ``x -> c + S (x - c)`` (another node within TOL), or None."""
    names = list(X)
    P = np.array([X[k] for k in names])
    img = (P - c) @ S.T + c
    d = np.linalg.norm(img[:, None, :] - P[None, :, :], axis=2)
    j = np.argmin(d, axis=1)
    if np.any(d[np.arange(len(names)), j] > TOL * scale) or len(set(j.tolist())) != len(names):
        return None
    return {names[i]: names[int(j[i])] for i in range(len(names))}


def _partners(
    scene: Scene, e: Element, f: Element, nmap: dict[str, str], S: np.ndarray, X: dict[str, np.ndarray]
) -> bool:
    """Whether element ``f`` (on the mirrored nodes of ``e``) is the image of ``e``: the same kind and
    properties, and for a beam the mirrored section orientation."""
    mats = {m.name: m for m in scene.materials}
    p, q = e.nodes
    if f.kind != e.kind or mats[f.material] != mats[e.material] or f.segments != e.segments:
        return False
    if f.rigid != e.rigid or f.generalised != e.generalised or f.kinematic_rigid != e.kinematic_rigid:
        return False
    reversed_ = f.nodes != (nmap[p], nmap[q])
    if isinstance(e, Truss):
        return isinstance(f, Truss) and f.area == e.area  # f is a Truss: same kind
    if isinstance(e, Beam):
        if not isinstance(f, Beam) or f.section != e.section:  # f is a Beam: same kind
            return False
        ends = set(e.rigid) | set(e.generalised) | set(e.kinematic_rigid or ())
        warp_one = isinstance(e.section, RectangularSection) and e.section.warping == "one_end"
        if reversed_ and (ends & _END_SPECIFIC or warp_one):
            return False  # end-specific data on an element the mirror runs the other way: no claim
        tf = X[f.nodes[1]] - X[f.nodes[0]]
        tf = tf / np.linalg.norm(tf)
        y_img = _perp_unit(S @ np.asarray(e.y_axis, float), tf)
        y_f = _perp_unit(np.asarray(f.y_axis, float), tf)
        # a doubly symmetric section (all the model has): its y axis matters up to sign
        if y_img is None or y_f is None or abs(abs(float(y_img @ y_f)) - 1.0) > TOL * 10:
            return False
    return True


def _element_map(scene: Scene, nmap: dict[str, str], S: np.ndarray, X: dict[str, np.ndarray]) -> dict[str, str] | None:
    """Each element's partner of the same kind and properties on the mirrored nodes, or None."""
    by_nodes: dict[frozenset, list] = {}
    for e in scene.elements:
        by_nodes.setdefault(frozenset(e.nodes), []).append(e)
    used: set[str] = set()
    emap: dict[str, str] = {}
    for e in scene.elements:
        p, q = e.nodes
        cands = [f for f in by_nodes.get(frozenset((nmap[p], nmap[q])), []) if f.name not in used]
        match = next((f for f in cands if _partners(scene, e, f, nmap, S, X)), None)
        if match is None:
            return None
        used.add(match.name)
        emap[e.name] = match.name
    return emap


def _body_map(scene: Scene, c: np.ndarray, S: np.ndarray, nmap: dict[str, str], scale: float) -> dict[str, str] | None:
    """Each body's image: the same mass, mirrored centre of mass and inertia, the mirrored set of attached
    nodes; or None."""
    free_bodies = {b.name: b for b in scene.bodies}
    bmap: dict[str, str] = {}
    for b in scene.bodies:
        com = S @ (np.asarray(b.center_of_mass, float) - c) + c
        J = S @ np.asarray(b.inertia, float) @ S
        nodes = {nmap[k] for k in b.nodes}
        jscale = max(np.abs(J).max(), 1e-300)
        hit = None
        for f in free_bodies.values():
            if (
                _close(f.mass, b.mass)
                and np.linalg.norm(np.asarray(f.center_of_mass, float) - com) <= TOL * scale
                and np.abs(np.asarray(f.inertia, float) - J).max() <= TOL * jscale
                and set(f.nodes) == nodes
            ):
                hit = f
                break
        if hit is None:
            return None
        bmap[b.name] = hit.name
        del free_bodies[hit.name]
    return bmap


def _supports_map(scene: Scene, S: np.ndarray, nmap: dict[str, str], bmap: dict[str, str]) -> bool:
    """Whether every support has an image (the mirrored node or body with the mirrored set of fixed
    directions) and the declared support directions map onto themselves."""

    def fixed(sup) -> tuple[np.ndarray, np.ndarray]:  # noqa: ANN001
        idx = [_DOF[d] for d in sup.dofs]
        E = np.eye(3)
        return (_projector([E[i] for i in idx if i < 3]), _projector([E[i - 3] for i in idx if i >= 3]))

    remaining = list(scene.supports)
    for sup in scene.supports:
        if sup.node is not None:
            target = ("node", nmap[sup.node])
        else:
            assert sup.body is not None  # a support names a node or a body (the scene's validator)
            target = ("body", bmap[sup.body])
        Pt, Pr = fixed(sup)
        Pt, Pr = S @ Pt @ S, S @ Pr @ S
        hit = None
        for other in remaining:
            o_target = ("node", other.node) if other.node is not None else ("body", other.body)
            if o_target != target:
                continue
            Ot, Or = fixed(other)
            if np.abs(Ot - Pt).max() <= 1e-9 and np.abs(Or - Pr).max() <= 1e-9:
                hit = other
                break
        if hit is None:
            return False
        remaining.remove(hit)
    sd = scene.support_directions
    if sd is not None:
        for vecs in (sd.translations, sd.rotations):
            Pv = _projector([np.asarray(v, float) for v in vecs])
            if np.abs(S @ Pv @ S - Pv).max() > 1e-9:
                return False
    return True


def _check(
    scene: Scene, st: Stroke, c: np.ndarray, S: np.ndarray, X: dict[str, np.ndarray], scale: float
) -> tuple[dict, dict] | None:
    """The node and element maps of ``x -> c + S (x - c)`` (``S`` symmetric orthogonal) if it maps the scene
    onto itself (nodes, elements, bodies, supports, and the driven node or body onto itself), else None."""
    nmap = _node_map(c, S, X, scale)
    if nmap is None:
        return None
    emap = _element_map(scene, nmap, S, X)
    if emap is None:
        return None
    bmap = _body_map(scene, c, S, nmap, scale)
    if bmap is None or not _supports_map(scene, S, nmap, bmap):
        return None
    if st.node is not None and nmap[st.node] != st.node:
        return None
    if st.body is not None and bmap.get(st.body) != st.body:
        return None
    return nmap, emap


def stroke_symmetry(scene: Scene) -> StrokeSymmetry | None:
    """A symmetry of ``scene`` that reverses its stroke (see the module docstring), or None."""
    st = scene.stroke
    if st is None:
        return None
    X = {nd.name: np.asarray(nd.position, dtype=float) for nd in scene.nodes}
    P = np.array(list(X.values()))
    c = P.mean(axis=0)
    scale = max(float(np.linalg.norm(P - c, axis=1).max()), 1e-300)
    a = np.asarray(st.axis, dtype=float)
    a = a / np.linalg.norm(a)
    # candidate reflections (normal n: S = I - 2 n n^T) and half-turns (axis u: S = 2 u u^T - I)
    normals: list[np.ndarray] = []
    axes: list[np.ndarray] = []
    iu = np.triu_indices(len(P), 1)
    diffs = (P[:, None, :] - P[None, :, :])[iu]
    mids = np.vstack([(P[:, None, :] + P[None, :, :])[iu] - 2 * c, P - c])  # pair midpoints, single nodes
    if st.kind == "translation":
        normals.append(a)  # reflection reversing the translation: n parallel to a
    else:
        # reflection reversing the rotation: the plane contains a; a mirror pair's difference is along n
        normals += [d for d in diffs if abs(d @ a) <= TOL * scale]
        span = np.vstack([a[None, :], (P - c) / scale])
        _, sv, Vt = np.linalg.svd(span)
        if len(sv) < 3 or sv[2] <= TOL * sv[0]:  # nodes and axis in one plane: every node its own image
            normals.append(Vt[2])
    # half-turn about u through c, u perpendicular to a (reverses rotations and translations along a): a
    # pair's midpoint lies on the axis and its difference is perpendicular to it
    axes += [m for m in mids if abs(m @ a) <= TOL * scale]
    axes += list(np.cross(a, diffs))  # a pair about c itself: the axis is perpendicular to d and a
    for kind, vecs in (("reflection", normals), ("half-turn", axes)):
        seen: list[np.ndarray] = []
        for v in vecs:
            nv = np.linalg.norm(v)
            if nv <= TOL * scale:
                continue
            v = v / nv
            if kind == "half-turn" and abs(v @ a) > 1e-9:
                continue
            if any(abs(abs(float(v @ m)) - 1.0) < 1e-12 for m in seen):
                continue
            seen.append(v)
            S = np.eye(3) - 2.0 * np.outer(v, v) if kind == "reflection" else 2.0 * np.outer(v, v) - np.eye(3)
            maps = _check(scene, st, c, S, X, scale)
            if maps is not None:
                k = int(np.argmax(np.abs(v)))
                v = v if v[k] > 0 else -v
                return StrokeSymmetry(kind, _vec3(c), _vec3(v), *maps)
    return None


def _vec3(v: np.ndarray) -> tuple[float, float, float]:
    """A point or direction as three floats."""
    return float(v[0]), float(v[1]), float(v[2])


def mirror_tol(internal: np.ndarray) -> float:
    """Strokes closer than this are one point for mirroring: a grid like linspace(-a, a, n) is symmetric
    only to rounding (its values at -s and s differ by a few ulps)."""
    return 1e-12 * float(np.max(np.abs(internal), initial=0.0))


def image_indices(solved: np.ndarray, internal: np.ndarray) -> list[int | None]:
    """For each requested stroke, the index in ``solved`` (sorted non-negative strokes) of the point that
    gives it -- the one at ``|s|``, within :func:`mirror_tol` -- or None when it was not solved."""
    tol = mirror_tol(internal)
    v = np.abs(np.asarray(internal, dtype=float))
    solved = np.asarray(solved, dtype=float)
    if not len(solved):
        return [None] * len(v)
    # the nearest of the two solved strokes around |s| (sorted), the lower one on a tie: the first nearest
    hi = np.clip(np.searchsorted(solved, v), 1, len(solved) - 1) if len(solved) > 1 else np.zeros(len(v), int)
    lo = np.maximum(hi - 1, 0)
    i = np.where(np.abs(solved[hi] - v) < np.abs(solved[lo] - v), hi, lo)
    ok = np.abs(solved[i] - v) <= tol
    out = i.tolist()
    if not ok.all():
        out = [j if o else None for j, o in zip(out, ok.tolist())]
    return out


def one_side(internal: np.ndarray) -> np.ndarray:
    """The non-negative strokes that give every requested point of a stroke-symmetric design: the requested
    non-negative ones and the image of each negative one not already among them (within rounding)."""
    internal = np.asarray(internal, dtype=float)
    tol = mirror_tol(internal)
    pos = np.sort(internal[internal >= 0])
    neg = np.sort(-internal[internal < 0])
    if len(pos) and len(neg):  # images within tol of a requested non-negative stroke are that stroke
        j = np.searchsorted(pos, neg)
        near = np.minimum(
            np.abs(pos[np.clip(j - 1, 0, len(pos) - 1)] - neg), np.abs(pos[np.clip(j, 0, len(pos) - 1)] - neg)
        )
        neg = neg[near > tol]
    if not len(neg):
        return pos
    keep = [neg[0]]  # the rest, ascending: one per group within tol of the last one kept
    for v in neg[1:].tolist():
        if v - keep[-1] > tol:
            keep.append(v)
    return np.sort(np.concatenate([pos, keep]))
