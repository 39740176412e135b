"""SPACAR's own D_cc of a ``.dat`` model: its coordinates, its deformations, its partition (seed 002, eqs. 3-11).

flexopt's diagnosis (:mod:`model.constraints`) takes D_cc in its own variables: the six increments of each
master (rigid bodies carry their nodes exactly), scaled by a characteristic length. A SPACAR user holds a
diagnosis against SPACAR's log, which counts and conditions D_cc in SPACAR's variables. This module builds
that matrix from a ``.dat`` text (a file, or :func:`model.spacar.write_dat` of a native scene), exactly, with
CasADi (no finite differences), at the file's configuration (the reference).

Definition used (written from seed 002 and the public descriptions of SPACAR's elements; **not checked
against a SPACAR log**, none being available):

- coordinates ``x``: per translational node (``X``) its ``x, y, z`` [m]; per rotational node (``R``, every
  rotational node a BEAM or HINGE names) its four Euler parameters ``lambda0..lambda3`` (reference
  ``(1, 0, 0, 0)``), with the rotation matrix ``R(lambda) = (lambda0^2 - v.v) I + 2 v v^T + 2 lambda0 [v]x``
  (``v = (lambda1, lambda2, lambda3)``; homogeneous of degree 2);
- deformations ``e``: per BEAM (and BEAMW) the six of seed 002 eq. 2 in SI (eps1 elongation [m], eps2 torsion and
  eps3..eps6 bending, each ``l0`` times an angle [m]; ``c_t = (EIy + EIz)/EA`` from ESTIFF, 0 without);
  per TRUSS its elongation ``l - l0`` [m]; per HINGE (axis ``a``, at each node the triad ``(a, b, c)`` turned
  by its node's rotation) the relative rotation about ``a`` and about ``b`` and ``c``, each
  ``(t_i^p . t_j^q - t_j^p . t_i^q) / 2`` [rad]; per rotational node not wholly fixed, the normalisation
  ``lambda . lambda - 1``, a deformation that is always rigid (this module's reading of how SPACAR keeps four
  parameters for three rotations; a wholly fixed node's parameters are all known, so it adds no equation);
- warping: a BEAMW's warping (W) nodes are left out, coordinates and deformations alike: SPACAR's definitions
  of the BEAMW warping deformations are not known from a public source, and flexopt invents none (a note
  says so);
- partition (seed 002 eq. 4): ``x(o)`` the FIXed coordinates, ``x(m)`` the INPUTX and DYNX ones, ``x(c)`` the
  others; ``e(m)`` the DYNE deformations (a HINGE's with DYNE), ``e(c)`` the RLSE ones (left out of D_cc),
  ``e(o)`` the others: rigid (no DYNE) and the normalisations;
- ``D_cc`` (eq. 9): rows ``[e(o); e(m)]``, columns ``x(c)`` of ``D = de/dx``, unscaled (SI);
- rank: singular values above ``sqrt(eps) sigma_max`` (the threshold the public SPACAR Light script applies to
  SPACAR's D_cc); condition number ``sigma_max / sigma_min`` over the ``min(m, n)`` singular values (infinite
  when D_cc is rank deficient);
- SPACAR's degrees of freedom: the input coordinates (INPUTX, DYNX; lambda0 of an input rotation follows from
  the normalisation and does not count) and the DYNE deformations.

A model is *under-constrained* (kinematically indeterminate, Table 1) when ``n > rank`` and
*over-constrained* (statically indeterminate) when ``m > rank``. Note that an input together with dynamic
deformations that already span every motion of the driven node over-determines D_cc: SPACAR then needs as
many of them released (RLSE) as the surplus, which is what SPACAR Light's automatic release does.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cache
from typing import Any

import casadi as ca
import numpy as np

from .elements import _beam_deformations
from .errors import SceneError
from .spacar_format import SpacarError, _parse

__all__ = ["SpacarDcc", "spacar_dcc", "surplus_dynamic_rows", "SPACAR_RANK_RTOL"]

#: Rank threshold relative to the largest singular value: sqrt of double precision's machine epsilon.
SPACAR_RANK_RTOL = float(np.sqrt(np.finfo(float).eps))


@dataclass(frozen=True)
class SpacarDcc:
    """D_cc of a SPACAR model in SPACAR's variables (see the module docstring). Shapes: m rows, n columns."""

    rows: tuple[str, ...]  # (m,) e.g. "BEAM 3 eps2", "TRUSS 1 eps1", "HINGE 4 eps1", "R 6 norm"
    row_kind: tuple[str, ...]  # (m,) "rigid" (e(o)) or "dynamic" (e(m))
    columns: tuple[str, ...]  # (n,) e.g. "X 3 y", "R 4 lambda2"
    D_cc: np.ndarray  # (m, n) SI: translations in m, Euler parameters dimensionless
    singular_values: np.ndarray  # (min(m, n),) descending
    rank: int
    dof: int  # SPACAR's degrees of freedom: inputs and dynamic deformations
    n_coordinates: int  # all coordinates x
    n_fixed: int  # x(o)
    n_inputs: int  # x(m)
    notes: tuple[str, ...] = field(default=())
    released: tuple[str, ...] = field(default=())  # the RLSE deformations left out of D_cc, e.g. "BEAM 3 eps5"

    @property
    def m(self) -> int:
        """Rows of D_cc: rigid and dynamic deformations."""
        return len(self.rows)

    @property
    def n(self) -> int:
        """Columns of D_cc: calculable coordinates."""
        return len(self.columns)

    @property
    def condition_number(self) -> float:
        """sigma_max / sigma_min of D_cc (infinite when rank deficient or empty)."""
        sv = self.singular_values
        if not sv.size or self.rank < sv.size:
            return float("inf")
        return float(sv[0] / sv[-1])

    @property
    def over_constrained(self) -> int:
        """Statically indeterminate states (m - rank; seed 002 Table 1)."""
        return self.m - self.rank

    @property
    def under_constrained(self) -> int:
        """Kinematically indeterminate motions (n - rank; seed 002 Table 1)."""
        return self.n - self.rank

    @property
    def verdict(self) -> str:
        """Table 1 in SPACAR's words."""
        parts = []
        if self.under_constrained:
            parts.append(f"under-constrained by {self.under_constrained} (kinematically indeterminate)")
        if self.over_constrained:
            parts.append(f"over-constrained by {self.over_constrained} (statically indeterminate)")
        return "; ".join(parts) if parts else "exactly constrained (D_cc square and regular)"

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready summary (without the matrix)."""
        cond = self.condition_number
        return {
            "dof": self.dof,
            "m": self.m,
            "n": self.n,
            "rank": self.rank,
            "condition_number": cond if np.isfinite(cond) else None,
            "smallest_singular_value": float(self.singular_values[-1]) if self.singular_values.size else None,
            "largest_singular_value": float(self.singular_values[0]) if self.singular_values.size else None,
            "under_constrained": self.under_constrained,
            "over_constrained": self.over_constrained,
            "verdict": self.verdict,
            "coordinates": self.n_coordinates,
            "fixed_coordinates": self.n_fixed,
            "input_coordinates": self.n_inputs,
            "released": len(self.released),
            "notes": list(self.notes),
            "definition": "D_cc = de/dx (seed 002 eq. 9) in SPACAR's variables, SI, unscaled: X nodes x y z, R "
            "nodes 4 Euler parameters with lambda.lambda - 1 a rigid deformation per R node not wholly fixed; "
            "rows rigid + DYNE deformations, columns not FIX/INPUTX/DYNX; rank above sqrt(eps) sigma_max; "
            "condition number sigma_max / sigma_min; at the file's (reference) configuration; not checked "
            "against a SPACAR log",
        }


def _rotation(lam: ca.SX) -> ca.SX:
    """Rotation matrix of Euler parameters (homogeneous quadratic form)."""
    l0, v = lam[0], lam[1:4]
    skew = ca.vertcat(
        ca.horzcat(0, -v[2], v[1]),
        ca.horzcat(v[2], 0, -v[0]),
        ca.horzcat(-v[1], v[0], 0),
    )
    return (l0**2 - ca.dot(v, v)) * ca.SX.eye(3) + 2 * (v @ v.T) + 2 * l0 * skew


@cache
def _jacobians() -> dict[str, ca.Function]:
    """Per element kind, ``[coordinates, constants] -> de/dx`` (dense): the beam's six deformations (seed 002
    eq. 2) of ``xp, lambda_p, xq, lambda_q`` (14) with constants ``l0, E0 (9, column-major), c_t``; the
    truss's elongation of ``xp, xq`` (6) with ``l0``; the hinge's three relative rotations of ``lambda_p,
    lambda_q`` (8) with its triad ``T0`` (9); the normalisation of ``lambda`` (4)."""
    xb, cb = ca.SX.sym("x", 14), ca.SX.sym("c", 11)
    e = _beam_deformations(
        xb[0:3], _rotation(xb[3:7]), xb[7:10], _rotation(xb[10:14]), cb[0], ca.reshape(cb[1:10], 3, 3), cb[10]
    )
    xt, ct = ca.SX.sym("x", 6), ca.SX.sym("c", 1)
    dx = xt[3:6] - xt[0:3]
    et = ca.sqrt(ca.dot(dx, dx)) - ct[0]
    xh, ch = ca.SX.sym("x", 8), ca.SX.sym("c", 9)
    T0 = ca.reshape(ch, 3, 3)
    tp, tq = _rotation(xh[0:4]) @ T0, _rotation(xh[4:8]) @ T0
    eh = ca.vertcat(
        *[(ca.dot(tp[:, i], tq[:, j]) - ca.dot(tp[:, j], tq[:, i])) / 2 for i, j in ((1, 2), (2, 0), (0, 1))]
    )
    xn = ca.SX.sym("x", 4)

    def fn(name: str, x: ca.SX, c: ca.SX, ex: ca.SX) -> ca.Function:
        return ca.Function(name, [x, c], [ca.densify(ca.jacobian(ex, x))])

    return {
        "beam": fn("spacar_beam_D", xb, cb, e),
        "truss": fn("spacar_truss_D", xt, ct, et),
        "hinge": fn("spacar_hinge_D", xh, ch, eh),
        "norm": fn("spacar_norm_D", xn, ca.SX.sym("c", 0), ca.dot(xn, xn) - 1),
    }


def _frame(axis: np.ndarray, across: np.ndarray | None) -> np.ndarray:
    """Columns (e_axis, e_b, e_c): a right-handed orthonormal triad with e_b along ``across`` made perpendicular
    (or, without it, along the coordinate axis least aligned with ``axis``)."""
    ex = axis / np.linalg.norm(axis)
    t = across if across is not None else np.eye(3)[int(np.argmin(np.abs(ex)))]
    ey = t - (t @ ex) * ex
    ey = ey / np.linalg.norm(ey)
    return np.column_stack([ex, ey, np.cross(ex, ey)])


def spacar_dcc(text: str, singular_values: bool = True) -> SpacarDcc:
    """D_cc of the SPACAR model ``text`` (a ``.dat`` file's contents) in SPACAR's variables.

    ``singular_values=False`` returns only the rows, their kinds and the matrix (no SVD: rank -1, counts 0),
    for :func:`surplus_dynamic_rows` on large models.

    Raises
    ------
    SceneError
        When the file does not parse (the reader's line errors) or names a node it never declares.
    """
    r = _parse(text)
    if r.err.items:
        raise SpacarError(r.err.items)
    X: dict[int, np.ndarray] = {n: np.array(p, dtype=float) for n, (p, _) in r.X.items()}
    undeclared = [
        f"line {ln}: {kw}: node {xn} is used but never declared with 'X {xn} x y z'"
        for kw, ends, ln in [(r.bkw(b[0]), (b[1], b[3]), b[-1]) for b in r.beams]
        + [("TRUSS", (t[1], t[2]), t[-1]) for t in r.trusses]
        for xn in ends
        if xn not in X
    ]
    if undeclared:
        raise SpacarError(undeclared)
    used_x = sorted(
        {b[1] for b in r.beams} | {b[3] for b in r.beams} | {t[1] for t in r.trusses} | {t[2] for t in r.trusses}
    )
    used_r = sorted({b[2] for b in r.beams} | {b[4] for b in r.beams} | {n for h in r.hinges for n in h[1:3]})
    both = sorted(set(used_r) & set(X))
    if both:
        raise SceneError("spacar", f"nodes {both} are used as rotational nodes but declared with X; check Xp Rp Xq Rq")
    # coordinates: (node, k) with k 1-3 for X nodes, 1-4 (lambda0..lambda3) for R nodes
    coords: list[tuple[int, int]] = [(n, k) for n in used_x for k in (1, 2, 3)]
    coords += [(n, k) for n in used_r for k in (1, 2, 3, 4)]
    index = {c: i for i, c in enumerate(coords)}
    x0 = np.zeros(len(coords))
    for n in used_x:
        x0[[index[(n, k)] for k in (1, 2, 3)]] = X[n]
    for n in used_r:
        x0[index[(n, 1)]] = 1.0

    def at(*nodes: int) -> list[int]:
        return [index[(n, k)] for n in nodes for k in ((1, 2, 3) if n in X else (1, 2, 3, 4))]

    fns = _jacobians()
    released: dict[int, set[int]] = {ne: {k for ks, _ in items for k in ks} for ne, items in r.rlse.items()}
    rows: list[tuple[str, str, list[int], np.ndarray]] = []  # label, kind, coordinate indices, de/dx
    left_out: list[str] = []

    def add(kw: str, ne: int, J: np.ndarray, idx: list[int]) -> None:
        for k in range(J.shape[0]):
            if k + 1 in released.get(ne, set()):
                left_out.append(f"{kw} {ne} eps{k + 1}")
                continue  # e(c): calculable, not a row of D_cc
            kind = "dynamic" if k + 1 in r.dyne.get(ne, set()) else "rigid"
            rows.append((f"{kw} {ne} eps{k + 1}", kind, idx, J[k]))

    for ne, xp, rp, xq, rq, oy, _ln in r.beams:
        d = X[xq] - X[xp]
        E0 = _frame(d, np.array(oy, dtype=float))
        k_ = r.estiff.get(ne, ([], 0))[0]
        ct = (k_[2] + k_[3]) / k_[0] if len(k_) >= 4 and k_[0] > 0 else 0.0
        idx = at(xp, rp, xq, rq)
        c = np.concatenate([[np.linalg.norm(d)], E0.ravel(order="F"), [ct]])
        add(r.bkw(ne), ne, np.asarray(fns["beam"](x0[idx], c)), idx)
    for ne, xp, xq, _ln in r.trusses:
        idx = at(xp, xq)
        add("TRUSS", ne, np.asarray(fns["truss"](x0[idx], float(np.linalg.norm(X[xq] - X[xp])))), idx)
    for ne, rp, rq, axis, _ln in r.hinges:
        idx = at(rp, rq)
        T0 = _frame(np.array(axis, dtype=float), None).ravel(order="F")
        add("HINGE", ne, np.asarray(fns["hinge"](x0[idx], T0)), idx)
    # x(o) and x(m)
    fixed: set[tuple[int, int]] = set()
    for n, ks, _ in r.fixes:
        dims = (1, 2, 3, 4) if n in used_r else (1, 2, 3)
        fixed.update((n, k) for k in (ks or dims))
    inputs: set[tuple[int, int]] = {(n, k) for n, ks, _ in r.inputs for k in ks}
    inputs |= {(n, k) for n, ks, _ in r.dynx for k in ks}
    inputs -= fixed
    for n in used_r:  # the normalisation of every rotational node not wholly fixed: rigid
        if not all((n, k) in fixed for k in (1, 2, 3, 4)):
            idx = at(n)
            rows.append((f"R {n} norm", "rigid", idx, np.asarray(fns["norm"](x0[idx], [])).ravel()))
    rows = [row for row in rows if row[1] == "rigid"] + [row for row in rows if row[1] == "dynamic"]
    D = np.zeros((len(rows), len(coords)))
    for i, (_, _, idx, vals) in enumerate(rows):
        np.add.at(D[i], idx, vals)
    cols = [i for i, c in enumerate(coords) if c not in fixed and c not in inputs]
    Dcc = D[:, cols]
    if not singular_values:  # the matrix only (for surplus_dynamic_rows): no SVD
        return SpacarDcc(tuple(r[0] for r in rows), tuple(r[1] for r in rows), (), Dcc, np.zeros(0), -1, 0, 0, 0, 0)
    sv = np.linalg.svd(Dcc, compute_uv=False) if Dcc.size else np.zeros(0)
    rank = int(np.sum(sv > SPACAR_RANK_RTOL * sv[0])) if sv.size and sv[0] > 0 else 0
    names = {1: "x", 2: "y", 3: "z"}
    col_labels = tuple(f"X {n} {names[k]}" if n in X else f"R {n} lambda{k - 1}" for n, k in (coords[i] for i in cols))
    n_dynamic = sum(1 for row in rows if row[1] == "dynamic")
    n_inputs = len({c for c in inputs if c in index and not (c[0] in used_r and c[1] == 1)})
    notes: list[str] = []
    if r.warp:
        notes.append(
            f"BEAMW elements {sorted(r.warp)}: their six beam deformations on the X and R coordinates only; the "
            "warping coordinates (W nodes) and any warping deformations are left out (SPACAR's BEAMW deformation "
            "definitions are not public), so D_cc here may differ from SPACAR's by those rows and columns"
        )
    unused = sorted(c for c in inputs if c not in index)
    if unused:
        notes.append(f"inputs on coordinates no element uses, left out: {unused}")
    surplus = len(rows) - rank
    if surplus and n_dynamic:
        notes.append(
            f"{surplus} more equations than independent ones: if they come from the dynamic deformations (DYNE) "
            "and inputs spanning more than the free motions, SPACAR needs that many of them released (RLSE: "
            "calculable, still elastic) for a square D_cc, as SPACAR Light's automatic release does; flexopt "
            "treats dynamic and calculable deformations alike (both flexible), so its frequencies do not change"
        )
    return SpacarDcc(
        rows=tuple(row[0] for row in rows),
        row_kind=tuple(row[1] for row in rows),
        columns=col_labels,
        D_cc=Dcc,
        singular_values=sv,
        rank=rank,
        dof=n_inputs + n_dynamic,
        n_coordinates=len(coords),
        n_fixed=sum(1 for c in coords if c in fixed),
        n_inputs=sum(1 for c in coords if c in inputs),
        notes=tuple(notes),
        released=tuple(left_out),
    )


def surplus_dynamic_rows(d: SpacarDcc) -> tuple[str, ...]:
    """The dynamic (DYNE) rows of ``d`` to release so that the remaining rows are independent: a maximal set
    of dynamic rows independent of each other and of the rigid rows is kept, the rest returned (labels, e.g.
    "BEAM 3 eps5"), in the order of ``d.rows``.

    Rank-revealing: the dynamic rows are projected onto the complement of the rigid rows' row space (its basis
    from the SVD of the rigid rows), then a QR factorisation with column pivoting of the projected rows
    (scipy.linalg.qr) orders them by how much each adds; the first ``k`` are kept, ``k`` the number of diagonal
    entries of R above :data:`SPACAR_RANK_RTOL` times the largest singular value of D_cc (the rank threshold).
    Releasing these removes every statically indeterminate state the dynamic rows add; dependent rigid rows
    (a rigid over-constraint) and free motions stay, and ``d``'s verdict after the release says so.
    """
    import scipy.linalg

    kind = np.array(d.row_kind)
    rigid, dyn = d.D_cc[kind == "rigid"], d.D_cc[kind == "dynamic"]
    labels = [r for r, k in zip(d.rows, d.row_kind, strict=True) if k == "dynamic"]
    if not dyn.size:
        return ()
    if d.singular_values.size:
        smax = float(d.singular_values[0])
    else:  # the largest singular value alone (ARPACK, a fixed start vector: the same answer every run)
        from scipy.sparse.linalg import svds

        A = d.D_cc
        smax = (
            float(svds(A, k=1, v0=np.ones(min(A.shape)), return_singular_vectors=False)[0])
            if min(A.shape) > 1
            else float(np.linalg.norm(A))
        )
    tol = SPACAR_RANK_RTOL * smax
    if rigid.size:
        _, sv, Vt = np.linalg.svd(rigid, full_matrices=False)
        V = Vt[sv > tol].T
        dyn = dyn - (dyn @ V) @ V.T
    _, R, piv = scipy.linalg.qr(dyn.T, mode="economic", pivoting=True)
    diag = np.abs(np.diag(R))
    k = int(np.sum(diag > tol))
    keep = set(int(i) for i in piv[:k])
    return tuple(lab for i, lab in enumerate(labels) if i not in keep)
