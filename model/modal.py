"""Linearised natural frequencies at an equilibrium, mode tracking and parasitic labels.

At a converged equilibrium the tangent stiffness ``K`` is the Hessian of the Lagrangian in the
exponential chart (material plus geometric stiffness from the internal generalised stresses, and the
multipliers' curvature for rigid deformations), and ``M`` the mass matrix at the deflected configuration.
With the drive locked, the drive DOF is removed: for a rotation drive that removes only the incremental
spin about the drive axis (delta_omega . axis = 0), with no curvature of the lock (the other incremental
rotations follow straight lines of the exponential chart). Rigid deformations are imposed on the
eigenproblem through an orthonormal null-space basis ``Z`` of their Jacobian: ``(Z^T K Z - w^2 Z^T M Z) y = 0``.

Modes are tracked between stroke points by the mass-weighted modal assurance criterion (MAC) and a
linear assignment, so curves follow modes through crossings.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
from scipy.linalg import lapack
from scipy.optimize import linear_sum_assignment

from .assembly import System
from .errors import FlexoptError
from .statics import Equilibrium

_ABSTOL = 2.0 * float(np.finfo(float).tiny)

__all__ = ["Modes", "modes_at", "track", "participation"]


@dataclass
class Modes:
    """Eigenpairs at one equilibrium."""

    omega2: np.ndarray  # (k,) eigenvalues [rad^2/s^2], ascending
    phi: np.ndarray  # (n, k) mass-normalised mode shapes over all DOFs (drive basis)
    M: np.ndarray  # (n, n) mass matrix used

    @property
    def hz(self) -> np.ndarray:
        """Natural frequencies [Hz] (negative eigenvalues give negative numbers: unstable)."""
        return np.sign(self.omega2) * np.sqrt(np.abs(self.omega2)) / (2 * np.pi)


def modes_at(sys: System, eq: Equilibrium, k: int, drive: str = "locked") -> Modes:
    """The ``k`` lowest eigenpairs at ``eq`` with the drive ``locked`` or ``free``."""
    s = sys.s
    M = sys.mass(eq.state)
    locked = drive == "locked"
    dofs = sys.free if locked else np.arange(sys.n)
    ix = sys.ix_free if locked else sys.ix_all
    K = eq.ev.H[ix]
    Mr = M[ix]
    Z = None
    if sys.n_con:
        Z = sla.null_space(eq.ev.G[:, dofs])
        K, Mr = Z.T @ K @ Z, Z.T @ Mr @ Z
    k = min(k, K.shape[0])
    if k == 0:
        return Modes(np.zeros(0), np.zeros((sys.n, 0)), M)
    # LAPACK's dsygvx (Cholesky of M, reduction, the k lowest pairs) called directly: the scipy.linalg.eigh
    # wrapper's checks cost a third of the solve on small models. Only the lower triangles are read, so
    # K's round-off asymmetry is irrelevant; F-ordered transposes avoid copies. ABSTOL = 2 * underflow is
    # LAPACK's setting for the most accurate eigenvalues: the default (eps * norm) would leave the lowest
    # eigenvalues of a stiff model with relative errors up to eps * lambda_max / lambda_min.
    w, V, _, _, info = lapack.dsygvx(K.T, Mr.T, itype=1, jobz="V", range="I", il=1, iu=k, uplo="L",
                                     abstol=_ABSTOL)
    if info > K.shape[0]:  # LAPACK: the leading minor of order info - n of M is not positive definite
        bad = [s.dof_label(int(sys.act_full[d])) for d in dofs[np.diag(M[ix]) <= 0][:5]]
        raise FlexoptError(
            "the mass matrix is singular" + (f" (no mass on {', '.join(bad)})" if bad else "")
            + "; give every moving body mass and inertia or attach it to beams"
        )
    if info != 0:
        raise FlexoptError(f"the eigen solver did not converge (LAPACK dsygvx info {info}); the stiffness "
                           "matrix may contain non-finite values: check the scene's dimensions")
    w, V = w[:k], V[:, :k]
    phi = np.zeros((sys.n, k))
    phi[dofs] = V if Z is None else Z @ V
    return Modes(w, phi, M)


def participation(sys: System, modes: Modes) -> np.ndarray | None:
    """Fraction of each mode's kinetic energy in the declared support directions (None if undeclared)."""
    P = sys.s.support_projector
    if P is None:
        return None
    phi = modes.phi
    pg = sys.support_projector() @ phi
    num = np.einsum("ik,ik->k", pg, modes.M @ pg)
    den = np.einsum("ik,ik->k", phi, modes.M @ phi)
    return np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)


def track(prev: Modes, cur: Modes) -> np.ndarray:
    """Permutation ``p`` such that ``cur`` mode ``p[i]`` continues ``prev`` mode ``i`` (mass-weighted MAC)."""
    A = prev.phi
    B = cur.phi
    MB = cur.M @ B
    num = (A.T @ MB) ** 2
    den = np.outer(np.einsum("ij,ij->j", A, cur.M @ A), np.einsum("ij,ij->j", B, MB))
    mac = num / np.where(den > 0, den, 1.0)
    rows, cols = linear_sum_assignment(-mac)
    perm = np.empty(len(rows), dtype=int)
    perm[rows] = cols
    return perm
