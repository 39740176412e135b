"""Modal and frequency derivatives at stroke 0 (seed 000, section 2) and the Taylor methods fd1 and fd2.

Notation (seed 000): ``K`` tangent stiffness (Hessian of the Lagrangian, model.assembly), ``M`` mass,
``phi_i`` mass-normalised modes with the drive locked, ``lambda_i = omega_i^2``, ``eta_j`` the modal
coordinate of the driving mode ``phi_j``, ``theta_ij = d phi_i / d eta_j`` (eq. 6), ``gamma_ij =
d lambda_i / d eta_j`` (eq. 9, corrected denominator ``phi_i^T M phi_i``).

Driving mode
------------
``phi_j`` is the *static* mode of the drive, the equilibrium tangent ``d xi / d s`` at stroke 0 (the
path a quasi-static stroke actually follows: the actuator loads the drive coordinate only), scaled so
that its drive component is 1. Then ``eta_j`` equals the stroke ``s`` (rad or length) to first order,
and exactly for the drive DOF of ``q(eta)`` because the modal derivative has no drive component (below).
The first free-drive vibration mode was not used: it is mass-weighted, so for a hinge carrying a body or
a leaf with distributed mass it is not the shape a slow stroke follows, and its drive component would
need a separate scaling to map eta to the stroke.

Singular K and what is projected out
------------------------------------
Every derivative is taken with the drive *locked*: the driving coordinate is prescribed by eta itself,
so the modal derivatives solve ``K_ff theta_f = -(dK/deta_j phi_i)_f`` over the free DOFs with
``theta_d = 0`` (a static modal derivative with the master DOF held, as in Idelsohn and Cardona 1985).
This removes the drive's (possibly zero: a mechanism's) stiffness from the solve, so ``K_ff`` is regular
for every stable flexure; a singular ``K_ff`` (a free mechanism) raises an error naming the fix.

Chart and mass
--------------
``dK/deta_j`` is :meth:`System.hessian_derivative` (exact third derivative) and ``d2K/deta_j^2`` along
the manifold is ``D2K[phi_j, phi_j] + DK[theta_jj]`` with ``D2K`` the exact fourth derivative from a
CasADi kernel built here (``jtimes`` twice, with a quartic exponential so fourth derivatives are exact).
These are derivatives in the exponential chart of the reference, whereas the exact method solves each
eigenproblem in the chart at the deflected state; :func:`_to_reference_chart` converts them (Baker-
Campbell-Hausdorff terms up to second order, including the drive reaction times the chart's curvature).
The mass derivatives along the path are exact too (:func:`mass_derivatives`). Without these two
corrections fd2's curvature at stroke 0 was 3.6 % (leaf) and 8 % (parallel leaf spring) off the exact
curve's; with them it agrees to 1e-6 (leaf) and 1e-3 (pivot) (tests/test_modal_derivatives.py).
The manifold and reduced methods evaluate K and M exactly at the manifold configuration.

Accuracy limits (bench/bench_methods.py)
----------------------------------------
The one-shot quadratic manifold is a position field accurate to O(eta^3); in thin leaves that error
produces spurious membrane strain, and its geometric stiffness corrupts K beyond a few degrees (seed
leaf: 0.13 % at 5 deg, 28 % at 15 deg). The Taylor estimate fd2 is far more robust on the templates.

Repeated eigenvalues
--------------------
Modes are grouped into clusters whose eigenvalues lie within ``CLUSTER_GAP`` (relative) of each other.
Within a cluster the frequency derivatives use degenerate (quasi-degenerate, Loewdin) perturbation: the
cluster's eigenvalues at eta are those of the small matrix

    Lambda_c + eta A1 + eta^2/2 A2,   A1 = P^T K1 P,   A2 = P^T K2 P + 2 P^T K1 R K1 P,

with ``P`` the cluster's modes and ``R = sum_{k outside} phi_k phi_k^T / (lambda_c - lambda_k)`` the
reduced resolvent, so no division by a gap inside the cluster ever occurs. A single-mode cluster gives
``gamma_i = A1`` (eq. 9) and ``d2 lambda_i/deta_j^2 = A2``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import cast

import numpy as np

from .. import elements as _el
from ..analysis import MeshAnalysis
from ..assembly import State, System
from ..errors import FlexoptError
from ..modal import Modes
from ..statics import Equilibrium, solve_point
from .common import CLUSTER_GAP, _hz

__all__ = [
    "ModalDerivatives",
    "modal_derivatives",
    "hessian_second_derivative",
    "mass_derivatives",
    "mass_slope",
    "projected_mass_slope",
    "taylor_curve",
]


def hessian_second_derivative(sys: System, st: State, v: np.ndarray) -> np.ndarray:
    """Second directional derivative of the Hessian along ``v``: ``D2K[v, v]`` (exact, CasADi).

    The fourth derivative of the Lagrangian in the exponential chart at ``st`` contracted twice with
    ``v`` (active numbering, drive basis); the companion of :meth:`System.hessian_derivative`.
    """
    N = sys.N
    sys.fill_inputs(st)
    vg = sys.to_global(np.asarray(v, dtype=float))
    out = np.zeros(N * N)
    for fn, inputs, dofs, flat in (
        (_el.beam_d4, sys.beam_in, sys.beam_dofs_full, sys.beam_flat),
        (_el.truss_d4, sys.truss_in, sys.truss_dofs_full, sys.truss_flat),
    ):
        if not len(inputs):
            continue
        arg = np.hstack([inputs, vg[dofs]])
        res = np.asarray(fn().map(arg.shape[0])(arg.T)).T  # (ne, 144), column-major blocks
        out += np.bincount(flat, res.ravel(), minlength=N * N)
    return sys.reduce_matrix(out.reshape(N, N))


#: Inverse Vandermonde matrix of the nodes -2..2: Taylor coefficients of the quartic through five values.
_VANDER_INV = np.linalg.inv(np.vander(np.array([-2.0, -1.0, 0.0, 1.0, 2.0]), 5, increasing=True))


def mass_derivatives(sys: System, st: State, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First and second derivatives of the mass matrix along ``q(eta) = a eta + 1/2 b eta^2`` at ``st``.

    The mass (:meth:`System.mass`) is a polynomial of degree 2 in the masters' rotation matrices (rotary
    inertia ``R J R^T``, offsets ``r = R r0``) and independent of their positions. Along the curve the
    rotations are ``R(eta) = expm(psi_a eta + 1/2 psi_b eta^2) R0``, whose second-order Taylor polynomial
    ``R0 + eta R1 + eta^2/2 R2`` (``R1 = [a] R0``, ``R2 = ([b] + [a]^2) R0``) gives exact first and
    second derivatives; the mass along that polynomial is a polynomial of degree 4 in eta, whose Taylor
    coefficients follow *exactly* (no truncation error, only rounding) from its values at five points by
    Lagrange interpolation. This is interpolation of a known-degree polynomial, not a finite difference.
    """
    from ..rotations import skew

    A = sys.to_global(a).reshape(-1, 6)[:, 3:]
    B = sys.to_global(b).reshape(-1, 6)[:, 3:]
    Sa, Sb = skew(A), skew(B)
    R1 = Sa @ st.R
    R2 = (Sb + Sa @ Sa) @ st.R
    nodes = np.array([-2.0, -1.0, 0.0, 1.0, 2.0])
    samples = []
    for e in nodes:
        trial = State(st.X, st.R + e * R1 + 0.5 * e * e * R2, st.lam)
        samples.append(sys.mass(trial))
    vals = np.array(samples)
    # exact derivatives at 0 of the degree-4 interpolant through the five points
    coef = (_VANDER_INV[1:3] @ vals.reshape(5, -1)).reshape((2,) + vals.shape[1:])
    coef = np.concatenate([np.zeros((1,) + vals.shape[1:]), coef])
    M1, M2 = coef[1], 2.0 * coef[2]
    return 0.5 * (M1 + M1.T), 0.5 * (M2 + M2.T)


def _rotation_increment(sys: System, st: State, a: np.ndarray) -> np.ndarray:
    """``R1 = [a] R0`` per master (nm, 3, 3): the first derivative of the masters' rotations along ``a``."""
    from ..rotations import skew

    return skew(sys.to_global(a).reshape(-1, 6)[:, 3:]) @ st.R


def _masses_off_path(sys: System, st: State, R1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The masses at ``R0 + R1`` and ``R0 - R1`` (see :func:`mass_slope`)."""
    return sys.mass(State(st.X, st.R + R1, st.lam)), sys.mass(State(st.X, st.R - R1, st.lam))


def mass_slope(sys: System, st: State, a: np.ndarray) -> np.ndarray:
    """First derivative of the mass matrix along ``q(eta) = a eta`` at ``st``: ``M1`` of
    :func:`mass_derivatives` with ``b = 0``, from two mass evaluations instead of five.

    The mass is a polynomial of degree 2 in the masters' rotation matrices (see :func:`mass_derivatives`),
    and its first derivative along ``R(eta) = expm(eta [a]) R0`` depends only on ``R'(0) = [a] R0``, so it
    equals the derivative along the straight line ``R0 + eta [a] R0``, on which the mass is a quadratic
    ``c0 + c1 eta + c2 eta^2``; ``(M(1) - M(-1)) / 2 = c1`` holds exactly (rounding only).
    """
    Mp, Mm = _masses_off_path(sys, st, _rotation_increment(sys, st, a))
    M1 = 0.5 * (Mp - Mm)
    return 0.5 * (M1 + M1.T)


def projected_mass_slope(sys: System, st: State, a: np.ndarray, P: np.ndarray) -> np.ndarray:
    """``P^T M1 P`` with ``M1`` of :func:`mass_slope` (k x k, symmetric), from the same two mass evaluations:
    ``P^T (M(R + R1) - M(R - R1)) P / 2`` symmetrised as a k x k matrix (the stroke slopes of ``hermite``
    need only this projection)."""
    return _projected_mass_slope(sys, st, _rotation_increment(sys, st, a), P)


def _projected_mass_slope(sys: System, st: State, R1: np.ndarray, P: np.ndarray) -> np.ndarray:
    """:func:`projected_mass_slope` from the masters' rotation increments ``R1 = [a] R0`` (nm, 3, 3)."""
    Mp, Mm = _masses_off_path(sys, st, R1)
    M1 = 0.5 * (P.T @ ((Mp - Mm) @ P))
    return 0.5 * (M1 + M1.T)


def _to_reference_chart(
    sys: System,
    K: np.ndarray,
    M: np.ndarray,
    K1: np.ndarray,
    K2: np.ndarray,
    M1: np.ndarray,
    M2: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
) -> tuple:
    """Put stiffness and mass derivatives along ``xi(eta) = a eta + 1/2 b eta^2`` in one chart.

    ``K1, K2`` (from the kernels) are derivatives of the Hessian in the exponential chart of the
    reference; the exact method solves, at each state, the eigenproblem in the chart *at that state*
    (spatial increments ``psi'``, drive lock ``psi'.axis = 0``), and ``M1, M2`` differentiate that
    mass. The two charts of a master's rotation are related by ``exp(xi + delta) = exp(psi') exp(xi)``;
    by the Baker-Campbell-Hausdorff series ``psi' = J delta + 1/2 delta^T Gamma delta`` with
    ``J = I + 1/2 [xi] + 1/6 [xi]^2 + O(xi^3)`` and, along the drive axis ``e`` for ``xi = eta e``,
    ``Gamma_e = (eta / 6)(I - e e^T) + O(eta^2)``. Hence (exactly to second order in eta)

        M_ref = J^T M J,    K_ref = J^T K' J + g_e Gamma_e,

    with ``g_e`` the drive reaction (``= eta (K a)_drive + O(eta^2)``, the only non-zero gradient
    entry at equilibrium) and, for a general rotation ``xi`` of the driven master, ``Gamma_e =
    (xi.e)/6 I - (xi e^T + e xi^T)/12``. The stiffness derivatives are transformed to the exact
    method's chart, ``K' = J^-T (K_ref - g Gamma) J^-1`` to second order, where the drive lock is the
    plain removal of the drive DOF; ``M1, M2`` are already in that chart. Returns ``K'_1, K'_2, M1, M2``.
    Checked against finite differences of K and of the eigenvalues in tests/test_modal_derivatives.py.
    """
    from ..rotations import skew

    n = sys.n
    T = sys.to_global(np.eye(n))  # (n_full, n); orthonormal columns
    A = sys.to_global(a).reshape(-1, 6)[:, 3:]
    B = sys.to_global(b).reshape(-1, 6)[:, 3:]
    nm = A.shape[0]
    J1g = np.zeros((6 * nm, 6 * nm))
    J2g = np.zeros((6 * nm, 6 * nm))
    for m in range(nm):
        r = slice(6 * m + 3, 6 * m + 6)
        Sa, Sb = skew(A[m]), skew(B[m])
        J1g[r, r] = 0.5 * Sa
        J2g[r, r] = 0.5 * Sb + Sa @ Sa / 3.0
    J1, J2 = T.T @ J1g @ T, T.T @ J2g @ T
    G2 = np.zeros((n, n))
    s = sys.s
    if s.drive_kind == "rotation":
        e = np.asarray(s.drive_axis, dtype=float)
        e = e / np.linalg.norm(e)
        t = A[s.drive_master]
        m1 = float((K @ a)[sys.drive])  # d g_e / d eta: the drive stiffness along the path
        Gg = np.zeros((6 * nm, 6 * nm))
        r = slice(6 * s.drive_master + 3, 6 * s.drive_master + 6)
        # d2/deta2 of g_e Gamma_e, Gamma_e = (xi.e)/6 I - (xi e^T + e xi^T)/12 (second-order BCH term)
        Gg[r, r] = 2.0 * m1 * (float(t @ e) / 6.0 * np.eye(3) - (np.outer(t, e) + np.outer(e, t)) / 12.0)
        G2 = T.T @ Gg @ T
    # K_ref = J^T K' J + G  =>  derivatives of K' (the exact method's chart) along the path
    Kn1 = K1 - (J1.T @ K + K @ J1)
    Kn2 = K2 - G2 - 2.0 * (J1.T @ Kn1 + Kn1 @ J1) - (J2.T @ K + K @ J2) - 2.0 * J1.T @ K @ J1
    sym = lambda X: 0.5 * (X + X.T)  # noqa: E731
    return sym(Kn1), sym(Kn2), M1, M2


# ----------------------------------------------------------------- derivatives at the reference
@dataclass(frozen=True)
class ModalDerivatives:
    """Modes, modal derivatives and frequency derivatives at the reference equilibrium (stroke 0).

    Vectors are over all active DOFs (drive basis); modes and derivatives have a zero drive entry except
    ``phi_j`` (drive entry 1).
    """

    omega2: np.ndarray  # (m,) locked eigenvalues lambda_i, ascending (all modes of the locked problem)
    phi: np.ndarray  # (n, m) mass-normalised locked modes
    M: np.ndarray  # (n, n) mass matrix at the reference
    phi_j: np.ndarray  # (n,) driving (static) mode, drive entry 1 (eta_j = stroke)
    theta_jj: np.ndarray  # (n,) static modal derivative of phi_j along itself (eq. 6)
    theta: np.ndarray  # (n, r) theta_ij = -K^-1 dK/deta_j phi_i for the first r modes (eq. 6)
    gamma: np.ndarray  # (m,) d lambda_i / d eta_j (eq. 9 corrected; diagonal of A1 in the mode basis)
    gamma2: np.ndarray  # (m,) d2 lambda_i / d eta_j^2 (diagonal of A2; see module docstring)
    clusters: tuple[np.ndarray, ...]  # mode indices of each (quasi-)degenerate cluster
    A1: tuple[np.ndarray, ...]  # per cluster: first-order matrix P^T K1 P
    A2: tuple[np.ndarray, ...]  # per cluster: second-order matrix (static correction + mode-shape term)
    labels: tuple[str, ...]  # labels of the modes at the reference ("parasitic" | "intended" | "drive")
    build_seconds: float
    dphi: np.ndarray  # (n, r) exact (dynamic) mode-shape derivatives d phi_i / d eta_j, outside clusters

    def symmetrised_theta(self, dK_i: np.ndarray, K_ff_solve, free: np.ndarray) -> np.ndarray:
        """``1/2 (theta_ij + theta_ji)``; equal to ``theta_ij`` up to rounding because ``dK`` comes from a
        symmetric third derivative (``dK[phi_j] phi_i = dK[phi_i] phi_j``). Provided for checks."""
        th_ji = np.zeros(len(self.phi_j))
        th_ji[free] = -K_ff_solve((dK_i @ self.phi_j)[free])
        return th_ji

    def eigenvalues(self, eta: np.ndarray, order: int) -> np.ndarray:
        """Estimate of all locked eigenvalues at ``eta``, shape (p, m).

        ``order`` 1: eq. 10, ``lambda_0 + gamma eta`` (with degenerate perturbation in clusters).
        ``order`` 2 (fd2): the second-order expansion. For an isolated mode that softens
        (``d2 lambda < 0``) the [0/2] Pade form ``lambda_0 / (1 - g eta + (g^2 - h/2) eta^2)`` with
        ``g = gamma/lambda_0``, ``h = gamma2/lambda_0``: same Taylor terms up to eta^2, but it is the exact
        shape of a support stiffness in series with a compliance growing as eta^2 (the 1/700 term of
        PHYSICS.md), stays positive, and does not cross zero like the parabola. Clusters use the
        quadratic matrix ``Lambda + eta A1 + eta^2/2 A2``.
        """
        eta = np.asarray(eta, dtype=float)
        out = np.empty((len(eta), len(self.omega2)))
        for c, a1, a2 in zip(self.clusters, self.A1, self.A2):
            lam0 = self.omega2[c]
            if len(c) == 1:
                l0, g, h = lam0[0], a1[0, 0], a2[0, 0]
                if order == 1:
                    out[:, c[0]] = l0 + g * eta
                elif h < 0 and l0 > 0:
                    gg, hh = g / l0, h / l0
                    out[:, c[0]] = l0 / (1.0 - gg * eta + (gg * gg - 0.5 * hh) * eta**2)
                else:
                    out[:, c[0]] = l0 + g * eta + 0.5 * h * eta**2
                continue
            e3 = eta[:, None, None]
            if order == 2 and np.all(lam0 > 0) and np.abs(a1).max() <= 1e-6 * lam0.max():
                # first-order splitting vanishes (a symmetric pair): second-order degenerate perturbation,
                # the branches are the eigenvectors of A2; each then gets the scalar form below
                lc = float(lam0.mean())
                hs = np.sort(np.linalg.eigvalsh(0.5 * (a2 + a2.T)))
                cols = []
                for h in hs:
                    cols.append(lc / (1.0 + 0.5 * (-h / lc) * eta**2) if h < 0 else lc + 0.5 * h * eta**2)
                out[:, c] = np.sort(np.column_stack(cols), axis=1)
                continue
            if order == 2 and np.all(lam0 > 0):
                # matrix [0/2] Pade: L^1/2 D(eta)^-1 L^1/2, D = I - eta G + eta^2 (G^2 - H/2),
                # G = L^-1/2 A1 L^-1/2, H = L^-1/2 A2 L^-1/2 (same Taylor terms up to eta^2)
                r = 1.0 / np.sqrt(lam0)
                G = r[:, None] * a1 * r[None, :]
                H = r[:, None] * a2 * r[None, :]
                if np.linalg.eigvalsh(0.5 * (H + H.T)).max() < 0:
                    D = np.eye(len(c))[None] - e3 * G[None] + e3**2 * (G @ G - 0.5 * H)[None]
                    D = 0.5 * (D + D.transpose(0, 2, 1))
                    # eigenvalues of L^1/2 D^-1 L^1/2 = 1 / eigenvalues of L^-1/2 D L^-1/2
                    B = r[None, :, None] * D * r[None, None, :]
                    out[:, c] = np.sort(1.0 / np.linalg.eigvalsh(0.5 * (B + B.transpose(0, 2, 1)))[:, ::-1], axis=1)
                    continue
            A = np.diag(lam0)[None] + e3 * a1[None] + (0.5 * e3**2 * a2[None] if order == 2 else 0.0)
            out[:, c] = np.linalg.eigvalsh(0.5 * (A + A.transpose(0, 2, 1)))
        return out


def _eq_at(sys: System, st: State) -> Equilibrium:
    """An Equilibrium-like object (state and evaluated kernels) for :func:`modes_at` at a non-equilibrium."""
    # a cast: modes_at reads only an equilibrium's .state and .ev, here those of a point off the equilibrium path
    return cast(Equilibrium, SimpleNamespace(state=st, ev=sys.evaluate(st)))


def _clusters(lam: np.ndarray, gap: float) -> list[np.ndarray]:
    """Runs of the ascending ``lam`` whose neighbours differ by at most ``gap`` relative (of the larger one,
    floored at 1e-12 of the largest magnitude): index arrays covering every position, in order."""
    lam = np.asarray(lam, dtype=float)
    n = len(lam)
    if n == 0:
        return []
    scale = max(float(np.abs(lam).max()), 1e-300)
    cut = np.abs(np.diff(lam)) > gap * np.maximum(np.abs(lam[1:]), 1e-12 * scale)
    if not cut.any():
        return [np.arange(n)]
    return np.split(np.arange(n), np.flatnonzero(cut) + 1)


def _multiple(lam: np.ndarray, gap: float) -> list[np.ndarray]:
    """The runs of :func:`_clusters` with more than one member (usually none: no split is made then)."""
    v = np.asarray(lam, dtype=float).tolist()  # a few eigenvalues: Python floats cost less than numpy calls here
    n = len(v)
    if n < 2:
        return []
    floor = 1e-12 * max(max(abs(x) for x in v), 1e-300)
    out, start = [], None  # runs of neighbours that are close: [start, i] (numpy.split costs more than this)
    for i in range(n - 1):  # the comparison of _clusters, neighbour by neighbour, in the same arithmetic
        if abs(v[i + 1] - v[i]) <= gap * max(abs(v[i + 1]), floor):
            if start is None:
                start = i
        elif start is not None:
            out.append(np.arange(start, i + 1))
            start = None
    if start is not None:
        out.append(np.arange(start, n))
    return out


def _perturbation(
    sys: System, M: np.ndarray, Kff: np.ndarray, K1: np.ndarray, K2: np.ndarray, M1: np.ndarray, M2: np.ndarray
) -> tuple:
    """All locked modes at the reference and the (quasi-)degenerate perturbation of their eigenvalues along
    the path (module docstring): ``w``, ``phi``, the clusters, their ``A1``, ``A2``, ``gamma``, ``gamma2`` and
    the outside-cluster mode-shape derivatives, from the stiffness and mass derivatives in the exact method's
    chart (:func:`_to_reference_chart`)."""
    import scipy.linalg as sla  # lazily: 0.2-1 s to import, which the hermite path (and auto) never needs

    f = sys.free
    # all locked modes (resolvent of the mode-shape term); small models: a dense solve
    # eigen solve on the DOF-scaled matrices D K D, D M D (D = the DOFs' length scales): the same
    # numbers in any consistent units, so results are unit-invariant to rounding
    Dv = sys.scale_free
    Mf = sys.free_block(M)
    Ms = Dv[:, None] * (0.5 * (Mf + Mf.T)) * Dv[None, :]
    w, V = sla.eigh(Dv[:, None] * Kff * Dv[None, :], Ms)
    V = Dv[:, None] * V
    phi = np.zeros((sys.n, len(w)))
    phi[f] = V
    # modal matrices of K(eta) = Lam + eta k1 + eta^2/2 k2 and M(eta) = I + eta m1 + eta^2/2 m2, then the
    # symmetric form S K S with S = M^-1/2 = I + eta s1 + eta^2 s2 (s1 = -m1/2, s2 = 3/8 m1^2 - 1/4 m2)
    k1, k2 = phi.T @ K1 @ phi, phi.T @ K2 @ phi
    m1, m2 = phi.T @ M1 @ phi, phi.T @ M2 @ phi
    s1, s2 = -0.5 * m1, 0.375 * m1 @ m1 - 0.25 * m2
    Lam = np.diag(w)
    t1 = k1 + s1 @ Lam + Lam @ s1
    t2 = 2.0 * (s2 @ Lam + Lam @ s2 + s1 @ Lam @ s1 + s1 @ k1 + k1 @ s1 + 0.5 * k2)
    t1, t2 = 0.5 * (t1 + t1.T), 0.5 * (t2 + t2.T)
    clusters = _clusters(w, CLUSTER_GAP)
    A1s, A2s = [], []
    dyn = np.zeros((sys.n, len(w)))  # exact (dynamic) mode-shape derivatives, outside-cluster part
    for c in clusters:
        lam_c = float(np.mean(w[c]))
        out = np.setdiff1d(np.arange(len(w)), c)
        R = 1.0 / (lam_c - w[out])
        A1s.append(t1[np.ix_(c, c)])
        A2s.append(t2[np.ix_(c, c)] + 2.0 * (t1[np.ix_(c, out)] * R) @ t1[np.ix_(out, c)])
        dyn[:, c] = phi[:, out] @ (R[:, None] * t1[np.ix_(out, c)])
    gamma = np.diag(t1).copy()
    gamma2 = np.empty(len(w))
    for c, a2 in zip(clusters, A2s):
        gamma2[c] = np.diag(a2)
    return w, phi, clusters, A1s, A2s, gamma, gamma2, dyn


def modal_derivatives(
    an: MeshAnalysis, eq0: Equilibrium | None = None, n_theta: int | None = None, labeller=None
) -> ModalDerivatives:
    """Modes, modal derivatives (eq. 6) and first and second frequency derivatives at stroke 0.

    Parameters
    ----------
    an : MeshAnalysis
        The compiled scene.
    eq0 : Equilibrium, optional
        The reference equilibrium (solved if not given).
    n_theta : int, optional
        Number of modes whose ``theta_ij`` are kept (default: the scene's reported modes + 2).

    Notes
    -----
    With ``K1 = dK/deta_j = DK[phi_j]`` and ``K2 = d2K/deta_j^2 = D2K[phi_j, phi_j] + DK[theta_jj]``
    (the second derivative along the quadratic manifold ``q = phi_j eta + 1/2 theta_jj eta^2``, eq. 7 with
    the 1/2), mass-normalised modes and M held at the reference: ``gamma_i = phi_i^T K1 phi_i`` (eq. 9;
    the second numerator term vanishes for exact eigenpairs) and ``d2 lambda_i/deta^2 = phi_i^T K2 phi_i +
    2 sum_{k != i} (phi_k^T K1 phi_i)^2 / (lambda_i - lambda_k)`` (the mode-shape sensitivity term).
    """
    import scipy.linalg as sla  # lazily: 0.2-1 s to import, which the hermite path (and auto) never needs

    t0 = time.perf_counter()
    sys = an.system
    if eq0 is None:
        eq0 = solve_point(sys, sys.reference_state(), 0.0, an.options, 0.0)
    if sys.n_con:
        raise FlexoptError(
            "modal derivatives do not support rigid deformations (constraints) yet; "
            "use method='exact' or make the elements flexible"
        )
    f, d = sys.free, sys.drive
    K = eq0.ev.H
    M = sys.mass(eq0.state)
    Kf = sys.free_block(K)
    Kff = 0.5 * (Kf + Kf.T)
    try:
        cho = sla.cho_factor(Kff)
    except np.linalg.LinAlgError as exc:
        raise FlexoptError(
            "the tangent stiffness with the drive locked is singular or indefinite at stroke 0 "
            "(a mechanism or an unstable reference): support the structure, or use "
            "method='exact'"
        ) from exc

    def solve(b: np.ndarray) -> np.ndarray:
        return sla.cho_solve(cho, b)

    # driving (static) mode: K_ff phi_f = -K_fd, drive entry 1 (the equilibrium tangent d xi/ds)
    phi_j = np.zeros(sys.n)
    phi_j[d] = 1.0
    phi_j[f] = solve(-K[f, d])
    K1 = sys.hessian_derivative(eq0.state, phi_j)
    K1 = 0.5 * (K1 + K1.T)
    theta_jj = np.zeros(sys.n)
    theta_jj[f] = -solve((K1 @ phi_j)[f])  # eq. 6 for i = j, drive held
    K2 = hessian_second_derivative(sys, eq0.state, phi_j) + sys.hessian_derivative(eq0.state, theta_jj)
    K2 = 0.5 * (K2 + K2.T)
    M1, M2 = mass_derivatives(sys, eq0.state, phi_j, theta_jj)
    K1, K2, M1, M2 = _to_reference_chart(sys, K, M, K1, K2, M1, M2, phi_j, theta_jj)
    w, phi, clusters, A1s, A2s, gamma, gamma2, dyn = _perturbation(sys, M, Kff, K1, K2, M1, M2)
    r = min(len(w), n_theta if n_theta is not None else max(2 * (an.scene.modes + 2), 12))
    theta = np.zeros((sys.n, r))
    theta[f] = -solve((K1 @ phi[:, :r])[f])  # eq. 6: theta_ij = -K^-1 dK/deta_j phi_i
    labels, _ = an.label_modes(Modes(w, phi, M))
    return ModalDerivatives(
        w,
        phi,
        M,
        phi_j,
        theta_jj,
        theta,
        gamma,
        gamma2,
        tuple(clusters),
        tuple(A1s),
        tuple(A2s),
        tuple(labels),
        time.perf_counter() - t0,
        dyn[:, :r],
    )


@dataclass
class _Prepared:
    an: MeshAnalysis
    eq0: Equilibrium
    md: ModalDerivatives
    basis: np.ndarray | None = None
    #: the exact first parasitic frequencies at check strokes (:mod:`.accuracy`), keyed by the strokes' bytes
    checks: dict = field(default_factory=dict)


def _prepare(an: MeshAnalysis) -> _Prepared:
    """The stroke-0 equilibrium and modal derivatives of ``an``, kept on it (``MeshAnalysis.expansion``)."""
    if not isinstance(an.expansion, _Prepared):
        sys = an.system
        eq0 = solve_point(sys, sys.reference_state(), 0.0, an.options, 0.0)
        an.expansion = _Prepared(an, eq0, modal_derivatives(an, eq0))
    return an.expansion


def taylor_curve(prep: _Prepared, eta: np.ndarray, order: int, n_rep: int) -> tuple:
    """fd1 (``order`` 1, eq. 10) or fd2 (second order): Taylor estimates of every branch at ``eta``."""
    md = prep.md
    lam = md.eigenvalues(eta, order)
    lab0 = np.array(md.labels, dtype=object)
    hz_all = _hz(lam)
    # the first parasitic frequency is sought among the reported modes: the Taylor
    # expansions of high modes are not meant to be used at large stroke
    par_mask = (lab0 == "parasitic") & (np.arange(len(lab0)) < n_rep)
    par = hz_all[:, par_mask].min(axis=1) if par_mask.any() else np.full(len(eta), np.nan)
    idx = np.argsort(lam, axis=1)[:, :n_rep]
    hz = np.take_along_axis(hz_all, idx, axis=1)
    labels = lab0[idx]
    return hz, labels, par
